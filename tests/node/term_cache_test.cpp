// The write path remembers dictionary ids across transactions (Env::term_cache) and the read
// path remembers decoded terms (Env::decoded). These tests check that what is remembered never
// outlives what it names: a collected term, an aborted transaction's new term, a term removed
// and added back in one transaction, a term collected through another handle of the store.
#include <gtest/gtest.h>

#include "tahvel/node/node.h"
#include "test_support.h"

namespace tahvel::node {
namespace {

using namespace std::chrono_literals;
using namespace testing;  // tahvel::node::testing: TempDir, make_node, ex
using Triples = std::vector<Triple>;

Item one(Term s, Term p, Term o) {
  Item item;
  item.add(std::move(s), std::move(p), std::move(o));
  return item;
}

// The triples with predicate `p`, in id order, read back through a fresh snapshot.
Triples with_predicate(const Node& node, const Term& p) {
  auto snap = node.snapshot();
  EXPECT_TRUE(snap);
  if (!snap) return {};
  auto records = snap->list(Pattern{.p = p});
  EXPECT_TRUE(records) << (records ? "" : records.error().message);
  Triples out;
  if (records)
    for (const Record& r : *records) out.push_back(r.triple);
  return out;
}

TEST(TermCache, ATermCollectedAndStoredAgainGetsItsNewId) {
  TempDir dir;
  Node node = make_node(dir.path());
  auto agent = node.agent("writer");
  ASSERT_TRUE(agent);
  const Term p = ex("onlyHere"), o = Term::literal("once");
  auto first = agent->store(one(ex("a"), p, o));
  ASSERT_TRUE(first);
  ASSERT_TRUE(agent->store(one(ex("b"), ex("other"), Term::literal("x"))));  // p, o remembered
  auto removed = node.remove_item(*first);  // the last use of p and o: both collected (R16)
  ASSERT_TRUE(removed);
  const auto terms_before = node.stats()->terms;
  auto again = agent->store(one(ex("c"), p, o));
  ASSERT_TRUE(again) << again.error().message;
  EXPECT_GT(node.stats()->terms, terms_before);  // p and o entered the dictionary again
  EXPECT_EQ(with_predicate(node, p), (Triples{{ex("c"), p, o}}));
}

// R16: a replace whose new items use the terms of the records it removes again (a board item
// rewritten every 5 s by the supervisor) collects none of them: each was removed and made anew
// under a new id, and every reader's decoded-term cache took an entry per new id.
TEST(TermCache, AReplaceThatUsesTheRemovedTermsAgainCollectsNoneOfThem) {
  TempDir dir;
  Node node = make_node(dir.path());
  auto agent = node.agent("board");
  ASSERT_TRUE(agent);
  const Term s = ex("node"), p = ex("programsAt"), q = ex("heldRecords");
  const std::vector<Pattern> old = {{.s = s, .source = agent->iri()}};
  auto written = [&](int n) {  // literals of the dictionary (small integers are inline, no terms)
    return std::vector<Item>{Item{}.add(s, p, Term::literal("five")).add(s, q, Term::literal("n=" + std::to_string(n)))};
  };
  ASSERT_TRUE(agent->replace(old, written(0)));
  const auto before = node.stats()->terms_collected;
  for (int i = 0; i < 20; ++i) ASSERT_TRUE(agent->replace(old, written(0)));
  EXPECT_EQ(node.stats()->terms_collected, before) << "the same terms, rewritten: none collected";
  // A value that changes is collected once the item that replaced it is in: the old one only.
  ASSERT_TRUE(agent->replace(old, written(1)));
  EXPECT_EQ(node.stats()->terms_collected, before + 1);
  ASSERT_TRUE(agent->replace(old, {Item{}.add(s, ex("other"), Term::integer(1))}));
  EXPECT_EQ(node.stats()->terms_collected, before + 5) << "p, q, \"five\" and \"n=1\" are used by nothing now";
  EXPECT_EQ(with_predicate(node, ex("other")), (Triples{{s, ex("other"), Term::integer(1)}}));
  EXPECT_EQ(with_predicate(node, p), Triples{});
}

TEST(TermCache, RemovalAndStoreInOneTransactionUseTheSameTermSafely) {
  TempDir dir;
  Node node = make_node(dir.path());
  auto agent = node.agent("writer");
  ASSERT_TRUE(agent);
  const Term p = ex("state"), o = Term::literal("up");
  ASSERT_TRUE(agent->store(one(ex("room"), p, o)));
  // Agent::replace removes the old state (collecting p and o) and writes the same terms anew.
  auto replaced = agent->replace({Pattern{.s = ex("room"), .p = p}}, {one(ex("room"), p, o)});
  ASSERT_TRUE(replaced) << replaced.error().message;
  ASSERT_TRUE(agent->store(one(ex("hall"), p, o)));  // and once more, from the caches
  EXPECT_EQ(with_predicate(node, p), (Triples{{ex("room"), p, o}, {ex("hall"), p, o}}));
}

TEST(TermCache, ANewTermOfAFailedWriteIsNotRemembered) {
  TempDir dir;
  Node node = make_node(dir.path());
  auto agent = node.agent("writer");
  ASSERT_TRUE(agent);
  const Term p = ex("fresh"), o = ex("freshObject");
  // The first item creates p and o; the second fails (an invalid IRI), so nothing is stored
  // and the ids the first one got are handed out again.
  auto failed = agent->store_all({one(ex("a"), p, o), one(Term::iri("not an iri"), ex("q"), o)});
  ASSERT_FALSE(failed);
  EXPECT_EQ(failed.error().code, Errc::invalid_iri);
  ASSERT_TRUE(agent->store(one(ex("other"), ex("taken"), Term::literal("the ids of p and o"))));
  ASSERT_TRUE(agent->store(one(ex("b"), p, o)));
  EXPECT_EQ(with_predicate(node, p), (Triples{{ex("b"), p, o}}));
  auto taken = with_predicate(node, ex("taken"));
  ASSERT_EQ(taken.size(), 1u);
  EXPECT_EQ(taken[0].o, Term::literal("the ids of p and o"));
}

TEST(TermCache, ACollectionThroughAnotherHandleIsSeen) {
  TempDir dir;
  Node node = make_node(dir.path());
  auto agent = node.agent("writer");
  ASSERT_TRUE(agent);
  const Term p = ex("shared");
  auto first = agent->store(one(ex("a"), p, Term::literal("v")));
  ASSERT_TRUE(first);
  {
    auto other = Node::open(dir.path());  // another handle: what another process would do
    ASSERT_TRUE(other);
    ASSERT_TRUE(other->remove_item(*first));
  }
  ASSERT_TRUE(agent->store(one(ex("b"), p, Term::literal("w"))));
  EXPECT_EQ(with_predicate(node, p), (Triples{{ex("b"), p, Term::literal("w")}}));
}

TEST(TermCache, TakersReadPredicatesAndSourcesOfManyItemsCorrectly) {
  TempDir dir;
  Node node = make_node(dir.path());
  auto writer = node.agent("writer");
  auto reader = node.agent("reader");
  ASSERT_TRUE(writer && reader);
  ASSERT_TRUE(reader->subscribe(Pattern{.s = ex("s")}));
  for (int i = 0; i < 20; ++i) {
    ASSERT_TRUE(writer->store(one(ex("s"), ex("p" + std::to_string(i % 3)), Term::integer(i))));
  }
  for (int i = 0; i < 20; ++i) {
    auto got = reader->take(1s);
    ASSERT_TRUE(got && *got);
    ASSERT_EQ((*got)->records.size(), 1u);
    const Record& r = (*got)->records[0];
    EXPECT_EQ(r.triple.p, ex("p" + std::to_string(i % 3)));
    EXPECT_EQ(r.triple.o, Term::integer(i));
    EXPECT_EQ(r.meta.source, writer->iri());
  }
}

TEST(Routing, ContextSubscriptionsGetOnlyTheirContextAndOthersGetEverything) {
  TempDir dir;
  Node node = make_node(dir.path());
  auto writer = node.agent("writer");
  auto narrow = node.agent("narrow");
  auto other = node.agent("other");
  auto wide = node.agent("wide");
  ASSERT_TRUE(writer && narrow && other && wide);
  const std::string ctx = "http://example.org/elsewhere/a", ctx2 = "http://example.org/elsewhere/b";
  ASSERT_TRUE(narrow->subscribe(Pattern{.p = ex("v"), .context = ctx}));
  ASSERT_TRUE(other->subscribe(Pattern{.p = ex("v"), .context = ctx2}));
  ASSERT_TRUE(wide->subscribe(Pattern{.p = ex("v")}));
  Item in_ctx = one(ex("x"), ex("v"), Term::integer(1));
  in_ctx.context = ctx;
  ASSERT_TRUE(writer->store(in_ctx));
  ASSERT_TRUE(writer->store(one(ex("y"), ex("v"), Term::integer(2))));
  EXPECT_EQ(*narrow->pending(), 1u);
  EXPECT_EQ(*other->pending(), 0u);
  EXPECT_EQ(*wide->pending(), 2u);
}

}  // namespace
}  // namespace tahvel::node
