// Areas on the whiteboard (tahvel/spatial/board.h, area_subscriptions.h), on a real store in a
// temporary directory: the plan read from GeoSPARQL triples (latest wins), listing by area, and
// area subscriptions following a sensor that moves from one room to another, kept by the agent
// itself or by the node's keeper.
#include "tahvel/spatial/board.h"
#include "tahvel/spatial/area_subscriptions.h"
#include "tahvel/spatial/environment_board.h"

#include <stdlib.h>

#include <chrono>
#include <filesystem>
#include <limits>
#include <set>

#include <gtest/gtest.h>

#include "tahvel/spatial/wkt.h"
#include "temp_dir.h"

namespace tahvel::spatial {
namespace {

namespace fs = std::filesystem;
using Ids = std::vector<std::string>;
using node::Term;

const std::string kHome = "http://example.org/home1";
const std::string kBedroom = kHome + "/room/bedroom";
const std::string kHall = kHome + "/room/hall";
const std::string kUpstairs = kHome + "/room/study";
const std::string kMote = kHome + "/mote1";
const std::string kMote2 = kHome + "/mote2";

class BoardTest : public testing::Test {
 protected:
  void SetUp() override {
    auto node = node::Node::init(dir_ / "store", {.iri = kHome});
    ASSERT_TRUE(node.has_value()) << node.error().message;
    node_.emplace(std::move(*node));
    auto plan = node_->agent("plan");
    ASSERT_TRUE(plan.has_value());
    plan_.emplace(std::move(*plan));
    // An L-shaped (concave) bedroom and a hall sharing its edge x = 4, a study upstairs.
    put(located_feature_item(kBedroom, "POLYGON((0 0, 4 0, 4 2, 2 2, 2 4, 0 4, 0 0))", 0));
    put(located_feature_item(kHall, "POLYGON((4 0, 8 0, 8 2, 4 2, 4 0))", 0));
    put(located_feature_item(kUpstairs, "POLYGON((0 0, 4 0, 4 4, 0 4, 0 0))", 1));
    put(located_feature_item(kMote, "POINT(1 1)", 0));       // in the bedroom
    put(located_feature_item(kMote2, "POINT(1 1)", 1));      // same x y, upstairs
  }
  void TearDown() override {
    plan_.reset();
    node_.reset();
  }

  static Term tv(const std::string& local) { return Term::iri("https://w3id.org/tahvel#" + local); }
  // Adds to `item` a declaration, as a file written by hand states one: blank node `label`
  // subscribes `subscriber` to `area` (a room's IRI or a WKT literal). Returns the item, for
  // more about it.
  static node::Item& declare(node::Item& item, const std::string& label, const Term& subscriber, const Term& area) {
    return item.add(Term::blank(label), tv("areaSubscriber"), subscriber).add(Term::blank(label), tv("area"), area);
  }

  // Stores `declarations` as an operator's file is put, then opens the area keeper on the store;
  // `first` gets the report of its first sync.
  Result<AreaKeeper> keep(const node::Item& declarations, AreaSyncReport& first) {
    auto writer = node_->agent("operator");
    EXPECT_TRUE(writer.has_value());
    EXPECT_TRUE(writer->store(declarations).has_value());
    return AreaKeeper::open(dir_ / "store", &first);
  }

  void put(const node::Item& item) {
    auto stored = plan_->store(item);
    ASSERT_TRUE(stored.has_value()) << stored.error().message;
  }

  // A reading of `sensor`, written by the sensor's own agent (its IRI is its source).
  void reading(const std::string& sensor_id, double celsius) {
    auto agent = node_->agent(sensor_id);
    ASSERT_TRUE(agent.has_value());
    node::Item item;
    item.add(Term::blank("o"), Term::iri(kSosaMadeBySensor), Term::iri(kHome + "/" + sensor_id))
        .add(Term::blank("o"), Term::iri("http://www.w3.org/ns/sosa/hasSimpleResult"),
             Term::literal(std::to_string(celsius), std::string(node::xsd::kDecimal)));
    ASSERT_TRUE(agent->store(item).has_value());
  }

  BoardPlan plan() {
    auto snapshot = node_->snapshot();
    EXPECT_TRUE(snapshot.has_value());
    auto board = load_plan(*snapshot);
    EXPECT_TRUE(board.has_value());
    return std::move(*board);
  }

  std::vector<node::Record> in_area(const AreaSpec& spec, node::Pattern pattern = {}) {
    auto snapshot = node_->snapshot();
    EXPECT_TRUE(snapshot.has_value());
    auto records = list_in_area(*snapshot, pattern, spec);
    EXPECT_TRUE(records.has_value()) << records.error().message;
    return records ? *records : std::vector<node::Record>{};
  }

  // The pattern of readings (a moved sensor's new geometry has the sensor as subject: selected
  // by an area subscription without a pattern, as `tahvel list --area` selects it).
  static node::Pattern readings() {
    node::Pattern p;
    p.p = Term::iri("http://www.w3.org/ns/sosa/hasSimpleResult");
    return p;
  }

  std::uint64_t pending(node::Agent& agent) {
    auto n = agent.pending();
    EXPECT_TRUE(n.has_value());
    return n ? *n : 0;
  }

