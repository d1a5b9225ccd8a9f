// The whiteboard node: a semantic triple store in one LMDB environment (a directory), shared by
// every local agent process, at once their database and their only channel (DESIGN §3).
//
//   auto node = Node::open("state/home1");            // every process opens the same directory
//   auto hrv = node->agent("hrv");                    // IRI = node IRI + "/hrv"; fixes `source`
//   if (!hrv->subscribe({.p = Term::iri(tv + "rr")})) ...   // a subscription: triples on the board
//   for (;;) {                                        // input buffer, woken by futex
//     auto d = hrv->take(1000ms, Ack::manual);        // nullopt: timeout, look again
//     if (!d) return d.error();                       // errors are values: the store is gone, ...
//     if (!*d) continue;
//     if (auto stored = hrv->store(item); !stored) return stored.error();  // derived from **d
//     hrv->ack((*d)->item);                           // only now: a crash before delivers it again
//   }
// (docs/api.md walks through a whole agent, agents/examples/example_agent_cpp.cpp.)
//
// Workload: many small items (measurements, 1-10 triples) from a few local writers, a few
// readers, occasional large literals (1 s ECG chunks). Writers are serialised by LMDB; readers
// never block and see a consistent snapshot.
//
// Threads: a Node, Agent or Snapshot object may be used from one thread at a time. Different
// objects (also of the same directory) may be used from different threads and processes.
// Lifetimes: Agent and Snapshot keep the node's environment open; they may outlive the Node
// object they came from. All results are copies owned by the caller.
#pragma once

#include <chrono>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "tahvel/node/error.h"
#include "tahvel/node/term.h"
#include "tahvel/uri/iri.h"

