// A Frame as one LCM message (lcm_frame.h), without a socket. That what a liblcm publish carries
// reaches an endpoint, and that a message whose lengths lie leaves the endpoint running, is
// tests/federation_net's (WireUdpm.*).
#include <gtest/gtest.h>

#include <cstdint>
#include <limits>
#include <string>

#include "tahvel/federation/lcm_frame.h"

namespace tahvel::federation {
namespace {

Frame sample_frame() {
  Frame f;
  f.kind = FrameKind::up;
  f.from = "tahvel://home/1";
  f.to = "tahvel://hospital";
  f.seq = std::numeric_limits<std::uint64_t>::max();
  f.prev = 7;
  f.ack = 1ull << 40;
  f.body = std::string("a\0b\xff", 4);
  return f;
}

// Where each field's length sits in the encoding of sample_frame() (big-endian int32s).
constexpr std::size_t kFromLength = 8 + 2 + 8 + 1;  // after the type hash, version, fingerprint, kind
constexpr std::size_t kToLength = kFromLength + 4 + 15 + 1;
constexpr std::size_t kBodySize = kToLength + 4 + 17 + 1 + 3 * 8;

void put_int32(std::string& bytes, std::size_t at, std::int32_t value) {
  for (int i = 0; i < 4; ++i) bytes[at + i] = static_cast<char>(static_cast<std::uint32_t>(value) >> (24 - 8 * i));
}

std::string refusal(const std::string& message) {
  auto decoded = decode_lcm_frame(message);
  return decoded ? std::string("decoded") : decoded.error().message;
}

TEST(LcmFrame, EveryFieldOfAFrameCrossesWhole) {
  const Frame sent = sample_frame();
  auto bytes = encode_lcm_frame(sent);
  ASSERT_TRUE(bytes) << bytes.error().message;
  EXPECT_EQ(bytes->size(), kBodySize + 4 + 4);
  auto got = decode_lcm_frame(*bytes);
  ASSERT_TRUE(got) << got.error().message;
  EXPECT_EQ(got->version, sent.version);
  EXPECT_EQ(got->fingerprint, sent.fingerprint);
  EXPECT_EQ(got->kind, sent.kind);
  EXPECT_EQ(got->from, sent.from);
  EXPECT_EQ(got->to, sent.to);
  EXPECT_EQ(got->seq, sent.seq);
  EXPECT_EQ(got->prev, sent.prev);
  EXPECT_EQ(got->ack, sent.ack);
  EXPECT_EQ(got->body, sent.body);
}

TEST(LcmFrame, AMessageWhoseLengthsLieIsRefusedNamingTheField) {
  const std::string good = encode_lcm_frame(sample_frame()).value();
  auto patched = [&](std::size_t at, std::int32_t value) {
    std::string bytes = good;
    put_int32(bytes, at, value);
    return refusal(bytes);
  };
  EXPECT_EQ(patched(kBodySize, -1), "not a tahvel_frame_t ('body' says -1 bytes, 4 are left)");
  EXPECT_EQ(patched(kBodySize, 5), "not a tahvel_frame_t ('body' says 5 bytes, 4 are left)");
  EXPECT_EQ(patched(kFromLength, -16), "not a tahvel_frame_t ('from' says -16 bytes, " +
                                           std::to_string(good.size() - kFromLength - 4) + " are left)");
  EXPECT_EQ(patched(kToLength, 0), "not a tahvel_frame_t ('to' says 0 bytes, " +
                                       std::to_string(good.size() - kToLength - 4) + " are left)");
  std::string unterminated = good;
  unterminated[kToLength - 1] = 'x';
  EXPECT_EQ(refusal(unterminated), "not a tahvel_frame_t ('from' does not end with the NUL its length counts)");
  EXPECT_EQ(refusal(good.substr(0, 5)), "not a tahvel_frame_t (cut short in 'type hash' (5 bytes))");
  EXPECT_EQ(refusal(good.substr(0, kBodySize + 2)),
            "not a tahvel_frame_t (cut short in 'body_size' (" + std::to_string(kBodySize + 2) + " bytes))");
  std::string other_type = good;
  other_type[0] ^= 1;
  EXPECT_NE(refusal(other_type).find("not a tahvel_frame_t (type hash 0x"), std::string::npos) << refusal(other_type);
  EXPECT_NE(refusal(good + "xyz").find("(kind 3 seq 18446744073709551615 from <tahvel://home/1> to <tahvel://hospital>) "
                                       "and 3 bytes after it"),
            std::string::npos)
      << refusal(good + "xyz");
}

// LCM's strings end at their first NUL: a `from` of "tahvel://home/1\0x" would have been taken
// as coming from tahvel://home/1. It is refused where it is made and where it is taken.
TEST(LcmFrame, AnIriWithANulInItIsRefusedWhenSentAndWhenTaken) {
  Frame f = sample_frame();
  f.from = std::string("tahvel://home/1\0x", 17);
  auto encoded = encode_lcm_frame(f);
  ASSERT_FALSE(encoded);
  EXPECT_EQ(encoded.error().code, Errc::invalid_argument);
  EXPECT_NE(encoded.error().message.find("a NUL"), std::string::npos) << encoded.error().message;
  std::string bytes = encode_lcm_frame(sample_frame()).value();
  bytes[kFromLength + 4 + 3] = '\0';
  EXPECT_EQ(refusal(bytes), "not a tahvel_frame_t ('from' has a NUL at byte 3 of its 15)");
}

}  // namespace
}  // namespace tahvel::federation
