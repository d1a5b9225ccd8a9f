// Map growth while other threads of the same process read: LMDB may remap only when the process
// has no transaction active, so growth must keep new transactions from starting meanwhile (a
// race here crashed a hospital's link process with 1,000 children: tahvel bench federation).
#include <gtest/gtest.h>

#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <optional>
#include <fstream>
#include <thread>

#include "test_support.h"

namespace tahvel::node::testing {
namespace {

TEST(Growth, MapGrowsWhileOtherThreadsOfTheProcessKeepReading) {
  TempDir dir;
  Node node = make_node(dir.path());
  const std::uint64_t initial_map = node.stats().value().map_bytes;
  std::atomic<bool> done{false};
  std::atomic<std::uint64_t> reads{0}, failures{0};
  std::vector<std::thread> readers;
  for (int t = 0; t < 4; ++t) {
    readers.emplace_back([&] {
      Node mine = Node::open(dir.path()).value();  // each thread its own handle, as a link does
      while (!done) {
        auto snap = mine.snapshot();
        if (!snap) {
          ++failures;
          continue;
        }
        if (!snap->count({.p = ex("blob")})) ++failures;
        ++reads;
      }
    });
  }
  Agent writer = node.agent("writer").value();
  const std::string blob(64 * 1024, 'x');
  std::uint64_t stored = 0;
  // Distinct literals (the dictionary keeps one copy of each), enough to grow the map twice.
  while (node.stats().value().map_bytes < initial_map * 4 && stored < 20000) {
    Item item;
    item.add(Term::iri(kNodeIri + "/blob/" + std::to_string(stored)), ex("blob"),
             Term::literal(std::to_string(stored) + blob));
    auto id = writer.store(item);
    if (!id) {
      ADD_FAILURE() << "store " << stored << ": " << id.error().message;
      break;
    }
    ++stored;
  }
  done = true;
  for (auto& t : readers) t.join();
  EXPECT_GE(node.stats().value().map_bytes, initial_map * 4);
  EXPECT_EQ(failures.load(), 0u);
  EXPECT_GT(reads.load(), 0u);
  EXPECT_EQ(node.snapshot().value().count({.p = ex("blob")}).value(), stored);
}

// Threads of one process each writing through their own Agent while the map grows (an agent
// taking on one thread, storing on another): a writer checking the map's size before its
// transaction read LMDB's meta pages while another thread's growth remapped them, and the
// process died (SIGSEGV in 3 of 6 runs of six writers, two growths).
TEST(Growth, MapGrowsWhileSeveralThreadsOfTheProcessWrite) {
  TempDir dir;
  Node node = make_node(dir.path());
  const std::uint64_t initial_map = node.stats().value().map_bytes;
  constexpr int kWriters = 6, kItems = 60;
  std::atomic<int> failures{0};
  std::vector<std::thread> writers;
  for (int w = 0; w < kWriters; ++w) {
    writers.emplace_back([&, w] {
      Agent agent = node.agent("w" + std::to_string(w)).value();
      for (int i = 0; i < kItems; ++i) {
        Item item;
        item.add(Term::iri(kNodeIri + "/blob/" + std::to_string(w) + "-" + std::to_string(i)), ex("blob"),
                 Term::literal(std::to_string(w) + "-" + std::to_string(i) + std::string(300'000, 'x')));
        if (auto id = agent.store(item); !id) {
          ADD_FAILURE() << "writer " << w << " item " << i << ": " << id.error().message;
          ++failures;
          return;
        }
      }
    });
  }
  for (auto& t : writers) t.join();
  EXPECT_EQ(failures.load(), 0);
  EXPECT_GE(node.stats().value().map_bytes, initial_map * 2) << "the map did not grow: the case did not happen";
  EXPECT_EQ(node.snapshot().value().count({.p = ex("blob")}).value(), static_cast<std::uint64_t>(kWriters * kItems));
}

// Bytes of `file` mapped into this process's page tables (Rss of its mapping in
// /proc/self/smaps): the pages this process has written or read, or faulted in ahead.
std::uint64_t mapped_bytes_of(const std::filesystem::path& file) {
  std::ifstream smaps("/proc/self/smaps");
  const std::string wanted = std::filesystem::canonical(file).string();
  bool in_it = false;
  for (std::string line; std::getline(smaps, line);) {
    const bool header = !line.empty() && std::isxdigit(static_cast<unsigned char>(line[0])) && line.find('-') < line.find(' ');
    if (header) in_it = line.size() >= wanted.size() && line.compare(line.size() - wanted.size(), wanted.size(), wanted) == 0;
    else if (in_it && line.rfind("Rss:", 0) == 0) return std::stoull(line.substr(4)) * 1024;
  }
  return 0;
}

// The first write to each new page of a growing store is a page fault on the writing thread
// (several per commit, 4-5 us each on a virtual machine, while its readers wait): the pages
// ahead of the last one in use are faulted in by a thread of the store's own beforehand.
TEST(Growth, PagesAheadOfTheWriterAreMappedBeforeItReachesThem) {
  TempDir dir;
  Node node = make_node(dir.path());
  Agent writer = node.agent("writer").value();
  for (int i = 0; i < 200; ++i) {
    Item item;
    item.add(Term::iri(kNodeIri + "/obs/" + std::to_string(i)), ex("value"), Term::literal(std::to_string(i)));
    ASSERT_TRUE(writer.store(item));
  }
  const std::uint64_t in_use = node.stats().value().high_water_bytes;
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(20);
  std::uint64_t mapped = 0;
  while ((mapped = mapped_bytes_of(dir.path() / "data.mdb")) < in_use + (512 << 10) &&
         std::chrono::steady_clock::now() < deadline)
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  EXPECT_GE(mapped, in_use + (512 << 10)) << in_use << " bytes in use";
}

// A process that forks after writing (its prefault thread idle) leaves the child a copy of the
// thread's state but not the thread: a child closing the store it inherited waited for ever in
// the destructor of a condition variable that counted the parent's thread.
TEST(Growth, AChildForkedAfterAWriteClosesTheStoreItInherited) {
  TempDir dir;
  std::optional<Node> node(make_node(dir.path()));
  std::optional<Agent> writer(node->agent("writer").value());
  Item item;
  item.add(Term::iri(kNodeIri + "/obs/1"), ex("value"), Term::literal("1"));
  ASSERT_TRUE(writer->store(item));
  std::this_thread::sleep_for(std::chrono::milliseconds(100));  // the thread waits for work again
  const pid_t pid = fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    alarm(10);  // a hang ends as SIGALRM
    writer.reset();
    node.reset();
    _exit(0);
  }
  int status = 0;
  ASSERT_EQ(waitpid(pid, &status, 0), pid);
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0)
      << (WIFSIGNALED(status) ? "child killed by signal " + std::to_string(WTERMSIG(status)) : "child exited with " + std::to_string(WEXITSTATUS(status)));
}

}  // namespace
}  // namespace tahvel::node::testing
