// The raw latency floors (floors.h) return sane figures: the smoke test of the benchmark's
// reference points. The figures are printed, never compared against a time.
#include "tahvel/federation/floors.h"

#include <gtest/gtest.h>

#include <cstdlib>
#include <iostream>

#include "wire_settings.h"

namespace tahvel::federation {
namespace {

void require_netns() {
  const char* in = std::getenv("TAHVEL_IN_NETNS");
  ASSERT_TRUE(in != nullptr && std::string(in) == "1")
      << "the floors send packets: run under tests/tools/netns-run";
}

void expect_sane(const char* name, const Result<LatencyFloor>& floor, int rounds) {
  ASSERT_TRUE(floor) << floor.error().message;
  std::cout << "[ floor ] " << name << " one-way p50 " << floor->p50_us << " us, p99 "
            << floor->p99_us << " us over " << floor->rounds << " rounds\n";
  EXPECT_EQ(floor->rounds, rounds);
  EXPECT_GT(floor->p50_us, 0.0);
  EXPECT_GE(floor->p99_us, floor->p50_us);
}

TEST(Floors, RawLcmPingPongGivesSaneFigures) {
  require_netns();
  expect_sane("lcm", raw_lcm_pingpong(conformance::test_lcm_settings(), 500), 500);
}

TEST(Floors, RawDdsPingPongGivesSaneFigures) {
  require_netns();
  expect_sane("dds", raw_dds_pingpong(conformance::test_dds_settings(), 500), 500);
}

TEST(Floors, ZeroRoundsIsAnError) {
  auto lcm = raw_lcm_pingpong(conformance::test_lcm_settings(), 0);
  ASSERT_FALSE(lcm);
  EXPECT_EQ(lcm.error().code, Errc::invalid_argument);
  auto dds = raw_dds_pingpong(conformance::test_dds_settings(), 0);
  ASSERT_FALSE(dds);
  EXPECT_EQ(dds.error().code, Errc::invalid_argument);
}

}  // namespace
}  // namespace tahvel::federation
