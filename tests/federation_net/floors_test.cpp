// The raw latency floors (floors.h) return sane figures: the smoke test of the benchmark's
// reference points. The figures are printed, never compared against a time.
#include "tahvel/federation/floors.h"

#include <gtest/gtest.h>

#include <sys/wait.h>
#include <unistd.h>

#include <cstdlib>
#include <functional>
#include <iostream>
#include <thread>

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

// Each round trip split in two legs at the echo's stamp (one machine, one clock): two legs per
// round, and together they are the round trips (twice the halves).
void expect_legs_add_up(const Result<LatencyFloor>& floor) {
  ASSERT_TRUE(floor) << floor.error().message;
  ASSERT_EQ(floor->legs_us.size(), 2 * floor->one_way_us.size());
  double legs = 0, halves = 0;
  for (double us : floor->legs_us) legs += us;
  for (double us : floor->one_way_us) halves += us;
  EXPECT_NEAR(legs, 2 * halves, 1e-6 * legs);
  EXPECT_GE(floor->legs_us.front(), 0.0);
  EXPECT_GT(floor->leg_p50_us, 0.0);
  EXPECT_GE(floor->leg_p99_us, floor->leg_p50_us);
}

TEST(Floors, RawLcmPingPongGivesSaneFigures) {
  require_netns();
  const auto floor = raw_lcm_pingpong(conformance::test_lcm_settings(), 500);
  expect_sane("lcm", floor, 500);
  expect_legs_add_up(floor);
}

TEST(Floors, RawDdsPingPongGivesSaneFigures) {
  require_netns();
  const auto floor = raw_dds_pingpong(conformance::test_dds_settings(), 500);
  expect_sane("dds", floor, 500);
  expect_legs_add_up(floor);
}

// The halves in two processes, as the bench measures them: a forked echo (before this process
// touches LCM or DDS), its readiness through a pipe.
// `legs`: the raw floors split their round trips; the bindings' floor does not.
template <class Echo, class Ping>
void across_processes(const char* name, Echo echo, Ping ping, bool legs = true) {
  int ready[2];
  ASSERT_EQ(pipe(ready), 0);
  const std::string channel = std::string(name) + "_" + std::to_string(getpid());
  pid_t child = fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    close(ready[0]);
    auto done = echo(channel, [&] { (void)!write(ready[1], "r", 1); });
    if (!done) std::cerr << "echo process: " << done.error().message << std::endl;
    _exit(done ? 0 : 1);
  }
  close(ready[1]);
  char c = 0;
  ASSERT_EQ(read(ready[0], &c, 1), 1) << "the echo process never listened";
  close(ready[0]);
  const auto floor = ping(channel);
  expect_sane(name, floor, 300);
  if (legs) expect_legs_add_up(floor);
  int status = 0;
  ASSERT_EQ(waitpid(child, &status, 0), child);
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << "the echo process failed";
}

TEST(Floors, LcmPingPongBetweenTwoProcessesGivesSaneFigures) {
  require_netns();
  const LcmSettings settings = conformance::test_lcm_settings();
  across_processes(
      "lcm_2p",
      [&](const std::string& n, const std::function<void()>& ready) { return lcm_echo(settings, n, ready, std::chrono::seconds(5)); },
      [&](const std::string& n) { return lcm_ping(settings, n, 300); });
}

TEST(Floors, DdsPingPongBetweenTwoProcessesGivesSaneFigures) {
  require_netns();
  const DdsSettings settings = conformance::test_dds_settings();
  across_processes(
      "dds_2p",
      [&](const std::string& n, const std::function<void()>& ready) { return dds_echo(settings, n, ready, std::chrono::seconds(5)); },
      [&](const std::string& n) { return dds_ping(settings, n, 300); });
}

// Through the bindings: the echo opens its endpoint in the forked process, as the bench's far end.
TEST(Floors, DdsBindingPingPongBetweenTwoProcessesGivesSaneFigures) {
  require_netns();
  const DdsSettings settings = conformance::test_dds_settings();
  auto iri = [](const std::string& n, const char* end) { return "http://floors.test/" + n + "/" + end; };
  across_processes(
      "dds_binding",
      [&](const std::string& n, const std::function<void()>& ready) -> Result<void> {
        auto echo = open_dds(settings, iri(n, "echo"), {});
        if (!echo) return node::fail(echo.error().code, echo.error().message);
        ready();
        return binding_echo(**echo, std::chrono::seconds(5));
      },
      [&](const std::string& n) -> Result<LatencyFloor> {
        auto ping = open_dds(settings, iri(n, "ping"), {});
        if (!ping) return node::fail(ping.error().code, ping.error().message);
        return binding_ping(**ping, iri(n, "echo"), 300, 568);
      },
      false);
}

TEST(Floors, BindingPingPongSendsAgainPastLostFramesAndStopsTheEcho) {
  MemoryBus bus;
  bus.set_faults({.seed = 3, .drop = 0.01});
  auto echo = bus.open("http://floors.test/echo");
  auto ping = bus.open("http://floors.test/ping");
  Result<void> echoed{};
  std::thread echoer([&] { echoed = binding_echo(*echo, std::chrono::seconds(10)); });
  auto floor = binding_ping(*ping, "http://floors.test/echo", 100, 100);
  // With one frame in 100 lost, some rounds were lost and sent again; the echo stopped at
  // the ping side's stop frame (three are sent), long before its 10 s of idleness.
  bus.set_faults({});
  const auto t0 = std::chrono::steady_clock::now();
  echoer.join();
  EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::seconds(5)) << "the echo did not stop";
  expect_sane("memory binding", floor, 100);
  EXPECT_TRUE(echoed) << echoed.error().message;
  EXPECT_EQ(binding_ping(*ping, "http://floors.test/echo", 0, 100).error().code, Errc::invalid_argument);
}

TEST(Floors, ZeroRoundsIsAnError) {
  auto lcm = raw_lcm_pingpong(conformance::test_lcm_settings(), 0);
  ASSERT_FALSE(lcm);
  EXPECT_EQ(lcm.error().code, Errc::invalid_argument);
  auto dds = raw_dds_pingpong(conformance::test_dds_settings(), 0);
  ASSERT_FALSE(dds);
  EXPECT_EQ(dds.error().code, Errc::invalid_argument);
  EXPECT_EQ(lcm_ping(conformance::test_lcm_settings(), "zero", 0).error().code, Errc::invalid_argument);
  EXPECT_EQ(dds_ping(conformance::test_dds_settings(), "zero", 0).error().code, Errc::invalid_argument);
}

}  // namespace
}  // namespace tahvel::federation
