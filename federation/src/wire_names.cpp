// Channel and topic names of the wire bindings (docs/transports.md).
#include "tahvel/federation/wire_names.h"

namespace tahvel::federation {
namespace {

std::string hex16(std::uint64_t value) {
  static constexpr char kDigits[] = "0123456789abcdef";
  std::string out(16, '0');
  for (int i = 15; i >= 0; --i, value >>= 4) out[static_cast<std::size_t>(i)] = kDigits[value & 15];
  return out;
}

}  // namespace

std::uint64_t wire_hash(std::string_view iri) noexcept {
  std::uint64_t h = 0xcbf29ce484222325ull;
  for (unsigned char c : iri) {
    h ^= c;
    h *= 0x100000001b3ull;
  }
  return h;
}

std::string lcm_channel(std::string_view iri) { return "TV" + hex16(wire_hash(iri)); }

std::string dds_topic(std::string_view iri) { return "tahvel_frame_" + hex16(wire_hash(iri)); }

}  // namespace tahvel::federation
