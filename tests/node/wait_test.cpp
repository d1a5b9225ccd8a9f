// Waiting for the board: a thread in take or watch first spins on the store's wake word, then
// sleeps on the futex (node.h, "Waiting"). Whichever way a waiter ends up waiting, no item and no
// commit may be missed: these cases run with spinning off, and on with gaps between the writes
// both shorter and longer than the budget, so that spins that see the word move, spins that run
// out into a sleep, and the quiet mode all meet a writer.
#include <gtest/gtest.h>

#include <pthread.h>
#include <signal.h>

#include <atomic>
#include <chrono>
#include <random>
#include <thread>

#include "test_support.h"
#include "tahvel/node/node.h"

namespace tahvel::node {
namespace {

using namespace std::chrono_literals;
using testing::ex;
using testing::make_node;
using testing::TempDir;

// Restores the process's spin budget after a case.
class SpinBudget {
 public:
  explicit SpinBudget(std::chrono::microseconds budget) : before_(wait_spin()) { set_wait_spin(budget); }
  ~SpinBudget() { set_wait_spin(before_); }

 private:
  std::chrono::microseconds before_;
};

// Gaps between writes around the spin budget: a third well inside, a third just past it, a third
// far past it (the waiter has long gone to sleep).
std::chrono::microseconds gap(std::mt19937& rng, std::chrono::microseconds budget) {
  const auto b = std::max<std::int64_t>(budget.count(), 50);
  switch (rng() % 3) {
    case 0: return std::chrono::microseconds(rng() % (b / 2 + 1));
    case 1: return std::chrono::microseconds(b + static_cast<std::int64_t>(rng() % b));
    default: return std::chrono::microseconds(5 * b);
  }
}

// After a gap drawn by `rng`, `agent` stores the one-triple item `subject predicate n`: the
// writes every case below makes at irregular times.
Result<std::uint64_t> store_after_gap(Agent& agent, std::mt19937& rng, const std::string& subject,
                                      const std::string& predicate, int n) {
  std::this_thread::sleep_for(gap(rng, wait_spin()));
  return agent.store(Item{}.add(ex(subject), ex(predicate), Term::integer(n)));
}

class Waiting : public ::testing::TestWithParam<int> {};

TEST_P(Waiting, PingPongBetweenTwoAgentsLosesNoWakeUp) {
  SpinBudget budget{std::chrono::microseconds(GetParam())};
  TempDir dir;
  make_node(dir.path());
  auto node = Node::open(dir.path());
  auto agent = node->agent("ping");
  ASSERT_TRUE(agent->subscribe(Pattern{.p = ex("pong")}));
  ASSERT_TRUE(node->agent("pong")->subscribe(Pattern{.p = ex("ping")}));
  constexpr int kRounds = 300;
  std::thread responder([&] {
    auto node = Node::open(dir.path());
    auto agent = node->agent("pong");
    std::mt19937 rng(7);
    for (int i = 0; i < kRounds; ++i) {
      auto d = agent->take(20s);
      ASSERT_TRUE(d && *d) << "ping " << i << " never woke the responder";
      ASSERT_TRUE(store_after_gap(*agent, rng, "r" + std::to_string(i), "pong", i));
    }
  });
  std::mt19937 rng(11);
  int answered = 0;
  for (int i = 0; i < kRounds; ++i) {
    ASSERT_TRUE(store_after_gap(*agent, rng, "q" + std::to_string(i), "ping", i));
    auto d = agent->take(20s);
    if (!d || !*d) break;
    ASSERT_EQ((*d)->records.at(0).triple.o, Term::integer(i));
    ++answered;
  }
  responder.join();
  EXPECT_EQ(answered, kRounds);
}

TEST_P(Waiting, AWatcherSeesEveryCommitInOrder) {
  SpinBudget budget{std::chrono::microseconds(GetParam())};
  TempDir dir;
  Node node = make_node(dir.path());
  const std::uint64_t start = node.snapshot()->last_seq();
  constexpr int kItems = 400;
  std::thread writer([&] {
    auto mine = Node::open(dir.path());
    auto agent = mine->agent("writer");
    std::mt19937 rng(5);
    for (int i = 0; i < kItems; ++i) {
      ASSERT_TRUE(store_after_gap(*agent, rng, "o" + std::to_string(i), "n", i));
    }
  });
  std::uint64_t bookmark = start;
  int next = 0;
  while (next < kItems) {
    auto changes = node.watch(bookmark, 20s);
    ASSERT_TRUE(changes);
    if (changes->empty()) break;  // 20 s without a commit it was woken for
    for (const Change& c : *changes) {
      bookmark = c.seq;
      ASSERT_EQ(c.record.triple.o, Term::integer(next)) << "after " << next << " items";
      ++next;
    }
  }
  writer.join();
  EXPECT_EQ(next, kItems);
}

INSTANTIATE_TEST_SUITE_P(SpinBudgets, Waiting, ::testing::Values(0, 200),
                         [](const ::testing::TestParamInfo<int>& info) {
                           return info.param == 0 ? std::string("SleepingOnly") : "Spinning" + std::to_string(info.param) + "us";
                         });

TEST(WaitSpin, IsSetForTheWholeProcessAndNeverNegative) {
  SpinBudget budget{50us};
  EXPECT_EQ(wait_spin(), 50us);
  set_wait_spin(-5us);
  EXPECT_EQ(wait_spin(), 0us);
}

// "Wait forever" as a C++ caller writes it: milliseconds::max() used to wrap to a deadline in the
// past, and take returned at once, turning an agent's loop into a busy spin.
TEST(Wait, ATakeWithTheLongestTimeoutWaitsForTheItem) {
  TempDir dir;
  Node node = make_node(dir.path());
  Agent reader = node.agent("reader").value();
  ASSERT_TRUE(reader.subscribe({.p = ex("value")}));
  std::thread writer([&] {
    std::this_thread::sleep_for(200ms);
    Item item;
    item.add(ex("s"), ex("value"), Term::integer(1));
    ASSERT_TRUE(node.agent("writer").value().store(item));
  });
  for (auto timeout : {std::chrono::milliseconds::max(), std::chrono::milliseconds(std::chrono::hours(24 * 365 * 300))}) {
    auto got = reader.take(timeout, Ack::manual);
    ASSERT_TRUE(got);
    EXPECT_TRUE(*got) << "returned without an item";
  }
  writer.join();
  ASSERT_TRUE(reader.take(0ms, Ack::automatic).value());  // the item, acknowledged
  const auto asked = std::chrono::steady_clock::now();
  EXPECT_FALSE(reader.take(-1ms).value()) << "nothing is there";
  EXPECT_LT(std::chrono::steady_clock::now() - asked, 1s) << "a negative timeout waited";
}

extern "C" void ignore_signal(int) {}

// An agent stops on SIGTERM by a flag its handler sets; a handler installed without SA_RESTART
// ends a wait, so the agent sees the flag instead of waiting on for an item that may never come.
TEST(Wait, ASignalHandlerEndsAWaitAsATimeout) {
  TempDir dir;
  Node node = make_node(dir.path());
  Agent reader = node.agent("reader").value();
  ASSERT_TRUE(reader.subscribe({.p = ex("value")}));
  struct sigaction action {}, before {};
  action.sa_handler = ignore_signal;
  sigemptyset(&action.sa_mask);
  action.sa_flags = 0;  // no SA_RESTART
  ASSERT_EQ(sigaction(SIGUSR1, &action, &before), 0);
  const pthread_t waiting = pthread_self();
  std::atomic<bool> done{false};
  std::thread signaller([&] {
    // Until the wait ends: a signal sent before the thread sleeps only cuts its spin short.
    for (int i = 0; i < 100 && !done; ++i) {
      std::this_thread::sleep_for(50ms);
      pthread_kill(waiting, SIGUSR1);
    }
  });
  const auto asked = std::chrono::steady_clock::now();
  auto got = reader.take(std::chrono::milliseconds::max());
  done = true;
  signaller.join();
  sigaction(SIGUSR1, &before, nullptr);
  ASSERT_TRUE(got);
  EXPECT_FALSE(*got);
  EXPECT_LT(std::chrono::steady_clock::now() - asked, 5s) << "the wait went on after the signal";
}

}  // namespace
}  // namespace tahvel::node
