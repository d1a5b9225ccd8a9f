// Node, Agent and Snapshot: the public C++ API over the environment, the query engine and the
// write path.
#include "tahvel/node/node.h"

#include <fcntl.h>
#include <stdio.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <limits>
#include <map>
#include <span>
#include <sstream>
#include <type_traits>

#include "check.h"
#include "dictionary.h"
#include "env.h"
#include "query.h"
#include "rows.h"
#include "write.h"

namespace tahvel::node {

using namespace detail;

namespace {

constexpr std::string_view kSubscriber = "https://w3id.org/tahvel#subscriber";
constexpr std::string_view kSubject = "https://w3id.org/tahvel#subject";
constexpr std::string_view kPredicate = "https://w3id.org/tahvel#predicate";
constexpr std::string_view kObject = "https://w3id.org/tahvel#object";

// A call on a handle whose contents were moved into another: an error, as a closed C handle
// gives, not a null dereference.
Unexpected<Error> moved_from() {
  return fail(Errc::invalid_argument, "this handle was moved from: use the one it was moved into");
}

// A read transaction that ends when it goes out of scope.
struct ReadTxn {
  Env& env;
  MDB_txn* txn = nullptr;
  explicit ReadTxn(Env& e) : env(e) {}
  ~ReadTxn() { if (txn) env.end_read(txn); }
  Result<void> begin() {
    auto t = env.begin_read();
    if (!t) return unexpected(t.error());
    txn = *t;
    return {};
  }
};

Result<void> load_vocabulary(Env& env) {
  // Once per Env: a later Node::open on another thread must not write `vocab` while a writer of
  // this process reads it (the ids are fixed, but the stores would be a data race).
  std::lock_guard lock(env.vocab_mutex);
  if (env.vocab_loaded) return {};
  ReadTxn read(env);
  if (auto r = read.begin(); !r) return r;
  std::uint64_t* slots[] = {&env.vocab.subscriber, &env.vocab.subject, &env.vocab.predicate, &env.vocab.object};
  std::string_view iris[] = {kSubscriber, kSubject, kPredicate, kObject};
  for (int i = 0; i < 4; ++i) {
    auto id = find_term(read.txn, env, Term::iri(std::string(iris[i])));
    if (!id) return unexpected(id.error());
    if (*id == 0) return fail(Errc::corrupt, env.dir().string() + ": vocabulary term missing: " + std::string(iris[i]));
    *slots[i] = *id;
  }
  env.vocab_loaded = true;
  return {};
}

Result<std::vector<Record>> materialize_all(Query& query, const std::vector<std::uint64_t>& ids) {
  std::vector<Record> out;
  out.reserve(ids.size());
  for (std::uint64_t id : ids) {
    auto rec = query.record(id);
    if (!rec) return unexpected(rec.error());
    if (*rec) out.push_back(std::move(**rec));
  }
  return out;
}

Result<std::vector<Record>> item_records(MDB_txn* txn, const Env& env, std::uint64_t item_id) {
  auto item = get_item(txn, env, item_id);
  if (!item) return unexpected(item.error());
  if (!*item) return fail(Errc::not_found, "no item " + std::to_string(item_id) + " in " + env.dir().string());
  Query query(txn, env);
  std::vector<std::uint64_t> ids;
  for (std::uint64_t id = item_id; id < item_id + (*item)->count; ++id) ids.push_back(id);
  return materialize_all(query, ids);
}

Error with_context(const Error& e, std::string_view what) { return Error{e.code, std::string(what) + ": " + e.message}; }

// Entry `id` of an input buffer as it is delivered: an item's records, or a removal notice's
// (R21); nullopt when neither is there any more (the item was removed since).
Result<std::optional<Delivery>> buffered(MDB_txn* txn, const Env& env, std::uint64_t id) {
  auto records = item_records(txn, env, id);
  if (records) return std::optional<Delivery>(Delivery{id, std::move(*records)});
  if (records.error().code != Errc::not_found) return unexpected(records.error());
  auto notice = get_notice(txn, env, id);
  if (!notice) return unexpected(notice.error());
  if (!*notice) return std::optional<Delivery>();
  return std::optional<Delivery>(Delivery{id, std::move(**notice), true});
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// Snapshot

struct Snapshot::Impl {
  std::shared_ptr<Env> env;
  MDB_txn* txn = nullptr;
  std::uint64_t last_seq = 0;
  std::uint64_t notice_seqs = 0;
  ~Impl() { if (txn) env->end_read(txn); }

  // A snapshot of the store as of now (Node::snapshot).
  static Result<Snapshot> open(const std::shared_ptr<Env>& env);
};

Snapshot::Snapshot(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}

Result<Snapshot> Snapshot::Impl::open(const std::shared_ptr<Env>& env) {
  auto impl = std::make_unique<Snapshot::Impl>();
  impl->env = env;
  auto txn = env->begin_read();
  if (!txn) return unexpected(txn.error());
  impl->txn = *txn;
  auto counters = load_counters(impl->txn, env->main);
  if (!counters) return unexpected(counters.error());
  impl->last_seq = counters->next_seq - 1;
  impl->notice_seqs = read_notice_seqs(impl->txn, env->meta);
  return Snapshot(std::move(impl));
}
Snapshot::Snapshot(Snapshot&&) noexcept = default;
Snapshot& Snapshot::operator=(Snapshot&&) noexcept = default;
Snapshot::~Snapshot() = default;

Result<std::vector<Record>> Snapshot::list(const Pattern& pattern, const ListOptions& options) const {
  if (!impl_) return moved_from();
  Query query(impl_->txn, *impl_->env);
  auto ids = query.collect(pattern, options);
  if (!ids) return unexpected(ids.error());
  return materialize_all(query, *ids);
}

Result<void> Snapshot::for_each(const Pattern& pattern, const std::function<bool(const Record&)>& visit) const {
  if (!impl_) return moved_from();
  Query query(impl_->txn, *impl_->env);
  std::optional<Error> failure;
  auto walked = query.for_each(pattern, [&](std::uint64_t id, const RecordRow& row) {
    auto rec = query.materialize(id, row);
    if (!rec) {
      failure = rec.error();
      return false;
    }
    return visit(*rec);
  });
  if (!walked) return walked;
  if (failure) return unexpected(*failure);
  return {};
}

Result<std::uint64_t> Snapshot::count(const Pattern& pattern) const {
  if (!impl_) return moved_from();
  Query query(impl_->txn, *impl_->env);
  std::uint64_t n = 0;
  auto walked = query.for_each(pattern, [&](std::uint64_t, const RecordRow&) { ++n; return true; });
  if (!walked) return unexpected(walked.error());
  return n;
}

namespace {

// Calls visit(cursor, key, first value, values) once for each key of the dupsort table `dbi`,
// the cursor on that key's first value; the summaries of predicates() and input_buffers() are
// read so, a step per key rather than a scan. `what` names the table in an error.
template <class Visit>
Result<void> for_each_key(MDB_txn* txn, MDB_dbi dbi, const std::string& what, Visit visit) {
  Cursor cursor;
  if (int rc = mdb_cursor_open(txn, dbi, &cursor.c); rc != 0) return lmdb_fail(rc, "reading " + what);
  MDB_val key, first;
  for (int rc = mdb_cursor_get(cursor.c, &key, &first, MDB_FIRST); rc != MDB_NOTFOUND;
       rc = mdb_cursor_get(cursor.c, &key, &first, MDB_NEXT_NODUP)) {
    if (rc != 0) return lmdb_fail(rc, "reading " + what);
    std::size_t values = 0;
    if (int c = mdb_cursor_count(cursor.c, &values); c != 0) return lmdb_fail(c, "counting in " + what);
    if (auto ok = visit(cursor.c, u64(key), first, values); !ok) return ok;
  }
  return {};
}

}  // namespace

Result<std::vector<PredicateSummary>> Snapshot::predicates() const {
  if (!impl_) return moved_from();
  MDB_txn* txn = impl_->txn;
  const Env& env = *impl_->env;
  auto asserted_at = [&](const MDB_val& record) -> Result<std::int64_t> {
    const std::uint64_t id = u64(record);
    auto row = get_record(txn, env, id);
    if (!row) return unexpected(row.error());
    if (!*row) return fail(Errc::corrupt, "the predicate index names record " + std::to_string(id) + ", which is not there");
    auto item = get_item(txn, env, (*row)->item);
    if (!item) return unexpected(item.error());
    if (!*item) return fail(Errc::corrupt, "record " + std::to_string(id) + " has no item");
    return (*item)->asserted_at;
  };
  TermReader terms(txn, env);
  std::vector<PredicateSummary> out;
  auto read = for_each_key(txn, env.idx_p, "the predicate index",
                           [&](MDB_cursor* cursor, std::uint64_t predicate, const MDB_val& first, std::size_t records) -> Result<void> {
    PredicateSummary summary;
    auto iri = terms.iri(predicate);
    if (!iri) return unexpected(iri.error());
    summary.predicate = std::move(*iri);
    summary.records = records;
    auto oldest = asserted_at(first);
    if (!oldest) return unexpected(oldest.error());
    summary.first_asserted_at = *oldest;
    MDB_val key, last;
    if (int l = mdb_cursor_get(cursor, &key, &last, MDB_LAST_DUP); l != 0) return lmdb_fail(l, "reading the predicate index");
    auto newest = asserted_at(last);
    if (!newest) return unexpected(newest.error());
    summary.last_asserted_at = *newest;
    out.push_back(std::move(summary));
    return {};
  });
  if (!read) return unexpected(read.error());
  std::sort(out.begin(), out.end(), [](const PredicateSummary& a, const PredicateSummary& b) { return a.predicate < b.predicate; });
  return out;
}

Result<std::vector<InputBufferSummary>> Snapshot::input_buffers() const {
  if (!impl_) return moved_from();
  MDB_txn* txn = impl_->txn;
  const Env& env = *impl_->env;
  TermReader terms(txn, env);
  std::vector<InputBufferSummary> out;
  auto read = for_each_key(txn, env.inbox, "the input buffers",
                           [&](MDB_cursor*, std::uint64_t agent, const MDB_val& first, std::size_t waiting) -> Result<void> {
    InputBufferSummary summary;
    auto iri = terms.iri(agent);
    if (!iri) return unexpected(iri.error());
    summary.agent = std::move(*iri);
    summary.waiting = waiting;
    summary.oldest_item = u64(first);
    auto item = get_item(txn, env, summary.oldest_item);
    if (!item) return unexpected(item.error());
    if (*item) summary.oldest_asserted_at = (*item)->asserted_at;
    out.push_back(std::move(summary));
    return {};
  });
  if (!read) return unexpected(read.error());
  std::sort(out.begin(), out.end(), [](const InputBufferSummary& a, const InputBufferSummary& b) { return a.agent < b.agent; });
  return out;
}

Result<std::vector<Record>> Snapshot::item(std::uint64_t item_id) const {
  if (!impl_) return moved_from();
  return item_records(impl_->txn, *impl_->env, item_id);
}

std::uint64_t Snapshot::last_seq() const { return impl_ ? impl_->last_seq : 0; }
std::uint64_t Snapshot::notice_seqs() const { return impl_ ? impl_->notice_seqs : 0; }

// ---------------------------------------------------------------------------------------------
// Agent

struct Agent::Impl {
  std::shared_ptr<Env> env;
  std::string id, iri;
  std::uint32_t slot = 0;

  // The agent's term id, 0 when the store has never seen the agent (then nothing waits for
  // it). Remembered once the term is pinned (the agent wrote or subscribed): then it is never
  // collected and its id never changes.
  Result<std::uint64_t> self_id(MDB_txn* txn) const {
    if (pinned_self) return pinned_self;
    auto id = find_term(txn, *env, Term::iri(iri));
    if (!id || *id == 0) return id;
    auto pinned = is_pinned(txn, *env, *id);
    if (!pinned) return unexpected(pinned.error());
    if (*pinned) pinned_self = *id;
    return id;
  }
  mutable std::uint64_t pinned_self = 0;

  // Runs `change` (detail::withdraw_unrouted, detail::deliver_persistent_again: a change of this
  // agent's input buffer that returns a count) in one write transaction with the agent's term
  // id; 0 without running it when the store has never seen the agent (it has no buffer).
  template <class Change>
  Result<std::uint64_t> change_own_buffer(Change change) {
    std::uint64_t count = 0;
    auto done = env->write([&](Txn& txn) -> Result<void> {
      auto self = self_id(txn.raw());
      if (!self) return unexpected(self.error());
      if (*self == 0) return {};
      auto n = change(txn, *self, iri);
      if (!n) return unexpected(n.error());
      count = *n;
      return {};
    });
    if (!done) return unexpected(done.error());
    return count;
  }

  // Reads (and with `remove`, takes) the head of the input buffer. Skips items removed since.
  Result<std::optional<Delivery>> head(bool remove);

  // Agent::replace without copying the items (store() of one item passes it in place).
  // `then`, when given, runs in the same transaction after the items are inserted, with their ids.
  using AfterInsert = std::function<Result<void>(Txn&, std::span<const std::uint64_t>)>;
  Result<std::vector<std::uint64_t>> write_items(std::span<const Pattern> removals, std::span<const Item> items,
                                                 const AfterInsert& then = {}) noexcept;

  // Removes `item` from the input buffer (acknowledges it); absent is not an error.
  Result<void> drop(std::uint64_t item_id);

  // The id of this agent's subscription with exactly `pattern`'s s, p and o, or 0.
  Result<std::uint64_t> find_subscription(Txn& txn, const Pattern& pattern, bool own_only) const;

  // Sources of relayed items found acceptable (relay): the most recent 16.
  std::vector<std::pair<std::string, bool>> relay_sources;  // checked sources, and whether each is under this agent
};

Result<std::uint64_t> Agent::Impl::find_subscription(Txn& txn, const Pattern& pattern, bool own_only) const {
  if (auto r = refresh_caches(txn); !r) return unexpected(r.error());
  auto self = self_id(txn.raw());
  if (!self || *self == 0) return self;
  std::uint64_t ids[5] = {0, 0, 0, 0, 0};
  std::optional<Term> context, source;
  if (pattern.context) context = Term::iri(*pattern.context);
  if (pattern.source) source = Term::iri(*pattern.source);
  const std::optional<Term>* terms[5] = {&pattern.s, &pattern.p, &pattern.o, &context, &source};
  for (int i = 0; i < 5; ++i) {
    if (!*terms[i]) continue;
    auto id = find_term(txn.raw(), *env, **terms[i]);
    if (!id) return id;
    if (*id == 0) return std::uint64_t{0};  // a term never seen: no subscription names it
    ids[i] = *id;
  }
  std::vector<std::uint64_t> same;
  {
    std::lock_guard lock(env->cache_mutex);
    for (const auto& sub : env->subs)
      if (sub.agent == *self && sub.s == ids[0] && sub.p == ids[1] && sub.o == ids[2] && sub.context == ids[3] &&
          sub.source == ids[4])
        same.push_back(sub.item);
  }
  for (const std::uint64_t item : same) {
    if (!own_only) return item;
    auto row = get_item(txn.raw(), *env, item);
    if (!row) return unexpected(row.error());
    if (*row && (*row)->source == *self) return item;
  }
  return std::uint64_t{0};
}

Result<void> Agent::Impl::drop(std::uint64_t item_id) {
  return env->write([&](Txn& txn) -> Result<void> {
    auto self = self_id(txn.raw());
    if (!self) return unexpected(self.error());
    if (*self == 0) return {};
    MDB_val k = val(*self), v = val(item_id);
    int rc = mdb_del(txn.raw(), txn.env().inbox, &k, &v);
    if (rc == MDB_NOTFOUND) return {};
    if (rc != 0) return lmdb_fail(rc, "acknowledging item " + std::to_string(item_id));
    if (txn.counters.pending > 0) --txn.counters.pending;
    auto item = get_item(txn.raw(), txn.env(), item_id);
    if (!item) return unexpected(item.error());
    if (!*item) return release_notice(txn, item_id);
    ItemRow row = **item;
    if (row.pending > 0) --row.pending;
    if (auto put = put_item(txn, item_id, row); !put) return put;
    if (row.pending == 0 && !row.persistent) return note_released(txn, item_id);
    return {};
  });
}

Result<std::optional<Delivery>> Agent::Impl::head(bool remove) {
  std::optional<Delivery> delivery;
  std::uint64_t stale = 0;  // an item removed from the store but still in the input buffer
  auto body = [&](MDB_txn* txn, Txn* writer) -> Result<void> {
    auto self = self_id(txn);
    if (!self) return unexpected(self.error());
    if (*self == 0) return {};
    for (;;) {
      MDB_cursor* cursor = nullptr;
      int rc = mdb_cursor_open(txn, env->inbox, &cursor);
      if (rc != 0) return lmdb_fail(rc, "opening the input buffer of " + iri);
      MDB_val k = val(*self), v;
      rc = mdb_cursor_get(cursor, &k, &v, MDB_SET);
      if (rc == 0) rc = mdb_cursor_get(cursor, &k, &v, MDB_FIRST_DUP);
      std::uint64_t item_id = rc == 0 ? u64(v) : 0;
      mdb_cursor_close(cursor);
      if (rc == MDB_NOTFOUND) return {};
      if (rc != 0) return lmdb_fail(rc, "reading the input buffer of " + iri);
      auto found = buffered(txn, *env, item_id);
      if (!found) return unexpected(found.error());
      const bool gone = !*found;
      if (writer) {
        MDB_val dk = val(*self), dv = val(item_id);
        if ((rc = mdb_del(txn, env->inbox, &dk, &dv)) != 0) return lmdb_fail(rc, "taking from the input buffer of " + iri);
        if (writer->counters.pending > 0) --writer->counters.pending;
        if (!gone && (*found)->removal) {
          if (auto r = release_notice(*writer, item_id); !r) return r;
        } else if (!gone) {
          auto item = get_item(txn, *env, item_id);
          if (!item) return unexpected(item.error());
          ItemRow row = **item;
          if (row.pending > 0) --row.pending;
          if (auto p = put_item(*writer, item_id, row); !p) return p;
          if (row.pending == 0 && !row.persistent)
            if (auto noted = note_released(*writer, item_id); !noted) return noted;
        }
      }
      if (gone) {
        if (!writer) {  // a read-only take cannot drop it: done after the snapshot ends
          stale = item_id;
          return {};
        }
        continue;
      }
      delivery = std::move(*found);
      return {};
    }
  };
  if (remove) {
    // Look first in a snapshot: an empty buffer must not cost a write transaction (which
    // would take the writer lock and wake every watcher) each time a taker wakes up.
    auto peeked = head(false);
    if (!peeked || !*peeked) return peeked;
    auto written = env->write([&](Txn& txn) { return body(txn.raw(), &txn); });
    if (!written) return unexpected(written.error());
  } else {
    {
      ReadTxn read(*env);
      if (auto r = read.begin(); !r) return unexpected(r.error());
      if (auto r = body(read.txn, nullptr); !r) return unexpected(r.error());
    }
    if (stale) {
      if (auto d = drop(stale); !d) return unexpected(d.error());
      return head(false);
    }
  }
  return delivery;
}

Agent::Agent(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
Agent::Agent(Agent&&) noexcept = default;
Agent& Agent::operator=(Agent&&) noexcept = default;
Agent::~Agent() = default;

namespace {
const std::string kNoText;  // what a handle moved from names
}  // namespace

const std::string& Agent::iri() const { return impl_ ? impl_->iri : kNoText; }
const std::string& Agent::id() const { return impl_ ? impl_->id : kNoText; }

std::uint32_t Agent::buffer_version() const noexcept { return impl_ ? impl_->env->wake().version(impl_->slot) : 0; }

Result<std::uint64_t> Agent::store(const Item& item) noexcept {
  if (!impl_) return moved_from();
  auto ids = impl_->write_items({}, std::span<const Item>(&item, 1));
  if (!ids) return unexpected(ids.error());
  return ids->front();
}

Result<std::vector<std::uint64_t>> Agent::store_all(const std::vector<Item>& items) noexcept {
  if (!impl_) return moved_from();
  if (items.empty()) return std::vector<std::uint64_t>{};
  return impl_->write_items({}, items);
}

Result<StoredSubscriptions> Agent::store_subscriptions(const std::vector<Item>& subscriptions,
                                                       std::span<const std::uint64_t> missed_after,
                                                       std::uint64_t older_than) noexcept {
  if (!impl_) return moved_from();
  if (missed_after.size() != subscriptions.size())
    return fail(Errc::invalid_argument, "store_subscriptions: " + std::to_string(subscriptions.size()) + " items but " +
                                            std::to_string(missed_after.size()) + " ids to catch up after");
  StoredSubscriptions stored;
  if (subscriptions.empty()) return stored;
  auto ids = impl_->write_items({}, subscriptions, [&](Txn& txn, std::span<const std::uint64_t> new_ids) -> Result<void> {
    std::vector<detail::MissedSince> missed;
    for (std::size_t i = 0; i < new_ids.size(); ++i) missed.push_back({new_ids[i], missed_after[i]});
    auto delivered = detail::deliver_missed(txn, missed, older_than != 0 ? older_than : new_ids.front());
    if (!delivered) return unexpected(delivered.error());
    stored.caught_up = *delivered;
    return {};
  });
  if (!ids) return unexpected(ids.error());
  stored.ids = std::move(*ids);
  return stored;
}

Result<std::vector<std::uint64_t>> Agent::replace(const std::vector<Pattern>& removals,
                                                  const std::vector<Item>& items) noexcept {
  if (!impl_) return moved_from();
  return impl_->write_items(removals, items);
}

Result<void> Agent::report_problem(std::string_view text) noexcept {
  if (!impl_) return moved_from();
  try {
    const std::string said = with_replacement_characters(text);
    const Term self = Term::iri(impl_->iri);
    const std::vector<Pattern> old = {{.s = self, .p = Term::iri(kProblem), .source = impl_->iri},
                                      {.s = self, .p = Term::iri(kProblemPid), .source = impl_->iri}};
    auto snapshot = Snapshot::Impl::open(impl_->env);
    if (!snapshot) return unexpected(snapshot.error());
    auto problem = snapshot->list(old[0]);
    if (!problem) return unexpected(problem.error());
    auto pid = snapshot->list(old[1]);
    if (!pid) return unexpected(pid.error());
    const bool said_already =
        said.empty() ? problem->empty() && pid->empty()
                     : problem->size() == 1 && problem->front().triple.o.value == said && pid->size() == 1 &&
                           pid->front().triple.o.value == std::to_string(getpid());
    if (said_already) return {};
    std::vector<Item> items;
    if (!said.empty()) {
      Item item;
      item.persistent = true;  // a ring must not take it while the problem lasts
      item.add(self, Term::iri(kProblem), Term::literal(said)).add(self, Term::iri(kProblemPid), Term::integer(getpid()));
      items.push_back(std::move(item));
    }
    auto written = impl_->write_items(old, items);
    if (!written) return unexpected(written.error());
    return {};
  } catch (const std::bad_alloc&) {
    return fail(Errc::io, "out of memory while reporting a problem");
  }
}

namespace {

// The removals of a write, grouped for Query::collect_exact: patterns giving s, p and o with the
// same subject and metadata filters together (a reasoner retracting conclusions, a link
// replacing a state), every other pattern alone.
std::vector<std::vector<const Pattern*>> removal_groups(std::span<const Pattern> removals) {
  std::vector<std::vector<const Pattern*>> groups;
  std::map<std::string, std::size_t> exact;  // the shared part, encoded -> its group
  for (const Pattern& p : removals) {
    if (!p.s || !p.p || !p.o) {
      groups.push_back({&p});
      continue;
    }
    auto text = [](const auto& field) -> std::string {
      if (!field) return "-";
      if constexpr (std::is_same_v<std::decay_t<decltype(*field)>, std::string>) return "+" + *field;
      else return "+" + std::to_string(*field);
    };
    std::string key = p.s->to_ntriples() + '\0' + text(p.context) + '\0' + text(p.source) + '\0' + text(p.since) + '\0' +
                      text(p.until) + '\0' + text(p.after_id);
    auto [at, fresh] = exact.emplace(std::move(key), groups.size());
    if (fresh) groups.emplace_back();
    groups[at->second].push_back(&p);
  }
  return groups;
}

}  // namespace

Result<std::vector<std::uint64_t>> Agent::Impl::write_items(std::span<const Pattern> removals,
                                                            std::span<const Item> items,
                                                            const AfterInsert& then) noexcept {
  try {
    for (const Pattern& p : removals) {
      if (!p.s && !p.p && !p.o && !p.context && !p.source)
        return fail(Errc::invalid_argument, "refusing to remove with an empty pattern; name a subject, predicate, object, context or source");
    }
    for (std::size_t i = 0; i < items.size(); ++i) {
      if (auto v = validate_item(items[i], env->settings()); !v)
        return unexpected(items.size() == 1 ? v.error() : with_context(v.error(), "item " + std::to_string(i + 1)));
    }
    WriteBound new_bytes;
    for (const Item& item : items) new_bytes += write_bound(item);
    std::vector<std::uint64_t> ids;
    auto written = env->write([&](Txn& txn) -> Result<void> {
      ids.clear();
      Query query(txn.raw(), txn.env());
      txn.defer_term_collection = !removals.empty() && !items.empty();
      txn.deferred_terms.clear();
      for (const auto& group : removal_groups(removals)) {
        auto gone = group.size() == 1 ? query.collect(*group.front(), ListOptions{0, 0}) : query.collect_exact(group);
        if (!gone) return unexpected(gone.error());
        for (std::uint64_t id : *gone) {
          auto exists = get_record(txn.raw(), txn.env(), id);
          if (!exists) return unexpected(exists.error());
          if (!*exists) continue;  // matched by an earlier pattern too
          if (auto d = delete_record(txn, id, Removal::explicit_removal); !d) return d;
        }
      }
      for (std::size_t i = 0; i < items.size(); ++i) {
        auto id = insert_item(txn, items[i], iri);
        if (!id) return unexpected(items.size() == 1 ? id.error() : with_context(id.error(), "item " + std::to_string(i + 1)));
        ids.push_back(*id);
      }
      if (txn.defer_term_collection) {
        txn.defer_term_collection = false;
        std::sort(txn.deferred_terms.begin(), txn.deferred_terms.end());
        txn.deferred_terms.erase(std::unique(txn.deferred_terms.begin(), txn.deferred_terms.end()), txn.deferred_terms.end());
        for (const std::uint64_t term : txn.deferred_terms)
          if (auto c = collect_term_if_unused(txn, term); !c) return c;
        txn.deferred_terms.clear();
      }
      if (then)
        if (auto done = then(txn, ids); !done) return done;
      auto reclaimed = apply_retention(txn);
      if (!reclaimed) return unexpected(reclaimed.error());
      return {};
    }, WriteKind::data, new_bytes);
    if (!written) return unexpected(written.error());
    return ids;
  } catch (const std::bad_alloc&) {
    return fail(Errc::io, "out of memory while storing");
  }
}

namespace {
// `timeout` from now, as a deadline: none (the clock's end) for one too long to add to now
// (milliseconds::max(), "wait forever"), which would otherwise wrap to a time in the past and
// return at once, a waiting loop turned into a spin. A negative timeout is a deadline passed.
template <class Rep, class Period>
std::chrono::steady_clock::time_point deadline_after(std::chrono::duration<Rep, Period> timeout) {
  using Clock = std::chrono::steady_clock;
  const auto now = Clock::now();
  if (timeout.count() <= 0) return now;
  const auto room = std::chrono::duration_cast<std::chrono::duration<Rep, Period>>(Clock::time_point::max() - now);
  if (timeout >= room) return Clock::time_point::max();
  return now + std::chrono::duration_cast<Clock::duration>(timeout);
}
}  // namespace

Result<std::optional<Delivery>> Agent::take(std::chrono::milliseconds timeout, Ack ack) noexcept {
  if (!impl_) return moved_from();
  try {
    const auto deadline = deadline_after(timeout);
    WakeBoard& board = impl_->env->wake();
    for (;;) {
      const std::uint32_t token = board.version(impl_->slot);
      auto got = impl_->head(ack == Ack::automatic);
      if (!got || *got) return got;
      // A store deleted or moved while it waits: nothing will ever come (not a timeout). Looked
      // at once a second at most while it waits (check_in_place says when it looks).
      if (auto in_place = impl_->env->check_in_place(); !in_place) return unexpected(in_place.error());
      auto left = deadline - std::chrono::steady_clock::now();
      if (left <= std::chrono::nanoseconds::zero()) return std::optional<Delivery>();
      // A signal handler ran (one installed without SA_RESTART): returned as a timeout, so that
      // the program sees the stop flag its handler set. A wait without limit wakes each second.
      if (board.sleep(impl_->slot, token, std::min<std::chrono::nanoseconds>(left, std::chrono::seconds(1))))
        return std::optional<Delivery>();
    }
  } catch (const std::bad_alloc&) {
    return fail(Errc::io, "out of memory while taking");
  }
}

Result<void> Agent::ack(std::uint64_t item_id) noexcept {
  if (!impl_) return moved_from();
  try {
    return impl_->drop(item_id);
  } catch (const std::bad_alloc&) {
    return fail(Errc::io, "out of memory while acknowledging");
  }
}

Result<std::uint64_t> Agent::pending() const noexcept {
  if (!impl_) return moved_from();
  ReadTxn read(*impl_->env);
  if (auto r = read.begin(); !r) return unexpected(r.error());
  auto self = impl_->self_id(read.txn);
  if (!self) return unexpected(self.error());
  if (*self == 0) return std::uint64_t{0};
  MDB_cursor* cursor = nullptr;
  int rc = mdb_cursor_open(read.txn, impl_->env->inbox, &cursor);
  if (rc != 0) return lmdb_fail(rc, "opening an input buffer");
  MDB_val k = val(*self), v;
  std::size_t n = 0;
  if (mdb_cursor_get(cursor, &k, &v, MDB_SET) == 0) mdb_cursor_count(cursor, &n);
  mdb_cursor_close(cursor);
  return std::uint64_t{n};
}

Result<std::vector<Delivery>> Agent::peek_newest(std::uint64_t after, std::uint64_t before, std::size_t limit) const noexcept {
  if (!impl_) return moved_from();
  try {
    std::vector<Delivery> out;
    ReadTxn read(*impl_->env);
    if (auto r = read.begin(); !r) return unexpected(r.error());
    auto self = impl_->self_id(read.txn);
    if (!self) return unexpected(self.error());
    if (*self == 0 || before <= after + 1) return out;
    std::vector<std::uint64_t> ids;
    MDB_cursor* cursor = nullptr;
    int rc = mdb_cursor_open(read.txn, impl_->env->inbox, &cursor);
    if (rc != 0) return lmdb_fail(rc, "opening the input buffer of " + impl_->iri);
    // The first entry at or after `before`, then back; or the last entry when none is.
    MDB_val k = val(*self), v = val(before);
    rc = mdb_cursor_get(cursor, &k, &v, MDB_GET_BOTH_RANGE);
    if (rc == MDB_NOTFOUND) {
      k = val(*self);
      rc = mdb_cursor_get(cursor, &k, &v, MDB_SET);
      if (rc == 0) rc = mdb_cursor_get(cursor, &k, &v, MDB_LAST_DUP);
    }
    for (; rc == 0 && (!limit || ids.size() < limit); rc = mdb_cursor_get(cursor, &k, &v, MDB_PREV_DUP)) {
      const std::uint64_t id = u64(v);
      if (id <= after) break;
      if (id < before) ids.push_back(id);
    }
    mdb_cursor_close(cursor);
    if (rc != 0 && rc != MDB_NOTFOUND) return lmdb_fail(rc, "reading the input buffer of " + impl_->iri);
    for (std::uint64_t id : ids) {
      auto found = buffered(read.txn, *impl_->env, id);
      if (!found) return unexpected(found.error());
      if (*found) out.push_back(std::move(**found));  // else removed since
    }
    return out;
  } catch (const std::bad_alloc&) {
    return fail(Errc::io, "out of memory while peeking");
  }
}

Result<std::vector<Delivery>> Agent::peek(std::uint64_t after, std::size_t limit,
                                          std::chrono::milliseconds timeout) noexcept {
  if (!impl_) return moved_from();
  try {
    const auto deadline = deadline_after(timeout);
    WakeBoard& board = impl_->env->wake();
    for (;;) {
      const std::uint32_t token = board.version(impl_->slot);
      std::vector<Delivery> out;
      {
        ReadTxn read(*impl_->env);
        if (auto r = read.begin(); !r) return unexpected(r.error());
        auto self = impl_->self_id(read.txn);
        if (!self) return unexpected(self.error());
        std::vector<std::uint64_t> ids;
        if (*self) {
          MDB_cursor* cursor = nullptr;
          int rc = mdb_cursor_open(read.txn, impl_->env->inbox, &cursor);
          if (rc != 0) return lmdb_fail(rc, "opening the input buffer of " + impl_->iri);
          std::uint64_t from = after + 1;
          MDB_val k = val(*self), v = val(from);
          for (rc = mdb_cursor_get(cursor, &k, &v, MDB_GET_BOTH_RANGE);
               rc == 0 && (!limit || ids.size() < limit); rc = mdb_cursor_get(cursor, &k, &v, MDB_NEXT_DUP))
            ids.push_back(u64(v));
          mdb_cursor_close(cursor);
        }
        for (std::uint64_t id : ids) {
          auto found = buffered(read.txn, *impl_->env, id);
          if (!found) return unexpected(found.error());
          if (*found) out.push_back(std::move(**found));  // else removed since
        }
      }
      auto left = deadline - std::chrono::steady_clock::now();
      if (!out.empty() || left <= std::chrono::nanoseconds::zero()) return out;
      if (board.sleep(impl_->slot, token, std::chrono::duration_cast<std::chrono::nanoseconds>(left))) return out;
    }
  } catch (const std::bad_alloc&) {
    return fail(Errc::io, "out of memory while peeking");
  }
}

Result<void> Agent::receive_removals() noexcept {
  if (!impl_) return moved_from();
  try {
    return impl_->env->write([&](Txn& txn) { return detail::receive_removals(txn, impl_->iri); });
  } catch (const std::bad_alloc&) {
    return fail(Errc::io, "out of memory while writing a setting");
  }
}

Result<std::uint64_t> Agent::ack_through(std::uint64_t through) noexcept {
  if (!impl_) return moved_from();
  try {
    std::uint64_t acked = 0;
    auto written = impl_->env->write([&](Txn& txn) -> Result<void> {
      acked = 0;
      auto self = impl_->self_id(txn.raw());
      if (!self) return unexpected(self.error());
      if (*self == 0) return {};
      // A link's outbox is trimmed a run at a time (hundreds of items) while its agents store:
      // one cursor per table walks the run in id order instead of a search from the root for
      // each entry, which took 0.4 µs per item while every store waited (docs/bench.md).
      Cursor inbox, items;
      int rc = mdb_cursor_open(txn.raw(), impl_->env->inbox, &inbox.c);
      if (rc == 0) rc = mdb_cursor_open(txn.raw(), impl_->env->items, &items.c);
      if (rc != 0) return lmdb_fail(rc, "opening the input buffer of " + impl_->iri);
      MDB_val k = val(*self), v;
      rc = mdb_cursor_get(inbox.c, &k, &v, MDB_SET);
      while (rc == 0) {
        const std::uint64_t id = u64(v);
        if (id > through) break;
        // Deleting the key's last entry moves the cursor to the next key, so the next entry is
        // this agent's only while it has more (counted before the delete).
        std::size_t left = 0;
        if ((rc = mdb_cursor_count(inbox.c, &left)) != 0) break;
        if ((rc = mdb_cursor_del(inbox.c, 0)) != 0) return lmdb_fail(rc, "acknowledging item " + std::to_string(id));
        if (txn.counters.pending > 0) --txn.counters.pending;
        ++acked;
        auto released = release_item(txn, items.c, id);
        if (!released) return unexpected(released.error());
        if (!*released) {
          if (auto r = release_notice(txn, id); !r) return r;
        }
        if (left <= 1) break;
        rc = mdb_cursor_get(inbox.c, &k, &v, MDB_GET_CURRENT);
      }
      if (rc != 0 && rc != MDB_NOTFOUND) return lmdb_fail(rc, "reading the input buffer of " + impl_->iri);
      return {};
    });
    if (!written) return unexpected(written.error());
    return acked;
  } catch (const std::bad_alloc&) {
    return fail(Errc::io, "out of memory while acknowledging");
  }
}

namespace {

std::string relay_mark_key(std::string_view stream) { return "relay:" + std::string(stream); }

// A number kept in the meta table under `key`, 0 when absent; `what` names it in errors.
Result<std::uint64_t> read_meta_number(MDB_txn* txn, const Env& env, const std::string& key, const std::string& what) {
  MDB_val k = val(key), v;
  int rc = mdb_get(txn, env.meta, &k, &v);
  if (rc == MDB_NOTFOUND) return std::uint64_t{0};
  if (rc != 0) return lmdb_fail(rc, "reading the " + what);
  if (v.mv_size != sizeof(std::uint64_t)) return fail(Errc::corrupt, "the " + what + " has " + std::to_string(v.mv_size) + " bytes");
  return u64(v);
}

Result<std::uint64_t> read_relay_mark(MDB_txn* txn, const Env& env, std::string_view stream) {
  return read_meta_number(txn, env, relay_mark_key(stream), "relay mark of " + std::string(stream));
}

// Which of a stream's items may repeat items held here (Agent::relay_may_repeat): those up to
// a seq, and those asserted at or before a time. Kept as the seq (8 bytes; so written up to
// session 63), then the time when one was said. Beside it, under a key of its own (so that a
// build before session 72 reads the first as it wrote it), the first item id that the store
// had not given when it was first said.
std::string relay_repeats_key(std::string_view stream) { return "relay-repeats:" + std::string(stream); }
std::string relay_held_before_key(std::string_view stream) { return "relay-repeats-held-before:" + std::string(stream); }

struct RepeatBounds {
  std::uint64_t through_seq = 0;
  std::optional<std::int64_t> asserted_through;
  // Items below this id were held before the stream began to repeat them: an item of the
  // stream that names the same thing as one of those, with other triples, was computed again
  // by the store that replaced the one it came from (held_twin). 0: none looked for (said
  // before session 72).
  std::uint64_t held_before = 0;
  bool said = false;  // kept in the store

  bool cover(const RelayedItem& relayed) const {
    return relayed.seq <= through_seq ||
           (asserted_through && relayed.item.asserted_at && *relayed.item.asserted_at <= *asserted_through);
  }
};

Result<RepeatBounds> read_relay_repeats(MDB_txn* txn, const Env& env, std::string_view stream) {
  const std::string key = relay_repeats_key(stream);
  MDB_val k = val(key), v;
  int rc = mdb_get(txn, env.meta, &k, &v);
  if (rc == MDB_NOTFOUND) return RepeatBounds{};
  const std::string what = "bounds of what " + std::string(stream) + " may repeat of what is held";
  if (rc != 0) return lmdb_fail(rc, "reading the " + what);
  if (v.mv_size != 8 && v.mv_size != 16) return fail(Errc::corrupt, "the " + what + " have " + std::to_string(v.mv_size) + " bytes");
  RepeatBounds bounds;
  bounds.said = true;
  std::memcpy(&bounds.through_seq, v.mv_data, 8);
  if (v.mv_size == 16) {
    std::int64_t t = 0;
    std::memcpy(&t, static_cast<const char*>(v.mv_data) + 8, 8);
    bounds.asserted_through = t;
  }
  auto held_before = read_meta_number(txn, env, relay_held_before_key(stream), "first id not held before " + std::string(stream));
  if (!held_before) return unexpected(held_before.error());
  bounds.held_before = *held_before;
  return bounds;
}

}  // namespace

namespace {

// Errors that say the item itself can never be stored here, whatever is retried.
bool refuses_the_item(Errc code) {
  return code == Errc::invalid_argument || code == Errc::invalid_iri || code == Errc::syntax ||
         code == Errc::literal_too_large;
}

}  // namespace

Result<RelayOutcome> Agent::relay(std::string_view stream, const std::vector<RelayedItem>& items) noexcept {
  if (!impl_) return moved_from();
  try {
    if (stream.empty()) return fail(Errc::invalid_argument, "relay: empty stream name");
    const std::string& node_iri = impl_->env->settings().iri;
    auto about = [&](std::size_t i) {
      return "relayed item " + std::to_string(i + 1) + " (seq " + std::to_string(items[i].seq) + ")";
    };
    // Why each item is refused, if it is (sized at the first refusal: nearly every call has
    // none); the checks that need no transaction come first.
    std::vector<std::optional<Error>> refusal;
    auto refuse = [&](std::size_t i, Error why) {
      refusal.resize(items.size());
      refusal[i] = std::move(why);
    };
    // A link agent's items come from few writers: each distinct source is checked once and
    // remembered by this handle (the checks parse IRIs, were a quarter of a hospital's ingest
    // cost, and depend only on the source, this agent and the node). A lone item on a quiet
    // link then costs no IRI parsing.
    std::vector<std::pair<std::string, bool>>& checked_sources = impl_->relay_sources;
    // Items from below (each source at or under this agent's IRI: a child node's writers) leave
    // this node's own agents their part of the maximum (WriteKind::from_below); a removal notice
    // alone frees room and is not held back.
    // For the first n items (the run is halved while it does not fit): all from below, and one
    // of them an item, not a notice.
    std::vector<char> item_below(items.size(), 0);
    for (std::size_t i = 0; i < items.size(); ++i) {
      const std::string& source = items[i].source;
      auto known = std::find_if(checked_sources.begin(), checked_sources.end(), [&](const auto& c) { return c.first == source; });
      if (known != checked_sources.end()) {
        item_below[i] = known->second;
      } else {
        const bool below = uri::is_under(source, impl_->iri);
        item_below[i] = below;
        if (!below && uri::is_under(source, node_iri)) {
          refuse(i, Error{Errc::invalid_argument, about(i) + ": source <" + source + "> is a writer of this node outside <" +
                                                       impl_->iri + ">; a link agent relays only its own subtree or writers above this node"});
          continue;
        }
        if (auto n = uri::normalize(source); !n) {
          refuse(i, Error{Errc::invalid_iri, about(i) + ": source: " + n.error().message});
          continue;
        }
        if (checked_sources.size() >= 16) checked_sources.erase(checked_sources.begin());
        checked_sources.emplace_back(source, below);
      }
      if (items[i].removal && items[i].positions.size() != items[i].item.triples.size()) {
        refuse(i, Error{Errc::invalid_argument, about(i) + ": a removal notice of " + std::to_string(items[i].item.triples.size()) +
                                                     " triple(s) gives " + std::to_string(items[i].positions.size()) +
                                                     " position(s); one per triple"});
        continue;
      }
      if (auto v = validate_item(items[i].item, impl_->env->settings()); !v) {
        if (!refuses_the_item(v.error().code)) return unexpected(with_context(v.error(), about(i)));
        refuse(i, with_context(v.error(), about(i)));
      }
    }
    auto from_below = [&](std::size_t n) {
      return std::all_of(item_below.begin(), item_below.begin() + static_cast<std::ptrdiff_t>(n), [](char b) { return b != 0; }) &&
             std::any_of(items.begin(), items.begin() + static_cast<std::ptrdiff_t>(n), [](const RelayedItem& r) { return !r.removal; });
    };
    RelayOutcome outcome;
    auto bound_of_first = [&](std::size_t n) {
      WriteBound bound;
      for (std::size_t i = 0; i < n; ++i) {
        bound += write_bound(items[i].item);
        // Its source IRI (up to 8192 bytes, P4), a term as write_bound counts them.
        const std::uint64_t source = items[i].source.size();
        bound += source > 1024 ? WriteBound{source + 4096, source + 4096} : WriteBound{source, 0};
      }
      return bound;
    };
    // A run the store has no room for is tried again with its first half, down to one item: a
    // store nearly full, where some room was freed, took one item per round trip (the sender
    // probes one at a time after a refusal, and its whole window again once one was stored).
    std::size_t applying = items.size();
    std::optional<Error> full;
    WriteBound new_bytes = bound_of_first(applying);
    // An item refused only when it is written (a term's IRI is checked when the dictionary first
    // meets it) aborts the transaction; it is then run again with that item refused, once per
    // such item.
    for (;;) {
      std::optional<std::size_t> refused_in_write;
      auto written = impl_->env->write([&](Txn& txn) -> Result<void> {
        outcome = RelayOutcome{};
        refused_in_write.reset();
        auto mark = read_relay_mark(txn.raw(), *impl_->env, stream);
        if (!mark) return unexpected(mark.error());
        outcome.mark = *mark;
        auto repeats = read_relay_repeats(txn.raw(), *impl_->env, stream);
        if (!repeats) return unexpected(repeats.error());
        for (std::size_t i = 0; i < applying; ++i) {
          const RelayedItem& relayed = items[i];
          if (relayed.seq <= outcome.mark) {
            ++outcome.duplicates;
            continue;
          }
          if (relayed.prev != outcome.mark) {
            outcome.gap = true;
            break;
          }
          if (!refusal.empty() && refusal[i]) {
            outcome.refused.push_back({relayed.seq, *refusal[i]});
          } else if (relayed.removal) {
            // The items of this run stored before it are in the index only once it is flushed.
            if (auto f = flush_index(txn); !f) return unexpected(f.error());
            auto copies = held_copies(txn.raw(), *impl_->env, relayed.item, relayed.positions, relayed.source);
            if (!copies) return unexpected(with_context(copies.error(), about(i)));
            // Whom the copies went to, read before they go (the last record takes the row).
            std::vector<std::uint64_t> remembered;
            for (std::uint64_t item_id : copies->items) {
              auto row = get_item(txn.raw(), *impl_->env, item_id);
              if (!row) return unexpected(with_context(row.error(), about(i)));
              if (*row) remembered.insert(remembered.end(), (*row)->noticed.begin(), (*row)->noticed.end());
            }
            for (std::uint64_t id : copies->records)
              if (auto d = delete_record(txn, id, Removal::quiet_removal); !d) return unexpected(with_context(d.error(), about(i)));
            if (auto on = pass_notice_on(txn, relayed.item, relayed.positions, relayed.source, impl_->iri, copies->items, remembered); !on)
              return unexpected(with_context(on.error(), about(i)));
            ++outcome.removals;
            outcome.records_removed += copies->records.size();
          } else if (auto twin = repeats->cover(relayed)
                                     ? held_twin(txn.raw(), *impl_->env, relayed.item, relayed.source, repeats->held_before)
                                     : held_persistent_twin(txn.raw(), *impl_->env, relayed.item, relayed.source);
                     !twin) {
            return unexpected(with_context(twin.error(), about(i)));
          } else if (twin->id != 0) {
            ++outcome.already_held;
            if (twin->recomputed) ++outcome.recomputed;
          } else {
            auto id = insert_item(txn, relayed.item, impl_->iri, &relayed.source);
            if (!id) {
              if (refuses_the_item(id.error().code)) refused_in_write = i;
              return unexpected(with_context(id.error(), about(i)));
            }
            outcome.stored.push_back(*id);
          }
          outcome.mark = relayed.seq;
        }
        if (outcome.mark != *mark) {
          std::string key = relay_mark_key(stream);
          MDB_val k = val(key), v = val(outcome.mark);
          if (int rc = mdb_put(txn.raw(), impl_->env->meta, &k, &v, 0); rc != 0)
            return lmdb_fail(rc, "writing the relay mark of " + std::string(stream));
        }
        if (!outcome.stored.empty()) {
          auto reclaimed = apply_retention(txn);
          if (!reclaimed) return unexpected(reclaimed.error());
        }
        return {};
      }, from_below(applying) ? WriteKind::from_below : WriteKind::data, new_bytes);
      if (!written && refused_in_write) {
        refuse(*refused_in_write, written.error());
        continue;
      }
      if (!written && written.error().code == Errc::store_full && applying > 1) {
        full = written.error();  // the smallest part that did not fit says most
        applying /= 2;
        new_bytes = bound_of_first(applying);
        continue;
      }
      if (!written) return unexpected(written.error());
      if (applying < items.size() && !outcome.gap) outcome.not_applied = std::move(full);
      return outcome;
    }
  } catch (const std::bad_alloc&) {
    return fail(Errc::io, "out of memory while relaying");
  }
}

Result<std::uint64_t> Agent::relay_mark(std::string_view stream) const noexcept {
  if (!impl_) return moved_from();
  try {
    ReadTxn read(*impl_->env);
    if (auto r = read.begin(); !r) return unexpected(r.error());
    return read_relay_mark(read.txn, *impl_->env, stream);
  } catch (const std::bad_alloc&) {
    return fail(Errc::io, "out of memory while reading a relay mark");
  }
}

Result<void> Agent::relay_may_repeat(std::string_view stream, std::uint64_t through_seq,
                                     std::optional<std::int64_t> asserted_through) noexcept {
  if (!impl_) return moved_from();
  try {
    if (stream.empty()) return fail(Errc::invalid_argument, "relay_may_repeat: empty stream name");
    return impl_->env->write([&](Txn& txn) -> Result<void> {
      auto now = read_relay_repeats(txn.raw(), *impl_->env, stream);
      if (!now) return unexpected(now.error());
      RepeatBounds wider = *now;
      wider.through_seq = std::max(wider.through_seq, through_seq);
      if (asserted_through) wider.asserted_through = std::max(wider.asserted_through.value_or(*asserted_through), *asserted_through);
      // The first time said: what the stream stores from now on is not what it may repeat. (Said
      // before session 72, when no id was kept, it stays without: the stream may have stored
      // items since.)
      if (!now->said) {
        std::string key = relay_held_before_key(stream);
        MDB_val k = val(key), v = val(txn.counters.next_seq);
        if (int rc = mdb_put(txn.raw(), impl_->env->meta, &k, &v, 0); rc != 0)
          return lmdb_fail(rc, "writing the first id not held before " + std::string(stream));
      }
      if (wider.through_seq == now->through_seq && wider.asserted_through == now->asserted_through && now->said) return {};
      char bytes[16];
      std::memcpy(bytes, &wider.through_seq, 8);
      if (wider.asserted_through) std::memcpy(bytes + 8, &*wider.asserted_through, 8);
      std::string key = relay_repeats_key(stream);
      MDB_val k = val(key), v{wider.asserted_through ? 16u : 8u, bytes};
      if (int rc = mdb_put(txn.raw(), impl_->env->meta, &k, &v, 0); rc != 0)
        return lmdb_fail(rc, "writing how far " + std::string(stream) + " may repeat what is held");
      return {};
    });
  } catch (const std::bad_alloc&) {
    return fail(Errc::io, "out of memory while writing how far a stream may repeat");
  }
}

Result<std::uint64_t> Agent::subscribe(const Pattern& given, const SubscribeOptions& options) {
  if (!impl_) return moved_from();
  Pattern pattern = given;
  if (pattern.source && !pattern.source->empty()) {
    // Kept in normal form: routing compares sources by dictionary id first.
    auto normal = uri::normalize(*pattern.source);
    if (!normal) return fail(Errc::invalid_iri, "subscription source: " + normal.error().message);
    pattern.source = std::move(*normal);
  }
  if (pattern.since || pattern.until || pattern.after_id || pattern.under)
    return fail(Errc::invalid_argument, "a subscription pattern takes subject, predicate, object, context and source only");
  if (pattern.context && pattern.context->empty())
    return fail(Errc::invalid_argument, "a subscription's context must be an IRI");
  if (pattern.source && pattern.source->empty())
    return fail(Errc::invalid_argument, "a subscription's source must be an IRI");
  for (const auto* t : {&pattern.s, &pattern.p, &pattern.o})
    if (*t && (*t)->is_blank()) return fail(Errc::invalid_argument, "a subscription pattern cannot name a blank node");
  // No record has such a subject or predicate: the subscription would never match (as the C
  // API refuses it).
  if (pattern.s && pattern.s->is_literal()) return fail(Errc::invalid_argument, "a subscription's subject cannot be a literal");
  if (pattern.p && !pattern.p->is_iri()) return fail(Errc::invalid_argument, "a subscription's predicate must be an IRI");
  if (pattern.o && pattern.o->is_literal())
    if (auto bad = detail::pattern_literal_problem(*pattern.o); !bad.empty())
      return fail(Errc::invalid_argument, "subscription object: " + bad);
  Item item;
  item.persistent = true;
  const Term node = Term::blank("subscription");
  // What the caller wrote, by the declaration's triple: a bad term is named by its field, not as
  // "triple 3, object" of a declaration the caller never wrote.
  std::vector<const char*> field{"subscriber"};
  item.add(node, Term::iri(std::string(kSubscriber)), Term::iri(impl_->iri));
  if (pattern.s) item.add(node, Term::iri(std::string(kSubject)), *pattern.s), field.push_back("subject");
  if (pattern.p) item.add(node, Term::iri(std::string(kPredicate)), *pattern.p), field.push_back("predicate");
  if (pattern.o) item.add(node, Term::iri(std::string(kObject)), *pattern.o), field.push_back("object");
  if (pattern.context) item.add(node, Term::iri(std::string(kSubscriptionContext)), Term::iri(*pattern.context)), field.push_back("context");
  if (pattern.source) item.add(node, Term::iri(std::string(kSubscriptionSource)), Term::iri(*pattern.source)), field.push_back("source");
  for (std::size_t i = 1; i < item.triples.size(); ++i)
    if (const Term& o = item.triples[i].o; o.is_iri())
      if (auto ok = uri::normalize(o.value); !ok) return fail(Errc::invalid_iri, std::string("subscription ") + field[i] + ": " + ok.error().message);
  if (auto v = validate_item(item, impl_->env->settings()); !v) {
    // "triple N, object: ..." of the declaration: the caller's term is the object of triple N.
    Error e = v.error();
    const std::size_t n = e.message.starts_with("triple ") ? std::strtoull(e.message.c_str() + 7, nullptr, 10) : 0;
    const std::size_t object = e.message.find(", object: ");
    if (n >= 2 && n <= field.size() && object != std::string::npos)
      e.message = std::string("subscription ") + field[n - 1] + ": " + e.message.substr(object + 10);
    return unexpected(std::move(e));
  }
  std::uint64_t id = 0;
  auto written = impl_->env->write([&](Txn& txn) -> Result<void> {
    auto existing = impl_->find_subscription(txn, pattern, options.own_only);
    if (!existing) return unexpected(existing.error());
    if (*existing) {  // a restarted agent subscribing again: the one it has stands
      id = *existing;
      return {};
    }
    auto stored = insert_item(txn, item, impl_->iri);
    if (!stored) return unexpected(stored.error());
    id = *stored;
    if (!options.earlier) return {};
    // Interned by the subscription item in this transaction (not remembered: it may abort).
    auto self = find_term(txn.raw(), txn.env(), Term::iri(impl_->iri));
    if (!self) return unexpected(self.error());
    auto delivered = detail::deliver_earlier(txn, *self, impl_->iri, pattern, id, options.persistent_only);
    if (!delivered) return unexpected(delivered.error());
    return {};
  });
  if (!written) return unexpected(written.error());
  return id;
}

Result<void> Agent::unsubscribe(std::uint64_t subscription) {
  if (!impl_) return moved_from();
  std::string subscriber(kSubscriber);
  return impl_->env->write([&](Txn& txn) -> Result<void> {
    Query query(txn.raw(), txn.env());
    auto first = query.record(subscription);
    if (!first) return unexpected(first.error());
    if (!*first || (*first)->triple.p.value != subscriber || (*first)->triple.o.value != impl_->iri)
      return fail(Errc::not_found, "no subscription " + std::to_string(subscription) + " of " + impl_->iri);
    auto removed = delete_item(txn, subscription, Removal::explicit_removal);
    if (!removed) return unexpected(removed.error());
    return {};
  });
}

Result<std::uint64_t> Agent::withdraw_unrouted(std::uint64_t after) {
  if (!impl_) return moved_from();
  return impl_->change_own_buffer([after](detail::Txn& txn, std::uint64_t agent, const std::string& agent_iri) {
    return detail::withdraw_unrouted(txn, agent, agent_iri, after);
  });
}

Result<std::uint64_t> Agent::deliver_persistent_again(Redelivery which) {
  if (!impl_) return moved_from();
  return impl_->change_own_buffer([which](detail::Txn& txn, std::uint64_t agent, const std::string& agent_iri) {
    return detail::deliver_persistent_again(txn, agent, agent_iri, which == Redelivery::addressed_too);
  });
}

Result<std::uint64_t> Agent::deliver_again_between(std::uint64_t after, std::uint64_t before, const std::string& source_under) {
  if (!impl_) return moved_from();
  return impl_->change_own_buffer([after, before, &source_under](detail::Txn& txn, std::uint64_t agent, const std::string& agent_iri) {
    return detail::deliver_again(txn, agent, agent_iri, false, after, before, source_under);
  });
}

Result<std::vector<std::uint64_t>> Agent::written(std::uint64_t after, std::size_t limit) const {
  if (!impl_) return moved_from();
  ReadTxn read(*impl_->env);
  if (auto r = read.begin(); !r) return unexpected(r.error());
  auto self = impl_->self_id(read.txn);
  if (!self) return unexpected(self.error());
  std::vector<std::uint64_t> out;
  if (*self == 0) return out;
  MDB_cursor* cursor = nullptr;
  int rc = mdb_cursor_open(read.txn, impl_->env->outbox, &cursor);
  if (rc != 0) return lmdb_fail(rc, "opening an output buffer");
  std::uint64_t from = after + 1;
  MDB_val k = val(*self), v = val(from);
  for (rc = mdb_cursor_get(cursor, &k, &v, MDB_GET_BOTH_RANGE); rc == 0 && (!limit || out.size() < limit);
       rc = mdb_cursor_get(cursor, &k, &v, MDB_NEXT_DUP))
    out.push_back(u64(v));
  mdb_cursor_close(cursor);
  return out;
}

// ---------------------------------------------------------------------------------------------
// Node

struct Node::Impl {
  std::shared_ptr<Env> env;
};

Node::Node(std::shared_ptr<Impl> impl) : impl_(std::move(impl)) {}
Node::Node(Node&&) noexcept = default;
Node& Node::operator=(Node&&) noexcept = default;
Node::~Node() = default;

Result<Node> Node::init(const std::filesystem::path& dir, const InitOptions& options) {
  auto iri = uri::node_iri(options.iri);
  if (!iri) return fail(Errc::invalid_iri, "node IRI: " + iri.error().message);
  if (options.max_map_bytes < kMinMaxMapBytes) return fail(Errc::invalid_argument, "max_map_bytes must be at least 1 MiB");
  InitOptions normalized = options;
  normalized.iri = *iri;
  auto vocabulary = [](Env& made) {
    return made.write([](Txn& txn) -> Result<void> {
      for (auto iri : {kSubscriber, kSubject, kPredicate, kObject}) {
        auto id = intern_term(txn, Term::iri(std::string(iri)), true);
        if (!id) return unexpected(id.error());
      }
      return {};
    });
  };
  auto env = Env::open(dir, &normalized, vocabulary);
  if (!env) return unexpected(env.error());
  if (auto v = load_vocabulary(**env); !v) return unexpected(v.error());
  return Node(std::make_shared<Impl>(Impl{std::move(*env)}));
}

Result<Node> Node::open(const std::filesystem::path& dir) {
  auto env = Env::open(dir, nullptr);
  if (!env) return unexpected(env.error());
  if (auto v = load_vocabulary(**env); !v) return unexpected(v.error());
  return Node(std::make_shared<Impl>(Impl{std::move(*env)}));
}

const std::string& Node::iri() const { return impl_ ? impl_->env->settings().iri : kNoText; }
const std::filesystem::path& Node::dir() const {
  static const std::filesystem::path none;  // of a handle moved from
  return impl_ ? impl_->env->dir() : none;
}

Result<Agent> Node::agent(std::string_view id) const {
  if (!impl_) return moved_from();
  auto agent_iri = uri::agent_iri(iri(), id);
  if (!agent_iri) return fail(Errc::invalid_iri, "agent id: " + agent_iri.error().message);
  auto impl = std::make_unique<Agent::Impl>();
  impl->env = impl_->env;
  impl->id = std::string(id);
  impl->iri = *agent_iri;
  impl->slot = WakeBoard::slot_for(*agent_iri);
  return Agent(std::move(impl));
}

std::optional<std::string> Node::addressee(std::string_view context) const {
  if (!impl_) return std::nullopt;
  auto normal = uri::normalize(context);  // as the store keeps an item's context
  if (!normal) return std::nullopt;
  return detail::addressee_of(iri(), *normal, {});
}

Result<Snapshot> Node::snapshot() const {
  if (!impl_) return moved_from();
  return Snapshot::Impl::open(impl_->env);
}

namespace {

// Removes the records that `collect` names (skipping any already gone, as sub-trees may
// overlap) in one transaction; returns how many went. When that does not fit a full store (the
// removal reserve holds one transaction's new pages: a removal of tens of thousands of scattered
// records touches more), it lists what to remove once and removes it in parts, each a
// transaction of its own that frees pages for the next, halving a part that does not fit, so
// that a full store can be emptied. The list is taken whole first: collected again per part, a
// match removed in one part took its sub-tree (cascade) out of the next part's list. What a
// part removed stays removed if a later one fails.
Result<std::uint64_t> remove_records(Env& env, Reach reach,
                                     const std::function<Result<std::vector<std::uint64_t>>(Txn&)>& collect) {
  const Removal why = reach == Reach::this_node ? Removal::quiet_removal : Removal::explicit_removal;
  std::uint64_t removed = 0;
  auto remove_ids = [&](Txn& txn, std::span<const std::uint64_t> ids) -> Result<void> {
    removed = 0;
    for (std::uint64_t id : ids) {
      auto exists = get_record(txn.raw(), txn.env(), id);
      if (!exists) return unexpected(exists.error());
      if (!*exists) continue;
      if (auto d = delete_record(txn, id, why); !d) return d;
      ++removed;
    }
    return {};
  };
  // On a disk that has filled, a page beyond what the data file has allocated is SIGBUS, not
  // MDB_MAP_FULL: the removal goes in parts from the start, each sized to what is allocated.
  auto room = env.disk_room_for_removal();
  if (!room) return unexpected(room.error());
  if (!*room) {
    auto written = env.write([&](Txn& txn) -> Result<void> {
      auto ids = collect(txn);
      if (!ids) return unexpected(ids.error());
      return remove_ids(txn, *ids);
    }, WriteKind::removal);
    if (written) return removed;
    if (written.error().code != Errc::store_full) return unexpected(written.error());
  }
  std::vector<std::uint64_t> ids;
  // Per record, what its removal adds at most beyond its table paths: its copy in the removal
  // log (R17: its terms, for watchers), whole pages (a large literal's copy is pages of its own,
  // a run that the free pages may not have: `long_copy`).
  std::vector<std::uint64_t> copies;
  std::vector<bool> long_copy;
  constexpr std::uint64_t kPage = 4096;
  auto listed = env.write([&](Txn& txn) -> Result<void> {
    auto all = collect(txn);
    if (!all) return unexpected(all.error());
    ids = std::move(*all);
    TermReader reader(txn.raw(), txn.env());
    for (std::uint64_t id : ids) {
      std::uint64_t bytes = 256;  // the record's meta, source and context, and the entry's own
      auto row = get_record(txn.raw(), txn.env(), id);
      if (!row) return unexpected(row.error());
      if (*row)
        for (std::uint64_t term : {(*row)->s, (*row)->p, (*row)->o})
          if (auto t = reader.get(term, false, false)) bytes += t->value.size() + t->datatype.size() + t->language.size();
      copies.push_back((bytes + kPage - 1) / kPage * kPage);
      long_copy.push_back(bytes > kPage / 4);
    }
    return {};
  }, WriteKind::removal);
  if (!listed) return unexpected(listed.error());
  // The pages a part's transaction copies along the paths of the tables it touches (about ten,
  // a few levels deep each), whatever its size.
  constexpr std::uint64_t kPathPages = 64 * kPage;
  std::uint64_t total = 0;
  auto failed = [&](Error error) -> Result<std::uint64_t> {
    if (total > 0)
      error.message += " (" + std::to_string(total) + " of the records were removed before it; the same removal again takes the rest)";
    return unexpected(std::move(error));
  };
  std::size_t part = 4096;
  std::size_t cap = 4096;        // halved by each part that did not fit: a bound on the parts after
  bool advanced = true;         // since the last part that went
  std::optional<std::uint64_t> per_record;  // on a full disk: how far the last part moved the high-water mark, per record
  for (std::size_t at = 0; at < ids.size();) {
    room = env.disk_room_for_removal();
    if (!room) return failed(room.error());
    if (*room) {
      // Half of what is allocated ahead, at what the last part took per record (a page at
      // least); the first part is one record.
      part = !per_record ? 1 : static_cast<std::size_t>(std::clamp<std::uint64_t>((*room)->at_end / 2 / std::max(*per_record, kPage), 1, 4096));
    }
    part = std::min(part, cap);
    if (*room) {
      // And no more than could be taken if LMDB took every long copy's run at the end (a page
      // written beyond what is allocated there is SIGBUS: the copies of records with large
      // literals made a part of one record take 500 KB, and a probe's 300 KB records died of a
      // bus error after the first few), and the rest from the free pages or the end.
      const auto need = [&](std::size_t n, bool long_only) {
        std::uint64_t sum = kPathPages;
        for (std::size_t i = at; i < at + n && i < ids.size(); ++i)
          if (!long_only || long_copy[i]) sum += copies[i];
        return sum;
      };
      const auto fits = [&](std::size_t n, const DiskRoom& r) {
        return need(n, true) <= r.at_end && need(n, false) <= r.at_end + r.reusable;
      };
      while (part > 1 && !fits(part, **room)) part /= 2;
      if (!fits(part, **room)) {
        // The disk may have room again (space freed since): allocated for this part, if so.
        room = env.disk_room_for_removal(need(part, false));
        if (!room) return failed(room.error());
      }
      if (*room && !fits(part, **room))
        return failed(Error{Errc::store_full, "store full: removing record " + std::to_string(ids[at]) + " copies " +
                                                  std::to_string(copies[at] / 1024) + " KB into the removal log (R17), and the disk holding the store has " +
                                                  std::to_string((*room)->at_end / 1024) + " KB allocated for it beyond its last page; free " +
                                                  std::to_string((need(part, false) + (1 << 20)) / (1 << 20) + 1) + " MB on that disk and remove again"});
    }
    const std::uint64_t end_before = env.pages_end_bytes();
    const std::span<const std::uint64_t> slice(ids.data() + at, std::min(part, ids.size() - at));
    // What the part may copy into the removal log, and its longest copy (one run of pages): the
    // map may grow beyond the removals' reserve for it.
    WriteBound bound;
    for (std::size_t i = at; i < at + slice.size(); ++i) {
      bound.bytes += copies[i];
      if (long_copy[i]) bound.large_term_bytes = std::max(bound.large_term_bytes, copies[i]);
    }
    auto done = env.write([&](Txn& txn) { return remove_ids(txn, slice); }, WriteKind::removal, bound);
    if (!done && done.error().code == Errc::store_full && !advanced) {
      // LMDB reuses the pages a transaction freed from the second transaction after it on: a
      // full store's next part found none, and every smaller one was the same first transaction
      // again. A small write in between makes them free.
      advanced = true;
      if (env.write([](Txn&) -> Result<void> { return {}; }, WriteKind::removal)) continue;
    }
    if (!done) {
      if (done.error().code != Errc::store_full || part == 1) return failed(done.error());
      cap = part / 2;
      part = cap;
      continue;
    }
    const std::uint64_t end_after = env.pages_end_bytes();
    const std::uint64_t took = (end_after > end_before ? end_after - end_before : 0) / slice.size();
    per_record = std::max(per_record.value_or(0) / 2, took);
    total += removed;
    at += slice.size();
    advanced = false;
    // On a full disk, a small write after each part, so that the next part can reuse the pages
    // this one freed (LMDB reuses them from the second transaction on) instead of taking more
    // of the little that is allocated.
    if (*room && at < ids.size())
      advanced = static_cast<bool>(env.write([](Txn&) -> Result<void> { return {}; }, WriteKind::removal));
  }
  return total;
}

// The records of an item and, with cascade N, the sub-trees (depth N) of their objects.
Result<std::vector<std::uint64_t>> item_with_subtrees(Txn& txn, std::uint64_t item_id, unsigned cascade) {
  auto item = get_item(txn.raw(), txn.env(), item_id);
  if (!item) return unexpected(item.error());
  if (!*item) return fail(Errc::not_found, "no item " + std::to_string(item_id) + " in " + txn.env().dir().string());
  Query query(txn.raw(), txn.env());
  std::vector<std::uint64_t> ids, objects;
  for (std::uint64_t id = item_id; id < item_id + (*item)->count; ++id) {
    auto row = get_record(txn.raw(), txn.env(), id);
    if (!row) return unexpected(row.error());
    if (!*row) continue;
    ids.push_back(id);
    objects.push_back((*row)->o);
  }
  if (cascade == 0) return ids;
  for (std::uint64_t object_id : objects) {
    auto object = query.terms().get(object_id);
    if (!object) return unexpected(object.error());
    if (object->is_literal()) continue;
    Pattern below;
    below.s = *object;
    auto sub = query.collect(below, ListOptions{cascade - 1, 0});
    if (!sub) return unexpected(sub.error());
    ids.insert(ids.end(), sub->begin(), sub->end());
  }
  return ids;
}

}  // namespace

namespace {

// The items that declare a subscription (a tv:subscriber record, R9).
Result<std::vector<std::uint64_t>> subscription_items(Txn& txn) {
  std::vector<std::uint64_t> items;
  const std::uint64_t subscriber = txn.env().vocab.subscriber;
  if (subscriber == 0) return items;
  MDB_cursor* cursor = nullptr;
  if (int rc = mdb_cursor_open(txn.raw(), txn.env().idx_p, &cursor); rc != 0) return lmdb_fail(rc, "opening the predicate index");
  MDB_val k = val(subscriber), v;
  std::vector<std::uint64_t> records;
  int rc = mdb_cursor_get(cursor, &k, &v, MDB_SET);
  for (; rc == 0; rc = mdb_cursor_get(cursor, &k, &v, MDB_NEXT_DUP)) records.push_back(u64(v));
  mdb_cursor_close(cursor);
  if (rc != MDB_NOTFOUND) return lmdb_fail(rc, "reading subscriptions");
  for (std::uint64_t id : records) {
    auto row = get_record(txn.raw(), txn.env(), id);
    if (!row) return unexpected(row.error());
    if (*row) items.push_back((*row)->item);
  }
  std::sort(items.begin(), items.end());
  return items;
}

}  // namespace

Result<std::uint64_t> Node::remove(const Pattern& pattern, unsigned cascade, Reach reach) {
  if (!impl_) return moved_from();
  if (!pattern.s && !pattern.p && !pattern.o && !pattern.context && !pattern.source && !pattern.under)
    return fail(Errc::invalid_argument, "refusing to remove with an empty pattern; name a subject, predicate, object, context, source or subject prefix");
  return remove_records(*impl_->env, reach, [&](Txn& txn) -> Result<std::vector<std::uint64_t>> {
    auto ids = Query(txn.raw(), txn.env()).collect(pattern, ListOptions{cascade, 0});
    if (!ids) return ids;
    // A subscription's records are data like any other, and `remove -o ex:heartRate` took the
    // `_:sub tv:object ex:heartRate` of one: the subscription went on, matching any object.
    // Removing by pattern leaves subscriptions whole; removing the item ends one (R9).
    auto subscriptions = subscription_items(txn);
    if (!subscriptions) return unexpected(subscriptions.error());
    if (subscriptions->empty()) return ids;
    std::vector<std::uint64_t> kept;
    for (std::uint64_t id : *ids) {
      auto row = get_record(txn.raw(), txn.env(), id);
      if (!row) return unexpected(row.error());
      if (*row && std::binary_search(subscriptions->begin(), subscriptions->end(), (*row)->item)) continue;
      kept.push_back(id);
    }
    return kept;
  });
}

Result<std::uint64_t> Node::remove_item(std::uint64_t item_id, unsigned cascade, Reach reach) {
  if (!impl_) return moved_from();
  return remove_records(*impl_->env, reach, [&](Txn& txn) { return item_with_subtrees(txn, item_id, cascade); });
}

Result<std::uint64_t> Node::remove_items(const std::vector<std::uint64_t>& item_ids, Reach reach) {
  if (!impl_) return moved_from();
  if (item_ids.empty()) return std::uint64_t{0};
  return remove_records(*impl_->env, reach, [&](Txn& txn) -> Result<std::vector<std::uint64_t>> {
    std::vector<std::uint64_t> ids;
    for (std::uint64_t item : item_ids) {
      auto records = item_with_subtrees(txn, item, 0);
      if (!records && records.error().code == Errc::not_found) continue;
      if (!records) return unexpected(records.error());
      ids.insert(ids.end(), records->begin(), records->end());
    }
    return ids;
  });
}

bool Node::wait_for_commit(const std::function<bool()>& ready, std::chrono::nanoseconds timeout) const {
  if (!impl_) return ready();
  const auto deadline = deadline_after(timeout);
  WakeBoard& board = impl_->env->wake();
  for (;;) {
    // A commit bumps the slots of the input buffers it changed before the commit slot: a
    // buffer version that `ready` misses moves the commit slot past `token`, and wait returns.
    const std::uint32_t token = board.version(WakeBoard::kAnyCommit);
    if (ready()) return true;
    auto left = deadline - std::chrono::steady_clock::now();
    if (left <= std::chrono::nanoseconds::zero()) return false;
    if (board.sleep_buffers(token, std::chrono::duration_cast<std::chrono::nanoseconds>(left))) return ready();
  }
}

void Node::wake_waiters() const {
  if (impl_) impl_->env->wake().wake_buffer_waiters();
}

void set_wait_spin(std::chrono::microseconds budget) { WakeBoard::set_spin_budget(budget); }

std::chrono::microseconds wait_spin() {
  return std::chrono::duration_cast<std::chrono::microseconds>(WakeBoard::spin_budget());
}

Result<std::vector<Change>> Node::watch(std::uint64_t bookmark, std::chrono::milliseconds timeout, std::size_t limit) const {
  if (!impl_) return moved_from();
  const auto deadline = deadline_after(timeout);
  WakeBoard& board = impl_->env->wake();
  for (;;) {
    const std::uint32_t token = board.version(WakeBoard::kAnyCommit);
    std::vector<Change> changes;
    {
      ReadTxn read(*impl_->env);
      if (auto r = read.begin(); !r) return unexpected(r.error());
      Query query(read.txn, *impl_->env);
      // Insertions: records after the bookmark. Removals: the log after the bookmark.
      Pattern after;
      after.after_id = bookmark;
      auto walked = query.for_each(after, [&](std::uint64_t id, const RecordRow& row) {
        auto rec = query.materialize(id, row);
        if (rec) {
          changes.push_back(Change{id, false, std::move(*rec), {}});
        } else {
          Change unreadable{id, false, {}, "record " + std::to_string(id) + ": " + rec.error().message};
          unreadable.record.meta.id = id;
          changes.push_back(std::move(unreadable));
        }
        return !(limit && changes.size() >= limit);
      });
      if (!walked) return unexpected(walked.error());
      MDB_cursor* cursor = nullptr;
      // Nothing comes after the greatest bookmark (bookmark + 1 wrapped to 0: every removal).
      if (bookmark != UINT64_MAX && mdb_cursor_open(read.txn, impl_->env->removals, &cursor) == 0) {
        std::uint64_t from = bookmark + 1;
        MDB_val k = val(from), v;
        for (int rc = mdb_cursor_get(cursor, &k, &v, MDB_SET_RANGE); rc == 0; rc = mdb_cursor_get(cursor, &k, &v, MDB_NEXT)) {
          Change change{u64(k), true, {}, {}};
          if (!decode_removed(view(v), change.record)) {
            change.record = Record{};
            change.unreadable = "removal log entry " + std::to_string(change.seq) +
                                " cannot be read: truncated, or written by a later build";
          }
          changes.push_back(std::move(change));
        }
        mdb_cursor_close(cursor);
      }
      // Removals after the bookmark that left the log before this read: said, not skipped.
      MDB_val tk = val(kRemovalsTrimmedKey), tv;
      if (mdb_get(read.txn, impl_->env->meta, &tk, &tv) == 0 && tv.mv_size == sizeof(std::uint64_t)) {
        const std::uint64_t trimmed = u64(tv);
        // From 0 a watcher reads every record as new: it saw none of those removed.
        if (bookmark != 0 && trimmed > bookmark) {
          Change gap{trimmed, true, {}, {}};
          gap.unreadable = "removals with sequence numbers " + std::to_string(bookmark + 1) + " to " + std::to_string(trimmed) +
                           " left the removal log before they were read (it keeps the latest, R17): records removed "
                           "then are not listed here; read the board again";
          changes.push_back(std::move(gap));
        }
      }
      // Records after the bookmark that the ring or a time-to-live reclaimed before this read:
      // they log no removal, and a `tail` of a ring store that fell behind skipped 36,000 of
      // 40,000 without a word. From 0 too: a `tail` begun on an empty store starts there.
      MDB_val rk = val(kReclaimedThroughKey), rv;
      if (mdb_get(read.txn, impl_->env->meta, &rk, &rv) == 0 && rv.mv_size == sizeof(std::uint64_t)) {
        const std::uint64_t reclaimed = u64(rv);
        if (reclaimed > bookmark) {
          Change gap{reclaimed, true, {}, {}, true};
          // "Some": a persistent record, or one waiting in a buffer, within the range is kept,
          // and is listed (a developer read "ids from 1 to 12 were reclaimed" after records 6
          // and 7, still there).
          gap.unreadable = "some records with ids from " + std::to_string(bookmark + 1) + " to " + std::to_string(reclaimed) +
                           " were reclaimed (the ring, or a time-to-live) before they were read: those are not "
                           "listed here; read the board again";
          changes.push_back(std::move(gap));
        }
      }
    }
    if (!changes.empty()) {
      std::sort(changes.begin(), changes.end(), [](const Change& a, const Change& b) { return a.seq < b.seq; });
      if (limit && changes.size() > limit) changes.resize(limit);
      return changes;
    }
    auto left = deadline - std::chrono::steady_clock::now();
    if (left <= std::chrono::nanoseconds::zero()) return changes;
    if (board.sleep(WakeBoard::kAnyCommit, token, std::chrono::duration_cast<std::chrono::nanoseconds>(left))) return changes;
  }
}

Result<void> Node::set_ttl(std::string_view predicate_iri, std::chrono::nanoseconds ttl) {
  if (!impl_) return moved_from();
  auto iri = uri::normalize(predicate_iri);
  if (!iri) return fail(Errc::invalid_iri, "TTL predicate: " + iri.error().message);
  if (ttl.count() < 0) return fail(Errc::invalid_argument, "a time-to-live cannot be negative");
  return impl_->env->write([&](Txn& txn) -> Result<void> {
    // Pinned so that the cached rule's id stays valid while no record uses the predicate.
    auto id = intern_term(txn, Term::iri(std::string(predicate_iri)), true);
    if (!id) return unexpected(id.error());
    std::string key = "ttl:" + std::string(predicate_iri);
    MDB_val k = val(key);
    std::int64_t ns = ttl.count();
    MDB_val v = val(&ns, sizeof ns);
    int rc = ns == 0 ? mdb_del(txn.raw(), txn.env().meta, &k, nullptr) : mdb_put(txn.raw(), txn.env().meta, &k, &v, 0);
    if (rc != 0 && rc != MDB_NOTFOUND) return lmdb_fail(rc, "writing a time-to-live rule");
    ++txn.counters.ttl_gen;
    return {};
  });
}

Result<std::vector<std::pair<std::string, std::chrono::nanoseconds>>> Node::ttls() const {
  if (!impl_) return moved_from();
  ReadTxn read(*impl_->env);
  if (auto r = read.begin(); !r) return unexpected(r.error());
  std::vector<std::pair<std::string, std::chrono::nanoseconds>> out;
  MDB_cursor* cursor = nullptr;
  int rc = mdb_cursor_open(read.txn, impl_->env->meta, &cursor);
  if (rc != 0) return lmdb_fail(rc, "opening settings");
  const std::string_view prefix = "ttl:";
  MDB_val k = val(prefix), v;
  for (rc = mdb_cursor_get(cursor, &k, &v, MDB_SET_RANGE); rc == 0; rc = mdb_cursor_get(cursor, &k, &v, MDB_NEXT)) {
    std::string_view key = view(k);
    if (key.substr(0, prefix.size()) != prefix) break;
    std::int64_t ns = 0;
    std::memcpy(&ns, v.mv_data, std::min(v.mv_size, sizeof ns));
    out.emplace_back(std::string(key.substr(prefix.size())), std::chrono::nanoseconds(ns));
  }
  mdb_cursor_close(cursor);
  return out;
}

Result<std::uint64_t> Node::reclaim() {
  if (!impl_) return moved_from();
  // A pass reclaims at most kTtlScanBudget records per TTL rule (a write's retention must stay
  // short): passes, each its own transaction, until one reclaims nothing, or as many records as
  // the store held at the start are reclaimed (writers storing records already due would keep
  // the loop going; their own writes reclaim too).
  // A pass that reclaimed nothing but stopped at its budget among records waiting in input
  // buffers has more to look at: it goes on, as many passes as the records could fill.
  auto held = stats();
  const std::uint64_t at_most = held ? held->records : ~0ull;
  std::uint64_t reclaimed = 0, empty_passes = 0;
  while (reclaimed < at_most) {
    std::uint64_t pass = 0;
    bool unfinished = false;
    auto written = impl_->env->write([&](Txn& txn) -> Result<void> {
      auto n = apply_retention(txn);
      if (!n) return unexpected(n.error());
      pass = *n;
      unfinished = txn.retention_unfinished;
      return {};
    }, WriteKind::removal);
    if (!written) return unexpected(written.error());
    if (pass == 0 && (!unfinished || ++empty_passes > at_most / 4096 + 2)) break;
    reclaimed += pass;
  }
  return reclaimed;
}

Result<void> Node::set_prefix(std::string_view prefix, std::string_view namespace_iri) {
  if (!impl_) return moved_from();
  uri::PrefixMap check;
  if (auto a = check.add(prefix, namespace_iri); !a) return fail(Errc::invalid_iri, a.error().message);
  return impl_->env->write([&](Txn& txn) -> Result<void> {
    std::string key = "prefix:" + std::string(prefix);
    MDB_val k = val(key), v = val(namespace_iri);
    int rc = mdb_put(txn.raw(), txn.env().meta, &k, &v, 0);
    if (rc != 0) return lmdb_fail(rc, "writing prefix " + std::string(prefix));
    return {};
  });
}

Result<std::string> Node::store_id() const {
  if (!impl_) return moved_from();
  ReadTxn read(*impl_->env);
  if (auto r = read.begin(); !r) return unexpected(r.error());
  MDB_val k = val(kStoreIdKey), v;
  int rc = mdb_get(read.txn, impl_->env->meta, &k, &v);
  if (rc != 0) return lmdb_fail(rc, "reading the store id");
  return std::string(view(v));
}

Result<std::vector<std::string>> Node::copied_from() const {
  if (!impl_) return moved_from();
  ReadTxn read(*impl_->env);
  if (auto r = read.begin(); !r) return unexpected(r.error());
  MDB_val k = val(kCopiedFromKey), v;
  int rc = mdb_get(read.txn, impl_->env->meta, &k, &v);
  if (rc == MDB_NOTFOUND) return std::vector<std::string>{};
  if (rc != 0) return lmdb_fail(rc, "reading the stores this one was copied from");
  std::vector<std::string> ids;
  std::istringstream text{std::string(view(v))};
  for (std::string id; text >> id;) ids.push_back(std::move(id));
  return ids;
}

namespace {

// fsync of a file or directory by path: what a rename needs before and after it to survive a
// power cut (the copy's data, the new name, the directory entry).
Result<void> sync_path(const std::filesystem::path& path, bool directory) {
  int fd = ::open(path.c_str(), (directory ? O_RDONLY | O_DIRECTORY : O_RDONLY) | O_CLOEXEC);
  if (fd < 0) return fail(Errc::io, "cannot open " + path.string() + " to sync it: " + std::strerror(errno));
  int rc = ::fsync(fd);
  int saved = errno;
  ::close(fd);
  if (rc != 0) return fail(Errc::io, "cannot sync " + path.string() + ": " + std::strerror(saved));
  return {};
}

}  // namespace

Result<std::uint64_t> Node::back_up(const std::filesystem::path& requested) const {
  if (!impl_) return moved_from();
  namespace fs = std::filesystem;
  // "copy/" names the directory copy: without the trailing separator its filename is "copy"
  // and the partial copy goes beside it, not inside it.
  fs::path dest = requested;
  while (!dest.empty() && !dest.has_filename() && dest.has_relative_path()) dest = dest.parent_path();
  if (dest.empty() || !dest.has_filename())
    return fail(Errc::invalid_argument, "'" + requested.string() + "' names no new directory for the backup");
  std::error_code ec;
  if (fs::exists(fs::symlink_status(dest, ec)))
    return fail(Errc::invalid_argument, dest.string() + " exists: a backup goes to a new directory");
  const fs::path parent = dest.has_parent_path() ? dest.parent_path() : fs::path(".");
  const fs::path partial = parent / (dest.filename().string() + ".partial-" + std::to_string(::getpid()));
  fs::remove_all(partial, ec);
  if (!fs::create_directory(partial, ec))
    return fail(Errc::io, "cannot make " + partial.string() + ": " + (ec ? ec.message() : "it exists"));
  auto discard = [&](Error error) -> Result<std::uint64_t> {
    std::error_code ignored;
    fs::remove_all(partial, ignored);
    return unexpected(std::move(error));
  };
  // MDB_CP_COMPACT copies from one read transaction: a snapshot, and without the free pages.
  if (int rc = mdb_env_copy2(impl_->env->raw(), partial.c_str(), MDB_CP_COMPACT); rc != 0)
    return discard(Error{rc == ENOSPC ? Errc::store_full : Errc::io,
                         "cannot copy the store to " + partial.string() + ": " + mdb_strerror(rc)});
  // A store restored from the copy goes on from the backup's snapshot, a point its peers have
  // passed: to them it must be another store, whose streams start again (what it sends again
  // is dropped where held, docs/protocol.md P10c), not this one, whose next ids they would drop
  // as ones they have. Only a peer's mark above what the link could have sent showed it before,
  // and agents that wrote before the link started hid that.
  if (auto renewed = renew_store_id_of_copy(partial); !renewed) return discard(renewed.error());
  const std::uintmax_t bytes = fs::file_size(partial / "data.mdb", ec);
  if (ec) return discard(Error{Errc::io, "cannot read the size of the copy in " + partial.string() + ": " + ec.message()});
  // LMDB's copy does not sync: without these a power cut soon after could leave DEST named but
  // its data not on disk.
  if (auto synced = sync_path(partial / "data.mdb", false); !synced) return discard(synced.error());
  if (auto synced = sync_path(partial, true); !synced) return discard(synced.error());
  // RENAME_NOREPLACE: a DEST made by someone else since the check above is not replaced.
  if (::renameat2(AT_FDCWD, partial.c_str(), AT_FDCWD, dest.c_str(), RENAME_NOREPLACE) != 0) {
    int saved = errno;
    if (saved == EEXIST || saved == ENOTEMPTY)
      return discard(Error{Errc::invalid_argument, dest.string() + " exists: a backup goes to a new directory"});
    return discard(Error{Errc::io, "cannot rename " + partial.string() + " to " + dest.string() + ": " + std::strerror(saved)});
  }
  if (auto synced = sync_path(parent, true); !synced) return unexpected(synced.error());
  return static_cast<std::uint64_t>(bytes);
}

Result<std::string> Node::renew_store_id() {
  if (!impl_) return moved_from();
  std::string id = new_store_id();
  auto written = impl_->env->write([&](Txn& txn) -> Result<void> {
    return renew_store_id_as_copy(txn.raw(), txn.env().meta, id);
  });
  if (!written) return unexpected(written.error());
  return id;
}

uri::PrefixMap Node::prefixes() const {
  uri::PrefixMap map;
  if (!impl_) return map;
  ReadTxn read(*impl_->env);
  if (!read.begin()) return map;
  MDB_cursor* cursor = nullptr;
  if (mdb_cursor_open(read.txn, impl_->env->meta, &cursor) != 0) return map;
  const std::string_view prefix = "prefix:";
  MDB_val k = val(prefix), v;
  for (int rc = mdb_cursor_get(cursor, &k, &v, MDB_SET_RANGE); rc == 0; rc = mdb_cursor_get(cursor, &k, &v, MDB_NEXT)) {
    std::string_view key = view(k);
    if (key.substr(0, prefix.size()) != prefix) break;
    (void)map.add(key.substr(prefix.size()), view(v));
  }
  mdb_cursor_close(cursor);
  return map;
}

Result<CheckReport> Node::check(std::size_t max_problems, const std::function<void(std::string_view)>& progress,
                                const std::function<void(std::string_view)>& found) const {
  if (!impl_) return moved_from();
  ReadTxn read(*impl_->env);
  if (auto r = read.begin(); !r) return unexpected(r.error());
  return check_store(*impl_->env, read.txn, max_problems, progress, found);
}

Result<Stats> Node::stats() const {
  if (!impl_) return moved_from();
  ReadTxn read(*impl_->env);
  if (auto r = read.begin(); !r) return unexpected(r.error());
  auto c = load_counters(read.txn, impl_->env->main);
  if (!c) return unexpected(c.error());
  const Settings& s = impl_->env->settings();
  Stats st;
  st.iri = s.iri;
  st.durability = s.durability;
  st.ring = s.ring;
  st.max_literal_bytes = s.max_literal_bytes;
  st.records = c->records;
  st.persistent_records = c->persistent_records;
  st.items = c->items;
  st.terms = c->terms;
  st.terms_collected = c->next_term - 1 - c->terms;
  st.subscriptions = c->subscriptions;
  st.pending_deliveries = c->pending;
  st.last_seq = c->next_seq - 1;
  st.reclaimed_records = c->reclaimed;
  const Env& env = *impl_->env;
  // Every page up to the last in use that is not free: the tables' pages, LMDB's own (its free
  // list, the meta pages) and those copies on write have not yet released. The sum of the tables'
  // pages left those out and showed a full store at 40-70% of its maximum.
  st.used_bytes = pages_in_use_bytes(env.raw(), read.txn);
  MDB_envinfo info;
  mdb_env_info(env.raw(), &info);
  MDB_stat ms;
  if (mdb_env_stat(env.raw(), &ms) == 0) st.high_water_bytes = (info.me_last_pgno + 1) * ms.ms_psize;
  st.map_bytes = info.me_mapsize;
  st.max_map_bytes = s.max_map_bytes;
  return st;
}

}  // namespace tahvel::node
