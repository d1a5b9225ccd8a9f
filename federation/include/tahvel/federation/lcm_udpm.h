// The receiving half of LCM's UDP multicast protocol ("udpm", LCM 1.x), on the caller's thread:
// what the LCM binding listens with (docs/transports.md, "Receiving without liblcm's thread").
//
// liblcm's udpm provider reads its socket on a thread of its own and hands every message to
// lcm_handle through a pipe: each message wakes two threads, its reader and then the caller,
// 20-30 µs on this machine's virtual CPUs, most of an item's way from a sensor to its gateway.
// Read where the frame is taken, a datagram wakes nobody when the taker is already looking.
// Sending stays liblcm's (lcm_publish); this reads exactly what it writes:
//
//   short message  "LC02" u32 magic, u32 sequence number, channel NUL-terminated, payload
//   fragment       "LC03" u32 magic, u32 sequence number, u32 payload size, u32 offset of this
//                  fragment in the payload, u16 fragment number, u16 fragments in the message;
//                  fragment 0 has the channel, NUL-terminated, before its part of the payload
//
// all big-endian, one message at a time per sending socket.
#pragma once

#include <netinet/in.h>

#include <chrono>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <unordered_map>
#include <utility>
#include <vector>

#include "tahvel/node/error.h"

namespace tahvel::federation {

// A udpm:// URL taken apart (check_lcm_url's rules; LCM's defaults where it says nothing).
struct UdpmAddress {
  in_addr group{};  // network byte order
  std::uint16_t port = 7667;
  std::optional<std::uint64_t> recv_buf_size;  // bytes asked of the kernel, if the URL says
};
node::Result<UdpmAddress> parse_udpm_url(std::string_view url);

// Datagrams in, whole messages of one channel out. Pure (no socket), so that tests and the fuzz
// target feed it datagrams. Messages on other channels are passed over without a word, as liblcm
// does for channels nobody subscribed to; what is malformed is refused with the reason.
class UdpmReassembler {
 public:
  // The most bytes held by default for messages not yet whole, over all senders: the largest
  // frame body a binding sends (wire.h's kMaxBody) and its envelope. Senders with a message
  // under way are at most 4,096; beyond, the oldest message is dropped.
  static constexpr std::size_t kMaxHeldBytes = (64u << 20) + (1u << 20);

  // A fragment that would take the bytes held past `max_held` drops the oldest partial messages
  // first; a message larger than `max_held` alone is refused at its first fragment.
  explicit UdpmReassembler(std::string channel, std::size_t max_held = kMaxHeldBytes)
      : channel_(std::move(channel)), max_held_(max_held) {}

  struct Taken {
    // A whole message on the channel: a view into the datagram (short message) or into this
    // reassembler (fragmented), valid until the next take().
    std::optional<std::string_view> payload;
    std::string refused;  // why the datagram was dropped; empty when it was not
  };
  // `sender` tells sending sockets apart (each has its own sequence of messages).
  Taken take(std::uint64_t sender, std::string_view datagram);

  // The bytes held for messages not yet whole: theirs and one per fragment.
  std::size_t held_bytes() const noexcept { return held_bytes_; }

 private:
  struct Partial {
    std::uint32_t seqno = 0, size = 0;
    std::uint16_t fragments = 0, received = 0;
    std::string have;  // one byte per fragment: 1 once it came
    // Not zero-filled: a fragment 0 claiming a message of 60 MB made the receiver write 60 MB of
    // zeros (40 ms) before any byte came, and 25 such datagrams a second kept a gateway from
    // hearing its sensors. A large block is mapped by the allocator and takes memory only where
    // fragments are copied.
    std::unique_ptr<char[]> data;
    // The bytes each fragment brought (offset, length): a message is whole when they tile it,
    // since what no fragment wrote was never set.
    std::vector<std::pair<std::uint32_t, std::uint32_t>> spans;
    bool other_channel = false;  // fragment 0 named another channel: its fragments are skipped
    std::uint64_t started = 0;   // take() count when it began, to drop the oldest first
  };
  Taken take_fragment(std::uint64_t sender, std::string_view datagram);
  // What a partial message holds: its bytes and its record of the fragments that came.
  static std::size_t held_size(std::uint32_t size, std::uint16_t fragments) { return std::size_t{size} + fragments; }
  void drop(std::unordered_map<std::uint64_t, Partial>::iterator it);
  bool make_room(std::size_t bytes, std::uint64_t keep);

  std::string channel_;
  std::size_t max_held_;
  std::unordered_map<std::uint64_t, Partial> partial_;
  std::size_t held_bytes_ = 0;
  std::uint64_t takes_ = 0;
  std::string whole_;  // the last message made whole, which take() returned a view of
};

// A socket on a udpm group and port, joined as liblcm joins it, read without blocking.
class UdpmSocket {
 public:
  // Asks the kernel for `recv_buf_size` bytes of buffer (the URL's, else `default_recv_buf`);
  // `*granted` gets what the kernel gave (capped by net.core.rmem_max).
  static node::Result<std::unique_ptr<UdpmSocket>> open(const UdpmAddress& address, std::size_t default_recv_buf,
                                                        std::size_t* granted);
  ~UdpmSocket();
  UdpmSocket(const UdpmSocket&) = delete;
  UdpmSocket& operator=(const UdpmSocket&) = delete;

  struct Datagram {
    std::uint64_t sender;  // address and port of the sending socket
    std::string_view bytes;  // valid until the next read()
  };
  // The next datagram if one waits (never blocks), nothing when none does.
  node::Result<std::optional<Datagram>> read();
  // Until a datagram waits or `timeout` passes; false when it passed.
  node::Result<bool> wait(std::chrono::milliseconds timeout);

  // "a.b.c.d:port" of a Datagram::sender, for log lines.
  static std::string sender_name(std::uint64_t sender);

 private:
  explicit UdpmSocket(int fd) : fd_(fd) {}
  int fd_;
  std::string buffer_;
};

}  // namespace tahvel::federation
