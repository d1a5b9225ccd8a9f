// The floor plan's index (plan.h): per floor, a CGAL kd-tree over sensor positions and a uniform
// grid over room bounding boxes, each rebuilt lazily after a change on its floor. Tuned for a
// home or a hospital wing: 10..10,000 sensors, 10..1,000 rooms, many more queries than changes.
#include "tahvel/spatial/plan.h"

#include <algorithm>
#include <cmath>
#include <map>

#include <CGAL/Fuzzy_iso_box.h>
#include <CGAL/Kd_tree.h>
#include <CGAL/Search_traits_2.h>
#include <CGAL/Search_traits_adapter.h>
#include <CGAL/property_map.h>
#include <boost/tuple/tuple.hpp>

#include "containment.h"
#include "prepared.h"

namespace tahvel::spatial {

namespace {

using detail::CgalPoint;
using detail::Kernel;

// A sensor position with its index in the floor's member list.
using IndexedPoint = boost::tuple<CgalPoint, std::uint32_t>;
using TreeTraits = CGAL::Search_traits_adapter<IndexedPoint,
                                               CGAL::Nth_of_tuple_property_map<0, IndexedPoint>,
                                               CGAL::Search_traits_2<Kernel>>;
using Tree = CGAL::Kd_tree<TreeTraits>;
using BoxQuery = CGAL::Fuzzy_iso_box<TreeTraits>;  // epsilon 0: a closed box

struct RoomEntry {
  Room room;
  detail::PreparedShape prepared;
};

struct SensorFloor {
  bool stale = true;
  std::unique_ptr<Tree> tree;  // points carry their index in Impl::sensors
};

// Rooms of one floor in a uniform grid: each cell lists the rooms whose box overlaps it.
struct RoomFloor {
  bool stale = true;
  std::vector<const RoomEntry*> members;
  Box bounds;
  double cell = 1;
  std::size_t nx = 1, ny = 1;
  std::vector<std::vector<std::uint32_t>> cells;

  // Cell coordinates are monotonic in x and y (subtraction, division by a positive constant
  // and floor all are), so a point inside a room's box always falls in a cell the room was
  // put in, also exactly on a cell border.
  std::size_t column(double x) const { return index(x - bounds.xmin, nx); }
  std::size_t row(double y) const { return index(y - bounds.ymin, ny); }
  std::size_t index(double offset, std::size_t n) const {
    double i = std::floor(offset / cell);
    if (!(i > 0)) return 0;
    return i >= static_cast<double>(n - 1) ? n - 1 : static_cast<std::size_t>(i);
  }
};

double median(std::vector<double> values) {
  std::nth_element(values.begin(), values.begin() + values.size() / 2, values.end());
  return values[values.size() / 2];
}

void build_grid(RoomFloor& floor) {
  floor.cells.clear();
  if (floor.members.empty()) return;
  std::vector<double> extents;
  floor.bounds = floor.members[0]->prepared.box;
  for (const RoomEntry* entry : floor.members) {
    const Box& b = entry->prepared.box;
    floor.bounds = {std::min(floor.bounds.xmin, b.xmin), std::min(floor.bounds.ymin, b.ymin),
                    std::max(floor.bounds.xmax, b.xmax), std::max(floor.bounds.ymax, b.ymax)};
    extents.push_back(std::max(b.xmax - b.xmin, b.ymax - b.ymin));
  }
  double width = floor.bounds.xmax - floor.bounds.xmin;
  double height = floor.bounds.ymax - floor.bounds.ymin;
  floor.cell = std::max(median(extents), std::max(width, height) / 4096);
  // At most about 4 cells per room: a few huge rooms among many tiny ones must not make the
  // grid quadratic in size.
  const double max_cells = 4.0 * static_cast<double>(floor.members.size()) + 64;
  while ((std::floor(width / floor.cell) + 1) * (std::floor(height / floor.cell) + 1) > max_cells) {
    floor.cell *= 1.5;
  }
  floor.nx = static_cast<std::size_t>(std::floor(width / floor.cell)) + 1;
  floor.ny = static_cast<std::size_t>(std::floor(height / floor.cell)) + 1;
  floor.cells.assign(floor.nx * floor.ny, {});
  for (std::uint32_t i = 0; i < floor.members.size(); ++i) {
    const Box& b = floor.members[i]->prepared.box;
    for (std::size_t r = floor.row(b.ymin); r <= floor.row(b.ymax); ++r) {
      for (std::size_t c = floor.column(b.xmin); c <= floor.column(b.xmax); ++c) {
        floor.cells[r * floor.nx + c].push_back(i);
      }
    }
  }
}

}  // namespace

struct Plan::Impl {
  std::map<std::string, RoomEntry, std::less<>> rooms;
  // Sensors in one dense array (what a scan of every sensor walks), found by id through the
  // map. Removal moves the last sensor into the hole, so indices change only then.
  std::vector<Sensor> sensors;
  std::map<std::string, std::uint32_t, std::less<>> sensor_index;
  mutable std::map<int, SensorFloor> sensor_floors;
  mutable std::map<int, RoomFloor> room_floors;