namespace tahvel::node {

// ---------------------------------------------------------------------------------------------
// Records

struct RecordMeta {
  std::uint64_t id = 0;           // monotonic per node, never reused
  std::uint64_t item = 0;         // the item it was written in (= the id of its first record)
  std::int64_t stored_at = 0;     // ns since the Unix epoch, set by the store
  std::int64_t asserted_at = 0;   // ns since the epoch when the fact held (default: stored_at)
  std::string source;             // IRI of the writing agent, set by the store, not forgeable
  std::string context;            // addressee or data group IRI, empty for none
  bool persistent = false;        // never expires by ring or time-to-live
  std::int64_t span = 0;          // ns the fact held from asserted_at (Item::span); 0: an instant
};

struct Record {
  Triple triple;
  RecordMeta meta;
};

// How far an explicit removal goes: also to the copies this node's link sent up or down, which
// the agents that receive removal notices are told of (Agent::receive_removals,
// docs/protocol.md P7a, P10a), or only this node's records (an operator pruning a gateway's
// store, whose parent keeps what it was sent).
enum class Reach { copies_too, this_node };

// What Agent::deliver_persistent_again puts into the buffer again: the persistent items the
// agent's subscriptions match, or those and the ones addressed to it by their context (R18).
enum class Redelivery { subscribed, addressed_too };

// A triple pattern with optional metadata filters. An unset position matches anything.
// A pattern with a bound subject, predicate or object is answered through an index; a pattern
// with none bound scans the records in id order. A time range (since, until) is answered
// through the time index when its items are fewer than the bound term's records: its cost
// follows the range, not the store. Matches come in id order either way.
struct Pattern {
  std::optional<Term> s, p, o;
  std::optional<std::string> context;    // exact context IRI ("" matches records without one)
  std::optional<std::string> source;     // source IRI, or any IRI under it (uri::is_under)
  // Subject IRI, or any IRI under it (uri::is_under): a recording's chunks, <rec>/chunk/N, are
  // under <rec>. A blank subject is under nothing. Not for subscriptions.
  std::optional<std::string> under;
  // A time range, ns: a record whose fact held at some time in [since, until). An instant
  // (span 0) when since <= asserted_at < until; a record with a span when [asserted_at,
  // asserted_at + span) overlaps the range, so that a range starting inside a chunk of signal
  // gets that chunk.
  std::optional<std::int64_t> since;
  std::optional<std::int64_t> until;
  std::optional<std::uint64_t> after_id; // record id > after_id
};

struct ListOptions {
  // Cascade depth: 0 returns the matches only; N also returns, for each match whose object is an
  // IRI or blank node, the records with that object as subject, recursively to depth N (the
  // thesis' cascade read). Each record appears once, matches first in id order, each followed by
  // its sub-tree in depth-first order.
  unsigned cascade = 0;
  std::size_t limit = 0;  // at most this many records in all (0: no limit)
};

// One entry of the change stream that Node::watch returns. Insertions carry the record's id as
// their sequence; removals get a new sequence number from the same counter, so the stream is
// totally ordered and a bookmark (the last seq seen) resumes it exactly.
struct Change {
  std::uint64_t seq = 0;
  bool removed = false;
  Record record;
  // Why this change cannot be read (a damaged record or removal-log entry, or one written by a
  // later build); empty when it can. Such a change stays in the stream, its record empty but
  // for meta.id (an insertion's record id), so that a reader knows what it did not see instead
  // of missing it without a word.
  std::string unreadable;
  // With `unreadable`: records with ids up to seq were reclaimed by the ring or a time-to-live
  // before this reader read them (Node::watch), rather than a change that cannot be read. A
  // reader that counts reclaims itself (Stats::reclaimed_records) may pass over it.
  bool reclaimed = false;
};

// ---------------------------------------------------------------------------------------------
// Snapshot: a consistent, read-only view of the whole whiteboard (an LMDB read transaction).
// Holding one does not block writers, but keeps the pages it sees from reuse: release it soon.
// While a process holds a snapshot it cannot adopt a map that another process grew, nor grow the
// map itself: a new snapshot, or a write that needs a larger map, in that process waits up to
// 1 s for its snapshots to end and then fails (Errc::io, "release the snapshot and retry").
// Release snapshots before writing, above all in a thread that writes.

// What Node::check found: every table read whole in one snapshot, each row decoded and each
// reference between tables followed (docs/architecture.md, "Checking a store").
struct CheckReport {
  std::uint64_t records = 0, items = 0, terms = 0;
  std::uint64_t index_entries = 0;   // subject, predicate and object index entries
  std::uint64_t time_entries = 0;    // time index entries
  std::uint64_t buffer_entries = 0;  // input and output buffer entries
  std::vector<std::string> problems; // empty: the store holds together; else the first ones found
  std::uint64_t problems_found = 0;  // all of them (problems holds up to max_problems)
};

// One agent's input buffer (Snapshot::input_buffers).
struct InputBufferSummary {
  std::string agent;                   // IRI
  std::uint64_t waiting = 0;           // items in it
  std::uint64_t oldest_item = 0;       // the first take() would return
  std::int64_t oldest_asserted_at = 0; // of that item, ns since the epoch
};

struct PredicateSummary {
  std::string predicate;  // IRI
  std::uint64_t records = 0;
  std::int64_t first_asserted_at = 0, last_asserted_at = 0;  // ns since the epoch
};

// For the "did you mean" of a predicate asked for (a pattern, a rule) among those a store holds
// (Snapshot::predicates): whether it is held (with records), and if not, the held predicate it
// is most likely a slip of: fewest one-character edits on the whole IRI or on the local name
// (after the last '#' or '/'; under another namespace one edit more: sosa:rmssdMs for the tv:
// one), fewer than `edits_below`; nullptr when none is that near.
struct PredicateMatch {
  bool held = false;
  const PredicateSummary* nearest = nullptr;  // into the vector given
  // The other held predicates exactly as near ("sdnMs" is one edit from "sd1Ms" and from
  // "sdnnMs"): naming only the first would guess. Empty when `nearest` is the only one.
  std::vector<const PredicateSummary*> as_near;
};
PredicateMatch match_predicate(std::string_view asked, const std::vector<PredicateSummary>& held, std::size_t edits_below);

class Snapshot {
 public:
  Snapshot(Snapshot&&) noexcept;
  Snapshot& operator=(Snapshot&&) noexcept;
  ~Snapshot();

  // Records matching `pattern` (see ListOptions for cascade and limit).
  Result<std::vector<Record>> list(const Pattern& pattern, const ListOptions& options = {}) const;

  // Calls `visit` for each match (no cascade) until it returns false. The Record is valid only
  // during the call. No allocation per record beyond the strings of its terms.
  Result<void> for_each(const Pattern& pattern,
                        const std::function<bool(const Record&)>& visit) const;

  // Number of records matching `pattern`.
  Result<std::uint64_t> count(const Pattern& pattern) const;

  // What the store holds, per predicate, in predicate IRI order: how many records, and the
  // asserted-at of the first and of the last stored of them (the oldest and newest record ids:
  // for data stored as it happens, such as a sensor's, its time range). Costs two record
  // lookups per distinct predicate, not a scan: an operator may ask a large store for it.
  Result<std::vector<PredicateSummary>> predicates() const;

  // Every input buffer that holds an item, in agent IRI order: how many wait and the oldest.
  // For an operator's "what waits for whom", an item addressed to an agent that never comes
  // among them; one lookup per agent, not a scan of the items.
  Result<std::vector<InputBufferSummary>> input_buffers() const;

  // All current records of one item, in id order. Error not_found when none remain.
  Result<std::vector<Record>> item(std::uint64_t item_id) const;

  // The highest sequence number (record id, removal or removal notice) visible in this snapshot.
  std::uint64_t last_seq() const;

