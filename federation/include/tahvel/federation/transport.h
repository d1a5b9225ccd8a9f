// A transport carries link frames between nodes (docs/protocol.md). It is a mailbox bound to one
// IRI (the endpoint receives the frames addressed to that IRI) plus "send to any IRI". It gives
// no delivery guarantee: frames may be lost, duplicated or reordered. Reliability (sequence
// numbers, acknowledgement, resend, flow control) is the link's job, the same over every binding.
//
// Three bindings: in-memory (deterministic tests), LCM (UDP multicast, sensor-to-gateway LAN) and
// Cyclone DDS (reliable QoS, gateway-to-hospital and above).
//
// Threads: send() may be called from any thread, also while another thread is in receive();
// receive() from one thread at a time.
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "tahvel/node/error.h"

namespace tahvel::federation {

using node::Error;
using node::Errc;
using node::Result;

// The protocol version this build speaks, and the oldest it still hears: a parent speaks to a
// child of an earlier version in that version (P3 in docs/protocol.md). Frames of other
// versions are dropped.
inline constexpr std::uint16_t kProtocolVersion = 5;
inline constexpr std::uint16_t kOldestProtocolVersion = 2;

enum class FrameKind : std::uint8_t {
  hello = 1,      // child -> parent: registration (child IRI, software version, last ack seen)
  welcome = 2,    // parent -> child: registration accepted, with the parent's last applied seq
  up = 3,         // child -> parent: one item of the outbox
  ack = 4,        // either way: cumulative acknowledgement (highest seq applied in order)
  down = 5,       // parent -> child: one item of configuration or a command
  query = 6,      // parent -> child: a remote query, routed down by the target IRI
  answer = 7,     // child -> parent: one chunk of a query's answer
  error = 8,      // either way: a refusal or failure, with a code and a message
  heartbeat = 9,  // child -> parent: liveness and state (outbox depth, software version)
};

// Bits of an up or down frame's `ack` field (docs/protocol.md P8, P9b).
inline constexpr std::uint64_t kAckNow = 1;      // the sender's window is half full: ack the stream now
inline constexpr std::uint64_t kMoreFollow = 2;  // more frames of the run sent back to back follow
// A welcome's seq (docs/protocol.md P6e): the parent's store is a copy (restored from a backup),
// holds nothing of the child's stream, and is not the store the child's hello named. 0
// otherwise, which a link before P6e sends and reads.
inline constexpr std::uint64_t kWelcomeFromACopy = 1;
// An up or down frame's `ack` also names both ends' stores (P6b), so that frames of two stores
// under one IRI are told apart: bits 16-39 a 24-bit tag of the sender's store id, bits 40-63 of
// the store it sends to (0: none).
inline constexpr int kStoreTagShift = 16, kPeerStoreTagShift = 40;
inline constexpr std::uint64_t kStoreTagMask = 0xFFFFFF;
// The tag of the store whose id is `store_id`: 24 bits of its 64-bit FNV-1a hash, never 0 (0 is
// no tag: an empty id, a peer from before tags).
std::uint64_t store_tag(std::string_view store_id) noexcept;

// The kind of a Cyclone DDS sample that carries several frames of one sender to one addressee
// (docs/transports.md, "Packing"). The DDS binding makes and unpacks such samples itself: it
// never comes out of receive(), and other bindings drop it as unknown. A frame of this kind
// handed to the DDS binding's send() goes as it is, one sample (tests send malformed packs so).
inline constexpr std::uint8_t kPackedKind = 10;

// 64-bit FNV-1a of the canonical description of Frame and FrameKind (federation/src/frame.cpp):
// two builds interoperate only when their message types agree field for field.
std::uint64_t message_fingerprint() noexcept;

// One frame on the wire. The same fields in the LCM type (federation/types/*.lcm) and the IDL
// type (federation/types/*.idl).
struct Frame {
  std::uint16_t version = kProtocolVersion;
  std::uint64_t fingerprint = message_fingerprint();
  FrameKind kind = FrameKind::heartbeat;
  std::string from;               // sender node IRI
  std::string to;                 // addressee node IRI (the endpoint that should receive it)
  std::uint64_t seq = 0;          // kind-specific (docs/protocol.md)
  std::uint64_t prev = 0;
  std::uint64_t ack = 0;
  std::string body;               // kind-specific payload bytes
  // Not on the wire: a frame to an addressee this endpoint may never have heard of (the answer to
  // a refused sender, P6), sent without waiting for the addressee to be found (DDS: a reader to
  // match its new writer) and lost when it is not found yet. A sender that made up its IRI has
  // nobody behind it, and each such wait held the sending thread up to 2 s.
  bool may_find_nobody = false;
};

// Called with one line whenever a binding drops something it received (undecodable bytes, a frame
// for another IRI, a wrong version or fingerprint): what and why. Default: stderr.
using DropLog = std::function<void(std::string_view reason)>;

class Transport {
 public:
  virtual ~Transport() = default;

