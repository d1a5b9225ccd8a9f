// Process-wide registry of the Cyclone DDS domains in use (see dds_domain.h).
#include "dds_domain.h"

#include <map>
#include <mutex>

namespace tahvel::federation::dds_domain {
namespace {

struct Use {
  dds_entity_t domain = 0;  // 0: implicit (created by the first participant from CYCLONEDDS_URI)
  std::string config;
  int users = 0;
};

std::mutex& registry_mutex() {
  static std::mutex m;
  return m;
}

std::map<dds_domainid_t, Use>& registry() {
  static std::map<dds_domainid_t, Use> r;
  return r;
}

}  // namespace

std::string retcode(dds_return_t rc) {
  return std::string(dds_strretcode(rc)) + " (" + std::to_string(rc) + ")";
}

node::Result<void> acquire(dds_domainid_t id, const std::string& config) {
  std::lock_guard lock(registry_mutex());
  auto it = registry().find(id);
  if (it != registry().end()) {
    if (!config.empty() && config != it->second.config) {
      return node::fail(node::Errc::invalid_argument,
                        "DDS domain " + std::to_string(id) +
                            " already runs in this process with another configuration");
    }
    ++it->second.users;
    return {};
  }
  Use use;
  use.config = config;
  if (!config.empty()) {
    use.domain = dds_create_domain(id, config.c_str());
    if (use.domain < 0) {
      return node::fail(node::Errc::invalid_argument,
                        "dds_create_domain " + std::to_string(id) +
                            " with the given configuration failed: " + retcode(use.domain));
    }
  }
  use.users = 1;
  registry().emplace(id, use);
  return {};
}

void release(dds_domainid_t id) {
  std::lock_guard lock(registry_mutex());
  auto it = registry().find(id);
  if (it == registry().end() || --it->second.users > 0) return;
  if (it->second.domain > 0) dds_delete(it->second.domain);
  registry().erase(it);
}

}  // namespace tahvel::federation::dds_domain
