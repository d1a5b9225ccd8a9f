// A recursive-descent reader for the WKT subset of wkt.h, and the writer. Tuned for short
// literals (a room has tens of vertices); errors name the 1-based byte column.
#include "tahvel/spatial/wkt.h"

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <optional>
#include <string>

#include "checks.h"

namespace tahvel::spatial {

namespace detail {

std::string format_number(double v) {
  char buffer[32];
  auto [end, ec] = std::to_chars(buffer, buffer + sizeof buffer, v);
  return ec == std::errc() ? std::string(buffer, end) : std::string("?");
}

}  // namespace detail

namespace {

bool is_space(char c) { return c == ' ' || c == '\t' || c == '\n' || c == '\r'; }
bool is_alpha(char c) { return std::isalpha(static_cast<unsigned char>(c)) != 0; }
bool is_digit(char c) { return c >= '0' && c <= '9'; }

// The value of a number whose magnitude is below the doubles' range (strtod gives zero or a
// subnormal, with ERANGE), or nullopt for one above it.
std::optional<double> underflowed(std::string_view number) {
  const std::string text(number);
  errno = 0;
  const double value = std::strtod(text.c_str(), nullptr);
  if (errno == ERANGE && std::abs(value) < std::numeric_limits<double>::min()) return value;
  return std::nullopt;
}

constexpr double kMaxCoordinate = 1e15;

class Parser {
 public:
  explicit Parser(std::string_view text) : text_(text) {}

  Result<Geometry> parse() {
    skip_space();
    if (text_.substr(pos_, 5) == "SRID=" || text_.substr(pos_, 5) == "srid=")
      return error(pos_, "EWKT's 'SRID=...;' is not WKT: give the CRS as an IRI before the geometry (<http://www.opengis.net/def/crs/...>)");
    if (auto crs = skip_crs(); !crs) return unexpected(crs.error());
    std::size_t at = pos_;
    auto word = keyword();
    if (!word) return unexpected(word.error());
    // "POLYGONZ" and the like: a known type with its dimension written against it.
    for (const char* type : {"POINT", "POLYGON", "MULTIPOLYGON"}) {
      const std::string_view stem(type);
      const std::string_view rest = std::string_view(*word).substr(std::min(word->size(), stem.size()));
      if (word->starts_with(stem) && (rest == "Z" || rest == "M" || rest == "ZM"))
        return error(at + stem.size(), "Z and M coordinates are not supported (the floor is tv:floor)");
    }
    Result<Geometry> geometry = fail("");
    if (*word == "POINT") {
      geometry = point_text();
    } else if (*word == "POLYGON") {
      geometry = polygon_shape();
    } else if (*word == "MULTIPOLYGON") {
      geometry = multipolygon_shape();
    } else {
      return error(at, "unsupported geometry type '" + *word +
                           "' (POINT, POLYGON or MULTIPOLYGON)");
    }
    if (!geometry) return geometry;
    skip_space();
    if (pos_ < text_.size()) return error(pos_, "unexpected " + found() + " after the geometry");
    return geometry;
  }

 private:
  Unexpected<Error> error(std::size_t at, const std::string& message) const {
    return fail("WKT column " + std::to_string(at + 1) + ": " + message, at + 1);
  }

  // What stands at the current position, for messages.
  std::string found() const {
    if (pos_ >= text_.size()) return "end of text";
    if (is_alpha(text_[pos_])) {
      std::size_t end = pos_;
      while (end < text_.size() && is_alpha(text_[end])) ++end;
      return "'" + std::string(text_.substr(pos_, end - pos_)) + "'";
    }
    // A number whole ("42" where a geometry type belongs was "found '4'").
    if (std::isdigit(static_cast<unsigned char>(text_[pos_]))) {
      std::size_t end = pos_;
      while (end < text_.size() && (std::isalnum(static_cast<unsigned char>(text_[end])) || text_[end] == '.')) ++end;
      return "'" + std::string(text_.substr(pos_, end - pos_)) + "'";
    }
    // A whole UTF-8 character (a Unicode minus, a non-breaking space), not its first byte.
    std::size_t end = pos_ + 1;
    while (end < text_.size() && (static_cast<unsigned char>(text_[end]) & 0xC0) == 0x80) ++end;
    if (static_cast<unsigned char>(text_[pos_]) < 0x80) end = pos_ + 1;
    return "'" + std::string(text_.substr(pos_, end - pos_)) + "'";
  }