  // The IRI this endpoint receives for.
  virtual const std::string& self() const = 0;

  // Sends `frame` to the endpoint bound to frame.to. Best effort: an error means it certainly
  // did not leave (e.g. too large, transport closed), success does not mean it arrived. A frame
  // of a run marked kMoreFollow may be held to travel with the frames after it (Cyclone DDS packs
  // a run into few samples, and with Internal/WriteBatch into few datagrams); it leaves at the
  // latest with the next frame to the same endpoint that is not so marked. When a later send to
  // that endpoint fails, the frames held with it may be lost too: the link sends again what is
  // not acknowledged (P8).
  virtual Result<void> send(const Frame& frame) = 0;

  // The next frame addressed to self(), waiting up to `timeout`; nullopt on timeout.
  // Frames that fail to decode, carry another version or fingerprint, or are addressed to another
  // IRI never come out of here: they go to the DropLog.
  virtual Result<std::optional<Frame>> receive(std::chrono::milliseconds timeout) = 0;

  // Push mode, where the binding has a thread of its own that receives (Cyclone DDS): `ready`
  // is called on that thread whenever frames may have arrived (or, for a sender in the same
  // process, inside that sender's send()), and may take them there with receive(0ms), saving the
  // wake-up of a thread of the caller's. Returns false when the binding has no such thread: the
  // caller then waits in receive(). An empty `ready` ends push mode and returns once no call of
  // the previous one is under way (so never from within `ready`). The binding makes one call at
  // a time per endpoint; `ready` counts as a thread calling receive(), and the caller keeps the
  // one-at-a-time rule between it and its own threads.
  //
  // `ready` must not send: a send to an endpoint of the same process is delivered inside it, and
  // a reply coming back to this endpoint would wait for this very call to end. Nor may it wait
  // for long: it holds up the binding's receiving for every endpoint of the process.
  virtual bool on_arrival(std::function<void()> ready) {
    (void)ready;
    return false;
  }
};

// ---------------------------------------------------------------------------------------------
// In-memory binding: endpoints of one MemoryBus exchange frames inside one process. Tests may
// make it drop, duplicate or reorder frames deterministically (a seeded schedule). Endpoints
// opened with the same IRI each get every frame to it, as on the wire bindings.

class MemoryBus {
 public:
  struct Faults {
    std::uint64_t seed = 1;
    double drop = 0;       // probability a frame is lost
    double duplicate = 0;  // probability a frame is delivered twice
    double reorder = 0;    // probability a frame is delivered after the next one
  };
  MemoryBus();
  ~MemoryBus();
  void set_faults(const Faults& faults);
  // Cuts (or restores) delivery to `iri`: frames sent to it while cut are lost.
  void set_cut(std::string_view iri, bool cut);
  std::unique_ptr<Transport> open(std::string_view self_iri, DropLog log = {});
  // Hands raw bytes to the endpoint bound to `to`, as a wire binding would after reading them
  // from the network (for tests of malformed input): they go through the same decode path.
  void inject_raw(std::string_view to, std::string bytes);

  struct Impl;