  // How many sequence numbers removal notices have taken in this store so far (never lowered).
  // A notice is neither a record nor a logged removal: a reader that accounts for every number
  // between two snapshots counts the difference of these too. (Notices written by a build from
  // before this count are not in it.)
  std::uint64_t notice_seqs() const;

 private:
  friend class Node;
  friend class Agent;
  struct Impl;
  explicit Snapshot(std::unique_ptr<Impl>);
  std::unique_ptr<Impl> impl_;
};

struct SubscribeOptions {
  // A new subscription also puts into the input buffer, in the same transaction, every item
  // already on the board that it would have routed, oldest first (R10a): an agent started after
  // its input was written (a stage of a pipeline started after a recording was replayed) still
  // gets all of it, and a crash cannot leave the subscription without its earlier items.
  bool earlier = false;
  // With `earlier`, only the persistent items: a child's link agent on a parent, the child added
  // to the tree after settings were written for the whole subtree (`<parent>/*`, P11), gets the
  // settings kept for every node, not the commands sent before it existed.
  bool persistent_only = false;
  // Only a subscription this agent wrote itself is "the existing one" a subscription with the
  // same pattern returns: one another writer made for it (a parent's forwarding policy sent down
  // for a node's uplink) is that writer's to remove, and a topology file's identical `forward`
  // pattern taken for it went with the parent's removal (raw ECG stopped going up).
  bool own_only = false;
};

// ---------------------------------------------------------------------------------------------
// Agent: a handle that fixes an agent's IRI (= node IRI + "/" + id) and so the `source` of what
// it writes. Owns the agent's output buffer (what it wrote, for audit) and input buffer
// (deliver-once queue of items routed to it by its subscriptions).

struct Delivery {
  std::uint64_t item = 0;       // the item's id, or the removal notice's
  std::vector<Record> records;  // the whole item as it is now; for a notice, the records removed
                                // (meta.id - meta.item: each one's position in its item)
  // A removal notice (Agent::receive_removals): records of an item routed to this agent were
  // removed explicitly. `records` are those records as they were (their metadata included).
  bool removal = false;
};

// An item that a link agent stores on behalf of a writer on another node (docs/protocol.md).
struct RelayedItem {
  std::uint64_t seq = 0;   // its sequence number on the stream (the item's id on the sender)
  std::uint64_t prev = 0;  // the sequence number the sender sent just before it on the stream
  std::string source;      // the original writer's IRI, kept as the records' source
  Item item;
  // A removal notice relayed: `item` holds the records removed on the sender (their context and
  // asserted-at time), and relay removes this store's copies of them instead of storing it.
  bool removal = false;
  // For a notice: each triple's position in its item (a notice's Record has it as
  // meta.id - meta.item). Relaying keeps the order of an item's triples, so a copy's record is
  // at the same position; a notice without one for each triple is refused.
  std::vector<std::uint32_t> positions;
};

// An item that Agent::relay refused for good: what it breaks is in `why`.
struct RefusedItem {
  std::uint64_t seq = 0;
  Error why;
};

struct RelayOutcome {
  std::uint64_t mark = 0;             // the stream's mark afterwards: last seq applied in order
  std::vector<std::uint64_t> stored;  // ids of the items stored, in order
  std::size_t duplicates = 0;         // items at or below the mark, dropped
  std::size_t already_held = 0;       // items this store holds already, the same from the
                                      // same source (sent again on another stream: persistent
                                      // ones, docs/protocol.md P6c, and any up to the stream's
                                      // relay_may_repeat): dropped, the mark moved past them
  std::size_t recomputed = 0;         // of those, items held by name only: computed again,
                                      // with other triples, by a store that replaced the one
                                      // they came from (relay_may_repeat)
  bool gap = false;                   // an item's prev was not the mark: it and those after it
                                      // were not applied (the sender resends from the mark)
  std::vector<RefusedItem> refused;   // items in order that this node can never store; the
                                      // mark moved past them
  std::size_t removals = 0;           // removal notices applied (RelayedItem::removal)
  std::uint64_t records_removed = 0;  // records they removed (0 for a copy no longer held)
  // The store had no room for the whole run: a first part that fit was applied (the run halved
  // until one did, so at least half of the items that would have fitted), up to
  // `mark`, and those after it were not, for this reason (store_full). The sender sends them
  // again from the mark once there is room.
  std::optional<Error> not_applied;
};

enum class Ack {
  automatic,  // take() removes the item from the input buffer in the same transaction
  manual,     // take() leaves it there; the agent calls ack(item) once it has processed it, so a
              // crash in between delivers it again after restart
};

// The records of Agent::report_problem.
inline const std::string kProblem = std::string(uri::kTahvelNs) + "problem";
inline const std::string kProblemPid = std::string(uri::kTahvelNs) + "pid";

// What Agent::store_subscriptions did: the new items' ids, in order, and how many items it put
// into their subscribers' input buffers.
struct StoredSubscriptions {
  std::vector<std::uint64_t> ids;
  std::uint64_t caught_up = 0;
};

class Agent {
 public:
  Agent(Agent&&) noexcept;
  Agent& operator=(Agent&&) noexcept;
  ~Agent();

