// The LCM binding (docs/transports.md): one lcm_t per endpoint, subscribed to the one channel
// named after its own IRI (lcm_channel()); send() publishes a tahvel_frame_t on the channel of
// frame.to, through a second, send-only lcm_t when the endpoint is a link's end (LcmEnd) and
// sends on the other port. Tuned for the sensor-to-gateway LAN: small frames at a steady rate,
// occasionally a chunk of raw signal of a few MB (LCM fragments it over UDP multicast).
//
// LCM may lose datagrams (a full socket buffer, a lost fragment): the link resends. What arrives
// is decoded here, from the raw bytes, so that anything malformed is reported to the DropLog
// with its channel and size instead of being printed by LCM's generated handler.
#include <arpa/inet.h>
#include <sched.h>
#include <lcm/lcm.h>

#include <algorithm>
#include <charconv>
#include <chrono>
#include <cstring>
#include <deque>
#include <mutex>
#include <vector>

#include "tahvel/federation/transport.h"
#include "tahvel/federation/wire_names.h"
#include "tahvel/node/node.h"
#include "tahvel_frame_t.h"
#include "wire_common.h"

namespace tahvel::federation {
namespace {

// Frames LCM keeps for our subscription between two lcm_handle calls (its default is 30, too few
// for a burst between two receive() calls; beyond this LCM drops the newest).
constexpr int kQueueCapacity = 10000;

// The kernel socket buffer LCM asks for when the URL does not say (udpm's recv_buf_size; the
// kernel caps it at net.core.rmem_max). The kernel default (~200 kB) holds only three of the
// 64 kB fragments of a large frame, so a frame of a few MB arriving while the receiving thread
// is busy would lose a fragment, and with it the whole frame.
constexpr const char* kRecvBufSize = "recv_buf_size=4194304";

// settings.url, with kRecvBufSize added to a udpm:// URL that sets no recv_buf_size.
std::string effective_url(const std::string& url) {
  if (url.rfind("udpm://", 0) != 0 || url.find("recv_buf_size=") != std::string::npos) return url;
  return url + (url.find('?') == std::string::npos ? "?" : "&") + kRecvBufSize;
}

class LcmTransport final : public Transport {
 public:
  // `listen` receives (and sends, if `send` is null); `send` is never subscribed, so liblcm
  // starts no receive thread for it. Takes both.
  LcmTransport(lcm_t* listen, lcm_t* send, std::string self, DropLog log)
      : lcm_(listen),
        send_lcm_(send),
        self_(std::move(self)),
        channel_(lcm_channel(self_)),
        log_(wire::or_stderr(std::move(log))) {}

  ~LcmTransport() override {
    if (sub_ != nullptr) lcm_unsubscribe(lcm_, sub_);
    lcm_destroy(lcm_);
    if (send_lcm_ != nullptr) lcm_destroy(send_lcm_);
  }

  LcmTransport(const LcmTransport&) = delete;
  LcmTransport& operator=(const LcmTransport&) = delete;

  Result<void> subscribe() {
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
    tahvel_frame_t msg{};
    msg.version = static_cast<int16_t>(frame.version);
    msg.fingerprint = static_cast<int64_t>(frame.fingerprint);
    msg.kind = static_cast<uint8_t>(frame.kind);
    msg.from = const_cast<char*>(frame.from.c_str());
    msg.to = const_cast<char*>(frame.to.c_str());
    msg.seq = static_cast<int64_t>(frame.seq);
    msg.prev = static_cast<int64_t>(frame.prev);
    msg.ack = static_cast<int64_t>(frame.ack);
    msg.body_size = static_cast<int32_t>(frame.body.size());
    msg.body = reinterpret_cast<uint8_t*>(const_cast<char*>(frame.body.data()));
    const int size = tahvel_frame_t_encoded_size(&msg);
    std::vector<char> bytes(static_cast<std::size_t>(size));
    if (tahvel_frame_t_encode(bytes.data(), 0, size, &msg) != size) {
      return node::fail(Errc::invalid_argument,
                        "lcm <" + self_ + ">: cannot encode " + wire::describe(frame));
    }
    const std::string channel = lcm_channel(frame.to);
    // lcm_publish on udpm locks internally; this lock also covers providers that do not.
    std::lock_guard lock(send_mutex_);
    lcm_t* via = send_lcm_ != nullptr ? send_lcm_ : lcm_;
    if (lcm_publish(via, channel.c_str(), bytes.data(), static_cast<unsigned>(size)) != 0) {
      return node::fail(Errc::io, "lcm <" + self_ + ">: publish of " + std::to_string(size) +
                                      " bytes on channel " + channel + " failed (" +
                                      wire::describe(frame) + ")");
    }
    return {};
  }

