// The write path; see write.h.
#include "write.h"

#include <unistd.h>

#include <algorithm>
#include <limits>
#include <cstdio>
#include <optional>
#include <unordered_map>

#include "dictionary.h"
#include "query.h"
#include "rows.h"
#include "wake.h"
#include "tahvel/uri/iri.h"

namespace tahvel::node::detail {
namespace {

constexpr std::size_t kTtlScanBudget = 64;  // records examined per rule per write
constexpr std::size_t kTtlPassBudget = 4096;  // persistent or waiting records passed, per rule per write

const char* position_name(int i) { return i == 0 ? "subject" : i == 1 ? "predicate" : "object"; }

// Interns a term at a position; new IRIs are validated here, once, when they enter the
// dictionary (terms already there were valid when they came). Sensor data repeats predicates,
// classes and sensors endlessly: intern_keyed finds them in the transaction's or the process's
// cache without a search. A new subject (an observation's own IRI) is remembered for this
// transaction only: it rarely comes again.
Result<std::uint64_t> term_id(Txn& txn, const Term& term, int position,
                              std::unordered_map<std::string, std::uint64_t>& blanks, TermKey& key) {
  if (term.kind == TermKind::blank) {
    auto [it, fresh] = blanks.try_emplace(term.value, 0);
    if (fresh) it->second = inline_blank(txn.counters.next_blank++);
    return it->second;
  }
  if (auto id = inline_id(term)) return *id;
  term_key(term, key);
  return intern_keyed(txn, term, key, {.remember_new = position != 0, .check_iri = true});
}

Result<std::vector<Subscription>> load_subscriptions(Txn& txn) {
  if (auto f = flush_index(txn); !f) return unexpected(f.error());
  std::vector<Subscription> subs;
  const auto& vocab = txn.env().vocab;
  MDB_txn* raw = txn.raw();
  Env& env = txn.env();
  MDB_cursor* cursor = nullptr;
  int rc = mdb_cursor_open(raw, env.idx_p, &cursor);
  if (rc != 0) return lmdb_fail(rc, "opening the predicate index");
  std::uint64_t context_predicate = vocab.context;
  if (!context_predicate) {
    auto found = find_term(raw, env, Term::iri(std::string(kSubscriptionContext)));
    if (!found) return unexpected(found.error());
    context_predicate = *found;
  }
  // tv:source is looked up the same way: it exists once a subscription has used it.
  auto source_predicate = find_term(raw, env, Term::iri(std::string(kSubscriptionSource)));
  if (!source_predicate) return unexpected(source_predicate.error());
  std::vector<std::uint64_t> ids;
  MDB_val k = val(vocab.subscriber), v;
  for (rc = mdb_cursor_get(cursor, &k, &v, MDB_SET); rc == 0; rc = mdb_cursor_get(cursor, &k, &v, MDB_NEXT_DUP))
    ids.push_back(u64(v));
  mdb_cursor_close(cursor);
  if (rc != MDB_NOTFOUND) return lmdb_fail(rc, "reading subscriptions");
  for (std::uint64_t id : ids) {
    auto head = get_record(raw, env, id);
    if (!head) return unexpected(head.error());
    if (!*head) continue;
    Subscription sub{(*head)->item, (*head)->o, 0, 0, 0};
    // The pattern's positions are the other triples about the same subscription node.
    if ((rc = mdb_cursor_open(raw, env.idx_s, &cursor)) != 0) return lmdb_fail(rc, "opening the subject index");
    MDB_val sk = val((*head)->s), sv;
    for (rc = mdb_cursor_get(cursor, &sk, &sv, MDB_SET); rc == 0; rc = mdb_cursor_get(cursor, &sk, &sv, MDB_NEXT_DUP)) {
      auto part = get_record(raw, env, u64(sv));
      if (!part || !*part) continue;
      const RecordRow& r = **part;
      if (r.p == vocab.subject) sub.s = r.o;
      else if (r.p == vocab.predicate) sub.p = r.o;
      else if (r.p == vocab.object) sub.o = r.o;
      else if (context_predicate && r.p == context_predicate) sub.context = r.o;
      else if (*source_predicate && r.p == *source_predicate) sub.source = r.o;
    }
    mdb_cursor_close(cursor);
    subs.push_back(sub);
  }
  return subs;
}

Result<std::vector<TtlRule>> load_ttl_rules(Txn& txn) {
  std::vector<TtlRule> rules;
  MDB_cursor* cursor = nullptr;
  int rc = mdb_cursor_open(txn.raw(), txn.env().meta, &cursor);
  if (rc != 0) return lmdb_fail(rc, "opening settings");
  const std::string_view prefix = "ttl:";
  MDB_val k = val(prefix), v;
  std::vector<std::pair<std::string, std::int64_t>> found;
  for (rc = mdb_cursor_get(cursor, &k, &v, MDB_SET_RANGE); rc == 0; rc = mdb_cursor_get(cursor, &k, &v, MDB_NEXT)) {
    std::string_view key = view(k);
    if (key.substr(0, prefix.size()) != prefix) break;
    std::int64_t ttl = 0;
    std::memcpy(&ttl, v.mv_data, std::min(v.mv_size, sizeof ttl));
    found.emplace_back(std::string(key.substr(prefix.size())), ttl);
  }
  mdb_cursor_close(cursor);
  for (const auto& [iri, ttl] : found) {
    auto id = find_term(txn.raw(), txn.env(), Term::iri(iri));
    if (!id) return unexpected(id.error());
    if (*id) rules.push_back({*id, ttl});
  }
  return rules;
}

Result<std::vector<std::uint64_t>> load_removal_receivers(Txn& txn) {
  std::vector<std::uint64_t> agents;
  MDB_cursor* cursor = nullptr;
  int rc = mdb_cursor_open(txn.raw(), txn.env().meta, &cursor);
  if (rc != 0) return lmdb_fail(rc, "opening settings");
  const std::string_view prefix = kRemovalReceiverKey;
  MDB_val k = val(prefix), v;
  std::vector<std::string> found;
  for (rc = mdb_cursor_get(cursor, &k, &v, MDB_SET_RANGE); rc == 0; rc = mdb_cursor_get(cursor, &k, &v, MDB_NEXT)) {
    std::string_view key = view(k);
    if (!key.starts_with(prefix)) break;
    found.emplace_back(key.substr(prefix.size()));
  }
  mdb_cursor_close(cursor);
  for (const std::string& iri : found) {
    auto id = find_term(txn.raw(), txn.env(), Term::iri(iri));
    if (!id) return unexpected(id.error());
    if (*id) agents.push_back(*id);
  }
  std::sort(agents.begin(), agents.end());  // searched by deliver (Txn::removal_receivers)
  return agents;
}

bool triple_matches(const Subscription& sub, std::uint64_t s, std::uint64_t p, std::uint64_t o) {
  return (!sub.s || sub.s == s) && (!sub.p || sub.p == p) && (!sub.o || sub.o == o);
}

// Puts `item_id` into the input buffer of `agent` (a term id) unless it is there already.
Result<void> deliver(Txn& txn, std::uint64_t agent, std::uint32_t slot, std::uint64_t item_id,
                     ItemRow& item) {
  MDB_val k = val(agent), v = val(item_id);
  int rc = mdb_put(txn.raw(), txn.env().inbox, &k, &v, MDB_NODUPDATA);
  if (rc == MDB_KEYEXIST) return {};  // two subscriptions of one agent: delivered once
  if (rc != 0) return lmdb_fail(rc, "routing an item into an input buffer");
  ++item.pending;
  ++txn.counters.pending;
  txn.wake_slots.push_back(slot);
  // Remembered for R21: a removal reaches this agent even once its subscriptions no longer
  // route the item. txn.removal_receivers is read by removals_noticed, which every caller has
  // asked before routing.
  if (std::binary_search(txn.removal_receivers.begin(), txn.removal_receivers.end(), agent) &&
      std::find(item.noticed.begin(), item.noticed.end(), agent) == item.noticed.end())
    item.noticed.push_back(agent);
  return {};
}


Result<void> route_to_addressee(Txn& txn, std::uint64_t item_id, ItemRow& item,
                                const std::string& context, const std::string& writer) {
  auto addressee = addressee_of(txn.env().settings().iri, context, writer);
  if (!addressee) return {};
  auto agent = intern_term(txn, Term::iri(*addressee), true);  // keys an input buffer: pinned
  if (!agent) return unexpected(agent.error());
  return deliver(txn, *agent, WakeBoard::slot_for(*addressee), item_id, item);
}

// A subscription's source condition: the item's source is the subscription's source IRI or
// lies under it (as Pattern::source reads). The prefix test rejects almost every other source
// without parsing an IRI.
bool source_matches(const Subscription& sub, std::uint64_t source, std::string_view source_iri) {
  if (!sub.source || sub.source == source) return true;
  return source_iri.starts_with(sub.source_iri) && uri::is_under(source_iri, sub.source_iri);
}

bool routes(const Subscription& sub, std::uint64_t item_id, const ItemRow& item,
            const std::vector<std::array<std::uint64_t, 3>>& triples, std::string_view source_iri) {
  if (sub.item == item_id) return false;  // a subscription does not receive itself
  if (!source_matches(sub, item.source, source_iri)) return false;
  return std::any_of(triples.begin(), triples.end(), [&](const auto& t) { return triple_matches(sub, t[0], t[1], t[2]); });
}

Result<void> route_to(Txn& txn, const Subscription& sub, std::uint64_t item_id, ItemRow& item,
                      const std::vector<std::array<std::uint64_t, 3>>& triples,
                      std::string_view source_iri) {
  if (!routes(sub, item_id, item, triples, source_iri)) return {};
  return deliver(txn, sub.agent, sub.slot, item_id, item);
}

// Subscriptions that require a context are looked up by the item's context: a parent with a
// thousand children has a thousand subtree subscriptions, and an item matches at most those
// of its own context.
Result<void> route(Txn& txn, std::uint64_t item_id, ItemRow& item,
                   const std::vector<std::array<std::uint64_t, 3>>& triples,
                   std::string_view source_iri) {
  Env& env = txn.env();
  std::lock_guard lock(env.cache_mutex);
  for (std::uint32_t i : env.subs_any_context)
    if (auto r = route_to(txn, env.subs[i], item_id, item, triples, source_iri); !r) return r;
  if (!item.context) return {};
  auto found = env.subs_by_context.find(item.context);
  if (found == env.subs_by_context.end()) return {};
  for (std::uint32_t i : found->second)
    if (auto r = route_to(txn, env.subs[i], item_id, item, triples, source_iri); !r) return r;
  return {};
}

// Evicts the oldest non-persistent items not waiting in an input buffer until the ring fits.
// The scan walks the items table from counters.ring_head, which then moves past the leading
// run of items that are persistent or evicted, so persistent items are passed over once; and
// items waiting in input buffers are passed over once too: the scan resumes where it stopped
// (kRingResume), going back only for those released since (kRingReleasedLow, kRingReleasedN).
Result<std::uint64_t> apply_ring(Txn& txn) {
  const std::uint64_t bound = txn.env().settings().ring;
  if (bound == 0 || txn.counters.ring_records <= bound) return std::uint64_t{0};
  MDB_txn* raw = txn.raw();
  const Env& env = txn.env();
  const std::uint64_t head = txn.counters.ring_head;
  std::uint64_t resume = std::max(head, meta_u64(raw, env, kRingResume).value_or(head));
  std::uint64_t released_n = meta_u64(raw, env, kRingReleasedN).value_or(0);
  const std::uint64_t released_low = std::max(head, meta_u64(raw, env, kRingReleasedLow).value_or(resume));
  const std::uint64_t start = released_n > 0 ? std::min(released_low, resume) : resume;
  std::vector<std::uint64_t> victims;
  std::uint64_t excess = txn.counters.ring_records - bound, freed = 0;
  std::optional<std::uint64_t> first_survivor;  // first non-persistent item kept
  std::uint64_t scanned_to = start;
  MDB_cursor* cursor = nullptr;
  int rc = mdb_cursor_open(raw, env.items, &cursor);
  if (rc != 0) return lmdb_fail(rc, "opening items");
  MDB_val k = val(start), v;
  for (rc = mdb_cursor_get(cursor, &k, &v, MDB_SET_RANGE); rc == 0 && freed < excess;
       rc = mdb_cursor_get(cursor, &k, &v, MDB_NEXT)) {
    ItemRow item;
    if (!decode_item(view(v), item)) {
      mdb_cursor_close(cursor);
      return fail(Errc::corrupt, "item " + std::to_string(u64(k)) +
                                     " cannot be read: its row is truncated, or written by a later build");
    }
    scanned_to = u64(k) + 1;
    if (item.persistent) continue;
    if (item.pending > 0) {  // unread: kept until taken
      if (!first_survivor) first_survivor = u64(k);
      continue;
    }
    victims.push_back(u64(k));
    if (u64(k) < resume && released_n > 0) --released_n;  // one the scan came back for
    freed += item.live;
  }
  mdb_cursor_close(cursor);
  if (rc == MDB_NOTFOUND) scanned_to = std::max(scanned_to, txn.counters.next_seq);  // to the end
  if (start == head) txn.counters.ring_head = first_survivor.value_or(scanned_to);
  // What lies in [start, scanned_to) is kept (persistent, waiting) or evicted now.
  if (scanned_to >= resume) {
    resume = scanned_to;
    released_n = 0;  // every one released below the old resume was met
  }
  if (auto r = put_meta_u64(raw, env, kRingResume, std::max(resume, txn.counters.ring_head)); !r) return unexpected(r.error());
  if (auto r = put_meta_u64(raw, env, kRingReleasedN, released_n); !r) return unexpected(r.error());
  if (released_n > 0)
    if (auto r = put_meta_u64(raw, env, kRingReleasedLow, std::max(scanned_to, released_low)); !r) return unexpected(r.error());
  std::uint64_t removed = 0;
  for (std::uint64_t id : victims) {
    auto n = delete_item(txn, id, Removal::retention);
    if (!n) return n;
    removed += *n;
  }
  return removed;
}

Result<std::uint64_t> apply_ttl(Txn& txn, const std::vector<TtlRule>& rules) {
  if (auto f = flush_index(txn); !f) return unexpected(f.error());
  std::uint64_t removed = 0;
  const std::int64_t now = now_ns();
  for (const auto& rule : rules) {
    std::vector<std::uint64_t> expired;
    MDB_cursor* cursor = nullptr;
    int rc = mdb_cursor_open(txn.raw(), txn.env().idx_p, &cursor);
    if (rc != 0) return lmdb_fail(rc, "opening the predicate index");
    // Persistent records of the predicate are never reclaimed: 64 of them at its head held every
    // later record back for good, each scan stopping at the budget. The scan starts past them,
    // where the store notes it (meta "ttl_from:<predicate id>": in the transaction, so an abort
    // forgets it with the records, and every process starts there).
    const std::string from_key = "ttl_from:" + std::to_string(rule.predicate);
    MDB_val fk = val(from_key), fv;
    std::uint64_t scan_from = 0;
    if (mdb_get(txn.raw(), txn.env().meta, &fk, &fv) == 0 && fv.mv_size == sizeof scan_from) scan_from = u64(fv);
    const std::uint64_t noted = scan_from;
    // More than a budget of records waiting in input buffers held back every expired record
    // behind them: each write's scan stopped among them, at the same place. A scan stopped by
    // a budget notes where (meta "ttl_resume:<predicate id>") and the next goes on from there;
    // one that reaches a record not yet due, or the end, starts the next from the head again,
    // where records waiting then may have been taken since.
    const std::string resume_key = "ttl_resume:" + std::to_string(rule.predicate);
    const std::optional<std::uint64_t> resume = meta_u64(txn.raw(), txn.env(), resume_key);
    const std::uint64_t start = resume && *resume > scan_from ? *resume : scan_from;
    bool at_head = start == scan_from;  // only persistent (or gone) records so far
    MDB_val k = val(rule.predicate), v = val(start);
    std::size_t examined = 0, passed = 0;
    std::uint64_t next = start;  // the record the next scan would look at
    bool not_due = false;        // stopped at a record not yet due: the rest is younger
    for (rc = mdb_cursor_get(cursor, &k, &v, MDB_GET_BOTH_RANGE); rc == 0 && examined < kTtlScanBudget && passed < kTtlPassBudget;
         rc = mdb_cursor_get(cursor, &k, &v, MDB_NEXT_DUP)) {
      std::uint64_t id = u64(v);
      next = id + 1;
      auto row = get_record(txn.raw(), txn.env(), id);
      auto item = row && *row ? get_item(txn.raw(), txn.env(), (*row)->item) : Result<std::optional<ItemRow>>(std::nullopt);
      if (!item || !*item) {
        ++examined;  // unreadable: each costs the budget, or a damaged index made the scan unbounded
        continue;
      }
      const ItemRow& it = **item;
      if (it.persistent) {
        if (at_head) scan_from = id + 1;
        ++passed;
        continue;
      }
      at_head = false;
      // ids ascend with time: the rest is younger. Saturating: a TTL of centuries (or
      // nanoseconds::max, "for ever") overflowed and reclaimed everything at once.
      std::int64_t expires = 0;
      if (__builtin_add_overflow(it.stored_at, rule.ttl_ns, &expires) || expires > now) {
        not_due = true;
        break;
      }
      // Waiting in an input buffer: reclaimable once taken, so passed, not examined (64 in a
      // slow subscriber's buffer held the rest back as the persistent ones did).
      if (it.pending > 0) {
        ++passed;
        continue;
      }
      ++examined;
      expired.push_back(id);
    }
    mdb_cursor_close(cursor);
    if (rc != 0 && rc != MDB_NOTFOUND) return lmdb_fail(rc, "walking the predicate index");
    if (scan_from != noted) {
      MDB_val nv = val(scan_from);
      if (int put = mdb_put(txn.raw(), txn.env().meta, &fk, &nv, 0); put != 0) return lmdb_fail(put, "noting where a time-to-live scan starts");
    }
    const bool stopped_by_budget = rc == 0 && !not_due;
    if (stopped_by_budget) {
      if (auto r = put_meta_u64(txn.raw(), txn.env(), resume_key, next); !r) return unexpected(r.error());
      txn.retention_unfinished = true;
    } else if (resume) {
      MDB_val rk = val(resume_key);
      if (int del = mdb_del(txn.raw(), txn.env().meta, &rk, nullptr); del != 0 && del != MDB_NOTFOUND)
        return lmdb_fail(del, "noting where a time-to-live scan starts");
    }
    for (std::uint64_t id : expired) {
      if (auto d = delete_record(txn, id, Removal::retention); !d) return unexpected(d.error());
      ++removed;
    }
  }
  return removed;
}

// Whether `subscriber` names an agent of this node (node IRI + "/" + id). A subscription for
// anyone else (one of another node's agents, brought in by `tahvel load` of that node's dump)
// routes nothing: no handle here could ever take what it would hold, and items waiting in an
// input buffer are never reclaimed.
bool subscriber_of_this_node(const Env& env, std::string_view subscriber) {
  const std::string& node = env.settings().iri;
  return subscriber.starts_with(node) && uri::child_id(subscriber, node).has_value();
}

// Caller holds env.cache_mutex.
void add_to_cache(Env& env, Subscription sub) {
  const auto index = static_cast<std::uint32_t>(env.subs.size());
  if (sub.context) {
    env.subs_by_context[sub.context].push_back(index);
  } else {
    env.subs_any_context.push_back(index);
  }
  env.subs.push_back(std::move(sub));
}

// The subscriptions item `item_id` declares, read from the item itself (`rows` are its triples'
// term ids) as load_subscriptions would read them from the store; nullopt when that cannot be
// told from the item alone: a subscription node that is not a blank node of the item (other
// items may say more about an IRI) or a subscriber that is not an IRI. Registering a thousand
// children at a parent is a thousand subscriptions: reloading all of them after each made it
// quadratic (14 s for 2,000 homes).
std::optional<std::vector<Subscription>> subscriptions_declared_by(
    const Env& env, const Item& item, std::uint64_t item_id, const std::vector<std::array<std::uint64_t, 3>>& rows) {
  std::vector<Subscription> subs;
  for (std::size_t i = 0; i < rows.size(); ++i) {
    if (rows[i][1] != env.vocab.subscriber) continue;
    const Triple& declared = item.triples[i];
    if (declared.s.kind != TermKind::blank || declared.o.kind != TermKind::iri) return std::nullopt;
    if (!subscriber_of_this_node(env, declared.o.value)) continue;
    Subscription sub{item_id, rows[i][2], 0, 0, 0};
    sub.slot = WakeBoard::slot_for(declared.o.value);
    for (std::size_t k = 0; k < rows.size(); ++k) {
      if (rows[k][0] != rows[i][0]) continue;
      const std::uint64_t p = rows[k][1], o = rows[k][2];
      const Triple& t = item.triples[k];
      if (p == env.vocab.subject) sub.s = o;
      else if (p == env.vocab.predicate) sub.p = o;
      else if (p == env.vocab.object) sub.o = o;
      else if (t.p.value == kSubscriptionContext) sub.context = o;
      else if (t.p.value == kSubscriptionSource) {
        if (t.o.kind != TermKind::iri) return std::nullopt;
        sub.source = o;
        sub.source_iri = t.o.value;
      }
    }
    subs.push_back(std::move(sub));
  }
  return subs;
}

}  // namespace

// R18: an item whose context lies under this node's IRI is addressed to the agent named by the
// context's first segment below the node (a local agent, or the link agent of a child node),
// which gets it in its input buffer without subscribing. The segment "*" names no agent (it
// addresses a whole subtree, see docs/protocol.md).
std::optional<std::string> addressee_of(const std::string& node_iri, std::string_view context, std::string_view writer) {
  // Agent IRI = node IRI + "/" + id, the '/' not doubled after a node IRI that ends in one
  // (uri::agent_iri).
  const std::size_t begin = node_iri.ends_with('/') ? node_iri.size() : node_iri.size() + 1;
  if (context.size() <= begin || context.compare(0, node_iri.size(), node_iri) != 0 || context[begin - 1] != '/')
    return std::nullopt;
  std::size_t end = context.find_first_of("/#?", begin);
  std::string addressee(context.substr(0, end));
  if (addressee.size() == begin || addressee.compare(begin, std::string::npos, "*") == 0 || addressee == writer)
    return std::nullopt;
  return addressee;
}

namespace {

// Turtle's and N-Triples' LANGTAG: [a-zA-Z]+ ('-' [a-zA-Z0-9]+)*. A tag outside it would be
// written out as text that is no longer one literal.
bool is_language_tag(std::string_view tag) {
  auto alpha = [](char c) { return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z'); };
  auto digit = [](char c) { return c >= '0' && c <= '9'; };
  bool first = true, empty = true;
  for (char c : tag) {
    if (c == '-') {
      if (empty) return false;
      first = false;
      empty = true;
    } else if (alpha(c) || (!first && digit(c))) {
      empty = false;
    } else {
      return false;
    }
  }
  return !empty;
}

// ": not UTF-8: ..." naming the first ill-formed byte of `text` (`of_what` after its offset), or
// "" when `text` is well-formed.
std::string not_utf8(std::string_view text, std::string_view of_what) {
  const std::size_t at = ill_formed_utf8_at(text);
  if (at == std::string_view::npos) return {};
  char byte[8];
  std::snprintf(byte, sizeof byte, "0x%02X", static_cast<unsigned char>(text[at]));
  return ": not UTF-8: byte " + std::string(byte) + " at offset " + std::to_string(at) + std::string(of_what) +
         " does not begin a well-formed sequence";
}

// What is wrong with a literal's language tag and its pairing with a datatype, or "".
std::string language_tag_problem(const Term& term) {
  if (term.language.size() > 255) return "language tag too long";
  if (!term.language.empty() && !is_language_tag(term.language))
    return "language tag '" + term.language + "' is not letters, then '-' and letters or digits (en, et-EE)";
  if (!term.language.empty() && !term.datatype.empty() && term.datatype != kRdfLangString)
    return "a literal has a language tag or a datatype, not both";
  // RDF 1.1: rdf:langString is the datatype of the literals with a language tag, and of no other.
  if (term.language.empty() && term.datatype == kRdfLangString) return "a literal of datatype rdf:langString needs a language tag";
  return {};
}

}  // namespace

std::string pattern_literal_problem(const Term& term) {
  if (auto bad = not_utf8(term.value, ""); !bad.empty()) return bad.substr(2);
  if (auto bad = not_utf8(term.datatype, " of the datatype"); !bad.empty()) return bad.substr(2);
  if (!term.datatype.empty() && !uri::is_valid(term.datatype)) return "its datatype <" + term.datatype + "> is not an absolute IRI";
  return language_tag_problem(term);
}

Result<void> validate_item(const Item& item, const Settings& settings) {
  if (item.triples.empty()) return fail(Errc::invalid_argument, "an item needs at least one triple");
  if (item.span < 0) return fail(Errc::invalid_argument, "span " + std::to_string(item.span) + " ns is negative");
  // Without an asserted-at the item is asserted when stored: about now (the clock is read only
  // for an item with a span: this runs for every item a hospital takes).
  const std::int64_t start = item.span > 0 ? item.asserted_at.value_or(now_ns()) : 0;
  std::int64_t end = 0;
  if (item.span > 0 && __builtin_add_overflow(start, item.span, &end))
    return fail(Errc::invalid_argument, "asserted-at " + std::to_string(start) + " plus span " +
                                            std::to_string(item.span) + " ns is past the largest time");
  if (auto bad = not_utf8(item.context, ""); !bad.empty()) return fail(Errc::invalid_argument, "context" + bad);
  for (std::size_t i = 0; i < item.triples.size(); ++i) {
    const Triple& t = item.triples[i];
    const Term* terms[] = {&t.s, &t.p, &t.o};
    auto where = [&](int pos) { return "triple " + std::to_string(i + 1) + ", " + position_name(pos); };
    if (t.s.kind == TermKind::literal) return fail(Errc::invalid_argument, where(0) + ": a literal cannot be a subject");
    if (t.p.kind != TermKind::iri) return fail(Errc::invalid_argument, where(1) + ": the predicate must be an IRI");
    for (int pos = 0; pos < 3; ++pos) {
      const Term& term = *terms[pos];
      if (term.kind == TermKind::iri && term.value.empty())
        return fail(Errc::invalid_iri, where(pos) + ": empty IRI");
      if (term.kind == TermKind::blank && term.value.empty())
        return fail(Errc::invalid_argument, where(pos) + ": empty blank-node label");
      if (auto bad = not_utf8(term.value, ""); !bad.empty()) return fail(Errc::invalid_argument, where(pos) + bad);
      if (auto bad = not_utf8(term.datatype, " of the datatype"); !bad.empty()) return fail(Errc::invalid_argument, where(pos) + bad);
      if (auto bad = not_utf8(term.language, " of the language tag"); !bad.empty())
        return fail(Errc::invalid_argument, where(pos) + bad);
      if (term.kind != TermKind::literal) continue;
      if (term.value.size() > settings.max_literal_bytes)
        return fail(Errc::literal_too_large, where(pos) + ": literal of " + std::to_string(term.value.size()) +
                                                 " bytes exceeds the node's limit of " +
                                                 std::to_string(settings.max_literal_bytes));
      if (auto bad = language_tag_problem(term); !bad.empty()) return fail(Errc::invalid_argument, where(pos) + ": " + bad);
    }
  }
  return {};
}

Result<void> refresh_caches(Txn& txn) {
  Env& env = txn.env();
  std::lock_guard lock(env.cache_mutex);
  if (env.subs_gen != txn.counters.sub_gen) {
    txn.touched_caches = true;
    auto subs = load_subscriptions(txn);
    if (!subs) return unexpected(subs.error());
    TermReader reader(txn.raw(), env);
    std::vector<Subscription> routing;
    for (auto& sub : *subs) {
      auto iri = reader.iri(sub.agent);
      if (!iri) return unexpected(iri.error());
      if (!subscriber_of_this_node(env, *iri)) continue;
      sub.slot = WakeBoard::slot_for(*iri);
      if (sub.source) {
        auto source = reader.iri(sub.source);
        if (!source) return unexpected(source.error());
        sub.source_iri = std::move(*source);
      }
      routing.push_back(std::move(sub));
    }
    env.subs.clear();
    env.subs_any_context.clear();
    env.subs_by_context.clear();
    for (Subscription& sub : routing) add_to_cache(env, std::move(sub));
    env.subs_gen = txn.counters.sub_gen;
  }
  if (env.ttl_gen != txn.counters.ttl_gen) {
    txn.touched_caches = true;
    auto rules = load_ttl_rules(txn);
    if (!rules) return unexpected(rules.error());
    auto receivers = load_removal_receivers(txn);
    if (!receivers) return unexpected(receivers.error());
    env.ttl_rules = std::move(*rules);
    env.removal_receivers = std::move(*receivers);
    env.ttl_gen = txn.counters.ttl_gen;
    txn.removals_noticed.reset();  // read again with the receivers (removals_noticed)
  }
  return {};
}

Result<bool> removals_noticed(Txn& txn) {
  if (!txn.removals_noticed) {
    if (auto r = refresh_caches(txn); !r) return unexpected(r.error());
    std::lock_guard lock(txn.env().cache_mutex);
    txn.removal_receivers = txn.env().removal_receivers;  // sorted
    txn.removals_noticed = !txn.removal_receivers.empty();
  }
  return *txn.removals_noticed;
}

Result<void> receive_removals(Txn& txn, const std::string& agent_iri) {
  // The agent's IRI keys its input buffer: pinned, so the cached id stays valid.
  auto id = intern_term(txn, Term::iri(agent_iri), true);
  if (!id) return unexpected(id.error());
  std::string key = std::string(kRemovalReceiverKey) + agent_iri;
  MDB_val k = val(key), v;
  int rc = mdb_get(txn.raw(), txn.env().meta, &k, &v);
  if (rc == 0) return {};
  if (rc != MDB_NOTFOUND) return lmdb_fail(rc, "reading the removal notice setting of " + agent_iri);
  MDB_val empty = val(std::string_view());
  if ((rc = mdb_put(txn.raw(), txn.env().meta, &k, &empty, 0)) != 0)
    return lmdb_fail(rc, "writing the removal notice setting of " + agent_iri);
  ++txn.counters.ttl_gen;
  return {};
}

namespace {

// The agents that receive removal notices (R21) to which an item of these records, source and
// context is routed (R10, R18): its plan's recipients. The writer (the agent whose output buffer
// holds it) is never its own addressee, as at insert.
Result<std::vector<std::pair<std::uint64_t, std::uint32_t>>> notice_recipients(
    Txn& txn, std::uint64_t item_id, std::uint64_t source, std::string_view source_iri, std::uint64_t context,
    std::string_view context_iri, std::uint64_t writer, const std::vector<std::array<std::uint64_t, 3>>& triples) {
  Env& env = txn.env();
  std::vector<std::pair<std::uint64_t, std::uint32_t>> to;
  // Addressed as at insert: by the context in normal form.
  std::optional<std::string> addressee;
  if (!context_iri.empty()) {
    if (auto normal = uri::normalize(context_iri)) addressee = addressee_of(env.settings().iri, *normal, {});
  }
  std::uint64_t addressee_id = 0;
  if (addressee) {
    auto found = find_term(txn.raw(), env, Term::iri(*addressee));
    if (!found) return unexpected(found.error());
    addressee_id = *found;
  }
  ItemRow item;
  item.source = source;
  item.context = context;
  std::lock_guard lock(env.cache_mutex);
  auto receives = [&](std::uint64_t agent) {
    return std::binary_search(env.removal_receivers.begin(), env.removal_receivers.end(), agent);
  };
  auto consider = [&](const Subscription& sub) {
    if (receives(sub.agent) && routes(sub, item_id, item, triples, source_iri)) to.emplace_back(sub.agent, sub.slot);
  };
  for (std::uint32_t i : env.subs_any_context) consider(env.subs[i]);
  if (context) {
    if (auto found = env.subs_by_context.find(context); found != env.subs_by_context.end())
      for (std::uint32_t i : found->second) consider(env.subs[i]);
  }
  if (addressee_id && addressee_id != writer && receives(addressee_id))
    to.emplace_back(addressee_id, WakeBoard::slot_for(*addressee));
  std::sort(to.begin(), to.end());
  to.erase(std::unique(to.begin(), to.end()), to.end());
  return to;
}

// The terms of the records of item `item_id` that are still in the store.
Result<std::vector<std::array<std::uint64_t, 3>>> records_left(MDB_txn* txn, const Env& env, std::uint64_t item_id,
                                                               std::uint64_t count) {
  std::vector<std::array<std::uint64_t, 3>> triples;
  for (std::uint64_t id = item_id; id < item_id + count; ++id) {
    auto left = get_record(txn, env, id);
    if (!left) return unexpected(left.error());
    if (*left) triples.push_back({(*left)->s, (*left)->p, (*left)->o});
  }
  return triples;
}

// Adds to `to` (agent ids and wake slots, sorted) the agents of `remembered` (ItemRow::noticed)
// that still receive notices: they got the item, whatever routes it now.
Result<void> add_remembered(Txn& txn, const std::vector<std::uint64_t>& remembered,
                            std::vector<std::pair<std::uint64_t, std::uint32_t>>& to) {
  if (remembered.empty()) return {};
  TermReader terms(txn.raw(), txn.env());
  for (std::uint64_t agent : remembered) {
    if (!std::binary_search(txn.removal_receivers.begin(), txn.removal_receivers.end(), agent)) continue;
    if (std::any_of(to.begin(), to.end(), [&](const auto& r) { return r.first == agent; })) continue;
    auto iri = terms.iri(agent);
    if (!iri) return unexpected(iri.error());
    to.emplace_back(agent, WakeBoard::slot_for(*iri));
  }
  std::sort(to.begin(), to.end());
  return {};
}

}  // namespace

Result<Txn::NoticePlan*> notice_plan(Txn& txn, std::uint64_t item_id, const ItemRow& item, const RecordMeta& meta) {
  if (auto planned = txn.notice_plan_of.find(item_id); planned != txn.notice_plan_of.end())
    return planned->second == Txn::kNoNotice ? nullptr : &txn.notice_plans[planned->second];
  auto noticed = removals_noticed(txn);
  if (!noticed) return unexpected(noticed.error());
  if (!*noticed) return nullptr;
  // The item is whole here (its first record in this transaction has not gone yet): routed by
  // all of its records, as when it was stored.
  auto triples = records_left(txn.raw(), txn.env(), item_id, item.count);
  if (!triples) return unexpected(triples.error());
  auto to = notice_recipients(txn, item_id, item.source, meta.source, item.context, meta.context, item.output_buffer(), *triples);
  if (!to) return unexpected(to.error());
  if (auto r = add_remembered(txn, item.noticed, *to); !r) return unexpected(r.error());
  if (to->empty()) {
    txn.notice_plan_of.emplace(item_id, Txn::kNoNotice);
    return nullptr;
  }
  txn.notice_plans.push_back({txn.take_notice_seq(), std::move(*to), {}});
  txn.notice_plan_of.emplace(item_id, txn.notice_plans.size() - 1);
  return &txn.notice_plans.back();
}

Result<void> pass_notice_on(Txn& txn, const Item& notice, const std::vector<std::uint32_t>& positions,
                            const std::string& source, const std::string& writer_iri,
                            const std::vector<std::uint64_t>& held_items, const std::vector<std::uint64_t>& remembered) {
  auto noticed = removals_noticed(txn);
  if (!noticed) return unexpected(noticed.error());
  if (!*noticed) return {};
  MDB_txn* raw = txn.raw();
  const Env& env = txn.env();
  // Routed by the notice's triples (a term this store has never seen matches only an open
  // position) and what is left of the items its copies were in.
  std::vector<std::array<std::uint64_t, 3>> triples;
  for (const Triple& t : notice.triples) {
    std::array<std::uint64_t, 3> row{};
    const Term* terms[] = {&t.s, &t.p, &t.o};
    for (std::size_t pos = 0; pos < 3; ++pos) {
      if (terms[pos]->is_blank()) continue;
      auto id = find_term(raw, env, *terms[pos]);
      if (!id) return unexpected(id.error());
      row[pos] = *id;
    }
    triples.push_back(row);
  }
  for (std::uint64_t item_id : held_items) {
    auto row = get_item(raw, env, item_id);
    if (!row) return unexpected(row.error());
    if (!*row) continue;
    auto left = records_left(raw, env, item_id, (*row)->count);
    if (!left) return unexpected(left.error());
    triples.insert(triples.end(), left->begin(), left->end());
  }
  std::uint64_t ids[3] = {};
  const std::string* iris[] = {&source, &notice.context, &writer_iri};
  for (int k = 0; k < 3; ++k) {
    if (iris[k]->empty()) continue;
    auto id = find_term(raw, env, Term::iri(*iris[k]));
    if (!id) return unexpected(id.error());
    ids[k] = *id;
  }
  auto to = notice_recipients(txn, 0, ids[0], source, ids[1], notice.context, ids[2], triples);
  if (!to) return unexpected(to.error());
  if (auto r = add_remembered(txn, remembered, *to); !r) return unexpected(r.error());
  if (to->empty()) return {};
  Txn::NoticePlan plan{txn.take_notice_seq(), std::move(*to), {}};
  // As the sender's records: meta.id - meta.item is each one's position in its item.
  for (std::size_t i = 0; i < notice.triples.size(); ++i) {
    Record record;
    record.triple = notice.triples[i];
    record.meta.id = positions[i];
    record.meta.item = 0;
    record.meta.asserted_at = notice.asserted_at.value_or(0);
    record.meta.stored_at = record.meta.asserted_at;
    record.meta.source = source;
    record.meta.context = notice.context;
    record.meta.persistent = notice.persistent;
    record.meta.span = notice.span;
    plan.records.push_back(std::move(record));
  }
  txn.notice_plans.push_back(std::move(plan));
  return {};
}

Result<void> deliver_removals(Txn& txn) {
  if (txn.notice_plans.empty()) return {};
  std::vector<Txn::NoticePlan> plans;
  plans.swap(txn.notice_plans);
  txn.notice_plan_of.clear();
  Env& env = txn.env();
  if (env.notices == 0)
    return fail(Errc::io, "the store in " + env.dir().string() + " has no table of removal notices yet: open it once with write access");
  MDB_txn* raw = txn.raw();
  for (const Txn::NoticePlan& plan : plans) {
    if (plan.records.empty()) continue;
    std::string bytes = encode_notice(plan.to.size(), plan.records);
    MDB_val k = val(plan.id), v = val(bytes);
    if (int rc = mdb_put(raw, env.notices, &k, &v, 0); rc != 0) return lmdb_fail(rc, "writing a removal notice");
    for (const auto& [agent, slot] : plan.to) {
      MDB_val ak = val(agent), nv = val(plan.id);
      if (int rc = mdb_put(raw, env.inbox, &ak, &nv, 0); rc != 0) return lmdb_fail(rc, "putting a removal notice into an input buffer");
      ++txn.counters.pending;
      txn.wake_slots.push_back(slot);
    }
  }
  return {};
}

Result<std::uint64_t> insert_item(Txn& txn, const Item& item, const std::string& agent_iri,
                                  const std::string* relayed_source) {
  MDB_txn* raw = txn.raw();
  Env& env = txn.env();
  // Writer, source and context are pinned: after the first item, the caches know them.
  TermKey key;
  auto pinned_iri = [&](const std::string& iri, bool check) {
    const Term term = Term::iri(iri);
    term_key(term, key);
    return intern_keyed(txn, term, key, {.pin = true, .check_iri = check});
  };
  auto writer = pinned_iri(agent_iri, false);
  if (!writer) return writer;
  auto source = writer;
  if (relayed_source) {
    source = pinned_iri(*relayed_source, false);
    if (!source) return source;
  }
  std::uint64_t context = 0;
  if (!item.context.empty()) {
    auto ctx = pinned_iri(item.context, true);
    if (!ctx) return fail(ctx.error().code, "context: " + ctx.error().message);
    context = *ctx;
  }
  const std::uint64_t item_id = txn.counters.next_seq;
  std::unordered_map<std::string, std::uint64_t> blanks;
  std::vector<std::array<std::uint64_t, 3>> ids;
  ids.reserve(item.triples.size());
  bool declares_subscription = false;
  bool states_a_pattern = false;  // tv:subject, tv:predicate or tv:object: a subscription's pattern
  for (std::size_t i = 0; i < item.triples.size(); ++i) {
    const Triple& t = item.triples[i];
    std::array<std::uint64_t, 3> row{};
    const Term* terms[] = {&t.s, &t.p, &t.o};
    for (int pos = 0; pos < 3; ++pos) {
      auto id = term_id(txn, *terms[pos], pos, blanks, key);
      if (!id) return fail(id.error().code, "triple " + std::to_string(i + 1) + ", " + position_name(pos) + ": " + id.error().message);
      row[pos] = *id;
    }
    std::uint64_t record_id = txn.counters.next_seq++;
    std::string bytes = encode_record(record_id, RecordRow{row[0], row[1], row[2], item_id});
    MDB_val k = val(record_id), v = val(bytes);
    int rc = mdb_put(raw, env.records, &k, &v, MDB_APPEND);
    if (rc != 0) return lmdb_fail(rc, "writing a record");
    txn.unflushed_index.push_back({env.idx_s, row[0], record_id});
    txn.unflushed_index.push_back({env.idx_p, row[1], record_id});
    txn.unflushed_index.push_back({env.idx_o, row[2], record_id});
    if (row[1] == env.vocab.subscriber) {
      declares_subscription = true;
      // The subscriber's IRI keys its input buffer: pinned, so its id never changes.
      if (auto p = pin_term(txn, row[2]); !p) return unexpected(p.error());
    }
    states_a_pattern = states_a_pattern || row[1] == env.vocab.subject || row[1] == env.vocab.predicate ||
                       row[1] == env.vocab.object;
    ids.push_back(row);
  }
  const std::int64_t now = now_ns();
  // A subscription is kept as long as it is not removed: written as plain data on a ring store,
  // the ring would reclaim it and the agent would stop receiving, silently (R9). Its pattern
  // too when written apart (one item per predicate, as a reasoner writes): reclaimed, it left a
  // subscription that matches every item.
  const bool persistent = item.persistent || declares_subscription || states_a_pattern;
  ItemRow meta{ids.size(), ids.size(), 0, now, item.asserted_at.value_or(now), item.span, *source, context,
               persistent, *writer != *source ? *writer : 0};
  if (auto r = refresh_caches(txn); !r) return unexpected(r.error());
  if (auto r = removals_noticed(txn); !r) return unexpected(r.error());
  if (auto r = route(txn, item_id, meta, ids, relayed_source ? *relayed_source : agent_iri); !r)
    return unexpected(r.error());
  if (context) {
    auto normal = uri::normalize(item.context);
    if (normal) {
      if (auto r = route_to_addressee(txn, item_id, meta, *normal, agent_iri); !r) return unexpected(r.error());
    }
  }
  if (auto r = put_item(txn, item_id, meta, MDB_APPEND); !r) return unexpected(r.error());
  txn.unflushed_index.push_back({env.outbox, *writer, item_id});
  txn.unflushed_index.push_back({env.by_time, time_key(meta.asserted_at), item_id});
  txn.counters.max_span = std::max(txn.counters.max_span, static_cast<std::uint64_t>(meta.span));
  if (!persistent) {
    txn.counters.ring_records += ids.size();
  } else {
    txn.counters.persistent_records += ids.size();
  }
  txn.counters.records += ids.size();
  ++txn.counters.items;
  if (declares_subscription) {
    // The process's cache, current before this item, takes its subscriptions as they are
    // instead of reloading them all at the next write.
    std::lock_guard lock(env.cache_mutex);
    const bool cache_current = env.subs_gen == txn.counters.sub_gen;
    ++txn.counters.sub_gen;
    ++txn.counters.subscriptions;
    if (cache_current) {
      if (auto declared = subscriptions_declared_by(env, item, item_id, ids)) {
        for (Subscription& sub : *declared) add_to_cache(env, std::move(sub));
        env.subs_gen = txn.counters.sub_gen;
        txn.touched_caches = true;
      }
    }
  }
  return item_id;
}

WriteBound write_bound(const Item& item) {
  // Rows of a triple (record, three index entries, its share of the item row and of the output
  // and input buffers) are under a hundred bytes; pages split half full and copied on write make
  // 512 a bound. A term longer than a quarter page goes to overflow pages: its size rounded up
  // to a page, with its header.
  constexpr std::uint64_t kPerTriple = 512;
  static const std::uint64_t page = static_cast<std::uint64_t>(std::max(4096L, sysconf(_SC_PAGESIZE)));
  WriteBound bound;
  bound.triples = item.triples.size();
  for (const Triple& t : item.triples) {
    bound.bytes += kPerTriple;
    for (const Term* term : {&t.s, &t.p, &t.o}) {
      const std::uint64_t size = term->value.size() + term->datatype.size() + term->language.size();
      if (size <= page / 4) {
        bound.bytes += size;
        continue;
      }
      bound.bytes += size + page;
      bound.large_term_bytes += size + page;
    }
  }
  return bound;
}

Result<std::uint64_t> apply_retention(Txn& txn) {
  if (auto r = refresh_caches(txn); !r) return unexpected(r.error());
  auto ring = apply_ring(txn);
  if (!ring) return ring;
  std::vector<TtlRule> rules;
  {
    std::lock_guard lock(txn.env().cache_mutex);
    rules = txn.env().ttl_rules;
  }
  if (rules.empty()) return *ring;
  auto ttl = apply_ttl(txn, rules);
  if (!ttl) return ttl;
  return *ring + *ttl;
}

namespace {

// Whether item `item_id` reaches the agent `agent_iri` without a new subscription: it is
// addressed to it or to something under it (R18), or one of `subs` (the agent's) routes it.
Result<bool> reaches_anyway(Txn& txn, TermReader& terms, std::uint64_t item_id, const ItemRow& item,
                            const std::string& agent_iri, const std::vector<Subscription>& subs) {
  if (item.context) {
    auto context = terms.iri(item.context);
    if (!context) return unexpected(context.error());
    if (*context == agent_iri || uri::is_under(*context, agent_iri)) return true;
  }
  std::vector<std::array<std::uint64_t, 3>> triples;
  for (std::uint64_t id = item_id; id < item_id + item.count; ++id) {
    auto record = get_record(txn.raw(), txn.env(), id);
    if (!record) return unexpected(record.error());
    if (*record) triples.push_back({(*record)->s, (*record)->p, (*record)->o});
  }
  auto source = terms.iri(item.source);
  if (!source) return unexpected(source.error());
  return std::any_of(subs.begin(), subs.end(), [&](const Subscription& sub) {
    return (!sub.context || sub.context == item.context) && routes(sub, item_id, item, triples, *source);
  });
}

}  // namespace

Result<std::uint64_t> withdraw_unrouted(Txn& txn, std::uint64_t agent, const std::string& agent_iri, std::uint64_t after) {
  if (auto r = refresh_caches(txn); !r) return unexpected(r.error());
  std::vector<std::uint64_t> waiting;
  {
    MDB_cursor* cursor = nullptr;
    int rc = mdb_cursor_open(txn.raw(), txn.env().inbox, &cursor);
    if (rc != 0) return lmdb_fail(rc, "opening the input buffers");
    MDB_val k = val(agent), v;
    for (rc = mdb_cursor_get(cursor, &k, &v, MDB_SET); rc == 0; rc = mdb_cursor_get(cursor, &k, &v, MDB_NEXT_DUP))
      if (u64(v) > after) waiting.push_back(u64(v));
    mdb_cursor_close(cursor);
    if (rc != MDB_NOTFOUND) return lmdb_fail(rc, "reading an input buffer");
  }
  std::vector<Subscription> own;
  {
    std::lock_guard lock(txn.env().cache_mutex);
    for (const Subscription& sub : txn.env().subs)
      if (sub.agent == agent) own.push_back(sub);
  }
  TermReader terms(txn.raw(), txn.env());
  std::uint64_t withdrawn = 0;
  for (const std::uint64_t item_id : waiting) {
    auto row = get_item(txn.raw(), txn.env(), item_id);
    if (!row) return unexpected(row.error());
    if (!*row) continue;  // removed; the buffer entry goes when it is taken
    ItemRow item = **row;
    auto routed = reaches_anyway(txn, terms, item_id, item, agent_iri, own);
    if (!routed) return unexpected(routed.error());
    if (*routed) continue;
    MDB_val k = val(agent), v = val(item_id);
    if (int rc = mdb_del(txn.raw(), txn.env().inbox, &k, &v); rc != 0) return lmdb_fail(rc, "withdrawing from an input buffer");
    if (txn.counters.pending > 0) --txn.counters.pending;
    if (item.pending > 0) --item.pending;
    // Nor does its removal go to the agent: a notice carries the records, which the narrowed
    // policy keeps here. (One the parent had not acknowledged may have gone up: its copy there
    // stays when the item is removed here.)
    std::erase(item.noticed, agent);
    if (auto put = put_item(txn, item_id, item); !put) return unexpected(put.error());
    if (item.pending == 0 && !item.persistent)
      if (auto noted = note_released(txn, item_id); !noted) return unexpected(noted.error());
    ++withdrawn;
  }
  return withdrawn;
}

namespace {

// Puts the items `ids` (ascending) into the agent's input buffer, but those there already (and,
// with persistent_only, those not persistent); returns how many went in.
Result<std::uint64_t> deliver_items(Txn& txn, std::uint64_t agent, const std::string& agent_iri,
                                    const std::vector<std::uint64_t>& ids, bool persistent_only,
                                    std::uint64_t given_by = 0) {
  if (auto r = removals_noticed(txn); !r) return unexpected(r.error());  // read by deliver
  const std::uint32_t slot = WakeBoard::slot_for(agent_iri);
  std::uint64_t delivered = 0;
  for (const std::uint64_t item_id : ids) {
    auto row = get_item(txn.raw(), txn.env(), item_id);
    if (!row) return unexpected(row.error());
    if (!*row || (persistent_only && !(*row)->persistent)) continue;
    // Stored before the subscription `given_by` and never put into the agent's buffer since (an
    // agent that receives removal notices is remembered on every item it is given): the item
    // did not go to the agent, and going again would send it where it never went.
    if (given_by != 0 && item_id <= given_by &&  // a subscription does not route itself (R10)
        std::find((*row)->noticed.begin(), (*row)->noticed.end(), agent) == (*row)->noticed.end())
      continue;
    ItemRow item = **row;
    const std::uint64_t pending = item.pending;
    if (auto d = deliver(txn, agent, slot, item_id, item); !d) return unexpected(d.error());
    if (item.pending == pending) continue;  // in the buffer already
    if (auto put = put_item(txn, item_id, item); !put) return unexpected(put.error());
    ++delivered;
  }
  return delivered;
}

}  // namespace

namespace {

// The persistent items written with exactly the context `context` before `before`, by reading
// the items' rows (a context has no index; there are fewer items than records, and a row says
// both the context and whether the item is persistent).
Result<std::vector<std::uint64_t>> persistent_items_with_context(Txn& txn, const std::string& context, std::uint64_t before) {
  std::vector<std::uint64_t> items;
  auto context_id = find_term(txn.raw(), txn.env(), Term::iri(context));
  if (!context_id) return unexpected(context_id.error());
  if (*context_id == 0) return items;  // never written: nothing has it
  MDB_cursor* cursor = nullptr;
  int rc = mdb_cursor_open(txn.raw(), txn.env().items, &cursor);
  if (rc != 0) return lmdb_fail(rc, "opening the items");
  MDB_val k, v;
  for (rc = mdb_cursor_get(cursor, &k, &v, MDB_FIRST); rc == 0; rc = mdb_cursor_get(cursor, &k, &v, MDB_NEXT)) {
    if (u64(k) >= before) break;
    ItemRow row;
    if (decode_item(view(v), row) && row.persistent && row.live != 0 && row.context == *context_id) items.push_back(u64(k));
  }
  mdb_cursor_close(cursor);
  if (rc != 0 && rc != MDB_NOTFOUND) return lmdb_fail(rc, "reading the items");
  return items;
}

}  // namespace

namespace {

// The items with an id below `before` that have a record matching `pattern`, ascending. Ids
// first, then the buffer: Query reads the indexes the deliveries would write beside.
Result<std::vector<std::uint64_t>> items_matching(Txn& txn, const Pattern& pattern, std::uint64_t before) {
  std::vector<std::uint64_t> items;
  Query query(txn.raw(), txn.env());
  auto walked = query.for_each(pattern, [&](std::uint64_t id, const RecordRow& row) {
    if (id >= before) return false;  // ascending ids: nothing earlier follows
    // after_id bounds record ids; an item at or before it whose matching record is a later
    // one of its own (an HRV window's second triple) is not after it.
    if (pattern.after_id && row.item <= *pattern.after_id) return true;
    if (items.empty() || items.back() != row.item) items.push_back(row.item);
    return true;
  });
  if (!walked) return unexpected(walked.error());
  std::sort(items.begin(), items.end());
  items.erase(std::unique(items.begin(), items.end()), items.end());
  return items;
}

// The pattern `sub` routes by: its s, p, o, context and source.
Result<Pattern> pattern_of(const Subscription& sub, TermReader& reader) {
  Pattern pattern;
  std::optional<Term>* positions[] = {&pattern.s, &pattern.p, &pattern.o};
  const std::uint64_t ids[] = {sub.s, sub.p, sub.o};
  for (int k = 0; k < 3; ++k) {
    if (ids[k] == 0) continue;
    auto term = reader.get(ids[k]);
    if (!term) return unexpected(term.error());
    *positions[k] = std::move(*term);
  }
  if (sub.context) {
    auto context = reader.iri(sub.context);
    if (!context) return unexpected(context.error());
    pattern.context = *context;
  }
  if (sub.source) pattern.source = sub.source_iri;
  return pattern;
}

}  // namespace

Result<std::uint64_t> deliver_earlier(Txn& txn, std::uint64_t agent, const std::string& agent_iri,
                                      const Pattern& pattern, std::uint64_t before, bool persistent_only,
                                      std::uint64_t given_by) {
  if (auto f = flush_index(txn); !f) return unexpected(f.error());
  // A child's down queue on a parent (P11): its subscription names a context only. Walking the
  // records for it took a hospital's writer for seconds at each new home.
  // Every persistent item before it went to the agent when it subscribed (SubscribeOptions::
  // earlier, persistent_only), so the check of what it was given is not made: a parent store of a
  // build that subscribed before receiving removal notices remembered none of them as given.
  if (persistent_only && !pattern.s && !pattern.p && !pattern.o && !pattern.source && pattern.context &&
      !pattern.context->empty()) {
    auto items = persistent_items_with_context(txn, *pattern.context, before);
    if (!items) return unexpected(items.error());
    return deliver_items(txn, agent, agent_iri, *items, true);
  }
  auto items = items_matching(txn, pattern, before);
  if (!items) return unexpected(items.error());
  return deliver_items(txn, agent, agent_iri, *items, persistent_only, given_by);
}

Result<std::uint64_t> deliver_missed(Txn& txn, std::span<const MissedSince> missed, std::uint64_t older_than) {
  if (auto r = refresh_caches(txn); !r) return unexpected(r.error());
  if (auto f = flush_index(txn); !f) return unexpected(f.error());
  std::vector<Subscription> subs;
  {
    std::lock_guard lock(txn.env().cache_mutex);
    subs = txn.env().subs;
  }
  TermReader reader(txn.raw(), txn.env());
  std::uint64_t delivered = 0;
  for (const MissedSince& late : missed) {
    auto sub = std::find_if(subs.begin(), subs.end(), [&](const Subscription& s) { return s.item == late.subscription; });
    if (sub == subs.end()) continue;  // removed meanwhile
    auto agent_iri = reader.iri(sub->agent);
    if (!agent_iri) return unexpected(agent_iri.error());
    auto pattern = pattern_of(*sub, reader);
    if (!pattern) return unexpected(pattern.error());
    if (late.after != 0) pattern->after_id = late.after;
    auto candidates = items_matching(txn, *pattern, late.subscription);
    if (!candidates) return unexpected(candidates.error());
    std::vector<Subscription> older;
    for (const Subscription& s : subs)
      if (s.agent == sub->agent && s.item < older_than) older.push_back(s);
    // What the subscriber got anyway, or has waiting: an item its older subscriptions route,
    // or one addressed to it (R18).
    std::vector<std::uint64_t> items;
    for (const std::uint64_t item_id : *candidates) {
      auto row = get_item(txn.raw(), txn.env(), item_id);
      if (!row) return unexpected(row.error());
      if (!*row) continue;
      auto got_anyway = reaches_anyway(txn, reader, item_id, **row, *agent_iri, older);
      if (!got_anyway) return unexpected(got_anyway.error());
      if (!*got_anyway) items.push_back(item_id);
    }
    auto n = deliver_items(txn, sub->agent, *agent_iri, items, false);
    if (!n) return unexpected(n.error());
    delivered += *n;
  }
  return delivered;
}

namespace {

// The term ids of `triples`, 0 for a blank node (a blank node's label is the sending store's
// own); nullopt when a term is one this store has never seen, so that nothing can match.
Result<std::optional<std::vector<std::array<std::uint64_t, 3>>>> ids_of(MDB_txn* txn, const Env& env,
                                                                          const std::vector<Triple>& triples) {
  std::vector<std::array<std::uint64_t, 3>> wanted;
  wanted.reserve(triples.size());
  for (const Triple& t : triples) {
    std::array<std::uint64_t, 3> row{};
    const Term* terms[] = {&t.s, &t.p, &t.o};
    for (int pos = 0; pos < 3; ++pos) {
      if (terms[pos]->is_blank()) continue;
      auto id = find_term(txn, env, *terms[pos]);
      if (!id) return unexpected(id.error());
      if (*id == 0) return std::optional<std::vector<std::array<std::uint64_t, 3>>>();
      row[static_cast<std::size_t>(pos)] = *id;
    }
    wanted.push_back(row);
  }
  return std::optional<std::vector<std::array<std::uint64_t, 3>>>(std::move(wanted));
}

// Whether a record's terms are `wanted` (ids_of), a 0 matching any blank node.
Result<bool> same_triple(TermReader& terms, const RecordRow& have, const std::array<std::uint64_t, 3>& wanted) {
  const std::uint64_t ids[] = {have.s, have.p, have.o};
  for (std::size_t pos = 0; pos < 3; ++pos) {
    if (wanted[pos] != 0) {
      if (ids[pos] != wanted[pos]) return false;
      continue;
    }
    auto term = terms.get(ids[pos]);
    if (!term) return unexpected(term.error());
    if (!term->is_blank()) return false;
  }
  return true;
}

// Record ids under `key` in index `dbi`.
Result<std::vector<std::uint64_t>> indexed(MDB_txn* txn, MDB_dbi dbi, std::uint64_t key) {
  MDB_cursor* cursor = nullptr;
  if (int rc = mdb_cursor_open(txn, dbi, &cursor); rc != 0) return lmdb_fail(rc, "opening an index");
  std::vector<std::uint64_t> records;
  MDB_val k = val(key), v;
  int rc = mdb_cursor_get(cursor, &k, &v, MDB_SET);
  for (; rc == 0; rc = mdb_cursor_get(cursor, &k, &v, MDB_NEXT_DUP)) records.push_back(u64(v));
  mdb_cursor_close(cursor);
  if (rc != MDB_NOTFOUND) return lmdb_fail(rc, "walking an index");
  return records;
}

}  // namespace

Result<HeldRepeat> held_twin(MDB_txn* txn, const Env& env, const Item& item, const std::string& source,
                             std::uint64_t namesakes_before) {
  if (!item.asserted_at || item.triples.empty() || !env.by_time) return HeldRepeat{};
  auto source_id = find_term(txn, env, Term::iri(source));
  if (!source_id) return unexpected(source_id.error());
  if (*source_id == 0) return HeldRepeat{};
  std::uint64_t context_id = 0;
  if (!item.context.empty()) {
    auto c = find_term(txn, env, Term::iri(item.context));
    if (!c) return unexpected(c.error());
    if (*c == 0) return HeldRepeat{};
    context_id = *c;
  }
  // A term this store has never met is in no item held here (blank nodes match any blank node).
  auto found = ids_of(txn, env, item.triples);
  if (!found) return unexpected(found.error());
  // What a recomputed item shares with the one held is its name, its first subject; its other
  // terms (the items it was derived from, cut otherwise) may be new here.
  std::uint64_t name_id = 0;
  if (namesakes_before > 0 && item.triples.front().s.is_iri()) {
    if (*found) {
      name_id = (**found)[0][0];
    } else {
      auto name = find_term(txn, env, item.triples.front().s);
      if (!name) return unexpected(name.error());
      name_id = *name;
    }
  }
  if (!*found && name_id == 0) return HeldRepeat{};
  // The candidates are the items asserted at the same nanosecond: the time index's entries.
  auto candidates = indexed(txn, env.by_time, time_key(*item.asserted_at));
  if (!candidates) return unexpected(candidates.error());
  TermReader terms(txn, env);
  HeldRepeat namesake;
  for (std::uint64_t candidate : *candidates) {
    auto row = get_item(txn, env, candidate);
    if (!row) return unexpected(row.error());
    if (!*row) continue;
    const ItemRow& it = **row;
    if (it.persistent != item.persistent || it.source != *source_id || it.asserted_at != *item.asserted_at ||
        it.context != context_id || it.live != it.count)
      continue;
    if (*found && it.count == (*found)->size()) {
      bool same = true;
      for (std::size_t i = 0; i < (*found)->size() && same; ++i) {
        auto r = get_record(txn, env, candidate + i);
        if (!r) return unexpected(r.error());
        if (!*r) {
          same = false;
          break;
        }
        auto matches = same_triple(terms, **r, (**found)[i]);
        if (!matches) return unexpected(matches.error());
        same = *matches;
      }
      if (same) return HeldRepeat{candidate, false};
    }
    // An item's id is its first record's.
    if (name_id != 0 && namesake.id == 0 && candidate < namesakes_before) {
      auto first = get_record(txn, env, candidate);
      if (!first) return unexpected(first.error());
      if (*first && (*first)->s == name_id) namesake = HeldRepeat{candidate, true};
    }
  }
  return namesake;
}

Result<HeldRepeat> held_persistent_twin(MDB_txn* txn, const Env& env, const Item& item, const std::string& source) {
  if (!item.persistent) return HeldRepeat{};
  return held_twin(txn, env, item, source);
}

Result<HeldCopies> held_copies(MDB_txn* txn, const Env& env, const Item& notice, const std::vector<std::uint32_t>& positions,
                               const std::string& source) {
  HeldCopies out;
  if (!notice.asserted_at || positions.size() != notice.triples.size()) return out;
  auto source_id = find_term(txn, env, Term::iri(source));
  if (!source_id) return unexpected(source_id.error());
  if (*source_id == 0) return out;
  std::uint64_t context_id = 0;
  if (!notice.context.empty()) {
    auto c = find_term(txn, env, Term::iri(notice.context));
    if (!c) return unexpected(c.error());
    if (*c == 0) return out;
    context_id = *c;
  }
  // Each triple's term ids; a triple with a term this store has never seen is held nowhere here.
  std::vector<std::optional<std::array<std::uint64_t, 3>>> wanted;
  for (const Triple& triple : notice.triples) {
    auto found = ids_of(txn, env, {triple});
    if (!found) return unexpected(found.error());
    wanted.push_back(*found ? std::optional((**found)[0]) : std::nullopt);
  }
  // The copies are found through the shortest index list of any of the notice's terms that is
  // not a blank node (a record about a common class or predicate is one of millions), at the
  // triple's position in its item (relaying keeps the order of an item's triples; so a blank
  // node names the same node in every triple of the notice that has it).
  MDB_cursor* cursor[3] = {};
  const MDB_dbi dbis[3] = {env.idx_s, env.idx_p, env.idx_o};
  for (int pos = 0; pos < 3; ++pos)
    if (int rc = mdb_cursor_open(txn, dbis[pos], &cursor[pos]); rc != 0) {
      for (MDB_cursor* c : cursor)
        if (c) mdb_cursor_close(c);
      return lmdb_fail(rc, "opening an index");
    }
  std::size_t anchor = 0, anchor_pos = 0, fewest = SIZE_MAX;
  for (std::size_t i = 0; i < wanted.size(); ++i) {
    if (!wanted[i]) continue;
    for (std::size_t pos = 0; pos < 3; ++pos) {
      if ((*wanted[i])[pos] == 0) continue;
      MDB_val k = val((*wanted[i])[pos]), v;
      std::size_t n = 0;
      if (mdb_cursor_get(cursor[pos], &k, &v, MDB_SET) == 0) mdb_cursor_count(cursor[pos], &n);
      if (n < fewest) {
        fewest = n;
        anchor = i;
        anchor_pos = pos;
      }
    }
  }
  for (MDB_cursor* c : cursor) mdb_cursor_close(c);
  if (fewest == SIZE_MAX || fewest == 0) return out;
  auto candidates = indexed(txn, dbis[anchor_pos], (*wanted[anchor])[anchor_pos]);
  if (!candidates) return unexpected(candidates.error());
  TermReader terms(txn, env);
  for (std::uint64_t record : *candidates) {
    auto row = get_record(txn, env, record);
    if (!row) return unexpected(row.error());
    if (!*row || record - (*row)->item != positions[anchor]) continue;
    const std::uint64_t item_id = (*row)->item;
    if (std::find(out.items.begin(), out.items.end(), item_id) != out.items.end()) continue;
    auto it = get_item(txn, env, item_id);
    if (!it) return unexpected(it.error());
    if (!*it || (*it)->source != *source_id || (*it)->asserted_at != *notice.asserted_at || (*it)->context != context_id)
      continue;
    std::vector<std::uint64_t> found;
    for (std::size_t i = 0; i < wanted.size(); ++i) {
      if (!wanted[i] || positions[i] >= (*it)->count) continue;
      auto copy = get_record(txn, env, item_id + positions[i]);
      if (!copy) return unexpected(copy.error());
      if (!*copy) continue;
      auto same = same_triple(terms, **copy, *wanted[i]);
      if (!same) return unexpected(same.error());
      if (*same) found.push_back(item_id + positions[i]);
    }
    if (found.empty()) continue;
    out.items.push_back(item_id);
    out.records.insert(out.records.end(), found.begin(), found.end());
  }
  std::sort(out.records.begin(), out.records.end());
  out.records.erase(std::unique(out.records.begin(), out.records.end()), out.records.end());
  return out;
}

Result<std::uint64_t> deliver_again(Txn& txn, std::uint64_t agent, const std::string& agent_iri, bool persistent_only,
                                    std::uint64_t after, std::uint64_t before, const std::string& source_under) {
  auto subs = load_subscriptions(txn);
  if (!subs) return unexpected(subs.error());
  TermReader reader(txn.raw(), txn.env());
  std::uint64_t delivered = 0;
  for (const Subscription& sub : *subs) {
    if (sub.agent != agent) continue;
    auto routed_by = pattern_of(sub, reader);
    if (!routed_by) return unexpected(routed_by.error());
    Pattern& pattern = *routed_by;
    if (!source_under.empty()) {
      // Both bounds: the narrower, or nothing when neither lies under the other.
      if (!pattern.source || uri::is_under(*pattern.source, source_under)) {
        if (!pattern.source) pattern.source = source_under;
      } else if (uri::is_under(source_under, *pattern.source)) {
        pattern.source = source_under;
      } else {
        continue;
      }
    }
    if (after != 0) pattern.after_id = after;
    auto n = deliver_earlier(txn, agent, agent_iri, pattern, before, persistent_only, sub.item);
    if (!n) return unexpected(n.error());
    delivered += *n;
  }
  return delivered;
}

Result<std::uint64_t> deliver_persistent_again(Txn& txn, std::uint64_t agent, const std::string& agent_iri,
                                               bool addressed_too) {
  auto subscribed = deliver_again(txn, agent, agent_iri, true, 0, std::numeric_limits<std::uint64_t>::max(), {});
  if (!subscribed) return unexpected(subscribed.error());
  const std::uint64_t delivered = *subscribed;
  if (!addressed_too) return delivered;
  // And those addressed to it (R18: a context under its IRI), which no subscription names: the
  // settings written on a parent for a child's node, which its link agent there carries down.
  // Items carry no context index, so this reads every item's row once: when a child's store was
  // made again, not in the course of things. The context is taken in normal form and the
  // writer is the item's output buffer, as when the item was stored and routed.
  if (auto f = flush_index(txn); !f) return unexpected(f.error());
  const std::string& node_iri = txn.env().settings().iri;
  TermReader reader(txn.raw(), txn.env());
  std::vector<std::uint64_t> addressed;
  {
    MDB_cursor* cursor = nullptr;
    int rc = mdb_cursor_open(txn.raw(), txn.env().items, &cursor);
    if (rc != 0) return lmdb_fail(rc, "opening the items");
    auto fail_with = [&](const Error& e) {
      mdb_cursor_close(cursor);
      return unexpected(e);
    };
    MDB_val k, v;
    for (rc = mdb_cursor_get(cursor, &k, &v, MDB_FIRST); rc == 0; rc = mdb_cursor_get(cursor, &k, &v, MDB_NEXT)) {
      ItemRow row;
      if (!decode_item(view(v), row) || !row.persistent || !row.context || row.live == 0) continue;
      auto context = reader.iri(row.context);
      if (!context) return fail_with(context.error());
      auto normal = uri::normalize(*context);
      auto writer = reader.iri(row.output_buffer());
      if (!writer) return fail_with(writer.error());
      if (addressee_of(node_iri, normal ? *normal : *context, *writer) == agent_iri) addressed.push_back(u64(k));
    }
    mdb_cursor_close(cursor);
    if (rc != MDB_NOTFOUND) return lmdb_fail(rc, "reading the items");
  }
  if (addressed.empty()) return delivered;
  auto n = deliver_items(txn, agent, agent_iri, addressed, true);
  if (!n) return unexpected(n.error());
  return delivered + *n;
}

}  // namespace tahvel::node::detail
