// Several processes on one store: a subscriber in another process woken without polling and
// served each item once across its restarts; writers killed with SIGKILL mid-write while
// readers check that no half item is ever visible.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <lmdb.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <random>
#include <set>
#include <thread>

#include "../node/test_support.h"
#include "tahvel/node/node.h"

namespace tahvel::node {
namespace {

using namespace std::chrono_literals;
using testing::ex;
using testing::make_node;
using testing::TempDir;

// Runs `child` in a forked process whose exit status is child()'s return value. The child opens
// its own Node: an LMDB handle must never cross fork().
template <class F>
pid_t spawn(F child) {
  pid_t pid = fork();
  if (pid == 0) {
    int status = 1;
    try {
      status = child();
    } catch (...) {
      status = 99;
    }
    _exit(status);
  }
  return pid;
}

int wait_exit(pid_t pid, std::chrono::seconds limit = 60s) {
  auto deadline = std::chrono::steady_clock::now() + limit;
  int status = 0;
  while (waitpid(pid, &status, WNOHANG) == 0) {
    if (std::chrono::steady_clock::now() > deadline) {
      kill(pid, SIGKILL);
      waitpid(pid, &status, 0);
      return -1;  // a survivor that blocked
    }
    std::this_thread::sleep_for(5ms);
  }
  return WIFEXITED(status) ? WEXITSTATUS(status) : -WTERMSIG(status);
}

// Reads whitespace-separated integers a child wrote to a pipe.
std::vector<std::uint64_t> read_ids(int fd) {
  std::vector<std::uint64_t> ids;
  FILE* in = fdopen(fd, "r");
  unsigned long long id = 0;
  while (fscanf(in, "%llu", &id) == 1) ids.push_back(id);
  fclose(in);
  return ids;
}

Item measurement(int i, int parts) {
  Item item;
  Term s = ex("obs" + std::to_string(i));
  for (int k = 0; k < parts; ++k) item.add(s, ex("part"), Term::integer(k));
  return item;
}

// A reader killed (SIGKILL, the OOM killer) while it holds a snapshot leaves its LMDB reader
// slot behind, and no page freed after that snapshot is used again while the slot stays: a
// ring store's writers that ran on took new pages for every write and failed with store_full,
// the store nearly empty, until some process opened the store (the only place slots of dead
// processes were cleared).
TEST(Processes, AReaderKilledHoldingItsSnapshotDoesNotFillTheStoreOfWritersThatRunOn) {
  TempDir dir;
  Node node = make_node(dir.path(), {.ring = 100, .max_map_bytes = 8 << 20});
  auto writer = node.agent("w");
  ASSERT_TRUE(writer);
  ASSERT_TRUE(writer->store(measurement(0, 3)));
  int ready[2];
  ASSERT_EQ(pipe(ready), 0);
  pid_t reader = spawn([&] {
    close(ready[0]);
    auto opened = Node::open(dir.path());
    if (!opened) return 2;
    auto snapshot = opened->snapshot();
    if (!snapshot) return 3;
    if (write(ready[1], "x", 1) != 1) return 4;
    pause();  // holds the snapshot until killed
    return 0;
  });
  close(ready[1]);
  char c = 0;
  ASSERT_EQ(read(ready[0], &c, 1), 1) << "the reader did not take its snapshot";
  close(ready[0]);
  kill(reader, SIGKILL);
  EXPECT_EQ(wait_exit(reader), -SIGKILL);
  for (int i = 1; i <= 5000; ++i) {
    auto stored = writer->store(measurement(i, 3));
    ASSERT_TRUE(stored) << "write " << i << ": " << stored.error().message;
  }
}

TEST(Processes, SubscriberInAnotherProcessGetsEachItemOnceAcrossRestarts) {
  TempDir dir;
  {
    Node node = make_node(dir.path());
    ASSERT_TRUE(node.agent("sub")->subscribe(Pattern{.p = ex("hr")}));
  }
  constexpr int kItems = 300;
  int pipe_fds[2];
  ASSERT_EQ(pipe(pipe_fds), 0);
  // The subscriber: a new process each round (a restart), taking up to 40 items per life.
  pid_t subscriber = spawn([&] {
    close(pipe_fds[0]);
    int taken = 0;
    while (taken < kItems) {
      pid_t life = spawn([&] {
        auto node = Node::open(dir.path());
        if (!node) return 2;
        auto agent = node->agent("sub");
        for (int n = 0; n < 40; ++n) {
          auto d = agent->take(20s);
          if (!d || !*d) return 3;
          dprintf(pipe_fds[1], "%llu\n", static_cast<unsigned long long>((*d)->item));
        }
        return 0;
      });
      if (wait_exit(life) != 0) return 4;
      taken += 40;
    }
    return 0;
  });
  close(pipe_fds[1]);
  pid_t writer = spawn([&] {
    auto node = Node::open(dir.path());
    if (!node) return 2;
    auto agent = node->agent("writer");
    for (int i = 0; i < kItems + 20; ++i) {
      if (!agent->store(Item{}.add(ex("o" + std::to_string(i)), ex("hr"), Term::integer(60 + i % 50)))) return 3;
      if (!agent->store(Item{}.add(ex("o" + std::to_string(i)), ex("spo2"), Term::integer(97)))) return 3;
      if (i % 7 == 0) std::this_thread::sleep_for(1ms);
    }
    return 0;
  });
  EXPECT_EQ(wait_exit(writer), 0);
  std::vector<std::uint64_t> got = read_ids(pipe_fds[0]);
  EXPECT_EQ(wait_exit(subscriber), 0);
  std::set<std::uint64_t> unique(got.begin(), got.end());
  EXPECT_EQ(got.size(), 320u);  // 8 lives x 40
  EXPECT_EQ(unique.size(), got.size()) << "an item was delivered twice";
  // Everything delivered matched, in order, and the rest is still waiting.
  EXPECT_TRUE(std::is_sorted(got.begin(), got.end()));
  auto node = Node::open(dir.path());
  EXPECT_EQ(*node->agent("sub")->pending(), 0u);
  for (std::uint64_t id : got) EXPECT_EQ(node->snapshot()->item(id)->front().triple.p, ex("hr"));
}

// A write that declares a subscription and then fails has touched this process's subscription
// cache. Another process's subscription then brings the store to the generation that cache had
// reached: this process must route by what the store holds, not by what it had cached.
TEST(Processes, AFailedWriteThatDeclaredASubscriptionLeavesNoSubscriptionBehindInTheCache) {
  TempDir dir;
  Node node = make_node(dir.path());
  Agent writer = node.agent("writer").value();
  Agent phantom = node.agent("phantom").value();
  // The cache is current, and the phantom's IRI has its dictionary id (else the failed write's
  // new id would be handed out again, to the other process's subscriber).
  ASSERT_TRUE(phantom.store(Item{}.add(ex("warm"), ex("other"), Term::integer(0))));
  const Term declared = Term::blank("subscription");
  Item declaration;
  declaration.add(declared, Term::iri("https://w3id.org/tahvel#subscriber"), Term::iri(phantom.iri()))
      .add(declared, Term::iri("https://w3id.org/tahvel#predicate"), ex("hr"));
  Item refused;  // its IRI is refused as it enters the dictionary: the transaction aborts
  refused.add(Term::iri("not an iri"), ex("hr"), Term::integer(1));
  ASSERT_FALSE(writer.store_all({declaration, refused}).has_value());
  pid_t other = spawn([&] {
    auto n = Node::open(dir.path());
    if (!n) return 2;
    return n->agent("real")->subscribe(Pattern{.p = ex("hr")}) ? 0 : 3;
  });
  ASSERT_EQ(wait_exit(other), 0);
  ASSERT_TRUE(writer.store(Item{}.add(ex("obs"), ex("hr"), Term::integer(72))));
  auto to_real = node.agent("real")->take(0ms);
  ASSERT_TRUE(to_real.has_value()) << to_real.error().message;
  EXPECT_TRUE(to_real->has_value()) << "the subscription made in the other process got nothing";
  auto to_phantom = phantom.take(0ms);
  ASSERT_TRUE(to_phantom.has_value()) << to_phantom.error().message;
  EXPECT_FALSE(to_phantom->has_value()) << "the subscription of the failed write received an item";
}

TEST(Processes, WaitingSubscriberSleepsInsteadOfPolling) {
  TempDir dir;
  make_node(dir.path());
  int pipe_fds[2];
  ASSERT_EQ(pipe(pipe_fds), 0);
  pid_t waiter = spawn([&] {
    auto node = Node::open(dir.path());
    auto agent = node->agent("idle");
    if (!agent->subscribe(Pattern{.p = ex("never")})) return 2;
    rusage before{}, after{};
    getrusage(RUSAGE_SELF, &before);
    auto d = agent->take(1500ms);
    getrusage(RUSAGE_SELF, &after);
    if (!d || *d) return 3;
    // Then a real wake-up.
    dprintf(pipe_fds[1], "%ld\n", after.ru_nvcsw - before.ru_nvcsw);
    close(pipe_fds[1]);
    auto woken = agent->take(20s);
    return woken && *woken ? 0 : 4;
  });
  close(pipe_fds[1]);
  auto switches = read_ids(pipe_fds[0]);
  ASSERT_EQ(switches.size(), 1u);
  // A polling loop would switch hundreds of times in 1.5 s; a futex sleep does a handful.
  EXPECT_LE(switches[0], 5u);
  auto node = Node::open(dir.path());
  ASSERT_TRUE(node->agent("w")->store(Item{}.add(ex("x"), ex("never"), Term::integer(1))));
  EXPECT_EQ(wait_exit(waiter, 30s), 0);
}

TEST(Processes, WritersKilledMidWriteNeverLeaveHalfItems) {
  TempDir dir;
  make_node(dir.path());
  constexpr int kParts = 10;
  std::atomic<bool> stop{false};
  int pipe_fds[2];
  ASSERT_EQ(pipe(pipe_fds), 0);
  auto start_writer = [&](int w) {
    return spawn([&, w] {
      close(pipe_fds[0]);
      auto node = Node::open(dir.path());
      if (!node) return 2;
      auto agent = node->agent("writer" + std::to_string(w));
      for (int i = 0;; ++i) {
        auto id = agent->store(measurement(w * 1'000'000 + i, kParts));
        if (!id) return 3;
        dprintf(pipe_fds[1], "%llu\n", static_cast<unsigned long long>(*id));
      }
    });
  };
  auto start_reader = [&] {
    return spawn([&] {
      close(pipe_fds[0]);
      close(pipe_fds[1]);
      auto node = Node::open(dir.path());
      if (!node) return 2;
      auto deadline = std::chrono::steady_clock::now() + 4s;
      while (std::chrono::steady_clock::now() < deadline) {
        {
          auto snap = node->snapshot();
          if (!snap) return 3;
          auto parts = snap->count(Pattern{.p = ex("part")});
          if (!parts || *parts % kParts != 0) return 4;  // a half item is visible
        }
        auto stats = node->stats();
        if (!stats) return 5;
      }
      return 0;
    });
  };
  std::vector<pid_t> readers;
  for (int r = 0; r < 4; ++r) readers.push_back(start_reader());
  std::vector<pid_t> writers;
  for (int w = 0; w < 4; ++w) writers.push_back(start_writer(w));
  std::mt19937 rng(7);
  for (int round = 0; round < 24; ++round) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20 + rng() % 80));
    int w = round % 4;
    kill(writers[w], SIGKILL);
    int status = 0;
    waitpid(writers[w], &status, 0);
    writers[w] = start_writer(w);
  }
  for (pid_t w : writers) kill(w, SIGKILL);
  for (pid_t w : writers) waitpid(w, nullptr, 0);
  close(pipe_fds[1]);
  std::vector<std::uint64_t> reported = read_ids(pipe_fds[0]);
  for (pid_t r : readers) EXPECT_EQ(wait_exit(r, 60s), 0) << "a reader saw a half item or blocked";
  (void)stop;

  auto node = Node::open(dir.path());
  ASSERT_TRUE(node) << node.error().message;
  auto stats = node->stats();
  ASSERT_TRUE(stats);
  EXPECT_GT(stats->items, 100u);
  EXPECT_EQ(stats->records, stats->items * kParts);
  auto snap = node->snapshot();
  EXPECT_EQ(*snap->count(Pattern{.p = ex("part")}), stats->records);
  // Every id a writer saw committed is there, whole.
  for (std::size_t i = 0; i < reported.size(); i += 1 + reported.size() / 200) {
    auto item = snap->item(reported[i]);
    ASSERT_TRUE(item) << reported[i];
    EXPECT_EQ(item->size(), static_cast<std::size_t>(kParts));
  }
  // And the store still takes writes.
  EXPECT_TRUE(node->agent("after")->store(measurement(0, kParts)));
}

