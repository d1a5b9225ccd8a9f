// Shared helpers for node tests: a temporary store directory that cleans up after itself.
#pragma once

#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <string>

#include "tahvel/node/node.h"

namespace tahvel::node::testing {

class TempDir {
 public:
  TempDir() {
    std::string pattern = (std::filesystem::temp_directory_path() / "tahvel-test-XXXXXX").string();
    path_ = mkdtemp(pattern.data());
  }
  ~TempDir() {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  const std::filesystem::path& path() const { return path_; }
  std::filesystem::path operator/(const std::string& name) const { return path_ / name; }

 private:
  std::filesystem::path path_;
};

inline const std::string kNodeIri = "http://example.org/home1";
inline const std::string kEx = "http://example.org/ns#";

inline Term ex(const std::string& local) { return Term::iri(kEx + local); }

inline Node make_node(const std::filesystem::path& dir, InitOptions options = {}) {
  if (options.iri.empty()) options.iri = kNodeIri;
  auto node = Node::init(dir, options);
  if (!node) throw std::runtime_error(node.error().message);
  return std::move(*node);
}

}  // namespace tahvel::node::testing
