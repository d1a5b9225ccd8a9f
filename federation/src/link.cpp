// The communication agent (link.h): child role, parent role and remote queries over any
// Transport. Protocol statements (Pn) are in docs/protocol.md.
//
// Threads: two receivers per transport (one takes and decodes frames, one applies them to the
// store; a small batch on an idle link the taker applies itself), one up-sender (child role), one
// down pump for all children (parent role), one timer (hello/heartbeat, child silence, answer
// resends). Each thread opens its own node::Node and agents (single-thread objects: a
// transport's two receivers share theirs, one at a time); shared state is under `mu`.
#include "tahvel/federation/link.h"

#include <fcntl.h>
#include <pthread.h>
#include <sys/file.h>
#include <sys/statvfs.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <condition_variable>
#include <charconv>
#include <cstring>
#include <deque>
#include <filesystem>
#include <iostream>
#include <limits>
#include <map>
#include <mutex>
#include <random>
#include <set>
#include <span>
#include <thread>
#include <unordered_map>
#include <utility>

#include "base64.h"
#include "children_hint.h"
#include "tahvel/uri/iri.h"
#include "tahvel/federation/wire.h"
#include "wire_common.h"

namespace tahvel::federation {
namespace {

using Clock = std::chrono::steady_clock;
using namespace std::chrono_literals;

constexpr std::uint16_t kFirstVersionWithSpans = 3;  // P3: version 2 had no item spans
constexpr std::size_t kAnswerChunkBytes = 48 * 1024;  // P14: fits LCM's datagram fragments well
constexpr std::size_t kAnswerWindow = 16;
constexpr std::size_t kAnswerPartMax = 1 << 20;  // base64 characters per literal of a chunk
// A node in the middle acknowledges a child's chunks at most this far beyond what its parent
// acknowledged, so that a fast child and a slow parent cost it a bounded buffer (P14).
constexpr std::size_t kAnswerRelayAhead = 2 * kAnswerWindow;
// An answer stream with no chunk and no acknowledgement for this long is forgotten (a parent or
// child that went away mid-answer; the origin gave up long before).
constexpr std::chrono::minutes kAnswerForgetAfter{10};
// P15: a node that has part of an answer and has heard nothing more from the child for this
// long sends its ack again; a child whose link restarted meanwhile answers link_restarted.
constexpr std::chrono::seconds kAnswerKeepalive{2};
// A query item still on the origin's board this long after its asker's timeout (tv:queryTimeout)
// belongs to an asker that died without removing it (SIGKILL): the link clears it (P18).
constexpr std::chrono::seconds kAskerGrace{2};
constexpr std::chrono::milliseconds kIdlePumpWait{250};  // the down pump with nothing to pace
// P6: an unanswered hello's gap doubles up to this, so that a parent slow to answer (its
// thousand children saying hello at once after it restarted) is not asked ever more often.
constexpr std::chrono::seconds kHelloGapMax{4};
// A batch of at most this many frames, taken while the applier is idle, is applied by the taker
// itself (one thread hand-off less on a quiet link); larger ones go to the applier, so that
// under load taking overlaps with the store transaction of the batch before.
constexpr std::size_t kInlineFrames = 8;
// How often at most the uplink removes from the outbox what the parent applied (up_loop).
constexpr auto kOutboxTrimEvery = std::chrono::milliseconds(50);
// P10c: what a store restored from a backup relays again for its own children comes under new
// seqs, but was asserted before the restore, on the clocks of the nodes below, which may run
// ahead of this one's by this much.
constexpr std::chrono::hours kRepeatClockAhead{1};

// P8: the ack of an item stream waits for this many items or LinkOptions::ack_delay, unless the
// sender asks for it (its window half full) or it signals a gap or a resend. On a quiet link an
// ack sent at once lands at the sender just as the next item is stored there, and the two store
// transactions and wake-ups contend (docs/bench.md); a busy one acks each run as before.
constexpr std::size_t kAckEvery = 256;
// How long a receiver in push mode holds a run whose last frame has not come (P9b).
constexpr std::chrono::milliseconds kRunWait{20};
// P12: a connected child's state is rewritten at least this often, so that its tv:lastSeen is
// never older than child_silence (3.5 s) while the child is heard (status prints its age).
constexpr std::int64_t kStateRefreshNs = 2'000'000'000;
// A gap between two of the timer's rounds longer than this is this process stalled, not its
// children silent (timer_loop).
constexpr std::chrono::seconds kOwnStall{1};
// The error code of P9a: an item passed over for good (frame seq = the item's seq).
constexpr std::string_view kItemRefused = "item_refused";
// P9b: the receiver could not store all of a run it was sent (its store full, an I/O error): at
// most a first part of it was applied, and the sender slows to a probe until the receiver's mark
// moves again.
constexpr std::string_view kCannotStore = "cannot_store";
// P12c: a child's link that stops on purpose says so to its parent (an error frame, seq 0, its
// store id as the origin), which takes the link as down at once rather than after child_silence.
constexpr std::string_view kLeaving = "leaving";
constexpr std::string_view kUplinkAgent = "uplink";
constexpr std::string_view kLinkAgent = "link";
constexpr std::string_view kDownStream = "down";

// Sends made on a transport's own thread in push mode, for the receive loop's taker thread to
// make (LinkOptions::push). Cyclone hands a frame to a reader in the same process inside the
// sender's dds_write and runs one listener call per reader at a time, so a send from within a
// listener call could come back to a reader whose call is under way on this very thread (a
// reply to a reply, between two links of one process) and wait for itself for ever; and a first
// send to a peer waits for discovery, which may need the thread it would block.
struct DeferredSends {
  std::mutex& mu;
  std::condition_variable& ready;
  std::vector<std::pair<Transport*, Frame>>& frames;
};
thread_local DeferredSends* t_deferred_sends = nullptr;

// Names the calling thread as `top -H`, `ps -L` and profilers show it (at most 15 bytes).
void name_thread(const char* name) { pthread_setname_np(pthread_self(), name); }

std::int64_t now_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

// The whole item of a delivery, as the sender's store holds it, with what travels of its
// metadata (P7).
wire::ItemBody item_of(const node::Delivery& delivery) {
  wire::ItemBody body;
  if (delivery.records.empty()) return body;
  const node::RecordMeta& meta = delivery.records.front().meta;
  body.source = meta.source;
  body.item.context = meta.context;
  body.item.persistent = meta.persistent;
  body.item.asserted_at = meta.asserted_at;
  body.item.span = meta.span;
  body.removal = delivery.removal;
  for (const auto& r : delivery.records) {
    body.item.triples.push_back(r.triple);
    if (delivery.removal) body.positions.push_back(static_cast<std::uint32_t>(r.meta.id - r.meta.item));
  }
  return body;
}

// uri::is_under(iri, ancestor) for one fixed ancestor, remembered per IRI. An up stream carries
// the items of a handful of sources, and normalising both IRIs again for each item cost ~6 µs of
// a link hop's ~130 (docs/bench.md, session 23).
class UnderAncestor {
 public:
  explicit UnderAncestor(std::string ancestor) : ancestor_(std::move(ancestor)) {}
  bool operator()(const std::string& iri) {
    if (auto it = known_.find(iri); it != known_.end()) return it->second;
    if (known_.size() >= kRemembered) known_.clear();  // a stream of ever new sources: start over
    return known_.emplace(iri, uri::is_under(iri, ancestor_)).first->second;
  }

 private:
  static constexpr std::size_t kRemembered = 4096;
  std::string ancestor_;
  std::unordered_map<std::string, bool> known_;
};

const node::Term* object_of(const std::vector<node::Record>& records, const std::string& predicate) {
  for (const auto& r : records)
    if (r.triple.p.kind == node::TermKind::iri && r.triple.p.value == predicate) return &r.triple.o;
  return nullptr;
}

std::optional<std::int64_t> integer_of(const std::vector<node::Record>& records, const std::string& predicate) {
  const node::Term* t = object_of(records, predicate);
  if (!t || t->kind != node::TermKind::literal) return std::nullopt;
  try {
    std::size_t used = 0;
    long long v = std::stoll(t->value, &used);
    if (used != t->value.size()) return std::nullopt;
    return v;
  } catch (...) {
    return std::nullopt;
  }
}

std::string query_key(std::string_view origin, std::uint64_t id) {
  return std::string(origin) + "#" + std::to_string(id);
}

// The child of `self` on the way to `target` (self + "/" + first segment), or empty.
std::string child_on_path(const std::string& self, const std::string& target) {
  if (target.size() <= self.size() + 1 || target.compare(0, self.size(), self) != 0 || target[self.size()] != '/')
    return {};
  std::size_t end = target.find_first_of("/#?", self.size() + 1);
  return target.substr(0, end);
}

// P11: a subtree address "<X>/*" that covers `node` (X is `node` or above it) reaches `node` as
// "<node>/*", so each hop forwards it to all of its own children; an address of a subtree
// further down stays as it is. Any other context is returned unchanged.
std::string subtree_for(const std::string& context, const std::string& node) {
  if (context.size() < 2 || !context.ends_with("/*")) return context;
  const std::string base = context.substr(0, context.size() - 2);
  return uri::is_under(node, base) ? node + "/*" : context;
}

// The kind of a reason a store gave for not storing, as P9b's logging tells reasons apart: its
// words before the first ": " ("store full"). The rest names figures that change at every turn
// of a store hovering at full ("this write may take up to 1297 bytes, and 905216 are in use…"),
// and each new figure was said as a new reason.
std::string_view reason_kind(std::string_view why) { return why.substr(0, why.find(": ")); }

// A child's down queue takes the items for the whole subtree (P11). A child new to the tree
// (added to the file, or accepted on its first hello) gets, when its queue first subscribes, the
// persistent ones written before it came: a setting for every node reaches a home deployed
// later, as one for the home alone waits in its queue (R18). The commands sent before it came
// are not its own.
constexpr node::SubscribeOptions kSubtreeSubscription{.earlier = true, .persistent_only = true};

}  // namespace

HelloGap next_hello_gap(std::chrono::nanoseconds before, std::chrono::nanoseconds heartbeat_every) {
  const std::chrono::nanoseconds first = std::min<std::chrono::nanoseconds>(heartbeat_every, 250ms);
  HelloGap gap;
  gap.base = before.count() <= 0 ? first : std::min<std::chrono::nanoseconds>(before * 2, std::max<std::chrono::nanoseconds>(first, kHelloGapMax));
  thread_local std::minstd_rand random(std::random_device{}());
  const std::int64_t quarter = gap.base.count() / 4;
  gap.wait = gap.base + std::chrono::nanoseconds(std::uniform_int_distribution<std::int64_t>(-quarter, quarter)(random));
  return gap;
}

std::vector<node::Pattern> default_forward_policy() {
  return {node::Pattern{.p = node::Term::iri("http://www.w3.org/ns/sosa/observedProperty"),
                        .o = node::Term::iri(std::string(vocab::kTv) + "HeartRateVariability")}};
}

// Two nodes with one IRI on one network (a second deployment of the same file, a copied store)
// take turns: each hello or welcome names the other's store, and their items mix under one IRI.
// A store id that changes once is a store made again; kFlips changes within kWindow are two
// stores alive at once. A frame from a store other than the registered one (a heartbeat, an ack)
// counts as a change: the registered store is alive, and so is that one. The conflict lasts
// `hold` after the last change (LinkOptions::conflict_hold).
class StoreFlips {
 public:
  // A store id as said: "id 07e11dc6…", or a store told by its tag only (describe_tag) as it is.
  static std::string named(const std::string& store) {
    return store.starts_with("the store of tag ") ? store : "id " + store;
  }
  void set_hold(Clock::duration hold) { hold_ = hold; }
  // A frame named `store`, where `before` was expected (empty: none yet). True when that makes a
  // conflict that was not one before. `twin_of`: this node's IRI when `store` is another store
  // of it, to which `who` sends too (the twin is this node, not the peer: two parents answer a
  // child, or a parent answers two children of one IRI).
  bool saw(const std::string& before, const std::string& store, const std::string& who, const std::string& twin_of = {}) {
    if (before.empty() || store.empty() || before == store) return false;  // no id: a peer from before ids
    const auto now = Clock::now();
    flips_.push_back(now);
    while (!flips_.empty() && now - flips_.front() > kWindow) flips_.pop_front();
    if (flips_.size() < kFlips) return false;
    const bool fresh = !active();
    said_ = (twin_of.empty() ? "two stores (" + named(before) + " and " + named(store) + ") take turns as " + who
                             : "two stores of <" + twin_of + "> are alive, and " + who + " sends to both (one is " + store + ")") +
            ": two nodes with one IRI on this network, such as a second deployment of the same file; this link "
            "does not link with it until " + std::to_string(std::chrono::duration_cast<std::chrono::seconds>(hold_).count()) +
            " s after the last sign of two";
    last_ = now;
    return fresh;
  }
  // Two stores were seen alive at once (P6b: a registered store heard after another said hello
  // under its IRI): a conflict now. True when it was not one before.
  bool declare(const std::string& registered, const std::string& other, const std::string& who) {
    flips_.assign(kFlips, Clock::now());
    const bool fresh = !active();
    said_ = "two stores (" + named(registered) + " and " + named(other) + ") are alive as " + who +
            ": two nodes with one IRI on this network, such as a second deployment of the same file; this link "
            "does not link with it until " + std::to_string(std::chrono::duration_cast<std::chrono::seconds>(hold_).count()) +
            " s after the last sign of two";
    last_ = Clock::now();
    return fresh;
  }
  bool active() const { return !said_.empty() && Clock::now() - last_ < hold_; }
  std::string said() const { return active() ? said_ : std::string(); }

 private:
  static constexpr std::size_t kFlips = 3;
  static constexpr auto kWindow = std::chrono::seconds(60);
  Clock::duration hold_ = std::chrono::minutes(2);
  std::deque<Clock::time_point> flips_;
  std::string said_;
  Clock::time_point last_{};
};

struct Link::Impl {
  LinkOptions opt;
  std::string self;
  // A shared lock on DIR/link.lock held while this link serves children: `remote_query` tells
  // "no link runs here" from a query that would time out (the lock goes with the process).
  int serving_lock = -1;
  ~Impl() {
    if (serving_lock >= 0) ::close(serving_lock);
  }
  std::atomic<bool> stopping{false};
  std::vector<std::thread> threads;
  // A run younger than child_silence has not yet heard every child that is up: those say hello
  // again within a heartbeat of hearing "unregistered" from it (P15, a query on the way down).
  const Clock::time_point run_started = Clock::now();

  mutable std::mutex mu;
  // With mu. `changed`: the up sender's session or window moved (a welcome, an ack). `board_due`:
  // the timer thread has board writes to make. Apart, so that the parent's acks (every 20 ms
  // under a stream) do not wake the timer thread for nothing on the path of the next item.
  std::condition_variable changed;
  std::condition_variable board_due;
  LinkCounters counters;

  // This node's store id (P6a): it names the streams of this store's items at the peers.
  std::string store_id;  // under mu
  // This run of the link (P12c): named in its hellos and its leaving notice, so that a parent
  // tells a late notice of the run before (the same store id) from one of the run it registered.
  const std::uint64_t run = [] {
    std::random_device seed;
    std::uint64_t token = 0;
    while (token == 0) token = (std::uint64_t{seed()} << 32) ^ seed();
    return token;
  }();
  std::optional<node::Node> own;  // this node's store, for its id and last seq; under own_mu
  std::mutex own_mu;  // a Node is used by one thread at a time; the receive loops both use it

  std::string current_store_id() {
    std::lock_guard lock(mu);
    return store_id;
  }
  // How full this store is, for the parent (wire::StoreRoom); none when it cannot be read.
  std::optional<wire::StoreRoom> store_room() {
    std::optional<wire::StoreRoom> room;
    {
      std::lock_guard own_lock(own_mu);
      auto stats = own->stats();
      if (!stats) return room;
      // Free space not known: said as all there is, not as none (which read as a full disk).
      room = wire::StoreRoom{stats->high_water_bytes, stats->used_bytes, stats->max_map_bytes, ~0ull};
    }
    if (struct statvfs disk {}; statvfs(opt.dir.c_str(), &disk) == 0)
      room->disk_free_bytes = static_cast<std::uint64_t>(disk.f_bavail) * disk.f_frsize;
    return room;
  }
  // The highest seq this store has issued (its item ids are below it); max on error, so that
  // nothing looks restored when the store cannot be read.
  std::uint64_t last_seq_here() {
    std::lock_guard own_lock(own_mu);
    auto stats = own->stats();
    return stats ? stats->last_seq : ~0ull;
  }
  // P6a: what a peer can have applied of this store's streams: items this store had issued
  // when this link started (earlier runs sent no more) and those this run has sent since. A
  // peer's mark above it knows a store that was here before: this one was restored from a
  // backup. Compared with the store's last seq instead, the agents' writes between the start
  // and the peer's welcome (seconds, with DDS discovery) could pass the mark and hide the
  // restore, and the peer would drop their items as duplicates.
  std::uint64_t seq_at_start = ~0ull;  // ~0 when it could not be read: nothing looks restored
  std::atomic<std::uint64_t> highest_sent{0};
  void note_sent(std::uint64_t seq) {
    for (std::uint64_t now = highest_sent.load(); seq > now && !highest_sent.compare_exchange_weak(now, seq);) {
    }
  }
  std::uint64_t issued_to_peers() const { return std::max(seq_at_start, highest_sent.load()); }
  // P6a: a peer has applied more of this store's stream than the store has issued, so this
  // store was restored from a backup (its ids go back in time). It takes a new id, so that its
  // streams start again at the peers, and every peer registers again to learn it.
  void renew_store_id(const std::string& why) {
    std::lock_guard own_lock(own_mu);
    auto id = own->renew_store_id();
    std::lock_guard lock(mu);
    if (!id) return log("cannot renew the store id (" + why + "): " + id.error().message);
    log("this store takes a new id " + *id + " (was " + store_id + "): " + why);
    store_id = *id;
    welcomed = false;  // says hello again, with the new id
    for (auto& [iri, child] : children) child->connected = false;  // they say hello again
  }

  // P6e: this node's store is a copy of another (Node::copied_from: restored from a backup),
  // and `other`, the store a child's hello names, is not it. Read when a hello asks: rare, and
  // both change only when the store takes a new id (renew_store_id, under own_mu too).
  bool store_is_a_copy(const std::string& other) {
    std::lock_guard own_lock(own_mu);
    auto id = own->store_id();
    auto lineage = own->copied_from();
    if (!id || !lineage) {
      log("cannot read which stores this one was copied from: " + (id ? lineage.error() : id.error()).message);
      return false;
    }
    return !lineage->empty() && other != *id;
  }

  // Child role (P5-P8).
  bool welcomed = false;
  // P12d: the parent said its link stops; cleared at the next welcome. Under mu.
  bool parent_left = false;
  // P12d: the run of the parent's link that last welcomed this node (0: a link before session
  // 81, which names none). Under mu.
  std::uint64_t parent_run = 0;
  // P6c: a welcome whose mark is 0; the up loop puts the persistent items its policy routes into
  // the outbox again. Under mu.
  bool resend_persistent = false;
  // P6d: a welcome with a mark above 0; the uplink puts back into its outbox what it took out
  // after that mark (a parent store restored from a backup acknowledged it, then lost it). P6e:
  // also a welcome with mark 0 from a copy, which says so.
  bool requeue_after_welcome = false;
  Clock::time_point last_welcome_at{};  // under mu
  static constexpr auto kStaleWelcome = std::chrono::seconds(2);
  // P6f: the last welcome said the parent's down queue held items for this node through this
  // seq (0: none); nothing goes up until they are applied here, or until down_hold_until (a
  // frame the parent cannot send, a store that cannot apply). Under mu.
  std::uint64_t down_hold_through = 0;
  Clock::time_point down_hold_until{};
  static constexpr auto kDownHoldMax = std::chrono::seconds(5);
  // The down stream the receive thread last relayed on and its mark after; a narrowing it found
  // is flagged (policy_narrowed) in the same locked section (P6f). Under mu.
  std::string down_applied_stream;
  std::uint64_t down_applied_mark = 0;
  // P6f: a removal from above took a subscription of the uplink; the up loop withdraws from the
  // outbox what the policy left no longer routes. Under mu.
  bool policy_narrowed = false;
  bool relaying_may_narrow = false;  // between mark_narrowing(true) and the relay's end; under mu
  // P6f: a file in the store while a down run that may narrow the policy is relayed and until
  // the withdrawal it calls for is done: a link stopped between the two withdraws at its next
  // start, since the removal is applied and nothing else would tell.
  std::filesystem::path narrowing_marker() const { return std::filesystem::path(opt.dir) / "uplink-policy-narrowed"; }
  void mark_narrowing(bool on) {
    std::error_code ec;
    if (on) {
      const int fd = ::open(narrowing_marker().c_str(), O_WRONLY | O_CREAT | O_CLOEXEC, 0644);
      if (fd >= 0) ::close(fd);
    } else {
      std::filesystem::remove(narrowing_marker(), ec);
    }
  }
  // P6e: the parent store whose welcome said it is a copy holding nothing of this store's
  // stream, until what the stores before had is back in the outbox. Its later welcomes do not
  // say so (this node's hello names it now): one not taken for a conflict (P6b) would otherwise
  // leave P6c in its place. Under mu.
  std::string copy_owed;
  std::string parent_store_id;  // from the welcome: names the down stream (P6a); under mu
  // The parent store an earlier run was welcomed by (its uplink state on the board), until the
  // first welcome of this run: the hello names it and carries this node's mark of its down
  // stream, so that a parent restored from a backup learns it went back in time even when this
  // node restarted too (P6a). Under mu.
  std::string parent_store_before;
  std::uint64_t up_mark = 0;       // the parent's mark of our stream: applied there
  std::uint64_t up_last_sent = 0;  // the seq of the last up frame sent
  std::uint64_t up_sent_highest = 0;  // of every up frame this run sent (a go-back goes below it)
  // When the parent's mark of this node's stream last moved (or the welcome), and the mark of an
  // ack refused as beyond what this store sent since: a stream the parent takes nothing of while
  // it is heard is this link's problem (say_problem). Under mu.
  Clock::time_point up_mark_moved_at{};
  std::uint64_t ack_beyond_seen = 0;
  std::deque<std::uint64_t> up_in_flight;
  Clock::time_point up_progress{};
  bool up_go_back = false;
  std::uint64_t up_went_back_to = ~0ull;
  Clock::time_point up_went_back_at{};
  // P8a: go-backs in a row after which the parent's mark has not moved. Each halves the window
  // and doubles the wait before the next; each ack that moves the mark takes one back. Under
  // mu. The mark at the last go-back tells whether one moved it.
  unsigned up_backoff = 0;
  std::uint64_t up_mark_at_go_back = ~0ull;
  static constexpr unsigned kMaxBackoff = 9;          // a window of 512 >> 9 = 1
  static constexpr unsigned kMaxResendDoublings = 4;  // resend_after x 16: 4.8 s by default

  std::chrono::milliseconds up_resend_after() const {
    return opt.resend_after * (1u << std::min(up_backoff, kMaxResendDoublings));
  }
  std::size_t up_window() const { return std::max<std::size_t>(1, opt.window >> std::min(up_backoff, kMaxBackoff)); }
  // P12a: this node's own view of its uplink, on its board.
  bool ever_welcomed = false;
  // Welcomed in an earlier run (this node's state on the board said "up" or "down"): a link
  // restarted while its parent is away is "down", with the time the parent was last heard, not
  // "never connected".
  bool welcomed_before = false;
  Clock::time_point parent_heard{};
  std::int64_t parent_heard_ns = 0;
  std::string refused_by_parent;  // the parent's refusal, until a welcome
  // P9b: why the parent could not store what this node sent, until its mark moves again.
  std::string parent_cannot_store;
  // P9b, as logged: a parent whose store is nearly full stores an item now and then between
  // refusals, and each turn took a pair of lines, two or three a second. A reason is said once
  // every 10 s (kRelayFailureSaidEvery), with the times it was not, and "stores again" once after it.
  struct CannotStoreSaid {
    std::string why;
    Clock::time_point at{};
    bool open = false;  // said, and "stores again" not said since
    std::uint64_t unsaid = 0;
  } parent_cannot_store_said;
  // P9b, at the receiving end: the last failure to store a sender's run, by sender, as logged.
  struct RelayFailure {
    std::string why;
    Clock::time_point said_at{}, sent_at{};
    std::uint64_t since_said = 0;
    bool stored_since_sent = false;  // a run of the sender stored since the last cannot_store sent
  };
  std::map<std::string, RelayFailure> relay_failures;
  // Items dropped as held already (P6c, P10c), by sender, as logged: a stream that repeats what
  // this store holds comes an item or two a run, and each run took a line. Said at once, then
  // every kRelayFailureSaidEvery with how many since.
  struct HeldAlreadySaid {
    Clock::time_point at{};
    std::uint64_t unsaid = 0, unsaid_recomputed = 0;
  };
  std::map<std::string, HeldAlreadySaid> held_already_said;  // under mu
  // The line that says `said`'s count for `sender`, which it resets. Caller holds mu.
  static std::string held_already_line(const std::string& sender, HeldAlreadySaid& said) {
    std::string line = "dropped " + std::to_string(said.unsaid) + " item(s) from <" + sender +
                       "> that this store holds already (sent again on a new stream: P6c, P10c)" +
                       (said.at == Clock::time_point{} ? "" : " since this was last said") +
                       (said.unsaid_recomputed > 0 ? "; " + std::to_string(said.unsaid_recomputed) +
                                                         " of them computed again with other triples, the one held of each name kept"
                                                   : std::string());
    said = {Clock::now(), 0, 0};
    return line;
  }
  // The counts of items dropped as held already that wait to be said: a burst that stops
  // within kRelayFailureSaidEvery of its last line would otherwise leave its rest unsaid; `all`
  // as the link stops. Caller holds mu.
  std::vector<std::string> held_already_due(Clock::time_point now, bool all = false) {
    std::vector<std::string> lines;
    for (auto it = held_already_said.begin(); it != held_already_said.end();) {
      if (!all && now - it->second.at < kRelayFailureSaidEvery) {
        ++it;
      } else if (it->second.unsaid > 0) {
        lines.push_back(held_already_line(it->first, it->second));
        ++it;
      } else {
        it = held_already_said.erase(it);  // quiet for a while: its next drop is said at once
      }
    }
    return lines;
  }
  // P9b from children: what was last logged of each and when, and whether that episode is
  // still open (the child has not stored since).
  struct CannotStore {
    std::string said;
    Clock::time_point at{};
    bool open = false;
  };
  std::map<std::string, CannotStore> child_cannot_store;
  static constexpr auto kRelayFailureSaidEvery = std::chrono::seconds(10);
  // P11a: the contexts of items applied from above, for the timer to see whom they address.
  std::vector<std::string> down_contexts;
  StoreFlips parent_flips;        // welcomes from two parents' stores in turn; under mu
  std::optional<Clock::time_point> acked_another_said;  // an ack for another store of this IRI, last logged; under mu
  Clock::time_point parent_store_heard{};  // last frame naming the welcoming parent's store
  std::string pending_parent_store;        // P6b: a welcome from another store while it lived
  Clock::time_point pending_parent_since{};
  std::string own_state_said;     // what the item on the board says now (rewritten on change)
  std::string own_state_logged;   // the uplink state the log last had ("up", "down", ...)
  std::int64_t own_state_written_ns = 0;