// A writer that hangs inside its transaction (a stopped or stuck process holds the store's
// write lock) must not hang every process that opens the store to read it: `tahvel status`, an
// operator's `tahvel list`. (Opening took a write transaction, and waited for ever.)
TEST(Processes, AStoreOpensAndReadsWhileAnotherProcessHangsInsideAWriteTransaction) {
  TempDir dir;
  std::uint64_t id = 0;
  {
    Node node = make_node(dir.path());
    id = node.agent("w")->store(measurement(1, 3)).value();
  }
  int ready[2];
  ASSERT_EQ(pipe(ready), 0);
  pid_t writer = spawn([&] {  // holds the write lock, as a writer stopped mid-transaction does
    MDB_env* env = nullptr;
    MDB_txn* txn = nullptr;
    if (mdb_env_create(&env) != 0 || mdb_env_set_maxdbs(env, 32) != 0 || mdb_env_open(env, dir.path().c_str(), 0, 0644) != 0 ||
        mdb_txn_begin(env, nullptr, 0, &txn) != 0)
      return 2;
    (void)!write(ready[1], "1", 1);
    pause();
    return 0;
  });
  close(ready[1]);
  char c = 0;
  ASSERT_EQ(read(ready[0], &c, 1), 1) << "the writer could not take the write lock";
  close(ready[0]);
  pid_t reader = spawn([&] {
    auto opened = Node::open(dir.path());
    if (!opened) return 2;
    auto item = opened->snapshot()->item(id);
    return item && item->size() == 3 ? 0 : 3;
  });
  EXPECT_EQ(wait_exit(reader, 10s), 0) << "-1: opening the store waited for the hung writer";
  kill(writer, SIGKILL);
  waitpid(writer, nullptr, 0);
}

