// Indexed pattern queries against a plain model: random items and removals, then every kind
// of pattern compared with a scan of what the test itself wrote.
#include <gtest/gtest.h>

#include <map>
#include <random>

#include "tahvel/node/node.h"
#include "test_support.h"

namespace tahvel::node {
namespace {

using testing::ex;
using testing::make_node;
using testing::TempDir;

struct ModelRecord {
  std::uint64_t id;
  Triple triple;
  std::string source, context;
  std::int64_t asserted_at = 0, span = 0;
};

// Times around the epoch (before it too), a few shared by many items; now and then a span,
// once in a while a long one (the time index is walked from `since` less the longest span).
void random_time(std::mt19937& rng, Item& item) {
  item.asserted_at = static_cast<std::int64_t>(rng() % 200) * 1'000 - 50'000;
  const int pick = rng() % 20;
  item.span = pick < 14 ? 0 : pick < 19 ? static_cast<std::int64_t>(rng() % 5'000) : static_cast<std::int64_t>(rng() % 80'000);
}

void random_range(std::mt19937& rng, Pattern& p) {
  const int pick = rng() % 8;
  if (pick >= 3) return;
  const std::int64_t a = static_cast<std::int64_t>(rng() % 220) * 1'000 - 60'000 + static_cast<std::int64_t>(rng() % 3) * 500;
  const std::int64_t b = a + static_cast<std::int64_t>(rng() % 30) * 1'000;  // may be empty (b == a)
  if (pick != 1) p.since = a;
  if (pick != 2) p.until = b;
}

// The time filter as Pattern::since documents it: an instant in [since, until), a span
// overlapping it.
bool model_in_range(const ModelRecord& r, const Pattern& p) {
  if (p.since && p.until && *p.until <= *p.since) return false;
  if (p.until && r.asserted_at >= *p.until) return false;
  if (p.since && (r.span == 0 ? r.asserted_at < *p.since : r.asserted_at + r.span <= *p.since)) return false;
  return true;
}

Term random_term(std::mt19937& rng, int position) {
  int pick = rng() % 10;
  if (position == 1) return ex("p" + std::to_string(rng() % 6));
  if (position == 0 || pick < 4) return ex("n" + std::to_string(rng() % 40));
  if (pick < 7) return Term::integer(static_cast<int>(rng() % 30) - 5);
  if (pick < 9) return Term::literal("v" + std::to_string(rng() % 20));
  return Term::lang_literal("w" + std::to_string(rng() % 5), "en");
}

std::optional<Term> maybe(std::mt19937& rng, int position) {
  if (rng() % 2) return std::nullopt;
  return random_term(rng, position);
}

bool model_matches(const ModelRecord& r, const Pattern& p) {
  return (!p.s || *p.s == r.triple.s) && (!p.p || *p.p == r.triple.p) && (!p.o || *p.o == r.triple.o) &&
         (!p.context || *p.context == r.context) && (!p.source || *p.source == r.source) && model_in_range(r, p);
}

std::vector<std::uint64_t> ids(const std::vector<Record>& records) {
  std::vector<std::uint64_t> out;
  for (const auto& r : records) out.push_back(r.meta.id);
  return out;
}

// `batched`: items go in with store_all, up to 40 per transaction, so that a transaction's
// items share subjects, predicates, objects and writers (the index entries of a transaction are
// put key by key when it ends).
void check_queries_against_plain_scan(bool batched) {
  TempDir dir;
  Node node = make_node(dir.path());
  std::mt19937 rng(20261121);
  std::vector<ModelRecord> model;
  const std::string contexts[] = {"", "http://example.org/ctx/a", "http://example.org/ctx/b"};
  const int rounds = batched ? 100 : 1500, removal_every = batched ? 4 : 50;
  for (int i = 0; i < rounds; ++i) {
    auto agent = node.agent("a" + std::to_string(rng() % 3));
    std::vector<Item> items(batched ? 1 + rng() % 40 : 1);
    for (Item& item : items) {
      item.context = contexts[rng() % 3];
      random_time(rng, item);
      int n = 1 + rng() % 4;
      for (int k = 0; k < n; ++k) item.add(random_term(rng, 0), random_term(rng, 1), random_term(rng, 2));
    }
    auto ids = agent->store_all(items);
    ASSERT_TRUE(ids) << ids.error().message;
    for (std::size_t j = 0; j < items.size(); ++j)
      for (std::size_t k = 0; k < items[j].triples.size(); ++k)
        model.push_back({(*ids)[j] + k, items[j].triples[k], agent->iri(), items[j].context, *items[j].asserted_at, items[j].span});
    // Now and then a removal by a random pattern, some by a time range (whole items go: their
    // time index entries with them).
    if (i % removal_every == removal_every - 1) {
      Pattern gone;
      gone.s = random_term(rng, 0);
      if (rng() % 3 == 0) random_range(rng, gone);
      else gone.p = random_term(rng, 1);
      auto removed = node.remove(gone);
      ASSERT_TRUE(removed);
      auto before = model.size();
      std::erase_if(model, [&](const ModelRecord& r) { return model_matches(r, gone); });
      ASSERT_EQ(*removed, before - model.size());
    }
  }
  auto snap = node.snapshot();
  ASSERT_TRUE(snap);
  std::map<std::uint64_t, const ModelRecord*> by_id;
  for (const auto& r : model) by_id[r.id] = &r;
  for (int q = 0; q < 1500; ++q) {
    Pattern p;
    p.s = maybe(rng, 0);
    p.p = maybe(rng, 1);
    p.o = maybe(rng, 2);
    if (rng() % 4 == 0) p.context = contexts[rng() % 3];
    if (rng() % 6 == 0) p.source = testing::kNodeIri + "/a" + std::to_string(rng() % 3);
    random_range(rng, p);
    std::vector<std::uint64_t> expected;
    for (const auto& r : model)
      if (model_matches(r, p)) expected.push_back(r.id);
    auto listed = snap->list(p);
    ASSERT_TRUE(listed) << listed.error().message;
    ASSERT_EQ(ids(*listed), expected) << "query " << q;
    auto counted = snap->count(p);
    ASSERT_EQ(*counted, expected.size());
    // Every returned record carries the triple and metadata the model has.
    for (std::size_t k = 0; k < listed->size(); ++k) {
      const auto& got = (*listed)[k];
      auto it = by_id.find(got.meta.id);
      ASSERT_NE(it, by_id.end());
      EXPECT_EQ(got.triple, it->second->triple);
      EXPECT_EQ(got.meta.source, it->second->source);
      EXPECT_EQ(got.meta.context, it->second->context);
      EXPECT_EQ(got.meta.asserted_at, it->second->asserted_at);
      EXPECT_EQ(got.meta.span, it->second->span);
    }
  }
  EXPECT_EQ(node.stats()->records, model.size());
}

TEST(Differential, IndexedPatternQueriesAgreeWithPlainScan) { check_queries_against_plain_scan(false); }

TEST(Differential, ItemsStoredManyToATransactionAreIndexedAsIfStoredOneByOne) {
  check_queries_against_plain_scan(true);
}

TEST(Differential, LimitAndAfterIdPageThroughAllMatches) {
  TempDir dir;
  Node node = make_node(dir.path());
  auto agent = node.agent("w");
  for (int i = 0; i < 200; ++i) ASSERT_TRUE(agent->store(Item{}.add(ex("s"), ex("p" + std::to_string(i % 2)), Term::integer(i))));
  auto snap = node.snapshot();
  Pattern p;
  p.p = ex("p1");
  auto all = snap->list(p);
  std::vector<std::uint64_t> paged;
  for (;;) {
    auto page = snap->list(p, ListOptions{0, 7});
    ASSERT_TRUE(page);
    if (page->empty()) break;
    for (const auto& r : *page) paged.push_back(r.meta.id);
    p.after_id = page->back().meta.id;
  }
  EXPECT_EQ(paged, ids(*all));
  EXPECT_EQ(paged.size(), 100u);
}

}  // namespace
}  // namespace tahvel::node
