// Rows of the record and item tables, their encodings, and the deletion of records and items
// (shared by explicit removal and retention).
//
// records: id -> varint(s) varint(p) varint(o) varint(id - item)
// items:   id -> varint(count) varint(live) varint(pending) zigzag(stored_at)
//                zigzag(asserted_at - stored_at) varint(source) varint(context) flags
// Metadata is per record in the model (DESIGN §2) and per item on disk: every record of an
// item shares it, and storing it once keeps a triple near 30 bytes.
#pragma once

#include <cstdint>
#include <optional>
#include <string>

#include "env.h"
#include "tahvel/node/node.h"

namespace tahvel::node::detail {

struct RecordRow {
  std::uint64_t s = 0, p = 0, o = 0, item = 0;
};

struct ItemRow {
  std::uint64_t count = 0;    // records written in the item (ids item .. item+count-1)
  std::uint64_t live = 0;     // records not yet removed
  std::uint64_t pending = 0;  // input buffers holding the item
  std::int64_t stored_at = 0;
  std::int64_t asserted_at = 0;
  std::uint64_t source = 0;   // term id
  std::uint64_t context = 0;  // term id, 0 for none
  bool persistent = false;
};

std::string encode_record(std::uint64_t id, const RecordRow& row);
bool decode_record(std::uint64_t id, std::string_view bytes, RecordRow& row);
std::string encode_item(const ItemRow& row);
bool decode_item(std::string_view bytes, ItemRow& row);

// nullopt when absent.
Result<std::optional<RecordRow>> get_record(MDB_txn* txn, const Env& env, std::uint64_t id);
Result<std::optional<ItemRow>> get_item(MDB_txn* txn, const Env& env, std::uint64_t id);
Result<void> put_item(Txn& txn, std::uint64_t id, const ItemRow& row, unsigned flags = 0);

// Why a record goes: explicit removal is logged for watchers; retention is not.
enum class Removal { explicit_removal, retention };

// Deletes record `id` (and its item once the last record goes), keeping counters, indexes,
// buffers and the dictionary consistent.
Result<void> delete_record(Txn& txn, std::uint64_t id, Removal why);

// Deletes every remaining record of item `id`; returns how many.
Result<std::uint64_t> delete_item(Txn& txn, std::uint64_t id, Removal why);

// The removal log entry for Node::watch: the record as it was.
std::string encode_removed(const Record& record);
bool decode_removed(std::string_view bytes, Record& record);

// Current time, ns since the Unix epoch.
std::int64_t now_ns();

}  // namespace tahvel::node::detail
