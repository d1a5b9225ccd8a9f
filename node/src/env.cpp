// LMDB environment lifecycle, table layout and the growing write transaction. See env.h and
// docs/record-model.md for what each table holds.
#include "env.h"

#include "rows.h"
#include "write.h"

#include <chrono>
#include <thread>

#include <fcntl.h>
#include <pthread.h>
#include <sys/mman.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <signal.h>
#include <stdio.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstddef>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <map>
#include <mutex>
#include <random>
#include <sstream>
#include <system_error>
#include <utility>

#include "codec.h"

namespace tahvel::node::detail {
namespace {

// <sys/mman.h> names it from glibc 2.35 on; the kernel has it from 5.14.
#ifdef MADV_POPULATE_WRITE
constexpr int kMadvPopulateWrite = MADV_POPULATE_WRITE;
#else
constexpr int kMadvPopulateWrite = 23;
#endif

// Where LMDB mapped `file` (open as `fd`, `size` bytes) in this process, from /proc/self/maps:
// LMDB tells the address of a fixed map only. The mapping of that inode and that path, at
// offset 0, writable, of that size. Null when not found.
char* find_map(int fd, const std::filesystem::path& file, std::uint64_t size) {
  struct stat st;
  if (fd < 0 || fstat(fd, &st) != 0) return nullptr;
  std::ifstream maps("/proc/self/maps");
  const std::string path = file.string();
  for (std::string line; std::getline(maps, line);) {
    unsigned long start = 0, end = 0, offset = 0, inode = 0;
    unsigned major = 0, minor = 0;
    char perms[5] = {};
    int name_at = 0;
    if (std::sscanf(line.c_str(), "%lx-%lx %4s %lx %x:%x %lu %n", &start, &end, perms, &offset, &major, &minor, &inode,
                    &name_at) != 7)
      continue;
    if (inode == st.st_ino && offset == 0 && end - start == size && perms[1] == 'w' &&
        line.compare(static_cast<std::size_t>(name_at), std::string::npos, path) == 0)
      return reinterpret_cast<char*>(start);
  }
  return nullptr;
}

// A process started with 0, 1 or 2 closed (by a supervisor, or `cmd >&-`) would have LMDB's
// files, or the wake board, opened as those numbers: its output, or a library's message to
// stderr, would then be written into lock.mdb or data.mdb. Before the first file of a store is
// opened, each closed one of them is opened on /dev/null.
void keep_standard_fds_taken() {
  static std::once_flag once;
  std::call_once(once, [] {
    for (int fd = 0; fd <= 2; ++fd) {
      if (fcntl(fd, F_GETFD) != -1 || errno != EBADF) continue;
      const int opened = ::open("/dev/null", fd == 0 ? O_RDONLY : O_WRONLY);
      if (opened >= 0 && opened != fd) ::close(opened);  // another thread took the number first
    }
  });
}

}  // namespace

namespace {

constexpr std::uint64_t kInitialMapBytes = 64ull << 20;

// What removals may use beyond a store's maximum `max`: a sixteenth of it and up to 1 MB more
// (an eighth, in a store of less than 8 MB).
std::uint64_t removal_reserve(std::uint64_t max) { return max / 16 + std::min<std::uint64_t>(1u << 20, max / 8); }

// How far beyond the last page in use the data file's blocks are allocated (reserve_disk): more
// than a write transaction of the store's usual size dirties in new pages.
constexpr std::uint64_t kDiskAhead = 16ull << 20;
// Where the disk has less than that left: what must be allocated for a write to go on.
constexpr std::uint64_t kDiskLeast = 4ull << 20;
constexpr unsigned kMaxReaders = 510;
constexpr unsigned kMaxTables = 16;

std::mutex registry_mutex;
std::map<std::pair<pid_t, std::string>, std::weak_ptr<Env>> registry;

std::string_view key(std::string_view k) { return k; }

Result<std::string> get_meta(MDB_txn* txn, MDB_dbi meta, std::string_view k) {
  MDB_val kv = val(key(k)), v;
  int rc = mdb_get(txn, meta, &kv, &v);
  if (rc != 0) return lmdb_fail(rc, "reading setting '" + std::string(k) + "'");
  return std::string(view(v));
}

Result<void> put_meta(MDB_txn* txn, MDB_dbi meta, std::string_view k, std::string_view value) {
  MDB_val kv = val(k), v = val(value);
  int rc = mdb_put(txn, meta, &kv, &v, 0);
  if (rc != 0) return lmdb_fail(rc, "writing setting '" + std::string(k) + "'");
  return {};
}

std::string u64_bytes(std::uint64_t x) { return std::string(reinterpret_cast<const char*>(&x), sizeof x); }
std::uint64_t bytes_u64(std::string_view s) {
  std::uint64_t x = 0;
  std::memcpy(&x, s.data(), std::min(s.size(), sizeof x));
  return x;
}

// The store format in `meta`; 0 when it says none.
Error other_format(const std::filesystem::path& dir, std::uint32_t v) {
  return Error{Errc::version, dir.string() + " has store format " + std::to_string(v) + ", this build reads " +
                                  std::to_string(kOldestUpgradedFormatVersion) + " to " + std::to_string(kFormatVersion)};
}

std::uint32_t format_of(MDB_txn* txn, MDB_dbi meta) {
  auto version = get_meta(txn, meta, "version");
  if (!version) return 0;
  std::uint32_t v = 0;
  std::memcpy(&v, version->data(), std::min<std::size_t>(version->size(), sizeof v));
  return v;
}

Result<void> put_format(MDB_txn* txn, MDB_dbi meta, std::uint32_t version) {
  return put_meta(txn, meta, "version", std::string(reinterpret_cast<const char*>(&version), sizeof version));
}

// Format 2 to 3: every item into the new (empty) time index, the longest span into the counters.
Result<void> upgrade_to_format_3(MDB_txn* txn, const Env& env) {
  std::vector<std::pair<std::uint64_t, std::uint64_t>> entries;  // (time key, item id)
  std::uint64_t max_span = 0;
  MDB_cursor* cursor = nullptr;
  int rc = mdb_cursor_open(txn, env.items, &cursor);
  if (rc != 0) return lmdb_fail(rc, "opening items");
  MDB_val k, v;
  for (rc = mdb_cursor_get(cursor, &k, &v, MDB_FIRST); rc == 0; rc = mdb_cursor_get(cursor, &k, &v, MDB_NEXT)) {
    ItemRow item;
    if (!decode_item(view(v), item)) {
      mdb_cursor_close(cursor);
      return fail(Errc::corrupt, "item " + std::to_string(u64(k)) + " cannot be read: its row is truncated");
    }
    entries.emplace_back(time_key(item.asserted_at), u64(k));
    max_span = std::max(max_span, static_cast<std::uint64_t>(item.span));
  }
  mdb_cursor_close(cursor);
  if (rc != MDB_NOTFOUND) return lmdb_fail(rc, "reading items");
  std::sort(entries.begin(), entries.end());
  if ((rc = mdb_cursor_open(txn, env.by_time, &cursor)) != 0) return lmdb_fail(rc, "opening the time index");
  for (const auto& [time, item] : entries) {
    MDB_val tk = val(time), iv = val(item);
    if ((rc = mdb_cursor_put(cursor, &tk, &iv, 0)) != 0) break;
  }
  mdb_cursor_close(cursor);
  if (rc != 0) return lmdb_fail(rc, "filling the time index with " + std::to_string(entries.size()) + " items");
  auto counters = load_counters(txn, env.main);
  if (!counters) return unexpected(counters.error());
  counters->max_span = std::max(counters->max_span, max_span);
  if (auto r = save_counters(txn, env.main, *counters); !r) return r;
  return put_format(txn, env.meta, 3);
}

// Format 3 to 4: the table of long terms, made empty with the later tables (open_later_tables);
// the long terms a store holds stay where they are (a term is looked up in `terms` first).
Result<void> upgrade_to_format_4(MDB_txn* txn, const Env& env) { return put_format(txn, env.meta, 4); }

}  // namespace

std::string new_store_id() {
  std::random_device random;  // the kernel's entropy (getrandom)
  char out[33];
  std::snprintf(out, sizeof out, "%08x%08x%08x%08x", random(), random(), random(), random());
  return out;
}

std::string data_file_identity(const std::filesystem::path& dir) {
  // No device number: it can change across reboots (btrfs, disks found in another order) while
  // the file stays the same one. An inode number is reused once freed, but not with the birth
  // time of the file it was.
  struct statx sx {};
  if (::statx(AT_FDCWD, (dir / "data.mdb").c_str(), 0, STATX_INO | STATX_BTIME, &sx) != 0) return {};
  std::string identity = std::to_string(sx.stx_ino) + ":";
  if (sx.stx_mask & STATX_BTIME)
    identity += std::to_string(sx.stx_btime.tv_sec) + "." + std::to_string(sx.stx_btime.tv_nsec);
  else
    identity += "-";
  return identity;
}

Result<void> renew_store_id_as_copy(MDB_txn* txn, MDB_dbi meta, const std::string& id) {
  // A store without an id yet (made before ids) was copied from none known; any other failure
  // to read says so rather than leaving a copy that names nothing it came from.
  std::string lineage;
  auto was = get_meta(txn, meta, kStoreIdKey);
  if (!was && was.error().code != Errc::not_found) return unexpected(was.error());
  if (was && !was->empty() && *was != id) {
    lineage = *was;
    auto before = get_meta(txn, meta, kCopiedFromKey);
    if (!before && before.error().code != Errc::not_found) return unexpected(before.error());
    if (before) {
      std::istringstream ids(*before);
      std::size_t kept = 1;
      for (std::string one; kept < kMaxCopiedFrom && ids >> one; ++kept) lineage += " " + one;
    }
  }
  if (auto r = put_meta(txn, meta, kStoreIdKey, id); !r) return r;
  if (lineage.empty()) return {};
  return put_meta(txn, meta, kCopiedFromKey, lineage);
}

Result<std::string> renew_store_id_of_copy(const std::filesystem::path& dir) {
  MDB_env* raw = nullptr;
  if (int rc = mdb_env_create(&raw); rc != 0) return lmdb_fail(rc, "opening the copy in " + dir.string());
  std::error_code ec;
  const std::uintmax_t bytes = std::filesystem::file_size(dir / "data.mdb", ec);
  if (ec) {
    mdb_env_close(raw);
    return fail(Errc::io, "cannot read the size of the copy in " + dir.string() + ": " + ec.message());
  }
  mdb_env_set_maxdbs(raw, kMaxTables);
  mdb_env_set_mapsize(raw, static_cast<std::size_t>(bytes) + (std::size_t{8} << 20));  // room for the new id's pages
  MDB_txn* txn = nullptr;
  MDB_dbi meta = 0;
  const std::string id = new_store_id();
  int rc = mdb_env_open(raw, dir.c_str(), MDB_NOTLS, 0644);
  if (rc == 0) rc = mdb_txn_begin(raw, nullptr, 0, &txn);
  if (rc == 0) rc = mdb_dbi_open(txn, "meta", 0, &meta);
  std::optional<Error> failed;
  if (rc == 0) {
    if (auto renewed = renew_store_id_as_copy(txn, meta, id); !renewed) failed = renewed.error();
  }
  // The copy's own file, which the rename into place keeps: its first open finds it the same.
  if (const std::string file = data_file_identity(dir); rc == 0 && !failed && !file.empty()) {
    MDB_val k{kDataFileKey.size(), const_cast<char*>(kDataFileKey.data())}, v{file.size(), const_cast<char*>(file.data())};
    rc = mdb_put(txn, meta, &k, &v, 0);
  }
  if (rc == 0 && !failed) {
    rc = mdb_txn_commit(txn);  // synced: the environment is opened without MDB_NOSYNC
    txn = nullptr;
  }
  if (txn) mdb_txn_abort(txn);
  mdb_env_close(raw);
  std::filesystem::remove(dir / "lock.mdb", ec);
  if (failed) return fail(failed->code, "giving the copy in " + dir.string() + " a store id of its own: " + failed->message);
  if (rc != 0) return lmdb_fail(rc, "giving the copy in " + dir.string() + " a store id of its own");
  return id;
}

Error lmdb_error(int rc, std::string_view what) {
  Errc code = Errc::io;
  if (rc == MDB_MAP_FULL) code = Errc::store_full;
  else if (rc == MDB_NOTFOUND || rc == ENOENT) code = Errc::not_found;
  else if (rc == MDB_VERSION_MISMATCH) code = Errc::version;
  else if (rc == MDB_INVALID || rc == MDB_CORRUPTED || rc == MDB_PAGE_NOTFOUND) code = Errc::corrupt;
  // LMDB's words name neither cause: the store's file is damaged (no page is checksummed), or
  // for a version mismatch also written by another LMDB build.
  // MDB_BAD_TXN: an earlier step of the transaction failed, which in a store's reads is a page
  // LMDB refused.
  const char* why = code == Errc::corrupt ? " (the store's data file, data.mdb, is damaged; restore it from a copy)"
                    : code == Errc::version ? " (the store was written by another LMDB build, or its data file, data.mdb, is damaged)"
                    : rc == MDB_BAD_TXN ? " (an earlier read of this transaction failed: the store's data file, data.mdb, may be "
                                          "damaged; 'tahvel check' on the store says)"
                                        : "";
  return Error{code, std::string(what) + ": " + mdb_strerror(rc) + why};
}

Result<Counters> load_counters(MDB_txn* txn, MDB_dbi meta) {
  MDB_val k = val(std::string_view("counters")), v;
  int rc = mdb_get(txn, meta, &k, &v);
  if (rc != 0) return lmdb_fail(rc, "reading counters");
  Counters c;
  // Format 2 wrote them without max_span, the last field.
  constexpr std::size_t kFormat2Size = offsetof(Counters, max_span);
  if (v.mv_size != sizeof c && v.mv_size != kFormat2Size) return fail(Errc::corrupt, "counters record has the wrong size");
  std::memcpy(&c, v.mv_data, v.mv_size);
  return c;
}

Result<void> save_counters(MDB_txn* txn, MDB_dbi meta, const Counters& c) {
  MDB_val k = val(std::string_view("counters")), v = val(&c, sizeof c);
  int rc = mdb_put(txn, meta, &k, &v, 0);
  if (rc != 0) return lmdb_fail(rc, "writing counters");
  return {};
}

std::uint64_t read_notice_seqs(MDB_txn* txn, MDB_dbi meta) {
  MDB_val k = val(kNoticeSeqsKey), v;
  if (mdb_get(txn, meta, &k, &v) != 0 || v.mv_size != sizeof(std::uint64_t)) return 0;
  return u64(v);
}

std::uint64_t TermCache::find(const TermKey& key, std::uint64_t gen, bool* pinned) {
  std::lock_guard lock(mu_);
  *pinned = true;
  if (auto it = pinned_.find(key); it != pinned_.end()) return it->second;
  *pinned = false;
  if (gen != gen_) return 0;
  if (auto it = unpinned_.find(key); it != unpinned_.end()) return it->second;
  return 0;
}

void TermCache::publish(TermIdMap& pinned, TermIdMap& unpinned, std::uint64_t gen) {
  if (pinned.empty() && unpinned.empty()) return;
  std::lock_guard lock(mu_);
  if (pinned_.size() + pinned.size() > kMaxEntries) pinned_.clear();
  pinned_.merge(pinned);
  if (gen < gen_) return;  // seen before a collection another transaction already published
  if (gen > gen_ || unpinned_.size() + unpinned.size() > kMaxEntries) {
    unpinned_.clear();
    gen_ = gen;
  }
  unpinned_.merge(unpinned);
}

bool DecodedTerms::find(std::uint64_t id, Term& out) {
  std::lock_guard lock(mu_);
  auto it = terms_.find(id);
  if (it == terms_.end()) return false;
  out = it->second;
  return true;
}

void DecodedTerms::add(std::uint64_t id, const Term& term) {
  std::lock_guard lock(mu_);
  if (terms_.size() >= kMaxEntries) terms_.clear();
  terms_.emplace(id, term);
}

// The prefault thread's state (env.h): one per Env and process.
struct Env::Prefaulter {
  pid_t pid = getpid();  // the process the thread runs in
  std::mutex mu;
  std::condition_variable cv;
  std::uint64_t wanted = 0;              // under mu: map offsets
  std::atomic<std::uint64_t> ready{0};   // faulted in up to here
  std::uint64_t moves_seen = 0;          // under mu: map_moves_ when `ready` was last valid
  bool stop = false;                     // under mu
  std::thread thread;
};

Env::~Env() {
  // In a child forked after the thread started, its copy is left alone (env.h).
  if (Prefaulter* p = prefaulter_.load(); p && p->pid == getpid()) {
    {
      std::lock_guard lock(p->mu);
      p->stop = true;
    }
    p->cv.notify_all();
    p->thread.join();
    delete p;
  }
  for (MDB_txn* txn : idle_readers_) mdb_txn_abort(txn);
  if (env_) mdb_env_close(env_);
}

Result<void> Env::open_tables(MDB_txn* txn, bool create) {
  struct Table { const char* name; MDB_dbi* dbi; unsigned flags; };
  const unsigned dupfixed = MDB_DUPSORT | MDB_DUPFIXED | MDB_INTEGERDUP;
  const Table tables[] = {
      {"meta", &meta, 0},
      {"terms", &terms, MDB_INTEGERKEY},
      {"term_hash", &term_hash, MDB_INTEGERKEY | dupfixed},
      {"records", &records, MDB_INTEGERKEY},
      {"items", &items, MDB_INTEGERKEY},
      {"idx_s", &idx_s, MDB_INTEGERKEY | dupfixed},
      {"idx_p", &idx_p, MDB_INTEGERKEY | dupfixed},
      {"idx_o", &idx_o, MDB_INTEGERKEY | dupfixed},
      {"inbox", &inbox, MDB_INTEGERKEY | dupfixed},
      {"outbox", &outbox, MDB_INTEGERKEY | dupfixed},
      {"removals", &removals, MDB_INTEGERKEY},
  };
  int rc = mdb_dbi_open(txn, nullptr, 0, &main);
  if (rc != 0) return lmdb_fail(rc, "opening the main table in " + dir_.string());
  for (const auto& t : tables) {
    rc = mdb_dbi_open(txn, t.name, t.flags | (create ? MDB_CREATE : 0), t.dbi);
    if (rc == MDB_NOTFOUND && !create) {
      // A store of a format this build does not read may lack a table this one has.
      if (const std::uint32_t v = t.dbi != &meta ? format_of(txn, meta) : 0; v != 0 && v != kFormatVersion && !is_upgraded_format(v))
        return unexpected(other_format(dir_, v));
      return fail(Errc::corrupt, dir_.string() + " is not a Tahvel store: its LMDB file has no table " + t.name +
                                     " (another program's database, or a damaged store)");
    }
    if (rc != 0) return lmdb_fail(rc, std::string("opening table ") + t.name + " in " + dir_.string());
  }
  return {};
}

Result<bool> Env::open_later_tables(MDB_txn* txn, bool create) {
  // Tables added to format 2 (notices), in format 3 (by_time) and 4 (long_terms): a store made before has them
  // not until its first open, which makes them in a write transaction (open_at).
  const unsigned dupfixed = MDB_DUPSORT | MDB_DUPFIXED | MDB_INTEGERDUP;
  const std::pair<const char*, std::pair<MDB_dbi*, unsigned>> later[] = {
      {"notices", {&notices, MDB_INTEGERKEY}},
      {"by_time", {&by_time, MDB_INTEGERKEY | dupfixed}},
      {"long_terms", {&long_terms, MDB_INTEGERKEY}},
  };
  bool all = true;
  for (const auto& [name, table] : later) {
    int rc = mdb_dbi_open(txn, name, table.second | (create ? MDB_CREATE : 0), table.first);
    if (rc == MDB_NOTFOUND && !create) {
      all = false;
      continue;
    }
    if (rc != 0) return lmdb_fail(rc, std::string("opening table ") + name + " in " + dir_.string());
  }
  return all;
}

namespace {
// Why the LMDB data file `file` is cut short (a copy that stopped half way, a disk that filled
// while copying), or nullopt: the file ends before a root page its newest meta page names. Such
// a file opened, and reads of its lost pages said "holds no Tahvel store settings" or
// MDB_CORRUPTED. Not the meta's last page: LMDB allows a file shorter than that when its free
// list holds the final pages (a store written without MDB_WRITEMAP, by mdb_load say), and the
// roots are pages every commit writes anew. The meta page as LMDB 0.9 writes it on a 64-bit
// machine: a 16-byte page header, then MDB_meta {uint32 magic, version; void* address; size_t
// mapsize; MDB_db dbs[2]; pgno_t last_pg; txnid_t txnid}, an MDB_db being 48 bytes that start
// with md_pad (the first's is the page size) and end with md_root. Anything else (another
// layout, a file too short for its metas) is left to LMDB to judge.
std::optional<std::string> cut_short(const std::filesystem::path& file) {
  if constexpr (sizeof(void*) != 8 || sizeof(std::size_t) != 8) return std::nullopt;
  constexpr std::uint32_t kMagic = 0xBEEFC0DE;
  constexpr std::uint64_t kNoPage = ~std::uint64_t{0};  // P_INVALID: an empty tree's root
  constexpr std::size_t kMagicAt = 16, kPageSizeAt = 40, kFreeRootAt = 80, kMainRootAt = 128, kTxnAt = 144, kMetaBytes = 152;
  std::ifstream in(file, std::ios::binary | std::ios::ate);  // one handle for the metas and the size
  if (!in) return std::nullopt;
  const std::streamoff end = in.tellg();
  if (end < 0) return std::nullopt;
  const auto size = static_cast<std::uint64_t>(end);
  struct Meta {
    std::uint32_t page_size = 0;
    std::uint64_t highest_root = 0, txn = 0;
  };
  auto meta_at = [&](std::uint64_t offset) -> std::optional<Meta> {
    char bytes[kMetaBytes];
    in.clear();
    in.seekg(static_cast<std::streamoff>(offset));
    if (!in.read(bytes, sizeof bytes)) return std::nullopt;
    std::uint32_t magic = 0;
    Meta m;
    std::uint64_t roots[2] = {};
    std::memcpy(&magic, bytes + kMagicAt, 4);
    std::memcpy(&m.page_size, bytes + kPageSizeAt, 4);
    std::memcpy(&roots[0], bytes + kFreeRootAt, 8);
    std::memcpy(&roots[1], bytes + kMainRootAt, 8);
    std::memcpy(&m.txn, bytes + kTxnAt, 8);
    if (magic != kMagic || m.page_size < 512 || (m.page_size & (m.page_size - 1)) != 0) return std::nullopt;
    for (std::uint64_t root : roots)
      if (root != kNoPage) m.highest_root = std::max(m.highest_root, root);
    return m;
  };
  std::optional<Meta> meta = meta_at(0);
  if (!meta) return std::nullopt;
  if (auto second = meta_at(meta->page_size); second && second->page_size == meta->page_size && second->txn > meta->txn) meta = second;
  if (meta->highest_root >= size / meta->page_size) {
    const std::uint64_t reach = (meta->highest_root + 1) * meta->page_size;
    return file.string() + " is cut short: its root page ends at byte " + std::to_string(reach) + ", the file holds " +
           std::to_string(size) + " (restore the store from a backup, or move its directory aside to make a new one)";
  }
  return std::nullopt;
}

// The names of `dir`'s subdirectories that hold a store, sorted, at most five and "…" after
// them; empty when none (or `dir` cannot be read).
std::string stores_in_subdirectories(const std::filesystem::path& dir) {
  std::error_code ec;
  std::vector<std::string> names;
  for (std::filesystem::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    std::error_code ignored;
    // Not the directories a store is made in before it is renamed into place: an init's dot
    // directories, `up`'s <id>.making.
    const std::string name = it->path().filename().string();
    if (!name.starts_with('.') && !name.ends_with(".making") && it->is_directory(ignored) &&
        std::filesystem::exists(it->path() / "data.mdb", ignored))
      names.push_back(it->path().filename().string());
  }
  std::sort(names.begin(), names.end());
  std::string list;
  for (std::size_t i = 0; i < names.size() && i < 5; ++i) list += (i == 0 ? "" : ", ") + names[i];
  if (names.size() > 5) list += ", …";
  return list;
}

void remove_abandoned_inits(const std::filesystem::path& dir);
}  // namespace

Result<std::shared_ptr<Env>> Env::open(const std::filesystem::path& dir_in, const InitOptions* init,
                                       const FirstWrite& first_write) {
  // An empty path is no directory: LMDB would make "/data.mdb" of it, and the store files the
  // current directory.
  if (dir_in.empty()) return fail(Errc::invalid_argument, "no store directory given (an empty path)");
  std::error_code ec;
  // The directories an init makes, deepest first: a failed init takes them away again ("nothing
  // was made" left an empty directory, which the next init took for a place already chosen).
  std::vector<std::filesystem::path> made_dirs;
  if (init) {
    for (auto at = std::filesystem::absolute(dir_in, ec); !ec && !at.empty() && !std::filesystem::exists(at, ec) && !ec;
         at = at.parent_path()) {
      made_dirs.push_back(at);
      if (at == at.parent_path()) break;
    }
    ec.clear();
  }
  if (init && !std::filesystem::create_directories(dir_in, ec) && ec)
    return fail(Errc::io, "cannot make the store's directory " + dir_in.string() + ": " + ec.message());
  auto unmake_dirs = [&] {
    std::error_code ignored;
    for (const auto& made : made_dirs) std::filesystem::remove(made, ignored);  // only while empty
  };
  auto dir = std::filesystem::weakly_canonical(dir_in, ec);
  if (ec) dir = dir_in;
  const bool exists = std::filesystem::exists(dir / "data.mdb", ec);
  if (ec && ec != std::errc::no_such_file_or_directory)
    return fail(Errc::io, "cannot look for a store in " + dir.string() + ": " + ec.message());
  if (init && exists) {
    // As opening it says (below): an empty data file is no store, and "already holds a store"
    // there sent the user to a store `list` says is not one.
    if (std::filesystem::file_size(dir / "data.mdb", ec) == 0 && !ec)
      return fail(Errc::exists, (dir / "data.mdb").string() + " is empty: not a store, but in the way of one; remove it to make a store there");
    return fail(Errc::exists, dir.string() + " already holds a store");
  }
  // A directory of node stores (tahvel up's state directory) given for one of them: the usual
  // slip, and "run tahvel init" made an empty store beside them that answered every question.
  if (const std::string below = init || !exists ? stores_in_subdirectories(dir) : ""; !below.empty()) {
    if (init)
      return fail(Errc::exists, dir.string() + " holds node stores in its subdirectories (" + below +
                                    "): not a place for another store");
    if (!exists)
      return fail(Errc::not_found, "no store in " + dir.string() + ": it holds node stores in its subdirectories (" + below +
                                       "); give one of them, as " + (dir / below.substr(0, below.find(',')))
                                       .string());
  }
  if (!init && !exists) return fail(Errc::not_found, "no store in " + dir.string() + " (run tahvel init)");
  // A store's file is made whole elsewhere and renamed into place (make_store): an empty one is
  // not a store, and opening it would make it an empty LMDB file.
  if (!init && std::filesystem::file_size(dir / "data.mdb", ec) == 0 && !ec)
    return fail(Errc::corrupt, (dir / "data.mdb").string() + " is empty: not a store");
  if (init) {
    if (auto made = make_store(dir, *init, first_write); !made) {
      unmake_dirs();
      return unexpected(made.error());
    }
  }
  auto opened = open_at(dir, nullptr);
  // What an init killed before it finished left here (its store being made, a sparse 64 MiB
  // file; or, killed once the store was in place, an empty directory that nothing else takes).
  if (opened && !(*opened)->read_only_) remove_abandoned_inits(dir);
  return opened;
}

namespace {

constexpr std::string_view kInitDirPrefix = ".init-";

// Directories that inits killed before they finished left in `dir` (their process is gone).
void remove_abandoned_inits(const std::filesystem::path& dir) {
  std::error_code ec;
  // increment(ec): a directory removed while listed ends the walk, not with an exception.
  for (auto entry = std::filesystem::directory_iterator(dir, ec); !ec && entry != std::filesystem::directory_iterator();
       entry.increment(ec)) {
    const std::string name = entry->path().filename().string();
    if (!name.starts_with(kInitDirPrefix)) continue;
    const long pid = std::strtol(name.c_str() + kInitDirPrefix.size(), nullptr, 10);
    if (pid > 0 && (kill(static_cast<pid_t>(pid), 0) == 0 || errno != ESRCH)) continue;
    std::error_code removing;
    std::filesystem::remove_all(entry->path(), removing);
  }
}

// Moves `from` to `to` unless `to` exists (atomically: of two movers one gets EEXIST).
int move_unless_there(const std::filesystem::path& from, const std::filesystem::path& to) {
  if (renameat2(AT_FDCWD, from.c_str(), AT_FDCWD, to.c_str(), RENAME_NOREPLACE) == 0) return 0;
  if (errno != EINVAL && errno != ENOSYS) return errno;
  // A filesystem without RENAME_NOREPLACE: link() fails on an existing name just as atomically.
  if (link(from.c_str(), to.c_str()) != 0) return errno;
  unlink(from.c_str());
  return 0;
}

}  // namespace

Result<void> Env::make_store(const std::filesystem::path& dir, const InitOptions& init, const FirstWrite& first_write) {
  remove_abandoned_inits(dir);
  std::random_device random;
  const std::filesystem::path building =
      dir / (std::string(kInitDirPrefix) + std::to_string(getpid()) + "-" + std::to_string(random()));
  std::error_code ec;
  std::filesystem::create_directory(building, ec);
  if (ec) return fail(Errc::io, "making " + building.string() + ": " + ec.message());
  auto cleanup = [&] {
    std::lock_guard lock(registry_mutex);
    registry.erase({getpid(), building.string()});
    std::filesystem::remove_all(building, ec);
  };
  // The error of a write into the store being made names the directory it is made in, which
  // is gone by then, and a full store's way out: there is no store yet to remove records from.
  auto making_failed = [&](Error error) {
    for (std::size_t at; (at = error.message.find(building.string())) != std::string::npos;)
      error.message.replace(at, building.string().size(), dir.string());
    if (error.code == Errc::store_full)
      for (const std::string_view removal : {", or remove records from the store,", ", remove records"})
        if (const std::size_t at = error.message.find(removal); at != std::string::npos) error.message.erase(at, removal.size());
    if (const std::size_t at = error.message.find(" and write again"); at != std::string::npos)
      error.message.replace(at, 16, " and make it again");
    error.message = "making a store in " + dir.string() + ": " + error.message + "; nothing was made";
    return unexpected(std::move(error));
  };
  {
    auto made = open_at(building, &init);
    if (!made) {
      cleanup();
      return making_failed(made.error());
    }
    if (first_write) {
      if (auto written = first_write(**made); !written) {
        *made = nullptr;  // closed before its directory goes
        cleanup();
        return making_failed(written.error());
      }
    }
  }  // closed: its data file is complete (and synced when durable)
  const int moved = move_unless_there(building / "data.mdb", dir / "data.mdb");
  cleanup();
  if (moved == EEXIST) return fail(Errc::exists, dir.string() + " already holds a store");
  if (moved != 0) return fail(Errc::io, "moving the new store into " + dir.string() + ": " + std::strerror(moved));
  if (init.durability == Durability::durable) {
    const int fd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY);
    if (fd >= 0) {
      fsync(fd);
      close(fd);
    }
  }
  return {};
}

