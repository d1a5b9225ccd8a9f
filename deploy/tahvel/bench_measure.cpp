// Timing helpers for `tahvel bench store` (see bench_measure.h).
#include "bench_measure.h"

#include <stdlib.h>
#include <time.h>

#include <algorithm>
#include <stdexcept>
#include <system_error>

namespace tahvel::cli::bench {

std::int64_t now_ns() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

double micros(Clock::duration d) { return std::chrono::duration<double, std::micro>(d).count(); }
double seconds(Clock::duration d) { return std::chrono::duration<double>(d).count(); }

Percentiles percentiles(std::vector<double> us) {
  Percentiles p;
  p.samples = us.size();
  if (us.empty()) return p;
  std::sort(us.begin(), us.end());
  auto rank = [&](double q) {
    std::size_t i = static_cast<std::size_t>(q * static_cast<double>(us.size()));
    return us[std::min(i, us.size() - 1)];
  };
  p.p50_us = rank(0.50);
  p.p99_us = rank(0.99);
  return p;
}

double Rate::items_per_s() const {
  double s = seconds(elapsed);
  return s > 0 ? static_cast<double>(items) / s : 0;
}

double Rate::triples_per_s() const {
  double s = seconds(elapsed);
  return s > 0 ? static_cast<double>(triples) / s : 0;
}

ScratchDir::ScratchDir(const std::filesystem::path& parent) {
  std::filesystem::path base = parent.empty() ? std::filesystem::temp_directory_path() : parent;
  std::string templ = (base / "tahvel-bench-XXXXXX").string();
  if (mkdtemp(templ.data()) == nullptr) {
    throw std::system_error(errno, std::generic_category(),
                            "cannot create a directory in " + base.string());
  }
  path_ = templ;
}

ScratchDir::~ScratchDir() {
  std::error_code ec;
  std::filesystem::remove_all(path_, ec);
}

}  // namespace tahvel::cli::bench
