// The communication agent of a node (DESIGN §5): one Link per node links it to its parent (the
// child role: items up, configuration down, queries answered) and to its children (the parent
// role: their items relayed into this store, configuration and queries sent down, their state
// kept as triples). The protocol is docs/protocol.md; its statements (P1...) are cited in code
// and tests.
//
//   auto link = Link::start({.dir = "state/home1", .parent_iri = hospital, .up = dds,
//                            .down = lcm});
//   ... // runs in its own threads until stop() or destruction
//
// Nothing is kept only in memory: the outbox is the input buffer of the node's agent "uplink"
// (its subscriptions are the forwarding policy), the down queue of child C is the input buffer of
// agent C (the child, seen as an agent of this node), and the marks of both directions are in
// the stores (node::Agent::relay). A link or node that restarts resumes where it was.
#pragma once

#include <chrono>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "tahvel/federation/transport.h"
#include "tahvel/node/node.h"

namespace tahvel::federation {

// One line per event worth an operator's attention (registration, refusal, link up/down, drop).
using LinkLog = std::function<void(std::string_view line)>;

// The vocabulary of link state, remote queries and answers (docs/protocol.md, "On the board").
namespace vocab {
inline constexpr std::string_view kTv = "https://w3id.org/tahvel#";
inline const std::string kLastSeen = std::string(kTv) + "lastSeen";
inline const std::string kLinkState = std::string(kTv) + "linkState";
inline const std::string kOutboxDepth = std::string(kTv) + "outboxDepth";
inline const std::string kSoftwareVersion = std::string(kTv) + "softwareVersion";
inline const std::string kParent = std::string(kTv) + "parent";
// The store a child registered with (P6a), kept so that a store made again while this node's
// link was down is still told apart from the one before (P10b).
inline const std::string kChildStoreId = std::string(kTv) + "childStoreId";
// A node's own view of its uplink (P12a): "up", "down", "never connected" or "refused".
inline const std::string kUplinkState = std::string(kTv) + "uplinkState";
inline const std::string kParentLastHeard = std::string(kTv) + "parentLastHeard";
// The parent store that welcomed this node (P6a), kept so that the next run's hello carries the
// node's mark of its down stream before any welcome.
inline const std::string kParentStoreId = std::string(kTv) + "parentStoreId";
inline const std::string kUplinkRefusal = std::string(kTv) + "uplinkRefusal";
// Two stores take turns under one child's or parent's IRI (P6b), said for two minutes after.
inline const std::string kLinkConflict = std::string(kTv) + "linkConflict";
// A child that is down because its link said it was stopping (P12c), not because it went
// silent: true, beside its tv:linkState "down", until it says hello again.
inline const std::string kLinkLeft = std::string(kTv) + "linkLeft";
// How full a child's store is, as its last hello or heartbeat said (wire::StoreRoom; protocol
// version 5): the bytes up to its last page in use, those holding data, its maximum, and what
// the disk holding it has free.
inline const std::string kStoreUsedBytes = std::string(kTv) + "storeUsedBytes";
inline const std::string kStoreDataBytes = std::string(kTv) + "storeDataBytes";
inline const std::string kStoreMaxBytes = std::string(kTv) + "storeMaxBytes";
inline const std::string kDiskFreeBytes = std::string(kTv) + "diskFreeBytes";
inline const std::string kRemoteQuery = std::string(kTv) + "RemoteQuery";
inline const std::string kQueryTarget = std::string(kTv) + "queryTarget";
inline const std::string kReplyTo = std::string(kTv) + "replyTo";
inline const std::string kQuerySubject = std::string(kTv) + "querySubject";
inline const std::string kQueryPredicate = std::string(kTv) + "queryPredicate";
inline const std::string kQueryObject = std::string(kTv) + "queryObject";
// A blank node of a query's pattern is written on the board as a literal of this datatype (its
// label): as a blank node it would be renamed on write, as every blank node of an item is.
inline const std::string kBlankNodeLabel = std::string(kTv) + "BlankNodeLabel";
inline const std::string kQuerySince = std::string(kTv) + "querySince";
inline const std::string kQueryUntil = std::string(kTv) + "queryUntil";
inline const std::string kQueryCascade = std::string(kTv) + "queryCascade";
inline const std::string kQueryLimit = std::string(kTv) + "queryLimit";
inline const std::string kQueryArea = std::string(kTv) + "queryArea";
inline const std::string kQueryFloor = std::string(kTv) + "queryFloor";
// node::Pattern::source and ::under (protocol version 4).
inline const std::string kQuerySource = std::string(kTv) + "querySource";
inline const std::string kQueryUnder = std::string(kTv) + "queryUnder";
// The asker's timeout in ms: its link clears a query still on the board 2 s after (P18).
inline const std::string kQueryTimeout = std::string(kTv) + "queryTimeout";
inline const std::string kAnswerTo = std::string(kTv) + "answerTo";
inline const std::string kAnswerChunk = std::string(kTv) + "answerChunk";
inline const std::string kAnswerLast = std::string(kTv) + "answerLast";
inline const std::string kAnswerRecords = std::string(kTv) + "answerRecords";
inline const std::string kErrorCode = std::string(kTv) + "errorCode";
inline const std::string kErrorMessage = std::string(kTv) + "errorMessage";
}  // namespace vocab

// Answers a query that names an area (a room IRI or WKT, and a floor for WKT) on one snapshot:
// the records matching `pattern` located in the area, with `options` applied. Federation knows
// no geometry; the command line gives the spatial library's answer (docs/spatial.md). Errors
// name what is wrong with the area.
using AreaQuery = std::function<node::Result<std::vector<node::Record>>(
    const node::Snapshot& snapshot, const node::Pattern& pattern, const std::string& area,
    std::optional<std::int64_t> floor, const node::ListOptions& options)>;

struct LinkOptions {
  std::filesystem::path dir;  // the node's store

