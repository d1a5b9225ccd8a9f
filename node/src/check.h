// Node::check: the whole store read in one snapshot, every row decoded and every reference
// between tables followed (docs/architecture.md, "Checking a store").
#pragma once

#include <cstddef>
#include <functional>
#include <string_view>

#include "env.h"
#include "tahvel/node/node.h"

namespace tahvel::node::detail {

// Reads every table of `env` in `txn` (a read transaction). Problems go into the report, up to
// `max_problems` of them; an error only when the walk cannot go on at all.
Result<CheckReport> check_store(Env& env, MDB_txn* txn, std::size_t max_problems,
                                const std::function<void(std::string_view table)>& progress,
                                const std::function<void(std::string_view problem)>& found);

}  // namespace tahvel::node::detail
