// `tahvel bench store`: the store benchmark, implemented in bench_store.cpp.
#pragma once

#include <string>
#include <vector>

namespace tahvel::cli {

int bench_store_main(const std::vector<std::string>& args);

}  // namespace tahvel::cli
