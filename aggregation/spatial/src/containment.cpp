// Polygon-in-area containment (docs/spatial.md S14): a shape lies in an area when its closed
// region is a subset of the area's closed region. Decided in three steps:
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
//   3. for a polygon with holes, the lines of its closed region that the regularized set drops:
//      a wall between two of its holes, a hole's wall along its outer wall (a sensor there is
//      in the room, S3, with no inside of the room beside it). Each edge of such a polygon is
//      cut where it meets the area's boundary; the pieces' ends and midpoints, exact, must be
//      in the area's closed region (a piece crosses no boundary inside it, so one point says
//      where all of it is).
#include "containment.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include <CGAL/Boolean_set_operations_2.h>
#include <CGAL/Exact_predicates_exact_constructions_kernel.h>
#include <CGAL/Polygon_2.h>
#include <CGAL/Polygon_set_2.h>
#include <CGAL/version.h>

namespace tahvel::spatial::detail {

namespace {

using ExactKernel = CGAL::Exact_predicates_exact_constructions_kernel;
using ExactPolygon = CGAL::Polygon_2<ExactKernel>;
using ExactSet = CGAL::Polygon_set_2<ExactKernel>;
using ExactPoint = ExactKernel::Point_2;
using ExactSegment = ExactKernel::Segment_2;

ExactPolygon exact_ring(const Ring& ring) {
  ExactPolygon out;
  for (const Point& p : ring) out.push_back(ExactKernel::Point_2(p.x, p.y));
  if (out.orientation() == CGAL::CLOCKWISE) out.reverse_orientation();
  return out;
}

// The union of a polygon's holes, joined at once (CGAL's aggregated union, divide and
// conquer). Subtracted from the outer ring one at a time, each difference walked all that the
// ones before had built: a hall with 2,000 pillars took 9 s at every read of the floor plan.
ExactSet joined_holes(const Polygon& polygon) {
  std::vector<ExactPolygon> holes;
  holes.reserve(polygon.holes.size());
  for (const Ring& hole : polygon.holes) holes.push_back(exact_ring(hole));
  ExactSet out;
  out.join(holes.begin(), holes.end());
  return out;
}

// The closed region of a valid shape: the union of its polygons, each its outer ring minus its
// holes (regularized: a hole's boundary stays in the region).
ExactSet exact_region(const Shape& shape) {
  ExactSet out;
  for (const Polygon& polygon : shape.polygons) {
    ExactSet part(exact_ring(polygon.outer));
    if (!polygon.holes.empty()) part.difference(joined_holes(polygon));
    out.join(part);
  }
  return out;
}

// The alternative T of an intersection's result, or null: CGAL 5 returns a boost::variant,
// CGAL 6 a std::variant.
template <class T, class Variant>
const T* alternative(const Variant& result) {
#if CGAL_VERSION_NR >= 1060000000  // 6.0
  return std::get_if<T>(&result);
#else
  return boost::get<T>(&result);
#endif
}

// A polygon's rings on the exact kernel, for S3 membership of points constructed exactly.
struct ExactRings {
  ExactPolygon outer;
  std::vector<ExactPolygon> holes;
};

std::vector<ExactRings> exact_rings(const Shape& shape) {
  std::vector<ExactRings> out;
  for (const Polygon& polygon : shape.polygons) {
    ExactRings rings{exact_ring(polygon.outer), {}};
    for (const Ring& hole : polygon.holes) rings.holes.push_back(exact_ring(hole));
    out.push_back(std::move(rings));
  }
  return out;
}

// S3 on an exact point: in some polygon's closed outer ring and in the open inside of none of its
// holes.
bool in_closed_region(const std::vector<ExactRings>& area, const ExactPoint& p) {
  for (const ExactRings& polygon : area) {
    if (polygon.outer.bounded_side(p) == CGAL::ON_UNBOUNDED_SIDE) continue;
    if (std::none_of(polygon.holes.begin(), polygon.holes.end(),
                     [&](const ExactPolygon& hole) { return hole.bounded_side(p) == CGAL::ON_BOUNDED_SIDE; }))
      return true;
  }
  return false;
}

// True when every point of the segment a-b is in the area's closed region.
bool segment_within(const std::vector<ExactRings>& area, const ExactPoint& a, const ExactPoint& b) {
  const ExactSegment along(a, b);
  std::vector<ExactPoint> cuts{a, b};
  auto cut_at_edges_of = [&](const ExactPolygon& ring) {
    for (auto edge = ring.edges_begin(); edge != ring.edges_end(); ++edge) {
      if (!CGAL::do_intersect(along, *edge)) continue;  // a filtered predicate: no construction
      auto hit = CGAL::intersection(along, *edge);
      if (!hit) continue;
      if (const ExactPoint* p = alternative<ExactPoint>(*hit)) {
        cuts.push_back(*p);
      } else if (const ExactSegment* s = alternative<ExactSegment>(*hit)) {
        cuts.push_back(s->source());
        cuts.push_back(s->target());
      }
    }
  };
  for (const ExactRings& polygon : area) {
    cut_at_edges_of(polygon.outer);
    for (const ExactPolygon& hole : polygon.holes) cut_at_edges_of(hole);
  }
  std::sort(cuts.begin(), cuts.end(), [&](const ExactPoint& p, const ExactPoint& q) {
    return CGAL::compare_distance_to_point(a, p, q) == CGAL::SMALLER;
  });
  cuts.erase(std::unique(cuts.begin(), cuts.end()), cuts.end());
  // The cuts between the ends lie on the area's boundary, so in it.
  if (!in_closed_region(area, a) || !in_closed_region(area, b)) return false;
  for (std::size_t i = 0; i + 1 < cuts.size(); ++i)
    if (!in_closed_region(area, CGAL::midpoint(cuts[i], cuts[i + 1]))) return false;
  return true;
}

// Step 3: every edge of every polygon of `inner` that has holes lies in the area.
bool lines_within(const std::vector<ExactRings>& area, const Shape& inner) {
  for (const Polygon& polygon : inner.polygons) {
    if (polygon.holes.empty()) continue;  // its walls all border its inside: step 2 saw them
    auto ring_within_area = [&](const Ring& ring) {
      for (std::size_t i = 0; i < ring.size(); ++i) {
        const Point& from = ring[i];
        const Point& to = ring[(i + 1) % ring.size()];  // the ring does not repeat its first vertex
        if (!segment_within(area, ExactPoint(from.x, from.y), ExactPoint(to.x, to.y))) return false;
      }
      return true;
    };
    if (!ring_within_area(polygon.outer)) return false;
    for (const Ring& hole : polygon.holes)
      if (!ring_within_area(hole)) return false;
  }
  return true;
}

}  // namespace

bool ring_within(const Ring& outer, const Ring& hole) {
  ExactSet outside(exact_ring(hole));
  outside.difference(exact_ring(outer));
  return outside.is_empty();
}

namespace {

// A ring's area (shoelace), from its first vertex: coordinates of projected metres (6.5e6) less
// that vertex keep the products near the room's own size.
double ring_area(const Ring& ring, const Point& origin) {
  double twice = 0;
  for (std::size_t i = 0; i < ring.size(); ++i) {
    const Point& a = ring[i];
    const Point& b = ring[(i + 1) % ring.size()];
    twice += (a.x - origin.x) * (b.y - origin.y) - (b.x - origin.x) * (a.y - origin.y);
  }
  return std::abs(twice) / 2;
}

}  // namespace

bool holes_cover_all(const Polygon& polygon) {
  if (polygon.holes.empty() || polygon.outer.empty()) return false;
  // Holes that cover the ring have areas adding up to its at least (more where they overlap):
  // short of it by far more than rounding, they do not, and the exact test is not needed.
  // Only where the areas are normal doubles well above rounding: near 1e-161 the products are
  // subnormal, rounded each on its own, and holes that tile a ring exactly added up to less
  // than 99 % of it (a review found 8 in 1,080 such triangles accepted).
  const Point& origin = polygon.outer.front();
  const double outer = ring_area(polygon.outer, origin);
  if (std::isfinite(outer) && outer >= std::numeric_limits<double>::min() / std::numeric_limits<double>::epsilon()) {
    double holes = 0;
    for (const Ring& hole : polygon.holes) holes += ring_area(hole, origin);
    if (holes < 0.99 * outer) return false;
  }
  ExactSet left(exact_ring(polygon.outer));
  left.difference(joined_holes(polygon));
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
  std::vector<ExactRings> rings;
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
  if (!impl_) impl_ = std::make_unique<Impl>(Impl{exact_region(area_), exact_rings(area_)});
  ExactSet rest = exact_region(inner);
  rest.difference(impl_->region);
  return rest.is_empty() && lines_within(impl_->rings, inner);
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
