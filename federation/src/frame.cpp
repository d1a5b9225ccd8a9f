// Frame fingerprint and the byte encoding used by the in-memory binding and by tests.
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
    "kind{hello=1;welcome=2;up=3;ack=4;down=5;query=6;answer=7;error=8;heartbeat=9}";

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

}  // namespace tahvel::federation
