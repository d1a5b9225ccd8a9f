// Exact point-in-area tests and ring validity with CGAL (Epick: exact predicates on the input
// doubles; nothing here constructs new coordinates, so nothing is rounded). Workload: a shape is
// prepared once and tested against many points (Plan), or tested once (locate()).
#include <algorithm>
#include <cmath>
#include <string>

#include <CGAL/Polygon_2_algorithms.h>

#include "checks.h"
#include "containment.h"
#include "prepared.h"

namespace tahvel::spatial {

namespace detail {
namespace {

std::vector<CgalPoint> to_cgal(const Ring& ring) {
  std::vector<CgalPoint> out;
  out.reserve(ring.size());
  for (const Point& p : ring) out.emplace_back(p.x, p.y);
  return out;
}

Box box_of(const Ring& ring) {
  Box box{ring[0].x, ring[0].y, ring[0].x, ring[0].y};
  for (const Point& p : ring) {
    box.xmin = std::min(box.xmin, p.x);
    box.xmax = std::max(box.xmax, p.x);
    box.ymin = std::min(box.ymin, p.y);
    box.ymax = std::max(box.ymax, p.y);
  }
  return box;
}

Box join(const Box& a, const Box& b) {
  return {std::min(a.xmin, b.xmin), std::min(a.ymin, b.ymin), std::max(a.xmax, b.xmax),
          std::max(a.ymax, b.ymax)};
}

CGAL::Bounded_side side(const std::vector<CgalPoint>& ring, const CgalPoint& q) {
  return CGAL::bounded_side_2(ring.begin(), ring.end(), q, Kernel());
}

std::string coordinates(Point p) {
  return "(" + format_number(p.x) + " " + format_number(p.y) + ")";
}

}  // namespace

namespace {

// Whether edges i < j (edge k runs from vertex k to k + 1) meet other than at the vertex
// adjacent edges share: crossing, touching, or folding back along each other.
bool edges_meet(const std::vector<CgalPoint>& v, std::size_t i, std::size_t j) {
  const std::size_t n = v.size();
  const CgalPoint& a = v[i];
  const CgalPoint& b = v[(i + 1) % n];
  const bool follows = i + 1 == j, wraps = i == 0 && j == n - 1;
  if (follows || wraps) {
    // Adjacent: sharing their common vertex is fine; overlapping beyond it is not.
    const CgalPoint& shared = follows ? b : a;
    const CgalPoint& mine = follows ? a : b;
    const CgalPoint& theirs = follows ? v[(j + 1) % n] : v[j];
    return CGAL::collinear(mine, shared, theirs) && !CGAL::collinear_are_strictly_ordered_along_line(mine, shared, theirs);
  }
  return CGAL::do_intersect(Kernel::Segment_2(a, b), Kernel::Segment_2(v[j], v[(j + 1) % n]));
}

// The first two edges that meet, first by the later edge j, then by i (the later of the two is
// the one an error names the column of). Only edges whose bounding boxes overlap are tested, in
// a sweep over x: testing every pair took 2.5 s for a ring of 40,000 vertices.
std::optional<std::pair<std::size_t, std::size_t>> meeting_edges(const std::vector<CgalPoint>& v) {
  const std::size_t n = v.size();
  struct Box {
    double x0, x1, y0, y1;
  };
  std::vector<Box> boxes(n);
  for (std::size_t k = 0; k < n; ++k) {
    const CgalPoint& a = v[k];
    const CgalPoint& b = v[(k + 1) % n];
    boxes[k] = {std::min(a.x(), b.x()), std::max(a.x(), b.x()), std::min(a.y(), b.y()), std::max(a.y(), b.y())};
  }
  std::vector<std::size_t> order(n);
  for (std::size_t k = 0; k < n; ++k) order[k] = k;
  std::sort(order.begin(), order.end(), [&](std::size_t p, std::size_t q) { return boxes[p].x0 < boxes[q].x0; });
  std::optional<std::pair<std::size_t, std::size_t>> best;
  std::vector<std::size_t> active;  // edges whose x range reaches the sweep's position
  for (const std::size_t k : order) {
    const Box& box = boxes[k];
    std::erase_if(active, [&](std::size_t e) { return boxes[e].x1 < box.x0; });
    for (const std::size_t e : active) {
      if (boxes[e].y1 < box.y0 || box.y1 < boxes[e].y0) continue;
      const std::pair<std::size_t, std::size_t> pair{std::min(e, k), std::max(e, k)};
      const bool earlier = !best || pair.second < best->second || (pair.second == best->second && pair.first < best->first);
      if (earlier && edges_meet(v, pair.first, pair.second)) best = pair;
    }
    active.push_back(k);
  }
  return best;
}

}  // namespace

std::optional<RingProblem> ring_problem(const Ring& ring) {
  if (ring.size() < 3) {
    return RingProblem{"a ring needs at least 3 distinct vertices, found " + std::to_string(ring.size()), 0};
  }
  std::vector<CgalPoint> points = to_cgal(ring);
  // is_simple_2 also refuses a repeated vertex and a ring whose vertices are all collinear
  // (its edges overlap), so a simple ring encloses a non-zero area.
  if (!CGAL::is_simple_2(points.begin(), points.end(), Kernel())) {
    auto edge = [&](std::size_t k) {
      return "the edge from " + coordinates(ring[k]) + " to " + coordinates(ring[(k + 1) % ring.size()]);
    };
    if (auto meet = meeting_edges(points)) {
      return RingProblem{"ring is not simple: " + edge(meet->second) + " meets " + edge(meet->first) + " (crossing, touching or overlapping it)",
                         meet->second};
    }
    return RingProblem{"ring is not simple (an edge touches or crosses another, or a vertex repeats)", 0};
  }
  return std::nullopt;
}

namespace {

// True when segments ab and cd cross at one point interior to both (not a touch at an end).
bool cross_properly(const CgalPoint& a, const CgalPoint& b, const CgalPoint& c,
                    const CgalPoint& d) {
  auto abc = CGAL::orientation(a, b, c), abd = CGAL::orientation(a, b, d);
  auto cda = CGAL::orientation(c, d, a), cdb = CGAL::orientation(c, d, b);
  return abc != CGAL::COLLINEAR && abd != CGAL::COLLINEAR && abc != abd &&
         cda != CGAL::COLLINEAR && cdb != CGAL::COLLINEAR && cda != cdb;
}

}  // namespace

std::optional<RingProblem> hole_problem(const Ring& outer, const Ring& hole) {
  std::vector<CgalPoint> outer_points = to_cgal(outer), hole_points = to_cgal(hole);
  for (std::size_t k = 0; k < hole.size(); ++k) {
    if (side(outer_points, CgalPoint(hole[k].x, hole[k].y)) == CGAL::ON_UNBOUNDED_SIDE) {
      return RingProblem{"hole vertex " + coordinates(hole[k]) + " lies outside the outer ring", k};
    }
  }
  for (const Point& p : outer) {
    if (side(hole_points, CgalPoint(p.x, p.y)) == CGAL::ON_BOUNDED_SIDE) {
      return RingProblem{"outer ring vertex " + coordinates(p) + " lies inside the hole"};
    }
  }
  for (std::size_t i = 0; i < hole_points.size(); ++i) {
    const CgalPoint& a = hole_points[i];
    const CgalPoint& b = hole_points[(i + 1) % hole_points.size()];
    for (std::size_t j = 0; j < outer_points.size(); ++j) {
      if (cross_properly(a, b, outer_points[j], outer_points[(j + 1) % outer_points.size()])) {
        return RingProblem{"a hole edge crosses the outer ring"};
      }
    }
  }
  // Vertices on the ring and edges that only touch it can still leave it (a hole drawn in a
  // concave ring's notch): decided exactly.
  if (!ring_within(outer, hole)) return RingProblem{"the hole reaches outside the outer ring"};
  return std::nullopt;
}

std::optional<std::string> area_problem(const Polygon& polygon) {
  if (polygon.holes.empty()) return std::nullopt;
  // Exactly: a sum of the holes' rounded areas counted overlapping holes twice and underflowed
  // for coordinates near 1e-200.
  if (holes_cover_all(polygon)) return "its holes cover all of it: it encloses no area";
  return std::nullopt;
}

PreparedShape prepare(const Shape& shape) {
  PreparedShape out;
  for (const Polygon& polygon : shape.polygons) {
    PreparedPolygon prepared;
    prepared.box = box_of(polygon.outer);
    prepared.outer = to_cgal(polygon.outer);
    for (const Ring& hole : polygon.holes) prepared.holes.push_back(to_cgal(hole));
    out.box = out.polygons.empty() ? prepared.box : join(out.box, prepared.box);
    out.polygons.push_back(std::move(prepared));
  }
  return out;
}

namespace {

Location locate_in(const PreparedShape& shape, Point p, bool use_boxes) {
  const CgalPoint q(p.x, p.y);
  bool on_boundary = false;
  for (const PreparedPolygon& polygon : shape.polygons) {
    if (use_boxes && !polygon.box.contains(p)) continue;
    CGAL::Bounded_side outer = side(polygon.outer, q);
    if (outer == CGAL::ON_UNBOUNDED_SIDE) continue;
    if (outer == CGAL::ON_BOUNDARY) {
      on_boundary = true;
      continue;
    }
    Location here = Location::inside;
    for (const std::vector<CgalPoint>& hole : polygon.holes) {
      CGAL::Bounded_side in_hole = side(hole, q);
      if (in_hole == CGAL::ON_BOUNDED_SIDE) {
        here = Location::outside;  // the open inside of a hole is not part of the area
        break;
      }
      if (in_hole == CGAL::ON_BOUNDARY) here = Location::boundary;
    }
    if (here == Location::inside) return Location::inside;
    if (here == Location::boundary) on_boundary = true;
  }
  return on_boundary ? Location::boundary : Location::outside;
}

}  // namespace

Location locate(const PreparedShape& shape, Point p) {
  if (shape.polygons.empty() || !shape.box.contains(p)) return Location::outside;
  return locate_in(shape, p, true);
}

Location locate_unfiltered(const PreparedShape& shape, Point p) {
  return locate_in(shape, p, false);
}

}  // namespace detail

Box bounding_box(const Shape& shape) {
  Box box = detail::box_of(shape.polygons.at(0).outer);
  for (const Polygon& polygon : shape.polygons) box = detail::join(box, detail::box_of(polygon.outer));
  return box;
}

Result<void> validate(const Shape& shape) {
  if (shape.polygons.empty()) return fail("a shape needs at least one polygon");
  for (std::size_t i = 0; i < shape.polygons.size(); ++i) {
    const Polygon& polygon = shape.polygons[i];
    std::string where = "polygon " + std::to_string(i + 1);
    if (auto problem = detail::ring_problem(polygon.outer)) {
      return fail(where + ", outer ring: " + problem->message);
    }
    for (std::size_t h = 0; h < polygon.holes.size(); ++h) {
      std::string hole = where + ", hole " + std::to_string(h + 1) + ": ";
      if (auto problem = detail::ring_problem(polygon.holes[h])) return fail(hole + problem->message);
      if (auto problem = detail::hole_problem(polygon.outer, polygon.holes[h])) {
        return fail(hole + problem->message);
      }
    }
    if (auto problem = detail::area_problem(polygon)) return fail(where + ": " + *problem);
  }
  return {};
}

Location locate(const Shape& shape, Point p) {
  if (shape.polygons.empty()) return Location::outside;
  return detail::locate(detail::prepare(shape), p);
}

}  // namespace tahvel::spatial