  // Empty for a handle moved from (its other calls fail with invalid_argument).
  const std::string& iri() const;
  const std::string& id() const;

  // Writes `item` atomically: terms are checked (IRIs absolute, literal size within the node's
  // limit), blank nodes renamed, the item recorded in this agent's output buffer, routed into the
  // input buffers of matching subscriptions, and subscribers woken. Returns the item id.
  // Errors: invalid_argument (empty item), invalid_iri, literal_too_large, store_full, io.
  // On error nothing of the item is stored.
  Result<std::uint64_t> store(const Item& item) noexcept;

  // Stores many items in one transaction (bulk load). Returns their ids in order.
  Result<std::vector<std::uint64_t>> store_all(const std::vector<Item>& items) noexcept;

  // Stores `subscriptions` (items holding subscription records, as store_all) that are written
  // after what they follow had begun: an area subscription's new expansion (docs/spatial.md S9),
  // when a sensor's readings between its move into the area and the expansion were routed by
  // the expansions then on the board. In the same transaction, puts into the input buffer of
  // each one's subscriber the items with an id after `missed_after[i]` (one per item; 0: from
  // the first) that it matches, unless the subscriber got them, or has them coming, anyway (one
  // of its subscriptions older than these routes them, or they are addressed to it, R18) or
  // they are there already; oldest first. Older than these: below `older_than`, or (0) than the
  // first of them (a caller storing one sync's subscriptions in parts gives the first part's
  // first id). A crash leaves both done or neither. Errors: those of store_all;
  // invalid_argument when the two lists differ in length.
  Result<StoredSubscriptions> store_subscriptions(const std::vector<Item>& subscriptions,
                                                  std::span<const std::uint64_t> missed_after,
                                                  std::uint64_t older_than = 0) noexcept;

  // Removes the records matching each of `removals` (as Node::remove with cascade 0) and stores
  // `items` (as store_all), in one transaction: a reader sees the old records or the new ones,
  // never neither (a room's state, a reasoner's conclusions). Either list may be empty. Returns
  // the ids of the items stored. Errors: those of store_all; invalid_argument for a removal
  // pattern with nothing bound. On error nothing is removed or stored.
  Result<std::vector<std::uint64_t>> replace(const std::vector<Pattern>& removals,
                                             const std::vector<Item>& items) noexcept;

  // Says on the board what this agent cannot do as asked, for `tahvel status` here and on the
  // nodes above (docs/vocabulary.md, "Problems"): `<agent> tv:problem "text"; tv:pid <this
  // process>`, one persistent item in place of the problem it said before; empty `text` says
  // the problem is over (removes it). Writes nothing when the board already says so, so an
  // agent may report its state each time it looks. Bytes of `text` that are not UTF-8 are
  // written as U+FFFD. Errors: those of replace.
  Result<void> report_problem(std::string_view text) noexcept;

  // The oldest item in this agent's input buffer, waiting up to `timeout` for one to arrive
  // (woken by the writer's commit, no polling). Returns nullopt on timeout. An item removed from
  // the store before it was taken is skipped. milliseconds::max() (or any timeout too long to
  // add to now) waits without limit; zero or a negative one does not wait. A signal that runs a
  // handler while it sleeps ends the wait as a timeout does, SA_RESTART or not (the kernel does
  // not restart a wait with a time limit), so that a program sees the stop flag its handler set;
  // so do peek, Node::watch and Node::wait_for_commit. One in the microseconds before the sleep
  // is not seen until the wait ends: a program that stops on a signal waits with a limit and
  // checks its flag between waits. A loop that waits for items takes nullopt as "look again".
  Result<std::optional<Delivery>> take(std::chrono::milliseconds timeout,
                                       Ack ack = Ack::automatic) noexcept;

  // Removes `item` from this agent's input buffer. Acknowledging an item that is not there is
  // not an error (it was acknowledged before).
  Result<void> ack(std::uint64_t item) noexcept;

  // Number of items waiting in this agent's input buffer.
  Result<std::uint64_t> pending() const noexcept;

  // Up to `limit` items of the input buffer with id > `after`, oldest first, left in place (a
  // sending window: the agent acknowledges them later with ack_through). Waits up to `timeout`
  // for the first one. Items removed from the store meanwhile are skipped.
  Result<std::vector<Delivery>> peek(std::uint64_t after, std::size_t limit,
                                     std::chrono::milliseconds timeout) noexcept;
  // Up to `limit` items of the input buffer with `after` < id < `before`, newest first, left in
  // place, without waiting (a link's down queue read from its end). Items removed meanwhile are
  // skipped.
  Result<std::vector<Delivery>> peek_newest(std::uint64_t after, std::uint64_t before, std::size_t limit) const noexcept;

