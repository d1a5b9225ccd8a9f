// Membership (tahvel/spatial/geometry.h, plan.h): concave rooms, holes, points on edges and on
// vertices, two floors; the boundary rule (closed areas) the same in locate(), sensors_in() and
// rooms_at().
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

}  // namespace
}  // namespace tahvel::spatial
