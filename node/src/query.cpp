// Pattern matching; see query.h.
#include "query.h"

#include <algorithm>
#include <climits>
#include <unordered_set>

#include "tahvel/uri/iri.h"
#include "write.h"

namespace tahvel::node::detail {
namespace {

bool has_metadata_filter(const Pattern& p) {
  return p.context || p.source || p.since || p.until;
}

// Whether an item's facts still held at `since` or after: an instant at or after it, a span
// ending after it (ends past the largest time count as after).
bool holds_at_or_after(const ItemRow& meta, std::int64_t since) {
  if (meta.span == 0) return meta.asserted_at >= since;
  std::int64_t end = 0;
  return __builtin_add_overflow(meta.asserted_at, meta.span, &end) || end > since;
}

}  // namespace

namespace {

// A pattern no record could match because it is ill-formed, not because nothing matches: said,
// as the C API and subscriptions say it, rather than answered with nothing (a relative IRI, a
// literal subject).
Result<void> check_pattern(const Pattern& pattern) {
  const char* names[3] = {"subject", "predicate", "object"};
  const std::optional<Term>* terms[3] = {&pattern.s, &pattern.p, &pattern.o};
  for (int k = 0; k < 3; ++k) {
    const std::optional<Term>& term = *terms[k];
    if (!term) continue;
    const std::string what = std::string("pattern ") + names[k] + " " + term->to_ntriples();
    if (term->is_iri() && !uri::is_valid(term->value)) return fail(Errc::invalid_iri, what + ": not an absolute IRI");
    if (k == 0 && term->is_literal()) return fail(Errc::invalid_argument, what + ": a subject cannot be a literal");
    if (k == 1 && !term->is_iri()) return fail(Errc::invalid_argument, what + ": a predicate must be an IRI");
    if (term->is_literal())
      if (auto bad = detail::pattern_literal_problem(*term); !bad.empty()) return fail(Errc::invalid_argument, what + ": " + bad);
  }
  if (pattern.under && !uri::is_valid(*pattern.under))
    return fail(Errc::invalid_iri, "pattern under <" + *pattern.under + ">: not an absolute IRI");
  if (pattern.source && !pattern.source->empty() && !uri::is_valid(*pattern.source))
    return fail(Errc::invalid_iri, "pattern source <" + *pattern.source + ">: not an absolute IRI");
  if (pattern.context && !pattern.context->empty() && !uri::is_valid(*pattern.context))
    return fail(Errc::invalid_iri, "pattern context <" + *pattern.context + ">: not an absolute IRI");
  return {};
}

}  // namespace

Result<Query::Bound> Query::resolve(const Pattern& pattern) {
  if (auto checked = check_pattern(pattern); !checked) return unexpected(checked.error());
  Bound b;
  auto one = [&](const std::optional<Term>& term, std::uint64_t& id) -> Result<void> {
    if (!term) return {};
    auto found = find_term(txn_, env_, *term);
    if (!found) return unexpected(found.error());
    id = *found;
    if (id == 0) b.empty = true;
    return {};
  };
  if (auto r = one(pattern.s, b.s); !r) return unexpected(r.error());
  if (auto r = one(pattern.p, b.p); !r) return unexpected(r.error());
  if (auto r = one(pattern.o, b.o); !r) return unexpected(r.error());
  if (pattern.context && !pattern.context->empty()) {
    auto found = find_term(txn_, env_, Term::iri(*pattern.context));
    if (!found) return unexpected(found.error());
    if (*found == 0) b.empty = true;
    b.context = *found;
  }
  b.has_context = pattern.context.has_value();
  // An empty range holds nothing, not even what held for long (a query from the wire is not
  // checked as the command line checks it).
  if (pattern.since && pattern.until && *pattern.until <= *pattern.since) b.empty = true;
  return b;
}

Result<const ItemRow*> Query::item(std::uint64_t id) {
  if (cached_item_id_ != id) {
    auto row = get_item(txn_, env_, id);
    if (!row) return unexpected(row.error());
    if (!*row) return fail(Errc::corrupt, "item " + std::to_string(id) + " is missing");
    cached_item_ = std::move(**row);
    cached_item_id_ = id;
  }
  return &cached_item_;
}

Result<bool> Query::metadata_matches(const Pattern& pattern, const Bound& bound, const RecordRow& row) {
  if (!has_metadata_filter(pattern)) return true;
  auto it = item(row.item);
  if (!it) return unexpected(it.error());
  const ItemRow& meta = **it;
  if (bound.has_context && meta.context != bound.context) return false;
  if (pattern.until && meta.asserted_at >= *pattern.until) return false;
  if (pattern.since && !holds_at_or_after(meta, *pattern.since)) return false;
  if (pattern.source) {
    auto cached = source_under_.find(meta.source);
    if (cached == source_under_.end()) {
      auto source = terms_.iri(meta.source);
      if (!source) return unexpected(source.error());
      cached = source_under_.emplace(meta.source, uri::is_under(*source, *pattern.source)).first;
    }
    if (!cached->second) return false;
  }
  return true;
}

Result<std::optional<std::vector<std::uint64_t>>> Query::items_in_range(const Pattern& pattern, std::size_t most) {
  using Items = std::optional<std::vector<std::uint64_t>>;
  auto counters = load_counters(txn_, env_.main);
  if (!counters) return unexpected(counters.error());
  std::int64_t from = INT64_MIN;
  if (pattern.since) {
    const std::uint64_t span = std::min<std::uint64_t>(counters->max_span, INT64_MAX);
    if (__builtin_sub_overflow(*pattern.since, static_cast<std::int64_t>(span), &from)) from = INT64_MIN;
  }
  std::vector<std::uint64_t> items;
  Cursor cur;
  int rc = mdb_cursor_open(txn_, env_.by_time, &cur.c);
  if (rc != 0) return lmdb_fail(rc, "opening the time index");
  const std::uint64_t first_key = time_key(from);
  MDB_val k = val(first_key), v;
  for (rc = mdb_cursor_get(cur.c, &k, &v, MDB_SET_RANGE); rc == 0; rc = mdb_cursor_get(cur.c, &k, &v, MDB_NEXT)) {
    if (pattern.until && time_of_key(u64(k)) >= *pattern.until) break;
    if (items.size() == most) return Items();
    items.push_back(u64(v));
  }
  if (rc != 0 && rc != MDB_NOTFOUND) return lmdb_fail(rc, "walking the time index");
  std::sort(items.begin(), items.end());
  return Items(std::move(items));
}

Result<bool> Query::subject_under(const std::string& ancestor, std::uint64_t subject) {
  // A subject's records come one after another (an item's, a chunk's): one check for them all.
  if (auto cached = subject_under_.find(subject); cached != subject_under_.end()) return cached->second;
  auto term = terms_.get(subject, false, /*remember=*/false);
  if (!term) return unexpected(term.error());
  const bool under = term->is_iri() && uri::is_under(term->value, ancestor);
  // Bounded: a scan of a large store meets a new subject at every item.
  if (subject_under_.size() >= kSubjectsKept) subject_under_.clear();
  subject_under_.emplace(subject, under);
  return under;
}

Result<std::size_t> Query::index_count(MDB_dbi index, std::uint64_t term) {
  Cursor probe;
  int rc = mdb_cursor_open(txn_, index, &probe.c);
  if (rc != 0) return lmdb_fail(rc, "opening an index");
  MDB_val k = val(term), v;
  rc = mdb_cursor_get(probe.c, &k, &v, MDB_SET);
  if (rc == MDB_NOTFOUND) return std::size_t{0};
  if (rc != 0) return lmdb_fail(rc, "reading an index");
  std::size_t n = 0;
  mdb_cursor_count(probe.c, &n);
  return n;
}

Result<std::vector<std::uint64_t>> Query::collect_exact(std::span<const Pattern* const> patterns) {
  std::vector<std::uint64_t> out;
  if (patterns.empty()) return out;
  auto each_alone = [&]() -> Result<std::vector<std::uint64_t>> {
    for (const Pattern* p : patterns) {
      auto r = for_each(*p, [&](std::uint64_t id, const RecordRow&) { return out.push_back(id), true; });
      if (!r) return unexpected(r.error());
    }
    return std::move(out);
  };
  Pattern walk = *patterns.front();
  walk.p.reset();
  walk.o.reset();
  auto bound = resolve(walk);
  if (!bound) return unexpected(bound.error());
  if (bound->empty) return out;
  auto records = index_count(env_.idx_s, bound->s);
  if (!records) return unexpected(records.error());
  // One walk of the subject's records when it reads few per pattern: removing a conclusion of
  // a transitive closure alone reads thousands (its subject's and object's lists interleave),
  // all the removed conclusions of one subject together read its list once.
  constexpr std::size_t kRecordsPerPattern = 8;
  if (*records > kRecordsPerPattern * patterns.size()) return each_alone();
  std::unordered_map<std::uint64_t, std::unordered_set<std::uint64_t>> wanted;  // p -> o
  for (const Pattern* p : patterns) {
    auto pid = find_term(txn_, env_, *p->p);
    if (!pid) return unexpected(pid.error());
    auto oid = find_term(txn_, env_, *p->o);
    if (!oid) return unexpected(oid.error());
    if (*pid != 0 && *oid != 0) wanted[*pid].insert(*oid);
  }
  auto r = for_each(walk, [&](std::uint64_t id, const RecordRow& row) {
    if (auto it = wanted.find(row.p); it != wanted.end() && it->second.count(row.o)) out.push_back(id);
    return true;
  });
  if (!r) return unexpected(r.error());
  return out;
}

Result<void> Query::for_each(const Pattern& pattern,
                             const std::function<bool(std::uint64_t, const RecordRow&)>& visit) {
  auto bound = resolve(pattern);
  if (!bound) return unexpected(bound.error());
  if (bound->empty) return {};
  // No record comes after the greatest id (after_id + 1 wrapped to 0: every record).
  if (pattern.after_id == UINT64_MAX) return {};
  const Bound& b = *bound;
  std::uint64_t first = pattern.after_id ? *pattern.after_id + 1 : 0;

  // Walk the list of the bound position with the fewest records.
  MDB_dbi index = 0;
  std::uint64_t key = 0;
  std::size_t best = SIZE_MAX;
  const std::pair<MDB_dbi, std::uint64_t> candidates[] = {{env_.idx_s, b.s}, {env_.idx_p, b.p}, {env_.idx_o, b.o}};
  for (const auto& [dbi, id] : candidates) {
    if (id == 0) continue;
    auto n = index_count(dbi, id);
    if (!n) return unexpected(n.error());
    if (*n == 0) return {};  // a bound term with no records
    if (*n < best) {
      best = *n;
      index = dbi;
      key = id;
    }
  }

  auto check = [&](std::uint64_t id, const RecordRow& row) -> Result<bool> {
    if ((b.s && row.s != b.s) || (b.p && row.p != b.p) || (b.o && row.o != b.o)) return true;
    if (pattern.under) {
      auto under = subject_under(*pattern.under, row.s);
      if (!under) return unexpected(under.error());
      if (!*under) return true;
    }
    auto meta_ok = metadata_matches(pattern, b, row);
    if (!meta_ok) return unexpected(meta_ok.error());
    if (!*meta_ok) return true;
    return visit(id, row);
  };

  // A time range: the items of the range, when they are fewer than the records the walk below
  // would read (an item has at least one record). Each item's records are checked in turn.
  constexpr std::size_t kRangeItemsMost = std::size_t{1} << 20;
  if ((pattern.since || pattern.until) && env_.by_time) {
    auto items = items_in_range(pattern, std::min(best, kRangeItemsMost));
    if (!items) return unexpected(items.error());
    if (*items) {
      Cursor records;
      int rc = mdb_cursor_open(txn_, env_.records, &records.c);
      if (rc != 0) return lmdb_fail(rc, "opening records");
      for (const std::uint64_t item_id : **items) {
        auto row = item(item_id);  // kept for check's metadata test
        if (!row) return unexpected(row.error());
        const std::uint64_t end = item_id + (*row)->count;
        if (end <= first) continue;
        MDB_val k = val(std::max(item_id, first)), v;
        for (rc = mdb_cursor_get(records.c, &k, &v, MDB_SET_RANGE); rc == 0 && u64(k) < end;
             rc = mdb_cursor_get(records.c, &k, &v, MDB_NEXT)) {
          const std::uint64_t id = u64(k);
          RecordRow record;
          if (!decode_record(id, view(v), record)) return fail(Errc::corrupt, "record " + std::to_string(id) + " is truncated");
          auto go_on = check(id, record);
          if (!go_on) return unexpected(go_on.error());
          if (!*go_on) return {};
        }
        if (rc != 0 && rc != MDB_NOTFOUND) return lmdb_fail(rc, "reading the records of item " + std::to_string(item_id));
      }
      return {};
    }
  }

  Cursor cur;
  if (key == 0) {  // nothing bound: scan records in id order
    int rc = mdb_cursor_open(txn_, env_.records, &cur.c);
    if (rc != 0) return lmdb_fail(rc, "opening records");
    MDB_val k = val(first), v;
    for (rc = mdb_cursor_get(cur.c, &k, &v, MDB_SET_RANGE); rc == 0;
         rc = mdb_cursor_get(cur.c, &k, &v, MDB_NEXT)) {
      std::uint64_t id = u64(k);
      RecordRow row;
      if (!decode_record(id, view(v), row)) return fail(Errc::corrupt, "record " + std::to_string(id) + " is truncated");
      auto go_on = check(id, row);
      if (!go_on) return unexpected(go_on.error());
      if (!*go_on) return {};
    }
    if (rc != MDB_NOTFOUND) return lmdb_fail(rc, "scanning records");
    return {};
  }

  int rc = mdb_cursor_open(txn_, index, &cur.c);
  if (rc != 0) return lmdb_fail(rc, "opening an index");
  MDB_val k = val(key), v = val(first);
  rc = mdb_cursor_get(cur.c, &k, &v, MDB_GET_BOTH_RANGE);
  for (; rc == 0; rc = mdb_cursor_get(cur.c, &k, &v, MDB_NEXT_DUP)) {
    std::uint64_t id = u64(v);
    auto row = get_record(txn_, env_, id);
    if (!row) return unexpected(row.error());
    if (!*row) return fail(Errc::corrupt, "index refers to missing record " + std::to_string(id));
    auto go_on = check(id, **row);
    if (!go_on) return unexpected(go_on.error());
    if (!*go_on) return {};
  }
  if (rc != MDB_NOTFOUND) return lmdb_fail(rc, "walking an index");
  return {};
}

Result<void> Query::cascade_from(std::uint64_t object, unsigned depth, std::vector<std::uint64_t>& out,
                                 std::unordered_map<std::uint64_t, unsigned>& reach, std::size_t limit) {
  // Depth first, each record before its object's sub-tree, on a stack of our own: a chain of
  // records (an RDF list, a linked log) can be as deep as --cascade lets it, and a frame of
  // recursion per level overflowed the thread's stack at about 21,000 levels.
  struct Level {
    std::vector<std::pair<std::uint64_t, std::uint64_t>> children;  // (record id, its object)
    std::size_t next = 0;
    unsigned depth = 0;  // the depth the children were reached with
  };
  const auto walked_deep_enough = [&](std::uint64_t id, unsigned at_depth) {
    auto it = reach.find(id);
    return it != reach.end() && it->second >= at_depth - 1;
  };
  std::vector<Level> stack;
  const auto expand = [&](std::uint64_t subject, unsigned at_depth) -> Result<void> {
    if (at_depth == 0) return {};
    Level level{.depth = at_depth};
    Cursor cur;
    int rc = mdb_cursor_open(txn_, env_.idx_s, &cur.c);
    if (rc != 0) return lmdb_fail(rc, "opening the subject index");
    MDB_val k = val(subject), v;
    for (rc = mdb_cursor_get(cur.c, &k, &v, MDB_SET); rc == 0; rc = mdb_cursor_get(cur.c, &k, &v, MDB_NEXT_DUP)) {
      std::uint64_t id = u64(v);
      if (walked_deep_enough(id, at_depth)) continue;
      auto row = get_record(txn_, env_, id);
      if (!row) return unexpected(row.error());
      if (!*row) continue;
      level.children.emplace_back(id, (*row)->o);
    }
    if (rc != MDB_NOTFOUND) return lmdb_fail(rc, "walking the subject index");
    if (!level.children.empty()) stack.push_back(std::move(level));
    return {};
  };
  if (limit && out.size() >= limit) return {};
  if (auto r = expand(object, depth); !r) return r;
  while (!stack.empty()) {
    if (limit && out.size() >= limit) return {};
    Level& top = stack.back();
    if (top.next == top.children.size()) {
      stack.pop_back();
      continue;
    }
    const auto [id, child_object] = top.children[top.next++];
    const unsigned at_depth = top.depth;  // `top` may move when expand pushes
    if (walked_deep_enough(id, at_depth)) continue;
    if (reach.emplace(id, at_depth - 1).second) out.push_back(id);
    else reach[id] = at_depth - 1;
    if (auto r = expand(child_object, at_depth - 1); !r) return r;
  }
  return {};
}

Result<std::vector<std::uint64_t>> Query::collect(const Pattern& pattern, const ListOptions& options) {
  std::vector<std::pair<std::uint64_t, std::uint64_t>> matches;  // (id, object)
  auto walked = for_each(pattern, [&](std::uint64_t id, const RecordRow& row) {
    matches.emplace_back(id, row.o);
    return !(options.limit && matches.size() >= options.limit);
  });
  if (!walked) return unexpected(walked.error());
  std::vector<std::uint64_t> out;
  if (options.cascade == 0) {
    for (const auto& m : matches) out.push_back(m.first);
    return out;
  }
  std::unordered_map<std::uint64_t, unsigned> reach;
  for (const auto& m : matches) reach[m.first] = options.cascade;
  for (const auto& [id, object] : matches) {
    if (options.limit && out.size() >= options.limit) break;
    out.push_back(id);
    // Literals have no sub-tree; IRIs and blank nodes may.
    if (auto r = cascade_from(object, options.cascade, out, reach, options.limit); !r) return unexpected(r.error());
  }
  return out;
}

Result<Record> Query::materialize(std::uint64_t id, const RecordRow& row) {
  auto it = item(row.item);
  if (!it) return unexpected(it.error());
  const ItemRow& meta = **it;  // the query's cached row: the term reads below leave it be
  auto s = terms_.get(row.s);
  if (!s) return unexpected(s.error());
  auto p = terms_.get(row.p, true);
  if (!p) return unexpected(p.error());
  auto o = terms_.get(row.o);
  if (!o) return unexpected(o.error());
  auto source = terms_.iri(meta.source);
  if (!source) return unexpected(source.error());
  auto context = terms_.iri(meta.context);
  if (!context) return unexpected(context.error());
  Record record;
  record.triple = {std::move(*s), std::move(*p), std::move(*o)};
  record.meta = {id, row.item, meta.stored_at, meta.asserted_at, std::move(*source), std::move(*context), meta.persistent, meta.span};
  return record;
}

Result<std::optional<Record>> Query::record(std::uint64_t id) {
  auto row = get_record(txn_, env_, id);
  if (!row) return unexpected(row.error());
  if (!*row) return std::optional<Record>();
  auto rec = materialize(id, **row);
  if (!rec) return unexpected(rec.error());
  return std::optional<Record>(std::move(*rec));
}

}  // namespace tahvel::node::detail
