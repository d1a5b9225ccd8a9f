// What the LCM and DDS bindings promise beyond the conformance suite: wire names, what send()
// refuses, and how opening fails (transport.h, wire_names.h, docs/transports.md).
#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cstdlib>
#include <fstream>
#include <functional>
#include <iterator>
#include <mutex>
#include <string>
#include <vector>

#include "tahvel/federation/lcm_frame.h"
#include "tahvel/federation/wire_names.h"
#include "wire_settings.h"

namespace tahvel::federation {
namespace {

using namespace std::chrono_literals;

void require_netns() {
  const char* in = std::getenv("TAHVEL_IN_NETNS");
  ASSERT_TRUE(in != nullptr && std::string(in) == "1")
      << "opens sockets: run under tests/tools/netns-run";
}

TEST(WireNames, AreShortFixedAndDerivedFromTheIri) {
  // FNV-1a of the empty string is the offset basis.
  EXPECT_EQ(lcm_channel(""), "TVcbf29ce484222325");
  EXPECT_EQ(dds_topic(""), "tahvel_frame_cbf29ce484222325");
  const std::string long_iri = "https://example.org/hospital/" + std::string(500, 'x') + "/home1";
  EXPECT_EQ(lcm_channel(long_iri).size(), 18u);
  EXPECT_EQ(lcm_channel(long_iri), lcm_channel(long_iri));
  EXPECT_NE(lcm_channel("http://h/hospital/home1"), lcm_channel("http://h/hospital/home2"));
  EXPECT_EQ(lcm_channel("http://h/a").substr(2), dds_topic("http://h/a").substr(13));
}

class WireSend : public ::testing::TestWithParam<std::string> {
 protected:
  void SetUp() override { require_netns(); }
  std::unique_ptr<Transport> open(const std::string& iri) {
    auto t = GetParam() == "lcm" ? open_lcm(conformance::test_lcm_settings(), iri)
                                 : open_dds(conformance::test_dds_settings(), iri);
    EXPECT_TRUE(t) << (t ? "" : t.error().message);
    return t ? std::move(*t) : nullptr;
  }
};

TEST_P(WireSend, RefusesEmptyToNulInAnIriAndAnOversizedBody) {
  auto a = open("tahvel://wire-send/" + GetParam() + "/a");
  ASSERT_TRUE(a);
  Frame f;
  f.from = a->self();
  f.to = "";
  auto empty = a->send(f);
  ASSERT_FALSE(empty);
  EXPECT_EQ(empty.error().code, Errc::invalid_argument);
  EXPECT_NE(empty.error().message.find("empty `to`"), std::string::npos) << empty.error().message;

  f.to = std::string("tahvel://x\0y", 12);
  auto nul = a->send(f);
  ASSERT_FALSE(nul);
  EXPECT_NE(nul.error().message.find("NUL"), std::string::npos) << nul.error().message;

  f.to = "tahvel://wire-send/" + GetParam() + "/nobody";
  f.body.assign((64u << 20) + 1, 'x');
  auto big = a->send(f);
  ASSERT_FALSE(big);
  EXPECT_EQ(big.error().code, Errc::invalid_argument);
  EXPECT_NE(big.error().message.find("67108865 bytes"), std::string::npos) << big.error().message;
}

INSTANTIATE_TEST_SUITE_P(Wire, WireSend, ::testing::Values("lcm", "dds"),
                         [](const auto& info) { return info.param; });

// A packed DDS sample (kind kPackedKind, docs/transports.md "Packing") is decoded strictly:
// the frames before one that does not decode come through, the rest is dropped with a line
// saying why; a count that does not match drops the whole sample; a frame of an unknown kind
// inside is dropped as it would be alone; a frame of another protocol version is never packed
// (it would pass as this build's). Malformed packs are sent as send() passes a frame of that
// kind: as it is, one sample.
std::string packed(FrameKind kind, std::uint64_t seq, const std::string& body, std::size_t claimed_size) {
  std::string out(1, static_cast<char>(kind));
  for (std::uint64_t v : {seq, seq - 1, std::uint64_t{0}})
    for (int i = 0; i < 8; ++i) out.push_back(static_cast<char>((v >> (8 * i)) & 0xff));
  for (int i = 0; i < 4; ++i) out.push_back(static_cast<char>((claimed_size >> (8 * i)) & 0xff));
  return out + body;
}

TEST(WireDds, APackedSampleThatDoesNotDecodeIsDroppedFromThereWithAReason) {
  require_netns();
  std::vector<std::string> lines;
  std::mutex mu;
  auto a = open_dds(conformance::test_dds_settings(), "tahvel://wire-pack/a").value();
  auto b = open_dds(conformance::test_dds_settings(), "tahvel://wire-pack/b", [&](std::string_view l) {
             std::lock_guard lock(mu);
             lines.emplace_back(l);
           }).value();
  auto sample = [&](std::uint64_t count, std::string body) {
    Frame f;
    f.kind = static_cast<FrameKind>(kPackedKind);
    f.from = a->self();
    f.to = b->self();
    f.seq = count;
    f.body = std::move(body);
    ASSERT_TRUE(a->send(f));
  };
  const std::string one = packed(FrameKind::up, 1, "one", 3), two = packed(FrameKind::up, 2, "two", 3);
  sample(3, one + two + "xyz");                                              // a header cut short
  sample(2, packed(FrameKind::up, 3, "three", 5) + packed(FrameKind::up, 4, "four", 100));  // a body cut short
  sample(2, packed(FrameKind::up, 5, "five", 4));                           // says 2, holds 1
  sample(2, packed(static_cast<FrameKind>(200), 6, "six", 3) + packed(FrameKind::up, 7, "seven", 5));
  Frame good;
  good.kind = FrameKind::up;
  good.from = a->self();
  good.to = b->self();
  good.seq = 8;
  Frame other_version = good;  // in a run, but a pack carries this build's version only
  other_version.seq = 9;
  other_version.version = kProtocolVersion + 1;
  other_version.ack = kMoreFollow;
  ASSERT_TRUE(a->send(other_version));
  ASSERT_TRUE(a->send(good));
  std::vector<std::uint64_t> seqs;
  for (;;) {
    auto got = b->receive(10s).value();
    ASSERT_TRUE(got.has_value()) << "the good frame did not come";
    seqs.push_back(got->seq);
    if (got->seq == 8) break;
  }
  EXPECT_EQ(seqs, (std::vector<std::uint64_t>{1, 2, 3, 7, 8}));
  std::string all;
  for (const auto& l : lines) all += l + "\n";
  EXPECT_EQ(lines.size(), 5u) << all;
  EXPECT_NE(all.find("protocol version " + std::to_string(kProtocolVersion + 1)), std::string::npos) << all;
  EXPECT_NE(all.find("packed frame 3 truncated in its header"), std::string::npos) << all;
  EXPECT_NE(all.find("packed frame 2 says its body has 100 bytes, 4 are left"), std::string::npos) << all;
  EXPECT_NE(all.find("the sample says it packs 2 frames, it holds 1"), std::string::npos) << all;
  EXPECT_NE(all.find("kind 200 unknown"), std::string::npos) << all;
}

TEST(WireOpen, EmptyIriIsRefused) {
  require_netns();
  auto lcm = open_lcm(conformance::test_lcm_settings(), "");
  ASSERT_FALSE(lcm);
  EXPECT_EQ(lcm.error().code, Errc::invalid_argument);
  auto dds = open_dds(conformance::test_dds_settings(), "");
  ASSERT_FALSE(dds);
  EXPECT_EQ(dds.error().code, Errc::invalid_argument);
}

TEST(WireOpen, LcmWithAnUnknownProviderFailsNamingTheUrl) {
  require_netns();
  LcmSettings settings;
  settings.url = "nosuchprovider://nowhere";
  auto t = open_lcm(settings, "tahvel://wire-open/lcm");
  ASSERT_FALSE(t);
  EXPECT_EQ(t.error().code, Errc::io);
  EXPECT_NE(t.error().message.find("nosuchprovider://nowhere"), std::string::npos)
      << t.error().message;
}

TEST(WireOpen, DdsRefusesAnotherConfigurationOfADomainThatRuns) {
  require_netns();
  DdsSettings settings = conformance::test_dds_settings();
  auto first = open_dds(settings, "tahvel://wire-open/dds/1");
  ASSERT_TRUE(first) << first.error().message;
  auto same = open_dds(settings, "tahvel://wire-open/dds/2");
  EXPECT_TRUE(same) << same.error().message;
  DdsSettings other = settings;
  other.config += "<!-- another configuration -->";
  auto refused = open_dds(other, "tahvel://wire-open/dds/3");
  ASSERT_FALSE(refused);
  EXPECT_EQ(refused.error().code, Errc::invalid_argument);
  EXPECT_NE(refused.error().message.find("another configuration"), std::string::npos)
      << refused.error().message;
  // An empty configuration joins the domain as it runs.
  DdsSettings empty = settings;
  empty.config.clear();
  EXPECT_TRUE(open_dds(empty, "tahvel://wire-open/dds/4"));
}

TEST(WireOpen, DdsWithAnInvalidConfigurationFails) {
  require_netns();
  DdsSettings settings;
  settings.domain = 77;
  settings.config =
      "<CycloneDDS><Domain><General><NoSuchSetting>1</NoSuchSetting></General>"
      "</Domain></CycloneDDS>";
  auto t = open_dds(settings, "tahvel://wire-open/dds/bad");
  ASSERT_FALSE(t);
  EXPECT_NE(t.error().message.find("dds_create_domain 77"), std::string::npos) << t.error().message;
  // The failed domain is not left registered: a good configuration of it works afterwards.
  settings.config = conformance::test_dds_settings().config;
  auto good = open_dds(settings, "tahvel://wire-open/dds/good");
  EXPECT_TRUE(good) << (good ? "" : good.error().message);
}

// The reason Cyclone logs (an interface the machine does not have: the multi-host template's
// eth0 on a machine with ens3) goes with the error, which is what `status` shows of the link;
// "Error (-1)" alone sent the operator to the link's log.
TEST(WireOpen, DdsWithAnInterfaceThatIsNotThereSaysSo) {
  require_netns();
  DdsSettings settings;
  settings.domain = 78;
  settings.config = conformance::test_dds_settings().config;
  const std::string lo = "<NetworkInterface name=\"lo\"";
  const auto at = settings.config.find(lo);
  ASSERT_NE(at, std::string::npos);
  settings.config.replace(at, lo.size(), "<NetworkInterface name=\"eth9\"");
  auto t = open_dds(settings, "tahvel://wire-open/dds/eth9");
  ASSERT_FALSE(t);
  EXPECT_NE(t.error().message.find("(Cyclone DDS: eth9: does not match an available interface"), std::string::npos)
      << t.error().message;
}

// What liblcm refuses only with "lcm_create failed" (a link configured so dies at each
// restart), or takes for something else than written, said part by part; the forms LCM takes
// as written pass.
TEST(WireOpen, LcmUrlCheckNamesWhatIsWrongAndPassesWhatLcmAccepts) {
  for (const char* url : {"udpm://239.255.76.67:7667?ttl=0", "udpm://", "udpm://?ttl=1", "udpm://239.255.76.67",
                          "udpm://224.0.0.1:1?ttl=0&recv_buf_size=4194304", "udpm://239.255.255.255:65535"})
    EXPECT_TRUE(check_lcm_url(url)) << url << ": " << check_lcm_url(url).error().message;
  const std::pair<const char*, const char*> refused[] = {
      {"udp://239.255.76.67:7667", "not udpm://GROUP:PORT"},
      {"udpm://10.0.0.1:7667", "10.0.0.1 is not a multicast address"},
      {"udpm://240.0.0.1:7667", "240.0.0.1 is not a multicast address"},
      {"udpm://hospital.example:7667", "'hospital.example' is not an IPv4 address"},
      {"udpm://239.255.76.67:0", "port '0' is not 1..65535"},
      {"udpm://239.255.76.67:7667x", "port '7667x' is not 1..65535"},
      {"udpm://239.255.76.67:07667", "port '07667' is not 1..65535 (in decimal, without a leading 0)"},
      {"udpm://:7667", "no group before ':'"},
      {"udpm://239.255.76.67:7667?ttl=-1", "ttl '-1' is not 0..255"},
      {"udpm://239.255.76.67:7667?ttl=0&tll=1", "unknown option 'tll=1' (known: ttl, recv_buf_size)"},
      {"udpm://239.255.76.67:7667?recv_buf_size=lots", "recv_buf_size 'lots' is not a size in bytes"},
      {"udpm://239.255.76.67:7667?ttl=0&ttl=1", "option 'ttl' is given twice"},
  };
  for (const auto& [url, why] : refused) {
    auto checked = check_lcm_url(url);
    ASSERT_FALSE(checked) << url;
    EXPECT_EQ(checked.error().code, Errc::invalid_argument);
    EXPECT_NE(checked.error().message.find(std::string("LCM URL '") + url + "': " + why), std::string::npos)
        << checked.error().message;
  }
}

// A link takes the URL's port for frames up and the next for frames down, same group and options.
TEST(WireOpen, LcmDownUrlIsTheNextPortAndThereIsNoneAfter65535) {
  EXPECT_EQ(lcm_down_url("udpm://239.255.76.67:7667?ttl=0").value(), "udpm://239.255.76.67:7668?ttl=0");
  EXPECT_EQ(lcm_down_url("udpm://224.0.0.1:1?ttl=1&recv_buf_size=65536").value(),
            "udpm://224.0.0.1:2?ttl=1&recv_buf_size=65536");
  EXPECT_EQ(lcm_down_url("udpm://").value(), "udpm://239.255.76.67:7668");  // liblcm's defaults
  EXPECT_EQ(lcm_down_url("udpm://?ttl=0").value(), "udpm://239.255.76.67:7668?ttl=0");
  EXPECT_EQ(lcm_down_url("udpm://239.1.2.3").value(), "udpm://239.1.2.3:7668");
  auto last = lcm_down_url("udpm://239.1.2.3:65535");
  ASSERT_FALSE(last);
  EXPECT_EQ(last.error().code, Errc::invalid_argument);
  EXPECT_NE(last.error().message.find("there is no port after 65535"), std::string::npos) << last.error().message;
  auto bad = lcm_down_url("udpm://10.0.0.1:7667");
  ASSERT_FALSE(bad);
  EXPECT_NE(bad.error().message.find("10.0.0.1 is not a multicast address"), std::string::npos) << bad.error().message;
  // An end cannot be opened on such a URL; a shared endpoint can.
  require_netns();
  LcmSettings settings{.url = "udpm://239.255.76.67:65535?ttl=0", .end = LcmEnd::parent};
  auto end = open_lcm(settings, "tahvel://wire-open/lcm-last-port");
  ASSERT_FALSE(end);
  EXPECT_NE(end.error().message.find("there is no port after 65535"), std::string::npos) << end.error().message;
  settings.end = LcmEnd::shared;
  EXPECT_TRUE(open_lcm(settings, "tahvel://wire-open/lcm-last-port"));
}

// Each end of an LCM link hears only the port of the frames addressed to it: the parent's frames
// to the child travel on PORT + 1, the child's to the parent on PORT. Plain LCM listeners on each
// port, bound to each IRI, show which port each frame took.
TEST(WireOpen, LcmLinkEndsSendEachDirectionOnItsOwnPort) {
  require_netns();
  const std::string parent_iri = "tahvel://wire-ends/parent", child_iri = parent_iri + "/child";
  const LcmSettings up_port = conformance::test_lcm_settings();
  const LcmSettings down_port{.url = lcm_down_url(up_port.url).value()};
  auto open = [](LcmSettings settings, LcmEnd end, const std::string& iri) {
    settings.end = end;
    auto t = open_lcm(settings, iri);
    EXPECT_TRUE(t) << iri << ": " << (t ? "" : t.error().message);
    return t ? std::move(*t) : nullptr;
  };
  auto parent = open(up_port, LcmEnd::parent, parent_iri), child = open(up_port, LcmEnd::child, child_iri);
  auto parent_on_up = open(up_port, LcmEnd::shared, parent_iri);
  auto parent_on_down = open(down_port, LcmEnd::shared, parent_iri);
  auto child_on_up = open(up_port, LcmEnd::shared, child_iri);
  auto child_on_down = open(down_port, LcmEnd::shared, child_iri);
  ASSERT_TRUE(parent && child && parent_on_up && parent_on_down && child_on_up && child_on_down);

  Frame up;
  up.kind = FrameKind::hello;
  up.from = child_iri;
  up.to = parent_iri;
  up.seq = 1;
  Frame down = up;
  down.kind = FrameKind::welcome;
  down.from = parent_iri;
  down.to = child_iri;
  down.seq = 2;
  ASSERT_TRUE(child->send(up));
  ASSERT_TRUE(parent->send(down));
  auto seq_of = [](Transport& t, std::chrono::milliseconds wait) -> std::uint64_t {
    auto got = t.receive(wait);
    return got && *got ? (*got)->seq : 0;
  };
  EXPECT_EQ(seq_of(*parent, 2s), 1u);
  EXPECT_EQ(seq_of(*child, 2s), 2u);
  EXPECT_EQ(seq_of(*parent_on_up, 2s), 1u);
  EXPECT_EQ(seq_of(*child_on_down, 2s), 2u);
  EXPECT_EQ(seq_of(*parent_on_down, 300ms), 0u) << "the child's frame up travelled on the port down";
  EXPECT_EQ(seq_of(*child_on_up, 300ms), 0u) << "the parent's frame down travelled on the port up";
}

TEST(WireOpen, LcmWithAUnicastGroupIsRefusedBeforeLcmIsAsked) {
  require_netns();
  LcmSettings settings;
  settings.url = "udpm://10.0.0.1:7667?ttl=0";
  auto t = open_lcm(settings, "tahvel://wire-open/lcm-unicast");
  ASSERT_FALSE(t);
  EXPECT_EQ(t.error().code, Errc::invalid_argument);
  EXPECT_NE(t.error().message.find("10.0.0.1 is not a multicast address"), std::string::npos) << t.error().message;
}

// The LCM endpoint reads LCM's datagrams itself (lcm_udpm.h); liblcm sends them. Frames of every
// size liblcm's publish makes (short messages up to its 1,400-byte bound, fragments of 65,423
// bytes beyond), on the edges of both, arrive whole.
TEST(WireUdpm, EverySizeLiblcmPublishesArrivesWhole) {
  require_netns();
  const LcmSettings settings{.url = "udpm://239.255.76.67:7751?ttl=0"};
  auto receiver = open_lcm(settings, "tahvel://wire-udpm/receiver");
  auto sender = open_lcm(settings, "tahvel://wire-udpm/sender");
  ASSERT_TRUE(receiver && sender);
  const std::size_t sizes[] = {0, 1, 1200, 1300, 1320, 1400, 1500, 65000, 65423, 65424, 130846, 200000, 2u << 20};
  std::uint64_t seq = 0;
  for (std::size_t size : sizes) {
    Frame f;
    f.kind = FrameKind::answer;
    f.from = (*sender)->self();
    f.to = (*receiver)->self();
    f.seq = ++seq;
    f.body.resize(size);
    for (std::size_t i = 0; i < size; ++i) f.body[i] = static_cast<char>((i * 7 + size) & 0xFF);
    ASSERT_TRUE((*sender)->send(f)) << size;
    auto got = (*receiver)->receive(5s);
    ASSERT_TRUE(got) << got.error().message;
    ASSERT_TRUE(*got) << "nothing arrived of a body of " << size << " bytes";
    EXPECT_EQ((*got)->seq, seq);
    EXPECT_TRUE((*got)->body == f.body) << "the body of " << size << " bytes came back changed";
  }
}

// A receiving LCM endpoint that keeps its drop lines, and a sender, on the group 239.255.76.67
// at `port`.
struct LcmPairWithDrops {
  explicit LcmPairWithDrops(int port)
      : receiver(open_lcm(settings(port), "tahvel://wire-udpm/receiver",
                          [this](std::string_view line) {
                            std::lock_guard lock(mu);
                            drops.emplace_back(line);
                          })),
        sender(open_lcm(settings(port), "tahvel://wire-udpm/sender")) {}
  static LcmSettings settings(int port) {
    return {.url = "udpm://239.255.76.67:" + std::to_string(port) + "?ttl=0"};
  }
  // Sends a good frame after whatever reached the receiver before it and waits for it: the
  // receiver's drop lines by then, or nothing when the good frame did not arrive.
  std::optional<std::vector<std::string>> drops_once_a_good_frame_arrives() {
    Frame f;
    f.kind = FrameKind::heartbeat;
    f.from = (*sender)->self();
    f.to = (*receiver)->self();
    f.seq = 42;
    if (!(*sender)->send(f)) return std::nullopt;
    auto got = (*receiver)->receive(5s);
    if (!got || !*got || (*got)->seq != 42) return std::nullopt;
    std::lock_guard lock(mu);
    return drops;
  }
  std::vector<std::string> drops;
  std::mutex mu;
  Result<std::unique_ptr<Transport>> receiver, sender;
};

// A UDP socket sending raw datagrams to the group 239.255.76.67 on `port`, as anything on the
// LAN may: what reaches an LCM endpoint that is not what its binding sends.
class RawGroupSender {
 public:
  explicit RawGroupSender(int port) : fd_(::socket(AF_INET, SOCK_DGRAM, 0)) {
    EXPECT_GE(fd_, 0);
    group_.sin_family = AF_INET;
    group_.sin_port = htons(static_cast<std::uint16_t>(port));
    inet_pton(AF_INET, "239.255.76.67", &group_.sin_addr);
  }
  ~RawGroupSender() { ::close(fd_); }
  RawGroupSender(const RawGroupSender&) = delete;
  RawGroupSender& operator=(const RawGroupSender&) = delete;