  SensorFloor& sensors_of(int floor) const {
    SensorFloor& f = sensor_floors[floor];
    if (!f.stale) return f;
    std::vector<IndexedPoint> points;
    for (std::uint32_t i = 0; i < sensors.size(); ++i) {
      if (sensors[i].floor != floor) continue;
      points.emplace_back(CgalPoint(sensors[i].at.x, sensors[i].at.y), i);
    }
    f.tree = std::make_unique<Tree>(points.begin(), points.end());
    if (!points.empty()) f.tree->build();  // CGAL's build() dereferences the first point
    f.stale = false;
    return f;
  }

  RoomFloor& rooms_of(int floor) const {
    RoomFloor& f = room_floors[floor];
    if (!f.stale) return f;
    f.members.clear();
    for (const auto& [id, entry] : rooms) {
      if (entry.room.floor == floor) f.members.push_back(&entry);
    }
    build_grid(f);
    f.stale = false;
    return f;
  }

  void sensors_changed(int floor) { sensor_floors[floor].stale = true; }
  void rooms_changed(int floor) { room_floors[floor].stale = true; }

  // The floors an area applies to that have sensors.
  std::vector<int> sensor_floor_numbers(const Area& area) const {
    if (area.floor) return {*area.floor};
    std::vector<int> floors;
    for (const auto& [floor, index] : sensor_floors) {
      if (index.stale || index.tree->size() != 0) floors.push_back(floor);
    }
    return floors;
  }
};

Plan::Plan() : impl_(std::make_unique<Impl>()) {}
Plan::Plan(Plan&&) noexcept = default;
Plan& Plan::operator=(Plan&&) noexcept = default;
Plan::~Plan() = default;

Result<void> Plan::put_room(Room room) {
  if (room.id.empty()) return fail("a room needs an id");
  if (auto valid = validate(room.shape); !valid) {
    return fail("room " + room.id + ": " + valid.error().message);
  }
  auto it = impl_->rooms.find(room.id);
  if (it != impl_->rooms.end()) {
    impl_->rooms_changed(it->second.room.floor);
    impl_->rooms.erase(it);
  }
  impl_->rooms_changed(room.floor);
  RoomEntry entry{std::move(room), {}};
  entry.prepared = detail::prepare(entry.room.shape);
  std::string id = entry.room.id;
  impl_->rooms.emplace(std::move(id), std::move(entry));
  return {};
}

bool Plan::remove_room(std::string_view id) {
  auto it = impl_->rooms.find(id);
  if (it == impl_->rooms.end()) return false;
  impl_->rooms_changed(it->second.room.floor);
  impl_->rooms.erase(it);
  return true;
}

Result<void> Plan::put_sensor(Sensor sensor) {
  if (sensor.id.empty()) return fail("a sensor needs an id");
  if (!std::isfinite(sensor.at.x) || !std::isfinite(sensor.at.y)) {
    return fail("sensor " + sensor.id + ": coordinates must be finite");
  }
  auto it = impl_->sensor_index.find(sensor.id);
  if (it != impl_->sensor_index.end()) {
    Sensor& old = impl_->sensors[it->second];
    impl_->sensors_changed(old.floor);
    impl_->sensors_changed(sensor.floor);
    old = std::move(sensor);
    return {};
  }
  impl_->sensors_changed(sensor.floor);
  impl_->sensor_index.emplace(sensor.id, static_cast<std::uint32_t>(impl_->sensors.size()));
  impl_->sensors.push_back(std::move(sensor));
  return {};
}

bool Plan::remove_sensor(std::string_view id) {
  auto it = impl_->sensor_index.find(id);
  if (it == impl_->sensor_index.end()) return false;
  std::uint32_t hole = it->second;
  impl_->sensors_changed(impl_->sensors[hole].floor);
  impl_->sensor_index.erase(it);
  if (hole + 1 != impl_->sensors.size()) {  // the last sensor fills the hole: its index changes
    Sensor& last = impl_->sensors.back();
    impl_->sensors_changed(last.floor);
    impl_->sensor_index[last.id] = hole;
    impl_->sensors[hole] = std::move(last);
  }
  impl_->sensors.pop_back();
  return true;
}

const Room* Plan::room(std::string_view id) const {
  auto it = impl_->rooms.find(id);
  return it == impl_->rooms.end() ? nullptr : &it->second.room;
}

const Sensor* Plan::sensor(std::string_view id) const {
  auto it = impl_->sensor_index.find(id);
  return it == impl_->sensor_index.end() ? nullptr : &impl_->sensors[it->second];
}

std::size_t Plan::room_count() const { return impl_->rooms.size(); }
std::size_t Plan::sensor_count() const { return impl_->sensors.size(); }

std::vector<std::string> Plan::room_ids() const {
  std::vector<std::string> out;
  for (const auto& [id, entry] : impl_->rooms) out.push_back(id);
  return out;
}

std::vector<std::string> Plan::sensor_ids() const {
  std::vector<std::string> out;
  for (const auto& [id, index] : impl_->sensor_index) out.push_back(id);
  return out;
}

std::vector<std::string> Plan::sensors_in(const Area& area) const {
  std::vector<std::string> out;
  if (area.shape.polygons.empty()) return out;
  detail::PreparedShape prepared = detail::prepare(area.shape);
  const Box& b = prepared.box;
  BoxQuery query(CgalPoint(b.xmin, b.ymin), CgalPoint(b.xmax, b.ymax));
  std::vector<IndexedPoint> candidates;
  candidates.reserve(64);  // a room's box holds a few dozen sensors: one allocation, not six
  for (int floor : impl_->sensor_floor_numbers(area)) {
    SensorFloor& f = impl_->sensors_of(floor);
    if (f.tree->size() == 0) continue;
    candidates.clear();
    f.tree->search(std::back_inserter(candidates), query);
    out.reserve(out.size() + candidates.size());
    for (const IndexedPoint& candidate : candidates) {
      const Sensor* sensor = &impl_->sensors[boost::get<1>(candidate)];
      if (detail::locate(prepared, sensor->at) != Location::outside) out.push_back(sensor->id);
    }
  }
  std::sort(out.begin(), out.end());
  return out;
}

std::vector<std::string> Plan::sensors_in_room(std::string_view id) const {
  auto it = impl_->rooms.find(id);
  if (it == impl_->rooms.end()) return {};
  return sensors_in(Area{it->second.room.shape, it->second.room.floor});
}

std::vector<std::string> Plan::rooms_at(Point p, int floor) const {
  std::vector<std::string> out;
  RoomFloor& f = impl_->rooms_of(floor);
  if (f.members.empty() || !f.bounds.contains(p)) return out;
  for (std::uint32_t i : f.cells[f.row(p.y) * f.nx + f.column(p.x)]) {
    const RoomEntry* entry = f.members[i];
    if (detail::locate(entry->prepared, p) != Location::outside) out.push_back(entry->room.id);
  }
  std::sort(out.begin(), out.end());
  return out;
}

std::vector<std::string> Plan::rooms_in(const Area& area) const {
  std::vector<std::string> out;
  if (area.shape.polygons.empty()) return out;
  detail::PreparedShape prepared = detail::prepare(area.shape);
  detail::AreaRegion region(area.shape, prepared);
  const Box& b = prepared.box;
  std::vector<int> floors;
  if (area.floor) {
    floors.push_back(*area.floor);
  } else {
    for (const auto& [floor, index] : impl_->room_floors) floors.push_back(floor);
  }
  for (int floor : floors) {
    RoomFloor& f = impl_->rooms_of(floor);
    if (f.members.empty() || !f.bounds.intersects(b)) continue;
    // A room whose box lies in the area's box has its box's lower-left corner there too, and
    // is listed in that corner's cell: visiting only that cell finds each candidate once.
    for (std::size_t r = f.row(b.ymin); r <= f.row(b.ymax); ++r) {
      for (std::size_t c = f.column(b.xmin); c <= f.column(b.xmax); ++c) {
        for (std::uint32_t i : f.cells[r * f.nx + c]) {
          const RoomEntry* entry = f.members[i];
          const Box& rb = entry->prepared.box;
          if (rb.xmin < b.xmin || rb.ymin < b.ymin || rb.xmax > b.xmax || rb.ymax > b.ymax) {
            continue;
          }
          if (f.row(rb.ymin) != r || f.column(rb.xmin) != c) continue;
          if (region.holds(entry->room.shape, entry->prepared)) out.push_back(entry->room.id);
        }
      }
    }
  }
  std::sort(out.begin(), out.end());
  return out;
}

std::vector<std::string> Plan::rooms_in_brute_force(const Area& area) const {
  std::vector<std::string> out;
  if (area.shape.polygons.empty()) return out;
  detail::PreparedShape prepared = detail::prepare(area.shape);
  detail::AreaRegion region(area.shape, prepared);
  for (const auto& [id, entry] : impl_->rooms) {
    if (area.floor && entry.room.floor != *area.floor) continue;
    if (region.holds(entry.room.shape, entry.prepared, false)) out.push_back(id);
  }
  return out;
}

std::vector<std::string> Plan::sensors_in_brute_force(const Area& area) const {
  std::vector<std::string> out;
  if (area.shape.polygons.empty()) return out;
  detail::PreparedShape prepared = detail::prepare(area.shape);
  for (const Sensor& sensor : impl_->sensors) {
    if (area.floor && sensor.floor != *area.floor) continue;
    if (detail::locate_unfiltered(prepared, sensor.at) != Location::outside) out.push_back(sensor.id);
  }
  std::sort(out.begin(), out.end());
  return out;
}

std::vector<std::string> Plan::sensors_in_scan(const Area& area) const {
  std::vector<std::string> out;
  if (area.shape.polygons.empty()) return out;
  detail::PreparedShape prepared = detail::prepare(area.shape);
  for (const Sensor& sensor : impl_->sensors) {
    if (area.floor && sensor.floor != *area.floor) continue;
    if (detail::locate(prepared, sensor.at) != Location::outside) out.push_back(sensor.id);
  }
  std::sort(out.begin(), out.end());
  return out;
}

std::vector<std::string> Plan::rooms_at_brute_force(Point p, int floor) const {
  std::vector<std::string> out;
  for (const auto& [id, entry] : impl_->rooms) {
    if (entry.room.floor != floor) continue;
    if (detail::locate_unfiltered(entry.prepared, p) != Location::outside) out.push_back(id);
  }
  return out;
}

}  // namespace tahvel::spatial
