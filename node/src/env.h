// One LMDB environment per node directory, shared by every Node/Agent/Snapshot object of this
// process (LMDB forbids opening the same environment twice in one process). Owns the named
// tables, the waking board, the transaction helpers that grow the map when it fills, and the
// per-process caches of slowly changing data (subscriptions, TTL rules).
#pragma once

#include <lmdb.h>
#include <sys/types.h>

#include <array>
#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <shared_mutex>
#include <string>
#include <string_view>
#include <thread>
#include <unordered_map>
#include <vector>

#include "tahvel/node/error.h"
#include "tahvel/node/node.h"
#include "wake.h"

namespace tahvel::node::detail {

inline constexpr std::uint32_t kFormatVersion = 4;
// A store of format 2 has no time index (and may lack the notices table), and one of format 3 no
// table of long terms: this build brings either up to format 4 at its first open, in one write
// transaction (Env::open), after which builds that read the format before refuse it (they would
// write items the time index does not list, or not find a long term).
inline constexpr std::uint32_t kOldestUpgradedFormatVersion = 2;
inline bool is_upgraded_format(std::uint32_t v) { return v >= kOldestUpgradedFormatVersion && v < kFormatVersion; }
// A term whose dictionary value is this long or longer (ECG samples, a long text) is kept in
// `long_terms`, apart from the short ones: removing old chunks then empties whole pages of it,
// where among short terms it left every page partly full, and LMDB frees no such page.
inline constexpr std::size_t kLongTermBytes = 256;

// Counters kept in one meta value so that a write touches one key for all of them.
struct Counters {
  std::uint64_t next_seq = 1;      // next record id / removal sequence number
  std::uint64_t next_term = 1;     // next dictionary id
  std::uint64_t next_blank = 1;    // next inline blank-node number
  std::uint64_t sub_gen = 0;       // bumped when subscriptions change
  std::uint64_t ttl_gen = 0;       // bumped when TTL rules change
  std::uint64_t records = 0;
  std::uint64_t persistent_records = 0;
  std::uint64_t items = 0;
  std::uint64_t ring_records = 0;  // non-persistent records (what the ring bounds)
  std::uint64_t reclaimed = 0;
  std::uint64_t pending = 0;       // entries in all input buffers
  std::uint64_t removals = 0;      // entries in the removal log
  std::uint64_t terms = 0;
  std::uint64_t subscriptions = 0;
  std::uint64_t ring_head = 0;     // items below this id are gone or persistent: the ring's scan
                                   // starts here
  // Added in format 3 (a format-2 store's counters end before it; load_counters reads them).
  std::uint64_t max_span = 0;      // ns: the longest Item::span ever stored, never lowered: a
                                   // time-range walk of by_time starts this much before its range
};

// Settings fixed at init.
// The store's identity in its meta table: random, made when the store is created (or first
// opened by a build that has ids), renewed by Node::renew_store_id.
inline constexpr std::string_view kStoreIdKey = "store_id";
// The last sequence number trimmed from the removal log (a u64), absent until the log is first
// trimmed. A key of its own, not a counter: builds that check the counters' size still open it.
inline constexpr std::string_view kRemovalsTrimmedKey = "removals_trimmed_through";
// The greatest record id the ring or a time-to-live reclaimed (they log no removal): Node::watch
// tells a reader whose bookmark is older that records it never read may be gone.
inline constexpr std::string_view kReclaimedThroughKey = "retention_reclaimed_through";
// How many sequence numbers removal notices have taken (a u64), absent until the first. A notice
// is neither a record nor a logged removal: a reader that accounts for every number between two
// snapshots (the reasoner's gap check) counts these too. A key of its own, like the one above.
inline constexpr std::string_view kNoticeSeqsKey = "notice_seqs";
std::string new_store_id();
// The stores a copy was made from, nearest first, space-separated (Node::copied_from): written
// whenever a store takes a new id because it is a copy (a backup, a file copy, a rollback a
// peer showed), absent in a store that was never one. A parent restored from a backup tells its
// children so by it (docs/protocol.md P6e). At most kMaxCopiedFrom ids are kept.
inline constexpr std::string_view kCopiedFromKey = "copied_from";
inline constexpr std::size_t kMaxCopiedFrom = 16;
// Gives the store of `txn` the new id `id`, its old one put first in kCopiedFromKey.
Result<void> renew_store_id_as_copy(MDB_txn* txn, MDB_dbi meta, const std::string& id);
// Which file the store's data last was, in its meta table: the data file's inode number and
// birth time (statx), recorded when the store is made and checked at every open that may
// write. A data file that is another file now was copied (`cp -a`, a restore from tar or
// rsync, a move to another disk): the copy goes on from the point it was copied at, which its
// peers may have passed, so it takes a new store id (docs/protocol.md P6a).
inline constexpr std::string_view kDataFileKey = "data_file";
// The identity kDataFileKey records of the data file in `dir` ("<inode>:<birth s>.<ns>", or
// "<inode>:-" where the filesystem keeps no birth time); empty when it cannot be read.
std::string data_file_identity(const std::filesystem::path& dir);
// Writes a new store id into the copy of a store in `dir` (Node::back_up's, not open anywhere):
// a store restored from it goes on from an earlier point than its peers know, and is another
// store to them (docs/protocol.md P6a). Leaves no lock file behind. Returns the id.
Result<std::string> renew_store_id_of_copy(const std::filesystem::path& dir);

struct Settings {
  std::string iri;
  Durability durability = Durability::fast;
  std::uint64_t ring = 0;
  std::uint64_t max_literal_bytes = 0;
  std::uint64_t max_map_bytes = 0;
};

struct Subscription {
  std::uint64_t item;    // the subscription's own item id
  std::uint64_t agent;   // term id of the subscriber's IRI
  std::uint64_t s, p, o; // term ids, 0 = any
  std::uint64_t context = 0; // term id of the item context it requires, 0 = any
  std::uint64_t source = 0;  // term id of the source IRI it requires (or one under it), 0 = any
  std::string source_iri;    // that IRI, for the "under it" test
  std::uint32_t slot = 0; // wake slot of the subscriber
};

struct TtlRule {
  std::uint64_t predicate;  // term id
  std::int64_t ttl_ns;
};

class Txn;

// `from_below`: items a child node relays up. They leave what kept_for_own_writers says of the
// maximum to this node's own writers: relayed into room a removal had just made, a sensor's
// backlog of raw ECG took all of it, and the agents that derive from it (R-peaks, RR, HRV) could
// not write, the store freed for nothing (an integrator's full home, session 87).
enum class WriteKind { data, from_below, removal };
// The part of a store's maximum `max` that items relayed from below leave free: a sixteenth, at
// most 64 MiB.
inline std::uint64_t kept_for_own_writers(std::uint64_t max) { return std::min<std::uint64_t>(max / 16, 64ull << 20); }

// An upper bound on the bytes of new pages a write transaction may add to the data file
// (write_bound, write.h), and the part of it in terms long enough for overflow pages: those
// need runs of consecutive pages, which the free pages may not have.
struct WriteBound {
  std::uint64_t bytes = 0;
  std::uint64_t large_term_bytes = 0;
  std::uint64_t triples = 0;  // what a smaller write would split (a store full says so)
  WriteBound& operator+=(const WriteBound& more) {
    bytes += more.bytes;
    large_term_bytes += more.large_term_bytes;
    triples += more.triples;
    return *this;
  }
};

// What a removal on a full disk may take (Env::disk_room_for_removal): the bytes the data file
// has allocated beyond its last page in use, which a long copy's run of pages may need, and the
// free pages inside the file that single pages are taken from first.
struct DiskRoom {
  std::uint64_t at_end = 0;
  std::uint64_t reusable = 0;
};

// A term's key in the write path's caches (term_key, dictionary.h) with its hash, computed once:
// one term is looked up in up to four of these maps (the transaction's ids, the process's pinned
// and unpinned caches, then remembered), and hashing the key at each was ~10% of a hospital's
// ingest.
struct TermKey {
  std::string text;
  std::size_t hash = 0;
  bool operator==(const TermKey& other) const noexcept { return hash == other.hash && text == other.text; }
};
struct TermKeyHash {
  std::size_t operator()(const TermKey& key) const noexcept { return key.hash; }
};
using TermIdMap = std::unordered_map<TermKey, std::uint64_t, TermKeyHash>;

// Dictionary ids this process has seen committed, so that the write path does not look the
// same writers, sources, predicates and classes up again in every transaction (each lookup is
// two B-tree searches, several microseconds when the caches are cold). Keys are the write
// path's term keys (write.cpp). Two kinds of entry:
//   pinned    terms that can never be collected (docs/record-model.md R16): valid for good.
//   unpinned  valid while no term has been collected since they were seen. The generation is
//             the number of terms ever collected, next_term - 1 - terms, which only collection
//             changes; any process that collects one changes it in the stored counters.
// Entries come only from committed transactions (Env::write publishes what a transaction
// staged after its commit): an aborted transaction's ids are handed out again.
class TermCache {
 public:
  static std::uint64_t generation(const Counters& c) { return c.next_term - 1 - c.terms; }
  // The id of `key`, or 0; unpinned entries only when `gen` is the cache's generation.
  // `*pinned` tells which kind the entry is.
  std::uint64_t find(const TermKey& key, std::uint64_t gen, bool* pinned);
  void publish(TermIdMap& pinned, TermIdMap& unpinned, std::uint64_t gen);

