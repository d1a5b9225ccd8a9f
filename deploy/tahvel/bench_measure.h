// Timing helpers shared by every system that `tahvel bench store` measures: a monotonic clock,
// percentiles of per-call latencies, write-rate accumulators and a scratch directory that is
// removed when the bench ends.
#pragma once

#include <sched.h>

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

namespace tahvel::cli::bench {

using Clock = std::chrono::steady_clock;

// Nanoseconds on the monotonic clock (CLOCK_MONOTONIC: the same in every process).
std::int64_t now_ns();

double micros(Clock::duration d);
double seconds(Clock::duration d);

struct Percentiles {
  double p50_us = 0, p99_us = 0;
  std::size_t samples = 0;
};

// Nearest-rank percentiles of latencies in microseconds (sorts `us`).
Percentiles percentiles(std::vector<double> us);

// Writes counted while the timed sections add up.
struct Rate {
  std::uint64_t items = 0, triples = 0;
  Clock::duration elapsed{};
  double items_per_s() const;
  double triples_per_s() const;
};

// Where the two processes of a latency pair run. A hand-off between processes on one CPU
// costs a context switch; between two CPUs it also costs waking the other CPU, which on a
// virtual machine is an inter-processor interrupt through the hypervisor and dominates the
// figure. Each measurement and its floor run under the same placement.
struct Placement {
  int parent_cpu = -1, child_cpu = -1;  // -1: wherever the scheduler puts it
  bool pinned() const { return parent_cpu >= 0; }
};

// Both processes on the first CPU this process may use, or on its first two; nullopt for
// "two CPUs" when it may use only one.
Placement one_cpu();
std::optional<Placement> two_cpus();

// Pins the calling process to `cpu` (no-op for -1); returns false when the kernel refuses.
bool pin_to_cpu(int cpu);

// Pins this process for its lifetime and restores the CPUs it could use before.
class ScopedPin {
 public:
  explicit ScopedPin(int cpu);
  ScopedPin(const ScopedPin&) = delete;
  ScopedPin& operator=(const ScopedPin&) = delete;
  ~ScopedPin();

 private:
  bool saved_ = false;
  cpu_set_t before_{};
};

// A fresh directory under `parent` (or the system's temporary directory when empty), removed
// with its contents by the destructor.
class ScratchDir {
 public:
  explicit ScratchDir(const std::filesystem::path& parent);
  ScratchDir(const ScratchDir&) = delete;
  ScratchDir& operator=(const ScratchDir&) = delete;
  ~ScratchDir();
  const std::filesystem::path& path() const { return path_; }
  // A new, not yet existing path inside the directory.
  std::filesystem::path sub(const std::string& name) const { return path_ / name; }

 private:
  std::filesystem::path path_;
};

}  // namespace tahvel::cli::bench

namespace tahvel::cli::bench {

// Calls `query(key)` once per key, timing each call; returns the latency percentiles and adds
// the rows each call reports to `rows`.
template <class Key, class Query>
Percentiles time_each(const std::vector<Key>& keys, std::uint64_t& rows, Query&& query) {
  std::vector<double> us;
  us.reserve(keys.size());
  for (const Key& key : keys) {
    auto t0 = Clock::now();
    rows += query(key);
    us.push_back(micros(Clock::now() - t0));
  }
  return percentiles(std::move(us));
}

}  // namespace tahvel::cli::bench