namespace {

// The size of the store's data file in `dir`, 0 when it cannot be told. A map is never made
// smaller than it: with MDB_WRITEMAP, mapping shrinks the file to the map.
std::uint64_t data_file_bytes(const std::filesystem::path& dir) {
  struct stat st {};
  if (::stat((dir / "data.mdb").c_str(), &st) != 0 || st.st_size <= 0) return 0;
  return static_cast<std::uint64_t>(st.st_size);
}

// What a permission error opening the store at `dir` comes from, as ": FILE is not …" (empty
// when every file is as it should be). Reading takes writing too: LMDB keeps its readers' table
// in lock.mdb, and a reader wakes writers through `wake`; the message alone left users
// looking at data.mdb.
std::string access_hint(const std::filesystem::path& dir) {
  std::string said;
  auto check = [&](const std::filesystem::path& file, int mode, const char* why) {
    if (::access(file.c_str(), F_OK) != 0 || ::access(file.c_str(), mode) == 0) return;
    said += "; " + file.filename().string() + " is not " + (mode == R_OK ? "readable" : "writable") + " by this user: " + why;
  };
  check(dir / "data.mdb", R_OK, "the records are in it");
  check(dir / "data.mdb", W_OK, "LMDB maps it read-write in every process, readers too");
  check(dir / "lock.mdb", R_OK | W_OK, "every process that reads the store, not only writers, registers in it");
  check(dir / "wake", R_OK | W_OK, "every process that opens the store uses it to wake the others");
  if (said.empty() && ::access(dir.c_str(), W_OK | X_OK) != 0)
    said = "; the directory is not writable by this user: the lock file is made there";
  if (!said.empty()) said += " (this user is uid " + std::to_string(::geteuid()) + "; run as the store's owner, or give it those rights)";
  return said;
}

// Allocates the blocks of the store's lock file up to what LMDB makes of it (its readers'
// table: kMaxReaders slots of a cache line, and its header), before LMDB maps it. LMDB sizes
// the file with ftruncate, which allocates nothing: on a full disk the first write into the map
// (at init) or the first into a reader slot on a page not touched before was SIGBUS, the store
// left half made. KEEP_SIZE: LMDB takes the file's size for its table's, so the size stays its.
// Where the file cannot be opened here (a read-only filesystem, another user's) LMDB says why.
Result<void> allocate_lock_file(const std::filesystem::path& dir) {
  const std::filesystem::path file = dir / "lock.mdb";
  const int fd = ::open(file.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
  if (fd < 0) return {};
  struct stat st {};
  const bool fresh = fstat(fd, &st) == 0 && st.st_size == 0;
  // A file LMDB sized already: its own size (beyond it a block may not be had on a full disk,
  // where this store must still open to be read and emptied). A new one: a margin over the table.
  const off_t bytes = fresh ? static_cast<off_t>(kMaxReaders) * 64 + 4096 : st.st_size;
  int rc = 0;
  do rc = bytes > 0 && fallocate(fd, FALLOC_FL_KEEP_SIZE, 0, bytes) != 0 ? errno : 0;
  while (rc == EINTR);
  ::close(fd);
  // A lock file an older version left sparse on a disk that has filled: opened as it is, as
  // before (a reader on one of its holes may die of SIGBUS), rather than not at all.
  if (rc == ENOSPC && fresh)
    return fail(Errc::store_full, "the disk holding " + dir.string() + " has no room for the store's lock file (" +
                                      std::to_string(bytes >> 10) + " KB): free some space on it and try again");
  return {};  // EOPNOTSUPP and the like: a filesystem without it, as LMDB alone
}

}  // namespace

Result<std::shared_ptr<Env>> Env::open_at(const std::filesystem::path& dir, const InitOptions* init) {
  std::lock_guard lock(registry_mutex);
  auto reg_key = std::make_pair(getpid(), dir.string());
  if (auto it = registry.find(reg_key); it != registry.end()) {
    if (auto shared = it->second.lock()) {
      // Not one whose data file is no longer the one at `dir` (the store deleted and made again
      // while a handle of this process kept the old one open: every write through it failed).
      // A second environment is opened only on another lock file: two on one lock file in one
      // process break LMDB's locks (its fcntl locks are the process's), and closing the old one
      // would clear the new one's reader slots. A data file put in place alone is refused.
      auto in_place = shared->check_in_place(/*now=*/true);
      if (in_place) return shared;
      struct stat lock {};
      if (::stat((dir / "lock.mdb").c_str(), &lock) == 0 && lock.st_dev == shared->lock_dev_ && lock.st_ino == shared->lock_ino_)
        return fail(Errc::io, in_place.error().message + "; this process still has the store it replaced open: close every "
                                                         "handle of it before opening the one now there");
    }
  }

  keep_standard_fds_taken();
  std::shared_ptr<Env> env(new Env());
  env->dir_ = dir;
  int rc = mdb_env_create(&env->env_);
  if (rc != 0) return lmdb_fail(rc, "creating LMDB environment");
  mdb_env_set_maxdbs(env->env_, kMaxTables);
  mdb_env_set_maxreaders(env->env_, kMaxReaders);
  // A new store gets the initial map size. An existing one is mapped at the size of its data
  // file: with MDB_WRITEMAP, LMDB sizes the file to the map, and the size its meta page records
  // is the last committed one, short of a file that a writer's transaction in progress grew (a
  // long `tahvel load`). Opened at that size, the file shrank under the writer, which died of
  // SIGBUS with its whole transaction.
  if (init) mdb_env_set_mapsize(env->env_, std::min<std::uint64_t>(kInitialMapBytes, init->max_map_bytes));
  else if (const std::uint64_t bytes = data_file_bytes(dir); bytes > 0) mdb_env_set_mapsize(env->env_, bytes);
  // NOTLS: snapshots are not tied to threads. WRITEMAP: writes go straight to the shared map
  // (fewer copies); LMDB stays copy-on-write, so a killed writer leaves no trace.
  unsigned flags = MDB_NOTLS | MDB_WRITEMAP | MDB_NOSYNC | MDB_NOMETASYNC;
  // Before mdb_env_open, which with MDB_WRITEMAP grows a short file to the map's size with zeros.
  if (!init)
    if (auto cut = cut_short(dir / "data.mdb")) return fail(Errc::corrupt, *cut);
  if (auto allocated = allocate_lock_file(dir); !allocated) return unexpected(allocated.error());
  rc = mdb_env_open(env->env_, dir.c_str(), flags, 0644);
  if (rc == EROFS && !init) {
    // A store on a read-only filesystem (a disk mounted read-only to save what is on it, a
    // copy on read-only media) is read without its lock file, which LMDB allows for a
    // read-only environment only; nothing can write there, so nothing is missed.
    mdb_env_close(env->env_);
    env->env_ = nullptr;
    if ((rc = mdb_env_create(&env->env_)) != 0) return lmdb_fail(rc, "creating LMDB environment");
    mdb_env_set_maxdbs(env->env_, kMaxTables);
    mdb_env_set_maxreaders(env->env_, kMaxReaders);
    if (const std::uint64_t bytes = data_file_bytes(dir); bytes > 0) mdb_env_set_mapsize(env->env_, bytes);
    rc = mdb_env_open(env->env_, dir.c_str(), MDB_NOTLS | MDB_RDONLY, 0644);
    env->read_only_ = rc == 0;
  }
  if (rc == EACCES || rc == EPERM) return fail(Errc::io, "opening store " + dir.string() + ": " + std::strerror(rc) + access_hint(dir));
  if (rc != 0) return lmdb_fail(rc, "opening store " + dir.string());
  // LMDB opens the data file without close-on-exec: a program this process starts (the
  // supervisor's agents, `up`'s checks) held the store open for as long as it ran.
  if (mdb_filehandle_t fd; mdb_env_get_fd(env->env_, &fd) == 0) ::fcntl(fd, F_SETFD, ::fcntl(fd, F_GETFD) | FD_CLOEXEC);
  // What check_in_place() compares the path with later: the file as the path named it now.
  if (struct stat data {}; ::stat((dir / "data.mdb").c_str(), &data) == 0) {
    env->data_dev_ = data.st_dev;
    env->data_ino_ = data.st_ino;
  }
  if (struct stat lock {}; ::stat((dir / "lock.mdb").c_str(), &lock) == 0) {
    env->lock_dev_ = lock.st_dev;
    env->lock_ino_ = lock.st_ino;
  }
  int dead = 0;
  mdb_reader_check(env->env_, &dead);  // reader slots of dead processes

  // An existing store is opened in a read transaction: a writer of another process that hangs
  // inside its transaction (stopped, stuck) must not hang every process that opens the store,
  // `tahvel status` among them. Only a store made before store ids (or before its data file
  // was recorded) needs a write, once, and a copy of a store in another file, at its first open.
  const unsigned first_flags = init ? 0 : MDB_RDONLY;
  bool needs_store_id = false, needs_tables = false, needs_file_record = false;
  std::uint32_t opened_format = 0;
  const std::string data_file = data_file_identity(dir);
  MDB_txn* txn = nullptr;
  rc = mdb_txn_begin(env->env_, nullptr, first_flags, &txn);
  if (rc == MDB_MAP_RESIZED) {
    mdb_env_set_mapsize(env->env_, data_file_bytes(dir));  // 0 (unknown): the committed size
    rc = mdb_txn_begin(env->env_, nullptr, first_flags, &txn);
  }
  if (rc != 0) return lmdb_fail(rc, "starting the first transaction in " + dir.string());
  auto body = [&]() -> Result<void> {
    if (auto t = env->open_tables(txn, init != nullptr); !t) return t;
    auto later = env->open_later_tables(txn, init != nullptr);
    if (!later) return unexpected(later.error());
    needs_tables = !*later;
    if (init) {
      Settings s{init->iri, init->durability, init->ring, init->max_literal_bytes, init->max_map_bytes};
      if (auto r = put_format(txn, env->meta, kFormatVersion); !r) return r;
      const std::pair<std::string_view, std::string> values[] = {
          {"iri", s.iri},
          {"durability", s.durability == Durability::durable ? "durable" : "fast"},
          {"ring", u64_bytes(s.ring)},
          {"max_literal", u64_bytes(s.max_literal_bytes)},
          {"max_map", u64_bytes(s.max_map_bytes)},
      };
      for (const auto& [k, v] : values)
        if (auto r = put_meta(txn, env->meta, k, v); !r) return r;
      const uri::PrefixMap standard = uri::PrefixMap::standard();
      for (const auto& [prefix, ns] : standard.entries())
        if (auto r = put_meta(txn, env->meta, "prefix:" + prefix, ns); !r) return r;
      if (auto r = save_counters(txn, env->main, Counters{}); !r) return r;
    }
    const std::uint32_t v = format_of(txn, env->meta);
    opened_format = v;
    if (v == 0)
      return fail(Errc::corrupt, dir.string() + " holds no Tahvel store settings (its settings table reads as empty: the "
                                               "store's data file, data.mdb, is damaged, or it is another program's LMDB "
                                               "file; restore it from a copy)");
    if (is_upgraded_format(v) && (first_flags & MDB_RDONLY)) {
      needs_tables = true;  // and its format written (format 2: its time index filled)
    } else if (v != kFormatVersion) {
      return unexpected(other_format(dir, v));
    }
    auto iri = get_meta(txn, env->meta, "iri");
    auto durability = get_meta(txn, env->meta, "durability");
    auto ring = get_meta(txn, env->meta, "ring");
    auto max_literal = get_meta(txn, env->meta, "max_literal");
    auto max_map = get_meta(txn, env->meta, "max_map");
    if (!iri || !durability || !ring || !max_literal || !max_map)
      return fail(Errc::corrupt, dir.string() + ": store settings incomplete");
    env->settings_ = Settings{*iri, *durability == "durable" ? Durability::durable : Durability::fast,
                              bytes_u64(*ring), bytes_u64(*max_literal), bytes_u64(*max_map)};
    // A store made before store ids existed gets one at its first open.
    if (!get_meta(txn, env->meta, kStoreIdKey)) {
      if (first_flags & MDB_RDONLY) needs_store_id = true;
      else if (auto r = put_meta(txn, env->meta, kStoreIdKey, new_store_id()); !r) return r;
    }
    if (init) {
      if (!data_file.empty())
        if (auto r = put_meta(txn, env->meta, kDataFileKey, data_file); !r) return r;
    } else if (!data_file.empty()) {
      auto recorded = get_meta(txn, env->meta, kDataFileKey);
      needs_file_record = !recorded || *recorded != data_file;
    }
    return {};
  };
  if (auto r = body(); !r) {
    mdb_txn_abort(txn);
    return unexpected(r.error());
  }
  rc = mdb_txn_commit(txn);  // also for a read transaction: the table handles outlive it
  if (rc != 0) return lmdb_fail(rc, "committing the first transaction in " + dir.string());
  // After the tables are found: a directory that holds another program's LMDB file gets no
  // file of ours.
  if (auto w = env->read_only_ ? env->wake_.open_private() : env->wake_.open(dir / "wake"); !w) {
    // The wake file alone another user's, or read-only: said as for the store's own files.
    if (const std::string hint = access_hint(dir); !hint.empty() && w.error().code == Errc::io)
      return fail(Errc::io, "opening store " + dir.string() + ": " + w.error().message + hint);
    return unexpected(w.error());
  }
  // Format 3 lacks only the table of long terms, which no read needs (long_terms stays 0): read
  // as it is. A format-2 store's time index must be filled first.
  if (env->read_only_ && needs_tables && opened_format == 3) needs_tables = false;
  if (env->read_only_ && needs_tables)
    return fail(Errc::version, dir.string() + " is on a read-only filesystem, and its store, of an earlier format, is upgraded at its first open: copy it to a writable disk to read it");
  if (env->read_only_) needs_store_id = needs_file_record = false;  // read as it is: nothing can write there
  // A format-2 store's time index needs room (tens of bytes an item): when the map is full the
  // transaction is tried again in a larger one, into the reserve kept for removals if need be
  // (a store that cannot be opened could not be emptied either).
  for (int attempt = 0; needs_store_id || needs_tables || needs_file_record; ++attempt) {
    rc = mdb_txn_begin(env->env_, nullptr, 0, &txn);
    if (rc != 0) return lmdb_fail(rc, "starting a transaction in " + dir.string());
    Result<void> r;
    if (!get_meta(txn, env->meta, kStoreIdKey)) r = put_meta(txn, env->meta, kStoreIdKey, new_store_id());
    // Read again in this transaction: another process may have opened the copy meanwhile and
    // given it its id. A store that recorded no file yet (made before this was kept) only
    // records it: nothing says it was copied.
    if (auto recorded = get_meta(txn, env->meta, kDataFileKey); r && needs_file_record && (!recorded || *recorded != data_file)) {
      if (recorded) r = renew_store_id_as_copy(txn, env->meta, new_store_id());
      if (r) r = put_meta(txn, env->meta, kDataFileKey, data_file);
    }
    if (r && needs_tables) {
      if (auto made = env->open_later_tables(txn, true); !made) r = unexpected(made.error());
    }
    // Read again in this transaction: another process may have upgraded the store meanwhile.
    if (r && format_of(txn, env->meta) == 2) r = upgrade_to_format_3(txn, *env);
    if (r && format_of(txn, env->meta) == 3) r = upgrade_to_format_4(txn, *env);
    if (r) {
      rc = mdb_txn_commit(txn);
      if (rc == 0) break;
      r = lmdb_fail(rc, "bringing " + dir.string() + " up to this build's tables");
    } else {
      mdb_txn_abort(txn);
    }
    if (r.error().code != Errc::store_full || attempt == 16) return unexpected(r.error());
    if (auto grown = env->grow(WriteKind::removal); !grown) return unexpected(grown.error());
  }
  if (env->settings_.durability == Durability::durable) {
    mdb_env_set_flags(env->env_, MDB_NOSYNC | MDB_NOMETASYNC, 0);
    if (init) mdb_env_sync(env->env_, 1);
  }
  registry[reg_key] = env;
  return env;
}

bool Env::quiesce_locked() {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(1);
  while (active_txns_.load() != 0) {
    if (std::chrono::steady_clock::now() >= deadline) return false;
    std::this_thread::sleep_for(std::chrono::microseconds(50));
  }
  return true;
}

Result<void> Env::begin(MDB_txn** txn, unsigned flags) {
  if (read_only_ && !(flags & MDB_RDONLY)) return unexpected(read_only_error());
  for (int attempt = 0; attempt < 2; ++attempt) {
    int rc = 0;
    {
      std::shared_lock lock(growth_mutex_);
      rc = mdb_txn_begin(env_, nullptr, flags, txn);
      if (rc == 0) {
        active_txns_.fetch_add(1);
        return {};
      }
    }
    // Another process grew the map: adopt its size and try again. LMDB allows that only while
    // this process has no transaction open.
    if (rc == MDB_MAP_RESIZED) {
      std::unique_lock lock(growth_mutex_);
      if (!quiesce_locked())
        return fail(Errc::io, "the store in " + dir_.string() +
                                  " grew in another process while this process holds a snapshot;"
                                  " release the snapshot and retry");
      mdb_env_set_mapsize(env_, data_file_bytes(dir_));  // not below the file: see open_at
      map_moves_.fetch_add(1);
      continue;
    }
    return lmdb_fail(rc, flags & MDB_RDONLY ? "starting a snapshot" : "starting a write");
  }
  return fail(Errc::io, "starting a transaction: map resized repeatedly");
}

Result<MDB_txn*> Env::begin_read() {
  MDB_txn* txn = nullptr;
  {
    std::lock_guard lock(idle_readers_mutex_);
    if (!idle_readers_.empty()) {
      txn = idle_readers_.back();
      idle_readers_.pop_back();
    }
  }
  if (txn) {
    // Renewing keeps the reader slot: no trip through LMDB's reader-table mutex.
    std::shared_lock lock(growth_mutex_);
    int rc = mdb_txn_renew(txn);
    if (rc == 0) {
      active_txns_.fetch_add(1);
      return txn;
    }
    lock.unlock();
    mdb_txn_abort(txn);  // e.g. MAP_RESIZED: the plain path below adopts the new size
    txn = nullptr;
  }
  if (auto r = begin(&txn, MDB_RDONLY); !r) return unexpected(r.error());
  return txn;
}

void Env::end_read(MDB_txn* txn) {
  mdb_txn_reset(txn);
  active_txns_.fetch_sub(1);
  std::lock_guard lock(idle_readers_mutex_);
  if (idle_readers_.size() < kIdleReaders) {
    idle_readers_.push_back(txn);
  } else {
    mdb_txn_abort(txn);
  }
}

namespace {
std::string pinned_by_a_reader(MDB_env* env, std::uint64_t last_txnid);
}  // namespace

Result<void> Env::grow(WriteKind kind, std::uint64_t removal_copy_bytes) {
  std::unique_lock lock(growth_mutex_);
  MDB_envinfo info;
  mdb_env_info(env_, &info);
  std::uint64_t current = info.me_mapsize;
  // Removal needs pages too (LMDB copies on write): a reserve beyond the maximum is kept for
  // it, so that a full store can always be emptied. A record's copy into the removal log is one
  // run of pages, as long as its literal (up to max_literal_bytes, 1 MB by default, which the
  // reserve of a small store is not): room for two, since the pages the last removal's copy
  // freed are not reused by the next transaction. A 1 MiB store holding 300 KB literals could
  // not be emptied.
  std::uint64_t limit = settings_.max_map_bytes;
  if (kind == WriteKind::removal) limit += removal_reserve(limit) + 2 * removal_copy_bytes;
  if (kind == WriteKind::from_below) limit -= kept_for_own_writers(limit);
  if (current >= limit) {
    if (kind == WriteKind::from_below) {
      MDB_stat stat;
      mdb_env_stat(env_, &stat);
      return from_below_refused((info.me_last_pgno + 1) * stat.ms_psize, true, pinned_by_a_reader(env_, info.me_last_txnid));
    }
    return fail(Errc::store_full, "store full: " + dir_.string() + " reached its maximum of " +
                                      std::to_string(settings_.max_map_bytes) + " bytes" +
                                      pinned_by_a_reader(env_, info.me_last_txnid));
  }
  if (!quiesce_locked())  // not full: growing waits for this process's own snapshots
    return fail(Errc::io, "the store in " + dir_.string() +
                              " must grow, and cannot while this process holds a snapshot; release the snapshot and retry");
  std::uint64_t next = std::min(limit, std::max(current * 2, current + kInitialMapBytes));
  // Not below the file, which another process's transaction in progress may have grown.
  next = std::max(next, data_file_bytes(dir_));
  int rc = mdb_env_set_mapsize(env_, next);
  map_moves_.fetch_add(1);
  if (rc != 0) return lmdb_fail(rc, "growing the store map of " + dir_.string());
  return {};
}

namespace {

// Where the data file's allocated blocks from `from` on end: the first hole at or after `from`.
// `from` itself where the filesystem cannot tell (without SEEK_HOLE support Linux reports the
// whole file as data, which for this sparse file would be a lie).
std::uint64_t allocated_from(int fd, std::uint64_t from) {
  struct stat st;
  if (::fstat(fd, &st) != 0) return from;
  const off_t hole = ::lseek(fd, static_cast<off_t>(from), SEEK_HOLE);
  if (hole < 0) return from;
  if (hole >= st.st_size && static_cast<std::uint64_t>(st.st_blocks) * 512 < static_cast<std::uint64_t>(st.st_size)) return from;
  return static_cast<std::uint64_t>(hole);
}

// The oldest snapshot any reader of the store holds, and the process holding it (LMDB's reader
// table, which mdb_reader_list prints as "pid thread txnid" lines, "-" for an idle slot); txnid
// ~0 when there is none.
struct OldestReader {
  std::uint64_t txnid = ~0ull;
  int pid = 0;
};
OldestReader oldest_reader(MDB_env* env) {
  OldestReader oldest;
  mdb_reader_list(
      env,
      [](const char* line, void* ctx) -> int {
        int pid = 0;
        std::size_t thread = 0;
        unsigned long long txnid = 0;
        if (std::sscanf(line, "%d %zx %llu", &pid, &thread, &txnid) == 3) {
          auto& least = *static_cast<OldestReader*>(ctx);
          if (txnid < least.txnid) least = {txnid, pid};
        }
        return 0;
      },
      &oldest);
  return oldest;
}

std::uint64_t oldest_reader_txnid(MDB_env* env) { return oldest_reader(env).txnid; }

// Why a store at its maximum may hold far less: a snapshot older than the last commits keeps
// every page freed since from being reused (LMDB), and the store filled with free pages (a
// `dump` stopped in a pipe, an agent that never ends its reads). Empty when no snapshot is.
std::string pinned_by_a_reader(MDB_env* env, std::uint64_t last_txnid) {
  const OldestReader oldest = oldest_reader(env);
  // A few commits behind is any busy reader; a read held over many is one that pins.
  constexpr std::uint64_t kPinningLag = 8;
  if (oldest.txnid == ~0ull || oldest.txnid + kPinningLag > last_txnid) return {};
  std::string who = "process " + std::to_string(oldest.pid);
  if (oldest.pid == getpid()) {
    who += " (this one)";
  } else if (std::ifstream comm("/proc/" + std::to_string(oldest.pid) + "/comm"); comm) {
    std::string name;
    if (std::getline(comm, name) && !name.empty()) who += " (" + name + ")";
  }
  return "; a snapshot that " + who + " has held for the last " + std::to_string(last_txnid - oldest.txnid) +
         " commits keeps the pages freed since from being reused (`tahvel stats` gives what the store holds): end that read";
}

// Bytes of the free pages a write transaction begun now may reuse.
std::uint64_t free_bytes_reusable(MDB_env* env, MDB_txn* txn) {
  MDB_envinfo info;
  MDB_stat stat;
  if (mdb_env_info(env, &info) != 0 || mdb_env_stat(env, &stat) != 0) return 0;
  // A write transaction takes the pages freed by transactions before every reader's snapshot
  // and before the last commit (whose pages the previous snapshot may still be reading).
  const std::uint64_t before = std::min<std::uint64_t>(oldest_reader_txnid(env), info.me_last_txnid);
  std::uint64_t free_pages = 0;
  MDB_cursor* cursor = nullptr;
  if (mdb_cursor_open(txn, 0, &cursor) != 0) return 0;
  MDB_val k, v;
  for (int rc = mdb_cursor_get(cursor, &k, &v, MDB_FIRST); rc == 0; rc = mdb_cursor_get(cursor, &k, &v, MDB_NEXT)) {
    std::size_t txnid = 0, count = 0;  // copied: LMDB aligns keys and values to 2 bytes only
    if (k.mv_size >= sizeof txnid) std::memcpy(&txnid, k.mv_data, sizeof txnid);
    if (txnid >= before) break;  // keys ascend
    if (v.mv_size >= sizeof count) std::memcpy(&count, v.mv_data, sizeof count);
    free_pages += count;
  }
  mdb_cursor_close(cursor);
  return free_pages * stat.ms_psize;
}

}  // namespace

std::uint64_t pages_in_use_bytes(MDB_env* env, MDB_txn* txn) {
  MDB_envinfo info;
  MDB_stat stat;
  if (mdb_env_info(env, &info) != 0 || mdb_env_stat(env, &stat) != 0) return 0;
  std::uint64_t free_pages = 0;
  MDB_cursor* cursor = nullptr;
  if (mdb_cursor_open(txn, 0, &cursor) == 0) {  // LMDB's free-page table (FREE_DBI)
    MDB_val k, v;
    // Each entry is a list of page numbers; its first word is the count (LMDB's IDL).
    for (int rc = mdb_cursor_get(cursor, &k, &v, MDB_FIRST); rc == 0; rc = mdb_cursor_get(cursor, &k, &v, MDB_NEXT)) {
      std::size_t count = 0;  // copied: LMDB aligns values to 2 bytes only
      if (v.mv_size >= sizeof count) std::memcpy(&count, v.mv_data, sizeof count);
      free_pages += count;
    }
    mdb_cursor_close(cursor);
  }
  const std::uint64_t pages = info.me_last_pgno + 1;
  return (pages - std::min<std::uint64_t>(free_pages, pages)) * stat.ms_psize;
}

bool Env::map_info(MDB_envinfo& info, MDB_stat& stat) {
  std::shared_lock lock(growth_mutex_);
  return mdb_env_info(env_, &info) == 0 && mdb_env_stat(env_, &stat) == 0;
}

Result<void> Env::from_below_refused(std::uint64_t in_use, bool map_end, const std::string& pinned) const {
  return fail(Errc::store_full, "store full: " + dir_.string() + ": " + std::to_string(in_use) + " bytes are in use " +
                                    (map_end ? "(up to its last page) " : "") + "of its maximum of " +
                                    std::to_string(settings_.max_map_bytes) + ", and items relayed from below leave the last " +
                                    std::to_string(kept_for_own_writers(settings_.max_map_bytes)) +
                                    " bytes of it to this node's own agents; they wait in the child's outbox" +
                                    (pinned.empty() ? ": remove records, the oldest first (tahvel remove --until T), and the backlog comes in"
                                                    : pinned));
}

Result<void> Env::check_reserve_untouched(std::uint64_t new_bytes, WriteKind kind) {
  MDB_envinfo info;
  MDB_stat stat;
  if (!map_info(info, stat)) return {};
  const bool into_reserve = info.me_mapsize > settings_.max_map_bytes;
  if (kind == WriteKind::from_below) {
    // Up to the last page in use first, which needs no read: within the room, free pages or not.
    const std::uint64_t kept = kept_for_own_writers(settings_.max_map_bytes);
    const std::uint64_t limit = settings_.max_map_bytes - kept -
                                (into_reserve ? std::min(removal_reserve(settings_.max_map_bytes), settings_.max_map_bytes - kept) : 0);
    if ((info.me_last_pgno + 1) * stat.ms_psize + new_bytes > limit) {
      // The free-page table is walked once per committed transaction: a store once near full
      // keeps its last page high for good, and every run from below, and each halving of one,
      // walked it again.
      std::uint64_t in_use = 0;
      {
        std::lock_guard lock(in_use_cache_mutex_);
        if (in_use_cache_txnid_ == info.me_last_txnid) in_use = in_use_cache_bytes_;
      }
      if (in_use == 0) {
        auto read = begin_read();
        if (!read) return {};
        in_use = pages_in_use_bytes(env_, *read);
        end_read(*read);
        std::lock_guard lock(in_use_cache_mutex_);
        in_use_cache_txnid_ = info.me_last_txnid;
        in_use_cache_bytes_ = in_use;
      }
      if (in_use + new_bytes > limit) return from_below_refused(in_use, false, {});
    }
  }
  if (!into_reserve) return {};
  // LMDB's free-page table can be read in a read transaction only (which also holds the map
  // in place while pages_in_use_bytes reads LMDB's meta pages).
  auto read = begin_read();
  if (!read) return {};
  const std::uint64_t in_use = pages_in_use_bytes(env_, *read);
  end_read(*read);
  // Copy on write needs pages besides those the data takes, and pages the last write freed are
  // not reusable by the next: as much as the reserve is left free for the removals' copies.
  const std::uint64_t reserve = removal_reserve(settings_.max_map_bytes);
  const std::uint64_t room = settings_.max_map_bytes > reserve ? settings_.max_map_bytes - reserve : 0;
  if (in_use + new_bytes <= room) return {};
  // Not "reached its maximum": the store may be nearly empty (a removal grew it into the reserve,
  // and what it freed is kept free for the next), and a smaller write may still fit.
  return fail(Errc::store_full, "store full: " + dir_.string() + ": this write may take up to " +
                                    std::to_string(new_bytes) + " bytes, and " + std::to_string(in_use) +
                                    " are in use of the " + std::to_string(room) + " that writes may fill (of its maximum of " +
                                    std::to_string(settings_.max_map_bytes) +
                                    " bytes, as much as a removal may need is kept free after one); " +
                                    (in_use < room ? "write less at a time, " : "") +
                                    "remove records, the oldest first (tahvel remove --until T): the maximum is the one the "
                                    "store was made with (tahvel init --max-map)");
}

Result<void> Env::reserve_disk(WriteKind kind, const WriteBound& bound) {
  if (read_only_) return unexpected(read_only_error());  // before every write, a removal's parts too
  const std::uint64_t new_bytes = bound.bytes;
  MDB_envinfo info;
  MDB_stat stat;
  if (!map_info(info, stat)) return {};
  const std::uint64_t page = stat.ms_psize;
  const std::uint64_t in_use = (info.me_last_pgno + 1) * page;
  const std::uint64_t reserved = disk_reserved_.load();
  const std::uint64_t ahead = kDiskAhead + new_bytes;
  if (std::min<std::uint64_t>(info.me_mapsize, in_use + ahead) <= reserved) return {};
  // A kDiskAhead more at a time: one fallocate (a filesystem transaction) per kDiskAhead of
  // growth, not one per write.
  const std::uint64_t want = std::min<std::uint64_t>(info.me_mapsize, in_use + ahead + kDiskAhead);
  int fd = -1;
  if (mdb_env_get_fd(env_, &fd) != 0) return {};
  // fallocate, not posix_fallocate: where the filesystem cannot, glibc's emulation writes a byte
  // into every block of the range. Blocks already allocated cost nothing, so a range from 0 is
  // as good as one from what this process reserved before.
  auto allocate = [&](std::uint64_t from, std::uint64_t to) {
    int rc = 0;
    do rc = fallocate(fd, 0, static_cast<off_t>(from), static_cast<off_t>(to - from)) == 0 ? 0 : errno;
    while (rc == EINTR);  // the agents' stop handlers do not restart system calls
    return rc;
  };
  const int rc = allocate(reserved, want);
  if (rc == 0) {
    disk_reserved_.store(want);
    disk_tight_.store(false);
    return {};
  }
  // Near a full disk the store goes on as long as a write's worth is there (kDiskLeast; a
  // removal, which frees space and mostly reuses pages, with less): allocated already, by this
  // process or another (a fresh `tahvel rm` on a full disk is how space is won back), or now.
  if (rc == ENOSPC) {
    const std::uint64_t least = (kind == WriteKind::removal ? (1u << 20) : kDiskLeast) + new_bytes;
    const std::uint64_t enough = std::min<std::uint64_t>(info.me_mapsize, in_use + least);
    if (enough <= reserved || allocate(0, enough) == 0) {
      disk_backed_.store(std::max(reserved, enough));
      disk_tight_.store(true);
      return {};
    }
  }
  if (rc == ENOSPC) {
    // Removals free pages inside the file, and LMDB reuses free pages before it takes new ones
    // at the end: without this a store emptied on a full disk took no write again until the
    // disk had room for it to grow (a probe). Single pages come from the free ones while any are
    // reusable; a long term's run of pages may still be taken at the end, where the blocks
    // allocated already must hold it (and 64 pages for the tables' paths, as a removal's part).
    // From free pages a write takes its rows' pages (bounded by four times its bytes: rows,
    // index entries, their branches) and its tables' paths (1 MB covers them many times over).
    // kDiskLeast here left a small store emptied on an 8 MB disk unwritable for good: its 3 MB of
    // free pages were never 4 (an exploratory run of session 74).
    const std::uint64_t least = (1u << 20) + (kind == WriteKind::removal ? new_bytes : 4 * new_bytes);
    const std::uint64_t backed = allocated_from(fd, in_use);
    const std::uint64_t free_bytes = reusable_free_bytes();
    if (free_bytes >= least && backed >= in_use + bound.large_term_bytes + 64 * page) {
      disk_backed_.store(std::max(reserved, backed));
      disk_tight_.store(true);
      return {};
    }
    const std::uint64_t needed = in_use + least;
    const std::uint64_t short_by = needed - std::min(backed, needed);
    const std::string why = free_bytes >= least
                                ? std::to_string(bound.large_term_bytes >> 10) + " KB of long terms, which need runs of pages the free ones may not have"
                                : std::to_string(free_bytes >> 20) + " MB of its pages are free for writes to reuse, less than this write may take";
    // The ways on that exist: an emptied store refused a load of 2,000 triples, telling to
    // remove records it did not hold, and took the same triples 500 at a time (an exploratory
    // run of session 84). Removing records helps a store that holds some; a smaller write, one
    // of several triples whose rows the free pages could hold were it a quarter of its size,
    // when only those pages are short (not the blocks for a long term's run of pages).
    std::uint64_t records = 1;  // unknown: as if some
    if (auto read = begin_read(); read) {
      if (auto counters = load_counters(*read, main); counters) records = counters->records;
      end_read(*read);
    }
    const bool smaller_fits = kind != WriteKind::removal && free_bytes < least && bound.triples > 1 &&
                              free_bytes >= (1u << 20) + new_bytes && backed >= in_use + bound.large_term_bytes + 64 * page;
    std::string ways = "free " + std::to_string(std::max<std::uint64_t>(1, (short_by + (1 << 20) - 1) >> 20)) + " MB on that disk";
    if (kind != WriteKind::removal && records > 0) ways += ", or remove records from the store,";
    if (smaller_fits) ways += std::string(records > 0 ? "" : ",") + " or write fewer triples at once (load --batch),";
    return fail(Errc::store_full, "store full: the disk holding " + dir_.string() + " has no room left for the store to grow: " + ways +
                                      " and write again (" + why + ")");
  }
  if (rc == EOPNOTSUPP || rc == ENOSYS || rc == EINVAL) {
    disk_reserved_.store(~0ull);  // this filesystem cannot: as before, without the reserve
    return {};
  }
  return fail(Errc::io, "reserving disk space for " + dir_.string() + ": " + std::strerror(rc));
}

std::uint64_t Env::reusable_free_bytes() {
  auto read = begin_read();
  if (!read) return 0;
  const std::uint64_t bytes = free_bytes_reusable(env_, *read);
  end_read(*read);
  return bytes;
}

Result<std::optional<DiskRoom>> Env::disk_room_for_removal(std::uint64_t need) {
  if (auto r = reserve_disk(WriteKind::removal, WriteBound{need, need}); !r) {
    // Not even that: what is allocated already is the room there is.
    if (r.error().code != Errc::store_full || need == 0) return unexpected(r.error());
    if (auto least = reserve_disk(WriteKind::removal, WriteBound{}); !least) return unexpected(least.error());
  }
  if (!disk_tight_.load()) return std::optional<DiskRoom>{};
  const std::uint64_t end = pages_end_bytes(), backed = disk_backed_.load();
  return std::optional<DiskRoom>{DiskRoom{backed > end ? backed - end : 0, reusable_free_bytes()}};
}

std::uint64_t Env::pages_end_bytes() {
  MDB_envinfo info;
  MDB_stat stat;
  if (!map_info(info, stat)) return 0;
  return (info.me_last_pgno + 1) * stat.ms_psize;
}

Error Env::read_only_error() const {
  return Error{Errc::io, "the store in " + dir_.string() + " is on a read-only filesystem: it can be read, not written"};
}

Result<void> Env::check_in_place(bool now_) {
  const std::int64_t now = std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now().time_since_epoch()).count();
  std::int64_t last = in_place_checked_ns_.load(std::memory_order_relaxed);
  // Once found gone, looked at every time (it may be moved back).
  if (!now_ && !out_of_place_.load(std::memory_order_relaxed) &&
      (now - last < 100'000'000 || !in_place_checked_ns_.compare_exchange_strong(last, now)))
    return {};
  mdb_filehandle_t fd = -1;
  struct stat open_file {}, at_path {};
  if (data_ino_ == 0 || mdb_env_get_fd(env_, &fd) != 0 || ::fstat(fd, &open_file) != 0) return {};
  const std::string path = (dir_ / "data.mdb").string();
  const bool deleted = open_file.st_nlink == 0;
  // The path against what it named at open (device and inode: a store of the same inode number
  // on another filesystem mounted over it is another store). A path that cannot be looked at for
  // another reason (permissions changed) is not called moved.
  const int looked = ::stat(path.c_str(), &at_path);
  const bool elsewhere = !deleted && (looked != 0 ? errno == ENOENT || errno == ENOTDIR
                                                  : at_path.st_dev != data_dev_ || at_path.st_ino != data_ino_);
  out_of_place_ = deleted || elsewhere;
  if (deleted && looked == 0)  // another file renamed over it: a restore, a copy put in its place
    return fail(Errc::io, path + " was replaced by another file while this process had the store open: what it writes now "
                                 "is lost; open the store again (a program under `tahvel up` is restarted)");
  if (deleted)
    return fail(Errc::io, path + " was deleted while this process had the store open: what it writes now is lost; open the "
                                 "store again (a program under `tahvel up` is restarted)");
  if (elsewhere)
    return fail(Errc::io, path + " is no longer the file this process opened (the store was moved or replaced while it ran): "
                                 "what it writes now is not in the store there; open the store again (a program under "
                                 "`tahvel up` is restarted)");
  return {};
}