  // Parent role (P10-P12).
  struct Child {
    std::string id, iri;
    std::string store_id;  // from its hello: names its up stream (P6a); under mu
    // The store it registered with in an earlier run, from its state on the board, until its
    // first hello in this run (P10b); under mu.
    std::string store_before;
    bool connected = false;
    bool ever = false;          // connected in this run
    bool ever_before = false;   // connected in an earlier run (its state on the board said so)
    bool left = false;          // its link said it was stopping (P12c), and it has not said hello since
    std::uint64_t run = 0;  // the run its last hello named (P12c; 0: a link that names none)
    Clock::time_point hello_while_up_at{};  // a hello said while it was connected (a run of 0)
    std::string copy_said_for;  // the store its hello named when P6e was last logged; under mu
    Clock::time_point last_seen{};
    std::int64_t last_seen_ns = 0;
    std::string version;
    std::uint64_t outbox_depth = 0;
    std::optional<wire::StoreRoom> room;  // as its last hello or heartbeat said (version 5)
    std::uint64_t down_mark = 0, down_last_sent = 0;
    std::deque<std::uint64_t> down_in_flight;
    Clock::time_point down_progress{};
    bool down_go_back = false;
    std::uint64_t went_back_to = ~0ull;
    Clock::time_point went_back_at{};
    // The transport its last hello came on: a node may listen on more than one (LCM for the
    // sensors of its LAN, DDS for nodes further away), and everything for this child goes there.
    Transport* via = nullptr;
    StoreFlips flips;  // hellos from two stores in turn
    // P6b: a store that said hello while the registered one was alive, and since when; it is
    // registered once that one has been silent for child_silence.
    std::string pending_store;
    Clock::time_point pending_since{};
    std::string conflict_written;  // what its state item on the board says of a conflict
    bool pumped = false;      // handed to the down pump (at its first hello)
    bool board_set = false;   // its agent takes subtree items and removal notices (first hello)
    bool pump_dirty = false;  // the pump reads its queue again: a hello or an ack came
    bool state_dirty = true;
    std::int64_t state_written_ns = 0;
  };
  std::map<std::string, std::shared_ptr<Child>> children;  // by IRI
  // Child IRI -> the store it registered with, as the board said at start (P10b); read-only after.
  std::map<std::string, std::string> stores_before;
  // P17 for the state body of a hello, welcome, heartbeat or item-stream ack: into `state`;
  // none for an empty body (a peer from before state bodies, whose store ids are empty, P6b).
  // False, logged, when the body does not decode: the frame is dropped. It was read as a peer
  // without store ids, so that a cut-short hello made the child's items a new stream, applied
  // again.
  // Not with `mu` held: a malformed body is said through refuse(), which takes it.
  bool read_state(const Frame& f, std::optional<wire::StateBody>& state) {
    state.reset();
    if (f.body.empty()) return true;
    auto decoded = wire::decode_state(f.body, f.version);
    if (!decoded) {
      dropped_malformed(f, "dropped a malformed " + frame_kind_name(f.kind) + " frame from <" + f.from + ">: " + decoded.error().message);
      return false;
    }
    state = std::move(*decoded);
    return true;
  }

  std::string ack_beyond_issued(std::uint64_t mark) const {
    return "it acknowledges up to " + std::to_string(mark) + ", and this store has sent no item past " +
           std::to_string(issued_to_peers());
  }

  struct Refusal {
    // When each reason was last logged: a few reasons per sender, so that two taking turns
    // (a malformed hello, a malformed heartbeat) are each said once a minute, not at each turn.
    std::map<std::string, Clock::time_point> logged;
    Clock::time_point answered{};  // when the sender was last told
    std::uint64_t unsaid = 0;      // the sender's refusals since its line before, not logged
  };
  static constexpr std::size_t kReasonsKeptPerSender = 8;
  std::map<std::string, Refusal> refusals;  // by sender (refuse())
  // Hellos refused from would-be children (a node whose id the file here lacks, an IRI outside
  // this subtree): by sender, why and when last, until it is welcomed or stops trying.
  struct RefusedHello {
    std::string why;
    Clock::time_point last;
  };
  std::map<std::string, RefusedHello> refused_hellos;
  static constexpr std::size_t kRefusedHellosShown = 8;
  static constexpr std::chrono::minutes kRefusedHelloShownFor{10};
  static constexpr std::size_t kRefusalsKept = 4096;
  static constexpr int kRefusalAnswersPerSecond = 20;
  Clock::time_point refusal_answers_since{};  // the second refusal_answers counts in
  int refusal_answers = 0;
  // Refusal lines, over all senders (made-up ones are many): at most kRefusalLinesPerWindow per
  // kRefusalLogWindow; those left out are counted and the count said with the next line.
  static constexpr int kRefusalLinesPerWindow = 10;
  static constexpr auto kRefusalLogWindow = std::chrono::seconds(10);
  Clock::time_point refusal_lines_since{};
  int refusal_lines = 0;
  std::uint64_t refusal_lines_left_out = 0;

  // Stream names (P6a): a child's items by its IRI and store id; what comes down by the parent's
  // store id. Without an id (a peer from before store ids): the names used then.
  static std::string up_stream(const std::string& child_iri, const std::string& child_store) {
    return child_store.empty() ? child_iri : child_iri + "#" + child_store;
  }
  std::string down_stream() const {  // under mu
    return parent_store_id.empty() ? std::string(kDownStream) : std::string(kDownStream) + "#" + parent_store_id;
  }

  // The tag bits of a frame from store `from` to store `to`.
  static std::uint64_t store_tags(const std::string& from, const std::string& to) {
    return (store_tag(from) << kStoreTagShift) | (store_tag(to) << kPeerStoreTagShift);
  }
  static std::string seconds_text(Clock::duration d) {
    char text[32];
    std::snprintf(text, sizeof text, "%.1f s", std::chrono::duration<double>(d).count());
    return text;
  }
  // P6b: a registered store heard this long after another said hello (or welcomed) under its
  // IRI is alive beside it (frames of a store that stopped arrive within milliseconds).
  static constexpr auto kBothAlive = std::chrono::seconds(1);
  // P6b: a frame names a store (`got`) other than the one registered for its sender
  // (`expected`). Either empty: a peer from before store ids, or none registered yet.
  static bool store_differs(const std::string& expected, const std::string& got) {
    return !expected.empty() && !got.empty() && expected != got;
  }
  // Caller holds mu. An item-stream ack to `to` of the stream of `to`'s store `peer_store`
  // (empty: not known), its body naming both stores (P6b): a second node under the same IRI
  // takes it for no ack of its own, and a second node under this one's IRI is seen by its store.
  Frame stream_ack(const std::string& to, const std::string& peer_store) const {
    Frame ack;
    ack.kind = FrameKind::ack;
    ack.to = to;
    ack.body = wire::encode_state({"", 0, store_id, peer_store});
    return ack;
  }
  // A store known by the tag its frames carry only, as StoreFlips names the two stores: "the
  // store of tag 9e9446, which sent …". Up to session 73 the text went in where an id goes:
  // "two stores (ids 07e11dc6 and (to another store of this node's IRI, tag 9e9446))".
  static std::string describe_tag(const char* after, std::uint64_t tag) {
    char text[120];
    std::snprintf(text, sizeof text, "the store of tag %06llx%s%s", static_cast<unsigned long long>(tag), *after ? ", " : "", after);
    return text;
  }
  // P6b: up or down frames came from, or went to, a store of the peer's or this node's IRI other
  // than the registered one (`other` says which; `to_twin`: went to another store of this node's
  // IRI): from the child `child`, or from the parent when null. Two stores are alive under one IRI.
  void other_store_sent(Child* child, const std::string& other, bool to_twin) {
    std::lock_guard lock(mu);
    ++counters.refused;
    const std::string twin_of = to_twin ? self : std::string();
    if (child) {
      if (child->flips.saw(child->store_id, other, "the child <" + child->iri + ">", twin_of)) log("conflict: " + child->flips.said());
      if (child->flips.active()) disconnect_for_conflict(*child);
    } else {
      if (parent_flips.saw(parent_store_id, other, "the parent <" + opt.parent_iri + ">", twin_of)) log("conflict: " + parent_flips.said());
      if (parent_flips.active() && welcomed) {
        log("the parent is not linked with while the conflict lasts");
        welcomed = false;
      }
    }
  }
  // Caller holds mu. P6b: a child under which two stores take turns is not linked with (its
  // frames are refused) until the conflict has passed.
  void disconnect_for_conflict(Child& child) {
    if (child.connected) log("child <" + child.iri + "> is not linked with while the conflict lasts");
    child.connected = false;
    child.state_dirty = true;
  }

  // Queries (P13-P16).
  // What the answerer still has to read for a query answered on this node (P14).
  struct Reading {
    wire::QueryBody q;
    std::uint64_t id = 0;          // the query's id (frames' seq)
    bool started = false;
    std::uint64_t horizon = 0;     // the store's last seq when reading began: nothing later is read
    std::uint64_t cursor = 0;      // id of the last match read (paged reading)
    std::uint64_t taken = 0;       // records put into chunks so far (for q.limit)
    std::vector<node::Record> whole;  // read at once (cascade or area), taken from the front
    std::size_t next_of_whole = 0;
    wire::AnswerBody chunk;        // the chunk being filled
    std::size_t chunk_bytes = 0;
    bool done = false;             // the last chunk is made
  };
  struct OutStream {  // answer chunks this node sends towards the origin
    std::string origin;
    std::uint64_t query = 0;
    std::deque<Frame> unacked;
    std::uint64_t next_chunk = 1;
    std::uint64_t sent_through = 0;   // the highest chunk sent so far
    std::uint64_t acked_through = 0;  // the highest chunk the parent acknowledged
    std::shared_ptr<Reading> reading;  // answered here and not all read yet
    // Relayed from a child whose last chunk has not come yet: kept while empty, so that the
    // child's next chunks continue its numbering instead of starting a new stream at 1.
    bool relaying = false;
    Clock::time_point last_send{}, last_progress{};
  };
  struct InStream {  // answer chunks this node receives from a child
    bool forward_up = false;
    std::string child;
    std::string target;  // the node asked, the child or one below it: named in errors (P15)
    std::string reply_to;
    std::uint64_t expected = 1;
    // Chunks passed on: acknowledged by the parent, or at the origin taken off the board by the
    // asking agent (a consumer slower than the link must hold the child back, not fill the store).
    std::uint64_t passed = 0;
    std::deque<std::pair<std::uint64_t, std::uint64_t>> unread;  // at the origin: (chunk, item id)
    bool done = false;
    bool cancelled = false;  // P18: the child's chunks are answered with a cancel, not taken
    Frame query_frame;  // resent until the first chunk or error arrives
    Clock::time_point expires = Clock::time_point::max();  // at the origin: asker's timeout + kAskerGrace
    Clock::time_point sent{};
    Clock::time_point last_progress{};
    Clock::time_point last_keepalive{};  // P15: the ack sent again to a child that went quiet
    int resends = 0;
  };
  std::map<std::string, OutStream> out_answers;
  std::map<std::string, InStream> in_answers;
  struct BoardWrite {  // an answer chunk or error to write on the board at the origin
    std::string key, reply_to;
    Frame frame;
  };
  std::deque<BoardWrite> board_writes;

  // Lines name IRIs and messages that came from the wire: each is made one line (wire::one_line).
  void log(const std::string& line) const {
    const std::string safe = wire::one_line(line);
    if (opt.log) opt.log(safe);
    else std::cerr << "tahvel link <" << self << ">: " << safe << "\n";
  }

  // Children heard speaking an earlier protocol version (P3), by IRI, and whether there are any:
  // they are spoken to in their version. Its own lock: send() runs without `mu`.
  std::mutex older_children_mu;
  std::unordered_map<std::string, std::uint16_t> older_children;
  std::atomic<bool> older_children_heard{false};

  // From a child's own frames (hello, heartbeat, up; not what it relays from below), also of
  // one not accepted, which is told why in its version; at most kOlderChildrenKept of those, so
  // that made-up senders cannot fill the table: an `accepted` child of a configured list is
  // always kept (without a list any IRI below is accepted, and counts against the bound).
  static constexpr std::size_t kOlderChildrenKept = 4096;
  std::size_t older_strangers_said = 0;  // under older_children_mu
  static constexpr std::size_t kOlderStrangersSaid = 8;
  void note_child_version(const std::string& iri, std::uint16_t version, bool accepted) {
    accepted = accepted && !opt.children.empty();
    if (version == kProtocolVersion && !older_children_heard.load(std::memory_order_relaxed)) return;
    std::lock_guard lock(older_children_mu);
    if (version == kProtocolVersion) {
      if (older_children.erase(iri) > 0 && accepted)
        log("child <" + iri + "> speaks protocol version " + std::to_string(version) + " again: spoken to in it");
    } else if (auto it = older_children.find(iri); it != older_children.end()) {
      it->second = version;
    } else if (accepted || older_children.size() < kOlderChildrenKept) {
      older_children.emplace(iri, version);
      // Senders this node does not take as children are refused on their own budget (P4): of
      // them only the first few are said here, else a flood of made-up senders wrote 4,096
      // lines (0.8 MB) in a second.
      if (accepted || ++older_strangers_said <= kOlderStrangersSaid)
        log("child <" + iri + "> speaks protocol version " + std::to_string(version) + ", this node " +
            std::to_string(kProtocolVersion) + ": spoken to in " + std::to_string(version) +
            (version < kFirstVersionWithSpans ? " (items sent down go without their span)" : "") +
            (!accepted && older_strangers_said == kOlderStrangersSaid
                 ? "; further senders of older versions that are not configured children are not logged"
                 : ""));
    }
    older_children_heard = !older_children.empty();
  }

  // `frame`, for a child of an earlier version, in that version: an item sent down to a child of
  // version 2 without its span (it has none, and would refuse the flag).
  void speak_as_older_child(Frame& frame) {
    {
      std::lock_guard lock(older_children_mu);
      auto it = older_children.find(frame.to);
      if (it == older_children.end()) return;
      frame.version = it->second;
    }
    if (frame.kind == FrameKind::query) {
      // Before version 4 a query has no source nor under: one with either never comes here
      // (unservable_by), so the layout is all that changes.
      if (auto q = wire::decode_query(frame.body))
        if (auto older = wire::encode_query(*q, frame.version)) frame.body = std::move(*older);
      return;
    }
    if (frame.kind != FrameKind::down || frame.version >= kFirstVersionWithSpans) return;
    if (auto item = wire::decode_item(frame.body); item && item->item.span != 0) {
      item->item.span = 0;
      frame.body = wire::encode_item(*item);
    }
  }

  // The protocol version the child `iri` is spoken to in.
  std::uint16_t version_of_child(const std::string& iri) {
    if (!older_children_heard.load(std::memory_order_relaxed)) return kProtocolVersion;
    std::lock_guard lock(older_children_mu);
    auto it = older_children.find(iri);
    return it == older_children.end() ? kProtocolVersion : it->second;
  }

  // Why the child `iri` on the way to a query's target cannot carry it (P3), if it cannot: a
  // query by source or by subject to a child of a version without them would come back as a
  // query without them, and the asker would take the whole node's records for the ones asked.
  std::optional<std::string> unservable_by(const std::string& iri, const wire::QueryBody& q) {
    if (q.source.empty() && q.under.empty()) return std::nullopt;
    const std::uint16_t version = version_of_child(iri);
    if (version >= 4) return std::nullopt;
    const std::string who = iri == q.target ? "<" + iri + ">" : "<" + iri + "> (on the way to <" + q.target + ">)";
    return who + " speaks protocol version " + std::to_string(version) +
           ", which has no query by source or by subject (--source, --under): upgrade it, or ask without them";
  }

  // Whether frames arriving on `via` come from children (a transport this node listens on).
  bool is_down(const Transport* via) const {
    if (!via) return false;
    if (via == opt.down.get()) return true;
    return std::any_of(opt.also_down.begin(), opt.also_down.end(), [&](const auto& t) { return t.get() == via; });
  }
  // The transport that reaches the child `iri`; under mu.
  Transport* via_to(const std::string& iri) const {
    auto it = children.find(iri);
    if (it != children.end() && it->second->via) return it->second->via;
    return opt.down.get();
  }

  // False when the frame certainly did not leave (logged). A binding may block in send (a DDS
  // writer whose reader stopped taking waits up to 1 s), so nothing is sent with `mu` held: a
  // stalled parent must not stop this node from serving its children, nor a stalled child the
  // others.
  bool send(Transport* via, Frame frame) {
    if (!via) return false;
    frame.from = self;
    if (DeferredSends* later = t_deferred_sends) {
      std::lock_guard lock(later->mu);
      later->frames.emplace_back(via, std::move(frame));
      later->ready.notify_all();
      return true;
    }
    // In this node's version, or in an older child's (P3), decided as it leaves: a frame relayed
    // from below (an error, an answer) keeps no version of its sender's.
    frame.version = kProtocolVersion;
    if (older_children_heard.load(std::memory_order_relaxed)) speak_as_older_child(frame);
    if (auto sent = via->send(frame); !sent) {
      log("send to <" + frame.to + "> failed: " + sent.error().message);
      return false;
    }
    return true;
  }

  // Sends `frames` in order, with `mu` not held, and stops at the first that did not leave: the
  // rest stay in flight in the stream's bookkeeping and go again at the next go-back (P8), so a
  // blocked binding costs one wait per round, not one per frame.
  void send_run(Transport* via, std::vector<Frame>& frames) {
    for (Frame& f : frames)
      if (!send(via, std::move(f))) break;
  }

  // Frames decided while `mu` is held (acknowledgements, answer chunks, queries, errors), sent by
  // send_all() once it is released, for the reason given at send().
  struct Outgoing {
    std::vector<std::pair<Transport*, Frame>> frames;
    void add(Transport* via, Frame f) {
      if (via) frames.emplace_back(via, std::move(f));
    }
    void error(Transport* via, const std::string& to, std::uint64_t seq, const wire::ErrorBody& body,
               bool may_find_nobody = false) {
      Frame f;
      f.kind = FrameKind::error;
      f.to = to;
      f.seq = seq;
      f.body = wire::encode_error(body);
      f.may_find_nobody = may_find_nobody;
      add(via, std::move(f));
    }
  };

  // Sends in order, with `mu` not held. After a frame that did not leave, the later ones to the
  // same peer on the same binding are skipped, as in send_run (a stalled peer costs one wait,
  // and the others still get theirs): answer chunks go again from the resend timer, a query from
  // the parent's, and acknowledgements and errors answer the peer's next resend.
  void send_all(Outgoing& out) {
    std::vector<std::pair<Transport*, std::string>> failed;
    for (auto& [via, f] : out.frames) {
      std::pair<Transport*, std::string> peer{via, f.to};
      if (std::find(failed.begin(), failed.end(), peer) != failed.end()) continue;
      if (!send(via, std::move(f))) failed.push_back(std::move(peer));
    }
    out.frames.clear();
  }

  void send_error(Transport* via, const std::string& to, std::uint64_t seq, const wire::ErrorBody& body,
                  bool may_find_nobody = false) {
    Outgoing out;
    out.error(via, to, seq, body, may_find_nobody);
    send_all(out);
  }

  // ---- receiving ----------------------------------------------------------------------------

  // Frames taken off a transport, with the bodies of item frames already decoded.
  struct ReceivedBatch {
    std::vector<Frame> frames;
    std::vector<std::optional<node::Result<wire::ItemBody>>> items;  // set for up and down frames
    std::vector<std::vector<node::RelayedItem>> applied;  // the items relayed, kept to be freed
  };

  // The acks of item streams held back (P8), by peer. Shared by the thread applying a batch,
  // which holds or sends them, and the taker, which sends those due while it waits for frames.
  class HeldAcks {
   public:
    explicit HeldAcks(std::chrono::milliseconds delay) : delay_(delay) {}
    // Holds `ack` for `items` more items of the peer's stream, unless `now`, kAckEvery items are
    // held or an older one is due; returns the ack to send at once, if any.
    std::optional<Frame> hold(Frame ack, std::size_t items, bool now) {
      std::lock_guard lock(mu_);
      auto it = held_.find(ack.to);
      if (it != held_.end()) {
        items += it->second.items;
        if (Clock::now() >= it->second.due) now = true;
      }
      if (now || items >= kAckEvery) {
        if (it != held_.end()) held_.erase(it);
        return ack;
      }
      if (it == held_.end()) {
        it = held_.emplace(ack.to, Held{{}, 0, Clock::now() + delay_}).first;
      }
      it->second.ack = std::move(ack);
      it->second.items = items;
      return std::nullopt;
    }
    // The held acks due by `now` (all of them when `all`), removed.
    std::vector<Frame> take_due(bool all = false) {
      std::vector<Frame> due;
      std::lock_guard lock(mu_);
      const auto now = Clock::now();
      for (auto it = held_.begin(); it != held_.end();) {
        if (all || now >= it->second.due) {
          due.push_back(std::move(it->second.ack));
          it = held_.erase(it);
        } else {
          ++it;
        }
      }
      return due;
    }
    // How long the taker may wait for frames before an ack falls due.
    std::chrono::milliseconds wait_at_most(std::chrono::milliseconds idle) const {
      std::lock_guard lock(mu_);
      auto wait = idle;
      const auto now = Clock::now();
      for (const auto& [to, h] : held_) {
        auto left = std::chrono::ceil<std::chrono::milliseconds>(h.due - now);
        wait = std::min(wait, std::max(left, std::chrono::milliseconds(0)));
      }
      return wait;
    }

   private:
    struct Held {
      Frame ack;
      std::size_t items = 0;
      Clock::time_point due;
    };
    const std::chrono::milliseconds delay_;
    mutable std::mutex mu_;
    std::map<std::string, Held> held_;  // by the peer the ack goes to
  };