 private:
  static constexpr std::size_t kMaxEntries = 1 << 16;  // then it starts again: no unbounded growth
  std::mutex mu_;
  TermIdMap pinned_, unpinned_;
  std::uint64_t gen_ = 0;
};

// Decoded dictionary terms by id. An id is never handed out twice once committed (next_term
// only grows), so the term an id names in any committed state never changes: entries need no
// invalidation. Only terms read in a snapshot are added (a write transaction may see ids of
// its own that an abort would hand out again).
class DecodedTerms {
 public:
  bool find(std::uint64_t id, Term& out);
  void add(std::uint64_t id, const Term& term);

 private:
  static constexpr std::size_t kMaxEntries = 1 << 14;
  std::mutex mu_;
  std::unordered_map<std::uint64_t, Term> terms_;
};

// An index or output-buffer entry waiting in a write transaction (Txn::unflushed_index).
struct IndexEntry {
  MDB_dbi dbi;
  std::uint64_t key, value;
};

// Bytes of the store's file that hold data: its pages up to the last in use, less the free ones
// LMDB will reuse (read in `txn`, a read transaction: LMDB lets no write transaction read its
// free-page table). What a store "uses" of its maximum.
std::uint64_t pages_in_use_bytes(MDB_env* env, MDB_txn* txn);

class Env {
 public:
  // Opens (or with `init` creates) the environment of `dir`; shared per process. A new store is
  // made in a directory of its own inside `dir` and its data file moved into place only once
  // complete, without replacing one there: of two inits at once one gets `exists`, and an init
  // killed half-way leaves no store that can neither be opened nor made again.
  // `first_write`, with `init`: what the new store holds from its first moment (the node's
  // vocabulary), written before its data file is moved into place. A store whose first write
  // failed (no room to grow on a full disk) was left in place, and every later open failed on
  // what it lacked.
  using FirstWrite = std::function<Result<void>(Env&)>;
  static Result<std::shared_ptr<Env>> open(const std::filesystem::path& dir, const InitOptions* init,
                                           const FirstWrite& first_write = {});
  ~Env();

