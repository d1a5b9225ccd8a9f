// Frames of the child role for programs that speak the link protocol (docs/protocol.md) without
// a store or a Link of their own: load generators such as the simulated homes of
// `tahvel bench federation`. A Link does all of this itself; use these only to stand in for many
// children cheaply. The caller keeps the child's state (its mark, window and resends, P6-P8).
//
//   Frame hello = sim::hello_frame(home, hospital, {});
//   Frame up = sim::up_frame(home, hospital, seq, prev, home + "/sensor", item);
//   transport->send(up);
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

#include "tahvel/federation/transport.h"
#include "tahvel/node/term.h"

namespace tahvel::federation::sim {

// A child's state as a hello or heartbeat carries it (P6, P12).
struct ChildState {
  std::string software_version = "tahvel-sim";
  std::uint64_t outbox_depth = 0;
  std::uint64_t down_mark = 0;  // hello only: the child's mark of its down stream
};

// A hello from child `from` to its parent `to`.
Frame hello_frame(std::string_view from, std::string_view to, const ChildState& state);

// A heartbeat from child `from` to its parent `to`.
Frame heartbeat_frame(std::string_view from, std::string_view to, const ChildState& state);

// One item going up (P7): `seq` is the item's id on the child, `prev` the seq of the up frame
// sent just before it (the parent's mark after a go-back), `source` the original writer's IRI
// (it must lie under `from`, or the parent refuses the run, P9). The body is encoded exactly as
// a Link encodes it (docs/protocol.md, "Bodies": item).
Frame up_frame(std::string_view from, std::string_view to, std::uint64_t seq, std::uint64_t prev,
               std::string_view source, const node::Item& item);

// The code of an error frame's body ("refused", "unregistered", ...), or nullopt when the frame
// is not an error or its body does not decode.
std::optional<std::string> error_code(const Frame& frame);

}  // namespace tahvel::federation::sim
