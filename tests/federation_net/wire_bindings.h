// The LCM and Cyclone DDS bindings as conformance-suite Bindings (wire_settings.h).
#pragma once

#include <lcm/lcm.h>

#include "tahvel/federation/transport.h"
#include "tahvel/federation/wire_names.h"
#include "transport_conformance.h"
#include "wire_settings.h"

namespace tahvel::federation::conformance {

template <class Open>
std::unique_ptr<Transport> opened(Open&& result) {
  EXPECT_TRUE(result) << (result ? "" : result.error().message);
  return result ? std::move(*result) : nullptr;
}

inline Binding lcm_binding() {
  Binding b;
  b.name = "lcm";
  b.open = [](std::string iri, DropLog log) {
    return opened(open_lcm(test_lcm_settings(), iri, std::move(log)));
  };
  // Raw bytes published with plain LCM on the channel the endpoint listens on.
  b.inject_raw = [](const std::string& to, const std::string& bytes) {
    lcm_t* lcm = lcm_create(test_lcm_settings().url.c_str());
    ASSERT_NE(lcm, nullptr);
    EXPECT_EQ(lcm_publish(lcm, lcm_channel(to).c_str(), bytes.data(),
                          static_cast<unsigned>(bytes.size())),
              0);
    lcm_destroy(lcm);
  };
  b.lossless = false;
  return b;
}

inline Binding dds_binding() {
  Binding b;
  b.name = "dds";
  b.open = [](std::string iri, DropLog log) {
    return opened(open_dds(test_dds_settings(), iri, std::move(log)));
  };
  b.no_raw_reason =
      "Cyclone DDS checks every sample's CDR against the topic type (dds_stream_normalize) "
      "before any reader sees it, so raw bytes cannot reach the endpoint";
  b.lossless = true;
  return b;
}

}  // namespace tahvel::federation::conformance
