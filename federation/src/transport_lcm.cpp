// The LCM binding (docs/transports.md): an endpoint listens on the one channel named after its
// own IRI (lcm_channel()); send() publishes a tahvel_frame_t on the channel of frame.to with
// liblcm, through an lcm_t that never subscribes (so liblcm starts no receive thread for it).
// On a udpm:// URL the endpoint reads LCM's datagrams itself (lcm_udpm.h: liblcm's receive
// thread and pipe cost two wake-ups per message); other providers are read through liblcm.
// Tuned for the sensor-to-gateway LAN: small frames at a steady rate, occasionally a chunk of
// raw signal of a few MB (LCM fragments it over UDP multicast).
//
// LCM may lose datagrams (a full socket buffer, a lost fragment): the link resends. What arrives
// is decoded here, from the raw bytes, so that anything malformed is reported to the DropLog
// with its channel and size instead of being printed by LCM's generated handler.
#include <arpa/inet.h>
#include <sched.h>
#include <lcm/lcm.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <deque>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "tahvel/federation/lcm_frame.h"
#include "tahvel/federation/lcm_udpm.h"
#include "tahvel/federation/transport.h"
#include "tahvel/federation/wire_names.h"
#include "tahvel/node/node.h"
#include "wire_common.h"

namespace tahvel::federation {
namespace {

// Frames LCM keeps for our subscription between two lcm_handle calls (its default is 30, too few
// for a burst between two receive() calls; beyond this LCM drops the newest).
constexpr int kQueueCapacity = 10000;

// The kernel socket buffer asked for when the URL does not say (udpm's recv_buf_size; the
// kernel caps it at net.core.rmem_max). The kernel default (~200 kB) holds only three of the
// 64 kB fragments of a large frame, so a frame of a few MB arriving while the receiving thread
// is busy would lose a fragment, and with it the whole frame.
constexpr std::size_t kRecvBufSize = 4194304;

class LcmTransport final : public Transport {
 public:
  // Listens with `udpm` when it is given, else with `listen` (subscribed by subscribe());
  // sends with `send`, or with `listen` when `send` is null. Takes all three.
  LcmTransport(std::unique_ptr<UdpmSocket> udpm, lcm_t* listen, lcm_t* send, std::string self, DropLog log)
      : udpm_(std::move(udpm)),
        lcm_(listen),
        send_lcm_(send),
        self_(std::move(self)),
        channel_(lcm_channel(self_)),
        reassembler_(channel_),
        log_(wire::rate_limited(wire::or_stderr(std::move(log)))) {}

  ~LcmTransport() override {
    if (sub_ != nullptr) lcm_unsubscribe(lcm_, sub_);
    if (lcm_ != nullptr) lcm_destroy(lcm_);
    if (send_lcm_ != nullptr) lcm_destroy(send_lcm_);
  }

  LcmTransport(const LcmTransport&) = delete;
  LcmTransport& operator=(const LcmTransport&) = delete;

  Result<void> subscribe() {
    if (lcm_ == nullptr) return {};
    sub_ = lcm_subscribe(lcm_, channel_.c_str(), &LcmTransport::on_message, this);
    if (sub_ == nullptr) {
      return node::fail(Errc::io, "lcm <" + self_ + ">: cannot subscribe to channel " + channel_);
    }
    lcm_subscription_set_queue_capacity(sub_, kQueueCapacity);
    return {};
  }

  const std::string& self() const override { return self_; }

  Result<void> send(const Frame& frame) override {
    if (auto ok = wire::check_sendable(frame, "lcm", self_); !ok) return ok;
    auto bytes = encode_lcm_frame(frame);
    if (!bytes)
      return node::fail(Errc::invalid_argument, "lcm <" + self_ + ">: cannot encode " + wire::describe(frame) + ": " +
                                                    bytes.error().message);
    const auto size = bytes->size();
    const std::string channel = lcm_channel(frame.to);
    // lcm_publish on udpm locks internally; this lock also covers providers that do not.
    std::lock_guard lock(send_mutex_);
    if (lcm_publish(send_lcm_ != nullptr ? send_lcm_ : lcm_, channel.c_str(), bytes->data(), static_cast<unsigned>(size)) != 0) {
      return node::fail(Errc::io, "lcm <" + self_ + ">: publish of " + std::to_string(size) +
                                      " bytes on channel " + channel + " failed (" +
                                      wire::describe(frame) + ")");
    }
    return {};
  }

  Result<std::optional<Frame>> receive(std::chrono::milliseconds timeout) override {
    return udpm_ ? receive_udpm(timeout) : receive_liblcm(timeout);
  }

