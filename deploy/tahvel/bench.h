// `tahvel bench store` (bench_store.cpp) and `tahvel bench hrv` (bench_hrv.cpp).
#pragma once

#include <string>
#include <vector>

namespace tahvel::cli {

int bench_store_main(const std::vector<std::string>& args);
int bench_hrv_main(const std::vector<std::string>& args);
int bench_reason_main(const std::vector<std::string>& args);  // bench_reason.cpp

}  // namespace tahvel::cli
