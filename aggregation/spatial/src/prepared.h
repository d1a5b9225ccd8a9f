// Private: shapes prepared for many exact point tests (CGAL points and per-polygon boxes,
// built once), used by locate() and by the Plan's index. CGAL stays behind this header.
#pragma once

#include <vector>

#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>

#include "tahvel/spatial/geometry.h"

namespace tahvel::spatial::detail {

using Kernel = CGAL::Exact_predicates_inexact_constructions_kernel;
using CgalPoint = Kernel::Point_2;

struct PreparedPolygon {
  Box box;
  std::vector<CgalPoint> outer;
  std::vector<std::vector<CgalPoint>> holes;
};

struct PreparedShape {
  Box box;
  std::vector<PreparedPolygon> polygons;
};

PreparedShape prepare(const Shape& shape);

// locate() of geometry.h on a prepared shape: exact (CGAL::bounded_side_2 with filtered exact
// predicates), the box test first.
Location locate(const PreparedShape& shape, Point p);

// The same answer without the box tests: every ring of every polygon is tested exactly. The
// brute-force baseline of the benchmark (what a query without any index or filter costs).
Location locate_unfiltered(const PreparedShape& shape, Point p);

}  // namespace tahvel::spatial::detail
