// Numbers and times of the built-ins: literals to values, arithmetic, comparison, values back
// to literals. Private to the reasoner.
#pragma once

#include <cstdint>
#include <optional>

#include "tahvel/node/term.h"

namespace tahvel::reasoner {

struct Value {
  enum Kind : std::uint8_t { none, integer, real, time } kind = none;
  std::int64_t i = 0;  // integer; time: ns since the Unix epoch
  double d = 0;        // real
};

// The value of a literal: xsd integer types, xsd:decimal/double/float, xsd:dateTime(Stamp)
// (no offset: UTC). Anything else: none.
Value value_of(const node::Term& term);

// Arithmetic: + - * / on numbers (integers stay integers unless / leaves a remainder), time ±
// seconds, time - time (seconds). none when undefined (a type mismatch, division by zero).
enum class ArithOp { add, sub, mul, div, neg };
Value arith(ArithOp op, const Value& a, const Value& b);

// Comparison of two numbers, two times, or a time and a number of seconds since the epoch.
// nullopt when the values are not comparable. Result: -1, 0, 1.
std::optional<int> compare_values(const Value& a, const Value& b);

// The literal of a value: xsd:integer, xsd:double (shortest form), xsd:dateTime (UTC, ns).
node::Term term_of(const Value& v);

// ns since the epoch as an xsd:dateTime lexical form ("2026-01-01T10:00:00Z").
std::string format_time(std::int64_t ns);

}  // namespace tahvel::reasoner
