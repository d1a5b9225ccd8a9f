// The transport conformance suite (tests/federation_net/transport_conformance.h) over the
// in-memory binding: the same cases as LCM and Cyclone DDS, without a network namespace.
#include "../federation_net/transport_conformance.h"

namespace tahvel::federation::conformance {
namespace {

Binding memory_binding() {
  static MemoryBus bus;  // outlives every endpoint of every case
  Binding b;
  b.name = "memory";
  b.open = [](std::string iri, DropLog log) { return bus.open(iri, std::move(log)); };
  b.inject_raw = [](const std::string& to, const std::string& bytes) { bus.inject_raw(to, bytes); };
  b.lossless = true;
  b.needs_netns = false;
  return b;
}

INSTANTIATE_TEST_SUITE_P(Memory, TransportConformance, ::testing::Values(memory_binding()), BindingName);

}  // namespace
}  // namespace tahvel::federation::conformance
