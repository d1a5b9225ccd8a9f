// Map growth while other threads of the same process read: LMDB may remap only when the process
// has no transaction active, so growth must keep new transactions from starting meanwhile (a
// race here crashed a hospital's link process with 1,000 children: tahvel bench federation).
#include <gtest/gtest.h>

#include <atomic>
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

}  // namespace
}  // namespace tahvel::node::testing