 private:
  std::shared_ptr<Impl> impl_;
};

// ---------------------------------------------------------------------------------------------
// Wire bindings.

// Which end of a link an LCM endpoint is. Multicast delivers every datagram to every socket
// on its group and port, the sender's own included, and liblcm's receive thread wakes for each
// before it filters by channel. So a link's two directions take two ports of the URL's group:
// frames to the parent travel on the URL's port P, frames to a child on P + 1, and each end
// listens only on the port of the frames addressed to it. A node then never wakes for its own
// frames, nor a child for its siblings' frames up. `shared` sends and listens on P alone, as
// plain LCM does, for tools and tests that are not a link's end; both ends of a link must be
// split or both shared. Only udpm:// URLs have ports; other providers stay shared.
enum class LcmEnd { shared, parent, child };

struct LcmSettings {
  // LCM provider URL. The default is LCM's own multicast group with ttl=0 (never leaves the
  // host); tests run it in a private network namespace with multicast routed to loopback.
  std::string url = "udpm://239.255.76.67:7667?ttl=0";
  LcmEnd end = LcmEnd::shared;
};

// The udpm:// URL of the port after `url`'s (where a parent end sends and a child end listens),
// with the same group and options; an error for a port of 65535, or a URL check_lcm_url refuses.
Result<std::string> lcm_down_url(std::string_view url);

struct DdsSettings {
  std::uint32_t domain = 0;
  // Cyclone DDS XML configuration (or empty: CYCLONEDDS_URI from the environment, else the
  // built-in default). deploy/cyclonedds-*.xml hold the ones we ship; they set
  // Internal/WriteBatch, which packs a run of frames into few datagrams (docs/transports.md).
  // The binding flushes at each run's end, so any configuration is correct without it too.
  std::string config;
};

// Whether a link can open the LCM URL `url` as written: udpm://GROUP:PORT?OPTIONS, GROUP an IPv4
// multicast address (224.0.0.0/4; the whole address left out: LCM's 239.255.76.67:7667), PORT
// 1..65535 in decimal (absent: 7667), OPTIONS `&`-separated among ttl=0..255 and
// recv_buf_size=BYTES. The error says which part is wrong. liblcm says only that lcm_create
// failed (a link configured so dies at each restart), or only warns and goes on with something
// else (an unknown option, a ttl that wraps, an octal port): both are refused here. open_lcm
// checks udpm:// URLs so; other providers go to liblcm as they are.
Result<void> check_lcm_url(std::string_view url);

// Whether `xml` (a Cyclone DDS configuration, as DdsSettings::config) parses with Cyclone's own
// XML parser; the error gives the line and the parser's message. The elements are Cyclone's to
// judge when the domain is created.
Result<void> check_dds_config(std::string_view xml);

Result<std::unique_ptr<Transport>> open_lcm(const LcmSettings& settings, std::string_view self_iri,
                                            DropLog log = {});
Result<std::unique_ptr<Transport>> open_dds(const DdsSettings& settings, std::string_view self_iri,
                                            DropLog log = {});

// Encoding of a Frame into bytes and back, shared by the memory binding and by tests; the wire
// bindings use their generated types. decode_frame names what is wrong on failure.
std::string encode_frame(const Frame& frame);
Result<Frame> decode_frame(std::string_view bytes);

// The kind's name as docs/protocol.md writes it ("hello", "up", …; "kind 12" for one it does not
// name), for log lines.
std::string frame_kind_name(FrameKind kind);

// The longest `from` IRI a frame may carry (P4): 40 levels of 200-byte ids. Frames from longer
// made-up IRIs are dropped before the link keeps or logs anything of them.
inline constexpr std::size_t kMaxFrameIriBytes = 8192;

// Why a received, decoded frame must be dropped by the endpoint bound to `self_iri` (another
// protocol version, another fingerprint, addressed to another IRI, a `from` over
// kMaxFrameIriBytes), or nullopt to accept it. Every binding applies this same rule
// (docs/protocol.md P4).
std::optional<std::string> frame_refusal(const Frame& frame, std::string_view self_iri);

}  // namespace tahvel::federation