  MDB_env* raw() const { return env_; }
  const Settings& settings() const { return settings_; }
  const std::filesystem::path& dir() const { return dir_; }
  WakeBoard& wake() { return wake_; }
  // Whether the store was opened on a read-only filesystem: it is read as usual, and every
  // write fails with io naming the filesystem.
  bool read_only() const { return read_only_; }
  Error read_only_error() const;

  // Table handles.
  // `main` is LMDB's unnamed table, which every write touches anyway (it holds the other
  // tables' roots): the counters live there, so they cost no extra page per write.
  MDB_dbi main = 0, meta = 0, terms = 0, term_hash = 0, records = 0, items = 0;
  MDB_dbi idx_s = 0, idx_p = 0, idx_o = 0, inbox = 0, outbox = 0, removals = 0;
  // Removal notices waiting in input buffers (R21): id -> varint(buffers holding it), then the
  // removed records. Stores made before the table existed get it at their first open.
  MDB_dbi notices = 0;
  // The time index: time_key(asserted_at) -> item ids ascending (rows.h). Every item is in it,
  // removed with its item (retire_item). Format 3; a format-2 store gets it, filled, at its first
  // open.
  MDB_dbi by_time = 0;
  // Dictionary terms of kLongTermBytes or more (id -> value, as `terms`), format 4. A term of a
  // store made before stays in `terms`: a term is looked up in `terms` first, then here.
  MDB_dbi long_terms = 0;

