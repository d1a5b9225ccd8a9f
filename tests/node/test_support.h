// Shared helpers for node tests: the node IRI and namespace they use, and a new store.
#pragma once

#include <filesystem>
#include <stdexcept>
#include <string>

#include "tahvel/node/node.h"
#include "temp_dir.h"

namespace tahvel::node::testing {

using tahvel::test_support::TempDir;

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
