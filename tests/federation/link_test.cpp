// The link protocol (docs/protocol.md) over the in-memory transport, with a seeded schedule of
// lost, doubled and reordered frames: items up exactly once (P7-P9), configuration down to the
// addressed node and agent only (P10-P11), registration checks (P1, P6), remote queries and their
// errors (P13-P16), malformed frames dropped (P4). Waits are bounded by deadlines, never sleeps
// that a result depends on.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <condition_variable>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <map>
#include <mutex>
#include <set>
#include <thread>

#include "tahvel/federation/link.h"
#include "tahvel/federation/transport.h"
#include "tahvel/federation/wire.h"
#include "eventually.h"
#include "temp_dir.h"

namespace tahvel::federation {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;
using node::Term;

const std::string kHospital = "http://example.org/hospital";
const std::string kHome1 = kHospital + "/home1";
const std::string kHome2 = kHospital + "/home2";
const std::string kEx = "http://example.org/ns#";
const Term kHrvProperty = Term::iri(std::string(vocab::kTv) + "HeartRateVariability");
const Term kObservedProperty = Term::iri("http://www.w3.org/ns/sosa/observedProperty");

// A store id as a store makes them (32 lowercase hex digits), all of one digit.
std::string store_of(char digit) { return std::string(32, digit); }

using tahvel::test_support::TempDir;

// Lines a link or transport logged, for assertions about drops and refusals.
struct Log {
  std::mutex mu;
  std::vector<std::string> lines;
  LinkLog sink() {
    return [this](std::string_view line) {
      std::lock_guard lock(mu);
      lines.emplace_back(line);
    };
  }
  bool has(std::string_view part) {
    std::lock_guard lock(mu);
    for (const auto& l : lines)
      if (l.find(part) != std::string::npos) return true;
    return false;
  }
  // How many lines hold `part`: a refusal or drop said once, not at every frame.
  std::size_t lines_with(std::string_view part) {
    std::lock_guard lock(mu);
    return static_cast<std::size_t>(std::count_if(lines.begin(), lines.end(), [&](const std::string& l) { return l.find(part) != std::string::npos; }));
  }
  std::string text() {  // for a failure's message
    std::lock_guard lock(mu);
    std::string all;
    for (const auto& l : lines) all += l + "\n";
    return all;
  }
};

using test_support::eventually;

node::Item hrv_item(int n) {
  node::Item item;
  const Term obs = Term::iri(kHome1 + "/rec/hrv/" + std::to_string(n));
  item.add(obs, kObservedProperty, kHrvProperty).add(obs, Term::iri(kEx + "n"), Term::integer(n));
  return item;
}

node::Item raw_item(int n) {
  node::Item item;
  item.add(Term::iri(kHome1 + "/rec/chunk/" + std::to_string(n)), Term::iri(kEx + "samples"),
           Term::literal("AAEC" + std::to_string(n)));
  return item;
}

// A forwarding policy for home1 written at the hospital: home1's agent "uplink" subscribes to raw
// samples too (context = home1's IRI, so it goes down to home1).
node::Item raw_samples_go_up() {
  node::Item policy;
  policy.context = kHome1;
  policy.persistent = true;
  const Term sub = Term::blank("sub");
  policy.add(sub, Term::iri(std::string(vocab::kTv) + "subscriber"), Term::iri(kHome1 + "/uplink"))
      .add(sub, Term::iri(std::string(vocab::kTv) + "predicate"), Term::iri(kEx + "samples"));
  return policy;
}
// home1's uplink's subscriptions: the default policy's one, and one per policy written since.
const node::Pattern kHome1UplinkSubscriptions{.p = Term::iri(std::string(vocab::kTv) + "subscriber"),
                                              .o = Term::iri(kHome1 + "/uplink")};

std::uint64_t count(const std::string& dir, node::Pattern pattern) {
  auto node = node::Node::open(dir);
  if (!node) return 0;
  return node->snapshot().value().count(pattern).value();
}

// The state the parent at `parent_dir` keeps of `child_iri` says "up" (P12).
bool state_says_up(const std::string& parent_dir, const std::string& child_iri) {
  return count(parent_dir, {.s = Term::iri(child_iri), .p = Term::iri(vocab::kLinkState), .o = Term::literal("up")}) == 1;
}

// The node's own view of its uplink (P12a): the objects of its tv:uplinkState records.
std::vector<std::string> uplink_states(const std::string& dir, const std::string& iri) {
  auto records = node::Node::open(dir).value().snapshot().value().list({.s = Term::iri(iri), .p = Term::iri(vocab::kUplinkState)}).value();
  std::vector<std::string> states;
  for (const auto& r : records) states.push_back(r.triple.o.value);
  return states;
}

// A hospital with two configured homes on one memory bus.
struct Tree {
  TempDir tmp{"tahvel-link"};
  MemoryBus bus;
  Log hospital_log, home1_log, home2_log;
  std::string hospital_dir = (tmp / "hospital").string();
  std::string home1_dir = (tmp / "home1").string();
  std::string home2_dir = (tmp / "home2").string();
  std::unique_ptr<Link> hospital, home1, home2;

  // The stores' settings but their IRIs (a ring, a literal limit, a maximum size).
  explicit Tree(node::InitOptions hospital_store = {}, node::InitOptions home1_store = {}) {
    hospital_store.iri = kHospital;
    home1_store.iri = kHome1;
    EXPECT_TRUE(node::Node::init(hospital_dir, hospital_store));
    EXPECT_TRUE(node::Node::init(home1_dir, home1_store));
    EXPECT_TRUE(node::Node::init(home2_dir, {.iri = kHome2}));
  }

