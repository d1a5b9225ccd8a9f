// The incremental evaluator (rules.h, docs/reasoner.md "Sessions"). Terms are interned to u32
// ids; each predicate is a relation of rows that are never moved (a row keeps its index while it
// comes and goes), with a base count (records in the store) and a derived flag (a rule gives it).
// A session touches rows and remembers their state at its start, so the facts that appeared
// and disappeared (for the strata above) and the conclusions that changed (for the store) are
// read off the touched rows at the end.
//
// Strata run in dependency order; a predicate's rules may lie in several (split by head
// pattern, RS6), and a row then records which of them derive it. A stratum whose inputs only
// grew runs semi-naive: each rule once per body atom that has new rows, that atom over the new
// rows only, then rounds over its own new rows to the fixpoint. A stratum reached by a removal,
// by any change under a negation, or using `now` is recomputed: its derived flags are cleared
// and it runs to the fixpoint again; what differs from before is what changed.
//
// Joins (docs/reasoner.md, "Joins") are tuned for sensor data: thousands of readings joined with
// context by time windows. An atom whose variable comparisons bound reads a sorted index over
// the window; a part of a rule independent of the steps before it is enumerated once per rule
// run and replayed; a full round starts from the atom with the fewest rows to read.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <deque>
#include <map>
#include <set>
#include <unordered_set>

#include "program.h"
#include "table.h"
#include "value.h"

namespace tahvel::reasoner {

namespace {

using Id = std::uint32_t;  // term id; 0 = unbound

// --- terms ------------------------------------------------------------------------------------

class Dict {
 public:
  Dict() { offsets_.push_back(0); values_.emplace_back(); }

  Id intern(const node::Term& term) {
    encode(term);
    std::uint64_t h = hash(key_);
    Id id = table_.find(h, [&](std::uint32_t id) { return key(id) == key_; });
    if (id != kNone) return id;
    id = static_cast<Id>(values_.size());
    arena_ += key_;
    offsets_.push_back(arena_.size());
    values_.push_back(value_of(term));
    table_.insert(h, id);
    return id;
  }
  Id find(const node::Term& term) {
    encode(term);
    Id id = table_.find(hash(key_), [&](std::uint32_t id) { return key(id) == key_; });
    return id == kNone ? 0 : id;
  }
  // Decoded from the arena (terms are kept once, as their key).
  node::Term term(Id id) const {
    std::string_view k = key(id);
    node::Term t;
    t.kind = static_cast<node::TermKind>(k[0]);
    std::size_t at = 1;
    auto get = [&](std::string& out) {
      std::uint32_t n;
      std::memcpy(&n, k.data() + at, sizeof n);
      out.assign(k.data() + at + sizeof n, n);
      at += sizeof n + n;
    };
    get(t.value);
    get(t.datatype);
    t.language.assign(k.substr(at));
    return t;
  }
  const Value& value(Id id) const { return values_[id]; }
  std::size_t size() const { return values_.size(); }

 private:
  std::string_view key(Id id) const {
    return std::string_view(arena_).substr(offsets_[id - 1], offsets_[id] - offsets_[id - 1]);
  }
  static std::uint64_t hash(std::string_view s) { return mix64(std::hash<std::string_view>{}(s)); }
  void encode(const node::Term& t) {
    key_.clear();
    key_ += static_cast<char>(t.kind);
    auto put = [&](const std::string& s) {
      std::uint32_t n = static_cast<std::uint32_t>(s.size());
      key_.append(reinterpret_cast<const char*>(&n), sizeof n);
      key_ += s;
    };
    put(t.value);
    put(t.datatype);
    key_ += t.language;
  }

  std::string arena_;
  std::vector<std::size_t> offsets_;  // key of id k: arena_[offsets_[k-1], offsets_[k])
  std::vector<Value> values_;
  IdTable table_;
  std::string key_;
};

// --- relations --------------------------------------------------------------------------------

std::uint64_t hash_ids(const Id* t, std::uint32_t n) {
  // Pairs (every triple's relation) in one mix: the lookups of fully bound atoms hash them.
  if (n == 2) return mix64((static_cast<std::uint64_t>(t[0]) << 32 | t[1]) ^ 0x9e3779b97f4a7c15ull);
  std::uint64_t h = 0x9e3779b97f4a7c15ull ^ n;
  for (std::uint32_t i = 0; i < n; ++i) h = mix64(h ^ t[i]) + i;
  return mix64(h);
}

// The key of the bound positions `mask` of tuple t: exact for one or two positions.
std::uint64_t index_key(const Id* t, std::uint32_t n, std::uint32_t mask) {
  Id vals[16];
  std::uint32_t k = 0;
  for (std::uint32_t i = 0; i < n; ++i) if (mask & (1u << i)) vals[k++] = t[i];
  if (k == 1) return vals[0];
  if (k == 2) return (static_cast<std::uint64_t>(vals[0]) << 32) | vals[1];
  std::uint64_t h = hash_ids(vals, k);
  return h == ~0ull ? h - 1 : h;
}

// Rows by the values of the bound positions `mask`: heads of chains through `next`. One bound
// position keys a dense vector by term id (ids are dense), more go through a hash map.
struct Index {
  std::uint32_t mask = 0;
  bool direct = false;
  std::vector<std::uint32_t> by_id;
  std::vector<std::uint32_t> count;  // direct: rows ever linked under each id (for plan choice)
  KeyMap head;
  std::vector<std::uint32_t> next;

  std::uint32_t first(std::uint64_t key) const {
    if (!direct) return head.get(key);
    return key < by_id.size() ? by_id[key] : kNone;
  }
  std::uint32_t push(std::uint64_t key, std::uint32_t row) {
    if (!direct) return head.put(key, row);
    if (key >= by_id.size()) {
      by_id.resize(std::max<std::size_t>(key + 1, by_id.size() * 3 / 2), kNone);
      count.resize(by_id.size(), 0);
    }
    ++count[key];
    std::uint32_t old = by_id[key];
    by_id[key] = row;
    return old;
  }
};

// The place of a number or time on one line, for sorted indexes: integers and reals as
// themselves, times as seconds since the epoch, as compare_values compares them. The map is
// monotone (a value that compares >= another never has a smaller key), though not one to one
// (integers beyond 2^53, times closer than a few ns share keys): a range of keys holds every
// value in the range of values, and the comparison itself, still in the rule, decides.
bool sort_key(const Value& v, double& key) {
  switch (v.kind) {
    case Value::integer: key = static_cast<double>(v.i); return true;
    case Value::real: key = v.d; return true;
    case Value::time: key = static_cast<double>(v.i) / 1e9; return true;
    default: return false;
  }
}

// Rows by the values of the bound positions `mask` (their index_key), then by the key of the
// value at `column`; rows whose value there is not a number or time are left out (no
// comparison holds on them). Rows are added to the index when it is next used.
struct SortedIndex {
  struct Entry {
    std::uint64_t eq;
    double key;
    std::uint32_t row;
    bool operator<(const Entry& o) const { return eq != o.eq ? eq < o.eq : key < o.key; }
  };
  std::uint32_t mask = 0, column = 0;
  std::uint32_t rows_seen = 0;
  std::vector<Entry> entries;
};

constexpr std::uint8_t kTouched = 0x80, kWasAlive = 1, kWasDerived = 2, kWasBase = 4;
// Conclusions one session may derive before it is taken for rules that never stop
// (RunawayDerivation). Shipped rule sets derive a few per fact; a thousand rules over ten
// thousand facts, half a million from scratch. Two million of the runaway counter took 0.3 GB.
constexpr std::size_t kMaxSessionConclusions = 2'000'000;

// Rows under the bound arguments up to which a chain is walked rather than a range searched.
constexpr int kShortChain = 16;

struct Relation {
  std::uint32_t arity = 0;
  Id pred_iri = 0;        // binary relations: the predicate's term id
  int pred = -1;          // program predicate, -1 for a relation of base facts only
  // The strata with rules for this relation, in order. A predicate's rules are split into
  // strata by head pattern (RS6), so several may derive one row: then `words` 64-bit words per
  // row in `owners` say which (bit k: deriving[k]), and derived[r] is whether any does, so
  // that recomputing one stratum clears only its own derivations.
  std::vector<std::uint32_t> deriving;
  std::uint32_t words = 0;  // 0: one stratum at most, derived[r] says it alone
  std::vector<std::uint64_t> owners;
  bool read = true;       // some rule reads it (base facts are kept only then)
  std::vector<Id> data;   // row r: data[r * arity .. + arity)
  std::vector<std::uint32_t> base;
  std::vector<std::uint8_t> derived, mark;
  std::vector<std::uint32_t> touched;
  IdTable rows;
  std::deque<Index> indexes;  // stable references: an index may be added during a walk