  Result<std::optional<Frame>> receive(std::chrono::milliseconds timeout) override {
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
      // First look without blocking for a while, as a waiter on the store does (node.h,
      // "Waiting"): LCM's own thread has the datagram, and waking this one from its pipe costs
      // a futex-sized wake-up on virtual CPUs. Only while recent waits were short.
      if (!spin_for_frame(left)) return handle_error();
      if (!queue_.empty()) break;
      // lcm_handle_timeout dispatches at most one message to on_message (which may drop it).
      if (lcm_handle_timeout(lcm_, static_cast<int>(left.count())) < 0) return handle_error();
    }
    if (queue_.empty()) return std::optional<Frame>();
    Frame frame = std::move(queue_.front());
    queue_.pop_front();
    return std::optional<Frame>(std::move(frame));
  }

 private:
  // Polls LCM without blocking for up to the process's wait spin (at most `left`), yielding
  // between looks; false on an LCM error. Four spins in a row that found nothing make the next
  // waits block at once, bar a probe in 64.
  bool spin_for_frame(std::chrono::milliseconds left) {
    using clock = std::chrono::steady_clock;
    ++waits_;
    const auto budget = std::min<std::chrono::nanoseconds>(node::wait_spin(), left);
    if (budget.count() <= 0 || (misses_ >= 4 && waits_ % 64 != 0)) return true;
    const auto end = clock::now() + budget;
    while (queue_.empty() && clock::now() < end) {
      if (lcm_handle_timeout(lcm_, 0) < 0) return false;
      if (queue_.empty()) sched_yield();
    }
    misses_ = queue_.empty() ? misses_ + 1 : 0;
    return true;
  }

  Result<std::optional<Frame>> handle_error() {
    return node::fail(Errc::io,
                      "lcm <" + self_ + ">: lcm_handle_timeout failed on channel " + channel_);
  }

  static void on_message(const lcm_recv_buf_t* rbuf, const char* channel, void* user) {
    static_cast<LcmTransport*>(user)->accept(rbuf, channel);
  }

  void accept(const lcm_recv_buf_t* rbuf, const char* channel) {
    const std::string where = "lcm <" + self_ + ">: dropped ";
    tahvel_frame_t msg{};
    const int used = tahvel_frame_t_decode(rbuf->data, 0, static_cast<int>(rbuf->data_size), &msg);
    if (used < 0) {
      log_(where + std::to_string(rbuf->data_size) + " bytes on channel " + channel +
           ": not a tahvel_frame_t (LCM decode failed: type hash, length or string)");
      return;
    }
    Frame frame;
    frame.version = static_cast<std::uint16_t>(msg.version);
    frame.fingerprint = static_cast<std::uint64_t>(msg.fingerprint);
    frame.kind = static_cast<FrameKind>(msg.kind);
    frame.from = msg.from != nullptr ? msg.from : "";
    frame.to = msg.to != nullptr ? msg.to : "";
    frame.seq = static_cast<std::uint64_t>(msg.seq);
    frame.prev = static_cast<std::uint64_t>(msg.prev);
    frame.ack = static_cast<std::uint64_t>(msg.ack);
    if (msg.body_size > 0) {
      frame.body.assign(reinterpret_cast<const char*>(msg.body),
                        static_cast<std::size_t>(msg.body_size));
    }
    tahvel_frame_t_decode_cleanup(&msg);
    if (static_cast<std::size_t>(used) != rbuf->data_size) {
      log_(where + wire::describe(frame) + " on channel " + channel + ": " +
           std::to_string(rbuf->data_size - static_cast<std::size_t>(used)) +
           " trailing bytes after the frame");
      return;
    }
    if (auto why = wire::reject_reason(frame, self_)) {
      log_(where + wire::describe(frame) + " on channel " + channel + ": " + *why);
      return;
    }
    queue_.push_back(std::move(frame));
  }

  lcm_t* lcm_;
  lcm_t* send_lcm_;  // null: sends through lcm_
  lcm_subscription_t* sub_ = nullptr;
  std::string self_;
  std::string channel_;
  DropLog log_;
  std::mutex send_mutex_;
  std::deque<Frame> queue_;  // decoded frames; touched only by the receive() thread
  unsigned misses_ = 0, waits_ = 0;  // spin_for_frame's record of recent waits
};

}  // namespace