  // Child role. parent_iri empty: this node is a root. `up` is bound to this node's IRI.
  std::string parent_iri;
  std::shared_ptr<Transport> up;
  // The forwarding policy: subscriptions of agent "uplink", written at start (idempotent). Empty:
  // keep what the store has, or on a new store the default — HRV windows only, never raw signals.
  std::vector<node::Pattern> forward;
  // False: the policy on the board is the whole of it, none included (`tahvel up` writes it).
  bool default_forward = true;
  // Whether stop() tells the parent that this link is leaving (docs/protocol.md P12c), and its
  // connected children (P12d), as a link stopped on purpose does. False: it stops as a killed
  // process would, unsaid (tests of a crash).
  bool say_leaving = true;

  // Parent role: the transport children reach this node on (bound to this node's IRI; may be the
  // same object as `up`). Null: a leaf.
  std::shared_ptr<Transport> down;
  // Further transports children reach this node on, each bound to this node's IRI and distinct
  // from `up` and `down` (a gateway with its LAN's sensors on LCM and a node further away on
  // DDS). A child is answered on the transport its hello came on.
  std::vector<std::shared_ptr<Transport>> also_down;
  // Child ids accepted. Empty: any direct child, for a network where only trusted nodes speak
  // (`tahvel link` without --child): each IRI that says hello is kept as a child, with its state
  // on the board, so made-up senders grow both.
  std::vector<std::string> children;

  std::size_t window = 512;                       // up or down items in flight per link
  std::chrono::milliseconds resend_after{300};    // no acknowledgement for this long: resend
  // A quiet stream's items are acknowledged together after this long (or at 256 items, or at once
  // when the sender's window is half full or something must be resent: P8). Each ack costs both
  // ends a send, a receive and a wake-up, and whatever item travels meanwhile waits for them; at
  // 2 ms a steady stream of single items had one round in thirty slowed so (docs/bench.md).
  std::chrono::milliseconds ack_delay{20};
  std::chrono::milliseconds heartbeat_every{1000};
  std::chrono::milliseconds child_silence{3500};  // a child not heard for this long is "down"
  // Two stores alive under one peer IRI (P6b): the link does not link with that peer until this
  // long after the last sign of the second store.
  std::chrono::milliseconds conflict_hold{120000};
  // Frames are taken on the transport's own receive thread where it has one (Cyclone DDS:
  // Transport::on_arrival), and a small run of items from a known peer is relayed there, saving
  // a thread's wake-up on the path of every item. A writer that holds this store's write lock
  // for long then holds up that thread too (the peers resend what it misses). False: a thread
  // of the link's takes every frame.
  bool push = true;
  std::string software_version = "tahvel 0.1.0";
  LinkLog log;
  AreaQuery area_query;  // answers queries with an area; unset: they fail with query_failed
};

struct LinkCounters {
  std::uint64_t up_sent = 0;        // up frames sent (first sends and resends)
  std::uint64_t up_resends = 0;     // times the up window went back to the parent's mark
  std::uint64_t relayed_in = 0;     // items relayed into this store from children
  std::uint64_t relay_writes = 0;   // store transactions that relayed them
  std::uint64_t duplicates_in = 0;  // relayed items dropped as duplicates (P9)
  std::uint64_t already_held_in = 0;  // items dropped as held already (P6c, P10c, R19)
  std::uint64_t down_applied = 0;   // items relayed into this store from the parent
  std::uint64_t removals_applied = 0;    // removal notices applied from either side (P7a, P10a)
  std::uint64_t records_removed_in = 0;  // the records of this store they removed
  std::uint64_t refused = 0;        // frames refused (foreign IRI, unknown child, bad body), and runs
                                    // this store could not hold, or held in part (P9b)
  std::uint64_t items_refused = 0;  // items received that this store can never hold, passed over
                                    // (P9a)
  std::uint64_t items_refused_by_peer = 0;  // items sent that the receiver refused so (P9a)
  std::uint64_t taken_pushed = 0;  // frames taken on a transport's own thread (LinkOptions::push)
};

class Link {
 public:
  static Result<std::unique_ptr<Link>> start(LinkOptions options);
  ~Link();  // stops the link's threads
  Link(const Link&) = delete;
  Link& operator=(const Link&) = delete;