  // Runs `body` in a write transaction and commits it. When the map fills, aborts, grows the
  // map (up to max_map_bytes) and runs `body` again from the start; past the maximum returns
  // store_full. Any error from `body` aborts: nothing is written. Removals may grow into a
  // reserve beyond the maximum, so that a full store can always be emptied.
  // `bound` bounds what `body` may add to the data file (write_bound, write.h): the disk
  // reserve covers it before the transaction starts. A removal's `bound.large_term_bytes` is
  // its largest record's copy into the removal log (see grow()).
  Result<void> write(const std::function<Result<void>(Txn&)>& body, WriteKind kind = WriteKind::data,
                     WriteBound bound = {});

  // On a disk that has filled (reserve_disk could not allocate its usual kDiskAhead ahead), the
  // room a removal has (DiskRoom): it must not take new pages beyond what the data file has
  // allocated, since a page beyond is SIGBUS, not an error. nullopt while the disk has room, and
  // where the filesystem cannot allocate ahead. Errors: store_full (not even a removal's least
  // is left), io.
  // `need`: what the next part may take beyond the last page in use; the file is allocated for
  // it, past the removal's usual 1 MB, when the disk has that much free (space freed since).
  Result<std::optional<DiskRoom>> disk_room_for_removal(std::uint64_t need = 0);
  // Whether the last write of this process found the disk full (went on within what the data
  // file had allocated, or the free pages inside it).
  bool disk_tight() const { return disk_tight_.load(); }
  // Bytes of the free pages inside the data file that a write transaction begun now may reuse:
  // those freed by transactions before every reader's snapshot and before the last commit.
  std::uint64_t reusable_free_bytes();
  // The data file's high-water mark: bytes up to its last page in use.
  std::uint64_t pages_end_bytes();

  // io when the data file this process has open is no longer DIR/data.mdb: deleted (`rm -rf`
  // of the store while it ran), or moved or replaced (a restore over it). What a write commits
  // there is lost, and nothing written by others reaches it. Looked at most every 100 ms (a
  // stat of the path and of the open file), or `now`; writes (once they hold the writer lock)
  // and take()'s waits call it, and open() before it hands out this environment again. A
  // process that changes its root or mount namespace after opening sees its stores as moved.
  Result<void> check_in_place(bool now = false);

  // Begins a read-only transaction (a snapshot), renewing an idle one when there is one. The
  // caller ends it with end_read().
  Result<MDB_txn*> begin_read();
  void end_read(MDB_txn* txn);

  // Per-process caches, refreshed when the stored generation differs from the cached one.
  std::mutex cache_mutex;
  std::uint64_t subs_gen = ~0ull;
  std::vector<Subscription> subs;
  // Indexes into `subs`: those with no context condition, and those with one by its term id.
  std::vector<std::uint32_t> subs_any_context;
  std::unordered_map<std::uint64_t, std::vector<std::uint32_t>> subs_by_context;
  std::uint64_t ttl_gen = ~0ull;
  std::vector<TtlRule> ttl_rules;
  // Agents that receive removal notices (R21, Agent::receive_removals): term ids of their IRIs.
  // Kept in the meta table beside the TTL rules, and reloaded with them (ttl_gen).
  std::vector<std::uint64_t> removal_receivers;  // sorted
  // Dictionary ids of the subscription vocabulary: interned and pinned at init, so fixed.
  struct Vocabulary {
    std::uint64_t subscriber = 0, subject = 0, predicate = 0, object = 0;
    // tv:context came with federation: stores made before have it only once a subscription
    // used it, so it is looked up when subscriptions are loaded (0 while absent).
    std::uint64_t context = 0;
  } vocab;
  // load_vocabulary fills `vocab` once per Env: every Node::open in the process shares this Env,
  // and writers read `vocab` in their transactions without a lock.
  std::mutex vocab_mutex;
  bool vocab_loaded = false;

  TermCache term_cache;
  mutable DecodedTerms decoded;
  // The write transaction in progress in this process (LMDB allows one at a time), so that a
  // reader of terms can tell a snapshot from the writer's own transaction.
  std::atomic<MDB_txn*> writing{nullptr};