  // Acknowledges every item of the input buffer with id <= `through`; returns how many.
  Result<std::uint64_t> ack_through(std::uint64_t through) noexcept;

  // From now on (idempotent, kept in the store) this agent's input buffer also gets a removal
  // notice (Delivery::removal) whenever records of an item that was routed to it are removed
  // explicitly (Node::remove, remove_item, Agent::replace, unsubscribe, a relayed removal;
  // not the ring or a time-to-live): one notice per item and transaction, with the records
  // removed, routed as the item was (by this agent's subscriptions, matched against the item's
  // records, or as the addressee of its context). A link's agents ask for them, so that a
  // removal follows the copies the link sent (docs/protocol.md P7a). Other agents never see
  // notices.
  Result<void> receive_removals() noexcept;

  // A number that changes whenever a commit puts an item into this agent's input buffer, for a
  // thread that serves many agents' buffers and sleeps in Node::wait_for_commit (a parent's
  // link sending down to a thousand children). It may also change for items of other agents
  // (agents share 1,023 wake slots by a hash of their IRI); it never stays the same when an item
  // arrived. Read it before reading the buffer: a change seen afterwards means read it again.
  std::uint32_t buffer_version() const noexcept;

  // Stores items relayed from another node, exactly once per (stream, seq), in one transaction
  // (docs/protocol.md). The stream's mark (the last seq applied) is kept in the store and moves
  // in the same transaction as the items, so a crash never applies an item twice nor loses the
  // mark. For each item in order: seq <= mark is a duplicate (dropped); prev == mark stores it
  // and sets mark = seq; anything else is a gap: it and the rest are left for a resend.
  // The source of a relayed item must lie at or under this agent's IRI (a child node's writers,
  // the child being this agent) or outside this node's IRI (a writer above, relayed down).
  // An item this node can never store — such a source, or a term that breaks its rules (an
  // invalid IRI, a literal over its limit: the sender's node may allow more) — is refused: not
  // stored, listed in `refused`, and the mark moves past it as if applied, so that one bad item
  // does not hold up the rest of the stream for ever (it stays in the sender's store). An error
  // that may pass (a full store, I/O) fails the call instead, and nothing of it is stored;
  // except that a store with room for part of the run stores a first part that fits (halving
  // the run until one does), in order, and says why the rest was not (RelayOutcome::not_applied).
  // A removal notice (RelayedItem::removal) takes the place of an item in the stream: it removes
  // the records of this store, relayed from the same source, that have the notice's context and
  // asserted-at time and its triples at their positions in their item (a blank node matches a
  // blank node: they are renamed on the way), in the same transaction; none held is no error
  // (the copy was never sent, or is gone: the ring took it). The notice goes on to this node's
  // agents that receive notices as an item of those triples would (receive_removals), whether
  // or not a copy was held, so that it reaches nodes beyond a copy gone here.
  // A persistent item that repeats one this store holds — persistent, from the same source, at
  // the same asserted-at time, with the same context and triples — is dropped as already held
  // (RelayOutcome::already_held): a node's persistent items go up again on a new stream when a
  // store on the way was made again or restored (docs/protocol.md P6c), and the nodes above
  // that store have them from the stream before.
  Result<RelayOutcome> relay(std::string_view stream, const std::vector<RelayedItem>& items) noexcept;

  // The stream's mark (0 when nothing was relayed on it).
  Result<std::uint64_t> relay_mark(std::string_view stream) const noexcept;

  // Says that the items of `stream` up to seq `through_seq`, and those asserted at or before
  // `asserted_through` (ns since the epoch) whatever their seq, may repeat items this store
  // holds already: relay() then drops each of them that repeats one held, persistent or not (as
  // it drops persistent ones on every stream), and counts it in RelayOutcome::already_held. A
  // child store restored from a backup sends again, on a new stream, what its backup's outbox
  // held, which the parent had applied from the stream before; and it relays again, under new
  // seqs that may pass the old stream's mark, what its own children send it again, all of it
  // asserted before the restore (docs/protocol.md P10c). Such an item also repeats one that
  // this store held when this was first said for the stream and that names the same thing —
  // the same source, asserted-at time, context and persistence, the same first subject (an
  // IRI) — with other triples: a store that took the place of another computed it again from
  // inputs cut otherwise (an HRV window of RR items named otherwise); the one held is kept
  // (RelayOutcome::recomputed). Kept in the store; bounds lower than ones said before change
  // nothing.
  Result<void> relay_may_repeat(std::string_view stream, std::uint64_t through_seq,
                                std::optional<std::int64_t> asserted_through = std::nullopt) noexcept;

