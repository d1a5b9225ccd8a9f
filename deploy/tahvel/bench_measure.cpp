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

namespace {

std::vector<int> usable_cpus() {
  cpu_set_t set;
  CPU_ZERO(&set);
  std::vector<int> cpus;
  if (sched_getaffinity(0, sizeof set, &set) != 0) return cpus;
  for (int cpu = 0; cpu < CPU_SETSIZE; ++cpu) {
    if (CPU_ISSET(cpu, &set)) cpus.push_back(cpu);
  }
  return cpus;
}

}  // namespace

Placement one_cpu() {
  std::vector<int> cpus = usable_cpus();
  if (cpus.empty()) return {};
  return {cpus[0], cpus[0]};
}

std::optional<Placement> two_cpus() {
  std::vector<int> cpus = usable_cpus();
  if (cpus.size() < 2) return std::nullopt;
  return Placement{cpus[0], cpus[1]};
}

bool pin_to_cpu(int cpu) {
  if (cpu < 0) return true;
  cpu_set_t set;
  CPU_ZERO(&set);
  CPU_SET(cpu, &set);
  return sched_setaffinity(0, sizeof set, &set) == 0;
}

ScopedPin::ScopedPin(int cpu) {
  if (cpu < 0) return;
  saved_ = sched_getaffinity(0, sizeof before_, &before_) == 0;
  if (saved_) pin_to_cpu(cpu);
}

ScopedPin::~ScopedPin() {
  if (saved_) sched_setaffinity(0, sizeof before_, &before_);
}

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
