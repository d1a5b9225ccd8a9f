// The Cyclone DDS domains of this process, shared by the DDS binding and the raw DDS latency
// floor. A domain can be configured only once per process (dds_create_domain); later users of
// the same domain id share it, and a user asking for a different configuration of a domain that
// already runs is refused rather than silently given the first one.
#pragma once

#include <dds/dds.h>

#include <functional>
#include <string>

#include "tahvel/node/error.h"

namespace tahvel::federation::dds_domain {

// Joins domain `id`, creating it with `config` (Cyclone XML, or empty: CYCLONEDDS_URI, else
// Cyclone's defaults) if this process does not run it yet. Each success needs one release().
node::Result<void> acquire(dds_domainid_t id, const std::string& config);
void release(dds_domainid_t id);

// Cyclone checks every sample that arrives from the network against its topic's type and drops
// a malformed one with a warning in its log ("deserialization <topic>/<type> failed"); no reader
// ever sees it. watch_rejections() installs (once per process, for good) a Cyclone log sink that
// hands such warnings about `topic` to `sink`, as one line without the newline, on a Cyclone
// thread; every other log message goes to stderr as Cyclone's default sink would write it.
// Returns a token for unwatch_rejections, after which `sink` is no longer called.
int watch_rejections(const std::string& topic, std::function<void(std::string line)> sink);
void unwatch_rejections(int token);

// Cyclone's name and number for a return code: "Timeout (-10)".
std::string retcode(dds_return_t rc);

// " (Cyclone DDS: <its last error message>)" for the failure of a call made after acquire()
// (which forgets earlier messages), or "" when Cyclone logged no error: its reasons ("eth0: does
// not match an available interface.") go to its log, and a bare return code says nothing.
std::string cyclone_said();

}  // namespace tahvel::federation::dds_domain
