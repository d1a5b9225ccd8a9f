// The environment agents as processes (docs/spatial.md, "Environment"): the demo home's floor
// plan (deploy/floorplans/home.ttl) loaded with `tahvel put`, sensing subscriptions written on
// the board, tahvel-env-motes run over one hour of virtual time, then tahvel-environment
// --once at chosen times. Checks: motes sense only what a subscription asks for, in its area, at
// its period, for its duration, and faster while the threshold rule holds; a room's motes take
// turns; a room's quantity
// with no reading within the valid time is "unknown" (the issue's test).
#include <stdlib.h>
#include <sys/wait.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <map>
#include <thread>

#include <gtest/gtest.h>

#include "tahvel/spatial/board.h"
#include "tahvel/spatial/environment_board.h"
#include "agent_process.h"
#include "temp_dir.h"

namespace tahvel::spatial {
namespace {

namespace fs = std::filesystem;

constexpr std::int64_t kS = 1'000'000'000;
constexpr std::int64_t kT0 = 1'800'000'000 * kS;  // virtual start (2027-01-15)
const std::string kHome = "http://example.org/home1";
const std::string kTv = "https://w3id.org/tahvel#";

int run(const std::string& command) {
  int status = std::system(command.c_str());
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

std::string bin(const char* name) { return std::string(TAHVEL_BIN_DIR) + "/" + name; }

class EnvironmentAgents : public testing::Test {
 protected:
  void SetUp() override {
    store_ = (dir_ / "home1").string();
    ASSERT_EQ(run(bin("tahvel") + " init " + store_ + " --iri " + kHome), 0);
    ASSERT_EQ(run(bin("tahvel") + " put " + store_ + " --persistent " + TAHVEL_SOURCE_DIR +
                  "/deploy/floorplans/home.ttl > /dev/null"),
              0);
  }

  void subscribe(const std::string& id, Quantity q, const std::string& room, double max_age_s,
                 double duration_s, std::optional<ThresholdRule> rule = std::nullopt) {
    auto node = node::Node::open(store_);
    ASSERT_TRUE(node.has_value());
    auto agent = node->agent("gateway");
    ASSERT_TRUE(agent.has_value());
    SensingSubscription s;
    s.iri = kHome + "/sensing/" + id;
    s.quantity = q;
    s.area = kHome + "/room/" + room;
    s.max_age_s = max_age_s;
    s.rule = rule;
    ASSERT_TRUE(agent->store(sensing_subscription_item(s, duration_s, kT0)).has_value());
  }

  // Readings on the board per mote (local name) and quantity, in time order.
  std::map<std::pair<std::string, Quantity>, std::vector<Reading>> readings() {
    auto node = node::Node::open(store_);
    EXPECT_TRUE(node.has_value());
    auto snapshot = node->snapshot();
    EXPECT_TRUE(snapshot.has_value());
    auto all = readings_since(*snapshot, 0);
    EXPECT_TRUE(all.has_value());
    std::map<std::pair<std::string, Quantity>, std::vector<Reading>> out;
    for (const MoteReading& r : *all) {
      out[{r.mote.substr(kHome.size() + 1), r.reading.quantity}].push_back(r.reading);
    }
    for (auto& [key, list] : out) {
      std::sort(list.begin(), list.end(), [](const Reading& a, const Reading& b) { return a.at_ns < b.at_ns; });
    }
    return out;
  }

  // The object of <room>/environment tv:<local>, in N-Triples lexical form ("unknown", "21.3").
  std::string environment(const std::string& room, const std::string& local) {
    auto node = node::Node::open(store_);
    EXPECT_TRUE(node.has_value());
    auto snapshot = node->snapshot();
    node::Pattern p;
    p.s = node::Term::iri(environment_iri(kHome + "/room/" + room));
    p.p = node::Term::iri(kTv + local);
    auto records = snapshot->list(p);
    EXPECT_TRUE(records.has_value());
    EXPECT_EQ(records->size(), 1u) << room << " " << local;
    return records->empty() ? "" : records->front().triple.o.value;
  }

  void simulate_one_hour() {
    ASSERT_EQ(run(bin("tahvel-env-motes") + " " + store_ + " --seed 7 --steps 360 --step-s 10 --start-ns " +
                  std::to_string(kT0) + " 2> /dev/null"),
              0);
  }

  void aggregate_at(std::int64_t now_ns) {
    ASSERT_EQ(run(bin("tahvel-environment") + " " + store_ + " --once --valid-s 900 --now-ns " +
                  std::to_string(now_ns)),
              0);
  }

  tahvel::test_support::TempDir tmp_{"tahvel-env"};
  const fs::path dir_ = tmp_.path();
  std::string store_;
};

TEST_F(EnvironmentAgents, MotesSenseWhatWhereAndHowOftenSubscriptionsAsk) {
  subscribe("bed-temp", Quantity::temperature, "bedroom", 300, 1800);
  subscribe("living-move", Quantity::movement, "living", 60, 0, ThresholdRule{0.5, 10});
  simulate_one_hour();
  auto all = readings();

  // Bedroom temperature: every 300 s while the 30-minute subscription lasts, then nothing.
  const auto& bed = all[{"mote-bed", Quantity::temperature}];
  ASSERT_EQ(bed.size(), 6u);
  for (std::size_t i = 0; i < bed.size(); ++i) EXPECT_EQ(bed[i].at_ns, kT0 + static_cast<std::int64_t>(i) * 300 * kS);
  // What nobody asked for is not sensed: the bedroom mote's humidity, the hall, the kitchen.
  EXPECT_EQ(all.count({"mote-bed", Quantity::humidity}), 0u);
  EXPECT_EQ(all.count({"mote-hall", Quantity::movement}), 0u);
  EXPECT_EQ(all.count({"mote-kitchen", Quantity::temperature}), 0u);

  // Living-room movement from both PIR motes of the room: each is due 10 s after its last
  // reading while the room's last reading (the higher of the two motes' last) shows movement,
  // else 60 s. Replayed step by step (10 s) from what is on the board.
  const char* const pirs[] = {"mote-living-1", "mote-living-2"};
  for (const char* mote : pirs) {
    const auto& pir = all[{mote, Quantity::movement}];
    ASSERT_GT(pir.size(), 60u) << mote;  // more than a plain 60 s period
  }
  std::size_t fast_by_the_other = 0;
  for (std::int64_t t = kT0; t < kT0 + 3600 * kS; t += 10 * kS) {
    std::optional<double> room_last;
    std::map<std::string, const Reading*> last;  // each mote's last reading before t
    for (const char* mote : pirs)
      for (const Reading& r : all[{mote, Quantity::movement}])
        if (r.at_ns < t) last[mote] = &r;
    for (const auto& [mote, r] : last) room_last = std::max(room_last.value_or(r->value), r->value);
    const bool movement = room_last && *room_last > 0.5;
    for (const char* mote : pirs) {
      const auto& pir = all[{mote, Quantity::movement}];
      const bool read_at_t = std::any_of(pir.begin(), pir.end(), [&](const Reading& r) { return r.at_ns == t; });
      const auto own = last.find(mote);
      const bool due = own == last.end() || t - own->second->at_ns >= (movement ? 10 : 60) * kS;
      EXPECT_EQ(read_at_t, due) << mote << " at +" << (t - kT0) / kS << " s";
      fast_by_the_other += read_at_t && movement && own != last.end() && own->second->value <= 0.5 &&
                           t - own->second->at_ns < 60 * kS;
    }
  }
  EXPECT_GT(fast_by_the_other, 0u) << "no mote was sped up by movement the other one saw";
}

// The network decides which motes answer (Paper 3 §5): the living room has two light motes;
// the room gets one reading per period, from each mote in turn, not one from each.
TEST_F(EnvironmentAgents, OneMoteAtATimeAnswersForARoomAndTheMotesTakeTurns) {
  subscribe("living-light", Quantity::light, "living", 300, 0);
  simulate_one_hour();
  auto all = readings();
  const auto& one = all[{"mote-living-1", Quantity::light}];
  const auto& two = all[{"mote-living-2", Quantity::light}];
  EXPECT_EQ(one.size(), 6u);
  EXPECT_EQ(two.size(), 6u);
  std::vector<std::int64_t> times;
  for (const auto* list : {&one, &two})
    for (const Reading& r : *list) times.push_back(r.at_ns);
  std::sort(times.begin(), times.end());
  ASSERT_EQ(times.size(), 12u);
  for (std::size_t i = 0; i < times.size(); ++i) EXPECT_EQ(times[i], kT0 + static_cast<std::int64_t>(i) * 300 * kS);
  for (std::size_t i = 1; i < one.size(); ++i) EXPECT_EQ(one[i].at_ns - one[i - 1].at_ns, 600 * kS);
}

// A mote on the wall between two rooms is in both (S3). Asked for light in the hall every 300 s
// and in the bathroom every 600 s, it took two readings at each instant both were due: a
// second reading of the same moment, which under the closed rule the first already gave both.
TEST_F(EnvironmentAgents, AMoteOnASharedWallTakesOneReadingForBothRoomsAtAnInstant) {
  const std::string wall =
      "@prefix geo: <http://www.opengis.net/ont/geosparql#> .\n@prefix tv: <https://w3id.org/tahvel#> .\n"
      "<" + kHome + "/mote-wall> a <http://www.w3.org/ns/sosa/Sensor> ; tv:floor 0 ; geo:hasGeometry <" + kHome +
      "/mote-wall/geometry> ; tv:senses tv:light .\n<" + kHome + "/mote-wall/geometry> geo:asWKT \"POINT(7 5)\"^^geo:wktLiteral .\n";
  std::ofstream(dir_ / "wall.ttl") << wall;
  ASSERT_EQ(run(bin("tahvel") + " put " + store_ + " --persistent " + (dir_ / "wall.ttl").string() + " > /dev/null"), 0);
  subscribe("hall-light", Quantity::light, "hall", 300, 0);
  subscribe("bath-light", Quantity::light, "bathroom", 600, 0);
  simulate_one_hour();
  const auto& taken = readings()[{"mote-wall", Quantity::light}];
  ASSERT_EQ(taken.size(), 12u);  // every 300 s for the hall, the bathroom's within them
  for (std::size_t i = 0; i < taken.size(); ++i) EXPECT_EQ(taken[i].at_ns, kT0 + static_cast<std::int64_t>(i) * 300 * kS);
  aggregate_at(kT0 + 3590 * kS);
  EXPECT_NE(environment("bathroom", "light"), "unknown");
  EXPECT_EQ(environment("bathroom", "light"), environment("hall", "light"));
}

// Three rooms in a row, A | B | C, temperature asked every 300 s in A and B and every 600 s in
// C: a mote on the A|B wall, one inside B, and C's only mote on a corner it shares with B. Each
// reading counts for every room its mote stands in (S12's closed rule). B got three readings at
// some instants, two at others: its own mote read for B, the corner mote for C, the wall mote
// for A (an exploratory run of session 81: 18 readings in the hour for 12 asked). Each room now
// gets one reading per instant it is due, and none twice.
TEST_F(EnvironmentAgents, RoomsWithMotesOnSharedWallsGetOneReadingAnInstant) {
  const auto room = [](const std::string& id, const std::string& wkt) {
    return "<" + kHome + "/room/" + id + "> a tv:Room ; tv:floor 0 ; geo:hasGeometry <" + kHome + "/room/" + id + "/g> .\n<" +
           kHome + "/room/" + id + "/g> geo:asWKT \"" + wkt + "\"^^geo:wktLiteral .\n";
  };
  const auto mote = [](const std::string& id, const std::string& at) {
    return "<" + kHome + "/" + id + "> a <http://www.w3.org/ns/sosa/Sensor> ; tv:floor 0 ; geo:hasGeometry <" + kHome + "/" + id +
           "/g> ; tv:senses tv:temperature .\n<" + kHome + "/" + id + "/g> geo:asWKT \"POINT(" + at + ")\"^^geo:wktLiteral .\n";
  };
  // Far from the home's own rooms.
  std::ofstream(dir_ / "row.ttl") << "@prefix geo: <http://www.opengis.net/ont/geosparql#> .\n@prefix tv: <https://w3id.org/tahvel#> .\n"
                                  << room("ra", "POLYGON((100 0, 104 0, 104 3, 100 3, 100 0))")
                                  << room("rb", "POLYGON((104 0, 108 0, 108 3, 104 3, 104 0))")
                                  << room("rc", "POLYGON((108 0, 112 0, 112 3, 108 3, 108 0))") << mote("m-a", "101 1")
                                  << mote("m-ab", "104 1") << mote("m-b", "106 1") << mote("m-bc", "108 3");
  const auto prepare = [&] {
    ASSERT_EQ(run(bin("tahvel") + " put " + store_ + " --persistent " + (dir_ / "row.ttl").string() + " > /dev/null"), 0);
    subscribe("ra-temperature", Quantity::temperature, "ra", 300, 0);
    subscribe("rb-temperature", Quantity::temperature, "rb", 300, 0);
    subscribe("rc-temperature", Quantity::temperature, "rc", 600, 0);
  };
  prepare();
  simulate_one_hour();
  auto all = readings();
  const std::map<std::string, std::vector<std::string>> motes_of = {
      {"ra", {"m-a", "m-ab"}}, {"rb", {"m-ab", "m-b", "m-bc"}}, {"rc", {"m-bc"}}};
  const std::map<std::string, std::size_t> asked = {{"ra", 12}, {"rb", 12}, {"rc", 6}};
  for (const auto& [id, motes] : motes_of) {
    std::vector<std::int64_t> times;
    for (const std::string& m : motes)
      for (const Reading& r : all[{m, Quantity::temperature}]) times.push_back(r.at_ns);
    std::sort(times.begin(), times.end());
    EXPECT_TRUE(std::adjacent_find(times.begin(), times.end()) == times.end()) << id << ": two readings of one instant";
    if (id == "rc") EXPECT_GE(times.size(), asked.at(id)) << id;  // also read for rb, when it is rc's latest
    else EXPECT_EQ(times.size(), asked.at(id)) << id;
  }
  // Restarted every 150 s, it takes the schedule up from the board as it kept it running: a
  // reading counts for each room its mote stands in, after a restart (from the board) as while
  // it runs.
  fs::remove_all(store_);
  SetUp();
  prepare();
  for (int part = 0; part < 24; ++part)
    ASSERT_EQ(run(bin("tahvel-env-motes") + " " + store_ + " --seed 7 --steps 15 --step-s 10 --start-ns " +
                  std::to_string(kT0 + part * 150 * kS) + " 2> /dev/null"),
              0);
  auto restarted = readings();
  for (const char* m : {"m-a", "m-ab", "m-b", "m-bc"}) {
    std::vector<std::int64_t> want, got;
    for (const Reading& r : all[{m, Quantity::temperature}]) want.push_back(r.at_ns);
    for (const Reading& r : restarted[{m, Quantity::temperature}]) got.push_back(r.at_ns);
    EXPECT_EQ(got, want) << m;
  }
}

// The supervisor restarts a crashed simulator: it picks the schedule and the turns up from the
// readings on the board. Restarted every 150 s, the hour is the one an uninterrupted run gives
// (it sensed everything at once at each start, and the first mote always answered).
TEST_F(EnvironmentAgents, ARestartedSimulatorKeepsTheScheduleAndTheTurns) {
  subscribe("living-light", Quantity::light, "living", 300, 0);
  for (int part = 0; part < 24; ++part)
    ASSERT_EQ(run(bin("tahvel-env-motes") + " " + store_ + " --seed 7 --steps 15 --step-s 10 --start-ns " +
                  std::to_string(kT0 + part * 150 * kS) + " 2> /dev/null"),
              0);
  auto all = readings();
  const auto& one = all[{"mote-living-1", Quantity::light}];
  const auto& two = all[{"mote-living-2", Quantity::light}];
  EXPECT_EQ(one.size(), 6u);
  EXPECT_EQ(two.size(), 6u);
  for (std::size_t i = 1; i < one.size(); ++i) EXPECT_EQ(one[i].at_ns - one[i - 1].at_ns, 600 * kS);
}

TEST_F(EnvironmentAgents, ARoomWithNoFreshReadingShowsUnknown) {
  subscribe("bed-temp", Quantity::temperature, "bedroom", 300, 1800);  // ends after 30 min
  subscribe("living-move", Quantity::movement, "living", 60, 0, ThresholdRule{0.5, 10});
  subscribe("kitchen-humidity", Quantity::humidity, "kitchen", 600, 0);
  simulate_one_hour();

  aggregate_at(kT0 + 1700 * kS);  // last bedroom reading at 1500 s: 200 s old
  EXPECT_NE(environment("bedroom", "temperature"), "unknown");
  EXPECT_EQ(environment("bedroom", "temperatureAt"), std::to_string(kT0 + 1500 * kS));
  EXPECT_EQ(environment("bedroom", "humidity"), "unknown");  // never sensed
  EXPECT_EQ(environment("kitchen", "temperature"), "unknown");
  EXPECT_NE(environment("kitchen", "humidity"), "unknown");
  EXPECT_NE(environment("living", "movementLevel"), "unknown");
  EXPECT_EQ(environment("hall", "movementLevel"), "unknown");  // a PIR mote, but not asked
  EXPECT_EQ(environment("bedroom", "validTimeS"), "900.0");

  aggregate_at(kT0 + 3600 * kS);  // 2100 s after the last bedroom reading: stale
  EXPECT_EQ(environment("bedroom", "temperature"), "unknown");
  EXPECT_NE(environment("kitchen", "humidity"), "unknown");     // still sensed every 600 s
  EXPECT_NE(environment("living", "movementLevel"), "unknown");
}

// A mote carried from the bedroom to the hall: what it sensed in the bedroom must not become
// the hall's value. It counts for no room (the plan keeps no past places); what it senses in
// the hall counts for the hall.
TEST_F(EnvironmentAgents, AReadingFromBeforeAMoteWasMovedIsNotCreditedToItsNewRoom) {
  subscribe("bed-temp", Quantity::temperature, "bedroom", 300, 0);
  ASSERT_EQ(run(bin("tahvel-env-motes") + " " + store_ + " --seed 7 --steps 10 --step-s 10 --start-ns " +
                std::to_string(kT0) + " 2> /dev/null"),
            0);
  aggregate_at(kT0 + 100 * kS);
  ASSERT_NE(environment("bedroom", "temperature"), "unknown");
  ASSERT_EQ(environment("hall", "temperature"), "unknown");
  {
    auto node = node::Node::open(store_);
    ASSERT_TRUE(node.has_value());
    auto carer = node->agent("carer");
    ASSERT_TRUE(carer.has_value());
    ASSERT_TRUE(carer->store(located_feature_item(kHome + "/mote-bed", "POINT(6 4)", 0)).has_value());  // in the hall
  }
  aggregate_at(kT0 + 110 * kS);
  EXPECT_EQ(environment("hall", "temperature"), "unknown") << "the bedroom's reading, credited to the hall";
  EXPECT_EQ(environment("bedroom", "temperature"), "unknown");
  subscribe("hall-temp", Quantity::temperature, "hall", 300, 0);
  ASSERT_EQ(run(bin("tahvel-env-motes") + " " + store_ + " --seed 7 --steps 1 --step-s 10 --start-ns " +
                std::to_string(kT0 + 120 * kS) + " 2> /dev/null"),
            0);
  aggregate_at(kT0 + 130 * kS);
  EXPECT_NE(environment("hall", "temperature"), "unknown");
}

// A room taken off the floor plan has no state any more. Its last one stayed, read as current
// for ever (a rule on tv:environment kept firing on it).
TEST_F(EnvironmentAgents, ARoomTakenOffThePlanLosesItsEnvironment) {
  subscribe("kitchen-humidity", Quantity::humidity, "kitchen", 600, 0);
  simulate_one_hour();
  aggregate_at(kT0 + 3600 * kS);
  ASSERT_NE(environment("kitchen", "humidity"), "unknown");
  ASSERT_EQ(run(bin("tahvel") + " remove " + store_ + " -s '<" + kHome + "/room/kitchen>' > /dev/null"), 0);
  aggregate_at(kT0 + 3610 * kS);
  auto node = node::Node::open(store_);
  ASSERT_TRUE(node.has_value());
  auto snapshot = node->snapshot();
  ASSERT_TRUE(snapshot.has_value());
  EXPECT_TRUE(snapshot->list({.s = node::Term::iri(environment_iri(kHome + "/room/kitchen"))})->empty())
      << "the kitchen's last state is still on the board";
  EXPECT_TRUE(snapshot->list({.s = node::Term::iri(kHome + "/room/kitchen"), .p = node::Term::iri(kTv + "environment")})->empty());
  EXPECT_EQ(environment("bedroom", "humidity"), "unknown");  // the other rooms keep theirs
}

// Both programs run under the supervisor, which sends SIGTERM and kills what has not ended 5 s
// later (every `down` took 5 s per home, the environment agent waiting out its 60 s interval).
TEST_F(EnvironmentAgents, BothProgramsEndCleanlyOnSigtermWhileWaiting) {
  for (const auto& argv : {std::vector<std::string>{bin("tahvel-environment"), store_, "--interval-s", "60"},
                           std::vector<std::string>{bin("tahvel-env-motes"), store_, "--step-s", "60"}}) {
    tahvel::test_support::AgentProcess program(argv, (dir_ / "stderr").string());
    std::this_thread::sleep_for(std::chrono::milliseconds(700));  // in its wait, past its first round
    ASSERT_EQ(program.poll(), -1) << argv[0] << " ended by itself";
    const auto asked = std::chrono::steady_clock::now();
    EXPECT_EQ(program.stop(), 0) << argv[0];
    EXPECT_LT(std::chrono::steady_clock::now() - asked, std::chrono::seconds(5)) << argv[0] << " outlived the supervisor's grace";
  }
}

}  // namespace
}  // namespace tahvel::spatial
