// The peers of `tahvel bench store`, measured in the same run on the same records:
//   SQLite  one table triples(id, s, p, o, item, stored_at, source) indexed on s, p and o; one
//           transaction per item through prepared statements. Two configurations: WAL with
//           synchronous=OFF (no fsync: the durability of Tahvel's fast mode) and SQLite's
//           defaults (rollback journal, synchronous=FULL), as the thesis compared.
//   Sord    libsord in memory with SPO, POS and OPS indexes (no transactions, no durability).
//   socket  a UNIX stream socketpair ping-pong with a forked child: the floor for any
//           cross-process wake-up.
//   futex   a bare FUTEX_WAIT/FUTEX_WAKE between two processes: the floor of the store's own
//           waking mechanism.
// Errors of the peers are thrown as std::runtime_error: they end the bench, which reports them.
#pragma once

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "bench_measure.h"
#include "tahvel/node/term.h"

struct sqlite3;
struct sqlite3_stmt;
typedef struct SordWorldImpl SordWorld;
typedef struct SordModelImpl SordModel;
typedef struct SordNodeImpl SordNode;

namespace tahvel::cli::bench {

enum class SqliteMode {
  wal_sync_off,  // journal_mode=WAL, synchronous=OFF
  defaults,      // journal_mode=DELETE, synchronous=FULL
};

// A row as a query returns it, copied out of SQLite (as Tahvel copies its records).
struct SqliteRow {
  std::int64_t id = 0, item = 0, stored_at = 0;
  std::string s, p, o, source;
};

class SqlitePeer {
 public:
  // Creates the database file `file` (which must not exist) with the table and its indexes.
  SqlitePeer(const std::filesystem::path& file, SqliteMode mode);
  SqlitePeer(const SqlitePeer&) = delete;
  SqlitePeer& operator=(const SqlitePeer&) = delete;
  ~SqlitePeer();

  // Writes one item in its own transaction (BEGIN; INSERT per triple; COMMIT).
  void store(const node::Item& item);
  // Writes many items in one transaction.
  void store_all(const std::vector<node::Item>& items);

  // Rows with subject IRI `s`, in id order.
  std::vector<SqliteRow> list_subject(const std::string& s);
  // The first `limit` rows with predicate IRI `p`, in id order.
  std::vector<SqliteRow> list_predicate(const std::string& p, std::size_t limit);
  // Indexes the asserted_at column (an item's time, as Tahvel's time index does); made after a
  // load, so that the write figures are those of the three term indexes alone.
  void index_time();
  // Rows asserted in [since, until), in id order.
  std::vector<SqliteRow> list_range(std::int64_t since, std::int64_t until);

  std::uint64_t rows();
  std::uint64_t used_bytes();  // (page_count - freelist_count) * page_size

 private:
  void exec(const char* sql);
  sqlite3_stmt* prepare(const char* sql);
  void step_done(sqlite3_stmt* stmt);
  void insert(const node::Item& item, std::int64_t stored_at);
  std::vector<SqliteRow> rows_of(sqlite3_stmt* stmt);
  [[noreturn]] void fail(const std::string& what);

  sqlite3* db_ = nullptr;
  sqlite3_stmt* insert_ = nullptr;
  sqlite3_stmt* begin_ = nullptr;
  sqlite3_stmt* commit_ = nullptr;
  sqlite3_stmt* by_s_ = nullptr;
  sqlite3_stmt* by_p_ = nullptr;
  sqlite3_stmt* by_range_ = nullptr;
  std::int64_t next_id_ = 1;
};

// A triple as a Sord query returns it, copied out (as Tahvel copies its records).
struct SordRow {
  std::string s, p, o;
};

class SordPeer {
 public:
  SordPeer();  // sord_new(world, SORD_SPO | SORD_POS | SORD_OPS, false)
  SordPeer(const SordPeer&) = delete;
  SordPeer& operator=(const SordPeer&) = delete;
  ~SordPeer();

  // Adds the triples of `items`: nodes made with sord_new_uri / sord_new_literal, sord_add.
  void add(const std::vector<node::Item>& items);

  std::vector<SordRow> list_subject(const std::string& s);
  std::vector<SordRow> list_predicate(const std::string& p, std::size_t limit);

  std::uint64_t triples() const;

 private:
  SordNode* make(const node::Term& term);
  std::vector<SordRow> rows_of(SordNode* s, SordNode* p, std::size_t limit);

  SordWorld* world_ = nullptr;
  SordModel* model_ = nullptr;
};

// One-way latency of a UNIX stream socketpair between this process and a forked child: half
// of each round trip of an 8-byte message. With a `pause`, the sender sleeps that long before
// each round trip, so that both sides wake from sleep as a subscriber does. `where` pins the
// two processes.
Percentiles unix_socket_one_way(std::size_t round_trips, std::chrono::microseconds pause,
                                Placement where = {});

// Latency of a bare futex wake-up across processes, the mechanism the store's waking uses:
// after `pause`, the parent increments a shared word and calls FUTEX_WAKE; a forked child
// asleep in FUTEX_WAIT notes when it returns. The floor of store-to-wake, with no store.
Percentiles futex_wake(std::size_t samples, std::chrono::microseconds pause,
                       Placement where = {});

}  // namespace tahvel::cli::bench
