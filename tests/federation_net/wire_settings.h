// The settings the network tests use: LCM's default loopback-only multicast URL (ttl=0), and
// deploy/cyclonedds-loopback.xml for Cyclone DDS.
#pragma once

#include <fstream>
#include <sstream>
#include <stdexcept>

#include "tahvel/federation/transport.h"

namespace tahvel::federation::conformance {

inline LcmSettings test_lcm_settings() { return LcmSettings{}; }

inline DdsSettings test_dds_settings() {
  std::ifstream in(TAHVEL_SOURCE_DIR "/deploy/cyclonedds-loopback.xml");
  std::stringstream text;
  text << in.rdbuf();
  if (text.str().empty()) throw std::runtime_error("cannot read deploy/cyclonedds-loopback.xml");
  DdsSettings s;
  s.config = text.str();
  return s;
}

}  // namespace tahvel::federation::conformance