  // Two stages per transport: a taker thread takes frames off the transport and decodes item
  // bodies; this thread applies them to the store and answers, batch after batch in arrival
  // order. Taking and decoding then overlap with the store transaction of the batch before, on
  // the other core. The queue is short: a backlog stays in the transport, whose flow control (the
  // senders' windows) bounds it. On a quiet link the hand-off is a wake-up on the path of every
  // item (docs/bench.md), so a small batch that finds the applier idle and nothing queued is
  // applied by the taker itself. One thread applies at a time (`applying`), and the taker applies
  // only when everything taken before is applied, so the order is the same either way.
  void receive_loop(std::shared_ptr<Transport> transport) {
    auto node = node::Node::open(opt.dir);
    if (!node) {
      log("cannot open the store: " + node.error().message);
      return;
    }
    // The relaying agents and held items, used by whichever thread is applying.
    std::map<std::string, node::Agent> agents;  // by id
    std::map<std::string, HeldFrames> held;     // per stream: items that came ahead of a hole
    HeldAcks acks(opt.ack_delay);
    auto agent = [&](const std::string& id) -> node::Agent* {
      auto it = agents.find(id);
      if (it == agents.end()) {
        auto a = node->agent(id);
        if (!a) return nullptr;
        it = agents.emplace(id, std::move(*a)).first;
      }
      return &it->second;
    };
    // P6: of several hellos alike from one sender in a batch only the last is answered (a
    // child asks again while its answer is on the way); hellos that differ (two stores under
    // one IRI, P6b) are each answered.
    std::unordered_map<std::string_view, std::size_t> last_hello;
    auto apply = [&](ReceivedBatch& batch) {
      last_hello.clear();
      if (std::count_if(batch.frames.begin(), batch.frames.end(), [](const Frame& f) { return f.kind == FrameKind::hello; }) > 1)
        for (std::size_t i = 0; i < batch.frames.size(); ++i)
          if (batch.frames[i].kind == FrameKind::hello) last_hello[batch.frames[i].from] = i;
      for (std::size_t i = 0; i < batch.frames.size();) {
        const Frame& f = batch.frames[i];
        if (f.kind == FrameKind::hello && !last_hello.empty()) {
          const Frame& last = batch.frames[last_hello[f.from]];
          if (&last != &f && last.body == f.body && last.ack == f.ack && last.version == f.version) {
            ++i;
            continue;
          }
        }
        if (f.kind == FrameKind::up || f.kind == FrameKind::down) {
          std::size_t j = i + 1;
          while (j < batch.frames.size() && batch.frames[j].kind == f.kind && batch.frames[j].from == f.from) ++j;
          relay_run(transport.get(), std::span(batch.frames).subspan(i, j - i),
                    std::span(batch.items).subspan(i, j - i), agent, held, acks, batch.applied);
          i = j;
        } else {
          dispatch(transport.get(), f, agent);
          ++i;
        }
      }
    };

    std::mutex queue_mu;
    // With queue_mu. `queue_cv`: the applier (a batch queued) and takers waiting for room.
    // `taker_cv`: the taker thread in push mode (frames left for it, sends deferred to it, room).
    // Apart, so that a held ack sent from the transport's thread wakes the taker that sends it
    // and not the applier as well: two wake-ups on the path of the next item (docs/bench.md,
    // session 32).
    std::condition_variable queue_cv;
    std::condition_variable taker_cv;
    std::deque<ReceivedBatch> queue;
    bool applying = false;  // a thread is applying a batch (under queue_mu)
    // Push mode: the transport's thread left frames in the transport, because the queue was full
    // or the applier busy; the taker thread takes them, once there is room (under queue_mu).
    bool deferred = false;
    // Batches the applier is done with. The taker, which allocated their frames and items, frees
    // them: under load the applier is the bottleneck, and the frees were ~7% of its time.
    std::vector<ReceivedBatch> spent;
    constexpr std::size_t kQueuedBatches = 4;

    // One round of taking, by one thread at a time: waits up to `wait` for a first frame,
    // drains what follows (runs of items from one sender then go into one transaction), decodes
    // item bodies, and applies the batch or queues it for the applier. False when nothing came.
    //
    // In push mode the transport's thread takes too, so nothing that takes may wait long: a
    // round takes nothing while the queue is full (`deferred`: the applier has the taker take
    // once it made room), and applies only items of known peers itself. Anything else may make
    // a first send to a new peer, which waits for DDS discovery, which may need the very thread
    // that would be waiting.
    std::atomic<bool> push_mode{true};  // until on_arrival says the transport has no thread
    // Applies `batch` here or queues it for the applier (see take_round). True.
    auto hand_on = [&](ReceivedBatch batch, bool push) {
      const bool inline_ok = batch.frames.size() <= kInlineFrames && (!push || items_of_known_peers(batch.frames));
      std::unique_lock lock(queue_mu);
      if (inline_ok && queue.empty() && !applying) {
        applying = true;
        lock.unlock();
        apply(batch);
        lock.lock();
        applying = false;
        return true;  // nothing was queued meanwhile: only a taking thread queues
      }
      // `stopping` is not signalled through queue_cv: re-checked every 100 ms. In push mode
      // there is room (checked by take_round, and only a taking thread adds).
      while (queue.size() >= kQueuedBatches && !stopping) queue_cv.wait_for(lock, 100ms);
      if (stopping) return false;
      queue.push_back(std::move(batch));
      queue_cv.notify_all();
      return true;
    };
    // Push mode: the frames of a run its sender marked as going on (P9b), held until the run's
    // last frame comes, so that a burst goes into the store a run per transaction (as the taker's
    // later wake-up gathered it in pull mode) rather than a frame per transaction. Touched only
    // by the thread that takes; `run_since_ns` is also read by the taker to wake for it.
    ReceivedBatch run_so_far;
    std::atomic<std::int64_t> run_since_ns{0};  // 0: nothing held
    auto goes_on = [](const Frame& f) {
      return (f.kind == FrameKind::up || f.kind == FrameKind::down) && (f.ack & kMoreFollow) != 0;
    };
    auto take_round = [&](std::chrono::milliseconds wait, bool on_transport_thread) -> bool {
      const bool push = push_mode.load();
      // On the transport's thread a send would only go to the taker, which wakes for held acks
      // as they fall due anyway.
      if (!on_transport_thread)
        for (Frame& ack : acks.take_due()) send(transport.get(), std::move(ack));
      {
        std::vector<ReceivedBatch> garbage;
        std::lock_guard lock(queue_mu);
        garbage.swap(spent);
        if (push && queue.size() >= kQueuedBatches) {
          deferred = true;
          return false;
        }
      }
      auto first = transport->receive(wait);
      if (!first) {
        log("receive failed: " + first.error().message);
        if (!push) std::this_thread::sleep_for(100ms);
        return false;
      }
      if (!*first) {
        // A held run whose last frame is late (its sender stopped, say) waits no longer.
        const std::int64_t since = run_since_ns.load();
        if (since == 0 || now_ns() - since < std::chrono::nanoseconds(kRunWait).count()) return false;
        run_since_ns = 0;
        hand_on(std::exchange(run_so_far, {}), push);
        return false;
      }
      ReceivedBatch batch;
      batch.frames.push_back(std::move(**first));
      while (batch.frames.size() < 512) {
        auto more = transport->receive(0ms);
        if (!more || !*more) break;
        batch.frames.push_back(std::move(**more));
      }
      batch.items.resize(batch.frames.size());
      for (std::size_t i = 0; i < batch.frames.size(); ++i) {
        const Frame& f = batch.frames[i];
        if (f.kind == FrameKind::up || f.kind == FrameKind::down) batch.items[i] = wire::decode_item(f.body);
      }
      if (on_transport_thread) {
        std::lock_guard lock(mu);
        counters.taken_pushed += batch.frames.size();
      }
      if (push) {
        if (!run_so_far.frames.empty()) {
          std::move(batch.frames.begin(), batch.frames.end(), std::back_inserter(run_so_far.frames));
          std::move(batch.items.begin(), batch.items.end(), std::back_inserter(run_so_far.items));
          batch = std::exchange(run_so_far, {});
        }
        if (goes_on(batch.frames.back()) && batch.frames.size() < 512) {
          if (run_since_ns.load() == 0) run_since_ns = now_ns();
          run_so_far = std::move(batch);
          return true;
        }
        run_since_ns = 0;
      }
      return hand_on(std::move(batch), push);
    };
    // Takes until the transport is empty. A thread that finds another one taking leaves it to
    // take `again`. On the transport's thread every send waits for the taker (DeferredSends).
    std::atomic<bool> taking{false}, again{false};
    std::vector<std::pair<Transport*, Frame>> deferred_sends;  // under queue_mu
    DeferredSends defer{queue_mu, taker_cv, deferred_sends};
    auto take_all = [&](bool on_transport_thread) {
      again = true;
      bool took = false;
      DeferredSends* outer = t_deferred_sends;
      if (on_transport_thread) t_deferred_sends = &defer;
      while (again.load()) {
        bool idle = false;
        if (!taking.compare_exchange_strong(idle, true)) break;
        took = true;
        again = false;
        // On the transport's thread one round drains what is there: a frame delivered after it
        // brings a call of its own (Cyclone queues it behind this one).
        while (!stopping && take_round(0ms, on_transport_thread) && !on_transport_thread) {
        }
        taking = false;
      }
      t_deferred_sends = outer;
      return took;
    };
    auto send_deferred = [&] {
      std::vector<std::pair<Transport*, Frame>> frames;
      {
        std::lock_guard lock(queue_mu);
        frames.swap(deferred_sends);
      }
      for (auto& [via, f] : frames) send(via, std::move(f));
    };

    // Push mode (Transport::on_arrival; Cyclone DDS): frames are taken on the transport's
    // receive thread as they arrive, and a quiet link's item is relayed there without waking
    // a thread of ours (tens of µs here; docs/bench.md). The taker thread then only sends held
    // acks as they fall due, takes what the transport's thread deferred, and every 100 ms takes
    // anything left (frames that arrived before push mode began).
    //
    // Under load (the applier busy or batches queued) the transport's thread leaves the taking
    // to the taker thread, as in pull mode: decoding there held up Cyclone's one receive thread
    // of the process, which then read the sockets of a thousand homes more slowly (docs/bench.md,
    // session 24).
    auto arrived = [&] {
      {
        std::lock_guard lock(queue_mu);
        if (applying || !queue.empty()) {
          if (!deferred) {  // one wake-up for the taker, not one per sample
            deferred = true;
            taker_cv.notify_all();
          }
          return;
        }
      }
      take_all(true);
    };
    if (!opt.push || !transport->on_arrival(arrived)) push_mode = false;
    std::thread taker([&] {
      name_thread(opt.up == transport ? "tv-take-up" : "tv-take-down");
      while (!stopping) {
        if (!push_mode) {  // the only thread that takes
          take_round(acks.wait_at_most(100ms), false);
          continue;
        }
        // Another thread taking sends the acks that are due; meanwhile this one waits a little
        // rather than spin on an ack that is due now.
        const auto at_least = take_all(false) ? 0ms : 1ms;
        send_deferred();
        auto wait = std::max(at_least, acks.wait_at_most(100ms));
        if (const std::int64_t since = run_since_ns.load(); since != 0) {
          const auto held = std::chrono::nanoseconds(now_ns() - since);
          wait = std::min(wait, std::max(at_least, std::chrono::ceil<std::chrono::milliseconds>(kRunWait - held)));
        }
        std::unique_lock lock(queue_mu);
        taker_cv.wait_for(lock, wait, [&] {
          return stopping || !deferred_sends.empty() || (deferred && queue.size() < kQueuedBatches);
        });
        deferred = false;
      }
    });

    while (true) {
      ReceivedBatch batch;
      {
        std::unique_lock lock(queue_mu);
        // A taking thread queues only while this thread applies or has batches waiting, and
        // applies itself only with nothing queued: never two at once.
        queue_cv.wait_for(lock, 100ms, [&] { return !queue.empty() || stopping; });
        if (queue.empty()) {
          if (stopping) break;
          continue;
        }
        // Room for a taker waiting in hand_on, or for a deferred take; anything else would
        // only wake the taker thread in push mode, which waits on the same condition.
        const bool room_awaited = queue.size() >= kQueuedBatches || deferred;
        batch = std::move(queue.front());
        queue.pop_front();
        applying = true;
        if (room_awaited) {
          queue_cv.notify_all();
          taker_cv.notify_all();
        }
      }
      apply(batch);
      std::lock_guard lock(queue_mu);
      applying = false;
      spent.push_back(std::move(batch));
    }
    // No call of the transport's thread is under way after this, and none starts.
    if (push_mode) transport->on_arrival({});
    taker.join();
    send_deferred();
    for (Frame& ack : acks.take_due(true)) send(transport.get(), std::move(ack));
  }

  // Whether every frame of `frames` is an item from a peer this node already exchanges items
  // with (a connected child's up frame, the welcoming parent's down frame): what the transport's
  // own thread may relay, since the replies go to peers it has sent to before.
  bool items_of_known_peers(const std::vector<Frame>& frames) {
    std::lock_guard lock(mu);
    const std::string* last = nullptr;
    for (const Frame& f : frames) {
      if (last && *last == f.from) continue;
      if (f.kind == FrameKind::up) {
        auto it = children.find(f.from);
        if (it == children.end() || !it->second->connected) return false;
      } else if (f.kind != FrameKind::down || !welcomed || !from_parent(f)) {
        return false;
      }
      last = &f.from;
    }
    return true;
  }

  bool from_parent(const Frame& f) const { return opt.up && !opt.parent_iri.empty() && f.from == opt.parent_iri; }

  void heard_from_parent() {
    std::lock_guard lock(mu);
    const Clock::time_point now = Clock::now();
    // P8a: a parent heard again after a silence is a path that passes frames again: what waits
    // goes now, in a whole window, not after a backed-off wait (up to 16 x resend_after).
    if (now - parent_heard > opt.child_silence && up_backoff > 0) {
      up_backoff = 0;
      up_mark_at_go_back = ~0ull;
      if (!up_in_flight.empty()) up_go_back = true;
      changed.notify_all();
    }
    parent_heard = now;
    parent_heard_ns = now_ns();
  }

  // P1: why the sender `iri` cannot be a child of this node, or its child id.
  node::Result<std::string> child_id_of(const std::string& iri) const {
    auto id = uri::child_id(iri, self);
    if (!id)
      return node::fail(Errc::invalid_argument, "<" + iri + "> is not a child of <" + self +
                                                    "> (a child's IRI is the parent's IRI + \"/\" + its id): " +
                                                    id.error().message);
    if (!opt.children.empty() && std::find(opt.children.begin(), opt.children.end(), *id) == opt.children.end())
      return node::fail(Errc::invalid_argument, "<" + iri + "> is not among the children configured for <" + self + ">");
    // Byte for byte: child_id compares normal forms, so that <http://H.test/p/c1> and
    // <http://h.test/p/../p/c1> were child c1 of <http://h.test/p> each, registered apart, their
    // items stored under IRIs that are no node's (an exploratory run of session 85).
    if (iri != self + "/" + *id)
      return node::fail(Errc::invalid_argument, "<" + iri + "> is not written as <" + self + "> writes its child '" + *id +
                                                    "': <" + self + "/" + *id + "> (a child's IRI is the parent's IRI + \"/\" + its id, byte for byte)");
    if (*id == kLinkAgent || *id == kUplinkAgent)  // child C is agent C of this node
      return node::fail(Errc::invalid_argument, "<" + iri + "> has the id '" + *id + "', which is this node's own agent '" +
                                                    *id + "' at <" + self + ">");
    return *id;
  }

  std::shared_ptr<Child> accepted_child(const std::string& iri, std::string* why) {
    auto id = child_id_of(iri);
    if (!id) {
      *why = id.error().message;
      return nullptr;
    }
    std::lock_guard lock(mu);
    auto& child = children[iri];
    if (!child) {
      child = std::make_shared<Child>();
      child->flips.set_hold(opt.conflict_hold);
      child->id = *id;
      child->iri = iri;
      if (auto before = stores_before.find(iri); before != stores_before.end()) child->store_before = before->second;
    }
    return child;
  }

  // P8: items of one stream that arrived after a lost one wait here (bounded, in memory only)
  // until the hole is filled, so a loss costs the resend of the missing items, not of everything
  // sent after them. Only the stream's receive thread touches it.
  struct HeldFrames {
    std::optional<std::uint64_t> mark;                  // the store's mark, read once
    std::map<std::uint64_t, node::RelayedItem> by_prev;  // keyed by the seq each one follows
  };
  static constexpr std::size_t kHeldMax = 4096;
  // And their bytes: items of up to 64 MB each made 4,096 held ones half a gigabyte of a
  // gateway's memory (a peer sending far ahead of a gap). What is dropped comes again (P8).
  static constexpr std::size_t kHeldMaxBytes = 64u << 20;
  static void drop_held_past(HeldFrames& held, std::size_t max_bytes) {
    std::size_t bytes = 0;
    for (auto it = held.by_prev.begin(); it != held.by_prev.end(); ++it) {
      const node::RelayedItem& r = it->second;
      bytes += r.source.size() + r.item.context.size() + 64;
      for (const node::Triple& t : r.item.triples)
        bytes += t.s.value.size() + t.p.value.size() + t.o.value.size() + t.o.datatype.size() + t.o.language.size() + 96;
      if (bytes > max_bytes) {
        held.by_prev.erase(it, held.by_prev.end());
        return;
      }
    }
  }

  template <class AgentFn>
  void relay_run(Transport* via, std::span<const Frame> frames,
                 std::span<std::optional<node::Result<wire::ItemBody>>> bodies, AgentFn& agent,
                 std::map<std::string, HeldFrames>& held, HeldAcks& acks,
                 std::vector<std::vector<node::RelayedItem>>& applied) {
    const Frame& head = frames.front();
    const bool up = head.kind == FrameKind::up;
    std::shared_ptr<Child> child;
    std::string conflict;  // P6b: why a known child is not linked with
    std::uint64_t head_registered_tag = 0;  // of the store registered for the sender, if any
    if (up) {
      std::lock_guard lock(mu);
      auto it = children.find(head.from);
      if (it != children.end() && it->second->connected) child = it->second;
      else if (it != children.end()) conflict = it->second->flips.said();
      if (it != children.end()) head_registered_tag = store_tag(it->second->store_id);
    }
    // A child's items may come before its hello (this node restarted): what it is told then
    // ("unregistered") must be in its version. Only a frame that would be taken says it: one
    // junk frame of version 3 under a child's name, its body undecodable or its store tag not the
    // registered store's, had the child spoken to in 3 (a prober's flood of session 87).
    if (up && *bodies.front()) {
      const std::uint64_t from_tag = (head.ack >> kStoreTagShift) & kStoreTagMask;
      if (head_registered_tag == 0 || from_tag == head_registered_tag)
        note_child_version(head.from, head.version, child_id_of(head.from).has_value());
    }
    bool unwelcomed = false;
    if (!up) {
      std::lock_guard lock(mu);
      unwelcomed = !welcomed;
    }
    if (!up && from_parent(head)) heard_from_parent();
    if (unwelcomed && from_parent(head)) {
      // P6a: until the welcome names the parent's store, it is not known which stream these
      // continue; the parent sends them again after the welcome (as if they were lost).
      return;
    }
    if (up ? !child : !from_parent(head)) {
      if (!up) return refuse(via, head.from, head.kind, frames.size(), "<" + head.from + "> is not this node's parent");
      if (!opt.down) return refuse(via, head.from, head.kind, frames.size(), "<" + self + "> takes no children");
      // A sender that is no child of this node is refused as its hello would be (P6), and
      // logged; a child that is not connected is told to say hello (P6).
      auto id = child_id_of(head.from);
      if (!id) return refuse(via, head.from, head.kind, frames.size(), id.error().message);
      {
        std::lock_guard lock(mu);
        counters.refused += frames.size();
      }
      if (!conflict.empty()) send_error(via, head.from, 0, {"refused", conflict, ""});
      else send_error(via, head.from, 0, {"unregistered", "<" + head.from + "> must say hello to <" + self + "> first", ""});
      return;
    }
    std::uint64_t registered_tag = 0, own_tag = 0;
    {
      std::lock_guard lock(mu);
      registered_tag = store_tag(up ? child->store_id : parent_store_id);
      own_tag = store_tag(store_id);
    }
    std::vector<node::RelayedItem> items;
    items.reserve(frames.size());
    std::string foreign;  // P6b: why frames of this run are not this stream's
    bool foreign_is_twin = false;  // they went to another store of this node's IRI
    std::size_t untagged = 0;  // P6b: frames without a store tag from a peer whose store has one
    for (std::size_t k = 0; k < frames.size(); ++k) {
      const Frame& f = frames[k];
      // A body that does not decode first (P17): a frame that is no item is dropped for that
      // alone, and its store tags, whatever they say, are no sign of another store (P6b) —
      // three such frames held a healthy child off for the conflict's two minutes.
      auto& body = *bodies[k];
      if (!body) {
        refuse(via, f.from, f.kind, 1,
               "dropped a malformed " + std::string(up ? "up" : "down") + " frame from <" + f.from + ">: " + body.error().message,
               "malformed", /*answer=*/false);
        break;  // the rest follows it in the sender's sequence: they come again after a resend
      }
      const std::uint64_t from_tag = (f.ack >> kStoreTagShift) & kStoreTagMask, to_tag = f.ack >> kPeerStoreTagShift;
      if (from_tag == 0 && registered_tag != 0) {
        // Only a peer from before store tags sends none, and it registered no store id: one
        // forged frame so, its seq far ahead, moved the mark past every item the child would
        // ever send, and the child's stream stopped for good.
        ++untagged;
        continue;
      }
      if (from_tag != 0 && registered_tag != 0 && from_tag != registered_tag) {
        foreign = describe_tag("which sent frames here", from_tag);
        foreign_is_twin = false;
        continue;  // the other store's seqs are not this stream's: never applied, never acknowledged
      }
      if (to_tag != 0 && own_tag != 0 && to_tag != own_tag) {
        foreign = describe_tag("", to_tag);
        foreign_is_twin = true;
        continue;  // sent on a link with that other store
      }
      if (!up) body->item.context = subtree_for(body->item.context, self);  // P11
      items.push_back({f.seq, f.prev, std::move(body->source), std::move(body->item), body->removal, std::move(body->positions)});
    }
    if (untagged > 0)
      refuse(via, head.from, head.kind, untagged,
             "dropped " + std::string(up ? "up" : "down") + " frames from <" + head.from +
                 "> that carry no store tag, though the store registered for it has one (P6b): a forger, or a peer "
                 "from before store tags whose store has an id now",
             "no store tag", /*answer=*/false);
    if (!foreign.empty()) other_store_sent(up ? child.get() : nullptr, foreign, foreign_is_twin);
    if (items.empty() && (!foreign.empty() || untagged > 0)) return;
    node::Agent* relayer = agent(up ? child->id : std::string(kUplinkAgent));
    if (!relayer) return;
    std::string stream;
    {
      std::lock_guard lock(mu);
      stream = up ? up_stream(child->iri, child->store_id) : down_stream();
    }
    HeldFrames& buffer = held[stream];
    if (!buffer.mark) {
      auto mark = relayer->relay_mark(stream);
      if (!mark) return log("cannot read the mark of " + stream + ": " + mark.error().message);
      buffer.mark = *mark;
    }
    // The run that continues the mark: items in order go straight into it (the usual case, no
    // hole); anything else waits among the held items, which then continue the run.
    std::size_t early_duplicates = 0;
    std::vector<node::RelayedItem> run;
    run.reserve(items.size());
    std::uint64_t next = *buffer.mark;  // the seq the run has reached
    for (auto& item : items) {
      if (item.seq <= *buffer.mark) {
        ++early_duplicates;
      } else if (buffer.by_prev.empty() && item.prev == next) {
        next = item.seq;
        run.push_back(std::move(item));
      } else {
        buffer.by_prev.insert_or_assign(item.prev, std::move(item));
      }
    }
    for (auto it = buffer.by_prev.find(next); it != buffer.by_prev.end(); it = buffer.by_prev.find(next)) {
      next = it->second.seq;
      run.push_back(std::move(it->second));
      buffer.by_prev.erase(it);
    }
    node::Result<node::RelayOutcome> outcome = node::RelayOutcome{.mark = *buffer.mark};
    const std::size_t relayed = run.size();
    // P6f: a removal from above may narrow the forwarding policy (the subscriptions of this
    // node's uplink, whose buffer is the outbox).
    const bool may_narrow = !up && std::any_of(run.begin(), run.end(), [](const node::RelayedItem& r) { return r.removal; });
    std::optional<std::set<std::uint64_t>> policy_before;
    if (may_narrow) {
      policy_before = policy_items();
      std::lock_guard lock(mu);
      relaying_may_narrow = true;
      mark_narrowing(true);  // before the removal is applied: a stop after it withdraws at the next start
    }
    if (!run.empty()) outcome = relayer->relay(stream, run);
    if (!up) {
      const bool narrowed = outcome && policy_before && outcome->removals > 0 && policy_narrowed_since(*policy_before);
      std::lock_guard lock(mu);
      if (narrowed) policy_narrowed = true;  // the up loop withdraws before it reads the outbox again
      if (may_narrow) {
        relaying_may_narrow = false;
        if (!policy_narrowed) mark_narrowing(false);
      }
      if (outcome) {
        // P6f: the hold's limit is for a down stream that stands; one that moves (30,000
        // settings relayed on a slow store) is waited for.
        if (down_hold_through != 0 && outcome->mark > down_applied_mark) down_hold_until = Clock::now() + kDownHoldMax;
        down_applied_stream = stream;
        down_applied_mark = outcome->mark;
        changed.notify_all();
      }
    }
    if (outcome && outcome->not_applied) std::erase_if(run, [&](const node::RelayedItem& r) { return r.seq > outcome->mark; });
    applied.push_back(std::move(run));  // freed by the taker, with the rest of the batch
    if (outcome) {
      buffer.mark = outcome->mark;
      outcome->duplicates += early_duplicates;
      std::erase_if(buffer.by_prev, [&](const auto& e) { return e.second.seq <= *buffer.mark; });
      while (buffer.by_prev.size() > kHeldMax) buffer.by_prev.erase(std::prev(buffer.by_prev.end()));
      drop_held_past(buffer, kHeldMaxBytes);
      outcome->gap = outcome->gap || !buffer.by_prev.empty();
    } else {
      buffer = HeldFrames{};  // read the mark again; the sender resends what is missing
    }
    Frame ack;
    {
      std::lock_guard lock(mu);
      ack = stream_ack(head.from, up ? child->store_id : parent_store_id);
    }
    if (!outcome) {  // a refused source (P9), a full store: nothing applied, the mark stays
      auto mark = relayer->relay_mark(stream);
      ack.ack = mark ? *mark : 0;
    } else {
      if (!outcome->stored.empty()) {
        // Stored again. A store nearly full takes a run now and then between refusals: the
        // failure after is said 10 s after the last at the earliest, as every repeat is (it
        // was said at once, two or three lines a second).
        std::lock_guard lock(mu);
        if (auto failed = relay_failures.find(head.from); failed != relay_failures.end()) {
          if (Clock::now() - failed->second.said_at >= kRelayFailureSaidEvery) relay_failures.erase(failed);
          else failed->second.stored_since_sent = true;
        }
      }
      ack.ack = outcome->mark;
      ack.prev = outcome->gap ? 1 : 0;
      // P9a: an item this node can never store is passed over, not resent for ever; the sender
      // is told which, and why.
      for (const node::RefusedItem& r : outcome->refused) {
        log("refused item " + std::to_string(r.seq) + " from <" + head.from + "> (it stays in the sender's store): " + r.why.message);
        send_error(via, head.from, r.seq, {std::string(kItemRefused), r.why.message, ""});
      }
      std::unique_lock lock(mu);
      if (outcome->already_held > 0) {
        HeldAlreadySaid& said = held_already_said[head.from];
        said.unsaid += outcome->already_held;
        said.unsaid_recomputed += outcome->recomputed;
        if (said.at == Clock::time_point{} || Clock::now() - said.at >= kRelayFailureSaidEvery) {
          const std::string line = held_already_line(head.from, said);
          lock.unlock();
          log(line);
          lock.lock();
        }
      }
      counters.items_refused += outcome->refused.size();
      counters.removals_applied += outcome->removals;
      counters.records_removed_in += outcome->records_removed;
      if (up) {
        counters.relayed_in += outcome->stored.size();
        if (!outcome->stored.empty()) ++counters.relay_writes;
        child->last_seen = Clock::now();
      } else {
        counters.down_applied += outcome->stored.size();
        for (const node::RelayedItem& r : applied.back())
          if (!r.removal && !r.item.context.empty()) down_contexts.push_back(r.item.context);
      }
      counters.duplicates_in += outcome->duplicates;
      counters.already_held_in += outcome->already_held;
    }
    // At once what the sender must act on: a refusal, a gap, a resend (duplicates), a run that
    // applied nothing, or its window half full (P8).
    const bool now = !outcome || outcome->not_applied || ack.prev == 1 || outcome->duplicates > 0 || relayed == 0 ||
                     !outcome->refused.empty() ||
                     std::any_of(frames.begin(), frames.end(), [](const Frame& f) { return (f.ack & kAckNow) != 0; });
    if (auto due = acks.hold(std::move(ack), relayed, now)) send(via, std::move(*due));
    // After the ack: an ack that moves the mark tells the sender the parent stores again, and
    // this says it cannot store the rest (the store took part of the run).
    if (!outcome) cannot_store_run(via, head.from, outcome.error().message);
    else if (outcome->not_applied)
      cannot_store_run(via, head.from, outcome->not_applied->message,
                       " the rest of a run, having stored " + std::to_string(applied.back().size()) + " of its " +
                           std::to_string(relayed) + " item(s)");
  }

