// A link over Cyclone DDS in push mode (LinkOptions::push, Transport::on_arrival): frames are
// taken on Cyclone's thread, and every item still arrives once; with push mode off a thread of
// the link's takes them all (docs/architecture.md).
#include <gtest/gtest.h>

#include <chrono>
#include <cstdlib>
#include <string>
#include <thread>

#include "tahvel/federation/link.h"
#include "tahvel/node/node.h"
#include "temp_dir.h"
#include "wire_settings.h"

namespace tahvel::federation {
namespace {

using namespace std::chrono_literals;
using node::Term;

const std::string kHospital = "http://example.org/push-hospital";
const std::string kHome = kHospital + "/home1";

template <class F>
bool eventually(F condition) {
  const auto deadline = std::chrono::steady_clock::now() + 20s;
  while (std::chrono::steady_clock::now() < deadline) {
    if (condition()) return true;
    std::this_thread::sleep_for(10ms);
  }
  return condition();
}

std::uint64_t numbered(const std::string& dir) {
  auto node = node::Node::open(dir).value();
  return node.snapshot().value().count({.p = Term::iri("http://example.org/n")}).value();
}

std::shared_ptr<Transport> dds(const std::string& iri) {
  return std::shared_ptr<Transport>(open_dds(conformance::test_dds_settings(), iri).value());
}

class LinkOverDds : public ::testing::TestWithParam<bool> {
 protected:
  void SetUp() override {
    const char* in = std::getenv("TAHVEL_IN_NETNS");
    ASSERT_TRUE(in != nullptr && std::string(in) == "1") << "sends packets: run under tests/tools/netns-run";
  }
};

TEST_P(LinkOverDds, ItemsArriveOnceEachAndInPushModeAreTakenOnCyclonesThread) {
  const bool push = GetParam();
  test_support::TempDir tmp("tahvel-push");
  const std::string hospital_dir = (tmp / "hospital").string(), home_dir = (tmp / "home").string();
  ASSERT_TRUE(node::Node::init(hospital_dir, {.iri = kHospital}));
  ASSERT_TRUE(node::Node::init(home_dir, {.iri = kHome}));
  auto hospital = Link::start({.dir = hospital_dir, .down = dds(kHospital), .children = {"home1"}, .push = push}).value();
  auto home = Link::start({.dir = home_dir, .parent_iri = kHospital, .up = dds(kHome), .push = push}).value();
  ASSERT_TRUE(eventually([&] { return home->connected(); }));

  auto hrv = node::Node::open(home_dir).value().agent("hrv").value();
  constexpr int kItems = 200;
  for (int n = 0; n < kItems; ++n) {
    const Term obs = Term::iri(kHome + "/rec/hrv/" + std::to_string(n));
    node::Item item;
    item.add(obs, Term::iri("http://www.w3.org/ns/sosa/observedProperty"),
             Term::iri(std::string(vocab::kTv) + "HeartRateVariability"))
        .add(obs, Term::iri("http://example.org/n"), Term::integer(n));
    ASSERT_TRUE(hrv.store(item));
  }
  ASSERT_TRUE(eventually([&] { return numbered(hospital_dir) >= kItems; })) << numbered(hospital_dir) << " of " << kItems;
  std::this_thread::sleep_for(300ms);
  EXPECT_EQ(numbered(hospital_dir), static_cast<std::uint64_t>(kItems));
  EXPECT_EQ(hospital->counters().relayed_in, static_cast<std::uint64_t>(kItems));
  if (push) {
    EXPECT_GT(hospital->counters().taken_pushed, 0u) << "no frame was taken on the transport's thread";
    EXPECT_GT(home->counters().taken_pushed, 0u) << "no ack was taken on the transport's thread";
  } else {
    EXPECT_EQ(hospital->counters().taken_pushed, 0u);
    EXPECT_EQ(home->counters().taken_pushed, 0u);
  }
  home.reset();
  hospital.reset();
}

INSTANTIATE_TEST_SUITE_P(Push, LinkOverDds, ::testing::Values(true, false),
                         [](const ::testing::TestParamInfo<bool>& info) { return info.param ? "On" : "Off"; });

}  // namespace
}  // namespace tahvel::federation