  std::uint32_t size() const { return static_cast<std::uint32_t>(base.size()); }
  const Id* row(std::uint32_t r) const { return data.data() + static_cast<std::size_t>(r) * arity; }
  bool alive(std::uint32_t r) const { return base[r] > 0 || derived[r]; }

  bool same(std::uint32_t r, const Id* t) const {  // arity 0: one row, data() may be null
    if (arity == 2) return row(r)[0] == t[0] && row(r)[1] == t[1];
    return arity == 0 || std::memcmp(row(r), t, arity * sizeof(Id)) == 0;
  }
  std::uint32_t find(const Id* t) const {
    return rows.find(hash_ids(t, arity), [&](std::uint32_t r) { return same(r, t); });
  }
  // find for the lookups of fully bound atoms, which mostly miss (is this timestamp's subject a
  // movement event?): the direct index on the first argument answers most misses with one load.
  std::uint32_t lookup(const Id* t) {
    if (arity == 0) return find(t);
    if (index(1).first(t[0]) == kNone) return kNone;
    return find(t);
  }
  std::uint32_t ensure(const Id* t) {
    std::uint64_t h = hash_ids(t, arity);
    std::uint32_t r = rows.find(h, [&](std::uint32_t r) { return same(r, t); });
    if (r != kNone) return r;
    r = size();
    data.insert(data.end(), t, t + arity);
    base.push_back(0);
    derived.push_back(0);
    owners.resize(owners.size() + words, 0);
    mark.push_back(0);
    rows.insert(h, r);
    for (Index& ix : indexes) link(ix, r);
    return r;
  }
  void link(Index& ix, std::uint32_t r) {
    ix.next.push_back(ix.push(index_key(row(r), arity, ix.mask), r));
  }
  std::int8_t small_index[16] = {-1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1};
  const Index& index(std::uint32_t mask) {
    if (mask < 16 && small_index[mask] >= 0) return indexes[static_cast<std::size_t>(small_index[mask])];
    for (const Index& ix : indexes) if (ix.mask == mask) return ix;
    if (mask < 16 && indexes.size() < 127) small_index[mask] = static_cast<std::int8_t>(indexes.size());
    indexes.emplace_back();
    Index& ix = indexes.back();
    ix.mask = mask;
    ix.direct = __builtin_popcount(mask) == 1;
    ix.next.reserve(size());
    for (std::uint32_t r = 0; r < size(); ++r) link(ix, r);
    return ix;
  }
  std::deque<SortedIndex> sorted;  // stable references, as indexes
  // The sorted index on `column` under the bound positions `mask`, brought up to date: the
  // rows added since its last use are sorted and merged in. Existing entries only move right,
  // so a walk by position that this update interrupts skips none of them (it may see one twice).
  const SortedIndex& sorted_index(std::uint32_t mask, std::uint32_t column, const Dict& dict) {
    SortedIndex* sx = nullptr;
    for (SortedIndex& s : sorted) if (s.mask == mask && s.column == column) sx = &s;
    if (!sx) {
      sx = &sorted.emplace_back();
      sx->mask = mask;
      sx->column = column;
    }
    if (sx->rows_seen == size()) return *sx;
    const std::size_t old = sx->entries.size();
    for (std::uint32_t r = sx->rows_seen; r < size(); ++r) {
      double key;
      if (!sort_key(dict.value(row(r)[column]), key)) continue;
      sx->entries.push_back({mask ? index_key(row(r), arity, mask) : 0, key, r});
    }
    sx->rows_seen = size();
    std::sort(sx->entries.begin() + static_cast<long>(old), sx->entries.end());
    std::inplace_merge(sx->entries.begin(), sx->entries.begin() + static_cast<long>(old), sx->entries.end());
    return *sx;
  }
  // The k-th of `deriving` derives row r (slot: its index there).
  bool derived_by(std::uint32_t r, std::uint32_t slot) const {
    if (!words) return derived[r] != 0;
    return (owners[static_cast<std::size_t>(r) * words + slot / 64] >> (slot % 64)) & 1u;
  }
  void set_derived(std::uint32_t r, std::uint32_t slot) {
    derived[r] = 1;
    if (words) owners[static_cast<std::size_t>(r) * words + slot / 64] |= std::uint64_t{1} << (slot % 64);
  }
  void clear_derived(std::uint32_t r, std::uint32_t slot) {
    if (!words) { derived[r] = 0; return; }
    const std::size_t at = static_cast<std::size_t>(r) * words;
    owners[at + slot / 64] &= ~(std::uint64_t{1} << (slot % 64));
    derived[r] = std::any_of(owners.begin() + static_cast<long>(at), owners.begin() + static_cast<long>(at + words),
                             [](std::uint64_t w) { return w != 0; });
  }
  void touch(std::uint32_t r) {
    if (mark[r]) return;
    mark[r] = kTouched | (alive(r) ? kWasAlive : 0) | (derived[r] ? kWasDerived : 0) | (base[r] > 0 ? kWasBase : 0);
    touched.push_back(r);
  }
  bool was_alive(std::uint32_t r) const { return mark[r] ? (mark[r] & kWasAlive) != 0 : alive(r); }
};

}  // namespace

// --- the engine -------------------------------------------------------------------------------

struct Engine::Impl {
  std::shared_ptr<const Program> program;
  Dict dict;
  std::vector<Relation> rels;
  std::vector<std::uint32_t> rel_of_pred;  // program predicate -> relation
  KeyMap binary;                           // predicate term id -> relation
  std::vector<Id> const_ids;               // program constant -> term id
  std::vector<std::uint32_t> slot_of_rule;  // rule -> its stratum's slot in its head's Relation::deriving
  std::vector<std::uint32_t> touched_rels;
  std::vector<std::uint8_t> rel_is_touched;
  std::int64_t now = 0;
  std::unordered_set<std::string> read_iris;  // binary predicates some rule reads
  bool first = true;
  std::size_t current_stratum = 0;
  // Each relation's rows new to a round (cur) and found in it (next), kept across strata and
  // empty between them. Made per stratum (two vectors per relation) they cost a from-scratch
  // session the square of the strata: 20,000 chained negations took 0.9 s with no fact at all.
  std::vector<std::vector<std::uint32_t>> cur_rows, next_rows;
  std::size_t session_new_rows = 0;  // conclusions derived in this apply
  std::size_t conclusion_limit = kMaxSessionConclusions;
  EngineStats st;

