// Membership (tahvel/spatial/geometry.h, plan.h): concave rooms, holes, points on edges and on
// vertices, two floors; the boundary rule (closed areas) the same in locate(), sensors_in() and
// rooms_at(); polygon features lying in an area (lies_in, rooms_in) under the same rule.
#include "tahvel/spatial/plan.h"

#include <cmath>

#include <gtest/gtest.h>

#include "tahvel/spatial/wkt.h"

namespace tahvel::spatial {
namespace {

using Ids = std::vector<std::string>;

Shape shape(const char* wkt) {
  auto s = parse_shape(wkt);
  EXPECT_TRUE(s.has_value()) << wkt << ": " << (s ? "" : s.error().message);
  return s ? *s : Shape{};
}

// An L-shaped (concave) room: the notch (2..4, 2..4) is outside; (2 2) is the reflex vertex.
const char* kLShape = "POLYGON((0 0, 4 0, 4 2, 2 2, 2 4, 0 4, 0 0))";
// A room with a pillar: the open square (2..3, 1..2) is not part of it.
const char* kWithHole = "POLYGON((0 0, 6 0, 6 4, 0 4, 0 0), (2 1, 3 1, 3 2, 2 2, 2 1))";

TEST(Locate, ConcaveRoom) {
  Shape l = shape(kLShape);
  EXPECT_EQ(locate(l, {1, 1}), Location::inside);
  EXPECT_EQ(locate(l, {1, 3}), Location::inside);   // in the upper arm
  EXPECT_EQ(locate(l, {3, 1}), Location::inside);   // in the right arm
  EXPECT_EQ(locate(l, {3, 3}), Location::outside);  // in the notch: inside the bounding box
  EXPECT_EQ(locate(l, {2, 2}), Location::boundary); // the reflex vertex
  EXPECT_EQ(locate(l, {3, 2}), Location::boundary); // on the notch's lower edge
  EXPECT_EQ(locate(l, {2, 3}), Location::boundary); // on the notch's left edge
  EXPECT_EQ(locate(l, {4, 4}), Location::outside);  // the bounding box's corner
  EXPECT_EQ(locate(l, {0, 0}), Location::boundary); // a convex vertex
  EXPECT_EQ(locate(l, {-1e-300, 1}), Location::outside);  // exact: no tolerance
}

TEST(Locate, HoleExcludesOnlyItsOpenInside) {
  Shape room = shape(kWithHole);
  EXPECT_EQ(locate(room, {2.5, 1.5}), Location::outside);   // in the pillar
  EXPECT_EQ(locate(room, {2.5, 1}), Location::boundary);    // on the pillar's edge
  EXPECT_EQ(locate(room, {3, 2}), Location::boundary);      // on the pillar's vertex
  EXPECT_EQ(locate(room, {1, 1}), Location::inside);
  EXPECT_EQ(locate(room, {6, 4}), Location::boundary);
  EXPECT_TRUE(contains(room, {2.5, 1}));
  EXPECT_FALSE(contains(room, {2.5, 1.5}));
}

TEST(Locate, MultipolygonIsTheUnion) {
  Shape two = shape("MULTIPOLYGON(((0 0, 2 0, 2 2, 0 2, 0 0)), ((2 0, 4 0, 4 2, 2 2, 2 0)))");
  EXPECT_EQ(locate(two, {1, 1}), Location::inside);
  EXPECT_EQ(locate(two, {3, 1}), Location::inside);
  EXPECT_EQ(locate(two, {2, 1}), Location::boundary);  // on both components' shared edge
  EXPECT_EQ(locate(two, {5, 1}), Location::outside);
}

TEST(Locate, ExactOnADiagonalEdge) {
  Shape triangle = shape("POLYGON((0 0, 4 2, 0 2, 0 0))");
  EXPECT_EQ(locate(triangle, {1, 0.5}), Location::boundary);  // 0.5 = 1/2 exactly
  EXPECT_EQ(locate(triangle, {1, 0.5 - 1e-15}), Location::outside);
  EXPECT_EQ(locate(triangle, {1, 0.5 + 1e-15}), Location::inside);
}

// Two rooms sharing an edge on floor 1, the same footprint on floor 2, and sensors on
// interiors, edges and vertices.
Plan two_floor_plan() {
  Plan plan;
  EXPECT_TRUE(plan.put_room({"bedroom", 1, shape(kLShape)}).has_value());
  EXPECT_TRUE(plan.put_room({"hall", 1, shape("POLYGON((4 0, 8 0, 8 2, 4 2, 4 0))")}).has_value());
  EXPECT_TRUE(plan.put_room({"office", 2, shape(kLShape)}).has_value());
  EXPECT_TRUE(plan.put_sensor({"m-bed", 1, {1, 1}}).has_value());
  EXPECT_TRUE(plan.put_sensor({"m-door", 1, {4, 1}}).has_value());     // shared edge
  EXPECT_TRUE(plan.put_sensor({"m-corner", 1, {4, 2}}).has_value());   // shared vertex
  EXPECT_TRUE(plan.put_sensor({"m-notch", 1, {3, 3}}).has_value());    // in the notch
  EXPECT_TRUE(plan.put_sensor({"m-office", 2, {1, 1}}).has_value());   // same x y, floor 2
  return plan;
}

TEST(Plan, RoomsSharingAnEdgeBothHoldItsPoints) {
  Plan plan = two_floor_plan();
  EXPECT_EQ(plan.rooms_at({4, 1}, 1), (Ids{"bedroom", "hall"}));
  EXPECT_EQ(plan.rooms_at({4, 2}, 1), (Ids{"bedroom", "hall"}));
  EXPECT_EQ(plan.rooms_at({3, 3}, 1), Ids{});
  EXPECT_EQ(plan.rooms_at({1, 1}, 1), Ids{"bedroom"});
  EXPECT_EQ(plan.sensors_in_room("bedroom"), (Ids{"m-bed", "m-corner", "m-door"}));
  EXPECT_EQ(plan.sensors_in_room("hall"), (Ids{"m-corner", "m-door"}));
}

TEST(Plan, FloorsSeparateRoomsAndSensors) {
  Plan plan = two_floor_plan();
  EXPECT_EQ(plan.rooms_at({1, 1}, 2), Ids{"office"});
  EXPECT_EQ(plan.sensors_in_room("office"), Ids{"m-office"});
  Shape l = shape(kLShape);
  EXPECT_EQ(plan.sensors_in({l, 2}), Ids{"m-office"});
  EXPECT_EQ(plan.sensors_in({l, std::nullopt}),
            (Ids{"m-bed", "m-corner", "m-door", "m-office"}));  // every floor
  EXPECT_EQ(plan.sensors_in({l, 7}), Ids{});
}

TEST(Plan, HoleInARoom) {
  Plan plan;
  ASSERT_TRUE(plan.put_room({"kitchen", 0, shape(kWithHole)}).has_value());
  ASSERT_TRUE(plan.put_sensor({"pillar", 0, {2.5, 1.5}}).has_value());
  ASSERT_TRUE(plan.put_sensor({"pillar-edge", 0, {2, 1.5}}).has_value());
  ASSERT_TRUE(plan.put_sensor({"pillar-vertex", 0, {2, 1}}).has_value());
  EXPECT_EQ(plan.sensors_in_room("kitchen"), (Ids{"pillar-edge", "pillar-vertex"}));
  EXPECT_EQ(plan.rooms_at({2.5, 1.5}, 0), Ids{});
  EXPECT_EQ(plan.rooms_at({2, 1}, 0), Ids{"kitchen"});
}

TEST(Plan, MovingASensorChangesItsRoom) {
  Plan plan = two_floor_plan();
  EXPECT_EQ(plan.sensors_in_room("hall"), (Ids{"m-corner", "m-door"}));
  ASSERT_TRUE(plan.put_sensor({"m-bed", 1, {6, 1}}).has_value());  // moved into the hall
  EXPECT_EQ(plan.sensors_in_room("hall"), (Ids{"m-bed", "m-corner", "m-door"}));
  EXPECT_EQ(plan.sensors_in_room("bedroom"), (Ids{"m-corner", "m-door"}));
  ASSERT_TRUE(plan.put_sensor({"m-bed", 2, {1, 1}}).has_value());  // upstairs
  EXPECT_EQ(plan.sensors_in_room("office"), (Ids{"m-bed", "m-office"}));
  EXPECT_TRUE(plan.remove_sensor("m-bed"));
  EXPECT_FALSE(plan.remove_sensor("m-bed"));
  EXPECT_EQ(plan.sensors_in_room("office"), Ids{"m-office"});
  EXPECT_EQ(plan.sensor_count(), 4u);
}

TEST(Plan, ReplacingARoomMovesItBetweenFloors) {
  Plan plan = two_floor_plan();
  ASSERT_TRUE(plan.put_room({"hall", 2, shape("POLYGON((4 0, 8 0, 8 2, 4 2, 4 0))")}).has_value());
  EXPECT_EQ(plan.rooms_at({6, 1}, 1), Ids{});
  EXPECT_EQ(plan.rooms_at({6, 1}, 2), Ids{"hall"});
  EXPECT_EQ(plan.room("hall")->floor, 2);
}

TEST(Plan, RefusesInvalidInputAndStaysUnchanged) {
  Plan plan = two_floor_plan();
  Shape bowtie{{Polygon{{{0, 0}, {4, 4}, {4, 0}, {0, 4}}, {}}}};
  auto r = plan.put_room({"hall", 1, bowtie});
  ASSERT_FALSE(r.has_value());
  EXPECT_NE(r.error().message.find("room hall: polygon 1, outer ring: ring is not simple"),
            std::string::npos)
      << r.error().message;
  EXPECT_EQ(plan.rooms_at({6, 1}, 1), Ids{"hall"});  // the old hall is still there
  EXPECT_FALSE(plan.put_room({"", 1, shape(kLShape)}).has_value());
  EXPECT_FALSE(plan.put_sensor({"m", 1, {std::nan(""), 0}}).has_value());
  EXPECT_EQ(plan.sensor("m"), nullptr);
}

// --- polygon features lying in an area (lies_in, Plan::rooms_in; docs/spatial.md S14) ---------

// A 10 x 10 area with a 2 x 2 hole in the middle (4..6, 4..6).
const char* kAreaWithHole = "POLYGON((0 0, 10 0, 10 10, 0 10, 0 0), (4 4, 6 4, 6 6, 4 6, 4 4))";

TEST(LiesIn, ARoomInsideALargerArea) {
  Shape area = shape(kAreaWithHole);
  EXPECT_TRUE(lies_in(shape("POLYGON((1 1, 3 1, 3 3, 1 3, 1 1))"), area));
  EXPECT_TRUE(lies_in(shape(kLShape), shape("POLYGON((-1 -1, 5 -1, 5 5, -1 5, -1 -1))")));
  EXPECT_TRUE(lies_in(area, area));  // a shape lies in itself, holes and all
  EXPECT_TRUE(lies_in(shape(kLShape), shape(kLShape)));
}

TEST(LiesIn, ARoomSharingAWallWithTheAreasBoundaryIsIn) {
  Shape area = shape(kAreaWithHole);
  EXPECT_TRUE(lies_in(shape("POLYGON((0 0, 3 0, 3 3, 0 3, 0 0))"), area));    // a corner, 2 walls
  EXPECT_TRUE(lies_in(shape("POLYGON((2 0, 3 0, 3 10, 2 10, 2 0))"), area));  // wall to wall
  EXPECT_TRUE(lies_in(shape("POLYGON((6 4, 8 4, 8 6, 6 6, 6 4))"), area));    // the hole's wall
  // Touching all four walls from inside, but the hole lies strictly inside this diamond.
  EXPECT_FALSE(lies_in(shape("POLYGON((5 0, 10 5, 5 10, 0 5, 5 0))"), area));
  EXPECT_TRUE(lies_in(shape("POLYGON((5 0, 10 5, 5 10, 0 5, 5 0), (4 4, 6 4, 6 6, 4 6, 4 4))"), area));
  // A room outside sharing the area's wall is not in it.
  EXPECT_FALSE(lies_in(shape("POLYGON((10 0, 12 0, 12 2, 10 2, 10 0))"), area));
  // Exact: 1e-15 beyond the wall is out.
  EXPECT_FALSE(lies_in(shape("POLYGON((1 1, 10.000000000000002 1, 3 3, 1 3, 1 1))"), area));
}

TEST(LiesIn, ARoomCrossingTheBoundaryIsOut) {
  Shape area = shape(kAreaWithHole);
  EXPECT_FALSE(lies_in(shape("POLYGON((8 8, 12 8, 12 12, 8 12, 8 8))"), area));
  // Every vertex on the boundary of the L, one edge through its notch (through no proper crossing:
  // it leaves and re-enters at vertices).
  EXPECT_FALSE(lies_in(shape("POLYGON((0 0, 4 2, 2 4, 0 0))"), shape(kLShape)));
  EXPECT_TRUE(lies_in(shape("POLYGON((0 0, 4 2, 2 2, 2 4, 0 0))"), shape(kLShape)));
}

TEST(LiesIn, ARoomInsideAnAreasHoleIsOut) {
  Shape area = shape(kAreaWithHole);
  EXPECT_FALSE(lies_in(shape("POLYGON((4.5 4.5, 5.5 4.5, 5.5 5.5, 4.5 5.5, 4.5 4.5))"), area));
  // The hole itself as a room: every point of its boundary is in the area, its inside is not.
  EXPECT_FALSE(lies_in(shape("POLYGON((4 4, 6 4, 6 6, 4 6, 4 4))"), area));
  // A room around the hole (the hole strictly inside the room) is out; with the same hole, in.
  EXPECT_FALSE(lies_in(shape("POLYGON((3 3, 7 3, 7 7, 3 7, 3 3))"), area));
  EXPECT_TRUE(lies_in(shape("POLYGON((3 3, 7 3, 7 7, 3 7, 3 3), (4 4, 6 4, 6 6, 4 6, 4 4))"), area));
  // A larger hole in the room covers the area's hole too.
  EXPECT_TRUE(lies_in(shape("POLYGON((2 2, 8 2, 8 8, 2 8, 2 2), (3 3, 7 3, 7 7, 3 7, 3 3))"), area));
  // A hole of the area whose vertices all lie on the room's boundary, its inside in the room's.
  EXPECT_FALSE(lies_in(shape("POLYGON((0 0, 4 0, 4 4, 0 4, 0 0))"),
                       shape("POLYGON((-1 -1, 5 -1, 5 5, -1 5, -1 -1), (0 0, 4 0, 2 2, 0 0))")));
}

// A wall between two holes of a room, and a hole's wall along the room's outer wall, are points
// of the room's closed region (S3: a sensor there is in the room) with no inside of the room
// beside them. The room lies in an area only when those lines do too: the regularized
// difference of step 2 does not see them.
TEST(LiesIn, TheLinesOfARoomThatHaveNoInsideBesideThemMustLieInTheAreaToo) {
  Shape two_pillars = shape("POLYGON((0 0, 10 0, 10 10, 0 10, 0 0), (2 2, 5 2, 5 8, 2 8, 2 2), (5 2, 8 2, 8 8, 5 8, 5 2))");
  Shape one_shaft = shape("POLYGON((0 0, 10 0, 10 10, 0 10, 0 0), (2 2, 8 2, 8 8, 2 8, 2 2))");
  ASSERT_TRUE(validate(two_pillars).has_value());
  ASSERT_TRUE(contains(two_pillars, {5, 5}));
  ASSERT_FALSE(contains(one_shaft, {5, 5}));
  EXPECT_FALSE(lies_in(two_pillars, one_shaft));
  EXPECT_TRUE(lies_in(one_shaft, two_pillars));
  EXPECT_TRUE(lies_in(two_pillars, two_pillars));
  // An area with the same wall between its two holes holds it.
  EXPECT_TRUE(lies_in(two_pillars, shape("POLYGON((-1 -1, 11 -1, 11 11, -1 11, -1 -1), (2 2, 5 2, 5 8, 2 8, 2 2), (5 2, 8 2, 8 8, 5 8, 5 2))")));
  // The area's one hole has the lower half of the wall as its wall; the upper half is in its inside.
  Shape l_shaft = shape("POLYGON((-1 -1, 11 -1, 11 11, -1 11, -1 -1), (2 2, 5 2, 5 5, 8 5, 8 8, 2 8, 2 2))");
  ASSERT_TRUE(contains(l_shaft, {5, 3}));
  ASSERT_FALSE(contains(l_shaft, {5, 6}));
  EXPECT_FALSE(lies_in(two_pillars, l_shaft));

  Shape alcove = shape("POLYGON((0 0, 10 0, 10 10, 0 10, 0 0), (0 2, 3 2, 3 5, 0 5, 0 2))");
  Shape notched = shape("POLYGON((0 0, 10 0, 10 10, 0 10, 0 5, 3 5, 3 2, 0 2, 0 0))");
  if (!validate(alcove)) GTEST_SKIP() << "a hole along the outer wall is refused: " << validate(alcove).error().message;
  ASSERT_TRUE(contains(alcove, {0, 3}));
  ASSERT_FALSE(contains(notched, {0, 3}));
  EXPECT_FALSE(lies_in(alcove, notched));
  EXPECT_TRUE(lies_in(notched, alcove));
}

TEST(LiesIn, MultipolygonsOnBothSides) {
  // Two halves of an area sharing the wall x = 5: a room across the wall lies in their union.
  Shape halves = shape("MULTIPOLYGON(((0 0, 5 0, 5 5, 0 5, 0 0)), ((5 0, 10 0, 10 5, 5 5, 5 0)))");
  EXPECT_TRUE(lies_in(shape("POLYGON((4 1, 6 1, 6 2, 4 2, 4 1))"), halves));
  // A two-part feature is in only when both parts are.
  EXPECT_TRUE(lies_in(shape("MULTIPOLYGON(((1 1, 2 1, 2 2, 1 2, 1 1)), ((8 1, 9 1, 9 2, 8 2, 8 1)))"),
                      halves));
  EXPECT_FALSE(lies_in(shape("MULTIPOLYGON(((1 1, 2 1, 2 2, 1 2, 1 1)), ((8 4, 9 4, 9 6, 8 6, 8 4)))"),
                       halves));
}

TEST(RoomsIn, IndexedWithFloorsAndTheBoundaryRule) {
  Plan plan;
  ASSERT_TRUE(plan.put_room({"area", 0, shape(kAreaWithHole)}).has_value());
  ASSERT_TRUE(plan.put_room({"inside", 0, shape("POLYGON((1 1, 3 1, 3 3, 1 3, 1 1))")}).has_value());
  ASSERT_TRUE(plan.put_room({"wall", 0, shape("POLYGON((0 7, 2 7, 2 10, 0 10, 0 7))")}).has_value());
  ASSERT_TRUE(plan.put_room({"crossing", 0, shape("POLYGON((8 8, 12 8, 12 12, 8 12, 8 8))")}).has_value());
  ASSERT_TRUE(plan.put_room({"in-hole", 0, shape("POLYGON((4 4, 5 4, 5 5, 4 5, 4 4))")}).has_value());
  ASSERT_TRUE(plan.put_room({"neighbour", 0, shape("POLYGON((10 0, 12 0, 12 2, 10 2, 10 0))")}).has_value());
  ASSERT_TRUE(plan.put_room({"upstairs", 1, shape("POLYGON((1 1, 3 1, 3 3, 1 3, 1 1))")}).has_value());
  const Room* area = plan.room("area");
  ASSERT_NE(area, nullptr);
  Area ground{area->shape, 0};
  EXPECT_EQ(plan.rooms_in(ground), (Ids{"area", "inside", "wall"}));
  EXPECT_EQ(plan.rooms_in(ground), plan.rooms_in_brute_force(ground));
  Area first{area->shape, 1};
  EXPECT_EQ(plan.rooms_in(first), Ids{"upstairs"});
  Area every{area->shape, std::nullopt};
  EXPECT_EQ(plan.rooms_in(every), (Ids{"area", "inside", "upstairs", "wall"}));
  EXPECT_EQ(plan.rooms_in(every), plan.rooms_in_brute_force(every));
  // Moving the room out of the area (a replacement) is seen by the next query.
  ASSERT_TRUE(plan.put_room({"inside", 0, shape("POLYGON((9 1, 11 1, 11 3, 9 3, 9 1))")}).has_value());
  EXPECT_EQ(plan.rooms_in(ground), (Ids{"area", "wall"}));
}

}  // namespace
}  // namespace tahvel::spatial