  void stop();
  bool connected() const;  // welcomed by the parent (child role)
  LinkCounters counters() const;

  struct Impl;

 private:
  explicit Link(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

// The file in a node's store directory that a link serving children holds a shared lock on; it
// holds that process's id.
inline constexpr const char* kServingLockFile = "link.lock";

// ---------------------------------------------------------------------------------------------
// Remote query, operator side: asks the node at `target` (this node or any node below it)
// through this node's board and its running Link, calling `each` for every record of the answer
// as chunks arrive. Errors: not_found "unknown node" (not under this node, or no such child),
// unreachable (errc io, message starts "unreachable:"; also when no link serves this node's
// children: no process holds its kServingLockFile, or the one that does is stopped by a
// signal or a debugger; when no link serves, the message says so whatever state the board
// keeps for the child), timeout. `cancelled`, when given, is asked at least every 100 ms and
// before each record is handed to `each`: once it says true, the query ends (errc io,
// message starts "cancelled"), its items leave the board, and the link tells the nodes below
// to stop answering (docs/protocol.md P18). A timeout cancels the same way.

struct RemoteQuery {
  std::string target;
  node::Pattern pattern;  // s, p, o, source, under, since, until (context and after_id: refused)
  unsigned cascade = 0;
  std::size_t limit = 0;
  std::string area;       // a room IRI (absolute) or WKT; the target resolves it (AreaQuery)
  std::optional<std::int64_t> floor;
  // How long (within the timeout) a link that is restarting is waited for: no link serving this
  // node, or the child on the way "never connected", or "down" in a run younger than
  // child_silence (a new run of the parent's link, before the child's hello). Its supervisor
  // starts a dead link again within a second, or after its back-off (up to 2 s for a link that
  // died three times in a minute); an operator's query meanwhile should not fail. 0: fail at
  // once (`tahvel status`, which asks many nodes).
  std::chrono::milliseconds restart_grace{5000};
};

// `area_query` answers a query with an area when the target is this node itself.
Result<std::uint64_t> remote_query(node::Node& node, const RemoteQuery& query,
                                   std::chrono::milliseconds timeout,
                                   const std::function<void(const node::Record&)>& each,
                                   const AreaQuery& area_query = {}, const std::function<bool()>& cancelled = {});

// The default forwarding policy (HRV windows: sosa:observedProperty tv:HeartRateVariability).
std::vector<node::Pattern> default_forward_policy();

// P6: how long a child that is not welcomed waits after a hello before the next, given the
// wait before it (zero: the hello is the first) and its LinkOptions::heartbeat_every:
// min(heartbeat_every, 250 ms) at first, then twice the wait before, up to 4 s; each moved by up
// to a quarter at random (the children of a restarted parent then do not ask together). For
// programs that speak the child role themselves (load generators), as the Link does.
struct HelloGap {
  std::chrono::nanoseconds base{0};  // before the random move; the next gap doubles this
  std::chrono::nanoseconds wait{0};  // the wait to use
};
HelloGap next_hello_gap(std::chrono::nanoseconds before, std::chrono::nanoseconds heartbeat_every);

}  // namespace tahvel::federation
