// Process-wide registry of the Cyclone DDS domains in use (see dds_domain.h).
#include "dds_domain.h"

#include <cstdio>
#include <map>
#include <mutex>
#include <string_view>

namespace tahvel::federation::dds_domain {
namespace {

struct Use {
  dds_entity_t domain = 0;  // 0: implicit (created by the first participant from CYCLONEDDS_URI)
  std::string config;
  int users = 0;
};

// The registries are never destroyed: Cyclone may still log (and so call log_sink) while the
// process exits, after function-local statics would have been destroyed.
std::mutex& registry_mutex() {
  static auto* m = new std::mutex;
  return *m;
}

std::map<dds_domainid_t, Use>& registry() {
  static auto* r = new std::map<dds_domainid_t, Use>;
  return *r;
}

struct Watch {
  std::string topic;
  std::function<void(std::string)> sink;
};

std::mutex& watches_mutex() {
  static auto* m = new std::mutex;
  return *m;
}

std::map<int, Watch>& watches() {
  static auto* w = new std::map<int, Watch>;
  return *w;
}

// The topic named in "... deserialization <topic>/<type> failed ...", or empty.
std::string rejected_topic(std::string_view message) {
  constexpr std::string_view kMark = "deserialization ";
  const auto at = message.find(kMark);
  if (at == std::string_view::npos || message.find(" failed", at) == std::string_view::npos)
    return {};
  const auto begin = at + kMark.size();
  const auto slash = message.find('/', begin);
  if (slash == std::string_view::npos) return {};
  return std::string(message.substr(begin, slash - begin));
}

// Cyclone's last error or fatal message (its reason for a failed dds_create_domain or
// participant: "eth0: does not match an available interface.").
std::mutex& last_error_mutex() {
  static auto* m = new std::mutex;
  return *m;
}

std::string& last_error_text() {
  static auto* text = new std::string;
  return *text;
}

void log_sink(void*, const dds_log_data_t* data) {
  std::string_view message(data->message, data->size);
  if (data->priority & (DDS_LC_ERROR | DDS_LC_FATAL)) {
    std::string_view text = message;
    while (!text.empty() && (text.back() == '\n' || text.back() == '\r' || text.back() == ' ')) text.remove_suffix(1);
    std::lock_guard lock(last_error_mutex());
    last_error_text() = std::string(text);
  }
  const std::string topic = rejected_topic(message);
  bool delivered = false;
  if (!topic.empty()) {
    std::string line(message);
    while (!line.empty() && (line.back() == '\n' || line.back() == '\r')) line.pop_back();
    std::lock_guard lock(watches_mutex());
    for (auto& [token, watch] : watches()) {
      if (watch.topic == topic) {
        watch.sink(line);
        delivered = true;
      }
    }
  }
  if (!delivered) {
    // Cyclone hands its messages over without their newline (vlog1's size leaves it out): the
    // next line of the log ran on after one, and a log's last line, which status shows, was two.
    std::fwrite(data->message, 1, data->size, stderr);
    if (data->size == 0 || data->message[data->size - 1] != '\n') std::fputc('\n', stderr);
  }
}

// Installed once and never removed: dds_set_log_sink waits for Cyclone's threads, so it must
// not run while a sink call might be waiting for watches_mutex.
void install_log_sink() {
  static std::once_flag installed;
  std::call_once(installed, [] { dds_set_log_sink(&log_sink, nullptr); });
}

void clear_last_error() {
  std::lock_guard lock(last_error_mutex());
  last_error_text().clear();
}

}  // namespace

std::string cyclone_said() {
  std::lock_guard lock(last_error_mutex());
  return last_error_text().empty() ? std::string() : " (Cyclone DDS: " + last_error_text() + ")";
}

int watch_rejections(const std::string& topic, std::function<void(std::string line)> sink) {
  install_log_sink();
  static int next = 0;
  std::lock_guard lock(watches_mutex());
  const int token = ++next;
  watches().emplace(token, Watch{topic, std::move(sink)});
  return token;
}

void unwatch_rejections(int token) {
  std::lock_guard lock(watches_mutex());
  watches().erase(token);
}

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
  install_log_sink();  // Cyclone's reason for a failure below goes into the error
  clear_last_error();
  if (!config.empty()) {
    use.domain = dds_create_domain(id, config.c_str());
    if (use.domain < 0) {
      return node::fail(node::Errc::invalid_argument,
                        "dds_create_domain " + std::to_string(id) +
                            " with the given configuration failed: " + retcode(use.domain) + cyclone_said());
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
