// LCM's udpm datagrams taken apart and put together (lcm_udpm.h), without a socket. Datagrams
// are built here as liblcm 1.3's lcm_udpm.c writes them; that liblcm's own publish reaches the
// endpoint, short and fragmented, is tests/federation_net's (WireUdpm.*).
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <string>
#include <vector>

#include "tahvel/federation/lcm_udpm.h"

namespace tahvel::federation {
namespace {

void put32(std::string& out, std::uint32_t v) {
  for (int shift = 24; shift >= 0; shift -= 8) out.push_back(static_cast<char>((v >> shift) & 0xFF));
}
void put16(std::string& out, std::uint16_t v) {
  out.push_back(static_cast<char>(v >> 8));
  out.push_back(static_cast<char>(v & 0xFF));
}

std::string short_message(std::uint32_t seqno, const std::string& channel, const std::string& payload) {
  std::string d;
  put32(d, 0x4c433032);
  put32(d, seqno);
  d += channel;
  d.push_back('\0');
  return d + payload;
}

// The fragments liblcm sends for `payload`: `chunk` payload bytes per fragment, the channel in
// fragment 0 before its (shorter) part.
std::vector<std::string> fragments(std::uint32_t seqno, const std::string& channel, const std::string& payload,
                                   std::size_t chunk) {
  const std::size_t first = chunk - channel.size() - 1;
  const std::size_t count = 1 + (payload.size() > first ? (payload.size() - first + chunk - 1) / chunk : 0);
  std::vector<std::string> out;
  std::size_t offset = 0;
  for (std::size_t n = 0; n < count; ++n) {
    std::string d;
    put32(d, 0x4c433033);
    put32(d, seqno);
    put32(d, static_cast<std::uint32_t>(payload.size()));
    put32(d, static_cast<std::uint32_t>(offset));
    put16(d, static_cast<std::uint16_t>(n));
    put16(d, static_cast<std::uint16_t>(count));
    const std::size_t take = std::min(n == 0 ? first : chunk, payload.size() - offset);
    if (n == 0) d += channel + std::string(1, '\0');
    d += payload.substr(offset, take);
    offset += take;
    out.push_back(d);
  }
  return out;
}

std::string pattern(std::size_t size) {
  std::string s(size, '\0');
  for (std::size_t i = 0; i < size; ++i) s[i] = static_cast<char>((i * 131 + i / 251) & 0xFF);
  return s;
}

constexpr std::uint64_t kSenderA = 1, kSenderB = 2;

TEST(UdpmReassembler, AShortMessageOnItsChannelIsItsPayloadAndOtherChannelsPassUnsaid) {
  UdpmReassembler r("TVchannel");
  // A short message's payload is a view into the datagram, which the caller keeps.
  const std::string datagram = short_message(7, "TVchannel", "payload bytes");
  auto mine = r.take(kSenderA, datagram);
  ASSERT_TRUE(mine.payload);
  EXPECT_EQ(*mine.payload, "payload bytes");
  EXPECT_TRUE(mine.refused.empty());
  const std::string empty_datagram = short_message(8, "TVchannel", "");
  auto empty = r.take(kSenderA, empty_datagram);
  ASSERT_TRUE(empty.payload);
  EXPECT_TRUE(empty.payload->empty());
  auto other = r.take(kSenderA, short_message(9, "TVother", "not for us"));
  EXPECT_FALSE(other.payload);
  EXPECT_TRUE(other.refused.empty());
}

TEST(UdpmReassembler, FragmentsInAnyOrderMakeTheWholeMessageOnce) {
  UdpmReassembler r("TVchannel");
  const std::string payload = pattern(200000);
  auto parts = fragments(3, "TVchannel", payload, 65423);
  ASSERT_EQ(parts.size(), 4u);
  std::reverse(parts.begin(), parts.end());  // fragment 0, with the channel, comes last
  for (std::size_t i = 0; i + 1 < parts.size(); ++i) {
    auto t = r.take(kSenderA, parts[i]);
    EXPECT_FALSE(t.payload) << i;
    EXPECT_TRUE(t.refused.empty()) << t.refused;
    if (i == 1) EXPECT_FALSE(r.take(kSenderA, parts[i]).payload) << "a duplicate fragment counts once";
  }
  EXPECT_EQ(r.held_bytes(), payload.size() + parts.size()) << "its bytes and a byte per fragment";
  auto whole = r.take(kSenderA, parts.back());
  ASSERT_TRUE(whole.payload);
  EXPECT_TRUE(*whole.payload == payload);
  EXPECT_EQ(r.held_bytes(), 0u);
}

TEST(UdpmReassembler, SendersAreReassembledApartAndANewMessageEndsTheSendersUnfinishedOne) {
  UdpmReassembler r("TVchannel");
  const std::string a = pattern(5000), b = std::string(4000, 'b');
  auto from_a = fragments(1, "TVchannel", a, 1500), from_b = fragments(1, "TVchannel", b, 1500);
  // Interleaved, as two senders' datagrams arrive.
  for (std::size_t i = 0; i + 1 < from_b.size(); ++i) {
    EXPECT_FALSE(r.take(kSenderA, from_a[i]).payload);
    EXPECT_FALSE(r.take(kSenderB, from_b[i]).payload);
  }
  EXPECT_TRUE(*r.take(kSenderB, from_b.back()).payload == b);
  // Sender A's message 1 lost its last fragments; its message 2 replaces it.
  const std::string a2 = pattern(3000);
  auto next = fragments(2, "TVchannel", a2, 1500);
  for (std::size_t i = 0; i + 1 < next.size(); ++i) EXPECT_FALSE(r.take(kSenderA, next[i]).payload);
  auto whole = r.take(kSenderA, next.back());
  ASSERT_TRUE(whole.payload);
  EXPECT_TRUE(*whole.payload == a2);
  EXPECT_EQ(r.held_bytes(), 0u) << "message 1's buffer is not kept";
  // A late fragment of message 1 starts it again; it is dropped when message 3 comes.
  EXPECT_FALSE(r.take(kSenderA, from_a.back()).payload);
  EXPECT_EQ(r.held_bytes(), a.size() + from_a.size());
  EXPECT_TRUE(r.take(kSenderA, short_message(3, "TVchannel", "x")).payload);
}

TEST(UdpmReassembler, FragmentsOfAnotherChannelAreNotHeld) {
  UdpmReassembler r("TVchannel");
  auto parts = fragments(4, "TVother", pattern(100000), 65423);
  for (const auto& p : parts) {
    auto t = r.take(kSenderA, p);
    EXPECT_FALSE(t.payload);
    EXPECT_TRUE(t.refused.empty()) << t.refused;
    EXPECT_EQ(r.held_bytes(), 0u);
  }
}

TEST(UdpmReassembler, MalformedDatagramsAreRefusedNamingWhatIsWrong) {
  UdpmReassembler r("TVchannel");
  auto refused = [&](const std::string& datagram) { return r.take(kSenderA, datagram).refused; };
  EXPECT_EQ(refused("LC0"), "shorter than an LCM header (3 bytes)");
  EXPECT_EQ(refused("GET / HTTP/1.1"), "not an LCM datagram (magic 0x47455420, LCM's are LC02 and LC03)");
  EXPECT_EQ(refused(std::string("LC02\0\0", 6)), "an LCM short message cut inside its header");
  EXPECT_EQ(refused(std::string("LC02\0\0\0\1", 8) + std::string(80, 'c')),
            "an LCM short message whose channel name has no end within 64 bytes");
  auto parts = fragments(5, "TVchannel", pattern(10000), 4000);
  EXPECT_EQ(refused(parts[1].substr(0, 19)), "an LCM fragment cut inside its header");
  std::string bad_number = parts[1];
  bad_number[16] = 0, bad_number[17] = 9;  // fragment 9 of 3
  EXPECT_EQ(refused(bad_number), "LCM fragment 9 of 3 of message 5: no such fragment");
  std::string past_end = parts[2];
  past_end[12] = 0, past_end[13] = 0, past_end[14] = 0x27, past_end[15] = 0x10;  // offset 10000
  EXPECT_NE(refused(past_end).find("LCM fragment 2 of 3 of message 5: bytes 10000..1"), std::string::npos)
      << refused(past_end);
  std::string no_end = parts[0].substr(0, 20) + std::string(70, 'c');
  EXPECT_EQ(refused(no_end), "LCM fragment 0 of 3 of message 5: its channel name has no end within 64 bytes");
  // None of that broke the message: its good fragments still make it.
  for (std::size_t i = 0; i + 1 < parts.size(); ++i) EXPECT_FALSE(r.take(kSenderA, parts[i]).payload);
  EXPECT_TRUE(r.take(kSenderA, parts.back()).payload);
}

// A message's bytes are not zero-filled before its fragments come (60 MB of zeros per forged
// fragment 0 kept a gateway from hearing its sensors): fragments that overlap, leaving bytes no
// fragment wrote, make no message.
TEST(UdpmReassembler, FragmentsThatDoNotTileTheirMessageMakeNoMessage) {
  UdpmReassembler r("TVchannel");
  const std::string payload = pattern(10000);
  auto parts = fragments(6, "TVchannel", payload, 4000);
  ASSERT_EQ(parts.size(), 3u);
  std::string overlapping = parts[2];  // fragment 2 written over fragment 1's first bytes
  const std::uint32_t at = 3990 - 10;  // fragment 1 starts at 3990 (4000 less the channel)
  overlapping[12] = 0, overlapping[13] = 0, overlapping[14] = static_cast<char>(at >> 8), overlapping[15] = static_cast<char>(at & 0xFF);
  EXPECT_FALSE(r.take(kSenderA, parts[0]).payload);
  EXPECT_FALSE(r.take(kSenderA, parts[1]).payload);
  auto t = r.take(kSenderA, overlapping);
  EXPECT_FALSE(t.payload);
  EXPECT_EQ(t.refused, "LCM fragment 2 of 3 of message 6: its fragments do not tile the message's 10000 bytes (they overlap or leave a hole)");
  EXPECT_EQ(r.held_bytes(), 0u);
  // The sender's next message is made whole as ever.
  auto again = fragments(7, "TVchannel", payload, 4000);
  for (std::size_t i = 0; i + 1 < again.size(); ++i) EXPECT_FALSE(r.take(kSenderA, again[i]).payload);
  auto whole = r.take(kSenderA, again.back());
  ASSERT_TRUE(whole.payload);
  EXPECT_TRUE(*whole.payload == payload);
}

TEST(UdpmReassembler, HeldBytesStayBoundedOverSendersThatNeverFinish) {
  UdpmReassembler r("TVchannel");
  std::string header;
  put32(header, 0x4c433033);
  auto first_fragment = [&](std::uint32_t size) {
    std::string d = header;
    put32(d, 1);
    put32(d, size);
    put32(d, 0);
    put16(d, 0);
    put16(d, 2);
    return d + "TVchannel" + std::string(1, '\0') + "x";
  };
  // A message larger than all that is held is refused at once.
  auto too_big = r.take(kSenderA, first_fragment(UdpmReassembler::kMaxHeldBytes + 1));
  EXPECT_NE(too_big.refused.find("more than the"), std::string::npos) << too_big.refused;
  // Senders that each start a 20 MB message and vanish: the oldest are dropped to make room.
  for (std::uint64_t sender = 10; sender < 20; ++sender) {
    EXPECT_TRUE(r.take(sender, first_fragment(20u << 20)).refused.empty());
    EXPECT_LE(r.held_bytes(), UdpmReassembler::kMaxHeldBytes);
  }
  EXPECT_EQ(r.held_bytes(), 3u * ((20u << 20) + 2)) << "three messages of 20 MB and two fragments each";
}

TEST(UdpmReassembler, SendersThatVanishMidMessageLeaveAtMost4096MarksAndAMessageTakesABytePerFragment) {
  UdpmReassembler r("TVchannel");
  auto first_of = [](std::uint32_t size, std::uint16_t count) {
    std::string d;
    put32(d, 0x4c433033);
    put32(d, 1);
    put32(d, size);
    put32(d, 0);
    put16(d, 0);
    put16(d, count);
    return d + "TVchannel" + std::string(1, '\0') + "x";
  };
  EXPECT_EQ(r.take(kSenderA, first_of(100, 101)).refused,
            "LCM fragment 0 of 101 of message 1: more fragments than the message's 100 bytes");
  for (std::uint64_t sender = 100; sender < 100 + 5000; ++sender) EXPECT_TRUE(r.take(sender, first_of(1000, 2)).refused.empty());
  EXPECT_EQ(r.held_bytes(), 4096u * 1002u) << "the oldest went to make room for the newest";
}

TEST(UdpmUrl, GivesGroupPortAndBufferWithLcmsDefaults) {
  auto full = parse_udpm_url("udpm://239.1.2.3:7700?ttl=1&recv_buf_size=65536");
  ASSERT_TRUE(full) << full.error().message;
  EXPECT_EQ(ntohl(full->group.s_addr), 0xEF010203u);
  EXPECT_EQ(full->port, 7700);
  EXPECT_EQ(full->recv_buf_size, 65536u);
  auto bare = parse_udpm_url("udpm://");
  ASSERT_TRUE(bare);
  EXPECT_EQ(ntohl(bare->group.s_addr), 0xEFFF4C43u);  // 239.255.76.67
  EXPECT_EQ(bare->port, 7667);
  EXPECT_FALSE(bare->recv_buf_size);
}

}  // namespace
}  // namespace tahvel::federation
