// Node::check (tahvel check): a store the library wrote holds together, and each kind of damage
// a disk or a foreign writer can leave is named with what it concerns.
#include <gtest/gtest.h>
#include <lmdb.h>

#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "tahvel/node/node.h"
#include "test_support.h"

namespace tahvel::node {
namespace {

using testing::change_with_lmdb;
using testing::ex;
using testing::make_node;
using testing::TempDir;

bool mentions(const CheckReport& report, const std::string& text) {
  for (const std::string& p : report.problems)
    if (p.find(text) != std::string::npos) return true;
  return false;
}

std::string all(const CheckReport& report) {
  std::string text;
  for (const std::string& p : report.problems) text += p + "\n";
  return text;
}

// Deletes the first entry of table `dbi` whose value is `id`; false when there is none.
bool delete_value(MDB_txn* txn, MDB_dbi dbi, std::uint64_t id) {
  MDB_cursor* c = nullptr;
  if (mdb_cursor_open(txn, dbi, &c) != 0) return false;
  MDB_val key, value;
  bool deleted = false;
  for (int rc = mdb_cursor_get(c, &key, &value, MDB_FIRST); rc == 0; rc = mdb_cursor_get(c, &key, &value, MDB_NEXT)) {
    std::uint64_t found = 0;
    std::memcpy(&found, value.mv_data, sizeof found);
    if (found == id) {
      deleted = mdb_cursor_del(c, 0) == 0;
      break;
    }
  }
  mdb_cursor_close(c);
  return deleted;
}

// LMDB checksums no page: bytes of a long literal overwritten in the file (a disk error, a
// stray write) still decoded, `check` said the store held together, and `dump` copied the
// garbage out as N-Triples that `load` refused. Text the store never writes (ill-formed UTF-8)
// and text that no longer hashes to its own entry are named.
TEST(Check, ALongLiteralWhoseBytesWereOverwrittenInTheFileIsNamedAsDamaged) {
  TempDir dir;
  const std::string literal(400'000, 'q');
  std::uint64_t other = 0;
  {
    Node node = make_node(dir.path());
    auto writer = node.agent("w").value();
    ASSERT_TRUE(writer.store(Item{}.add(ex("a"), ex("p"), Term::literal(literal))));
    other = writer.store(Item{}.add(ex("b"), ex("p"), Term::literal(std::string(300'000, 'r')))).value();
  }
  ASSERT_GT(other, 0u);
  const std::filesystem::path data = dir.path() / "data.mdb";
  std::fstream file(data, std::ios::in | std::ios::out | std::ios::binary);
  std::string bytes((std::istreambuf_iterator<char>(file)), {});
  // Two runs of 8 KB in the middle of each literal: random-looking bytes in one, valid ASCII in
  // the other (only its hash tells).
  const std::size_t q = bytes.find(std::string(100'000, 'q')), r = bytes.find(std::string(100'000, 'r'));
  ASSERT_NE(q, std::string::npos);
  ASSERT_NE(r, std::string::npos);
  for (std::size_t i = 0; i < 8192; ++i) bytes[q + 50'000 + i] = static_cast<char>(0x80 + i % 0x7f);
  for (std::size_t i = 0; i < 8192; ++i) bytes[r + 50'000 + i] = 'x';
  file.seekp(0);
  file.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  file.close();

  Node node = Node::open(dir.path()).value();
  auto report = node.check();
  ASSERT_TRUE(report) << report.error().message;
  EXPECT_EQ(report->problems_found, 2u) << all(*report);
  EXPECT_TRUE(mentions(*report, ": not UTF-8 at byte 50000 of its text (damaged)")) << all(*report);
  EXPECT_TRUE(mentions(*report, ": its text is not found under its own hash (damaged, or its hash entry is)")) << all(*report);
}

// Items of every shape the write path handles differently: several triples, literals of several
// kinds, blank nodes, a batch, a relayed item's writer, removals, ring eviction, a subscription
// and its input buffer.
TEST(Check, AStoreTheLibraryWroteHoldsTogetherAndIsCountedWhole) {
  TempDir dir;
  Node node = make_node(dir.path(), InitOptions{.ring = 40});
  auto writer = node.agent("w").value();
  auto reader = node.agent("r").value();
  ASSERT_TRUE(reader.subscribe(Pattern{.p = ex("hr")}));
  for (int i = 0; i < 30; ++i) {
    Item item;
    item.add(ex("obs" + std::to_string(i)), ex("hr"), Term::integer(60 + i))
        .add(ex("obs" + std::to_string(i)), ex("note"), Term::lang_literal("fine", "en"))
        .add(Term::blank("b"), ex("about"), ex("obs" + std::to_string(i)));
    ASSERT_TRUE(writer.store(item));
  }
  std::vector<Item> batch;
  for (int i = 0; i < 20; ++i) batch.push_back({.triples = {{ex("s" + std::to_string(i)), ex("p"), Term::literal("x" + std::to_string(i))}}});
  ASSERT_TRUE(writer.store_all(batch));
  ASSERT_TRUE(node.remove(Pattern{.s = ex("s3")}));

  auto report = node.check();
  ASSERT_TRUE(report) << report.error().message;
  EXPECT_TRUE(report->problems.empty()) << all(*report);
  EXPECT_EQ(report->problems_found, 0u);
  auto stats = node.stats().value();
  EXPECT_EQ(report->records, stats.records);
  EXPECT_EQ(report->items, stats.items);
  EXPECT_EQ(report->terms, stats.terms);
  EXPECT_EQ(report->index_entries, 3 * stats.records);
  EXPECT_EQ(report->time_entries, stats.items);
  EXPECT_GT(report->buffer_entries, 0u);
  EXPECT_GT(stats.reclaimed_records, 0u) << "the ring evicted nothing: the test does not cover eviction";
}

// The damage LMDB itself cannot see (it checksums nothing): a row that does not decode, an index
// entry lost, an item row lost, an index entry pointing elsewhere. Each is named by what it
// concerns, and every one is counted.
TEST(Check, RowsThatDoNotDecodeAndReferencesThatLeadNowhereAreEachNamed) {
  TempDir dir;
  std::uint64_t first = 0, second = 0, third = 0;
  {
    Node node = make_node(dir.path());
    auto writer = node.agent("w").value();
    first = writer.store(Item{}.add(ex("a"), ex("p"), Term::literal("one")).add(ex("a"), ex("q"), ex("b"))).value();
    second = writer.store(Item{}.add(ex("c"), ex("p"), Term::literal("two"))).value();
    third = writer.store(Item{}.add(ex("d"), ex("p"), Term::literal("three"))).value();
  }
  ASSERT_TRUE(change_with_lmdb(dir.path(), [&](MDB_txn* txn) {
    MDB_dbi records, items, idx_p;
    if (mdb_dbi_open(txn, "records", MDB_INTEGERKEY, &records) != 0 || mdb_dbi_open(txn, "items", MDB_INTEGERKEY, &items) != 0 ||
        mdb_dbi_open(txn, "idx_p", MDB_INTEGERKEY | MDB_DUPSORT | MDB_DUPFIXED | MDB_INTEGERDUP, &idx_p) != 0)
      return false;
    // The first record's row cut to one byte that starts a longer varint.
    const std::uint64_t garbled = first;
    MDB_val k{sizeof garbled, const_cast<std::uint64_t*>(&garbled)}, v{1, const_cast<char*>("\xff")};
    if (mdb_put(txn, records, &k, &v, 0) != 0) return false;
    // The second item's row gone, its record left.
    MDB_val item_key{sizeof second, &second};
    if (mdb_del(txn, items, &item_key, nullptr) != 0) return false;
    // The third item's predicate index entry and its output buffer entry gone.
    MDB_dbi outbox;
    if (mdb_dbi_open(txn, "outbox", MDB_INTEGERKEY | MDB_DUPSORT | MDB_DUPFIXED | MDB_INTEGERDUP, &outbox) != 0) return false;
    return delete_value(txn, idx_p, third) && delete_value(txn, outbox, third);
  }));

  Node node = Node::open(dir.path()).value();
  auto report = node.check();
  ASSERT_TRUE(report) << report.error().message;
  const std::string f = std::to_string(first), s = std::to_string(second), t = std::to_string(third);
  EXPECT_TRUE(mentions(*report, "record " + f + ": its row does not decode")) << all(*report);
  EXPECT_TRUE(mentions(*report, "record " + s + " names item " + s + ", which is not in the store")) << all(*report);
  EXPECT_TRUE(mentions(*report, "record " + t + " is not in the predicate index")) << all(*report);
  EXPECT_TRUE(mentions(*report, "counters: items 3, the tables hold 2")) << all(*report);
  EXPECT_TRUE(mentions(*report, "item " + t + " is not in its writer's output buffer")) << all(*report);
  EXPECT_TRUE(mentions(*report, "outbox: agent term ")) << "the lost item's output buffer entry names nothing\n" << all(*report);
  EXPECT_TRUE(mentions(*report, "idx_p: term ")) << "the garbled record's index entries name a row that does not decode\n"
                                                  << all(*report);
  EXPECT_EQ(report->problems_found, report->problems.size());

  auto few = node.check(2);
  ASSERT_TRUE(few);
  EXPECT_EQ(few->problems.size(), 2u);
  EXPECT_EQ(few->problems_found, report->problems_found) << "problems beyond the list are still counted";
}

}  // namespace
}  // namespace tahvel::node
