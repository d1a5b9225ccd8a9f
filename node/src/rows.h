// Rows of the record and item tables, their encodings, and the deletion of records and items
// (shared by explicit removal and retention).
//
// records: id -> varint(s) varint(p) varint(o) varint(id - item)
// items:   id -> varint(count) varint(live) varint(pending) zigzag(stored_at)
//                zigzag(asserted_at - stored_at) varint(source) varint(context) flags
//                [varint(writer) when flags has the relayed bit]
//                [varint(count) count × varint(agent) when flags has the noticed bit]
//                [varint(span) when flags has the span bit]
// Metadata is per record in the model (DESIGN §2) and per item on disk: every record of an
// item shares it, and storing it once keeps a triple near 30 bytes.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "env.h"
#include "tahvel/node/node.h"

namespace tahvel::node::detail {

// The time index's key for an item asserted at `ns`: the sign bit flipped, so that unsigned
// integer order (MDB_INTEGERKEY) is time order, before the epoch included.
inline std::uint64_t time_key(std::int64_t ns) { return static_cast<std::uint64_t>(ns) ^ (std::uint64_t{1} << 63); }
inline std::int64_t time_of_key(std::uint64_t key) { return static_cast<std::int64_t>(key ^ (std::uint64_t{1} << 63)); }

struct RecordRow {
  std::uint64_t s = 0, p = 0, o = 0, item = 0;
};

struct ItemRow {
  std::uint64_t count = 0;    // records written in the item (ids item .. item+count-1)
  std::uint64_t live = 0;     // records not yet removed
  std::uint64_t pending = 0;  // input buffers holding the item
  std::int64_t stored_at = 0;
  std::int64_t asserted_at = 0;
  std::int64_t span = 0;      // ns, >= 0 (Item::span)
  std::uint64_t source = 0;   // term id
  std::uint64_t context = 0;  // term id, 0 for none
  bool persistent = false;
  std::uint64_t writer = 0;   // term id of the agent whose output buffer holds the item, when
                              // not the source (a link agent relaying from below); 0: the source
  std::uint64_t output_buffer() const { return writer ? writer : source; }
  // The agents that receive removal notices (R21) whose input buffers the item was put into:
  // a removal notices them whatever their subscriptions are by then (a forwarding policy
  // narrowed after the item went up). Empty in rows written before it was kept.
  std::vector<std::uint64_t> noticed;
};

std::string encode_record(std::uint64_t id, const RecordRow& row);
bool decode_record(std::uint64_t id, std::string_view bytes, RecordRow& row);
std::string encode_item(const ItemRow& row);
bool decode_item(std::string_view bytes, ItemRow& row);

// nullopt when absent.
Result<std::optional<RecordRow>> get_record(MDB_txn* txn, const Env& env, std::uint64_t id);
Result<std::optional<ItemRow>> get_item(MDB_txn* txn, const Env& env, std::uint64_t id);
Result<void> put_item(Txn& txn, std::uint64_t id, const ItemRow& row, unsigned flags = 0);

// One input buffer fewer holds item `id`: its pending count goes down, rewritten in place through
// `items`, a cursor on the items table. A cursor already near `id` finds it without a search from
// the root, so a caller releasing a run of items in id order keeps one cursor for them all.
// False when no such item is in the store (removed since, or the id of a removal notice).
Result<bool> release_item(Txn& txn, MDB_cursor* items, std::uint64_t id);

// The ring's scan (apply_ring) resumes where it last stopped instead of walking, at every write,
// the items that wait in input buffers (a subscriber that does not take made each write walk
// all of them: 20,000 writes took 10.7 s on a ring of 10, 0.25 s without it). Kept in the meta
// table, in the transaction:
//   kRingResume      items in [ring_head, this) were persistent, gone or waiting when scanned;
//   kRingReleasedLow the least id below kRingResume released since (waiting no longer), and
//   kRingReleasedN   how many were: the scan goes back for them.
// Absent (a store from before): the scan starts at ring_head, as it did.
inline constexpr std::string_view kRingResume = "ring_resume";
inline constexpr std::string_view kRingReleasedLow = "ring_released_low";
inline constexpr std::string_view kRingReleasedN = "ring_released_n";
std::optional<std::uint64_t> meta_u64(MDB_txn* txn, const Env& env, std::string_view key);
Result<void> put_meta_u64(MDB_txn* txn, const Env& env, std::string_view key, std::uint64_t value);
// A non-persistent item `id` no longer waits in any input buffer: the ring may take it.
Result<void> note_released(Txn& txn, std::uint64_t id);

// Puts the entries in txn.unflushed_index into their tables and empties it. Values only grow
// (record and item ids), so each entry is the last of its key: appended, no search among the
// duplicates. Anything that reads or deletes index or output-buffer entries in a transaction
// that inserted items flushes first; Env::write flushes before it commits.
Result<void> flush_index(Txn& txn);

// Why a record goes: explicit removal is logged for watchers and notifies the agents that receive
// removal notices (R21); a quiet one is logged only (a relayed removal, whose notice
// Agent::relay passes on itself, or one meant for this node only, Reach::this_node); retention
// is neither.
enum class Removal { explicit_removal, quiet_removal, retention };

// Deletes record `id` (and its item once the last record goes), keeping counters, indexes,
// buffers and the dictionary consistent.
Result<void> delete_record(Txn& txn, std::uint64_t id, Removal why);

// Deletes every remaining record of item `id`; returns how many.
Result<std::uint64_t> delete_item(Txn& txn, std::uint64_t id, Removal why);

// The removal log entry for Node::watch: the record as it was.
std::string encode_removed(const Record& record);
bool decode_removed(std::string_view bytes, Record& record);

// Removal notices (R21): a row holds how many input buffers hold the notice, and the records
// removed, as encode_removed writes them.
std::string encode_notice(std::uint64_t pending, const std::vector<Record>& records);
// `records` may be null: only the count is read.
bool decode_notice(std::string_view bytes, std::uint64_t& pending, std::vector<Record>* records);
// The records of notice `id`; nullopt when there is no such notice.
Result<std::optional<std::vector<Record>>> get_notice(MDB_txn* txn, const Env& env, std::uint64_t id);
// One input buffer fewer holds notice `id`: the row goes with the last. Absent is no error.
Result<void> release_notice(Txn& txn, std::uint64_t id);

// Current time, ns since the Unix epoch.
std::int64_t now_ns();

}  // namespace tahvel::node::detail