  explicit Impl(std::shared_ptr<const Program> p) : program(std::move(p)) {
    for (const node::Term& t : program->constants) const_ids.push_back(dict.intern(t));
    for (std::uint32_t i = 0; i < program->preds.size(); ++i) {
      const Pred& pred = program->preds[i];
      std::uint32_t r = (!pred.internal && pred.arity == 2) ? binary_rel(dict.intern(node::Term::iri(pred.iri)))
                                                            : new_rel(pred.arity, 0);
      rels[r].pred = static_cast<int>(i);
      rel_of_pred.push_back(r);
    }
    for (std::uint32_t s = 0; s < program->strata.size(); ++s)
      for (std::uint32_t p : program->strata[s].preds) rels[rel_of_pred[p]].deriving.push_back(s);
    for (Relation& R : rels)
      if (R.deriving.size() > 1) R.words = static_cast<std::uint32_t>((R.deriving.size() + 63) / 64);
    slot_of_rule.resize(program->rules.size());
    for (std::uint32_t s = 0; s < program->strata.size(); ++s)
      for (std::uint32_t ri : program->strata[s].rules) slot_of_rule[ri] = slot(rel_of_pred[program->rules[ri].head], s);
    for (std::uint32_t p : program->read_binary) read_iris.insert(program->preds[p].iri);
    for (Relation& R : rels)
      if (R.pred_iri && R.pred >= 0) R.read = relevant(program->preds[R.pred].iri);
  }

  std::uint32_t new_rel(std::uint32_t arity, Id iri) {
    rels.emplace_back();
    rels.back().arity = arity;
    rels.back().pred_iri = iri;
    rel_is_touched.push_back(0);
    return static_cast<std::uint32_t>(rels.size() - 1);
  }
  std::uint32_t binary_rel(Id iri) {
    std::uint32_t r = binary.get(iri);
    if (r != kNone) return r;
    r = new_rel(2, iri);
    binary.put(iri, r);
    return r;
  }
  // The index of stratum s in rels[rel].deriving (s has rules for it).
  std::uint32_t slot(std::uint32_t rel, std::uint32_t s) const {
    const auto& d = rels[rel].deriving;
    return static_cast<std::uint32_t>(std::find(d.begin(), d.end(), s) - d.begin());
  }
  void touch(std::uint32_t rel, std::uint32_t row) {
    rels[rel].touch(row);
    if (!rel_is_touched[rel]) { rel_is_touched[rel] = 1; touched_rels.push_back(rel); }
  }

  bool relevant(std::string_view iri) const {
    return program->reads_any_binary || read_iris.count(std::string(iri)) > 0;
  }

  // Rows of `rel` that became visible (plus) or stopped being visible (minus) this session.
  std::vector<std::uint32_t> delta(std::uint32_t rel, bool plus) const {
    std::vector<std::uint32_t> out;
    const Relation& R = rels[rel];
    for (std::uint32_t r : R.touched) {
      bool was = (R.mark[r] & kWasAlive) != 0, now_alive = R.alive(r);
      if (plus ? (now_alive && !was) : (!now_alive && was)) out.push_back(r);
    }
    return out;
  }

  void base_change(const node::Triple& t, bool insert);
  void run_stratum(std::size_t s);
  std::size_t full_plan(const Rule& rule, std::vector<std::vector<std::uint32_t>>& next);
  bool needs_recompute(const Stratum& stratum);
  bool only_negations_grew(const Stratum& stratum);
  void retract_for_negations(const Stratum& stratum, std::vector<std::vector<std::uint32_t>>& cur,
                             std::vector<std::vector<std::uint32_t>>& next);
  Update finish();
  Update apply(std::span<const node::Triple> inserted, std::span<const node::Triple> removed, std::int64_t now_ns);
  Atom atom_of(const Relation& R, std::uint32_t row) const;
};

// --- evaluation of one rule -------------------------------------------------------------------

namespace {

template <class EngineImpl>  // Engine::Impl (private: named only where it is visible)
class RuleRun {
 public:
  // delta: per relation, the rows the first literal of `plan` iterates (nullptr: all rows).
  RuleRun(EngineImpl& e, const Rule& rule, const std::vector<std::uint32_t>& plan,
          const std::vector<std::vector<std::uint32_t>>* delta, std::vector<std::vector<std::uint32_t>>& out)
      : e_(e), rule_(rule), plan_(plan), delta_(delta), out_(out), bind_(rule.vars, 0),
        slot_(e.slot_of_rule[static_cast<std::size_t>(&rule - e.program->rules.data())]) {
    for (std::size_t i = 0; i < rule.plans.size(); ++i)
      if (&rule.plans[i] == &plan) { ready_ = rule.ready[i]; ranges_ = &rule.plan_ranges[i]; memos_ = &rule.plan_memos[i]; }
    for (std::size_t i = 0; i < rule.neg_plans.size(); ++i)
      if (&rule.neg_plans[i] == &plan) { ranges_ = &rule.neg_plan_ranges[i]; memos_ = &rule.neg_plan_memos[i]; }
    if (memos_ && std::none_of(memos_->begin(), memos_->end(), [](const Memo& m) { return m.end != 0; })) memos_ = nullptr;
    if (memos_) {
      memo_state_.resize(plan.size());
      cross_step_.assign(plan.size(), 0);
      for (const Memo& m : *memos_) for (std::uint32_t q : m.cross) cross_step_[q] = 1;
    }
  }

  void run() { step(0); }
  // An upper bound of the rows the plan's first atom reads with nothing bound: under its
  // constants (a direct index counts them), in the window of its constant bounds, or all.
  std::size_t first_rows();
  // Modes for a negation that gained rows (Engine::Impl::retract_for_negations): the first
  // literal is a negation read as positive over the delta; other negations are not checked;
  // head tuples are collected instead of derived.
  void collect_into(std::vector<std::vector<Id>>* out) { collect_ = out; neg_first_ = true; skip_neg_ = true; }
  // Runs with the head bound to `tuple` (re-derivation of one conclusion).
  void run_bound(const Id* tuple) {
    for (std::size_t i = 0; i < rule_.head_args.size(); ++i) {
      const Arg& a = rule_.head_args[i];
      Id have = arg(a);
      if (have && have != tuple[i]) return;
      if (a.is_var) bind_[a.index] = tuple[i];
    }
    step(0);
  }

 private:
  Id arg(const Arg& a) const { return a.is_var ? bind_[a.index] : e_.const_ids[a.index]; }
  void step(std::size_t k);
  void atom(const Literal& l, std::size_t k);
  void match_rel(const Literal& l, const Arg* args, std::uint32_t rel, std::size_t k, bool only_delta);
  void match_range(const RangeScan& scan, const Arg* args, Relation& R, const Id* probe, std::uint32_t mask,
                   std::size_t k);
  bool range_of(const RangeScan& scan, double& lo, double& hi);
  void memo_step(std::size_t k);
  void memo_build(std::size_t k);
  void memo_replay(std::size_t k);
  bool try_row(const Arg* args, std::uint32_t n, const Id* row, std::size_t k);
  bool holds(const Literal& l);
  Value eval(const Expr& x);
  Value small_eval(const Expr& x);
  void emit();

