// The floor plan read from the whiteboard, areas, listing by area and area subscriptions
// (board.h). Reading a plan is O(located features) per snapshot: homes and wards hold tens to
// thousands of them, and the plan is re-read only when a geometry or floor record changes.
#include "tahvel/spatial/board.h"

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <iterator>
#include <mutex>
#include <unordered_map>
#include <cstdio>
#include <cstring>
#include <set>

#include "tahvel/spatial/wkt.h"
#include "tahvel/uri/iri.h"

namespace tahvel::spatial {

namespace {


Unexpected<Error> store_error(const node::Error& e) { return fail(e.message); }

struct Latest {
  std::uint64_t id = 0;
  std::int64_t asserted_at = 0;
  node::Term value;
  std::uint64_t item = 0;  // histories() only
};

// The order of a plan's statements: by when they were asserted, then by arrival. A plan sent
// down from the hospital while the link was cut arrives after the home's newer one, and must
// not undo it (docs/spatial.md S6).
bool stated_before(std::int64_t asserted_a, std::uint64_t id_a, std::int64_t asserted_b, std::uint64_t id_b) {
  return asserted_a != asserted_b ? asserted_a < asserted_b : id_a < id_b;
}
bool stated_before(const Latest& a, const Latest& b) { return stated_before(a.asserted_at, a.id, b.asserted_at, b.id); }

// A statement's asserted-at, but never later than its arrival here: a writer whose clock runs
// ahead (a mote, a gateway) would otherwise win over every statement until real time caught up.
std::int64_t stated_at(const node::RecordMeta& meta) { return std::min(meta.asserted_at, meta.stored_at); }

// For every IRI subject of `predicate`: the object of its record stated last.
Result<std::map<std::string, Latest>> latest_objects(const node::Snapshot& snapshot,
                                                     const char* predicate) {
  std::map<std::string, Latest> out;
  node::Pattern pattern;
  pattern.p = node::Term::iri(predicate);
  auto read = snapshot.for_each(pattern, [&](const node::Record& r) {
    if (!r.triple.s.is_iri()) return true;
    Latest& latest = out[r.triple.s.value];
    if (latest.id == 0 || stated_before(latest.asserted_at, latest.id, stated_at(r.meta), r.meta.id))
      latest = {r.meta.id, stated_at(r.meta), r.triple.o};
    return true;
  });
  if (!read) return store_error(read.error());
  return out;
}

// parse_wkt, remembered per process by the text: the keeper, the simulator and the
// environment agent read the whole plan again at every step, and checking a ring (simple, its
// holes inside) is most of that: a self-intersecting ring of 40,000 vertices took 2.5 s to
// refuse, at each read. Bounded: forgotten all at once past kMaxRemembered texts or bytes.
Result<Geometry> parse_wkt_remembered(const std::string& text) {
  constexpr std::size_t kMaxRemembered = 4096, kMaxBytes = 64u << 20;
  static std::mutex mutex;
  static std::unordered_map<std::string, Result<Geometry>> remembered;
  static std::size_t bytes = 0;
  {
    std::lock_guard lock(mutex);
    if (auto it = remembered.find(text); it != remembered.end()) return it->second;
  }
  Result<Geometry> parsed = parse_wkt(text);
  std::lock_guard lock(mutex);
  if (remembered.size() >= kMaxRemembered || bytes + text.size() > kMaxBytes) {
    remembered.clear();
    bytes = 0;
  }
  bytes += 2 * text.size();  // the text and, roughly, its coordinates
  remembered.emplace(text, parsed);
  return parsed;
}


// The geo:asWKT of geometry `g` stated last, or nullopt; `*id` gets its record's id. An object
// that is no literal (an IRI) is returned as Term::to_ntriples gives it, `*not_literal` set.
Result<std::optional<std::string>> latest_wkt(const node::Snapshot& snapshot, const node::Term& g, std::uint64_t* id,
                                              bool* not_literal) {
  node::Pattern pattern;
  pattern.s = g;
  pattern.p = node::Term::iri(kGeoAsWkt);
  std::optional<std::string> wkt;
  std::uint64_t best = 0;
  std::int64_t best_asserted = 0;
  *not_literal = false;
  auto read = snapshot.for_each(pattern, [&](const node::Record& r) {
    if (best == 0 || stated_before(best_asserted, best, stated_at(r.meta), r.meta.id)) {
      best = r.meta.id;
      best_asserted = stated_at(r.meta);
      *not_literal = !r.triple.o.is_literal();
      wkt = *not_literal ? r.triple.o.to_ntriples() : r.triple.o.value;
    }
    return true;
  });
  if (!read) return store_error(read.error());
  *id = best;
  return wkt;
}

// A term as a map key: blank nodes apart from IRIs of the same text.
std::string key_of(const node::Term& t) { return (t.is_blank() ? "_:" : "<") + t.value; }

// Every record of `predicate` whose subject is not a literal, by subject (key_of), in the order
// they were stated.
Result<std::map<std::string, std::vector<Latest>>> histories(const node::Snapshot& snapshot, const char* predicate) {
  std::map<std::string, std::vector<Latest>> out;
  node::Pattern pattern;
  pattern.p = node::Term::iri(predicate);
  auto read = snapshot.for_each(pattern, [&](const node::Record& r) {
    if (!r.triple.s.is_literal()) out[key_of(r.triple.s)].push_back({r.meta.id, stated_at(r.meta), r.triple.o, r.meta.item});
    return true;
  });
  if (!read) return store_error(read.error());
  for (auto& [subject, records] : out)
    std::sort(records.begin(), records.end(), [](const Latest& a, const Latest& b) { return stated_before(a, b); });
  return out;
}

// A place as compared between statements: a point by its coordinates ("POINT(1 2)" and
// "Point (1.0 2.0)" are one place), any other WKT by its text.
std::string place_key(const std::string& wkt) {
  if (auto parsed = parse_wkt_remembered(wkt); parsed && std::holds_alternative<Point>(*parsed)) {
    char text[64];
    std::snprintf(text, sizeof text, "POINT %a %a", std::get<Point>(*parsed).x, std::get<Point>(*parsed).y);
    return text;
  }
  return "WKT " + wkt;
}

// Since when a feature has stood where it stands now: the first of the records stating its place
// (its geo:hasGeometry, those geometries' geo:asWKT, its tv:floor) after which the place they
// give together is today's. A restatement of the same place (a plan put again, a mote announcing
// its position, a new blank geometry with the same WKT) is no move: what the sensor wrote before
// it was written there.
//
// Readings are ordered by arrival (record id), so the records are replayed in arrival order too,
// each statement's place being the latest asserted of those arrived so far. Replayed in order of
// assertion, a position asserted before the plan's geo:hasGeometry but stored after it made the
// geo:hasGeometry record the start of today's place, and a reading stored between the old and
// the new position was credited to the new room (docs/spatial.md S8).
std::uint64_t placed_since(const std::vector<Latest>& geometry_records, const std::vector<Latest>* floor_records,
                           const std::map<std::string, std::vector<Latest>>& wkt_records) {
  enum class Kind { geometry, wkt, floor };
  struct Event {
    std::uint64_t id;
    std::int64_t asserted_at;
    Kind kind;
    const Latest* record;
    std::string geometry;  // wkt: whose
  };
  std::vector<Event> events;
  std::set<std::string> geometries;
  for (const Latest& g : geometry_records) {
    events.push_back({g.id, g.asserted_at, Kind::geometry, &g, {}});
    if (!g.value.is_literal() && geometries.insert(key_of(g.value)).second)
      if (auto it = wkt_records.find(key_of(g.value)); it != wkt_records.end())
        for (const Latest& w : it->second) events.push_back({w.id, w.asserted_at, Kind::wkt, &w, it->first});
  }
  if (floor_records)
    for (const Latest& f : *floor_records) events.push_back({f.id, f.asserted_at, Kind::floor, &f, {}});
  std::sort(events.begin(), events.end(), [](const Event& a, const Event& b) { return a.id < b.id; });
  // The latest statement of each part among those arrived so far.
  const Event* geometry = nullptr;
  const Event* floor = nullptr;
  std::map<std::string, const Event*> wkt_of;  // geometry -> its latest literal WKT so far
  auto later = [](const Event* latest, const Event& e) {
    return latest == nullptr || stated_before(latest->asserted_at, latest->id, e.asserted_at, e.id);
  };
  std::vector<std::string> places;
  for (const Event& e : events) {
    if (e.kind == Kind::geometry && later(geometry, e)) geometry = &e;
    if (e.kind == Kind::wkt && e.record->value.is_literal() && later(wkt_of[e.geometry], e)) wkt_of[e.geometry] = &e;
    if (e.kind == Kind::floor && later(floor, e)) floor = &e;
    std::string floor_text = "0";
    if (floor) {
      const auto parsed = parse_floor(floor->record->value);
      floor_text = parsed ? std::to_string(*parsed) : "?" + floor->record->value.value;
    }
    const Event* text = nullptr;
    if (geometry && !geometry->record->value.is_literal())
      if (auto it = wkt_of.find(key_of(geometry->record->value)); it != wkt_of.end()) text = it->second;
    // The place an item states, after all of its records: a new geometry and its WKT come in one.
    places.push_back((text ? place_key(text->record->value.value) : std::string("none")) + "\n" + floor_text);
  }
  std::size_t first = places.size();
  while (first > 0 && (places[first - 1] == places.back() ||
                       (first < places.size() && events[first - 1].record->item == events[first].record->item)))
    --first;
  // Readings are ordered by arrival: those after the first record that stated today's place
  // were taken there.
  return first < events.size() ? events[first].id : 0;
}

// True when `source` is one of `sensors` or lies under one (a sensor that is a node of its own,
// whose agents write under its IRI): the ancestors of an IRI are its prefixes ending before a
// '/', '#' or '?', so each is looked up rather than every sensor tested.
// Returns that sensor, or null.
const std::string* sensor_of(const std::set<std::string>& sensors, const std::string& source) {
  if (auto it = sensors.find(source); it != sensors.end()) return &*it;
  for (std::size_t i = source.find_first_of("/#?"); i != std::string::npos; i = source.find_first_of("/#?", i + 1)) {
    auto it = sensors.find(source.substr(0, i));
    if (it != sensors.end() && uri::is_under(source, *it)) return &*it;
  }
  return nullptr;
}

}  // namespace

std::optional<int> parse_floor(const node::Term& term) {
  if (!term.is_literal()) return std::nullopt;
  const std::string& text = term.value;
  int value = 0;
  const char* begin = text.data() + (!text.empty() && text[0] == '+' ? 1 : 0);
  auto [end, ec] = std::from_chars(begin, text.data() + text.size(), value);
  if (ec == std::errc() && end == text.data() + text.size() && begin != end) {
    if (value < -1'000'000'000 || value > 1'000'000'000) return std::nullopt;  // std::abs(INT_MIN) is undefined
    return value;
  }
  // A whole number written as a decimal or double ("1.0", "2e0") is that floor, as "1" is.
  double number = 0;
  auto [stop, error] = std::from_chars(begin, text.data() + text.size(), number);
  if (error != std::errc() || stop != text.data() + text.size() || begin == stop || !std::isfinite(number) ||
      number != std::floor(number) || std::abs(number) > 1e9)
    return std::nullopt;
  return static_cast<int>(number);
}

Result<BoardPlan> load_plan(const node::Snapshot& snapshot) {
  auto geometries = latest_objects(snapshot, kGeoHasGeometry);
  if (!geometries) return unexpected(geometries.error());
  auto floors = latest_objects(snapshot, kTvFloor);
  if (!floors) return unexpected(floors.error());
  auto geometry_history = histories(snapshot, kGeoHasGeometry);
  if (!geometry_history) return unexpected(geometry_history.error());
  auto floor_history = histories(snapshot, kTvFloor);
  if (!floor_history) return unexpected(floor_history.error());
  auto wkt_history = histories(snapshot, kGeoAsWkt);
  if (!wkt_history) return unexpected(wkt_history.error());
  BoardPlan out;
  for (const auto& [feature, geometry] : *geometries) {
    int floor = 0;
    if (auto it = floors->find(feature); it != floors->end()) {
      auto parsed = parse_floor(it->second.value);
      if (!parsed) {
        out.problems.push_back(feature + ": tv:floor '" + it->second.value.value + "' is not a whole number within ±1e9");
        continue;
      }
      floor = *parsed;
    }
    if (geometry.value.is_literal()) {
      out.problems.push_back(feature + ": geo:hasGeometry must name a geometry, not a literal");
      continue;
    }
    std::uint64_t wkt_id = 0;
    bool not_literal = false;
    auto wkt = latest_wkt(snapshot, geometry.value, &wkt_id, &not_literal);
    if (!wkt) return unexpected(wkt.error());
    if (!*wkt) {
      // Not located: said, as a malformed place is. A sensor moved in two puts (its new
      // geo:hasGeometry, then that geometry's WKT) is in no area in between, and a room drawn so
      // was "no room on the board" though it has a geo:hasGeometry.
      out.problems.push_back(feature + ": its geometry " + geometry.value.to_ntriples() +
                             " has no geo:asWKT (yet): in no area until it has one");
      continue;
    }
    // Skipped without a word, the feature was "no room on the board" to whoever named it.
    if (not_literal) {
      out.problems.push_back(feature + ": geo:asWKT of " + geometry.value.to_ntriples() + " must be a WKT literal, not " + **wkt);
      continue;
    }
    const auto floor_records = floor_history->find("<" + feature);
    out.placed_by[feature] = placed_since(geometry_history->at("<" + feature),
                                          floor_records == floor_history->end() ? nullptr : &floor_records->second, *wkt_history);
    auto parsed = parse_wkt_remembered(**wkt);
    if (!parsed) {
      out.problems.push_back(feature + ": " + parsed.error().message);
      continue;
    }
    Result<void> put = std::holds_alternative<Point>(*parsed)
                           ? out.plan.put_sensor({feature, floor, std::get<Point>(*parsed)})
                           : out.plan.put_room({feature, floor, std::get<Shape>(*parsed)});
    if (!put) out.problems.push_back(feature + ": " + put.error().message);
  }
  return out;
}

node::Item located_feature_item(const std::string& feature_iri, const std::string& wkt, int floor) {
  const std::string geometry = feature_iri + "/geometry";
  node::Item item;
  item.persistent = true;
  item.add(node::Term::iri(feature_iri), node::Term::iri(kGeoHasGeometry), node::Term::iri(geometry))
      .add(node::Term::iri(geometry), node::Term::iri(kGeoAsWkt),
           node::Term::literal(wkt, kGeoWktLiteral))
      .add(node::Term::iri(feature_iri), node::Term::iri(kTvFloor), node::Term::integer(floor));
  return item;
}

bool looks_like_wkt(std::string_view text) {
  std::size_t i = 0;
  auto skip_space = [&] {
    while (i < text.size() && std::isspace(static_cast<unsigned char>(text[i]))) ++i;
  };
  skip_space();
  if (i < text.size() && text[i] == '<') {
    std::size_t close = text.find('>', i);
    if (close == std::string_view::npos) return false;
    std::size_t after = close + 1;
    // "<iri>" alone is an IRI; "<crs> POINT(...)" is WKT.
    i = after;
    skip_space();
    if (i >= text.size()) return false;
  }
  std::size_t start = i;
  while (i < text.size() && std::isalpha(static_cast<unsigned char>(text[i]))) ++i;
  if (i == start || (i < text.size() && text[i] == ':')) return false;
  // Only an OGC geometry type starts WKT: "kitchen" is a (relative, so refused) IRI, not WKT.
  std::string word(text.substr(start, i - start));
  for (char& c : word) c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
  static const std::set<std::string> kTypes = {
      "POINT", "LINESTRING", "POLYGON", "MULTIPOINT", "MULTILINESTRING", "MULTIPOLYGON",
      "GEOMETRYCOLLECTION", "TRIANGLE", "TIN", "POLYHEDRALSURFACE", "CIRCULARSTRING",
      "COMPOUNDCURVE", "CURVEPOLYGON", "MULTICURVE", "MULTISURFACE"};
  if (kTypes.count(word) > 0) return true;
  // A dimension written against the type ("POLYGONZ"), or EWKT's "SRID=4326;POLYGON(...)": WKT
  // that the parser refuses with the reason, not an IRI with white space in it.
  for (const char* suffix : {"ZM", "Z", "M"})
    if (word.ends_with(suffix) && kTypes.count(word.substr(0, word.size() - std::strlen(suffix))) > 0) return true;
  return word == "SRID" && i < text.size() && text[i] == '=';
}

Result<Area> resolve_area(const BoardPlan& board, const AreaSpec& spec) {
  if (!spec.room_iri.empty()) {
    const Room* room = board.plan.room(spec.room_iri);
    if (!room) {
      // On the board but skipped by the plan (a malformed WKT or floor): say why.
      const std::string prefix = spec.room_iri + ": ";
      for (const std::string& problem : board.problems)
        if (problem.rfind(prefix, 0) == 0) return fail(spec.room_iri + " cannot be used as an area (its place cannot be read): " + problem.substr(prefix.size()));
      if (board.plan.sensor(spec.room_iri))
        return fail(spec.room_iri + " is a sensor (its geo:asWKT is a POINT), not a room");
      return fail("no room " + spec.room_iri +
                  " on the board (a feature with geo:hasGeometry whose geo:asWKT is a POLYGON or "
                  "MULTIPOLYGON)");
    }
    return Area{room->shape, room->floor};
  }
  if (!spec.shape) return fail("an area needs a room IRI or a shape");
  return Area{*spec.shape, spec.floor};
}

std::vector<std::string> features_in(const Plan& plan, const AreaSpec& spec, const Area& area) {
  std::vector<std::string> out = plan.sensors_in(area);
  std::vector<std::string> rooms = plan.rooms_in(area);
  // The room named as the area lies in it (rooms_in finds it); kept explicitly all the same.
  if (!spec.room_iri.empty() && plan.room(spec.room_iri) &&
      !std::binary_search(rooms.begin(), rooms.end(), spec.room_iri)) {
    rooms.insert(std::lower_bound(rooms.begin(), rooms.end(), spec.room_iri), spec.room_iri);
  }
  std::vector<std::string> merged;
  merged.reserve(out.size() + rooms.size());
  std::set_union(out.begin(), out.end(), rooms.begin(), rooms.end(), std::back_inserter(merged));
  return merged;
}

Result<std::vector<node::Record>> list_in_area(const node::Snapshot& snapshot,
                                               const node::Pattern& pattern, const AreaSpec& spec,
                                               const node::ListOptions& options,
                                               std::vector<std::string>* skipped) {
  auto board = load_plan(snapshot);
  if (!board) return unexpected(board.error());
  if (skipped) *skipped = board->problems;
  auto area = resolve_area(*board, spec);
  if (!area) return unexpected(area.error());
  const std::vector<std::string> located = features_in(board->plan, spec, *area);
  const std::set<std::string> features(located.begin(), located.end());
  const std::vector<std::string> sensor_list = board->plan.sensors_in(*area);
  const std::set<std::string> sensors(sensor_list.begin(), sensor_list.end());

  std::vector<node::Record> matches;
  auto read = snapshot.for_each(pattern, [&](const node::Record& r) {
    if (r.triple.s.is_iri() && features.count(r.triple.s.value)) {
      matches.push_back(r);
    } else if (const std::string* sensor = sensor_of(sensors, r.meta.source)) {
      // What a sensor wrote before its place was last stated, it wrote standing elsewhere (it
      // was carried here since): listed in no area, as the environment agent counts it (S12),
      // or a room would list another room's readings.
      const auto placed = board->placed_by.find(*sensor);
      if (placed == board->placed_by.end() || r.meta.id > placed->second) matches.push_back(r);
    }
    return true;
  });
  if (!read) return store_error(read.error());

  // Cascade and limit as Snapshot::list applies them: each match followed by its sub-tree,
  // each record once.
  std::vector<node::Record> out;
  std::set<std::uint64_t> seen;
  auto full = [&] { return options.limit != 0 && out.size() >= options.limit; };
  for (node::Record& match : matches) {
    if (full()) break;
    if (!seen.insert(match.meta.id).second) continue;
    out.push_back(match);
    if (options.cascade == 0 || match.triple.o.is_literal()) continue;
    node::Pattern below;
    below.s = match.triple.o;
    auto tree = snapshot.list(below, {options.cascade - 1, 0});
    if (!tree) return store_error(tree.error());
    for (node::Record& r : *tree) {
      if (full()) break;
      if (seen.insert(r.meta.id).second) out.push_back(std::move(r));
    }
  }
  return out;
}

}  // namespace tahvel::spatial
