// The Cyclone DDS domains of this process, shared by the DDS binding and the raw DDS latency
// floor. A domain can be configured only once per process (dds_create_domain); later users of
// the same domain id share it, and a user asking for a different configuration of a domain that
// already runs is refused rather than silently given the first one.
#pragma once

#include <dds/dds.h>

#include <string>

#include "tahvel/node/error.h"

namespace tahvel::federation::dds_domain {

// Joins domain `id`, creating it with `config` (Cyclone XML, or empty: CYCLONEDDS_URI, else
// Cyclone's defaults) if this process does not run it yet. Each success needs one release().
node::Result<void> acquire(dds_domainid_t id, const std::string& config);
void release(dds_domainid_t id);

// Cyclone's name and number for a return code: "Timeout (-10)".
std::string retcode(dds_return_t rc);

}  // namespace tahvel::federation::dds_domain