 private:
  Env() = default;
  // Opens the environment of the directory `dir` (canonical), making its tables and settings
  // with `init`. open() calls it on the finished store, and with `init` on the new one.
  static Result<std::shared_ptr<Env>> open_at(const std::filesystem::path& dir, const InitOptions* init);
  // Makes a new store in a directory of its own in `dir`, then moves its data file into `dir`.
  static Result<void> make_store(const std::filesystem::path& dir, const InitOptions& init, const FirstWrite& first_write);
  Result<void> open_tables(MDB_txn* txn, bool create);
  // Opens the tables added since format 2; false (and nothing opened) when the store has not
  // got them yet and `create` is false.
  Result<bool> open_later_tables(MDB_txn* txn, bool create);
  // Grows the map, up to max_map_bytes, or for a removal into the reserve beyond it, and further
  // by twice `removal_copy_bytes`: the run of pages a record's copy into the removal log takes
  // (R17), which a record with a literal larger than the reserve would not find there.
  Result<void> grow(WriteKind kind, std::uint64_t removal_copy_bytes = 0);
  // mdb_env_info and mdb_env_stat under growth_mutex_ held shared: they read LMDB's meta pages,
  // inside the map, which another thread's grow() may be moving. (Within a transaction of this
  // process the map cannot move, and they may be called directly.)
  bool map_info(MDB_envinfo& info, MDB_stat& stat);
  // A data write in a map that a removal grew beyond the maximum (into the removals' reserve):
  // store_full when the pages in use, free ones not counted, and `new_bytes` would exceed the
  // maximum. Without it data filled the reserve, and then even removals were refused.
  // For a write from below (WriteKind::from_below): store_full too when the pages in use and
  // `new_bytes` would leave less than kept_for_own_writers within the room writes may fill.
  Result<void> check_reserve_untouched(std::uint64_t new_bytes, WriteKind kind);
  // The store_full of a write from below, `in_use` bytes in use (`map_end`: up to the last page,
  // the map at its limit); `pinned`: what pinned_by_a_reader says, said instead of the advice.
  Result<void> from_below_refused(std::uint64_t in_use, bool map_end, const std::string& pinned) const;
  // pages_in_use_bytes as of the transaction id it was read at (check_reserve_untouched).
  std::mutex in_use_cache_mutex_;
  std::uint64_t in_use_cache_txnid_ = 0, in_use_cache_bytes_ = 0;
  Result<void> begin(MDB_txn** txn, unsigned flags);
  // With MDB_WRITEMAP the data file is as large as the map but sparse: a page written where the
  // file has no block yet takes one from the filesystem, and on a full disk that is SIGBUS in
  // whichever process writes (the supervisor included), not an error. So before each write the
  // file's blocks are allocated (fallocate) up to kDiskAhead, plus what the transaction may add
  // (`new_bytes`), beyond the last page in use; a full disk is then a store_full error naming it
  // (a removal goes on within what is allocated). Filesystems without fallocate are left as they
  // were.
  // On a disk that is full, a data write goes on within the pages removals freed inside the
  // file when they hold it and the blocks allocated at the end hold its large terms.
  Result<void> reserve_disk(WriteKind kind, const WriteBound& bound);
  std::atomic<std::uint64_t> disk_reserved_{0};  // bytes of the file allocated by this process
  // Whether the last reserve_disk found the disk full (and went on within `disk_backed_`, the
  // bytes of the file known to have blocks).
  std::atomic<bool> disk_tight_{false};
  std::atomic<std::uint64_t> disk_backed_{0};

