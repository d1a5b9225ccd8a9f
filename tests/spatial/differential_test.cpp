// Differential tests (STYLE §11): on seeded random layouts, the indexed queries of Plan agree
// with the brute-force test of every sensor and every room (which rooms hold a point, and which
// rooms lie in an area), before and after sensors move and rooms are replaced; and locate()
// agrees with an independent exact oracle written here in integer arithmetic (coordinates are
// multiples of 1/2, so doubled they are small integers and every orientation is computed
// exactly without CGAL).
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <random>

#include <gtest/gtest.h>

#include "tahvel/spatial/plan.h"
#include "tahvel/spatial/wkt.h"

namespace tahvel::spatial {
namespace {

using Ids = std::vector<std::string>;

// --- the oracle: winding number with exact integer orientation (Sunday's formulation) -------

struct IntPoint {
  std::int64_t x, y;
};

IntPoint doubled(Point p) {
  return {static_cast<std::int64_t>(std::llround(p.x * 2)), static_cast<std::int64_t>(std::llround(p.y * 2))};
}

std::int64_t orient(IntPoint a, IntPoint b, IntPoint c) {
  return (b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x);
}

// -1 outside, 0 on the ring, 1 strictly inside.
int ring_side(const Ring& ring, Point point) {
  IntPoint p = doubled(point);
  int winding = 0;
  for (std::size_t i = 0; i < ring.size(); ++i) {
    IntPoint a = doubled(ring[i]), b = doubled(ring[(i + 1) % ring.size()]);
    std::int64_t o = orient(a, b, p);
    if (o == 0 && std::min(a.x, b.x) <= p.x && p.x <= std::max(a.x, b.x) &&
        std::min(a.y, b.y) <= p.y && p.y <= std::max(a.y, b.y)) {
      return 0;
    }
    if (a.y <= p.y && b.y > p.y && o > 0) ++winding;
    if (a.y > p.y && b.y <= p.y && o < 0) --winding;
  }
  return winding != 0 ? 1 : -1;
}

bool oracle_contains(const Shape& shape, Point p) {
  for (const Polygon& polygon : shape.polygons) {
    if (ring_side(polygon.outer, p) < 0) continue;
    bool in_a_hole = false;
    for (const Ring& hole : polygon.holes) in_a_hole = in_a_hole || ring_side(hole, p) > 0;
    if (!in_a_hole) return true;
  }
  return false;
}

// --- random layouts -------------------------------------------------------------------------

class Layout {
 public:
  explicit Layout(std::uint32_t seed) : rng_(seed) {}

  double half_step(double lo, double hi) {  // a multiple of 0.5 in [lo, hi]
    std::uniform_int_distribution<int> d(static_cast<int>(lo * 2), static_cast<int>(hi * 2));
    return d(rng_) / 2.0;
  }
  int floor() { return std::uniform_int_distribution<int>(0, 2)(rng_); }

  // A star-shaped polygon around (cx, cy) on the half grid (often concave), sometimes with a
  // rectangular hole around its centre, sometimes two of them as a multipolygon. Retries
  // until the rounded vertices make a valid shape.
  Shape room(double cx, double cy) {
    for (;;) {
      Shape shape;
      shape.polygons.push_back(star(cx, cy));
      if (chance(0.3)) {
        shape.polygons[0].holes.push_back(
            {{cx - 0.5, cy - 0.5}, {cx + 0.5, cy - 0.5}, {cx + 0.5, cy + 0.5}, {cx - 0.5, cy + 0.5}});
      }
      if (chance(0.15)) shape.polygons.push_back(star(cx + 12, cy));
      if (validate(shape).has_value()) return shape;
    }
  }

  Point point(double lo, double hi) { return {half_step(lo, hi), half_step(lo, hi)}; }
  bool chance(double p) { return std::uniform_real_distribution<double>(0, 1)(rng_) < p; }