  // The items of this node's forwarding policy: the subscriptions of its agent uplink (P5);
  // nullopt when the store cannot be read.
  std::optional<std::set<std::uint64_t>> policy_items() {
    auto failed = [&](const node::Error& e) {
      log("cannot read the forwarding policy: " + e.message);
      return std::nullopt;
    };
    auto node = node::Node::open(opt.dir);
    if (!node) return failed(node.error());
    auto snapshot = node->snapshot();
    if (!snapshot) return failed(snapshot.error());
    auto subscriptions = snapshot->list({.p = node::Term::iri(std::string(vocab::kTv) + "subscriber"),
                                         .o = node::Term::iri(self + "/" + std::string(kUplinkAgent))});
    if (!subscriptions) return failed(subscriptions.error());
    std::set<std::uint64_t> items;
    for (const node::Record& r : *subscriptions) items.insert(r.meta.item);
    return items;
  }

  // P6f: whether a subscription of the policy `before` is gone.
  bool policy_narrowed_since(const std::set<std::uint64_t>& before) {
    auto after = policy_items();
    return after && !std::includes(after->begin(), after->end(), before.begin(), before.end());
  }

  // A full store applied none, or only the first part, of a run from `from` (P9b). The sender is
  // told why and probes with one frame at a time until the mark moves: a home resent its window
  // every resend_after, and this log took a line for each, for as long as the store was full.
  // `part` says what of the run was stored, when some was.
  void cannot_store_run(Transport* via, const std::string& from, const std::string& why, const std::string& part = "") {
    std::unique_lock lock(mu);
    RelayFailure& failure = relay_failures[from];
    // Once a second at most (a sender of a build before P9b logs each one), and at once after
    // a run was stored: the sender then sends its whole window again.
    const bool new_kind = reason_kind(why) != reason_kind(failure.why);
    if (new_kind || failure.stored_since_sent || Clock::now() - failure.sent_at >= std::chrono::seconds(1)) {
      failure.sent_at = Clock::now();
      failure.stored_since_sent = false;
      lock.unlock();
      send_error(via, from, 0, {std::string(kCannotStore), why, ""});
      lock.lock();
    }
    if (new_kind || Clock::now() - failure.said_at >= kRelayFailureSaidEvery) {
      log("relay from <" + from + "> refused" + part + ": " + why +
          (failure.since_said > 0 && !new_kind ? " (and " + std::to_string(failure.since_said) + " times more since it was last said)" : ""));
      failure.why = why;
      failure.said_at = Clock::now();
      failure.since_said = 0;
    } else {
      ++failure.since_said;
    }
    ++counters.refused;
  }

  // P6f: the id of the last item after `after` in `queue` (a child's down queue) that the pump
  // sends as a down frame; 0 when none. Read from the queue's end: the newest is nearly always
  // one (not the child's own item, nor a query).
  std::uint64_t last_going_down(const node::Agent& queue, const std::string& child_iri, std::uint64_t after) {
    for (std::uint64_t before = std::numeric_limits<std::uint64_t>::max();;) {
      auto newest = queue.peek_newest(after, before, 16);
      if (!newest) {
        log("cannot read the down queue of <" + child_iri + ">: " + newest.error().message);
        return 0;
      }
      if (newest->empty()) return 0;
      for (const node::Delivery& d : *newest) {
        if (!d.records.empty() && uri::is_under(d.records.front().meta.source, child_iri)) continue;  // came up from it
        if (object_of(d.records, vocab::kQueryTarget)) continue;  // goes as a query frame, or not at all
        return d.item;
      }
      before = newest->back().item;
    }
  }

  template <class AgentFn>
  void dispatch(Transport* via, const Frame& f, AgentFn& agent) {
    if (from_parent(f)) {
      heard_from_parent();
      return from_parent_frame(via, f, agent);
    }
    std::string why;
    if (is_down(via)) {
      auto child = accepted_child(f.from, &why);
      // A hello or heartbeat whose body does not decode is dropped (read_state): it says nothing
      // of its sender's version either.
      if ((f.kind == FrameKind::hello || f.kind == FrameKind::heartbeat) && (f.body.empty() || wire::decode_state(f.body, f.version)))
        note_child_version(f.from, f.version, child != nullptr);
      if (child) {
        if (f.version != kProtocolVersion && f.kind == FrameKind::answer) return answer_of_older_child(via, f, child, agent);
        return from_child_frame(via, f, child, agent);
      }
    } else {
      // A node whose LCM URL for its children is one port above its parent's has both ends
      // listening on one port (LcmEnd): its children's frames reach its end up too, and its end
      // down takes them. Not refused here: "not the parent" misled whoever read the log.
      if ((opt.down || !opt.also_down.empty()) && f.from != self && uri::is_under(f.from, self)) return;
      why = "<" + f.from + "> is not the parent <" + opt.parent_iri + "> of <" + self + ">";
    }
    refuse(via, f.from, f.kind, 1, why);
  }

  // `frames` frames of `kind` from `from` that this node does not take, counted, and logged with
  // `why` once a minute per sender and reason (`reason`: the reason without the figures that
  // change from one frame to the next; a refused child says hello every second). P6: from a
  // sender that is no child of this node (or not a connected one), a hello, heartbeat or up is
  // answered with `refused`, so that a child that was welcomed and is no longer accepted (its
  // parent restarted with a file without it) learns so from its next heartbeat or item; at most
  // once a second per sender and kRefusalAnswersPerSecond in all, without waiting for the sender
  // to be found (Frame::may_find_nobody), so that frames from made-up IRIs cost this node
  // bounded work.
  // `answer` false: logged and counted only (a frame from a sender this node takes, dropped).
  // `counted` false: a frame taken but whose line is limited all the same (an error frame that
  // anyone on the network can send, said a line each).
  void refuse(Transport* via, const std::string& from, FrameKind kind, std::size_t frames, const std::string& why,
              const std::string& reason = {}, bool answer_it = true, bool counted = true) {
    const bool answered_kind = answer_it && is_down(via) &&
                               (kind == FrameKind::hello || kind == FrameKind::heartbeat || kind == FrameKind::up);
    bool say = false, answer = false;
    std::uint64_t left_out = 0;  // refusal lines not said in the window before this line
    std::uint64_t unsaid = 0;    // this sender's refusals not said since its line before
    {
      std::lock_guard lock(mu);
      if (counted) counters.refused += frames;
      // Bounded: each sender a frame makes up is one more entry.
      if (refusals.size() >= kRefusalsKept && !refusals.contains(from)) refusals.clear();
      Refusal& last = refusals[from];
      const std::string& key = reason.empty() ? why : reason;
      // A would-be child's hello, for `status` here (say_problem): it was in the log only.
      if (answered_kind && kind == FrameKind::hello) {
        if (refused_hellos.size() >= kRefusedHellosShown && !refused_hellos.contains(from))
          refused_hellos.erase(std::min_element(refused_hellos.begin(), refused_hellos.end(), [](const auto& a, const auto& b) {
                                 return a.second.last < b.second.last;
                               }));
        refused_hellos[from] = {why, Clock::now()};
      }
      const auto now = Clock::now();
      const auto said = last.logged.find(key);
      if (said == last.logged.end() || now - said->second > std::chrono::minutes(1)) {
        if (now - refusal_lines_since >= kRefusalLogWindow) {
          left_out = refusal_lines_left_out;
          refusal_lines_since = now;
          refusal_lines = 0;
          refusal_lines_left_out = 0;
        }
        say = refusal_lines < kRefusalLinesPerWindow;
        // Only a line said counts as this sender's last: one left out is counted each time, and
        // the sender's next refusal after the window is said.
        if (say) {
          ++refusal_lines;
          if (said == last.logged.end() && last.logged.size() >= kReasonsKeptPerSender)
            last.logged.erase(std::min_element(last.logged.begin(), last.logged.end(),
                                               [](const auto& a, const auto& b) { return a.second < b.second; }));
          last.logged[key] = now;
          unsaid = std::exchange(last.unsaid, 0);
        } else {
          ++refusal_lines_left_out;
        }
      } else {
        // Counted, and said with the sender's next line: 8 malformed up frames of one sender in
        // a minute left one line, and no trace of the other 7 (session 85).
        last.unsaid += frames;
      }
      if (now - refusal_answers_since >= std::chrono::seconds(1)) {
        refusal_answers_since = now;
        refusal_answers = 0;
      }
      if (answered_kind && now - last.answered >= std::chrono::seconds(1) && refusal_answers < kRefusalAnswersPerSecond) {
        last.answered = now;
        ++refusal_answers;
        answer = true;
      }
    }
    if (left_out > 0)
      log(std::to_string(left_out) + " more refusal" + (left_out == 1 ? " was" : "s were") + " not logged (at most " +
          std::to_string(kRefusalLinesPerWindow) + " lines per " + std::to_string(kRefusalLogWindow.count()) + " s)");
    if (say) {
      const std::string name = frame_kind_name(kind);
      const std::string count = frames != 1 ? std::to_string(frames) + " " : name.find_first_of("aeiu") == 0 ? "an " : "a ";
      const std::string since = unsaid == 0 ? std::string()
                                            : " (" + std::to_string(unsaid) + " more frame" + (unsaid == 1 ? "" : "s") +
                                                  " of this sender " + (counted ? "refused" : "dropped or said") + " since its line before, not logged)";
      log((answer_it ? "refused " + count + name + (frames == 1 ? " frame: " : " frames: ") + why : why) + since);
    }
    if (answer) send_error(via, from, 0, {"refused", why, ""}, /*may_find_nobody=*/true);
  }

  // A malformed frame's line, said as refusals are (P4: a line per sender and reason a minute,
  // and so many lines a window): 5,000 malformed heartbeats, answers, errors and queries in 3.6 s
  // were 3,750 lines of a parent's log, one a frame, up to session 84.
  void dropped_malformed(const Frame& f, const std::string& line) {
    refuse(nullptr, f.from, f.kind, 1, line, "malformed " + frame_kind_name(f.kind), /*answer_it=*/false);
  }
  // An error frame's line, limited as refusals are: a flood of error frames of made-up codes,
  // each well formed, wrote a line a frame on both sides (a prober of session 87). Not with
  // `mu` held.
  void error_said(const Frame& f, const std::string& line, const std::string& code, const std::string& message) {
    refuse(nullptr, f.from, f.kind, 1, line, "error " + code.substr(0, 64) + " " + std::string(reason_kind(message).substr(0, 64)),
           /*answer_it=*/false, /*counted=*/false);
  }

  // An answer in an earlier version's layout, read on as this version's: it goes on the board
  // and up as it is, and its readers read this version.
  template <class AgentFn>
  void answer_of_older_child(Transport* via, const Frame& f, const std::shared_ptr<Child>& child, AgentFn& agent) {
    auto body = wire::decode_answer(f.body, f.version);
    if (!body) {
      dropped_malformed(f, "dropped a malformed answer (protocol version " + std::to_string(f.version) + ") from <" + f.from +
                               ">: " + body.error().message);
      return;
    }
    Frame upgraded = f;
    upgraded.version = kProtocolVersion;
    upgraded.body = wire::encode_answer(*body);
    from_child_frame(via, upgraded, child, agent);
  }

  template <class AgentFn>
  void from_child_frame(Transport* via, const Frame& f, const std::shared_ptr<Child>& child, AgentFn& agent) {
    switch (f.kind) {
      case FrameKind::hello: {
        std::optional<wire::StateBody> state;
        if (!read_state(f, state)) return;
        node::Agent* link = agent(child->id);
        if (!link) return;
        std::string child_store = state ? state->store_id : std::string();
        if (child_store.empty()) {
          // P6b: an empty id (a peer from before store ids) is taken as a match: it goes on with
          // the stream registered, and is not a new one from its start (whose items the parent
          // would apply again).
          std::lock_guard lock(mu);
          child_store = child->store_id.empty() ? child->store_before : child->store_id;
        }
        auto mark = link->relay_mark(up_stream(child->iri, child_store));
        if (!mark) {
          log("cannot read the mark of <" + child->iri + ">: " + mark.error().message);
          return;
        }
        // P6a: the child's down mark counts in this store's ids only if it names this store.
        std::uint64_t down_from = f.ack;
        if (f.ack != 0 && (!state || state->peer_store_id != store_id)) {
          log("child <" + child->iri + ">: its down mark " + std::to_string(f.ack) +
              " is for another store of this node; its queue is sent from the start");
          down_from = 0;
        } else if (f.ack != 0 && f.ack > issued_to_peers()) {
          renew_store_id("child <" + child->iri + "> has applied up to " + std::to_string(f.ack) +
                         " of this store, which has issued less");
          down_from = 0;
        }
        // P11: its down queue also takes whole-subtree items (configured children were
        // subscribed at start). Once per child and run: two store transactions that change
        // nothing, for every hello of a thousand children after this node restarted, were
        // most of what answering them cost.
        bool board_set = false;
        {
          std::lock_guard lock(mu);
          board_set = child->board_set;
        }
        if (!board_set) {
          node::Pattern subtree;
          subtree.context = self + "/*";
          // Removals first: the items the subscription puts into the buffer at once are
          // remembered as given to it, and so go down again to a store made again (P10b).
          auto removals = link->receive_removals();
          if (!removals) log("cannot have removals sent to <" + child->iri + ">: " + removals.error().message);
          auto sub = link->subscribe(subtree, kSubtreeSubscription);
          if (!sub) log("cannot subscribe <" + child->iri + "> to subtree items: " + sub.error().message);
          std::lock_guard lock(mu);
          child->board_set = sub && removals;
        }
        std::string refusal;
        {
          std::lock_guard lock(mu);
          const auto now = Clock::now();
          if (child->connected && store_differs(child->store_id, child_store) && now - child->last_seen < opt.child_silence) {
            // P6b: the registered store is alive. A store made again in its place (a replaced disk)
            // comes after the old one fell silent; this one waits until it has.
            if (child->pending_store != child_store) {
              child->pending_store = child_store;
              child->pending_since = now;
            } else if (child->last_seen > child->pending_since + kBothAlive) {
              if (child->flips.declare(child->store_id, child_store, "the child <" + child->iri + ">"))
                log("conflict: " + child->flips.said());
              disconnect_for_conflict(*child);
            }
            refusal = child->flips.active()
                         ? child->flips.said()
                         : "another store (id " + child->store_id + ") is registered as <" + child->iri + "> and was heard " +
                               seconds_text(now - child->last_seen) + " ago; this one (id " + child_store +
                               ") registers once that one has been silent " + seconds_text(opt.child_silence) +
                               " (the node's store made again or restored from a backup, which is then "
                               "expected; else a second node with this IRI on this network)";
          }
        }
        if (!refusal.empty()) {
          // Said at the parent too, as other refusals are (a line per sender and reason a
          // minute): the hospital's operator saw nothing while a replaced home was kept out.
          refuse(via, f.from, f.kind, 1, refusal, "another store is registered");
          return;
        }
        bool store_made_again = false;
        std::string store_registered;
        std::uint64_t held_of_store_before = 0;  // this store's mark of that store's stream
        {
          std::lock_guard lock(mu);
          if (child->store_id != child_store) child->pending_store.clear();
          // The store registered before: in this run, or in an earlier one (the board's state).
          const std::string known = child->store_id.empty() ? child->store_before : child->store_id;
          store_made_again = known != child_store && !known.empty();
          store_registered = known;
          if (store_made_again)
            log("child <" + child->iri + "> has another store (id " + child_store + ", was " + known +
                "): its items are a new stream, from its start");
          child->store_before.clear();
          if (child->flips.saw(child->store_id, child_store, "the child <" + child->iri + ">"))
            log("conflict: " + child->flips.said());
          child->store_id = child_store;
          child->via = via;
          if (child->flips.active()) {
            // P6b: which store is the impostor cannot be told; linking with either mixes their
            // items under one IRI and lets one's acknowledgements empty the other's outbox.
            refusal = child->flips.said();
            disconnect_for_conflict(*child);
          }
        }
        if (!refusal.empty()) {
          refuse(via, f.from, f.kind, 1, refusal, "another store is registered");
          return;
        }
        if (store_made_again) {
          // P10c: a store restored from a backup sends again, on its new stream, what its
          // backup's outbox held, which this store applied from the stream before; a store made
          // again from nothing repeats nothing, and loses nothing by the check.
          auto before = link->relay_mark(up_stream(child->iri, store_registered));
          held_of_store_before = before ? *before : ~0ull;  // unknown: taken as held (no P6e)
          if (!before)
            log("cannot read the mark of <" + child->iri + ">'s store before: " + before.error().message);
          else if (*before > 0)
            if (auto said = link->relay_may_repeat(up_stream(child->iri, child_store), *before, repeats_asserted_through()); !said)
              log("cannot note that <" + child->iri + ">'s new stream may repeat the one before: " + said.error().message);
        }
        if (store_made_again && down_from == 0) {
          // What the store before applied leaves the down queue first: the queue is trimmed a
          // while after each acknowledgement, and a store made again may say hello at once (its
          // link said it left, P12c), when the rest would go down again with the persistent. Not
          // for a store that holds part of the stream (a backup of the child, down_from > 0):
          // what the store before applied after that part is what it lacks.
          std::uint64_t applied_before = 0;
          {
            std::lock_guard lock(mu);
            applied_before = child->down_mark;
          }
          if (applied_before > 0)
            if (auto trimmed = link->ack_through(applied_before); !trimmed)
              log("cannot take out of <" + child->iri + ">'s down queue what its store before applied: " + trimmed.error().message);
        }
        if (store_made_again && down_from == 0) {
          // P10b: the new store holds nothing of what came down; what was written for it to
          // keep (a setting put --persistent) goes down again, as P6c sends it up again.
          if (auto again = link->deliver_persistent_again(node::Redelivery::addressed_too); !again)
            log("cannot queue the persistent items for <" + child->iri + "> again: " + again.error().message);
          else if (*again > 0)
            log("child <" + child->iri + ">'s new store holds nothing of what came down: " + std::to_string(*again) +
                " persistent item(s) for it go down again");
        }
        {
          std::lock_guard lock(mu);
          bool was = child->connected;
          child->connected = child->ever = true;
          child->left = false;
          child->run = f.prev;
          child->hello_while_up_at = was ? Clock::now() : Clock::time_point{};
          child->last_seen = Clock::now();
          child->last_seen_ns = now_ns();
          if (state) {
            child->version = state->software_version;
            child->outbox_depth = state->outbox_depth;
          }
          // None from a child that says none (an older build after a rollback): figures kept
          // from before would be shown under its fresh last-seen time.
          child->room = state ? state->room : std::nullopt;
          child->down_mark = child->down_last_sent = down_from;  // P6: resume down from the child's mark
          child->down_in_flight.clear();
          child->down_progress = Clock::now();
          child->state_dirty = true;
          if (!child->pumped) {
            child->pumped = true;
            pump_new.push_back(child);
          }
          if (!was) log("child <" + child->iri + "> registered (" + child->version + ")");
          refused_hellos.erase(child->iri);
        }
        Frame welcome;
        welcome.kind = FrameKind::welcome;
        welcome.to = child->iri;
        welcome.ack = *mark;
        welcome.prev = run;  // P12d: its leaving notice names the same
        // Not for a child store made again whose store before this one holds part of: what it
        // sends again is the stream before, which P10c weighs (an item removed here came back).
        if (*mark == 0 && held_of_store_before == 0 && state && !state->peer_store_id.empty() &&
            store_is_a_copy(state->peer_store_id)) {
          // P6e: a store restored from a backup made before the child's stream reached the
          // store it was copied from. It holds nothing of the stream, as a store made new (P6c),
          // but the child sent its items since to another store of this node, and they are not
          // here. Which store that was the hello does not say beyond the last one (after two
          // restores, not one this store is a copy of): any copy asks, and at worst gets items
          // it never had.
          welcome.seq = kWelcomeFromACopy;
          bool said = false;
          {
            std::lock_guard lock(mu);  // once, not for each hello the child repeats meanwhile
            said = std::exchange(child->copy_said_for, state->peer_store_id) == state->peer_store_id;
          }
          if (!said)
            log("child <" + child->iri + "> was linked with store " + state->peer_store_id +
                " of this node, and this store, a copy (restored from a backup), holds nothing of its stream: "
                "it is asked to send up again all it sent (P6e)");
        }
        // Its peer store names the stream the mark is of: a second node under the child's IRI
        // gets this welcome too, and must not take the mark for its own (P6b). P6f: its outbox
        // depth is the last item of the child's down queue, which the child applies before it
        // sends anything up.
        welcome.body = wire::encode_state({opt.software_version, last_going_down(*link, child->iri, down_from),
                                           current_store_id(), child_store});
        send(via, std::move(welcome));
        std::lock_guard lock(mu);
        nudge_pump(*child);  // after the welcome: down frames follow it
        return;
      }
      case FrameKind::heartbeat: {
        std::optional<wire::StateBody> state;
        if (!read_state(f, state)) return;
        std::unique_lock lock(mu);
        if (state && child->connected && store_differs(child->store_id, state->store_id)) {
          // P6b: another store than the registered one beats as this child: both are alive.
          if (child->flips.saw(child->store_id, state->store_id, "the child <" + child->iri + ">"))
            log("conflict: " + child->flips.said());
          if (child->flips.active()) disconnect_for_conflict(*child);
          else {
            // Its answer names the registered store: the other says hello again (P6b).
            Frame answer = stream_ack(child->iri, child->store_id);
            lock.unlock();
            send(via, std::move(answer));
            return;
          }
        }
        if (!child->connected) {
          const std::string conflict = child->flips.said();
          lock.unlock();
          if (!conflict.empty()) send_error(via, f.from, 0, {"refused", conflict, ""});
          else send_error(via, f.from, 0, {"unregistered", "<" + f.from + "> must say hello to <" + self + "> first", ""});
          return;
        }
        child->last_seen = Clock::now();
        child->last_seen_ns = now_ns();
        // A new version is written at once; a new outbox depth with the next refresh of the
        // child's state (kStateRefreshNs): under load every heartbeat of every child brings
        // one, and a thousand children each rewriting their state every beat took the
        // hospital's writer from its ingest.
        if (state) {
          if (state->software_version != child->version) child->state_dirty = true;
          child->outbox_depth = state->outbox_depth;
          child->version = state->software_version;
          child->room = state->room;
        }
        // P12a: so that the child hears its parent while nothing else comes down (an ack whose
        // mark 0 moves nothing).
        Frame heard = stream_ack(child->iri, child->store_id);
        lock.unlock();
        send(via, std::move(heard));
        return;
      }
      case FrameKind::ack: {
        // An item-stream ack's state body is read before `mu` is taken: a malformed one is said
        // through refuse(), which takes it (session 85's first version read it under `mu`, and
        // one such frame hung the link for good).
        std::optional<wire::StateBody> stores;
        if (f.seq == 0 && !read_state(f, stores)) return;
        std::unique_lock lock(mu);
        if (f.seq != 0) {
          child->last_seen = Clock::now();
          Outgoing out;
          answer_ack(f, out);
          lock.unlock();
          return send_all(out);
        }
        // P6b: the acknowledgement of another store than the registered one (a second node
        // under this child's IRI) would move the registered one's down window.
        if (stores && store_differs(store_id, stores->peer_store_id)) return;  // of another parent's down stream
        if (stores && store_differs(child->store_id, stores->store_id)) {
          if (child->flips.saw(child->store_id, stores->store_id, "the child <" + child->iri + ">"))
            log("conflict: " + child->flips.said());
          if (child->flips.active()) disconnect_for_conflict(*child);
          return;
        }
        if (f.ack > issued_to_peers()) {
          lock.unlock();
          // P6a: a child that names this store and has applied more of its stream than it has
          // issued knows a store that was here before: this one was restored from a backup (the
          // child's hello carried no mark: its board named no parent store, as a child's from
          // before tv:parentStoreId). Taken as a mark, the child would drop this store's next
          // items as ones it has.
          if (stores && !stores->peer_store_id.empty())
            return renew_store_id("child <" + child->iri + "> acknowledges up to " + std::to_string(f.ack) +
                                  " of this store, which has issued less");
          // Never sent: taken, it would empty the child's down window of items it never had.
          return refuse(via, f.from, f.kind, 1, ack_beyond_issued(f.ack), "an ack beyond what this store sent");
        }
        child->last_seen = Clock::now();
        bool news = false;  // for the pump: room in the window, items to acknowledge, a go-back
        if (f.ack > child->down_mark) {
          child->down_mark = f.ack;
          child->down_progress = Clock::now();
          news = true;
          // It stored again: a later P9b of the same reason is a new episode, logged as such
          // (once per 10 s, so a child hovering at full is not a line per cycle).
          if (auto it = child_cannot_store.find(child->iri); it != child_cannot_store.end() && it->second.open) {
            it->second.open = false;
            log("child <" + child->iri + "> stores what this node sends down again");
          }
        }
        if (f.prev == 1 && (f.ack != child->went_back_to || Clock::now() - child->went_back_at > opt.resend_after)) {
          child->down_go_back = true;  // P8: once per mark and interval, not on every gap ack
          child->went_back_to = f.ack;
          child->went_back_at = Clock::now();
          news = true;
        }
        if (news) nudge_pump(*child);
        return;
      }
      case FrameKind::answer:
        return answer_from_child(via, f);
      case FrameKind::error:
        return error_from_child(f);
      default:
        refuse(via, f.from, f.kind, 1, "refused a frame of kind " + std::to_string(static_cast<int>(f.kind)) + " from child <" + f.from + ">",
               "kind " + std::to_string(static_cast<int>(f.kind)), /*answer=*/false);
    }
  }

