// A Frame as a tahvel_frame_t, through the lcm-gen generated C code (lcm_frame.h).
#include "tahvel/federation/lcm_frame.h"

#include <cstdint>
#include <cstdio>
#include <cstring>
#include <optional>

#include "tahvel_frame_t.h"
#include "wire_common.h"

namespace tahvel::federation {
namespace {

// Why `data` is not a whole tahvel_frame_t as lcm-gen lays one out (big-endian: type hash,
// version, fingerprint, kind, from, to, seq, prev, ack, body size, body; a string is an int32
// length counting its NUL, then its bytes), or nothing. Bytes after the body are left to the
// caller, which names them.
std::optional<std::string> layout_problem(const unsigned char* data, std::size_t size) {
  std::size_t at = 0;
  auto int_at = [&](std::size_t bytes) {
    std::uint64_t value = 0;
    for (std::size_t i = 0; i < bytes; ++i) value = value << 8 | data[at + i];
    at += bytes;
    return value;
  };
  auto cut = [&](std::size_t need, const char* field) -> std::optional<std::string> {
    if (size - at >= need) return std::nullopt;
    return std::string("cut short in '") + field + "' (" + std::to_string(size) + " bytes)";
  };
  if (auto c = cut(8, "type hash")) return c;
  const auto hash = int_at(8);
  if (hash != static_cast<std::uint64_t>(__tahvel_frame_t_get_hash())) {
    char text[80];
    std::snprintf(text, sizeof text, "type hash 0x%016llx, a tahvel_frame_t's is 0x%016llx",
                  static_cast<unsigned long long>(hash), static_cast<unsigned long long>(__tahvel_frame_t_get_hash()));
    return text;
  }
  if (auto c = cut(2 + 8 + 1, "kind")) return c;
  at += 2 + 8 + 1;
  for (const char* field : {"from", "to"}) {
    if (auto c = cut(4, field)) return c;
    const auto length = static_cast<std::int32_t>(int_at(4));
    if (length < 1 || static_cast<std::size_t>(length) > size - at)
      return std::string("'") + field + "' says " + std::to_string(length) + " bytes, " + std::to_string(size - at) +
             " are left";
    const auto text_length = static_cast<std::size_t>(length) - 1;
    if (data[at + text_length] != 0) return std::string("'") + field + "' does not end with the NUL its length counts";
    // The decoder would keep the IRI up to its first NUL: a frame would arrive under another
    // name than it was sent with.
    if (const void* nul = std::memchr(data + at, 0, text_length))
      return std::string("'") + field + "' has a NUL at byte " +
             std::to_string(static_cast<const unsigned char*>(nul) - (data + at)) + " of its " +
             std::to_string(text_length);
    at += static_cast<std::size_t>(length);
  }
  if (auto c = cut(3 * 8 + 4, "body_size")) return c;
  at += 3 * 8;
  const auto body = static_cast<std::int32_t>(int_at(4));
  if (body < 0 || static_cast<std::size_t>(body) > size - at)
    return "'body' says " + std::to_string(body) + " bytes, " + std::to_string(size - at) + " are left";
  return std::nullopt;
}

Result<Frame> not_a_frame(const std::string& why) {
  return node::fail(Errc::invalid_argument, "not a tahvel_frame_t (" + why + ")");
}

}  // namespace

Result<std::string> encode_lcm_frame(const Frame& frame) {
  if (frame.from.find('\0') != std::string::npos || frame.to.find('\0') != std::string::npos)
    return node::fail(Errc::invalid_argument, "an IRI of the frame has a NUL in it, which LCM's strings cannot carry");
  // The whole message in an int, as lcm-gen adds its size up (in an int: past it, undefined).
  const std::size_t whole = 8 + 2 + 8 + 1 + (4 + frame.from.size() + 1) + (4 + frame.to.size() + 1) + 3 * 8 + 4 + frame.body.size();
  if (whole > static_cast<std::size_t>(INT32_MAX))
    return node::fail(Errc::invalid_argument, "a frame of " + std::to_string(whole) +
                                                  " bytes is more than an LCM message holds (2 GB)");
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
  if (size < 0 || static_cast<std::size_t>(size) != whole) return node::fail(Errc::invalid_argument, "LCM's encoder sized the frame otherwise");
  std::string bytes(whole, '\0');
  if (tahvel_frame_t_encode(bytes.data(), 0, size, &msg) != size)
    return node::fail(Errc::invalid_argument, "LCM's encoder refused the frame");
  return bytes;
}

Result<Frame> decode_lcm_frame(std::string_view message) {
  if (message.size() > static_cast<std::size_t>(INT32_MAX)) return not_a_frame("larger than LCM's 2 GB");
  if (auto problem = layout_problem(reinterpret_cast<const unsigned char*>(message.data()), message.size()))
    return not_a_frame(*problem);
  tahvel_frame_t msg{};
  const int used = tahvel_frame_t_decode(message.data(), 0, static_cast<int>(message.size()), &msg);
  // After the layout check the decoder cannot fail; should it, it is said as the rest are.
  if (used < 0) return not_a_frame("LCM's decoder refused it");
  Frame frame;
  frame.version = static_cast<std::uint16_t>(msg.version);
  frame.fingerprint = static_cast<std::uint64_t>(msg.fingerprint);
  frame.kind = static_cast<FrameKind>(msg.kind);
  frame.from = msg.from != nullptr ? msg.from : "";
  frame.to = msg.to != nullptr ? msg.to : "";
  frame.seq = static_cast<std::uint64_t>(msg.seq);
  frame.prev = static_cast<std::uint64_t>(msg.prev);
  frame.ack = static_cast<std::uint64_t>(msg.ack);
  if (msg.body_size > 0) frame.body.assign(reinterpret_cast<const char*>(msg.body), static_cast<std::size_t>(msg.body_size));
  tahvel_frame_t_decode_cleanup(&msg);
  if (static_cast<std::size_t>(used) != message.size())
    return node::fail(Errc::invalid_argument, "a tahvel_frame_t (" + wire::describe(frame) + ") and " +
                                                  std::to_string(message.size() - static_cast<std::size_t>(used)) +
                                                  " bytes after it");
  return frame;
}

}  // namespace tahvel::federation
