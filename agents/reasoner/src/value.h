// Numbers and times of the built-ins: literals to values, arithmetic, comparison, values back
// to literals. Private to the reasoner.
#pragma once

#include <cmath>
#include <cstdint>
#include <optional>

#include "tahvel/node/term.h"

namespace tahvel::reasoner {

struct Value {
  enum Kind : std::uint8_t { none, integer, real, time } kind = none;
  // A real read from an xsd:decimal whose integer part fits an int64 is also held exactly, for
  // comparisons: `i` is that part (truncated toward zero) and `frac` the rest, of the same sign.
  // A double rounds past 2^53, and 9007199254740993.0 equalled the integer 9007199254740992.
  std::int64_t i = 0;  // integer; time: ns since the Unix epoch; real: its integer part if split
  double d = 0;        // real
  double frac = 0;     // real, if split: what follows the integer part
  bool split = false;
};

// The value of a literal: xsd integer types, xsd:decimal/double/float, xsd:dateTime(Stamp)
// (no offset: UTC). Anything else: none.
Value value_of(const node::Term& term);

// For a literal whose datatype value_of reads: that datatype as "xsd:<local name>". Empty for
// any other term. A rule's constant of such a type without a value ("12x"^^xsd:integer) would
// compare with nothing, so the rule reader refuses it.
std::string valued_type_name(const node::Term& term);

// True for a well-formed xsd:dateTime outside the times value_of reads (ns since the epoch in
// 64 bits: 1677-09-21 to 2262-04-11), such as a "valid forever" 9999-12-31.
bool datetime_beyond_range(std::string_view lex);

// Arithmetic: + - * / on numbers (integers stay integers unless / leaves a remainder), time ±
// seconds, time - time (seconds). none when undefined: a type mismatch, division by zero, an
// integer result outside int64, a time outside 1677-09-21..2262-04-11.
enum class ArithOp { add, sub, mul, div, neg };
Value arith(ArithOp op, const Value& a, const Value& b);

inline Value integer(std::int64_t i) { return {Value::integer, i, 0}; }
inline Value real(double d) { return std::isfinite(d) ? Value{Value::real, 0, d} : Value{}; }

// arith on two integers (neg: of a). Inline: the evaluator's common case.
inline Value integer_arith(ArithOp op, std::int64_t a, std::int64_t b) {
  std::int64_t out;
  switch (op) {
    case ArithOp::add: return __builtin_add_overflow(a, b, &out) ? Value{} : integer(out);
    case ArithOp::sub: return __builtin_sub_overflow(a, b, &out) ? Value{} : integer(out);
    case ArithOp::mul: return __builtin_mul_overflow(a, b, &out) ? Value{} : integer(out);
    case ArithOp::div:
      if (b == 0) return {};
      if (b == -1) return __builtin_sub_overflow(std::int64_t{0}, a, &out) ? Value{} : integer(out);
      return a % b == 0 ? integer(a / b) : real(static_cast<double>(a) / static_cast<double>(b));
    case ArithOp::neg: return __builtin_sub_overflow(std::int64_t{0}, a, &out) ? Value{} : integer(out);
  }
  return {};
}

// Comparison of two numbers, two times, or a time and a number of seconds since the epoch.
// nullopt when the values are not comparable. Result: -1, 0, 1.
std::optional<int> compare_values(const Value& a, const Value& b);

// The literal of a value: xsd:integer, xsd:double (shortest form), xsd:dateTime (UTC, ns).
node::Term term_of(const Value& v);

// ns since the epoch as an xsd:dateTime lexical form ("2026-01-01T10:00:00Z").
std::string format_time(std::int64_t ns);

}  // namespace tahvel::reasoner