  // P10c, downwards: a parent store restored from a backup sends again, on its new stream,
  // what its backup's down queue held, which this node applied from the stream `before`: the
  // new stream's items up to that stream's mark may repeat items held here.
  template <class AgentFn>
  void note_down_repeats(AgentFn& agent, const std::string& before, const std::string& after) {
    node::Agent* uplink = agent(std::string(kUplinkAgent));
    if (!uplink) return;
    auto mark = uplink->relay_mark(before);
    if (!mark) return log("cannot read the mark of " + before + ": " + mark.error().message);
    if (*mark == 0) return;
    if (auto said = uplink->relay_may_repeat(after, *mark, repeats_asserted_through()); !said)
      log("cannot note that " + after + " may repeat " + before + ": " + said.error().message);
  }

  // P10c: the items of a restored store's new stream asserted up to now (allowing for clocks
  // ahead) may repeat items held here, whatever their seq: what its children sent it again.
  static std::int64_t repeats_asserted_through() {
    return now_ns() + std::chrono::duration_cast<std::chrono::nanoseconds>(kRepeatClockAhead).count();
  }

  template <class AgentFn>
  void from_parent_frame(Transport* via, const Frame& f, AgentFn& agent) {
    switch (f.kind) {
      case FrameKind::welcome: {
        std::optional<wire::StateBody> state;
        if (!read_state(f, state)) return;
        // P6b: the welcome of another store of this node's IRI (a second node under it), whose
        // mark would empty this one's outbox of items never applied.
        if (state && store_differs(current_store_id(), state->peer_store_id)) return;
        // P6a: a parent that has applied more of this store's stream than the store has issued
        // knows a store that was here before (this one was restored from a backup): this store
        // takes a new id, and says hello with it.
        if (f.ack > issued_to_peers()) {
          renew_store_id("the parent <" + opt.parent_iri + "> has applied up to " + std::to_string(f.ack) +
                         " of this store, which has issued less");
          return;
        }
        std::unique_lock lock(mu);
        const auto now = Clock::now();
        if (state && ever_welcomed && store_differs(parent_store_id, state->store_id) &&
            now - parent_store_heard < opt.child_silence) {
          // P6b: the parent store that welcomed this node is alive; a store made again in its
          // place comes after it fell silent. Until then this welcome is not taken.
          if (pending_parent_store != state->store_id) {
            pending_parent_store = state->store_id;
            pending_parent_since = now;
          } else if (parent_store_heard > pending_parent_since + kBothAlive) {
            if (parent_flips.declare(parent_store_id, state->store_id, "the parent <" + opt.parent_iri + ">"))
              log("conflict: " + parent_flips.said());
            if (welcomed) log("the parent is not linked with while the conflict lasts");
            welcomed = false;
          }
          return;
        }
        const bool same_store_as_last_welcome = !state || state->store_id == parent_store_id;
        if (state && state->store_id != parent_store_id) pending_parent_store.clear();
        parent_store_heard = now;
        if (!welcomed) log("registered with the parent <" + opt.parent_iri + ">");
        if (state && state->store_id != parent_store_id) {
          // The store before: of this run, or the one an earlier run was welcomed by.
          const std::string was = parent_store_id.empty() ? parent_store_before : parent_store_id;
          if (!was.empty() && was != state->store_id)
            log("the parent <" + opt.parent_iri + "> has another store (id " + state->store_id + ", was " +
                was + "): what comes down is a new stream, from its start; " +
                (f.ack == 0 && (f.seq == kWelcomeFromACopy || state->store_id == copy_owed)
                     ? std::string("it is a copy (restored from a backup) that holds nothing of this node's stream: "
                                   "what went up to the stores before goes up again (P6e)")
                 : f.ack == 0 ? std::string("of what went up to the store before, only persistent items are sent again "
                                          "(P6c): the others it had are not in this one")
                            : "it holds this node's stream up to " + std::to_string(f.ack) +
                                  " (a store restored from a backup, which took a new id): what it lacks after that goes up again (P6d)"));
          if (parent_flips.saw(parent_store_id, state->store_id, "the parent <" + opt.parent_iri + ">"))
            log("conflict: " + parent_flips.said());
          const std::string before = !was.empty() && was != state->store_id ? std::string(kDownStream) + "#" + was : std::string();
          parent_store_id = state->store_id;
          parent_store_before.clear();
          if (!before.empty()) {
            const std::string after = down_stream();
            lock.unlock();  // a store write; this thread is the only one that takes welcomes
            note_down_repeats(agent, before, after);
            lock.lock();
          }
        }
        if (state && f.ack == 0 && f.seq == kWelcomeFromACopy) copy_owed = state->store_id;
        else if (state && f.ack != 0 && state->store_id == copy_owed) copy_owed.clear();  // it has had items since
        const bool from_a_copy = f.ack == 0 && state && !copy_owed.empty() && state->store_id == copy_owed;
        // P6b: while two stores take turns as the parent, this node links with neither: their
        // acknowledgements would empty its outbox of items that only one of them has.
        if (parent_flips.active()) {
          if (welcomed) log("the parent is not linked with while the conflict lasts");
          welcomed = false;
          return;
        }
        // A welcome hard on the heels of another from the same store answers a hello repeated
        // while the first was on its way (below: its mark is stale).
        const bool repeated = same_store_as_last_welcome && now - last_welcome_at < kStaleWelcome;
        welcomed = ever_welcomed = true;
        parent_left = false;
        parent_run = f.prev;
        // P6f: a repeated welcome does not put the time limit off; a new session has its own.
        if (!repeated || down_hold_through == 0) down_hold_until = now + kDownHoldMax;
        down_hold_through = state ? state->outbox_depth : 0;
        refused_by_parent.clear();
        parent_cannot_store.clear();  // said again by a parent that still cannot (P9b)
        // The parent holds nothing of this store's stream: a first welcome, or a parent store
        // made again (a replaced gateway) that never got what the one before it applied.
        // P6e: unless it is a copy (restored from a backup made before any of the stream
        // reached the store it was copied from), which lacks everything the stores before had.
        if (f.ack == 0 && !from_a_copy) {
          resend_persistent = true;
        } else if (!repeated) {
          // A welcome hard on the heels of another from the same store answers a hello repeated
          // while the first was on its way: its mark is stale, not a store gone back in time.
          requeue_after_welcome = true;
        }
        last_welcome_at = now;
        up_mark = f.ack;
        up_last_sent = f.ack;
        if (!repeated) up_sent_highest = f.ack;  // what went after the mark before did not reach this store
        up_mark_moved_at = now;
        ack_beyond_seen = 0;
        up_in_flight.clear();
        up_progress = Clock::now();
        up_backoff = 0;  // P8a: a new session
        up_mark_at_go_back = ~0ull;
        changed.notify_all();
        return;
      }
      case FrameKind::ack: {
        std::optional<wire::StateBody> stores;
        if (f.seq == 0 && !read_state(f, stores)) return;  // before `mu`, as the parent's ack case
        std::unique_lock lock(mu);
        if (f.seq != 0) {
          Outgoing out;
          answer_ack(f, out);
          lock.unlock();
          return send_all(out);
        }
        if (stores) {
          // P6b: from another store than the parent that welcomed this node: two parents under
          // one IRI.
          if (store_differs(parent_store_id, stores->store_id)) {
            if (parent_flips.saw(parent_store_id, stores->store_id, "the parent <" + opt.parent_iri + ">"))
              log("conflict: " + parent_flips.said());
            if (parent_flips.active() && welcomed) {
              log("the parent is not linked with while the conflict lasts");
              welcomed = false;
            }
            return;
          }
          if (!stores->store_id.empty()) parent_store_heard = Clock::now();
          // Of another store of this node's IRI: the parent holds that one as this node (a second
          // node under this IRI said hello after this one). This one says hello again, which
          // the parent sees as two stores taking turns.
          if (store_differs(store_id, stores->peer_store_id)) {
            // Said, at most once a minute: registration dropped without a word looked like a
            // link that stalls for no reason.
            if (!acked_another_said || Clock::now() - *acked_another_said >= 60s) {
              acked_another_said = Clock::now();
              log("the parent <" + opt.parent_iri + "> acknowledges another store of this node's IRI (id " + stores->peer_store_id +
                  "; this one is " + store_id + "): a second node under <" + self +
                  ">? This one says hello again; the parent logs a conflict while both do (P6b)");
            }
            welcomed = false;
            return;
          }
        }
        if (f.ack > issued_to_peers()) {
          // Never sent: taken, it would leave every later item in the outbox for good (the
          // outbox is emptied up to the mark, and the mark would never be passed again).
          ack_beyond_seen = f.ack;
          lock.unlock();
          return refuse(via, f.from, f.kind, 1, ack_beyond_issued(f.ack), "an ack beyond what this store sent");
        }
        if (f.ack > up_mark) {
          up_mark = f.ack;
          up_progress = up_mark_moved_at = Clock::now();
          ack_beyond_seen = 0;
          if (up_backoff > 0) --up_backoff;  // P8a
          if (!parent_cannot_store.empty()) {
            if (parent_cannot_store_said.open) log("the parent <" + opt.parent_iri + "> stores what this node sends again");
            parent_cannot_store_said.open = false;
            parent_cannot_store.clear();
          }
        }
        if (f.prev == 1 && (f.ack != up_went_back_to || Clock::now() - up_went_back_at > up_resend_after())) {
          up_go_back = true;  // P8: once per mark and interval, not on every gap ack
          up_went_back_to = f.ack;
          up_went_back_at = Clock::now();
        }
        changed.notify_all();
        return;
      }
      case FrameKind::query:
        return query_from_parent(via, f);
      case FrameKind::error: {
        auto body = wire::decode_error(f.body);
        if (!body) {  // it said "error from the parent: malformed", a line a frame
          dropped_malformed(f, "dropped a malformed error from the parent <" + f.from + ">: " + body.error().message);
          return;
        }
        std::string code = body->code;
        std::unique_lock lock(mu);
        if (code == kItemRefused) {
          ++counters.items_refused_by_peer;
          lock.unlock();
          error_said(f, "the parent refused item " + std::to_string(f.seq) + " (it stays in this node's store): " + body->message, code,
                     body->message);
          return;
        }
        if (code == kCannotStore) {
          const std::string why = body ? body->message : std::string("no reason given");
          CannotStoreSaid& said = parent_cannot_store_said;
          const bool new_kind = reason_kind(why) != reason_kind(said.why);
          // Said again only after the parent stored since (a store hovering at full); a parent
          // that stays full says so once a second, and that is one episode. One whose last line
          // is "stores again" (a late ack moved the mark) and that refuses on is said again 10 s
          // after: the log ended on "stores again" while the parent stored nothing for minutes.
          if (new_kind || ((parent_cannot_store.empty() || !said.open) && Clock::now() - said.at >= kRelayFailureSaidEvery)) {
            log("the parent <" + opt.parent_iri + "> cannot store what this node sends: " + why +
                "; items wait in the outbox, sent one at a time until it can" +
                (said.unsaid > 0 && !new_kind
                     ? " (and " + std::to_string(said.unsaid) + " times more since it was last said, storing some between)"
                     : ""));
            said = {why, Clock::now(), true, 0};
          } else if (parent_cannot_store.empty() || !said.open) {
            ++said.unsaid;
          }
          parent_cannot_store = why;
          return;
        }
        if (code == "cancelled" && f.seq != 0) {
          Outgoing out;
          cancel_from_parent(f, *body, out);
          lock.unlock();
          return send_all(out);
        }
        if (code == kLeaving && f.seq == 0) {  // P12d
          // A notice of another store than the one that welcomed this node (P6b) changes nothing.
          if (!welcomed || !body || store_differs(parent_store_id, body->origin)) return;
          if (f.ack != 0 && parent_run != 0 && f.ack != parent_run) {
            // Of the parent's run before the one that welcomed this node, come late (a DDS
            // writer outlives its process by about a second), as P12c's notices of a child.
            log("dropped a notice that the parent's link is stopping from a run before the one that welcomed this node "
                "(it came late)");
            return;
          }
          welcomed = false;
          parent_left = true;
          log("the parent <" + opt.parent_iri + ">'s link is stopping (it said so): link down until it is back");
          return;
        }
        if (code == "unregistered") {
          welcomed = false;
        } else if (code == "refused") {
          welcomed = false;
          const std::string why = body ? body->message : std::string("refused");
          if (why != refused_by_parent) log("the parent refused this node: " + why);  // not at every hello
          refused_by_parent = why;
        } else {
          lock.unlock();
          error_said(f, "error from the parent: " + wire::printable(code, 200) + ": " + body->message, code, body->message);
        }
        return;
      }
      default:
        refuse(via, f.from, f.kind, 1, "refused a frame of kind " + std::to_string(static_cast<int>(f.kind)) + " from the parent",
               "kind " + std::to_string(static_cast<int>(f.kind)), /*answer=*/false);
    }
  }

  // ---- queries ------------------------------------------------------------------------------

  void query_from_parent(Transport* via, const Frame& f) {
    auto q = wire::decode_query(f.body, f.version);
    if (!q) {
      dropped_malformed(f, "dropped a malformed query from the parent: " + q.error().message);
      return;
    }
    // The answer goes to the origin, up through this node's parent: an origin that is not a
    // node above this one (empty, made up) has no way there.
    if (q->origin == self || !uri::is_under(self, q->origin)) {
      log("dropped a query from the parent whose origin <" + wire::printable(q->origin, 200) + "> is not a node above <" + self + ">");
      return;
    }
    const std::string key = query_key(q->origin, f.seq);
    {
      std::lock_guard lock(mu);
      if (out_answers.count(key) || in_answers.count(key)) return;  // a resent query under way
    }
    if (q->target == self) {
      std::lock_guard lock(mu);
      OutStream& out = out_answers[key];
      out.origin = q->origin;
      out.query = f.seq;
      out.last_progress = Clock::now();
      out.reading = std::make_shared<Reading>();
      out.reading->q = std::move(*q);
      out.reading->id = f.seq;
      answers_due.notify_all();
      return;
    }
    std::string child_iri = child_on_path(self, q->target);
    Outgoing out;
    std::optional<wire::ErrorBody> unknown;  // said once `mu` is released: its hint reads the store
    {
      std::lock_guard lock(mu);
      auto it = child_iri.empty() ? children.end() : children.find(child_iri);
      // P15: in a young run, a child that is not connected yet (never heard, or not yet known to
      // a node that accepts any child) is most likely on its way back: the query is left
      // unanswered, and the parent's resend, a second later, finds it connected.
      const bool young = Clock::now() - run_started < opt.child_silence;
      const bool not_yet = it == children.end() ? opt.children.empty() && !child_iri.empty()
                                                : !it->second->connected && !it->second->ever;
      if (opt.down && young && not_yet) return;
      if (it == children.end() || !opt.down) {
        std::string hint;  // a child written with characters where the query percent-encodes them, or the other way
        for (const auto& [iri, child] : children)
          if (!child_iri.empty() && iri != child_iri && uri::percent_decoded(iri) == uri::percent_decoded(child_iri))
            hint = "; did you mean <" + iri + ">? (an IRI is compared as written: a character and its percent-encoding are two IRIs)";
        // Otherwise the children there are, as the asking node's own error names its own.
        if (hint.empty()) {
          std::vector<std::string> known;
          for (const auto& entry : children) known.push_back(entry.first);
          hint = detail::children_hint(std::move(known), "; it has no child node");
        }
        // Worded as the asking node words its own: "unknown node <T>: <here> has no child <C>".
        const std::string why = child_iri.empty() ? "not below <" + self + ">" : "<" + self + "> has no child <" + child_iri + ">";
        unknown = {"unknown_node", "<" + q->target + ">: " + why + hint, q->origin};
      } else if (!it->second->connected) {
        out.error(via, opt.parent_iri, f.seq,
                  {"unreachable", "<" + child_iri + ">" + (child_iri == q->target ? "" : " (on the way to <" + q->target + ">)") +
                                      (it->second->ever || it->second->ever_before ? " is down at <" : " has never connected to <") +
                                      self + ">" +  // as remote_query says it
                                      (it->second->left ? " (its link was stopped: it said so as it left)" : ""),
                   q->origin});
      } else if (auto why = unservable_by(child_iri, *q)) {
        out.error(via, opt.parent_iri, f.seq, {"query_failed", *why, q->origin});
      } else {
        Frame down = f;
        down.to = child_iri;
        down.body = wire::encode_query(*q).value();  // in this node's version, as send() says
        InStream& in = in_answers[key];
        in.forward_up = true;
        in.child = child_iri;
        in.target = q->target;
        in.query_frame = down;
        in.sent = Clock::now();
        out.add(via_to(child_iri), std::move(down));
      }
    }
    if (unknown) {
      // The IRI of an agent here (a recording's prefix, <…/ecg1/ecg>, taken for a node); a
      // spelling of a child's IRI said first.
      if (!child_iri.empty() && unknown->message.find("; did you mean <") == std::string::npos && names_an_agent_here(child_iri))
        unknown->message = "<" + q->target + ">: <" + self + "> has no child <" + child_iri + ">: <" + child_iri + "> is an agent of <" +
                           self + ">, not a node (ask --at <" + self + ">)";
      out.error(via, opt.parent_iri, f.seq, std::move(*unknown));
    }
    send_all(out);
  }

  // Whether the board of this node says `iri` made data here (detail::made_data): a
  // query --at an agent's IRI is told to ask the agent's node.
  bool names_an_agent_here(const std::string& iri) {
    std::lock_guard own_lock(own_mu);
    auto snap = own->snapshot();
    return snap && detail::made_data(*snap, iri);
  }

  // ---- answering a query on this node (P14) -------------------------------------------------
  //
  // One answerer thread reads the records of the queries asked of this node and packs them into
  // chunks as the parent acknowledges the ones before, never more than the window ahead. So an
  // operator asking a home for a day of raw ECG costs the home a window of chunks in memory, not
  // the day (the whole answer was read at once before: ~5x its size at the peak), and the
  // receive thread that took the query goes back to the node's children at once.

  std::condition_variable answers_due;  // with mu: a stream being read has room in its window,
                                        // or answers_up holds frames
  // With mu: answer chunks due to the parent that the receiving thread made due (a child's chunk
  // relayed, an ack that opened the window). The answerer sends them: a parent whose reader
  // stalls blocks a send for up to 1 s, and the thread that takes the children's items must not
  // wait on it.
  Outgoing answers_up;

  void answer_loop() {
    auto node = node::Node::open(opt.dir);
    if (!node) return log("cannot open the store: " + node.error().message);
    std::unique_lock lock(mu);
    while (!stopping) {
      if (!answers_up.frames.empty()) {
        Outgoing sends = std::exchange(answers_up, {});
        lock.unlock();
        send_all(sends);
        lock.lock();
        continue;
      }
      auto due = std::find_if(out_answers.begin(), out_answers.end(), [](const auto& e) {
        return e.second.reading && e.second.unacked.size() < kAnswerWindow;
      });
      if (due == out_answers.end()) {
        answers_due.wait_for(lock, 100ms);
        continue;
      }
      const std::string key = due->first;
      std::shared_ptr<Reading> reading = due->second.reading;
      const std::size_t room = kAnswerWindow - due->second.unacked.size();
      lock.unlock();
      std::vector<wire::AnswerBody> chunks;
      auto read = read_chunks(*node, *reading, room, chunks);
      std::vector<Frame> frames;
      for (auto& chunk : chunks) {
        Frame f;
        f.kind = FrameKind::answer;
        f.to = opt.parent_iri;
        f.seq = reading->id;
        f.body = wire::encode_answer(chunk);
        frames.push_back(std::move(f));
      }
      Outgoing window;
      lock.lock();
      auto it = out_answers.find(key);
      if (it == out_answers.end() || it->second.reading != reading) continue;  // forgotten meanwhile
      OutStream& out = it->second;
      if (!read) {
        out_answers.erase(it);
        window.error(opt.up.get(), opt.parent_iri, reading->id, {"query_failed", "<" + self + ">: " + read.error().message, reading->q.origin});
      } else {
        for (Frame& f : frames) {
          f.prev = out.next_chunk++;
          out.unacked.push_back(std::move(f));
        }
        if (reading->done) out.reading.reset();
        answer_window(out, window);
      }
      lock.unlock();
      send_all(window);
      lock.lock();
    }
  }

  // Reads on from where `r` stopped and packs the records into at most `room` full chunks, plus
  // the last chunk (possibly empty) once everything is read. Touches nothing but `r`, so it runs
  // without mu. A plain pattern is read page by page in record-id order up to the horizon (the
  // records present when the reading began), each page on a fresh snapshot, released at once
  // (a snapshot held for the whole answer would keep a ring store from reusing its pages). With
  // a cascade or an area the answer is read whole at the start, as `list` reads it: each record
  // appears once across the answer, which pages read on separate snapshots could not promise.
  node::Result<void> read_chunks(node::Node& node, Reading& r, std::size_t room, std::vector<wire::AnswerBody>& chunks) {
    auto snap = node.snapshot();
    if (!snap) return tahvel::unexpected(snap.error());
    const wire::QueryBody& q = r.q;
    node::Pattern pattern{.s = q.s, .p = q.p, .o = q.o, .since = q.since, .until = q.until};
    if (!q.source.empty()) pattern.source = q.source;
    if (!q.under.empty()) pattern.under = q.under;
    const bool whole = q.cascade > 0 || !q.area.empty();
    if (!r.started) {
      r.started = true;
      r.horizon = snap->last_seq();
      if (whole) {
        node::ListOptions options{.cascade = q.cascade, .limit = q.limit};
        node::Result<std::vector<node::Record>> found = std::vector<node::Record>{};
        if (q.area.empty()) found = snap->list(pattern, options);
        else if (opt.area_query) found = opt.area_query(*snap, pattern, q.area, q.floor, options);
        else found = node::fail(Errc::invalid_argument, "this node's link answers no queries by area");
        if (!found) return tahvel::unexpected(found.error());
        r.whole = std::move(*found);
      }
    }
    auto seal = [&](bool last) {
      r.chunk.origin = q.origin;
      r.chunk.last = last;
      chunks.push_back(std::move(r.chunk));
      r.chunk = {};
      r.chunk_bytes = 0;
    };
    // Makes room for `record` in the chunk being filled; false when `room` chunks are full and
    // the record must wait for the next call (it is then left as it was: a record moved into a
    // refused call was lost, and the next call sent it empty).
    auto room_for = [&](const node::Record& record) {
      const std::size_t size = record.triple.s.value.size() + record.triple.p.value.size() +
                               record.triple.o.value.size() + record.triple.o.datatype.size() + record.triple.o.language.size() +
                               record.meta.source.size() + record.meta.context.size() + 72;
      if (r.chunk_bytes > 0 && r.chunk_bytes + size > kAnswerChunkBytes) {
        if (chunks.size() >= room) return false;
        seal(false);
      }
      r.chunk_bytes += size;
      ++r.taken;
      return true;
    };
    bool exhausted = true;
    if (whole) {
      while (r.next_of_whole < r.whole.size()) {
        if (!room_for(r.whole[r.next_of_whole])) {
          exhausted = false;
          break;
        }
        r.chunk.records.push_back(std::move(r.whole[r.next_of_whole]));
        ++r.next_of_whole;
      }
    } else {
      pattern.after_id = r.cursor;
      auto walked = snap->for_each(pattern, [&](const node::Record& record) {
        if (record.meta.id > r.horizon) return false;     // stored after the query arrived
        if (q.limit && r.taken >= q.limit) return false;
        if (!room_for(record)) {
          exhausted = false;
          return false;
        }
        r.chunk.records.push_back(record);
        r.cursor = record.meta.id;
        return true;
      });
      if (!walked) return walked;
    }
    if (exhausted) {
      seal(true);
      r.done = true;
      r.whole = {};
    }
    return {};
  }

  // Caller holds mu: the chunks of `out` within its window that were not sent yet (with `again`,
  // the whole window: a resend), to send once mu is released.
  void answer_window(OutStream& out, Outgoing& window, bool again = false) {
    const std::size_t n = std::min(out.unacked.size(), kAnswerWindow);
    bool sent = false;
    for (std::size_t i = 0; i < n; ++i) {
      const Frame& f = out.unacked[i];
      if (!again && f.prev <= out.sent_through) continue;
      window.add(opt.up.get(), f);
      out.sent_through = std::max(out.sent_through, f.prev);
      sent = true;
    }
    if (sent) out.last_send = Clock::now();
  }

  // Caller holds mu. The parent acknowledged chunks of an answer stream of this node.
  void answer_ack(const Frame& f, Outgoing& window) {
    const std::string key = query_key(f.body, f.seq);
    auto it = out_answers.find(key);
    if (it == out_answers.end()) {
      // P15: an ack for an answer this node does not have: its link restarted (the stream was
      // in the memory of the run before) or it forgot the stream. The rest cannot come; the
      // asker is told now instead of at its timeout.
      if (!in_answers.count(key))
        window.error(opt.up.get(), opt.parent_iri, f.seq,
                     {"link_restarted", "<" + self + "> no longer has the answer to query " + std::to_string(f.seq) +
                                            " of <" + f.body + "> (its link restarted, or it forgot the stream)", f.body});
      return;
    }
    OutStream& out = it->second;
    if (f.ack <= out.acked_through) return;
    out.acked_through = f.ack;
    out.last_send = out.last_progress = Clock::now();  // progress: the resend timer starts again
    while (!out.unacked.empty() && out.unacked.front().prev <= f.ack) out.unacked.pop_front();
    answer_window(out, answers_up);
    answers_due.notify_all();
    // A node in the middle: the child may send on, as far as this node has room for.
    auto in = in_answers.find(key);
    if (in != in_answers.end() && in->second.forward_up) {
      in->second.passed = out.acked_through;
      window.add(via_to(in->second.child), answer_ack_to_child(in->second, f.seq, f.body));
    }
    if (out.unacked.empty() && !out.reading && !out.relaying) out_answers.erase(it);
  }

