// Differential runs of the engine (rules_test, stratification_test): random sessions applied
// incrementally, checked against one from-scratch run on the base facts they leave.
#pragma once

#include <gtest/gtest.h>

#include <cstddef>
#include <memory>
#include <random>
#include <set>
#include <string>
#include <vector>

#include "tahvel/agents/rules.h"

namespace tahvel::reasoner::differential {

// Takes up to `removes` random facts out of `held` as the session's removals, adds `in`, and
// applies the session to `incremental`.
inline void apply_session(Engine& incremental, std::vector<node::Triple>& held, const std::vector<node::Triple>& in,
                          int removes, std::mt19937& rng) {
  std::vector<node::Triple> out;
  for (int i = 0; i < removes && !held.empty(); ++i) {
    const std::size_t k = rng() % held.size();
    out.push_back(held[k]);
    held.erase(held.begin() + static_cast<long>(k));
  }
  held.insert(held.end(), in.begin(), in.end());
  incremental.apply(in, out, 0);
}

inline std::set<std::string> as_strings(const std::vector<Atom>& atoms) {
  std::set<std::string> out;
  for (const Atom& a : atoms) out.insert(a.to_string());
  return out;
}

// The conclusions `incremental` holds are those a fresh engine draws from `held`.
inline void expect_as_from_scratch(const std::shared_ptr<const Program>& program, const Engine& incremental,
                                   const std::vector<node::Triple>& held, int round) {
  Engine scratch(program);
  scratch.apply(held, {}, 0);
  EXPECT_EQ(as_strings(incremental.conclusions()), as_strings(scratch.conclusions())) << "round " << round;
}

}  // namespace tahvel::reasoner::differential