  void send(const std::string& bytes) {
    ASSERT_EQ(::sendto(fd_, bytes.data(), bytes.size(), 0, reinterpret_cast<sockaddr*>(&group_), sizeof group_),
              static_cast<ssize_t>(bytes.size()));
  }
  // The port the datagrams came from (after the first send).
  int port() const {
    sockaddr_in bound{};
    socklen_t size = sizeof bound;
    EXPECT_EQ(::getsockname(fd_, reinterpret_cast<sockaddr*>(&bound), &size), 0);
    return ntohs(bound.sin_port);
  }

 private:
  int fd_;
  sockaddr_in group_{};
};

// Whatever else reaches the group's port (a program that is not LCM, a broken fragment) is
// dropped with its sender and what is wrong, and the endpoint goes on receiving.
TEST(WireUdpm, DatagramsThatAreNotLcmAreDroppedNamingTheirSenderAndTheEndpointGoesOn) {
  require_netns();
  LcmPairWithDrops pair(7752);
  ASSERT_TRUE(pair.receiver && pair.sender);
  RawGroupSender raw(7752);
  raw.send("hello");
  raw.send(std::string("LC03\0\0\0\1", 8));
  raw.send(std::string("LC03\0\0\0\1\0\0\0\4\0\0\0\0\0\2\0\1", 20));  // fragment 2 of 1
  const int port = raw.port();
  auto said = pair.drops_once_a_good_frame_arrives();
  ASSERT_TRUE(said) << "the good frame after the bad datagrams did not arrive";
  const std::vector<std::string>& drops = *said;
  ASSERT_EQ(drops.size(), 3u);
  // The source address is the namespace's (0.0.0.0 on a loopback without routes); the port is the socket's.
  const std::string from = ":" + std::to_string(port) + ": ";
  EXPECT_EQ(drops[0].rfind("lcm <tahvel://wire-udpm/receiver>: dropped a datagram of 5 bytes from ", 0), 0u) << drops[0];
  EXPECT_NE(drops[0].find(from + "not an LCM datagram (magic 0x68656c6c, LCM's are LC02 and LC03)"), std::string::npos)
      << drops[0];
  EXPECT_NE(drops[1].find(from + "an LCM fragment cut inside its header"), std::string::npos) << drops[1];
  EXPECT_NE(drops[2].find(from + "LCM fragment 2 of 1 of message 1: no such fragment"), std::string::npos) << drops[2];
}

// An LCM message on the endpoint's channel whose tahvel_frame_t lengths lie (a negative body
// size or string length, a string without the NUL its length counts, a body longer than the
// message) is dropped naming the field, and the endpoint goes on: lcm-gen's decoder handed a
// negative length to malloc and memcpy, and one datagram of 164 bytes crashed a link.
TEST(WireUdpm, AFrameWhoseLengthsLieIsDroppedNamingTheFieldAndTheEndpointGoesOn) {
  require_netns();
  LcmPairWithDrops pair(7754);
  ASSERT_TRUE(pair.receiver && pair.sender);
  Frame heartbeat;
  heartbeat.kind = FrameKind::heartbeat;
  heartbeat.from = (*pair.sender)->self();
  heartbeat.to = (*pair.receiver)->self();
  heartbeat.body = "abc";
  // The frame as the binding encodes it, then `patch`ed, in one LCM datagram on the receiver's channel.
  auto datagram = [&](const std::function<void(std::string&)>& patch) {
    std::string frame = encode_lcm_frame(heartbeat).value();
    patch(frame);
    return std::string("LC02\0\0\0\1", 8) + lcm_channel(heartbeat.to) + '\0' + frame;
  };
  auto put_int32 = [](std::string& bytes, std::size_t at, std::int32_t value) {
    for (int i = 0; i < 4; ++i) bytes[at + i] = static_cast<char>(static_cast<std::uint32_t>(value) >> (24 - 8 * i));
  };
  const std::size_t from_length = 8 + 2 + 8 + 1;  // after the type hash, version, fingerprint, kind
  const std::size_t to_length = from_length + 4 + heartbeat.from.size() + 1;
  const std::size_t body_size = to_length + 4 + heartbeat.to.size() + 1 + 3 * 8;
  RawGroupSender raw(7754);
  raw.send(datagram([&](std::string& f) { put_int32(f, body_size, -1); }));
  raw.send(datagram([&](std::string& f) { put_int32(f, from_length, -16); }));
  raw.send(datagram([&](std::string& f) { put_int32(f, to_length, 0); }));
  raw.send(datagram([&](std::string& f) { f[to_length - 1] = 'x'; }));  // from's NUL
  raw.send(datagram([&](std::string& f) { put_int32(f, body_size, INT32_MAX); }));
  auto said = pair.drops_once_a_good_frame_arrives();
  ASSERT_TRUE(said) << "the good frame after the bad ones did not arrive";
  const std::vector<std::string>& drops = *said;
  ASSERT_EQ(drops.size(), 5u);
  for (const std::string& drop : drops)
    EXPECT_EQ(drop.rfind("lcm <tahvel://wire-udpm/receiver>: dropped ", 0), 0u) << drop;
  EXPECT_NE(drops[0].find(": not a tahvel_frame_t ('body' says -1 bytes, 3 are left)"), std::string::npos) << drops[0];
  EXPECT_NE(drops[1].find(": not a tahvel_frame_t ('from' says -16 bytes, "), std::string::npos) << drops[1];
  EXPECT_NE(drops[2].find(": not a tahvel_frame_t ('to' says 0 bytes, "), std::string::npos) << drops[2];
  EXPECT_NE(drops[3].find(": not a tahvel_frame_t ('from' does not end with the NUL its length counts)"), std::string::npos)
      << drops[3];
  EXPECT_NE(drops[4].find(": not a tahvel_frame_t ('body' says 2147483647 bytes, 3 are left)"), std::string::npos) << drops[4];
}

// A sender of junk filled the log with a line per datagram, pushing out what it held; a frame
// from a made-up IRI of megabytes was kept and logged whole by the link (P4). The first is
// dropped naming the limit; then at most 10 lines per 10 s are said.
TEST(WireUdpm, AnOverlongSenderIriIsDroppedAndAFloodOfJunkIsLoggedAtMostTenLinesAWindow) {
  require_netns();
  LcmPairWithDrops pair(7755);
  ASSERT_TRUE(pair.receiver && pair.sender);
  const auto began = std::chrono::steady_clock::now();
  Frame made_up;
  made_up.kind = FrameKind::hello;
  made_up.from = "tahvel://wire-udpm/receiver/" + std::string(kMaxFrameIriBytes, 'a');
  made_up.to = (*pair.receiver)->self();
  ASSERT_TRUE((*pair.sender)->send(made_up));
  auto first = pair.drops_once_a_good_frame_arrives();
  ASSERT_TRUE(first) << "the good frame after the overlong IRI did not arrive";
  ASSERT_EQ(first->size(), 1u);
  EXPECT_NE((*first)[0].find("a sender IRI of " + std::to_string(made_up.from.size()) + " bytes, over the limit of 8192"),
            std::string::npos)
      << (*first)[0];
  EXPECT_LT((*first)[0].size(), 1000u);
  RawGroupSender raw(7755);
  for (int i = 0; i < 30; ++i) raw.send("junk");
  auto said = pair.drops_once_a_good_frame_arrives();
  ASSERT_TRUE(said) << "the good frame after the junk did not arrive";
  if (std::chrono::steady_clock::now() - began < 9s)
    EXPECT_EQ(said->size(), 10u) << "one line for the IRI and nine of the junk in the first window";
  else  // a machine slow enough to spread the drops over two windows: the second says its count
    EXPECT_LE(said->size(), 21u);
}

// Linux hands a socket bound to a port the datagrams of every group any socket of the host joined
// on it; an endpoint hears only its URL's group.
TEST(WireUdpm, AnEndpointDoesNotHearAnotherGroupOnItsPort) {
  require_netns();
  const std::string iri = "tahvel://wire-udpm/one-group";
  auto here = open_lcm(LcmSettings{.url = "udpm://239.255.76.67:7753?ttl=0"}, iri);
  auto elsewhere = open_lcm(LcmSettings{.url = "udpm://239.255.76.68:7753?ttl=0"}, iri);
  auto sender = open_lcm(LcmSettings{.url = "udpm://239.255.76.68:7753?ttl=0"}, "tahvel://wire-udpm/sender");
  ASSERT_TRUE(here && elsewhere && sender);
  Frame f;
  f.from = (*sender)->self();
  f.to = iri;
  f.seq = 7;
  ASSERT_TRUE((*sender)->send(f));
  auto there = (*elsewhere)->receive(5s);
  ASSERT_TRUE(there && *there) << "the frame did not reach its own group";
  auto got = (*here)->receive(300ms);
  ASSERT_TRUE(got);
  EXPECT_FALSE(*got) << "a frame sent to 239.255.76.68 reached the endpoint of 239.255.76.67";
}

// The configurations we ship parse; what is not XML, or not well-formed, is said with its line
// before Cyclone is asked (which says only that dds_create_domain failed).
TEST(WireOpen, DdsConfigCheckPassesTheShippedFilesAndNamesTheLineOfAnError) {
  for (const char* name : {"cyclonedds-loopback.xml", "cyclonedds-multi-host.xml"}) {
    std::ifstream in(std::string(TAHVEL_SOURCE_DIR) + "/deploy/" + name);
    const std::string xml((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    ASSERT_FALSE(xml.empty()) << name;
    EXPECT_TRUE(check_dds_config(xml)) << name << ": " << check_dds_config(xml).error().message;
  }
  EXPECT_TRUE(check_dds_config("<CycloneDDS/>"));
  auto not_xml = check_dds_config("[node]\nid = 1\n");
  ASSERT_FALSE(not_xml);
  EXPECT_NE(not_xml.error().message.find("not XML"), std::string::npos) << not_xml.error().message;
  EXPECT_FALSE(check_dds_config("   "));
  auto mismatch = check_dds_config("<CycloneDDS>\n<Domain>\n</General>\n</CycloneDDS>");
  ASSERT_FALSE(mismatch);
  EXPECT_EQ(mismatch.error().code, Errc::invalid_argument);
  EXPECT_NE(mismatch.error().message.find("line 3"), std::string::npos) << mismatch.error().message;
}

}  // namespace
}  // namespace tahvel::federation