  // With `say_leaving` false its stop is as its process dying: its children are not told (P12d).
  std::unique_ptr<Link> start_hospital(std::chrono::milliseconds ack_delay = LinkOptions{}.ack_delay, bool say_leaving = true) {
    return Link::start({.dir = hospital_dir, .say_leaving = say_leaving,
                        .down = std::shared_ptr<Transport>(bus.open(kHospital, hospital_log.sink())),
                        .children = {"home1", "home2"}, .resend_after = 100ms, .ack_delay = ack_delay,
                        .log = hospital_log.sink()})
        .value();
  }
  // home1 as a gateway on `endpoint` (its side towards the hospital and towards its children),
  // and a sensor node ecg1 below it with a store at `sensor_dir`: the sensor's link.
  std::unique_ptr<Link> start_gateway_and_sensor(std::shared_ptr<Transport> endpoint, const std::string& sensor_dir) {
    const std::string sensor_iri = kHome1 + "/ecg1";
    EXPECT_TRUE(node::Node::init(sensor_dir, {.iri = sensor_iri}));
    // Stopped by its tests as a killed process stops, unsaid (P15).
    home1 = Link::start({.dir = home1_dir, .parent_iri = kHospital, .up = endpoint, .say_leaving = false, .down = endpoint,
                         .resend_after = 100ms, .heartbeat_every = 200ms, .log = home1_log.sink()})
                .value();
    return Link::start({.dir = sensor_dir, .parent_iri = kHome1,
                        .up = std::shared_ptr<Transport>(bus.open(sensor_iri, home2_log.sink())),
                        .resend_after = 100ms, .heartbeat_every = 200ms, .log = home2_log.sink()})
        .value();
  }
  // The hospital, home1 as a gateway and the sensor ecg1 below it with its store at `sensor_dir`,
  // once home1 and the sensor are welcomed: the sensor's link.
  std::unique_ptr<Link> start_three_tiers(const std::string& sensor_dir) {
    hospital = start_hospital();
    auto sensor = start_gateway_and_sensor(std::shared_ptr<Transport>(bus.open(kHome1, home1_log.sink())), sensor_dir);
    EXPECT_TRUE(eventually([&] { return home1->connected() && sensor->connected(); }));
    return sensor;
  }
  // The hospital and home1, once the hospital's state of home1 says "up" (so a query is routed).
  bool start_hospital_and_home1() {
    hospital = start_hospital();
    home1 = start_home(home1_dir, kHome1, home1_log);
    return eventually([&] { return state_says_up(hospital_dir, kHome1); });
  }
  std::unique_ptr<Link> start_home(const std::string& dir, const std::string& iri, Log& log,
                                   std::size_t window = LinkOptions{}.window,
                                   std::chrono::milliseconds resend_after = 100ms) {
    return Link::start({.dir = dir, .parent_iri = kHospital, .up = std::shared_ptr<Transport>(bus.open(iri, log.sink())),
                        .window = window, .resend_after = resend_after, .heartbeat_every = 200ms, .log = log.sink()})
        .value();
  }
};

// Items in the outbox of the node at `dir`: stored there and not yet acknowledged by its parent.
std::uint64_t outbox(const std::string& dir) {
  return node::Node::open(dir).value().agent("uplink").value().pending().value();
}

// Fills the store at `dir` (of the node `iri`) to its last page with ex:fill records, smaller
// ones once larger ones no longer fit; they go with a removal of -p ex:fill.
void fill_to_the_last_page(const std::string& dir, const std::string& iri) {
  auto filler = node::Node::open(dir).value().agent("filler").value();
  int i = 0;
  for (std::size_t size : {2000, 200, 20})
    while (filler.store(node::Item{}.add(Term::iri(iri + "/f" + std::to_string(i)), Term::iri(kEx + "fill"),
                                         Term::literal(std::string(size, 'f') + std::to_string(i)))))
      ++i;
}

// Stores hrv_item(first) .. hrv_item(first + n - 1) on home1, each in its own transaction.
void store_hrv_items(const std::string& home_dir, int first, int n) {
  auto hrv = node::Node::open(home_dir).value().agent("hrv").value();
  for (int i = first; i < first + n; ++i) ASSERT_TRUE(hrv.store(hrv_item(i)));
}

// Stores hrv_item(first) .. on home1 (running) and waits until the hospital holds `total`
// numbered items and home1's outbox is empty: all of it acknowledged.
bool home1_sends(Tree& tree, int first, int n, std::uint64_t total) {
  store_hrv_items(tree.home1_dir, first, n);
  return eventually([&] {
    return count(tree.hospital_dir, {.p = Term::iri(kEx + "n")}) == total && outbox(tree.home1_dir) == 0;
  });
}

// P4: a node whose IRI is longer than a frame's sender may be would have every frame it sent
// dropped by its peers, who would never tell it why. Its link does not start, and says so.
TEST(Link, ANodeWhoseIriIsLongerThanAFrameMayNameDoesNotStartALink) {
  TempDir tmp{"tahvel-link"};
  const std::string iri = kHospital + "/" + std::string(kMaxFrameIriBytes, 'h');
  ASSERT_TRUE(node::Node::init((tmp / "long").string(), {.iri = iri}));
  MemoryBus bus;
  auto link = Link::start({.dir = (tmp / "long").string(), .down = std::shared_ptr<Transport>(bus.open(iri))});
  ASSERT_FALSE(link);
  EXPECT_EQ(link.error().code, Errc::invalid_argument);
  EXPECT_NE(link.error().message.find("the node IRI is " + std::to_string(iri.size()) + " bytes, over the 8192"), std::string::npos)
      << link.error().message.substr(0, 200);
}

TEST(Link, ItemsGoUpExactlyOnceThroughLossDuplicationAndReorderingAndRawSignalsStayHome) {
  Tree tree;
  tree.bus.set_faults({.seed = 7, .drop = 0.2, .duplicate = 0.1, .reorder = 0.1});
  tree.hospital = tree.start_hospital();
  tree.home1 = tree.start_home(tree.home1_dir, kHome1, tree.home1_log);
  auto home = node::Node::open(tree.home1_dir).value();
  auto hrv = home.agent("hrv").value();
  auto sensor = home.agent("ecg").value();
  constexpr int kItems = 400;
  for (int i = 0; i < kItems; ++i) {
    ASSERT_TRUE(hrv.store(hrv_item(i)));
    ASSERT_TRUE(sensor.store(raw_item(i)));
  }
  const node::Pattern numbered{.p = Term::iri(kEx + "n")};
  ASSERT_TRUE(eventually([&] { return count(tree.hospital_dir, numbered) >= kItems; }))
      << count(tree.hospital_dir, numbered) << " of " << kItems << " arrived";
  auto hospital = node::Node::open(tree.hospital_dir).value();
  // Let resends still in flight land (they must be dropped as duplicates).
  std::this_thread::sleep_for(500ms);
  auto records = hospital.snapshot().value().list(numbered).value();
  std::set<std::string> seen;
  for (const auto& r : records) {
    EXPECT_TRUE(seen.insert(r.triple.o.value).second) << "item " << r.triple.o.value << " arrived twice";
    EXPECT_EQ(r.meta.source, kHome1 + "/hrv");
  }
  EXPECT_EQ(seen.size(), static_cast<std::size_t>(kItems));
  EXPECT_EQ(count(tree.hospital_dir, {.p = Term::iri(kEx + "samples")}), 0u) << "raw ECG went up";
  EXPECT_GT(tree.home1->counters().up_resends, 0u) << "the fault schedule should have forced resends";
}

TEST(Link, AQuietLinkAcknowledgesItemsTogetherAfterTheAckDelayAndTheOutboxEmpties) {
  Tree tree;
  tree.hospital = tree.start_hospital();
  tree.home1 = tree.start_home(tree.home1_dir, kHome1, tree.home1_log);
  ASSERT_TRUE(eventually([&] { return tree.home1->connected(); }));
  const node::Pattern numbered{.p = Term::iri(kEx + "n")};
  for (int i = 0; i < 5; ++i) {  // one at a time, as an HRV agent writes: nothing else to ack with
    store_hrv_items(tree.home1_dir, i, 1);
    ASSERT_TRUE(eventually([&] { return count(tree.hospital_dir, numbered) == static_cast<std::uint64_t>(i + 1); }));
  }
  EXPECT_TRUE(eventually([&] { return outbox(tree.home1_dir) == 0; }))
      << outbox(tree.home1_dir) << " item(s) left in the outbox: a held ack was never sent";
  EXPECT_EQ(tree.home1->counters().up_resends, 0u) << "an ack held back made the home resend";
}

TEST(Link, ASendersFullWindowIsAcknowledgedAtOnceWhateverTheAckDelay) {
  Tree tree;
  tree.hospital = tree.start_hospital(10min);  // only the sender's ask or 256 items bring an ack
  tree.home1 = tree.start_home(tree.home1_dir, kHome1, tree.home1_log, /*window=*/8);
  ASSERT_TRUE(eventually([&] { return tree.home1->connected(); }));
  store_hrv_items(tree.home1_dir, 0, 300);
  const node::Pattern numbered{.p = Term::iri(kEx + "n")};
  EXPECT_TRUE(eventually([&] { return count(tree.hospital_dir, numbered) == 300; }))
      << count(tree.hospital_dir, numbered) << " of 300 arrived: the window of 8 stalled on a held ack";
  EXPECT_TRUE(eventually([&] { return outbox(tree.home1_dir) < 8; })) << outbox(tree.home1_dir);
  EXPECT_EQ(tree.home1->counters().up_resends, 0u) << "the window went on only by the home's resends";
}

TEST(Link, AStreamIsAcknowledgedEvery256ItemsWhateverTheAckDelay) {
  Tree tree;
  tree.hospital = tree.start_hospital(10min);
  // A window never half full here, and a resend only after 5 s: relaying the first 256 items
  // (under a sanitizer) may take longer than the usual 100 ms, and only their ack may end it.
  tree.home1 = tree.start_home(tree.home1_dir, kHome1, tree.home1_log, /*window=*/2048, /*resend_after=*/5s);
  ASSERT_TRUE(eventually([&] { return tree.home1->connected(); }));
  store_hrv_items(tree.home1_dir, 0, 600);
  const node::Pattern numbered{.p = Term::iri(kEx + "n")};
  ASSERT_TRUE(eventually([&] { return count(tree.hospital_dir, numbered) == 600; }));
  EXPECT_TRUE(eventually([&] { return outbox(tree.home1_dir) < 256; }))
      << outbox(tree.home1_dir) << " of 600 items still unacknowledged";
  EXPECT_EQ(tree.home1->counters().up_resends, 0u);
}

TEST(Link, AnItemWrittenWhileTheLinkIsCutArrivesOnceAfterItIsRestored) {
  Tree tree;
  tree.hospital = tree.start_hospital();
  tree.home1 = tree.start_home(tree.home1_dir, kHome1, tree.home1_log);
  ASSERT_TRUE(eventually([&] { return tree.home1->connected(); }));
  auto hrv = node::Node::open(tree.home1_dir).value().agent("hrv").value();
  for (int i = 0; i < 100; ++i) ASSERT_TRUE(hrv.store(hrv_item(i)));
  tree.bus.set_cut(kHospital, true);
  for (int i = 100; i < 200; ++i) ASSERT_TRUE(hrv.store(hrv_item(i)));
  // The hospital's link stops while cut; a new one starts from the marks in the store.
  tree.hospital.reset();
  tree.bus.set_cut(kHospital, false);
  for (int i = 200; i < 300; ++i) ASSERT_TRUE(hrv.store(hrv_item(i)));
  tree.hospital = tree.start_hospital();
  const node::Pattern numbered{.p = Term::iri(kEx + "n")};
  ASSERT_TRUE(eventually([&] { return count(tree.hospital_dir, numbered) >= 300; }));
  std::this_thread::sleep_for(300ms);
  EXPECT_EQ(count(tree.hospital_dir, numbered), 300u);
}

// P8: while its parent is down (not heard for child_silence) a home resent its whole window every
// resend_after, for as long as the outage lasted: 300 items every 100 ms here, over a LAN or a
// sensor's radio to no one. It sends one frame per go-back instead, a probe, and once the parent
// is back everything arrives, once.
TEST(Link, AHomeWhoseParentIsDownProbesWithOneFrameInsteadOfResendingItsWindow) {
  Tree tree;
  tree.hospital = tree.start_hospital(LinkOptions{}.ack_delay, /*say_leaving=*/false);  // it dies unheard
  tree.home1 = tree.start_home(tree.home1_dir, kHome1, tree.home1_log);
  ASSERT_TRUE(eventually([&] { return tree.home1->connected(); }));
  tree.hospital.reset();
  store_hrv_items(tree.home1_dir, 0, 300);
  ASSERT_TRUE(eventually([&] { return uplink_states(tree.home1_dir, kHome1) == std::vector<std::string>{"down"}; }, 10s));
  const std::uint64_t before = tree.home1->counters().up_sent;
  std::this_thread::sleep_for(4s);
  const std::uint64_t sent = tree.home1->counters().up_sent - before;
  // Probes every resend_after backed off (P8a) to 16 x 100 ms at most.
  EXPECT_LE(sent, 20u) << "frames sent in 4 s to a parent that is down (resend_after 100 ms)";
  EXPECT_GE(sent, 2u) << "the home stopped probing";
  tree.hospital = tree.start_hospital();
  const node::Pattern numbered{.p = Term::iri(kEx + "n")};
  ASSERT_TRUE(eventually([&] { return count(tree.hospital_dir, numbered) >= 300 && outbox(tree.home1_dir) == 0; }, 10s));
  EXPECT_EQ(count(tree.hospital_dir, numbered), 300u);
}

// P8a: a path that loses what it is given, while the parent is still taken to be there (before
// child_silence): the home resent its whole window every resend_after, 300 items every 100 ms
// here, about 9,000 frames in 3 s. An exploratory run cut a sensor LAN's capacity by a tenth and
// the sensors' resends offered it 23 times its load. Each go-back the last did not get past
// halves the window and doubles the wait; once frames pass again, everything arrives, once.
TEST(Link, AHomeWhoseGoBacksDoNotGetThroughBacksOffItsWindowAndItsResends) {
  Tree tree;
  tree.hospital = tree.start_hospital();
  tree.home1 = tree.start_home(tree.home1_dir, kHome1, tree.home1_log);
  ASSERT_TRUE(eventually([&] { return tree.home1->connected(); }));
  tree.bus.set_cut(kHospital, true);
  const std::uint64_t before = tree.home1->counters().up_sent;
  store_hrv_items(tree.home1_dir, 0, 300);
  std::this_thread::sleep_for(3s);  // within child_silence (3.5 s): no probes yet
  const std::uint64_t sent = tree.home1->counters().up_sent - before;
  EXPECT_LE(sent, 2000u) << "frames sent in 3 s for 300 items none of which got through (resend_after 100 ms)";
  EXPECT_GE(sent, 600u) << "the home stopped resending";
  tree.bus.set_cut(kHospital, false);
  const node::Pattern numbered{.p = Term::iri(kEx + "n")};
  ASSERT_TRUE(eventually([&] { return count(tree.hospital_dir, numbered) >= 300 && outbox(tree.home1_dir) == 0; }, 15s))
      << count(tree.hospital_dir, numbered);
  EXPECT_EQ(count(tree.hospital_dir, numbered), 300u);
  // The window opens again as the mark moves: 300 more go up at once, without the go-backs of a
  // window left shut. One or two go-backs are an ack later than resend_after (100 ms) under a
  // slow build: the AddressSanitizer one of session 85 went back once in one run of five.
  const std::uint64_t resends = tree.home1->counters().up_resends;
  store_hrv_items(tree.home1_dir, 300, 300);
  ASSERT_TRUE(eventually([&] { return count(tree.hospital_dir, numbered) >= 600 && outbox(tree.home1_dir) == 0; }, 15s));
  EXPECT_LE(tree.home1->counters().up_resends - resends, 2u);
}

// P6a: a home whose store is made again (a replaced disk or gateway) issues item ids from the
// start. The hospital's mark of the old store's stream must not swallow them as duplicates.
TEST(Link, AChildWhoseStoreIsMadeAgainHasAllOfItsNewItemsArrive) {
  Tree tree;
  tree.hospital = tree.start_hospital();
  tree.home1 = tree.start_home(tree.home1_dir, kHome1, tree.home1_log);
  ASSERT_TRUE(home1_sends(tree, 0, 50, 50));
  const node::Pattern numbered{.p = Term::iri(kEx + "n")};
  tree.home1.reset();
  std::filesystem::remove_all(tree.home1_dir);
  ASSERT_TRUE(node::Node::init(tree.home1_dir, {.iri = kHome1}));
  tree.home1 = tree.start_home(tree.home1_dir, kHome1, tree.home1_log);  // subscribes the outbox
  store_hrv_items(tree.home1_dir, 1000, 10);
  EXPECT_TRUE(eventually([&] { return count(tree.hospital_dir, numbered) == 60; })) << count(tree.hospital_dir, numbered);
  EXPECT_TRUE(tree.hospital_log.has("has another store"));
}

// HRV window n of home1 as a gateway computes it: named by its start, asserted at its signal
// time, derived from an RR item whose name depends on where the gateway's RR series began.
node::Item window_item(int n, const std::string& rr_series) {
  node::Item item = hrv_item(n);
  item.asserted_at = 1'780'000'000'000'000'000 + std::int64_t{n} * 300'000'000'000;
  item.add(Term::iri(kHome1 + "/rec/hrv/" + std::to_string(n)), Term::iri("http://www.w3.org/ns/prov#wasDerivedFrom"),
           Term::iri(kHome1 + "/rec/rr/" + rr_series + std::to_string(n)));
  return item;
}

// P10c: a standby gateway with a store of its own takes home1's place and computes its HRV
// windows again from RR items cut otherwise (a sensor's ring no longer holding the recording's
// start). The hospital keeps the window of each name it held; the windows after them arrive.
// Up to session 71 it held both of each (docs/deploy.md).
TEST(Link, WindowsAStoreInTheChildsPlaceComputesAgainAreNotDoubledAtTheParent) {
  Tree tree;
  tree.hospital = tree.start_hospital();
  tree.home1 = tree.start_home(tree.home1_dir, kHome1, tree.home1_log);
  const node::Pattern numbered{.p = Term::iri(kEx + "n")};
  {
    auto hrv = node::Node::open(tree.home1_dir).value().agent("hrv").value();
    for (int n = 0; n < 10; ++n) ASSERT_TRUE(hrv.store(window_item(n, "first-")));
  }
  ASSERT_TRUE(eventually([&] { return count(tree.hospital_dir, numbered) == 10 && outbox(tree.home1_dir) == 0; }));
  tree.home1.reset();
  std::filesystem::remove_all(tree.home1_dir);
  ASSERT_TRUE(node::Node::init(tree.home1_dir, {.iri = kHome1}));
  tree.home1 = tree.start_home(tree.home1_dir, kHome1, tree.home1_log);
  {
    auto hrv = node::Node::open(tree.home1_dir).value().agent("hrv").value();
    for (int n = 0; n < 15; ++n) ASSERT_TRUE(hrv.store(window_item(n, "later-")));
  }
  EXPECT_TRUE(eventually([&] { return count(tree.hospital_dir, numbered) >= 15 && outbox(tree.home1_dir) == 0; }))
      << count(tree.hospital_dir, numbered) << " windows at the hospital";
  std::this_thread::sleep_for(300ms);
  EXPECT_EQ(count(tree.hospital_dir, numbered), 15u);
  for (int n : {0, 9, 10, 14}) EXPECT_EQ(count(tree.hospital_dir, {.p = Term::iri(kEx + "n"), .o = Term::integer(n)}), 1u) << n;
  const node::Pattern first_series{.o = Term::iri(kHome1 + "/rec/rr/first-0")};
  EXPECT_EQ(count(tree.hospital_dir, first_series), 1u) << "the window held is kept";
  EXPECT_TRUE(tree.hospital_log.has("of them computed again with other triples")) << tree.hospital_log.text();
}

// Keeps the bytes of the store at `store` (nothing has it open) in `snapshot`, for
// roll_back_in_place.
void take_snapshot(const std::filesystem::path& store, const std::filesystem::path& snapshot) {
  std::filesystem::create_directories(snapshot);
  std::filesystem::copy_file(store / "data.mdb", snapshot / "data.mdb");
}

// Puts the bytes of `snapshot` (take_snapshot) back into the data file of the store at `store`,
// which stays the same file: a VM or filesystem snapshot rolled back. The store keeps its id
// (a copy put in its place would take a new one at its first open: Store tests), and only its
// peers' marks can show that it went back in time (docs/protocol.md P6a, P6d).
void roll_back_in_place(const std::filesystem::path& snapshot, const std::filesystem::path& store) {
  std::ifstream from(snapshot / "data.mdb", std::ios::binary);
  std::ofstream to(store / "data.mdb", std::ios::binary | std::ios::in | std::ios::trunc);
  to << from.rdbuf();
  ASSERT_TRUE(to.flush()) << "cannot write " << (store / "data.mdb").string();
  std::filesystem::remove_all(snapshot);
}

// Takes a snapshot of home1's store (its link stopped), lets it send `n` items more (numbered
// from `first`; `total` at the hospital then) and rolls the store back to the snapshot: home1's
// link is stopped, and its store has gone back in time under its id.
void roll_home1_back_after_sending_more(Tree& tree, int first, int n, std::uint64_t total) {
  tree.home1.reset();
  const std::filesystem::path snapshot = tree.tmp / "home1-snapshot";
  take_snapshot(tree.home1_dir, snapshot);
  tree.home1 = tree.start_home(tree.home1_dir, kHome1, tree.home1_log);
  ASSERT_TRUE(home1_sends(tree, first, n, total));
  tree.home1.reset();
  ASSERT_NO_FATAL_FAILURE(roll_back_in_place(snapshot, tree.home1_dir));
}

// Both ends running, and home1's items n = 0..9 at the hospital, its outbox empty.
void both_running_with_ten_of_home1s_items_sent(Tree& tree) {
  tree.hospital = tree.start_hospital();
  tree.home1 = tree.start_home(tree.home1_dir, kHome1, tree.home1_log);
  ASSERT_TRUE(home1_sends(tree, 0, 10, 10));
}

// P6a: a home's store rolled back to a snapshot goes back in time under its id: its next ids
// are ones the hospital has applied already. The hospital's mark shows it; the home takes a new
// store id and its new items arrive.
TEST(Link, AChildRolledBackToASnapshotHasItsNewItemsArrive) {
  Tree tree;
  tree.hospital = tree.start_hospital();
  tree.home1 = tree.start_home(tree.home1_dir, kHome1, tree.home1_log);
  ASSERT_TRUE(home1_sends(tree, 0, 10, 10));
  ASSERT_NO_FATAL_FAILURE(roll_home1_back_after_sending_more(tree, 100, 40, 50));
  store_hrv_items(tree.home1_dir, 1000, 5);
  tree.home1 = tree.start_home(tree.home1_dir, kHome1, tree.home1_log);
  EXPECT_TRUE(eventually([&] { return count(tree.hospital_dir, {.p = Term::iri(kEx + "n")}) >= 55; }));
  for (int n = 1000; n < 1005; ++n)
    EXPECT_EQ(count(tree.hospital_dir, {.p = Term::iri(kEx + "n"), .o = Term::integer(n)}), 1u) << n;
  EXPECT_TRUE(tree.home1_log.has("this store takes a new id"));
}

// P10c: a home's store rolled back to a snapshot taken while items waited in its outbox (its
// link stopped) sends them again on its new stream. The hospital had applied them from the
// stream before, and keeps one of each; what the home writes after the roll-back arrives.
TEST(Link, ItemsWaitingInTheOutboxOfAChildsSnapshotAreNotDoubledAtTheParent) {
  Tree tree;
  const node::Pattern numbered{.p = Term::iri(kEx + "n")};
  ASSERT_NO_FATAL_FAILURE(both_running_with_ten_of_home1s_items_sent(tree));
  tree.home1.reset();
  store_hrv_items(tree.home1_dir, 100, 20);  // they wait in the outbox, and so in the snapshot
  ASSERT_EQ(outbox(tree.home1_dir), 20u);
  const std::filesystem::path snapshot = tree.tmp / "home1-snapshot";
  take_snapshot(tree.home1_dir, snapshot);
  tree.home1 = tree.start_home(tree.home1_dir, kHome1, tree.home1_log);
  ASSERT_TRUE(eventually([&] { return count(tree.hospital_dir, numbered) == 30 && outbox(tree.home1_dir) == 0; }));
  ASSERT_TRUE(home1_sends(tree, 200, 5, 35));
  tree.home1.reset();
  ASSERT_NO_FATAL_FAILURE(roll_back_in_place(snapshot, tree.home1_dir));
  tree.home1 = tree.start_home(tree.home1_dir, kHome1, tree.home1_log);
  ASSERT_TRUE(eventually([&] { return tree.home1_log.has("this store takes a new id"); })) << "the case under test did not happen: "
                                                                                         << tree.home1_log.text();
  store_hrv_items(tree.home1_dir, 1000, 3);
  EXPECT_TRUE(eventually([&] { return count(tree.hospital_dir, numbered) == 38 && outbox(tree.home1_dir) == 0; }))
      << count(tree.hospital_dir, numbered) << " numbered items at the hospital";
  std::this_thread::sleep_for(300ms);
  EXPECT_EQ(count(tree.hospital_dir, numbered), 38u);
  for (int n : {100, 119, 1000, 1002}) EXPECT_EQ(count(tree.hospital_dir, {.p = Term::iri(kEx + "n"), .o = Term::integer(n)}), 1u) << n;
  EXPECT_TRUE(tree.hospital_log.has("that this store holds already (sent again on a new stream")) << tree.hospital_log.text();
}

// P6a with a backup made by Node::back_up (`tahvel backup`): the copy has a store id of its own,
// so a home restored from it is another store to the hospital from its first hello. Up to
// session 62 the copy kept the id, and only a mark of the hospital's above what the home's link
// could have sent showed the restore: agents that wrote more, before the link started, than
// the hospital had applied since the backup hid it, and the hospital dropped their first items
// as ones it had.
void restored_home1_whose_agents_wrote_before_its_link_started_loses_nothing(
    Tree& tree, const std::function<void(const std::filesystem::path& backup)>& back_up) {
  const node::Pattern numbered{.p = Term::iri(kEx + "n")};
  ASSERT_NO_FATAL_FAILURE(both_running_with_ten_of_home1s_items_sent(tree));
  const std::filesystem::path backup = tree.tmp / "home1-backup";
  ASSERT_NO_FATAL_FAILURE(back_up(backup));
  ASSERT_TRUE(home1_sends(tree, 100, 5, 15));
  tree.home1.reset();
  std::filesystem::remove_all(tree.home1_dir);
  std::filesystem::rename(backup, tree.home1_dir);
  store_hrv_items(tree.home1_dir, 1000, 50);  // before its link starts
  tree.home1 = tree.start_home(tree.home1_dir, kHome1, tree.home1_log);
  EXPECT_TRUE(eventually([&] { return count(tree.hospital_dir, numbered) == 65 && outbox(tree.home1_dir) == 0; }))
      << count(tree.hospital_dir, numbered) << " numbered items at the hospital, " << outbox(tree.home1_dir) << " in the outbox";
  for (int n : {1000, 1001, 1004, 1049}) EXPECT_EQ(count(tree.hospital_dir, {.p = Term::iri(kEx + "n"), .o = Term::integer(n)}), 1u) << n;
}

TEST(Link, AChildRestoredFromABackupWhoseAgentsWroteBeforeItsLinkStartedLosesNothing) {
  Tree tree;
  restored_home1_whose_agents_wrote_before_its_link_started_loses_nothing(tree, [&](const std::filesystem::path& backup) {
    ASSERT_TRUE(node::Node::open(tree.home1_dir).value().back_up(backup));
  });
}

// The same with a copy made by `cp -a` while home1's link was stopped, not by `tahvel backup`:
// its data file is another file, so its first open gives it a store id of its own (P6a). Up to
// session 63 it kept the id, and lost 5 of these 50 items as the backup above did.
TEST(Link, AChildRestoredFromAFileCopyWhoseAgentsWroteBeforeItsLinkStartedLosesNothing) {
  Tree tree;
  restored_home1_whose_agents_wrote_before_its_link_started_loses_nothing(tree, [&](const std::filesystem::path& backup) {
    tree.home1.reset();
    std::filesystem::copy(tree.home1_dir, backup, std::filesystem::copy_options::recursive);
    tree.home1 = tree.start_home(tree.home1_dir, kHome1, tree.home1_log);
  });
}

// P10c across a gateway: home1, between its sensor and the hospital, restored from a backup.
// The sensor sends again what home1 had acknowledged after the backup (P6d), and home1 relays
// those items again under ids of its new stream. Its own agents wrote before its link started,
// so those ids lie beyond the hospital's mark of home1's old stream, where up to session 63 the
// hospital looked for no twins: it held each of those items twice.
TEST(Link, ItemsASensorSendsAgainToItsRestoredGatewayAreNotDoubledAtTheHospital) {
  Tree tree;
  const std::string sensor_dir = (tree.tmp / "ecg1").string();
  auto sensor_link = tree.start_three_tiers(sensor_dir);
  const node::Pattern numbered{.p = Term::iri(kEx + "n")};
  auto all_sent = [&](std::uint64_t total) {
    return eventually([&] {
      return count(tree.hospital_dir, numbered) == total && outbox(sensor_dir) == 0 && outbox(tree.home1_dir) == 0;
    }, 20s);
  };
  store_hrv_items(sensor_dir, 0, 5);
  ASSERT_TRUE(all_sent(5));
  const std::filesystem::path backup = tree.tmp / "home1-backup";
  ASSERT_TRUE(node::Node::open(tree.home1_dir).value().back_up(backup));
  store_hrv_items(sensor_dir, 100, 20);
  ASSERT_TRUE(all_sent(25));
  tree.home1.reset();
  std::filesystem::remove_all(tree.home1_dir);
  std::filesystem::rename(backup, tree.home1_dir);
  store_hrv_items(tree.home1_dir, 1000, 60);  // before its link starts
  auto endpoint = std::shared_ptr<Transport>(tree.bus.open(kHome1, tree.home1_log.sink()));
  tree.home1 = Link::start({.dir = tree.home1_dir, .parent_iri = kHospital, .up = endpoint, .down = endpoint,
                            .resend_after = 100ms, .heartbeat_every = 200ms, .log = tree.home1_log.sink()})
                   .value();
  ASSERT_TRUE(eventually([&] { return tree.home2_log.has("what it lacks after that goes up again (P6d)"); }, 20s))
      << "the case under test did not happen: " << tree.home2_log.text();
  EXPECT_TRUE(all_sent(85)) << count(tree.hospital_dir, numbered) << " numbered items at the hospital";
  std::this_thread::sleep_for(300ms);
  EXPECT_EQ(count(tree.hospital_dir, numbered), 85u);
  for (int n : {100, 110, 119, 1000, 1059})
    EXPECT_EQ(count(tree.hospital_dir, {.p = Term::iri(kEx + "n"), .o = Term::integer(n)}), 1u) << n;
}

// Both ends running, and at the hospital: a persistent item of home1 (its description, n = 7)
// and five others (n = 0..4).
void home1_sends_a_description_and_five_items(Tree& tree) {
  tree.hospital = tree.start_hospital();
  tree.home1 = tree.start_home(tree.home1_dir, kHome1, tree.home1_log);
  node::Item description = hrv_item(7);
  description.persistent = true;
  ASSERT_TRUE(node::Node::open(tree.home1_dir).value().agent("hrv").value().store(description));
  ASSERT_TRUE(home1_sends(tree, 0, 5, 6));
}

// P6c: a parent whose store is made again (a replaced gateway) holds nothing of what the store
// before it applied. What the child wrote once and keeps (persistent: a recording's description,
// which the parent's agents need for every chunk after it) goes up again; the rest does not.
TEST(Link, APersistentItemGoesUpAgainToAParentWhoseStoreIsMadeAgain) {
  Tree tree;
  ASSERT_NO_FATAL_FAILURE(home1_sends_a_description_and_five_items(tree));
  tree.hospital.reset();
  std::filesystem::remove_all(tree.hospital_dir);
  ASSERT_TRUE(node::Node::init(tree.hospital_dir, {.iri = kHospital}));
  tree.hospital = tree.start_hospital();
  store_hrv_items(tree.home1_dir, 100, 2);
  EXPECT_TRUE(eventually([&] { return count(tree.hospital_dir, {.p = Term::iri(kEx + "n")}) == 3; }))
      << count(tree.hospital_dir, {.p = Term::iri(kEx + "n")});
  EXPECT_EQ(count(tree.hospital_dir, {.p = Term::iri(kEx + "n"), .o = Term::integer(7)}), 1u);
  EXPECT_TRUE(eventually([&] { return outbox(tree.home1_dir) == 0; })) << "the new store's acknowledgements empty the outbox";
  EXPECT_TRUE(tree.home1_log.has("1 persistent item(s) its policy routes go up again"));
  // The home's log says what the new store lacks (an operator saw only "a new stream").
  EXPECT_TRUE(tree.home1_log.has("of what went up to the store before, only persistent items are sent again (P6c)"));
  // A restart of either link is not a new store: nothing goes up twice.
  tree.home1.reset();
  tree.home1 = tree.start_home(tree.home1_dir, kHome1, tree.home1_log);
  store_hrv_items(tree.home1_dir, 200, 1);
  EXPECT_TRUE(eventually([&] { return count(tree.hospital_dir, {.p = Term::iri(kEx + "n")}) == 4; }));
  std::this_thread::sleep_for(300ms);
  EXPECT_EQ(count(tree.hospital_dir, {.p = Term::iri(kEx + "n"), .o = Term::integer(7)}), 1u);
}

// P6c with P6a: a home's store rolled back to a snapshot takes a new store id once the
// hospital's mark shows it, and the hospital holds nothing of the new stream; the home's
// persistent items go up again, and the hospital, which has them from the stream before, keeps
// one of each.
TEST(Link, APersistentItemOfAStoreRolledBackToASnapshotIsNotDoubledAtTheParent) {
  Tree tree;
  ASSERT_NO_FATAL_FAILURE(home1_sends_a_description_and_five_items(tree));
  ASSERT_NO_FATAL_FAILURE(roll_home1_back_after_sending_more(tree, 100, 5, 11));
  tree.home1 = tree.start_home(tree.home1_dir, kHome1, tree.home1_log);
  store_hrv_items(tree.home1_dir, 200, 2);
  const node::Pattern numbered{.p = Term::iri(kEx + "n")};
  EXPECT_TRUE(eventually([&] { return count(tree.hospital_dir, numbered) == 13; })) << count(tree.hospital_dir, numbered);
  EXPECT_TRUE(tree.home1_log.has("persistent item(s) its policy routes go up again")) << "the case under test did not happen: " << tree.home1_log.text();
  EXPECT_TRUE(eventually([&] { return outbox(tree.home1_dir) == 0; }));
  std::this_thread::sleep_for(300ms);
  EXPECT_EQ(count(tree.hospital_dir, {.p = Term::iri(kEx + "n"), .o = Term::integer(7)}), 1u) << "the description is doubled";
  EXPECT_EQ(count(tree.hospital_dir, numbered), 13u);
}

// P6d: a hospital whose store is rolled back to a snapshot (under its id) holds home1's stream
// only up to the snapshot, though it had acknowledged more, and home1 had emptied its outbox of
// that. Those items go up again (home1 still holds them), persistent or not; the home's link
// restarted meanwhile, so it knows of the gap only from its outbox. They were lost, without a
// word in either log.
TEST(Link, ItemsAParentRolledBackToASnapshotHadAcknowledgedGoUpAgain) {
  Tree tree;
  ASSERT_NO_FATAL_FAILURE(home1_sends_a_description_and_five_items(tree));
  tree.hospital.reset();
  const std::filesystem::path snapshot = tree.tmp / "hospital-snapshot";
  take_snapshot(tree.hospital_dir, snapshot);
  tree.hospital = tree.start_hospital();
  node::Item setting = hrv_item(8);
  setting.persistent = true;
  ASSERT_TRUE(node::Node::open(tree.home1_dir).value().agent("hrv").value().store(setting));
  ASSERT_TRUE(home1_sends(tree, 100, 5, 12));
  tree.hospital.reset();
  ASSERT_NO_FATAL_FAILURE(roll_back_in_place(snapshot, tree.hospital_dir));
  tree.home1.reset();
  tree.home1 = tree.start_home(tree.home1_dir, kHome1, tree.home1_log);
  tree.hospital = tree.start_hospital();
  store_hrv_items(tree.home1_dir, 200, 2);
  const node::Pattern numbered{.p = Term::iri(kEx + "n")};
  EXPECT_TRUE(eventually([&] { return count(tree.hospital_dir, numbered) == 14 && outbox(tree.home1_dir) == 0; }))
      << count(tree.hospital_dir, numbered) << " at the hospital, " << outbox(tree.home1_dir) << " in the outbox";
  std::this_thread::sleep_for(300ms);
  for (int n : {0, 1, 2, 3, 4, 7, 8, 100, 101, 102, 103, 104, 200, 201})
    EXPECT_EQ(count(tree.hospital_dir, {.p = Term::iri(kEx + "n"), .o = Term::integer(n)}), 1u) << n;
  EXPECT_TRUE(tree.home1_log.has("6 item(s) it acknowledged after that go up again (P6d)")) << tree.home1_log.text();
}

// P6e: a hospital restored from a backup made before home1 first registered holds nothing of
// home1's stream: its mark is 0, as a store made new would say (P6c, persistent items only).
// It is a copy of the store home1 was linked with, and says so in its welcome, so everything
// home1 sent up since goes up again. Up to session 79 home1 sent only its description: the
// hospital lost the other five items, which home1 had taken out of its outbox.
TEST(Link, ItemsAParentRestoredFromABackupOlderThanTheChildsFirstLinkHadGoUpAgain) {
  Tree tree;
  const std::filesystem::path backup = tree.tmp / "hospital-backup";
  ASSERT_TRUE(node::Node::open(tree.hospital_dir).value().back_up(backup));
  ASSERT_NO_FATAL_FAILURE(home1_sends_a_description_and_five_items(tree));
  tree.hospital.reset();
  std::filesystem::remove_all(tree.hospital_dir);
  std::filesystem::rename(backup, tree.hospital_dir);
  tree.hospital = tree.start_hospital();
  store_hrv_items(tree.home1_dir, 100, 2);
  const node::Pattern numbered{.p = Term::iri(kEx + "n")};
  EXPECT_TRUE(eventually([&] { return count(tree.hospital_dir, numbered) == 8 && outbox(tree.home1_dir) == 0; }))
      << count(tree.hospital_dir, numbered) << " at the hospital, " << outbox(tree.home1_dir) << " in the outbox\n"
      << tree.home1_log.text();
  std::this_thread::sleep_for(300ms);
  for (int n : {0, 1, 2, 3, 4, 7, 100, 101})
    EXPECT_EQ(count(tree.hospital_dir, {.p = Term::iri(kEx + "n"), .o = Term::integer(n)}), 1u) << n;
  EXPECT_TRUE(tree.home1_log.has("6 item(s) the stores before had acknowledged go up again (P6e)")) << tree.home1_log.text();
  EXPECT_TRUE(tree.hospital_log.has("and this store, a copy (restored from a backup), holds nothing of its stream")) << tree.hospital_log.text();
  // A restart of either link later is no copy: nothing goes up again.
  tree.home1.reset();
  tree.home1 = tree.start_home(tree.home1_dir, kHome1, tree.home1_log);
  store_hrv_items(tree.home1_dir, 200, 1);
  EXPECT_TRUE(eventually([&] { return count(tree.hospital_dir, numbered) == 9 && outbox(tree.home1_dir) == 0; }));
  std::this_thread::sleep_for(300ms);
  EXPECT_EQ(count(tree.hospital_dir, numbered), 9u);
}

// P6e after two restores: the hospital restored from backup B1 (P6d), then from B0, made
// before home1 first linked. Home1 was last linked with B1's store, of which B0 is no copy
// (both are copies of the store before them): B0 asks all the same, and gets everything home1
// had sent. Asked only by copies of the store the hello named, home1 sent its description
// alone (an exploratory run of session 80).
TEST(Link, ItemsAParentRestoredFromAnOlderBackupAfterAnotherRestoreHadGoUpAgain) {
  Tree tree;
  const std::filesystem::path b0 = tree.tmp / "hospital-b0", b1 = tree.tmp / "hospital-b1";
  ASSERT_TRUE(node::Node::open(tree.hospital_dir).value().back_up(b0));
  ASSERT_NO_FATAL_FAILURE(home1_sends_a_description_and_five_items(tree));
  ASSERT_TRUE(node::Node::open(tree.hospital_dir).value().back_up(b1));
  ASSERT_TRUE(home1_sends(tree, 100, 5, 11));
  const node::Pattern numbered{.p = Term::iri(kEx + "n")};
  auto restore = [&](const std::filesystem::path& backup) {
    tree.hospital.reset();
    std::filesystem::remove_all(tree.hospital_dir);
    std::filesystem::rename(backup, tree.hospital_dir);
    tree.hospital = tree.start_hospital();
  };
  restore(b1);
  ASSERT_TRUE(eventually([&] { return count(tree.hospital_dir, numbered) == 11 && outbox(tree.home1_dir) == 0; }))
      << count(tree.hospital_dir, numbered) << " at the hospital restored from B1\n" << tree.home1_log.text();
  ASSERT_TRUE(tree.home1_log.has("(P6d)")) << tree.home1_log.text();
  restore(b0);
  store_hrv_items(tree.home1_dir, 200, 1);
  EXPECT_TRUE(eventually([&] { return count(tree.hospital_dir, numbered) == 12 && outbox(tree.home1_dir) == 0; }))
      << count(tree.hospital_dir, numbered) << " at the hospital restored from B0\n" << tree.home1_log.text();
  std::this_thread::sleep_for(300ms);
  for (int n : {0, 4, 7, 100, 104, 200}) EXPECT_EQ(count(tree.hospital_dir, {.p = Term::iri(kEx + "n"), .o = Term::integer(n)}), 1u) << n;
  EXPECT_TRUE(tree.home1_log.has("11 item(s) the stores before had acknowledged go up again (P6e)")) << tree.home1_log.text();
}

// P6e is for a stream the parent lacks, not for a child's new one: the hospital restored from a
// backup older than home1's first link (P6e: everything comes back), then home1 restored from a
// backup of its own, which names the hospital's store before. The restored hospital holds part
// of home1's stream before, so the new stream is P6c with P10c: an item removed at the hospital
// since stays removed. Asked for everything (found by a review of session 80), home1 sent the
// whole of its history again and the removed item came back.
TEST(Link, AChildRestoredFromABackupAfterItsParentWasIsNotAskedForAllItSent) {
  Tree tree;
  const std::filesystem::path hospital_backup = tree.tmp / "hospital-backup", home1_backup = tree.tmp / "home1-backup";
  ASSERT_TRUE(node::Node::open(tree.hospital_dir).value().back_up(hospital_backup));
  ASSERT_NO_FATAL_FAILURE(home1_sends_a_description_and_five_items(tree));
  std::this_thread::sleep_for(2500ms);  // home1's board names the hospital's store it is linked with
  ASSERT_TRUE(node::Node::open(tree.home1_dir).value().back_up(home1_backup));
  tree.hospital.reset();
  std::filesystem::remove_all(tree.hospital_dir);
  std::filesystem::rename(hospital_backup, tree.hospital_dir);
  tree.hospital = tree.start_hospital();
  const node::Pattern numbered{.p = Term::iri(kEx + "n")};
  const node::Pattern one{.p = Term::iri(kEx + "n"), .o = Term::integer(1)};
  ASSERT_TRUE(eventually([&] { return count(tree.hospital_dir, numbered) == 6 && outbox(tree.home1_dir) == 0; }))
      << count(tree.hospital_dir, numbered) << "\n" << tree.home1_log.text();
  {
    auto hospital = node::Node::open(tree.hospital_dir).value();
    auto held = hospital.snapshot().value().list(one).value();
    ASSERT_EQ(held.size(), 1u);
    ASSERT_TRUE(hospital.remove_item(held[0].meta.item));
  }
  tree.home1.reset();
  std::filesystem::remove_all(tree.home1_dir);
  std::filesystem::rename(home1_backup, tree.home1_dir);
  tree.home1 = tree.start_home(tree.home1_dir, kHome1, tree.home1_log);
  store_hrv_items(tree.home1_dir, 100, 1);
  EXPECT_TRUE(eventually([&] { return count(tree.hospital_dir, numbered) == 6 && outbox(tree.home1_dir) == 0; }))
      << count(tree.hospital_dir, numbered) << "\n" << tree.home1_log.text() << "\n" << tree.hospital_log.text();
  std::this_thread::sleep_for(300ms);
  EXPECT_EQ(count(tree.hospital_dir, one), 0u) << "the removed item came back\n" << tree.home1_log.text();
  EXPECT_EQ(count(tree.hospital_dir, {.p = Term::iri(kEx + "n"), .o = Term::integer(100)}), 1u);
}

// P6d on a plain restart (nothing restored): the item at the parent's mark, whose triple the
// policy matches is not its first (an HRV window's sosa:observedProperty is its second), was put
// back into the outbox at every welcome, logged as a restore, and waited there for ever.
TEST(Link, ARestartedLinkPutsNothingBackWhenTheParentHasEverything) {
  Tree tree;
  ASSERT_TRUE(tree.start_hospital_and_home1());
  auto hrv = node::Node::open(tree.home1_dir).value().agent("hrv").value();
  for (int n = 0; n < 3; ++n) {
    node::Item item;
    const Term obs = Term::iri(kHome1 + "/rec/hrv/" + std::to_string(n));
    item.add(obs, Term::iri(kEx + "n"), Term::integer(n)).add(obs, kObservedProperty, kHrvProperty);
    ASSERT_TRUE(hrv.store(item));
  }
  const node::Pattern numbered{.p = Term::iri(kEx + "n")};
  ASSERT_TRUE(eventually([&] { return count(tree.hospital_dir, numbered) == 3 && outbox(tree.home1_dir) == 0; }));
  tree.home1.reset();
  tree.home1 = tree.start_home(tree.home1_dir, kHome1, tree.home1_log);
  ASSERT_TRUE(eventually([&] { return tree.home1->connected(); }));
  EXPECT_TRUE(eventually([&] { return outbox(tree.home1_dir) == 0; })) << outbox(tree.home1_dir) << " in the outbox";
  EXPECT_FALSE(tree.home1_log.has("(P6d)")) << tree.home1_log.text();
  EXPECT_EQ(count(tree.hospital_dir, numbered), 3u);
}

// P5: a pattern added to the policy takes the items stored after it. Those stored before stay home,
// also when the link registers again: its welcome (mark above 0, P6d; mark 0, P6c for the
// persistent ones) put back into the outbox every item after the parent's mark that the policy
// matched now, so some old raw items went up and others did not, by where the mark stood.
void items_before_a_pattern_stay_home_after_a_restart(bool something_went_up_before) {
  Tree tree;
  ASSERT_TRUE(tree.start_hospital_and_home1());
  auto home1 = node::Node::open(tree.home1_dir).value();
  auto hrv = home1.agent("hrv").value();
  if (something_went_up_before) {
    ASSERT_TRUE(hrv.store(hrv_item(0)));
    ASSERT_TRUE(eventually([&] { return count(tree.hospital_dir, {.p = Term::iri(kEx + "n")}) == 1 && outbox(tree.home1_dir) == 0; }));
  }
  const Term raw = Term::iri(kEx + "raw");
  auto raw_sample = [&](int n, bool persistent) {
    node::Item item;
    item.add(Term::iri(kHome1 + "/rec/ecg/" + std::to_string(n)), raw, Term::integer(n));
    item.persistent = persistent;
    return hrv.store(item).has_value();
  };
  ASSERT_TRUE(raw_sample(1, false));
  ASSERT_TRUE(raw_sample(2, true));
  ASSERT_TRUE(home1.agent("uplink").value().subscribe({.p = raw}));
  tree.home1.reset();
  tree.home1 = tree.start_home(tree.home1_dir, kHome1, tree.home1_log);
  ASSERT_TRUE(eventually([&] { return tree.home1->connected(); }));
  ASSERT_TRUE(raw_sample(3, false));
  EXPECT_TRUE(eventually([&] { return count(tree.hospital_dir, {.p = raw}) >= 1 && outbox(tree.home1_dir) == 0; }));
  std::this_thread::sleep_for(300ms);
  EXPECT_EQ(count(tree.hospital_dir, {.p = raw}), 1u) << tree.home1_log.text();
  EXPECT_EQ(count(tree.hospital_dir, {.p = raw, .o = Term::integer(3)}), 1u);
  EXPECT_FALSE(tree.home1_log.has("go up again")) << tree.home1_log.text();
}

TEST(Link, ItemsStoredBeforeAPatternWasAddedStayHomeWhenTheLinkRegistersAgain) {
  items_before_a_pattern_stay_home_after_a_restart(true);
}

TEST(Link, ItemsStoredBeforeAPatternWasAddedStayHomeWhenNothingHadGoneUpYet) {
  items_before_a_pattern_stay_home_after_a_restart(false);
}

// P12c: a child whose link stops on purpose says so, and its parent takes the link as down at
// once, not after child_silence (a query for it waited that long and ended "went silent"). It is
// up again at its next hello.
TEST(Link, AChildWhoseLinkStopsSaysSoAndItsParentTakesTheLinkAsDownAtOnce) {
  Tree tree;
  ASSERT_TRUE(tree.start_hospital_and_home1());
  tree.home1.reset();
  EXPECT_TRUE(eventually([&] { return !state_says_up(tree.hospital_dir, kHome1); }));
  EXPECT_TRUE(tree.hospital_log.has("child <" + kHome1 + ">'s link is stopping (it said so): link down")) << tree.hospital_log.text();
  EXPECT_FALSE(tree.hospital_log.has("silent for")) << tree.hospital_log.text();
  tree.home1 = tree.start_home(tree.home1_dir, kHome1, tree.home1_log);
  EXPECT_TRUE(eventually([&] { return state_says_up(tree.hospital_dir, kHome1); }));
}

// P12c: a child whose link is stopped on purpose lets what it has sent be acknowledged first
// (up to 1 s, while its parent is up): a sensor taken out of the file had its end of recording
// at its parent and in its own outbox, and `up` said it would never go up (session 88).
TEST(Link, AChildWhoseLinkStopsOnPurposeLetsWhatItSentBeAcknowledgedFirst) {
  Tree tree;
  tree.hospital = tree.start_hospital(/*ack_delay=*/200ms);  // acknowledged that long after they arrive
  tree.home1 = tree.start_home(tree.home1_dir, kHome1, tree.home1_log);
  ASSERT_TRUE(eventually([&] { return state_says_up(tree.hospital_dir, kHome1); }));
  store_hrv_items(tree.home1_dir, 0, 3);
  tree.home1.reset();  // at once: they go up and are acknowledged as it stops
  EXPECT_EQ(outbox(tree.home1_dir), 0u);
  EXPECT_EQ(count(tree.hospital_dir, {.p = Term::iri(kEx + "n")}), 3u);
  EXPECT_TRUE(eventually([&] { return tree.hospital_log.has("child <" + kHome1 + ">'s link is stopping (it said so): link down"); }))
      << tree.hospital_log.text();
}

// P12c: a child's hello names its link's run, and so does its leaving notice. A notice of
// another run than the one registered was sent by its run before (the store id is the same in
// both), delivered after the new run's hello: the parent keeps the link up. The registered
// run's notice takes it down, as does one naming no run (a link before runs were named).
TEST(Link, ALeavingNoticeOfAnotherRunThanTheRegisteredOneIsDropped) {
  Tree tree;
  tree.hospital = tree.start_hospital();
  auto child = tree.bus.open(kHome1);
  auto send = [&](FrameKind kind, std::uint64_t run, std::string body) {
    Frame f;
    f.kind = kind;
    f.from = kHome1;
    f.to = kHospital;
    if (kind == FrameKind::hello) f.prev = run;
    else f.ack = run;
    f.body = std::move(body);
    return child->send(f);
  };
  auto hello = [&](std::uint64_t run) { return send(FrameKind::hello, run, wire::encode_state({"home", 0, store_of('a'), ""})); };
  auto leaving = [&](std::uint64_t run) {
    return send(FrameKind::error, run, wire::encode_error({"leaving", "<" + kHome1 + ">'s link stops", store_of('a')}));
  };
  ASSERT_TRUE(hello(11));
  ASSERT_TRUE(eventually([&] { return state_says_up(tree.hospital_dir, kHome1); }));
  ASSERT_TRUE(hello(12));  // its new run, whose run before has not been heard leave
  std::this_thread::sleep_for(100ms);
  ASSERT_TRUE(leaving(11));
  EXPECT_TRUE(eventually([&] { return tree.hospital_log.has("dropped a notice that its link is stopping from a run before"); }))
      << tree.hospital_log.text();
  std::this_thread::sleep_for(300ms);
  EXPECT_TRUE(state_says_up(tree.hospital_dir, kHome1));
  ASSERT_TRUE(leaving(12));
  EXPECT_TRUE(eventually([&] { return !state_says_up(tree.hospital_dir, kHome1); }));
  EXPECT_TRUE(tree.hospital_log.has("child <" + kHome1 + ">'s link is stopping (it said so): link down")) << tree.hospital_log.text();
  ASSERT_TRUE(hello(0));
  ASSERT_TRUE(eventually([&] { return state_says_up(tree.hospital_dir, kHome1); }));
  ASSERT_TRUE(leaving(0));
  EXPECT_TRUE(eventually([&] { return !state_says_up(tree.hospital_dir, kHome1); }));
  EXPECT_FALSE(tree.hospital_log.has("silent for")) << "taken as down only once silent\n" << tree.hospital_log.text();
}

// P12d: a parent whose link stops says so to its connected children, as a child does (P12c):
// the child's state is "down" at once. It was "up" until child_silence had passed (an
// exploratory run of session 81: a home showed its stopped gateway "up, parent last heard
// 2.3 s ago"), and the child logged the parent as not heard. Back, the parent welcomes it; a
// late notice of the parent's run before is dropped by its run (a review of session 81).
TEST(Link, AParentWhoseLinkStopsSaysSoToItsChildrenWhichTakeItAsDownAtOnce) {
  Tree tree;
  ASSERT_TRUE(tree.start_hospital_and_home1());
  ASSERT_TRUE(eventually([&] { return uplink_states(tree.home1_dir, kHome1) == std::vector<std::string>{"up"}; }));
  tree.hospital.reset();
  EXPECT_TRUE(eventually([&] { return uplink_states(tree.home1_dir, kHome1) == std::vector<std::string>{"down"}; }, 10s));
  EXPECT_TRUE(tree.home1_log.has("the parent <" + kHospital + ">'s link is stopping (it said so): link down until it is back"))
      << tree.home1_log.text();
  EXPECT_FALSE(tree.home1_log.has("has not been heard for")) << tree.home1_log.text();
  store_hrv_items(tree.home1_dir, 0, 3);
  tree.hospital = tree.start_hospital(LinkOptions{}.ack_delay, /*say_leaving=*/false);
  const node::Pattern numbered{.p = Term::iri(kEx + "n")};
  EXPECT_TRUE(eventually([&] { return count(tree.hospital_dir, numbered) == 3 && outbox(tree.home1_dir) == 0; }, 10s))
      << tree.home1_log.text();
  ASSERT_TRUE(eventually([&] { return uplink_states(tree.home1_dir, kHome1) == std::vector<std::string>{"up"}; }));
  // A notice naming another run of the parent's link than the one that welcomed it (its run
  // before's, come late) is dropped; one naming no run (a parent before runs were named) is taken.
  tree.hospital.reset();  // unsaid, as a crash: the notices below are the test's
  const std::string hospital_store = node::Node::open(tree.hospital_dir).value().store_id().value();
  auto parent = tree.bus.open(kHospital);
  auto leaving = [&](std::uint64_t run) {
    Frame f;
    f.kind = FrameKind::error;
    f.from = kHospital;
    f.to = kHome1;
    f.ack = run;
    f.body = wire::encode_error({"leaving", "<" + kHospital + ">'s link stops", hospital_store});
    return parent->send(f);
  };
  ASSERT_TRUE(leaving(1));
  EXPECT_TRUE(eventually([&] { return tree.home1_log.has("dropped a notice that the parent's link is stopping from a run before"); }))
      << tree.home1_log.text();
  EXPECT_TRUE(tree.home1->connected());
  ASSERT_TRUE(leaving(0));
  EXPECT_TRUE(eventually([&] { return !tree.home1->connected(); })) << tree.home1_log.text();
}

// P6a: the same downwards. A hospital whose store is made again issues configuration with ids
// that a home has applied already from the old store; the home still gets it.
// Settings `first` .. `first + n - 1` for home1's agent hrv, written on the hospital by its
// agent operator.
void configure_home1(Tree& tree, int first, int n) {
  auto operator_ = node::Node::open(tree.hospital_dir).value().agent("operator").value();
  for (int i = first; i < first + n; ++i) {
    node::Item config;
    config.context = kHome1 + "/hrv";
    config.add(Term::iri(kHome1 + "/hrv"), Term::iri(kEx + "setting"), Term::integer(i));
    ASSERT_TRUE(operator_.store(config));
  }
}

TEST(Link, ConfigurationFromAParentWhoseStoreIsMadeAgainArrives) {
  Tree tree;
  tree.hospital = tree.start_hospital();
  tree.home1 = tree.start_home(tree.home1_dir, kHome1, tree.home1_log);
  auto configure = [&](int first, int n) { configure_home1(tree, first, n); };
  const node::Pattern settings{.p = Term::iri(kEx + "setting")};
  configure(0, 30);
  ASSERT_TRUE(eventually([&] { return count(tree.home1_dir, settings) == 30; }));
  tree.hospital.reset();
  std::filesystem::remove_all(tree.hospital_dir);
  ASSERT_TRUE(node::Node::init(tree.hospital_dir, {.iri = kHospital}));
  tree.hospital = tree.start_hospital();
  configure(1000, 5);
  EXPECT_TRUE(eventually([&] { return count(tree.home1_dir, settings) == 35; })) << count(tree.home1_dir, settings);
  std::this_thread::sleep_for(300ms);
  EXPECT_EQ(count(tree.home1_dir, settings), 35u);
}

// P10c downwards: a hospital rolled back to a snapshot (under its id) taken while settings for
// home1 waited in its down queue (home1's link stopped) takes a new id once home1's marks show
// it, and sends them again on its new stream. Home1 had applied them from the stream before,
// and keeps one of each; what the hospital writes after the roll-back arrives.
TEST(Link, SettingsWaitingInTheDownQueueOfAParentsSnapshotAreNotDoubledAtTheChild) {
  Tree tree;
  const node::Pattern settings{.p = Term::iri(kEx + "setting")};
  tree.hospital = tree.start_hospital();
  tree.home1 = tree.start_home(tree.home1_dir, kHome1, tree.home1_log);
  configure_home1(tree, 0, 5);
  ASSERT_TRUE(eventually([&] { return count(tree.home1_dir, settings) == 5; }));
  tree.home1.reset();
  configure_home1(tree, 100, 10);  // they wait in the hospital's queue for home1, and so in the snapshot
  tree.hospital.reset();
  const std::filesystem::path snapshot = tree.tmp / "hospital-snapshot";
  take_snapshot(tree.hospital_dir, snapshot);
  tree.hospital = tree.start_hospital();
  tree.home1 = tree.start_home(tree.home1_dir, kHome1, tree.home1_log);
  ASSERT_TRUE(eventually([&] { return count(tree.home1_dir, settings) == 15; }));
  configure_home1(tree, 200, 3);
  ASSERT_TRUE(eventually([&] { return count(tree.home1_dir, settings) == 18; }));
  // Home1's uplink state names the parent store that welcomed it (written at a heartbeat).
  ASSERT_TRUE(eventually([&] { return count(tree.home1_dir, {.s = Term::iri(kHome1), .p = Term::iri(vocab::kParentStoreId)}) == 1; }));
  tree.hospital.reset();
  tree.home1.reset();
  ASSERT_NO_FATAL_FAILURE(roll_back_in_place(snapshot, tree.hospital_dir));
  // Written before home1 is back, they take ids that the hospital had issued before the restore:
  // home1, restarted too, says hello without a mark, and only its acknowledgement tells the
  // hospital that it went back in time (its next ids would have been dropped at home1 as ones
  // applied).
  tree.hospital = tree.start_hospital();
  configure_home1(tree, 300, 25);
  tree.home1 = tree.start_home(tree.home1_dir, kHome1, tree.home1_log);
  ASSERT_TRUE(eventually([&] { return tree.hospital_log.has("this store takes a new id"); })) << "the case under test did not happen: "
                                                                                            << tree.hospital_log.text();
  EXPECT_TRUE(eventually([&] { return count(tree.home1_dir, settings) == 43; })) << count(tree.home1_dir, settings) << " settings at home1";
  std::this_thread::sleep_for(300ms);
  EXPECT_EQ(count(tree.home1_dir, settings), 43u);
  for (int n : {100, 109, 300, 324}) EXPECT_EQ(count(tree.home1_dir, {.p = Term::iri(kEx + "setting"), .o = Term::integer(n)}), 1u) << n;
}

// P10b: a child whose store is made again (a replaced disk) holds nothing of what came down.
// What was written for it to keep (a setting put --persistent) goes down again; the rest does
// not, as P6c upwards.
TEST(Link, APersistentSettingGoesDownAgainToAChildWhoseStoreIsMadeAgain) {
  Tree tree;
  tree.hospital = tree.start_hospital();
  tree.home1 = tree.start_home(tree.home1_dir, kHome1, tree.home1_log);
  auto operator_ = node::Node::open(tree.hospital_dir).value().agent("operator").value();
  for (int i = 0; i < 6; ++i) {
    node::Item config;
    config.context = kHome1 + "/hrv";
    config.add(Term::iri(kHome1 + "/hrv"), Term::iri(kEx + "setting"), Term::integer(i));
    config.persistent = i == 5;
    ASSERT_TRUE(operator_.store(config));
  }
  const node::Pattern settings{.p = Term::iri(kEx + "setting")};
  ASSERT_TRUE(eventually([&] { return count(tree.home1_dir, settings) == 6; }));
  tree.home1.reset();
  std::filesystem::remove_all(tree.home1_dir);
  ASSERT_TRUE(node::Node::init(tree.home1_dir, {.iri = kHome1}));
  tree.home1 = tree.start_home(tree.home1_dir, kHome1, tree.home1_log);
  EXPECT_TRUE(eventually([&] { return count(tree.home1_dir, settings) == 1; })) << count(tree.home1_dir, settings);
  EXPECT_EQ(count(tree.home1_dir, {.p = Term::iri(kEx + "setting"), .o = Term::integer(5)}), 1u);
  EXPECT_TRUE(tree.hospital_log.has("1 persistent item(s) for it go down again")) << tree.hospital_log.text();
  // Applied by the new store, it leaves home1's down queue at the hospital.
  EXPECT_TRUE(eventually([&] { return node::Node::open(tree.hospital_dir).value().agent("home1").value().pending().value() == 0; }));
  // A restart of either link is not a new store: nothing comes down twice.
  tree.home1.reset();
  tree.home1 = tree.start_home(tree.home1_dir, kHome1, tree.home1_log);
  std::this_thread::sleep_for(500ms);
  EXPECT_EQ(count(tree.home1_dir, settings), 1u);
}

// P10b: the store a child registered with is on the parent's board, so a store made again
// while the parent's link was down is still known for a new one at its first hello, by a parent
// with configured children and by one that accepts any child.
TEST(Link, APersistentSettingGoesDownAgainToAChildWhoseStoreIsMadeAgainWhileTheParentWasDown) {
  for (const bool configured : {true, false}) {
    SCOPED_TRACE(configured ? "configured children" : "any child");
    Tree tree;
    auto start_hospital = [&] {
      if (configured) return tree.start_hospital();
      return Link::start({.dir = tree.hospital_dir, .down = std::shared_ptr<Transport>(tree.bus.open(kHospital, tree.hospital_log.sink())),
                          .resend_after = 100ms, .log = tree.hospital_log.sink()})
          .value();
    };
    tree.hospital = start_hospital();
    tree.home1 = tree.start_home(tree.home1_dir, kHome1, tree.home1_log);
    auto operator_ = node::Node::open(tree.hospital_dir).value().agent("operator").value();
    node::Item config;
    config.context = kHome1 + "/hrv";
    config.add(Term::iri(kHome1 + "/hrv"), Term::iri(kEx + "setting"), Term::integer(7));
    config.persistent = true;
    ASSERT_TRUE(operator_.store(config));
    const node::Pattern settings{.p = Term::iri(kEx + "setting")};
    ASSERT_TRUE(eventually([&] { return count(tree.home1_dir, settings) == 1; }));
    ASSERT_TRUE(eventually([&] { return count(tree.hospital_dir, {.s = Term::iri(kHome1), .p = Term::iri(vocab::kChildStoreId)}) == 1; }));
    // Acknowledged by home1 and so out of its down queue here: a setting still queued when the
    // hospital stops goes down from the queue to the new store, and is not "again".
    ASSERT_TRUE(eventually([&] { return node::Node::open(tree.hospital_dir).value().agent("home1").value().pending().value() == 0; }));

    tree.hospital.reset();
    tree.home1.reset();
    std::filesystem::remove_all(tree.home1_dir);
    ASSERT_TRUE(node::Node::init(tree.home1_dir, {.iri = kHome1}));
    tree.hospital = start_hospital();
    tree.home1 = tree.start_home(tree.home1_dir, kHome1, tree.home1_log);
    EXPECT_TRUE(eventually([&] { return count(tree.home1_dir, settings) == 1; })) << tree.hospital_log.text();
    EXPECT_TRUE(tree.hospital_log.has("1 persistent item(s) for it go down again")) << tree.hospital_log.text();

    // Both restarted with the stores they have: the same store, nothing comes down twice.
    tree.hospital.reset();
    tree.home1.reset();
    tree.hospital = start_hospital();
    tree.home1 = tree.start_home(tree.home1_dir, kHome1, tree.home1_log);
    ASSERT_TRUE(eventually([&] { return tree.home1->connected(); }));
    std::this_thread::sleep_for(500ms);
    EXPECT_EQ(count(tree.home1_dir, settings), 1u);
  }
}

// P9a: the home's store allows longer literals than the hospital's. Resending the long one
// could never succeed; it is passed over (and stays at home), and the items after it go up.
TEST(Link, AnItemTheParentCanNeverStoreIsPassedOverAndTheItemsAfterItStillGoUp) {
  Tree tree({.max_literal_bytes = 200});
  tree.hospital = tree.start_hospital();
  tree.home1 = tree.start_home(tree.home1_dir, kHome1, tree.home1_log);
  ASSERT_TRUE(eventually([&] { return tree.home1->connected(); }));
  auto hrv = node::Node::open(tree.home1_dir).value().agent("hrv").value();
  node::Item too_long = hrv_item(0);
  too_long.add(Term::iri(kHome1 + "/rec/hrv/0"), Term::iri(kEx + "note"), Term::literal(std::string(300, 'x')));
  ASSERT_TRUE(hrv.store(too_long));
  store_hrv_items(tree.home1_dir, 1, 3);
  const node::Pattern numbered{.p = Term::iri(kEx + "n")};
  EXPECT_TRUE(eventually([&] { return count(tree.hospital_dir, numbered) == 3; }))
      << count(tree.hospital_dir, numbered) << " of the 3 items after the long one arrived";
  EXPECT_EQ(count(tree.hospital_dir, {.p = Term::iri(kEx + "note")}), 0u);
  EXPECT_TRUE(eventually([&] { return outbox(tree.home1_dir) == 0; })) << outbox(tree.home1_dir) << " left in the outbox";
  EXPECT_EQ(count(tree.home1_dir, {.p = Term::iri(kEx + "note")}), 1u) << "the refused item must stay at home";
  EXPECT_TRUE(eventually([&] { return tree.home1_log.has("the parent refused item"); }));
  EXPECT_TRUE(tree.hospital_log.has("literal of 300 bytes exceeds the node's limit of 200"));
  EXPECT_EQ(tree.hospital->counters().items_refused, 1u);
  EXPECT_EQ(tree.home1->counters().items_refused_by_peer, 1u);
  EXPECT_EQ(tree.hospital->counters().relayed_in, 3u);
}

// A frame has at most 64 MiB of body (P4); a store may allow larger items. Such an item is not
// sent, and does not hold back the items after it.
TEST(Link, AnItemTooLargeForAnyFrameStaysHomeAndTheItemsAfterItGoUp) {
  Tree tree({}, {.max_literal_bytes = 80u << 20});
  ASSERT_TRUE(tree.start_hospital_and_home1());
  auto hrv = node::Node::open(tree.home1_dir).value().agent("hrv").value();
  node::Item huge = hrv_item(0);
  huge.add(Term::iri(kHome1 + "/rec/hrv/0"), Term::iri(kEx + "note"), Term::literal(std::string(65u << 20, 'x')));
  ASSERT_TRUE(hrv.store(huge));
  store_hrv_items(tree.home1_dir, 1, 2);
  const node::Pattern numbered{.p = Term::iri(kEx + "n")};
  EXPECT_TRUE(eventually([&] { return count(tree.hospital_dir, numbered) == 2; }))
      << count(tree.hospital_dir, numbered) << " of the 2 items after the huge one arrived";
  EXPECT_TRUE(eventually([&] { return outbox(tree.home1_dir) == 0; })) << outbox(tree.home1_dir) << " left in the outbox";
  EXPECT_TRUE(tree.home1_log.has("is over the links' limit"));
  EXPECT_EQ(tree.home1->counters().items_refused, 1u);
}

// The same downwards: configuration the home can never store does not hold up what follows.
TEST(Link, ConfigurationAChildCanNeverStoreIsPassedOverAndTheConfigurationAfterItArrives) {
  Tree tree({}, {.max_literal_bytes = 200});
  tree.hospital = tree.start_hospital();
  tree.home1 = tree.start_home(tree.home1_dir, kHome1, tree.home1_log);
  ASSERT_TRUE(eventually([&] { return tree.home1->connected(); }));
  auto operator_ = node::Node::open(tree.hospital_dir).value().agent("operator").value();
  for (const std::string& value : {std::string(300, 'x'), std::string("short")}) {
    node::Item config;
    config.context = kHome1 + "/hrv";
    config.add(Term::iri(kHome1 + "/hrv"), Term::iri(kEx + "label"), Term::literal(value));
    ASSERT_TRUE(operator_.store(config));
  }
  auto home1_hrv = node::Node::open(tree.home1_dir).value().agent("hrv").value();
  auto delivered = home1_hrv.take(10s).value();
  ASSERT_TRUE(delivered.has_value()) << "the configuration after the long one never arrived";
  EXPECT_EQ(delivered->records[0].triple.o.value, "short");
  EXPECT_TRUE(eventually([&] { return tree.hospital_log.has("child <" + kHome1 + "> refused item"); }));
  EXPECT_TRUE(tree.home1_log.has("literal of 300 bytes exceeds the node's limit of 200"));
  EXPECT_EQ(tree.home1->counters().items_refused, 1u);
}

// P11a: configuration addressed to an agent the home does not have (a typo in the context at
// the hospital, "hrvv") waited in that agent's input buffer for ever, and no node said a word.
// The home's link says it as its problem, on the home's board (status shows it there and above),
// and takes it back once the agent is known there (here: it subscribes) or nothing waits for it
// any more (the item removed at the hospital). What the item itself
// says of the agent does not make it known. An item for an agent the home knows raises nothing.
TEST(Link, ConfigurationForAnAgentTheHomeDoesNotKnowIsItsLinksProblemUntilTheAgentIsKnown) {
  Tree tree;
  ASSERT_TRUE(tree.start_hospital_and_home1());
  auto home1 = node::Node::open(tree.home1_dir).value();
  auto hrv = home1.agent("hrv").value();
  ASSERT_TRUE(hrv.subscribe({.p = Term::iri(kEx + "n")}));
  auto operator_ = node::Node::open(tree.hospital_dir).value().agent("operator").value();
  std::uint64_t last_configured = 0;
  auto configure = [&](const std::string& agent) {
    node::Item config;
    config.context = kHome1 + "/" + agent;
    config.add(Term::iri(kHome1 + "/" + agent), Term::iri(kEx + "windowS"), Term::integer(120));
    auto stored = operator_.store(config);
    last_configured = stored ? *stored : 0;
    return static_cast<bool>(stored);
  };
  const node::Pattern problem{.s = Term::iri(kHome1 + "/link"), .p = Term::iri(node::kProblem)};
  auto problems = [&] {
    std::vector<std::string> said;
    const std::vector<node::Record> records = home1.snapshot().value().list(problem).value();
    for (const auto& r : records) said.push_back(r.triple.o.value);
    return said;
  };
  ASSERT_TRUE(configure("hrv"));
  ASSERT_TRUE(eventually([&] { return count(tree.home1_dir, {.p = Term::iri(kEx + "windowS")}) == 1; }));
  std::this_thread::sleep_for(300ms);
  EXPECT_TRUE(problems().empty()) << problems().front();
  // An area subscription (docs/spatial.md) makes its agent known too, whether or not a sensor
  // stands in the area now.
  node::Item area;
  area.add(Term::blank("a"), Term::iri(std::string(vocab::kTv) + "areaSubscriber"), Term::iri(kHome1 + "/ui"));
  ASSERT_TRUE(home1.agent("carer").value().store(area));
  ASSERT_TRUE(configure("ui"));
  ASSERT_TRUE(configure("hrvv"));
  ASSERT_TRUE(eventually([&] { return problems().size() == 1; }));
  EXPECT_EQ(problems().front().find("/ui>"), std::string::npos) << problems().front();
  EXPECT_NE(problems().front().find("configuration from above addresses <" + kHome1 + "/hrvv>, which nothing on <" + kHome1 +
                                    "> knows (no program of that id runs here"),
            std::string::npos)
      << problems().front();
  // The link writes the problem on the board before its log line.
  EXPECT_TRUE(eventually([&] { return tree.home1_log.text().find("addresses <" + kHome1 + "/hrvv>") != std::string::npos; }))
      << tree.home1_log.text();
  // The operator removes the misaddressed item at the hospital: it leaves the home too (P10a),
  // nothing waits for the unknown agent, and the problem goes (it stayed until the link restarted).
  ASSERT_TRUE(node::Node::open(tree.hospital_dir).value().remove_item(last_configured));
  EXPECT_TRUE(eventually([&] { return problems().empty(); }, 5s)) << problems().front();
  EXPECT_EQ(home1.agent("hrvv").value().pending().value(), 0u);
  // Misaddressed again: said again, and the agent made known takes it back.
  ASSERT_TRUE(configure("hrvv"));
  ASSERT_TRUE(eventually([&] { return problems().size() == 1; }));
  ASSERT_TRUE(home1.agent("hrvv").value().subscribe({.p = Term::iri(kEx + "n")}));
  EXPECT_TRUE(eventually([&] { return problems().empty(); }, 5s));
}

TEST(Link, ConfigurationForOneHomeReachesThatHomeAndTheAddressedAgentOnly) {
  Tree tree;
  tree.hospital = tree.start_hospital();
  tree.home1 = tree.start_home(tree.home1_dir, kHome1, tree.home1_log);
  tree.home2 = tree.start_home(tree.home2_dir, kHome2, tree.home2_log);
  ASSERT_TRUE(eventually([&] { return tree.home1->connected() && tree.home2->connected(); }));
  auto home1_hrv = node::Node::open(tree.home1_dir).value().agent("hrv").value();
  auto home2_hrv = node::Node::open(tree.home2_dir).value().agent("hrv").value();
  auto operator_ = node::Node::open(tree.hospital_dir).value().agent("operator").value();
  node::Item config;
  config.context = kHome1 + "/hrv";
  config.add(Term::iri(kHome1 + "/hrv"), Term::iri(kEx + "windowS"), Term::integer(120));
  ASSERT_TRUE(operator_.store(config));
  auto delivered = home1_hrv.take(10s).value();
  ASSERT_TRUE(delivered.has_value());
  ASSERT_EQ(delivered->records.size(), 1u);
  EXPECT_EQ(delivered->records[0].triple.o.value, "120");
  EXPECT_EQ(delivered->records[0].meta.source, kHospital + "/operator");
  EXPECT_EQ(delivered->records[0].meta.context, kHome1 + "/hrv");
  EXPECT_FALSE(home2_hrv.take(300ms).value().has_value());
  EXPECT_EQ(count(tree.home2_dir, {.p = Term::iri(kEx + "windowS")}), 0u);
  // A whole subtree: every home gets it.
  node::Item all;
  all.context = kHospital + "/*";
  all.add(Term::iri(kHospital), Term::iri(kEx + "notice"), Term::literal("maintenance"));
  ASSERT_TRUE(operator_.store(all));
  EXPECT_TRUE(eventually([&] {
    return count(tree.home1_dir, {.p = Term::iri(kEx + "notice")}) == 1 &&
           count(tree.home2_dir, {.p = Term::iri(kEx + "notice")}) == 1;
  }));
  // Configuration relayed down never travels back up (P7), although it matches nothing there.
  std::this_thread::sleep_for(300ms);
  EXPECT_EQ(count(tree.hospital_dir, {.p = Term::iri(kEx + "notice")}), 1u);
}

// A setting written for the whole tree (`<hospital>/*`, persistent) reached the nodes there were
// when it was written, and never one added to the tree later, even across restarts: a home added
// to the hospital's file, or a sensor that first says hello to its home. Each gets it once; a
// command sent to the whole tree before it came (not persistent) is not its.
TEST(Link, ASettingForTheWholeTreeReachesNodesAddedLaterAtEachHopAndACommandSentBeforeDoesNot) {
  Tree tree;
  tree.hospital = Link::start({.dir = tree.hospital_dir,
                               .down = std::shared_ptr<Transport>(tree.bus.open(kHospital, tree.hospital_log.sink())),
                               .children = {"home1"}, .resend_after = 100ms, .log = tree.hospital_log.sink()})
                      .value();
  auto home1_endpoint = std::shared_ptr<Transport>(tree.bus.open(kHome1, tree.home1_log.sink()));
  tree.home1 = Link::start({.dir = tree.home1_dir, .parent_iri = kHospital, .up = home1_endpoint, .down = home1_endpoint,
                            .resend_after = 100ms, .heartbeat_every = 200ms, .log = tree.home1_log.sink()})
                   .value();
  ASSERT_TRUE(eventually([&] { return tree.home1->connected(); }));
  auto operator_ = node::Node::open(tree.hospital_dir).value().agent("operator").value();
  auto to_all = [&](const std::string& what, const std::string& value, bool persistent) {
    node::Item item;
    item.context = kHospital + "/*";
    item.persistent = persistent;
    item.add(Term::iri(kHospital), Term::iri(kEx + what), Term::literal(value));
    return static_cast<bool>(operator_.store(item));
  };
  const auto has = [&](const std::string& dir, const std::string& what) { return count(dir, {.p = Term::iri(kEx + what)}); };
  ASSERT_TRUE(to_all("policy", "tree-wide", true));
  ASSERT_TRUE(to_all("notice", "maintenance", false));
  ASSERT_TRUE(eventually([&] { return has(tree.home1_dir, "policy") == 1 && has(tree.home1_dir, "notice") == 1; }));
  // home2 joins the tree: the hospital's link starts again with it configured, as `tahvel up`
  // with the new file does; and a sensor says hello to home1 for the first time.
  tree.hospital.reset();
  tree.hospital = tree.start_hospital();
  tree.home2 = tree.start_home(tree.home2_dir, kHome2, tree.home2_log);
  const std::string sensor_dir = (tree.tmp / "ecg1").string();
  ASSERT_TRUE(node::Node::init(sensor_dir, {.iri = kHome1 + "/ecg1"}));
  Log sensor_log;
  auto sensor = Link::start({.dir = sensor_dir, .parent_iri = kHome1,
                             .up = std::shared_ptr<Transport>(tree.bus.open(kHome1 + "/ecg1", sensor_log.sink())),
                             .resend_after = 100ms, .heartbeat_every = 200ms, .log = sensor_log.sink()})
                    .value();
  ASSERT_TRUE(eventually([&] { return tree.home1->connected() && tree.home2->connected() && sensor->connected(); }));
  // A persistent marker sent after both came: it follows whatever the queues would hold before it.
  ASSERT_TRUE(to_all("marker", "after", true));
  for (const std::string& dir : {tree.home2_dir, sensor_dir}) {
    EXPECT_TRUE(eventually([&] { return has(dir, "marker") == 1; })) << dir << tree.hospital_log.text() << tree.home1_log.text();
    EXPECT_EQ(has(dir, "policy"), 1u) << dir;
    EXPECT_EQ(has(dir, "notice"), 0u) << dir;
  }
  EXPECT_EQ(has(tree.home1_dir, "policy"), 1u);
  EXPECT_EQ(has(tree.home1_dir, "notice"), 1u);
}

// A node may listen on two transports (LCM for its LAN, DDS beyond): home1 reaches the hospital
// on one bus and home2 on another. Items come up from both, and what goes to a child — its
// configuration, a query, the acks of its items — goes on the transport its hello came on.
TEST(Link, AParentListeningOnTwoTransportsServesEachChildOnTheOneItsHelloCameOn) {
  Tree tree;
  MemoryBus second;
  tree.hospital = Link::start({.dir = tree.hospital_dir,
                               .down = std::shared_ptr<Transport>(tree.bus.open(kHospital, tree.hospital_log.sink())),
                               .also_down = {std::shared_ptr<Transport>(second.open(kHospital, tree.hospital_log.sink()))},
                               .children = {"home1", "home2"}, .resend_after = 100ms, .log = tree.hospital_log.sink()})
                      .value();
  tree.home1 = tree.start_home(tree.home1_dir, kHome1, tree.home1_log);
  tree.home2 = Link::start({.dir = tree.home2_dir, .parent_iri = kHospital,
                            .up = std::shared_ptr<Transport>(second.open(kHome2, tree.home2_log.sink())),
                            .resend_after = 100ms, .heartbeat_every = 200ms, .log = tree.home2_log.sink()})
                   .value();
  ASSERT_TRUE(eventually([&] { return tree.home1->connected() && tree.home2->connected(); }));

  store_hrv_items(tree.home1_dir, 0, 30);
  store_hrv_items(tree.home2_dir, 100, 30);
  ASSERT_TRUE(eventually([&] {
    return count(tree.hospital_dir, {.p = Term::iri(kEx + "n")}) == 60 && outbox(tree.home1_dir) == 0 &&
           outbox(tree.home2_dir) == 0;
  }));
  EXPECT_EQ(count(tree.hospital_dir, {.p = Term::iri(kEx + "n"), .source = kHome2}), 30u);

  auto operator_ = node::Node::open(tree.hospital_dir).value().agent("operator").value();
  node::Item config;
  config.context = kHome2 + "/hrv";
  config.add(Term::iri(kHome2 + "/hrv"), Term::iri(kEx + "windowS"), Term::integer(90));
  ASSERT_TRUE(operator_.store(config));
  auto delivered = node::Node::open(tree.home2_dir).value().agent("hrv").value().take(10s).value();
  ASSERT_TRUE(delivered.has_value());
  EXPECT_EQ(delivered->records[0].triple.o.value, "90");
  EXPECT_EQ(count(tree.home1_dir, {.p = Term::iri(kEx + "windowS")}), 0u);

  ASSERT_TRUE(eventually([&] { return state_says_up(tree.hospital_dir, kHome2); }));
  auto hospital = node::Node::open(tree.hospital_dir).value();
  std::vector<node::Record> got;
  auto answered = remote_query(hospital, {.target = kHome2, .pattern = {.p = Term::iri(kEx + "n")}}, 10s,
                               [&](const node::Record& r) { got.push_back(r); });
  ASSERT_TRUE(answered) << answered.error().message;
  EXPECT_EQ(got.size(), 30u);
}

// The parent sends down to all of its children from one pump (P10): each child's queue is read
// when an item lands in it, and lost, doubled or reordered frames are made good per child by
// go-back to that child's mark (P8), without holding up the others.
TEST(Link, ConfigurationReachesEachOfManyChildrenExactlyOnceThroughLossDuplicationAndReordering) {
  TempDir tmp{"tahvel-link-many"};
  MemoryBus bus;
  Log log;
  const std::string hospital_dir = (tmp / "hospital").string();
  ASSERT_TRUE(node::Node::init(hospital_dir, {.iri = kHospital}));
  auto hospital = Link::start({.dir = hospital_dir, .down = std::shared_ptr<Transport>(bus.open(kHospital, log.sink())),
                               .resend_after = 100ms, .log = log.sink()})
                      .value();
  constexpr int kHomes = 12, kEach = 25, kNotices = 10;
  std::vector<std::string> dirs;
  std::vector<std::unique_ptr<Link>> homes;
  for (int h = 1; h <= kHomes; ++h) {
    const std::string iri = kHospital + "/home" + std::to_string(h);
    dirs.push_back((tmp / ("home" + std::to_string(h))).string());
    ASSERT_TRUE(node::Node::init(dirs.back(), {.iri = iri}));
    homes.push_back(Link::start({.dir = dirs.back(), .parent_iri = kHospital,
                                 .up = std::shared_ptr<Transport>(bus.open(iri, log.sink())),
                                 .resend_after = 100ms, .heartbeat_every = 200ms, .log = log.sink()})
                        .value());
  }
  ASSERT_TRUE(eventually([&] {
    for (auto& home : homes)
      if (!home->connected()) return false;
    return true;
  }));
  bus.set_faults({.seed = 11, .drop = 0.2, .duplicate = 0.1, .reorder = 0.1});
  auto operator_ = node::Node::open(hospital_dir).value().agent("operator").value();
  for (int i = 0; i < kEach; ++i) {
    for (int h = 1; h <= kHomes; ++h) {
      const std::string home = kHospital + "/home" + std::to_string(h);
      node::Item config;
      config.context = home + "/hrv";
      config.add(Term::iri(home + "/hrv"), Term::iri(kEx + "setting"), Term::integer(i));
      ASSERT_TRUE(operator_.store(config));
    }
    if (i < kNotices) {
      node::Item all;
      all.context = kHospital + "/*";
      all.add(Term::iri(kHospital), Term::iri(kEx + "notice"), Term::integer(i));
      ASSERT_TRUE(operator_.store(all));
    }
  }
  for (int h = 0; h < kHomes; ++h) {
    EXPECT_TRUE(eventually([&] {
      return count(dirs[h], {.p = Term::iri(kEx + "setting")}) >= kEach &&
             count(dirs[h], {.p = Term::iri(kEx + "notice")}) >= kNotices;
    })) << "home" << h + 1;
  }
  std::this_thread::sleep_for(500ms);  // resends still in flight must be dropped as duplicates
  for (int h = 0; h < kHomes; ++h) {
    auto home = node::Node::open(dirs[h]).value();
    auto settings = home.snapshot().value().list({.p = Term::iri(kEx + "setting")}).value();
    std::set<std::string> seen;
    for (const auto& r : settings) {
      EXPECT_TRUE(seen.insert(r.triple.o.value).second) << "home" << h + 1 << " got setting " << r.triple.o.value << " twice";
      EXPECT_EQ(r.meta.source, kHospital + "/operator");
      EXPECT_EQ(r.triple.s.value, kHospital + "/home" + std::to_string(h + 1) + "/hrv") << "another home's setting";
    }
    EXPECT_EQ(seen.size(), static_cast<std::size_t>(kEach)) << "home" << h + 1;
    EXPECT_EQ(count(dirs[h], {.p = Term::iri(kEx + "notice")}), static_cast<std::uint64_t>(kNotices)) << "home" << h + 1;
  }
}

// P12: each child's state is one item on the parent's board, replaced (never accumulated) as the
// child registers, falls silent, and across a restart of the parent's link.
TEST(Link, EachChildHasOneStateItemThatFollowsItsLinkAcrossARestartOfTheParent) {
  Tree tree;
  auto state_of = [&](const std::string& child) {
    auto node = node::Node::open(tree.hospital_dir).value();
    auto records = node.snapshot().value().list({.s = Term::iri(child), .p = Term::iri(vocab::kLinkState)}).value();
    std::vector<std::string> states;
    for (const auto& r : records) states.push_back(r.triple.o.value);
    return states;
  };
  using States = std::vector<std::string>;
  tree.hospital = tree.start_hospital();
  ASSERT_TRUE(eventually([&] { return state_of(kHome2) == States{"never connected"}; }));
  tree.home1 = tree.start_home(tree.home1_dir, kHome1, tree.home1_log);
  ASSERT_TRUE(eventually([&] { return state_of(kHome1) == States{"up"}; })) << state_of(kHome1).size() << " state records";
  auto registrations = [&] {
    std::lock_guard lock(tree.hospital_log.mu);
    return std::count_if(tree.hospital_log.lines.begin(), tree.hospital_log.lines.end(),
                         [](const std::string& l) { return l.find("<" + kHome1 + "> registered") != std::string::npos; });
  };
  ASSERT_EQ(registrations(), 1);
  tree.hospital.reset();
  tree.hospital = tree.start_hospital();  // the new run replaces what the last one wrote
  ASSERT_TRUE(eventually([&] { return registrations() == 2 && state_of(kHome1) == States{"up"}; }))
      << state_of(kHome1).size() << " state records";
  EXPECT_EQ(state_of(kHome2), States{"never connected"});
  tree.home1.reset();  // silent for child_silence: down
  EXPECT_TRUE(eventually([&] { return state_of(kHome1) == States{"down"}; })) << state_of(kHome1).size() << " state records";
  EXPECT_EQ(count(tree.hospital_dir, {.s = Term::iri(kHome1), .p = Term::iri(vocab::kParent)}), 1u);
  // The parent restarts while home1 is away: home1 was connected before, so it is "down" with
  // the time it was last seen, not "never connected" and never seen (a restarted gateway's
  // children said so until they were back).
  auto last_seen = [&] {
    return node::Node::open(tree.hospital_dir).value().snapshot().value().list({.s = Term::iri(kHome1), .p = Term::iri(vocab::kLastSeen)}).value();
  };
  ASSERT_EQ(last_seen().size(), 1u);
  const std::string seen_before = last_seen()[0].triple.o.value;
  const std::uint64_t item_before = last_seen()[0].meta.item;
  auto state_item = [&] {
    auto records = node::Node::open(tree.hospital_dir).value().snapshot().value().list({.s = Term::iri(kHome1), .p = Term::iri(vocab::kLinkState)}).value();
    return records.empty() ? 0 : records[0].meta.item;
  };
  tree.hospital.reset();
  tree.hospital = tree.start_hospital();
  ASSERT_TRUE(eventually([&] { return state_item() != item_before; })) << "the new run wrote no state of home1";
  EXPECT_EQ(state_of(kHome1), States{"down"});
  ASSERT_EQ(last_seen().size(), 1u);
  EXPECT_EQ(last_seen()[0].triple.o.value, seen_before);
  EXPECT_EQ(state_of(kHome2), States{"never connected"});
  // And with what it last said of itself: its version and outbox depth (a new run wrote no
  // version and an outbox of 0, while the child's own view said 12 items waited).
  auto said = [&](const std::string& predicate) {
    auto records = node::Node::open(tree.hospital_dir).value().snapshot().value().list({.s = Term::iri(kHome1), .p = Term::iri(predicate)}).value();
    return records.size() == 1 ? records[0].triple.o.value : "(" + std::to_string(records.size()) + " records)";
  };
  const std::string version = said(vocab::kSoftwareVersion);
  EXPECT_NE(version.find("tahvel"), std::string::npos) << version;
  {  // as a run that last heard home1 with 12 items in its outbox left it
    auto hospital_node = node::Node::open(tree.hospital_dir).value();
    auto link_agent = hospital_node.agent("link").value();
    node::Item state;
    state.persistent = true;
    state.add(Term::iri(kHome1), Term::iri(vocab::kParent), Term::iri(kHospital))
        .add(Term::iri(kHome1), Term::iri(vocab::kLinkState), Term::literal("down"))
        .add(Term::iri(kHome1), Term::iri(vocab::kLastSeen), Term::integer(std::stoll(seen_before)))
        .add(Term::iri(kHome1), Term::iri(vocab::kOutboxDepth), Term::integer(12))
        .add(Term::iri(kHome1), Term::iri(vocab::kSoftwareVersion), Term::literal(version))
        // Its store's figures, the free disk not known to it (P12).
        .add(Term::iri(kHome1), Term::iri(vocab::kStoreUsedBytes), Term::integer(4096))
        .add(Term::iri(kHome1), Term::iri(vocab::kStoreDataBytes), Term::integer(2048))
        .add(Term::iri(kHome1), Term::iri(vocab::kStoreMaxBytes), Term::integer(1 << 20));
    tree.hospital.reset();
    ASSERT_TRUE(link_agent.replace({{.s = Term::iri(kHome1), .source = link_agent.iri()}}, {state}).has_value());
  }
  const std::uint64_t item_written = state_item();
  tree.hospital = tree.start_hospital();
  ASSERT_TRUE(eventually([&] { return state_item() != item_written; })) << "the new run wrote no state of home1";
  EXPECT_EQ(state_of(kHome1), States{"down"});
  EXPECT_EQ(said(vocab::kOutboxDepth), "12");
  EXPECT_EQ(said(vocab::kSoftwareVersion), version);
  EXPECT_EQ(said(vocab::kLastSeen), seen_before);
  EXPECT_EQ(said(vocab::kStoreMaxBytes), std::to_string(1 << 20));
  EXPECT_EQ(said(vocab::kDiskFreeBytes), "(0 records)") << "not known is not 0 bytes free";
}

// P12a: a child keeps its own view of its uplink on its board (what `tahvel status` shows on a
// machine without the parent): up once welcomed, down within child_silence of its parent going
// silent (nothing else comes down on a quiet link: the parent's answers to heartbeats are what
// it hears), up again when the parent is back, and refused with the parent's reason.
TEST(Link, AChildKeepsItsOwnViewOfItsUplinkThatFollowsItsParent) {
  Tree tree;
  auto own_state = uplink_states;
  using States = std::vector<std::string>;
  tree.home1 = tree.start_home(tree.home1_dir, kHome1, tree.home1_log);
  ASSERT_TRUE(eventually([&] { return own_state(tree.home1_dir, kHome1) == States{"never connected"}; }));
  tree.hospital = tree.start_hospital(LinkOptions{}.ack_delay, /*say_leaving=*/false);  // it dies unheard
  ASSERT_TRUE(eventually([&] { return own_state(tree.home1_dir, kHome1) == States{"up"}; }));
  // Up for longer than child_silence with nothing but heartbeats: still up.
  std::this_thread::sleep_for(LinkOptions{}.child_silence + 1s);
  EXPECT_EQ(own_state(tree.home1_dir, kHome1), States{"up"});
  EXPECT_EQ(count(tree.home1_dir, {.s = Term::iri(kHome1), .p = Term::iri(vocab::kParent), .o = Term::iri(kHospital)}), 1u);
  EXPECT_EQ(count(tree.home1_dir, {.s = Term::iri(kHome1), .p = Term::iri(vocab::kParentLastHeard)}), 1u);
  tree.hospital.reset();
  EXPECT_TRUE(eventually([&] { return own_state(tree.home1_dir, kHome1) == States{"down"}; }));
  // Its log says so too, as the parent's log says a child went silent.
  EXPECT_TRUE(tree.home1_log.has("the parent <" + kHospital + "> has not been heard for ")) << tree.home1_log.text();
  EXPECT_TRUE(tree.home1_log.has(": link down; items wait in the outbox (0) until it is heard again")) << tree.home1_log.text();
  tree.hospital = tree.start_hospital();
  EXPECT_TRUE(eventually([&] { return own_state(tree.home1_dir, kHome1) == States{"up"}; }));
  EXPECT_TRUE(eventually([&] { return tree.home1_log.has("the parent <" + kHospital + "> is heard again: link up"); }))
      << tree.home1_log.text();

  const std::string home3 = kHospital + "/home3", home3_dir = (tree.tmp / "home3").string();  // not configured
  ASSERT_TRUE(node::Node::init(home3_dir, {.iri = home3}));
  Log home3_log;
  auto link3 = tree.start_home(home3_dir, home3, home3_log);
  EXPECT_TRUE(eventually([&] { return own_state(home3_dir, home3) == States{"refused"}; }));
  EXPECT_EQ(count(home3_dir, {.s = Term::iri(home3), .p = Term::iri(vocab::kUplinkRefusal)}), 1u);
}

// A child started well before its parent backs its hellos off to 4 s (P6). Its first heartbeat
// after the welcome kept the next hello's time, 3-5 s on, and the parent called it silent a few
// seconds after welcoming it, and it its parent: every child of a gateway brought up before the
// gateway's own parent flapped down and up. Heartbeats start at the welcome.
TEST(Link, AChildThatWaitedLongForItsParentBeatsFromTheWelcomeAndStaysUp) {
  Tree tree;
  tree.home1 = tree.start_home(tree.home1_dir, kHome1, tree.home1_log);
  std::this_thread::sleep_for(7s);  // hellos at 0.2, 0.4, 0.8, 1.6, 3.2 s apart, then 4 s
  tree.hospital = Link::start({.dir = tree.hospital_dir, .down = std::shared_ptr<Transport>(tree.bus.open(kHospital, tree.hospital_log.sink())),
                               .children = {"home1", "home2"}, .resend_after = 100ms, .child_silence = 2s,
                               .log = tree.hospital_log.sink()})
                      .value();
  ASSERT_TRUE(eventually([&] { return tree.home1->connected(); }, 10s)) << tree.home1_log.text();
  std::this_thread::sleep_for(4s);
  EXPECT_FALSE(tree.hospital_log.has("silent for")) << tree.hospital_log.text();
  EXPECT_TRUE(state_says_up(tree.hospital_dir, kHome1));
  EXPECT_FALSE(tree.home1_log.has("has not been heard for")) << tree.home1_log.text();
}

// P12a: the child's view went "down" at its next heartbeat after child_silence had passed, up
// to a heartbeat late (`status` on the home's machine said "up" 4-5.7 s after the parent fell
// silent, deploy.md says 3.5). It goes down at the round that passes child_silence, which the
// link's log line gives as the silence it saw: with heartbeats every 3 s, one at the beat after
// would have seen 6 s.
TEST(Link, AChildsOwnViewGoesDownWhenItsParentsSilencePassesChildSilenceNotAtItsNextHeartbeat) {
  Tree tree;
  tree.hospital = tree.start_hospital(LinkOptions{}.ack_delay, /*say_leaving=*/false);  // it dies unheard
  const LinkOptions defaults;
  tree.home1 = Link::start({.dir = tree.home1_dir, .parent_iri = kHospital,
                            .up = std::shared_ptr<Transport>(tree.bus.open(kHome1, tree.home1_log.sink())),
                            .resend_after = 100ms, .heartbeat_every = 3s, .log = tree.home1_log.sink()})
                   .value();
  ASSERT_TRUE(eventually([&] { return uplink_states(tree.home1_dir, kHome1) == std::vector<std::string>{"up"}; }));
  tree.hospital.reset();
  ASSERT_TRUE(eventually([&] { return uplink_states(tree.home1_dir, kHome1) == std::vector<std::string>{"down"}; }, 15s));
  const std::string said = tree.home1_log.text();
  const std::string lead = "the parent <" + kHospital + "> has not been heard for ";
  const std::size_t at = said.find(lead);
  ASSERT_NE(at, std::string::npos) << said;
  const double seconds = std::stod(said.substr(at + lead.size()));
  EXPECT_GE(seconds, std::chrono::duration<double>(defaults.child_silence).count()) << said;
  EXPECT_LT(seconds, std::chrono::duration<double>(defaults.child_silence).count() + 1.5) << said;
}

// P12a across a restart of the child's link: a link restarted while its parent is away says
// "down" with the time the parent was last heard (the earlier run's), not "never connected" —
// what `tahvel status` on the child's machine shows of a home whose link was restarted in an
// outage.
TEST(Link, AChildsLinkRestartedWhileItsParentIsAwaySaysDownWithWhenItWasLastHeard) {
  Tree tree;
  ASSERT_TRUE(tree.start_hospital_and_home1());
  using States = std::vector<std::string>;
  auto own_state = [&] { return uplink_states(tree.home1_dir, kHome1); };
  auto last_heard = [&] {
    auto records = node::Node::open(tree.home1_dir).value().snapshot().value().list(
        {.s = Term::iri(kHome1), .p = Term::iri(vocab::kParentLastHeard)}).value();
    return records.empty() ? std::string() : records[0].triple.o.value;
  };
  auto state_item = [&] {
    auto records = node::Node::open(tree.home1_dir).value().snapshot().value().list(
        {.s = Term::iri(kHome1), .p = Term::iri(vocab::kUplinkState)}).value();
    return records.empty() ? 0 : records[0].meta.item;
  };
  ASSERT_TRUE(eventually([&] { return own_state() == States{"up"}; }));
  tree.hospital.reset();
  ASSERT_TRUE(eventually([&] { return own_state() == States{"down"}; }));
  const std::string heard = last_heard();
  ASSERT_FALSE(heard.empty());
  const std::uint64_t item_before = state_item();
  tree.home1.reset();
  tree.home1 = tree.start_home(tree.home1_dir, kHome1, tree.home1_log);
  ASSERT_TRUE(eventually([&] { return state_item() != item_before; })) << "the new run wrote no state of its uplink";
  EXPECT_EQ(own_state(), States{"down"});
  EXPECT_EQ(last_heard(), heard);
  // And up again once the parent is back.
  tree.hospital = tree.start_hospital();
  EXPECT_TRUE(eventually([&] { return own_state() == States{"up"}; }));
  EXPECT_NE(last_heard(), heard);
}

// A child that was welcomed learns that its parent no longer accepts it (the parent restarted
// with a file without it) from the answer to its next heartbeat: "refused", with the reason, not
// "down" for ever. The parent drops the state it kept of it.
TEST(Link, AWelcomedChildThatItsParentNoLongerAcceptsIsRefusedNotLeftDown) {
  Tree tree;
  ASSERT_TRUE(tree.start_hospital_and_home1());
  using States = std::vector<std::string>;
  auto own_state = [&] { return uplink_states(tree.home1_dir, kHome1); };
  ASSERT_TRUE(eventually([&] { return own_state() == States{"up"}; }));
  tree.hospital.reset();
  tree.hospital = Link::start({.dir = tree.hospital_dir, .down = std::shared_ptr<Transport>(tree.bus.open(kHospital, tree.hospital_log.sink())),
                               .children = {"home2"}, .log = tree.hospital_log.sink()})
                      .value();
  EXPECT_TRUE(eventually([&] { return own_state() == States{"refused"}; })) << own_state().size() << " states";
  // Nor does the parent keep, from its earlier run, a state of it that would say "up" for ever.
  EXPECT_EQ(count(tree.hospital_dir, {.s = Term::iri(kHome1), .p = Term::iri(vocab::kLinkState)}), 0u);
  EXPECT_EQ(count(tree.home1_dir, {.s = Term::iri(kHome1), .p = Term::iri(vocab::kUplinkRefusal),
                                   .o = Term::literal("<" + kHome1 + "> is not among the children configured for <" + kHospital + ">")}),
            1u);
}

// P6: a thousand homes whose hospital restarted all say hello; a hospital slow to answer them
// must not be asked ever more often (at a fixed 250 ms it fell behind, its children's heartbeats
// came too late, it called them down and they said hello again: docs/bench.md, session 35).
TEST(HelloGap, StartsAtAQuarterSecondDoublesUpToFourSecondsEachWaitWithinAQuarterOfIt) {
  using std::chrono::nanoseconds;
  std::vector<nanoseconds> bases;
  nanoseconds before{0};
  for (int i = 0; i < 8; ++i) {
    const HelloGap gap = next_hello_gap(before, 1s);
    bases.push_back(gap.base);
    EXPECT_GE(gap.wait, gap.base - gap.base / 4) << "hello " << i + 1;
    EXPECT_LE(gap.wait, gap.base + gap.base / 4) << "hello " << i + 1;
    before = gap.base;
  }
  EXPECT_EQ(bases, (std::vector<nanoseconds>{250ms, 500ms, 1s, 2s, 4s, 4s, 4s, 4s}));
  // A faster heartbeat starts faster; the ceiling stays.
  EXPECT_EQ(next_hello_gap(nanoseconds{0}, 100ms).base, 100ms);
  EXPECT_EQ(next_hello_gap(3s, 100ms).base, 4s);
  // The waits differ: children that lost their parent together do not ask together.
  std::set<nanoseconds::rep> waits;
  for (int i = 0; i < 20; ++i) waits.insert(next_hello_gap(2s, 1s).wait.count());
  EXPECT_GT(waits.size(), 10u);
}

TEST(Link, AChildWhoseParentDoesNotAnswerSaysHelloLessAndLessOften) {
  Tree tree;
  auto parent = std::unique_ptr<Transport>(tree.bus.open(kHospital, tree.hospital_log.sink()));
  tree.home1 = tree.start_home(tree.home1_dir, kHome1, tree.home1_log);
  // Hellos at about 0, 0.2, 0.6, 1.4 and 3 s (heartbeat_every 200 ms): five in 3.5 s, where a
  // fixed gap said eighteen.
  int hellos = 0;
  const auto end = std::chrono::steady_clock::now() + 3500ms;
  while (std::chrono::steady_clock::now() < end) {
    auto frame = parent->receive(50ms);
    ASSERT_TRUE(frame) << frame.error().message;
    if (*frame && (*frame)->kind == FrameKind::hello) ++hellos;
  }
  EXPECT_GE(hellos, 2);
  EXPECT_LE(hellos, 7);
}

// `tahvel status` prints the age of tv:lastSeen: while a child is heard it must never look
// older than child_silence (3.5 s), the age at which the parent would call it down.
TEST(Link, AChildThatIsHeardNeverLooksSilentLongerThanChildSilenceInItsState) {
  Tree tree;
  ASSERT_TRUE(tree.start_hospital_and_home1());
  auto last_seen_age = [&] {
    auto records = node::Node::open(tree.hospital_dir).value().snapshot().value()
                       .list({.s = Term::iri(kHome1), .p = Term::iri(vocab::kLastSeen)}).value();
    EXPECT_EQ(records.size(), 1u);
    const auto now = std::chrono::system_clock::now().time_since_epoch();
    return records.empty() ? 0ns : std::chrono::nanoseconds(now) - std::chrono::nanoseconds(std::stoll(records[0].triple.o.value));
  };
  std::chrono::nanoseconds oldest{0};
  for (auto until = std::chrono::steady_clock::now() + 7s; std::chrono::steady_clock::now() < until;) {
    oldest = std::max(oldest, last_seen_age());
    std::this_thread::sleep_for(100ms);
  }
  EXPECT_LT(oldest, 3500ms) << "tv:lastSeen was " << std::chrono::duration_cast<std::chrono::milliseconds>(oldest).count()
                            << " ms old while the child was heard";
}

// The kind of the hospital's answer to a hello from `iri` (nullopt: none within 5 s).
std::optional<FrameKind> answer_to_hello(MemoryBus& bus, const std::string& iri) {
  auto endpoint = bus.open(iri);
  Frame hello;
  hello.kind = FrameKind::hello;
  hello.from = iri;
  hello.to = kHospital;
  if (!endpoint->send(hello)) return std::nullopt;
  auto answer = endpoint->receive(5s);
  if (!answer || !*answer) return std::nullopt;
  return (*answer)->kind;
}

TEST(Link, ParentRefusesAChildOutsideItsSubtreeAndAnUnconfiguredChild) {
  Tree tree;
  tree.hospital = tree.start_hospital();
  EXPECT_FALSE(Link::start({.dir = tree.home1_dir, .parent_iri = "http://example.org/other",
                            .up = std::shared_ptr<Transport>(tree.bus.open(kHome1))}));
  // Frames from an IRI that is not a configured child of the hospital.
  EXPECT_EQ(answer_to_hello(tree.bus, kHospital + "/home3"), FrameKind::error);
  EXPECT_TRUE(tree.hospital_log.has("not among the children configured"));
  EXPECT_EQ(answer_to_hello(tree.bus, kHome1 + "/ecg"), FrameKind::error);
  EXPECT_TRUE(tree.hospital_log.has("is not a child of"));
  // Said on the board too, as the link's problem, for `tahvel status` at the parent: a home whose
  // id the hospital's file lacks was refused in the hospital's log only.
  auto board = tahvel::node::Node::open(tree.hospital_dir);
  ASSERT_TRUE(board.has_value());
  std::string problem;
  EXPECT_TRUE(eventually([&] {
    auto snap = board->snapshot();
    auto said = snap ? snap->list({.s = Term::iri(kHospital + "/link"), .p = Term::iri(tahvel::node::kProblem)})
                     : tahvel::node::Result<std::vector<tahvel::node::Record>>(std::vector<tahvel::node::Record>{});
    problem = said && !said->empty() ? said->front().triple.o.value : "";
    return problem.find("<" + kHospital + "/home3>: <" + kHospital + "/home3> is not among the children configured") !=
           std::string::npos;
  })) << problem;
  EXPECT_NE(problem.find("refuses the hello of "), std::string::npos) << problem;
}

// P1, byte for byte: an IRI that is the child's in normal form only (the host's case, a ".."
// segment) is no child. Each such spelling of home1 was registered as a child of its own, and
// its items stored at the parent under an IRI that is no node's (an exploratory run of session
// 85, with hellos and up frames made by hand).
TEST(Link, ParentRefusesAnIriThatIsItsChildsOnlyInNormalForm) {
  Tree tree;
  tree.hospital = tree.start_hospital();
  for (const std::string& alias : {std::string("http://EXAMPLE.org/hospital/home1"), kHospital + "/../hospital/home1",
                                  kHospital + "/./home1"}) {
    EXPECT_EQ(answer_to_hello(tree.bus, alias), FrameKind::error) << alias;
    EXPECT_TRUE(eventually([&] {
      return tree.hospital_log.has("<" + alias + "> is not written as <" + kHospital + "> writes its child 'home1': <" + kHome1 + ">");
    })) << tree.hospital_log.text();
    EXPECT_EQ(count(tree.hospital_dir, {.s = Term::iri(alias), .p = Term::iri(vocab::kLinkState)}), 0u) << alias;
  }
  EXPECT_EQ(answer_to_hello(tree.bus, kHome1), FrameKind::welcome);
}

// A node that accepts any child still refuses one whose id is not in NFC: "café" with a
// combining accent would be a second node that looks like "café" (uri::check_id).
TEST(Link, ParentRefusesAChildWhoseIdLooksLikeAnotherButIsNotInNfc) {
  Tree tree;
  auto gateway = Link::start({.dir = tree.hospital_dir, .down = std::shared_ptr<Transport>(tree.bus.open(kHospital)),
                              .log = tree.hospital_log.sink()})
                     .value();
  EXPECT_EQ(answer_to_hello(tree.bus, kHospital + "/cafe\xCC\x81"), FrameKind::error);
  EXPECT_TRUE(tree.hospital_log.has("not in Unicode normalization form C (NFC)"));
  EXPECT_EQ(count(tree.hospital_dir, {.s = Term::iri(kHospital + "/cafe\xCC\x81"), .p = Term::iri(vocab::kLinkState)}), 0u);
  EXPECT_EQ(answer_to_hello(tree.bus, kHospital + "/caf\xC3\xA9"), FrameKind::welcome);
}

// P1: child C is agent C of its parent, so no child may take the id of the link's own agents,
// configured or not (its items would be the uplink's outbox, its state the link's).
TEST(Link, ParentRefusesAChildWhoseIdIsOneOfTheLinksOwnAgents) {
  Tree tree;
  EXPECT_FALSE(Link::start({.dir = tree.hospital_dir, .down = std::shared_ptr<Transport>(tree.bus.open(kHospital)),
                            .children = {"home1", "uplink"}}));
  tree.hospital = Link::start({.dir = tree.hospital_dir, .down = std::shared_ptr<Transport>(tree.bus.open(kHospital)),
                               .log = tree.hospital_log.sink()})
                      .value();
  for (const std::string id : {"uplink", "link"}) {
    EXPECT_EQ(answer_to_hello(tree.bus, kHospital + "/" + id), FrameKind::error) << id;
    EXPECT_TRUE(tree.hospital_log.has("which is this node's own agent '" + id + "'")) << id;
  }
}

// P6b: two stores taking turns under one IRI (a second deployment of the same file on one
// network) are said to be a conflict, on the side that sees it, in the state status shows.
TEST(Link, TwoStoresTakingTurnsUnderOneIriAreAConflictInTheStateOfTheSideThatSeesIt) {
  Tree tree;
  tree.hospital = tree.start_hospital();
  auto twin = tree.bus.open(kHome1);
  // A hello or heartbeat from home1's IRI naming `store` as the sender's.
  auto from_store = [&](FrameKind kind, const std::string& store) {
    Frame f;
    f.kind = kind;
    f.from = kHome1;
    f.to = kHospital;
    f.body = wire::encode_state({"twin", 0, store, ""});
    return twin->send(f);
  };
  auto hello_from = [&](const std::string& store) { return from_store(FrameKind::hello, store); };
  auto heartbeat_from = [&](const std::string& store) { return from_store(FrameKind::heartbeat, store); };
  const Term conflict = Term::iri(vocab::kLinkConflict);
  // A new store while the registered one is heard waits (a store made again comes after the old
  // one fell silent): no conflict yet.
  ASSERT_TRUE(hello_from(store_of('a')));
  ASSERT_TRUE(eventually([&] { return state_says_up(tree.hospital_dir, kHome1); }));
  ASSERT_TRUE(hello_from(store_of('b')));
  std::this_thread::sleep_for(300ms);
  EXPECT_EQ(count(tree.hospital_dir, {.s = Term::iri(kHome1), .p = conflict}), 0u);
  // The registered one heard more than a second after the new one's hello: both are alive.
  std::this_thread::sleep_for(1100ms);
  ASSERT_TRUE(heartbeat_from(store_of('a')));
  std::this_thread::sleep_for(100ms);
  ASSERT_TRUE(hello_from(store_of('b')));
  EXPECT_TRUE(eventually([&] { return tree.hospital_log.has("conflict: two stores (id " + store_of('a') + " and id " + store_of('b') + ") are alive as the child <" + kHome1 + ">"); }));
  EXPECT_TRUE(eventually([&] { return count(tree.hospital_dir, {.s = Term::iri(kHome1), .p = conflict}) == 1; }));

  // The child's side: welcomes from two stores of its parent.
  Tree other;
  auto parent = other.bus.open(kHospital);
  other.home1 = other.start_home(other.home1_dir, kHome1, other.home1_log);
  // The second store's welcome waits while the first is heard; the first heard more than a
  // second after it, and it welcomes again: both are alive.
  for (const std::string& store : {store_of('c'), store_of('d'), std::string(), store_of('c'), store_of('d')}) {
    if (store.empty()) {
      std::this_thread::sleep_for(1100ms);
      continue;
    }
    Frame welcome;
    welcome.kind = FrameKind::welcome;
    welcome.from = kHospital;
    welcome.to = kHome1;
    welcome.body = wire::encode_state({"twin", 0, store, ""});
    ASSERT_TRUE(parent->send(welcome));
    std::this_thread::sleep_for(50ms);
  }
  EXPECT_TRUE(eventually([&] { return other.home1_log.has("conflict: two stores (id " + store_of('c') + " and id " + store_of('d') + ") are alive as the parent <" + kHospital + ">"); }))
      << other.home1_log.text();
  EXPECT_TRUE(eventually([&] { return count(other.home1_dir, {.s = Term::iri(kHome1), .p = conflict}) == 1; }));
}

// P6b: a second node under a child's IRI (a second deployment of the same file on one network):
// the parent sees two stores taking turns, links with neither while both live (their items
// would mix under one IRI, and one's acknowledgements would empty the other's outbox), and once
// one is gone links again with the other, which then sends everything it kept. Nothing of either
// store is lost or doubled.
TEST(Link, ASecondNodeUnderAChildsIriStopsThatLinkUntilItGoesAndNothingIsLost) {
  Tree tree;
  const auto hold = 1500ms;
  tree.hospital = Link::start({.dir = tree.hospital_dir, .down = std::shared_ptr<Transport>(tree.bus.open(kHospital, tree.hospital_log.sink())),
                               .children = {"home1", "home2"}, .resend_after = 100ms, .conflict_hold = hold,
                               .log = tree.hospital_log.sink()})
                      .value();
  auto start_home1 = [&](const std::string& dir, Log& log) {
    return Link::start({.dir = dir, .parent_iri = kHospital, .up = std::shared_ptr<Transport>(tree.bus.open(kHome1, log.sink())),
                        .resend_after = 100ms, .heartbeat_every = 200ms, .conflict_hold = hold, .log = log.sink()})
        .value();
  };
  tree.home1 = start_home1(tree.home1_dir, tree.home1_log);
  ASSERT_TRUE(home1_sends(tree, 0, 20, 20));

  const std::string twin_dir = (tree.tmp / "twin").string();
  ASSERT_TRUE(node::Node::init(twin_dir, {.iri = kHome1}));
  Log twin_log;
  auto twin = start_home1(twin_dir, twin_log);
  store_hrv_items(twin_dir, 1000, 20);  // after its start: the uplink's outbox takes them
  ASSERT_TRUE(eventually([&] { return tree.hospital_log.has("conflict: two stores"); })) << tree.hospital_log.text();
  ASSERT_TRUE(eventually([&] { return count(tree.hospital_dir, {.s = Term::iri(kHome1), .p = Term::iri(vocab::kLinkConflict)}) == 1; }));
  // The hospital's operator is told of the twin's first hellos, refused before the conflict
  // was declared, and not once a hello.
  EXPECT_EQ(tree.hospital_log.lines_with("refused a hello frame: another store (id "), 1u) << tree.hospital_log.text();

  // While both live, nothing more of home1's is taken, and none of it leaves its outbox.
  store_hrv_items(tree.home1_dir, 20, 20);
  std::this_thread::sleep_for(1s);
  for (int n = 20; n < 40; ++n) EXPECT_EQ(count(tree.hospital_dir, {.p = Term::iri(kEx + "n"), .o = Term::integer(n)}), 0u) << n;
  EXPECT_EQ(outbox(tree.home1_dir), 20u);

  twin.reset();
  ASSERT_TRUE(eventually([&] { return count(tree.hospital_dir, {.p = Term::iri(kEx + "n"), .o = Term::integer(39)}) == 1; }, 15s))
      << tree.home1_log.text();
  EXPECT_TRUE(eventually([&] { return outbox(tree.home1_dir) == 0; }));
  for (int n = 0; n < 40; ++n) EXPECT_EQ(count(tree.hospital_dir, {.p = Term::iri(kEx + "n"), .o = Term::integer(n)}), 1u) << n;
  // The twin's items: each at the hospital once, or still in the twin's outbox.
  const std::uint64_t kept = outbox(twin_dir);
  std::uint64_t arrived = 0;
  for (int n = 1000; n < 1020; ++n) {
    const std::uint64_t c = count(tree.hospital_dir, {.p = Term::iri(kEx + "n"), .o = Term::integer(n)});
    EXPECT_LE(c, 1u) << n;
    arrived += c;
  }
  EXPECT_GE(arrived + kept, 20u) << "arrived " << arrived << ", kept " << kept;
}

// P6b, the child's side: a second node under its parent's IRI (a second hospital of the same
// file on one network). The child links with neither while both live, and once one is gone
// sends everything to the other, once.
TEST(Link, ASecondNodeUnderTheParentsIriStopsTheChildsUplinkUntilItGoesAndNothingIsLost) {
  Tree tree;
  const auto hold = 1500ms;
  auto start_hospital = [&](const std::string& dir, Log& log) {
    return Link::start({.dir = dir, .down = std::shared_ptr<Transport>(tree.bus.open(kHospital, log.sink())),
                        .children = {"home1", "home2"}, .resend_after = 100ms, .conflict_hold = hold, .log = log.sink()})
        .value();
  };
  tree.hospital = start_hospital(tree.hospital_dir, tree.hospital_log);
  tree.home1 = Link::start({.dir = tree.home1_dir, .parent_iri = kHospital,
                            .up = std::shared_ptr<Transport>(tree.bus.open(kHome1, tree.home1_log.sink())),
                            .resend_after = 100ms, .heartbeat_every = 200ms, .conflict_hold = hold, .log = tree.home1_log.sink()})
                   .value();
  ASSERT_TRUE(home1_sends(tree, 0, 20, 20));

  const std::string twin_dir = (tree.tmp / "twin-hospital").string();
  ASSERT_TRUE(node::Node::init(twin_dir, {.iri = kHospital}));
  Log twin_log;
  auto twin = start_hospital(twin_dir, twin_log);
  ASSERT_TRUE(eventually([&] { return tree.home1_log.has("conflict: two stores"); })) << tree.home1_log.text();
  ASSERT_TRUE(eventually([&] { return tree.home1_log.has("the parent is not linked with while the conflict lasts"); }))
      << tree.home1_log.text();
  store_hrv_items(tree.home1_dir, 20, 20);
  std::this_thread::sleep_for(1s);
  EXPECT_EQ(outbox(tree.home1_dir), 20u);  // sent to neither, kept
  for (int n = 20; n < 40; ++n) EXPECT_EQ(count(tree.hospital_dir, {.p = Term::iri(kEx + "n"), .o = Term::integer(n)}), 0u) << n;

  twin.reset();
  ASSERT_TRUE(eventually([&] { return outbox(tree.home1_dir) == 0; }, 15s)) << tree.home1_log.text();
  for (int n = 0; n < 40; ++n) EXPECT_EQ(count(tree.hospital_dir, {.p = Term::iri(kEx + "n"), .o = Term::integer(n)}), 1u) << n;
}

// home1's link under a parent played by hand on the bus (the hospital's endpoint), as the store
// of id store_of('e'): home1 welcomed, with five items sent up.
struct HomeUnderAParentByHand {
  Tree tree;
  std::unique_ptr<Transport> parent = tree.bus.open(kHospital);
  std::string own_store;  // home1's store id
  Frame welcome;
  std::set<std::uint64_t> sent;  // the seqs of the five items

