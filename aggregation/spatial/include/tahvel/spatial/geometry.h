// Plane geometry of a floor plan (docs/spatial.md): points, polygons with holes and
// multipolygons as plain values, their bounding boxes, and the exact point-in-area test with the
// one boundary rule that every spatial query of Tahvel applies.
//
// Coordinates are planar (metres in the plan's own frame is the convention; nothing here
// depends on the unit). Floors are not a coordinate: rooms and sensors carry a floor number
// beside their geometry (plan.h). The tests are exact for the double values given (CGAL's
// filtered exact predicates), so a point written with the same decimals as a vertex or lying
// exactly on an edge is on the boundary, never "just outside" by rounding.
//
// Boundary rule (the same everywhere): an area is CLOSED. A point on an edge or a vertex of the
// outer ring belongs to the area; a point on the edge or vertex of a hole also belongs to it
// (only the open inside of a hole is excluded). A point on the edge shared by two rooms belongs
// to both.
#pragma once

#include <cstddef>
#include <string>
#include <vector>

#include "tahvel/spatial/error.h"

namespace tahvel::spatial {

struct Point {
  double x = 0;
  double y = 0;
  friend bool operator==(const Point&, const Point&) = default;
};

// A ring's vertices in order, without repeating the first at the end (WKT repeats it; the
// parser drops it, and keeps a vertex repeated at once only once). A valid ring has at least 3
// vertices, is simple (no edge touches or crosses another except consecutive edges at their
// shared vertex) and encloses a non-zero area. Either orientation. A polygon's holes must leave
// some of its area.
using Ring = std::vector<Point>;

struct Polygon {
  Ring outer;
  std::vector<Ring> holes;  // each valid, inside `outer` (no vertex outside it, no outer
                            // vertex inside the hole, no edge crossing it; touching allowed)
};

// A region: the union of its polygons (a WKT POLYGON is a Shape of one polygon).
struct Shape {
  std::vector<Polygon> polygons;
};

// Closed axis-aligned box; contains(p) includes its edges.
struct Box {
  double xmin = 0, ymin = 0, xmax = 0, ymax = 0;
  bool contains(Point p) const { return p.x >= xmin && p.x <= xmax && p.y >= ymin && p.y <= ymax; }
  bool intersects(const Box& b) const {
    return b.xmin <= xmax && b.xmax >= xmin && b.ymin <= ymax && b.ymax >= ymin;
  }
};

// The smallest box holding every vertex of `shape` (of its outer rings). Precondition: the
// shape has at least one polygon with a vertex.
Box bounding_box(const Shape& shape);

// Checks the rules stated above for every ring of every polygon. The error names the polygon
// and ring ("polygon 2, hole 1: ring is not simple: the edge from (2 1) to (1 2) meets …").
// Shapes from parse_wkt() are already valid.
Result<void> validate(const Shape& shape);

enum class Location {
  outside,
  boundary,  // on an edge or vertex of an outer ring or of a hole
  inside,    // in the open interior
};

// Where `p` lies relative to `shape` (a valid shape). A point inside one polygon of a
// multipolygon is `inside` even if it lies on another one's boundary. O(vertices); for many
// points against one shape, or many shapes, use Plan (plan.h), which prepares shapes once and
// indexes them.
Location locate(const Shape& shape, Point p);

// The boundary rule: locate(shape, p) != Location::outside.
inline bool contains(const Shape& shape, Point p) { return locate(shape, p) != Location::outside; }

// Polygon containment under the same closed rule (docs/spatial.md S14): true when every point
// of `inner`'s closed region (its polygons, each minus the open inside of its holes) belongs to
// `area`'s closed region. So a shape touching the area's boundary from inside, or sharing a wall
// with it, lies in it; one crossing the boundary, or overlapping the open inside of one of the
// area's holes, does not; a shape lies in itself. Both shapes valid. Exact: cheap exact
// predicates first (box, every vertex located), then an exact regularized difference, and for a
// polygon with holes its edges (a wall between two holes is in the room, though no inside of it
// borders the wall).
bool lies_in(const Shape& inner, const Shape& area);

}  // namespace tahvel::spatial
