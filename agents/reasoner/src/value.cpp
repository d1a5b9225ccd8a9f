// Values of the built-ins (value.h): parsing of numeric and dateTime literals, arithmetic and
// comparison. Times are ns since the Unix epoch (int64, ±292 years); no leap seconds.
#include "value.h"

#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <string>
#include <string_view>

namespace tahvel::reasoner {

namespace {

constexpr std::string_view kXsd = "http://www.w3.org/2001/XMLSchema#";

struct IntegerType {
  std::string_view local;
  std::int64_t min, max;  // the type's range, cut to 64 bits (unsignedLong reads up to 2^63 - 1)
};

constexpr std::int64_t kMin64 = std::numeric_limits<std::int64_t>::min();
constexpr std::int64_t kMax64 = std::numeric_limits<std::int64_t>::max();
constexpr IntegerType kIntegerTypes[] = {
    {"integer", kMin64, kMax64},         {"long", kMin64, kMax64},
    {"int", -2147483648LL, 2147483647},  {"short", -32768, 32767},
    {"byte", -128, 127},                 {"nonNegativeInteger", 0, kMax64},
    {"positiveInteger", 1, kMax64},      {"negativeInteger", kMin64, -1},
    {"nonPositiveInteger", kMin64, 0},   {"unsignedLong", 0, kMax64},
    {"unsignedInt", 0, 4294967295LL},    {"unsignedShort", 0, 65535},
    {"unsignedByte", 0, 255}};

const IntegerType* integer_type(std::string_view local) {
  for (const IntegerType& t : kIntegerTypes)
    if (t.local == local) return &t;
  return nullptr;
}

bool is_integer_type(std::string_view local) { return integer_type(local) != nullptr; }

// XSD's decimal lexical form: an optional sign, digits with at most one '.', at least one digit
// (no exponent, no INF or NaN, which from_chars would read).
bool is_decimal_lexical(std::string_view lex) {
  if (!lex.empty() && (lex[0] == '+' || lex[0] == '-')) lex.remove_prefix(1);
  bool digit = false, point = false;
  for (char c : lex) {
    if (c >= '0' && c <= '9') digit = true;
    else if (c == '.' && !point) point = true;
    else return false;
  }
  return digit;
}

// A decimal's exact parts (Value::split), for one whose integer part fits an int64. `lex` is
// a decimal's lexical form without a leading '+'.
void split_decimal(std::string_view lex, Value& v) {
  const bool negative = !lex.empty() && lex[0] == '-';
  if (negative) lex.remove_prefix(1);
  const std::size_t point = lex.find('.');
  const std::string_view whole = lex.substr(0, point);
  std::uint64_t magnitude = 0;
  if (!whole.empty()) {
    auto [end, ec] = std::from_chars(whole.data(), whole.data() + whole.size(), magnitude);
    if (ec != std::errc() || end != whole.data() + whole.size() || magnitude > 9223372036854775807ull) return;
  }
  double rest = 0;
  if (point != std::string_view::npos && point + 1 < lex.size()) {
    const std::string fraction = "0" + std::string(lex.substr(point));
    std::from_chars(fraction.data(), fraction.data() + fraction.size(), rest);
  }
  v.i = negative ? -static_cast<std::int64_t>(magnitude) : static_cast<std::int64_t>(magnitude);
  v.frac = negative ? -rest : rest;
  v.split = true;
}

// XSD's double and float lexical form: a decimal with an optional exponent (the special values
// are read apart). from_chars also reads "nan", "inf" and "infinity" in any case.
bool is_double_lexical(std::string_view lex) {
  const std::size_t e = lex.find_first_of("eE");
  if (e == std::string_view::npos) return is_decimal_lexical(lex);
  std::string_view exponent = lex.substr(e + 1);
  if (!exponent.empty() && (exponent[0] == '+' || exponent[0] == '-')) exponent.remove_prefix(1);
  return is_decimal_lexical(lex.substr(0, e)) && !exponent.empty() &&
         exponent.find_first_not_of("0123456789") == std::string_view::npos;
}

// Days from 1970-01-01 to y-m-d (proleptic Gregorian; H. Hinnant's algorithm).
std::int64_t days_from_civil(std::int64_t y, unsigned m, unsigned d) {
  y -= m <= 2;
  const std::int64_t era = (y >= 0 ? y : y - 399) / 400;
  const unsigned yoe = static_cast<unsigned>(y - era * 400);
  const unsigned doy = (153 * (m + (m > 2 ? -3 : 9)) + 2) / 5 + d - 1;
  const unsigned doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
  return era * 146097 + static_cast<std::int64_t>(doe) - 719468;
}

bool digits(std::string_view s, std::size_t at, std::size_t n, int& out) {
  if (at + n > s.size()) return false;
  out = 0;
  for (std::size_t k = at; k < at + n; ++k) {
    if (s[k] < '0' || s[k] > '9') return false;
    out = out * 10 + (s[k] - '0');
  }
  return true;
}

// nullopt when `s` is not an xsd:dateTime the built-ins read; *beyond then says whether it is
// a well-formed one outside 1677-09-21..2262-04-11.
std::optional<std::int64_t> parse_datetime(std::string_view s, bool* beyond = nullptr) {
  int y, mo, d, h, mi, se;
  if (!digits(s, 0, 4, y) || s.size() < 19 || s[4] != '-' || !digits(s, 5, 2, mo) || s[7] != '-' ||
      !digits(s, 8, 2, d) || s[10] != 'T' || !digits(s, 11, 2, h) || s[13] != ':' ||
      !digits(s, 14, 2, mi) || s[16] != ':' || !digits(s, 17, 2, se))
    return std::nullopt;
  // XSD's dateTime: a day of its month (29 February in leap years only), seconds below 60, and
  // 24:00:00 only, the end of the day. "2026-02-30" was read as 2 March.
  static constexpr int kDays[] = {31, 28, 31, 30, 31, 30, 31, 31, 30, 31, 30, 31};
  const bool leap = (y % 4 == 0 && y % 100 != 0) || y % 400 == 0;
  if (mo < 1 || mo > 12 || d < 1 || d > kDays[mo - 1] + (mo == 2 && leap) || h > 24 || mi > 59 || se > 59 ||
      (h == 24 && (mi != 0 || se != 0)))
    return std::nullopt;
  std::size_t k = 19;
  std::int64_t frac = 0;
  if (k < s.size() && s[k] == '.') {
    std::int64_t scale = 100000000;
    for (++k; k < s.size() && s[k] >= '0' && s[k] <= '9'; ++k) {
      frac += (s[k] - '0') * scale;
      scale /= 10;
    }
  }
  if (h == 24 && frac != 0) return std::nullopt;
  std::int64_t offset = 0;
  if (k < s.size()) {
    if (s[k] == 'Z') {
      ++k;
    } else if (s[k] == '+' || s[k] == '-') {
      int oh, om;
      if (!digits(s, k + 1, 2, oh) || s.size() < k + 6 || s[k + 3] != ':' || !digits(s, k + 4, 2, om)) return std::nullopt;
      if (om > 59 || oh > 14 || (oh == 14 && om != 0)) return std::nullopt;  // XSD: -14:00 to +14:00
      offset = (oh * 3600 + om * 60) * (s[k] == '-' ? -1 : 1);
      k += 6;
    }
  }
  if (k != s.size()) return std::nullopt;
  std::int64_t secs = days_from_civil(y, static_cast<unsigned>(mo), static_cast<unsigned>(d)) * 86400 +
                      h * 3600 + mi * 60 + se - offset;
  // Outside 1677-09-21..2262-04-11 the ns do not fit: not a time (rather than a wrapped one).
  std::int64_t ns;
  if (__builtin_mul_overflow(secs, std::int64_t{1000000000}, &ns) || __builtin_add_overflow(ns, frac, &ns)) {
    if (beyond) *beyond = true;
    return std::nullopt;
  }
  return ns;
}

Value time(std::int64_t ns) { return {Value::time, ns, 0}; }
double as_double(const Value& v) { return v.kind == Value::integer ? static_cast<double>(v.i) : v.d; }
bool is_number(const Value& v) { return v.kind == Value::integer || v.kind == Value::real; }

// Seconds to ns; nullopt when they do not fit in an int64 (±292 years).
std::optional<std::int64_t> ns_of(const Value& seconds) {
  std::int64_t ns;
  if (seconds.kind == Value::integer)
    return __builtin_mul_overflow(seconds.i, std::int64_t{1000000000}, &ns) ? std::nullopt : std::optional(ns);
  const double x = seconds.d * 1e9;
  if (!(x > -9.2e18 && x < 9.2e18)) return std::nullopt;  // llround is unspecified beyond
  return static_cast<std::int64_t>(std::llround(x));
}

// time ± seconds; none when the result leaves the range of times.
Value shifted(std::int64_t ns, const Value& seconds, bool add) {
  auto by = ns_of(seconds);
  std::int64_t out;
  if (!by || (add ? __builtin_add_overflow(ns, *by, &out) : __builtin_sub_overflow(ns, *by, &out))) return {};
  return time(out);
}

Value numeric(ArithOp op, const Value& a, const Value& b) {
  if (a.kind == Value::integer && b.kind == Value::integer) return integer_arith(op, a.i, b.i);
  double x = as_double(a), y = as_double(b);
  switch (op) {
    case ArithOp::add: return real(x + y);
    case ArithOp::sub: return real(x - y);
    case ArithOp::mul: return real(x * y);
    case ArithOp::div: return y == 0 ? Value{} : real(x / y);
    default: return {};
  }
}

}  // namespace

Value value_of(const node::Term& term) {
  if (!term.is_literal() || term.datatype.size() <= kXsd.size() ||
      std::string_view(term.datatype).substr(0, kXsd.size()) != kXsd)
    return {};
  std::string_view local = std::string_view(term.datatype).substr(kXsd.size());
  std::string_view lex = term.value;
  if (const IntegerType* type = integer_type(local)) {
    if (!lex.empty() && lex[0] == '+') lex.remove_prefix(1);
    std::int64_t i = 0;
    auto [end, ec] = std::from_chars(lex.data(), lex.data() + lex.size(), i);
    if (ec != std::errc() || end != lex.data() + lex.size()) return {};
    if (i < type->min || i > type->max) return {};  // "300"^^xsd:byte is no byte
    return integer(i);
  }
  if (local == "decimal" || local == "double" || local == "float") {
    // xsd:double's infinities compare with every number; arithmetic on them gives none (real()).
    const bool decimal = local == "decimal";
    if (!decimal && (lex == "INF" || lex == "+INF")) return Value{Value::real, 0, INFINITY};
    if (!decimal && lex == "-INF") return Value{Value::real, 0, -INFINITY};
    if (decimal ? !is_decimal_lexical(lex) : !is_double_lexical(lex)) return {};
    if (!lex.empty() && lex[0] == '+') lex.remove_prefix(1);
    double d = 0;
    auto [end, ec] = std::from_chars(lex.data(), lex.data() + lex.size(), d);
    if (ec == std::errc::result_out_of_range && end == lex.data() + lex.size()) {
      // XSD 1.1 rounds to the nearest double: beyond its range an infinity, below it zero or a
      // subnormal. 1e400 compared with nothing ("V < 1e400" never held, without a word).
      const std::string text(lex);
      d = std::strtod(text.c_str(), nullptr);
      if (std::isinf(d)) return Value{Value::real, 0, d};
      return real(d);
    }
    if (ec != std::errc() || end != lex.data() + lex.size()) return {};
    Value v = real(d);
    if (decimal) split_decimal(lex, v);
    return v;
  }
  if (local == "dateTime" || local == "dateTimeStamp") {
    auto ns = parse_datetime(lex);
    if (!ns) return {};
    return {Value::time, *ns, 0};
  }
  return {};
}

bool datetime_beyond_range(std::string_view lex) {
  bool beyond = false;
  return !parse_datetime(lex, &beyond) && beyond;
}

std::string valued_type_name(const node::Term& term) {
  if (!term.is_literal() || term.datatype.size() <= kXsd.size() ||
      std::string_view(term.datatype).substr(0, kXsd.size()) != kXsd)
    return {};
  std::string_view local = std::string_view(term.datatype).substr(kXsd.size());
  if (is_integer_type(local) || local == "decimal" || local == "double" || local == "float" ||
      local == "dateTime" || local == "dateTimeStamp")
    return "xsd:" + std::string(local);
  return {};
}

Value arith(ArithOp op, const Value& a, const Value& b) {
  if (op == ArithOp::neg) {
    if (a.kind == Value::integer) return integer_arith(ArithOp::neg, a.i, 0);
    if (a.kind == Value::real) return real(-a.d);
    return {};
  }
  if (is_number(a) && is_number(b)) return numeric(op, a, b);
  if (a.kind == Value::time && is_number(b) && (op == ArithOp::add || op == ArithOp::sub))
    return shifted(a.i, b, op == ArithOp::add);
  if (is_number(a) && b.kind == Value::time && op == ArithOp::add) return shifted(b.i, a, true);
  // Seconds since the epoch minus a time: the number is an instant, as in a comparison (RS5),
  // so that sensors writing epoch seconds and others writing dateTimes can be subtracted.
  if (is_number(a) && b.kind == Value::time && op == ArithOp::sub) {
    auto ns = ns_of(a);
    return ns ? arith(op, time(*ns), b) : Value{};
  }
  if (a.kind == Value::time && b.kind == Value::time && op == ArithOp::sub) {
    std::int64_t ns;
    if (__builtin_sub_overflow(a.i, b.i, &ns)) return {};
    return ns % 1000000000 == 0 ? integer(ns / 1000000000) : real(static_cast<double>(ns) / 1e9);
  }
  return {};
}

namespace {

// An integer against a double, exactly: converted to a double, an integer above 2^53 rounds,
// and 9007199254740993 > 9007199254740992.0 did not hold.
int compare_integer_double(std::int64_t i, double d) {
  if (std::isnan(d)) return 0;  // not read as a number (value.h); kept as the double compare had it
  if (d >= 9223372036854775808.0) return -1;   // 2^63: above every int64
  if (d < -9223372036854775808.0) return 1;    // below -2^63
  const double whole = std::trunc(d);
  const auto w = static_cast<std::int64_t>(whole);  // in range: -2^63 <= whole < 2^63
  if (i != w) return i < w ? -1 : 1;
  const double frac = d - whole;  // exact: d and whole are close doubles
  return frac > 0 ? -1 : (frac < 0 ? 1 : 0);
}

// A decimal held exactly (Value::split) against a double, as compare_integer_double does.
int compare_split_double(const Value& s, double d) {
  if (std::isnan(d)) return 0;
  if (d >= 9223372036854775808.0) return -1;
  if (d < -9223372036854775808.0) return 1;
  const double whole = std::trunc(d);
  const auto w = static_cast<std::int64_t>(whole);
  if (s.i != w) return s.i < w ? -1 : 1;
  const double frac = d - whole;
  return s.frac < frac ? -1 : (frac < s.frac ? 1 : 0);
}

}  // namespace

std::optional<int> compare_values(const Value& a, const Value& b) {
  auto sign = [](auto x, auto y) { return x < y ? -1 : (y < x ? 1 : 0); };
  if (a.kind == Value::integer && b.kind == Value::integer) return sign(a.i, b.i);
  // Decimals exactly, by their integer parts first (an integer's rest is 0); against a double,
  // by its integer part too, or =:= was not transitive: 9007199254740993.0 above the integer
  // 9007199254740992 and equal to the double 9007199254740992.0, which equals that integer.
  if ((a.split || a.kind == Value::integer) && (b.split || b.kind == Value::integer) && (a.split || b.split)) {
    if (a.i != b.i) return sign(a.i, b.i);
    return sign(a.split ? a.frac : 0.0, b.split ? b.frac : 0.0);
  }
  if (a.split && b.kind == Value::real && !b.split) return compare_split_double(a, b.d);
  if (b.split && a.kind == Value::real && !a.split) return -compare_split_double(b, a.d);
  if (a.kind == Value::integer && b.kind == Value::real) return compare_integer_double(a.i, b.d);
  if (a.kind == Value::real && b.kind == Value::integer) return -compare_integer_double(b.i, a.d);
  if (is_number(a) && is_number(b)) return sign(as_double(a), as_double(b));
  if (a.kind == Value::time && b.kind == Value::time) return sign(a.i, b.i);
  if (a.kind == Value::time && is_number(b)) return sign(static_cast<double>(a.i) / 1e9, as_double(b));
  if (is_number(a) && b.kind == Value::time) return sign(as_double(a), static_cast<double>(b.i) / 1e9);
  return std::nullopt;
}

std::string format_time(std::int64_t ns) {
  std::int64_t secs = ns / 1000000000, frac = ns % 1000000000;
  if (frac < 0) { frac += 1000000000; --secs; }
  std::int64_t days = secs / 86400, rem = secs % 86400;
  if (rem < 0) { rem += 86400; --days; }
  // civil_from_days (H. Hinnant)
  days += 719468;
  const std::int64_t era = (days >= 0 ? days : days - 146096) / 146097;
  const unsigned doe = static_cast<unsigned>(days - era * 146097);
  const unsigned yoe = (doe - doe / 1460 + doe / 36524 - doe / 146096) / 365;
  const unsigned doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
  const unsigned mp = (5 * doy + 2) / 153;
  const unsigned d = doy - (153 * mp + 2) / 5 + 1;
  const unsigned m = mp < 10 ? mp + 3 : mp - 9;
  const std::int64_t y = static_cast<std::int64_t>(yoe) + era * 400 + (m <= 2);
  char buf[64];
  int n = std::snprintf(buf, sizeof buf, "%04lld-%02u-%02uT%02lld:%02lld:%02lld", static_cast<long long>(y), m, d,
                        static_cast<long long>(rem / 3600), static_cast<long long>(rem / 60 % 60),
                        static_cast<long long>(rem % 60));
  std::string out(buf, static_cast<std::size_t>(n));
  if (frac) {
    char f[16];
    std::snprintf(f, sizeof f, ".%09lld", static_cast<long long>(frac));
    std::string fs(f);
    while (fs.back() == '0') fs.pop_back();
    out += fs;
  }
  return out + "Z";
}

node::Term term_of(const Value& v) {
  switch (v.kind) {
    case Value::integer: return node::Term::integer(v.i);
    case Value::real: {
      char buf[32];
      auto [end, ec] = std::to_chars(buf, buf + sizeof buf, v.d);
      std::string lex(buf, end);
      if (lex.find_first_of(".eEn") == std::string::npos) lex += ".0";
      return node::Term::literal(lex, std::string(node::xsd::kDouble));
    }
    case Value::time: return node::Term::literal(format_time(v.i), std::string(node::xsd::kDateTime));
    default: return node::Term::literal("");
  }
}

}  // namespace tahvel::reasoner
