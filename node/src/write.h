// The write path: validation, item insertion with blank-node renaming, routing into input
// buffers, and retention (ring and TTL). Runs inside Env::write.
#pragma once

#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "env.h"
#include "rows.h"
#include "tahvel/node/node.h"

namespace tahvel::node::detail {

// Checks what can be checked without the store: item not empty, term kinds per position,
// literal sizes and language tags. Error names the triple (1-based) and position.
Result<void> validate_item(const Item& item, const Settings& settings);

// What keeps `literal`, a pattern's object, from being a term any record could hold, or "" when
// nothing: not UTF-8, a datatype that is not an absolute IRI, a language tag that is not one or
// beside a datatype other than rdf:langString, rdf:langString without a tag. A pattern with such
// a term is an error, not an empty answer (stored literals get the same checks from validate_item
// and, for the datatype, as it enters the dictionary).
std::string pattern_literal_problem(const Term& literal);

// The subscription vocabulary term for an item-context condition (tv:context).
inline constexpr std::string_view kSubscriptionContext = "https://w3id.org/tahvel#context";
// The subscription vocabulary term for a source condition (tv:source): the writer's IRI or an
// IRI above it.
inline constexpr std::string_view kSubscriptionSource = "https://w3id.org/tahvel#source";

// R18: the agent an item of context `context` (in normal form) written by `writer` is addressed
// to on the node of IRI `node_iri`; nullopt for none.
std::optional<std::string> addressee_of(const std::string& node_iri, std::string_view context, std::string_view writer);

// Inserts one validated item written by `agent_iri` (its output buffer), routes it, and returns
// its id. Its records' source is `agent_iri`, or `*relayed_source` for an item relayed by a link
// agent (the caller has checked that the agent may relay that source).
Result<std::uint64_t> insert_item(Txn& txn, const Item& item, const std::string& agent_iri,
                                  const std::string* relayed_source = nullptr);

// An item this store holds that a relayed item repeats (held_twin).
struct HeldRepeat {
  std::uint64_t id = 0;     // 0 when none
  bool recomputed = false;  // of the same name only, with other triples
};

// The item this store holds that `item`, relayed from `source`, repeats: persistent or not as
// it is, the same source, asserted-at time and context, and the same triples in the same order
// (blank nodes match blank nodes, as they are renamed on the way). Failing that, when
// `namesakes_before` is above 0, an item with an id below it that names the same thing — the
// same source, asserted-at time, context and persistence, the same first subject (an IRI), all
// of its records still held — and so was computed again by a store that replaced the one it
// came from (docs/protocol.md P10c). The candidates are the time index's items of that
// nanosecond.
Result<HeldRepeat> held_twin(MDB_txn* txn, const Env& env, const Item& item, const std::string& source,
                             std::uint64_t namesakes_before = 0);

// held_twin for a persistent item, none for any other, and no namesakes. A node sends its
// persistent items again to a parent that says it holds nothing of its stream (docs/protocol.md
// P6c), and a parent made again, or a child restored from a backup, passes them on to nodes
// above that have them already on the stream before.
Result<HeldRepeat> held_persistent_twin(MDB_txn* txn, const Env& env, const Item& item, const std::string& source);

// The copies this store holds of the records a relayed removal notice names
// (RelayedItem::removal): records of items relayed from `source` with the notice's asserted-at
// time and context, at each triple's position in its item (`positions`), with that triple (a
// blank node matches a blank node: they are renamed on the way). Record ids in order, and the
// items they are in.
struct HeldCopies {
  std::vector<std::uint64_t> records, items;
};
Result<HeldCopies> held_copies(MDB_txn* txn, const Env& env, const Item& notice, const std::vector<std::uint32_t>& positions,
                               const std::string& source);

// An upper bound on the bytes of new pages that inserting `item` may add to the data file: its
// terms (a large literal takes overflow pages of its own) and a generous share of the record,
// index and item rows per triple. Env::write reserves the disk for it before the transaction
// writes, since with a memory-mapped file a page with no disk block behind it is SIGBUS.
WriteBound write_bound(const Item& item);

// Takes out of the input buffer of `agent` (a term id; IRI `agent_iri`) the items that none of
// its subscriptions routes to it now and that are not addressed to it (R18); returns how many.
Result<std::uint64_t> withdraw_unrouted(Txn& txn, std::uint64_t agent, const std::string& agent_iri,
                                         std::uint64_t after);

// Puts into the input buffer of `agent` (a term id; IRI `agent_iri`) every item with id below
// `before` that has a record matching `pattern` (s, p, o, context, source: what a subscription
// routes), oldest first, unless it is there already: a new subscription's earlier items
// (SubscribeOptions::earlier). Returns how many it put. With `given_by` (a subscription's item
// id), an item stored before that subscription is put only if it was put into the agent's buffer
// before (ItemRow::noticed): what the subscription gave the agent goes again, nothing more.
Result<std::uint64_t> deliver_earlier(Txn& txn, std::uint64_t agent, const std::string& agent_iri,
                                      const Pattern& pattern, std::uint64_t before, bool persistent_only = false,
                                      std::uint64_t given_by = 0);

// A subscription written after what it follows had begun, and the id after which it should
// have been in force.
struct MissedSince {
  std::uint64_t subscription = 0;  // the subscription's item id
  std::uint64_t after = 0;         // a record id: items after it were missed
};

// The catch-up of Agent::store_subscriptions in `txn`: for each of `missed`, the items with an
// id in (after, subscription) that it matches, that none of the subscriber's subscriptions with
// an id below `older_than` routes, not addressed to it and not in its input buffer, put there.
// A subscription not on the board is skipped. Returns how many it put.
Result<std::uint64_t> deliver_missed(Txn& txn, std::span<const MissedSince> missed, std::uint64_t older_than);

// deliver_earlier for each of the subscriptions of `agent`, given by it: the items it gave the
// agent (routed when stored, or put into its buffer since), with ids in (after, before)
// (after 0: from the first), persistent ones only when `persistent_only`, and with
// `source_under` only those whose source is that IRI or under it (Agent::deliver_again_between).
Result<std::uint64_t> deliver_again(Txn& txn, std::uint64_t agent, const std::string& agent_iri, bool persistent_only,
                                    std::uint64_t after, std::uint64_t before, const std::string& source_under);

// deliver_earlier for each of the subscriptions of `agent`, persistent items only, and with
// `addressed_too` the persistent items addressed to it by their context (R18), found by reading
// every item's row (Agent::deliver_persistent_again).
Result<std::uint64_t> deliver_persistent_again(Txn& txn, std::uint64_t agent, const std::string& agent_iri,
                                               bool addressed_too);

// Applies ring and TTL retention; returns the number of records reclaimed.
Result<std::uint64_t> apply_retention(Txn& txn);

// Reloads the per-process subscription and TTL caches when their generation changed.
Result<void> refresh_caches(Txn& txn);

// Removal notices (docs/record-model.md R21). The meta key that says an agent receives them is
// this prefix and the agent's IRI.
inline constexpr std::string_view kRemovalReceiverKey = "removal-notices:";
// Whether any agent of the store receives removal notices (asked once per transaction).
Result<bool> removals_noticed(Txn& txn);
// Makes agent `agent_iri` receive removal notices from now on (idempotent).
Result<void> receive_removals(Txn& txn, const std::string& agent_iri);
// The notice of item `item_id` (`item` its row, `meta` a record's metadata as read) in this
// transaction, planned at its first record's removal: routed to every agent that receives
// notices and to which the item goes, by its subscriptions or as its addressee (R10, R18), and
// to those it went to when stored (ItemRow::noticed). Null when it goes to none. The caller adds the records it removes.
Result<Txn::NoticePlan*> notice_plan(Txn& txn, std::uint64_t item_id, const ItemRow& item, const RecordMeta& meta);
// Plans the notice that a relayed removal notice (Agent::relay) becomes on this node, whether or
// not it held copies (`held_items`: the items its copies were in): routed by the notice's
// triples and what is left of those items, from `writer_iri`, the relaying agent, and to the
// agents in `remembered` (the ItemRow::noticed of the copies removed) that still receive notices.
Result<void> pass_notice_on(Txn& txn, const Item& notice, const std::vector<std::uint32_t>& positions,
                            const std::string& source, const std::string& writer_iri,
                            const std::vector<std::uint64_t>& held_items, const std::vector<std::uint64_t>& remembered);
// Writes the notices planned in this transaction and puts them into their agents' input
// buffers. Env::write runs it before the commit.
Result<void> deliver_removals(Txn& txn);

}  // namespace tahvel::node::detail