 private:
  Polygon star(double cx, double cy) {
    int n = std::uniform_int_distribution<int>(3, 9)(rng_);
    Polygon polygon;
    for (int i = 0; i < n; ++i) {
      double angle = (i + std::uniform_real_distribution<double>(0.1, 0.9)(rng_)) * 2 * M_PI / n;
      double radius = std::uniform_real_distribution<double>(1.5, 6)(rng_);
      polygon.outer.push_back({std::round((cx + radius * std::cos(angle)) * 2) / 2,
                               std::round((cy + radius * std::sin(angle)) * 2) / 2});
    }
    return polygon;
  }

  std::mt19937 rng_;
};

// Rooms on a 12 m pitch (so neighbours overlap and share edges sometimes), sensors on the half
// grid (so many lie exactly on edges and vertices).
Plan random_plan(Layout& layout, int rooms, int sensors) {
  Plan plan;
  for (int i = 0; i < rooms; ++i) {
    double cx = 6 + 12.0 * (i % 10), cy = 6 + 12.0 * (i / 10);
    auto put = plan.put_room({"r" + std::to_string(i), layout.floor(), layout.room(cx, cy)});
    EXPECT_TRUE(put.has_value());
  }
  for (int i = 0; i < sensors; ++i) {
    EXPECT_TRUE(plan.put_sensor({"s" + std::to_string(i), layout.floor(), layout.point(-2, 130)})
                    .has_value());
  }
  return plan;
}

// A large area for polygon features (8..40 m rectangles on the half grid, so room vertices often
// lie on its walls), sometimes with a rectangular hole, sometimes with a second rectangle
// sharing its east wall (a multipolygon whose union a room may span).
Shape big_area(Layout& layout) {
  for (;;) {
    double x0 = layout.half_step(-2, 100), y0 = layout.half_step(-2, 100);
    double w = layout.half_step(8, 40), h = layout.half_step(8, 40);
    Polygon polygon;
    polygon.outer = {{x0, y0}, {x0 + w, y0}, {x0 + w, y0 + h}, {x0, y0 + h}};
    if (layout.chance(0.4)) {
      double hx = layout.half_step(x0 + 1, x0 + w - 4), hy = layout.half_step(y0 + 1, y0 + h - 4);
      double hw = layout.half_step(1, 8), hh = layout.half_step(1, 8);
      polygon.holes.push_back({{hx, hy}, {hx + hw, hy}, {hx + hw, hy + hh}, {hx, hy + hh}});
    }
    Shape shape;
    shape.polygons.push_back(std::move(polygon));
    if (layout.chance(0.3)) {
      double w2 = layout.half_step(4, 20);
      shape.polygons.push_back(
          {{{x0 + w, y0}, {x0 + w + w2, y0}, {x0 + w + w2, y0 + h}, {x0 + w, y0 + h}}, {}});
    }
    if (validate(shape).has_value()) return shape;
  }
}

// Every room as an area, and random areas on one floor or all: index == brute force, for
// sensors (points) and for rooms (polygon features lying in the area). `rooms_found` counts
// the rooms found in the large areas, so that the caller can check the test exercises
// containment at all.
void expect_queries_agree(const Plan& plan, Layout& layout, int rooms, int sensors,
                          std::size_t& rooms_found) {
  for (int i = 0; i < rooms; ++i) {
    std::string id = "r" + std::to_string(i);
    const Room* room = plan.room(id);
    if (!room) continue;
    Area area{room->shape, room->floor};
    EXPECT_EQ(plan.sensors_in(area), plan.sensors_in_brute_force(area)) << id;
    EXPECT_EQ(plan.sensors_in(area), plan.sensors_in_scan(area)) << id;
    Area all_floors{room->shape, std::nullopt};
    EXPECT_EQ(plan.sensors_in(all_floors), plan.sensors_in_brute_force(all_floors)) << id;
    Ids in_room = plan.rooms_in(area);
    EXPECT_EQ(in_room, plan.rooms_in_brute_force(area)) << id;
    EXPECT_TRUE(std::binary_search(in_room.begin(), in_room.end(), id)) << id;  // itself
  }
  for (int i = 0; i < 20; ++i) {
    Shape shape = layout.room(layout.half_step(0, 120), layout.half_step(0, 120));
    Area area{shape, layout.chance(0.5) ? std::optional<int>(layout.floor()) : std::nullopt};
    EXPECT_EQ(plan.sensors_in(area), plan.sensors_in_brute_force(area)) << to_wkt(shape);
    EXPECT_EQ(plan.rooms_in(area), plan.rooms_in_brute_force(area)) << to_wkt(shape);
  }
  for (int i = 0; i < 30; ++i) {
    Shape shape = big_area(layout);
    Area area{shape, layout.chance(0.5) ? std::optional<int>(layout.floor()) : std::nullopt};
    Ids found = plan.rooms_in(area);
    EXPECT_EQ(found, plan.rooms_in_brute_force(area)) << to_wkt(shape);
    EXPECT_EQ(plan.sensors_in(area), plan.sensors_in_brute_force(area)) << to_wkt(shape);
    rooms_found += found.size();
  }
  for (int i = 0; i < sensors; ++i) {
    const Sensor* s = plan.sensor("s" + std::to_string(i));
    if (!s) continue;
    EXPECT_EQ(plan.rooms_at(s->at, s->floor), plan.rooms_at_brute_force(s->at, s->floor)) << s->id;
  }
}

TEST(SpatialDifferential, IndexAgreesWithBruteForceOnRandomLayouts) {
  constexpr int kRooms = 100, kSensors = 3000;
  std::size_t rooms_found = 0;
  for (std::uint32_t seed : {1u, 2u, 3u, 4u, 5u}) {
    SCOPED_TRACE("seed " + std::to_string(seed));
    Layout layout(seed);
    Plan plan = random_plan(layout, kRooms, kSensors);
    expect_queries_agree(plan, layout, kRooms, kSensors, rooms_found);
    // Move a tenth of the sensors (some across floors), replace a tenth of the rooms, drop a few.
    for (int i = 0; i < kSensors; i += 10) {
      ASSERT_TRUE(plan.put_sensor({"s" + std::to_string(i), layout.floor(), layout.point(-2, 130)})
                      .has_value());
    }
    for (int i = 0; i < kRooms; i += 10) {
      double cx = 6 + 12.0 * (i % 10), cy = 6 + 12.0 * (i / 10);
      ASSERT_TRUE(plan.put_room({"r" + std::to_string(i), layout.floor(), layout.room(cx, cy)})
                      .has_value());
    }
    for (int i = 5; i < kRooms; i += 25) plan.remove_room("r" + std::to_string(i));
    for (int i = 7; i < kSensors; i += 97) plan.remove_sensor("s" + std::to_string(i));
    expect_queries_agree(plan, layout, kRooms, kSensors, rooms_found);
  }
  // 600 large areas over 100 rooms on 3 floors: containment must occur often, or the rooms'
  // part of the test would compare empty answers.
  EXPECT_GT(rooms_found, 100u);
}

TEST(SpatialDifferential, LocateAgreesWithAnIntegerOracle) {
  Layout layout(42);
  int on_boundary = 0, inside = 0, checked = 0;
  for (int shapes = 0; shapes < 300; ++shapes) {
    Shape shape = layout.room(0, 0);
    for (double x = -7; x <= 19; x += 0.5) {
      for (double y = -7; y <= 7; y += 0.5) {
        Location where = locate(shape, {x, y});
        ASSERT_EQ(where != Location::outside, oracle_contains(shape, {x, y}))
            << to_wkt(shape) << " at (" << x << " " << y << ")";
        on_boundary += where == Location::boundary;
        inside += where == Location::inside;
        ++checked;
      }
    }
  }
  // The grid must hit edges and vertices often (about 1 point in 100), or the test would not
  // exercise the rule; and both other answers must occur.
  EXPECT_GT(on_boundary, checked / 200);
  EXPECT_GT(inside, checked / 20);
  EXPECT_GT(checked - inside - on_boundary, checked / 20);
}

}  // namespace
}  // namespace tahvel::spatial
