// The peers of `tahvel bench store`: SQLite, Sord and a UNIX-socket ping-pong (see bench_peers.h).
// Each is used the way its documentation recommends for speed (prepared statements, one
// transaction per item; interned Sord nodes), so that a ratio against it means something.
#include "bench_peers.h"

#include <signal.h>
#include <sord/sord.h>
#include <sqlite3.h>
#include <linux/futex.h>
#include <sys/mman.h>
#include <sys/socket.h>
#include <sys/syscall.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include <atomic>
#include <cstdio>
#include <new>
#include <stdexcept>
#include <thread>

namespace tahvel::cli::bench {
namespace {

// A subject or predicate as its IRI (or _:label); the object column holds the N-Triples form,
// so that literals and IRIs stay apart.
std::string key_of(const node::Term& t) { return t.is_blank() ? "_:" + t.value : t.value; }

std::string object_of(const node::Term& t) {
  if (t.is_iri()) return "<" + t.value + ">";
  if (t.is_blank()) return "_:" + t.value;
  std::string out = "\"";
  for (char c : t.value) {
    if (c == '"' || c == '\\') out += '\\';
    out += c;
  }
  out += '"';
  if (!t.language.empty()) return out + "@" + t.language;
  if (!t.datatype.empty() && t.datatype != node::xsd::kString) out += "^^<" + t.datatype + ">";
  return out;
}

std::int64_t wall_ns() {
  timespec ts{};
  clock_gettime(CLOCK_REALTIME, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

std::string column_text(sqlite3_stmt* stmt, int col) {
  const unsigned char* text = sqlite3_column_text(stmt, col);
  return text ? std::string(reinterpret_cast<const char*>(text),
                            static_cast<std::size_t>(sqlite3_column_bytes(stmt, col)))
              : std::string();
}

const char* kSource = "http://example.org/home1/bench";

}  // namespace

// --------------------------------------------------------------------------------------------
// SQLite

SqlitePeer::SqlitePeer(const std::filesystem::path& file, SqliteMode mode) {
  if (sqlite3_open(file.c_str(), &db_) != SQLITE_OK) fail("open " + file.string());
  if (mode == SqliteMode::wal_sync_off) {
    exec("PRAGMA journal_mode=WAL");
    exec("PRAGMA synchronous=OFF");
  } else {
    exec("PRAGMA journal_mode=DELETE");
    exec("PRAGMA synchronous=FULL");
  }
  exec(
      "CREATE TABLE triples(id INTEGER PRIMARY KEY, s TEXT, p TEXT, o TEXT, item INT,"
      " stored_at INT, source TEXT, asserted_at INT)");
  exec("CREATE INDEX triples_s ON triples(s)");
  exec("CREATE INDEX triples_p ON triples(p)");
  exec("CREATE INDEX triples_o ON triples(o)");
  insert_ = prepare("INSERT INTO triples VALUES(?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8)");
  begin_ = prepare("BEGIN");
  commit_ = prepare("COMMIT");
  by_s_ = prepare(
      "SELECT id, s, p, o, item, stored_at, source FROM triples WHERE s = ?1"
      " ORDER BY id");
  by_p_ = prepare(
      "SELECT id, s, p, o, item, stored_at, source FROM triples WHERE p = ?1"
      " ORDER BY id LIMIT ?2");
  by_range_ = prepare(
      "SELECT id, s, p, o, item, stored_at, source FROM triples WHERE asserted_at >= ?1 AND asserted_at < ?2"
      " ORDER BY id");
}

SqlitePeer::~SqlitePeer() {
  for (sqlite3_stmt* s : {insert_, begin_, commit_, by_s_, by_p_, by_range_}) sqlite3_finalize(s);
  sqlite3_close(db_);
}

void SqlitePeer::fail(const std::string& what) {
  throw std::runtime_error("sqlite: " + what + ": " + (db_ ? sqlite3_errmsg(db_) : "no memory"));
}

void SqlitePeer::exec(const char* sql) {
  char* message = nullptr;
  if (sqlite3_exec(db_, sql, nullptr, nullptr, &message) != SQLITE_OK) {
    std::string text = message ? message : "?";
    sqlite3_free(message);
    throw std::runtime_error(std::string("sqlite: ") + sql + ": " + text);
  }
}

sqlite3_stmt* SqlitePeer::prepare(const char* sql) {
  sqlite3_stmt* stmt = nullptr;
  if (sqlite3_prepare_v2(db_, sql, -1, &stmt, nullptr) != SQLITE_OK) fail(sql);
  return stmt;
}

void SqlitePeer::step_done(sqlite3_stmt* stmt) {
  if (sqlite3_step(stmt) != SQLITE_DONE) fail(sqlite3_sql(stmt));
  sqlite3_reset(stmt);
}

void SqlitePeer::insert(const node::Item& item, std::int64_t stored_at) {
  const std::int64_t item_id = next_id_;
  for (const node::Triple& t : item.triples) {
    std::string s = key_of(t.s), o = object_of(t.o);
    sqlite3_bind_int64(insert_, 1, next_id_++);
    sqlite3_bind_text(insert_, 2, s.data(), static_cast<int>(s.size()), SQLITE_STATIC);
    sqlite3_bind_text(insert_, 3, t.p.value.data(), static_cast<int>(t.p.value.size()),
                      SQLITE_STATIC);
    sqlite3_bind_text(insert_, 4, o.data(), static_cast<int>(o.size()), SQLITE_STATIC);
    sqlite3_bind_int64(insert_, 5, item_id);
    sqlite3_bind_int64(insert_, 6, stored_at);
    sqlite3_bind_text(insert_, 7, kSource, -1, SQLITE_STATIC);
    sqlite3_bind_int64(insert_, 8, item.asserted_at.value_or(stored_at));
    step_done(insert_);
  }
}

void SqlitePeer::store(const node::Item& item) {
  step_done(begin_);
  insert(item, wall_ns());
  step_done(commit_);
}

void SqlitePeer::store_all(const std::vector<node::Item>& items) {
  step_done(begin_);
  const std::int64_t stored_at = wall_ns();
  for (const node::Item& item : items) insert(item, stored_at);
  step_done(commit_);
}

std::vector<SqliteRow> SqlitePeer::rows_of(sqlite3_stmt* stmt) {
  std::vector<SqliteRow> rows;
  int rc;
  while ((rc = sqlite3_step(stmt)) == SQLITE_ROW) {
    SqliteRow& r = rows.emplace_back();
    r.id = sqlite3_column_int64(stmt, 0);
    r.s = column_text(stmt, 1);
    r.p = column_text(stmt, 2);
    r.o = column_text(stmt, 3);
    r.item = sqlite3_column_int64(stmt, 4);
    r.stored_at = sqlite3_column_int64(stmt, 5);
    r.source = column_text(stmt, 6);
  }
  if (rc != SQLITE_DONE) fail(sqlite3_sql(stmt));
  sqlite3_reset(stmt);
  return rows;
}

std::vector<SqliteRow> SqlitePeer::list_subject(const std::string& s) {
  sqlite3_bind_text(by_s_, 1, s.data(), static_cast<int>(s.size()), SQLITE_STATIC);
  return rows_of(by_s_);
}

void SqlitePeer::index_time() { exec("CREATE INDEX triples_asserted_at ON triples(asserted_at)"); }

std::vector<SqliteRow> SqlitePeer::list_range(std::int64_t since, std::int64_t until) {
  sqlite3_bind_int64(by_range_, 1, since);
  sqlite3_bind_int64(by_range_, 2, until);
  return rows_of(by_range_);
}

std::vector<SqliteRow> SqlitePeer::list_predicate(const std::string& p, std::size_t limit) {
  sqlite3_bind_text(by_p_, 1, p.data(), static_cast<int>(p.size()), SQLITE_STATIC);
  sqlite3_bind_int64(by_p_, 2, static_cast<sqlite3_int64>(limit));
  return rows_of(by_p_);
}

std::uint64_t SqlitePeer::rows() {
  sqlite3_stmt* stmt = prepare("SELECT count(*) FROM triples");
  std::uint64_t n = sqlite3_step(stmt) == SQLITE_ROW ? sqlite3_column_int64(stmt, 0) : 0;
  sqlite3_finalize(stmt);
  return n;
}

std::uint64_t SqlitePeer::used_bytes() {
  auto pragma = [&](const char* sql) {
    sqlite3_stmt* stmt = prepare(sql);
    std::uint64_t n = sqlite3_step(stmt) == SQLITE_ROW ? sqlite3_column_int64(stmt, 0) : 0;
    sqlite3_finalize(stmt);
    return n;
  };
  return (pragma("PRAGMA page_count") - pragma("PRAGMA freelist_count")) *
         pragma("PRAGMA page_size");
}

// --------------------------------------------------------------------------------------------
// Sord

SordPeer::SordPeer() : world_(sord_world_new()) {
  model_ = sord_new(world_, SORD_SPO | SORD_POS | SORD_OPS, false);
  if (!world_ || !model_) throw std::runtime_error("sord: cannot create a model");
}

SordPeer::~SordPeer() {
  sord_free(model_);
  sord_world_free(world_);
}

SordNode* SordPeer::make(const node::Term& t) {
  auto bytes = [](const std::string& s) { return reinterpret_cast<const uint8_t*>(s.c_str()); };
  if (t.is_iri()) return sord_new_uri(world_, bytes(t.value));
  if (t.is_blank()) return sord_new_blank(world_, bytes(t.value));
  SordNode* datatype = nullptr;
  if (!t.datatype.empty() && t.datatype != node::xsd::kString) {
    datatype = sord_new_uri(world_, bytes(t.datatype));
  }
  SordNode* literal = sord_new_literal(world_, datatype, bytes(t.value),
                                       t.language.empty() ? nullptr : t.language.c_str());
  if (datatype) sord_node_free(world_, datatype);
  return literal;
}

void SordPeer::add(const std::vector<node::Item>& items) {
  for (const node::Item& item : items) {
    for (const node::Triple& t : item.triples) {
      SordNode* s = make(t.s);
      SordNode* p = make(t.p);
      SordNode* o = make(t.o);
      SordQuad quad = {s, p, o, nullptr};
      sord_add(model_, quad);
      sord_node_free(world_, s);
      sord_node_free(world_, p);
      sord_node_free(world_, o);
    }
  }
}

std::vector<SordRow> SordPeer::rows_of(SordNode* s, SordNode* p, std::size_t limit) {
  std::vector<SordRow> rows;
  SordQuad pattern = {s, p, nullptr, nullptr};
  SordIter* it = sord_find(model_, pattern);
  for (; it && !sord_iter_end(it) && (limit == 0 || rows.size() < limit); sord_iter_next(it)) {
    SordQuad quad;
    sord_iter_get(it, quad);
    auto text = [](const SordNode* n) {
      return std::string(reinterpret_cast<const char*>(sord_node_get_string(n)));
    };
    rows.push_back({text(quad[SORD_SUBJECT]), text(quad[SORD_PREDICATE]), text(quad[SORD_OBJECT])});
  }
  sord_iter_free(it);
  if (s) sord_node_free(world_, s);
  if (p) sord_node_free(world_, p);
  return rows;
}

std::vector<SordRow> SordPeer::list_subject(const std::string& s) {
  return rows_of(make(node::Term::iri(s)), nullptr, 0);
}

std::vector<SordRow> SordPeer::list_predicate(const std::string& p, std::size_t limit) {
  return rows_of(nullptr, make(node::Term::iri(p)), limit);
}

std::uint64_t SordPeer::triples() const { return sord_num_quads(model_); }

// --------------------------------------------------------------------------------------------
// UNIX socket ping-pong

namespace {

bool full_io(int fd, char* buf, std::size_t n, bool write_side) {
  std::size_t done = 0;
  while (done < n) {
    ssize_t r = write_side ? ::write(fd, buf + done, n - done) : ::read(fd, buf + done, n - done);
    if (r <= 0) return false;
    done += static_cast<std::size_t>(r);
  }
  return true;
}

[[noreturn]] void echo_child(int fd) {
  char buf[8];
  while (full_io(fd, buf, sizeof buf, false) && full_io(fd, buf, sizeof buf, true)) {
  }
  _exit(0);
}

}  // namespace

Percentiles unix_socket_one_way(std::size_t round_trips, std::chrono::microseconds pause,
                                Placement where) {
  int fds[2];
  if (socketpair(AF_UNIX, SOCK_STREAM, 0, fds) != 0) throw std::runtime_error("socketpair failed");
  std::fflush(nullptr);
  pid_t pid = fork();
  if (pid < 0) throw std::runtime_error("fork failed");
  if (pid == 0) {
    ::close(fds[0]);
    pin_to_cpu(where.child_cpu);
    echo_child(fds[1]);
  }
  ScopedPin pinned(where.parent_cpu);
  ::close(fds[1]);
  std::vector<double> us;
  us.reserve(round_trips);
  char buf[8] = {};
  bool ok = true;
  const std::size_t warmup = round_trips / 10 + 10;
  for (std::size_t i = 0; ok && i < warmup + round_trips; ++i) {
    if (pause.count() > 0) std::this_thread::sleep_for(pause);
    auto t0 = Clock::now();
    ok = full_io(fds[0], buf, sizeof buf, true) && full_io(fds[0], buf, sizeof buf, false);
    if (i >= warmup) us.push_back(micros(Clock::now() - t0) / 2);
  }
  ::close(fds[0]);  // the child reads EOF and exits
  int status = 0;
  waitpid(pid, &status, 0);
  if (!ok) throw std::runtime_error("unix socket ping-pong: the echo child went away");
  return percentiles(std::move(us));
}

// --------------------------------------------------------------------------------------------
// Futex wake-up

namespace {

struct FutexBoard {
  std::atomic<std::uint32_t> word;  // bumped per probe; the child sleeps on it
  std::atomic<std::uint32_t> taken; // probes the child has seen
  std::atomic<std::int64_t> sent_ns, woke_ns;
};

std::int64_t steady_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now().time_since_epoch()).count();
}

long futex(std::atomic<std::uint32_t>* word, int op, std::uint32_t value) {
  timespec limit{1, 0};  // never sleep for good if a wake-up were lost: the bench would hang
  return syscall(SYS_futex, reinterpret_cast<std::uint32_t*>(word), op, value,
                 op == FUTEX_WAIT ? &limit : nullptr, nullptr, 0);
}

[[noreturn]] void futex_child(FutexBoard* b, std::size_t probes) {
  std::uint32_t seen = 0;
  while (b->taken.load() < probes) {
    std::uint32_t now = b->word.load();
    if (now == seen) {
      futex(&b->word, FUTEX_WAIT, seen);
      continue;
    }
    b->woke_ns.store(steady_ns());
    seen = now;
    b->taken.fetch_add(1);
  }
  _exit(0);
}

}  // namespace

Percentiles futex_wake(std::size_t samples, std::chrono::microseconds pause, Placement where) {
  void* mem = mmap(nullptr, sizeof(FutexBoard), PROT_READ | PROT_WRITE, MAP_SHARED | MAP_ANONYMOUS, -1, 0);
  if (mem == MAP_FAILED) throw std::runtime_error("futex bench: mmap failed");
  auto* b = new (mem) FutexBoard{};
  const std::size_t warmup = samples / 10 + 10, probes = warmup + samples;
  std::fflush(nullptr);
  pid_t pid = fork();
  if (pid < 0) throw std::runtime_error("fork failed");
  if (pid == 0) {
    pin_to_cpu(where.child_cpu);
    futex_child(b, probes);
  }
  ScopedPin pinned(where.parent_cpu);
  std::vector<double> us;
  us.reserve(samples);
  bool ok = true;
  for (std::size_t i = 0; ok && i < probes; ++i) {
    std::this_thread::sleep_for(pause);
    const std::int64_t sent = steady_ns();
    b->word.fetch_add(1);
    futex(&b->word, FUTEX_WAKE, 1);
    const auto deadline = Clock::now() + std::chrono::seconds(5);
    while (b->taken.load() <= i) {  // the child notes its time first, then counts
      if (Clock::now() > deadline) { ok = false; break; }
      std::this_thread::yield();
    }
    if (ok && i >= warmup) us.push_back(static_cast<double>(b->woke_ns.load() - sent) / 1000.0);
  }
  kill(pid, SIGKILL);
  waitpid(pid, nullptr, 0);
  munmap(mem, sizeof(FutexBoard));
  if (!ok) throw std::runtime_error("futex wake-up: the child did not answer");
  return percentiles(std::move(us));
}

}  // namespace tahvel::cli::bench