  void skip_space() {
    while (pos_ < text_.size() && is_space(text_[pos_])) ++pos_;
  }

  // GeoSPARQL: an optional "<crs-iri>" before the geometry.
  Result<void> skip_crs() {
    if (pos_ >= text_.size() || text_[pos_] != '<') return {};
    std::size_t close = text_.find('>', pos_);
    if (close == std::string_view::npos) return error(pos_, "CRS IRI '<' without '>'");
    // "<junk junk> POLYGON(…)": no IRI holds a space, or nothing at all.
    const std::string_view iri = text_.substr(pos_ + 1, close - pos_ - 1);
    if (iri.empty() || std::any_of(iri.begin(), iri.end(), [](char c) { return is_space(c); }))
      return error(pos_, "'<" + std::string(iri) + ">' is not a CRS IRI");
    pos_ = close + 1;
    skip_space();
    return {};
  }

  Result<std::string> keyword() {
    skip_space();
    std::size_t start = pos_;
    while (pos_ < text_.size() && is_alpha(text_[pos_])) ++pos_;
    if (start == pos_) return error(start, "expected a geometry type, found " + found());
    std::string word(text_.substr(start, pos_ - start));
    for (char& c : word) c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
    return word;
  }

  // After a type keyword: "EMPTY" and Z/M dimensions are refused, then '(' must follow.
  Result<void> open_geometry() {
    skip_space();
    if (pos_ < text_.size() && is_alpha(text_[pos_])) {
      std::size_t at = pos_;
      auto word = keyword();
      if (!word) return unexpected(word.error());
      if (*word == "EMPTY") return error(at, "EMPTY geometries are not supported");
      if (*word == "Z" || *word == "M" || *word == "ZM") {
        return error(at, "Z and M coordinates are not supported (the floor is tv:floor)");
      }
      return error(at, "expected '(', found '" + *word + "'");
    }
    return expect('(');
  }

  Result<void> expect(char c) {
    skip_space();
    if (pos_ >= text_.size() || text_[pos_] != c) {
      return error(pos_, std::string("expected '") + c + "', found " + found());
    }
    ++pos_;
    return {};
  }

  // True (and consumed) when the next token is `c`.
  bool accept(char c) {
    skip_space();
    if (pos_ < text_.size() && text_[pos_] == c) {
      ++pos_;
      return true;
    }
    return false;
  }

  Result<double> number() {
    skip_space();
    std::size_t start = pos_, i = pos_;
    if (i < text_.size() && (text_[i] == '-' || text_[i] == '+')) ++i;
    std::size_t digits_from = i;
    while (i < text_.size() && is_digit(text_[i])) ++i;
    std::size_t digits = i - digits_from;
    if (i < text_.size() && text_[i] == '.') {
      ++i;
      std::size_t fraction_from = i;
      while (i < text_.size() && is_digit(text_[i])) ++i;
      digits += i - fraction_from;
    }
    if (digits == 0) return error(start, "expected a number, found " + found());
    if (i < text_.size() && (text_[i] == 'e' || text_[i] == 'E')) {
      std::size_t e = i + 1;
      if (e < text_.size() && (text_[e] == '-' || text_[e] == '+')) ++e;
      std::size_t exponent_from = e;
      while (e < text_.size() && is_digit(text_[e])) ++e;
      if (e == exponent_from) return error(i, "exponent without digits");
      i = e;
    }
    std::size_t from = text_[start] == '+' ? start + 1 : start;  // from_chars refuses '+'
    // A number ends at white space, ',' or ')': "1.5.5" or "4-0" is a typo, not two numbers.
    if (i < text_.size() && !is_space(text_[i]) && text_[i] != ',' && text_[i] != ')') {
      std::size_t end = i;
      while (end < text_.size() && !is_space(text_[end]) && text_[end] != ',' && text_[end] != ')') ++end;
      return error(start, "malformed number '" + std::string(text_.substr(start, end - start)) + "'");
    }
    double value = 0;
    auto [end, ec] = std::from_chars(text_.data() + from, text_.data() + i, value);
    // Below the least subnormal (1e-330) from_chars says out of range; the nearest double
    // (S1) is zero, of the number's sign.
    if (ec == std::errc::result_out_of_range && end == text_.data() + i) {
      if (auto tiny = underflowed(text_.substr(start, i - start))) ec = std::errc(), value = *tiny;
    }
    if (ec != std::errc() || end != text_.data() + i || !std::isfinite(value)) {
      return error(start, "number '" + std::string(text_.substr(start, i - start)) +
                              "' is out of range");
    }
    // Beyond this the exact geometry's products overflow a double (and no floor plan, in metres
    // or in degrees, comes near it).
    if (std::abs(value) > kMaxCoordinate) {
      return error(start, "coordinate '" + std::string(text_.substr(start, i - start)) +
                              "' is beyond +/-1e15, the range a floor plan may use");
    }
    pos_ = i;
    return value;
  }

