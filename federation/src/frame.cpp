// Frame fingerprint, store tags and the byte encoding used by the in-memory binding and by tests.
#include <cstring>

#include "tahvel/federation/transport.h"

namespace tahvel::federation {
namespace {

// The canonical description of the message types: any change to a field, its order or its type,
// or to the kinds, changes the fingerprint (docs/protocol.md P3). Keep it in step with
// federation/types/tahvel_frame.lcm and federation/types/tahvel_frame.idl.
constexpr std::string_view kSchema =
    "frame{u16 version;u64 fingerprint;u8 kind;str from;str to;u64 seq;u64 prev;u64 ack;"
    "bytes body}"
    "kind{hello=1;welcome=2;up=3;ack=4;down=5;query=6;answer=7;error=8;heartbeat=9;packed=10}";

constexpr std::uint64_t fnv1a64(std::string_view text) {
  std::uint64_t h = 0xcbf29ce484222325ull;
  for (unsigned char c : text) {
    h ^= c;
    h *= 0x100000001b3ull;
  }
  return h;
}

}  // namespace

std::uint64_t message_fingerprint() noexcept { return fnv1a64(kSchema); }

std::uint64_t store_tag(std::string_view store_id) noexcept {
  if (store_id.empty()) return 0;
  const std::uint64_t tag = (fnv1a64(store_id) >> 40) & kStoreTagMask;
  return tag != 0 ? tag : 1;
}

}  // namespace tahvel::federation

namespace tahvel::federation {
namespace {

// Little-endian fixed-width integers and length-prefixed strings (u32 length).
void put_uint(std::string& out, std::uint64_t value, int bytes) {
  for (int i = 0; i < bytes; ++i) out.push_back(static_cast<char>((value >> (8 * i)) & 0xff));
}

void put_bytes(std::string& out, std::string_view bytes) {
  put_uint(out, bytes.size(), 4);
  out.append(bytes);
}

class Reader {
 public:
  explicit Reader(std::string_view bytes) : bytes_(bytes) {}

  Result<std::uint64_t> uint(int width, const char* field) {
    if (bytes_.size() - pos_ < static_cast<std::size_t>(width)) return truncated(field);
    std::uint64_t value = 0;
    for (int i = 0; i < width; ++i)
      value |= std::uint64_t{static_cast<unsigned char>(bytes_[pos_ + i])} << (8 * i);
    pos_ += width;
    return value;
  }

  Result<std::string> bytes(const char* field) {
    auto size = uint(4, field);
    if (!size) return Unexpected<Error>{size.error()};
    if (bytes_.size() - pos_ < *size) return truncated(field);
    std::string value(bytes_.substr(pos_, *size));
    pos_ += *size;
    return value;
  }

  std::size_t remaining() const { return bytes_.size() - pos_; }
  std::size_t position() const { return pos_; }

 private:
  Unexpected<Error> truncated(const char* field) const {
    return node::fail(Errc::syntax, "frame truncated in field '" + std::string(field) +
                                        "' at byte " + std::to_string(pos_) + " of " +
                                        std::to_string(bytes_.size()));
  }

  std::string_view bytes_;
  std::size_t pos_ = 0;
};

}  // namespace

std::string encode_frame(const Frame& frame) {
  std::string out;
  out.reserve(48 + frame.from.size() + frame.to.size() + frame.body.size());
  put_uint(out, frame.version, 2);
  put_uint(out, frame.fingerprint, 8);
  put_uint(out, static_cast<std::uint8_t>(frame.kind), 1);
  put_bytes(out, frame.from);
  put_bytes(out, frame.to);
  put_uint(out, frame.seq, 8);
  put_uint(out, frame.prev, 8);
  put_uint(out, frame.ack, 8);
  put_bytes(out, frame.body);
  return out;
}

Result<Frame> decode_frame(std::string_view bytes) {
  Reader in(bytes);
  Frame frame;
  auto version = in.uint(2, "version");
  if (!version) return Unexpected<Error>{version.error()};
  frame.version = static_cast<std::uint16_t>(*version);
  auto fingerprint = in.uint(8, "fingerprint");
  if (!fingerprint) return Unexpected<Error>{fingerprint.error()};
  frame.fingerprint = *fingerprint;
  auto kind = in.uint(1, "kind");
  if (!kind) return Unexpected<Error>{kind.error()};
  if (*kind < 1 || *kind > 9)
    return node::fail(Errc::syntax, "frame kind " + std::to_string(*kind) + " unknown (byte 10)");
  frame.kind = static_cast<FrameKind>(*kind);
  for (auto [field, name] : {std::pair{&frame.from, "from"}, std::pair{&frame.to, "to"}}) {
    auto value = in.bytes(name);
    if (!value) return Unexpected<Error>{value.error()};
    *field = std::move(*value);
  }
  for (auto [field, name] : {std::pair{&frame.seq, "seq"}, std::pair{&frame.prev, "prev"},
                             std::pair{&frame.ack, "ack"}}) {
    auto value = in.uint(8, name);
    if (!value) return Unexpected<Error>{value.error()};
    *field = *value;
  }
  auto body = in.bytes("body");
  if (!body) return Unexpected<Error>{body.error()};
  frame.body = std::move(*body);
  if (in.remaining() != 0)
    return node::fail(Errc::syntax, std::to_string(in.remaining()) +
                                        " stray bytes after the frame at byte " +
                                        std::to_string(in.position()));
  return frame;
}

std::string frame_kind_name(FrameKind kind) {
  switch (kind) {
    case FrameKind::hello: return "hello";
    case FrameKind::welcome: return "welcome";
    case FrameKind::up: return "up";
    case FrameKind::ack: return "ack";
    case FrameKind::down: return "down";
    case FrameKind::query: return "query";
    case FrameKind::answer: return "answer";
    case FrameKind::error: return "error";
    case FrameKind::heartbeat: return "heartbeat";
  }
  return "kind " + std::to_string(static_cast<unsigned>(kind));
}

std::optional<std::string> frame_refusal(const Frame& frame, std::string_view self_iri) {
  // First: the reasons below quote the sender's IRI.
  if (frame.from.size() > kMaxFrameIriBytes)
    return "a sender IRI of " + std::to_string(frame.from.size()) + " bytes, over the limit of " +
           std::to_string(kMaxFrameIriBytes) + " (<" + frame.from.substr(0, 80) + "...>)";
  if (frame.version < kOldestProtocolVersion || frame.version > kProtocolVersion)
    return "protocol version " + std::to_string(frame.version) + " from <" + frame.from + ">, this node speaks " +
           std::to_string(kProtocolVersion) + " and hears " + std::to_string(kOldestProtocolVersion) + " to " +
           std::to_string(kProtocolVersion);
  if (frame.fingerprint != message_fingerprint())
    return "message-type fingerprint mismatch from <" + frame.from + "> (other build's types differ)";
  if (frame.to != self_iri) return "frame for <" + frame.to + ">, not for this endpoint <" +
                                   std::string(self_iri) + ">";
  return std::nullopt;
}

}  // namespace tahvel::federation
