// The example rule files of agents/reasoner/rules/, compiled into the library so that the
// benchmark and tools run exactly the rules the tests check: "robot" (Paper 2 §7), "spo2"
// (Paper 5 §5.1) and "heart_rate" (heart rate in context, Paper 5 §5.1 in words).
#pragma once

#include <string_view>

namespace tahvel::reasoner {

// The text of rules/NAME.rules; empty for an unknown name. Static storage.
std::string_view shipped_rules(std::string_view name);

}  // namespace tahvel::reasoner
