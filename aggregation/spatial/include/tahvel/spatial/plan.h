// A floor plan with its sensors, indexed for the questions of spatial sensing
// (docs/spatial.md): which sensors lie in an area, which rooms hold a point, and which rooms
// (polygon features) lie in an area.
//
//   Plan plan;
//   plan.put_room({"bedroom", 1, *parse_shape("POLYGON((0 0,4 0,4 3,0 3,0 0))")});
//   plan.put_sensor({"mote7", 1, {1.5, 2}});
//   plan.sensors_in_room("bedroom");          // {"mote7"}
//   plan.rooms_at({4, 1}, 1);                 // {"bedroom"} (on its edge: closed rooms)
//
// Floors: every room and sensor has one floor number; an area may name a floor or apply to
// all of them. Membership follows the boundary rule of geometry.h (closed areas), exactly.
//
// Index (why these): sensors are points queried by region, so they live in one CGAL kd-tree
// per floor (adaptive to clustered motes, exact closed-box range search), and an area query
// tests exactly only the sensors in the area's bounding box. Rooms are boxes queried by point;
// rooms of one floor tile it at similar sizes, so a uniform grid per floor (cell = the median
// room extent) yields a handful of candidates per lookup; the same grid gives the rooms whose
// box lies in an area's box, the only ones tested for lying in the area. Both are rebuilt lazily: a change
// marks its floor stale, and the next query on that floor rebuilds it (O(n log n) for the
// kd-tree, O(n) for the grid). Plans change rarely (a mote moved, a room drawn); queries are
// frequent.
//
// Threads: one thread at a time (queries may rebuild). Ids are any strings (IRIs on the board).
#pragma once

#include <cstddef>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "tahvel/spatial/error.h"
#include "tahvel/spatial/geometry.h"

namespace tahvel::spatial {

struct Room {
  std::string id;
  int floor = 0;
  Shape shape;  // POLYGON or MULTIPOLYGON, valid
};

struct Sensor {
  std::string id;
  int floor = 0;
  Point at;
};

// A region to query: a shape on one floor, or on every floor when `floor` is unset.
struct Area {
  Shape shape;
  std::optional<int> floor;
};

class Plan {
 public:
  Plan();
  Plan(Plan&&) noexcept;
  Plan& operator=(Plan&&) noexcept;
  ~Plan();

  // Adds a room, or replaces the room with the same id. Errors: the shape is not valid
  // (validate()), the id is empty. On error the plan is unchanged.
  Result<void> put_room(Room room);
  // Removes a room; false when there was none with that id.
  bool remove_room(std::string_view id);

  // Adds a sensor, or moves the sensor with the same id (floor and position). Error: empty id,
  // a coordinate that is not finite.
  Result<void> put_sensor(Sensor sensor);
  bool remove_sensor(std::string_view id);

  // Null when unknown. The pointer is valid until the next put/remove.
  const Room* room(std::string_view id) const;
  const Sensor* sensor(std::string_view id) const;
  std::size_t room_count() const;
  std::size_t sensor_count() const;
  // Every room id / sensor id, sorted.
  std::vector<std::string> room_ids() const;
  std::vector<std::string> sensor_ids() const;

  // Ids of the sensors inside `area` (closed), sorted. Tests exactly only the sensors whose
  // position lies in the area's bounding box (kd-tree range search). The area's shape must be
  // valid (from parse_shape, validate, or a room).
  std::vector<std::string> sensors_in(const Area& area) const;
  // The sensors of room `id` (its shape on its floor); empty when the room is unknown.
  std::vector<std::string> sensors_in_room(std::string_view id) const;
  // Ids of the rooms on `floor` whose closed shape holds `p`, sorted (several on a shared edge
  // or vertex, none outside every room).
  std::vector<std::string> rooms_at(Point p, int floor) const;
  // Ids of the rooms (polygon features) lying in `area` (lies_in of geometry.h: closed, a
  // shared wall is in, a crossing is not), on the area's floor or on every floor when it is
  // unset, sorted. A room named as the area lies in it. Uses the rooms' grid: only rooms whose
  // box lies in the area's box are tested exactly (each found once, in the cell of its box's
  // lower-left corner).
  std::vector<std::string> rooms_in(const Area& area) const;

  // The same answers by testing every sensor or room of the floor exactly, with no index and no
  // bounding-box filter: the naive model for differential tests and the benchmark's baseline.
  std::vector<std::string> sensors_in_brute_force(const Area& area) const;
  std::vector<std::string> rooms_at_brute_force(Point p, int floor) const;
  std::vector<std::string> rooms_in_brute_force(const Area& area) const;
  // Every sensor, but the area's bounding box tested first: the strongest index-free peer
  // (reported beside the brute force by `tahvel bench spatial`).
  std::vector<std::string> sensors_in_scan(const Area& area) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace tahvel::spatial
