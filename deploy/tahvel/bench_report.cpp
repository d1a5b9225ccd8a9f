// Ratios, targets and output of `tahvel bench store` (see bench_report.h). The rows of the
// table are data: one line per (figure, peer) pair, so a new peer is one more line.
#include "bench_report.h"

#include <iostream>
#include <stdexcept>
#include "bench.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <ostream>

namespace tahvel::cli::bench {
namespace {

enum class Goal { none, ratio_at_least, value_at_most };

struct Row {
  const char* figure;     // what is measured
  const char* key;        // Tahvel's figure
  const char* peer;       // the peer, as printed
  const char* peer_key;   // nullptr: a figure without a peer (a breakdown)
  const char* ratio_key;  // nullptr when peer_key is
  Goal goal = Goal::none;
  double target = 0;
  const char* target_key = nullptr;  // "target_<name>_met" in the JSON
};

const Row kRows[] = {
    {"single-triple items/s", "item_writes_per_s", "SQLite WAL sync=OFF",
     "sqlite_item_writes_per_s", "ratio_items_vs_sqlite", Goal::ratio_at_least, 4,
     "target_items_met"},
    {"single-triple items/s", "item_writes_per_s", "SQLite defaults",
     "sqlite_default_item_writes_per_s", "ratio_items_vs_sqlite_default"},
    {"single-triple store() p50 us", "item_store_p50_us", "SQLite WAL sync=OFF",
     "sqlite_item_store_p50_us", "ratio_item_store_p50_vs_sqlite"},
    {"single-triple store() p99 us", "item_store_p99_us", "SQLite WAL sync=OFF",
     "sqlite_item_store_p99_us", "ratio_item_store_p99_vs_sqlite"},
    {"durable single-triple items/s", "item_durable_writes_per_s", "SQLite defaults",
     "sqlite_default_item_writes_per_s", "ratio_durable_items_vs_sqlite_default"},
    {"10-triple items/s", "item10_writes_per_s", "SQLite WAL sync=OFF",
     "sqlite_item10_writes_per_s", "ratio_item10_vs_sqlite"},
    {"bulk load triples/s", "bulk_triples_per_s", "Sord (memory)", "sord_bulk_triples_per_s",
     "ratio_bulk_vs_sord", Goal::ratio_at_least, 1, "target_bulk_met"},
    {"bulk load triples/s", "bulk_triples_per_s", "SQLite WAL sync=OFF",
     "sqlite_bulk_triples_per_s", "ratio_bulk_vs_sqlite"},
    {"query bound s p50 us", "query_s_p50_us", "SQLite", "sqlite_query_s_p50_us",
     "ratio_query_s_p50_vs_sqlite"},
    {"query bound s p99 us", "query_s_p99_us", "SQLite", "sqlite_query_s_p99_us",
     "ratio_query_s_p99_vs_sqlite"},
    {"query bound s p50 us", "query_s_p50_us", "Sord (memory)", "sord_query_s_p50_us",
     "ratio_query_s_p50_vs_sord"},
    {"query bound s p99 us", "query_s_p99_us", "Sord (memory)", "sord_query_s_p99_us",
     "ratio_query_s_p99_vs_sord"},
    {"query bound p, 100 p50 us", "query_p_p50_us", "SQLite", "sqlite_query_p_p50_us",
     "ratio_query_p_p50_vs_sqlite"},
    {"query bound p, 100 p99 us", "query_p_p99_us", "SQLite", "sqlite_query_p_p99_us",
     "ratio_query_p_p99_vs_sqlite"},
    {"query bound p, 100 p50 us", "query_p_p50_us", "Sord (memory)", "sord_query_p_p50_us",
     "ratio_query_p_p50_vs_sord"},
    {"query bound p, 100 p99 us", "query_p_p99_us", "Sord (memory)", "sord_query_p_p99_us",
     "ratio_query_p_p99_vs_sord"},
    {"query time range, 1000 p50 us", "query_range_p50_us", "SQLite", "sqlite_query_range_p50_us",
     "ratio_query_range_p50_vs_sqlite"},
    {"query time range, 1000 p99 us", "query_range_p99_us", "SQLite", "sqlite_query_range_p99_us",
     "ratio_query_range_p99_vs_sqlite"},
    {"store-to-wake p50 us", "wake_p50_us", "UNIX socket one-way", "unix_socket_p50_us",
     "ratio_wake_vs_unix_socket", Goal::value_at_most, 10, "target_wake_p50_met"},
    {"store-to-wake p99 us", "wake_p99_us", "UNIX socket one-way", "unix_socket_p99_us",
     "ratio_wake_p99_vs_unix_socket", Goal::value_at_most, 50, "target_wake_p99_met"},
    // On one CPU the woken subscriber preempts the writer inside store(), so the store() call
    // outlasts the wake and "after store()" is negative; only the JSON keeps both.
    {"store-to-wake, 2 CPUs p50 us", "wake_two_cpus_p50_us", "UNIX socket, 2 CPUs",
     "unix_socket_two_cpus_p50_us", "ratio_wake_two_cpus_vs_unix_socket_two_cpus"},
    {"store-to-wake, 2 CPUs p99 us", "wake_two_cpus_p99_us", "UNIX socket, 2 CPUs",
     "unix_socket_two_cpus_p99_us", "ratio_wake_two_cpus_p99_vs_unix_socket_two_cpus"},
    {"store-to-wake, paused p50 us", "wake_paused_p50_us", "UNIX socket, paused",
     "unix_socket_paused_p50_us", "ratio_wake_paused_vs_unix_socket_paused"},
    {"store-to-wake, paused p99 us", "wake_paused_p99_us", "UNIX socket, paused",
     "unix_socket_paused_p99_us", "ratio_wake_paused_p99_vs_unix_socket_paused"},
    {"store-to-wake, paused p50 us", "wake_paused_p50_us", "bare futex wake, paused",
     "futex_wake_p50_us", "ratio_wake_paused_vs_futex"},
    {"store-to-wake, paused p99 us", "wake_paused_p99_us", "bare futex wake, paused",
     "futex_wake_p99_us", "ratio_wake_paused_p99_vs_futex"},
    {"  of which store() call p50", "wake_paused_store_call_p50_us", "", nullptr, nullptr},
    {"  of which after store() p50", "wake_paused_after_store_p50_us", "UNIX socket, paused",
     "unix_socket_paused_p50_us", "ratio_wake_paused_after_store_vs_unix_socket_paused"},
    {"bytes per triple", "bytes_per_triple", "SQLite WAL sync=OFF", "sqlite_bytes_per_triple",
     "ratio_bytes_vs_sqlite", Goal::value_at_most, 100, "target_bytes_met"},
};

bool met(const Row& row, const Figures& f) {
  if (row.goal == Goal::ratio_at_least) return f.get(row.ratio_key) >= row.target;
  return f.has(row.key) && f.get(row.key) <= row.target;
}

std::string number(double v) {
  char buf[32];
  double a = std::fabs(v);
  if (a >= 1e4)
    std::snprintf(buf, sizeof buf, "%.0f", v);
  else if (a >= 100)
    std::snprintf(buf, sizeof buf, "%.1f", v);
  else
    std::snprintf(buf, sizeof buf, "%.2f", v);
  return buf;
}

std::string target_text(const Row& row) {
  char buf[48];
  if (row.goal == Goal::ratio_at_least)
    std::snprintf(buf, sizeof buf, "ratio >= %g", row.target);
  else if (row.goal == Goal::value_at_most)
    std::snprintf(buf, sizeof buf, "<= %g", row.target);
  else
    return "";
  return buf;
}

std::string pad(std::string s, std::size_t width, bool right = false) {
  if (s.size() >= width) return s;
  std::string fill(width - s.size(), ' ');
  return right ? fill + s : s + fill;
}

}  // namespace

void Figures::set(const std::string& key, double value) {
  auto it =
      std::find_if(values_.begin(), values_.end(), [&](const auto& kv) { return kv.first == key; });
  if (it != values_.end())
    it->second = value;
  else
    values_.emplace_back(key, value);
}

bool Figures::has(const std::string& key) const {
  return std::any_of(values_.begin(), values_.end(),
                     [&](const auto& kv) { return kv.first == key; });
}

double Figures::get(const std::string& key) const {
  for (const auto& [k, v] : values_) {
    if (k == key) return v;
  }
  return 0;
}

void add_ratios(Figures& f) {
  for (const Row& row : kRows) {
    if (!row.peer_key || !f.has(row.key)) continue;
    double peer = f.get(row.peer_key);
    f.set(row.ratio_key, peer > 0 ? f.get(row.key) / peer : 0);
  }
  for (const Row& row : kRows) {
    if (row.target_key) f.set(row.target_key, met(row, f) ? 1 : 0);
  }
}

void print_json(std::ostream& out, const Figures& f) {
  out << "{";
  const char* sep = "\n  ";
  for (const auto& [key, value] : f.all()) {
    char buf[64];
    const double v = std::isfinite(value) ? value : 0.0;
    const bool whole = v == std::floor(v) && std::fabs(v) < 1e15;  // counts print exactly
    std::snprintf(buf, sizeof buf, whole ? "%.0f" : "%.6g", v);
    out << sep << '"' << key << "\": " << buf;
    sep = ",\n  ";
  }
  out << "\n}\n";
}

void print_table(std::ostream& out, const Figures& f) {
  const std::size_t w[] = {30, 12, 22, 12, 8, 12};
  out << pad("figure", w[0]) << pad("Tahvel", w[1], true) << "   " << pad("peer", w[2])
      << pad("peer value", w[3], true) << pad("ratio", w[4], true) << "   " << pad("target", w[5])
      << "met\n";
  out << std::string(w[0] + w[1] + w[2] + w[3] + w[4] + w[5] + 9, '-') << "\n";
  for (const Row& row : kRows) {
    if (!f.has(row.key)) continue;  // not measured here (two CPUs on a one-CPU machine)
    const bool peer = row.peer_key != nullptr;
    out << pad(row.figure, w[0]) << pad(number(f.get(row.key)), w[1], true) << "   "
        << pad(row.peer, w[2]) << pad(peer ? number(f.get(row.peer_key)) : "", w[3], true)
        << pad(peer ? number(f.get(row.ratio_key)) : "", w[4], true) << "   "
        << pad(target_text(row), w[5])
        << (row.goal == Goal::none ? ""
            : met(row, f)          ? "yes"
                                   : "NO")
        << "\n";
  }
  out << "\nratio = Tahvel / peer: above 1 is better for rates, below 1 for latencies and sizes.\n";
}

}  // namespace tahvel::cli::bench

namespace tahvel::cli {

int guarded_bench_main(const char* name, const std::function<int()>& body) {
  try {
    return body();
  } catch (const std::invalid_argument& e) {
    std::cerr << "tahvel: bench " << name << ": " << e.what() << "\n";
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "tahvel: bench " << name << ": " << e.what() << "\n";
    return 1;
  }
}

}  // namespace tahvel::cli
