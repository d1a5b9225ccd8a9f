// Polygon-in-area containment (docs/spatial.md S14): a shape lies in an area when its closed
// region is a subset of the area's closed region. Decided in two steps:
//   1. cheap exact rejections with the filtered exact predicates of locate(): the shape's box
//      must lie in the area's box, and no vertex of the shape may lie outside the area;
//   2. the exact answer: the regularized difference shape \ area (CGAL Boolean set operations on
//      the exact-construction kernel, built from the input doubles, so nothing is rounded) is
//      empty. For closed regular sets, an empty regularized difference is exactly "subset": a
//      point of the shape outside the closed area would have a neighbourhood outside it, and
//      that neighbourhood meets the shape's interior.
// Step 2 settles uniformly what vertex and edge tests alone get wrong or need many special
// cases for: an edge leaving the area through a reflex vertex of its boundary, a hole of the
// area whose boundary lies on the shape's own boundary (the area's hole is the shape itself,
// or the shape's hole is the area's hole), and a shape spanning two polygons of a
// multipolygon area that share a wall.
#include "containment.h"

#include <CGAL/Boolean_set_operations_2.h>
#include <CGAL/Exact_predicates_exact_constructions_kernel.h>
#include <CGAL/Polygon_2.h>
#include <CGAL/Polygon_set_2.h>

namespace tahvel::spatial::detail {

namespace {

using ExactKernel = CGAL::Exact_predicates_exact_constructions_kernel;
using ExactPolygon = CGAL::Polygon_2<ExactKernel>;
using ExactSet = CGAL::Polygon_set_2<ExactKernel>;

ExactPolygon exact_ring(const Ring& ring) {
  ExactPolygon out;
  for (const Point& p : ring) out.push_back(ExactKernel::Point_2(p.x, p.y));
  if (out.orientation() == CGAL::CLOCKWISE) out.reverse_orientation();
  return out;
}

// The closed region of a valid shape: the union of its polygons, each its outer ring minus its
// holes (regularized: a hole's boundary stays in the region).
ExactSet exact_region(const Shape& shape) {
  ExactSet out;
  for (const Polygon& polygon : shape.polygons) {
    ExactSet part(exact_ring(polygon.outer));
    for (const Ring& hole : polygon.holes) part.difference(exact_ring(hole));
    out.join(part);
  }
  return out;
}

}  // namespace

bool ring_within(const Ring& outer, const Ring& hole) {
  ExactSet outside(exact_ring(hole));
  outside.difference(exact_ring(outer));
  return outside.is_empty();
}

bool holes_cover_all(const Polygon& polygon) {
  ExactSet left(exact_ring(polygon.outer));
  for (const Ring& hole : polygon.holes) left.difference(exact_ring(hole));
  return left.is_empty();
}

namespace {

// The same vertices in the same order, ring by ring: a shape lies in itself (the room named as
// the area), decided without building exact regions.
bool same_shape(const Shape& a, const Shape& b) {
  if (a.polygons.size() != b.polygons.size()) return false;
  for (std::size_t i = 0; i < a.polygons.size(); ++i) {
    const Polygon& p = a.polygons[i];
    const Polygon& q = b.polygons[i];
    if (p.outer != q.outer || p.holes != q.holes) return false;
  }
  return true;
}

bool box_inside(const Box& inner, const Box& outer) {
  return inner.xmin >= outer.xmin && inner.xmax <= outer.xmax && inner.ymin >= outer.ymin &&
         inner.ymax <= outer.ymax;
}

}  // namespace

struct AreaRegion::Impl {
  ExactSet region;
};

AreaRegion::AreaRegion(const Shape& area, const PreparedShape& prepared)
    : area_(area), prepared_(prepared) {}

AreaRegion::~AreaRegion() = default;

bool AreaRegion::holds(const Shape& inner, const PreparedShape& inner_prepared, bool use_boxes) {
  if (inner.polygons.empty() || prepared_.polygons.empty()) return false;
  if (use_boxes && !box_inside(inner_prepared.box, prepared_.box)) return false;
  // Every vertex of the shape (of outer rings and holes) is a point of its closed region.
  for (const Polygon& polygon : inner.polygons) {
    for (const Point& p : polygon.outer) {
      Location at = use_boxes ? locate(prepared_, p) : locate_unfiltered(prepared_, p);
      if (at == Location::outside) return false;
    }
  }
  if (same_shape(inner, area_)) return true;
  if (!impl_) impl_ = std::make_unique<Impl>(Impl{exact_region(area_)});
  ExactSet rest = exact_region(inner);
  rest.difference(impl_->region);
  return rest.is_empty();
}

}  // namespace tahvel::spatial::detail

namespace tahvel::spatial {

bool lies_in(const Shape& inner, const Shape& area) {
  if (inner.polygons.empty() || area.polygons.empty()) return false;
  detail::PreparedShape prepared = detail::prepare(area);
  detail::AreaRegion region(area, prepared);
  return region.holds(inner, detail::prepare(inner));
}

}  // namespace tahvel::spatial