 private:
  // First looks without blocking for a while, as a waiter on the store does (node.h,
  // "Waiting"): a datagram that comes meanwhile is read at once, where waking this thread from
  // poll costs a futex-sized wake-up on virtual CPUs. Only while recent waits were that short:
  // four spins in a row that found nothing make the next waits block at once, bar a probe in 64.
  Result<std::optional<Frame>> receive_udpm(std::chrono::milliseconds timeout) {
    using clock = std::chrono::steady_clock;
    const auto deadline = clock::now() + timeout;
    auto got = take_datagrams();
    if (!got || *got || timeout.count() <= 0) return got;
    ++waits_;
    const auto budget = std::min<std::chrono::nanoseconds>(node::wait_spin(), timeout);
    if (budget.count() > 0 && (misses_ < 4 || waits_ % 64 == 0)) {
      const auto end = clock::now() + budget;
      do {
        sched_yield();
        got = take_datagrams();
        if (!got || *got) {
          misses_ = 0;
          return got;
        }
      } while (clock::now() < end);
      ++misses_;
    }
    while (true) {
      // Rounded up, so that a wait never ends before the deadline.
      const auto left = std::chrono::ceil<std::chrono::milliseconds>(deadline - clock::now());
      if (left.count() <= 0) return take_datagrams();
      auto readable = udpm_->wait(left);
      if (!readable) return socket_error(readable.error());
      got = take_datagrams();
      if (!got || *got) return got;
    }
  }

  // Reads datagrams until one completes a frame for this endpoint or none waits.
  Result<std::optional<Frame>> take_datagrams() {
    while (true) {
      auto datagram = udpm_->read();
      if (!datagram) return socket_error(datagram.error());
      if (!*datagram) return std::optional<Frame>();
      const auto [sender, bytes] = **datagram;
      auto taken = reassembler_.take(sender, bytes);
      if (!taken.refused.empty()) {
        log_("lcm <" + self_ + ">: dropped a datagram of " + std::to_string(bytes.size()) + " bytes from " +
             UdpmSocket::sender_name(sender) + ": " + taken.refused);
        continue;
      }
      if (!taken.payload) continue;
      if (auto frame = decode(taken.payload->data(), taken.payload->size(), channel_.c_str(), sender))
        return std::optional<Frame>(std::move(*frame));
    }
  }

  Result<std::optional<Frame>> socket_error(const Error& error) {
    return node::fail(Errc::io, "lcm <" + self_ + ">: receiving on channel " + channel_ + ": " + error.message);
  }

  Result<std::optional<Frame>> receive_liblcm(std::chrono::milliseconds timeout) {
    using clock = std::chrono::steady_clock;
    const auto deadline = clock::now() + timeout;
    while (queue_.empty()) {
      // Rounded up, so that a wait never ends before the deadline.
      const auto left = std::chrono::ceil<std::chrono::milliseconds>(deadline - clock::now());
      if (left.count() <= 0) {
        // One last non-blocking look, so that a zero timeout still drains what has arrived.
        if (lcm_handle_timeout(lcm_, 0) < 0) return handle_error();
        break;
      }
      // lcm_handle_timeout dispatches at most one message to on_message (which may drop it).
      if (lcm_handle_timeout(lcm_, static_cast<int>(left.count())) < 0) return handle_error();
    }
    if (queue_.empty()) return std::optional<Frame>();
    Frame frame = std::move(queue_.front());
    queue_.pop_front();
    return std::optional<Frame>(std::move(frame));
  }

  Result<std::optional<Frame>> handle_error() {
    return node::fail(Errc::io,
                      "lcm <" + self_ + ">: lcm_handle_timeout failed on channel " + channel_);
  }

  static void on_message(const lcm_recv_buf_t* rbuf, const char* channel, void* user) {
    auto* self = static_cast<LcmTransport*>(user);
    if (auto frame = self->decode(rbuf->data, rbuf->data_size, channel)) self->queue_.push_back(std::move(*frame));
  }

  // The frame in one LCM message on `channel`, or nothing when it is dropped (with a log line).
  // `sender`: the datagram's address (UdpmSocket), said in the line: a frame names the node it
  // claims to come from, and a forged one was blamed on that node (a prober of session 87).
  // liblcm does not give it.
  std::optional<Frame> decode(const void* data, std::size_t size, const char* channel,
                              std::optional<std::uint64_t> sender = std::nullopt) {
    auto where = [&] {
      return "lcm <" + self_ + ">: dropped " + (sender ? "(sent from " + UdpmSocket::sender_name(*sender) + ") " : std::string());
    };
    auto decoded = decode_lcm_frame({static_cast<const char*>(data), size});
    if (!decoded) {
      log_(where() + std::to_string(size) + " bytes on channel " + channel + ": " + decoded.error().message);
      return std::nullopt;
    }
    Frame& frame = *decoded;
    if (auto why = wire::reject_reason(frame, self_)) {
      log_(where() + wire::describe(frame) + " on channel " + channel + ": " + *why);
      return std::nullopt;
    }
    return std::move(frame);
  }

