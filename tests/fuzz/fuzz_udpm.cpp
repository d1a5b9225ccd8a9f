// Fuzz target: LCM's udpm datagrams as the LCM endpoint takes them (federation/lcm_udpm.h),
// which come from anything on the LAN that sends to the group's port, and each whole message
// decoded as a frame (federation/lcm_frame.h), as the endpoint does next. The input is a run of
// datagrams, each `u8 sender, u16 length (little-endian), bytes`. Properties: no crash or
// sanitizer report; the bytes held for unfinished messages never pass the bound; a refused
// datagram yields no message and says why; a short message's payload is the datagram's tail; a
// message taken as a frame is exactly that frame's encoding, and one refused says why.
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "require.h"
#include "tahvel/federation/lcm_frame.h"
#include "tahvel/federation/lcm_udpm.h"

using namespace tahvel::federation;

namespace {
constexpr std::size_t kMaxHeld = 1u << 20;  // small, so that mutated sizes stay cheap
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  UdpmReassembler reassembler("TVchannel", kMaxHeld);
  std::string_view input(reinterpret_cast<const char*>(data), size);
  while (input.size() >= 3) {
    const std::uint64_t sender = static_cast<std::uint8_t>(input[0]) % 4;
    const std::size_t length = static_cast<std::uint8_t>(input[1]) | (static_cast<std::uint8_t>(input[2]) << 8);
    input.remove_prefix(3);
    const std::string_view datagram = input.substr(0, length);
    input.remove_prefix(datagram.size());
    auto taken = reassembler.take(sender, datagram);
    REQUIRE(reassembler.held_bytes() <= kMaxHeld);
    if (!taken.refused.empty()) REQUIRE(!taken.payload);
    if (taken.payload && datagram.starts_with("LC02")) REQUIRE(datagram.ends_with(*taken.payload));
    if (taken.payload) {
      auto frame = decode_lcm_frame(*taken.payload);
      if (frame) {
        auto again = encode_lcm_frame(*frame);
        REQUIRE(again && *again == *taken.payload);
      } else {
        REQUIRE(!frame.error().message.empty());
      }
    }
  }
  return 0;
}

namespace {
void put(std::string& out, std::uint64_t v, int bytes) {
  for (int i = bytes - 1; i >= 0; --i) out.push_back(static_cast<char>((v >> (8 * i)) & 0xFF));
}
std::string framed(std::uint8_t sender, const std::string& datagram) {
  std::string out(1, static_cast<char>(sender));
  out.push_back(static_cast<char>(datagram.size() & 0xFF));
  out.push_back(static_cast<char>(datagram.size() >> 8));
  return out + datagram;
}
}  // namespace

std::vector<std::string> fuzz_seeds() {
  Frame up;
  up.kind = FrameKind::up;
  up.from = "tahvel://home/1";
  up.to = "tahvel://hospital";
  up.seq = 5;
  up.body = std::string("item\0body", 9);
  const std::string frame = encode_lcm_frame(up).value();
  std::string short_message;
  put(short_message, 0x4c433032, 4);
  put(short_message, 1, 4);
  short_message += std::string("TVchannel") + '\0' + frame;
  // The frame as a message of two fragments.
  auto fragment = [&](int number, std::size_t offset, std::size_t length) {
    std::string d;
    put(d, 0x4c433033, 4);
    put(d, 2, 4);
    put(d, frame.size(), 4);
    put(d, offset, 4);
    put(d, number, 2);
    put(d, 2, 2);
    if (number == 0) d += std::string("TVchannel") + '\0';
    return d + frame.substr(offset, length);
  };
  const std::size_t half = frame.size() / 2;
  return {framed(0, short_message),
          framed(1, fragment(1, half, frame.size() - half)) + framed(1, fragment(0, 0, half)),
          framed(2, fragment(0, 0, half)) + framed(3, short_message)};
}
