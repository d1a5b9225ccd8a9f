// The `tahvel bench` subcommands: store, hrv, spatial, reason and federation (bench_NAME.cpp).
#pragma once

#include <functional>
#include <iostream>
#include <string>
#include <vector>

namespace tahvel::cli {

// Runs a benchmark's main body: std::invalid_argument (a bad flag) prints
// "tahvel: bench NAME: <message>" and gives 2, any other exception gives 1.
int guarded_bench_main(const char* name, const std::function<int()>& body);

// A benchmark whose `parse(args)` gives its settings, or nullopt for --help (then `usage` is
// printed and the status is 0), and whose `run(settings)` gives the exit status; both guarded.
template <class Parse, class Run>
int parse_and_run_bench(const char* name, const std::vector<std::string>& args, const char* usage,
                        Parse parse, Run run) {
  return guarded_bench_main(name, [&] {
    auto settings = parse(args);
    if (!settings) {
      std::cout << usage;
      return 0;
    }
    return run(*settings);
  });
}

int bench_store_main(const std::vector<std::string>& args);
int bench_hrv_main(const std::vector<std::string>& args);
int bench_spatial_main(const std::vector<std::string>& args);
int bench_reason_main(const std::vector<std::string>& args);  // bench_reason.cpp
int bench_federation_main(const std::vector<std::string>& args);  // bench_federation.cpp

}  // namespace tahvel::cli
