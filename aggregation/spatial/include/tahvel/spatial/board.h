// Areas on the whiteboard (docs/spatial.md): the floor plan as GeoSPARQL triples read from a
// snapshot, areas named by a room's IRI or by WKT, the records located in an area (`tahvel list
// --area`), and area subscriptions that follow sensors as they are added or moved.
//
// Triples read (vocabulary: docs/vocabulary.md, "Spatial"):
//   <feature> geo:hasGeometry <g> .   <g> geo:asWKT "POLYGON((...))"^^geo:wktLiteral .
//   <feature> tv:floor 1 .            (xsd:integer; absent: floor 0)
// A feature whose geometry is a POLYGON or MULTIPOLYGON is a room (an area); one whose geometry
// is a POINT is a sensor (a located thing). When a feature has several geo:hasGeometry records,
// or a geometry several geo:asWKT records, or a feature several tv:floor records, the one with
// the highest record id wins: moving a sensor is writing its new geometry.
//
// Errors name the feature or the text and, for WKT, the column.
#pragma once

#include <chrono>
#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "tahvel/node/node.h"
#include "tahvel/spatial/error.h"
#include "tahvel/spatial/plan.h"

namespace tahvel::spatial {

inline constexpr const char* kGeo = "http://www.opengis.net/ont/geosparql#";
inline constexpr const char* kGeoHasGeometry = "http://www.opengis.net/ont/geosparql#hasGeometry";
inline constexpr const char* kGeoAsWkt = "http://www.opengis.net/ont/geosparql#asWKT";
inline constexpr const char* kGeoWktLiteral = "http://www.opengis.net/ont/geosparql#wktLiteral";
inline constexpr const char* kTvFloor = "https://w3id.org/tahvel#floor";
inline constexpr const char* kSosaMadeBySensor = "http://www.w3.org/ns/sosa/madeBySensor";

// The located features of one snapshot, as a Plan: rooms (polygon features) and sensors (point
// features), ids = their IRIs.
struct BoardPlan {
  Plan plan;
  // Features skipped because their WKT is malformed or their tv:floor is not an integer, one
  // line each ("<iri>: WKT column 9: ring is not closed ..."). The rest of the plan stands.
  std::vector<std::string> problems;
};

// Reads every located feature of `snapshot`. Errors: only the store's (reading failed).
Result<BoardPlan> load_plan(const node::Snapshot& snapshot);

// The items that state a feature's place, for writers (the simulator, the demo, tests): the
// feature's geo:hasGeometry to <feature>/geometry, that geometry's geo:asWKT literal, and
// tv:floor. Persistent: a plan is configuration, not a reading.
node::Item located_feature_item(const std::string& feature_iri, const std::string& wkt, int floor);

// True when `text` reads as WKT rather than as an IRI or CURIE: after spaces and an optional
// "<crs>", a word of letters not followed by ':' ("POLYGON((...", "point (1 2)").
bool looks_like_wkt(std::string_view text);

// What an area names: a room on the board (kept by IRI, so that redrawing the room moves the
// area), or a fixed shape (WKT) on one floor or on all.
struct AreaSpec {
  std::string room_iri;          // set: the room's shape and floor
  std::optional<Shape> shape;    // else: this shape
  std::optional<int> floor;      // with a shape: its floor (unset: every floor)
};

// The area `spec` names in `plan`. Error: the room is not on the board (or has no polygon).
Result<Area> resolve_area(const Plan& plan, const AreaSpec& spec);

// The features located in `area`: the sensors inside it (closed, plan.h) and the polygon
// features (rooms, zones, furniture...) lying in it (Plan::rooms_in: closed, a shared wall is
// in, a crossing is not; docs/spatial.md S14), which include the room when the area is a room.
// Sorted IRIs.
std::vector<std::string> features_in(const Plan& plan, const AreaSpec& spec, const Area& area);

// The records matching `pattern` whose subject is a feature located in the area or whose source
// is a sensor located there, in id order, with the cascade and limit of `options` applied to
// those matches (as Snapshot::list does). Errors: the store's, or resolve_area's.
Result<std::vector<node::Record>> list_in_area(const node::Snapshot& snapshot,
                                               const node::Pattern& pattern, const AreaSpec& spec,
                                               const node::ListOptions& options = {});

// An agent's subscription to an area: one node subscription {p = sosa:madeBySensor, o = sensor}
// per sensor located in the area, kept current as sensors are added, moved or removed and as
// the room is redrawn. Readings reach the agent when they name their sensor with
// sosa:madeBySensor. The AreaSubscription owns the agent's madeBySensor subscriptions: it
// removes those of sensors that are not (or no longer) in the area, also ones left by an earlier
// run. One per agent.
class AreaSubscription {
 public:
  // Subscribes `agent` (of `node`) to the sensors of `spec` as the board places them now.
  // `node` and `agent` are borrowed: both must outlive the AreaSubscription.
  // Errors: the store's; the room of `spec` is not on the board (nothing is changed then).
  static Result<AreaSubscription> open(const node::Node& node, node::Agent& agent, AreaSpec spec);

  // Reads the change stream since the last call (waiting up to `wait` for a change); when a
  // geo:asWKT, geo:hasGeometry or tv:floor record was stored or removed, re-reads the plan and
  // subscribes/unsubscribes the difference. Returns true when the set of sensors changed.
  // Call it before taking readings, or from the agent's loop.
  Result<bool> refresh(std::chrono::milliseconds wait = std::chrono::milliseconds(0));

  // The sensors subscribed to now, sorted.
  std::vector<std::string> sensors() const;

 private:
  AreaSubscription(const node::Node& node, node::Agent& agent, AreaSpec spec);
  Result<bool> sync();

  const node::Node* node_;
  node::Agent* agent_;
  AreaSpec spec_;
  std::uint64_t bookmark_ = 0;
  std::map<std::string, std::uint64_t> subscriptions_;  // sensor IRI -> subscription item
};

}  // namespace tahvel::spatial