  // The pages a writer takes as the store grows are new to the process: the first write to each
  // is a page fault (4-5 us on a virtual machine, in runs of several per commit), on the thread
  // that writes, while its readers wait. A thread of low priority faults them in ahead instead
  // (madvise MADV_POPULATE_WRITE: page tables only, the pages' contents untouched, so pages
  // another process may be writing are safe). After each commit prefault_ahead() asks it for
  // kPrefaultAhead beyond the last page in use once less than half of that is ready. Started at
  // the first write; not for durable stores (every commit syncs the map, and a page faulted in
  // ahead would be written twice); off for good where the kernel has no MADV_POPULATE_WRITE
  // (before Linux 5.14), where the map is not found, or where the thread cannot be started (a
  // task limit): it only saves time, and a write never fails for it.
  static constexpr std::uint64_t kPrefaultAhead = 1 << 20;
  struct Prefaulter;
  void prefault_ahead();
  void prefault_loop(Prefaulter& p);
  // On the heap, and left alone by a child forked after the thread started: the child has no
  // such thread, and its condition variable and mutexes still count it (destroying them there
  // waited for ever).
  std::atomic<Prefaulter*> prefaulter_{nullptr};  // owned; set once, under prefaulter_start_mutex_
  std::mutex prefaulter_start_mutex_;
  std::atomic<bool> prefault_off_{false};
  std::atomic<std::uint64_t> map_moves_{0};  // mdb_env_set_mapsize calls: LMDB may remap

  // Read transactions reset after use, renewed by the next begin_read (a handful: one per
  // thread that reads at once is enough).
  static constexpr std::size_t kIdleReaders = 8;
  std::mutex idle_readers_mutex_;
  std::vector<MDB_txn*> idle_readers_;