  EngineImpl& e_;
  const Rule& rule_;
  const std::vector<std::uint32_t>& plan_;
  const std::vector<std::vector<std::uint32_t>>* delta_;
  std::vector<std::vector<std::uint32_t>>& out_;
  std::vector<Id> bind_;
  std::uint32_t slot_;  // the rule's stratum among those deriving its head (Relation::deriving)
  std::size_t ready_ = ~std::size_t{0};
  const std::vector<RangeScan>* ranges_ = nullptr;  // per step of plan_
  // Independent runs (program.h, Memo): per step, the bindings kept once enumerated.
  struct MemoState {
    std::uint32_t reaches = 0;
    bool built = false;
    std::vector<Id> rows;  // exported.size() ids per binding
    // Bindings in `rows`; a run that exports no variable (its atoms share none with the rest of
    // the rule) holds rows of no width: at most one binding, present when the run has a solution.
    std::size_t bindings = 0;
    std::vector<std::pair<double, std::uint32_t>> by_key;  // (sort_key, binding) with a range
  };
  const std::vector<Memo>* memos_ = nullptr;
  std::vector<MemoState> memo_state_;
  std::vector<std::uint8_t> cross_step_;  // steps that are cross filters of a run
  std::size_t collect_at_ = ~std::size_t{0};  // while a run is enumerated: the step after it
  MemoState* collecting_ = nullptr;
  const Memo* collecting_spec_ = nullptr;
  bool cut_ = false;  // the head is derived: unwind to the step where its variables were bound
  bool neg_first_ = false, skip_neg_ = false;
  std::vector<std::vector<Id>>* collect_ = nullptr;
  void step_literal(std::size_t k);
};

// eval without the call for the forms of window bounds (T - 600, T + D): integer leaves, inline.
template <class E>
Value RuleRun<E>::small_eval(const Expr& x) {
  if (x.kind == Expr::arg) { Id id = arg(x.leaf); return id ? e_.dict.value(id) : Value{}; }
  if ((x.kind == Expr::add || x.kind == Expr::sub) && x.a->kind == Expr::arg && x.b->kind == Expr::arg) {
    Id ia = arg(x.a->leaf), ib = arg(x.b->leaf);
    if (ia && ib) {
      const Value& a = e_.dict.value(ia);
      const Value& b = e_.dict.value(ib);
      if (a.kind == Value::integer && b.kind == Value::integer)
        return integer_arith(x.kind == Expr::add ? ArithOp::add : ArithOp::sub, a.i, b.i);
    }
  }
  return eval(x);
}

template <class E>
Value RuleRun<E>::eval(const Expr& x) {
  switch (x.kind) {
    case Expr::arg: { Id id = arg(x.leaf); return id ? e_.dict.value(id) : Value{}; }
    case Expr::now: return Value{Value::time, e_.now, 0};
    case Expr::neg: return reasoner::arith(ArithOp::neg, eval(*x.a), {});
    case Expr::add: case Expr::sub: case Expr::mul: {
      Value a = eval(*x.a), b = eval(*x.b);
      const ArithOp op = x.kind == Expr::add ? ArithOp::add : x.kind == Expr::sub ? ArithOp::sub : ArithOp::mul;
      if (a.kind == Value::integer && b.kind == Value::integer) return integer_arith(op, a.i, b.i);  // the common case
      return reasoner::arith(op, a, b);
    }
    case Expr::div: return reasoner::arith(ArithOp::div, eval(*x.a), eval(*x.b));
  }
  return {};
}

template <class E>
void RuleRun<E>::emit() {
  Id tuple[16];
  for (std::size_t i = 0; i < rule_.head_args.size(); ++i) tuple[i] = arg(rule_.head_args[i]);
  if (collect_) {
    collect_->emplace_back(tuple, tuple + rule_.head_args.size());
    return;
  }
  ++e_.st.derivations;
  std::uint32_t rel = e_.rel_of_pred[rule_.head];
  Relation& R = e_.rels[rel];
  std::uint32_t r = R.ensure(tuple);
  if (R.derived_by(r, slot_)) return;
  e_.touch(rel, r);
  bool was_visible = R.alive(r);
  R.set_derived(r, slot_);
  if (!was_visible) out_[rel].push_back(r);
  // A rule whose conclusion feeds itself new values (count(X, N1) :- count(X, N), N1 is N + 1)
  // never reaches a fixpoint: it took all the memory there is. Stopped with where it is.
  if (++e_.session_new_rows > e_.conclusion_limit) {
    const Pred& head = e_.program->preds[rule_.head];
    throw RunawayDerivation(e_.program->file + ":" + std::to_string(rule_.pos.line) + ":" + std::to_string(rule_.pos.col) +
                            ": the rules derive without end: more than " + std::to_string(e_.conclusion_limit) +
                            " conclusions in one session, the last of " + (head.internal ? "a helper of this rule" : "<" + head.iri + ">") +
                            " by this rule; a rule whose conclusion gives itself new values (N1 is N + 1, a new node) never stops"
                            " (rules whose closure is finite but larger: raise the limit, tahvel reason --max-conclusions)");
  }
}

// Binds the unbound arguments of one literal to `row`; false (and nothing bound) on mismatch.
template <class E>
bool RuleRun<E>::try_row(const Arg* args, std::uint32_t n, const Id* row, std::size_t k) {
  std::uint32_t newly[16];
  std::uint32_t count = 0;
  bool ok = true;
  for (std::uint32_t i = 0; i < n && ok; ++i) {
    Id want = arg(args[i]);
    if (want) {
      ok = want == row[i];
    } else {
      bind_[args[i].index] = row[i];
      newly[count++] = args[i].index;
    }
  }
  if (ok) step(k + 1);
  for (std::uint32_t i = 0; i < count; ++i) bind_[newly[i]] = 0;
  return ok;
}

template <class E>
void RuleRun<E>::match_rel(const Literal& l, const Arg* args, std::uint32_t rel, std::size_t k, bool only_delta) {
  Relation& R = e_.rels[rel];
  const std::uint32_t n = R.arity;
  if (only_delta) {
    const auto& rows = (*delta_)[rel];
    for (std::size_t i = 0; i < rows.size() && !cut_; ++i) {
      if (R.alive(rows[i])) try_row(args, n, R.row(rows[i]), k);
    }
    return;
  }
  Id probe[16] = {};
  std::uint32_t mask = 0;
  for (std::uint32_t i = 0; i < n; ++i) {
    probe[i] = arg(args[i]);
    if (probe[i]) mask |= 1u << i;
  }
  (void)l;
  if (mask == (1u << n) - 1) {
    std::uint32_t r = R.lookup(probe);
    if (r != kNone && R.alive(r)) step(k + 1);
    return;
  }
  // A range scan unless the bounded argument is bound already (run_bound binds head variables
  // the plan did not expect bound) or the rows under the bound arguments are few: then
  // following them is cheaper than a binary search (a sample's one heart rate).
  const bool ranged = ranges_ && collecting_ == nullptr && (*ranges_)[k].position >= 0 &&
                      !(mask & (1u << (*ranges_)[k].position));
  if (ranged && mask == 0) {
    match_range((*ranges_)[k], args, R, probe, mask, k);
    return;
  }
  if (mask == 0) {
    for (std::uint32_t r = 0; r < R.size() && !cut_; ++r) if (R.alive(r)) try_row(args, n, R.row(r), k);
    return;
  }
  const Index& ix = R.index(mask);
  const std::uint32_t head = ix.first(index_key(probe, n, mask));
  if (ranged) {
    std::uint32_t r = head;
    for (int seen = 0; r != kNone && seen < kShortChain; ++seen) r = ix.next[r];
    if (r != kNone) {
      match_range((*ranges_)[k], args, R, probe, mask, k);
      return;
    }
  }
  for (std::uint32_t r = head; r != kNone && !cut_; r = ix.next[r]) {
    if (R.alive(r)) try_row(args, n, R.row(r), k);
  }
}

template <class E>
std::size_t RuleRun<E>::first_rows() {
  std::size_t q = 0;
  while (q < plan_.size() && rule_.body[plan_[q]].kind != Literal::atom) ++q;
  if (q == plan_.size()) return 0;
  const Literal& l = rule_.body[plan_[q]];
  if (l.pred == kAnyBinary) return ~std::size_t{0} / 2;
  Relation& R = e_.rels[e_.rel_of_pred[l.pred]];
  Id probe[16] = {};
  std::uint32_t mask = 0;
  for (std::uint32_t i = 0; i < R.arity; ++i) {
    probe[i] = arg(l.args[i]);
    if (probe[i]) mask |= 1u << i;
  }
  if (R.arity > 0 && mask == (1u << R.arity) - 1) return 1;
  if (ranges_ && (*ranges_)[q].position >= 0 && !(mask & (1u << (*ranges_)[q].position))) {
    double lo, hi;
    if (!range_of((*ranges_)[q], lo, hi)) return 0;
    const SortedIndex& sx = R.sorted_index(mask, static_cast<std::uint32_t>((*ranges_)[q].position), e_.dict);
    const std::uint64_t eq = mask ? index_key(probe, R.arity, mask) : 0;
    auto from = std::lower_bound(sx.entries.begin(), sx.entries.end(), SortedIndex::Entry{eq, lo, 0});
    auto to = std::upper_bound(from, sx.entries.end(), SortedIndex::Entry{eq, hi, 0});
    return static_cast<std::size_t>(to - from);
  }
  if (__builtin_popcount(mask) == 1) {
    const Index& ix = R.index(mask);
    const std::uint64_t key = index_key(probe, R.arity, mask);
    return key < ix.count.size() ? ix.count[key] : 0;
  }
  return R.size();
}

// The keys (sort_key) between which the bounded argument's value must lie for every comparison
// of `scan` to hold, widened by more than the rounding of the arithmetic (a range of keys is a
// superset: the comparisons decide). False when no value can satisfy them (an undefined bound:
// the comparison fails on every row).
template <class E>
bool RuleRun<E>::range_of(const RangeScan& scan, double& lo, double& hi) {
  lo = -HUGE_VAL;
  hi = HUGE_VAL;
  for (const RangeBound& b : scan.bounds) {
    double key, term;
    if (!sort_key(eval(b.other), key)) return false;
    double scale = std::fabs(key);
    for (const auto& [subtracted, x] : b.offsets) {  // V + t op other: V op other - t
      if (!sort_key(eval(x), term)) return false;
      key += subtracted ? term : -term;
      scale += std::fabs(term);
    }
    const double slack = scale * 1e-12 + 1e-6;
    if (b.lower) lo = std::max(lo, key - slack);
    if (b.upper) hi = std::min(hi, key + slack);
  }
  return lo <= hi;
}

template <class E>
void RuleRun<E>::match_range(const RangeScan& scan, const Arg* args, Relation& R, const Id* probe,
                             std::uint32_t mask, std::size_t k) {
  double lo, hi;
  if (!range_of(scan, lo, hi)) return;
  const auto column = static_cast<std::uint32_t>(scan.position);
  const SortedIndex& sx = R.sorted_index(mask, column, e_.dict);
  const std::uint64_t eq = mask ? index_key(probe, R.arity, mask) : 0;
  using Entry = SortedIndex::Entry;
  std::size_t at = static_cast<std::size_t>(
      std::lower_bound(sx.entries.begin(), sx.entries.end(), Entry{eq, lo, 0}) - sx.entries.begin());
  // By position, re-reading the vector: a step below may merge new rows into this index.
  for (; at < sx.entries.size() && !cut_; ++at) {
    const Entry en = sx.entries[at];
    if (en.eq != eq || en.key > hi) break;
    if (R.alive(en.row)) try_row(args, R.arity, R.row(en.row), k);
  }
}

template <class E>
void RuleRun<E>::atom(const Literal& l, std::size_t k) {
  const bool only_delta = k == 0 && delta_ != nullptr;
  if (l.pred != kAnyBinary) {
    match_rel(l, l.args.data(), e_.rel_of_pred[l.pred], k, only_delta);
    return;
  }
  // fact(S, P, O) with a variable P: one relation when P is bound, else every binary one.
  const Arg so[2] = {l.args[0], l.args[2]};
  const Arg& p = l.args[1];
  if (Id bound = bind_[p.index]) {
    std::uint32_t rel = e_.binary.get(bound);
    if (rel != kNone) match_rel(l, so, rel, k, only_delta);
    return;
  }
  for (std::uint32_t rel = 0; rel < e_.rels.size() && !cut_; ++rel) {
    const Relation& R = e_.rels[rel];
    if (!R.pred_iri) continue;
    if (only_delta && (*delta_)[rel].empty()) continue;
    bind_[p.index] = R.pred_iri;
    match_rel(l, so, rel, k, only_delta);
  }
  bind_[p.index] = 0;
}

bool compare_op(Literal::Op op, int c) {
  switch (op) {
    case Literal::lt: return c < 0;
    case Literal::gt: return c > 0;
    case Literal::le: return c <= 0;
    case Literal::ge: return c >= 0;
    case Literal::eq: return c == 0;
    case Literal::ne: return c != 0;
  }
  return false;
}

template <class E>
bool RuleRun<E>::holds(const Literal& l) {
  switch (l.kind) {
    case Literal::negation: {
      if (skip_neg_) return true;
      Id tuple[16];
      std::uint32_t rel;
      if (l.pred == kAnyBinary) {
        rel = e_.binary.get(arg(l.args[1]));
        if (rel == kNone) return true;
        tuple[0] = arg(l.args[0]);
        tuple[1] = arg(l.args[2]);
      } else {
        rel = e_.rel_of_pred[l.pred];
        for (std::size_t i = 0; i < l.args.size(); ++i) tuple[i] = arg(l.args[i]);
      }
      Relation& R = e_.rels[rel];
      std::uint32_t r = R.lookup(tuple);
      return r == kNone || !R.alive(r);
    }
    case Literal::compare: {
      // Fast path: two integer arguments (timestamps, counts), no expression to evaluate.
      if (l.lhs.kind == Expr::arg && l.rhs.kind == Expr::arg) {
        const Value& a = e_.dict.value(arg(l.lhs.leaf));
        const Value& b = e_.dict.value(arg(l.rhs.leaf));
        if (a.kind == Value::integer && b.kind == Value::integer) return compare_op(l.op, a.i < b.i ? -1 : (b.i < a.i ? 1 : 0));
      }
      Value a = small_eval(l.lhs), b = small_eval(l.rhs);
      if (a.kind == Value::integer && b.kind == Value::integer) return compare_op(l.op, a.i < b.i ? -1 : (b.i < a.i ? 1 : 0));
      auto c = compare_values(a, b);
      return c && compare_op(l.op, *c);
    }
    case Literal::identical: return arg(l.lhs.leaf) == arg(l.rhs.leaf);
    case Literal::not_unify: return arg(l.lhs.leaf) != arg(l.rhs.leaf);
    default: return false;
  }
}

template <class E>
void RuleRun<E>::step(std::size_t k) {
  if (k == collect_at_) {  // enumerating an independent run: keep its bindings
    if (collecting_spec_->exported.empty()) {
      collecting_->bindings = 1;
      return;
    }
    for (std::uint32_t v : collecting_spec_->exported) collecting_->rows.push_back(bind_[v]);
    ++collecting_->bindings;
    return;
  }
  if (k == plan_.size()) {
    emit();
    cut_ = ready_ < plan_.size();
    return;
  }
  if (memos_) {
    if ((*memos_)[k].end && collecting_ == nullptr) {
      memo_step(k);
    } else if (cross_step_[k] && collecting_) {
      step(k + 1);  // checked when the run's bindings are replayed
    } else {
      step_literal(k);
    }
  } else {
    step_literal(k);
  }
  if (k == ready_) cut_ = false;
}

// Rows a run's enumeration costs per outer binding (with its range scans) against enumerating
// it once unconstrained: the run is kept from this many reaches on, so that a run reached once
// or twice (a session's few new rows) stays a narrow nested scan.
constexpr std::uint32_t kMemoAfterReaches = 8;

template <class E>
void RuleRun<E>::memo_step(std::size_t k) {
  const Memo& spec = (*memos_)[k];
  MemoState& m = memo_state_[k];
  // A head variable bound by run_bound among the exported ones: enumerate in place.
  bool prebound = std::any_of(spec.exported.begin(), spec.exported.end(), [&](std::uint32_t v) { return bind_[v] != 0; });
  if (prebound || (!m.built && ++m.reaches < kMemoAfterReaches)) {
    step_literal(k);
    return;
  }
  if (!m.built) memo_build(k);
  memo_replay(k);
}

// Enumerates the run without its cross filters and range scans (both read outer variables), its
// bindings of the exported variables collected at its end.
template <class E>
void RuleRun<E>::memo_build(std::size_t k) {
  const Memo& spec = (*memos_)[k];
  MemoState& m = memo_state_[k];
  collect_at_ = spec.end;
  collecting_ = &m;
  collecting_spec_ = &spec;
  step_literal(k);
  collect_at_ = ~std::size_t{0};
  collecting_ = nullptr;
  collecting_spec_ = nullptr;
  m.built = true;
  if (spec.range.position < 0) return;
  const std::size_t width = spec.exported.size();
  for (std::size_t i = 0; i < m.bindings; ++i) {
    double key;
    if (sort_key(e_.dict.value(m.rows[i * width + static_cast<std::size_t>(spec.range.position)]), key))
      m.by_key.emplace_back(key, static_cast<std::uint32_t>(i));
  }
  std::sort(m.by_key.begin(), m.by_key.end());
}

template <class E>
void RuleRun<E>::memo_replay(std::size_t k) {
  const Memo& spec = (*memos_)[k];
  MemoState& m = memo_state_[k];
  const std::size_t width = spec.exported.size();
  // A cut set below the run but above this step (the head's variables are bound inside the run)
  // ends only that binding: each replayed binding is a different one.
  const bool cut_inside = ready_ > k && ready_ <= spec.end;
  auto visit = [&](std::size_t i) {
    for (std::size_t s = 0; s < width; ++s) bind_[spec.exported[s]] = m.rows[i * width + s];
    bool pass = true;
    for (std::uint32_t q : spec.cross) if (!holds(rule_.body[plan_[q]])) { pass = false; break; }
    if (pass) step(spec.end);
    for (std::uint32_t v : spec.exported) bind_[v] = 0;
    if (cut_inside) cut_ = false;
  };
  if (spec.range.position < 0) {
    for (std::size_t i = 0; i < m.bindings && !cut_; ++i) visit(i);
    return;
  }
  double lo, hi;
  if (!range_of(spec.range, lo, hi)) return;
  auto at = std::lower_bound(m.by_key.begin(), m.by_key.end(), std::pair<double, std::uint32_t>(lo, 0));
  for (; at != m.by_key.end() && at->first <= hi && !cut_; ++at) visit(at->second);
}

template <class E>
void RuleRun<E>::step_literal(std::size_t k) {
  const Literal& l = rule_.body[plan_[k]];
  if (k == 0 && neg_first_) { atom(l, k); return; }
  switch (l.kind) {
    case Literal::atom: atom(l, k); return;
    case Literal::assign: {
      Value v = eval(l.rhs);
      if (v.kind == Value::none) return;
      Id target = arg(l.lhs.leaf);
      // Bound or not, the target must be the very term the expression gives: an unbound one is
      // bound to it and later joins compare terms, so comparing values here (5 with 5.0, or a
      // time written in another zone) made what a rule derives depend on which of its atoms
      // came first — a session's order, not the rule. (A term the dictionary lacks is no bound
      // target's: looked up, not added, or each session's `now` arithmetic would grow it.)
      if (target) {
        if (target == e_.dict.find(term_of(v))) step(k + 1);
        return;
      }
      bind_[l.lhs.leaf.index] = e_.dict.intern(term_of(v));
      step(k + 1);
      bind_[l.lhs.leaf.index] = 0;
      return;
    }
    case Literal::skolem: {
      std::uint64_t h = 1469598103934665603ull;  // FNV-1a 64 of the arguments' N-Triples
      for (std::size_t i = 1; i < l.args.size(); ++i) {
        for (unsigned char c : e_.dict.term(arg(l.args[i])).to_ntriples()) h = (h ^ c) * 1099511628211ull;
        h = (h ^ 0x1f) * 1099511628211ull;
      }
      char hex[17];
      std::snprintf(hex, sizeof hex, "%016llx", static_cast<unsigned long long>(h));
      Id minted = e_.dict.intern(node::Term::iri(e_.program->me + "/.well-known/genid/s" + hex));
      Id target = arg(l.args[0]);
      if (target) { if (target == minted) step(k + 1); return; }
      bind_[l.args[0].index] = minted;
      step(k + 1);
      bind_[l.args[0].index] = 0;
      return;
    }
    case Literal::unify: {
      Id a = arg(l.lhs.leaf), b = arg(l.rhs.leaf);
      if (a && b) { if (a == b) step(k + 1); return; }
      const Arg& free = a ? l.rhs.leaf : l.lhs.leaf;
      bind_[free.index] = a ? a : b;
      step(k + 1);
      bind_[free.index] = 0;
      return;
    }
    default:
      if (holds(l)) step(k + 1);
      return;
  }
}

}  // namespace

// --- strata -----------------------------------------------------------------------------------

bool Engine::Impl::needs_recompute(const Stratum& stratum) {
  if (first || stratum.volatile_) return true;
  // A row that lost its last record but is still derived stays alive, so it is in no delta. In a
  // recursive stratum that derivation may rest on the row itself (knows(Y,X) :- knows(X,Y), the
  // record of knows(a,b) removed): only recomputing the stratum tells.
  auto lost_base = [&](std::uint32_t rel) {
    if (!stratum.recursive || !rel_is_touched[rel]) return false;
    const Relation& R = rels[rel];
    return std::any_of(R.touched.begin(), R.touched.end(),
                       [&](std::uint32_t r) { return (R.mark[r] & kWasBase) != 0 && R.base[r] == 0 && R.derived[r]; });
  };
  auto changed = [&](std::uint32_t rel, bool plus) {
    return rel_is_touched[rel] && (!delta(rel, plus).empty() || (!plus && lost_base(rel)));
  };
  for (std::uint32_t ri : stratum.rules) {
    for (const Literal& l : program->rules[ri].body) {
      if (l.kind != Literal::atom && l.kind != Literal::negation) continue;
      const bool neg = l.kind == Literal::negation;
      auto check = [&](std::uint32_t rel) { return changed(rel, false) || (neg && changed(rel, true)); };
      if (l.pred != kAnyBinary) {
        if (check(rel_of_pred[l.pred])) return true;
        continue;
      }
      for (std::uint32_t rel : touched_rels) if (rels[rel].pred_iri && check(rel)) return true;
    }
  }
  return false;
}

// A stratum that reads nothing of its own, whose positive inputs did not shrink and whose
// negated inputs only grew: the conclusions it may lose are those a rule gives with a negated
// literal true on one of the new rows. These are withdrawn and derived again if another
// derivation holds (delete and re-derive, without recomputing the stratum).
bool Engine::Impl::only_negations_grew(const Stratum& stratum) {
  if (first || stratum.volatile_ || stratum.recursive) return false;
  auto changed = [&](std::uint32_t rel, bool plus) { return rel_is_touched[rel] && !delta(rel, plus).empty(); };
  bool grew = false;
  for (std::uint32_t ri : stratum.rules) {
    for (const Literal& l : program->rules[ri].body) {
      if (l.kind != Literal::atom && l.kind != Literal::negation) continue;
      std::vector<std::uint32_t> rels_read;
      if (l.pred != kAnyBinary) rels_read.push_back(rel_of_pred[l.pred]);
      else for (std::uint32_t rel : touched_rels) if (rels[rel].pred_iri) rels_read.push_back(rel);
      for (std::uint32_t rel : rels_read) {
        if (changed(rel, false)) return false;
        if (l.kind == Literal::negation && changed(rel, true)) grew = true;
      }
    }
  }
  return grew;
}

void Engine::Impl::retract_for_negations(const Stratum& stratum, std::vector<std::vector<std::uint32_t>>& cur,
                                         std::vector<std::vector<std::uint32_t>>& next) {
  for (std::uint32_t rel : touched_rels) cur[rel] = delta(rel, true);
  // Candidates: head tuples with some negated literal on a new row (other negations ignored).
  std::vector<std::pair<std::uint32_t, std::vector<std::vector<Id>>>> candidates;
  for (std::uint32_t ri : stratum.rules) {
    const Rule& rule = program->rules[ri];
    std::vector<std::vector<Id>> found;
    for (std::size_t k = 0; k < rule.neg_plans.size(); ++k) {
      const Literal& l = rule.body[rule.neg_literal[k]];
      if (l.pred == kAnyBinary || cur[rel_of_pred[l.pred]].empty()) continue;
      RuleRun run(*this, rule, rule.neg_plans[k], &cur, next);
      run.collect_into(&found);
      run.run();
    }
    if (!found.empty()) candidates.emplace_back(rule.head, std::move(found));
  }
  // Withdraw them, then derive each again from any rule of its predicate.
  // Only this stratum's derivations: another stratum's rules of the predicate (another head
  // pattern) may derive the same row, and it stays theirs.
  std::vector<std::pair<std::uint32_t, std::uint32_t>> withdrawn;  // (relation, row)
  for (auto& [head, tuples] : candidates) {
    std::uint32_t rel = rel_of_pred[head];
    Relation& R = rels[rel];
    const std::uint32_t own = slot(rel, static_cast<std::uint32_t>(current_stratum));
    for (const auto& t : tuples) {
      std::uint32_t r = R.find(t.data());
      if (r == kNone || !R.derived_by(r, own)) continue;
      touch(rel, r);
      R.clear_derived(r, own);
      withdrawn.emplace_back(rel, r);
    }
  }
  for (auto [rel, row] : withdrawn) {
    std::vector<Id> tuple(rels[rel].row(row), rels[rel].row(row) + rels[rel].arity);
    for (std::uint32_t ri : stratum.rules) {
      const Rule& rule = program->rules[ri];
      if (rel_of_pred[rule.head] != rel || rels[rel].derived_by(row, slot_of_rule[ri])) continue;
      RuleRun(*this, rule, rule.plans[0], nullptr, next).run_bound(tuple.data());
    }
  }
}

// The plan of a full round: the body's first atom as written, unless the rows another atom
// would start from (under its constants or in a window of constant bounds: a delta plan read
// whole) are fewer than half as many. Heart rates above 90 are a quarter of the samples that
// the written `fact(ppg_sensor_uri, sample_uri, X)` starts from.
std::size_t Engine::Impl::full_plan(const Rule& rule, std::vector<std::vector<std::uint32_t>>& next) {
  constexpr std::size_t kSmall = 32;  // too few rows for another order to matter
  std::size_t best = 0, best_rows = RuleRun(*this, rule, rule.plans[0], nullptr, next).first_rows();
  if (best_rows <= kSmall) return 0;
  const std::size_t written = best_rows;
  for (std::size_t k = 0; k < rule.kth_atom.size(); ++k) {
    const Literal& l = rule.body[rule.kth_atom[k]];
    const bool narrowed = std::any_of(l.args.begin(), l.args.end(), [](const Arg& a) { return !a.is_var; }) ||
                          rule.plan_ranges[1 + k][0].position >= 0;
    if (!narrowed) continue;  // all of a relation: never fewer than the written start's bound
    std::size_t rows = RuleRun(*this, rule, rule.plans[1 + k], nullptr, next).first_rows();
    if (rows * 2 < written && rows < best_rows) { best = 1 + k; best_rows = rows; }
  }
  return best;
}

void Engine::Impl::run_stratum(std::size_t s) {
  const Stratum& stratum = program->strata[s];
  current_stratum = s;
  // A stratum none of whose inputs changed has nothing to do. Setting it up (two vectors per
  // relation) for every stratum of every session made a session's cost grow with the square of
  // the rules: one new fact that derived nothing took 25 ms under 2,000 rules.
  if (!first && !stratum.volatile_) {
    bool touched = false;
    for (std::uint32_t ri : stratum.rules) {
      for (const Literal& l : program->rules[ri].body) {
        if (l.kind != Literal::atom && l.kind != Literal::negation) continue;
        if (l.pred == kAnyBinary) touched |= !touched_rels.empty();
        else touched |= rel_is_touched[rel_of_pred[l.pred]] != 0;
        if (touched) break;
      }
      if (touched) break;
    }
    if (!touched) return;
  }
  // Relations are made before the strata run (base_change), never while they do.
  if (cur_rows.size() < rels.size()) {
    cur_rows.resize(rels.size());
    next_rows.resize(rels.size());
  }
  auto& cur = cur_rows;
  auto& next = next_rows;
  // A stratum fills cur from the relations touched this session and from its own relations'
  // next, and next only in its own relations (the heads of its rules): those are emptied.
  std::vector<std::uint32_t> own;
  for (std::uint32_t p : stratum.preds) own.push_back(rel_of_pred[p]);
  std::sort(own.begin(), own.end());
  own.erase(std::unique(own.begin(), own.end()), own.end());
  auto clear_cur = [&] {
    for (std::uint32_t rel : touched_rels) cur[rel].clear();
    for (std::uint32_t rel : own) cur[rel].clear();
  };
  const bool negations_grew = only_negations_grew(stratum);
  const bool recompute = !negations_grew && needs_recompute(stratum);
  bool any_input = false;
  if (negations_grew) {
    retract_for_negations(stratum, cur, next);
    any_input = true;
    clear_cur();
  }
  if (recompute) {
    for (std::uint32_t rel : own) {
      Relation& R = rels[rel];
      const std::uint32_t mine = slot(rel, static_cast<std::uint32_t>(s));
      for (std::uint32_t r = 0; r < R.size(); ++r) {
        if (!R.derived_by(r, mine)) continue;
        touch(rel, r);
        R.clear_derived(r, mine);
      }
    }
    for (std::uint32_t ri : stratum.rules) {
      const Rule& rule = program->rules[ri];
      RuleRun(*this, rule, rule.plans[full_plan(rule, next)], nullptr, next).run();
    }
    ++st.strata_recomputed;
    any_input = true;
  } else {
    // Semi-naive seed: the rows that appeared in the relations this stratum reads.
    for (std::uint32_t rel : touched_rels) cur[rel] = delta(rel, true);
    for (std::uint32_t ri : stratum.rules) {
      const Rule& rule = program->rules[ri];
      for (std::size_t k = 0; k < rule.kth_atom.size(); ++k) {
        const Literal& l = rule.body[rule.kth_atom[k]];
        bool has = false;
        if (l.pred != kAnyBinary) has = !cur[rel_of_pred[l.pred]].empty();
        else for (std::uint32_t rel : touched_rels) has |= rels[rel].pred_iri && !cur[rel].empty();
        if (!has) continue;
        any_input = true;
        RuleRun(*this, rule, rule.plans[1 + k], &cur, next).run();
      }
    }
  }
  if (any_input) ++st.strata_run;
  // Rounds over this stratum's own new rows (recursion) to the fixpoint.
  for (;;) {
    clear_cur();
    bool more = false;
    for (std::uint32_t rel : own)
      if (!next[rel].empty()) { cur[rel].swap(next[rel]); more = true; }
    if (!more) break;
    for (std::uint32_t ri : stratum.rules) {
      const Rule& rule = program->rules[ri];
      for (std::size_t k = 0; k < rule.kth_atom.size(); ++k) {
        const Literal& l = rule.body[rule.kth_atom[k]];
        bool has = false;
        if (l.pred != kAnyBinary)
          has = std::binary_search(own.begin(), own.end(), rel_of_pred[l.pred]) && !cur[rel_of_pred[l.pred]].empty();
        else for (std::uint32_t rel : own) has |= rels[rel].pred_iri && !cur[rel].empty();
        if (has) RuleRun(*this, rule, rule.plans[1 + k], &cur, next).run();
      }
    }
  }
}

Atom Engine::Impl::atom_of(const Relation& R, std::uint32_t row) const {
  Atom a;
  a.predicate = R.pred_iri ? dict.term(R.pred_iri).value : program->preds[R.pred].iri;
  for (std::uint32_t i = 0; i < R.arity; ++i) a.args.push_back(dict.term(R.row(row)[i]));
  return a;
}

void Engine::Impl::base_change(const node::Triple& t, bool insert) {
  if (!t.p.is_iri()) return;
  Id p = insert ? dict.intern(t.p) : dict.find(t.p);
  if (!p) return;
  std::uint32_t rel = binary.get(p);
  if (rel == kNone) {
    if (!insert || !relevant(t.p.value)) return;
    rel = binary_rel(p);
  }
  Relation& R = rels[rel];
  if (R.pred >= 0 && !R.read) return;  // a conclusion no rule reads: base facts not kept
  if (insert) {
    Id tuple[2] = {dict.intern(t.s), dict.intern(t.o)};
    std::uint32_t r = R.ensure(tuple);
    touch(rel, r);
    ++R.base[r];
    return;
  }
  Id tuple[2] = {dict.find(t.s), dict.find(t.o)};
  if (!tuple[0] || !tuple[1]) return;
  std::uint32_t r = R.find(tuple);
  if (r == kNone || R.base[r] == 0) return;
  touch(rel, r);
  --R.base[r];
}

Engine::Update Engine::Impl::finish() {
  Update u;
  for (std::uint32_t rel : touched_rels) {
    Relation& R = rels[rel];
    const bool reported = R.pred >= 0 && !program->preds[R.pred].internal;
    for (std::uint32_t r : R.touched) {
      bool was = (R.mark[r] & kWasDerived) != 0;
      if (reported && was != (R.derived[r] != 0)) (was ? u.removed : u.added).push_back(atom_of(R, r));
      R.mark[r] = 0;
    }
    R.touched.clear();
    rel_is_touched[rel] = 0;
  }
  touched_rels.clear();
  return u;
}

Engine::Update Engine::Impl::apply(std::span<const node::Triple> inserted,
                                   std::span<const node::Triple> removed, std::int64_t now_ns) {
  now = now_ns;
  session_new_rows = 0;
  st.derivations = st.strata_run = st.strata_recomputed = 0;
  for (const node::Triple& t : inserted) base_change(t, true);
  for (const node::Triple& t : removed) base_change(t, false);
  for (std::size_t s = 0; s < program->strata.size(); ++s) run_stratum(s);
  first = false;
  return finish();
}

// --- public -----------------------------------------------------------------------------------

Engine::Engine(std::shared_ptr<const Program> program) : impl_(std::make_unique<Impl>(std::move(program))) {}
Engine::Engine(Engine&&) noexcept = default;
Engine& Engine::operator=(Engine&&) noexcept = default;
Engine::~Engine() = default;

Engine::Update Engine::apply(std::span<const node::Triple> inserted, std::span<const node::Triple> removed,
                             std::int64_t now_ns) {
  return impl_->apply(inserted, removed, now_ns);
}

Engine::Update Engine::recompute(std::int64_t now_ns) {
  impl_->first = true;
  return impl_->apply({}, {}, now_ns);
}

Engine::Update Engine::compact(std::int64_t now_ns) { return reload(impl_->program, now_ns); }

Engine::Update Engine::reload(std::shared_ptr<const Program> program, std::int64_t now_ns) {
  std::vector<Atom> before = conclusions();
  std::vector<node::Triple> base;
  for (const Relation& R : impl_->rels) {
    if (!R.pred_iri) continue;
    for (std::uint32_t r = 0; r < R.size(); ++r) {
      for (std::uint32_t n = 0; n < R.base[r]; ++n)
        base.push_back({impl_->dict.term(R.row(r)[0]), impl_->dict.term(R.pred_iri), impl_->dict.term(R.row(r)[1])});
    }
  }
  auto fresh = std::make_unique<Impl>(std::move(program));
  fresh->apply(base, {}, now_ns);
  impl_ = std::move(fresh);
  std::vector<Atom> after = conclusions();
  Update u;
  std::set_difference(after.begin(), after.end(), before.begin(), before.end(), std::back_inserter(u.added));
  std::set_difference(before.begin(), before.end(), after.begin(), after.end(), std::back_inserter(u.removed));
  return u;
}

std::vector<Atom> Engine::conclusions() const {
  std::vector<Atom> out;
  for (const Relation& R : impl_->rels) {
    if (R.pred < 0 || impl_->program->preds[R.pred].internal) continue;
    for (std::uint32_t r = 0; r < R.size(); ++r) if (R.derived[r]) out.push_back(impl_->atom_of(R, r));
  }
  std::sort(out.begin(), out.end());
  return out;
}

bool Engine::relevant(std::string_view predicate_iri) const { return impl_->relevant(predicate_iri); }

void Engine::set_conclusion_limit(std::size_t limit) { impl_->conclusion_limit = limit; }

EngineStats Engine::stats() const {
  EngineStats s = impl_->st;
  s.base_facts = s.conclusions = s.rows = 0;
  s.terms = impl_->dict.size() - 1;
  for (const Relation& R : impl_->rels) {
    s.rows += R.size();
    for (std::uint32_t r = 0; r < R.size(); ++r) {
      s.base_facts += R.base[r] > 0;
      s.conclusions += R.derived[r] && R.pred >= 0 && !impl_->program->preds[R.pred].internal;
    }
  }
  return s;
}

}  // namespace tahvel::reasoner
