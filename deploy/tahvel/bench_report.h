// The figures of `tahvel bench store` and their two renderings: one JSON object (--json) and a
// table with each figure, its peer, the ratio and whether the target is met.
// Every ratio is Tahvel's figure divided by the peer's: above 1 is better for rates, below 1 is
// better for latencies and sizes.
#pragma once

#include <iosfwd>
#include <string>
#include <utility>
#include <vector>

namespace tahvel::cli::bench {

// Named numbers in the order they were set (the JSON keys).
class Figures {
 public:
  void set(const std::string& key, double value);
  bool has(const std::string& key) const;
  double get(const std::string& key) const;  // 0 when unset
  const std::vector<std::pair<std::string, double>>& all() const { return values_; }

 private:
  std::vector<std::pair<std::string, double>> values_;
};

// Adds every ratio and target verdict to `f` (call once all measurements are in).
void add_ratios(Figures& f);

void print_json(std::ostream& out, const Figures& f);
void print_table(std::ostream& out, const Figures& f);

}  // namespace tahvel::cli::bench
