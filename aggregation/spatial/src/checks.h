// Private: the validity rules of geometry.h for one ring and one hole, shared by the WKT parser
// (which names the column) and validate() (which names the polygon and ring). No CGAL here so
// that the parser compiles fast; geometry.cpp implements them with CGAL.
#pragma once

#include <optional>
#include <string>

#include "tahvel/spatial/geometry.h"

namespace tahvel::spatial::detail {

// What is wrong with a ring, and at which vertex (0-based index into the ring) to point.
struct RingProblem {
  std::string message;
  std::size_t vertex = 0;
};

// Why `ring` (closing vertex already dropped) is not a valid ring, or nullopt. For a ring that
// is not simple, `vertex` starts the later of the first two edges found to meet.
std::optional<RingProblem> ring_problem(const Ring& ring);

// Why `hole` cannot be a hole of a polygon with outer ring `outer` (both valid rings), or
// nullopt. `vertex`: the hole's vertex that lies outside the outer ring, when that is why (0
// otherwise, as for ring_problem: the ring as a whole).
std::optional<RingProblem> hole_problem(const Ring& outer, const Ring& hole);

// Why `polygon` (valid rings, valid holes) encloses no area: its holes cover all of it.
std::optional<std::string> area_problem(const Polygon& polygon);

// The shortest decimal that reads back to `v` ("1.5", "1e-07"); wkt.cpp.
std::string format_number(double v);

}  // namespace tahvel::spatial::detail
