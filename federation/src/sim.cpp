// Child-role frames for load generators (sim.h), encoded with the Link's own body codecs.
#include "tahvel/federation/sim.h"

#include "tahvel/federation/wire.h"

namespace tahvel::federation::sim {
namespace {

Frame state_frame(FrameKind kind, std::string_view from, std::string_view to, const ChildState& state) {
  Frame f;
  f.kind = kind;
  f.from = std::string(from);
  f.to = std::string(to);
  if (kind == FrameKind::hello) f.ack = state.down_mark;
  f.body = wire::encode_state({state.software_version, state.outbox_depth});
  return f;
}

}  // namespace

Frame hello_frame(std::string_view from, std::string_view to, const ChildState& state) {
  return state_frame(FrameKind::hello, from, to, state);
}

Frame heartbeat_frame(std::string_view from, std::string_view to, const ChildState& state) {
  return state_frame(FrameKind::heartbeat, from, to, state);
}

Frame up_frame(std::string_view from, std::string_view to, std::uint64_t seq, std::uint64_t prev,
               std::string_view source, const node::Item& item) {
  Frame f;
  f.kind = FrameKind::up;
  f.from = std::string(from);
  f.to = std::string(to);
  f.seq = seq;
  f.prev = prev;
  f.body = wire::encode_item({std::string(source), item});
  return f;
}

std::optional<std::string> error_code(const Frame& frame) {
  if (frame.kind != FrameKind::error) return std::nullopt;
  auto body = wire::decode_error(frame.body);
  if (!body) return std::nullopt;
  return body->code;
}

}  // namespace tahvel::federation::sim
