// Private: "a shape lies inside an area" (geometry.h lies_in, docs/spatial.md S14), decided
// exactly. Kept in its own translation unit: it needs CGAL's exact-construction kernel and
// Boolean set operations, which are slow to compile and must not reach geometry.cpp/plan.cpp.
#pragma once

#include <memory>

#include "prepared.h"

namespace tahvel::spatial::detail {

// Exact (CGAL Boolean set operations on the exact kernel), for the checks of a polygon's holes
// (geometry.cpp), where sums of rounded areas and vertex tests went wrong: overlapping holes,
// coordinates near 1e-200, a hole in a concave ring's notch whose vertices lie on the ring.
// Both rings simple. True when the closed region of `hole` lies in that of `outer`.
bool ring_within(const Ring& outer, const Ring& hole);
// True when `polygon`'s outer ring minus its holes (overlapping or not) leaves no area.
bool holes_cover_all(const Polygon& polygon);

// An area prepared for many "does this shape lie in it" questions. The exact region (CGAL
// Polygon_set_2 on the exact kernel) is built on the first question that needs it, so a query
// whose candidates are all rejected by the cheap tests never builds it.
class AreaRegion {
 public:
  AreaRegion(const Shape& area, const PreparedShape& prepared);
  ~AreaRegion();
  AreaRegion(const AreaRegion&) = delete;
  AreaRegion& operator=(const AreaRegion&) = delete;

  // True when the closed region of `inner` is a subset of the area's closed region.
  // `inner_prepared` is prepare(inner). With `use_boxes` false the box test is skipped (the
  // brute-force baseline); the answer is the same.
  bool holds(const Shape& inner, const PreparedShape& inner_prepared, bool use_boxes = true);

 private:
  struct Impl;
  const Shape& area_;
  const PreparedShape& prepared_;
  std::unique_ptr<Impl> impl_;
};

}  // namespace tahvel::spatial::detail
