// The wire bindings between two processes (tahvel_transport_peer), the way nodes use them: a
// receiver that is open before the sender starts gets the frames sent right after the sender
// opened (for DDS: send() waits for discovery, docs/transports.md), and frames go both ways.
// Each frame is sent once, so this also shows that LCM loses nothing on an idle loopback.
#include <gtest/gtest.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdlib>
#include <set>
#include <string>
#include <vector>

#include "wire_settings.h"

extern char** environ;

namespace tahvel::federation {
namespace {

using namespace std::chrono_literals;

class WireBetweenProcesses : public ::testing::TestWithParam<std::string> {
 protected:
  void SetUp() override {
    const char* in = std::getenv("TAHVEL_IN_NETNS");
    ASSERT_TRUE(in != nullptr && std::string(in) == "1")
        << "sends packets: run under tests/tools/netns-run";
  }

  std::unique_ptr<Transport> open(const std::string& iri) {
    auto t = GetParam() == "lcm" ? open_lcm(conformance::test_lcm_settings(), iri)
                                 : open_dds(conformance::test_dds_settings(), iri);
    EXPECT_TRUE(t) << (t ? "" : t.error().message);
    return t ? std::move(*t) : nullptr;
  }

  static std::string iri(const std::string& name) {
    return "tahvel://process-test/" + std::to_string(getpid()) + "/" + name;
  }

  // Starts the peer; returns its pid (or -1).
  static pid_t spawn(std::vector<std::string> args) {
    args.insert(args.begin(), TAHVEL_PEER_PATH);
    std::vector<char*> argv;
    for (auto& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    pid_t pid = -1;
    if (posix_spawn(&pid, TAHVEL_PEER_PATH, nullptr, nullptr, argv.data(), environ) != 0) return -1;
    return pid;
  }

  static int wait_exit(pid_t pid) {
    int status = 0;
    if (waitpid(pid, &status, 0) != pid) return -1;
    return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  }
};

TEST_P(WireBetweenProcesses, FramesSentRightAfterOpenReachAnEarlierReceiver) {
  auto receiver = open(iri("receiver"));
  ASSERT_TRUE(receiver);
  pid_t peer = spawn({GetParam(), iri("sender"), receiver->self(), "20"});
  ASSERT_GT(peer, 0);
  std::set<std::uint64_t> seqs;
  while (seqs.size() < 20) {
    auto got = receiver->receive(15s);
    ASSERT_TRUE(got) << got.error().message;
    if (!*got) break;
    EXPECT_EQ((*got)->body, "peer " + std::to_string((*got)->seq));
    EXPECT_EQ((*got)->from, iri("sender"));
    seqs.insert((*got)->seq);
  }
  EXPECT_EQ(wait_exit(peer), 0);
  EXPECT_EQ(seqs.size(), 20u) << "frames sent once right after the sender opened were lost";
}

TEST_P(WireBetweenProcesses, FramesGoBothWays) {
  auto local = open(iri("local"));
  ASSERT_TRUE(local);
  const std::string remote = iri("remote");
  pid_t peer = spawn({GetParam(), remote, local->self(), "1", "echo"});
  ASSERT_GT(peer, 0);
  // The peer's first frame says it is up; then each of ours comes back.
  auto hello = local->receive(15s);
  ASSERT_TRUE(hello && *hello) << "no first frame from the peer";
  std::set<std::uint64_t> echoed;
  for (std::uint64_t i = 100; i < 150; ++i) {
    Frame f;
    f.kind = FrameKind::query;
    f.from = local->self();
    f.to = remote;
    f.seq = i;
    f.body = std::string(1000, static_cast<char>(i));
    ASSERT_TRUE(local->send(f));
    auto back = local->receive(15s);
    ASSERT_TRUE(back && *back) << "no echo of seq " << i;
    EXPECT_EQ((*back)->seq, i);
    EXPECT_EQ((*back)->body, f.body);
    EXPECT_EQ((*back)->from, remote);
    echoed.insert((*back)->seq);
  }
  Frame stop;
  stop.kind = FrameKind::error;
  stop.from = local->self();
  stop.to = remote;
  ASSERT_TRUE(local->send(stop));
  EXPECT_EQ(wait_exit(peer), 0);
  EXPECT_EQ(echoed.size(), 50u);
}

INSTANTIATE_TEST_SUITE_P(Wire, WireBetweenProcesses, ::testing::Values("lcm", "dds"),
                         [](const auto& info) { return info.param; });

}  // namespace
}  // namespace tahvel::federation