  // `welcome_names_own_store`: the welcome's mark is of home1's stream by its store id (else by
  // none, as from before store ids).
  void start(bool welcome_names_own_store) {
    tree.home1 = tree.start_home(tree.home1_dir, kHome1, tree.home1_log);
    own_store = node::Node::open(tree.home1_dir).value().store_id().value();
    ASSERT_TRUE(next(FrameKind::hello));
    welcome.kind = FrameKind::welcome;
    welcome.from = kHospital;
    welcome.to = kHome1;
    welcome.body = wire::encode_state({"test", 0, store_of('e'), welcome_names_own_store ? own_store : ""});
    ASSERT_TRUE(parent->send(welcome));
    store_hrv_items(tree.home1_dir, 0, 5);
    while (sent.size() < 5) {
      auto up = next(FrameKind::up);
      ASSERT_TRUE(up);
      sent.insert(up->seq);
    }
  }
  // Sends home1 an ack of its stream up to `mark`, saying the stream is of `peer_store`.
  bool ack(std::uint64_t mark, const std::string& peer_store) {
    Frame f;
    f.kind = FrameKind::ack;
    f.from = kHospital;
    f.to = kHome1;
    f.ack = mark;
    f.body = wire::encode_state({"", 0, store_of('e'), peer_store});
    return parent->send(f).has_value();
  }
  // The next frame of `kind` home1 sends, within 5 s.
  std::optional<Frame> next(FrameKind kind) {
    for (auto deadline = std::chrono::steady_clock::now() + 5s; std::chrono::steady_clock::now() < deadline;) {
      auto f = parent->receive(100ms);
      if (f && *f && (*f)->kind == kind) return **f;
    }
    return std::nullopt;
  }
};

// P6b: an acknowledgement names the store whose stream it moves. One of another store of the
// child's IRI (a second node under it, registered at the parent) would otherwise empty this
// one's outbox of items the parent never applied.
TEST(Link, AChildKeepsItsOutboxWhenAnAckIsOfAnotherStoresStream) {
  HomeUnderAParentByHand home;
  ASSERT_NO_FATAL_FAILURE(home.start(false));
  auto& [tree, parent, own_store, welcome, sent] = home;
  auto next = [&](FrameKind kind) { return home.next(kind); };
  const std::uint64_t last = *sent.rbegin();
  auto ack_of = [&](const std::string& peer_store) { return home.ack(last, peer_store); };
  ASSERT_TRUE(ack_of(store_of('b')));
  // The parent holds that other store as this node: this one says hello again, and says why
  // (its registration was dropped without a word).
  EXPECT_TRUE(next(FrameKind::hello));
  EXPECT_EQ(outbox(tree.home1_dir), 5u);
  EXPECT_TRUE(eventually([&] {
    return tree.home1_log.has("the parent <" + kHospital + "> acknowledges another store of this node's IRI (id " + store_of('b') + "; this one is " +
                              own_store + "): a second node under <" + kHome1 + ">?");
  })) << tree.home1_log.text();
  welcome.ack = last;  // the parent's mark of home1's stream: all of it applied
  ASSERT_TRUE(parent->send(welcome));
  ASSERT_TRUE(ack_of(own_store));
  EXPECT_TRUE(eventually([&] { return outbox(tree.home1_dir) == 0; }));
}

TEST(Link, MalformedFramesAreDroppedWithAReasonAndTheLinkKeepsWorking) {
  Tree tree;
  tree.hospital = tree.start_hospital();
  tree.bus.inject_raw(kHospital, "garbage");
  Frame old;
  old.kind = FrameKind::hello;
  old.version = kProtocolVersion + 1;
  old.from = kHome1;
  old.to = kHospital;
  tree.bus.inject_raw(kHospital, encode_frame(old));
  Frame bad_body;
  bad_body.kind = FrameKind::up;
  bad_body.from = kHome1;
  bad_body.to = kHospital;
  bad_body.body = "\x01\x02";
  tree.bus.inject_raw(kHospital, encode_frame(bad_body));
  // A peer's text that is not UTF-8 would be refused by the store it is relayed into.
  Frame latin1 = bad_body;
  latin1.body = wire::encode_error({"refused", "caf\xE9", ""});
  latin1.kind = FrameKind::error;
  EXPECT_FALSE(wire::decode_error(latin1.body));
  tree.bus.inject_raw(kHospital, encode_frame(latin1));
  tree.home1 = tree.start_home(tree.home1_dir, kHome1, tree.home1_log);
  auto hrv = node::Node::open(tree.home1_dir).value().agent("hrv").value();
  ASSERT_TRUE(hrv.store(hrv_item(1)));
  EXPECT_TRUE(eventually([&] { return count(tree.hospital_dir, {.p = Term::iri(kEx + "n")}) == 1; }));
  EXPECT_TRUE(tree.hospital_log.has("undecodable"));
  EXPECT_TRUE(tree.hospital_log.has("protocol version"));
  EXPECT_TRUE(tree.hospital_log.has("not UTF-8"));
}

// P17, P6b, P4: a state body whose store id is not one (32 lowercase hex digits) is malformed.
// A hello of home1 with one digit of its store id changed was taken for another store of
// home1, and a few of them (random mutations of frames off the wire) made a conflict that kept
// home1 out for two minutes. Malformed heartbeats, answers, errors and queries were a log line
// each (5,000 in 3.6 s were 3,750 lines); they are said as refusals are, once per sender and
// reason a minute.
TEST(Link, AStateBodyWithAStoreIdThatIsNoneIsMalformedAndSaidOnceAMinute) {
  Tree tree;
  ASSERT_TRUE(tree.start_hospital_and_home1());
  ASSERT_TRUE(home1_sends(tree, 0, 10, 10));
  const std::string store = node::Node::open(tree.home1_dir).value().store_id().value();
  for (int k = 0; k < 50; ++k) {
    std::string damaged = store;
    damaged[static_cast<std::size_t>(k) % damaged.size()] = k % 2 ? 'o' : 'D';
    Frame f;
    f.kind = k % 2 ? FrameKind::hello : FrameKind::heartbeat;
    f.from = kHome1;
    f.to = kHospital;
    f.body = wire::encode_state({"tahvel 0.1.0", 0, damaged, ""});
    tree.bus.inject_raw(kHospital, encode_frame(f));
  }
  // An item-stream ack (seq 0) with such a body, each way: read under the link's lock, it hung
  // the link for good (a review of session 85).
  for (const auto& [from, to] : {std::pair{kHome1, kHospital}, std::pair{kHospital, kHome1}}) {
    Frame ack;
    ack.kind = FrameKind::ack;
    ack.from = from;
    ack.to = to;
    ack.body = wire::encode_state({"", 0, std::string(32, 'D'), ""});
    tree.bus.inject_raw(to, encode_frame(ack));
  }
  ASSERT_TRUE(home1_sends(tree, 10, 10, 20));
  EXPECT_TRUE(eventually([&] { return tree.hospital_log.has("dropped a malformed ack frame from <" + kHome1 + ">"); }))
      << tree.hospital_log.text();
  EXPECT_TRUE(eventually([&] { return tree.home1_log.has("dropped a malformed ack frame from <" + kHospital + ">"); }))
      << tree.home1_log.text();
  EXPECT_TRUE(eventually([&] { return tree.hospital_log.has("is not a store id (32 lowercase hex digits)"); }))
      << tree.hospital_log.text();
  EXPECT_FALSE(tree.hospital_log.has("has another store")) << tree.hospital_log.text();
  EXPECT_FALSE(tree.hospital_log.has("conflict")) << tree.hospital_log.text();
  EXPECT_EQ(tree.hospital_log.lines_with("dropped a malformed hello frame"), 1u) << tree.hospital_log.text();
  EXPECT_EQ(tree.hospital_log.lines_with("dropped a malformed heartbeat frame"), 1u) << tree.hospital_log.text();
  EXPECT_EQ(count(tree.hospital_dir, {.p = Term::iri(kEx + "n")}), 20u);
  EXPECT_FALSE(wire::decode_state(wire::encode_state({"v", 0, std::string(31, 'a'), ""})));
  EXPECT_FALSE(wire::decode_state(wire::encode_state({"v", 0, store_of('a'), "not-a-store"})));
  EXPECT_TRUE(wire::decode_state(wire::encode_state({"v", 0, store_of('a'), store_of('0')})));
}

// P17, P6b: a hello whose state body does not decode is dropped with a line; it was read as a
// hello of a store without an id, and the child's items became a new stream, from its start,
// applied again at the parent ("has another store (id , was …)"). A hello with no body at all
// (a peer from before state bodies) goes on with the stream registered.
TEST(Link, AHelloWhoseStateBodyDoesNotDecodeIsDroppedAndStartsNoNewStream) {
  Tree tree;
  ASSERT_TRUE(tree.start_hospital_and_home1());
  ASSERT_TRUE(home1_sends(tree, 0, 10, 10));
  Frame hello;
  hello.kind = FrameKind::hello;
  hello.from = kHome1;
  hello.to = kHospital;
  hello.body = std::string("\x05\x00\x00\x00" "ab", 6);  // a software version cut short
  tree.bus.inject_raw(kHospital, encode_frame(hello));
  hello.body.clear();
  tree.bus.inject_raw(kHospital, encode_frame(hello));
  ASSERT_TRUE(home1_sends(tree, 10, 10, 20));
  EXPECT_TRUE(eventually([&] { return tree.hospital_log.has("dropped a malformed hello frame from <" + kHome1 + ">: "); }))
      << tree.hospital_log.text();
  EXPECT_FALSE(tree.hospital_log.has("has another store")) << tree.hospital_log.text();
  EXPECT_EQ(count(tree.hospital_dir, {.p = Term::iri(kEx + "n")}), 20u);
}

// P17, P6b, P4: up frames whose body does not decode, carrying store tags of no store the
// parent knows, were counted as signs of another store before their body was looked at: three
// of them held the child off for the conflict's two minutes. They are dropped as malformed, with
// at most one line per sender and reason a minute; the child's stream goes on.
TEST(Link, UpFramesThatDoNotDecodeAreDroppedAndAreNoSignOfAnotherStore) {
  Tree tree;
  ASSERT_TRUE(tree.start_hospital_and_home1());
  ASSERT_TRUE(home1_sends(tree, 0, 10, 10));
  for (std::uint64_t k = 0; k < 20; ++k) {
    Frame bad;
    bad.kind = FrameKind::up;
    bad.from = kHome1;
    bad.to = kHospital;
    bad.seq = 999'999 - k;
    bad.prev = 998;
    bad.ack = (std::uint64_t{0xAAAAAA} << kPeerStoreTagShift) | (std::uint64_t{0xBBBBBB} << kStoreTagShift);
    bad.body = "\x01";
    tree.bus.inject_raw(kHospital, encode_frame(bad));
  }
  ASSERT_TRUE(home1_sends(tree, 10, 10, 20));
  EXPECT_TRUE(eventually([&] { return tree.hospital_log.has("dropped a malformed up frame from <" + kHome1 + ">: "); }))
      << tree.hospital_log.text();
  EXPECT_FALSE(tree.hospital_log.has("another store")) << tree.hospital_log.text();
  EXPECT_FALSE(tree.hospital_log.has("conflict")) << tree.hospital_log.text();
  EXPECT_EQ(tree.hospital_log.lines_with("dropped a malformed up frame"), 1u) << tree.hospital_log.text();
  EXPECT_EQ(count(tree.hospital_dir, {.p = Term::iri(kEx + "n")}), 20u);
}

// P3, P17, P4: junk under a child's name (a prober's flood of session 87). A heartbeat, hello or
// up frame of version 3 whose body does not decode, or an up frame of another store's tag, had
// the hospital speak to home1 in version 3 (queries by source were refused as too old for it)
// though each was dropped. Error frames of made-up codes, each well formed, and error frames
// whose body does not decode were a log line each, on both sides.
TEST(Link, FramesDroppedUnderAChildsNameSayNothingOfItsVersionAndErrorFloodsAreLimited) {
  Tree tree;
  ASSERT_TRUE(tree.start_hospital_and_home1());
  ASSERT_TRUE(home1_sends(tree, 0, 10, 10));
  const std::string home1_store = node::Node::open(tree.home1_dir).value().store_id().value();
  for (FrameKind kind : {FrameKind::heartbeat, FrameKind::hello, FrameKind::up, FrameKind::up}) {
    Frame junk;
    junk.version = 3;
    junk.kind = kind;
    junk.from = kHome1;
    junk.to = kHospital;
    junk.seq = kind == FrameKind::up ? 999'999 : 0;
    junk.prev = kind == FrameKind::up ? 999'998 : 0;
    junk.body = "\x01\x02";
    tree.bus.inject_raw(kHospital, encode_frame(junk));
  }
  Frame other_store;  // decodes, but of no store registered for home1
  other_store.version = 3;
  other_store.kind = FrameKind::up;
  other_store.from = kHome1;
  other_store.to = kHospital;
  other_store.seq = 999'999;
  other_store.prev = 999'998;
  other_store.ack = (std::uint64_t{0xBBBBBB} << kStoreTagShift);
  node::Item item;
  item.add(Term::iri(kHome1 + "/junk"), Term::iri(kEx + "junk"), Term::integer(1));
  other_store.body = wire::encode_item({kHome1 + "/hrv", item});
  ASSERT_NE(store_tag(home1_store), std::uint64_t{0xBBBBBB});
  tree.bus.inject_raw(kHospital, encode_frame(other_store));
  for (int k = 0; k < 40; ++k) {
    Frame error;
    error.kind = FrameKind::error;
    error.from = kHome1;
    error.to = kHospital;
    error.body = wire::encode_error({"code" + std::to_string(k), "m", ""});
    tree.bus.inject_raw(kHospital, encode_frame(error));
    error.from = kHospital;
    error.to = kHome1;
    tree.bus.inject_raw(kHome1, encode_frame(error));
    error.body = "\x07";
    tree.bus.inject_raw(kHome1, encode_frame(error));
  }
  ASSERT_TRUE(home1_sends(tree, 10, 10, 20));
  EXPECT_TRUE(eventually([&] { return tree.hospital_log.has("dropped a malformed heartbeat frame from <" + kHome1 + ">"); }))
      << tree.hospital_log.text();
  EXPECT_TRUE(eventually([&] { return tree.home1_log.has("dropped a malformed error from the parent <" + kHospital + ">: "); }))
      << tree.home1_log.text();
  EXPECT_FALSE(tree.hospital_log.has("speaks protocol version 3")) << tree.hospital_log.text();
  EXPECT_EQ(count(tree.hospital_dir, {.p = Term::iri(kEx + "junk")}), 0u);
  // At most 10 lines in 10 s of all such lines on a node (P4), not one a frame.
  EXPECT_GE(tree.hospital_log.lines_with("error from child <" + kHome1 + ">: code"), 1u) << tree.hospital_log.text();
  EXPECT_LE(tree.hospital_log.lines_with("error from child <" + kHome1 + ">: code"), 10u) << tree.hospital_log.text();
  EXPECT_LE(tree.home1_log.lines_with("error from the parent: code"), 10u) << tree.home1_log.text();
  EXPECT_EQ(tree.home1_log.lines_with("dropped a malformed error from the parent"), 1u) << tree.home1_log.text();
  EXPECT_EQ(tree.home1_log.lines_with("error from the parent: malformed"), 0u) << tree.home1_log.text();
}

// P6b: an up frame without a store tag, from a child whose registered store has one. A forger on
// the LAN sent one so, its seq far ahead and its prev the mark it read off an ack: the mark went
// past every item the child would send, and the child's stream stopped for good.
TEST(Link, AnUpFrameWithoutAStoreTagFromAChildWhoseStoreHasOneIsDroppedAndTheStreamGoesOn) {
  Tree tree;
  ASSERT_TRUE(tree.start_hospital_and_home1());
  ASSERT_TRUE(home1_sends(tree, 0, 10, 10));
  const std::uint64_t mark = node::Node::open(tree.home1_dir).value().agent("hrv").value().written().value().back();
  for (std::uint64_t k = 0; k < 5; ++k) {
    Frame forged;
    forged.kind = FrameKind::up;
    forged.from = kHome1;
    forged.to = kHospital;
    forged.prev = mark + k;
    forged.seq = (std::uint64_t{1} << 62) + forged.prev;
    node::Item item;
    item.add(Term::iri(kHome1 + "/forged"), Term::iri(kEx + "forged"), Term::integer(1));
    forged.body = wire::encode_item({kHome1 + "/hrv", item});
    tree.bus.inject_raw(kHospital, encode_frame(forged));
  }
  ASSERT_TRUE(home1_sends(tree, 10, 10, 20)) << tree.hospital_log.text();
  EXPECT_EQ(count(tree.hospital_dir, {.p = Term::iri(kEx + "forged")}), 0u);
  EXPECT_TRUE(tree.hospital_log.has("that carry no store tag, though the store registered for it has one")) << tree.hospital_log.text();
  EXPECT_FALSE(tree.hospital_log.has("conflict")) << tree.hospital_log.text();
}

// P6b: a child whose frames go to a second store of its parent's IRI (the parent's node brought
// up twice on one network: two parents answer the child) was said to be "two stores (the child's
// and the parent's twin) take turns as the child": an operator looked for a second sensor that
// did not exist (an exploratory run of session 84). The conflict says that the twin is this node.
TEST(Link, AChildSendingToATwinOfItsParentIsSaidToSendToAnotherStoreOfTheParentsIri) {
  Tree tree;
  ASSERT_TRUE(tree.start_hospital_and_home1());
  ASSERT_TRUE(home1_sends(tree, 0, 10, 10));
  const std::string home1_store = node::Node::open(tree.home1_dir).value().store_id().value();
  const std::uint64_t twin_tag = store_tag("a second store of the hospital's IRI");
  for (std::uint64_t k = 0; k < 3; ++k) {
    Frame sent;
    sent.kind = FrameKind::up;
    sent.from = kHome1;
    sent.to = kHospital;
    sent.seq = 1 + k;
    sent.prev = k;
    sent.ack = (store_tag(home1_store) << kStoreTagShift) | (twin_tag << kPeerStoreTagShift);
    node::Item item;
    item.add(Term::iri(kHome1 + "/for-the-twin"), Term::iri(kEx + "twin"), Term::integer(static_cast<std::int64_t>(k)));
    sent.body = wire::encode_item({kHome1 + "/hrv", item});
    tree.bus.inject_raw(kHospital, encode_frame(sent));
    std::this_thread::sleep_for(50ms);
  }
  char tag[16];
  std::snprintf(tag, sizeof tag, "%06llx", static_cast<unsigned long long>(twin_tag));
  EXPECT_TRUE(eventually([&] {
    return tree.hospital_log.has("conflict: two stores of <" + kHospital + "> are alive, and the child <" + kHome1 +
                                 "> sends to both (one is the store of tag " + tag + "): two nodes with one IRI on this network");
  })) << tree.hospital_log.text();
  EXPECT_FALSE(tree.hospital_log.has("take turns as")) << tree.hospital_log.text();
  EXPECT_EQ(count(tree.hospital_dir, {.p = Term::iri(kEx + "twin")}), 0u);
}

// P13: a query frame with an empty origin was answered, the whole store sent up towards no one.
// It is dropped with a line, and the link goes on.
TEST(Link, AQueryFromTheParentWhoseOriginIsNoNodeAboveIsDropped) {
  Tree tree;
  ASSERT_TRUE(tree.start_hospital_and_home1());
  for (const std::string& origin : {std::string(), std::string("http://example.org/elsewhere")}) {
    wire::QueryBody body;
    body.origin = origin;
    body.target = kHome1;
    Frame query;
    query.kind = FrameKind::query;
    query.from = kHospital;
    query.to = kHome1;
    query.seq = 77;
    query.body = wire::encode_query(body).value();
    tree.bus.inject_raw(kHome1, encode_frame(query));
    EXPECT_TRUE(eventually([&] {
      return tree.home1_log.has("dropped a query from the parent whose origin <" + origin + "> is not a node above <" + kHome1 + ">");
    })) << tree.home1_log.text();
  }
  ASSERT_TRUE(home1_sends(tree, 0, 5, 5));
}

// P8, P6a: an acknowledgement of more than the child has sent is refused with a line: taken, it
// emptied the outbox of items the parent never had, and left every later one there for good.
TEST(Link, AnAckBeyondWhatTheChildHasSentIsRefusedAndTheOutboxKeepsItsItems) {
  HomeUnderAParentByHand home;
  ASSERT_NO_FATAL_FAILURE(home.start(true));
  auto& [tree, parent, own_store, welcome, sent] = home;
  auto next = [&](FrameKind kind) { return home.next(kind); };
  auto ack = [&](std::uint64_t mark) { return home.ack(mark, own_store); };
  const std::uint64_t last = *sent.rbegin();
  ASSERT_TRUE(ack(std::uint64_t{1} << 62));
  EXPECT_TRUE(eventually([&] { return tree.home1_log.has("it acknowledges up to 4611686018427387904, and this store has sent no item past"); }))
      << tree.home1_log.text();
  EXPECT_EQ(outbox(tree.home1_dir), 5u);
  ASSERT_TRUE(ack(last));
  EXPECT_TRUE(eventually([&] { return outbox(tree.home1_dir) == 0; }));
  store_hrv_items(tree.home1_dir, 5, 1);
  bool later_sent = false;  // past the resends of the first five
  for (auto deadline = std::chrono::steady_clock::now() + 5s; !later_sent && std::chrono::steady_clock::now() < deadline;)
    if (auto up = next(FrameKind::up)) later_sent = up->seq > last;
  EXPECT_TRUE(later_sent) << "items after it are sent";
}

// A parent that keeps acknowledging past all the child sent (its mark of the stream moved by a
// forged frame) takes everything after for repeats: the child's stream stands while the link is
// up. Up to session 82 only a line of the child's log said so, once a minute; `status` showed
// "link up". It is the link's problem on the board, and goes once the mark moves.
TEST(Link, AStreamTheParentAppliesNothingOfWhileItIsHeardIsTheLinksProblem) {
  HomeUnderAParentByHand home;
  ASSERT_NO_FATAL_FAILURE(home.start(true));
  auto& [tree, parent, own_store, welcome, sent] = home;
  const node::Pattern problem{.s = Term::iri(kHome1 + "/link"), .p = Term::iri(node::kProblem)};
  const auto problems = [&] {
    std::string text;
    const std::vector<node::Record> records = node::Node::open(tree.home1_dir).value().snapshot().value().list(problem).value();
    for (const auto& r : records) text += r.triple.o.value;
    return text;
  };
  bool said = false;
  for (auto deadline = std::chrono::steady_clock::now() + 20s; !said && std::chrono::steady_clock::now() < deadline;) {
    ASSERT_TRUE(home.ack(std::uint64_t{1} << 62, own_store));  // heard, and beyond
    std::this_thread::sleep_for(300ms);
    said = problems().find("has applied nothing this node sent for over 7.0 s though it is heard") != std::string::npos;
  }
  ASSERT_TRUE(said) << problems() << tree.home1_log.text();
  EXPECT_NE(problems().find("it acknowledges up to 4611686018427387904, past all this store sent"), std::string::npos) << problems();
  ASSERT_TRUE(home.ack(*sent.rbegin(), own_store));
  EXPECT_TRUE(eventually([&] { return problems().empty(); })) << problems();
}

// The same at the parent: a child's acknowledgement of more of the down stream than the parent
// has sent is refused with a line, once however many come.
TEST(Link, AChildsAckBeyondWhatTheParentHasSentIsRefusedWithOneLine) {
  Tree tree;
  tree.hospital = tree.start_hospital();
  auto child = tree.bus.open(kHome1);
  bool welcomed = false;
  for (int i = 0; i < 50 && !welcomed; ++i) {
    Frame hello;
    hello.kind = FrameKind::hello;
    hello.from = kHome1;
    hello.to = kHospital;
    ASSERT_TRUE(child->send(hello));
    if (auto got = child->receive(100ms); got && *got) welcomed = (*got)->kind == FrameKind::welcome;
  }
  ASSERT_TRUE(welcomed);
  for (int i = 0; i < 3; ++i) {
    Frame ack;
    ack.kind = FrameKind::ack;
    ack.from = kHome1;
    ack.to = kHospital;
    ack.ack = (std::uint64_t{1} << 62) + static_cast<std::uint64_t>(i);
    ASSERT_TRUE(child->send(ack));
  }
  EXPECT_TRUE(eventually([&] { return tree.hospital_log.has("refused an ack frame: it acknowledges up to 4611686018427387904, "); }))
      << tree.hospital_log.text();
  std::this_thread::sleep_for(200ms);
  std::lock_guard lock(tree.hospital_log.mu);
  EXPECT_EQ(std::count_if(tree.hospital_log.lines.begin(), tree.hospital_log.lines.end(),
                          [](const std::string& l) { return l.find("refused an ack frame") != std::string::npos; }),
            1)
      << "one line a minute, not one per ack";
}

// P6: frames from a sender that is no child of this node, up frames too, are refused in a line
// that names the frame's kind, and every line is one line whatever the sender's IRI holds (a
// newline in it wrote a forged line of its own into the log).
TEST(Link, FramesFromSendersThatAreNoChildAreRefusedInOneLogLineEach) {
  Tree tree;
  tree.hospital = tree.start_hospital();
  Frame up;
  up.kind = FrameKind::up;
  up.from = kHospital + "/stranger";
  up.to = kHospital;
  up.seq = 1;
  up.body = wire::encode_item({.source = up.from, .item = hrv_item(1)});
  tree.bus.inject_raw(kHospital, encode_frame(up));
  Frame hello;
  hello.kind = FrameKind::hello;
  hello.from = "http://x/\n2026-12-02T06:00:00.000Z child <" + kHome1 + "> registered\x1b[2K\xff";
  hello.to = kHospital;
  tree.bus.inject_raw(kHospital, encode_frame(hello));
  EXPECT_TRUE(eventually([&] {
    return tree.hospital_log.has("refused an up frame: <" + kHospital + "/stranger> is not among the children configured");
  })) << tree.hospital_log.text();
  EXPECT_TRUE(eventually([&] { return tree.hospital_log.has("refused a hello frame: <http://x/\\x0a2026-12-02T06:00:00.000Z"); }))
      << tree.hospital_log.text();
  std::lock_guard lock(tree.hospital_log.mu);
  for (const std::string& line : tree.hospital_log.lines) {
    EXPECT_EQ(line.find('\n'), std::string::npos) << line;
    EXPECT_EQ(line.find('\x1b'), std::string::npos) << line;
    EXPECT_EQ(line.find('\xff'), std::string::npos) << line;
  }
  EXPECT_EQ(count(tree.hospital_dir, {.p = Term::iri(kEx + "n")}), 0u);
}

// A node of an earlier protocol version (2 or 3) as the link sees it: what it sends is in that
// version (answers in its layout), and what reaches it is checked to be in that version, with
// no item spans before version 3, which it would refuse else (P3, P4).
class OlderVersion : public Transport {
 public:
  OlderVersion(std::unique_ptr<Transport> inner, std::uint16_t version) : inner_(std::move(inner)), version_(version) {}
  const std::string& self() const override { return inner_->self(); }
  Result<void> send(const Frame& frame) override {
    Frame old = frame;
    old.version = version_;
    if (old.kind == FrameKind::answer) old.body = wire::encode_answer(wire::decode_answer(frame.body).value(), version_);
    if ((old.kind == FrameKind::hello || old.kind == FrameKind::heartbeat) && version_ < 5) {  // no store room before 5
      auto state = wire::decode_state(frame.body).value();
      state.room.reset();
      old.body = wire::encode_state(state);
    }
    return inner_->send(old);
  }
  Result<std::optional<Frame>> receive(std::chrono::milliseconds timeout) override {
    auto got = inner_->receive(timeout);
    if (got && *got) {
      const Frame& f = **got;
      std::lock_guard lock(mu_);
      if (f.version != version_) refused_.push_back("version " + std::to_string(f.version));
      if (f.kind == FrameKind::up || f.kind == FrameKind::down)
        if (auto item = wire::decode_item(f.body); !item || (version_ < 3 && item->item.span != 0))
          refused_.push_back("an item with a span");
      if (f.kind == FrameKind::query && !wire::decode_query(f.body, version_)) refused_.push_back("a query not in its layout");
      if (f.kind == FrameKind::welcome && !f.body.empty() && !wire::decode_state(f.body, version_))
        refused_.push_back("a welcome not in its layout");
      if (f.kind == FrameKind::down)
        if (auto item = wire::decode_item(f.body)) spans_.push_back(item->item.span);
    }
    return got;
  }
  // The spans of the items that came down, in order.
  std::vector<std::int64_t> spans() const {
    std::lock_guard lock(mu_);
    return spans_;
  }
  std::vector<std::string> refused() const {
    std::lock_guard lock(mu_);
    return refused_;
  }

