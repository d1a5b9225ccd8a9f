// `tahvel bench store` (bench_store.cpp), `tahvel bench hrv` (bench_hrv.cpp) and
// `tahvel bench spatial` (bench_spatial.cpp).
#pragma once

#include <string>
#include <vector>

namespace tahvel::cli {

int bench_store_main(const std::vector<std::string>& args);
int bench_hrv_main(const std::vector<std::string>& args);
int bench_spatial_main(const std::vector<std::string>& args);
int bench_reason_main(const std::vector<std::string>& args);  // bench_reason.cpp
int bench_federation_main(const std::vector<std::string>& args);  // bench_federation.cpp

}  // namespace tahvel::cli
