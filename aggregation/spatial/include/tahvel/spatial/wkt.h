// Well-Known Text (OGC Simple Features) for the geometries of a floor plan, as they appear in
// GeoSPARQL geo:wktLiteral values: POINT, POLYGON and MULTIPOLYGON (holes allowed).
//
//   auto g = parse_wkt("POLYGON((0 0, 6 0, 6 4, 0 4, 0 0), (2 1, 3 1, 3 2, 2 2, 2 1))");
//   if (!g) std::cerr << g.error().message;   // "WKT column 12: expected a number, found ','"
//
// Accepted: keywords in any case; spaces, tabs and newlines between tokens; numbers in decimal
// or exponent form ("-1.5", "2e3"), read to the nearest double; an optional leading CRS IRI
// ("<http://www.opengis.net/def/crs/OGC/1.3/CRS84> POINT(1 2)", GeoSPARQL's form), which is
// skipped: Tahvel treats every plan as planar in its own frame.
// Refused, each with an error naming the 1-based column: other geometry types, EMPTY, a Z or M
// coordinate ("POINT Z", or a third number: floors are tv:floor, not a coordinate), NaN or
// infinite numbers, a ring that is not closed (first point != last), has fewer than 3 distinct
// vertices, is not simple or encloses no area, a hole with a vertex outside its outer ring
// (or an outer vertex inside it, or an edge crossing it), holes covering the whole polygon, and
// anything after the geometry. A vertex repeated at once is kept once.
// Not checked: holes overlapping each other, polygons of a multipolygon overlapping (the
// area is then still well defined: the union of the polygons, each minus its open holes).
#pragma once

#include <string>
#include <string_view>
#include <variant>

#include "tahvel/spatial/error.h"
#include "tahvel/spatial/geometry.h"

namespace tahvel::spatial {

// A parsed geometry: a POINT, or a POLYGON/MULTIPOLYGON as a Shape (valid: geometry.h).
using Geometry = std::variant<Point, Shape>;

Result<Geometry> parse_wkt(std::string_view text);

// The CRS IRI written before the geometry (without its <>), or empty when none is. The CRS is
// not applied (a plan is planar in its own frame); `tahvel put` warns of one other than CRS84.
std::string_view wkt_crs(std::string_view text);

// The CRS IRI that says what Tahvel assumes of every plan anyway: no CRS at all.
inline constexpr std::string_view kCrs84 = "http://www.opengis.net/def/crs/OGC/1.3/CRS84";

// parse_wkt, then refuse the other kind ("WKT column 1: expected a POINT, found POLYGON").
Result<Point> parse_point(std::string_view text);
Result<Shape> parse_shape(std::string_view text);

// WKT with the shortest decimals that read back to the same doubles: POINT(x y);
// POLYGON((...)) for one polygon, MULTIPOLYGON(((...)),((...))) for several. Rings are closed
// (the first vertex repeated). parse_wkt(to_wkt(g)) == g for valid geometries.
std::string to_wkt(Point p);
std::string to_wkt(const Shape& shape);

}  // namespace tahvel::spatial
