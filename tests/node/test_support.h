// Shared helpers for node tests: the node IRI and namespace they use, and a new store.
#pragma once

#include <lmdb.h>
#include <sys/wait.h>
#include <unistd.h>

#include <filesystem>
#include <functional>
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

// Changes the store in `dir` through LMDB itself, as an earlier build or a damaged disk left it:
// `change` runs in a write transaction, in a process of its own (LMDB forbids a second handle on
// an environment this process has open), and commits when it returns true. True on success.
inline bool change_with_lmdb(const std::filesystem::path& dir, const std::function<bool(MDB_txn*)>& change) {
  pid_t pid = fork();
  if (pid == 0) {
    MDB_env* env = nullptr;
    MDB_txn* txn = nullptr;
    const bool ok = mdb_env_create(&env) == 0 && mdb_env_set_maxdbs(env, 32) == 0 &&
                    mdb_env_open(env, dir.c_str(), 0, 0644) == 0 && mdb_txn_begin(env, nullptr, 0, &txn) == 0 &&
                    change(txn) && mdb_txn_commit(txn) == 0;
    _exit(ok ? 0 : 1);
  }
  int status = 0;
  waitpid(pid, &status, 0);
  return WIFEXITED(status) && WEXITSTATUS(status) == 0;
}

}  // namespace tahvel::node::testing