TEST(Processes, OpeningAGrownStoreNeverShrinksItUnderAnotherProcess) {
  TempDir dir;
  Node node = make_node(dir.path());
  auto agent = node.agent("w");
  std::uint64_t last = 0;
  for (int i = 0; i < 160; ++i) {  // ~80 MiB through a 64 MiB first map
    auto id = agent->store(Item{}.add(ex("chunk" + std::to_string(i)), ex("data"),
                                      Term::literal(std::string(1 << 19, 'a' + i % 26) + std::to_string(i))));
    ASSERT_TRUE(id) << id.error().message;
    last = *id;
  }
  const auto grown = std::filesystem::file_size(dir / "data.mdb");
  ASSERT_GT(grown, 64u << 20);
  pid_t other = spawn([&] {
    auto opened = Node::open(dir.path());
    if (!opened) return 2;
    auto item = opened->snapshot()->item(last);
    return item && item->size() == 1 ? 0 : 3;
  });
  EXPECT_EQ(wait_exit(other), 0);
  EXPECT_GE(std::filesystem::file_size(dir / "data.mdb"), grown);
  // This process still reads and writes its whole map.
  EXPECT_EQ(node.snapshot()->item(last)->size(), 1u);
  EXPECT_TRUE(agent->store(Item{}.add(ex("after"), ex("data"), Term::literal(std::string(1 << 19, 'z')))));
}

}  // namespace
}  // namespace tahvel::node