  std::unique_ptr<UdpmSocket> udpm_;  // null: listens through lcm_
  lcm_t* lcm_;                        // null when udpm_ listens
  lcm_t* send_lcm_;                   // null: sends through lcm_
  lcm_subscription_t* sub_ = nullptr;
  std::string self_;
  std::string channel_;
  UdpmReassembler reassembler_;  // udpm_'s; touched only by the receive() thread
  DropLog log_;
  std::mutex send_mutex_;
  std::deque<Frame> queue_;  // lcm_'s decoded frames; touched only by the receive() thread
  unsigned misses_ = 0, waits_ = 0;  // receive_udpm's record of recent waits
};

}  // namespace

Result<void> check_lcm_url(std::string_view url) {
  auto parsed = parse_udpm_url(url);
  if (!parsed) return node::fail(parsed.error().code, parsed.error().message);
  return {};
}

Result<std::string> lcm_down_url(std::string_view url) {
  auto parsed = parse_udpm_url(url);
  if (!parsed) return node::fail(parsed.error().code, parsed.error().message);
  if (parsed->port == 65535) {
    return node::fail(Errc::invalid_argument, "LCM URL '" + std::string(url) +
                                                  "': a link takes two ports, PORT for frames up and PORT + 1 for frames "
                                                  "down, and there is no port after 65535");
  }
  const std::string_view rest = url.substr(std::string_view("udpm://").size());
  const std::size_t question = rest.find('?');
  const std::string_view options = question == std::string_view::npos ? std::string_view{} : rest.substr(question);
  char group[INET_ADDRSTRLEN] = "";
  inet_ntop(AF_INET, &parsed->group, group, sizeof group);
  return "udpm://" + std::string(group) + ":" + std::to_string(parsed->port + 1) + std::string(options);
}

Result<std::unique_ptr<Transport>> open_lcm(const LcmSettings& settings, std::string_view self_iri,
                                            DropLog log) {
  if (self_iri.empty() || self_iri.find('\0') != std::string_view::npos) {
    return node::fail(Errc::invalid_argument, "open_lcm: the endpoint IRI is empty or has a NUL");
  }
  auto create = [&](const std::string& url) -> Result<lcm_t*> {
    lcm_t* lcm = lcm_create(url.c_str());
    if (lcm == nullptr)
      return node::fail(Errc::io, "open_lcm <" + std::string(self_iri) + ">: lcm_create failed for provider " + url);
    return lcm;
  };
  if (!settings.url.starts_with("udpm://")) {  // another provider: one lcm_t listens and sends
    auto lcm = create(settings.url);
    if (!lcm) return node::fail(lcm.error().code, lcm.error().message);
    auto transport = std::make_unique<LcmTransport>(nullptr, *lcm, nullptr, std::string(self_iri), std::move(log));
    if (auto ok = transport->subscribe(); !ok) return node::fail(ok.error().code, ok.error().message);
    return std::unique_ptr<Transport>(std::move(transport));
  }
  if (auto ok = check_lcm_url(settings.url); !ok) return node::fail(ok.error().code, "open_lcm: " + ok.error().message);
  // A link's end listens on the port of the frames addressed to it and sends on the other.
  std::string listen_url = settings.url, send_url = settings.url;
  if (settings.end != LcmEnd::shared) {
    auto down = lcm_down_url(settings.url);
    if (!down) return node::fail(down.error().code, "open_lcm: " + down.error().message);
    (settings.end == LcmEnd::parent ? send_url : listen_url) = *down;
  }
  auto address = parse_udpm_url(listen_url);
  if (!address) return node::fail(address.error().code, "open_lcm: " + address.error().message);
  std::size_t granted = 0;
  auto socket = UdpmSocket::open(*address, kRecvBufSize, &granted);
  if (!socket) return node::fail(socket.error().code, "open_lcm <" + std::string(self_iri) + ">: " + socket.error().message);
  const std::size_t asked = address->recv_buf_size.value_or(kRecvBufSize);
  if (granted < asked) {
    // What liblcm warns of too: large frames will lose fragments while the receiver is busy.
    // Not a drop, so not the DropLog's.
    std::fprintf(stderr, "lcm <%.*s>: the kernel gave a receive buffer of %zu bytes for %s, %zu asked; raise net.core.rmem_max (docs/transports.md)\n",
                 static_cast<int>(self_iri.size()), self_iri.data(), granted, listen_url.c_str(), asked);
  }
  auto send = create(send_url);
  if (!send) return node::fail(send.error().code, send.error().message);
  return std::unique_ptr<Transport>(
      std::make_unique<LcmTransport>(std::move(*socket), nullptr, *send, std::string(self_iri), std::move(log)));
}

}  // namespace tahvel::federation