Result<void> check_lcm_url(std::string_view url) {
  constexpr std::string_view scheme = "udpm://";
  auto bad = [&](const std::string& why) {
    return node::fail(Errc::invalid_argument, "LCM URL '" + std::string(url) + "': " + why);
  };
  if (!url.starts_with(scheme))
    return bad("not udpm://GROUP:PORT[?ttl=N], LCM over UDP multicast with GROUP an IPv4 multicast address");
  std::string_view rest = url.substr(scheme.size());
  const std::size_t question = rest.find('?');
  const std::string_view address = rest.substr(0, question);
  std::string_view options = question == std::string_view::npos ? std::string_view{} : rest.substr(question + 1);
  auto number = [](std::string_view text, std::uint64_t& out) {
    auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), out);
    return !text.empty() && ec == std::errc() && end == text.data() + text.size();
  };
  const std::size_t colon = address.rfind(':');
  const std::string group(address.substr(0, colon));
  // liblcm takes its default group only for an empty address, not for ":PORT".
  if (group.empty() && colon != std::string_view::npos) return bad("no group before ':' (leave the whole address out for LCM's default)");
  if (!group.empty()) {
    in_addr a{};
    if (inet_pton(AF_INET, group.c_str(), &a) != 1) return bad("'" + group + "' is not an IPv4 address");
    if ((ntohl(a.s_addr) >> 28) != 0xE) return bad(group + " is not a multicast address (224.0.0.0 to 239.255.255.255)");
  }
  if (colon != std::string_view::npos) {
    const std::string_view text = address.substr(colon + 1);
    std::uint64_t port = 0;
    // A leading 0 would be octal to liblcm (strtol base 0): 07667 is its port 4023.
    if (!number(text, port) || port == 0 || port > 65535 || text.front() == '0')
      return bad("port '" + std::string(text) + "' is not 1..65535 (in decimal, without a leading 0)");
  }
  while (!options.empty()) {
    const std::size_t amp = options.find('&');
    const std::string_view option = options.substr(0, amp);
    options = amp == std::string_view::npos ? std::string_view{} : options.substr(amp + 1);
    const std::size_t eq = option.find('=');
    const std::string_view name = option.substr(0, eq);
    const std::string_view value = eq == std::string_view::npos ? std::string_view{} : option.substr(eq + 1);
    std::uint64_t n = 0;
    if (name == "ttl") {
      if (!number(value, n) || n > 255) return bad("ttl '" + std::string(value) + "' is not 0..255");
    } else if (name == "recv_buf_size") {
      if (!number(value, n) || n == 0 || n > (1ull << 31)) return bad("recv_buf_size '" + std::string(value) + "' is not a size in bytes");
    } else {
      return bad("unknown option '" + std::string(option) + "' (known: ttl, recv_buf_size)");
    }
  }
  return {};
}

Result<std::string> lcm_down_url(std::string_view url) {
  if (auto ok = check_lcm_url(url); !ok) return node::fail(ok.error().code, ok.error().message);
  const std::string_view rest = url.substr(std::string_view("udpm://").size());
  const std::size_t question = rest.find('?');
  const std::string_view address = rest.substr(0, question);
  const std::string_view options = question == std::string_view::npos ? std::string_view{} : rest.substr(question);
  const std::size_t colon = address.rfind(':');
  std::string group(address.substr(0, colon));
  std::uint32_t port = 7667;  // liblcm's defaults, as check_lcm_url describes
  if (group.empty()) group = "239.255.76.67";
  if (colon != std::string_view::npos)
    std::from_chars(address.data() + colon + 1, address.data() + address.size(), port);
  if (port == 65535) {
    return node::fail(Errc::invalid_argument, "LCM URL '" + std::string(url) +
                                                  "': a link takes two ports, PORT for frames up and PORT + 1 for frames "
                                                  "down, and there is no port after 65535");
  }
  return "udpm://" + group + ":" + std::to_string(port + 1) + std::string(options);
}

Result<std::unique_ptr<Transport>> open_lcm(const LcmSettings& settings, std::string_view self_iri,
                                            DropLog log) {
  if (self_iri.empty() || self_iri.find('\0') != std::string_view::npos) {
    return node::fail(Errc::invalid_argument, "open_lcm: the endpoint IRI is empty or has a NUL");
  }
  const bool udpm = settings.url.starts_with("udpm://");
  if (udpm) {
    if (auto ok = check_lcm_url(settings.url); !ok) return node::fail(ok.error().code, "open_lcm: " + ok.error().message);
  }
  // A link's end listens on the port of the frames addressed to it and sends on the other.
  std::string listen_url = settings.url, send_url;
  if (udpm && settings.end != LcmEnd::shared) {
    auto down = lcm_down_url(settings.url);
    if (!down) return node::fail(down.error().code, "open_lcm: " + down.error().message);
    if (settings.end == LcmEnd::parent) {
      send_url = *down;
    } else {
      listen_url = *down;
      send_url = settings.url;
    }
  }
  auto create = [&](const std::string& url) -> Result<lcm_t*> {
    const std::string effective = effective_url(url);
    lcm_t* lcm = lcm_create(effective.c_str());
    if (lcm == nullptr)
      return node::fail(Errc::io, "open_lcm <" + std::string(self_iri) + ">: lcm_create failed for provider " + effective);
    return lcm;
  };
  auto listen = create(listen_url);
  if (!listen) return node::fail(listen.error().code, listen.error().message);
  lcm_t* send = nullptr;
  if (!send_url.empty()) {
    auto created = create(send_url);
    if (!created) {
      lcm_destroy(*listen);
      return node::fail(created.error().code, created.error().message);
    }
    send = *created;
  }
  auto transport = std::make_unique<LcmTransport>(*listen, send, std::string(self_iri), std::move(log));
  if (auto ok = transport->subscribe(); !ok) return node::fail(ok.error().code, ok.error().message);
  return std::unique_ptr<Transport>(std::move(transport));
}

}  // namespace tahvel::federation