  // Caller holds mu. The acknowledgement of a child's answer chunks: those taken in order, but
  // at most kAnswerRelayAhead beyond the ones passed on (acknowledged by the parent, or written
  // on the board at the origin), so that a fast child and a slow parent or board cost this node
  // a bounded buffer; the child's window holds the rest back until this node sends a new ack.
  Frame answer_ack_to_child(const InStream& in, std::uint64_t query, const std::string& origin) {
    Frame ack;
    ack.kind = FrameKind::ack;
    ack.to = in.child;
    ack.seq = query;
    ack.ack = std::min<std::uint64_t>(in.expected - 1, in.passed + kAnswerRelayAhead);
    ack.body = origin;
    return ack;
  }

  // P18: tells `child` that query `query` (of `origin`) is cancelled.
  static Frame cancel_frame(const std::string& child, std::uint64_t query, const std::string& origin) {
    Frame f;
    f.kind = FrameKind::error;
    f.to = child;
    f.seq = query;
    f.body = wire::encode_error({"cancelled", "the query was cancelled at <" + origin + ">", origin});
    return f;
  }

  // Caller holds mu. P18: the parent cancelled a query this node answers or relays: its answer
  // stream ends here, and a child answering it is told in turn.
  void cancel_from_parent(const Frame& f, const wire::ErrorBody& body, Outgoing& out) {
    const std::string key = query_key(body.origin, f.seq);
    out_answers.erase(key);
    auto in = in_answers.find(key);
    if (in == in_answers.end() || in->second.cancelled) return;
    in->second.cancelled = in->second.done = true;
    out.add(via_to(in->second.child), cancel_frame(in->second.child, f.seq, body.origin));
  }

  void answer_from_child(Transport* via, const Frame& f) {
    auto body = wire::decode_answer(f.body);
    if (!body) {
      dropped_malformed(f, "dropped a malformed answer from <" + f.from + ">: " + body.error().message);
      return;
    }
    const std::string key = query_key(body->origin, f.seq);
    Outgoing out;
    std::unique_lock lock(mu);
    auto it = in_answers.find(key);
    if (it == in_answers.end()) {
      // A query this node no longer waits for (forgotten, or lost when it restarted): without a
      // cancel the child would resend its window for good (P18). Above, the asker may still
      // wait for the rest (P15): it is told the answer is lost. (At the origin an earlier run's
      // queries are ended at start, interrupt_earlier_queries.)
      out.add(via, cancel_frame(f.from, f.seq, body->origin));
      if (body->origin != self)
        out.error(opt.up.get(), opt.parent_iri, f.seq,
                  {"link_restarted", "<" + self + "> lost the answer to query " + std::to_string(f.seq) + " of <" + body->origin +
                                         "> coming up through <" + f.from + "> (its link restarted)", body->origin});
      lock.unlock();
      return send_all(out);
    }
    InStream& in = it->second;
    if (in.cancelled) {  // the child missed the cancel (P18): it comes again with each chunk
      out.add(via, cancel_frame(in.child, f.seq, body->origin));
      lock.unlock();
      return send_all(out);
    }
    const bool next = f.prev == in.expected && !in.done;
    if (next) {
      ++in.expected;
      in.last_progress = Clock::now();
      if (body->last) in.done = true;
    }
    if (in.forward_up) {
      OutStream& stream = out_answers[key];
      if (next) {
        stream.origin = body->origin;
        stream.query = f.seq;
        stream.last_progress = Clock::now();
        Frame up = f;
        up.to = opt.parent_iri;
        up.prev = stream.next_chunk++;
        stream.unacked.push_back(std::move(up));
        stream.relaying = !in.done;
        answer_window(stream, answers_up);
        answers_due.notify_all();
      }
      if (stream.unacked.empty() && !stream.reading && !stream.relaying) out_answers.erase(key);
    } else if (next) {
      board_writes.push_back({key, in.reply_to, f});
      board_due.notify_all();
    }
    out.add(via, answer_ack_to_child(in, f.seq, body->origin));
    lock.unlock();
    send_all(out);
  }

  // Caller holds mu. P15: the child answers of `child_iri` come from went down: the rest cannot
  // come. Each asker is told now (an error up, or on the board at the origin), not at its timeout.
  // `why` is completed with how far each answer had come ("before its first answer chunk", "after
  // 12 answer chunk(s)"): an operator told that a node went silent "while it answered" after
  // nothing came looks for a lost answer.
  void end_answers_from(const std::string& child_iri, const std::string& code, const std::string& why) {
    for (auto& [key, in] : in_answers) {
      if (in.child != child_iri || in.done || in.cancelled) continue;
      in.done = true;
      Frame f;
      f.kind = FrameKind::error;
      f.from = child_iri;
      f.seq = in.query_frame.seq;
      const std::string when = in.expected <= 1 ? " before its first answer chunk"
                                                : " after " + std::to_string(in.expected - 1) + " answer chunk(s)";
      // The node asked is named too when it lies below the child: "<home1> (on the way to
      // <home1/ecg1>) went silent", as the other errors of P15 say it.
      const std::string asked = in.target.empty() || in.target == child_iri ? "" : " (on the way to <" + in.target + ">)";
      std::string said = why;
      if (const std::string child_named = "<" + child_iri + ">"; !asked.empty() && said.starts_with(child_named))
        said.insert(child_named.size(), asked);
      f.body = wire::encode_error({code, said + when, key.substr(0, key.rfind('#'))});
      if (in.forward_up) {
        f.to = opt.parent_iri;
        answers_up.add(opt.up.get(), std::move(f));
        answers_due.notify_all();
      } else {
        f.to = self;
        board_writes.push_back({key, in.reply_to, std::move(f)});
        board_due.notify_all();
      }
    }
  }