  // Writes a subscription as a persistent item of triples (vocabulary: docs/record-model.md):
  // from now on every stored item with at least one triple matching the pattern's s, p and o
  // (and, when pattern.context is set, written with exactly that context; when pattern.source
  // is set, whose source is that IRI or lies under it) lands in this agent's input buffer.
  // since, until and after_id must be unset. Returns the
  // subscription's item id. Subscribing again with the same pattern (an agent restarted by its
  // supervisor) returns the existing subscription instead of adding another, and delivers
  // nothing more. Errors: invalid_argument (a blank node or literal as subject, since, until,
  // under or after_id set), invalid_iri, store_full, io.
  Result<std::uint64_t> subscribe(const Pattern& pattern, const SubscribeOptions& options = {});

  // Removes one of this agent's subscriptions (by the id subscribe returned). Items it routed
  // that wait in the input buffer stay there (see withdraw_unrouted).
  Result<void> unsubscribe(std::uint64_t subscription);
  // Takes out of the input buffer the items that none of this agent's subscriptions would route
  // to it now and that are not addressed to it (R18): after unsubscribing, what the old
  // subscriptions alone brought and the agent has not taken. Only items with ids above `after`:
  // a link's outbox keeps what its parent has applied (its mark) until it trims it. Returns how
  // many. (A link's outbox when its forwarding policy is narrowed: what was queued under the old
  // policy stays home.)
  Result<std::uint64_t> withdraw_unrouted(std::uint64_t after = 0);
  // Puts into the input buffer again every persistent item that one of this agent's
  // subscriptions gave it (with Redelivery::addressed_too, also those addressed to it by their
  // context, R18) and that is not there, oldest first; returns how many. A subscription gave the
  // agent the items it routed when they were stored, and those stored before it that were put
  // into the buffer since (SubscribeOptions::earlier), which the node remembers only for an
  // agent that receives removal notices (receive_removals: call it before subscribing); an item
  // stored before the subscription and never given to the agent is not put. (A link whose parent
  // has a new store, a replaced gateway: the descriptions it sent the store before, a
  // recording's, which the parent's agents need for everything after, go to the new one; and,
  // addressed too, a child's link agent on the parent when the child's store was made again:
  // the settings kept for it.) The addressed items are found by reading every item's row once.
  Result<std::uint64_t> deliver_persistent_again(Redelivery which = Redelivery::subscribed);
  // Puts into the input buffer again every item with an id in (`after`, `before`) that one of
  // this agent's subscriptions gave it (as above), whose source is `source_under` or under it (empty: any),
  // and that is not there, oldest first; returns how many. (A link whose parent's store was
  // restored from a backup: what this node's subtree wrote that that store had acknowledged
  // since the backup, and the link had therefore taken out of its outbox, goes up again.)
  Result<std::uint64_t> deliver_again_between(std::uint64_t after, std::uint64_t before, const std::string& source_under = {});

  // Item ids in this agent's output buffer after `after`, oldest first (audit of its writes).
  Result<std::vector<std::uint64_t>> written(std::uint64_t after = 0, std::size_t limit = 0) const;

 private:
  friend class Node;
  struct Impl;
  explicit Agent(std::unique_ptr<Impl>);
  std::unique_ptr<Impl> impl_;
};

// ---------------------------------------------------------------------------------------------
// Node

enum class Durability {
  fast,     // no fsync on commit: survives a crashed process, not a crashed machine (default)
  durable,  // each commit synced to disk before store() returns
};

struct InitOptions {
  std::string iri;                           // the node's IRI (required, absolute)
  Durability durability = Durability::fast;
  std::uint64_t ring = 0;                    // keep at most this many non-persistent records;
                                             // 0: no ring (explicit removal and TTL only)
  std::uint64_t max_literal_bytes = 1 << 20; // larger literals are refused
  std::uint64_t max_map_bytes = 1ull << 36;  // writes may fill the store up to this size
                                             // (64 GiB), then are refused with store_full; at
                                             // least kMinMaxMapBytes. Removals may take its file
                                             // beyond, into a reserve of 1/16 of it and up to
                                             // 1 MB more (an eighth under 8 MB), so that a full
                                             // store can be emptied
};

// The smallest InitOptions::max_map_bytes; Node::init refuses less (invalid_argument).
inline constexpr std::uint64_t kMinMaxMapBytes = 1ull << 20;  // 1 MiB


struct Stats {
  std::string iri;
  Durability durability = Durability::fast;
  std::uint64_t ring = 0;
  std::uint64_t max_literal_bytes = 0;
  std::uint64_t records = 0;             // current records (triples)
  std::uint64_t persistent_records = 0;
  std::uint64_t items = 0;
  std::uint64_t terms = 0;               // entries in the term dictionary
  std::uint64_t terms_collected = 0;     // entries removed from it as unused, since init (R16)
  std::uint64_t subscriptions = 0;
  std::uint64_t pending_deliveries = 0;  // items waiting in input buffers, over all agents
  std::uint64_t last_seq = 0;
  std::uint64_t reclaimed_records = 0;   // removed by ring or TTL since init
  std::uint64_t used_bytes = 0;          // pages holding data (up to the last in use, less free ones)
  std::uint64_t high_water_bytes = 0;    // up to the last page in use, free ones included: a write
                                         // that needs pages beyond max_map_bytes is refused
  std::uint64_t map_bytes = 0;           // current LMDB map size
  std::uint64_t max_map_bytes = 0;
};

class Node {
 public:
  // Creates a new store in `dir` (created if missing; must not already hold a store).
  // Errors: exists, invalid_iri, io, invalid_argument (max_map_bytes below kMinMaxMapBytes).
  static Result<Node> init(const std::filesystem::path& dir, const InitOptions& options);