  MDB_env* env_ = nullptr;
  bool read_only_ = false;
  std::atomic<std::int64_t> in_place_checked_ns_{0};  // steady clock, check_in_place()'s last look
  std::atomic<bool> out_of_place_{false};              // what check_in_place() last found
  dev_t data_dev_ = 0;                                 // DIR/data.mdb as opened (0: not known)
  ino_t data_ino_ = 0;
  dev_t lock_dev_ = 0;                                 // DIR/lock.mdb as opened
  ino_t lock_ino_ = 0;
  std::filesystem::path dir_;
  Settings settings_;
  WakeBoard wake_;
  // Starting a transaction holds it shared; changing the map size holds it exclusively, so no
  // thread of this process starts a transaction while LMDB remaps (mdb_env_set_mapsize needs
  // none active in the process).
  std::shared_mutex growth_mutex_;
  // The buffer of Txn::unflushed_index, handed from one write transaction of this process to
  // the next (LMDB runs one at a time): growing it anew was 3% of a relay. Not kept beyond
  // kSpareIndexMax entries, so one bulk load does not hold its size for ever.
  static constexpr std::size_t kSpareIndexMax = 1 << 16;
  std::vector<IndexEntry> spare_index_;
  // Waits, holding growth_mutex_ exclusively, until this process has no transaction active
  // (up to a second: other threads' reads are short). False when one stays open (a snapshot held).
  bool quiesce_locked();
  std::atomic<int> active_txns_{0};
};

// A write transaction with the helpers the write path needs.
class Txn {
 public:
  Txn(Env& env, MDB_txn* txn) : env_(env), txn_(txn) {}
  Env& env() { return env_; }
  MDB_txn* raw() { return txn_; }
  Counters counters;             // loaded before `body`, saved after it
  // The last sequence number this transaction trimmed from the removal log (0: none), kept in
  // `meta` (kRemovalsTrimmedKey) at the end of the transaction: Node::watch tells a reader whose
  // bookmark is older that it missed removals.
  std::uint64_t removals_trimmed_through = 0;
  // The greatest record id this transaction reclaimed (Removal::retention; 0: none), kept in
  // `meta` (kReclaimedThroughKey) at its end when greater than what is there.
  std::uint64_t reclaimed_through = 0;
  // Sequence numbers this transaction gave to removal notices, added to kNoticeSeqsKey at its end.
  std::uint64_t notice_seqs_taken = 0;
  std::uint64_t take_notice_seq() {
    ++notice_seqs_taken;
    return counters.next_seq++;
  }
  // A time-to-live scan stopped at its budget with records left to look at (apply_ttl):
  // Node::reclaim goes on with another pass even when this one reclaimed nothing.
  bool retention_unfinished = false;
  std::vector<std::uint32_t> wake_slots;  // woken after commit
  // While set (Agent::replace: removals, then the items that take their place), the terms the
  // removals leave unused are collected only once the items are in (deferred_terms): those the
  // items use again keep their ids. A supervisor rewriting its board every 5 s collected and
  // made anew each of its predicates, under a new id each time: a new entry per id in every
  // reader's decoded-term cache (+7 MB/h until the cache's cap). Its timestamps still change,
  // and each one collected moves the term cache's generation (TermCache).
  bool defer_term_collection = false;
  std::vector<std::uint64_t> deferred_terms;
  // Term ids looked up or created in this transaction (write.cpp), and whether the term is
  // known to be pinned (then a caller that pins it needs nothing more: the writer and source of
  // every item of a relayed run). Cleared whenever a term is collected, since a collected id
  // must not be handed out again.
  struct KnownTerm {
    std::uint64_t id = 0;
    bool pinned = false;
  };
  std::unordered_map<TermKey, KnownTerm, TermKeyHash> term_ids;
  // Ids to publish to the Env's TermCache once this transaction has committed (dictionary.cpp).
  TermIdMap staged_pinned, staged_unpinned;
  // Index and output-buffer entries of the items inserted since the last flush_index (rows.h),
  // in insertion order. They go in by key, all values of one key in one put: a batch of items
  // repeats predicates, classes and writers, and one put per entry was a fifth of an ingest.
  using IndexEntry = detail::IndexEntry;
  std::vector<IndexEntry> unflushed_index;
  // This transaction changed the Env's subscription or TTL cache (write.cpp): should it not
  // commit, the cache is marked stale, for its generation may be reached again by a different
  // change that does.
  bool touched_caches = false;
  // Removal notices this transaction makes (R21), one per item that loses records and was
  // routed to an agent that receives notices; deliver_removals (write.h) writes them before the
  // commit. The plan is made when the item's first record goes, while the item is whole: whom it
  // goes to, and its id, taken from the sequence then, so that a notice comes before the items
  // the same transaction stores after the removal (Agent::replace), as the removal did. Only the
  // records of planned notices are kept, with their terms read at removal (before the dictionary
  // may collect them).
  struct NoticePlan {
    std::uint64_t id = 0;
    std::vector<std::pair<std::uint64_t, std::uint32_t>> to;  // agent term ids and wake slots
    std::vector<Record> records;
  };
  std::vector<NoticePlan> notice_plans;
  // Item id -> its plan's index in notice_plans, or kNoNotice when the item goes to nobody.
  static constexpr std::size_t kNoNotice = ~std::size_t{0};
  std::unordered_map<std::uint64_t, std::size_t> notice_plan_of;
  std::optional<bool> removals_noticed;  // whether any agent receives notices (asked once)
  // When removals_noticed is set: the agents that receive them (Env::removal_receivers, sorted),
  // read with it, so that routing records which of them got an item (ItemRow::noticed) without
  // taking the cache lock again.
  std::vector<std::uint64_t> removal_receivers;
 private:
  Env& env_;
  MDB_txn* txn_;
};

// Error for an LMDB return code, naming the operation.
Error lmdb_error(int rc, std::string_view what);
inline Unexpected<Error> lmdb_fail(int rc, std::string_view what) { return {lmdb_error(rc, what)}; }

// Helpers over MDB_val.
inline MDB_val val(const void* data, std::size_t size) { return MDB_val{size, const_cast<void*>(data)}; }
inline MDB_val val(std::string_view s) { return val(s.data(), s.size()); }
inline MDB_val val(const std::uint64_t& v) { return val(&v, sizeof v); }
inline std::string_view view(const MDB_val& v) { return {static_cast<const char*>(v.mv_data), v.mv_size}; }
inline std::uint64_t u64(const MDB_val& v) {
  std::uint64_t x = 0;
  std::memcpy(&x, v.mv_data, v.mv_size < sizeof x ? v.mv_size : sizeof x);
  return x;
}

// An LMDB cursor closed when it goes out of scope: mdb_cursor_open(txn, dbi, &cursor.c).
struct Cursor {
  MDB_cursor* c = nullptr;
  Cursor() = default;
  Cursor(const Cursor&) = delete;
  Cursor& operator=(const Cursor&) = delete;
  ~Cursor() { if (c) mdb_cursor_close(c); }
};

Result<Counters> load_counters(MDB_txn* txn, MDB_dbi meta);
Result<void> save_counters(MDB_txn* txn, MDB_dbi meta, const Counters& c);
// kNoticeSeqsKey in the meta table; 0 when absent (no notice yet, or written by an older build).
std::uint64_t read_notice_seqs(MDB_txn* txn, MDB_dbi meta);

}  // namespace tahvel::node::detail
