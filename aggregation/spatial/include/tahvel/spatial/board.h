// Areas on the whiteboard (docs/spatial.md): the floor plan as GeoSPARQL triples read from a
// snapshot, areas named by a room's IRI or by WKT, the records located in an area (`tahvel list
// --area`). Area subscriptions, which follow sensors as they are added or moved, are in
// area_subscriptions.h.
//
// Triples read (vocabulary: docs/vocabulary.md, "Spatial"):
//   <feature> geo:hasGeometry <g> .   <g> geo:asWKT "POLYGON((...))"^^geo:wktLiteral .
//   <feature> tv:floor 1 .            (xsd:integer; absent: floor 0)
// A feature whose geometry is a POLYGON or MULTIPOLYGON is a room (an area); one whose geometry
// is a POINT is a sensor (a located thing). When a feature has several geo:hasGeometry records,
// or a geometry several geo:asWKT records, or a feature several tv:floor records, the one stated
// last wins (the latest asserted-at, taken as no later than its arrival; then the highest record
// id): moving a sensor is writing its new geometry.
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
  // Features skipped because their WKT is malformed or their tv:floor is not a whole number within ±1e9, one
  // line each ("<iri>: WKT column 9: ring is not closed ..."). The rest of the plan stands.
  std::vector<std::string> problems;
  // Per located feature, the id of the record from which on the records stating its place
  // (geo:hasGeometry, those geometries' geo:asWKT, tv:floor) have given the place it has now:
  // what was stored before it was stored while the feature stood elsewhere. A place stated again
  // unchanged (a point however written, a new geometry with the same WKT) does not move it.
  std::map<std::string, std::uint64_t> placed_by;
};

// A floor as written on the board (tv:floor, tv:areaFloor): a whole number however written ("1",
// "+1", "1.0", "2e0") within ±1e9; nullopt for anything else (a fraction, text, a value that
// would not fit).
std::optional<int> parse_floor(const node::Term& term);

// Reads every located feature of `snapshot`. Errors: only the store's (reading failed).
Result<BoardPlan> load_plan(const node::Snapshot& snapshot);

// The items that state a feature's place, for writers (the simulator, the demo, tests): the
// feature's geo:hasGeometry to <feature>/geometry, that geometry's geo:asWKT literal, and
// tv:floor. Persistent: a plan is configuration, not a reading.
node::Item located_feature_item(const std::string& feature_iri, const std::string& wkt, int floor);

// True when `text` reads as WKT rather than as an IRI or CURIE: after spaces and an optional
// "<crs>", an OGC geometry type in any case, not followed by ':' ("POLYGON((...", "point (1 2)";
// not "kitchen", "ex:kitchen" or "<http://…/kitchen>").
bool looks_like_wkt(std::string_view text);

// What an area names: a room on the board (kept by IRI, so that redrawing the room moves the
// area), or a fixed shape (WKT) on one floor or on all.
struct AreaSpec {
  std::string room_iri;          // set: the room's shape and floor
  std::optional<Shape> shape;    // else: this shape
  std::optional<int> floor;      // with a shape: its floor (unset: every floor)
};

// The area `spec` names on `board`. Error: the room is not on the board, or is there with a
// place the plan cannot use (its problem line), or is not a polygon.
Result<Area> resolve_area(const BoardPlan& board, const AreaSpec& spec);

// The features located in `area`: the sensors inside it (closed, plan.h) and the polygon
// features (rooms, zones, furniture...) lying in it (Plan::rooms_in: closed, a shared wall is
// in, a crossing is not; docs/spatial.md S14), which include the room when the area is a room.
// Sorted IRIs.
std::vector<std::string> features_in(const Plan& plan, const AreaSpec& spec, const Area& area);

// The records matching `pattern` whose subject is a feature located in the area or whose source
// is a sensor located there (or a writer under one: uri::is_under), in id order, with the cascade and limit of `options` applied to
// those matches (as Snapshot::list does). Errors: the store's, or resolve_area's. Features the
// plan skipped (BoardPlan::problems: in no area, whatever their place) go to `*skipped` if given.
Result<std::vector<node::Record>> list_in_area(const node::Snapshot& snapshot,
                                               const node::Pattern& pattern, const AreaSpec& spec,
                                               const node::ListOptions& options = {},
                                               std::vector<std::string>* skipped = nullptr);

}  // namespace tahvel::spatial
