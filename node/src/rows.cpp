// Record and item rows; deletion. See rows.h.
#include "rows.h"

#include <algorithm>
#include <cstdint>
#include <ctime>
#include <vector>

#include "codec.h"
#include "dictionary.h"
#include "write.h"

namespace tahvel::node::detail {
namespace {

// Watchers further behind miss removals. A removal is logged with its terms (150 bytes and up):
// a store whose maximum is small keeps fewer, one per 8 KB of it, or emptying a full store would
// fill it with the log of what was removed.
std::uint64_t removal_log_limit(const Settings& settings) {
  return std::clamp<std::uint64_t>(settings.max_map_bytes / 8192, 16, 65536);
}
// And by size (16 MB at most): a removed record may be large (a remote query's answer chunks, up to the literal
// limit each, are removed from the asking board as they are read), and 65,536 of them kept every
// answer of the last hundreds of queries, raw ECG included, in the hospital's store. At least
// 256 KB, but never more than 1/64 of a small store: 256 KB of a 1 MiB store kept most of what
// a removal freed, and the full store stayed full.
std::uint64_t removal_log_bytes_limit(const Settings& settings) {
  const std::uint64_t floor = std::min<std::uint64_t>(256 << 10, settings.max_map_bytes / 64);
  return std::clamp<std::uint64_t>(settings.max_map_bytes / 4096, floor, 16 << 20);
}

std::uint64_t table_bytes(MDB_txn* txn, MDB_dbi dbi) {
  MDB_stat st{};
  if (mdb_stat(txn, dbi, &st) != 0) return 0;
  return (st.ms_branch_pages + st.ms_leaf_pages + st.ms_overflow_pages) * static_cast<std::uint64_t>(st.ms_psize);
}
constexpr std::uint8_t kItemPersistent = 1;
constexpr std::uint8_t kItemRelayed = 2;  // the writer's term id follows (ItemRow::writer)
constexpr std::uint8_t kItemNoticed = 4;  // a count and that many agent term ids follow (ItemRow::noticed)
constexpr std::uint8_t kItemSpan = 8;     // the span follows (ItemRow::span)

void put_string(std::string& out, std::string_view s) {
  codec::put_varint(out, s.size());
  out += s;
}

bool get_string(std::string_view in, std::size_t& pos, std::string& s) {
  std::uint64_t n = 0;
  if (!codec::get_varint(in, pos, n) || pos + n > in.size()) return false;
  s.assign(in.substr(pos, n));
  pos += n;
  return true;
}

void put_term(std::string& out, const Term& t) {
  out.push_back(static_cast<char>(t.kind));
  put_string(out, t.value);
  put_string(out, t.datatype);
  put_string(out, t.language);
}

bool get_term(std::string_view in, std::size_t& pos, Term& t) {
  if (pos >= in.size()) return false;
  t.kind = static_cast<TermKind>(in[pos++]);
  return get_string(in, pos, t.value) && get_string(in, pos, t.datatype) &&
         get_string(in, pos, t.language);
}

Result<void> del_dup(MDB_txn* txn, MDB_dbi dbi, std::uint64_t key, std::uint64_t value, const char* what) {
  MDB_val k = val(key), v = val(value);
  int rc = mdb_del(txn, dbi, &k, &v);
  if (rc != 0 && rc != MDB_NOTFOUND) return lmdb_fail(rc, what);
  return {};
}

// Removes `item` from every input buffer that holds it (rare: only removal of unread items).
Result<std::uint64_t> drop_from_inboxes(Txn& txn, std::uint64_t item) {
  MDB_cursor* cursor = nullptr;
  int rc = mdb_cursor_open(txn.raw(), txn.env().inbox, &cursor);
  if (rc != 0) return lmdb_fail(rc, "opening input buffers");
  std::vector<std::uint64_t> agents;
  MDB_val k, v;
  for (rc = mdb_cursor_get(cursor, &k, &v, MDB_FIRST); rc == 0;
       rc = mdb_cursor_get(cursor, &k, &v, MDB_NEXT_NODUP))
    agents.push_back(u64(k));
  mdb_cursor_close(cursor);
  if (rc != MDB_NOTFOUND) return lmdb_fail(rc, "reading input buffers");
  std::uint64_t dropped = 0;
  for (std::uint64_t agent : agents) {
    MDB_val ak = val(agent), iv = val(item);
    rc = mdb_del(txn.raw(), txn.env().inbox, &ak, &iv);
    if (rc == 0) ++dropped;
    else if (rc != MDB_NOTFOUND) return lmdb_fail(rc, "removing an item from an input buffer");
  }
  return dropped;
}

Result<Record> log_removal(Txn& txn, std::uint64_t id, const RecordRow& row, const ItemRow& item) {
  TermReader reader(txn.raw(), txn.env());
  Record record;
  auto s = reader.get(row.s), p = reader.get(row.p), o = reader.get(row.o);
  auto source = reader.iri(item.source), context = reader.iri(item.context);
  if (!s || !p || !o || !source || !context) return fail(Errc::corrupt, "record " + std::to_string(id) + " refers to a missing term");
  record.triple = {std::move(*s), std::move(*p), std::move(*o)};
  record.meta = {id, row.item, item.stored_at, item.asserted_at, *source, *context, item.persistent, item.span};
  std::string bytes = encode_removed(record);
  std::uint64_t seq = txn.counters.next_seq++;
  MDB_val k = val(seq), v = val(bytes);
  int rc = mdb_put(txn.raw(), txn.env().removals, &k, &v, MDB_APPEND);
  if (rc != 0) return lmdb_fail(rc, "logging a removal");
  ++txn.counters.removals;
  const Settings& settings = txn.env().settings();
  // On a full disk, the least (256 KB): its copies took what the removals freed, and a disk
  // smaller than the store's maximum never saw the log trimmed, so emptying the store won
  // nothing back (a probe; watchers further behind are told what they missed, as above).
  const std::uint64_t byte_limit = txn.env().disk_tight() ? std::min<std::uint64_t>(removal_log_bytes_limit(settings), 256 << 10)
                                                          : removal_log_bytes_limit(settings);
  // The oldest go; the newest entry always stays, however large.
  while (txn.counters.removals > 1 && (txn.counters.removals > removal_log_limit(settings) ||
                                       table_bytes(txn.raw(), txn.env().removals) > byte_limit)) {
    MDB_cursor* cursor = nullptr;
    if ((rc = mdb_cursor_open(txn.raw(), txn.env().removals, &cursor)) != 0) return lmdb_fail(rc, "trimming the removal log");
    MDB_val fk, fv;
    rc = mdb_cursor_get(cursor, &fk, &fv, MDB_FIRST);
    const std::uint64_t first = rc == 0 ? u64(fk) : 0;
    if (rc == 0) rc = mdb_cursor_del(cursor, 0);
    mdb_cursor_close(cursor);
    if (rc == MDB_NOTFOUND) break;
    // A failed delete (MDB_MAP_FULL: deleting copies pages too) leaves the transaction unusable:
    // said as what it is, not as the next call's MDB_BAD_TXN.
    if (rc != 0) return lmdb_fail(rc, "trimming the removal log");
    txn.removals_trimmed_through = std::max(txn.removals_trimmed_through, first);
    --txn.counters.removals;
  }
  return record;
}

Result<void> retire_item(Txn& txn, std::uint64_t item_id, const ItemRow& item) {
  MDB_txn* raw = txn.raw();
  Env& env = txn.env();
  MDB_val k = val(item_id);
  int rc = mdb_del(raw, env.items, &k, nullptr);
  if (rc != 0) return lmdb_fail(rc, "removing item " + std::to_string(item_id));
  if (auto r = del_dup(raw, env.outbox, item.output_buffer(), item_id, "removing an item from an output buffer"); !r) return r;
  if (auto r = del_dup(raw, env.by_time, time_key(item.asserted_at), item_id, "removing an item from the time index"); !r) return r;
  if (item.pending > 0) {
    auto dropped = drop_from_inboxes(txn, item_id);
    if (!dropped) return unexpected(dropped.error());
    txn.counters.pending -= std::min(txn.counters.pending, *dropped);
  }
  --txn.counters.items;
  return {};
}

}  // namespace

std::int64_t now_ns() {
  timespec ts;
  clock_gettime(CLOCK_REALTIME, &ts);
  return std::int64_t(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

std::string encode_record(std::uint64_t id, const RecordRow& row) {
  std::string out;
  out.reserve(24);
  codec::put_varint(out, row.s);
  codec::put_varint(out, row.p);
  codec::put_varint(out, row.o);
  codec::put_varint(out, id - row.item);
  return out;
}

bool decode_record(std::uint64_t id, std::string_view bytes, RecordRow& row) {
  std::size_t pos = 0;
  std::uint64_t delta = 0;
  if (!codec::get_varint(bytes, pos, row.s) || !codec::get_varint(bytes, pos, row.p) ||
      !codec::get_varint(bytes, pos, row.o) || !codec::get_varint(bytes, pos, delta))
    return false;
  row.item = id - delta;
  return true;
}

std::string encode_item(const ItemRow& row) {
  std::string out;
  out.reserve(32);
  codec::put_varint(out, row.count);
  codec::put_varint(out, row.live);
  codec::put_varint(out, row.pending);
  codec::put_varint(out, codec::zigzag(row.stored_at));
  codec::put_varint(out, codec::zigzag(row.asserted_at - row.stored_at));
  codec::put_varint(out, row.source);
  codec::put_varint(out, row.context);
  out.push_back(static_cast<char>((row.persistent ? kItemPersistent : 0) | (row.writer ? kItemRelayed : 0) |
                                  (row.noticed.empty() ? 0 : kItemNoticed) | (row.span != 0 ? kItemSpan : 0)));
  if (row.writer) codec::put_varint(out, row.writer);
  if (!row.noticed.empty()) {
    codec::put_varint(out, row.noticed.size());
    for (std::uint64_t agent : row.noticed) codec::put_varint(out, agent);
  }
  if (row.span != 0) codec::put_varint(out, static_cast<std::uint64_t>(row.span));
  return out;
}

bool decode_item(std::string_view bytes, ItemRow& row) {
  std::size_t pos = 0;
  std::uint64_t stored = 0, asserted_delta = 0;
  if (!codec::get_varint(bytes, pos, row.count) || !codec::get_varint(bytes, pos, row.live) ||
      !codec::get_varint(bytes, pos, row.pending) || !codec::get_varint(bytes, pos, stored) ||
      !codec::get_varint(bytes, pos, asserted_delta) || !codec::get_varint(bytes, pos, row.source) ||
      !codec::get_varint(bytes, pos, row.context) || pos >= bytes.size())
    return false;
  row.stored_at = codec::unzigzag(stored);
  row.asserted_at = row.stored_at + codec::unzigzag(asserted_delta);
  const std::uint8_t flags = static_cast<std::uint8_t>(bytes[pos++]);
  // A flag this build does not know is a row of a later build, which it would misread.
  if (flags & ~(kItemPersistent | kItemRelayed | kItemNoticed | kItemSpan)) return false;
  row.persistent = flags & kItemPersistent;
  row.writer = 0;
  if ((flags & kItemRelayed) && !codec::get_varint(bytes, pos, row.writer)) return false;
  row.noticed.clear();
  if (flags & kItemNoticed) {
    std::uint64_t n = 0;
    // Each id takes at least a byte: a count beyond what is left is a damaged row.
    if (!codec::get_varint(bytes, pos, n) || n == 0 || n > bytes.size() - pos) return false;
    row.noticed.resize(n);
    for (std::uint64_t& agent : row.noticed)
      if (!codec::get_varint(bytes, pos, agent)) return false;
  }
  row.span = 0;
  if (flags & kItemSpan) {
    std::uint64_t span = 0;
    if (!codec::get_varint(bytes, pos, span) || span > static_cast<std::uint64_t>(INT64_MAX)) return false;
    row.span = static_cast<std::int64_t>(span);
  }
  return true;
}

Result<std::optional<RecordRow>> get_record(MDB_txn* txn, const Env& env, std::uint64_t id) {
  MDB_val k = val(id), v;
  int rc = mdb_get(txn, env.records, &k, &v);
  if (rc == MDB_NOTFOUND) return std::optional<RecordRow>();
  if (rc != 0) return lmdb_fail(rc, "reading record " + std::to_string(id));
  RecordRow row;
  if (!decode_record(id, view(v), row)) return fail(Errc::corrupt, "record " + std::to_string(id) + " is truncated");
  return std::optional<RecordRow>(row);
}

namespace {
auto item_unreadable(std::uint64_t id) {
  return fail(Errc::corrupt, "item " + std::to_string(id) + " cannot be read: its row is truncated, or written by a later build");
}
}  // namespace

Result<std::optional<ItemRow>> get_item(MDB_txn* txn, const Env& env, std::uint64_t id) {
  MDB_val k = val(id), v;
  int rc = mdb_get(txn, env.items, &k, &v);
  if (rc == MDB_NOTFOUND) return std::optional<ItemRow>();
  if (rc != 0) return lmdb_fail(rc, "reading item " + std::to_string(id));
  ItemRow row;
  if (!decode_item(view(v), row)) return item_unreadable(id);
  return std::optional<ItemRow>(std::move(row));
}

Result<void> put_item(Txn& txn, std::uint64_t id, const ItemRow& row, unsigned flags) {
  std::string bytes = encode_item(row);
  MDB_val k = val(id), v = val(bytes);
  int rc = mdb_put(txn.raw(), txn.env().items, &k, &v, flags);
  if (rc != 0) return lmdb_fail(rc, "writing item " + std::to_string(id));
  return {};
}

Result<bool> release_item(Txn& txn, MDB_cursor* items, std::uint64_t id) {
  MDB_val k = val(id), v;
  int rc = mdb_cursor_get(items, &k, &v, MDB_SET_KEY);
  if (rc == MDB_NOTFOUND) return false;
  if (rc != 0) return lmdb_fail(rc, "reading item " + std::to_string(id));
  ItemRow row;
  if (!decode_item(view(v), row)) return item_unreadable(id);
  if (row.pending == 0) return true;
  --row.pending;
  const std::string bytes = encode_item(row);
  MDB_val key = val(id), value = val(bytes);
  if ((rc = mdb_cursor_put(items, &key, &value, MDB_CURRENT)) != 0)
    return lmdb_fail(rc, "writing item " + std::to_string(id));
  if (row.pending == 0 && !row.persistent)
    if (auto noted = note_released(txn, id); !noted) return unexpected(noted.error());
  return true;
}

std::optional<std::uint64_t> meta_u64(MDB_txn* txn, const Env& env, std::string_view key) {
  MDB_val k{key.size(), const_cast<char*>(key.data())}, v;
  if (mdb_get(txn, env.meta, &k, &v) != 0 || v.mv_size != sizeof(std::uint64_t)) return std::nullopt;
  return u64(v);
}

Result<void> put_meta_u64(MDB_txn* txn, const Env& env, std::string_view key, std::uint64_t value) {
  MDB_val k{key.size(), const_cast<char*>(key.data())}, v = val(value);
  if (int rc = mdb_put(txn, env.meta, &k, &v, 0); rc != 0) return lmdb_fail(rc, "noting the ring's scan");
  return {};
}

Result<void> note_released(Txn& txn, std::uint64_t id) {
  if (txn.env().settings().ring == 0) return {};
  const auto resume = meta_u64(txn.raw(), txn.env(), kRingResume);
  if (!resume || id >= *resume) return {};  // the scan has not passed it yet
  const std::uint64_t low = meta_u64(txn.raw(), txn.env(), kRingReleasedLow).value_or(id);
  const std::uint64_t n = meta_u64(txn.raw(), txn.env(), kRingReleasedN).value_or(0);
  if (auto r = put_meta_u64(txn.raw(), txn.env(), kRingReleasedLow, std::min(low, id)); !r) return r;
  return put_meta_u64(txn.raw(), txn.env(), kRingReleasedN, n + 1);
}

Result<void> flush_index(Txn& txn) {
  auto& entries = txn.unflushed_index;
  if (entries.empty()) return {};
  // Stable: the values of one key stay in the ascending order they were added in.
  std::stable_sort(entries.begin(), entries.end(), [](const Txn::IndexEntry& a, const Txn::IndexEntry& b) {
    return a.dbi != b.dbi ? a.dbi < b.dbi : a.key < b.key;
  });
  std::vector<std::uint64_t> values;
  MDB_cursor* cursor = nullptr;
  MDB_dbi cursor_dbi = 0;
  Result<void> result;
  for (std::size_t first = 0; first < entries.size() && result;) {
    const Txn::IndexEntry& head = entries[first];
    std::size_t end = first;
    values.clear();
    while (end < entries.size() && entries[end].dbi == head.dbi && entries[end].key == head.key)
      values.push_back(entries[end++].value);
    if (!cursor || cursor_dbi != head.dbi) {
      if (cursor) mdb_cursor_close(cursor);
      cursor = nullptr;
      if (int rc = mdb_cursor_open(txn.raw(), head.dbi, &cursor); rc != 0) {
        result = lmdb_fail(rc, "opening an index");
        break;
      }
      cursor_dbi = head.dbi;
    }
    // MDB_MULTIPLE (the tables are MDB_DUPFIXED): data[0] is the first value and its size,
    // data[1].mv_size the count; LMDB writes back how many it stored.
    MDB_val k = val(head.key);
    MDB_val data[2] = {val(values.data(), sizeof(std::uint64_t)), MDB_val{values.size(), nullptr}};
    int rc = mdb_cursor_put(cursor, &k, data, MDB_MULTIPLE | MDB_APPENDDUP);
    if (rc == MDB_KEYEXIST) {
      result = fail(Errc::corrupt, "indexing: id " + std::to_string(values[data[1].mv_size]) + " out of order under key " +
                                       std::to_string(head.key));
    } else if (rc != 0) {
      result = lmdb_fail(rc, "indexing " + std::to_string(values.size()) + " entries");
    }
    first = end;
  }
  if (cursor) mdb_cursor_close(cursor);
  entries.clear();
  return result;
}

Result<void> delete_record(Txn& txn, std::uint64_t id, Removal why) {
  if (auto f = flush_index(txn); !f) return f;
  MDB_txn* raw = txn.raw();
  Env& env = txn.env();
  auto row = get_record(raw, env, id);
  if (!row) return unexpected(row.error());
  if (!*row) return {};  // already gone
  const RecordRow r = **row;
  auto item = get_item(raw, env, r.item);
  if (!item) return unexpected(item.error());
  if (!*item) return fail(Errc::corrupt, "record " + std::to_string(id) + " has no item");
  ItemRow it = **item;
  if (why != Removal::retention) {
    auto logged = log_removal(txn, id, r, it);
    if (!logged) return unexpected(logged.error());
    if (why == Removal::explicit_removal) {
      auto plan = notice_plan(txn, r.item, it, logged->meta);
      if (!plan) return unexpected(plan.error());
      if (*plan) (*plan)->records.push_back(std::move(*logged));
    }
  }
  if (auto d = del_dup(raw, env.idx_s, r.s, id, "unindexing a subject"); !d) return d;
  if (auto d = del_dup(raw, env.idx_p, r.p, id, "unindexing a predicate"); !d) return d;
  if (auto d = del_dup(raw, env.idx_o, r.o, id, "unindexing an object"); !d) return d;
  MDB_val k = val(id);
  int rc = mdb_del(raw, env.records, &k, nullptr);
  if (rc != 0) return lmdb_fail(rc, "removing record " + std::to_string(id));
  --txn.counters.records;
  if (it.persistent) --txn.counters.persistent_records;
  else --txn.counters.ring_records;
  if (why == Removal::retention) {
    ++txn.counters.reclaimed;
    txn.reclaimed_through = std::max(txn.reclaimed_through, id);
  }
  if (r.p == env.vocab.subscriber) {
    ++txn.counters.sub_gen;
    if (txn.counters.subscriptions > 0) --txn.counters.subscriptions;
  }
  if (--it.live == 0) {
    if (auto x = retire_item(txn, r.item, it); !x) return x;
  } else if (auto x = put_item(txn, r.item, it); !x) {
    return x;
  }
  for (std::uint64_t term : {r.s, r.p, r.o}) {
    if (txn.defer_term_collection) {
      txn.deferred_terms.push_back(term);
      continue;
    }
    if (auto c = collect_term_if_unused(txn, term); !c) return c;
  }
  return {};
}

Result<std::uint64_t> delete_item(Txn& txn, std::uint64_t id, Removal why) {
  auto item = get_item(txn.raw(), txn.env(), id);
  if (!item) return unexpected(item.error());
  if (!*item) return std::uint64_t{0};
  std::uint64_t count = (*item)->count, removed = 0;
  for (std::uint64_t rid = id; rid < id + count; ++rid) {
    auto exists = get_record(txn.raw(), txn.env(), rid);
    if (!exists) return unexpected(exists.error());
    if (!*exists) continue;
    if (auto d = delete_record(txn, rid, why); !d) return unexpected(d.error());
    ++removed;
  }
  return removed;
}

std::string encode_notice(std::uint64_t pending, const std::vector<Record>& records) {
  std::string out;
  codec::put_varint(out, pending);
  codec::put_varint(out, records.size());
  for (const Record& record : records) put_string(out, encode_removed(record));
  return out;
}

bool decode_notice(std::string_view in, std::uint64_t& pending, std::vector<Record>* records) {
  std::size_t pos = 0;
  std::uint64_t n = 0;
  if (!codec::get_varint(in, pos, pending) || !codec::get_varint(in, pos, n)) return false;
  if (!records) return true;
  records->clear();
  for (std::uint64_t i = 0; i < n; ++i) {
    std::string bytes;
    Record record;
    if (!get_string(in, pos, bytes) || !decode_removed(bytes, record)) return false;
    records->push_back(std::move(record));
  }
  return pos == in.size();
}

Result<std::optional<std::vector<Record>>> get_notice(MDB_txn* txn, const Env& env, std::uint64_t id) {
  if (env.notices == 0) return std::optional<std::vector<Record>>();  // a store that has none yet
  MDB_val k = val(id), v;
  int rc = mdb_get(txn, env.notices, &k, &v);
  if (rc == MDB_NOTFOUND) return std::optional<std::vector<Record>>();
  if (rc != 0) return lmdb_fail(rc, "reading removal notice " + std::to_string(id));
  std::uint64_t pending = 0;
  std::vector<Record> records;
  if (!decode_notice(view(v), pending, &records))
    return fail(Errc::corrupt, "removal notice " + std::to_string(id) + " is truncated");
  return std::optional<std::vector<Record>>(std::move(records));
}

Result<void> release_notice(Txn& txn, std::uint64_t id) {
  if (txn.env().notices == 0) return {};
  MDB_val k = val(id), v;
  int rc = mdb_get(txn.raw(), txn.env().notices, &k, &v);
  if (rc == MDB_NOTFOUND) return {};
  if (rc != 0) return lmdb_fail(rc, "reading removal notice " + std::to_string(id));
  std::uint64_t pending = 0;
  if (!decode_notice(view(v), pending, nullptr))
    return fail(Errc::corrupt, "removal notice " + std::to_string(id) + " is truncated");
  if (pending <= 1) {
    if ((rc = mdb_del(txn.raw(), txn.env().notices, &k, nullptr)) != 0)
      return lmdb_fail(rc, "removing removal notice " + std::to_string(id));
    return {};
  }
  // The count is the row's first varint: rewritten with the rest as it is.
  std::string bytes(view(v));
  std::size_t pos = 0;
  std::uint64_t old = 0;
  codec::get_varint(bytes, pos, old);
  std::string out;
  codec::put_varint(out, pending - 1);
  out.append(bytes, pos, std::string::npos);
  MDB_val nv = val(out);
  if ((rc = mdb_put(txn.raw(), txn.env().notices, &k, &nv, 0)) != 0)
    return lmdb_fail(rc, "writing removal notice " + std::to_string(id));
  return {};
}

std::string encode_removed(const Record& record) {
  std::string out;
  codec::put_varint(out, record.meta.id);
  codec::put_varint(out, record.meta.item);
  codec::put_varint(out, codec::zigzag(record.meta.stored_at));
  codec::put_varint(out, codec::zigzag(record.meta.asserted_at));
  put_string(out, record.meta.source);
  put_string(out, record.meta.context);
  out.push_back(static_cast<char>((record.meta.persistent ? 1 : 0) | (record.meta.span != 0 ? 2 : 0)));
  if (record.meta.span != 0) codec::put_varint(out, static_cast<std::uint64_t>(record.meta.span));
  put_term(out, record.triple.s);
  put_term(out, record.triple.p);
  put_term(out, record.triple.o);
  return out;
}

bool decode_removed(std::string_view in, Record& record) {
  std::size_t pos = 0;
  std::uint64_t stored = 0, asserted = 0;
  if (!codec::get_varint(in, pos, record.meta.id) || !codec::get_varint(in, pos, record.meta.item) ||
      !codec::get_varint(in, pos, stored) || !codec::get_varint(in, pos, asserted) ||
      !get_string(in, pos, record.meta.source) || !get_string(in, pos, record.meta.context) || pos >= in.size())
    return false;
  record.meta.stored_at = codec::unzigzag(stored);
  record.meta.asserted_at = codec::unzigzag(asserted);
  const auto flags = static_cast<std::uint8_t>(in[pos++]);
  if (flags & ~3) return false;  // a later build's entry, which this one would misread
  record.meta.persistent = (flags & 1) != 0;
  record.meta.span = 0;
  if (flags & 2) {
    std::uint64_t span = 0;
    if (!codec::get_varint(in, pos, span) || span > static_cast<std::uint64_t>(INT64_MAX)) return false;
    record.meta.span = static_cast<std::int64_t>(span);
  }
  return get_term(in, pos, record.triple.s) && get_term(in, pos, record.triple.p) &&
         get_term(in, pos, record.triple.o);
}

}  // namespace tahvel::node::detail