  // "x y": exactly two numbers.
  Result<Point> coordinates() {
    auto x = number();
    if (!x) return unexpected(x.error());
    if (pos_ < text_.size() && !is_space(text_[pos_]))
      return error(pos_, "expected white space and a second coordinate, found " + found());
    auto y = number();
    if (!y) return unexpected(y.error());
    skip_space();
    if (pos_ < text_.size() && (is_digit(text_[pos_]) || text_[pos_] == '-' ||
                                text_[pos_] == '+' || text_[pos_] == '.')) {
      return error(pos_, "a third coordinate is not supported (the floor is tv:floor, not Z)");
    }
    return Point{*x, *y};
  }

  Result<Geometry> point_text() {
    if (auto open = open_geometry(); !open) return unexpected(open.error());
    auto point = coordinates();
    if (!point) return unexpected(point.error());
    if (auto close = expect(')'); !close) return unexpected(close.error());
    return Geometry(*point);
  }

  // "(x y, x y, ...)": closed, then the closing vertex dropped and the ring checked.
  // `columns_out`: where each vertex was read, for errors found once the ring is whole.
  Result<Ring> ring(std::vector<std::size_t>* columns_out = nullptr) {
    skip_space();
    std::size_t at = pos_;
    if (auto open = expect('('); !open) return unexpected(open.error());
    Ring ring;
    std::vector<std::size_t> columns;  // of each vertex, for errors
    std::size_t read = 0;
    do {
      skip_space();
      std::size_t point_at = pos_;
      auto point = coordinates();
      if (!point) return unexpected(point.error());
      ++read;
      // A vertex repeated at once adds nothing (OGC allows it; exporters write it): kept once.
      if (!ring.empty() && ring.back() == *point) continue;
      ring.push_back(*point);
      columns.push_back(point_at);
    } while (accept(','));
    if (auto close = expect(')'); !close) return unexpected(close.error());
    if (read < 4) {
      return error(at, "a ring needs at least 4 points (3 vertices and the closing one), found " +
                           std::to_string(read));
    }
    if (!(ring.front() == ring.back())) {
      return error(at, "ring is not closed (its last point differs from its first)");
    }
    if (ring.size() > 1) ring.pop_back();
    if (auto problem = detail::ring_problem(ring)) {
      return error(problem->vertex == 0 ? at : columns[problem->vertex], problem->message);
    }
    if (columns_out) *columns_out = std::move(columns);
    return ring;
  }

  // "((outer), (hole), ...)".
  Result<Polygon> polygon_text() {
    skip_space();
    const std::size_t polygon_at = pos_;
    if (auto open = expect('('); !open) return unexpected(open.error());
    Polygon polygon;
    auto outer = ring();
    if (!outer) return unexpected(outer.error());
    polygon.outer = std::move(*outer);
    while (accept(',')) {
      skip_space();
      std::size_t at = pos_;
      std::vector<std::size_t> columns;
      auto hole = ring(&columns);
      if (!hole) return unexpected(hole.error());
      if (auto problem = detail::hole_problem(polygon.outer, *hole))
        return error(problem->vertex == 0 || problem->vertex >= columns.size() ? at : columns[problem->vertex], problem->message);
      polygon.holes.push_back(std::move(*hole));
    }
    if (auto close = expect(')'); !close) return unexpected(close.error());
    if (auto problem = detail::area_problem(polygon)) return error(polygon_at, "polygon: " + *problem);
    return polygon;
  }