Result<void> Env::write(const std::function<Result<void>(Txn&)>& body, WriteKind kind, WriteBound bound) {
  const std::uint64_t new_bytes = bound.bytes;
  bool dead_readers_cleared = false, freelist_turned = false;
  for (;;) {
    if (auto r = reserve_disk(kind, bound); !r) return r;
    if (kind != WriteKind::removal) {
      if (auto r = check_reserve_untouched(new_bytes, kind); !r) return r;
    }
    MDB_txn* raw = nullptr;
    if (auto r = begin(&raw, 0); !r) return r;
    Txn txn(*this, raw);
    txn.unflushed_index.swap(spare_index_);  // this thread is the process's one writer now
    std::uint64_t first_seq = 0;
    auto run = [&]() -> Result<void> {
      // With the writer lock held: a write that waited for it (behind a long load) while the
      // store was deleted is told so, not committed into the unlinked file.
      if (auto r = check_in_place(); !r) return r;
      auto counters = load_counters(raw, main);
      if (!counters) return unexpected(counters.error());
      txn.counters = *counters;
      first_seq = counters->next_seq;
      if (auto r = body(txn); !r) return r;
      if (auto r = deliver_removals(txn); !r) return r;
      if (auto r = flush_index(txn); !r) return r;
      if (txn.removals_trimmed_through != 0) {
        MDB_val k = val(kRemovalsTrimmedKey), v = val(txn.removals_trimmed_through);
        if (int rc = mdb_put(raw, meta, &k, &v, 0); rc != 0) return lmdb_fail(rc, "noting the removal log's trimmed end");
      }
      if (txn.reclaimed_through != 0) {
        MDB_val k = val(kReclaimedThroughKey), v;
        const bool noted = mdb_get(raw, meta, &k, &v) == 0 && v.mv_size == sizeof(std::uint64_t);
        if (!noted || u64(v) < txn.reclaimed_through) {
          v = val(txn.reclaimed_through);
          if (int rc = mdb_put(raw, meta, &k, &v, 0); rc != 0) return lmdb_fail(rc, "noting the records reclaimed");
        }
      }
      if (txn.notice_seqs_taken != 0) {
        const std::uint64_t taken = read_notice_seqs(raw, meta) + txn.notice_seqs_taken;
        MDB_val k = val(kNoticeSeqsKey), v = val(taken);
        if (int rc = mdb_put(raw, meta, &k, &v, 0); rc != 0) return lmdb_fail(rc, "counting the sequence numbers of removal notices");
      }
      return save_counters(raw, main, txn.counters);
    };
    writing.store(raw);
    auto result = run();
    writing.store(nullptr);
    // Handed back while this thread is still the writer (before the commit or abort).
    txn.unflushed_index.clear();
    if (txn.unflushed_index.capacity() <= kSpareIndexMax) spare_index_.swap(txn.unflushed_index);
    int rc = 0;
    auto end_txn = [&] {
      if (result) {
        rc = mdb_txn_commit(raw);
      } else {
        mdb_txn_abort(raw);
      }
    };
    if (txn.touched_caches) {
      // Held across the commit or abort: once LMDB's writer lock is free, another thread's
      // write must not find the cache at a generation this transaction reached but did not
      // store, which another process may have stored since, with other subscriptions.
      std::lock_guard lock(cache_mutex);
      end_txn();
      if (!result || rc != 0) subs_gen = ttl_gen = ~0ull;
    } else {
      end_txn();
    }
    active_txns_.fetch_sub(1);
    bool map_full = (!result && result.error().code == Errc::store_full) || rc == MDB_MAP_FULL;
    if (map_full) {
      // A reader that died holding its snapshot (SIGKILL, the OOM killer) leaves its slot, and
      // LMDB hands out no page freed after that snapshot while the slot stays: the map filled
      // with free pages it would not reuse, and a ring store's writers failed with store_full,
      // the store nearly empty. Slots of dead processes were cleared only when a process opened
      // the store; they are cleared here too, and the write tried again, before the map grows.
      int dead = 0;
      if (!dead_readers_cleared && mdb_reader_check(env_, &dead) == 0 && dead > 0) {
        dead_readers_cleared = true;
        continue;
      }
      if (auto g = grow(kind, kind == WriteKind::removal ? bound.large_term_bytes : 0); !g) {
        // LMDB reuses the pages a transaction freed from the second transaction after it on: the
        // first write after a large removal found none and the map at its maximum, the store
        // nearly empty. A small write in between makes them free (as between a removal's parts).
        if (kind == WriteKind::removal || freelist_turned) return g;
        freelist_turned = true;
        // Only where free pages would hold the write: a store truly full got a commit (an fsync
        // when durable) at every refused write.
        std::uint64_t in_use = settings_.max_map_bytes;
        if (auto read = begin_read()) {
          in_use = pages_in_use_bytes(env_, *read);
          end_read(*read);
        }
        if (in_use + new_bytes > settings_.max_map_bytes) return g;
        if (!write([](Txn&) -> Result<void> { return {}; }, WriteKind::removal)) return g;
      }
      continue;
    }
    if (!result) return result;
    if (rc != 0) return lmdb_fail(rc, "committing a write to " + dir_.string());
    // Wake first: a sleeping taker is the latency the node is measured by; the rest is
    // bookkeeping of this process.
    for (auto slot : txn.wake_slots) wake_.bump(slot);
    // Watchers follow the change stream: wake them only when it grew (not for acks, TTL rules
    // or prefixes).
    // Threads waiting for input buffers (a link's pump) wake only when one changed.
    if (txn.counters.next_seq != first_seq) wake_.bump_commit(!txn.wake_slots.empty());
    term_cache.publish(txn.staged_pinned, txn.staged_unpinned, TermCache::generation(txn.counters));
    prefault_ahead();
    return {};
  }
}