  tahvel::test_support::TempDir tmp_{"tahvel-spatial"};
  const fs::path dir_ = tmp_.path();
  std::optional<node::Node> node_;
  std::optional<node::Agent> plan_;
};

TEST_F(BoardTest, PlanFromGeoSparqlTriples) {
  BoardPlan board = plan();
  EXPECT_TRUE(board.problems.empty());
  EXPECT_EQ(board.plan.room_count(), 3u);
  EXPECT_EQ(board.plan.sensor_count(), 2u);
  EXPECT_EQ(board.plan.sensors_in_room(kBedroom), Ids{kMote});
  EXPECT_EQ(board.plan.sensors_in_room(kUpstairs), Ids{kMote2});
  EXPECT_EQ(board.plan.rooms_at({4, 1}, 0), (Ids{kBedroom, kHall}));
}

TEST_F(BoardTest, LatestGeometryWinsAndMalformedWktIsReportedNotFatal) {
  put(located_feature_item(kMote, "POINT(6 1)", 0));  // moved into the hall
  put(located_feature_item(kHome + "/broken", "POLYGON((0 0, 1 0, 1 1))", 0));
  BoardPlan board = plan();
  EXPECT_EQ(board.plan.sensors_in_room(kHall), Ids{kMote});
  EXPECT_EQ(board.plan.sensors_in_room(kBedroom), Ids{});
  ASSERT_EQ(board.problems.size(), 1u);
  EXPECT_NE(board.problems[0].find(kHome + "/broken: WKT column 9: a ring needs at least 4 points"),
            std::string::npos)
      << board.problems[0];
}

// A geometry whose geo:asWKT is an IRI (`<POLYGON>`, angle brackets where quotes belong) was
// skipped without a word: naming the room then said only that it is not on the board.
TEST_F(BoardTest, AGeometryWhoseWktIsAnIriIsReportedNotSkippedSilently) {
  const std::string room = kHome + "/room/iri";
  node::Item item;
  item.persistent = true;
  item.add(Term::iri(room), Term::iri(kGeoHasGeometry), Term::iri(room + "/g"))
      .add(Term::iri(room + "/g"), Term::iri(kGeoAsWkt), Term::iri(kHome + "/POLYGON"));
  put(item);
  BoardPlan board = plan();
  EXPECT_EQ(board.plan.room(room), nullptr);
  ASSERT_EQ(board.problems.size(), 1u);
  EXPECT_EQ(board.problems[0], room + ": geo:asWKT of <" + room + "/g> must be a WKT literal, not <" + kHome + "/POLYGON>");
}

// A floor is a whole number however it is written: "2" was one and "1.0" was refused.
TEST_F(BoardTest, AFloorWrittenAsAWholeDecimalIsThatFloorAndAFractionIsReported) {
  auto with_floor = [](const std::string& feature, Term floor) {
    node::Item item = located_feature_item(feature, "POINT(4 1)", 0);
    std::erase_if(item.triples, [](const node::Triple& t) { return t.p.value == kTvFloor; });
    item.add(Term::iri(feature), Term::iri(kTvFloor), std::move(floor));
    return item;
  };
  put(with_floor(kHome + "/m-decimal", Term::literal("1.0", "http://www.w3.org/2001/XMLSchema#decimal")));
  put(with_floor(kHome + "/m-double", Term::literal("1e0", "http://www.w3.org/2001/XMLSchema#double")));
  put(with_floor(kHome + "/m-half", Term::literal("1.5", "http://www.w3.org/2001/XMLSchema#decimal")));
  // A whole number out of range was said to be "not an integer", which sent the author to the
  // wrong fix.
  put(with_floor(kHome + "/m-high", Term::integer(2'000'000'000)));
  BoardPlan board = plan();
  EXPECT_EQ(board.plan.sensor(kHome + "/m-decimal")->floor, 1);
  EXPECT_EQ(board.plan.sensor(kHome + "/m-double")->floor, 1);
  EXPECT_EQ(board.plan.sensor(kHome + "/m-half"), nullptr);
  EXPECT_EQ(board.plan.sensor(kHome + "/m-high"), nullptr);
  ASSERT_EQ(board.problems.size(), 2u);
  std::sort(board.problems.begin(), board.problems.end());
  EXPECT_NE(board.problems[0].find("tv:floor '1.5' is not a whole number within ±1e9"), std::string::npos) << board.problems[0];
  EXPECT_NE(board.problems[1].find("tv:floor '2000000000' is not a whole number within ±1e9"), std::string::npos)
      << board.problems[1];
}

TEST_F(BoardTest, ListByRoomSelectsTheRoomItsSensorsAndTheirReadings) {
  reading("mote1", 21.5);
  reading("mote2", 18.0);
  std::vector<node::Record> records = in_area({kBedroom, std::nullopt, std::nullopt});
  std::set<std::string> subjects, sources;
  for (const auto& r : records) {
    subjects.insert(r.triple.s.value);
    sources.insert(r.meta.source);
  }
  EXPECT_TRUE(subjects.count(kBedroom));
  EXPECT_TRUE(subjects.count(kMote));
  EXPECT_FALSE(subjects.count(kMote2));  // upstairs
  EXPECT_FALSE(subjects.count(kHall));
  EXPECT_TRUE(sources.count(kMote));     // the bedroom mote's reading
  EXPECT_FALSE(sources.count(kMote2));
  // The reading's two triples (source mote1) and the bedroom's and mote1's own triples.
  std::size_t readings = 0;
  for (const auto& r : records) readings += r.meta.source == kMote;
  EXPECT_EQ(readings, 2u);
}

// A mote carried from the bedroom into the hall: the hall listed the reading it took in the
// bedroom, since the plan says only where it stands now. As the environment agent counts it
// (S12), what it wrote before its place was last stated is in no area.
TEST_F(BoardTest, AReadingTakenBeforeASensorWasMovedIsNotListedWhereItStandsNow) {
  reading("mote1", 21.0);
  EXPECT_EQ(in_area({kBedroom, std::nullopt, std::nullopt}, readings()).size(), 1u);
  put(located_feature_item(kMote, "POINT(6 1)", 0));  // carried into the hall
  EXPECT_EQ(in_area({kHall, std::nullopt, std::nullopt}, readings()).size(), 0u);
  EXPECT_EQ(in_area({kBedroom, std::nullopt, std::nullopt}, readings()).size(), 0u);
  reading("mote1", 22.0);
  auto hall = in_area({kHall, std::nullopt, std::nullopt}, readings());
  ASSERT_EQ(hall.size(), 1u);
  EXPECT_EQ(hall.front().triple.o.value, std::to_string(22.0));
  // The mote's own triples (its place) are still listed with it: they are not readings.
  EXPECT_FALSE(in_area({kHall, std::nullopt, std::nullopt}, node::Pattern{.s = Term::iri(kMote)}).empty());
}

// The plan put again, or a mote announcing where it stands (a new blank geometry, the same point
// written otherwise, its floor stated again): no move. Each such restatement took every earlier
// reading out of the room, and the environment agent called the room unknown.
TEST_F(BoardTest, APlaceStatedAgainUnchangedKeepsTheReadingsTakenThere) {
  reading("mote1", 21.0);
  put(located_feature_item(kMote, "POINT(1 1)", 0));
  node::Item announced;
  const Term geometry = Term::blank("g");
  announced.add(Term::iri(kMote), Term::iri(kGeoHasGeometry), geometry)
      .add(geometry, Term::iri(kGeoAsWkt), Term::literal("Point (1.0 1.0)", kGeoWktLiteral))
      .add(Term::iri(kMote), Term::iri(kTvFloor), Term::literal("0.0", "http://www.w3.org/2001/XMLSchema#decimal"));
  put(announced);
  EXPECT_EQ(in_area({kBedroom, std::nullopt, std::nullopt}, readings()).size(), 1u);
  // Carried into the hall and back: what it wrote before is still not the bedroom's.
  put(located_feature_item(kMote, "POINT(6 1)", 0));
  put(located_feature_item(kMote, "POINT(1 1)", 0));
  EXPECT_EQ(in_area({kBedroom, std::nullopt, std::nullopt}, readings()).size(), 0u);
  reading("mote1", 22.0);
  put(located_feature_item(kMote, "POINT(1 1)", 0));
  EXPECT_EQ(in_area({kBedroom, std::nullopt, std::nullopt}, readings()).size(), 1u);
  // Upstairs at the same x and y is another place.
  put(located_feature_item(kMote, "POINT(1 1)", 1));
  EXPECT_EQ(in_area({kBedroom, std::nullopt, std::nullopt}, readings()).size(), 0u);
}

// A plan statement is ordered by when it was asserted: one sent down from the hospital while the
// link was cut, and so stored after the home's newer one, does not move the sensor back.
TEST_F(BoardTest, APlaceAssertedEarlierButStoredLaterDoesNotUndoANewerOne) {
  const std::string mote = kHome + "/mote3";
  const std::int64_t now = std::chrono::duration_cast<std::chrono::nanoseconds>(
                              std::chrono::system_clock::now().time_since_epoch()).count();
  const std::int64_t hour = 3600'000'000'000;
  node::Item sent_down = located_feature_item(mote, "POINT(6 1)", 0);  // the hall
  sent_down.asserted_at = now - 2 * hour;
  node::Item put_at_home = located_feature_item(mote, "POINT(1 1)", 0);  // the bedroom
  put_at_home.asserted_at = now - hour;
  put(put_at_home);
  reading("mote3", 21.0);
  put(sent_down);
  EXPECT_EQ(plan().plan.sensors_in_room(kBedroom), (Ids{kMote, mote}));
  // The late statement of another place is no move: the reading stays the bedroom's.
  node::Pattern of_mote3 = readings();
  of_mote3.source = mote;
  EXPECT_EQ(in_area({kBedroom, std::nullopt, std::nullopt}, of_mote3).size(), 1u);
}

// A writer whose clock runs an hour ahead does not win over every later statement until that
// hour has passed: a statement counts as asserted no later than it arrived.
TEST_F(BoardTest, APlaceAssertedAheadOfItsArrivalCountsAsAssertedOnArrival) {
  const std::string mote = kHome + "/mote4";
  node::Item ahead = located_feature_item(mote, "POINT(6 1)", 0);  // the hall
  ahead.asserted_at = std::chrono::duration_cast<std::chrono::nanoseconds>(
                          (std::chrono::system_clock::now() + std::chrono::hours(1)).time_since_epoch()).count();
  put(ahead);
  put(located_feature_item(mote, "POINT(1 1)", 0));  // then the bedroom, asserted now
  EXPECT_EQ(plan().plan.sensors_in_room(kBedroom), (Ids{kMote, mote}));
}

// A locator that writes a mote's position as of its fix, a few seconds back, after the plan
// linked the mote to its geometry: the positions were replayed by when they were asserted, so the
// plan's later geo:hasGeometry looked like the start of today's place, and a reading stored
// between the old position and the new one was credited to the new room.
TEST_F(BoardTest, AReadingStoredBeforeAMoveAssertedInThePastIsNotCreditedToTheNewRoom) {
  const std::string mote = kHome + "/mote5";
  const Term geometry = Term::iri(mote + "/geometry");
  const std::int64_t now = std::chrono::duration_cast<std::chrono::nanoseconds>(
                              std::chrono::system_clock::now().time_since_epoch()).count();
  const std::int64_t second = 1'000'000'000;
  node::Item linked;
  linked.add(Term::iri(mote), Term::iri(kGeoHasGeometry), geometry)
      .add(Term::iri(mote), Term::iri(kTvFloor), Term::integer(0));
  put(linked);
  auto fix = [&](const char* wkt, std::int64_t asserted_at) {
    node::Item item;
    item.asserted_at = asserted_at;
    item.add(geometry, Term::iri(kGeoAsWkt), Term::literal(wkt, kGeoWktLiteral));
    put(item);
  };
  fix("POINT(1 1)", now - 10 * second);  // the bedroom
  reading("mote5", 20.0);
  fix("POINT(6 1)", now - 2 * second);  // the hall
  node::Pattern of_mote5 = readings();
  of_mote5.source = mote;
  EXPECT_EQ(plan().plan.sensors_in_room(kHall), Ids{mote});
  EXPECT_EQ(in_area({kHall, std::nullopt, std::nullopt}, of_mote5).size(), 0u);
  EXPECT_EQ(in_area({kBedroom, std::nullopt, std::nullopt}, of_mote5).size(), 0u);
  reading("mote5", 22.0);
  auto hall = in_area({kHall, std::nullopt, std::nullopt}, of_mote5);
  ASSERT_EQ(hall.size(), 1u);
  EXPECT_EQ(hall.front().triple.o.value, std::to_string(22.0));
}

TEST_F(BoardTest, ListByWktOnEveryFloorOrOne) {
  auto shape = parse_shape("POLYGON((0 0, 2 0, 2 2, 0 2, 0 0))");
  ASSERT_TRUE(shape.has_value());
  node::Pattern floors;
  floors.p = Term::iri(kTvFloor);
  auto all = in_area({"", *shape, std::nullopt}, floors);
  ASSERT_EQ(all.size(), 2u);  // mote1 and mote2: their tv:floor records
  auto upstairs = in_area({"", *shape, 1}, floors);
  ASSERT_EQ(upstairs.size(), 1u);
  EXPECT_EQ(upstairs[0].triple.s.value, kMote2);
}

// Issue 6: an area selects the records whose subject is a feature located in it, polygon
// features included (docs/spatial.md S14): a wardrobe drawn in the bedroom, against its walls,
// and the bedroom itself lie in a WKT area around the bedroom; the hall, which crosses it, and
// the study upstairs (with --floor 0) do not.
TEST_F(BoardTest, ListByWktSelectsRoomsLyingInTheArea) {
  const std::string wardrobe = kHome + "/furniture/wardrobe";
  put(located_feature_item(wardrobe, "POLYGON((0 3, 1 3, 1 4, 0 4, 0 3))", 0));
  node::Item about;
  about.add(Term::iri(wardrobe), Term::iri("http://www.w3.org/2000/01/rdf-schema#label"),
            Term::literal("wardrobe"));
  put(about);
  auto shape = parse_shape("POLYGON((-1 -1, 5 -1, 5 5, -1 5, -1 -1))");
  ASSERT_TRUE(shape.has_value());
  node::Pattern has_geometry;
  has_geometry.p = Term::iri(kGeoHasGeometry);
  auto subjects = [&](const std::vector<node::Record>& records) {
    std::set<std::string> out;
    for (const auto& r : records) out.insert(r.triple.s.value);
    return out;
  };
  EXPECT_EQ(subjects(in_area({"", *shape, 0}, has_geometry)),
            (std::set<std::string>{kBedroom, kMote, wardrobe}));
  EXPECT_EQ(subjects(in_area({"", *shape, std::nullopt}, has_geometry)),
            (std::set<std::string>{kBedroom, kMote, kMote2, kUpstairs, wardrobe}));
  // Every record about the wardrobe, not only its geometry: its label too.
  std::vector<node::Record> all = in_area({"", *shape, 0});
  bool label = false;
  for (const auto& r : all) {
    label = label || (r.triple.s.value == wardrobe && r.triple.o.value == "wardrobe");
  }
  EXPECT_TRUE(label);
  // The bedroom as the area: the wardrobe against its walls is in it, the hall beside it is not.
  EXPECT_EQ(subjects(in_area({kBedroom, std::nullopt, std::nullopt}, has_geometry)),
            (std::set<std::string>{kBedroom, kMote, wardrobe}));
  BoardPlan board = plan();
  EXPECT_EQ(features_in(board.plan, {"", *shape, 0}, Area{*shape, 0}),
            (Ids{wardrobe, kMote, kBedroom}));  // sorted IRIs
}

TEST_F(BoardTest, CascadeAndLimitApplyToTheKeptMatches) {
  node::Pattern has_geometry;
  has_geometry.p = Term::iri(kGeoHasGeometry);
  auto snapshot = node_->snapshot();
  ASSERT_TRUE(snapshot.has_value());
  // The bedroom and mote1 match; each is followed by its geometry's WKT record.
  auto records = list_in_area(*snapshot, has_geometry, {kBedroom, std::nullopt, std::nullopt}, {1, 0});
  ASSERT_TRUE(records.has_value()) << records.error().message;
  std::vector<std::string> shape;
  for (const auto& r : *records) shape.push_back(r.triple.s.value + " " + r.triple.p.value);
  EXPECT_EQ(shape, (std::vector<std::string>{kBedroom + " " + kGeoHasGeometry, kBedroom + "/geometry " + kGeoAsWkt,
                                             kMote + " " + kGeoHasGeometry, kMote + "/geometry " + kGeoAsWkt}));
  auto limited = list_in_area(*snapshot, has_geometry, {kBedroom, std::nullopt, std::nullopt}, {1, 3});
  ASSERT_TRUE(limited.has_value());
  EXPECT_EQ(limited->size(), 3u);
}

TEST_F(BoardTest, AnUnknownRoomIsAnErrorNamingIt) {
  auto snapshot = node_->snapshot();
  ASSERT_TRUE(snapshot.has_value());
  auto records = list_in_area(*snapshot, {}, {kHome + "/room/attic", std::nullopt, std::nullopt});
  ASSERT_FALSE(records.has_value());
  EXPECT_NE(records.error().message.find("no room " + kHome + "/room/attic"), std::string::npos);
}

// A room that is on the board with a place the plan cannot use is not "no room": the error says
// what is wrong with it, and a sensor named as an area is said to be one.
TEST_F(BoardTest, NamingARoomWithMalformedGeometryOrASensorSaysSo) {
  const std::string bowtie = kHome + "/room/bowtie";
  put(located_feature_item(bowtie, "POLYGON((0 0, 10 0, 0 10, 10 10, 0 0))", 0));
  auto snapshot = node_->snapshot();
  ASSERT_TRUE(snapshot.has_value());
  auto records = list_in_area(*snapshot, {}, {bowtie, std::nullopt, std::nullopt});
  ASSERT_FALSE(records.has_value());
  EXPECT_EQ(records.error().message.rfind(bowtie + " cannot be used as an area (its place cannot be read): WKT column", 0), 0u) << records.error().message;
  auto sensor = list_in_area(*snapshot, {}, {kMote, std::nullopt, std::nullopt});
  ASSERT_FALSE(sensor.has_value());
  EXPECT_EQ(sensor.error().message, kMote + " is a sensor (its geo:asWKT is a POINT), not a room");
  // Listing another area names the skipped feature too: it is in no area, whatever its place.
  std::vector<std::string> skipped;
  auto hall = list_in_area(*snapshot, {}, {kHall, std::nullopt, std::nullopt}, {}, &skipped);
  ASSERT_TRUE(hall.has_value());
  ASSERT_EQ(skipped.size(), 1u);
  EXPECT_EQ(skipped[0].rfind(bowtie + ": WKT column", 0), 0u) << skipped[0];
}

// NaN and infinite periods are refused with a reason; a period of centuries is "rarely" and a
// duration of centuries ends at the end of time, neither an overflow into the past.
TEST_F(BoardTest, SensingSubscriptionsRefuseNonFiniteAgesAndSaturateHugeOnes) {
  auto subscription = [&](const std::string& id, const std::string& max_age, const std::string& duration) {
    const Term self = Term::iri(kHome + "/sensing/" + id);
    const auto tv = [](const char* local) { return Term::iri(std::string(uri::kTahvelNs) + local); };
    node::Item item;
    item.persistent = true;
    item.add(self, Term::iri(std::string(node::kRdfType)), tv("SensingSubscription"))
        .add(self, tv("quantity"), tv("temperature"))
        .add(self, tv("area"), Term::iri(kBedroom))
        .add(self, tv("maxAgeS"), Term::literal(max_age, std::string(node::xsd::kDouble)));
    if (!duration.empty()) item.add(self, tv("durationS"), Term::literal(duration, std::string(node::xsd::kDouble)));
    put(item);
  };
  subscription("nan", "NaN", "");
  subscription("inf", "INF", "");
  subscription("nan-duration", "600", "NaN");
  subscription("centuries", "1e10", "1e10");
  auto read = read_sensing_subscriptions(*node_->snapshot());
  ASSERT_TRUE(read.has_value());
  ASSERT_EQ(read->problems.size(), 3u);
  std::set<std::string> refused(read->problems.begin(), read->problems.end());
  EXPECT_TRUE(refused.count(kHome + "/sensing/nan: tv:maxAgeS must be a positive finite number of seconds"));
  EXPECT_TRUE(refused.count(kHome + "/sensing/inf: tv:maxAgeS must be a positive finite number of seconds"));
  EXPECT_TRUE(refused.count(kHome + "/sensing/nan-duration: tv:durationS must be a positive number of seconds (absent: no end)"));
  ASSERT_EQ(read->subscriptions.size(), 1u);
  EXPECT_EQ(read->subscriptions[0].until_ns, std::numeric_limits<std::int64_t>::max());
  EXPECT_EQ(saturating_ns(1e10), std::numeric_limits<std::int64_t>::max());
  EXPECT_EQ(saturating_ns(1.5), 1'500'000'000);
}

TEST_F(BoardTest, LooksLikeWkt) {
  EXPECT_TRUE(looks_like_wkt("POLYGON((0 0, 1 0, 1 1, 0 0))"));
  EXPECT_TRUE(looks_like_wkt("  point (1 2)"));
  EXPECT_TRUE(looks_like_wkt("<http://www.opengis.net/def/crs/OGC/1.3/CRS84> POINT(1 2)"));
  EXPECT_FALSE(looks_like_wkt("http://example.org/home1/room/bedroom"));
  EXPECT_FALSE(looks_like_wkt("ex:bedroom"));
  EXPECT_FALSE(looks_like_wkt("<http://example.org/home1/room/bedroom>"));
  // A relative IRI is refused as one ("not an IRI or CURIE"), not read as WKT of type KITCHEN.
  EXPECT_FALSE(looks_like_wkt("kitchen"));
  EXPECT_FALSE(looks_like_wkt("room/kitchen"));
  EXPECT_TRUE(looks_like_wkt("MultiPolygon(((0 0, 1 0, 1 1, 0 0)))"));
  EXPECT_TRUE(looks_like_wkt("LINESTRING(0 0, 1 1)"));  // WKT, refused by the parser as a type
  // Refused by the parser with the reason, not taken for an IRI with white space in it.
  EXPECT_TRUE(looks_like_wkt("POLYGONZ((0 0 0, 1 0 0, 1 1 0, 0 0 0))"));
  EXPECT_TRUE(looks_like_wkt("PointM(1 2 3)"));
  EXPECT_TRUE(looks_like_wkt("SRID=4326;POINT(1 2)"));
  EXPECT_FALSE(looks_like_wkt("srid:x"));
}

// The issue's test: moving a sensor from one room to another changes which area subscription
// receives its readings.
TEST_F(BoardTest, MovingASensorMovesItsReadingsBetweenAreaSubscriptions) {
  auto bed_agent = node_->agent("bedroom-watch");
  auto hall_agent = node_->agent("hall-watch");
  ASSERT_TRUE(bed_agent.has_value() && hall_agent.has_value());
  auto bed = AreaSubscription::open(*node_, *bed_agent, {kBedroom, std::nullopt, std::nullopt}, readings());
  auto hall = AreaSubscription::open(*node_, *hall_agent, {kHall, std::nullopt, std::nullopt}, readings());
  ASSERT_TRUE(bed.has_value()) << bed.error().message;
  ASSERT_TRUE(hall.has_value()) << hall.error().message;
  EXPECT_EQ(bed->sensors(), Ids{kMote});
  EXPECT_EQ(hall->sensors(), Ids{});

  reading("mote1", 21.0);
  EXPECT_EQ(pending(*bed_agent), 1u);
  EXPECT_EQ(pending(*hall_agent), 0u);

  put(located_feature_item(kMote, "POINT(6 1)", 0));  // carried into the hall
  auto bed_changed = bed->refresh();
  auto hall_changed = hall->refresh();
  ASSERT_TRUE(bed_changed.has_value() && hall_changed.has_value());
  EXPECT_TRUE(*bed_changed);
  EXPECT_TRUE(*hall_changed);
  EXPECT_EQ(bed->sensors(), Ids{});
  EXPECT_EQ(hall->sensors(), Ids{kMote});

  reading("mote1", 22.0);
  EXPECT_EQ(pending(*bed_agent), 1u);   // only the reading from before the move
  EXPECT_EQ(pending(*hall_agent), 1u);

  // Onto the shared wall x = 4: closed rooms, so both receive it.
  put(located_feature_item(kMote, "POINT(4 1)", 0));
  ASSERT_TRUE(bed->refresh().has_value());
  ASSERT_TRUE(hall->refresh().has_value());
  reading("mote1", 23.0);
  EXPECT_EQ(pending(*bed_agent), 2u);
  EXPECT_EQ(pending(*hall_agent), 2u);

  // A refresh with no plan change changes nothing.
  reading("mote2", 17.0);
  auto quiet = bed->refresh();
  ASSERT_TRUE(quiet.has_value());
  EXPECT_FALSE(*quiet);
}

TEST_F(BoardTest, RemovingASensorsGeometryEndsItsSubscriptionAndANewSensorGetsOne) {
  auto agent = node_->agent("bedroom-watch");
  ASSERT_TRUE(agent.has_value());
  auto bed = AreaSubscription::open(*node_, *agent, {kBedroom, std::nullopt, std::nullopt}, readings());
  ASSERT_TRUE(bed.has_value());
  node::Pattern wkt;
  wkt.s = Term::iri(kMote + "/geometry");
  auto removed = node_->remove(wkt);
  ASSERT_TRUE(removed.has_value());
  EXPECT_EQ(*removed, 1u);
  auto changed = bed->refresh();
  ASSERT_TRUE(changed.has_value());
  EXPECT_TRUE(*changed);
  EXPECT_EQ(bed->sensors(), Ids{});
  reading("mote1", 20.0);
  EXPECT_EQ(pending(*agent), 0u);

  put(located_feature_item(kHome + "/mote3", "POINT(0.5 3.5)", 0));  // a new mote, bedroom arm
  changed = bed->refresh();
  ASSERT_TRUE(changed.has_value());
  EXPECT_TRUE(*changed);
  EXPECT_EQ(bed->sensors(), Ids{kHome + "/mote3"});
  reading("mote3", 20.5);
  EXPECT_EQ(pending(*agent), 1u);
}

TEST_F(BoardTest, AReopenedAreaSubscriptionDropsSensorsThatLeftWhileItWasAway) {
  auto agent = node_->agent("bedroom-watch");
  ASSERT_TRUE(agent.has_value());
  {
    auto bed = AreaSubscription::open(*node_, *agent, {kBedroom, std::nullopt, std::nullopt}, readings());
    ASSERT_TRUE(bed.has_value());
    EXPECT_EQ(bed->sensors(), Ids{kMote});
  }
  put(located_feature_item(kMote, "POINT(6 1)", 0));  // moved while no one watched
  auto bed = AreaSubscription::open(*node_, *agent, {kBedroom, std::nullopt, std::nullopt}, readings());
  ASSERT_TRUE(bed.has_value());
  EXPECT_EQ(bed->sensors(), Ids{});
  reading("mote1", 20.0);
  EXPECT_EQ(pending(*agent), 0u);
}

// `tahvel subscribe --area` and `tahvel up`: the declaration is on the board, the node's keeper
// expands it and follows the plan; the subscriber does nothing but take.
TEST_F(BoardTest, TheKeeperMovesADeclaredAreaSubscriptionWithItsSensor) {
  auto ui = node_->agent("ui");
  ASSERT_TRUE(ui.has_value());
  auto declared = declare_area_subscription(*node_, *ui, {kBedroom, std::nullopt, std::nullopt}, readings());
  ASSERT_TRUE(declared.has_value()) << declared.error().message;
  // Declaring again (a restarted agent) is the same declaration.
  EXPECT_EQ(declare_area_subscription(*node_, *ui, {kBedroom, std::nullopt, std::nullopt}, readings()).value(), *declared);
  auto keeper = AreaKeeper::open(dir_ / "store");
  ASSERT_TRUE(keeper.has_value()) << keeper.error().message;
  auto snapshot = node_->snapshot();
  ASSERT_TRUE(snapshot.has_value());
  EXPECT_EQ(area_expansion(*snapshot, *declared).value().sensors, Ids{kMote});

  reading("mote1", 21.0);
  reading("mote2", 19.0);  // upstairs: not in the bedroom
  EXPECT_EQ(pending(*ui), 1u);

  put(located_feature_item(kMote, "POINT(6 1)", 0));  // carried into the hall
  auto synced = keeper->poll();
  ASSERT_TRUE(synced.has_value()) << synced.error().message;
  ASSERT_TRUE(synced->has_value());
  EXPECT_EQ((*synced)->removed, 2u);  // mote1 as a source and as a subject
  reading("mote1", 22.0);
  EXPECT_EQ(pending(*ui), 1u);

  put(located_feature_item(kMote, "POINT(1 3)", 0));  // back, into the bedroom's other arm
  ASSERT_TRUE(keeper->poll().has_value());
  reading("mote1", 23.0);
  EXPECT_EQ(pending(*ui), 2u);

  // A poll with no plan change does not sync.
  reading("mote1", 24.0);
  auto quiet = keeper->poll();
  ASSERT_TRUE(quiet.has_value());
  EXPECT_FALSE(quiet->has_value());
  EXPECT_EQ(pending(*ui), 3u);

  // Removing the declaration ends it: the keeper removes its expansions.
  ASSERT_TRUE(node_->remove_item(*declared).has_value());
  auto ended = keeper->poll();
  ASSERT_TRUE(ended.has_value() && ended->has_value());
  EXPECT_EQ((*ended)->declarations, 0u);
  reading("mote1", 25.0);
  EXPECT_EQ(pending(*ui), 3u);
}

// Routing happens when a reading is stored, by the expansions then on the board: a reading
// stored after its sensor's move and before the keeper's sync went by the old room's expansions.
// The sync that adds the hall's expansion puts it into the hall's subscriber too (S9), and not
// into a subscriber that got it already by another subscription.
TEST_F(BoardTest, AReadingStoredBetweenASensorsMoveAndTheSyncReachesTheRoomItMovedInto) {
  auto bed_watch = node_->agent("bedroom-watch");
  auto hall_watch = node_->agent("hall-watch");
  auto house_watch = node_->agent("house-watch");  // both rooms
  auto logger = node_->agent("logger");            // the hall, and every reading besides
  ASSERT_TRUE(bed_watch && hall_watch && house_watch && logger);
  const AreaSpec bedroom{kBedroom, std::nullopt, std::nullopt}, hall{kHall, std::nullopt, std::nullopt};
  ASSERT_TRUE(declare_area_subscription(*node_, *bed_watch, bedroom, readings()).has_value());
  ASSERT_TRUE(declare_area_subscription(*node_, *hall_watch, hall, readings()).has_value());
  ASSERT_TRUE(declare_area_subscription(*node_, *house_watch, bedroom, readings()).has_value());
  ASSERT_TRUE(declare_area_subscription(*node_, *house_watch, hall, readings()).has_value());
  ASSERT_TRUE(declare_area_subscription(*node_, *logger, hall, readings()).has_value());
  ASSERT_TRUE(logger->subscribe(readings()).has_value());
  auto keeper = AreaKeeper::open(dir_ / "store");
  ASSERT_TRUE(keeper.has_value()) << keeper.error().message;

  reading("mote1", 21.0);  // in the bedroom
  put(located_feature_item(kMote, "POINT(6 1)", 0));  // carried into the hall
  reading("mote1", 22.0);  // before the keeper has seen the move
  EXPECT_EQ(pending(*hall_watch), 0u);

  auto synced = keeper->poll();
  ASSERT_TRUE(synced.has_value()) << synced.error().message;
  ASSERT_TRUE(synced->has_value());
  EXPECT_EQ((*synced)->caught_up, 1u);  // to the hall's watcher only
  auto taken = hall_watch->take(std::chrono::milliseconds(0));
  ASSERT_TRUE(taken.has_value() && taken->has_value());
  bool is_22 = false;
  for (const node::Record& r : (*taken)->records) is_22 = is_22 || r.triple.o.value == std::to_string(22.0);
  EXPECT_TRUE(is_22) << "the hall's watcher got the reading taken before the move";
  EXPECT_EQ(pending(*hall_watch), 0u);
  EXPECT_EQ(pending(*house_watch), 2u);  // each reading once, by the bedroom's expansion
  EXPECT_EQ(pending(*logger), 2u);       // each once, by its own subscription

  // After the sync the hall's expansion routes the reading as it is stored; nothing is caught up.
  reading("mote1", 23.0);
  EXPECT_EQ(pending(*hall_watch), 1u);
  put(located_feature_item(kMote, "POINT(6 1)", 0));  // the same place stated again: no move
  auto again = keeper->poll();
  ASSERT_TRUE(again.has_value() && again->has_value());
  EXPECT_EQ((*again)->added, 0u);
  EXPECT_EQ((*again)->caught_up, 0u);
  EXPECT_EQ(pending(*hall_watch), 1u);
}

TEST_F(BoardTest, AnAreaSubscriptionSelectsRecordsAboutFeaturesInTheAreaBySubject) {
  auto ui = node_->agent("ui");
  auto writer = node_->agent("environment");
  ASSERT_TRUE(ui.has_value() && writer.has_value());
  auto declared = declare_area_subscription(*node_, *ui, {kBedroom, std::nullopt, std::nullopt});
  ASSERT_TRUE(declared.has_value());
  ASSERT_TRUE(sync_area_subscriptions(*node_).has_value());
  const Term state = Term::iri("https://w3id.org/tahvel#environment");
  node::Item about_bedroom, about_hall;
  about_bedroom.add(Term::iri(kBedroom), state, Term::blank("e"));
  about_hall.add(Term::iri(kHall), state, Term::blank("e"));
  auto bedroom_item = writer->store(about_bedroom);
  ASSERT_TRUE(bedroom_item.has_value());
  ASSERT_TRUE(writer->store(about_hall).has_value());
  auto taken = ui->take(std::chrono::milliseconds(0));
  ASSERT_TRUE(taken.has_value() && taken->has_value());
  EXPECT_EQ((*taken)->item, *bedroom_item);
  EXPECT_EQ(pending(*ui), 0u);
}

TEST_F(BoardTest, AWktAreaOnOneFloorExpandsToTheSensorsOfThatFloorOnly) {
  auto ui = node_->agent("ui");
  ASSERT_TRUE(ui.has_value());
  auto square = parse_shape("POLYGON((0 0, 4 0, 4 4, 0 4, 0 0))");
  ASSERT_TRUE(square.has_value());
  auto declared = declare_area_subscription(*node_, *ui, {"", *square, 1}, readings());
  ASSERT_TRUE(declared.has_value()) << declared.error().message;
  ASSERT_TRUE(sync_area_subscriptions(*node_).has_value());
  auto snapshot = node_->snapshot();
  ASSERT_TRUE(snapshot.has_value());
  EXPECT_EQ(area_expansion(*snapshot, *declared).value().sensors, Ids{kMote2});
  reading("mote1", 21.0);
  reading("mote2", 19.0);
  EXPECT_EQ(pending(*ui), 1u);
}

// Declarations written by hand, several in one item (as `tahvel put` of a file makes them):
// each subject of tv:areaSubscriber is a declaration of its own, expanded on its own, and a
// problem is reported against the declaration that has it. The keeper's first sync is reported.
TEST_F(BoardTest, EachDeclarationInAnItemIsKeptAndItsProblemsAreItsOwn) {
  node::Item item;
  item.persistent = true;
  declare(item, "a", Term::iri(kHome + "/ui-bed"), Term::iri(kBedroom))
      .add(Term::blank("a"), tv("predicate"), Term::iri("http://www.w3.org/ns/sosa/hasSimpleResult"));
  declare(item, "b", Term::iri(kHome + "/ui-up"), Term::iri(kUpstairs));
  declare(item, "c", Term::iri(kHome + "/ui-bad"), Term::iri(kHall)).add(Term::blank("c"), tv("areaFloor"), Term::integer(1));
  AreaSyncReport first;
  auto keeper = keep(item, first);
  ASSERT_TRUE(keeper.has_value()) << keeper.error().message;
  EXPECT_EQ(first.declarations, 3u);
  EXPECT_EQ(first.added, 6u);  // per room: its mote as a source and as a subject, and the room
  ASSERT_EQ(first.problems.size(), 1u);
  EXPECT_NE(first.problems[0].find("of <" + kHome + "/ui-bad>: tv:areaFloor goes with a WKT tv:area only"), std::string::npos)
      << first.problems[0];
  reading("mote1", 21.0);
  reading("mote2", 19.0);
  auto bed = node_->agent("ui-bed"), up = node_->agent("ui-up"), bad = node_->agent("ui-bad");
  ASSERT_TRUE(bed && up && bad);
  EXPECT_EQ(pending(*bed), 1u);
  EXPECT_EQ(pending(*up), 1u);
  EXPECT_EQ(pending(*bad), 0u);
}

// A declaration whose subscriber is a string or a blank node (`tv:areaSubscriber "ui2"`, `[]`)
// made an expansion the node refused: every sync of the node failed ("item 1: triple 1,
// object: invalid IRI 'ui2'", naming neither the declaration nor its agent), the other
// declarations stopped following their sensors, and so did every `tahvel remove`. It is now
// that declaration's problem, and the others are kept current.
TEST_F(BoardTest, ADeclarationWhoseSubscriberIsNotAnIriIsItsOwnProblemAndTheOthersAreKept) {
  node::Item item;
  item.persistent = true;
  declare(item, "a", Term::iri(kHome + "/ui-bed"), Term::iri(kBedroom));
  declare(item, "b", Term::literal("ui2"), Term::iri(kBedroom));
  declare(item, "c", Term::blank("someone"), Term::iri(kHall));
  declare(item, "d", Term::iri(kHome + "/ui-hall"), Term::iri(kHall)).add(Term::blank("d"), tv("predicate"), Term::literal("hasSimpleResult"));
  AreaSyncReport first;
  auto keeper = keep(item, first);
  ASSERT_TRUE(keeper.has_value()) << keeper.error().message;
  EXPECT_EQ(first.declarations, 4u);
  ASSERT_EQ(first.problems.size(), 3u);
  EXPECT_NE(first.problems[0].find("tv:areaSubscriber \"ui2\" (a literal) is not an agent's IRI"), std::string::npos) << first.problems[0];
  EXPECT_NE(first.problems[1].find("tv:areaSubscriber _:"), std::string::npos) << first.problems[1];
  EXPECT_NE(first.problems[2].find("of <" + kHome + "/ui-hall>: tv:predicate \"hasSimpleResult\" (a literal) is not an absolute IRI"),
            std::string::npos) << first.problems[2];
  auto bed = node_->agent("ui-bed");
  ASSERT_TRUE(bed.has_value());
  reading("mote1", 21.0);
  EXPECT_EQ(pending(*bed), 1u);
  // The keeper still follows the plan: mote1 carried into the hall leaves the bedroom's subscriber.
  put(located_feature_item(kMote, "POINT(6 1)", 0));
  auto synced = keeper->poll();
  ASSERT_TRUE(synced.has_value()) << synced.error().message;
  ASSERT_TRUE(synced->has_value());
  EXPECT_EQ((*synced)->removed, 2u);
  const std::size_t before = pending(*bed);  // the move itself is about mote1, still in the bedroom then
  reading("mote1", 22.0);
  EXPECT_EQ(pending(*bed), before);
}

// Each move of a sensor syncs the keeper; a feature the plan skips was reported again at each
// sync, and a log of `tahvel up` or `tahvel areas` repeated it at every move.
TEST_F(BoardTest, TheKeeperReportsAProblemOnceHoweverOftenItSyncs) {
  put(located_feature_item(kHome + "/broken", "POLYGON((0 0, 1 0, 1 1))", 0));
  auto ui = node_->agent("ui");
  ASSERT_TRUE(ui.has_value());
  ASSERT_TRUE(declare_area_subscription(*node_, *ui, {kBedroom, std::nullopt, std::nullopt}, readings()).has_value());
  AreaSyncReport first;
  auto keeper = AreaKeeper::open(dir_ / "store", &first);
  ASSERT_TRUE(keeper.has_value()) << keeper.error().message;
  ASSERT_EQ(first.problems.size(), 1u);
  EXPECT_NE(first.problems[0].find(kHome + "/broken: WKT column 9"), std::string::npos) << first.problems[0];

  for (const char* where : {"POINT(6 1)", "POINT(1 3)"}) {
    put(located_feature_item(kMote, where, 0));
    auto synced = keeper->poll();
    ASSERT_TRUE(synced.has_value()) << synced.error().message;
    ASSERT_TRUE(synced->has_value()) << "a move syncs";
    EXPECT_TRUE((*synced)->problems.empty()) << (*synced)->problems[0];
  }
  // A problem not met before is reported when it appears.
  put(located_feature_item(kHome + "/broken2", "POLYGON((0 0, 2 0, 2 2))", 0));
  auto synced = keeper->poll();
  ASSERT_TRUE(synced.has_value() && synced->has_value());
  ASSERT_EQ((*synced)->problems.size(), 1u);
  EXPECT_NE((*synced)->problems[0].find(kHome + "/broken2"), std::string::npos) << (*synced)->problems[0];
  // Fixed, then broken again: said again.
  put(located_feature_item(kHome + "/broken2", "POLYGON((0 0, 2 0, 2 2, 0 0))", 0));
  synced = keeper->poll();
  ASSERT_TRUE(synced.has_value() && synced->has_value());
  EXPECT_TRUE((*synced)->problems.empty()) << (*synced)->problems[0];
  put(located_feature_item(kHome + "/broken2", "POLYGON((0 0, 2 0, 2 2))", 0));
  synced = keeper->poll();
  ASSERT_TRUE(synced.has_value() && synced->has_value());
  ASSERT_EQ((*synced)->problems.size(), 1u);
  EXPECT_NE((*synced)->problems[0].find(kHome + "/broken2"), std::string::npos) << (*synced)->problems[0];
}

// tv:areaFloor is a floor as tv:floor is (S5): "1.0" was refused as not an integer, and
// 4294967296 was cut to an int and read as floor 0.
TEST_F(BoardTest, AnAreaFloorIsReadAsAFeatureFloorIs) {
  const Term square = Term::literal("POLYGON((0 0, 2 0, 2 2, 0 2, 0 0))", kGeoWktLiteral);
  node::Item item;
  item.persistent = true;
  declare(item, "a", Term::iri(kHome + "/ui-up"), square)
      .add(Term::blank("a"), tv("areaFloor"), Term::literal("1.0", "http://www.w3.org/2001/XMLSchema#decimal"));
  declare(item, "b", Term::iri(kHome + "/ui-far"), square).add(Term::blank("b"), tv("areaFloor"), Term::integer(4294967296));
  AreaSyncReport first;
  auto keeper = keep(item, first);
  ASSERT_TRUE(keeper.has_value()) << keeper.error().message;
  ASSERT_EQ(first.problems.size(), 1u);
  EXPECT_NE(first.problems[0].find("of <" + kHome + "/ui-far>: tv:areaFloor '4294967296' is not a whole number"), std::string::npos)
      << first.problems[0];
  reading("mote1", 21.0);
  reading("mote2", 19.0);
  auto up = node_->agent("ui-up"), far = node_->agent("ui-far");
  ASSERT_TRUE(up && far);
  EXPECT_EQ(pending(*up), 1u);  // mote2's, upstairs
  EXPECT_EQ(pending(*far), 0u);
}

TEST_F(BoardTest, ADeclarationForARoomNotYetDrawnIsReportedThenExpandedWhenItIs) {
  auto ui = node_->agent("ui");
  ASSERT_TRUE(ui.has_value());
  const std::string kitchen = kHome + "/room/kitchen";
  auto declared = declare_area_subscription(*node_, *ui, {kitchen, std::nullopt, std::nullopt}, readings());
  ASSERT_TRUE(declared.has_value());
  auto keeper = AreaKeeper::open(dir_ / "store");
  ASSERT_TRUE(keeper.has_value());
  auto report = sync_area_subscriptions(*node_);
  ASSERT_TRUE(report.has_value());
  ASSERT_EQ(report->problems.size(), 1u);
  EXPECT_NE(report->problems[0].find(kitchen), std::string::npos) << report->problems[0];
  put(located_feature_item(kitchen, "POLYGON((5 3, 7 3, 7 5, 5 5, 5 3))", 0));
  put(located_feature_item(kHome + "/mote9", "POINT(6 4)", 0));
  auto synced = keeper->poll();
  ASSERT_TRUE(synced.has_value() && synced->has_value());
  EXPECT_TRUE((*synced)->problems.empty());
  reading("mote9", 20.0);
  EXPECT_EQ(pending(*ui), 1u);
}

}  // namespace
}  // namespace tahvel::spatial