  Result<Geometry> polygon_shape() {
    if (auto open = open_geometry(); !open) return unexpected(open.error());
    --pos_;  // the '(' opens the polygon text
    auto polygon = polygon_text();
    if (!polygon) return unexpected(polygon.error());
    return Geometry(Shape{{std::move(*polygon)}});
  }

  Result<Geometry> multipolygon_shape() {
    if (auto open = open_geometry(); !open) return unexpected(open.error());
    Shape shape;
    do {
      skip_space();
      auto polygon = polygon_text();
      if (!polygon) return unexpected(polygon.error());
      shape.polygons.push_back(std::move(*polygon));
    } while (accept(','));
    if (auto close = expect(')'); !close) return unexpected(close.error());
    return Geometry(std::move(shape));
  }

  std::string_view text_;
  std::size_t pos_ = 0;
};

void append_ring(std::string& out, const Ring& ring) {
  out += '(';
  for (std::size_t i = 0; i <= ring.size(); ++i) {
    const Point& p = ring[i % ring.size()];  // the first vertex again closes the ring
    if (i != 0) out += ", ";
    out += detail::format_number(p.x) + " " + detail::format_number(p.y);
  }
  out += ')';
}

void append_polygon(std::string& out, const Polygon& polygon) {
  out += '(';
  append_ring(out, polygon.outer);
  for (const Ring& hole : polygon.holes) {
    out += ", ";
    append_ring(out, hole);
  }
  out += ')';
}

// The position of the geometry keyword (after an optional CRS IRI and spaces).
std::size_t keyword_column(std::string_view text) {
  std::size_t i = 0;
  while (i < text.size() && is_space(text[i])) ++i;
  if (i < text.size() && text[i] == '<') {
    std::size_t close = text.find('>', i);
    i = close == std::string_view::npos ? i : close + 1;
    while (i < text.size() && is_space(text[i])) ++i;
  }
  return i + 1;
}

}  // namespace

Result<Geometry> parse_wkt(std::string_view text) { return Parser(text).parse(); }

std::string_view wkt_crs(std::string_view text) {
  std::size_t i = 0;
  while (i < text.size() && is_space(text[i])) ++i;
  if (i >= text.size() || text[i] != '<') return {};
  const std::size_t close = text.find('>', i);
  if (close == std::string_view::npos) return {};
  return text.substr(i + 1, close - i - 1);
}

Result<Point> parse_point(std::string_view text) {
  auto geometry = parse_wkt(text);
  if (!geometry) return unexpected(geometry.error());
  if (const Point* point = std::get_if<Point>(&*geometry)) return *point;
  std::size_t column = keyword_column(text);
  return fail("WKT column " + std::to_string(column) + ": expected a POINT, found a polygon",
              column);
}

Result<Shape> parse_shape(std::string_view text) {
  auto geometry = parse_wkt(text);
  if (!geometry) return unexpected(geometry.error());
  if (Shape* shape = std::get_if<Shape>(&*geometry)) return std::move(*shape);
  std::size_t column = keyword_column(text);
  return fail("WKT column " + std::to_string(column) +
                  ": expected a POLYGON or MULTIPOLYGON, found a POINT",
              column);
}

std::string to_wkt(Point p) {
  return "POINT(" + detail::format_number(p.x) + " " + detail::format_number(p.y) + ")";
}

std::string to_wkt(const Shape& shape) {
  std::string out;
  if (shape.polygons.size() == 1) {
    out = "POLYGON";
    append_polygon(out, shape.polygons[0]);
    return out;
  }
  out = "MULTIPOLYGON(";
  for (std::size_t i = 0; i < shape.polygons.size(); ++i) {
    if (i != 0) out += ", ";
    append_polygon(out, shape.polygons[i]);
  }
  out += ')';
  return out;
}

}  // namespace tahvel::spatial
