// `tahvel bench store` (bench_store.cpp), `tahvel bench hrv` (bench_hrv.cpp) and
// `tahvel bench spatial` (bench_spatial.cpp).
#pragma once

#include <functional>
#include <string>
#include <vector>

namespace tahvel::cli {

// Runs a benchmark's main body: std::invalid_argument (a bad flag) prints
// "tahvel: bench NAME: <message>" and gives 2, any other exception gives 1.
int guarded_bench_main(const char* name, const std::function<int()>& body);

int bench_store_main(const std::vector<std::string>& args);
int bench_hrv_main(const std::vector<std::string>& args);
int bench_spatial_main(const std::vector<std::string>& args);
int bench_reason_main(const std::vector<std::string>& args);  // bench_reason.cpp
int bench_federation_main(const std::vector<std::string>& args);  // bench_federation.cpp

}  // namespace tahvel::cli