void Env::prefault_ahead() {
  if (prefault_off_.load(std::memory_order_relaxed) || settings_.durability == Durability::durable) return;
  MDB_envinfo info;
  MDB_stat stat;
  if (!map_info(info, stat) || stat.ms_psize == 0) return;
  const std::uint64_t page = stat.ms_psize;
  const std::uint64_t in_use = (info.me_last_pgno + 1) * page;
  const std::uint64_t moves = map_moves_.load();
  Prefaulter* p = prefaulter_.load();
  if (!p) {
    std::lock_guard start(prefaulter_start_mutex_);
    if (!(p = prefaulter_.load())) {
      auto made = std::make_unique<Prefaulter>();
      // Started with the program's stop signals blocked, which it inherits: taken by this
      // thread, they left a take() in the program's own thread waiting out its timeout instead
      // of returning at the signal (stop_signal.h).
      sigset_t stops, before;
      sigemptyset(&stops);
      sigaddset(&stops, SIGINT);
      sigaddset(&stops, SIGTERM);
      pthread_sigmask(SIG_BLOCK, &stops, &before);
      try {
        made->thread = std::thread([this, q = made.get()] { prefault_loop(*q); });
      } catch (const std::system_error&) {
        pthread_sigmask(SIG_SETMASK, &before, nullptr);
        prefault_off_.store(true);  // no thread to be had (a task limit): the writer faults as before
        return;
      }
      pthread_sigmask(SIG_SETMASK, &before, nullptr);
      p = made.release();
      prefaulter_.store(p);
    }
  }
  if (p->pid != getpid()) return;  // a forked child's copy
  {
    std::lock_guard lock(p->mu);
    if (p->moves_seen == moves && in_use + kPrefaultAhead / 2 <= p->ready.load()) return;
    // Never the pages in use: the writer faulted them in already, or another process wrote them
    // and this one may never read them. After the map moved, what was faulted in is gone.
    if (p->moves_seen != moves || p->ready.load() < in_use) p->ready.store(in_use);
    p->moves_seen = moves;
    // Within the blocks reserve_disk() allocated, where the filesystem can: a page of a hole
    // would take one of the disk. In whole pages: madvise takes nothing else.
    const std::uint64_t wanted = std::min({static_cast<std::uint64_t>(info.me_mapsize), disk_reserved_.load(), in_use + kPrefaultAhead});
    p->wanted = wanted / page * page;
  }
  p->cv.notify_one();
}