  // Opens an existing store. Clears reader slots left by dead processes (a write that finds the
  // map full clears them too). Errors: not_found, io, corrupt, version.
  static Result<Node> open(const std::filesystem::path& dir);

  Node(Node&&) noexcept;
  Node& operator=(Node&&) noexcept;
  ~Node();

  // Empty for a handle moved from.
  const std::string& iri() const;
  const std::filesystem::path& dir() const;

  // A handle for agent `id` (IRI = iri() + "/" + id). Errors: invalid_iri for a bad id.
  Result<Agent> agent(std::string_view id) const;

  // R18: the IRI of the agent on this node (a local one, or the link agent of a child node) that
  // an item of context `context` is addressed to, or nullopt when it names none (a context
  // outside this node, the node itself, `<node>/*`, or not an IRI).
  std::optional<std::string> addressee(std::string_view context) const;

  Result<Snapshot> snapshot() const;

  // Removals are one transaction each, bar one case: a removal too large for a full store's
  // removal reserve is done in parts (each a transaction; what was listed at the start is
  // removed; parts done stay done if a later one fails), so that a full store can be emptied.

  // Removes the records matching `pattern` and, with cascade N, their sub-trees (as in
  // ListOptions). A pattern with nothing bound is refused (invalid_argument). Records of
  // subscription items (R9) are left: remove a subscription by its item. Items waiting in
  // input buffers are removed from them too. Returns the number of records removed. By default
  // the removal follows the copies this node's link sent up or down (Reach).
  Result<std::uint64_t> remove(const Pattern& pattern, unsigned cascade = 0, Reach reach = Reach::copies_too);

  // Removes every record of an item, and with cascade N their sub-trees. Error not_found.
  Result<std::uint64_t> remove_item(std::uint64_t item_id, unsigned cascade = 0, Reach reach = Reach::copies_too);

  // Removes every record of each item of `item_ids` together (one commit: one sync on a durable
  // store, where remove_item per item syncs each); items already gone are skipped. Returns the
  // number of records removed.
  Result<std::uint64_t> remove_items(const std::vector<std::uint64_t>& item_ids, Reach reach = Reach::copies_too);

  // Changes after `bookmark` (a seq), oldest first, at most `limit` (0: no limit). Waits up to
  // `timeout` for the first one when there is none yet; an empty vector means timeout. Removals
  // after a non-zero bookmark that already left the removal log (it keeps the latest, R17) come
  // as one change: removed, seq = the last trimmed, `unreadable` naming the range (read the
  // board again). So do records after the bookmark (0 too: a reader from the start never saw
  // them) that the ring or a time-to-live reclaimed before this call: one change, removed and
  // `reclaimed`, seq = the greatest id reclaimed.
  Result<std::vector<Change>> watch(std::uint64_t bookmark, std::chrono::milliseconds timeout,
                                    std::size_t limit = 0) const;

  // Sleeps until a commit that routes an item into an input buffer (from any process; it changes
  // the agent's buffer_version() before the commit's wake-up; commits that route nothing, such
  // as a parent relaying its children's items, do not wake it) or a call of wake_waiters(), and
  // calls `ready` again; returns true as soon as `ready` does, false when `timeout` passes first. `ready` is called once before sleeping,
  // after this thread is registered as a waiter, so no commit between the check and the sleep
  // is missed. For a thread serving many input buffers: `ready` compares their buffer_version()
  // with what it saw last.
  bool wait_for_commit(const std::function<bool()>& ready, std::chrono::nanoseconds timeout) const;

  // Wakes every thread in wait_for_commit or watch on this store (in any process: they share
  // the wake word of commits); each calls its check again and sleeps on if nothing changed.
  // Safe from any thread. A link uses it to hand its pump a registration or an acknowledgement.
  void wake_waiters() const;

