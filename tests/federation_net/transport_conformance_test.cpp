// The transport conformance suite (transport_conformance.h) over the wire bindings.
#include "transport_conformance.h"

#include "wire_bindings.h"

namespace tahvel::federation::conformance {

INSTANTIATE_TEST_SUITE_P(Wire, TransportConformance,
                         ::testing::Values(lcm_binding(), dds_binding()), BindingName);

}  // namespace tahvel::federation::conformance
