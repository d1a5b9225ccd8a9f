// LCM's udpm protocol, receiving side (lcm_udpm.h). The layout is liblcm 1.3's
// (lcm/lcm_udpm.c: lcm2_header_short_t, lcm2_header_long_t); docs/transports.md says why we
// read it ourselves.
#include "tahvel/federation/lcm_udpm.h"

#include <arpa/inet.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cstring>
#include <vector>

namespace tahvel::federation {
namespace {

constexpr std::uint32_t kMagicShort = 0x4c433032;  // "LC02"
constexpr std::uint32_t kMagicLong = 0x4c433033;   // "LC03"
constexpr std::size_t kShortHeader = 8, kLongHeader = 20;
// LCM channel names are at most 63 bytes (lcm.h, LCM_MAX_CHANNEL_NAME_LENGTH).
constexpr std::size_t kMaxChannel = 63;
constexpr std::size_t kMaxDatagram = 65536;
constexpr std::size_t kMaxSenders = 4096;

std::uint32_t be32(std::string_view b, std::size_t at) {
  return (std::uint32_t(std::uint8_t(b[at])) << 24) | (std::uint32_t(std::uint8_t(b[at + 1])) << 16) |
         (std::uint32_t(std::uint8_t(b[at + 2])) << 8) | std::uint32_t(std::uint8_t(b[at + 3]));
}
std::uint16_t be16(std::string_view b, std::size_t at) {
  return static_cast<std::uint16_t>((std::uint8_t(b[at]) << 8) | std::uint8_t(b[at + 1]));
}

// The channel at the start of `rest`, NUL-terminated; nullopt when there is no NUL within
// kMaxChannel + 1 bytes.
std::optional<std::string_view> channel_at(std::string_view rest) {
  const std::size_t nul = rest.substr(0, kMaxChannel + 1).find('\0');
  if (nul == std::string_view::npos) return std::nullopt;
  return rest.substr(0, nul);
}

std::string errno_text(const char* what) { return std::string(what) + ": " + std::strerror(errno); }

}  // namespace

node::Result<UdpmAddress> parse_udpm_url(std::string_view url) {
  constexpr std::string_view scheme = "udpm://";
  auto bad = [&](const std::string& why) {
    return node::fail(node::Errc::invalid_argument, "LCM URL '" + std::string(url) + "': " + why);
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
  UdpmAddress parsed;
  inet_pton(AF_INET, "239.255.76.67", &parsed.group);  // liblcm's default group
  const std::size_t colon = address.rfind(':');
  const std::string group(address.substr(0, colon));
  // liblcm takes its default group only for an empty address, not for ":PORT".
  if (group.empty() && colon != std::string_view::npos) return bad("no group before ':' (leave the whole address out for LCM's default)");
  if (!group.empty()) {
    if (inet_pton(AF_INET, group.c_str(), &parsed.group) != 1) return bad("'" + group + "' is not an IPv4 address");
    if ((ntohl(parsed.group.s_addr) >> 28) != 0xE) return bad(group + " is not a multicast address (224.0.0.0 to 239.255.255.255)");
  }
  if (colon != std::string_view::npos) {
    const std::string_view text = address.substr(colon + 1);
    std::uint64_t port = 0;
    // A leading 0 would be octal to liblcm (strtol base 0): 07667 is its port 4023.
    if (!number(text, port) || port == 0 || port > 65535 || text.front() == '0')
      return bad("port '" + std::string(text) + "' is not 1..65535 (in decimal, without a leading 0)");
    parsed.port = static_cast<std::uint16_t>(port);
  }
  // One value a name: "ttl=0&ttl=1", read as ttl=0 by whoever reads the file, is ttl=1 to a
  // reader that takes the last, and packets would leave the host.
  std::vector<std::string_view> named;
  while (!options.empty()) {
    const std::size_t amp = options.find('&');
    const std::string_view option = options.substr(0, amp);
    options = amp == std::string_view::npos ? std::string_view{} : options.substr(amp + 1);
    const std::size_t eq = option.find('=');
    const std::string_view name = option.substr(0, eq);
    const std::string_view value = eq == std::string_view::npos ? std::string_view{} : option.substr(eq + 1);
    std::uint64_t n = 0;
    if (std::find(named.begin(), named.end(), name) != named.end())
      return bad("option '" + std::string(name) + "' is given twice");
    named.push_back(name);
    if (name == "ttl") {
      if (!number(value, n) || n > 255) return bad("ttl '" + std::string(value) + "' is not 0..255");
    } else if (name == "recv_buf_size") {
      if (!number(value, n) || n == 0 || n > (1ull << 31)) return bad("recv_buf_size '" + std::string(value) + "' is not a size in bytes");
      parsed.recv_buf_size = n;
    } else {
      return bad("unknown option '" + std::string(option) + "' (known: ttl, recv_buf_size)");
    }
  }
  return parsed;
}

// ---- UdpmReassembler --------------------------------------------------------------------------

UdpmReassembler::Taken UdpmReassembler::take(std::uint64_t sender, std::string_view datagram) {
  ++takes_;
  // The message returned last is the caller's no longer: its buffer (up to max_held_) goes.
  if (!whole_.empty()) std::string().swap(whole_);
  if (datagram.size() < 4) return {{}, "shorter than an LCM header (" + std::to_string(datagram.size()) + " bytes)"};
  const std::uint32_t magic = be32(datagram, 0);
  if (magic == kMagicLong) return take_fragment(sender, datagram);
  if (magic != kMagicShort) {
    char hex[16];
    std::snprintf(hex, sizeof hex, "0x%08x", magic);
    return {{}, std::string("not an LCM datagram (magic ") + hex + ", LCM's are LC02 and LC03)"};
  }
  if (datagram.size() < kShortHeader) return {{}, "an LCM short message cut inside its header"};
  auto channel = channel_at(datagram.substr(kShortHeader));
  if (!channel) return {{}, "an LCM short message whose channel name has no end within 64 bytes"};
  if (*channel != channel_) return {};
  return {datagram.substr(kShortHeader + channel->size() + 1), {}};
}

UdpmReassembler::Taken UdpmReassembler::take_fragment(std::uint64_t sender, std::string_view d) {
  if (d.size() < kLongHeader) return {{}, "an LCM fragment cut inside its header"};
  const std::uint32_t seqno = be32(d, 4), size = be32(d, 8), offset = be32(d, 12);
  const std::uint16_t number = be16(d, 16), fragments = be16(d, 18);
  const std::string where = "LCM fragment " + std::to_string(number) + " of " + std::to_string(fragments) +
                            " of message " + std::to_string(seqno);
  if (fragments == 0 || number >= fragments) return {{}, where + ": no such fragment"};
  // liblcm puts at least a byte of the message in every fragment.
  if (fragments > size) return {{}, where + ": more fragments than the message's " + std::to_string(size) + " bytes"};
  std::string_view part = d.substr(kLongHeader);
  std::optional<std::string_view> channel;
  if (number == 0) {
    channel = channel_at(part);
    if (!channel) return {{}, where + ": its channel name has no end within 64 bytes"};
    part.remove_prefix(channel->size() + 1);
  }
  if (std::uint64_t(offset) + part.size() > size)
    return {{}, where + ": bytes " + std::to_string(offset) + ".." + std::to_string(std::uint64_t(offset) + part.size()) +
                    " lie past the message's " + std::to_string(size)};

  auto it = partial_.find(sender);
  // A new message from this sender ends the one before it (liblcm does the same): one sender
  // sends one message at a time, so the rest of the earlier one is not coming.
  if (it != partial_.end() && (it->second.seqno != seqno || it->second.size != size || it->second.fragments != fragments)) {
    drop(it);
    it = partial_.end();
  }
  if (it == partial_.end()) {
    if (channel && *channel != channel_) {
      // Other channels' senders come and go (a new port at each restart): their marks are
      // forgotten before they pile up.
      if (partial_.size() >= kMaxSenders) std::erase_if(partial_, [](const auto& e) { return e.second.other_channel; });
      if (partial_.size() >= kMaxSenders) return {};
      Partial skip;
      skip.seqno = seqno, skip.size = size, skip.fragments = fragments, skip.other_channel = true;
      partial_.emplace(sender, std::move(skip));
      return {};
    }
    if (held_size(size, fragments) > max_held_)
      return {{}, where + ": a message of " + std::to_string(size) + " bytes, more than the " +
                      std::to_string(max_held_) + " held for messages being reassembled"};
    if (partial_.size() >= kMaxSenders) std::erase_if(partial_, [](const auto& e) { return e.second.other_channel; });
    if (!make_room(held_size(size, fragments), sender)) return {{}, where + ": no room to reassemble it"};
    Partial p;
    p.seqno = seqno, p.size = size, p.fragments = fragments, p.started = takes_;
    p.have.assign(fragments, '\0');
    p.data.reset(new char[size]);
    held_bytes_ += held_size(size, fragments);
    it = partial_.emplace(sender, std::move(p)).first;
  }
  Partial& p = it->second;
  if (p.other_channel) return {};
  if (channel && *channel != channel_) {  // fragments before fragment 0 were buffered for nothing
    drop(it);
    Partial skip;
    skip.seqno = seqno, skip.size = size, skip.fragments = fragments, skip.other_channel = true;
    partial_.emplace(sender, std::move(skip));
    return {};
  }
  if (p.have[number]) return {};  // a duplicate
  p.have[number] = 1;
  ++p.received;
  std::memcpy(p.data.get() + offset, part.data(), part.size());
  p.spans.emplace_back(offset, static_cast<std::uint32_t>(part.size()));
  if (p.received < p.fragments) return {};
  std::sort(p.spans.begin(), p.spans.end());
  std::uint64_t covered = 0;
  for (const auto& [at, length] : p.spans) {
    if (at != covered) break;
    covered += length;
  }
  if (covered != p.size) {
    drop(it);
    return {{}, where + ": its fragments do not tile the message's " + std::to_string(size) +
                    " bytes (they overlap or leave a hole)"};
  }
  whole_.assign(p.data.get(), p.size);
  drop(it);
  return {std::string_view(whole_), {}};
}

void UdpmReassembler::drop(std::unordered_map<std::uint64_t, Partial>::iterator it) {
  if (!it->second.other_channel) held_bytes_ -= held_size(it->second.size, it->second.fragments);
  partial_.erase(it);
}

bool UdpmReassembler::make_room(std::size_t bytes, std::uint64_t keep) {
  // Also a sender's mark at most: a host has only so many sending sockets, and senders that
  // vanish mid-message (restarted on another port) leave theirs.
  while (held_bytes_ + bytes > max_held_ || partial_.size() >= kMaxSenders) {
    auto oldest = partial_.end();
    for (auto it = partial_.begin(); it != partial_.end(); ++it)
      if (it->first != keep && !it->second.other_channel && (oldest == partial_.end() || it->second.started < oldest->second.started))
        oldest = it;
    if (oldest == partial_.end()) return false;
    drop(oldest);
  }
  return true;
}

// ---- UdpmSocket -------------------------------------------------------------------------------

node::Result<std::unique_ptr<UdpmSocket>> UdpmSocket::open(const UdpmAddress& address, std::size_t default_recv_buf,
                                                           std::size_t* granted) {
  char group[INET_ADDRSTRLEN] = "";
  inet_ntop(AF_INET, &address.group, group, sizeof group);
  const std::string where = std::string("udpm ") + group + ":" + std::to_string(address.port) + ": ";
  const int fd = ::socket(AF_INET, SOCK_DGRAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
  if (fd < 0) return node::fail(node::Errc::io, where + errno_text("socket"));
  std::unique_ptr<UdpmSocket> socket(new UdpmSocket(fd));
  auto failed = [&](const char* what) { return node::fail(node::Errc::io, where + errno_text(what)); };
  // As liblcm: every LCM instance on the host binds the group's port.
  const int one = 1;
  if (setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one) != 0) return failed("SO_REUSEADDR");
  const int asked = static_cast<int>(std::min<std::uint64_t>(address.recv_buf_size.value_or(default_recv_buf), 1u << 30));
  // Past net.core.rmem_max where the process may (CAP_NET_ADMIN); else up to it. The buffer is
  // what holds a burst while the thread that reads the socket applies the batch before it.
  if (setsockopt(fd, SOL_SOCKET, SO_RCVBUFFORCE, &asked, sizeof asked) != 0 &&
      setsockopt(fd, SOL_SOCKET, SO_RCVBUF, &asked, sizeof asked) != 0)
    return failed("SO_RCVBUF");
  int got = 0;
  socklen_t got_size = sizeof got;
  if (getsockopt(fd, SOL_SOCKET, SO_RCVBUF, &got, &got_size) != 0) return failed("SO_RCVBUF");
  // Linux reports twice what it reserves for data (the rest is its bookkeeping).
  if (granted != nullptr) *granted = static_cast<std::size_t>(got) / 2;
  sockaddr_in bind_to{};
  bind_to.sin_family = AF_INET;
  bind_to.sin_port = htons(address.port);
  bind_to.sin_addr.s_addr = htonl(INADDR_ANY);
  if (::bind(fd, reinterpret_cast<sockaddr*>(&bind_to), sizeof bind_to) != 0) return failed("bind");
#ifdef IP_MULTICAST_ALL
  // Only this group's datagrams: Linux otherwise delivers those of every group any socket of
  // the host joined on this port.
  const int zero = 0;
  if (setsockopt(fd, IPPROTO_IP, IP_MULTICAST_ALL, &zero, sizeof zero) != 0) return failed("IP_MULTICAST_ALL");
#endif
  ip_mreq join{};
  join.imr_multiaddr = address.group;
  join.imr_interface.s_addr = htonl(INADDR_ANY);
  if (setsockopt(fd, IPPROTO_IP, IP_ADD_MEMBERSHIP, &join, sizeof join) != 0) return failed("IP_ADD_MEMBERSHIP");
  socket->buffer_.resize(kMaxDatagram);
  return socket;
}

UdpmSocket::~UdpmSocket() { ::close(fd_); }

node::Result<std::optional<UdpmSocket::Datagram>> UdpmSocket::read() {
  sockaddr_in from{};
  while (true) {
    socklen_t from_size = sizeof from;
    const ssize_t n = ::recvfrom(fd_, buffer_.data(), buffer_.size(), MSG_DONTWAIT, reinterpret_cast<sockaddr*>(&from), &from_size);
    if (n >= 0) {
      const std::uint64_t sender = (std::uint64_t(ntohl(from.sin_addr.s_addr)) << 16) | ntohs(from.sin_port);
      return std::optional<Datagram>(Datagram{sender, std::string_view(buffer_.data(), static_cast<std::size_t>(n))});
    }
    if (errno == EAGAIN || errno == EWOULDBLOCK) return std::optional<Datagram>();
    if (errno != EINTR) return node::fail(node::Errc::io, errno_text("recvfrom"));
  }
}

node::Result<bool> UdpmSocket::wait(std::chrono::milliseconds timeout) {
  pollfd p{fd_, POLLIN, 0};
  const int n = ::poll(&p, 1, static_cast<int>(std::min<std::int64_t>(timeout.count(), 1 << 30)));
  if (n < 0 && errno != EINTR) return node::fail(node::Errc::io, errno_text("poll"));
  return n > 0;
}

std::string UdpmSocket::sender_name(std::uint64_t sender) {
  const std::uint32_t ip = static_cast<std::uint32_t>(sender >> 16);
  return std::to_string(ip >> 24) + "." + std::to_string((ip >> 16) & 255) + "." + std::to_string((ip >> 8) & 255) + "." +
         std::to_string(ip & 255) + ":" + std::to_string(sender & 0xFFFF);
}

}  // namespace tahvel::federation