 private:
  std::unique_ptr<Transport> inner_;
  std::uint16_t version_;
  mutable std::mutex mu_;
  std::vector<std::string> refused_;
  std::vector<std::int64_t> spans_;
};

// home1's kEx:samples records as the hospital's remote query returns them (P13), and as home1's
// own store holds them.
struct SamplesAnswer {
  node::Result<std::uint64_t> answered;
  std::vector<node::Record> got, expected;
};
SamplesAnswer ask_home1_for_samples(const Tree& tree, std::chrono::seconds timeout) {
  auto hospital = node::Node::open(tree.hospital_dir).value();
  const node::Pattern samples{.p = Term::iri(kEx + "samples")};
  SamplesAnswer a{0, {}, {}};
  a.answered = remote_query(hospital, {.target = kHome1, .pattern = samples}, timeout,
                            [&](const node::Record& r) { a.got.push_back(r); });
  a.expected = node::Node::open(tree.home1_dir).value().snapshot().value().list(samples).value();
  return a;
}

// P3, P4: made-up senders of an older version (a flood on the LAN) were each logged as a child
// speaking that version, 4,096 lines in a second; refused on P4's budget, only the first 8 are.
TEST(Link, OlderVersionsOfSendersThatAreNoChildrenAreLoggedForTheFirstFewOnly) {
  Tree tree;
  ASSERT_TRUE(tree.start_hospital_and_home1());
  for (int k = 0; k < 40; ++k) {
    Frame hello;
    hello.version = 2;
    hello.kind = FrameKind::hello;
    hello.from = "http://evil.example/x" + std::to_string(k);
    hello.to = kHospital;
    hello.body = wire::encode_state({"v", 0});
    tree.bus.inject_raw(kHospital, encode_frame(hello));
  }
  ASSERT_TRUE(home1_sends(tree, 0, 3, 3));
  EXPECT_TRUE(eventually([&] { return tree.hospital_log.has("further senders of older versions that are not configured children are not logged"); }))
      << tree.hospital_log.text();
  EXPECT_EQ(tree.hospital_log.lines_with("speaks protocol version 2"), 8u) << tree.hospital_log.text();
}

// A hospital upgraded before its homes (docs/deploy.md, "Upgrading"): a home of the version
// before is registered, its items go up, configuration goes down to it in its version (without
// the span it would refuse) and its answers are read in its layout.
TEST(Link, AParentSpeaksToAChildOfTheVersionBeforeInThatVersion) {
  Tree tree;
  tree.hospital = tree.start_hospital();
  auto old_home = std::make_shared<OlderVersion>(tree.bus.open(kHome1, tree.home1_log.sink()), 2);
  tree.home1 = Link::start({.dir = tree.home1_dir, .parent_iri = kHospital, .up = old_home, .resend_after = 100ms,
                            .heartbeat_every = 200ms, .log = tree.home1_log.sink()})
                   .value();
  ASSERT_TRUE(eventually([&] { return tree.home1->connected(); })) << tree.hospital_log.text();
  EXPECT_TRUE(tree.hospital_log.has("speaks protocol version 2")) << tree.hospital_log.text();
  store_hrv_items(tree.home1_dir, 0, 3);
  EXPECT_TRUE(eventually([&] { return count(tree.hospital_dir, {.p = Term::iri(kEx + "n")}) == 3; }));

  node::Item config;
  config.context = kHome1 + "/hrv";
  config.asserted_at = 1'000'000;
  config.span = 60'000'000'000;
  config.add(Term::iri(kHome1 + "/hrv"), Term::iri(kEx + "windowS"), Term::integer(60));
  ASSERT_TRUE(node::Node::open(tree.hospital_dir).value().agent("operator").value().store(config));
  ASSERT_TRUE(eventually([&] { return count(tree.home1_dir, {.p = Term::iri(kEx + "windowS")}) == 1; }));
  const auto arrived = node::Node::open(tree.home1_dir).value().snapshot().value().list({.p = Term::iri(kEx + "windowS")}).value();
  EXPECT_EQ(arrived.front().meta.asserted_at, 1'000'000);
  EXPECT_EQ(arrived.front().meta.span, 0) << "version 2 has no spans";

  auto sensor = node::Node::open(tree.home1_dir).value().agent("ecg").value();
  for (int i = 0; i < 3; ++i)
    ASSERT_TRUE(sensor.store(node::Item{}.add(Term::iri(kHome1 + "/rec/chunk/" + std::to_string(i)),
                                              Term::iri(kEx + "samples"), Term::literal("s" + std::to_string(i)))));
  const SamplesAnswer a = ask_home1_for_samples(tree, 10s);
  ASSERT_TRUE(a.answered) << a.answered.error().message;
  ASSERT_EQ(a.got.size(), a.expected.size());
  for (std::size_t i = 0; i < a.got.size(); ++i) {
    EXPECT_EQ(a.got[i].triple, a.expected[i].triple);
    EXPECT_EQ(a.got[i].meta.asserted_at, a.expected[i].meta.asserted_at);
  }
  // The hospital's link restarts: the home's next items come before its hello, and what it is
  // told then ("unregistered") is in its version too, so it says hello again.
  tree.hospital.reset();
  store_hrv_items(tree.home1_dir, 3, 3);
  tree.hospital = tree.start_hospital();
  EXPECT_TRUE(eventually([&] { return count(tree.hospital_dir, {.p = Term::iri(kEx + "n")}) == 6; }, 15s))
      << tree.hospital_log.text();
  EXPECT_EQ(old_home->refused(), std::vector<std::string>{}) << "frames the old home would have refused";
}

// A child of version 3 has item spans (P3): its settings came down without theirs. And 4,200
// hellos of version 3 from made-up children filled the table of older children, so that the
// real one, heard after them, was spoken to in version 4, which it cannot hear; each made-up
// sender was one more line in the log.
TEST(Link, AChildOfVersionThreeGetsSpansAndIsHeardInItsVersionAfterAFloodOfMadeUpOlderSenders) {
  Tree tree;
  tree.hospital = tree.start_hospital();
  auto injector = tree.bus.open(kHospital + "/injector");
  for (int i = 0; i < 4200; ++i) {
    Frame hello;
    hello.version = 3;
    hello.kind = FrameKind::hello;
    hello.from = kHospital + "/made" + std::to_string(i);
    hello.to = kHospital;
    hello.body = wire::encode_state({"tahvel 0.0.3", 0, "", ""});
    ASSERT_TRUE(injector->send(hello));
  }
  ASSERT_TRUE(eventually([&] { return tree.hospital->counters().refused >= 4200; }, 20s));
  // One line per made-up sender filled the log: at most 10 refusal lines per 10 s are said.
  {
    std::lock_guard lock(tree.hospital_log.mu);
    const auto& lines = tree.hospital_log.lines;
    EXPECT_LE(std::count_if(lines.begin(), lines.end(), [](const std::string& l) { return l.starts_with("refused a hello"); }), 20)
        << lines.size() << " lines";
  }
  auto old_home = std::make_shared<OlderVersion>(tree.bus.open(kHome1, tree.home1_log.sink()), 3);
  tree.home1 = Link::start({.dir = tree.home1_dir, .parent_iri = kHospital, .up = old_home, .resend_after = 100ms,
                            .heartbeat_every = 200ms, .log = tree.home1_log.sink()})
                   .value();
  ASSERT_TRUE(eventually([&] { return tree.home1->connected(); })) << tree.home1_log.text();
  EXPECT_TRUE(tree.hospital_log.has("<" + kHome1 + "> speaks protocol version 3")) << tree.hospital_log.text();
  node::Item config;
  config.context = kHome1 + "/hrv";
  config.span = 60'000'000'000;
  config.add(Term::iri(kHome1 + "/hrv"), Term::iri(kEx + "windowS"), Term::integer(60));
  ASSERT_TRUE(node::Node::open(tree.hospital_dir).value().agent("operator").value().store(config));
  ASSERT_TRUE(eventually([&] { return count(tree.home1_dir, {.p = Term::iri(kEx + "windowS")}) == 1; }));
  const auto arrived = node::Node::open(tree.home1_dir).value().snapshot().value().list({.p = Term::iri(kEx + "windowS")}).value();
  EXPECT_EQ(arrived.front().meta.span, 60'000'000'000) << "version 3 has spans";
  EXPECT_EQ(old_home->refused(), std::vector<std::string>{}) << "frames the version-3 home would have refused";
}

// Two patients' recordings on one sensor node, written by two agents: a query two hops down by
// subject (--under a recording) or by writer (--source) returns exactly what the sensor's own
// store holds for that pattern (P13, protocol version 4).
TEST(Link, AQueryBySubjectOrBySourceTwoHopsDownReturnsExactlyWhatTheTargetHoldsUnderThem) {
  Tree tree;
  const std::string sensor_iri = kHome1 + "/ecg1";
  const std::string sensor_dir = (tree.tmp / "ecg1").string();
  auto sensor_link = tree.start_three_tiers(sensor_dir);
  auto sensor = node::Node::open(sensor_dir).value();
  const Term samples = Term::iri(kEx + "samples");
  for (const std::string writer : {"bed1", "bed2"}) {
    auto agent = sensor.agent(writer).value();
    // bed2's recording 1000 starts with the characters of bed1's 100, and is not under it.
    for (const std::string rec : {writer == "bed1" ? "100" : "1000", writer == "bed1" ? "101" : "102"})
      for (int second = 0; second < 4; ++second)
        ASSERT_TRUE(agent.store(node::Item{}.add(Term::iri(agent.iri() + "/recording/" + rec + "/chunk/" + std::to_string(second)),
                                                 samples, Term::literal(writer + rec + "s" + std::to_string(second)))));
  }
  auto hospital = node::Node::open(tree.hospital_dir).value();
  ASSERT_TRUE(eventually([&] { return state_says_up(tree.hospital_dir, kHome1); }));
  auto asked_and_held = [&](const node::Pattern& pattern) {
    std::vector<std::string> got, held;
    auto answered = remote_query(hospital, {.target = sensor_iri, .pattern = pattern}, 10s,
                                 [&](const node::Record& r) { got.push_back(r.triple.o.value); });
    EXPECT_TRUE(answered) << answered.error().message;
    const std::vector<node::Record> records = sensor.snapshot().value().list(pattern).value();
    for (const auto& r : records) held.push_back(r.triple.o.value);
    EXPECT_EQ(got, held);
    return got;
  };
  EXPECT_EQ(asked_and_held({.p = samples, .under = sensor_iri + "/bed1/recording/100"}),
            (std::vector<std::string>{"bed1100s0", "bed1100s1", "bed1100s2", "bed1100s3"}));
  EXPECT_EQ(asked_and_held({.under = sensor_iri + "/bed2/recording/102/chunk/3"}), std::vector<std::string>{"bed2102s3"});
  EXPECT_EQ(asked_and_held({.p = samples, .source = sensor_iri + "/bed2"}).size(), 8u);
  EXPECT_EQ(asked_and_held({.source = sensor_iri + "/bed1", .under = sensor_iri + "/bed2"}).size(), 0u);
  // Not IRIs, or what a query frame cannot carry: said before anything is asked.
  auto bad = remote_query(hospital, {.target = sensor_iri, .pattern = {.under = "not an iri"}}, 10s, [](const node::Record&) {});
  ASSERT_FALSE(bad);
  EXPECT_EQ(bad.error().code, Errc::invalid_iri) << bad.error().message;
  auto by_context = remote_query(hospital, {.target = sensor_iri, .pattern = {.context = kHome1}}, 10s, [](const node::Record&) {});
  ASSERT_FALSE(by_context);
  EXPECT_EQ(by_context.error().code, Errc::invalid_argument) << by_context.error().message;
}

// P3: a child of a version before 4 would pass a query on without its source and subject, and
// the asker would take the whole node's records for the ones asked. The node above that child
// refuses such a query, naming the child and its version: as the origin (home1 asking its own
// sensor) and on the way (the hospital asking through home1). Without them the query is answered
// in the child's layout.
TEST(Link, AQueryBySubjectOrSourceIsRefusedNamingTheChildOfAnEarlierVersionOnTheWay) {
  Tree tree;
  const std::string sensor_iri = kHome1 + "/ecg1";
  const std::string sensor_dir = (tree.tmp / "ecg1").string();
  ASSERT_TRUE(node::Node::init(sensor_dir, {.iri = sensor_iri}));
  tree.hospital = tree.start_hospital();
  std::shared_ptr<Transport> gateway(tree.bus.open(kHome1, tree.home1_log.sink()));
  tree.home1 = Link::start({.dir = tree.home1_dir, .parent_iri = kHospital, .up = gateway, .down = gateway,
                            .resend_after = 100ms, .heartbeat_every = 200ms, .log = tree.home1_log.sink()})
                   .value();
  auto old_sensor = std::make_shared<OlderVersion>(tree.bus.open(sensor_iri, tree.home2_log.sink()), 2);
  auto sensor_link = Link::start({.dir = sensor_dir, .parent_iri = kHome1, .up = old_sensor, .resend_after = 100ms,
                                  .heartbeat_every = 200ms, .log = tree.home2_log.sink()})
                         .value();
  ASSERT_TRUE(eventually([&] { return tree.home1->connected() && sensor_link->connected(); }));
  ASSERT_TRUE(eventually([&] { return state_says_up(tree.hospital_dir, kHome1) && state_says_up(tree.home1_dir, sensor_iri); }));
  ASSERT_TRUE(node::Node::open(sensor_dir).value().agent("ecg").value().store(raw_item(1)));
  const node::Pattern by_subject{.under = kHome1 + "/rec"};
  for (const std::string& asker : {tree.home1_dir, tree.hospital_dir}) {
    auto origin = node::Node::open(asker).value();
    auto refused = remote_query(origin, {.target = sensor_iri, .pattern = by_subject}, 10s, [](const node::Record&) {});
    ASSERT_FALSE(refused) << asker;
    EXPECT_EQ(refused.error().message,
              "query_failed: <" + sensor_iri +
                  "> speaks protocol version 2, which has no query by source or by subject (--source, --under): "
                  "upgrade it, or ask without them")
        << asker;
    std::size_t got = 0;
    auto answered = remote_query(origin, {.target = sensor_iri, .pattern = {.p = Term::iri(kEx + "samples")}}, 10s,
                                 [&](const node::Record&) { ++got; });
    ASSERT_TRUE(answered) << asker << ": " << answered.error().message;
    EXPECT_EQ(got, 1u) << asker;
  }
  EXPECT_EQ(old_sensor->refused(), std::vector<std::string>{}) << "frames the old sensor would have refused";
}

TEST(Link, RemoteQueryReturnsExactlyTheRecordsHeldBelowAndNamesItsErrors) {
  Tree tree;
  tree.hospital = tree.start_hospital();
  tree.home1 = tree.start_home(tree.home1_dir, kHome1, tree.home1_log);
  ASSERT_TRUE(eventually([&] { return tree.home1->connected(); }));
  auto hospital = node::Node::open(tree.hospital_dir).value();
  ASSERT_TRUE(eventually([&] { return state_says_up(tree.hospital_dir, kHome1); }));
  auto sensor = node::Node::open(tree.home1_dir).value().agent("ecg").value();
  // Enough raw data for several answer chunks.
  std::string big(20000, 'x');
  for (int i = 0; i < 20; ++i) {
    node::Item item;
    item.add(Term::iri(kHome1 + "/rec/chunk/" + std::to_string(i)), Term::iri(kEx + "samples"),
             Term::literal(big + std::to_string(i)));
    ASSERT_TRUE(sensor.store(item));
  }
  auto [n, got, expected] = ask_home1_for_samples(tree, 10s);
  ASSERT_TRUE(n) << n.error().message;
  ASSERT_EQ(got.size(), expected.size());
  for (std::size_t i = 0; i < got.size(); ++i) {
    EXPECT_EQ(got[i].triple.o.value, expected[i].triple.o.value);
    EXPECT_EQ(got[i].meta.id, expected[i].meta.id);
    EXPECT_EQ(got[i].meta.source, kHome1 + "/ecg");
  }
  // Nothing of the raw data was stored at the hospital by asking.
  EXPECT_EQ(count(tree.hospital_dir, {.p = Term::iri(kEx + "samples")}), 0u);
  // The node's IRI as a browser writes it, with a trailing slash, is the node.
  std::size_t with_slash = 0;
  auto slashed = remote_query(hospital, {.target = kHome1 + "/", .pattern = {.p = Term::iri(kEx + "samples")}}, 10s,
                              [&](const node::Record&) { ++with_slash; });
  ASSERT_TRUE(slashed) << slashed.error().message;
  EXPECT_EQ(with_slash, expected.size());

  auto unknown = remote_query(hospital, {.target = kHospital + "/home9"}, 2s, [](const node::Record&) {});
  ASSERT_FALSE(unknown);
  EXPECT_EQ(unknown.error().code, Errc::not_found);
  // A doubled slash is no child (it was said to be "no child <…/hospital/>").
  auto doubled = remote_query(hospital, {.target = kHospital + "//home1"}, 2s, [](const node::Record&) {});
  ASSERT_FALSE(doubled);
  EXPECT_EQ(doubled.error().code, Errc::not_found);
  EXPECT_EQ(doubled.error().message, "unknown node <" + kHospital + "//home1>: an empty segment follows <" + kHospital +
                                         "> (a node's IRI is its parent's, '/' and its id)");
  auto unreachable = remote_query(hospital, {.target = kHome2}, 2s, [](const node::Record&) {});
  ASSERT_FALSE(unreachable);
  EXPECT_EQ(unreachable.error().code, Errc::io);
  EXPECT_NE(unreachable.error().message.find("unreachable"), std::string::npos);
  auto below_home = remote_query(hospital, {.target = kHome1 + "/ecg9"}, 5s, [](const node::Record&) {});
  ASSERT_FALSE(below_home);
  EXPECT_EQ(below_home.error().code, Errc::not_found) << below_home.error().message;
  // The hop that does not know the node says which children it has (here none).
  // Worded as the first hop words it (up to session 86 "unknown node: no node <…> below <…>").
  EXPECT_EQ(below_home.error().message,
            "unknown node <" + kHome1 + "/ecg9>: <" + kHome1 + "> has no child <" + kHome1 + "/ecg9>; it has no child node");
}

// A cascade answer is read whole at the target and sent a window of chunks at a time: the
// record that did not fit in a full window must go in the next one, not be lost (it was sent
// emptied, and N-Triples output dropped it).
TEST(Link, ACascadeAnswerLargerThanTheChunkWindowReturnsEveryRecord) {
  Tree tree;
  ASSERT_TRUE(tree.start_hospital_and_home1());
  auto sensor = node::Node::open(tree.home1_dir).value().agent("ecg").value();
  const std::string big(20000, 'x');
  for (int i = 0; i < 80; ++i) {  // 1.6 MB: more than 16 chunks in flight
    node::Item item;
    item.add(Term::iri(kHome1 + "/rec/chunk/" + std::to_string(i)), Term::iri(kEx + "samples"), Term::literal(big + std::to_string(i)));
    ASSERT_TRUE(sensor.store(item));
  }
  const node::Pattern samples{.p = Term::iri(kEx + "samples")};
  auto hospital = node::Node::open(tree.hospital_dir).value();
  std::vector<node::Record> got;
  auto n = remote_query(hospital, {.target = kHome1, .pattern = samples, .cascade = 1}, 30s,
                        [&](const node::Record& r) { got.push_back(r); });
  ASSERT_TRUE(n) << n.error().message;
  const auto expected = node::Node::open(tree.home1_dir).value().snapshot().value().list(samples, {.cascade = 1}).value();
  ASSERT_EQ(got.size(), expected.size());
  for (std::size_t i = 0; i < got.size(); ++i) {
    EXPECT_EQ(got[i].meta.id, expected[i].meta.id);
    EXPECT_EQ(got[i].triple.s.value, expected[i].triple.s.value);
    EXPECT_EQ(got[i].triple.o.value, expected[i].triple.o.value);
  }
}

// The answer crosses the asking node's board (P14), whose literal limit the target's largest
// record may come close to: a record as large as the target allows must still come back whole.
TEST(Link, ARemoteQueryReturnsARecordAsLargeAsTheTargetAllows) {
  Tree tree;
  ASSERT_TRUE(tree.start_hospital_and_home1());
  const std::size_t largest = node::InitOptions{}.max_literal_bytes;
  node::Item item;
  item.add(Term::iri(kHome1 + "/rec/chunk/0"), Term::iri(kEx + "samples"), Term::literal(std::string(largest, 'x')));
  ASSERT_TRUE(node::Node::open(tree.home1_dir).value().agent("ecg").value().store(item));
  auto [n, got, expected] = ask_home1_for_samples(tree, 20s);
  ASSERT_TRUE(n) << n.error().message;
  ASSERT_EQ(got.size(), 1u);
  EXPECT_EQ(got[0].triple.o.value.size(), largest);
}

// P9b: a parent whose store is full could not store what a child sent; the child resent its
// whole window every resend_after for as long as that lasted (660,000 frames in 225 s in a
// probe), the parent logged a line for each, and the child's own state said "up". The child
// now probes with one frame at a time, its state says why, and once the parent has room again
// everything arrives once.
TEST(Link, AChildWhoseParentCannotStoreSendsOneFrameAtATimeAndSaysWhy) {
  Tree tree({.max_map_bytes = 1 << 20});
  ASSERT_TRUE(tree.start_hospital_and_home1());
  fill_to_the_last_page(tree.hospital_dir, kHospital);
  store_hrv_items(tree.home1_dir, 0, 40);
  const std::string why = "the parent cannot store what this node sends: store full";
  auto refusal = [&] {
    auto records = node::Node::open(tree.home1_dir).value().snapshot().value().list(
        {.s = Term::iri(kHome1), .p = Term::iri(vocab::kUplinkRefusal)}).value();
    return records.empty() ? std::string() : records.front().triple.o.value;
  };
  ASSERT_TRUE(eventually([&] { return refusal().rfind(why, 0) == 0; })) << refusal() << tree.hospital_log.text() << tree.home1_log.text();
  const std::uint64_t sent_before = tree.home1->counters().up_sent;
  std::this_thread::sleep_for(1s);  // ten resend intervals
  EXPECT_LE(tree.home1->counters().up_sent - sent_before, 15u) << "frames sent in a second to a parent that cannot store them";
  EXPECT_EQ(outbox(tree.home1_dir), 40u);
  {
    std::lock_guard lock(tree.hospital_log.mu);
    const auto said = std::count_if(tree.hospital_log.lines.begin(), tree.hospital_log.lines.end(), [](const std::string& l) {
      return l.find("relay from <" + kHome1 + "> refused: store full") != std::string::npos;
    });
    EXPECT_EQ(said, 1) << "the parent's log said the same failure again and again";
  }
  ASSERT_TRUE(node::Node::open(tree.hospital_dir).value().remove({.p = Term::iri(kEx + "fill")}));
  EXPECT_TRUE(eventually([&] { return count(tree.hospital_dir, {.p = Term::iri(kEx + "n")}) == 40 && outbox(tree.home1_dir) == 0; }));
  EXPECT_TRUE(eventually([&] { return refusal().empty(); })) << refusal();
  EXPECT_TRUE(tree.home1_log.has("stores what this node sends again")) << tree.home1_log.text();
}

// A parent store nearly full takes an item now and then between refusals (a probe's hospital:
// 3,386 items in 86 s). Each turn was said at both ends, two or three lines a second: the parent's
// "refused: store full", the child's "cannot store" and "stores again". Each is said once in 10 s.
TEST(Link, AParentThatStoresNowAndThenBetweenRefusalsIsNotSaidAtEachTurn) {
  Tree tree({.max_map_bytes = 1 << 20});
  ASSERT_TRUE(tree.start_hospital_and_home1());
  fill_to_the_last_page(tree.hospital_dir, kHospital);
  int sent = 400;
  store_hrv_items(tree.home1_dir, 0, sent);
  ASSERT_TRUE(eventually([&] { return tree.hospital->counters().refused > 0; })) << tree.hospital_log.text();
  const auto first_refused = std::chrono::steady_clock::now();
  const auto stored = [&] { return count(tree.hospital_dir, {.p = Term::iri(kEx + "n")}); };
  int turns = 0;
  for (int f = 0; f < 300 && turns < 3; f += 30) {
    const std::uint64_t before = stored(), refused = tree.hospital->counters().refused;
    auto hospital = node::Node::open(tree.hospital_dir).value();
    for (int k = f; k < f + 30; ++k) ASSERT_TRUE(hospital.remove({.s = Term::iri(kHospital + "/f" + std::to_string(k))}));
    if (!eventually([&] { return stored() > before; }, 3s)) continue;  // the room freed took no item
    // The next refusal; a room that took every item the home had is given more to refuse.
    ASSERT_TRUE(eventually([&] {
      if (tree.hospital->counters().refused > refused) return true;
      if (stored() == static_cast<std::uint64_t>(sent)) store_hrv_items(tree.home1_dir, std::exchange(sent, sent + 100), 100);
      return false;
    })) << stored() << " of " << sent << " items stored; outbox " << outbox(tree.home1_dir) << "\n" << tree.hospital_log.text() << tree.home1_log.text();
    ++turns;
  }
  ASSERT_EQ(turns, 3) << "the case under test did not happen: " << stored() << " items stored";
  auto lines_with = [](Log& log, const std::string& text) {
    std::lock_guard lock(log.mu);
    return std::count_if(log.lines.begin(), log.lines.end(), [&](const std::string& l) { return l.find(text) != std::string::npos; });
  };
  // Once per 10 s (a slow machine may take longer than that over the three turns).
  const long allowed = 1 + std::chrono::duration_cast<std::chrono::seconds>(std::chrono::steady_clock::now() - first_refused).count() / 10;
  EXPECT_LE(lines_with(tree.hospital_log, "relay from <" + kHome1 + "> refused: store full"), allowed) << tree.hospital_log.text();
  EXPECT_LE(lines_with(tree.home1_log, "cannot store what this node sends: store full"), allowed) << tree.home1_log.text();
  EXPECT_LE(lines_with(tree.home1_log, "stores what this node sends again"), allowed) << tree.home1_log.text();
}

// A parent whose full store had room freed takes what fits of the child's window at once, then
// refuses the rest: it refused the whole window, and took one item per probe after each refusal
// (the probes come every resend_after). Once it has room for all, every item is there once.
TEST(Link, AParentWithRoomForPartOfAWindowStoresWhatFitsAndLosesNothing) {
  Tree tree({.max_map_bytes = 1 << 20});
  ASSERT_TRUE(tree.start_hospital_and_home1());
  fill_to_the_last_page(tree.hospital_dir, kHospital);
  store_hrv_items(tree.home1_dir, 0, 400);
  ASSERT_TRUE(eventually([&] { return tree.hospital->counters().refused > 0; })) << tree.hospital_log.text();
  const auto stored = [&] { return count(tree.hospital_dir, {.p = Term::iri(kEx + "n")}); };
  const std::uint64_t before = stored(), refused = tree.hospital->counters().refused;
  auto hospital = node::Node::open(tree.hospital_dir).value();
  for (int k = 0; k < 120; ++k) ASSERT_TRUE(hospital.remove({.s = Term::iri(kHospital + "/f" + std::to_string(k))}));
  // 120 fill records of 2 KB make room for about a hundred of these items beyond the 64 KiB a
  // 1 MiB store leaves its own writers (items from below stop short of it) and the reserve kept
  // for removals: the first 50 come in a few runs, each ended by a refusal of the rest (one
  // refusal per item stored before).
  ASSERT_TRUE(eventually([&] { return stored() >= before + 50; })) << stored() << tree.hospital_log.text();
  const std::uint64_t refusals = tree.hospital->counters().refused - refused, taken = stored() - before;
  EXPECT_LT(refusals, taken / 3) << refusals << " refusals while " << taken << " items were stored";
  ASSERT_TRUE(hospital.remove({.p = Term::iri(kEx + "fill")}));
  ASSERT_TRUE(eventually([&] { return stored() == 400 && outbox(tree.home1_dir) == 0; }))
      << stored() << " stored, outbox " << outbox(tree.home1_dir) << tree.hospital_log.text();
  std::this_thread::sleep_for(300ms);
  std::set<std::int64_t> numbers;
  const auto records = hospital.snapshot().value().list({.p = Term::iri(kEx + "n")}).value();
  for (const auto& r : records)
    EXPECT_TRUE(numbers.insert(std::stoll(r.triple.o.value)).second) << "item " << r.triple.o.value << " was stored twice";
  EXPECT_EQ(numbers.size(), 400u);
  EXPECT_EQ(numbers.empty() ? -1 : *numbers.begin(), 0);
  EXPECT_EQ(numbers.empty() ? -1 : *numbers.rbegin(), 399);
}

// P9b downwards: a parent logs a child that cannot store what it sends down once per reason; it
// remembered the reason for ever, so when the child's store filled a second time, after it had
// stored again, the parent's log said nothing of it. Episodes are said once per 10 s at most
// (a child hovering at full would be a pair of lines per cycle): the second comes after that.
TEST(Link, AParentLogsEachEpisodeOfAChildThatCannotStoreWhatItSendsDown) {
  Tree tree({}, {.max_map_bytes = 1 << 20});
  ASSERT_TRUE(tree.start_hospital_and_home1());
  auto operator_ = node::Node::open(tree.hospital_dir).value().agent("operator").value();
  auto configure = [&](const std::string& value) {
    node::Item config;
    config.context = kHome1 + "/hrv";
    config.add(Term::iri(kHome1 + "/hrv"), Term::iri(kEx + "label"), Term::literal(value));
    return static_cast<bool>(operator_.store(config));
  };
  auto episodes = [&] {
    std::lock_guard lock(tree.hospital_log.mu);
    return std::count_if(tree.hospital_log.lines.begin(), tree.hospital_log.lines.end(), [](const std::string& l) {
      return l.find("child <" + kHome1 + "> cannot store what this node sends down") != std::string::npos;
    });
  };
  auto home1_labels = [&] { return count(tree.home1_dir, {.p = Term::iri(kEx + "label")}); };
  for (int episode = 1; episode <= 2; ++episode) {
    fill_to_the_last_page(tree.home1_dir, kHome1);
    ASSERT_TRUE(configure("first of episode " + std::to_string(episode)));
    ASSERT_TRUE(eventually([&] { return episodes() == episode; })) << tree.hospital_log.text();
    ASSERT_TRUE(node::Node::open(tree.home1_dir).value().remove({.p = Term::iri(kEx + "fill")}));
    ASSERT_TRUE(eventually([&] { return home1_labels() == static_cast<std::uint64_t>(episode); }))
        << home1_labels() << tree.home1_log.text();
    EXPECT_TRUE(eventually([&] { return tree.hospital_log.has("child <" + kHome1 + "> stores what this node sends down again"); }))
        << tree.hospital_log.text();
    if (episode == 1) std::this_thread::sleep_for(10s);
  }
}

// P12: a child says how full its store is in its hellos and heartbeats (version 5), and its
// state at the parent follows it as the store fills, and is kept by a new run of the parent's
// link while the child is away: a home whose store refused its agents' writes looked well from
// the hospital.
TEST(Link, AChildsStateAtTheParentSaysHowFullItsStoreIsAndFollowsItAsItFills) {
  Tree tree({}, {.max_map_bytes = 1 << 20});
  ASSERT_TRUE(tree.start_hospital_and_home1());
  auto said = [&](const std::string& predicate) -> std::optional<std::uint64_t> {
    auto records = node::Node::open(tree.hospital_dir).value().snapshot().value().list({.s = Term::iri(kHome1), .p = Term::iri(predicate)}).value();
    if (records.size() != 1) return std::nullopt;
    return std::stoull(records[0].triple.o.value);
  };
  ASSERT_TRUE(eventually([&] { return said(vocab::kStoreMaxBytes) == (1u << 20); })) << tree.hospital_log.text();
  ASSERT_TRUE(said(vocab::kStoreUsedBytes) && said(vocab::kStoreDataBytes) && said(vocab::kDiskFreeBytes));
  EXPECT_LT(*said(vocab::kStoreUsedBytes), (1u << 20) * 9 / 10) << "a new store is far from full";
  EXPECT_LE(*said(vocab::kStoreDataBytes), *said(vocab::kStoreUsedBytes));
  EXPECT_GT(*said(vocab::kDiskFreeBytes), 0u);
  fill_to_the_last_page(tree.home1_dir, kHome1);
  const auto stats = node::Node::open(tree.home1_dir).value().stats().value();
  // Within a refresh of the child's state (2 s) and a heartbeat.
  EXPECT_TRUE(eventually([&] { return said(vocab::kStoreUsedBytes) >= stats.high_water_bytes; }, 10s))
      << said(vocab::kStoreUsedBytes).value_or(0) << " of " << stats.high_water_bytes;
  ASSERT_TRUE(said(vocab::kStoreDataBytes));
  EXPECT_GE(*said(vocab::kStoreDataBytes) * 2, stats.max_map_bytes);
  // Away, and the parent's link started again: it keeps what the child last said.
  tree.home1.reset();
  ASSERT_TRUE(eventually([&] { return !state_says_up(tree.hospital_dir, kHome1); }));
  const auto used = said(vocab::kStoreUsedBytes);
  auto state_item = [&] {
    auto records = node::Node::open(tree.hospital_dir).value().snapshot().value().list({.s = Term::iri(kHome1), .p = Term::iri(vocab::kLinkState)}).value();
    return records.empty() ? 0 : records[0].meta.item;
  };
  const std::uint64_t item_before = state_item();
  tree.hospital.reset();
  tree.hospital = tree.start_hospital();
  ASSERT_TRUE(eventually([&] { return state_item() != item_before && state_item() != 0; })) << "the new run wrote no state of home1";
  EXPECT_EQ(said(vocab::kStoreUsedBytes), used);
  EXPECT_EQ(said(vocab::kStoreMaxBytes), 1u << 20);
  // A child of version 4 says none: its state has no figures, and its items go up as before.
  auto old_home = std::make_shared<OlderVersion>(tree.bus.open(kHome2, tree.home2_log.sink()), 4);
  tree.home2 = Link::start({.dir = tree.home2_dir, .parent_iri = kHospital, .up = old_home, .resend_after = 100ms,
                            .heartbeat_every = 200ms, .log = tree.home2_log.sink()})
                   .value();
  ASSERT_TRUE(eventually([&] { return state_says_up(tree.hospital_dir, kHome2); })) << tree.hospital_log.text();
  EXPECT_TRUE(tree.hospital_log.has("<" + kHome2 + "> speaks protocol version 4")) << tree.hospital_log.text();
  store_hrv_items(tree.home2_dir, 0, 2);
  EXPECT_TRUE(eventually([&] { return count(tree.hospital_dir, {.p = Term::iri(kEx + "n")}) == 2; }));
  std::this_thread::sleep_for(2500ms);  // a refresh of its state
  EXPECT_EQ(count(tree.hospital_dir, {.s = Term::iri(kHome2), .p = Term::iri(vocab::kStoreMaxBytes)}), 0u);
  EXPECT_EQ(old_home->refused(), std::vector<std::string>{}) << "frames the version 4 home would have refused";
}

// A chunk the asking node cannot write on its board (here its store is full) ends the query
// with that reason at once, rather than at the asker's timeout with a chunk missing.
TEST(Link, AnAnswerChunkTheAskingBoardCannotHoldEndsTheQueryWithTheReason) {
  Tree tree({.max_map_bytes = 1 << 20});
  ASSERT_TRUE(tree.start_hospital_and_home1());
  node::Item item;
  item.add(Term::iri(kHome1 + "/rec/chunk/0"), Term::iri(kEx + "samples"), Term::literal(std::string(900'000, 'x')));
  ASSERT_TRUE(node::Node::open(tree.home1_dir).value().agent("ecg").value().store(item));
  auto hospital = node::Node::open(tree.hospital_dir).value();
  const auto asked = std::chrono::steady_clock::now();
  auto n = remote_query(hospital, {.target = kHome1, .pattern = {.p = Term::iri(kEx + "samples")}}, 30s,
                        [](const node::Record&) {});
  ASSERT_FALSE(n);
  EXPECT_EQ(n.error().message.rfind("query_failed: answer chunk 1 could not be written on the board of <" + kHospital + ">", 0), 0u)
      << n.error().message;
  EXPECT_LT(std::chrono::steady_clock::now() - asked, 20s) << "the query waited for its timeout";
}

// The same where the asking node's own limit is small: every chunk crosses its board in parts.
TEST(Link, ARemoteQueryAnswersWholeThroughAnAskingBoardWithASmallLiteralLimit) {
  Tree tree({.max_literal_bytes = 1000});
  ASSERT_TRUE(tree.start_hospital_and_home1());
  auto sensor = node::Node::open(tree.home1_dir).value().agent("ecg").value();
  for (int i = 0; i < 30; ++i) {
    node::Item item;
    item.add(Term::iri(kHome1 + "/rec/chunk/" + std::to_string(i)), Term::iri(kEx + "samples"),
             Term::literal(std::string(5000 + i, static_cast<char>('a' + i % 26))));
    ASSERT_TRUE(sensor.store(item));
  }
  auto [n, got, expected] = ask_home1_for_samples(tree, 20s);
  ASSERT_TRUE(n) << n.error().message;
  ASSERT_EQ(got.size(), expected.size());
  for (std::size_t i = 0; i < got.size(); ++i) EXPECT_EQ(got[i].triple.o.value, expected[i].triple.o.value);
}

// `cancelled` is asked before each record is handed over: a caller that stops taking records
// (`tahvel query` at Ctrl-C, its output ended) gets none after, and the count in the error is of
// those handed over. It was asked between chunks only (and, asked at the node itself, never):
// the rest of the chunk was handed over and counted.
TEST(Link, ARemoteQueryCancelledPartWayThroughAChunkHandsOverNoMoreRecords) {
  Tree tree;
  ASSERT_TRUE(tree.start_hospital_and_home1());
  auto sensor = node::Node::open(tree.home1_dir).value().agent("ecg").value();
  for (int i = 0; i < 40; ++i) {
    node::Item item;
    item.add(Term::iri(kHome1 + "/rec/chunk/" + std::to_string(i)), Term::iri(kEx + "samples"), Term::integer(i));
    ASSERT_TRUE(sensor.store(item));
  }
  for (const std::string& dir : {tree.hospital_dir, tree.home1_dir}) {  // through the link, and at the node itself
    auto asking = node::Node::open(dir).value();
    std::size_t handed = 0;
    auto n = remote_query(asking, {.target = kHome1, .pattern = {.p = Term::iri(kEx + "samples")}}, 10s,
                          [&](const node::Record&) { ++handed; }, {}, [&] { return handed >= 10; });
    ASSERT_FALSE(n) << "asked at " << asking.iri();
    EXPECT_EQ(n.error().message, "cancelled after 10 records from <" + kHome1 + ">") << "asked at " << asking.iri();
    EXPECT_EQ(handed, 10u) << "asked at " << asking.iri();
  }
}

// A blank node in the pattern is the node of that label in the target's store, as `tahvel list
// -s _:b1` there means. Written on the asking board as a blank node it was renamed (as every
// item's blank nodes are) and matched nothing.
TEST(Link, ARemoteQueryByABlankNodeMatchesThatNodeInTheTargetsStore) {
  Tree tree;
  ASSERT_TRUE(tree.start_hospital_and_home1());
  auto sensor = node::Node::open(tree.home1_dir).value().agent("ecg").value();
  node::Item item;
  item.add(Term::blank("w"), Term::iri(kEx + "n"), Term::integer(1));
  item.add(Term::blank("w"), Term::iri(kEx + "of"), Term::blank("v"));
  ASSERT_TRUE(sensor.store(item));
  auto at_home = node::Node::open(tree.home1_dir).value().snapshot().value().list({.p = Term::iri(kEx + "of")}).value();
  ASSERT_EQ(at_home.size(), 1u);
  const Term subject = at_home[0].triple.s, object = at_home[0].triple.o;
  ASSERT_TRUE(subject.is_blank());
  auto hospital = node::Node::open(tree.hospital_dir).value();
  std::vector<node::Record> got;
  auto n = remote_query(hospital, {.target = kHome1, .pattern = {.s = subject}}, 10s, [&](const node::Record& r) { got.push_back(r); });
  ASSERT_TRUE(n) << n.error().message;
  EXPECT_EQ(got.size(), 2u);
  got.clear();
  n = remote_query(hospital, {.target = kHome1, .pattern = {.o = object}}, 10s, [&](const node::Record& r) { got.push_back(r); });
  ASSERT_TRUE(n) << n.error().message;
  ASSERT_EQ(got.size(), 1u);
  EXPECT_EQ(got[0].triple.s, subject);
}

// A node whose link is stopped keeps its children's last state ("up") on its board; a query
// asked there used to wait out its whole timeout. Whether a link serves the node's children is
// known at once (the link's lock), and the query is unreachable, naming the node, once the
// restart grace (2 s) is over.
TEST(Link, AQueryAskedWhereNoLinkRunsIsUnreachableWithoutWaitingForItsTimeout) {
  Tree tree;
  ASSERT_TRUE(tree.start_hospital_and_home1());
  auto hospital = node::Node::open(tree.hospital_dir).value();
  auto asked = remote_query(hospital, {.target = kHome1}, 10s, [](const node::Record&) {});
  ASSERT_TRUE(asked) << asked.error().message;
  tree.hospital.reset();
  ASSERT_TRUE(state_says_up(tree.hospital_dir, kHome1));
  const auto before = std::chrono::steady_clock::now();
  asked = remote_query(hospital, {.target = kHome1}, 60s, [](const node::Record&) {});
  ASSERT_FALSE(asked);
  EXPECT_EQ(asked.error().code, Errc::io);
  EXPECT_EQ(asked.error().message.rfind("unreachable: no link runs for <" + kHospital + ">", 0), 0u) << asked.error().message;
  EXPECT_LT(std::chrono::steady_clock::now() - before, 30s) << "waited for the timeout";
}

// Where no link runs, that is why every child cannot be reached, whatever state the link's last
// run left for it: `tahvel status` (no restart grace) said of a child that run had not heard
// from "<…/home2> has never connected to <…/hospital>", and of one it had, "no link runs". A
// child no run has heard of was an unknown node (exit 4), though only a running link can tell.
TEST(Link, WhereNoLinkRunsEveryChildIsUnreachableBecauseNoLinkRunsNotForItsLastState) {
  Tree tree;
  ASSERT_TRUE(tree.start_hospital_and_home1());
  tree.hospital.reset();
  auto hospital = node::Node::open(tree.hospital_dir).value();
  for (const std::string& child : {kHome1, kHome2, kHospital + "/home9"}) {
    auto asked = remote_query(hospital, {.target = child, .restart_grace = {}}, 10s, [](const node::Record&) {});
    ASSERT_FALSE(asked) << child;
    EXPECT_EQ(asked.error().code, Errc::io) << child;
    EXPECT_EQ(asked.error().message.rfind("unreachable: no link runs for <" + kHospital + ">", 0), 0u) << asked.error().message;
  }
}

// A link that its supervisor starts again (within a second) leaves for that while no link
// serving the node and then, in its new run, its children "never connected" until their hello:
// an operator's query asked then waits for it (RemoteQuery::restart_grace) instead of failing.
TEST(Link, AQueryAskedWhileTheOriginsLinkRestartsWaitsForIt) {
  Tree tree;
  ASSERT_TRUE(tree.start_hospital_and_home1());
  auto hospital = node::Node::open(tree.hospital_dir).value();
  tree.hospital.reset();
  std::thread restart([&] {
    std::this_thread::sleep_for(300ms);
    tree.hospital = tree.start_hospital();
  });
  auto asked = remote_query(hospital, {.target = kHome1, .restart_grace = 20s}, 30s, [](const node::Record&) {});
  restart.join();
  EXPECT_TRUE(asked) << asked.error().message;

  // With no grace (`tahvel status`), the same moment is unreachable at once.
  tree.hospital.reset();
  auto at_once = remote_query(hospital, {.target = kHome1, .restart_grace = {}}, 30s, [](const node::Record&) {});
  ASSERT_FALSE(at_once);
  EXPECT_EQ(at_once.error().message.rfind("unreachable: no link runs for <" + kHospital + ">", 0), 0u) << at_once.error().message;
}

// A new run of the origin's link has its children as the run before left them until their hello,
// a heartbeat later: "down" when it stopped saying so. A query asked in that moment failed at
// once, "unreachable: <home1> is down at <hospital>" of a healthy home (a probe killed the
// hospital's link: every query failed so for 1.4 s). It waits for the hello now.
TEST(Link, AQueryAskedBeforeTheChildrenGreetANewRunOfTheOriginsLinkWaitsForThem) {
  Tree tree;
  ASSERT_TRUE(tree.start_hospital_and_home1());
  auto hospital = node::Node::open(tree.hospital_dir).value();
  tree.hospital.reset();
  auto home1_state = [&] {
    auto records = hospital.snapshot().value().list({.s = Term::iri(kHome1), .p = Term::iri(vocab::kLinkState)}).value();
    return records.empty() ? std::string() : records.back().triple.o.value;
  };
  node::Agent link = hospital.agent("link").value();
  ASSERT_TRUE(link.replace({{.s = Term::iri(kHome1), .p = Term::iri(vocab::kLinkState)}},
                           {node::Item{}.add(Term::iri(kHome1), Term::iri(vocab::kLinkState), Term::literal("down"))}));
  ASSERT_EQ(home1_state(), "down");
  tree.hospital = tree.start_hospital();
  auto asked = remote_query(hospital, {.target = kHome1}, 30s, [](const node::Record&) {});
  EXPECT_TRUE(asked) << asked.error().message;
}

// P12c: a child whose link said it was stopping is "down" with tv:linkLeft on the board, and a
// query for it asked by another process says why, as the link says it of a node further down
// (an operator's probe of session 86: `down --node home2` read as a crash), until it is back.
TEST(Link, AQueryForAChildWhoseLinkSaidItLeftSaysSo) {
  Tree tree;
  ASSERT_TRUE(tree.start_hospital_and_home1());
  auto hospital = node::Node::open(tree.hospital_dir).value();
  tree.home1.reset();  // says it leaves (say_leaving)
  ASSERT_TRUE(eventually([&] { return count(tree.hospital_dir, {.s = Term::iri(kHome1), .p = Term::iri(vocab::kLinkLeft)}) == 1; }));
  auto asked = remote_query(hospital, {.target = kHome1}, 5s, [](const node::Record&) {});
  ASSERT_FALSE(asked);
  EXPECT_EQ(asked.error().message,
            "unreachable: <" + kHome1 + "> is down at <" + kHospital + "> (its link was stopped: it said so as it left)");
  // A new run of the hospital's link keeps it (review of session 86: the first state it wrote
  // dropped it).
  tree.hospital.reset();
  tree.hospital = tree.start_hospital();
  std::this_thread::sleep_for(500ms);  // its first state writes
  asked = remote_query(hospital, {.target = kHome1}, 5s, [](const node::Record&) {});
  ASSERT_FALSE(asked);
  EXPECT_NE(asked.error().message.find("(its link was stopped: it said so as it left)"), std::string::npos) << asked.error().message;
  // Back: the mark goes with the "down".
  tree.home1 = tree.start_home(tree.home1_dir, kHome1, tree.home1_log);
  ASSERT_TRUE(eventually([&] { return state_says_up(tree.hospital_dir, kHome1); }));
  EXPECT_TRUE(eventually([&] { return count(tree.hospital_dir, {.s = Term::iri(kHome1), .p = Term::iri(vocab::kLinkLeft)}) == 0; }));
}

TEST(Link, ParentChangesAChildsForwardingPolicyBySendingASubscriptionDown) {
  Tree tree;
  tree.hospital = tree.start_hospital();
  tree.home1 = tree.start_home(tree.home1_dir, kHome1, tree.home1_log);
  ASSERT_TRUE(eventually([&] { return tree.home1->connected(); }));
  auto sensor = node::Node::open(tree.home1_dir).value().agent("ecg").value();
  ASSERT_TRUE(sensor.store(raw_item(1)));
  // The policy is subscriptions of home1's agent "uplink": the hospital writes one more, for
  // home1 (context = home1's IRI), and raw samples start to go up.
  auto operator_ = node::Node::open(tree.hospital_dir).value().agent("operator").value();
  ASSERT_TRUE(operator_.store(raw_samples_go_up()));
  ASSERT_TRUE(eventually([&] { return count(tree.home1_dir, kHome1UplinkSubscriptions) == 2; }));
  ASSERT_TRUE(sensor.store(raw_item(2)));
  ASSERT_TRUE(eventually([&] { return count(tree.hospital_dir, {.p = Term::iri(kEx + "samples")}) == 1; }));
  // Only what was written after the policy changed.
  auto records = node::Node::open(tree.hospital_dir).value().snapshot().value().list({.p = Term::iri(kEx + "samples")}).value();
  ASSERT_EQ(records.size(), 1u);
  EXPECT_EQ(records[0].triple.s.value, kHome1 + "/rec/chunk/2");
  EXPECT_EQ(records[0].meta.source, kHome1 + "/ecg");
}

// P7a: a chunk that went up while the hospital's wider policy held is removed at the hospital
// when the home removes it, after the hospital has narrowed the policy again.
TEST(Link, ACopySentUnderAPolicyNarrowedSinceGoesWhenTheHomeRemovesIt) {
  Tree tree;
  ASSERT_TRUE(tree.start_hospital_and_home1());
  auto home = node::Node::open(tree.home1_dir).value();
  auto sensor = home.agent("ecg").value();
  auto hospital = node::Node::open(tree.hospital_dir).value();
  auto operator_ = hospital.agent("operator").value();
  const std::uint64_t policy_id = operator_.store(raw_samples_go_up()).value();
  ASSERT_TRUE(eventually([&] { return count(tree.home1_dir, kHome1UplinkSubscriptions) == 2; }));
  const std::uint64_t chunk = sensor.store(raw_item(2)).value();
  const node::Pattern samples{.p = Term::iri(kEx + "samples")};
  ASSERT_TRUE(eventually([&] { return count(tree.hospital_dir, samples) == 1; }));
  // Narrowed again: the policy's removal at the hospital takes the subscription at home (P10a).
  ASSERT_TRUE(hospital.remove_item(policy_id));
  ASSERT_TRUE(eventually([&] { return count(tree.home1_dir, kHome1UplinkSubscriptions) == 1; }));
  ASSERT_TRUE(home.remove_item(chunk));
  EXPECT_TRUE(eventually([&] { return count(tree.hospital_dir, samples) == 0; }))
      << count(tree.hospital_dir, samples) << " chunk(s) left at the hospital";
}

// P6f's case: a policy that sends raw samples up is written at the hospital for home1; home1
// stops; the hospital writes `settings` items for an agent of home1, then removes the policy;
// home1's sensor stores 20 raw chunks and its HRV agent a window, all queued in the outbox under
// the old policy, which home1 has not yet heard was removed.
void remove_the_policy_while_home1_is_away(Tree& tree, std::size_t settings) {
  ASSERT_TRUE(tree.start_hospital_and_home1());
  auto home = node::Node::open(tree.home1_dir).value();
  auto hospital = node::Node::open(tree.hospital_dir).value();
  auto operator_ = hospital.agent("operator").value();
  const std::uint64_t policy_id = operator_.store(raw_samples_go_up()).value();
  ASSERT_TRUE(eventually([&] { return count(tree.home1_dir, kHome1UplinkSubscriptions) == 2; }));
  tree.home1.reset();
  std::vector<node::Item> items(settings);
  for (std::size_t i = 0; i < items.size(); ++i) {
    items[i].context = kHome1 + "/cfg";
    items[i].add(Term::iri(kHome1 + "/cfg"), Term::iri(kEx + "setting"), Term::integer(static_cast<std::int64_t>(i)));
  }
  ASSERT_TRUE(operator_.store_all(items));
  ASSERT_TRUE(hospital.remove_item(policy_id));
  auto sensor = home.agent("ecg").value();
  for (int i = 0; i < 20; ++i) ASSERT_TRUE(sensor.store(raw_item(i)));
  store_hrv_items(tree.home1_dir, 0, 1);
  ASSERT_EQ(outbox(tree.home1_dir), 21u) << "the old policy did not route the backlog: the case under test did not happen";
}

// P6f: a policy removed at the hospital while the home was away. What the home queued under the
// old policy meanwhile (a sensor's backlog) stays home: the home applies what came down before it
// sends anything up, and takes out of its outbox what the narrowed policy no longer sends.
TEST(Link, WhatAPolicyRemovedWhileTheHomeWasAwayQueuedStaysHomeWhenItComesBack) {
  Tree tree;
  // Settings for an agent of home1 written meanwhile, before the removal, put it far down the
  // queue (a first version looked at its first 4,096 items only, and the backlog went up).
  ASSERT_NO_FATAL_FAILURE(remove_the_policy_while_home1_is_away(tree, 5000));

  tree.home1 = tree.start_home(tree.home1_dir, kHome1, tree.home1_log);
  ASSERT_TRUE(eventually([&] { return count(tree.hospital_dir, {.p = Term::iri(kEx + "n")}) == 1 && outbox(tree.home1_dir) == 0; }))
      << outbox(tree.home1_dir) << " item(s) left in the outbox";
  EXPECT_EQ(count(tree.home1_dir, kHome1UplinkSubscriptions), 1u);
  EXPECT_EQ(count(tree.hospital_dir, {.p = Term::iri(kEx + "samples")}), 0u) << "raw samples went up under the removed policy";
  EXPECT_EQ(count(tree.home1_dir, {.p = Term::iri(kEx + "samples")}), 20u);
  EXPECT_TRUE(tree.home1_log.has("20 item(s) it no longer sends")) << tree.home1_log.text();
}

// P6f: the hold of a session that ended before the down stream was applied (the parent's link
// stopped) does not cut the next session's hold short: a first version kept its time limit, and
// at the next welcome, seconds later, the home sent its backlog at once (a review's test).
TEST(Link, AHoldOfAnEndedSessionDoesNotCutTheNextSessionsHoldShort) {
  Tree tree;
  ASSERT_NO_FATAL_FAILURE(remove_the_policy_while_home1_is_away(tree, 30000));

  tree.home1 = tree.start_home(tree.home1_dir, kHome1, tree.home1_log);
  ASSERT_TRUE(eventually([&] { return tree.home1->connected(); }));
  tree.hospital.reset();  // its link stops (and says so), most likely before home1 applied the removal
  std::this_thread::sleep_for(6s);
  tree.hospital = tree.start_hospital();
  ASSERT_TRUE(eventually([&] { return count(tree.hospital_dir, {.p = Term::iri(kEx + "n")}) == 1 && outbox(tree.home1_dir) == 0; }))
      << outbox(tree.home1_dir) << " item(s) left in the outbox";
  EXPECT_EQ(count(tree.hospital_dir, {.p = Term::iri(kEx + "samples")}), 0u) << tree.home1_log.text();
  EXPECT_FALSE(tree.home1_log.has("sends up again before applying")) << tree.home1_log.text();
}

// P6f: a link stopped between a narrowing's removal and its withdrawal (its store keeps a file
// saying so) withdraws at its next start, before anything goes up.
TEST(Link, ANarrowingAStopCutShortIsWithdrawnAtTheNextStart) {
  Tree tree;
  ASSERT_TRUE(tree.start_hospital_and_home1());
  auto home = node::Node::open(tree.home1_dir).value();
  auto uplink = home.agent("uplink").value();
  const std::uint64_t local_policy = uplink.subscribe({.p = Term::iri(kEx + "samples")}).value();
  tree.home1.reset();
  auto sensor = home.agent("ecg").value();
  for (int i = 0; i < 5; ++i) ASSERT_TRUE(sensor.store(raw_item(i)));
  ASSERT_EQ(outbox(tree.home1_dir), 5u);
  ASSERT_TRUE(home.remove_item(local_policy));  // as a removal relayed just before the stop
  { std::ofstream marker(tree.home1_dir + "/uplink-policy-narrowed"); }
  store_hrv_items(tree.home1_dir, 0, 1);
  tree.home1 = tree.start_home(tree.home1_dir, kHome1, tree.home1_log);
  ASSERT_TRUE(eventually([&] { return count(tree.hospital_dir, {.p = Term::iri(kEx + "n")}) == 1 && outbox(tree.home1_dir) == 0; }))
      << outbox(tree.home1_dir) << " item(s) left in the outbox";
  EXPECT_EQ(count(tree.hospital_dir, {.p = Term::iri(kEx + "samples")}), 0u) << tree.home1_log.text();
  EXPECT_TRUE(tree.home1_log.has("5 item(s) it no longer sends")) << tree.home1_log.text();
  EXPECT_FALSE(std::filesystem::exists(tree.home1_dir + "/uplink-policy-narrowed"));
}

TEST(Link, ConfigurationTravelsTwoHopsDownToAnAgentOfASensorNode) {
  Tree tree;
  const std::string sensor_iri = kHome1 + "/ecg1";
  const std::string sensor_dir = (tree.tmp / "ecg1").string();
  auto sensor_link = tree.start_three_tiers(sensor_dir);  // home1: the hospital's child, ecg1's parent
  auto source = node::Node::open(sensor_dir).value().agent("source").value();
  auto operator_ = node::Node::open(tree.hospital_dir).value().agent("operator").value();
  node::Item config;
  config.context = sensor_iri + "/source";
  config.add(Term::iri(sensor_iri + "/source"), Term::iri(kEx + "rateHz"), Term::integer(250));
  ASSERT_TRUE(operator_.store(config));
  auto delivered = source.take(10s).value();
  ASSERT_TRUE(delivered.has_value());
  EXPECT_EQ(delivered->records[0].triple.o.value, "250");
  EXPECT_EQ(delivered->records[0].meta.source, kHospital + "/operator");
  // Stored on the way (home1 keeps what passed through its board) and at the sensor, once each.
  EXPECT_EQ(count(tree.home1_dir, {.p = Term::iri(kEx + "rateHz")}), 1u);
  EXPECT_EQ(count(sensor_dir, {.p = Term::iri(kEx + "rateHz")}), 1u);
  // A query two hops down, and a timeout when the node on the way stops answering.
  auto hospital = node::Node::open(tree.hospital_dir).value();
  ASSERT_TRUE(eventually([&] { return state_says_up(tree.hospital_dir, kHome1); }));
  std::size_t got = 0;
  auto answered = remote_query(hospital, {.target = sensor_iri, .pattern = {.p = Term::iri(kEx + "rateHz")}}, 10s,
                               [&](const node::Record&) { ++got; });
  ASSERT_TRUE(answered) << answered.error().message;
  EXPECT_EQ(got, 1u);
  sensor_link.reset();
  tree.home1.reset();  // stopped; the hospital still believes home1 is up for a while
  auto late = remote_query(hospital, {.target = sensor_iri}, 1s, [](const node::Record&) {});
  ASSERT_FALSE(late);
  EXPECT_EQ(late.error().code, Errc::timeout) << late.error().message;
}

// P15: a gateway whose link has just restarted has not heard its sensor yet (it says hello again
// within a heartbeat of hearing "unregistered"). A query from the hospital for the sensor that
// arrives then is answered once the sensor is back, not refused as an unknown node.
TEST(Link, AQueryOnTheWayDownWaitsForAChildThatHasNotYetSaidHelloToANewRunOfItsParent) {
  Tree tree;
  const std::string sensor_iri = kHome1 + "/ecg1";
  const std::string sensor_dir = (tree.tmp / "ecg1").string();
  auto sensor_link = tree.start_three_tiers(sensor_dir);
  ASSERT_TRUE(node::Node::open(sensor_dir).value().agent("ecg").value().store(raw_item(7)));
  auto hospital = node::Node::open(tree.hospital_dir).value();
  const RemoteQuery ask{.target = sensor_iri, .pattern = {.p = Term::iri(kEx + "samples")}};

  // home1's new run accepts any child (as before): it knows none until its first hello.
  tree.home1.reset();
  std::shared_ptr<Transport> endpoint(tree.bus.open(kHome1, tree.home1_log.sink()));
  tree.home1 = Link::start({.dir = tree.home1_dir, .parent_iri = kHospital, .up = endpoint, .down = endpoint,
                            .resend_after = 100ms, .heartbeat_every = 200ms, .log = tree.home1_log.sink()})
                   .value();
  ASSERT_TRUE(eventually([&] { return tree.home1->connected() && state_says_up(tree.hospital_dir, kHome1); }));
  std::size_t got = 0;
  auto answered = remote_query(hospital, ask, 10s, [&](const node::Record&) { ++got; });
  ASSERT_TRUE(answered) << answered.error().message;
  EXPECT_EQ(got, 1u);

  // A node that is not there is still an unknown node, once the run is no longer young.
  std::this_thread::sleep_for(LinkOptions{}.child_silence);
  auto unknown = remote_query(hospital, {.target = kHome1 + "/ecg9"}, 10s, [](const node::Record&) {});
  ASSERT_FALSE(unknown);
  EXPECT_EQ(unknown.error().code, Errc::not_found) << unknown.error().message;
}

// A binding whose sends to one IRI block while `stalled`, as a Cyclone DDS writer does when the
// reader on the other side has stopped taking (a frozen parent): each waits up to 1 s, then fails
// with a timeout. Everything else passes through.
class StallingTransport : public Transport {
 public:
  StallingTransport(std::unique_ptr<Transport> inner, std::string stalled_to)
      : inner_(std::move(inner)), stalled_to_(std::move(stalled_to)) {}
  const std::string& self() const override { return inner_->self(); }
  Result<void> send(const Frame& frame) override {
    if (frame.to == stalled_to_) {
      std::unique_lock lock(mu_);
      if (stalled_) {
        ++blocked_;
        ++blocked_kinds_[frame.kind];
        if (cv_.wait_for(lock, 1s, [&] { return !stalled_; }) == false)
          return node::fail(Errc::timeout, "write blocked 1 s: the reader takes nothing");
      }
    }
    return inner_->send(frame);
  }
  Result<std::optional<Frame>> receive(std::chrono::milliseconds timeout) override { return inner_->receive(timeout); }
  void stall(bool on) {
    std::lock_guard lock(mu_);
    stalled_ = on;
    cv_.notify_all();
  }
  int blocked() {
    std::lock_guard lock(mu_);
    return blocked_;
  }
  int blocked(FrameKind kind) {
    std::lock_guard lock(mu_);
    return blocked_kinds_[kind];
  }

 private:
  std::unique_ptr<Transport> inner_;
  std::string stalled_to_;
  std::mutex mu_;
  std::condition_variable cv_;
  bool stalled_ = false;
  int blocked_ = 0;
  std::map<FrameKind, int> blocked_kinds_;
};

// The hospital, home1 as a gateway whose sends to the hospital can be stalled, and its sensor
// ecg1 (in `sensor_dir`); the caller waits for the links to be up.
struct StallableGateway {
  std::string sensor_dir;
  std::shared_ptr<StallingTransport> home1_endpoint;
  std::unique_ptr<Link> sensor_link;
};

StallableGateway start_stallable_gateway(Tree& tree) {
  StallableGateway g;
  g.sensor_dir = (tree.tmp / "ecg1").string();
  tree.hospital = tree.start_hospital();
  g.home1_endpoint = std::make_shared<StallingTransport>(tree.bus.open(kHome1, tree.home1_log.sink()), kHospital);
  g.sensor_link = tree.start_gateway_and_sensor(g.home1_endpoint, g.sensor_dir);
  return g;
}

TEST(Link, AGatewayKeepsTakingItsSensorsItemsWhileItsParentStallsItsSends) {
  Tree tree;
  StallableGateway g = start_stallable_gateway(tree);
  ASSERT_TRUE(eventually([&] { return tree.home1->connected() && g.sensor_link->connected(); }));
  auto hrv = node::Node::open(g.sensor_dir).value().agent("hrv").value();
  const node::Pattern numbered{.p = Term::iri(kEx + "n")};

  g.home1_endpoint->stall(true);
  for (int i = 0; i < 20; ++i) ASSERT_TRUE(hrv.store(hrv_item(i)));
  ASSERT_TRUE(eventually([&] { return g.home1_endpoint->blocked() > 0; })) << "the home never tried to send up";
  // While its sends up block, the home still relays what its sensor sends it, item by item.
  for (int i = 20; i < 40; ++i) ASSERT_TRUE(hrv.store(hrv_item(i)));
  const auto deadline = std::chrono::steady_clock::now() + 4s;
  while (count(tree.home1_dir, numbered) < 40 && std::chrono::steady_clock::now() < deadline)
    std::this_thread::sleep_for(10ms);
  EXPECT_EQ(count(tree.home1_dir, numbered), 40u) << "the home stopped serving its sensor while its parent stalled";
  EXPECT_EQ(count(tree.hospital_dir, numbered), 0u);

  g.home1_endpoint->stall(false);
  ASSERT_TRUE(eventually([&] { return count(tree.hospital_dir, numbered) >= 40; }))
      << count(tree.hospital_dir, numbered) << " of 40 reached the hospital after the stall";
  std::this_thread::sleep_for(300ms);
  EXPECT_EQ(count(tree.hospital_dir, numbered), 40u);
  g.sensor_link.reset();
}

// Wraps an endpoint: counts the answer chunks it sends, by chunk number, can hold back the
// chunks after a given one (a slow node), and can lose the acknowledgements of answer chunks that
// reach it (a parent whose acks do not arrive).
class AnswerTap : public Transport {
 public:
  explicit AnswerTap(std::unique_ptr<Transport> inner) : inner_(std::move(inner)) {}
  const std::string& self() const override { return inner_->self(); }
  Result<void> send(const Frame& frame) override {
    if (frame.kind == FrameKind::answer) {
      std::unique_lock lock(mu_);
      if (frame.prev > holding_after_ && !released_.wait_for(lock, 10s, [&] { return frame.prev <= holding_after_; }))
        return node::fail(Errc::timeout, "held back");
      ++sent_[frame.prev];
    }
    return inner_->send(frame);
  }
  void hold_chunks_after(std::uint64_t chunk) {
    std::lock_guard lock(mu_);
    holding_after_ = chunk;
    released_.notify_all();
  }
  Result<std::optional<Frame>> receive(std::chrono::milliseconds timeout) override {
    auto got = inner_->receive(timeout);
    if (got && *got && (*got)->kind == FrameKind::ack && (*got)->seq != 0 && losing_acks_.load())
      return std::optional<Frame>{};
    return got;
  }
  void lose_acks(bool on) { losing_acks_ = on; }
  std::map<std::uint64_t, int> sent() {
    std::lock_guard lock(mu_);
    return sent_;
  }
  std::uint64_t highest_sent() {
    std::lock_guard lock(mu_);
    return sent_.empty() ? 0 : sent_.rbegin()->first;
  }

 private:
  std::unique_ptr<Transport> inner_;
  std::atomic<bool> losing_acks_{false};
  std::mutex mu_;
  std::condition_variable released_;
  std::uint64_t holding_after_ = ~0ull;
  std::map<std::uint64_t, int> sent_;
};

// `n` records of raw samples at the node in `dir`, each large enough to fill an answer chunk
// (48 KiB, P14) nearly alone, so that the answer has `n` chunks.
void store_chunk_sized_records(const std::string& dir, const std::string& node_iri, int n, int first = 0) {
  auto ecg = node::Node::open(dir).value().agent("ecg").value();
  const std::string samples(40 * 1024, 'x');
  for (int i = first; i < first + n; ++i) {
    node::Item chunk;
    chunk.add(Term::iri(node_iri + "/rec/long/" + std::to_string(i)), Term::iri(kEx + "samples"),
              Term::literal(std::to_string(i) + samples));
    ASSERT_TRUE(ecg.store(chunk));
  }
}

// The hospital and home1, whose endpoint is tapped; the caller waits with home1_is_up.
std::shared_ptr<AnswerTap> start_tapped_home(Tree& tree, std::chrono::milliseconds resend_after, bool say_leaving = false) {
  tree.hospital = tree.start_hospital();
  auto tap = std::make_shared<AnswerTap>(tree.bus.open(kHome1, tree.home1_log.sink()));
  // Most of its tests stop it as a killed process stops, unsaid (P15: a restart, a node gone
  // silent).
  tree.home1 = Link::start({.dir = tree.home1_dir, .parent_iri = kHospital, .up = tap, .say_leaving = say_leaving, .down = tap,
                            .resend_after = resend_after, .heartbeat_every = 200ms, .log = tree.home1_log.sink()})
                   .value();
  return tap;
}

// home1 registered, and the hospital's state triples say so (so a query for it is routed).
bool home1_is_up(Tree& tree) {
  return eventually([&] {
    return tree.home1->connected() &&
           state_says_up(tree.hospital_dir, kHome1);
  });
}

// A remote query from the hospital for the raw samples held at `target`, asked on its own
// thread; finish() waits for its end. With `pause_after`, the caller stops taking records after
// that many until resume(): a consumer slower than the link. cancel() cancels it (P18).
class SamplesQuery {
 public:
  SamplesQuery(Tree& tree, const std::string& target, std::chrono::seconds timeout,
               std::size_t pause_after = std::numeric_limits<std::size_t>::max())
      : hospital_(node::Node::open(tree.hospital_dir).value()), pause_after_(pause_after), asking_([this, target, timeout] {
          answered_ = remote_query(hospital_, {.target = target, .pattern = {.p = Term::iri(kEx + "samples")}}, timeout,
                                   [this](const node::Record&) {
                                     std::unique_lock lock(mu_);
                                     resumed_.wait(lock, [&] { return got_.load() < pause_after_; });
                                     ++got_;
                                   }, {}, [this] { return cancelled_.load(); });
        }) {}
  ~SamplesQuery() {
    resume();
    if (asking_.joinable()) asking_.join();
  }
  std::size_t received() const { return got_.load(); }
  void cancel() { cancelled_ = true; }
  void resume() {
    std::lock_guard lock(mu_);
    pause_after_ = std::numeric_limits<std::size_t>::max();
    resumed_.notify_all();
  }
  // The number of records answered, or the query's error.
  Result<std::size_t> finish() {
    asking_.join();
    if (!answered_) return tahvel::unexpected(answered_.error());
    return got_.load();
  }

 private:
  node::Node hospital_;
  Result<std::uint64_t> answered_ = 0;
  std::atomic<std::size_t> got_{0};
  std::atomic<bool> cancelled_{false};
  std::mutex mu_;
  std::condition_variable resumed_;
  std::size_t pause_after_;
  std::thread asking_;
};

// The hospital and home1 (endpoint tapped, resending after `resend_after`), home1 registered,
// and `chunks` chunk-sized records on home1 for the hospital to ask for.
std::shared_ptr<AnswerTap> start_answering_home(Tree& tree, std::chrono::milliseconds resend_after, int chunks,
                                                bool say_leaving = false) {
  auto tap = start_tapped_home(tree, resend_after, say_leaving);
  EXPECT_TRUE(home1_is_up(tree));
  store_chunk_sized_records(tree.home1_dir, kHome1, chunks);
  return tap;
}

// `query` ends with every one of the `chunks` records asked for.
void expect_whole_answer(SamplesQuery& query, int chunks) {
  auto got = query.finish();
  ASSERT_TRUE(got) << got.error().message;
  EXPECT_EQ(*got, static_cast<std::size_t>(chunks));
}

TEST(Link, EachAnswerChunkIsSentOnceWhenNoneIsLost) {
  Tree tree;
  constexpr int kChunks = 60;
  // No resend can be due while the answer flows: every send counted is a first send.
  auto tap = start_answering_home(tree, 10s, kChunks);
  SamplesQuery query(tree, kHome1, 30s);
  expect_whole_answer(query, kChunks);
  const auto sent = tap->sent();
  EXPECT_EQ(sent.size(), static_cast<std::size_t>(kChunks));
  for (const auto& [chunk, times] : sent) EXPECT_EQ(times, 1) << "chunk " << chunk << " was sent " << times << " times";
}

TEST(Link, AnAnswerRunsNoFurtherThanItsWindowAheadOfTheParentsAcksAndHoldsWhatWasThereWhenAsked) {
  Tree tree;
  constexpr int kChunks = 50;
  auto tap = start_answering_home(tree, 100ms, kChunks);

  tap->lose_acks(true);
  SamplesQuery query(tree, kHome1, 30s);
  ASSERT_TRUE(eventually([&] { return tap->highest_sent() >= 16; })) << "the answer did not start";
  // No acknowledgement arrives: the home resends its window (resend_after = 100 ms), and goes no
  // further than it (P14: 16 chunks).
  ASSERT_TRUE(eventually([&] { return tap->sent()[1] >= 3; })) << "the window was not resent";
  EXPECT_EQ(tap->highest_sent(), 16u);
  // Records stored after the query arrived are not part of its answer.
  store_chunk_sized_records(tree.home1_dir, kHome1, 5, kChunks);

  tap->lose_acks(false);
  expect_whole_answer(query, kChunks);
  EXPECT_EQ(tap->highest_sent(), static_cast<std::uint64_t>(kChunks));
}

TEST(Link, AnAnswerTheAskerDoesNotReadHoldsTheTargetBackInsteadOfPilingUpOnTheOriginsBoard) {
  Tree tree;
  constexpr int kChunks = 120;
  auto tap = start_answering_home(tree, 100ms, kChunks);

  // The asker takes chunk 1 and hands its record over, takes chunk 2 and waits.
  SamplesQuery query(tree, kHome1, 60s, /*pause_after=*/1);
  ASSERT_TRUE(eventually([&] { return query.received() == 1 && tap->highest_sent() >= 16; }));
  // The home stops sending: the answer is held back, not finished.
  ASSERT_TRUE(eventually([&] {
    const std::uint64_t before = tap->highest_sent();
    std::this_thread::sleep_for(300ms);
    return tap->highest_sent() == before;
  }));
  // The hospital acknowledges at most 32 chunks beyond those taken off its board (two), and the
  // home's window is 16 beyond that: nothing more leaves the home, nothing more is on the board.
  // How far it got before stopping depends on when the asker paused; what it sent waits on the
  // board, except the chunks the asker took.
  const std::uint64_t sent = tap->highest_sent();
  EXPECT_LE(sent, 2u + 32 + 16);
  EXPECT_LT(sent, static_cast<std::uint64_t>(kChunks));
  std::uint64_t on_board = 0;
  auto count_on_board = [&] {
    on_board = 0;
    auto board = node::Node::open(tree.hospital_dir).value().snapshot().value();
    EXPECT_TRUE(board.for_each({.p = Term::iri(vocab::kAnswerChunk)}, [&](const node::Record&) { return ++on_board, true; }));
    return on_board;
  };
  EXPECT_TRUE(eventually([&] { return count_on_board() + 2 >= sent; })) << on_board << " on the board of " << sent << " sent";
  EXPECT_LE(count_on_board(), 32u + 16);

  query.resume();
  expect_whole_answer(query, kChunks);
  EXPECT_EQ(tap->highest_sent(), static_cast<std::uint64_t>(kChunks));
}

// A hospital whose store is a ring takes in more than the ring holds while an operator's query
// runs: the ring must not reclaim the query item (that reads as a cancel, P18), so the whole
// answer still arrives.
TEST(Link, AQueryRunsToItsEndWhileTheOriginsRingReclaimsTheRecordsAroundIt) {
  Tree tree({.ring = 100});
  constexpr int kChunks = 40;
  auto tap = start_answering_home(tree, 100ms, kChunks);

  SamplesQuery query(tree, kHome1, 20s, /*pause_after=*/1);
  ASSERT_TRUE(eventually([&] { return query.received() == 1; }));
  auto hospital = node::Node::open(tree.hospital_dir).value();
  auto trend = hospital.agent("trend").value();
  for (int i = 0; i < 300; ++i) ASSERT_TRUE(trend.store(hrv_item(i)));
  ASSERT_GT(hospital.stats().value().reclaimed_records, 0u) << "the ring reclaimed nothing: the test proves nothing";

  query.resume();
  expect_whole_answer(query, kChunks);
}

// All the answer chunks `tap` has sent, first sends and resends.
int answer_sends(AnswerTap& tap) {
  int total = 0;
  for (const auto& [chunk, times] : tap.sent()) total += times;
  return total;
}

// The node behind `tap` has stopped sending answer chunks: a live stream would resend its window
// every 100 ms (resend_after) while nothing acknowledges it.
bool answer_sends_stop(AnswerTap& tap) {
  return eventually([&] {
    const int before = answer_sends(tap);
    std::this_thread::sleep_for(400ms);
    return answer_sends(tap) == before;
  });
}

// Neither the query item nor any of its answer items is left on the hospital's board.
bool hospital_board_is_clear_of_the_query(Tree& tree) {
  return eventually([&] {
    return count(tree.hospital_dir, {.p = Term::iri(vocab::kAnswerChunk)}) == 0 &&
           count(tree.hospital_dir, {.o = Term::iri(vocab::kRemoteQuery)}) == 0;
  });
}

// Starts a query for the 120 chunk-sized records at `target` whose asker pauses after the first
// record; once `sender` has sent a window, cancels it. The caller checks what stopped.
void ask_and_cancel(Tree& tree, const std::string& target, AnswerTap& sender) {
  SamplesQuery query(tree, target, 60s, /*pause_after=*/1);
  ASSERT_TRUE(eventually([&] { return query.received() == 1 && sender.highest_sent() >= 16; }));
  query.cancel();
  query.resume();
  auto got = query.finish();
  ASSERT_FALSE(got);
  EXPECT_EQ(got.error().message.rfind("cancelled", 0), 0u) << got.error().message;
}

TEST(Link, ACancelledQueryStopsTheTargetAndLeavesNothingOnTheOriginsBoard) {
  Tree tree;
  auto tap = start_answering_home(tree, 100ms, 120);
  ask_and_cancel(tree, kHome1, *tap);
  EXPECT_TRUE(hospital_board_is_clear_of_the_query(tree));
  EXPECT_TRUE(answer_sends_stop(*tap)) << "home1 went on answering a cancelled query";
  EXPECT_LT(tap->highest_sent(), 120u);
}

// The hospital asks for the 40 chunk-sized records held at `target` (home1 itself, or its sensor
// through it) while home1's sends to the hospital are stalled. While the answer waits on the
// stalled parent, home1 must still take, item by item, what its sensor sends it: no answer chunk
// is sent from the thread that receives. Once the parent takes again, everything arrives.
void expect_the_gateway_serves_its_sensor_while_an_answer_waits(Tree& tree, StallableGateway& g, const std::string& target_dir,
                                                                const std::string& target) {
  const std::string sensor_iri = kHome1 + "/ecg1";
  ASSERT_TRUE(home1_is_up(tree));
  ASSERT_TRUE(eventually([&] {
    return g.sensor_link->connected() &&
           state_says_up(tree.home1_dir, sensor_iri);
  }));
  store_chunk_sized_records(target_dir, target, 40);  // more chunks than the answer window (P14)

  g.home1_endpoint->stall(true);  // the query still goes down; the answer's way up is stalled
  SamplesQuery query(tree, target, 60s);
  ASSERT_TRUE(eventually([&] { return g.home1_endpoint->blocked(FrameKind::answer) > 0; }))
      << "home1 never tried to send the answer up";
  auto hrv = node::Node::open(g.sensor_dir).value().agent("hrv").value();
  for (int i = 0; i < 20; ++i) ASSERT_TRUE(hrv.store(hrv_item(i)));
  const node::Pattern numbered{.p = Term::iri(kEx + "n")};
  const auto deadline = std::chrono::steady_clock::now() + 3s;
  while (count(tree.home1_dir, numbered) < 20 && std::chrono::steady_clock::now() < deadline)
    std::this_thread::sleep_for(10ms);
  EXPECT_EQ(count(tree.home1_dir, numbered), 20u) << "home1 stopped serving its sensor while the answer waited";

  g.home1_endpoint->stall(false);
  expect_whole_answer(query, 40);
  ASSERT_TRUE(eventually([&] { return count(tree.hospital_dir, numbered) == 20; }));
  g.sensor_link.reset();
}

TEST(Link, AGatewayKeepsTakingItsSensorsItemsWhileItsAnswerToAStalledParentWaits) {
  Tree tree;
  StallableGateway g = start_stallable_gateway(tree);
  expect_the_gateway_serves_its_sensor_while_an_answer_waits(tree, g, tree.home1_dir, kHome1);
}

TEST(Link, AGatewayKeepsTakingItsSensorsItemsWhileARelayedAnswerToAStalledParentWaits) {
  Tree tree;
  StallableGateway g = start_stallable_gateway(tree);
  expect_the_gateway_serves_its_sensor_while_an_answer_waits(tree, g, g.sensor_dir, kHome1 + "/ecg1");
}

// An answer of 120 chunks from home1 under way: the asker (paused after its first record) has
// taken a chunk and home1 has sent its window.
struct PausedAnswer {
  // `say_leaving`: home1's link says so when it stops (P12c); else it stops as a killed one.
  explicit PausedAnswer(bool say_leaving = false) : tap(start_answering_home(tree, 100ms, 120, say_leaving)) {}
  Tree tree;
  std::shared_ptr<AnswerTap> tap;
  SamplesQuery query{tree, kHome1, 60s, /*pause_after=*/1};
  bool under_way() {
    return eventually([&] { return query.received() == 1 && tap->highest_sent() >= 16; });
  }
};

// The hospital's link restarts while home1 answers a query: the new link knows nothing of it
// and must tell home1 to stop (P18), not leave it resending its window for good. The hospital's
// link restarts while an answer runs: its stream's state is gone, so the asker is
// told at once (not at its timeout of a minute), home1 stops, and nothing stays on the board.
TEST(Link, AQueryUnderWayWhenTheOriginsLinkRestartsEndsAtOnceAndStopsTheTarget) {
  PausedAnswer answer;
  ASSERT_TRUE(answer.under_way());
  auto& [tree, tap, query] = answer;

  tree.hospital.reset();
  tree.hospital = tree.start_hospital();
  EXPECT_TRUE(answer_sends_stop(*tap)) << "home1 went on resending an answer nobody waits for";
  EXPECT_LT(tap->highest_sent(), 120u);
  query.resume();
  auto got = query.finish();
  ASSERT_FALSE(got);
  EXPECT_EQ(got.error().code, Errc::io) << got.error().message;
  EXPECT_EQ(got.error().message.rfind("link_restarted: the link of <" + kHospital + "> restarted", 0), 0u) << got.error().message;
  EXPECT_TRUE(eventually([&] { return count(tree.hospital_dir, {.p = Term::iri(vocab::kQueryTarget)}) == 0; }));
  EXPECT_TRUE(eventually([&] { return count(tree.hospital_dir, {.p = Term::iri(vocab::kAnswerTo)}) == 0; }))
      << "answer items left on the hospital's board";
}

// home1's link stopped and started again on `endpoint`: a new run, with none of the old one's
// answer streams in memory.
void restart_home1(Tree& tree, std::shared_ptr<Transport> endpoint) {
  tree.home1.reset();
  tree.home1 = Link::start({.dir = tree.home1_dir, .parent_iri = kHospital, .up = endpoint, .say_leaving = false, .down = endpoint,
                            .resend_after = 100ms, .heartbeat_every = 200ms, .log = tree.home1_log.sink()})
                   .value();
}

// The paused `query` is resumed and ends, well before its 60 s timeout, with an error whose
// message starts with `prefix`, having received part of its `chunks` records.
void expect_query_ends_early_with(SamplesQuery& query, const std::string& prefix, std::size_t chunks) {
  query.resume();
  const auto resumed = std::chrono::steady_clock::now();
  auto got = query.finish();
  ASSERT_FALSE(got);
  EXPECT_EQ(got.error().code, Errc::io) << got.error().message;
  EXPECT_EQ(got.error().message.rfind(prefix, 0), 0u) << got.error().message;
  EXPECT_LT(std::chrono::steady_clock::now() - resumed, 30s) << "the asker waited for its timeout";
  EXPECT_LT(query.received(), chunks);
}

// P15: the target's link restarts while its answer is under way; the stream was in the memory
// of the run before. The hospital, hearing nothing more, sends its ack again; the new run has no
// such stream and says so, and the asker ends with link_restarted instead of its timeout.
TEST(Link, AQueryWhoseTargetsLinkRestartsMidAnswerEndsWithLinkRestarted) {
  PausedAnswer answer;
  ASSERT_TRUE(answer.under_way());
  auto& [tree, tap, query] = answer;
  restart_home1(tree, tap);
  expect_query_ends_early_with(query, "link_restarted: <" + kHome1 + "> no longer has the answer", 120);
}

// P15: the target goes silent mid-answer (its node stopped). Once the hospital declares it down,
// the asker ends with unreachable (exit 5 for `tahvel query`), not at its timeout.
TEST(Link, AQueryWhoseTargetGoesSilentMidAnswerEndsUnreachable) {
  PausedAnswer answer;
  ASSERT_TRUE(answer.under_way());
  auto& [tree, tap, query] = answer;
  tree.home1.reset();
  // Said with how far the answer had come: an operator told it went silent "while it answered"
  // when nothing had come would look for a lost answer.
  expect_query_ends_early_with(query, "unreachable: <" + kHome1 + "> went silent at <" + kHospital + "> after ", 120);
}

// P12c: the target's link is stopped on purpose mid-answer (`tahvel down`, its supervisor's
// stop or restart): it says so as it goes, and the asker ends at once as unreachable, saying
// why, not once the hospital has called home1 silent.
TEST(Link, AQueryWhoseTargetsLinkIsStoppedMidAnswerEndsAtOnceSayingItLeft) {
  PausedAnswer answer{/*say_leaving=*/true};
  ASSERT_TRUE(answer.under_way());
  auto& [tree, tap, query] = answer;
  tree.home1.reset();
  expect_query_ends_early_with(query, "unreachable: <" + kHome1 + ">'s link was stopped at <" + kHospital + "> (it said so as it left)", 120);
  EXPECT_FALSE(tree.hospital_log.has("silent for")) << tree.hospital_log.text();
}

// The asking node's own link is stopped (`tahvel down`) while the answer comes: nothing will
// bring the rest, so the asker ends as unreachable a few seconds later, not at its timeout of
// a minute (a restart would have told it link_restarted).
TEST(Link, AQueryWhoseOriginsLinkStopsMidAnswerEndsUnreachable) {
  PausedAnswer answer;
  ASSERT_TRUE(answer.under_way());
  auto& [tree, tap, query] = answer;
  tree.hospital.reset();
  expect_query_ends_early_with(query, "unreachable: the link of <" + kHospital + "> stopped while the query ran", 120);
}

// P15: the node in the middle (home1, between the hospital and its sensor) restarts while an
// answer from the sensor passes through it. Its new run has no such stream: the sensor's next
// chunks, or the hospital's ack sent again, are answered with link_restarted up to the asker.
TEST(Link, AQueryWhoseNodeOnTheWayRestartsMidAnswerEndsWithLinkRestarted) {
  Tree tree;
  const std::string sensor_dir = (tree.tmp / "ecg1").string(), sensor_iri = kHome1 + "/ecg1";
  tree.hospital = tree.start_hospital();
  auto endpoint = std::shared_ptr<Transport>(tree.bus.open(kHome1, tree.home1_log.sink()));
  auto sensor_link = tree.start_gateway_and_sensor(endpoint, sensor_dir);
  ASSERT_TRUE(home1_is_up(tree));
  ASSERT_TRUE(eventually([&] { return state_says_up(tree.home1_dir, sensor_iri); }));
  store_chunk_sized_records(sensor_dir, sensor_iri, 120);
  SamplesQuery query(tree, sensor_iri, 60s, /*pause_after=*/1);
  ASSERT_TRUE(eventually([&] { return query.received() == 1; }));
  restart_home1(tree, endpoint);
  expect_query_ends_early_with(query, "link_restarted: <" + kHome1 + ">", 120);
}

// An asker killed with SIGKILL never removes its query item nor reads its answer. The P13 item
// is written here by hand, as such an asker left it, with a timeout of 300 ms: 2 s after it,
// the hospital's link removes the item and the answer on its board and stops the target.
TEST(Link, AQueryLeftBehindByADeadAskerIsClearedAfterItsTimeout) {
  Tree tree;
  auto tap = start_answering_home(tree, 100ms, 120);
  auto asker = node::Node::open(tree.hospital_dir).value().agent("query-1-1").value();
  node::Item ask;
  ask.context = kHome1;
  const Term q = Term::blank("query");
  ask.persistent = true;
  ask.add(q, Term::iri(std::string(node::kRdfType)), Term::iri(vocab::kRemoteQuery))
      .add(q, Term::iri(vocab::kQueryTarget), Term::iri(kHome1))
      .add(q, Term::iri(vocab::kReplyTo), Term::iri(asker.iri()))
      .add(q, Term::iri(vocab::kQueryPredicate), Term::iri(kEx + "samples"))
      .add(q, Term::iri(vocab::kQueryTimeout), Term::integer(300));
  ASSERT_TRUE(asker.store(ask));
  ASSERT_TRUE(eventually([&] { return count(tree.hospital_dir, {.p = Term::iri(vocab::kAnswerChunk)}) > 0; }));

  EXPECT_TRUE(hospital_board_is_clear_of_the_query(tree));
  EXPECT_TRUE(answer_sends_stop(*tap)) << "home1 went on answering a query whose asker is gone";
  EXPECT_LT(tap->highest_sent(), 120u);
  EXPECT_TRUE(tree.hospital_log.has("its asker is gone"));
}

// home1 as a gateway and its sensor ecg1, both endpoints tapped.
struct TappedGateway {
  std::shared_ptr<AnswerTap> home1_endpoint, sensor_endpoint;
  std::string sensor_iri = kHome1 + "/ecg1";
  std::string sensor_dir;
  std::unique_ptr<Link> sensor;
};

TappedGateway start_tapped_gateway(Tree& tree) {
  TappedGateway g;
  g.home1_endpoint = start_tapped_home(tree, 100ms);  // a gateway: its children use it too
  g.sensor_dir = (tree.tmp / "ecg1").string();
  EXPECT_TRUE(node::Node::init(g.sensor_dir, {.iri = g.sensor_iri}));
  g.sensor_endpoint = std::make_shared<AnswerTap>(tree.bus.open(g.sensor_iri, tree.home2_log.sink()));
  g.sensor = Link::start({.dir = g.sensor_dir, .parent_iri = kHome1, .up = g.sensor_endpoint, .resend_after = 100ms,
                          .heartbeat_every = 200ms, .log = tree.home2_log.sink()})
                 .value();
  return g;
}

// The hospital, and home1 as a gateway with its sensor ecg1 (TappedGateway), both links
// registered and each parent's state triples saying so (so queries are routed).
class AnswerThroughAGateway : public ::testing::Test {
 protected:
  void SetUp() override {
    g = start_tapped_gateway(tree);
    ASSERT_TRUE(home1_is_up(tree));
    ASSERT_TRUE(eventually([&] {
      return g.sensor->connected() &&
             state_says_up(tree.home1_dir, g.sensor_iri);
    }));
  }
  Tree tree;
  TappedGateway g;
};

TEST_F(AnswerThroughAGateway, TheGatewayHoldsItsChildBackWhileItsParentDoesNotAcknowledge) {
  auto& home1_endpoint = g.home1_endpoint;
  auto& sensor_endpoint = g.sensor_endpoint;
  const std::string& sensor_iri = g.sensor_iri;
  const std::string& sensor_dir = g.sensor_dir;
  constexpr int kChunks = 100;
  store_chunk_sized_records(sensor_dir, sensor_iri, kChunks);

  home1_endpoint->lose_acks(true);  // the hospital's acknowledgements do not reach the gateway
  SamplesQuery query(tree, sensor_iri, 60s);
  // The gateway takes the sensor's chunks beyond its own window towards the hospital, but only
  // so far (32 beyond what the hospital acknowledged, and the sensor's window of 16 on top).
  ASSERT_TRUE(eventually([&] { return sensor_endpoint->highest_sent() > 16; })) << "the gateway took no more than one window";
  ASSERT_TRUE(eventually([&] { return home1_endpoint->sent()[1] >= 3; })) << "the gateway did not resend its window";
  const std::uint64_t held_back_at = sensor_endpoint->highest_sent();
  EXPECT_LE(held_back_at, 48u);
  EXPECT_EQ(home1_endpoint->highest_sent(), 16u);

  home1_endpoint->lose_acks(false);
  expect_whole_answer(query, kChunks);
}

TEST_F(AnswerThroughAGateway, TheGatewayKeepsTheAnswersNumberingWhenItsParentHasAcknowledgedAllSoFar) {
  constexpr int kChunks = 20;
  store_chunk_sized_records(g.sensor_dir, g.sensor_iri, kChunks);
  g.sensor_endpoint->hold_chunks_after(5);  // a slow sensor: the gateway's stream runs empty
  SamplesQuery query(tree, g.sensor_iri, 30s);
  ASSERT_TRUE(eventually([&] { return query.received() == 5; }));
  // Give the hospital's acknowledgement of chunk 5 time to reach the gateway (whichever way this
  // goes, the answer must complete).
  std::this_thread::sleep_for(200ms);
  g.sensor_endpoint->hold_chunks_after(~0ull);
  expect_whole_answer(query, kChunks);
}

TEST_F(AnswerThroughAGateway, ACancelReachesTheTargetThroughTheGateway) {
  store_chunk_sized_records(g.sensor_dir, g.sensor_iri, 120);
  ask_and_cancel(tree, g.sensor_iri, *g.home1_endpoint);
  EXPECT_TRUE(hospital_board_is_clear_of_the_query(tree));
  EXPECT_TRUE(answer_sends_stop(*g.sensor_endpoint)) << "the sensor went on answering a cancelled query";
  EXPECT_TRUE(answer_sends_stop(*g.home1_endpoint)) << "the gateway went on relaying a cancelled query";
  EXPECT_LT(g.sensor_endpoint->highest_sent(), 120u);
}

TEST(Link, QueryByAreaIsResolvedAtTheTargetThroughItsAreaQuery) {
  Tree tree;
  tree.hospital = tree.start_hospital();
  // home1 resolves areas with a stand-in for the spatial library: it keeps the records whose
  // subject starts with the area's text, and records what it was asked.
  std::mutex asked_mu;
  std::vector<std::pair<std::string, std::optional<std::int64_t>>> asked;
  AreaQuery by_prefix = [&](const node::Snapshot& snap, const node::Pattern& pattern, const std::string& area,
                            std::optional<std::int64_t> floor, const node::ListOptions& options) -> node::Result<std::vector<node::Record>> {
    {
      std::lock_guard lock(asked_mu);
      asked.emplace_back(area, floor);
    }
    auto all = snap.list(pattern, options);
    if (!all) return all;
    std::vector<node::Record> kept;
    for (auto& r : *all)
      if (r.triple.s.value.rfind(area, 0) == 0) kept.push_back(std::move(r));
    return kept;
  };
  tree.home1 = Link::start({.dir = tree.home1_dir, .parent_iri = kHospital,
                            .up = std::shared_ptr<Transport>(tree.bus.open(kHome1, tree.home1_log.sink())),
                            .resend_after = 100ms, .heartbeat_every = 200ms, .log = tree.home1_log.sink(),
                            .area_query = by_prefix})
                   .value();
  ASSERT_TRUE(eventually([&] { return state_says_up(tree.hospital_dir, kHome1); }));
  auto motes = node::Node::open(tree.home1_dir).value().agent("motes").value();
  for (const std::string room : {"bedroom", "kitchen"}) {
    node::Item reading;
    reading.add(Term::iri(kHome1 + "/" + room + "/t1"), Term::iri(kEx + "celsius"), Term::integer(21));
    ASSERT_TRUE(motes.store(reading));
  }
  auto hospital = node::Node::open(tree.hospital_dir).value();
  std::vector<std::string> subjects;
  auto n = remote_query(hospital, {.target = kHome1, .pattern = {.p = Term::iri(kEx + "celsius")}, .area = kHome1 + "/bedroom", .floor = 2},
                        10s, [&](const node::Record& r) { subjects.push_back(r.triple.s.value); });
  ASSERT_TRUE(n) << n.error().message;
  EXPECT_EQ(subjects, std::vector<std::string>{kHome1 + "/bedroom/t1"});
  {
    std::lock_guard lock(asked_mu);
    ASSERT_EQ(asked.size(), 1u);
    EXPECT_EQ(asked[0].first, kHome1 + "/bedroom");
    EXPECT_EQ(asked[0].second, std::optional<std::int64_t>(2));
  }
  // A node whose link has no area resolver says so.
  tree.home2 = tree.start_home(tree.home2_dir, kHome2, tree.home2_log);
  ASSERT_TRUE(eventually([&] { return state_says_up(tree.hospital_dir, kHome2); }));
  auto refused = remote_query(hospital, {.target = kHome2, .area = kHome2 + "/bedroom"}, 10s, [](const node::Record&) {});
  ASSERT_FALSE(refused);
  EXPECT_NE(refused.error().message.find("area"), std::string::npos) << refused.error().message;
}

// P7a: a removal follows the copies the links sent, hop by hop: a whole item, part of one, one
// removed before it went up, one removed while the link was cut, all through a lossy bus.
TEST(Link, WhatIsRemovedBelowIsRemovedAtEveryNodeAboveThatGotIt) {
  Tree tree;
  tree.bus.set_faults({.seed = 5, .drop = 0.2, .duplicate = 0.1, .reorder = 0.1});
  const std::string sensor_dir = (tree.tmp / "ecg1").string();
  auto sensor_link = tree.start_three_tiers(sensor_dir);
  auto sensor = node::Node::open(sensor_dir).value();
  auto hrv = sensor.agent("hrv").value();
  std::vector<std::uint64_t> ids;
  for (int i = 0; i < 20; ++i) ids.push_back(hrv.store(hrv_item(i)).value());
  const node::Pattern numbered{.p = Term::iri(kEx + "n")};
  ASSERT_TRUE(eventually([&] { return count(tree.hospital_dir, numbered) == 20 && count(tree.home1_dir, numbered) == 20; }));
  // Whole items 3 and 4, and the number of item 7 only.
  ASSERT_TRUE(sensor.remove_item(ids[3]));
  ASSERT_TRUE(sensor.remove_item(ids[4]));
  ASSERT_EQ(sensor.remove({.s = Term::iri(kHome1 + "/rec/hrv/7"), .p = Term::iri(kEx + "n")}).value(), 1u);
  // Cut: the sensor's link stops, an item goes, the link comes back.
  sensor_link.reset();
  ASSERT_TRUE(sensor.remove_item(ids[10]));
  sensor_link = Link::start({.dir = sensor_dir, .parent_iri = kHome1,
                             .up = std::shared_ptr<Transport>(tree.bus.open(kHome1 + "/ecg1", tree.home2_log.sink())),
                             .resend_after = 100ms, .heartbeat_every = 200ms, .log = tree.home2_log.sink()})
                    .value();
  // One stored and removed at once, before it could go up.
  ASSERT_TRUE(sensor.remove_item(hrv.store(hrv_item(99)).value()));
  const node::Pattern hrv_windows{.p = kObservedProperty, .o = kHrvProperty};
  for (const std::string& dir : {tree.hospital_dir, tree.home1_dir}) {
    EXPECT_TRUE(eventually([&] { return count(dir, numbered) == 16 && count(dir, hrv_windows) == 17; }))
        << dir << ": " << count(dir, numbered) << " numbers, " << count(dir, hrv_windows) << " windows";
    for (int gone : {3, 4, 7, 10, 99})
      EXPECT_EQ(count(dir, {.s = Term::iri(kHome1 + "/rec/hrv/" + std::to_string(gone)), .p = Term::iri(kEx + "n")}), 0u) << gone;
  }
  // The applier counts a removal after its write commits: the counts above can show it first.
  EXPECT_TRUE(eventually([&] { return tree.hospital->counters().removals_applied >= 4u; }))
      << tree.hospital->counters().removals_applied << " removals applied";
  // The sensor keeps what it was not asked to remove.
  EXPECT_EQ(count(sensor_dir, hrv_windows), 17u);
}

// A state replaced while the parent is stopped: when it is back, each replaced state comes up
// with its removal in one run, and the parent ends with the last state only.
TEST(Link, AStateReplacedWhileTheParentIsStoppedEndsAsTheLastStateThere) {
  Tree tree;
  ASSERT_TRUE(tree.start_hospital_and_home1());
  auto home = node::Node::open(tree.home1_dir).value();
  auto hrv = home.agent("hrv").value();
  ASSERT_TRUE(hrv.store(hrv_item(0)));
  const node::Pattern numbered{.p = Term::iri(kEx + "n")};
  ASSERT_TRUE(eventually([&] { return count(tree.hospital_dir, numbered) == 1; }));
  tree.hospital.reset();
  for (int i = 1; i <= 6; ++i)
    ASSERT_TRUE(hrv.replace({{.p = Term::iri(kEx + "n")}}, {hrv_item(i)}));
  tree.hospital = tree.start_hospital();
  EXPECT_TRUE(eventually([&] {
    auto states = node::Node::open(tree.hospital_dir).value().snapshot().value().list(numbered).value();
    return states.size() == 1 && states[0].triple.o == Term::integer(6) && outbox(tree.home1_dir) == 0;
  })) << count(tree.hospital_dir, numbered) << " states at the hospital";
  // Only the number went each time: the windows' other record stays, one per replaced state.
  EXPECT_EQ(count(tree.hospital_dir, {.p = kObservedProperty}), 7u);
}

// P10a: configuration removed where it was written is removed where it went, and the settings
// sent to a whole subtree with it.
TEST(Link, ConfigurationRemovedAtTheHospitalIsRemovedBelowHopByHop) {
  Tree tree;
  const std::string sensor_iri = kHome1 + "/ecg1";
  const std::string sensor_dir = (tree.tmp / "ecg1").string();
  auto sensor_link = tree.start_three_tiers(sensor_dir);
  tree.home2 = tree.start_home(tree.home2_dir, kHome2, tree.home2_log);
  ASSERT_TRUE(eventually([&] { return tree.home2->connected(); }));
  auto hospital = node::Node::open(tree.hospital_dir).value();
  auto operator_ = hospital.agent("operator").value();
  node::Item rate;
  rate.context = sensor_iri + "/source";
  rate.add(Term::iri(sensor_iri + "/source"), Term::iri(kEx + "rateHz"), Term::integer(250));
  const std::uint64_t rate_id = operator_.store(rate).value();
  node::Item all;
  all.context = kHospital + "/*";
  all.add(Term::iri(kHospital), Term::iri(kEx + "notice"), Term::literal("maintenance"));
  const std::uint64_t all_id = operator_.store(all).value();
  const node::Pattern rates{.p = Term::iri(kEx + "rateHz")}, notices{.p = Term::iri(kEx + "notice")};
  ASSERT_TRUE(eventually([&] {
    return count(sensor_dir, rates) == 1 && count(tree.home1_dir, rates) == 1 && count(sensor_dir, notices) == 1 &&
           count(tree.home2_dir, notices) == 1;
  }));
  // A setting written at home1 for the sensor stays: the removal names the hospital's only.
  auto local = node::Node::open(tree.home1_dir).value().agent("operator").value();
  node::Item own = rate;
  own.triples[0].o = Term::integer(125);
  ASSERT_TRUE(local.store(own));
  ASSERT_TRUE(eventually([&] { return count(sensor_dir, rates) == 2; }));
  ASSERT_TRUE(hospital.remove_item(rate_id));
  ASSERT_TRUE(hospital.remove_item(all_id));
  EXPECT_TRUE(eventually([&] {
    return count(sensor_dir, rates) == 1 && count(tree.home1_dir, rates) == 1 && count(sensor_dir, notices) == 0 &&
           count(tree.home1_dir, notices) == 0 && count(tree.home2_dir, notices) == 0;
  }));
  auto left = node::Node::open(sensor_dir).value().snapshot().value().list(rates).value();
  ASSERT_EQ(left.size(), 1u);
  EXPECT_EQ(left[0].triple.o.value, "125");
  // The agent it addressed never sees a removal notice: the setting it had not taken left its
  // input buffer with the store, and the one that stays is there.
  auto source = node::Node::open(sensor_dir).value().agent("source").value();
  std::vector<std::string> taken;
  while (auto d = source.take(0ms).value()) {
    EXPECT_FALSE(d->removal);
    taken.push_back(d->records.at(0).triple.o.value);
  }
  EXPECT_EQ(taken, std::vector<std::string>{"125"});
}

}  // namespace
}  // namespace tahvel::federation
