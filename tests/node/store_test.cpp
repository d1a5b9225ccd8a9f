// Store behaviour in one process: items, blank-node renaming, cascade read and removal,
// subscriptions and input buffers, errors that leave nothing behind, retention.
#include <gtest/gtest.h>
#include <lmdb.h>
#include <sched.h>
#include <sys/mount.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <cstring>
#include <fstream>
#include <optional>
#include <functional>
#include <limits>
#include <map>
#include <set>
#include <sstream>
#include <thread>

#include "tahvel/node/format.h"
#include "tahvel/node/node.h"
#include "test_support.h"

namespace tahvel::node {
namespace {

using namespace std::chrono_literals;
using testing::ex;
using testing::change_with_lmdb;
using testing::make_node;
using testing::TempDir;

std::vector<Triple> turtle(const std::string& text) {
  ParseOptions options;
  options.format = Format::turtle;
  auto triples = parse_rdf(text, options);
  EXPECT_TRUE(triples) << (triples ? "" : triples.error().message);
  return triples ? *triples : std::vector<Triple>{};
}

Item item_of(std::vector<Triple> triples) {
  Item item;
  item.triples = std::move(triples);
  return item;
}

std::set<std::uint64_t> ids_of(const std::vector<Record>& records) {
  std::set<std::uint64_t> ids;
  for (const auto& r : records) ids.insert(r.meta.id);
  return ids;
}

const char* kObservation = R"(
  @prefix ex: <http://example.org/ns#> .
  ex:root ex:has _:obs .
  _:obs ex:value 72 ; ex:sensor _:sensor .
  _:sensor ex:model "ECG-1" .
)";

// The same Turtle with blank nodes, put twice by one agent.
class TwoObservations : public ::testing::Test {
 protected:
  void SetUp() override {
    auto a = node.agent("writer");
    ASSERT_TRUE(a);
    auto f = a->store(item_of(turtle(kObservation)));
    auto s = a->store(item_of(turtle(kObservation)));
    ASSERT_TRUE(f && s);
    first = *f;
    second = *s;
  }
  TempDir dir;
  Node node = make_node(dir.path());
  std::uint64_t first = 0, second = 0;
};

TEST_F(TwoObservations, SameTurtleWithBlankNodesTwiceGivesItemsWhoseBlankNodesNeverCollide) {
  EXPECT_NE(first, second);
  auto snap = node.snapshot();
  ASSERT_TRUE(snap);
  std::set<std::string> blanks_first, blanks_second;
  auto records_first = snap->item(first);
  auto records_second = snap->item(second);
  ASSERT_TRUE(records_first && records_second);
  for (const auto& r : *records_first)
    for (const Term* t : {&r.triple.s, &r.triple.o}) if (t->is_blank()) blanks_first.insert(t->value);
  for (const auto& r : *records_second)
    for (const Term* t : {&r.triple.s, &r.triple.o}) if (t->is_blank()) blanks_second.insert(t->value);
  EXPECT_EQ(blanks_first.size(), 2u);
  EXPECT_EQ(blanks_second.size(), 2u);
  for (const auto& b : blanks_first) EXPECT_EQ(blanks_second.count(b), 0u) << b;
}

TEST_F(TwoObservations, CascadeListFromItemRootReturnsExactlyItsSubtree) {
  auto snap = node.snapshot();
  auto item = snap->item(first);
  ASSERT_TRUE(item);
  // Roots: the first item's ex:has triple; its sub-tree is that item's records only.
  Pattern root;
  root.s = ex("root");
  root.p = ex("has");
  root.o = item->front().triple.o;
  auto listed = snap->list(root, ListOptions{5, 0});
  ASSERT_TRUE(listed);
  EXPECT_EQ(ids_of(*listed), ids_of(*item));
  EXPECT_EQ(listed->size(), 4u);
  EXPECT_EQ(listed->front().meta.id, first);
  // Depth 1 stops below the observation: root triple + the observation's two triples.
  auto shallow = snap->list(root, ListOptions{1, 0});
  ASSERT_TRUE(shallow);
  EXPECT_EQ(shallow->size(), 3u);
}

// A record first met deep in one match's sub-tree and then nearer another's is walked again
// from the nearer place: `ex:deep ex:z 1`, 2 levels below `m q2 k`, was left out of a cascade 2
// read of m because it was first met 3 levels below `m q1 n`.
// A call on a handle moved into another crashed (a null dereference) where a closed C handle
// gives an error.
TEST(Store, AHandleMovedFromGivesAnErrorNotACrash) {
  TempDir dir;
  Node node = make_node(dir.path());
  auto agent = node.agent("writer");
  ASSERT_TRUE(agent);
  Agent moved_into = std::move(*agent);
  auto stored = agent->store(Item{}.add(ex("s"), ex("p"), ex("o")));
  ASSERT_FALSE(stored);
  EXPECT_EQ(stored.error().code, Errc::invalid_argument);
  EXPECT_NE(stored.error().message.find("moved from"), std::string::npos) << stored.error().message;
  EXPECT_FALSE(agent->take(std::chrono::milliseconds(0)));
  EXPECT_FALSE(agent->pending());
  EXPECT_TRUE(moved_into.store(Item{}.add(ex("s"), ex("p"), ex("o"))));
  Node other = std::move(node);
  EXPECT_FALSE(node.snapshot());
  EXPECT_FALSE(node.agent("x"));
  EXPECT_TRUE(other.snapshot());
  // The calls that return no Result crashed too (a developer's probe of session 84).
  EXPECT_EQ(agent->buffer_version(), 0u);
  EXPECT_TRUE(node.dir().empty());
  EXPECT_TRUE(node.prefixes().entries().empty());
  EXPECT_FALSE(node.addressee(other.iri() + "/writer"));
  node.wake_waiters();
  EXPECT_FALSE(node.wait_for_commit([] { return false; }, std::chrono::milliseconds(1)));
  EXPECT_TRUE(node.wait_for_commit([] { return true; }, std::chrono::milliseconds(1)));
  EXPECT_FALSE(other.dir().empty());
  // Their names: empty, not a read through a null pointer (a partner's probe of session 88).
  EXPECT_TRUE(agent->iri().empty());
  EXPECT_TRUE(agent->id().empty());
  EXPECT_TRUE(node.iri().empty());
  EXPECT_EQ(moved_into.id(), "writer");
  // A snapshot moved from, too (a developer's probe of session 86: a segmentation fault).
  auto snapshot = other.snapshot();
  ASSERT_TRUE(snapshot);
  Snapshot kept = std::move(*snapshot);
  const auto listed = snapshot->list({});
  ASSERT_FALSE(listed);
  EXPECT_NE(listed.error().message.find("moved from"), std::string::npos) << listed.error().message;
  EXPECT_FALSE(snapshot->count({}));
  EXPECT_FALSE(snapshot->item(1));
  EXPECT_FALSE(snapshot->predicates());
  EXPECT_FALSE(snapshot->input_buffers());
  EXPECT_FALSE(snapshot->for_each({}, [](const Record&) { return true; }));
  EXPECT_EQ(snapshot->last_seq(), 0u);
  EXPECT_TRUE(kept.count({}));
}

// A store deleted (`rm -rf` of its directory) while an agent had it open took its writes into
// the unlinked file and answered them as stored, and its takes timed out for ever (a partner's
// probe of session 88); so did a store moved away. Both are io errors naming the file, and a
// store moved back takes writes again.
TEST(Store, WritesAndTakesOfAStoreDeletedOrMovedAwayWhileOpenAreErrorsNotLostWrites) {
  TempDir dir;
  const std::filesystem::path store = dir.path() / "moving";
  auto agent = make_node(store).agent("writer").value();
  const Item item = Item{}.add(ex("s"), ex("p"), ex("o"));
  ASSERT_TRUE(agent.store(item));
  std::filesystem::rename(store, dir.path() / "moved");
  std::this_thread::sleep_for(150ms);  // past the 100 ms between looks
  auto stored = agent.store(item);
  ASSERT_FALSE(stored);
  EXPECT_EQ(stored.error().code, Errc::io);
  EXPECT_NE(stored.error().message.find((store / "data.mdb").string() + " is no longer the file this process opened"),
            std::string::npos) << stored.error().message;
  EXPECT_FALSE(agent.store(item)) << "said at every write, not once in 100 ms";
  std::filesystem::rename(dir.path() / "moved", store);
  EXPECT_TRUE(agent.store(item));
  // Its data file replaced by another store's (a restore over it): another file at the path.
  make_node(dir.path() / "other", {.iri = "http://example.org/other"});
  std::filesystem::rename(dir.path() / "other" / "data.mdb", store / "data.mdb");
  std::this_thread::sleep_for(150ms);
  stored = agent.store(item);
  ASSERT_FALSE(stored);
  EXPECT_NE(stored.error().message.find((store / "data.mdb").string() + " was replaced by another file while this process had the store open"),
            std::string::npos) << stored.error().message;
  std::filesystem::remove_all(store);
  std::this_thread::sleep_for(150ms);
  stored = agent.store(item);
  ASSERT_FALSE(stored);
  EXPECT_NE(stored.error().message.find((store / "data.mdb").string() + " was deleted while this process had the store open"),
            std::string::npos) << stored.error().message;
  // A take, with a limit or without one: no wait for an item that cannot come.
  for (const auto limit : {std::chrono::milliseconds(50), std::chrono::milliseconds::max()}) {
    auto taken = agent.take(limit);
    ASSERT_FALSE(taken) << "a take of a deleted store is no timeout";
    EXPECT_EQ(taken.error().code, Errc::io);
  }
  // A store made again at the path is that store to this process, not the one it had open.
  auto again = make_node(store).agent("writer").value();
  EXPECT_TRUE(again.store(item));
  EXPECT_EQ(Node::open(store).value().snapshot().value().count({}).value(), 1u);
}

TEST(Store, ACascadeTakesWhatLiesWithinItsDepthOfAnyMatchWhateverTheOrder) {
  TempDir dir;
  Node node = make_node(dir.path());
  auto writer = node.agent("writer");
  ASSERT_TRUE(writer->store(Item{}
                                .add(ex("m"), ex("q1"), ex("n"))
                                .add(ex("n"), ex("q1"), ex("k"))
                                .add(ex("k"), ex("q1"), ex("deep"))
                                .add(ex("deep"), ex("z"), Term::integer(1))
                                .add(ex("m"), ex("q2"), ex("k"))));
  Pattern from_m;
  from_m.s = ex("m");
  auto snap = node.snapshot();
  auto listed = snap->list(from_m, ListOptions{2, 0});
  ASSERT_TRUE(listed);
  std::set<std::string> got;
  for (const Record& r : *listed) got.insert(r.triple.s.value + " " + r.triple.p.value);
  EXPECT_EQ(listed->size(), got.size());  // each record once
  EXPECT_EQ(got, (std::set<std::string>{ex("m").value + " " + ex("q1").value, ex("m").value + " " + ex("q2").value,
                                        ex("n").value + " " + ex("q1").value, ex("k").value + " " + ex("q1").value,
                                        ex("deep").value + " " + ex("z").value}));
}

// A chain of records (an RDF list, a linked log) read or removed with a cascade as deep as it
// is: the walk took a frame of recursion per level and overflowed the stack at about 21,000.
TEST(Store, ACascadeThroughAChainOfFiftyThousandRecordsReadsAndRemovesItWhole) {
  TempDir dir;
  Node node = make_node(dir.path());
  constexpr int kLinks = 50'000;
  Item chain;
  for (int i = 0; i < kLinks; ++i) chain.add(ex("n" + std::to_string(i)), ex("next"), ex("n" + std::to_string(i + 1)));
  ASSERT_TRUE(node.agent("writer")->store(chain));
  Pattern head;
  head.s = ex("n0");
  {
    auto snap = node.snapshot();
    auto listed = snap->list(head, ListOptions{kLinks + 10, 0});
    ASSERT_TRUE(listed) << listed.error().message;
    ASSERT_EQ(listed->size(), static_cast<std::size_t>(kLinks));
    EXPECT_EQ(listed->back().triple.s, ex("n" + std::to_string(kLinks - 1)));  // in the chain's order
    auto part = snap->list(head, ListOptions{99, 0});
    ASSERT_TRUE(part);
    EXPECT_EQ(part->size(), 100u);  // the match and 99 levels below it
  }
  auto removed = node.remove(head, kLinks);
  ASSERT_TRUE(removed) << removed.error().message;
  EXPECT_EQ(*removed, static_cast<std::uint64_t>(kLinks));
}

TEST_F(TwoObservations, CascadeRemoveRemovesExactlyTheSubtree) {
  std::vector<Record> first_records, second_records;
  {
    auto snap = node.snapshot();
    first_records = *snap->item(first);
    second_records = *snap->item(second);
  }
  Pattern root;
  root.s = ex("root");
  root.o = first_records.front().triple.o;
  auto removed = node.remove(root, 5);
  ASSERT_TRUE(removed) << removed.error().message;
  EXPECT_EQ(*removed, 4u);
  auto snap = node.snapshot();
  auto left = snap->item(first);
  ASSERT_FALSE(left);
  EXPECT_EQ(left.error().code, Errc::not_found);
  auto kept = snap->item(second);
  ASSERT_TRUE(kept);
  EXPECT_EQ(ids_of(*kept), ids_of(second_records));
  auto stats = node.stats();
  EXPECT_EQ(stats->records, 4u);
}

TEST(Store, RecordMetadataCarriesSourceContextAndTimes) {
  TempDir dir;
  Node node = make_node(dir.path());
  auto agent = node.agent("hrv");
  Item item = item_of(turtle(kObservation));
  item.context = "http://example.org/hospital";
  item.asserted_at = 1'000'000'000;
  auto id = agent->store(item);
  ASSERT_TRUE(id);
  auto records = node.snapshot()->item(*id);
  ASSERT_TRUE(records);
  for (const auto& r : *records) {
    EXPECT_EQ(r.meta.source, testing::kNodeIri + "/hrv");
    EXPECT_EQ(r.meta.context, "http://example.org/hospital");
    EXPECT_EQ(r.meta.asserted_at, 1'000'000'000);
    EXPECT_GT(r.meta.stored_at, 1'600'000'000'000'000'000);
    EXPECT_EQ(r.meta.item, *id);
  }
}

// Two recordings on one home board, as two bed sensors leave them: asking for what lies under
// one recording's IRI gets its description and its chunks, not the other's nor a recording
// whose IRI only starts with the same characters; a blank subject is under nothing.
TEST(Store, APatternUnderAnIriTakesTheRecordsOfThatSubjectAndOfTheSubjectsBelowIt) {
  TempDir dir;
  Node node = make_node(dir.path());
  const std::string base = "http://example.org/home1/ecg1/source/recording/";
  const Term samples = Term::iri("http://example.org/ns#samples");
  for (const std::string name : {"100", "101", "1000"}) {
    Item description;
    description.add(Term::iri(base + name), Term::iri("http://example.org/ns#rate"), Term::integer(360));
    ASSERT_TRUE(node.agent("source")->store(description));
    for (int second = 0; second < 3; ++second) {
      Item chunk;
      chunk.add(Term::iri(base + name + "/chunk/" + std::to_string(second)), samples, Term::literal(name));
      chunk.asserted_at = 1'000 + second;
      ASSERT_TRUE(node.agent("source")->store(chunk));
    }
  }
  Item blank;
  blank.add(Term::blank("b"), samples, Term::literal("100"));
  ASSERT_TRUE(node.agent("source")->store(blank));
  auto subjects = [&](const Pattern& pattern) {
    std::vector<std::string> out;
    auto records = node.snapshot()->list(pattern);
    EXPECT_TRUE(records) << records.error().message;
    if (records)
      for (const auto& r : *records) out.push_back(r.triple.s.value.substr(base.size()));
    return out;
  };
  EXPECT_EQ(subjects({.under = base + "100"}),
            (std::vector<std::string>{"100", "100/chunk/0", "100/chunk/1", "100/chunk/2"}));
  EXPECT_EQ(subjects({.p = samples, .under = base + "101", .since = 1'001}),
            (std::vector<std::string>{"101/chunk/1", "101/chunk/2"}));
  EXPECT_EQ(subjects({.under = base + "1000/chunk/2"}), (std::vector<std::string>{"1000/chunk/2"}));
  EXPECT_TRUE(subjects({.under = base + "999"}).empty());
  auto chunks = node.snapshot()->count({.p = samples, .under = base});
  ASSERT_TRUE(chunks);
  EXPECT_EQ(*chunks, 9u);
  // Not a subscription's: routing does not look at subjects' IRIs.
  auto refused = node.agent("reader")->subscribe({.under = base + "100"});
  ASSERT_FALSE(refused);
  EXPECT_EQ(refused.error().code, Errc::invalid_argument);
  // A bad term is named by the field it was given in ("triple 3, object: invalid IRI 'rel'"
  // named a triple of a declaration the caller never wrote).
  auto relative = node.agent("reader")->subscribe({.p = samples, .context = "rel"});
  ASSERT_FALSE(relative);
  EXPECT_EQ(relative.error().message.rfind("subscription context: invalid IRI 'rel'", 0), 0u) << relative.error().message;
  auto object = node.agent("reader")->subscribe({.p = samples, .o = Term::iri("http://[::1/p")});
  ASSERT_FALSE(object);
  EXPECT_EQ(object.error().message.rfind("subscription object: invalid IRI", 0), 0u) << object.error().message;
  auto not_text = node.agent("reader")->subscribe({.p = samples, .o = Term::literal("a\xFF")});
  ASSERT_FALSE(not_text);
  EXPECT_EQ(not_text.error().message.rfind("subscription object: ", 0), 0u) << not_text.error().message;
  // Not "triple 2, object: invalid IRI 'integer'", a triple of the declaration.
  auto datatype = node.agent("reader")->subscribe({.p = samples, .o = Term::literal("1", "integer")});
  ASSERT_FALSE(datatype);
  EXPECT_EQ(datatype.error().message, "subscription object: its datatype <integer> is not an absolute IRI");
}

// A time range takes an item that held for a span of time (a second of ECG) when the span
// overlaps the range: an operator asking from the middle of a second gets that second's chunk.
TEST(Store, ATimeRangeTakesTheItemsWhoseSpanOverlapsItAndTheInstantsInIt) {
  TempDir dir;
  auto stored = [](Node& node, const std::string& name, std::int64_t at, std::int64_t span) {
    Item item;
    item.add(Term::iri("http://example.org/" + name), Term::iri("http://example.org/ns#at"), Term::integer(at));
    item.asserted_at = at;
    item.span = span;
    ASSERT_TRUE(node.agent("source")->store(item));
  };
  auto names_in = [](const Node& node, std::int64_t since, std::int64_t until) {
    std::set<std::string> names;
    auto records = node.snapshot()->list({.since = since, .until = until});
    EXPECT_TRUE(records) << records.error().message;
    for (const auto& r : *records) names.insert(r.triple.s.value.substr(std::string("http://example.org/").size()));
    return names;
  };
  {
    Node node = make_node(dir.path());
    stored(node, "ends-at-since", 50, 50);        // [50, 100)
    stored(node, "holds-at-since", 60, 41);       // [60, 101)
    stored(node, "instant-before", 99, 0);
    stored(node, "instant-at-since", 100, 0);
    stored(node, "starts-inside", 150, 1000);     // [150, 1150)
    stored(node, "starts-at-until", 200, 10);     // [200, 210)
    stored(node, "covers-the-range", 0, 10'000);  // [0, 10000)
    const std::set<std::string> expected{"holds-at-since", "instant-at-since", "starts-inside", "covers-the-range"};
    EXPECT_EQ(names_in(node, 100, 200), expected);
    // A range that ends before it starts (a query from the wire is not checked as the command
    // line checks it) holds nothing, not even what holds for long.
    EXPECT_TRUE(names_in(node, 200, 100).empty());
    // The span is metadata of each record, kept with its item.
    auto chunk = node.snapshot()->list({.s = Term::iri("http://example.org/starts-inside")});
    ASSERT_TRUE(chunk && chunk->size() == 1u);
    EXPECT_EQ(chunk->front().meta.span, 1000);
    EXPECT_EQ(chunk->front().meta.asserted_at, 150);
  }
  // As stored: the same after the store is opened again.
  auto again = Node::open(dir.path());
  ASSERT_TRUE(again) << again.error().message;
  EXPECT_EQ(names_in(*again, 100, 200),
            (std::set<std::string>{"holds-at-since", "instant-at-since", "starts-inside", "covers-the-range"}));
  EXPECT_EQ(names_in(*again, 1150, 2000), (std::set<std::string>{"covers-the-range"}));
}

// A time range is read from the time index: the items of the range and no other, so an
// operator's query for ten seconds of a month of ECG reads ten seconds' worth. Shown with an
// item outside the range whose row is damaged: the range never reads it, a scan does.
TEST(Store, ATimeRangeReadsOnlyTheItemsOfItsRange) {
  TempDir dir;
  std::vector<std::uint64_t> items;
  {
    Node node = make_node(dir.path());
    for (std::int64_t second = 0; second < 10; ++second) {
      Item item;
      item.add(Term::iri("http://example.org/chunk/" + std::to_string(second)), ex("samples"), Term::literal("AAAA"));
      item.asserted_at = second * 1'000'000'000;
      item.span = 1'000'000'000;
      items.push_back(node.agent("ecg")->store(item).value());
    }
  }
  const std::uint64_t damaged = items[8];
  ASSERT_TRUE(change_with_lmdb(dir.path(), [&](MDB_txn* txn) {
    MDB_dbi table = 0;
    MDB_val key{sizeof damaged, const_cast<std::uint64_t*>(&damaged)}, row{1, const_cast<char*>("\x80")};
    return mdb_dbi_open(txn, "items", MDB_INTEGERKEY, &table) == 0 && mdb_put(txn, table, &key, &row, 0) == 0;
  })) << "could not damage the item";
  Node node = Node::open(dir.path()).value();
  // From the middle of second 2 to the start of second 5: the chunks of seconds 2, 3 and 4.
  auto range = node.snapshot()->list({.since = 2'500'000'000, .until = 5'000'000'000});
  ASSERT_TRUE(range) << range.error().message;
  std::vector<std::string> subjects;
  for (const auto& r : *range) subjects.push_back(r.triple.s.value);
  EXPECT_EQ(subjects, (std::vector<std::string>{"http://example.org/chunk/2", "http://example.org/chunk/3",
                                                "http://example.org/chunk/4"}));
  // The same with a bound predicate (its index lists every chunk: the range lists fewer).
  auto samples = node.snapshot()->count({.p = ex("samples"), .since = 2'500'000'000, .until = 5'000'000'000});
  ASSERT_TRUE(samples) << samples.error().message;
  EXPECT_EQ(*samples, 3u);
  // A scan without a range meets the damaged row and says so.
  auto all = node.snapshot()->list({});
  ASSERT_FALSE(all);
  EXPECT_EQ(all.error().code, Errc::corrupt);
  EXPECT_NE(all.error().message.find("item " + std::to_string(damaged)), std::string::npos) << all.error().message;
}

// A store of format 2, as the builds before the time index left it, gets the index, filled, at
// its first open (and format 3 written: those builds would add items the index does not list,
// and refuse it). A format this build does not know is refused, naming both.
TEST(Store, AStoreOfFormat2GetsItsTimeIndexAtItsFirstOpenAndAnUnknownFormatIsRefused) {
  TempDir dir;
  // In a process of its own (change_with_lmdb), which commits nothing it changed.
  auto format_is = [&](std::uint32_t expected) {
    return change_with_lmdb(dir.path(), [&](MDB_txn* txn) {
      MDB_dbi meta = 0;
      MDB_val key{7, const_cast<char*>("version")}, value;
      if (mdb_dbi_open(txn, "meta", 0, &meta) != 0 || mdb_get(txn, meta, &key, &value) != 0 || value.mv_size != 4) return false;
      std::uint32_t format = 0;
      std::memcpy(&format, value.mv_data, 4);
      return format == expected;
    });
  };
  auto set_format = [&](std::uint32_t format) {
    return change_with_lmdb(dir.path(), [&](MDB_txn* txn) {
      MDB_dbi meta = 0;
      MDB_val key{7, const_cast<char*>("version")}, value{4, &format};
      return mdb_dbi_open(txn, "meta", 0, &meta) == 0 && mdb_put(txn, meta, &key, &value, 0) == 0;
    });
  };
  {
    Node node = make_node(dir.path());
    for (std::int64_t i = 0; i < 50; ++i) {
      Item item;
      item.add(ex("w" + std::to_string(i)), ex("at"), Term::integer(i));
      item.asserted_at = (49 - i) * 100;  // not in the order of the ids
      item.span = i == 7 ? 2'000 : 0;     // item 7: [4200, 6200)
      ASSERT_TRUE(node.agent("w")->store(item));
    }
  }
  ASSERT_TRUE(format_is(4));
  // Back to format 2: no time index, counters without the longest span.
  ASSERT_TRUE(change_with_lmdb(dir.path(), [](MDB_txn* txn) {
    MDB_dbi by_time = 0, main = 0;
    MDB_val key{8, const_cast<char*>("counters")}, value;
    if (mdb_dbi_open(txn, "by_time", 0, &by_time) != 0 || mdb_drop(txn, by_time, 1) != 0) return false;
    if (mdb_dbi_open(txn, nullptr, 0, &main) != 0 || mdb_get(txn, main, &key, &value) != 0) return false;
    std::string format2(static_cast<const char*>(value.mv_data), 15 * 8);  // 15 counters in format 2
    MDB_val shorter{format2.size(), format2.data()};
    return mdb_put(txn, main, &key, &shorter, 0) == 0;
  })) << "could not take the index away";
  ASSERT_TRUE(set_format(2));
  {
    auto node = Node::open(dir.path());
    ASSERT_TRUE(node) << node.error().message;
    auto range = node->snapshot()->list({.since = 4'500, .until = 4'800});
    ASSERT_TRUE(range) << range.error().message;
    std::set<std::string> subjects;
    for (const auto& r : *range) subjects.insert(r.triple.s.value.substr(testing::kEx.size()));
    // Instants at 4500, 4600, 4700 (w4, w3, w2), and w7's span.
    EXPECT_EQ(subjects, (std::set<std::string>{"w2", "w3", "w4", "w7"}));
    ASSERT_TRUE(node->agent("w")->store(Item{}.add(ex("later"), ex("at"), Term::integer(1))));
  }
  EXPECT_TRUE(format_is(4));
  ASSERT_TRUE(set_format(9));
  auto refused = Node::open(dir.path());
  ASSERT_FALSE(refused);
  EXPECT_EQ(refused.error().code, Errc::version);
  EXPECT_NE(refused.error().message.find("has store format 9, this build reads 2 to 4"), std::string::npos)
      << refused.error().message;
}

// Format 4 keeps long terms (ECG samples) apart from short ones. A store of format 3 holds its
// long terms among the short ones: it is brought to format 4 at its first open, its long terms
// are read where they are, removed from there, and new ones go to the table of long terms.
TEST(Store, AStoreOfFormat3KeepsItsLongTermsWhereTheyAreAndGetsTheTableOfLongTerms) {
  TempDir dir;
  const std::string long_text(600, 'x');
  {
    Node node = make_node(dir.path());
    ASSERT_TRUE(node.agent("w")->store(Item{}.add(ex("old"), ex("text"), Term::literal(long_text + "old"))));
    ASSERT_TRUE(node.agent("w")->store(Item{}.add(ex("short"), ex("text"), Term::literal("short"))));
  }
  // As a format-3 build left it: the long term in `terms`, no table of long terms.
  ASSERT_TRUE(change_with_lmdb(dir.path(), [](MDB_txn* txn) {
    MDB_dbi terms = 0, long_terms = 0, meta = 0;
    if (mdb_dbi_open(txn, "terms", MDB_INTEGERKEY, &terms) != 0 || mdb_dbi_open(txn, "long_terms", MDB_INTEGERKEY, &long_terms) != 0 ||
        mdb_dbi_open(txn, "meta", 0, &meta) != 0)
      return false;
    MDB_cursor* cursor = nullptr;
    if (mdb_cursor_open(txn, long_terms, &cursor) != 0) return false;
    std::vector<std::pair<std::uint64_t, std::string>> moved;
    MDB_val k, v;
    for (int rc = mdb_cursor_get(cursor, &k, &v, MDB_FIRST); rc == 0; rc = mdb_cursor_get(cursor, &k, &v, MDB_NEXT)) {
      std::uint64_t id = 0;
      std::memcpy(&id, k.mv_data, sizeof id);
      moved.emplace_back(id, std::string(static_cast<const char*>(v.mv_data), v.mv_size));
    }
    mdb_cursor_close(cursor);
    if (moved.size() != 1) return false;
    for (auto& [id, value] : moved) {
      MDB_val mk{sizeof id, &id}, mv{value.size(), value.data()};
      if (mdb_put(txn, terms, &mk, &mv, 0) != 0) return false;
    }
    std::uint32_t format = 3;
    MDB_val key{7, const_cast<char*>("version")}, value{4, &format};
    return mdb_drop(txn, long_terms, 1) == 0 && mdb_put(txn, meta, &key, &value, 0) == 0;
  })) << "could not make the store of format 3";
  {
    auto node = Node::open(dir.path());
    ASSERT_TRUE(node) << node.error().message;
    auto texts = node->snapshot()->list({.p = ex("text")});
    ASSERT_TRUE(texts) << texts.error().message;
    ASSERT_EQ(texts->size(), 2u);
    EXPECT_EQ(texts->at(0).triple.o.value, long_text + "old");
    ASSERT_TRUE(node->agent("w")->store(Item{}.add(ex("new"), ex("text"), Term::literal(long_text + "new"))));
    ASSERT_TRUE(node->remove({.s = ex("old")}));
    auto left = node->snapshot()->list({.p = ex("text")});
    ASSERT_TRUE(left);
    std::set<std::string> values;
    for (const auto& r : *left) values.insert(r.triple.o.value);
    EXPECT_EQ(values, (std::set<std::string>{"short", long_text + "new"}));
    auto checked = node->check();
    ASSERT_TRUE(checked) << checked.error().message;
    EXPECT_TRUE(checked->problems.empty()) << ::testing::PrintToString(checked->problems);
    EXPECT_EQ(checked->terms, node->stats()->terms);
  }
  // Format 4, the old long term gone from `terms`, the new one in `long_terms`.
  ASSERT_TRUE(change_with_lmdb(dir.path(), [&](MDB_txn* txn) {
    MDB_dbi terms = 0, long_terms = 0, meta = 0;
    MDB_stat in_terms, in_long;
    MDB_val key{7, const_cast<char*>("version")}, value;
    std::uint32_t format = 0;
    if (mdb_dbi_open(txn, "terms", 0, &terms) != 0 || mdb_dbi_open(txn, "long_terms", 0, &long_terms) != 0 ||
        mdb_dbi_open(txn, "meta", 0, &meta) != 0 || mdb_get(txn, meta, &key, &value) != 0 || mdb_stat(txn, long_terms, &in_long) != 0 ||
        mdb_stat(txn, terms, &in_terms) != 0)
      return false;
    std::memcpy(&format, value.mv_data, 4);
    MDB_cursor* cursor = nullptr;
    bool long_in_terms = false;
    if (mdb_cursor_open(txn, terms, &cursor) != 0) return false;
    MDB_val k, v;
    for (int rc = mdb_cursor_get(cursor, &k, &v, MDB_FIRST); rc == 0; rc = mdb_cursor_get(cursor, &k, &v, MDB_NEXT))
      long_in_terms = long_in_terms || v.mv_size >= 256;
    mdb_cursor_close(cursor);
    return format == 4 && in_long.ms_entries == 1 && !long_in_terms;
  })) << "not format 4 with the new long term apart";
}

TEST(Store, ANegativeSpanOrOneEndingPastTheLargestTimeIsRefusedAndNothingIsWritten) {
  TempDir dir;
  Node node = make_node(dir.path());
  auto agent = node.agent("source");
  Item item;
  item.add(Term::iri("http://example.org/a"), Term::iri("http://example.org/ns#p"), Term::integer(1));
  item.asserted_at = 1'000;
  item.span = -1;
  auto negative = agent->store(item);
  ASSERT_FALSE(negative);
  EXPECT_EQ(negative.error().code, Errc::invalid_argument);
  EXPECT_NE(negative.error().message.find("span -1 ns is negative"), std::string::npos) << negative.error().message;
  item.asserted_at = std::numeric_limits<std::int64_t>::max() - 5;
  item.span = 6;
  auto past = agent->store(item);
  ASSERT_FALSE(past);
  EXPECT_NE(past.error().message.find("past the largest time"), std::string::npos) << past.error().message;
  EXPECT_EQ(node.stats()->records, 0u);
}

// A row with a flag this build does not know (a later build wrote it, and the store was taken
// back to this one) is said to be unreadable, not read without what the flag adds.
TEST(Store, AnItemRowWithAFlagOfALaterBuildIsReportedUnreadableNotMisread) {
  TempDir dir;
  std::uint64_t id = 0;
  {
    Node node = make_node(dir.path());
    Item item;
    item.add(ex("a"), ex("p"), Term::integer(1));
    id = node.agent("writer")->store(item).value();
  }
  ASSERT_TRUE(change_with_lmdb(dir.path(), [&](MDB_txn* txn) {
    MDB_dbi items;
    if (mdb_dbi_open(txn, "items", MDB_INTEGERKEY, &items) != 0) return false;
    MDB_val k{sizeof id, &id}, v;
    if (mdb_get(txn, items, &k, &v) != 0) return false;
    std::string row(static_cast<const char*>(v.mv_data), v.mv_size);
    // The flags byte follows seven varints (count, live, pending, times, source, context).
    std::size_t pos = 0;
    for (int field = 0; field < 7; ++field)
      while (static_cast<unsigned char>(row.at(pos++)) & 0x80) {
      }
    row.at(pos) = static_cast<char>(row.at(pos) | 0x40);
    MDB_val changed{row.size(), row.data()};
    return mdb_put(txn, items, &k, &changed, 0) == 0;
  }));
  auto node = Node::open(dir.path());
  ASSERT_TRUE(node) << node.error().message;
  auto records = node->snapshot()->list({.s = ex("a")});
  ASSERT_FALSE(records);
  EXPECT_EQ(records.error().code, Errc::corrupt);
  EXPECT_NE(records.error().message.find("written by a later build"), std::string::npos) << records.error().message;
}

// An agent's problem (docs/vocabulary.md, "Problems"): one persistent item of its own, replaced
// when the problem changes, written only when the board says otherwise, gone when it is over.
TEST(Store, AnAgentsProblemIsOneItemOfItsOwnReplacedWhenItChangesAndRemovedWhenOver) {
  TempDir dir;
  Node node = make_node(dir.path());
  auto hrv = node.agent("hrv");
  const Term self = Term::iri(hrv->iri());
  auto said = [&] {
    auto records = node.snapshot()->list({.s = self, .source = hrv->iri()});
    std::map<std::string, std::string> by_predicate;
    for (const auto& r : *records) {
      EXPECT_TRUE(r.meta.persistent);
      by_predicate[r.triple.p.value] = r.triple.o.value;
    }
    return by_predicate;
  };
  ASSERT_TRUE(hrv->report_problem("window 'abc' is not a number"));
  EXPECT_EQ(said(), (std::map<std::string, std::string>{{kProblem, "window 'abc' is not a number"},
                                                        {kProblemPid, std::to_string(getpid())}}));
  const std::uint64_t before = node.snapshot()->last_seq();
  ASSERT_TRUE(hrv->report_problem("window 'abc' is not a number"));
  EXPECT_EQ(node.snapshot()->last_seq(), before) << "the same problem again wrote to the board";
  // A byte that is not UTF-8 (a Latin-1 file quoted) is written as U+FFFD.
  ASSERT_TRUE(hrv->report_problem("step 'f\xF6\xF6'"));
  EXPECT_EQ(said().at(kProblem), "step 'f\uFFFD\uFFFD'");
  EXPECT_EQ(node.snapshot()->count({.p = Term::iri(kProblem)}).value(), 1u);
  // Another agent's records about this one are not its problem and stay.
  ASSERT_TRUE(node.agent("operator")->store(Item{}.add(self, Term::iri(kProblem), Term::literal("seen from outside"))));
  ASSERT_TRUE(hrv->report_problem(""));
  EXPECT_TRUE(said().empty());
  EXPECT_EQ(node.snapshot()->count({.p = Term::iri(kProblem)}).value(), 1u);
  const std::uint64_t over = node.snapshot()->last_seq();
  ASSERT_TRUE(hrv->report_problem(""));
  EXPECT_EQ(node.snapshot()->last_seq(), over);
}

// A link tells a replaced store from the one it knew by this id (docs/protocol.md P6a).
TEST(Store, AStoreKeepsItsIdAcrossOpensAndAStoreMadeAgainInItsPlaceHasAnother) {
  TempDir dir;
  std::string first;
  {
    Node node = make_node(dir.path() / "n");
    first = node.store_id().value();
    EXPECT_EQ(first.size(), 32u);
  }
  EXPECT_EQ(Node::open(dir.path() / "n")->store_id().value(), first);
  std::filesystem::remove_all(dir.path() / "n");
  Node again = make_node(dir.path() / "n");
  const std::string second = again.store_id().value();
  EXPECT_NE(second, first);
  const std::string renewed = again.renew_store_id().value();
  EXPECT_NE(renewed, second);
  EXPECT_EQ(Node::open(dir.path() / "n")->store_id().value(), renewed);
}

// A store made before store ids gets one at its first open, and keeps it (an existing store is
// opened in a read transaction; this is the one write an open may need).
TEST(Store, AStoreMadeBeforeStoreIdsGetsOneAtItsFirstOpenAndKeepsIt) {
  TempDir dir;
  { make_node(dir.path() / "n"); }
  ASSERT_TRUE(change_with_lmdb(dir.path() / "n", [](MDB_txn* txn) {
    MDB_dbi meta = 0;
    MDB_val key{8, const_cast<char*>("store_id")};
    return mdb_dbi_open(txn, "meta", 0, &meta) == 0 && mdb_del(txn, meta, &key, nullptr) == 0;
  })) << "could not take the store id away";
  std::string given;
  {
    auto opened = Node::open(dir.path() / "n");
    ASSERT_TRUE(opened) << opened.error().message;
    given = opened->store_id().value();
    EXPECT_EQ(given.size(), 32u);
  }
  EXPECT_EQ(Node::open(dir.path() / "n")->store_id().value(), given);
}

TEST(Store, LiteralsKeepDatatypeAndLanguage) {
  TempDir dir;
  Node node = make_node(dir.path());
  auto agent = node.agent("w");
  Item item;
  item.add(ex("a"), ex("int"), Term::integer(-42))
      .add(ex("a"), ex("big"), Term::literal("123456789012345678901234567890", std::string(xsd::kInteger)))
      .add(ex("a"), ex("padded"), Term::literal("007", std::string(xsd::kInteger)))
      .add(ex("a"), ex("label"), Term::lang_literal("süda", "et"))
      .add(ex("a"), ex("plain"), Term::literal("x"))
      .add(ex("a"), ex("dec"), Term::literal("72.5", std::string(xsd::kDecimal)));
  auto id = agent->store(item);
  ASSERT_TRUE(id);
  auto records = node.snapshot()->item(*id);
  ASSERT_TRUE(records);
  ASSERT_EQ(records->size(), item.triples.size());
  for (std::size_t i = 0; i < item.triples.size(); ++i) EXPECT_EQ((*records)[i].triple, item.triples[i]);
}

// RDF 1.1: rdf:langString is the datatype of language-tagged literals only. "x"^^rdf:langString
// without a tag was stored and dumped, and no RDF tool reads it back.
TEST(Store, ALangStringWithoutALanguageTagIsRefused) {
  TempDir dir;
  Node node = make_node(dir.path());
  auto agent = node.agent("w");
  auto stored = agent->store(
      Item{}.add(ex("a"), ex("label"), Term::literal("x", "http://www.w3.org/1999/02/22-rdf-syntax-ns#langString")));
  ASSERT_FALSE(stored);
  EXPECT_EQ(stored.error().code, Errc::invalid_argument);
  EXPECT_NE(stored.error().message.find("rdf:langString needs a language tag"), std::string::npos) << stored.error().message;
  EXPECT_TRUE(agent->store(Item{}.add(ex("a"), ex("label"), Term::lang_literal("x", "en"))));
}

// Through the C++ API a tag with a quote in it was stored as given, and N-Triples out of the store
// (tahvel_take, tahvel list) then held other triples than the item's; a relative datatype was
// stored too. Tags are compared without regard to case, as the RDF parser lowers them.
TEST(Store, ALanguageTagOrDatatypeThatRdfCannotWriteIsRefusedAndTagsIgnoreCase) {
  TempDir dir;
  Node node = make_node(dir.path());
  auto agent = node.agent("w");
  auto injected = agent->store(Item{}.add(ex("a"), ex("label"), Term::lang_literal("v", "en\" . <http://evil/s> <http://evil/p> \"x")));
  ASSERT_FALSE(injected);
  EXPECT_EQ(injected.error().code, Errc::invalid_argument);
  EXPECT_NE(injected.error().message.find("triple 1, object: language tag"), std::string::npos) << injected.error().message;
  for (const char* bad : {"-en", "en-", "en--us", "1en", "en_US", "en us"})
    EXPECT_FALSE(agent->store(Item{}.add(ex("a"), ex("label"), Term::lang_literal("v", bad)))) << bad;
  auto relative = agent->store(Item{}.add(ex("a"), ex("label"), Term::literal("v", "relative-datatype")));
  ASSERT_FALSE(relative);
  EXPECT_EQ(relative.error().code, Errc::invalid_iri) << relative.error().message;
  EXPECT_EQ(node.stats()->records, 0u);

  ASSERT_TRUE(agent->store(Item{}.add(ex("a"), ex("label"), Term::lang_literal("süda", "ET-ee"))));
  auto found = node.snapshot()->list({.o = Term::lang_literal("süda", "et-EE")});
  ASSERT_TRUE(found);
  ASSERT_EQ(found->size(), 1u);
  EXPECT_EQ(found->front().triple.o.language, "et-ee");
  EXPECT_TRUE(agent->store(Item{}.add(ex("a"), ex("label"), Term::lang_literal("v", "zh-Hant-TW-x-private1"))));
}

TEST(Store, PatternWithBoundObjectFindsLiteral) {
  TempDir dir;
  Node node = make_node(dir.path());
  auto agent = node.agent("w");
  for (int i = 0; i < 10; ++i) ASSERT_TRUE(agent->store(Item{}.add(ex("s" + std::to_string(i)), ex("hr"), Term::integer(60 + i % 3))));
  Pattern p;
  p.o = Term::integer(61);
  auto listed = node.snapshot()->list(p);
  ASSERT_TRUE(listed);
  EXPECT_EQ(listed->size(), 3u);
  p.o = Term::integer(99);
  EXPECT_TRUE(node.snapshot()->list(p)->empty());
}

// A pattern no record could match because it is ill-formed (a literal subject, a relative IRI,
// an `under` that is no IRI) answered OK and nothing from the C++ API, where the C API and
// subscriptions refuse it: a caller's typo read as "no data". Every read and removal by pattern
// says what is wrong with it.
TEST(Store, AnIllFormedPatternIsRefusedNamingWhatIsWrongNotAnsweredWithNothing) {
  TempDir dir;
  Node node = make_node(dir.path());
  ASSERT_TRUE(node.agent("w")->store(Item{}.add(ex("a"), ex("p"), Term::literal("x"))));
  const std::vector<std::pair<Pattern, std::string>> bad = {
      {Pattern{.s = Term::literal("x")}, "pattern subject \"x\": a subject cannot be a literal"},
      {Pattern{.p = Term::literal("x")}, "pattern predicate \"x\": a predicate must be an IRI"},
      {Pattern{.p = Term::iri("rel")}, "pattern predicate <rel>: not an absolute IRI"},
      {Pattern{.o = Term::iri("")}, "pattern object <>: not an absolute IRI"},
      {Pattern{.under = "bad iri"}, "pattern under <bad iri>: not an absolute IRI"},
      {Pattern{.source = "w"}, "pattern source <w>: not an absolute IRI"},
      // Literals no record can hold: a relative datatype, rdf:langString without a tag, a
      // language tag that is none (they answered nothing where the C API refused them).
      {Pattern{.o = Term::literal("1", "integer")},
       "pattern object \"1\"^^<integer>: its datatype <integer> is not an absolute IRI"},
      {Pattern{.o = Term::literal("x", "http://www.w3.org/1999/02/22-rdf-syntax-ns#langString")},
       "pattern object \"x\"^^<http://www.w3.org/1999/02/22-rdf-syntax-ns#langString>: a literal of datatype "
       "rdf:langString needs a language tag"},
      {Pattern{.o = Term::lang_literal("x", "not a tag")},
       "pattern object \"x\"@not a tag: language tag 'not a tag' is not letters, then '-' and letters or digits (en, et-EE)"},
  };
  {
    auto snapshot = node.snapshot();
    ASSERT_TRUE(snapshot);
    for (const auto& [pattern, message] : bad) {
      auto listed = snapshot->list(pattern);
      ASSERT_FALSE(listed) << message;
      EXPECT_EQ(listed.error().message, message);
      EXPECT_FALSE(snapshot->count(pattern)) << message;
      EXPECT_FALSE(snapshot->for_each(pattern, [](const Record&) { return true; })) << message;
    }
  }
  auto removed = node.remove({.s = Term::literal("x")});
  ASSERT_FALSE(removed);
  EXPECT_EQ(removed.error().code, Errc::invalid_argument);
  auto relative_datatype = node.remove({.o = Term::literal("x", "string")});
  ASSERT_FALSE(relative_datatype);
  EXPECT_EQ(relative_datatype.error().code, Errc::invalid_argument);
  // An empty context stays what it means: the records without one.
  EXPECT_EQ(*node.snapshot()->count({.context = ""}), 1u);
  EXPECT_EQ(*node.snapshot()->count({}), 1u);
}

TEST(Store, InvalidIriIsRefusedAndNothingIsStored) {
  TempDir dir;
  Node node = make_node(dir.path());
  auto agent = node.agent("w");
  Item item;
  item.add(ex("a"), ex("b"), Term::integer(1)).add(Term::iri("http://exa mple.org/x"), ex("b"), Term::integer(2));
  auto id = agent->store(item);
  ASSERT_FALSE(id);
  EXPECT_EQ(id.error().code, Errc::invalid_iri);
  EXPECT_NE(id.error().message.find("triple 2, subject"), std::string::npos) << id.error().message;
  EXPECT_NE(id.error().message.find("position"), std::string::npos) << id.error().message;
  EXPECT_EQ(node.stats()->records, 0u);
  EXPECT_EQ(node.stats()->terms, 4u);  // only the subscription vocabulary
}

// RDF terms are Unicode: a literal in Latin-1 stored through the API ("caf\xE9") was kept, then
// `dump` wrote it out and `load` refused the dump. The store refuses it, naming the byte.
TEST(Store, ATermThatIsNotUtf8IsRefusedNamingTheByteAndNothingIsStored) {
  TempDir dir;
  Node node = make_node(dir.path());
  auto agent = node.agent("w");
  Item item;
  item.add(ex("a"), ex("b"), Term::literal("caf\xE9 au lait"));
  auto id = agent->store(item);
  ASSERT_FALSE(id);
  EXPECT_EQ(id.error().code, Errc::invalid_argument);
  EXPECT_EQ(id.error().message, "triple 1, object: not UTF-8: byte 0xE9 at offset 3 does not begin a well-formed sequence");
  Item surrogate, in_datatype;
  surrogate.add(ex("a"), ex("b"), Term::literal("\xED\xA0\x80"));  // U+D800 as if it were a character
  in_datatype.add(ex("a"), ex("b"), Term::literal("1", "http://example.org/t\xFF"));
  EXPECT_FALSE(agent->store(surrogate));
  auto dt = agent->store(in_datatype);
  ASSERT_FALSE(dt);
  EXPECT_NE(dt.error().message.find("of the datatype"), std::string::npos) << dt.error().message;
  EXPECT_EQ(node.stats()->records, 0u);
  Item fine;
  fine.add(ex("a"), ex("b"), Term::literal(with_replacement_characters("caf\xE9")));
  ASSERT_TRUE(agent->store(fine));
  EXPECT_EQ(node.snapshot()->list({.s = ex("a")})->at(0).triple.o.value, "caf\xEF\xBF\xBD");
}

TEST(Store, LiteralOverLimitIsRefusedAndNothingIsStored) {
  TempDir dir;
  InitOptions options;
  options.max_literal_bytes = 100;
  Node node = make_node(dir.path(), options);
  auto agent = node.agent("w");
  Item item;
  item.add(ex("a"), ex("b"), Term::literal("short")).add(ex("a"), ex("c"), Term::literal(std::string(101, 'x')));
  auto id = agent->store(item);
  ASSERT_FALSE(id);
  EXPECT_EQ(id.error().code, Errc::literal_too_large);
  EXPECT_NE(id.error().message.find("triple 2, object"), std::string::npos) << id.error().message;
  EXPECT_NE(id.error().message.find("101"), std::string::npos);
  EXPECT_EQ(node.stats()->records, 0u);
}

TEST(Store, FullStoreIsRefusedWithClearErrorAndNothingHalfWritten) {
  TempDir dir;
  InitOptions options;
  options.max_map_bytes = 2 << 20;
  Node node = make_node(dir.path(), options);
  auto agent = node.agent("w");
  std::uint64_t stored = 0;
  Result<std::uint64_t> last = std::uint64_t{0};
  for (int i = 0; i < 100000; ++i) {
    Item item;
    for (int j = 0; j < 10; ++j) item.add(ex("s" + std::to_string(i)), ex("p" + std::to_string(j)), Term::literal(std::string(200, 'a' + j) + std::to_string(i)));
    last = agent->store(item);
    if (!last) break;
    ++stored;
  }
  ASSERT_FALSE(last);
  EXPECT_EQ(last.error().code, Errc::store_full);
  EXPECT_NE(last.error().message.find("store full"), std::string::npos) << last.error().message;
  auto stats = node.stats();
  EXPECT_EQ(stats->records, stored * 10);  // whole items only
  EXPECT_EQ(stats->items, stored);
  // Removing data makes room again: the oldest half here. (In a store this small the removals'
  // reserve, which data may not take once a removal has used it, is half of the maximum; and
  // a B-tree frees a page only when most of what it held is gone, as when the oldest go.)
  for (std::uint64_t item = 1; item <= stored / 2; ++item) {
    const std::uint64_t id = node.snapshot()->list({.s = ex("s" + std::to_string(item - 1))})->at(0).meta.item;
    auto removed = node.remove_item(id);  // no snapshot held: it would keep the map from growing
    ASSERT_TRUE(removed) << removed.error().message;
  }
  Item small;
  small.add(ex("x"), ex("y"), Term::integer(1));
  auto after = agent->store(small);
  EXPECT_TRUE(after) << after.error().message << " (used " << node.stats()->used_bytes << ", high water "
                     << node.stats()->high_water_bytes << ", map " << node.stats()->map_bytes << ")";
}

// A store whose pages are all free but pinned by an old snapshot (a `dump` stopped in a pipe)
// said only "reached its maximum", which read as a size problem: it names the reader now.
TEST(Store, AStoreFullOfPagesAnOldSnapshotPinsNamesThatReader) {
  TempDir dir;
  {
    Node made = make_node(dir.path(), {.max_map_bytes = 2 << 20});
    ASSERT_TRUE(made.agent("w")->store(Item{}.add(ex("first"), ex("p"), Term::integer(0))));
  }
  int held[2], release[2];
  ASSERT_EQ(pipe(held), 0);
  ASSERT_EQ(pipe(release), 0);
  const pid_t reader = fork();
  if (reader == 0) {  // another process, as a `dump` is: opens the store and holds a snapshot
    auto node = Node::open(dir.path());
    auto snapshot = node ? node->snapshot() : Result<Snapshot>(fail(Errc::io, ""));
    const char ok = snapshot ? 'y' : 'n';
    char go = 0;
    _exit(write(held[1], &ok, 1) == 1 && read(release[0], &go, 1) >= 0 ? 0 : 1);
  }
  struct AtEnd {  // the reader does not wait for ever when an assertion below ends the test
    pid_t reader;
    ~AtEnd() {
      if (reader <= 0) return;  // reaped already (kill(-1) would signal every process)
      kill(reader, SIGKILL);
      waitpid(reader, nullptr, 0);
    }
  } reaped{reader};
  char ok = 0;
  ASSERT_EQ(read(held[0], &ok, 1), 1);
  ASSERT_EQ(ok, 'y');
  Node node = Node::open(dir.path()).value();
  auto agent = node.agent("w");
  Result<std::uint64_t> last = std::uint64_t{0};
  for (int i = 0; i < 10000 && last; ++i) {
    Item item;
    for (int j = 0; j < 10; ++j) item.add(ex("s" + std::to_string(i)), ex("p" + std::to_string(j)), Term::literal(std::string(200, 'a')));
    last = agent->store(item);
    if (last) {
      ASSERT_TRUE(node.remove_item(*last));  // never more than one item held
    }
  }
  const char go = 'g';
  EXPECT_EQ(write(release[1], &go, 1), 1);
  int status = 0;
  waitpid(reader, &status, 0);
  reaped.reader = 0;  // reaped: nothing for the guard to do
  ASSERT_FALSE(last);
  EXPECT_EQ(last.error().code, Errc::store_full);
  EXPECT_NE(last.error().message.find("a snapshot that process " + std::to_string(reader) + " ("), std::string::npos)
      << last.error().message;
  // The read ended (its process, here): the freed pages serve again.
  EXPECT_TRUE(agent->store(Item{}.add(ex("after"), ex("p"), Term::integer(1))));
  for (int fd : {held[0], held[1], release[0], release[1]}) close(fd);
}

// The removal log is bounded by size too: removed records can be large (a remote query's
// answer chunks, removed from the asking board as they are read), and a count alone let it keep
// hundreds of MB of them. Watchers still see the newest removals, with their terms.
TEST(Store, TheRemovalLogOfLargeRecordsStaysWithinItsSizeAndKeepsTheNewest) {
  TempDir dir;
  Node node = make_node(dir.path(), {.max_map_bytes = std::uint64_t{1} << 32});  // log: 1 MB
  auto agent = node.agent("w");
  std::vector<std::uint64_t> items;
  for (int i = 0; i < 200; ++i) {
    Item item;
    item.add(ex("chunk" + std::to_string(i)), ex("bytes"), Term::literal(std::string(50'000, static_cast<char>('a' + i % 26))));
    auto stored = agent->store(item);
    ASSERT_TRUE(stored) << stored.error().message;
    items.push_back(*stored);
  }
  const std::uint64_t before_removals = node.snapshot()->last_seq();
  for (std::uint64_t item : items) ASSERT_TRUE(node.remove_item(item));
  auto changes = node.watch(before_removals, std::chrono::milliseconds(0));
  ASSERT_TRUE(changes) << changes.error().message;
  ASSERT_FALSE(changes->empty());
  EXPECT_LE(changes->size(), 21u) << "1 MB of 50-KB removals";
  EXPECT_TRUE(changes->back().removed);
  EXPECT_EQ(changes->back().record.triple.s, ex("chunk199"));
  EXPECT_EQ(changes->back().record.triple.o.value, std::string(50'000, static_cast<char>('a' + 199 % 26)));
  // 10 MB were removed; the store does not keep them.
  EXPECT_LT(node.stats()->used_bytes, std::uint64_t{4} << 20);
}

// The removals' reserve beyond the maximum is theirs: data written after a removal grew the map
// into it must not fill it (it did: the file grew past the maximum and then even removals were
// refused). Full and emptied again, over and over: every removal goes through, the file stays
// within the maximum and the reserve, and the status figures say the store is full.
TEST(Store, AFullStoreCanAlwaysBeEmptiedAndDataNeverTakesTheRemovalsReserve) {
  TempDir dir;
  constexpr std::uint64_t kMax = 4 << 20;
  Node node = make_node(dir.path(), {.max_map_bytes = kMax});
  auto agent = node.agent("w");
  int next = 0;
  auto fill = [&] {
    for (;;) {
      Item item;
      for (int j = 0; j < 200; ++j)
        item.add(ex("s" + std::to_string(next)), ex("p" + std::to_string(j)), Term::literal("value " + std::to_string(next) + " padding"));
      auto stored = agent->store(item);
      if (!stored) return stored.error();
      ++next;
    }
  };
  for (int round = 0; round < 4; ++round) {
    const Error full = fill();
    ASSERT_EQ(full.code, Errc::store_full) << full.message;
    // After removals the store refuses short of its maximum, and says why, not "reached its
    // maximum" (a probe's store was nearly empty).
    if (round > 0) {
      EXPECT_NE(full.message.find(" that writes may fill (of its maximum of " + std::to_string(kMax) + " bytes"), std::string::npos)
          << full.message;
    }
    auto stats = node.stats();
    EXPECT_GE(stats->high_water_bytes * 10, kMax * 9) << "round " << round << ": full, so at the high-water mark";
    EXPECT_LE(stats->high_water_bytes, kMax + kMax / 16 + (1 << 20)) << "round " << round;
    // Half of what is there goes; each removal must go through.
    auto items = node.snapshot()->list({.p = ex("p0")});
    ASSERT_TRUE(items);
    for (std::size_t i = 0; i < items->size(); i += 2) {
      auto removed = node.remove_item(items->at(i).meta.item);
      ASSERT_TRUE(removed) << "round " << round << ", removal " << i / 2 << " of " << items->size() / 2 << ": " << removed.error().message
                           << " (high water " << node.stats()->high_water_bytes << ", used " << node.stats()->used_bytes << ")";
    }
  }
  auto after = agent->store(Item{}.add(ex("x"), ex("y"), Term::integer(1)));
  EXPECT_TRUE(after) << after.error().message << " (high water " << node.stats()->high_water_bytes << ", used "
                     << node.stats()->used_bytes << ")";
}

// A 1 MiB store full of items with 2 KB literals: removing a third of them freed 20 KB, as the
// removal log kept what was removed (at least 256 KB of it, a quarter of the store), and the
// next small write was refused. The log of a small store keeps at most 1/64 of it. The oldest
// third goes, as retention takes it (`remove --until`): long literals lie apart from the short
// terms (format 4), so the pages they filled empty whole; LMDB frees no page left part full, so
// removing every third of them would free little.
TEST(Store, RemovingAThirdOfASmallFullStoreMakesRoomForMore) {
  TempDir dir;
  Node node = make_node(dir.path(), {.max_map_bytes = 1 << 20});
  auto agent = node.agent("w");
  std::vector<std::uint64_t> items;
  for (;;) {
    const std::string i = std::to_string(items.size());
    auto written = agent->store(Item{}.add(ex("s" + i), ex("kept"), Term::literal(std::string(2000, 'b') + i)));
    if (!written) {
      ASSERT_EQ(written.error().code, Errc::store_full) << written.error().message;
      break;
    }
    items.push_back(*written);
  }
  const std::size_t stored = items.size();
  ASSERT_GT(stored, 100u);
  std::size_t removed_items = 0;
  for (std::size_t k = 0; k < stored / 3; ++k) {
    auto gone = node.remove_item(items[k]);
    ASSERT_TRUE(gone) << "removal " << k << ": " << gone.error().message;
    ++removed_items;
  }
  for (int k = 0; k < 20; ++k) {
    auto after = agent->store(Item{}.add(ex("new" + std::to_string(k)), ex("kept"), Term::literal(std::string(2000, 'c'))));
    ASSERT_TRUE(after) << "write " << k << " after removing " << removed_items << " of " << stored << ": " << after.error().message;
  }
}

// Removing a recording's oldest raw ECG freed almost nothing while the agents deriving from it
// ran: their short terms (R-peak lists, IRIs) lay on the same pages as the samples, each page
// left a third full, and LMDB frees no such page (4,951 chunks removed, 115 KB freed of 4.6 MB:
// an integrator's full home, session 87). Long terms lie apart (format 4): the pages of the
// oldest samples empty whole.
TEST(Store, RemovingTheOldestChunksFreesTheirPagesThoughShortTermsWereWrittenBetween) {
  TempDir dir;
  Node node = make_node(dir.path(), {.max_map_bytes = 16 << 20});
  auto ecg = node.agent("ecg"), rpeak = node.agent("rpeak");
  constexpr int kChunks = 2000;
  constexpr std::size_t kSampleBytes = 900;
  for (int i = 0; i < kChunks; ++i) {
    const std::string n = std::to_string(i);
    Item chunk;
    chunk.asserted_at = 1'000'000'000LL * (i + 1);
    chunk.add(ex("rec/chunk/" + n), ex("samples"), Term::literal(std::string(kSampleBytes - n.size(), 's') + n));
    ASSERT_TRUE(ecg->store(chunk));
    Item peaks;  // about half as much again in short terms, on the same pages
    peaks.asserted_at = chunk.asserted_at;
    for (int k = 0; k < 4; ++k)
      peaks.add(ex("rec/rpeaks/" + n), ex("p" + std::to_string(k)), Term::literal(n + " 1234 2345 3456 4567 5678 6789 7890 8901 9012 " + std::to_string(k)));
    ASSERT_TRUE(rpeak->store(peaks));
  }
  const std::uint64_t before = node.stats()->used_bytes;
  auto removed = node.remove({.p = ex("samples"), .until = 1'000'000'000LL * (kChunks / 2) + 1});
  ASSERT_TRUE(removed) << removed.error().message;
  ASSERT_EQ(*removed, static_cast<std::uint64_t>(kChunks / 2));
  const std::uint64_t after = node.stats()->used_bytes;
  const std::uint64_t samples_removed = kChunks / 2 * kSampleBytes;
  EXPECT_GE(before - std::min(before, after), samples_removed / 2)
      << "used " << before << " bytes before, " << after << " after removing " << samples_removed << " bytes of samples";
}

// A removed record's copy in the removal log (R17) is one run of pages as long as its literal:
// a 1 MiB store full of 200-300 KB literals (the limit is 1 MB) could not remove a record, since
// the removals' reserve beyond the maximum (192 KB) is shorter than one copy: neither one item
// nor a pattern went, and the store could not be emptied. Every removal goes now, and the store
// takes data again.
TEST(Store, AFullStoreOfLiteralsLongerThanTheRemovalsReserveCanBeEmptied) {
  TempDir dir;
  Node node = make_node(dir.path(), {.max_map_bytes = 1 << 20});
  auto agent = node.agent("w");
  std::vector<std::uint64_t> items;
  for (int n = 0;; ++n) {
    const std::size_t bytes = n % 2 == 0 ? 300'000 : 200'000;
    auto stored = agent->store(Item{}.add(ex("s"), ex("p"), Term::literal(std::string(bytes, static_cast<char>('a' + n)))));
    if (!stored) {
      ASSERT_EQ(stored.error().code, Errc::store_full) << stored.error().message;
      break;
    }
    items.push_back(*stored);
  }
  ASSERT_GE(items.size(), 2u);
  // A small write still fits beside them.
  ASSERT_TRUE(agent->store(Item{}.add(ex("s"), ex("q"), Term::integer(1))));
  auto one = node.remove_item(items.front());
  ASSERT_TRUE(one) << one.error().message;
  auto rest = node.remove({.p = ex("p")});
  ASSERT_TRUE(rest) << rest.error().message;
  EXPECT_EQ(*rest, items.size() - 1);
  EXPECT_EQ(*node.snapshot()->count({.p = ex("p")}), 0u);
  auto after = agent->store(Item{}.add(ex("s"), ex("p"), Term::literal(std::string(200'000, 'z'))));
  EXPECT_TRUE(after) << after.error().message;
}

// Stores item_of(0), item_of(1), ... in transactions of 200 until the store is full; returns how
// many were stored (0 after a failure other than store_full).
std::uint64_t fill_until_full(Agent& agent, const std::function<Item(std::uint64_t)>& item_of) {
  for (std::uint64_t stored = 0;; stored += 200) {
    std::vector<Item> batch;
    for (std::uint64_t n = stored; n < stored + 200; ++n) batch.push_back(item_of(n));
    auto written = agent.store_all(batch);
    if (!written) {
      EXPECT_EQ(written.error().code, Errc::store_full) << written.error().message;
      return written.error().code == Errc::store_full ? stored : 0;
    }
  }
}

// One pattern naming tens of thousands of scattered records touches more pages in one
// transaction than the removal reserve holds: `remove -p` of a full store failed with store_full
// however often it was tried. It goes in parts now, and the store takes data again.
TEST(Store, AFullStoreIsEmptiedByOneLargeRemovalByPattern) {
  TempDir dir;
  constexpr std::uint64_t kMax = 8 << 20;
  Node node = make_node(dir.path(), {.max_map_bytes = kMax});
  auto agent = node.agent("w");
  const std::uint64_t stored = fill_until_full(*agent, [](std::uint64_t n) {
    const std::string i = std::to_string(n);
    return Item{}.add(ex("s" + i), ex("p" + std::to_string(n % 3)), Term::literal("v" + i)).add(ex("s" + i), ex("q"), Term::integer(static_cast<std::int64_t>(n)));
  });
  ASSERT_GT(stored, 10'000u);
  auto removed = node.remove({.p = ex("q")});
  ASSERT_TRUE(removed) << removed.error().message;
  EXPECT_EQ(*removed, stored);
  EXPECT_EQ(*node.snapshot()->count({.p = ex("q")}), 0u);
  EXPECT_EQ(*node.snapshot()->count({}), stored);  // the other record of each item stays
  for (const char* p : {"p0", "p1", "p2"}) ASSERT_TRUE(node.remove({.p = ex(p)}));
  EXPECT_EQ(*node.snapshot()->count({}), 0u);
  auto after = agent->store(Item{}.add(ex("x"), ex("y"), Term::integer(1)));
  EXPECT_TRUE(after) << after.error().message;
}

// The same with --cascade: each part removed matches whose sub-trees a list collected again
// per part no longer reached, and those stayed behind.
TEST(Store, AFullStoreRemovalInPartsTakesEachMatchsSubTreeToo) {
  TempDir dir;
  Node node = make_node(dir.path(), {.max_map_bytes = 8 << 20});
  auto agent = node.agent("w");
  const std::uint64_t stored = fill_until_full(*agent, [](std::uint64_t n) {
    const std::string i = std::to_string(n);
    return Item{}.add(ex("s" + i), ex("has"), ex("o" + i)).add(ex("o" + i), ex("v"), Term::literal("value " + i));
  });
  ASSERT_GT(stored, 5'000u);
  auto removed = node.remove({.p = ex("has")}, /*cascade=*/1);
  ASSERT_TRUE(removed) << removed.error().message;
  EXPECT_EQ(*removed, 2 * stored);
  EXPECT_EQ(*node.snapshot()->count({}), 0u);
}

// A snapshot held in the writing process keeps the map from growing (LMDB may not remap under
// an open transaction of the process): the write that needs a larger map fails with an io error
// that says so, not with store_full (the store is not full), and succeeds once it is released.
TEST(Store, AWriteThatMustGrowTheMapWhileTheProcessHoldsASnapshotSaysSoAndSucceedsAfter) {
  TempDir dir;
  Node node = make_node(dir.path());
  auto agent = node.agent("w");
  const std::string big(1 << 19, 'x');  // 0.5 MB literals, each its own: the 64 MB first map fills soon
  std::optional<Snapshot> held(node.snapshot().value());
  Result<std::uint64_t> stored = std::uint64_t{0};
  int i = 0;
  for (; i < 400 && stored; ++i) stored = agent->store(Item{}.add(ex("s" + std::to_string(i)), ex("p"), Term::literal(big + std::to_string(i))));
  ASSERT_FALSE(stored) << "200 MB went into the first map";
  EXPECT_EQ(stored.error().code, Errc::io) << stored.error().message;
  EXPECT_NE(stored.error().message.find("release the snapshot and retry"), std::string::npos) << stored.error().message;
  held.reset();
  EXPECT_TRUE(agent->store(Item{}.add(ex("s" + std::to_string(i)), ex("p"), Term::literal(big + std::to_string(i)))));
}

// Runs `body` in a child process with its own mount namespace and a tmpfs of `size` mounted on
// `dir`. The child ends through `say(text, status)`; a child that cannot mount ends with 77.
using Say = std::function<void(const std::string& text, int status)>;
struct ChildEnd {
  int status = -1;  // exit status, or -1 when killed
  int signal = 0;
  std::string said;
};
ChildEnd run_in_tmpfs(const std::filesystem::path& dir, const char* size, const std::function<void(const Say&)>& body) {
  int pipe_fds[2];
  if (pipe(pipe_fds) != 0) return {.said = "pipe failed"};
  const pid_t pid = fork();
  if (pid < 0) return {.said = "fork failed"};
  if (pid == 0) {
    close(pipe_fds[0]);
    const Say say = [&](const std::string& text, int status) {
      (void)!write(pipe_fds[1], text.data(), text.size());
      _exit(status);
    };
    const std::string options = std::string("size=") + size;
    if (unshare(CLONE_NEWNS) != 0 || mount("none", "/", nullptr, MS_REC | MS_PRIVATE, nullptr) != 0 ||
        mount("tmpfs", dir.c_str(), "tmpfs", 0, options.c_str()) != 0)
      say("cannot mount a tmpfs here", 77);
    body(say);
    say("the body ended without saying how", 1);
  }
  close(pipe_fds[1]);
  ChildEnd end;
  char buffer[512];
  for (ssize_t n; (n = read(pipe_fds[0], buffer, sizeof buffer)) > 0;) end.said.append(buffer, static_cast<std::size_t>(n));
  close(pipe_fds[0]);
  int status = 0;
  if (waitpid(pid, &status, 0) != pid) return end;
  if (WIFEXITED(status)) end.status = WEXITSTATUS(status);
  if (WIFSIGNALED(status)) end.signal = WTERMSIG(status);
  return end;
}

// run_in_tmpfs with a new store at dir/store and its agent "w".
ChildEnd run_on_small_disk(const std::filesystem::path& dir, const char* size,
                           const std::function<void(const Say&, Node&, Agent&)>& body) {
  return run_in_tmpfs(dir, size, [&](const Say& say) {
    if (auto made = Node::init(dir / "store", {.iri = "http://example.org/n"}); !made) say("init: " + made.error().message, 1);
    auto node = Node::open(dir / "store");
    if (!node) say("open: " + node.error().message, 1);
    auto agent = node->agent("w");
    if (!agent) say("agent: " + agent.error().message, 1);
    body(say, *node, *agent);
  });
}

// An init on a disk without room for the store's first write (3 MiB free; the map reserves
// more) left the new store in place without its vocabulary: every later open failed on
// "vocabulary term missing", and init again said the directory "already holds a store". It
// leaves nothing now, and the same init succeeds once there is room. Its error named the
// temporary directory it was made in and told to remove records from a store not yet there.
TEST(Store, AnInitWithoutRoomForItsFirstWriteLeavesNoStore) {
  TempDir dir;
  const ChildEnd end = run_in_tmpfs(dir.path(), "3m", [&](const Say& say) {
    auto made = Node::init(dir.path() / "store", {.iri = "http://example.org/n"});
    if (made) say("a 3 MiB disk took a new store", 2);
    if (std::filesystem::exists(dir.path() / "store" / "data.mdb")) say("init failed (" + made.error().message + ") and left data.mdb", 1);
    auto opened = Node::open(dir.path() / "store");
    if (opened || opened.error().code != Errc::not_found) say("open after the failed init: " + (opened ? std::string("opened") : opened.error().message), 1);
    // Named as the store being made, not as the directory it was made in (gone by then), and
    // with no records to remove (there is no store yet).
    const std::string& message = made.error().message;
    if (message.find("making a store in " + (dir.path() / "store").string() + ": ") != 0 || message.find(".init-") != std::string::npos ||
        message.find("remove records") != std::string::npos || !message.ends_with("; nothing was made"))
      say("the failed init said: " + message, 1);
    say(message, 0);
  });
  if (end.status == 77) GTEST_SKIP() << end.said;
  if (end.status == 2) GTEST_SKIP() << "this filesystem gives the store its first write: " << end.said;
  EXPECT_EQ(end.status, 0) << end.said;
}

// A disk that fills under the store: the data file is as large as the map but sparse, and a
// page written where it has no block used to be SIGBUS in the writing process (a supervisor,
// and with it every program of the node). It is a store_full error naming the disk, whole
// items only, and removing data still works, from this process and from a fresh one. Runs in a
// child with a 24 MiB tmpfs (skipped where mounting is not allowed).
TEST(Store, AFullDiskIsAStoreFullErrorNotACrash) {
  TempDir dir;
  const ChildEnd end = run_on_small_disk(dir.path(), "24m", [&](const Say& say, Node& node, Agent& agent) {
    std::uint64_t stored = 0;
    Result<std::uint64_t> last = std::uint64_t{0};
    for (int i = 0; i < 2000 && last; ++i) {
      Item item;
      item.add(ex("chunk" + std::to_string(i)), ex("data"), Term::literal(std::string(200000, 'a' + i % 26) + std::to_string(i)));
      if ((last = agent.store(item))) ++stored;
    }
    if (last) say("the 24 MiB disk took 400 MB", 1);
    if (last.error().code != Errc::store_full || last.error().message.find("the disk holding") == std::string::npos)
      say("wrong error: " + last.error().message, 1);
    if (node.stats()->items != stored) say("items " + std::to_string(node.stats()->items) + " of " + std::to_string(stored), 1);
    if (auto removed = node.remove_item(1); !removed) say("remove: " + removed.error().message, 1);
    // A fresh process (`tahvel rm` run to make room) removes too: it has reserved nothing itself.
    const pid_t fresh = fork();
    if (fresh == 0) {
      auto again = Node::open(dir.path() / "store");
      _exit(again && again->remove_item(2) ? 0 : 3);
    }
    int fresh_status = 0;
    if (fresh < 0 || waitpid(fresh, &fresh_status, 0) != fresh || !WIFEXITED(fresh_status) || WEXITSTATUS(fresh_status) != 0)
      say("a fresh process could not remove an item from the store on the full disk", 1);
    say(last.error().message, 0);
  });
  ASSERT_EQ(end.signal, 0) << "the writer died of signal " << end.signal << " (7: SIGBUS)";
  if (end.status == 77) GTEST_SKIP() << end.said;
  EXPECT_EQ(end.status, 0) << end.said;
}

// A small store on a small disk that filled, then emptied: its free pages (3 MB) were never the
// 4 MB a write on a full disk required of them, so it refused every write for good, even of 50
// bytes, telling to remove records it no longer had. A write that its free pages hold goes in.
TEST(Store, AStoreEmptiedOnAFullDiskTakesAWriteItsFreePagesHold) {
  TempDir dir;
  const ChildEnd end = run_on_small_disk(dir.path(), "8m", [&](const Say& say, Node& node, Agent& agent) {
    Result<std::uint64_t> last = std::uint64_t{0};
    for (int i = 0; last && i < 1000; ++i) {
      Item item;
      item.add(ex("f" + std::to_string(i)), ex("p"), Term::literal(std::string(100000, 'a' + i % 26) + std::to_string(i)));
      last = agent.store(item);
    }
    if (last) say("an 8 MiB disk took 100 MB", 1);
    if (last.error().code != Errc::store_full) say("wrong error: " + last.error().message, 1);
    auto removed = node.remove(Pattern{.p = ex("p")});
    if (!removed) say("remove: " + removed.error().message, 1);
    Item small;
    small.add(ex("x"), ex("q"), Term::literal("small"));
    if (auto stored = agent.store(small); !stored) say("a 50-byte write to the emptied store: " + stored.error().message, 1);
    say("stored", 0);
  });
  ASSERT_EQ(end.signal, 0) << "the writer died of signal " << end.signal << " (7: SIGBUS)";
  if (end.status == 77) GTEST_SKIP() << end.said;
  EXPECT_EQ(end.status, 0) << end.said;
}

// Many small records on a disk that filled: the way to win space back, removing some, took more
// new pages at once than the store had allocated (1 MiB) and died of SIGBUS from 1,150 records
// of 80 bytes up. It removes them all now, in parts that fit.
TEST(Store, RemovingManyRecordsOnAFullDiskIsNotACrash) {
  TempDir dir;
  const ChildEnd end = run_on_small_disk(dir.path(), "12m", [&](const Say& say, Node& node, Agent& agent) {
    Result<std::uint64_t> last = std::uint64_t{0};
    for (int i = 0; last; ++i) {
      Item item;
      for (int k = 0; k < 20; ++k) {
        const int n = i * 20 + k;
        item.add(ex("s" + std::to_string(n)), ex("p" + std::to_string(n % 7)), Term::literal(std::string(80, 'x') + std::to_string(n)));
      }
      last = agent.store(item);
      if (i > 100000) say("a 12 MiB disk took 2 million records", 1);
    }
    if (last.error().code != Errc::store_full) say("wrong error: " + last.error().message, 1);
    Pattern third;
    third.p = ex("p3");
    const std::uint64_t before = node.stats()->records;
    auto removed = node.remove(third);
    if (!removed) say("remove: " + removed.error().message, 1);
    if (*removed < 1500) say("only " + std::to_string(*removed) + " records matched", 1);
    if (node.stats()->records != before - *removed) say("the count of records is off after the removal", 1);
    say(std::to_string(*removed) + " removed", 0);
  });
  ASSERT_EQ(end.signal, 0) << "the remover died of signal " << end.signal << " (7: SIGBUS)";
  if (end.status == 77) GTEST_SKIP() << end.said;
  EXPECT_EQ(end.status, 0) << end.said;
}

// Records of 300 KB literals on a disk that filled: a removal logs each record's terms (R17),
// so a part of one record took 300 KB of new pages, and after the first few parts the next went
// beyond what the store had allocated: SIGBUS every time (a probe), or the store left unable to
// take any removal. Each part now stays within what is allocated; what cannot is refused with
// how much to free.
TEST(Store, RemovingRecordsWithLargeLiteralsOnAFullDiskIsNotACrash) {
  TempDir dir;
  const ChildEnd end = run_on_small_disk(dir.path(), "24m", [&](const Say& say, Node& node, Agent& agent) {
    Result<std::uint64_t> last = std::uint64_t{0};
    for (int i = 0; last; ++i) {
      last = agent.store(Item{}.add(ex("s" + std::to_string(i)), ex("p"), Term::literal(std::string(300'000 + i, 'a' + i % 26))));
      if (i > 1000) say("a 24 MiB disk took 300 MB", 1);
    }
    if (last.error().code != Errc::store_full) say("wrong error: " + last.error().message, 1);
    const std::uint64_t before = node.stats()->records;
    Pattern all;
    all.p = ex("p");
    auto removed = node.remove(all);
    const std::uint64_t after = node.stats()->records;
    if (removed) {
      if (after != 0) say(std::to_string(after) + " records left after a removal that succeeded", 1);
      say("all " + std::to_string(*removed) + " removed", 0);
    }
    if (removed.error().code != Errc::store_full) say("wrong error: " + removed.error().message, 1);
    if (removed.error().message.find("MB on that disk and remove again") == std::string::npos)
      say("the error does not say what to free: " + removed.error().message, 1);
    // A part of one record fits what is allocated: a refusal comes after some went.
    if (after >= before) say("nothing was removed", 1);
    say(std::to_string(before - after) + " removed, then: " + removed.error().message, 0);
  });
  ASSERT_EQ(end.signal, 0) << "the remover died of signal " << end.signal << " (7: SIGBUS)";
  if (end.status == 77) GTEST_SKIP() << end.said;
  EXPECT_EQ(end.status, 0) << end.said;
}

// A disk that filled, then the store emptied: the removals logged copies of what they removed
// (R17), up to 16 MB on a store of the default maximum, more than such a disk has, and a write
// still asked the disk for room to grow beyond the last page in use; every write was refused
// until something else on the disk was deleted (a probe). On a full disk the log keeps 256 KB,
// and writes reuse the freed pages, until those are taken; then the refusal says how much to
// free. Large literals, which need runs of pages the free ones may not have, are refused rather
// than written beyond what the disk holds (SIGBUS).
TEST(Store, AStoreEmptiedOnAFullDiskTakesWritesAgainInThePagesItFreed) {
  TempDir dir;
  const ChildEnd end = run_on_small_disk(dir.path(), "16m", [&](const Say& say, Node& node, Agent& agent) {
    auto batch = [](int i) {
      Item item;
      for (int k = 0; k < 20; ++k) {
        const int n = i * 20 + k;
        item.add(ex("s" + std::to_string(n)), ex("p" + std::to_string(n % 4)), Term::literal(std::string(150, 'a' + n % 26) + std::to_string(n)));
      }
      return item;
    };
    int stored = 0;
    Result<std::uint64_t> last = std::uint64_t{0};
    for (; last; ++stored) {
      last = agent.store(batch(stored));
      if (stored > 100000) say("a 16 MiB disk took 2 million records", 1);
    }
    if (last.error().code != Errc::store_full) say("wrong error filling the disk: " + last.error().message, 1);
    // All of it: removing one predicate of four leaves every page three quarters full (B-tree
    // pages are merged under a quarter), and frees little whatever the disk.
    for (int p = 0; p < 4; ++p) {
      Pattern pattern;
      pattern.p = ex("p" + std::to_string(p));
      if (auto removed = node.remove(pattern); !removed) say("remove p" + std::to_string(p) + ": " + removed.error().message, 1);
    }
    int again = 0;
    for (last = std::uint64_t{0}; last; ++again) last = agent.store(batch(stored + again));
    if (again < 2) say("no write went into the pages the removals freed: " + last.error().message, 1);
    if (last.error().code != Errc::store_full || last.error().message.find("MB on that disk") == std::string::npos)
      say("the refusal once the freed pages are taken does not say what to free: " + last.error().message, 1);
    auto large = agent.store(Item{}.add(ex("large"), ex("p"), Term::literal(std::string(2'000'000, 'z'))));
    if (large) say("a 2 MB literal went onto a full disk", 1);
    auto report = node.check();
    if (!report || !report->problems.empty())
      say("check: " + (report ? report->problems.front() : report.error().message), 1);
    say(std::to_string(again - 1) + " items stored after the removals, then: " + last.error().message, 0);
  });
  ASSERT_EQ(end.signal, 0) << "the writer died of signal " << end.signal << " (7: SIGBUS)";
  if (end.status == 77) GTEST_SKIP() << end.said;
  EXPECT_EQ(end.status, 0) << end.said;
}

// A backup is the store as of one snapshot, under a store id of its own: a store restored from
// it goes on from a point its peers have passed, and must be another store to them
// (docs/protocol.md P6a). No lock file of the copying is left in it.
TEST(Store, ABackupHoldsTheSameRecordsUnderAStoreIdOfItsOwn) {
  TempDir dir, copies;
  ASSERT_TRUE(Node::init(dir.path(), {.iri = "http://example.org/n"}));
  auto node = Node::open(dir.path());
  ASSERT_TRUE(node);
  for (int i = 0; i < 3; ++i) ASSERT_TRUE(node->agent("w")->store(Item{}.add(ex("a"), ex("p"), Term::integer(i))));
  const std::filesystem::path backup = copies.path() / "copy";
  ASSERT_TRUE(node->back_up(backup));
  EXPECT_FALSE(std::filesystem::exists(backup / "lock.mdb"));
  auto copy = Node::open(backup);
  ASSERT_TRUE(copy) << copy.error().message;
  EXPECT_NE(copy->store_id().value(), node->store_id().value());
  EXPECT_EQ(copy->store_id().value().size(), node->store_id().value().size());
  EXPECT_EQ(copy->snapshot()->list({.p = ex("p")})->size(), 3u);
  EXPECT_EQ(copy->stats()->last_seq, node->stats()->last_seq) << "the same ids: it goes on from the same point";
  EXPECT_TRUE(copy->check().value().problems.empty());
  // It names the store it is a copy of: a parent restored from it tells a child that was
  // linked with that store (docs/protocol.md P6e).
  EXPECT_EQ(copy->copied_from().value(), std::vector<std::string>{node->store_id().value()});
  EXPECT_TRUE(node->copied_from().value().empty()) << "the original was never a copy";
}

// A copy of a copy names both stores, nearest first, and a copy's id renewed (a rollback a
// peer showed, P6a) puts the id it had first. The list is bounded.
TEST(Store, ACopyOfACopyNamesEveryStoreItCameFromNearestFirst) {
  TempDir dir, copies;
  ASSERT_TRUE(Node::init(dir.path(), {.iri = "http://example.org/n"}));
  auto original = Node::open(dir.path());
  ASSERT_TRUE(original);
  ASSERT_TRUE(original->back_up(copies.path() / "first"));
  auto first = Node::open(copies.path() / "first");
  ASSERT_TRUE(first);
  ASSERT_TRUE(first->back_up(copies.path() / "second"));
  auto second = Node::open(copies.path() / "second");
  ASSERT_TRUE(second);
  EXPECT_EQ(second->copied_from().value(), (std::vector<std::string>{first->store_id().value(), original->store_id().value()}));
  const std::string before = second->store_id().value();
  ASSERT_TRUE(second->renew_store_id());
  EXPECT_EQ(second->copied_from().value(),
            (std::vector<std::string>{before, first->store_id().value(), original->store_id().value()}));
  for (int i = 0; i < 20; ++i) ASSERT_TRUE(second->renew_store_id());
  EXPECT_EQ(second->copied_from().value().size(), 16u);
}

// A store copied with `cp -a` (or restored from tar or rsync, or moved to another disk) goes on
// from the point it was copied at, which its peers may have passed; up to session 63 it kept the
// id, and a restore from such a copy could lose items (docs/protocol.md P6a). Its data file is
// another file: its first open gives it an id of its own, which it keeps. The original, and a
// store moved within its filesystem (the same file), keep theirs.
TEST(Store, AStoreCopiedToAnotherFileTakesAStoreIdOfItsOwnAtItsFirstOpen) {
  TempDir dir, copies;
  const std::filesystem::path original = dir.path() / "store", copied = copies.path() / "copy",
                              moved = copies.path() / "moved";
  std::string id;
  {
    ASSERT_TRUE(Node::init(original, {.iri = "http://example.org/n"}));
    auto node = Node::open(original);
    ASSERT_TRUE(node);
    ASSERT_TRUE(node->agent("w")->store(Item{}.add(ex("a"), ex("p"), Term::integer(1))));
    id = node->store_id().value();
  }
  std::filesystem::copy(original, copied, std::filesystem::copy_options::recursive);
  std::string copy_id;
  {
    auto copy = Node::open(copied);
    ASSERT_TRUE(copy) << copy.error().message;
    copy_id = copy->store_id().value();
    EXPECT_NE(copy_id, id);
    EXPECT_EQ(copy->copied_from().value(), std::vector<std::string>{id});
    EXPECT_EQ(copy->snapshot()->list({.p = ex("p")})->size(), 1u);
  }
  std::filesystem::rename(copied, moved);
  EXPECT_EQ(Node::open(moved)->store_id().value(), copy_id) << "a store moved (the same file) is the same store";
  EXPECT_EQ(Node::open(moved)->copied_from().value(), std::vector<std::string>{id}) << "and no copy again";
  EXPECT_EQ(Node::open(original)->store_id().value(), id);
}

// A disk mounted read-only to save what is on it (or a copy on read-only media): every open
// failed "Read-only file system", since LMDB's lock file cannot be written there, and nothing
// could be read, backed up or checked. It opens read-only now: reads, check and backup work,
// and every write fails with an error that says why.
TEST(Store, AStoreOnAReadOnlyFilesystemIsReadAndRefusesWritesSayingWhy) {
  TempDir dir, copies;
  const std::filesystem::path backup = copies.path() / "copy";
  const ChildEnd end = run_in_tmpfs(dir.path(), "8m", [&](const Say& say) {
    {
      if (auto made = Node::init(dir.path() / "store", {.iri = "http://example.org/n"}); !made) say("init: " + made.error().message, 1);
      auto node = Node::open(dir.path() / "store");
      if (!node) say("open: " + node.error().message, 1);
      if (!node->agent("w")->store(Item{}.add(ex("a"), ex("p"), Term::literal("1")))) say("store failed", 1);
    }
    if (mount(nullptr, dir.path().c_str(), nullptr, MS_REMOUNT | MS_RDONLY, nullptr) != 0) say("cannot remount read-only", 77);
    auto node = Node::open(dir.path() / "store");
    if (!node) say("open on a read-only filesystem: " + node.error().message, 1);
    auto records = node->snapshot()->list({.p = ex("p")});
    if (!records || records->size() != 1) say("the record was not read back", 1);
    auto report = node->check();
    if (!report || !report->problems.empty()) say("check: " + (report ? report->problems.front() : report.error().message), 1);
    if (auto copied = node->back_up(backup); !copied) say("backup: " + copied.error().message, 1);
    auto agent = node->agent("w");
    auto stored = agent->store(Item{}.add(ex("b"), ex("p"), Term::literal("2")));
    if (stored || stored.error().message.find("read-only filesystem: it can be read, not written") == std::string::npos)
      say("a write: " + (stored ? std::string("stored") : stored.error().message), 1);
    auto removed = node->remove_item(1);
    if (removed || removed.error().message.find("read-only filesystem") == std::string::npos)
      say("a removal: " + (removed ? std::string("removed") : removed.error().message), 1);
    say("read, checked and copied; writes refused", 0);
  });
  if (end.status == 77) GTEST_SKIP() << end.said;
  ASSERT_EQ(end.status, 0) << end.said;
  auto copy = Node::open(backup);
  ASSERT_TRUE(copy) << copy.error().message;
  EXPECT_EQ(copy->stats()->records, 1u);
}

// A store at its maximum map size: a removal's trimming of the removal log met MDB_MAP_FULL,
// went on in the spoilt transaction and failed with "MDB_BAD_TXN", after parts of the removal
// had been committed. It is a store-full condition the removal works around (in smaller parts).
TEST(Store, RemovingFromAStoreAtItsMaximumWorksInParts) {
  TempDir dir;
  ASSERT_TRUE(Node::init(dir.path(), {.iri = "http://example.org/n", .max_map_bytes = kMinMaxMapBytes}));
  auto node = Node::open(dir.path());
  ASSERT_TRUE(node);
  auto agent = node->agent("w");
  ASSERT_TRUE(agent);
  Result<std::uint64_t> last = std::uint64_t{0};
  for (int i = 0; last && i < 10000; ++i) {
    Item item;
    for (int k = 0; k < 20; ++k) {
      const int n = i * 20 + k;
      item.add(ex("s" + std::to_string(n)), ex("p" + std::to_string(n % 7)), Term::literal(std::string(80, 'x') + std::to_string(n)));
    }
    last = agent->store(item);
  }
  ASSERT_FALSE(last);
  ASSERT_EQ(last.error().code, Errc::store_full) << last.error().message;
  for (int p = 0; p < 7; ++p) {
    Pattern pattern;
    pattern.p = ex("p" + std::to_string(p));
    auto removed = node->remove(pattern);
    ASSERT_TRUE(removed) << "p" << p << ": " << removed.error().message;
    EXPECT_GT(*removed, 100u) << "p" << p;
    auto left = node->snapshot()->list(pattern);
    ASSERT_TRUE(left);
    EXPECT_TRUE(left->empty()) << "p" << p << ": " << left->size() << " records left";
  }
}

// One transaction that alone is larger than what the disk has left (a `tahvel load` batch of
// large literals): the reserve made before it covers its own size, so it is refused whole with
// store_full rather than SIGBUS halfway through, and smaller writes go on.
TEST(Store, ATransactionLargerThanTheDiskLeftIsRefusedWholeNotACrash) {
  TempDir dir;
  const ChildEnd end = run_on_small_disk(dir.path(), "40m", [&](const Say& say, Node& node, Agent& agent) {
    std::vector<Item> batch;
    for (int i = 0; i < 48; ++i) {
      Item item;
      item.add(ex("chunk" + std::to_string(i)), ex("data"), Term::literal(std::string(900000, 'a' + i % 26) + std::to_string(i)));
      batch.push_back(std::move(item));
    }
    auto stored = agent.store_all(batch);
    if (stored) say("48 literals of 900 kB went onto a 40 MiB disk", 1);
    if (stored.error().code != Errc::store_full || stored.error().message.find("the disk holding") == std::string::npos)
      say("wrong error: " + stored.error().message, 1);
    if (node.stats()->items != 0) say("items " + std::to_string(node.stats()->items) + " of the refused batch stored", 1);
    batch.resize(8);
    if (auto fits = agent.store_all(batch); !fits) say("8 of them: " + fits.error().message, 1);
    say(stored.error().message, 0);
  });
  ASSERT_EQ(end.signal, 0) << "the writer died of signal " << end.signal << " (7: SIGBUS)";
  if (end.status == 77) GTEST_SKIP() << end.said;
  EXPECT_EQ(end.status, 0) << end.said;
}

TEST(Store, MapGrowsWhenItFills) {
  TempDir dir;
  Node node = make_node(dir.path());
  auto agent = node.agent("w");
  // ~100 MiB of literals through a 64 MiB initial map.
  for (int i = 0; i < 200; ++i) {
    Item item;
    item.add(ex("chunk" + std::to_string(i)), ex("data"), Term::literal(std::string(1 << 19, 'a' + i % 26) + std::to_string(i), std::string(xsd::kBase64Binary)));
    auto id = agent->store(item);
    ASSERT_TRUE(id) << id.error().message;
  }
  EXPECT_GT(node.stats()->map_bytes, 64u << 20);
}

TEST(Store, SubscriberGetsMatchingItemsOnceInOrder) {
  TempDir dir;
  Node node = make_node(dir.path());
  auto reader = node.agent("reader");
  auto writer = node.agent("writer");
  Pattern hr;
  hr.p = ex("hr");
  ASSERT_TRUE(reader->subscribe(hr));
  std::vector<std::uint64_t> sent;
  for (int i = 0; i < 5; ++i) {
    sent.push_back(*writer->store(Item{}.add(ex("obs" + std::to_string(i)), ex("hr"), Term::integer(70 + i))));
    ASSERT_TRUE(writer->store(Item{}.add(ex("obs" + std::to_string(i)), ex("other"), Term::integer(1))));
  }
  EXPECT_EQ(*reader->pending(), 5u);
  std::vector<std::uint64_t> got;
  while (auto d = reader->take(0ms)) {
    if (!*d) break;
    got.push_back((*d)->item);
    EXPECT_EQ((*d)->records.front().triple.p, ex("hr"));
  }
  EXPECT_EQ(got, sent);
  EXPECT_EQ(*reader->pending(), 0u);
}

// Every Node::open in a process shares one Env; opening must not rewrite the vocabulary ids
// that a writer on another thread reads in its transaction (a data race ThreadSanitizer reported
// from the link's threads: load_vocabulary against insert_item). Fails only under -fsanitize=thread.
TEST(Store, OpeningTheStoreOnAnotherThreadWhileOneWritesLeavesTheWriterAlone) {
  TempDir dir;
  Node node = make_node(dir.path());
  auto writer = node.agent("writer");
  ASSERT_TRUE(writer);
  std::atomic<bool> done{false};
  std::thread opener([&] {
    while (!done) {
      auto other = Node::open(dir.path());
      ASSERT_TRUE(other) << other.error().message;
    }
  });
  for (int i = 0; i < 200; ++i)
    ASSERT_TRUE(writer->store(Item{}.add(ex("obs" + std::to_string(i)), ex("hr"), Term::integer(70 + i))));
  done = true;
  opener.join();
  auto again = Node::open(dir.path());
  ASSERT_TRUE(again);
  auto snap = again->snapshot();
  ASSERT_TRUE(snap);
  EXPECT_EQ(*snap->count({.p = ex("hr")}), 200u);
}

TEST(Store, ManualAckRedeliversUntilAcknowledged) {
  TempDir dir;
  Node node = make_node(dir.path());
  {
    auto reader = node.agent("reader");
    ASSERT_TRUE(reader->subscribe(Pattern{.p = ex("hr")}));
  }
  auto writer = node.agent("writer");
  auto id = writer->store(Item{}.add(ex("o"), ex("hr"), Term::integer(70)));
  {
    auto reader = node.agent("reader");
    auto d = reader->take(0ms, Ack::manual);
    ASSERT_TRUE(d && *d);
    EXPECT_EQ((*d)->item, *id);
  }  // "crash" before ack
  auto reader = node.agent("reader");
  auto again = reader->take(0ms, Ack::manual);
  ASSERT_TRUE(again && *again);
  EXPECT_EQ((*again)->item, *id);
  ASSERT_TRUE(reader->ack(*id));
  auto none = reader->take(0ms, Ack::manual);
  ASSERT_TRUE(none);
  EXPECT_FALSE(*none);
}

// Agent "reader" subscribed to ex:hr and agent "writer": what unsubscribing leaves behind.
class HeartRateReader : public ::testing::Test {
 protected:
  TempDir dir_;
  Node node_ = make_node(dir_.path());
  Agent reader_ = node_.agent("reader").value();
  Agent writer_ = node_.agent("writer").value();
  std::uint64_t hr_ = reader_.subscribe(Pattern{.p = ex("hr")}).value();
};

TEST_F(HeartRateReader, UnsubscribeStopsDelivery) {
  ASSERT_TRUE(writer_.store(Item{}.add(ex("o"), ex("hr"), Term::integer(70))));
  ASSERT_TRUE(reader_.unsubscribe(hr_));
  ASSERT_TRUE(writer_.store(Item{}.add(ex("o"), ex("hr"), Term::integer(71))));
  EXPECT_EQ(*reader_.pending(), 1u);
  auto other = node_.agent("other");
  EXPECT_FALSE(other->unsubscribe(hr_));
}

// A narrowed forwarding policy: the uplink unsubscribes a pattern, and what that pattern alone
// queued must not go up after all. Items another subscription routes, or addressed to the
// agent, stay.
TEST_F(HeartRateReader, WithdrawUnroutedTakesOutOnlyWhatNoSubscriptionRoutesAnyMore) {
  ASSERT_TRUE(reader_.subscribe(Pattern{.p = ex("spo2")}));
  const std::uint64_t hr_only = writer_.store(Item{}.add(ex("o1"), ex("hr"), Term::integer(70))).value();
  const std::uint64_t spo2 = writer_.store(Item{}.add(ex("o2"), ex("spo2"), Term::integer(97))).value();
  const std::uint64_t both =
      writer_.store(Item{}.add(ex("o3"), ex("hr"), Term::integer(71)).add(ex("o3"), ex("spo2"), Term::integer(98))).value();
  Item addressed;
  addressed.add(ex("o4"), ex("hr"), Term::integer(72));
  addressed.context = reader_.iri();
  const std::uint64_t to_reader = writer_.store(addressed).value();
  ASSERT_EQ(*reader_.pending(), 4u);
  EXPECT_EQ(*reader_.withdraw_unrouted(), 0u);  // every one still routed
  ASSERT_TRUE(reader_.unsubscribe(hr_));
  EXPECT_EQ(*reader_.pending(), 4u);  // unsubscribing alone leaves them
  EXPECT_EQ(*reader_.withdraw_unrouted(), 1u);
  std::vector<std::uint64_t> taken;
  while (auto d = reader_.take(std::chrono::milliseconds(0)).value()) taken.push_back(d->item);
  EXPECT_EQ(taken, (std::vector<std::uint64_t>{spo2, both, to_reader}));
  EXPECT_EQ(node_.snapshot()->list({.s = ex("o1")})->size(), 1u) << "the item stays in the store, item " << hr_only;
}

TEST(Store, RemovedUnreadItemLeavesInputBuffer) {
  TempDir dir;
  Node node = make_node(dir.path());
  auto reader = node.agent("reader");
  auto writer = node.agent("writer");
  ASSERT_TRUE(reader->subscribe(Pattern{.p = ex("hr")}));
  auto id = writer->store(Item{}.add(ex("o"), ex("hr"), Term::integer(70)));
  ASSERT_TRUE(node.remove_item(*id));
  EXPECT_EQ(*reader->pending(), 0u);
  EXPECT_EQ(node.stats()->pending_deliveries, 0u);
}

// What a reader of many items (answer chunks) removes once read, in one commit: each listed
// item goes with its records and its place in input buffers; one already gone (or listed twice)
// is skipped, not an error that would leave the rest on the board.
TEST(Store, RemoveItemsRemovesEachListedItemAndSkipsThoseGone) {
  TempDir dir;
  Node node = make_node(dir.path());
  auto reader = node.agent("reader");
  auto writer = node.agent("writer");
  ASSERT_TRUE(reader->subscribe(Pattern{.p = ex("hr")}));
  const std::uint64_t subscription_records = node.stats()->records;
  std::vector<std::uint64_t> ids;
  for (int i = 0; i < 4; ++i)
    ids.push_back(*writer->store(Item{}.add(ex("o" + std::to_string(i)), ex("hr"), Term::integer(70 + i)).add(ex("o" + std::to_string(i)), ex("at"), Term::integer(i))));
  ASSERT_TRUE(node.remove_item(ids[3]));
  auto removed = node.remove_items({ids[0], ids[2], ids[3], ids[0], 999'999});
  ASSERT_TRUE(removed) << removed.error().message;
  EXPECT_EQ(*removed, 4u);  // two records of each of ids[0] and ids[2]
  EXPECT_EQ(*reader->pending(), 1u);
  auto left = reader->take(std::chrono::milliseconds(0));
  ASSERT_TRUE(left && *left);
  EXPECT_EQ((*left)->item, ids[1]);
  EXPECT_EQ(node.stats()->records, subscription_records + 2);  // and ids[1]
  EXPECT_EQ(*node.remove_items({}), 0u);
}

// What an operator asks before fetching anything: per predicate, how many records and the
// asserted-at of the first and last stored (for a sensor's data, its time range).
TEST(Store, PredicatesSayHowManyRecordsAndWhenTheFirstAndLastStoredWereAsserted) {
  TempDir dir;
  Node node = make_node(dir.path());
  auto ecg = node.agent("ecg");
  for (int i = 0; i < 5; ++i) {
    Item chunk;
    chunk.asserted_at = 1'000'000'000LL * (100 + i);
    chunk.add(ex("chunk" + std::to_string(i)), ex("samples"), Term::literal("AAAA"));
    if (i % 2 == 0) chunk.add(ex("chunk" + std::to_string(i)), ex("lead"), Term::literal("MLII"));
    ASSERT_TRUE(ecg->store(chunk));
  }
  Item late;  // stored last, asserted earliest: the range is of the first and last stored
  late.asserted_at = 1'000'000'000LL * 50;
  late.add(ex("chunk9"), ex("samples"), Term::literal("BBBB"));
  ASSERT_TRUE(ecg->store(late));
  ASSERT_TRUE(node.remove_item(*ecg->written().value().begin()));  // the first chunk goes

  auto held = node.snapshot().value().predicates();
  ASSERT_TRUE(held) << held.error().message;
  ASSERT_EQ(held->size(), 2u);
  EXPECT_EQ((*held)[0].predicate, testing::kEx + "lead");  // in IRI order
  EXPECT_EQ((*held)[0].records, 2u);
  EXPECT_EQ((*held)[0].first_asserted_at, 102'000'000'000LL);
  EXPECT_EQ((*held)[0].last_asserted_at, 104'000'000'000LL);
  EXPECT_EQ((*held)[1].predicate, testing::kEx + "samples");
  EXPECT_EQ((*held)[1].records, 5u);
  EXPECT_EQ((*held)[1].first_asserted_at, 101'000'000'000LL);
  EXPECT_EQ((*held)[1].last_asserted_at, 50'000'000'000LL);
}

// What waits for whom, for an operator: an item addressed to an agent that never comes (a home
// not deployed) shows among the input buffers, with its age, beside a reader's backlog.
TEST(Store, InputBuffersSayWhatWaitsForEachAgentAndSinceWhen) {
  TempDir dir;
  Node node = make_node(dir.path());
  auto writer = node.agent("writer");
  auto hrv = node.agent("hrv");
  ASSERT_TRUE(hrv->subscribe({.p = ex("rr")}));
  EXPECT_TRUE(node.snapshot().value().input_buffers().value().empty());
  std::vector<std::uint64_t> beats;
  for (int i = 0; i < 3; ++i) {
    Item beat;
    beat.asserted_at = 1'000'000'000LL * (200 + i);
    beat.add(ex("beat" + std::to_string(i)), ex("rr"), Term::integer(800 + i));
    beats.push_back(writer->store(beat).value());
  }
  Item window;
  window.asserted_at = 1'000'000'000LL * 100;
  window.context = testing::kNodeIri + "/ghost/hrv";  // R18: waits in agent ghost's buffer
  window.add(ex("config"), ex("windowS"), Term::integer(120));
  const std::uint64_t addressed = writer->store(window).value();
  ASSERT_EQ(hrv->take(std::chrono::milliseconds(0)).value()->item, beats[0]);

  auto buffers = node.snapshot().value().input_buffers();
  ASSERT_TRUE(buffers) << buffers.error().message;
  ASSERT_EQ(buffers->size(), 2u);
  EXPECT_EQ((*buffers)[0].agent, testing::kNodeIri + "/ghost");  // in IRI order
  EXPECT_EQ((*buffers)[0].waiting, 1u);
  EXPECT_EQ((*buffers)[0].oldest_item, addressed);
  EXPECT_EQ((*buffers)[0].oldest_asserted_at, 100'000'000'000LL);
  EXPECT_EQ((*buffers)[1].agent, testing::kNodeIri + "/hrv");
  EXPECT_EQ((*buffers)[1].waiting, 2u);
  EXPECT_EQ((*buffers)[1].oldest_item, beats[1]);
  EXPECT_EQ((*buffers)[1].oldest_asserted_at, 201'000'000'000LL);
}

TEST(Store, OutputBufferListsWhatTheAgentWrote) {
  TempDir dir;
  Node node = make_node(dir.path());
  auto a = node.agent("a");
  auto b = node.agent("b");
  auto a1 = a->store(Item{}.add(ex("x"), ex("p"), Term::integer(1)));
  ASSERT_TRUE(b->store(Item{}.add(ex("x"), ex("p"), Term::integer(2))));
  auto a2 = a->store(Item{}.add(ex("x"), ex("p"), Term::integer(3)));
  EXPECT_EQ(*a->written(), (std::vector<std::uint64_t>{*a1, *a2}));
  EXPECT_EQ(*a->written(*a1), (std::vector<std::uint64_t>{*a2}));
}

// A store with a ring of `ring` records, agent "writer", and agent "reader" subscribed to the
// records of `predicate` (what waits in its buffer the ring keeps).
struct RingWithReader {
  RingWithReader(std::uint64_t ring, const std::string& predicate)
      : node(make_node(dir.path(), InitOptions{.ring = ring})), writer(node.agent("writer").value()),
        reader(node.agent("reader").value()) {
    EXPECT_TRUE(reader.subscribe(Pattern{.p = ex(predicate)}));
  }
  TempDir dir;
  Node node;
  Agent writer, reader;
};

TEST(Store, RingKeepsStoreWithinBoundAndKeepsPersistentAndUnreadItems) {
  RingWithReader ring(100, "alarm");
  Node& node = ring.node;
  Agent* writer = &ring.writer;
  Agent* reader = &ring.reader;
  Item keep;
  keep.persistent = true;
  keep.add(ex("config"), ex("window"), Term::integer(300));
  auto persistent = writer->store(keep);
  auto unread = writer->store(Item{}.add(ex("a1"), ex("alarm"), Term::literal("high")));
  ASSERT_TRUE(persistent && unread);
  for (int i = 0; i < 5000; ++i) {
    Item item;
    item.add(ex("obs" + std::to_string(i)), ex("hr"), Term::integer(60 + i % 40)).add(ex("obs" + std::to_string(i)), ex("t"), Term::literal(std::to_string(i)));
    ASSERT_TRUE(writer->store(item));
    auto stats = node.stats();
    ASSERT_LE(stats->records - stats->persistent_records, 100u + 1u) << "after " << i;  // + the unread item
  }
  auto snap = node.snapshot();
  EXPECT_TRUE(snap->item(*persistent));
  EXPECT_TRUE(snap->item(*unread));
  auto stats = node.stats();
  EXPECT_GE(stats->reclaimed_records, 9800u);
  // Once taken, the unread item may go.
  auto d = reader->take(0ms);
  ASSERT_TRUE(d && *d);
  for (int i = 0; i < 200; ++i) ASSERT_TRUE(writer->store(Item{}.add(ex("more"), ex("hr"), Term::integer(i))));
  EXPECT_FALSE(node.snapshot()->item(*unread));
  // Terms of reclaimed records are collected too: the dictionary stays small.
  EXPECT_LT(node.stats()->terms, 400u);
}

// The ring's scan resumes past the items waiting in input buffers (a subscriber that does not
// take made every write walk all of them) and comes back for those taken since: taken, they
// are the oldest the ring may reclaim, and go first.
TEST(Store, TheRingReclaimsItemsTakenLongAfterTheyWereStoredAndKeepsThoseStillWaiting) {
  RingWithReader ring(10, "hr");
  Node& node = ring.node;
  Agent* writer = &ring.writer;
  Agent* reader = &ring.reader;
  std::vector<std::uint64_t> ids;
  for (int i = 0; i < 300; ++i) {
    auto id = writer->store(Item{}.add(ex("obs" + std::to_string(i)), ex("hr"), Term::integer(i)));
    ASSERT_TRUE(id);
    ids.push_back(*id);
  }
  auto ring_records = [&] { return node.stats()->records - node.stats()->persistent_records; };
  EXPECT_EQ(ring_records(), 300u) << "items waiting in a buffer are kept";
  for (int i = 0; i < 100; ++i) {
    auto d = reader->take(0ms);
    ASSERT_TRUE(d && *d);
  }
  // Items nobody waits for, then one more: the ring takes the 100 taken and the unwatched ones
  // beyond its bound, and keeps the 200 still waiting.
  for (int i = 0; i < 20; ++i) ASSERT_TRUE(writer->store(Item{}.add(ex("other" + std::to_string(i)), ex("t"), Term::integer(i))));
  auto snap = node.snapshot();
  for (int i = 0; i < 100; ++i) EXPECT_FALSE(snap->item(ids[i])) << "taken item " << i << " was kept";
  for (int i = 100; i < 300; ++i) EXPECT_TRUE(snap->item(ids[i])) << "waiting item " << i << " was reclaimed";
  EXPECT_LE(ring_records(), 200u + 10u);
  // Taken in two more rounds, with writes between: each round's taken items go too.
  for (int round = 0; round < 2; ++round) {
    for (int i = 0; i < 50; ++i) ASSERT_TRUE(reader->take(0ms).value().has_value());
    ASSERT_TRUE(writer->store(Item{}.add(ex("late" + std::to_string(round)), ex("t"), Term::integer(round))));
  }
  snap = node.snapshot();
  for (int i = 100; i < 200; ++i) EXPECT_FALSE(snap->item(ids[i])) << "taken item " << i << " was kept";
  for (int i = 200; i < 300; ++i) EXPECT_TRUE(snap->item(ids[i])) << "waiting item " << i << " was reclaimed";
  EXPECT_LE(ring_records(), 100u + 10u);
}

// More than a scan's budget (4,096) of records waiting in an input buffer at the head of a
// predicate held every expired record behind them: each write's scan stopped among them, at
// the same place, and reclaim() returned 0 with 100 records due. The scan goes on from where
// it stopped, and reclaim() passes until it has looked at them all.
TEST(Store, TimeToLiveReachesExpiredRecordsBehindManyWaitingOnes) {
  TempDir dir;
  Node node = make_node(dir.path());
  auto writer = node.agent("writer");
  auto reader = node.agent("reader");
  ASSERT_TRUE(reader->subscribe(Pattern{.p = ex("ecg"), .o = Term::literal("waiting")}));
  std::vector<Item> waiting(5000, Item{}.add(ex("c"), ex("ecg"), Term::literal("waiting")));
  ASSERT_TRUE(writer->store_all(waiting));
  for (int i = 0; i < 100; ++i) ASSERT_TRUE(writer->store(Item{}.add(ex("d" + std::to_string(i)), ex("ecg"), Term::literal("due"))));
  ASSERT_TRUE(node.set_ttl(testing::kEx + std::string("ecg"), std::chrono::nanoseconds(1)));
  auto reclaimed = node.reclaim();
  ASSERT_TRUE(reclaimed) << reclaimed.error().message;
  EXPECT_EQ(*reclaimed, 100u);
  EXPECT_EQ(*node.snapshot()->count({.p = ex("ecg"), .o = Term::literal("due")}), 0u);
  EXPECT_EQ(*node.snapshot()->count({.p = ex("ecg"), .o = Term::literal("waiting")}), 5000u) << "waiting records are kept";
  // And by writes alone, a budget at a time.
  for (int i = 0; i < 100; ++i) ASSERT_TRUE(writer->store(Item{}.add(ex("e" + std::to_string(i)), ex("ecg"), Term::literal("due"))));
  for (int i = 0; i < 5; ++i) ASSERT_TRUE(writer->store(Item{}.add(ex("x"), ex("other"), Term::integer(i))));
  EXPECT_EQ(*node.snapshot()->count({.p = ex("ecg"), .o = Term::literal("due")}), 0u);
}

TEST(Store, TimeToLiveReclaimsOldRecordsOfThatPredicateOnly) {
  TempDir dir;
  Node node = make_node(dir.path());
  auto writer = node.agent("writer");
  ASSERT_TRUE(node.set_ttl(testing::kEx + std::string("ecg"), std::chrono::hours(1)));
  ASSERT_TRUE(writer->store(Item{}.add(ex("c1"), ex("ecg"), Term::literal("AAAA"))));
  EXPECT_EQ(*node.reclaim(), 0u);
  ASSERT_TRUE(node.set_ttl(testing::kEx + std::string("ecg"), std::chrono::nanoseconds(1)));
  ASSERT_TRUE(writer->store(Item{}.add(ex("h1"), ex("hrv"), Term::integer(42))));
  Item kept;
  kept.persistent = true;
  kept.add(ex("c0"), ex("ecg"), Term::literal("BBBB"));
  ASSERT_TRUE(writer->store(kept));
  ASSERT_TRUE(node.reclaim());  // retention also runs after each write
  EXPECT_EQ(node.stats()->reclaimed_records, 1u);
  auto snap = node.snapshot();
  EXPECT_EQ(*snap->count(Pattern{.p = ex("ecg")}), 1u);
  EXPECT_EQ(*snap->count(Pattern{.p = ex("hrv")}), 1u);
  auto ttls = node.ttls();
  ASSERT_EQ(ttls->size(), 1u);
}

// 64 persistent records at the head of a TTL predicate's records used up every scan's budget:
// nothing after them was ever reclaimed. And a TTL of centuries overflowed and reclaimed all.
TEST(Store, TimeToLiveReachesPastPersistentRecordsAndAVeryLongOneKeepsEverything) {
  TempDir dir;
  Node node = make_node(dir.path());
  auto writer = node.agent("writer");
  for (int i = 0; i < 70; ++i) {
    Item kept;
    kept.persistent = true;
    kept.add(ex("kept" + std::to_string(i)), ex("ecg"), Term::integer(i));
    ASSERT_TRUE(writer->store(kept));
  }
  for (int i = 0; i < 10; ++i) ASSERT_TRUE(writer->store(Item{}.add(ex("plain" + std::to_string(i)), ex("ecg"), Term::integer(i))));
  ASSERT_TRUE(node.set_ttl(testing::kEx + std::string("ecg"), std::chrono::nanoseconds::max()));
  ASSERT_TRUE(node.reclaim());
  EXPECT_EQ(*node.snapshot()->count(Pattern{.p = ex("ecg")}), 80u) << "a TTL of 292 years reclaimed";
  ASSERT_TRUE(node.set_ttl(testing::kEx + std::string("ecg"), std::chrono::nanoseconds(1)));
  ASSERT_TRUE(node.reclaim());
  EXPECT_EQ(*node.snapshot()->count(Pattern{.p = ex("ecg")}), 70u);  // the persistent ones only
}

// The same for 70 items waiting in a subscriber's buffer at the head: the later records no buffer
// holds are reclaimed, and the waiting ones once taken.
TEST(Store, TimeToLiveReachesPastItemsWaitingInABuffer) {
  TempDir dir;
  Node node = make_node(dir.path());
  auto reader = node.agent("reader");
  auto writer = node.agent("writer");
  auto other = node.agent("other");
  ASSERT_TRUE(reader->subscribe(Pattern{.p = ex("ecg"), .source = writer->iri()}));
  for (int i = 0; i < 70; ++i) ASSERT_TRUE(writer->store(Item{}.add(ex("held" + std::to_string(i)), ex("ecg"), Term::integer(i))));
  for (int i = 0; i < 10; ++i) ASSERT_TRUE(other->store(Item{}.add(ex("free" + std::to_string(i)), ex("ecg"), Term::integer(i))));
  ASSERT_TRUE(node.set_ttl(testing::kEx + std::string("ecg"), std::chrono::nanoseconds(1)));
  ASSERT_TRUE(node.reclaim());
  EXPECT_EQ(*node.snapshot()->count(Pattern{.p = ex("ecg")}), 70u);  // the waiting ones only
  while (auto d = reader->take(0ms)) {
    if (!*d) break;
  }
  // 64 are examined per pass of a write's retention; reclaim() makes passes until none is due.
  EXPECT_EQ(node.reclaim().value(), 70u);
  EXPECT_EQ(*node.snapshot()->count(Pattern{.p = ex("ecg")}), 0u);
}

// A watcher further behind than the removal log reaches was given what was left of the log and
// nothing else: `tahvel tail` printed 65,536 of 100,000 removals without a word.
TEST(Store, AWatcherBehindTheRemovalLogIsToldWhatItMissed) {
  TempDir dir;
  Node node = make_node(dir.path(), {.max_map_bytes = 1 << 20});  // a log of 128 removals
  auto writer = node.agent("writer");
  std::vector<Item> items;
  for (int i = 0; i < 300; ++i) items.push_back(Item{}.add(ex("s" + std::to_string(i)), ex("p"), Term::integer(i)));
  ASSERT_TRUE(writer->store_all(items));
  const std::uint64_t bookmark = node.snapshot()->last_seq();
  ASSERT_EQ(*node.remove({.p = ex("p")}), 300u);
  auto changes = node.watch(bookmark, 0ms);
  ASSERT_TRUE(changes);
  ASSERT_FALSE(changes->empty());
  const Change& first = changes->front();
  EXPECT_TRUE(first.removed);
  EXPECT_NE(first.unreadable.find("removals with sequence numbers " + std::to_string(bookmark + 1) + " to "), std::string::npos)
      << first.unreadable;
  std::size_t listed = 0;
  for (const Change& c : *changes) listed += c.removed && c.unreadable.empty();
  EXPECT_LT(listed, 300u);
  // From past the gap on, nothing is said of it again.
  auto later = node.watch(first.seq, 0ms);
  ASSERT_TRUE(later);
  for (const Change& c : *later) EXPECT_TRUE(c.unreadable.empty()) << c.unreadable;
}

// Records the ring reclaimed before a watcher read them log no removal: `tahvel tail` of a
// ring of 1,000 printed 4,000 of 40,000 loaded records, and nothing of the rest. A watcher that
// kept up, whose bookmark is past every record reclaimed, is told nothing.
TEST(Store, AWatcherBehindTheRingIsToldThatRecordsItNeverReadWereReclaimed) {
  TempDir dir;
  Node node = make_node(dir.path(), {.ring = 10});
  auto writer = node.agent("writer");
  const auto store_n = [&](int from, int n) {
    std::vector<Item> items;
    for (int i = from; i < from + n; ++i) items.push_back(Item{}.add(ex("s" + std::to_string(i)), ex("p"), Term::integer(i)));
    ASSERT_TRUE(writer->store_all(items));
  };
  store_n(0, 5);
  std::uint64_t bookmark = node.snapshot()->last_seq();
  store_n(5, 10);  // the ring keeps 10: the first 5 go, all before the bookmark
  auto changes = node.watch(bookmark, 0ms);
  ASSERT_TRUE(changes);
  EXPECT_EQ(changes->size(), 10u);
  for (const Change& c : *changes) EXPECT_TRUE(c.unreadable.empty()) << c.unreadable;
  bookmark = changes->back().seq;
  store_n(15, 30);  // 20 of them go before the watcher reads again
  changes = node.watch(bookmark, 0ms);
  ASSERT_TRUE(changes);
  std::size_t listed = 0, gaps = 0;
  for (const Change& c : *changes) {
    listed += !c.removed && c.unreadable.empty();
    if (!c.unreadable.empty()) {
      ++gaps;
      EXPECT_TRUE(c.removed);
      EXPECT_TRUE(c.reclaimed);
      EXPECT_NE(c.unreadable.find("records with ids from " + std::to_string(bookmark + 1) + " to "), std::string::npos)
          << c.unreadable;
    }
  }
  EXPECT_EQ(listed, 10u);
  EXPECT_EQ(gaps, 1u);
  auto later = node.watch(changes->back().seq, 0ms);
  ASSERT_TRUE(later);
  EXPECT_TRUE(later->empty());
}

TEST(Store, WatchReturnsInsertionsAndRemovalsAfterBookmark) {
  TempDir dir;
  Node node = make_node(dir.path());
  auto writer = node.agent("writer");
  std::uint64_t bookmark = node.snapshot()->last_seq();
  auto id = writer->store(Item{}.add(ex("a"), ex("p"), Term::integer(1)));
  auto inserted = node.watch(bookmark, 0ms);
  ASSERT_TRUE(inserted);
  ASSERT_EQ(inserted->size(), 1u);
  EXPECT_FALSE((*inserted)[0].removed);
  EXPECT_EQ((*inserted)[0].seq, *id);
  ASSERT_TRUE(node.remove_item(*id));
  auto changes = node.watch((*inserted)[0].seq, 0ms);
  ASSERT_TRUE(changes);
  ASSERT_EQ(changes->size(), 1u);
  EXPECT_TRUE((*changes)[0].removed);
  EXPECT_EQ((*changes)[0].record.meta.id, *id);
  EXPECT_EQ((*changes)[0].record.triple.o, Term::integer(1));
  auto none = node.watch((*changes)[0].seq, 10ms);
  ASSERT_TRUE(none);
  EXPECT_TRUE(none->empty());
}

// A change the store cannot read (an item row or removal-log entry damaged, or written by a
// later build) stays in the stream, saying why: tail, the reasoner and the area keeper would
// otherwise miss it without a word.
TEST(Store, WatchReportsAChangeItCannotReadInsteadOfSkippingIt) {
  TempDir dir;
  std::uint64_t a = 0, b = 0, removal = 0;
  {
    Node node = make_node(dir.path());
    auto writer = node.agent("writer");
    a = writer->store(Item{}.add(ex("a"), ex("p"), Term::integer(1))).value();
    b = writer->store(Item{}.add(ex("b"), ex("p"), Term::integer(2))).value();
    const std::uint64_t c = writer->store(Item{}.add(ex("c"), ex("p"), Term::integer(3))).value();
    ASSERT_TRUE(node.remove_item(c));
    removal = node.snapshot()->last_seq();
  }
  ASSERT_TRUE(change_with_lmdb(dir.path(), [&](MDB_txn* txn) {
    MDB_dbi items = 0, removals = 0;
    MDB_val item_key{sizeof b, &b}, removal_key{sizeof removal, &removal}, junk{1, const_cast<char*>("\x80")};
    return mdb_dbi_open(txn, "items", MDB_INTEGERKEY, &items) == 0 && mdb_put(txn, items, &item_key, &junk, 0) == 0 &&
           mdb_dbi_open(txn, "removals", MDB_INTEGERKEY, &removals) == 0 &&
           mdb_put(txn, removals, &removal_key, &junk, 0) == 0;
  })) << "could not damage the store";
  Node node = Node::open(dir.path()).value();
  auto changes = node.watch(0, 0ms);
  ASSERT_TRUE(changes) << changes.error().message;
  ASSERT_EQ(changes->size(), 3u);
  EXPECT_EQ((*changes)[0].seq, a);
  EXPECT_TRUE((*changes)[0].unreadable.empty());
  EXPECT_EQ((*changes)[0].record.triple.o, Term::integer(1));
  EXPECT_EQ((*changes)[1].seq, b);
  EXPECT_FALSE((*changes)[1].removed);
  EXPECT_EQ((*changes)[1].record.meta.id, b);
  EXPECT_NE((*changes)[1].unreadable.find("record " + std::to_string(b) + ": item " + std::to_string(b) + " cannot be read"),
            std::string::npos)
      << (*changes)[1].unreadable;
  EXPECT_EQ((*changes)[2].seq, removal);
  EXPECT_TRUE((*changes)[2].removed);
  EXPECT_NE((*changes)[2].unreadable.find("removal log entry " + std::to_string(removal) + " cannot be read"), std::string::npos)
      << (*changes)[2].unreadable;
  // As tail prints them.
  std::ostringstream text, json;
  {
    RecordWriter nt(text, Format::ntriples), js(json, Format::json);
    for (const Change& change : *changes) {
      nt.write(change);
      js.write(change);
    }
  }
  EXPECT_NE(text.str().find("# unreadable record " + std::to_string(b) + ": record " + std::to_string(b)), std::string::npos)
      << text.str();
  EXPECT_NE(text.str().find("# unreadable removal " + std::to_string(removal) + ": removal log entry"), std::string::npos)
      << text.str();
  EXPECT_NE(json.str().find("{\"seq\":" + std::to_string(removal) + ",\"removed\":true,\"unreadable\":\"removal log entry"),
            std::string::npos)
      << json.str();
}

TEST(Store, ReopenKeepsEverything) {
  TempDir dir;
  std::uint64_t id = 0;
  {
    Node node = make_node(dir.path());
    id = *node.agent("w")->store(Item{}.add(ex("a"), ex("p"), Term::literal("x")));
  }
  auto node = Node::open(dir.path());
  ASSERT_TRUE(node);
  EXPECT_EQ(node->iri(), testing::kNodeIri);
  EXPECT_EQ(node->snapshot()->item(id)->size(), 1u);
}

// Agents commonly "open, else init": processes racing so must end with one store, one set of
// settings and every other init refused, and none of them may reset what the winner wrote.
TEST(Store, OfInitsRacingOnOneDirectoryExactlyOneMakesTheStoreAndTheRestGetExists) {
  for (int round = 0; round < 5; ++round) {
    TempDir dir;
    const auto store_dir = dir / "node";
    constexpr int kProcesses = 6;
    std::vector<pid_t> children;
    for (int i = 0; i < kProcesses; ++i) {
      const pid_t pid = fork();
      ASSERT_GE(pid, 0);
      if (pid == 0) {
        auto node = Node::init(store_dir, InitOptions{.iri = testing::kNodeIri, .ring = 100u + static_cast<unsigned>(i)});
        if (!node) _exit(node.error().code == Errc::exists ? 3 : 1);
        auto agent = node->agent("a" + std::to_string(i));
        _exit(agent && agent->store(Item{}.add(ex("o"), ex("by"), Term::integer(i))) ? 0 : 1);
      }
      children.push_back(pid);
    }
    int made = 0, refused = 0;
    for (pid_t pid : children) {
      int status = 0;
      ASSERT_EQ(waitpid(pid, &status, 0), pid);
      ASSERT_TRUE(WIFEXITED(status));
      if (WEXITSTATUS(status) == 0) ++made;
      else if (WEXITSTATUS(status) == 3) ++refused;
    }
    EXPECT_EQ(made, 1) << "round " << round;
    EXPECT_EQ(refused, kProcesses - 1) << "round " << round;
    auto node = Node::open(store_dir);
    ASSERT_TRUE(node) << node.error().message;
    const auto records = node->snapshot()->list({.p = ex("by")});
    ASSERT_TRUE(records);
    ASSERT_EQ(records->size(), 1u);
    EXPECT_EQ(node->stats()->ring, 100u + std::stoul(records->front().triple.o.value)) << "the winner's settings";
    EXPECT_TRUE(node->agent("later")->store(Item{}.add(ex("o"), ex("by"), Term::integer(99))));
  }
}

// An init killed before it finished leaves only its own directory, which the next init clears.
TEST(Store, AnInitKilledHalfWayLeavesNothingThatStopsTheNextOne) {
  TempDir dir;
  const pid_t gone = fork();
  ASSERT_GE(gone, 0);
  if (gone == 0) _exit(0);
  ASSERT_EQ(waitpid(gone, nullptr, 0), gone);
  const auto abandoned = dir / (".init-" + std::to_string(gone) + "-1");
  std::filesystem::create_directories(abandoned);
  std::ofstream(abandoned / "data.mdb") << "half a store";
  EXPECT_FALSE(Node::open(dir.path()));
  auto node = Node::init(dir.path(), InitOptions{.iri = testing::kNodeIri});
  ASSERT_TRUE(node) << node.error().message;
  EXPECT_FALSE(std::filesystem::exists(abandoned));
  for (const auto& entry : std::filesystem::directory_iterator(dir.path()))
    EXPECT_FALSE(entry.path().filename().string().starts_with(".init-")) << entry.path();
  // Killed once its store was in place, it left its empty directory beside the store, which no
  // init comes to clear: the next open does. A live init's is left alone.
  node = Result<Node>(fail(Errc::io, ""));  // closed
  const auto after_the_move = dir / (".init-" + std::to_string(gone) + "-2");
  const auto running = dir / (".init-" + std::to_string(getpid()) + "-3");
  std::filesystem::create_directories(after_the_move);
  std::filesystem::create_directories(running);
  ASSERT_TRUE(Node::open(dir.path()));
  EXPECT_FALSE(std::filesystem::exists(after_the_move));
  EXPECT_TRUE(std::filesystem::exists(running));
}

// A data.mdb cut short (a copy that stopped half way) opened, and reads of the lost pages said
// "holds no Tahvel store settings" or MDB_CORRUPTED. It is refused, naming where its root page
// ends and how much the file holds.
// A writer's transaction that outgrows the map grows the data file at once, and its meta page
// records the size only at its commit (a bulk `tahvel load` runs for seconds so). Any process
// that opened the store meanwhile mapped it at the recorded size, which with MDB_WRITEMAP
// truncates the file: the writer died of SIGBUS, its whole load lost. The map now covers the file.
TEST(Store, OpeningAStoreNeverShrinksItsDataFile) {
  TempDir dir;
  { make_node(dir.path()); }
  const std::filesystem::path data = dir.path() / "data.mdb";
  const std::uintmax_t committed = std::filesystem::file_size(data);
  std::filesystem::resize_file(data, committed * 2);  // as the writer's growth leaves it
  {
    auto node = Node::open(dir.path());
    ASSERT_TRUE(node) << node.error().message;
    EXPECT_EQ(std::filesystem::file_size(data), committed * 2);
    auto writer = node->agent("writer");
    ASSERT_TRUE(writer);
    Item item;
    item.add(Term::iri("http://example.org/s"), Term::iri("http://example.org/p"), Term::literal("o"));
    EXPECT_TRUE(writer->store(item));
  }
  EXPECT_GE(std::filesystem::file_size(data), committed * 2);
  auto again = Node::open(dir.path());
  ASSERT_TRUE(again) << again.error().message;
  EXPECT_EQ(again->snapshot().value().list({.p = Term::iri("http://example.org/p")}).value().size(), 1u);
}

TEST(Store, AStoreFileCutShortIsRefusedNamingWhatItLacks) {
  TempDir dir;
  {
    Node node = make_node(dir.path());
    auto agent = node.agent("w").value();
    std::vector<Item> batch;
    for (int i = 0; i < 2000; ++i) batch.push_back({.triples = {{ex("s" + std::to_string(i)), ex("p"), Term::integer(i)}}});
    ASSERT_TRUE(agent.store_all(batch));
  }
  MDB_env* env = nullptr;
  MDB_envinfo info{};
  MDB_stat st{};
  ASSERT_EQ(mdb_env_create(&env), 0);
  ASSERT_EQ(mdb_env_open(env, dir.path().c_str(), MDB_RDONLY, 0644), 0);
  ASSERT_EQ(mdb_env_info(env, &info), 0);
  ASSERT_EQ(mdb_env_stat(env, &st), 0);
  mdb_env_close(env);
  const std::uint64_t used = (info.me_last_pgno + 1) * st.ms_psize;
  std::filesystem::resize_file(dir / "data.mdb", used / 2);
  auto opened = Node::open(dir.path());
  ASSERT_FALSE(opened);
  EXPECT_EQ(opened.error().code, Errc::corrupt);
  EXPECT_NE(opened.error().message.find("data.mdb is cut short: its root page ends at byte "), std::string::npos)
      << opened.error().message;
  EXPECT_NE(opened.error().message.find(", the file holds " + std::to_string(used / 2) + " ("), std::string::npos)
      << opened.error().message;
}

// `tahvel up`'s state directory given where a node's store goes (DIR for DIR/hospital): opening
// it said "no store (run tahvel init)", and doing so made an empty store beside the nodes' that
// answered every question with nothing. Open names the stores below; init refuses.
TEST(Store, ADirectoryOfNodeStoresIsNamedAsSuchAndGetsNoStoreOfItsOwn) {
  TempDir dir;
  make_node(dir / "hospital");
  make_node(dir / "home1");
  auto opened = Node::open(dir.path());
  ASSERT_FALSE(opened);
  EXPECT_EQ(opened.error().code, Errc::not_found);
  EXPECT_NE(opened.error().message.find("it holds node stores in its subdirectories (home1, hospital); give one of them, as " +
                                        (dir / "home1").string()),
            std::string::npos)
      << opened.error().message;
  auto made = Node::init(dir.path(), InitOptions{.iri = testing::kNodeIri});
  ASSERT_FALSE(made);
  EXPECT_EQ(made.error().code, Errc::exists);
  EXPECT_NE(made.error().message.find("holds node stores in its subdirectories (home1, hospital)"), std::string::npos)
      << made.error().message;
  EXPECT_FALSE(std::filesystem::exists(dir / "data.mdb"));
  EXPECT_TRUE(Node::open(dir / "hospital")) << "the stores below are untouched";
}

TEST(Store, InitRefusesExistingStoreAndOpenRefusesMissingOne) {
  TempDir dir;
  make_node(dir.path());
  auto again = Node::init(dir.path(), InitOptions{.iri = testing::kNodeIri});
  ASSERT_FALSE(again);
  EXPECT_EQ(again.error().code, Errc::exists);
  auto missing = Node::open(dir / "nothing");
  ASSERT_FALSE(missing);
  EXPECT_EQ(missing.error().code, Errc::not_found);
  auto bad = Node::init(dir / "bad", InitOptions{.iri = "not an iri"});
  ASSERT_FALSE(bad);
  EXPECT_EQ(bad.error().code, Errc::invalid_iri);
  // Two stores whose IRIs look alike would be two nodes: only the composed form names one.
  auto decomposed = Node::init(dir / "decomposed", InitOptions{.iri = "http://example.org/cafe\xCC\x81"});
  ASSERT_FALSE(decomposed);
  EXPECT_EQ(decomposed.error().code, Errc::invalid_iri);
  EXPECT_NE(decomposed.error().message.find("NFC"), std::string::npos) << decomposed.error().message;
  EXPECT_FALSE(std::filesystem::exists(dir / "decomposed" / "data.mdb"));
  // A directory that cannot be made is named with why, not a temporary file inside it ("making
  // …/.init-NNN: No such file or directory").
  std::ofstream(dir / "a_file") << "x";
  auto under_a_file = Node::init(dir / "a_file" / "store", InitOptions{.iri = testing::kNodeIri});
  ASSERT_FALSE(under_a_file);
  EXPECT_EQ(under_a_file.error().message,
            "cannot make the store's directory " + (dir / "a_file" / "store").string() + ": Not a directory");
}

// What is not a store is an error value naming the place, never an exception, never a store made
// of it: an empty path (LMDB made "/data.mdb" of it, and the store files in the current
// directory), a name too long, another program's LMDB database, an empty data.mdb.
TEST(Store, APathThatHoldsNoStoreIsAnErrorNamingItAndIsLeftAsItWas) {
  TempDir dir;
  auto refused = [](const Result<Node>& r) { return r ? Error{} : r.error(); };
  for (const Error& e : {refused(Node::open("")), refused(Node::init("", InitOptions{.iri = testing::kNodeIri}))})
    EXPECT_EQ(e.code, Errc::invalid_argument) << e.message;
  EXPECT_FALSE(std::filesystem::exists("data.mdb"));
  EXPECT_FALSE(std::filesystem::exists("wake"));

  const std::filesystem::path too_long = dir / std::string(300, 'n');
  for (const Error& e : {refused(Node::open(too_long)), refused(Node::init(too_long, InitOptions{.iri = testing::kNodeIri}))})
    EXPECT_NE(e.message.find(std::string(300, 'n')), std::string::npos) << e.message;

  const std::filesystem::path foreign = dir / "foreign";
  std::filesystem::create_directories(foreign);
  MDB_env* env = nullptr;
  ASSERT_EQ(mdb_env_create(&env), 0);
  mdb_env_set_maxdbs(env, 2);
  ASSERT_EQ(mdb_env_open(env, foreign.c_str(), 0, 0644), 0);
  MDB_txn* txn = nullptr;
  MDB_dbi other = 0;
  ASSERT_EQ(mdb_txn_begin(env, nullptr, 0, &txn), 0);
  ASSERT_EQ(mdb_dbi_open(txn, "accounts", MDB_CREATE, &other), 0);
  ASSERT_EQ(mdb_txn_commit(txn), 0);
  mdb_env_close(env);
  auto opened = Node::open(foreign);
  ASSERT_FALSE(opened);
  EXPECT_EQ(opened.error().code, Errc::corrupt);
  EXPECT_NE(opened.error().message.find("not a Tahvel store"), std::string::npos) << opened.error().message;

  const std::filesystem::path empty = dir / "empty";
  std::filesystem::create_directories(empty);
  std::ofstream(empty / "data.mdb").close();
  auto from_empty = Node::open(empty);
  ASSERT_FALSE(from_empty);
  EXPECT_EQ(from_empty.error().code, Errc::corrupt);
  EXPECT_NE(from_empty.error().message.find((empty / "data.mdb").string()), std::string::npos) << from_empty.error().message;
  EXPECT_EQ(std::filesystem::file_size(empty / "data.mdb"), 0u);
}

TEST(Store, AgentIriIsNodeIriSlashId) {
  TempDir dir;
  Node node = make_node(dir.path());
  EXPECT_EQ(node.agent("ecg")->iri(), testing::kNodeIri + "/ecg");
  EXPECT_FALSE(node.agent("a/b"));
  EXPECT_FALSE(node.agent(""));
}

}  // namespace
}  // namespace tahvel::node

namespace tahvel::node {
namespace {

TEST(Store, AgentWhoseIriWasCollectedStillReceivesAfterSubscribing) {
  TempDir dir;
  Node node = make_node(dir.path());
  auto reader = node.agent("reader");
  auto writer = node.agent("writer");
  // The reader's IRI first appears as a plain object, unpinned, and is collected again.
  auto mention = writer->store(Item{}.add(ex("note"), ex("about"), Term::iri(reader->iri())));
  ASSERT_TRUE(mention);
  ASSERT_TRUE(reader->take(std::chrono::milliseconds(0)));  // looks its own IRI up
  ASSERT_TRUE(node.remove_item(*mention));
  ASSERT_TRUE(reader->subscribe(Pattern{.p = ex("hr")}));
  auto sent = writer->store(Item{}.add(ex("o"), ex("hr"), Term::integer(70)));
  auto got = reader->take(std::chrono::milliseconds(0));
  ASSERT_TRUE(got && *got);
  EXPECT_EQ((*got)->item, *sent);
}

TEST(Store, SubscriptionWrittenByAnotherAgentRoutesToTheNamedSubscriber) {
  TempDir dir;
  Node node = make_node(dir.path());
  auto config = node.agent("config");
  auto reader = node.agent("reader");
  Item sub;
  sub.persistent = true;
  sub.add(Term::blank("s"), Term::iri(std::string(uri::kTahvelNs) + "subscriber"), Term::iri(reader->iri()))
      .add(Term::blank("s"), Term::iri(std::string(uri::kTahvelNs) + "predicate"), ex("hr"));
  ASSERT_TRUE(config->store(sub));
  auto sent = config->store(Item{}.add(ex("o"), ex("hr"), Term::integer(70)));
  auto got = reader->take(std::chrono::milliseconds(0));
  ASSERT_TRUE(got && *got);
  EXPECT_EQ((*got)->item, *sent);
}

// A subscription written late (an area's expansion after a sensor moved in) comes with what it
// missed since a given item, in the same transaction: a refused subscription delivers nothing.
TEST(Store, SubscriptionsStoredLateBringWhatTheyMissedInTheSameTransaction) {
  TempDir dir;
  Node node = make_node(dir.path());
  auto keeper = node.agent("keeper");
  auto reader = node.agent("reader");
  auto sensor = node.agent("sensor");
  const auto subscription_to = [&](const std::string& predicate) {
    Item sub;
    sub.persistent = true;
    sub.add(Term::blank("s"), Term::iri(std::string(uri::kTahvelNs) + "subscriber"), Term::iri(reader->iri()))
        .add(Term::blank("s"), Term::iri(std::string(uri::kTahvelNs) + "predicate"), ex(predicate));
    return sub;
  };
  const std::uint64_t before = *sensor->store(Item{}.add(ex("o0"), ex("hr"), Term::integer(60)));
  const std::uint64_t missed = *sensor->store(Item{}.add(ex("o1"), ex("hr"), Term::integer(61)));
  ASSERT_TRUE(sensor->store(Item{}.add(ex("o2"), ex("temp"), Term::integer(36))));

  const std::uint64_t after[] = {before};
  auto stored = keeper->store_subscriptions({subscription_to("hr")}, after);
  ASSERT_TRUE(stored) << stored.error().message;
  ASSERT_EQ(stored->ids.size(), 1u);
  EXPECT_EQ(stored->caught_up, 1u);
  auto got = reader->take(std::chrono::milliseconds(0));
  ASSERT_TRUE(got && *got);
  EXPECT_EQ((*got)->item, missed) << "only what came after the given item";
  EXPECT_FALSE(*reader->take(std::chrono::milliseconds(0)));

  // A refused one (an empty item) stores nothing and delivers nothing.
  const std::uint64_t none[] = {0, 0};
  auto refused = keeper->store_subscriptions({subscription_to("temp"), Item{}}, none);
  EXPECT_FALSE(refused);
  EXPECT_EQ(*reader->pending(), 0u);
  const std::uint64_t one[] = {0};
  EXPECT_EQ(keeper->store_subscriptions({subscription_to("temp")}, std::span(none)).error().code, Errc::invalid_argument);
  EXPECT_TRUE(keeper->store_subscriptions({subscription_to("temp")}, one));
  EXPECT_EQ(*reader->pending(), 1u) << "the temperature reading, missed since the first item";
}

// A subscription naming another node's agent (what loading that node's dump brings) must not
// hold items in a buffer nobody here can take: they would never be reclaimed. Checked both
// ways the cache learns of it: as it is stored, and reloaded by a process that opens the store.
TEST(Store, ASubscriptionForAnAgentOfAnotherNodeRoutesNothingAndKeepsNothingFromTheRing) {
  TempDir dir;
  for (const bool reopen : {false, true}) {
    const auto where = dir / (reopen ? "reopened" : "as-stored");
    std::optional<Node> node = make_node(where, {.ring = 4});
    auto loader = node->agent("loader");
    Item sub;
    sub.persistent = true;
    sub.add(Term::blank("s"), Term::iri(std::string(uri::kTahvelNs) + "subscriber"), Term::iri("http://example.org/other/m"))
        .add(Term::blank("s"), Term::iri(std::string(uri::kTahvelNs) + "predicate"), ex("hr"));
    ASSERT_TRUE(loader->store(sub));
    if (reopen) {
      node.reset();
      node.emplace(Node::open(where).value());
    }
    auto sensor = node->agent("sensor");
    for (int i = 0; i < 10; ++i) ASSERT_TRUE(sensor->store(Item{}.add(ex("o" + std::to_string(i)), ex("hr"), Term::integer(i))));
    EXPECT_EQ(node->stats()->pending_deliveries, 0u) << (reopen ? "reopened" : "as stored");
    EXPECT_EQ(node->snapshot()->list({.p = ex("hr")})->size(), 4u) << "the ring keeps the newest 4";
  }
}

}  // namespace
}  // namespace tahvel::node

namespace tahvel::node {
namespace {

// `remove -o ex:heartRate` took the `tv:object ex:heartRate` record of a subscription on it along
// with the data: the subscription went on matching any object.
TEST(Store, ARemovalByPatternLeavesSubscriptionsWholeAndRemovingTheItemEndsOne) {
  TempDir dir;
  Node node = make_node(dir.path());
  auto monitor = node.agent("monitor");
  auto writer = node.agent("writer");
  Pattern heart;
  heart.p = ex("observedProperty");
  heart.o = ex("heartRate");
  auto subscription = monitor->subscribe(heart);
  ASSERT_TRUE(subscription);
  ASSERT_TRUE(writer->store(Item{}.add(ex("o1"), ex("observedProperty"), ex("heartRate"))));
  Pattern by_object;
  by_object.o = ex("heartRate");
  EXPECT_EQ(*node.remove(by_object), 1u);  // the observation, not the subscription's record
  ASSERT_TRUE(writer->store(Item{}.add(ex("o2"), ex("observedProperty"), ex("temperature"))));
  ASSERT_TRUE(writer->store(Item{}.add(ex("o3"), ex("observedProperty"), ex("heartRate"))));
  std::vector<Term> taken;
  while (auto d = monitor->take(0ms)) {
    if (!*d) break;
    taken.push_back((*d)->records.front().triple.s);
  }
  EXPECT_EQ(taken, (std::vector<Term>{ex("o3")}));  // o1 left the buffer with its removal
  ASSERT_TRUE(node.remove_item(*subscription));
  ASSERT_TRUE(writer->store(Item{}.add(ex("o4"), ex("observedProperty"), ex("heartRate"))));
  EXPECT_EQ(*monitor->pending(), 0u);
}

// A literal subject or predicate matches no record: Agent::subscribe stored such a subscription,
// persistent and never matching, where the C API refuses it (an API probe).
TEST(Store, ASubscriptionWithALiteralSubjectOrPredicateIsRefusedAsTheCApiRefusesIt) {
  TempDir dir;
  Node node = make_node(dir.path());
  auto agent = node.agent("a").value();
  for (const Pattern& pattern : {Pattern{.s = Term::literal("x")}, Pattern{.p = Term::literal("x")}}) {
    auto subscribed = agent.subscribe(pattern);
    ASSERT_FALSE(subscribed);
    EXPECT_EQ(subscribed.error().code, Errc::invalid_argument) << subscribed.error().message;
  }
  EXPECT_EQ(node.snapshot().value().count({.p = Term::iri("https://w3id.org/tahvel#subscriber")}).value(), 0u);
  EXPECT_TRUE(agent.subscribe({.o = Term::literal("x")})) << "an object may be a literal";
}

TEST(Store, SubscribingAgainWithTheSamePatternKeepsOneSubscription) {
  TempDir dir;
  Node node = make_node(dir.path());
  auto first = node.agent("reader")->subscribe(Pattern{.p = ex("hr")});
  auto again = node.agent("reader")->subscribe(Pattern{.p = ex("hr")});  // after a restart
  auto other = node.agent("reader")->subscribe(Pattern{.p = ex("spo2")});
  auto someone_else = node.agent("other")->subscribe(Pattern{.p = ex("hr")});
  ASSERT_TRUE(first && again && other && someone_else);
  EXPECT_EQ(*first, *again);
  EXPECT_NE(*first, *other);
  EXPECT_NE(*first, *someone_else);
  EXPECT_EQ(node.stats()->subscriptions, 3u);
  ASSERT_TRUE(node.agent("w")->store(Item{}.add(ex("o"), ex("hr"), Term::integer(70))));
  EXPECT_EQ(*node.agent("reader")->pending(), 1u);
}

// A subscription another writer made for an agent (a parent's forwarding policy sent down for
// a node's uplink) is that writer's: with own_only the agent's own identical one is another, so
// that the other writer's removal leaves the agent's standing. Items still land once.
TEST(Store, SubscribingOwnOnlyBesideAnotherWritersIdenticalSubscriptionMakesTheAgentsOwn) {
  TempDir dir;
  Node node = make_node(dir.path());
  auto uplink = node.agent("uplink");
  Item sent_down;
  sent_down.persistent = true;
  sent_down.add(Term::blank("sub"), Term::iri("https://w3id.org/tahvel#subscriber"), Term::iri(uplink->iri()))
      .add(Term::blank("sub"), Term::iri("https://w3id.org/tahvel#predicate"), ex("hr"));
  const auto parents = node.agent("operator")->store(sent_down);
  ASSERT_TRUE(parents);
  EXPECT_EQ(*uplink->subscribe(Pattern{.p = ex("hr")}), *parents);  // as before: the one there is
  const auto own = uplink->subscribe(Pattern{.p = ex("hr")}, {.own_only = true});
  ASSERT_TRUE(own);
  EXPECT_NE(*own, *parents);
  EXPECT_EQ(*uplink->subscribe(Pattern{.p = ex("hr")}, {.own_only = true}), *own);  // a restart
  ASSERT_TRUE(node.agent("w")->store(Item{}.add(ex("o"), ex("hr"), Term::integer(70))));
  EXPECT_EQ(*uplink->pending(), 1u);
  ASSERT_TRUE(node.remove_item(*parents));
  ASSERT_TRUE(node.agent("w")->store(Item{}.add(ex("o"), ex("hr"), Term::integer(71))));
  EXPECT_EQ(*uplink->pending(), 2u);
}

// R10a: a new subscription with `earlier` brings what it would have routed had it been there
// from the start: oldest first, once, with its source and context conditions, and the items
// wait in the buffer like any other (a ring does not reclaim them, the count says so).
TEST(Store, SubscribingWithEarlierDeliversTheMatchingItemsAlreadyOnTheBoardOldestFirst) {
  TempDir dir;
  Node node = make_node(dir.path(), {.ring = 8});
  auto sensor = node.agent("sensor");
  auto other = node.agent("other");
  auto reader = node.agent("reader");
  ASSERT_TRUE(sensor && other && reader);
  const std::uint64_t first = sensor->store(Item{}.add(ex("o1"), ex("hr"), Term::integer(70))).value();
  ASSERT_TRUE(sensor->store(Item{}.add(ex("o2"), ex("spo2"), Term::integer(97))));
  ASSERT_TRUE(other->store(Item{}.add(ex("o3"), ex("hr"), Term::integer(50))));  // another source
  const std::uint64_t both =
      sensor->store(Item{}.add(ex("o4"), ex("hr"), Term::integer(71)).add(ex("o4"), ex("hr"), Term::integer(72))).value();
  const Pattern hr_of_sensor{.p = ex("hr"), .source = sensor->iri()};
  const std::uint64_t sub = reader->subscribe(hr_of_sensor, {.earlier = true}).value();
  EXPECT_EQ(*reader->pending(), 2u);
  EXPECT_EQ(node.stats()->pending_deliveries, 2u);
  // Subscribing again finds the subscription and brings nothing more.
  EXPECT_EQ(reader->subscribe(hr_of_sensor, {.earlier = true}).value(), sub);
  EXPECT_EQ(*reader->pending(), 2u);
  const std::uint64_t later = sensor->store(Item{}.add(ex("o5"), ex("hr"), Term::integer(73))).value();
  // Ring of 8 records: the unread items are kept, what nobody waits for goes.
  for (int i = 0; i < 6; ++i) ASSERT_TRUE(other->store(Item{}.add(ex("x"), ex("noise"), Term::integer(i))));
  std::vector<std::uint64_t> taken;
  while (auto d = reader->take(0ms).value()) taken.push_back(d->item);
  EXPECT_EQ(taken, (std::vector<std::uint64_t>{first, both, later}));
  // Without `earlier`, only what comes after.
  auto plain = node.agent("plain");
  ASSERT_TRUE(plain->subscribe(Pattern{.p = ex("hr")}));
  EXPECT_EQ(*plain->pending(), 0u);
}

// A program that a process with an open store starts does not hold the store's data file open:
// LMDB opens it without close-on-exec, and a supervisor's restarted agents held every store of
// the deployment (a store removed meanwhile kept its space while they ran).
TEST(StoreFiles, AProgramStartedByAProcessWithAnOpenStoreDoesNotInheritItsDataFile) {
  TempDir dir;
  Node node = make_node(dir.path());
  const std::string probe = "ls -l /proc/$$/fd 2>/dev/null | grep -q '" + dir.path().string() + "/data.mdb'";
  EXPECT_NE(std::system(probe.c_str()), 0) << "the shell started here holds the store's data.mdb";
}

}  // namespace
}  // namespace tahvel::node