void Env::prefault_loop(Prefaulter& p) {
  pthread_setname_np(pthread_self(), "tv-prefault");
  setpriority(PRIO_PROCESS, static_cast<id_t>(gettid()), 19);  // Linux: this thread only
  constexpr std::uint64_t kChunk = 64 << 10;  // a short hold of growth_mutex_ at a time
  char* map_base = nullptr;
  std::uint64_t map_size = 0, map_seen_moves = ~0ull;
  int fd = -1;
  mdb_env_get_fd(env_, &fd);
  const std::filesystem::path data_file = dir_ / "data.mdb";
  std::unique_lock lock(p.mu);
  while (!p.stop) {
    const std::uint64_t from = p.ready.load();
    if (from >= p.wanted) {
      p.cv.wait(lock);
      continue;
    }
    const std::uint64_t to = std::min(p.wanted, from + kChunk);
    lock.unlock();
    int err = 0;
    {
      // Shared, as a transaction: the map is not moved meanwhile (grow() holds it exclusively).
      std::shared_lock map_lock(growth_mutex_);
      MDB_envinfo info;
      if (mdb_env_info(env_, &info) == 0 && to <= info.me_mapsize) {
        if (map_seen_moves != map_moves_.load() || map_size != info.me_mapsize) {
          map_base = find_map(fd, data_file, info.me_mapsize);
          map_size = info.me_mapsize;
          map_seen_moves = map_moves_.load();
        }
        if (!map_base) err = ENOSYS;
        else
          while (madvise(map_base + from, to - from, kMadvPopulateWrite) != 0 && (err = errno) == EINTR) err = 0;
      }
    }
    lock.lock();
    if (err == EINVAL || err == ENOSYS || err == EPERM) {
      prefault_off_.store(true);  // this kernel cannot, or the map is not found: as before
      return;
    }
    // Done, or failed at that range (beyond the file, no memory): not tried again until the
    // writer goes past it. (A writer that overtook this thread moved the mark beyond `to`.)
    if (p.ready.load() < to) p.ready.store(to);
  }
}

}  // namespace tahvel::node::detail