  // P12c: a link stopped on purpose first lets what waits in its outbox go up and be
  // acknowledged, while its parent is up, for up to `limit`: the last items of a node taken out of
  // the file (a replay's end of recording) had arrived and their acknowledgement not, and `up`
  // said they never would go up.
  void drain_outbox(std::chrono::milliseconds limit) {
    {
      std::lock_guard lock(mu);
      if (!opt.up || !welcomed || !opt.say_leaving) return;
    }
    std::optional<node::Agent> uplink;
    {
      std::lock_guard own_lock(own_mu);
      auto agent = own->agent(kUplinkAgent);
      if (!agent) return;
      uplink.emplace(std::move(*agent));
    }
    const auto until = Clock::now() + limit;
    for (;;) {
      auto waiting = uplink->pending();
      if (!waiting || *waiting == 0 || Clock::now() >= until) return;
      {
        std::lock_guard lock(mu);
        if (!welcomed || parent_left) return;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
  }

  // P12c: said once, as the link stops on purpose (not when its process is killed), to a parent
  // that welcomed it, so that its queries and state say so at once rather than after child_silence.
  void say_leaving() {
    std::string own_store;
    {
      std::lock_guard lock(mu);
      if (!opt.up || !welcomed || !opt.say_leaving) return;
      own_store = store_id;
    }
    Outgoing out;
    out.error(opt.up.get(), opt.parent_iri, 0, {std::string(kLeaving), "<" + self + ">'s link stops", own_store});
    if (!out.frames.empty()) out.frames.back().second.ack = run;  // which run leaves (P12c), as its hellos said
    send_all(out);
  }

  // P12d: said once, as the link stops on purpose, to each child connected to it, as a child
  // says so to its parent (P12c): the child's state is "down" at once, not after child_silence
  // (a child showed its stopped parent "up, last heard 2.3 s ago").
  void say_leaving_to_children() {
    Outgoing out;
    {
      std::lock_guard lock(mu);
      if (!opt.say_leaving) return;
      for (const auto& [iri, child] : children) {
        if (!child->connected || !child->via) continue;
        const std::size_t before = out.frames.size();
        out.error(child->via, iri, 0, {std::string(kLeaving), "<" + self + ">'s link stops", store_id});
        if (out.frames.size() > before) out.frames.back().second.ack = run;
      }
    }
    send_all(out);
  }

  void error_from_child(const Frame& f) {
    auto body = wire::decode_error(f.body);
    if (!body) {
      dropped_malformed(f, "dropped a malformed error from <" + f.from + ">: " + body.error().message);
      return;
    }
    std::unique_lock lock(mu);
    if (body->code == kItemRefused) {
      ++counters.items_refused_by_peer;
      lock.unlock();
      error_said(f, "child <" + f.from + "> refused item " + std::to_string(f.seq) + " sent down (it stays in this node's store): " +
                        body->message, body->code, body->message);
      return;
    }
    if (body->code == kCannotStore) {  // P9b: once per reason; the child's mark stays put or moves by parts meanwhile
      CannotStore& episode = child_cannot_store[f.from];
      const auto now = Clock::now();
      if (reason_kind(episode.said) != reason_kind(body->message) || (!episode.open && now - episode.at >= kRelayFailureSaidEvery)) {
        log("child <" + f.from + "> cannot store what this node sends down: " + body->message);
        episode.said = body->message;
        episode.at = now;
        episode.open = true;
      }
      return;
    }
    if (body->code == kLeaving) {  // P12c
      auto it = children.find(f.from);
      if (it == children.end() || !it->second->connected || store_differs(it->second->store_id, body->origin)) return;
      Child& child = *it->second;
      if (f.ack != 0 && child.run != 0 && f.ack != child.run) {
        // Its store's id does not tell two runs apart: a notice of the run before, delivered
        // after the new run's hello (a DDS writer outlives its process by about a second),
        // would take the new one as down until its next heartbeat.
        log("child <" + f.from + ">: dropped a notice that its link is stopping from a run before the one registered "
            "(it came late)");
        return;
      }
      if (child.run == 0 && Clock::now() - child.hello_while_up_at < kBothAlive) {
        // A link that names no run (session 79): a hello while it was up within the second
        // before is most likely a new run, and the notice its run before's.
        log("child <" + f.from + ">: dropped a notice that its link is stopping, heard within " + seconds_text(kBothAlive) +
            " of a hello it said while up (its link names no run: taken as its run before's, late)");
        return;
      }
      child.connected = false;
      child.left = true;
      child.state_dirty = true;
      log("child <" + f.from + ">'s link is stopping (it said so): link down");
      end_answers_from(f.from, "unreachable", "<" + f.from + ">'s link was stopped at <" + self + "> (it said so as it left)");
      board_due.notify_all();
      return;
    }
    if (f.seq == 0) {
      lock.unlock();
      error_said(f, "error from child <" + f.from + ">: " + wire::printable(body->code, 200) + ": " + body->message, body->code,
                 body->message);
      return;
    }
    const std::string key = query_key(body->origin, f.seq);
    auto it = in_answers.find(key);
    if (it == in_answers.end() || it->second.done) return;
    it->second.done = true;
    if (it->second.forward_up) {
      Frame up = f;
      up.to = opt.parent_iri;
      answers_up.add(opt.up.get(), std::move(up));  // sent by the answerer, as the chunks are
      answers_due.notify_all();
    } else {
      board_writes.push_back({key, it->second.reply_to, f});
      board_due.notify_all();
    }
  }

  // ---- child role: up sender ----------------------------------------------------------------

  // An item whose frame no binding takes (P4: bodies up to 64 MiB) could never be sent: it is
  // passed over in the stream (the next frame chains to the one before it) and stays in this
  // store, rather than being retried for ever ahead of everything after it (as P9a at the
  // receiver).
  bool fits_a_frame(const Frame& f, std::uint64_t item) {
    if (f.body.size() <= wire::kMaxBody) return true;
    log("item " + std::to_string(item) + " is not sent to <" + f.to + "> (it stays in this store): its frame body of " +
        std::to_string(f.body.size()) + " bytes is over the links' limit of " + std::to_string(wire::kMaxBody));
    ++counters.items_refused;
    return false;
  }

  void up_loop() {
    auto node = node::Node::open(opt.dir);
    if (!node) return log("cannot open the store: " + node.error().message);
    auto uplink = node->agent(kUplinkAgent);
    if (!uplink) return log("cannot open agent uplink: " + uplink.error().message);
    std::uint64_t acked_locally = 0;
    Clock::time_point trimmed{};  // when the outbox last lost what the parent applied
    UnderAncestor from_this_subtree(self);
    if (std::error_code ec; std::filesystem::exists(narrowing_marker(), ec)) {
      std::lock_guard lock(mu);
      policy_narrowed = true;  // P6f: an earlier run stopped between a narrowing and its withdrawal
    }
    while (!stopping) {
      std::uint64_t after = 0, mark = 0;
      std::size_t room = 0;
      bool resend = false, requeue = false;
      // P6f: items above this id that the forwarding policy does not route leave the outbox
      // before it is read again (none: the largest id).
      std::uint64_t withdraw_above = std::numeric_limits<std::uint64_t>::max();
      {
        std::unique_lock lock(mu);
        if (!welcomed) {
          changed.wait_for(lock, 100ms);
          continue;
        }
        if (down_hold_through != 0) {
          // P6f: what came down while this node was away first (a forwarding policy narrowed
          // meanwhile keeps at home what the old one queued).
          const bool applied = down_applied_stream == down_stream() && down_applied_mark >= down_hold_through;
          if (!applied && Clock::now() < down_hold_until) {
            changed.wait_for(lock, 20ms);
            continue;
          }
          if (!applied)
            log("sends up again before applying what the parent's welcome said waits for it (through item " +
                std::to_string(down_hold_through) + " of its down queue; its down stream stood for " + seconds_text(kDownHoldMax) + ")");
          down_hold_through = 0;
        }
        while (!up_in_flight.empty() && up_in_flight.front() <= up_mark) up_in_flight.pop_front();
        if (up_go_back || (!up_in_flight.empty() && Clock::now() - up_progress > up_resend_after())) {
          up_last_sent = up_mark;  // P8: go back to the parent's mark
          up_in_flight.clear();
          up_go_back = false;
          up_progress = Clock::now();
          ++counters.up_resends;
          // P8a: a go-back that the last one did not get past is a sign of a path that loses
          // what it is given (a LAN or radio at its capacity): resending the whole window every
          // resend_after multiplied what a sensor offered it 23-fold, and its gateway's own
          // uplink went down with it, for a cut of a tenth of the capacity.
          if (up_mark == up_mark_at_go_back && up_backoff < kMaxBackoff) ++up_backoff;
          up_mark_at_go_back = up_mark;
        }
        mark = up_mark;
        after = up_last_sent;
        // P8: a parent not heard for child_silence (stopped, or cut off) gets one frame per
        // go-back, a probe, not the window: a sensor resent 512 items every resend_after onto
        // its LAN for as long as its gateway was down. Any frame from it opens the window again.
        const bool parent_silent = Clock::now() - parent_heard > opt.child_silence;
        const std::size_t window = parent_silent || !parent_cannot_store.empty() ? 1 : up_window();
        room = window > up_in_flight.size() ? window - up_in_flight.size() : 0;
        if (room == 0) {
          changed.wait_for(lock, 20ms);
          continue;
        }
        if (std::exchange(policy_narrowed, false)) withdraw_above = std::max(up_mark, up_sent_highest);
        resend = std::exchange(resend_persistent, false);
        requeue = std::exchange(requeue_after_welcome, false);
      }
      if (withdraw_above != std::numeric_limits<std::uint64_t>::max()) {
        // What went up stays sent: the parent may hold it, and a removal here goes after it (P7a).
        // Above the welcome's mark nothing is at the parent (it applies a stream in order).
        // Here, in the only thread that reads the outbox to send, so that nothing read before
        // the withdrawal goes up after it.
        auto withdrawn = uplink->withdraw_unrouted(withdraw_above);
        if (!withdrawn)
          log("cannot take out of the outbox what the narrowed forwarding policy keeps here: " + withdrawn.error().message);
        else if (*withdrawn > 0)
          log("the forwarding policy was narrowed: " + std::to_string(*withdrawn) +
              " item(s) it no longer sends, queued in the outbox and not yet sent, stay on this node");
        std::lock_guard lock(mu);
        if (withdrawn && !policy_narrowed && !relaying_may_narrow) mark_narrowing(false);
      }
      if (resend) {
        // P6c: what the parent's agents need for everything after (an ECG recording's
        // description, sent once) was applied by the store before; this one gets it too.
        if (auto again = uplink->deliver_persistent_again(); !again) {
          log("cannot queue the persistent items for the parent again: " + again.error().message);
        } else if (*again > 0) {
          log("the parent <" + opt.parent_iri + "> holds nothing of this store's stream (a new store in its place): " +
              std::to_string(*again) + " persistent item(s) its policy routes go up again");
          acked_locally = 0;  // they have ids below what the store before acknowledged
        }
      }
      if (requeue) {
        // P6d: the outbox is emptied up to the parent's mark only, so what it lacks after the
        // welcome's mark and before what waits in the outbox was acknowledged by a store the
        // parent no longer is (restored from a backup). Read up to the first item waiting, not
        // the whole store: a link restarted with a long backlog looks at no more than its gap.
        auto waiting = uplink->peek(mark, 1, 0ms);
        const std::uint64_t before = waiting && !waiting->empty() ? waiting->front().item : std::numeric_limits<std::uint64_t>::max();
        // Only what goes up: items relayed down from above are never sent (P7).
        auto again = uplink->deliver_again_between(mark, before, self);
        if (again && mark == 0) {
          std::lock_guard lock(mu);
          copy_owed.clear();
        }
        if (!again) {
          log("cannot queue for the parent again what it acknowledged before its mark went back: " + again.error().message);
        } else if (*again > 0 && mark == 0) {
          log("the parent <" + opt.parent_iri + "> holds nothing of this store's stream, restored from a backup: " +
              std::to_string(*again) + " item(s) the stores before had acknowledged go up again (P6e)");
          acked_locally = 0;
        } else if (*again > 0) {
          log("the parent <" + opt.parent_iri + "> holds this store's stream up to " + std::to_string(mark) +
              " only, though it had acknowledged more (its store restored from a backup?): " + std::to_string(*again) +
              " item(s) it acknowledged after that go up again (P6d)");
          acked_locally = std::min(acked_locally, mark);
        }
      }
      auto ready = uplink->peek(after, room, 50ms);
      if (!ready) {
        log("reading the outbox failed: " + ready.error().message);
        std::this_thread::sleep_for(100ms);
        continue;
      }
      std::vector<std::uint64_t> from_above;
      std::vector<Frame> frames;
      std::unique_lock lock(mu);
      if (!welcomed || up_last_sent != after) continue;  // the session moved meanwhile
      const std::uint64_t own_tag = store_tags(store_id, parent_store_id);  // P6b
      for (const auto& d : *ready) {
        wire::ItemBody body = item_of(d);
        if (!from_this_subtree(body.source)) {
          // Written above this node (relayed down): never goes back up (P7).
          from_above.push_back(d.item);
          continue;
        }
        Frame f;
        f.kind = FrameKind::up;
        f.to = opt.parent_iri;
        f.seq = d.item;
        f.prev = up_last_sent;
        f.ack = own_tag;
        f.body = wire::encode_item(body);
        if (!fits_a_frame(f, d.item)) {
          from_above.push_back(d.item);  // acknowledged here, as those are
          continue;
        }
        frames.push_back(std::move(f));
        if (up_in_flight.empty()) up_progress = Clock::now();
        up_in_flight.push_back(d.item);
        up_last_sent = d.item;
        up_sent_highest = std::max(up_sent_highest, d.item);
        note_sent(d.item);
        ++counters.up_sent;
      }
      for (std::size_t k = 0; k + 1 < frames.size(); ++k) frames[k].ack |= kMoreFollow;  // P9b
      if (!frames.empty() && up_in_flight.size() * 2 >= up_window()) frames.back().ack |= kAckNow;  // P8
      mark = up_mark;
      lock.unlock();
      // Only this thread sends up frames, so they leave in the order of the stream; a go-back
      // meanwhile (an ack of the parent) at worst has some of them sent twice, which P9 drops.
      send_run(opt.up.get(), frames);
      for (std::uint64_t id : from_above) (void)uplink->ack(id);
      // What the parent applied leaves the outbox after the send, not before the peek (a new
      // item goes up first, and this store transaction runs while it travels), and at most every
      // kOutboxTrimEvery: under a steady stream an ack comes every ack_delay, and a write of the
      // home's store for each was in a third of the slowest 2% of a hop (docs/bench.md, session
      // 23). Items the parent applied but still here are not sent again: a new session starts
      // after the parent's mark (P8).
      if (mark > acked_locally && Clock::now() - trimmed >= kOutboxTrimEvery) {
        if (auto a = uplink->ack_through(mark); a) acked_locally = mark;
        trimmed = Clock::now();
      }
    }
    // Stopping: what the parent applied leaves the outbox now, so that what is left there is
    // what it lacks (`tahvel up` withdraws from it what a narrowed policy keeps home).
    std::uint64_t applied = 0;
    {
      std::lock_guard lock(mu);
      applied = welcomed ? up_mark : 0;
    }
    if (applied > acked_locally) (void)uplink->ack_through(applied);
  }

  // ---- parent role: one down pump for all children ------------------------------------------
  //
  // One thread sends down to every connected child (P10). It reads a child's down queue when
  // the queue got an item (Agent::buffer_version moved), when the receiver nudged it (a hello,
  // an ack that moved the mark or asked to go back) or when its oldest frame in flight is due
  // for a resend; in between it sleeps in Node::wait_for_commit. A thread per child (1,000 at a
  // hospital, each waking to re-check its window) cost the hospital ~4% of its CPU, and a hello
  // storm woke them all to fight over `mu` (docs/bench.md).

  std::vector<std::shared_ptr<Child>> pump_new;  // welcomed for the first time; under mu
  std::atomic<bool> pump_nudged{false};
  std::optional<node::Node> waker;  // for wake_waiters(), from any thread

  // Has the pump read `child`'s queue again soon. Caller holds mu.
  void nudge_pump(Child& child) {
    child.pump_dirty = true;
    pump_nudged.store(true);
    if (waker) waker->wake_waiters();
  }

  struct Pumped {
    std::shared_ptr<Child> child;
    node::Agent agent;             // the child as an agent of this node: its down queue
    std::uint32_t version = 0;     // agent.buffer_version() when the queue was last read
    std::uint64_t acked_locally = 0;
    bool read = true;              // read the queue at the next visit
    Clock::time_point due{};       // visit by then with no news (a resend)
  };

  void pump_loop() {
    auto node = node::Node::open(opt.dir);
    if (!node) return log("cannot open the store: " + node.error().message);
    std::vector<Pumped> pumped;
    while (!stopping) {
      // Before the visits: a nudge during them makes the wait below return at once.
      const bool nudged = pump_nudged.exchange(false);
      std::vector<std::shared_ptr<Child>> fresh;
      {
        std::lock_guard lock(mu);
        fresh.swap(pump_new);
      }
      std::vector<std::shared_ptr<Child>> retry;
      for (auto& child : fresh) {
        auto agent = node->agent(child->id);
        if (!agent) {
          // A store error now must not leave the child unserved for good: tried again after
          // the idle wait.
          log("cannot open agent " + child->id + ": " + agent.error().message + "; trying again");
          retry.push_back(child);
          continue;
        }
        pumped.push_back({child, std::move(*agent)});
      }
      if (!retry.empty()) {
        std::lock_guard lock(mu);
        pump_new.insert(pump_new.end(), retry.begin(), retry.end());
      }
      auto due = Clock::now() + kIdlePumpWait;
      for (auto& p : pumped) {
        // Only children with news or a resend due; a nudge (rare) has every child visited.
        if (nudged || !fresh.empty() || p.read || p.agent.buffer_version() != p.version || Clock::now() >= p.due)
          p.due = visit(p);
        due = std::min(due, p.due);
      }
      auto left = due - Clock::now();
      if (left <= Clock::duration::zero()) continue;
      node->wait_for_commit(
          [&] {
            if (stopping || pump_nudged.load()) return true;
            for (const auto& p : pumped)
              if (p.agent.buffer_version() != p.version) return true;
            return false;
          },
          left);
    }
  }

  // Sends what a child's window has room for, goes back on a gap or a stalled mark (P8), and
  // acknowledges locally what the child applied. Returns when it next needs a visit with no news
  // (a resend due), at the latest a far time.
  Clock::time_point visit(Pumped& p) {
    Child& child = *p.child;
    constexpr auto kNever = Clock::time_point::max();
    // Read before the queue: an item routed after this moves it again, and the pump comes back.
    const std::uint32_t version = p.agent.buffer_version();
    std::uint64_t after = 0, mark = 0;
    std::size_t room = 0;
    {
      std::lock_guard lock(mu);
      if (version != p.version) p.read = true;
      if (std::exchange(child.pump_dirty, false)) p.read = true;
      p.version = version;
      if (!child.connected) return kNever;  // a hello nudges it
      while (!child.down_in_flight.empty() && child.down_in_flight.front() <= child.down_mark)
        child.down_in_flight.pop_front();
      const auto now = Clock::now();
      if (child.down_go_back ||
          (!child.down_in_flight.empty() && now - child.down_progress > opt.resend_after)) {
        child.down_last_sent = child.down_mark;
        child.down_in_flight.clear();
        child.down_go_back = false;
        child.down_progress = now;
        p.read = true;
      }
      const auto resend = child.down_in_flight.empty() ? kNever : child.down_progress + opt.resend_after;
      // A child's new store (P10b) applies from 0 again: what goes down again, with ids below
      // the old store's mark, is acknowledged here as the new one applies it.
      if (child.down_mark < p.acked_locally) p.acked_locally = child.down_mark;
      mark = child.down_mark;
      after = child.down_last_sent;
      room = opt.window > child.down_in_flight.size() ? opt.window - child.down_in_flight.size() : 0;
      if (!p.read && mark <= p.acked_locally) return resend;
      if (room == 0) return resend;  // p.read stays: the ack that makes room nudges
    }
    if (mark > p.acked_locally) {
      if (auto a = p.agent.ack_through(mark); a) p.acked_locally = mark;
    }
    if (!p.read) return resend_time(child);
    auto ready = p.agent.peek(after, room, 0ms);
    if (!ready) {
      log("reading the down queue of <" + child.iri + "> failed: " + ready.error().message);
      return Clock::now() + 100ms;  // p.read stays
    }
    p.read = ready->size() >= room;  // a full window's worth: there may be more
    std::vector<std::uint64_t> local_acks;
    std::vector<Frame> frames;
    Transport* via = nullptr;
    {
      std::lock_guard lock(mu);
      via = via_to(child.iri);
      if (!child.connected || child.down_last_sent != after) {
        p.read = true;  // the session moved meanwhile (a hello, which nudged): read again
        return Clock::now();
      }
      for (const auto& d : *ready) {
        wire::ItemBody body = item_of(d);
        if (uri::is_under(body.source, child.iri)) {  // came up from that child
          local_acks.push_back(d.item);
          continue;
        }
        if (object_of(d.records, vocab::kQueryTarget)) {
          // A query item's removal (answered, cancelled) is the query's own business (P18).
          if (d.removal) {
            local_acks.push_back(d.item);
            continue;
          }
          if (auto query = start_query(child, d)) frames.push_back(std::move(*query));
          local_acks.push_back(d.item);
          continue;
        }
        body.item.context = subtree_for(body.item.context, child.iri);  // P11
        Frame f;
        f.kind = FrameKind::down;
        f.to = child.iri;
        f.seq = d.item;
        f.prev = child.down_last_sent;
        f.ack = store_tags(store_id, child.store_id);  // P6b
        f.body = wire::encode_item(body);
        if (!fits_a_frame(f, d.item)) {
          local_acks.push_back(d.item);
          continue;
        }
        frames.push_back(std::move(f));
        if (child.down_in_flight.empty()) child.down_progress = Clock::now();
        child.down_in_flight.push_back(d.item);
        child.down_last_sent = d.item;
        note_sent(d.item);
      }
      auto last = std::find_if(frames.rbegin(), frames.rend(), [](const Frame& f) { return f.kind == FrameKind::down; });
      for (auto f = frames.rbegin(); f != frames.rend(); ++f)
        if (f->kind == FrameKind::down && f != last) f->ack |= kMoreFollow;  // P9b
      if (last != frames.rend() && child.down_in_flight.size() * 2 >= opt.window) last->ack |= kAckNow;  // P8
    }
    // Only this thread sends down frames, in the order of each child's stream.
    send_run(via, frames);
    // Items not sent down are done with here; they leave the queue now (outside the lock).
    for (std::uint64_t id : local_acks) (void)p.agent.ack(id);
    return resend_time(child);
  }

  Clock::time_point resend_time(const Child& child) {
    std::lock_guard lock(mu);
    return child.down_in_flight.empty() ? Clock::time_point::max() : child.down_progress + opt.resend_after;
  }

  // A query item written on this board (the origin) for a node below `child` (P13): the query
  // frame to send, now kept for resends; none when `child` cannot carry it, which the asker is
  // told on the board. Caller holds mu.
  std::optional<Frame> start_query(const Child& child, const node::Delivery& d) {
    wire::QueryBody q;
    q.origin = self;
    const node::Term* target = object_of(d.records, vocab::kQueryTarget);
    const node::Term* reply_to = object_of(d.records, vocab::kReplyTo);
    q.target = target->value;
    auto as_asked = [](const node::Term& t) {
      return t.is_literal() && t.datatype == vocab::kBlankNodeLabel ? node::Term::blank(t.value) : t;
    };
    if (auto t = object_of(d.records, vocab::kQuerySubject)) q.s = as_asked(*t);
    if (auto t = object_of(d.records, vocab::kQueryPredicate)) q.p = *t;
    if (auto t = object_of(d.records, vocab::kQueryObject)) q.o = as_asked(*t);
    q.since = integer_of(d.records, vocab::kQuerySince);
    q.until = integer_of(d.records, vocab::kQueryUntil);
    q.cascade = static_cast<std::uint32_t>(integer_of(d.records, vocab::kQueryCascade).value_or(0));
    q.limit = static_cast<std::uint64_t>(integer_of(d.records, vocab::kQueryLimit).value_or(0));
    if (auto t = object_of(d.records, vocab::kQueryArea)) q.area = t->value;
    q.floor = integer_of(d.records, vocab::kQueryFloor);
    if (auto t = object_of(d.records, vocab::kQuerySource)) q.source = t->value;
    if (auto t = object_of(d.records, vocab::kQueryUnder)) q.under = t->value;
    Frame f;
    f.kind = FrameKind::query;
    f.to = child.iri;
    f.seq = d.item;
    f.body = wire::encode_query(q).value();  // in this node's version, which has every field
    const std::string key = query_key(self, d.item);
    InStream& in = in_answers[key];
    in.reply_to = reply_to ? reply_to->value : std::string();
    in.target = q.target;
    if (auto why = unservable_by(child.iri, q)) {
      in.done = true;
      Frame error;
      error.kind = FrameKind::error;
      error.from = child.iri;
      error.to = self;
      error.seq = d.item;
      error.body = wire::encode_error({"query_failed", *why, self});
      board_writes.push_back({key, in.reply_to, std::move(error)});
      board_due.notify_all();
      return std::nullopt;
    }
    in.child = child.iri;
    in.query_frame = f;
    in.sent = Clock::now();
    // Capped at a year: a timeout beyond it is "never" and must not overflow the clock.
    if (auto ms = integer_of(d.records, vocab::kQueryTimeout); ms && *ms > 0)
      in.expires = in.sent + std::chrono::milliseconds(std::min<std::int64_t>(*ms, 365ll * 24 * 3600 * 1000)) + kAskerGrace;
    return f;
  }

  // ---- timer: hello/heartbeat, silence, state triples, resends, answers on the board ----------

  void timer_loop() {
    auto node = node::Node::open(opt.dir);
    if (!node) return log("cannot open the store: " + node.error().message);
    auto link = node->agent(kLinkAgent);
    auto uplink = node->agent(kUplinkAgent);
    if (!link || !uplink) return log("cannot open the link's agents");
    if (opt.down) interrupt_earlier_queries(*node, *link);
    // Answer chunks go on the board as base64 literals in parts this store takes (P14).
    std::size_t answer_part = kAnswerPartMax;
    if (auto st = node->stats(); st && st->max_literal_bytes > 0)
      answer_part = std::max<std::size_t>(4, std::min<std::size_t>(answer_part, st->max_literal_bytes) / 4 * 4);
    Clock::time_point next_beat{};
    std::chrono::nanoseconds hello_gap{0};  // after the last hello, before the random move; 0 while welcomed (P6)
    // P11a: agents of this node that items from above address and nothing here knows. An earlier
    // run's problem is not this run's to keep: it would stay on the board, said by no one.
    std::set<std::string> unknown_addressees;
    Clock::time_point next_addressee_check{};
    say_problem(*link);  // an earlier run's problem is not this run's to keep
    Clock::time_point held_checked{};
    while (!stopping) {
      std::vector<BoardWrite> writes;
      std::vector<std::shared_ptr<Child>> dirty;
      std::vector<std::string> held_lines;
      bool beat = false, parent_went_silent = false;
      Outgoing resends;
      {
        std::unique_lock lock(mu);
        // While answer chunks wait on the board, look often for the asker having taken them.
        const bool unread = std::any_of(in_answers.begin(), in_answers.end(), [](const auto& e) { return !e.second.unread.empty(); });
        const auto waited_from = Clock::now();
        board_due.wait_for(lock, unread ? 5ms : 50ms, [&] { return !board_writes.empty() || stopping.load(); });
        writes.assign(std::make_move_iterator(board_writes.begin()), std::make_move_iterator(board_writes.end()));
        board_writes.clear();
        const auto now = Clock::now();
        if (now - held_checked >= 1s) {  // a walk over every sender: not at every round
          held_lines = held_already_due(now);
          held_checked = now;
        }
        // Hellos back off to kHelloGapMax while the parent is away, longer than child_silence:
        // the first heartbeat after a welcome kept the hello's time, and the parent called the
        // child silent (and the child its parent) a few seconds after welcoming it.
        if (welcomed && next_beat - now > opt.heartbeat_every) next_beat = now + opt.heartbeat_every;
        if (now >= next_beat) {
          beat = true;
          // A refused node asks again at the heartbeat's pace, not four times a second.
          // So does one whose parent said it is stopping (P12d): its heartbeats kept that pace
          // before, and a parent restarted on purpose (its supervisor, an upgrade) has it back
          // within a heartbeat, not after a hello backed off to 4 s.
          if (welcomed || !refused_by_parent.empty() || parent_left) {
            next_beat = now + opt.heartbeat_every;
            hello_gap = {};
          } else {
            const HelloGap gap = next_hello_gap(hello_gap, opt.heartbeat_every);
            hello_gap = gap.base;
            next_beat = now + std::chrono::duration_cast<Clock::duration>(gap.wait);
          }
        }
        const std::int64_t wall = now_ns();
        // The wait above ends within 50 ms. A longer one is this process not running (stopped by
        // a signal, a paused machine): its children and its parent were not heard because it
        // did not listen, so each keeps the silence it had left, rather than being declared down
        // at once (a gateway stopped for 24 s logged that its parent "has not been heard for
        // 24.8 s", and its parent was fine). Only the wait: the round's board writes may take
        // long on a busy store while the receiving threads hear on.
        const auto stalled = now - waited_from - std::chrono::milliseconds(50);
        if (stalled > kOwnStall) {
          for (auto& [iri, child] : children) child->last_seen = std::min(now, child->last_seen + stalled);
          if (opt.up) parent_heard = std::min(now, parent_heard + stalled);
          log("this process did not run for " + seconds_text(stalled) +
              " (stopped by a signal, or the machine paused): its parent and children keep the silence they had left");
        }
        for (auto& [iri, child] : children) {
          if (child->connected && now - child->last_seen > opt.child_silence) {
            child->connected = false;
            child->state_dirty = true;
            log("child <" + iri + "> silent for " + std::to_string(opt.child_silence.count()) + " ms: link down");
            end_answers_from(iri, "unreachable", "<" + iri + "> went silent at <" + self + ">");
          }
          if (child->connected && wall - child->state_written_ns > kStateRefreshNs) child->state_dirty = true;
          if (child->flips.said() != child->conflict_written) child->state_dirty = true;  // a conflict ended (P6b)
          if (child->state_dirty) dirty.push_back(child);
        }
        // The parent's silence is told as the parent tells a child's: at the round it passes
        // child_silence, not at the next heartbeat (which made it "up" for up to a second more).
        parent_went_silent = opt.up && welcomed && own_state_logged == "up" && now - parent_heard > opt.child_silence;
        for (auto& [key, out] : out_answers)
          if (!out.unacked.empty() && now - out.last_send > opt.resend_after) answer_window(out, resends, true);
        // Resends are not progress: a parent that never acknowledges again is given up on.
        std::erase_if(out_answers, [&](const auto& e) { return now - e.second.last_progress > kAnswerForgetAfter; });
        std::erase_if(in_answers, [&](const auto& e) {
          return now - std::max(e.second.sent, e.second.last_progress) > kAnswerForgetAfter;
        });
        for (auto& [key, in] : in_answers) {
          if (!in.done && in.expected == 1 && now - in.sent > 1s && in.resends < 10) {
            ++in.resends;
            in.sent = now;
            resends.add(via_to(in.child), in.query_frame);
          }
          // P15: a child that sent part of an answer and went quiet is sent its ack again; one
          // whose link restarted since answers that it no longer has the stream.
          if (!in.done && !in.cancelled && in.expected > 1 &&
              now - std::max(in.last_progress, in.last_keepalive) > kAnswerKeepalive) {
            in.last_keepalive = now;
            resends.add(via_to(in.child), answer_ack_to_child(in, in.query_frame.seq, key.substr(0, key.rfind('#'))));
          }
        }
      }
      for (const std::string& line : held_lines) log(line);
      send_all(resends);
      if (beat && opt.up) {
        auto depth = uplink->pending();
        Frame f;
        f.to = opt.parent_iri;
        std::string stream, parent_store;
        {
          std::lock_guard lock(mu);
          f.kind = welcomed ? FrameKind::heartbeat : FrameKind::hello;
          stream = down_stream();
          parent_store = parent_store_id;
          if (parent_store.empty() && !parent_store_before.empty()) {
            parent_store = parent_store_before;
            stream = std::string(kDownStream) + "#" + parent_store_before;
          }
        }
        // A heartbeat names this store too: a parent then sees a second node under this IRI (P6b).
        wire::StateBody state{opt.software_version, depth ? *depth : 0, current_store_id(), "", store_room()};
        if (f.kind == FrameKind::hello) {
          auto down_mark = uplink->relay_mark(stream);
          f.ack = down_mark ? *down_mark : 0;
          f.prev = run;  // P12c: its leaving notice names the same
          state.peer_store_id = parent_store;
        }
        f.body = wire::encode_state(state);
        send(opt.up.get(), std::move(f));
        write_own_state(*link, depth ? *depth : 0);
      } else if (parent_went_silent) {
        auto depth = uplink->pending();
        write_own_state(*link, depth ? *depth : 0);
      }
      std::vector<std::pair<const BoardWrite*, std::uint64_t>> written;
      // The chunks that came meanwhile go on the board in one transaction: one commit (one sync
      // on a durable store) for a window of chunks, not one each. Should that fail, one by one,
      // so that only the chunk that cannot be written fails its query.
      std::vector<node::Item> items;
      for (const BoardWrite& w : writes) items.push_back(answer_item(w.reply_to, w.frame, answer_part));
      std::optional<std::vector<std::uint64_t>> ids;
      if (items.size() > 1) {
        if (auto all = link->store_all(items)) ids = std::move(*all);
      }
      for (std::size_t k = 0; k < writes.size(); ++k) {
        const BoardWrite& w = writes[k];
        if (ids) {
          written.emplace_back(&w, (*ids)[k]);
          continue;
        }
        auto id = write_answer(*link, w.reply_to, w.frame, answer_part);
        if (!id && w.frame.kind == FrameKind::answer) answer_not_written(*link, w, id.error(), answer_part);
        written.emplace_back(&w, id ? *id : 0);
      }
      std::vector<std::uint64_t> abandoned;
      Outgoing acks = acks_for_chunks_read(*node, written, abandoned);
      send_all(acks);
      for (std::uint64_t item : abandoned) (void)node->remove_item(item);
      write_child_states(*link, dirty);
      if (opt.up) look_at_addressees(*node, *link, unknown_addressees, next_addressee_check);
      say_problem(*link);
    }
  }

  // P11a: an item from above addressed (R18) to an agent of this node that nothing here knows —
  // no program runs as it, it subscribes to nothing and no agent of this node has written about
  // it — waits in that agent's input buffer for ever: a typo in the --context at the hospital,
  // two hops up, was stored without a word anywhere. Said as the link's problem, which `status`
  // shows on this node and on the machines above, until each such agent is known; looked at
  // again every second while any is not. What items from above say about the agent does not make
  // it known: such an item is usually about its own addressee.
  void look_at_addressees(node::Node& node, node::Agent& link, std::set<std::string>& unknown, Clock::time_point& next_check) {
    std::vector<std::string> contexts;
    {
      std::lock_guard lock(mu);
      contexts.swap(down_contexts);
    }
    const auto now = Clock::now();
    if (contexts.empty() && (unknown.empty() || now < next_check)) return;
    next_check = now + 1s;
    std::set<std::string> candidates = unknown, still_unknown;
    for (const std::string& context : contexts)
      if (auto agent = node.addressee(context)) candidates.insert(*agent);
    {  // released before the problem is written
      auto snap = node.snapshot();
      if (!snap) return;
      auto any = [&](const node::Pattern& pattern) {
        bool found = false;
        auto read = snap->for_each(pattern, [&](const node::Record&) { return !(found = true); });
        return found || !read;  // a read error is no reason to complain
      };
      // Index lookups only (by subject, by predicate and object): this runs every second while
      // an agent is unknown, on stores of millions of records.
      const node::Term subscriber = node::Term::iri(std::string(vocab::kTv) + "subscriber");
      const node::Term area_subscriber = node::Term::iri(std::string(vocab::kTv) + "areaSubscriber");  // docs/spatial.md
      for (const std::string& agent : candidates) {
        const node::Term who = node::Term::iri(agent);
        if (!any({.s = who, .source = self}) && !any({.p = subscriber, .o = who, .source = self}) &&
            !any({.p = area_subscriber, .o = who, .source = self}))
          still_unknown.insert(agent);
      }
    }
    // The problem is what waits for such an agent: once nothing does (the item removed above,
    // P10a, and so from the buffer; or taken), there is nothing to say, though the agent stays
    // unknown. It stayed said until the link restarted.
    std::erase_if(still_unknown, [&](const std::string& agent) {
      auto id = uri::child_id(agent, self);
      auto handle = id ? node.agent(*id) : node::Result<node::Agent>(unexpected(node::Error{}));
      auto waiting = handle ? handle->pending() : node::Result<std::uint64_t>(unexpected(handle.error()));
      return waiting && *waiting == 0;
    });
    if (still_unknown == unknown) return;
    std::string names;
    for (const std::string& agent : still_unknown) names += (names.empty() ? "<" : ", <") + agent + ">";
    const std::string problem =
        still_unknown.empty() ? std::string()
                              : "configuration from above addresses " + names + ", which nothing on <" + self +
                                    "> knows (no program of that id runs here, it subscribes to nothing, and nothing here "
                                    "has written of it): it waits in that agent's input buffer until one takes it (a typo in "
                                    "the item's context, or an agent not deployed here?)";
    addressee_problem = problem;
    say_problem(link);
    log(problem.empty() ? "every agent that configuration from above addresses is known here now" : problem);
    unknown = std::move(still_unknown);
  }

  // The link's problem on the board (report_problem keeps one per agent), for `tahvel status`:
  // what waits for agents nothing here knows (P11a) and the would-be children whose hellos it
  // refuses (P6), together. The refusals go from it once the sender is welcomed, or has not
  // tried for kRefusedHelloShownFor. Written when the text changes (the run loop's thread only).
  std::string addressee_problem, problem_said;
  bool problem_written = false;
  Clock::time_point problem_retry_at{};  // after a failed write (a full store): not at every turn
  void say_problem(node::Agent& link) {
    std::string refusals, stall;
    {
      std::lock_guard lock(mu);
      const auto now = Clock::now();
      std::erase_if(refused_hellos, [&](const auto& r) { return now - r.second.last > kRefusedHelloShownFor; });
      for (const auto& [from, r] : refused_hellos) refusals += (refusals.empty() ? "" : "; ") + ("<" + from + ">: " + r.why);
      // Items in flight, the parent heard, and its mark still: the link is up and the stream
      // stands. Up to session 82 `status` said "link up" while a sensor's outbox grew for minutes.
      const auto stands_for = 2 * opt.child_silence;
      if (opt.up && welcomed && !up_in_flight.empty() && now - parent_heard < opt.child_silence &&
          now - up_mark_moved_at > stands_for) {
        stall = "the parent <" + opt.parent_iri + "> has applied nothing this node sent for over " + seconds_text(stands_for) +
                " though it is heard; items wait in the outbox";
        if (ack_beyond_seen != 0)
          stall += ": it acknowledges up to " + std::to_string(ack_beyond_seen) + ", past all this store sent (" +
                   std::to_string(issued_to_peers()) +
                   "), so its mark of this node's stream is wrong and it takes what comes for repeats (a forged frame on "
                   "the network? docs/protocol.md, Trust)";
        else if (!parent_cannot_store.empty())
          stall += ": it cannot store them (" + parent_cannot_store + ")";
      }
    }
    std::string text = addressee_problem;
    if (!refusals.empty()) text += (text.empty() ? "" : "; ") + std::string("refuses the hello of ") + refusals;
    if (!stall.empty()) text += (text.empty() ? "" : "; ") + stall;
    if (text == problem_said && problem_written) return;
    if (Clock::now() < problem_retry_at) return;
    if (auto said = link.report_problem(text); !said) {
      problem_retry_at = Clock::now() + std::chrono::seconds(10);
      return log("cannot write the link's problem: " + said.error().message);
    }
    problem_said = text;
    problem_written = true;
  }

  // P13: queries asked on this board that an earlier run of the link had sent down. Their answer
  // streams' state was in that run's memory, so the rest of an answer cannot come: the asker is
  // told at once (error `link_restarted`, exit 1 for `tahvel query`) instead of at its timeout, and
  // the node below is told to stop (P18). The query stays known, cancelled, so that a dead asker's
  // items are still cleared kAskerGrace after its timeout. Queries still waiting in a child's
  // queue are not touched: the down pump sends them as usual.
  void interrupt_earlier_queries(node::Node& node, node::Agent& link) {
    auto snap = node.snapshot();
    if (!snap) return log("cannot read the board for earlier queries: " + snap.error().message);
    auto asked = snap->list({.p = node::Term::iri(vocab::kQueryTarget)});
    if (!asked) return log("cannot read the board for earlier queries: " + asked.error().message);
    for (const node::Record& r : *asked) {
      const std::uint64_t query = r.meta.item;
      const std::string child = child_on_path(self, r.triple.o.value);
      auto records = snap->item(query);
      if (child.empty() || !records) continue;
      auto queue = node.agent(child.substr(self.size() + 1));
      if (!queue) continue;
      auto waiting = queue->peek(query - 1, 1, 0ms);
      if (!waiting || (!waiting->empty() && waiting->front().item == query)) continue;
      const node::Term* reply_to = object_of(*records, vocab::kReplyTo);
      if (!reply_to) continue;
      const std::string key = query_key(self, query);
      {
        std::lock_guard lock(mu);
        if (in_answers.count(key)) continue;  // sent by this run's pump meanwhile
      }
      Frame error;
      error.kind = FrameKind::error;
      error.seq = query;
      error.body = wire::encode_error({"link_restarted",
                                       "the link of <" + self + "> restarted while the query ran; what was not printed is lost: ask again",
                                       self});
      // The earlier run's chunks still on the board go with the query when it ends.
      std::vector<std::uint64_t> unread = answers_on_board(node, reply_to->value, query);
      const auto stored = write_answer(link, reply_to->value, error, kAnswerPartMax);
      const std::uint64_t written = stored ? *stored : 0;
      log("query " + std::to_string(query) + " of <" + reply_to->value + "> was under way when this link stopped: told its asker");
      Outgoing cancel;
      {
        std::lock_guard lock(mu);
        InStream& in = in_answers[key];
        in.reply_to = reply_to->value;
        in.child = child;
        in.query_frame.seq = query;
        in.done = in.cancelled = true;
        in.sent = in.last_progress = Clock::now();
        for (std::uint64_t item : unread) in.unread.emplace_back(0, item);
        if (written != 0) in.unread.emplace_back(0, written);
        if (auto ms = integer_of(*records, vocab::kQueryTimeout); ms && *ms > 0) {
          const std::int64_t left_ns = r.meta.stored_at + std::min<std::int64_t>(*ms, 365ll * 24 * 3600 * 1000) * 1'000'000 - now_ns();
          in.expires = in.sent + std::chrono::nanoseconds(std::max<std::int64_t>(left_ns, 0)) + kAskerGrace;
        }
        cancel.add(via_to(child), cancel_frame(child, query, self));
      }
      send_all(cancel);
    }
  }

  // The answer items of `query` in the input buffer of the asking agent `reply_to`.
  std::vector<std::uint64_t> answers_on_board(node::Node& node, const std::string& reply_to, std::uint64_t query) {
    std::vector<std::uint64_t> items;
    auto id = uri::child_id(reply_to, self);
    if (!id) return items;
    auto asker = node.agent(*id);
    if (!asker) return items;
    auto waiting = asker->peek(0, 1024, 0ms);
    if (!waiting) return items;
    for (const node::Delivery& d : *waiting) {
      auto to = integer_of(d.records, vocab::kAnswerTo);
      if (to && static_cast<std::uint64_t>(*to) == query) items.push_back(d.item);
    }
    return items;
  }

  // The chunks just `written` on the board (item ids; 0 when the write failed) wait there until
  // the asking agent has taken them off; those taken, in chunk order, are passed on, and the
  // children may send on (answer_ack_to_child). Chunks are written only here, at the origin, so
  // their origin is this node. A query whose item the asker removed before its answer was all
  // read is cancelled (P18): the child is told, and the chunks still on the board go to
  // `abandoned`, for the caller to remove. So is a query whose item outlives its asker's timeout
  // by kAskerGrace (the asker died without removing it); its item goes to `abandoned` too.
  Outgoing acks_for_chunks_read(node::Node& node, const std::vector<std::pair<const BoardWrite*, std::uint64_t>>& written,
                                std::vector<std::uint64_t>& abandoned) {
    std::lock_guard lock(mu);
    for (const auto& [w, item] : written) {
      auto it = in_answers.find(w->key);
      if (it == in_answers.end() || w->frame.kind != FrameKind::answer) continue;
      if (!it->second.cancelled) it->second.unread.emplace_back(w->frame.prev, item);
      else if (item != 0) abandoned.push_back(item);  // taken from the child just before the cancel
    }
    Outgoing acks;
    std::optional<node::Snapshot> snap;
    const auto now = Clock::now();
    for (auto& [key, in] : in_answers) {
      // A cancelled query has no unread chunks, but for one interrupted by a restart (its error).
      if (in.forward_up || (in.cancelled && in.unread.empty())) continue;
      const bool expired = now >= in.expires;
      if (in.done && in.unread.empty() && !expired) continue;
      if (!snap) {
        auto s = node.snapshot();
        if (!s) {
          log("cannot read the board for answers taken: " + s.error().message);
          return acks;
        }
        snap.emplace(std::move(*s));
      }
      auto asked = snap->item(in.query_frame.seq);
      if ((!asked && asked.error().code == Errc::not_found) || expired) {
        if (asked) {
          log("query " + std::to_string(in.query_frame.seq) + " of <" + in.reply_to +
              "> is still on the board after its timeout: its asker is gone; removed with its answer");
          abandoned.push_back(in.query_frame.seq);
        }
        for (const auto& [chunk, item] : in.unread)
          if (item != 0) abandoned.push_back(item);
        in.unread.clear();
        if (!in.done) acks.add(via_to(in.child), cancel_frame(in.child, in.query_frame.seq, self));
        in.cancelled = in.done = true;
        continue;
      }
      const std::uint64_t before = in.passed;
      while (!in.unread.empty()) {
        const auto [chunk, item] = in.unread.front();
        if (item != 0) {
          auto still = snap->item(item);
          if (still || still.error().code != Errc::not_found) break;
        }
        in.passed = std::max(in.passed, chunk);
        in.unread.pop_front();
      }
      if (in.passed != before) acks.add(via_to(in.child), answer_ack_to_child(in, in.query_frame.seq, self));
    }
    return acks;
  }

  // An answer chunk or error on the origin's board, addressed to the asking agent (P16); the
  // item's id, or 0 when it could not be written (logged).
  node::Result<std::uint64_t> write_answer(node::Agent& link, const std::string& reply_to, const Frame& f, std::size_t part) {
    auto stored = link.store(answer_item(reply_to, f, part));
    if (!stored) log("cannot write an answer for <" + reply_to + ">: " + stored.error().message);
    return stored;
  }

  // The item of write_answer.
  static node::Item answer_item(const std::string& reply_to, const Frame& f, std::size_t part) {
    node::Item item;
    item.context = reply_to;
    const node::Term a = node::Term::blank("answer");
    item.add(a, node::Term::iri(vocab::kAnswerTo), node::Term::integer(static_cast<std::int64_t>(f.seq)));
    if (f.kind == FrameKind::answer) {
      auto body = wire::decode_answer(f.body);
      item.add(a, node::Term::iri(vocab::kAnswerChunk), node::Term::integer(static_cast<std::int64_t>(f.prev)));
      item.add(a, node::Term::iri(vocab::kAnswerLast),
               node::Term::literal(body && body->last ? "true" : "false", std::string(node::xsd::kBoolean)));
      // In parts, in order: one record of the target may be as large as the target's literal
      // limit allows, which may be more than this store's.
      const std::string encoded = detail::base64_encode(f.body);
      std::size_t at = 0;
      do {
        item.add(a, node::Term::iri(vocab::kAnswerRecords),
                 node::Term::literal(encoded.substr(at, part), std::string(node::xsd::kBase64Binary)));
        at += part;
      } while (at < encoded.size());
    } else {
      auto body = wire::decode_error(f.body);
      item.add(a, node::Term::iri(vocab::kErrorCode), node::Term::literal(body ? body->code : "malformed"));
      item.add(a, node::Term::iri(vocab::kErrorMessage), node::Term::literal(body ? body->message : "malformed error"));
    }
    return item;
  }

  // A chunk that could not be written on the board (a full store, I/O) would leave the asker
  // waiting for it until its timeout: it is told now (query_failed), and the answer is
  // cancelled below (P18).
  void answer_not_written(node::Agent& link, const BoardWrite& w, const node::Error& why, std::size_t part) {
    Frame failed;
    failed.kind = FrameKind::error;
    failed.seq = w.frame.seq;
    failed.body = wire::encode_error({"query_failed", "answer chunk " + std::to_string(w.frame.prev) + " could not be written on the board of <" + self + ">: " + why.message, self});
    (void)write_answer(link, w.reply_to, failed, part);
    Outgoing cancel;
    {
      std::lock_guard lock(mu);
      auto it = in_answers.find(w.key);
      if (it == in_answers.end() || it->second.done) return;
      it->second.cancelled = it->second.done = true;
      cancel.add(via_to(it->second.child), cancel_frame(it->second.child, it->second.query_frame.seq, self));
    }
    send_all(cancel);
  }

  // Each child's state as one persistent item about the child, replacing the previous one, also
  // one left by an earlier run of the link (P12): the records about the child that agent `link`
  // wrote are removed in the transaction that stores the new item. Up to kStatesPerWrite
  // children share a transaction: a thousand children whose heartbeats change their outbox depth
  // cost a hospital a few transactions a second instead of two per child (store, then remove),
  // which took a tenth of its CPU during ingest (docs/bench.md); a chunk keeps each transaction
  // short, since the relays of children's items wait for the store's one writer.
  void write_child_states(node::Agent& link, const std::vector<std::shared_ptr<Child>>& dirty) {
    constexpr std::size_t kStatesPerWrite = 64;
    for (std::size_t first = 0; first < dirty.size(); first += kStatesPerWrite) {
      const std::size_t end = std::min(dirty.size(), first + kStatesPerWrite);
      std::vector<node::Pattern> previous;
      std::vector<node::Item> items;
      {
        std::lock_guard lock(mu);
        for (std::size_t k = first; k < end; ++k) {
          Child& child = *dirty[k];
          items.push_back(state_item(child));
          child.conflict_written = child.flips.said();
          child.state_dirty = false;
          child.state_written_ns = now_ns();
          previous.push_back({.s = node::Term::iri(child.iri), .source = link.iri()});
        }
      }
      if (auto stored = link.replace(previous, items); !stored)
        say_state_write_failure(state_write_failure, "the state of " + std::to_string(items.size()) + " child(ren)",
                                stored.error().message);
    }
  }
  // The last failure to write the children's state, as logged (write_child_states' thread only).
  struct StateWriteFailure {
    std::string why;
    Clock::time_point at{};
    std::uint64_t unsaid = 0;
  } state_write_failure, uplink_state_write_failure;
  // "cannot write <what>: <why>", once per 10 s and kind of reason (P9b's lines): a full store
  // refused a state every 1-2 s, a line each.
  void say_state_write_failure(StateWriteFailure& said, const std::string& what, const std::string& why) {
    const bool new_kind = reason_kind(why) != reason_kind(said.why);
    if (new_kind || Clock::now() - said.at >= kRelayFailureSaidEvery) {
      log("cannot write " + what + ": " + why +
          (said.unsaid > 0 && !new_kind ? " (and " + std::to_string(said.unsaid) + " times more since it was last said)" : ""));
      said = {why, Clock::now(), 0};
    } else {
      ++said.unsaid;
    }
  }

  // P12a: this node's view of its uplink as one persistent item about the node, written by its
  // agent `link` when what it says changes and every kStateRefreshNs while the link is up, so
  // that `tahvel status` on a machine without the parent can say how the uplink is.
  void write_own_state(node::Agent& link, std::uint64_t outbox_depth) {
    node::Item item;
    item.persistent = true;
    const node::Term me = node::Term::iri(self);
    std::string said, went;  // went: the link going down or up again, for the log
    {
      std::lock_guard lock(mu);
      const auto silence = Clock::now() - parent_heard;
      const bool silent = welcomed && silence > opt.child_silence;
      const std::string state = !refused_by_parent.empty() ? "refused"
                                : welcomed && !silent      ? "up"
                                : ever_welcomed || welcomed_before ? "down"
                                                                   : "never connected";
      // The parent logs a silent child; the child logs its silent parent, which it sees only as
      // frames that stop coming.
      // Down while the parent is heard: this node must say hello again (the parent answered
      // "unregistered": its link restarted, or it found this node silent while this process
      // was stopped; or this node's store or the parent's changed).
      if (state == "down" && own_state_logged == "up" && parent_left)
        went = "items wait in the outbox (" + std::to_string(outbox_depth) + ") until the parent <" + opt.parent_iri +
               "> is back";
      else if (state == "down" && own_state_logged == "up" && silence <= opt.child_silence)
        went = "the parent <" + opt.parent_iri + "> is heard, but this node must say hello to it again: link down until "
               "it is welcomed; items wait in the outbox (" + std::to_string(outbox_depth) + ")";
      else if (state == "down" && own_state_logged == "up")
        went = "the parent <" + opt.parent_iri + "> has not been heard for " + seconds_text(silence) +
               ": link down; items wait in the outbox (" + std::to_string(outbox_depth) + ") until it is heard again";
      else if (state == "up" && own_state_logged == "down" && !silent)
        went = "the parent <" + opt.parent_iri + "> is heard again: link up";
      own_state_logged = state;
      const std::string conflict = parent_flips.said();
      const std::string refusal = !refused_by_parent.empty()     ? refused_by_parent
                                  : !parent_cannot_store.empty() ? "the parent cannot store what this node sends: " + parent_cannot_store
                                                                 : std::string();
      said = state + " " + std::to_string(outbox_depth) + " " + refusal + " " + conflict + " " + parent_store_id;
      const std::int64_t wall = now_ns();
      if (said == own_state_said && !(state == "up" && wall - own_state_written_ns > kStateRefreshNs)) return;
      own_state_said = said;
      own_state_written_ns = wall;
      item.add(me, node::Term::iri(vocab::kParent), node::Term::iri(opt.parent_iri));
      item.add(me, node::Term::iri(vocab::kUplinkState), node::Term::literal(state));
      if (parent_heard_ns) item.add(me, node::Term::iri(vocab::kParentLastHeard), node::Term::integer(parent_heard_ns));
      if (const std::string& parent_store = parent_store_id.empty() ? parent_store_before : parent_store_id; !parent_store.empty())
        item.add(me, node::Term::iri(vocab::kParentStoreId), node::Term::literal(parent_store));
      item.add(me, node::Term::iri(vocab::kOutboxDepth), node::Term::integer(static_cast<std::int64_t>(outbox_depth)));
      if (!refusal.empty()) item.add(me, node::Term::iri(vocab::kUplinkRefusal), node::Term::literal(refusal));
      if (!conflict.empty()) item.add(me, node::Term::iri(vocab::kLinkConflict), node::Term::literal(conflict));
    }
    if (!went.empty()) log(went);
    if (auto stored = link.replace({{.s = node::Term::iri(self), .source = link.iri()}}, {item}); !stored) {
      say_state_write_failure(uplink_state_write_failure, "this node's uplink state", stored.error().message);
      std::lock_guard lock(mu);
      own_state_said.clear();  // again at the next beat
    }
  }

  // Caller holds mu.
  node::Item state_item(const Child& child) const {
    node::Item item;
    item.persistent = true;
    const node::Term c = node::Term::iri(child.iri);
    item.add(c, node::Term::iri(vocab::kParent), node::Term::iri(self));
    item.add(c, node::Term::iri(vocab::kLinkState),
             node::Term::literal(child.connected ? "up" : (child.ever || child.ever_before ? "down" : "never connected")));
    if (child.last_seen_ns) item.add(c, node::Term::iri(vocab::kLastSeen), node::Term::integer(child.last_seen_ns));
    item.add(c, node::Term::iri(vocab::kOutboxDepth), node::Term::integer(static_cast<std::int64_t>(child.outbox_depth)));
    if (!child.version.empty()) item.add(c, node::Term::iri(vocab::kSoftwareVersion), node::Term::literal(child.version));
    if (child.room) {
      const auto bytes = [](std::uint64_t n) { return node::Term::integer(static_cast<std::int64_t>(std::min<std::uint64_t>(n, std::numeric_limits<std::int64_t>::max()))); };
      item.add(c, node::Term::iri(vocab::kStoreUsedBytes), bytes(child.room->used_bytes));
      item.add(c, node::Term::iri(vocab::kStoreDataBytes), bytes(child.room->data_bytes));
      item.add(c, node::Term::iri(vocab::kStoreMaxBytes), bytes(child.room->max_bytes));
      if (child.room->disk_free_bytes != ~0ull)  // not known to the child
        item.add(c, node::Term::iri(vocab::kDiskFreeBytes), bytes(child.room->disk_free_bytes));
    }
    if (const std::string& store = child.store_id.empty() ? child.store_before : child.store_id; !store.empty())
      item.add(c, node::Term::iri(vocab::kChildStoreId), node::Term::literal(store));
    if (const std::string conflict = child.flips.said(); !conflict.empty())
      item.add(c, node::Term::iri(vocab::kLinkConflict), node::Term::literal(conflict));
    if (!child.connected && child.left) item.add(c, node::Term::iri(vocab::kLinkLeft), node::Term::literal("true", std::string(node::xsd::kBoolean)));
    return item;
  }
};

Link::Link(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}

Link::~Link() { stop(); }

void Link::stop() {
  if (!impl_ || impl_->stopping.load()) return;
  impl_->drain_outbox(std::chrono::seconds(1));
  if (impl_->stopping.exchange(true)) return;
  impl_->changed.notify_all();
  impl_->board_due.notify_all();
  impl_->answers_due.notify_all();
  if (impl_->waker) impl_->waker->wake_waiters();  // the down pump
  for (auto& t : impl_->threads) t.join();
  impl_->threads.clear();
  std::vector<std::string> held_lines;  // what the receivers dropped since the last line
  {
    std::lock_guard lock(impl_->mu);
    held_lines = impl_->held_already_due(Clock::now(), true);
  }
  for (const std::string& line : held_lines) impl_->log(line);
  // P12c, once this run sends nothing more: a heartbeat after it, answered "unregistered", could
  // have had a hello follow it, and the parent take the child as up again as it died.
  impl_->say_leaving();
  impl_->say_leaving_to_children();
}

bool Link::connected() const {
  std::lock_guard lock(impl_->mu);
  return impl_->welcomed;
}

LinkCounters Link::counters() const {
  std::lock_guard lock(impl_->mu);
  return impl_->counters;
}

Result<std::unique_ptr<Link>> Link::start(LinkOptions options) {
  auto node = node::Node::open(options.dir);
  if (!node) return Unexpected<Error>{node.error()};
  // P4: every peer would drop what it sent, and never say why to it.
  if (node->iri().size() > kMaxFrameIriBytes)
    return node::fail(Errc::invalid_argument, "the node IRI is " + std::to_string(node->iri().size()) + " bytes, over the " +
                                                  std::to_string(kMaxFrameIriBytes) + " a link frame's sender may have (P4)");
  if (!options.parent_iri.empty()) {
    if (!options.up) return node::fail(Errc::invalid_argument, "a parent IRI needs a transport to the parent");
    auto id = uri::child_id(node->iri(), options.parent_iri);
    if (!id)
      return node::fail(Errc::invalid_argument, "<" + node->iri() + "> cannot be a child of <" + options.parent_iri +
                                                    ">: a child's IRI is its parent's IRI + \"/\" + an id");
  }
  if (!options.also_down.empty() && !options.down)
    return node::fail(Errc::invalid_argument, "also_down without down: a node listens on `down` first");
  for (const auto& transport : options.also_down) {
    if (!transport || transport == options.down || transport == options.up)
      return node::fail(Errc::invalid_argument, "also_down holds a null transport or one already given as up or down");
  }
  std::vector<std::shared_ptr<Transport>> bound{options.up, options.down};
  bound.insert(bound.end(), options.also_down.begin(), options.also_down.end());
  for (const auto& transport : bound) {
    if (transport && transport->self() != node->iri())
      return node::fail(Errc::invalid_argument, "transport bound to <" + transport->self() + ">, not to the node <" + node->iri() + ">");
  }
  auto impl = std::make_unique<Impl>();
  impl->self = node->iri();
  auto store_id = node->store_id();
  if (!store_id) return Unexpected<Error>{store_id.error()};
  impl->store_id = *store_id;
  auto own = node::Node::open(options.dir);
  if (!own) return Unexpected<Error>{own.error()};
  impl->own.emplace(std::move(*own));
  impl->seq_at_start = impl->last_seq_here();
  if (options.up) {
    auto uplink = node->agent(kUplinkAgent);
    if (!uplink) return Unexpected<Error>{uplink.error()};
    auto policy = options.forward;
    if (policy.empty()) {
      // A new store gets the default; an existing one keeps the policy it has (P5).
      auto snap = node->snapshot();
      if (!snap) return Unexpected<Error>{snap.error()};
      auto subs = snap->count({.p = node::Term::iri(std::string(vocab::kTv) + "subscriber"), .o = node::Term::iri(uplink->iri())});
      if (!subs) return Unexpected<Error>{subs.error()};
      if (*subs == 0 && options.default_forward) policy = default_forward_policy();
    }
    // P7a: a removal follows what went up. Set before the first subscription, so that every
    // item the policy routes is remembered as given to the uplink (P6c, P6d send only those again).
    if (auto r = uplink->receive_removals(); !r) return Unexpected<Error>{r.error()};
    for (const auto& pattern : policy) {  // its own, beside a parent's identical one (`up` too)
      if (auto s = uplink->subscribe(pattern, {.own_only = true}); !s) return Unexpected<Error>{s.error()};
    }
    // P12a: what an earlier run said of this uplink, so that a link restarted while its parent
    // is away says "down" and when the parent was last heard.
    auto link_agent = node->agent(kLinkAgent);
    if (!link_agent) return Unexpected<Error>{link_agent.error()};
    auto snap = node->snapshot();
    if (!snap) return Unexpected<Error>{snap.error()};
    const node::Term me = node::Term::iri(node->iri());
    auto states = snap->list({.s = me, .p = node::Term::iri(vocab::kUplinkState), .source = link_agent->iri()});
    if (!states) return Unexpected<Error>{states.error()};
    for (const auto& r : *states)
      if (r.triple.o.value == "up" || r.triple.o.value == "down") impl->welcomed_before = true;
    if (impl->welcomed_before) {
      auto heard = snap->list({.s = me, .p = node::Term::iri(vocab::kParentLastHeard), .source = link_agent->iri()});
      if (!heard) return Unexpected<Error>{heard.error()};
      if (!heard->empty()) {
        const std::string& text = heard->back().triple.o.value;
        std::from_chars(text.data(), text.data() + text.size(), impl->parent_heard_ns);
      }
    }
    auto parent_store = snap->list({.s = me, .p = node::Term::iri(vocab::kParentStoreId), .source = link_agent->iri()});
    if (!parent_store) return Unexpected<Error>{parent_store.error()};
    // Only of this parent: a node moved under another would name a store of its old parent in
    // its hellos, and a copy at the new one would ask it for all it ever sent the old (P6e).
    auto parent_before = snap->list({.s = me, .p = node::Term::iri(vocab::kParent), .source = link_agent->iri()});
    if (!parent_before) return Unexpected<Error>{parent_before.error()};
    const bool same_parent = !parent_before->empty() && parent_before->back().triple.o.value == options.parent_iri;
    if (!parent_store->empty() && same_parent) impl->parent_store_before = parent_store->back().triple.o.value;
  }
  Link::Impl& s = *impl;
  s.opt = std::move(options);
  s.parent_flips.set_hold(s.opt.conflict_hold);
  if (s.opt.down) {
    auto link_agent = node->agent(kLinkAgent);
    if (!link_agent) return Unexpected<Error>{link_agent.error()};
    {
      // Released before the subscriptions below write: a store restored from a backup (its map
      // no larger than its data) must grow for them, and cannot while this process holds a
      // snapshot.
      auto snap = node->snapshot();
      if (!snap) return Unexpected<Error>{snap.error()};
      // P10b: the stores children registered with in earlier runs, so that one made again while
      // this link was down is known for what it is at its first hello.
      auto stores = snap->list({.p = node::Term::iri(vocab::kChildStoreId), .source = link_agent->iri()});
      if (!stores) return Unexpected<Error>{stores.error()};
      for (const auto& r : *stores) s.stores_before[r.triple.s.value] = r.triple.o.value;
    }
    // Configured children: their down queues also take whole-subtree items (P11), and their state
    // is on the board from the start ("never connected").
    for (const auto& id : s.opt.children) {
      auto iri = uri::child_node_iri(s.self, id);
      if (!iri) return node::fail(Errc::invalid_argument, "child id '" + id + "': " + iri.error().message);
      if (id == kLinkAgent || id == kUplinkAgent)
        return node::fail(Errc::invalid_argument, "child id '" + id + "' is this node's own agent '" + id + "' (P1)");
      auto agent = node->agent(id);
      if (!agent) return Unexpected<Error>{agent.error()};
      node::Pattern subtree;
      subtree.context = s.self + "/*";
      if (auto r = agent->receive_removals(); !r) return Unexpected<Error>{r.error()};  // P10a; first, as above
      if (auto sub = agent->subscribe(subtree, kSubtreeSubscription); !sub) return Unexpected<Error>{sub.error()};
      auto child = std::make_shared<Impl::Child>();
      child->flips.set_hold(s.opt.conflict_hold);
      child->id = id;
      child->iri = *iri;
      if (auto before = s.stores_before.find(*iri); before != s.stores_before.end()) child->store_before = before->second;
      s.children[*iri] = child;
    }
    // The state an earlier run kept of a child that is no longer configured (taken out of the
    // file) would stay "up" on the board for ever: it goes (P12).
    std::vector<std::uint64_t> gone_states;
    if (!s.opt.children.empty()) {
      auto snap = node->snapshot();
      if (!snap) return Unexpected<Error>{snap.error()};
      auto states = snap->list({.p = node::Term::iri(vocab::kLinkState), .source = link_agent->iri()});
      if (!states) return Unexpected<Error>{states.error()};
      for (const auto& r : *states) {
        if (auto known = s.children.find(r.triple.s.value); known != s.children.end()) {
          // A child an earlier run had connected is "down" until it says hello again, with the
          // time it was last seen, the outbox depth and version it last said, not "never
          // connected" (a restarted gateway's children), nor an outbox of 0 (a child whose
          // parent's link was killed while its items waited showed "outbox 0" for as long as
          // Cyclone's lease kept it from saying hello again).
          if (r.triple.o.value == "up" || r.triple.o.value == "down") {
            Impl::Child& child = *known->second;
            child.ever_before = true;
            auto said = snap->list({.s = r.triple.s, .source = link_agent->iri()});
            for (const node::Record& k : said ? *said : std::vector<node::Record>{}) {
              const std::string& text = k.triple.o.value;
              if (k.triple.p.value == vocab::kLastSeen) {
                std::from_chars(text.data(), text.data() + text.size(), child.last_seen_ns);
              } else if (k.triple.p.value == vocab::kOutboxDepth) {
                std::from_chars(text.data(), text.data() + text.size(), child.outbox_depth);
              } else if (k.triple.p.value == vocab::kSoftwareVersion) {
                child.version = text;
              } else if (std::uint64_t wire::StoreRoom::*field =
                             k.triple.p.value == vocab::kStoreUsedBytes   ? &wire::StoreRoom::used_bytes
                             : k.triple.p.value == vocab::kStoreDataBytes ? &wire::StoreRoom::data_bytes
                             : k.triple.p.value == vocab::kStoreMaxBytes  ? &wire::StoreRoom::max_bytes
                             : k.triple.p.value == vocab::kDiskFreeBytes  ? &wire::StoreRoom::disk_free_bytes
                                                                          : nullptr) {
                if (!child.room) child.room = wire::StoreRoom{.disk_free_bytes = ~0ull};  // absent: not known
                std::from_chars(text.data(), text.data() + text.size(), child.room.value().*field);
              } else if (k.triple.p.value == vocab::kLinkLeft) {
                child.left = text == "true";  // kept until it says hello again, this run too
              }
            }
          }
          continue;
        }
        gone_states.push_back(r.meta.item);
      }
    }
    for (std::uint64_t item : gone_states)  // with the snapshot released, as above
      if (auto gone = node->remove_item(item); !gone) return Unexpected<Error>{gone.error()};
    s.waker = std::move(*node);
    s.serving_lock = ::open((s.opt.dir / kServingLockFile).c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
    if (s.serving_lock < 0 || flock(s.serving_lock, LOCK_SH) != 0)
      return node::fail(Errc::io, (s.opt.dir / kServingLockFile).string() + ": " + std::strerror(errno));
    // Who holds it: an asker whose answer does not come looks whether this process was stopped
    // (kill -STOP, a debugger), which the lock alone does not show.
    const std::string pid = std::to_string(getpid()) + "\n";
    if (ftruncate(s.serving_lock, 0) != 0 ||
        pwrite(s.serving_lock, pid.data(), pid.size(), 0) != static_cast<ssize_t>(pid.size()))
      s.log((s.opt.dir / kServingLockFile).string() + ": cannot write this process's id: " + std::strerror(errno));
  } else {
    // A node that served children once and no longer listens (its `listen` taken out of the
    // file): the lock file left by those runs told a query that a link serving children had
    // stopped, and every child was "unreachable: no link runs", though this link runs.
    std::error_code ec;
    std::filesystem::remove(s.opt.dir / kServingLockFile, ec);
  }
  std::unique_ptr<Link> link(new Link(std::move(impl)));
  Impl* p = link->impl_.get();
  if (p->opt.up) {
    p->threads.emplace_back([p, t = p->opt.up] { name_thread("tv-apply-up"), p->receive_loop(t); });
    p->threads.emplace_back([p] { name_thread("tv-uplink"), p->up_loop(); });
  }
  if (p->opt.down && p->opt.down != p->opt.up)
    p->threads.emplace_back([p, t = p->opt.down] { name_thread("tv-apply-down"), p->receive_loop(t); });
  for (const auto& t : p->opt.also_down)
    p->threads.emplace_back([p, t] { name_thread("tv-apply-down"), p->receive_loop(t); });
  p->threads.emplace_back([p] { name_thread("tv-timer"), p->timer_loop(); });
  if (p->opt.up) p->threads.emplace_back([p] { name_thread("tv-answer"), p->answer_loop(); });
  if (p->opt.down) p->threads.emplace_back([p] { name_thread("tv-pump"), p->pump_loop(); });
  return link;
}

}  // namespace tahvel::federation