  // Time-to-live for non-persistent records of one predicate (0 removes the rule). Records
  // older than this (by stored_at) are reclaimed at the next write or reclaim().
  Result<void> set_ttl(std::string_view predicate_iri, std::chrono::nanoseconds ttl);
  Result<std::vector<std::pair<std::string, std::chrono::nanoseconds>>> ttls() const;

  // Runs retention now (ring and TTL) until nothing more is due, in transactions of at most 64
  // records per TTL rule; returns the number of records reclaimed. Retention also runs after each
  // write (one such step). It never reclaims persistent records nor items waiting in an input
  // buffer.
  Result<std::uint64_t> reclaim();

  // Prefixes kept in the store, used to read and write CURIEs; init stores the standard set.
  Result<void> set_prefix(std::string_view prefix, std::string_view namespace_iri);
  uri::PrefixMap prefixes() const;

  Result<Stats> stats() const;

  // Reads the whole store in one snapshot (agents may go on writing) and reports what does not
  // hold together: rows that do not decode, records whose item, terms or index entries are
  // missing, index and time-index entries that name nothing, counters that disagree with the
  // tables. Errors only when no snapshot can be taken. LMDB checksums no page, so a damaged page
  // may also end the reading process (SIGSEGV, SIGBUS, an abort): `tahvel check` runs this in a
  // child process. `progress`, when set, is called with each table's name before it is read,
  // and `found` with each problem as it is found (of those the report keeps): a caller whose
  // process a damaged page ends has them. The walk holds one snapshot, but for a read that LMDB
  // refuses (a damaged page, MDB_CORRUPTED): the read transaction then refuses every later read,
  // so the tables after that one are read on a new snapshot, and what the refused read said
  // after its first problem is counted (a line says how many), not reported: one bad page of
  // one index read as eleven damaged tables. Pages freed meanwhile are not reused until the walk
  // ends, and this process cannot grow the map while it runs (see Snapshot).
  Result<CheckReport> check(std::size_t max_problems = 100,
                            const std::function<void(std::string_view table)>& progress = {},
                            const std::function<void(std::string_view problem)>& found = {}) const;

  // The store's identity: 32 hex digits, random, made when the store was created. A store made
  // again in the same place (a replaced disk, a new machine) has another one, so that a peer
  // which kept positions in this store's streams (a link's marks) can tell them void. So has a
  // copy of the store in another file (`cp -a`, a restore from tar, a move to another disk): its
  // first open finds its data file is not the one the store recorded, and gives it a new id.
  Result<std::string> store_id() const;
  // A new identity, for a store restored from a backup: its ids go back in time, and peers must
  // not take them for ones they have seen. Returns the new id.
  Result<std::string> renew_store_id();
  // The stores this one is a copy of, nearest first: the id it had before each time it took a
  // new one as a copy (back_up's copy, a file copy found at its first open) or went back in time
  // (renew_store_id: a rollback a peer showed), up to 16. Empty for a store that never did. A
  // parent restored so tells a child that was linked with another store of it
  // (docs/protocol.md P6e).
  Result<std::vector<std::string>> copied_from() const;

  // Writes a copy of the store, as of one snapshot, to the new directory `dest` (it must not
  // exist; its parent must), while agents go on writing: what a copy of the files made then
  // would not be (a page being written is copied half old, half new). Free pages are left out.
  // The copy is made beside `dest` (as `dest`.partial-PID) and synced, renamed to it once whole
  // (never over a `dest` made meanwhile), and the rename synced: nothing half-written is left
  // under `dest`, and a `dest` that exists holds the whole copy after a power cut. A process
  // killed while copying leaves its .partial-PID directory behind. The copy has a store id of
  // its own (store_id): a store restored from it is another store to its peers, whose streams
  // start again (docs/protocol.md P6a, P10c). Returns the copy's size in bytes. Errors:
  // invalid_argument (`dest` exists or names no directory), io, store_full.
  Result<std::uint64_t> back_up(const std::filesystem::path& dest) const;

 private:
  friend class Agent;
  struct Impl;
  explicit Node(std::shared_ptr<Impl>);
  std::shared_ptr<Impl> impl_;
};

// ---------------------------------------------------------------------------------------------
// Waiting
//
// A thread in Agent::take, Agent::peek or Node::watch first watches the store's wake word for up
// to this long before it sleeps in the kernel: a futex wake-up costs tens of µs on each side on
// virtual CPUs, a word seen moving well under one. It spins only while its recent waits ended
// within the budget (a busy stream), and yields the CPU as it spins; a waiter on a quiet buffer
// goes straight to sleep. Default: TAHVEL_SPIN_US from the environment, else 200 µs. Zero never
// spins: for a node whose CPU time counts for more than a hop's latency. For the whole process.
void set_wait_spin(std::chrono::microseconds budget);
std::chrono::microseconds wait_spin();

}  // namespace tahvel::node
