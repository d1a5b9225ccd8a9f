// The node features that federation stands on: subscriptions by item context, items addressed to
// an agent by their context (R18), a sending window over the input buffer (peek, ack_through) and
// exactly-once relaying of items from another node (relay, R19).
#include <gtest/gtest.h>

#include <atomic>
#include <limits>
#include <random>
#include <set>
#include <thread>

#include "test_support.h"

namespace tahvel::node::testing {
namespace {

using namespace std::chrono_literals;

Item reading(int n, std::string context = {}) {
  Item item;
  item.add(Term::iri(kNodeIri + "/obs/" + std::to_string(n)), ex("value"), Term::integer(n));
  item.context = std::move(context);
  return item;
}

std::vector<std::uint64_t> taken_ids(Agent& agent) {
  std::vector<std::uint64_t> ids;
  while (auto d = agent.take(0ms).value()) ids.push_back(d->item);
  return ids;
}

TEST(Context, SubscriptionWithContextGetsOnlyItemsWrittenWithThatContext) {
  TempDir dir;
  Node node = make_node(dir.path());
  Agent link = node.agent("link").value();
  Agent writer = node.agent("writer").value();
  ASSERT_TRUE(link.subscribe({.context = "http://example.org/group/a"}));
  std::uint64_t in_group = writer.store(reading(1, "http://example.org/group/a")).value();
  ASSERT_TRUE(writer.store(reading(2, "http://example.org/group/b")));
  ASSERT_TRUE(writer.store(reading(3)));
  EXPECT_EQ(taken_ids(link), std::vector<std::uint64_t>{in_group});
  // Subscribing again with the same context is the same subscription.
  EXPECT_EQ(link.subscribe({.context = "http://example.org/group/a"}).value(),
            link.subscribe({.context = "http://example.org/group/a"}).value());
  EXPECT_FALSE(link.subscribe({.context = ""}));
}

// Area subscriptions (docs/spatial.md) select readings by the sensor that wrote them: the
// source, or a writer under it (a child node's agents, relayed up).
TEST(Source, SubscriptionWithSourceGetsOnlyItemsOfThatWriterOrOfWritersUnderIt) {
  TempDir dir;
  Node node = make_node(dir.path());
  Agent watcher = node.agent("watcher").value();
  Agent mote = node.agent("mote1").value();
  Agent other = node.agent("mote10").value();  // a prefix of the IRI string is not "under"
  Agent link = node.agent("child").value();
  ASSERT_TRUE(watcher.subscribe({.p = ex("value"), .source = kNodeIri + "/mote1"}));
  ASSERT_TRUE(watcher.subscribe({.source = kNodeIri + "/child"}));
  std::uint64_t own = mote.store(reading(1)).value();
  ASSERT_TRUE(other.store(reading(2)));
  Item no_value;
  no_value.add(Term::iri(kNodeIri + "/obs/3"), ex("note"), Term::integer(3));
  ASSERT_TRUE(mote.store(no_value));  // the source matches, the predicate does not
  RelayedItem from_below{1, 0, kNodeIri + "/child/ecg", reading(4)};
  auto relayed = link.relay("child-up", {from_below});
  ASSERT_TRUE(relayed.has_value()) << relayed.error().message;
  ASSERT_EQ(relayed->stored.size(), 1u);
  EXPECT_EQ(taken_ids(watcher), (std::vector<std::uint64_t>{own, relayed->stored[0]}));
  // The same source, written another way, is the same subscription; an invalid one is refused.
  EXPECT_EQ(watcher.subscribe({.source = kNodeIri + "/child"}).value(),
            watcher.subscribe({.source = kNodeIri + "/./child"}).value());
  auto bad = watcher.subscribe({.source = "not an iri"});
  ASSERT_FALSE(bad.has_value());
  EXPECT_EQ(bad.error().code, Errc::invalid_iri);
}

// A new subscription joins the process's routing as it is stored (not by reloading all of
// them): each of many subscriptions, made one after another between writes, of every kind of
// condition, gets exactly the items written after it that its pattern matches. (Later
// subscriptions are items too, and some match: they are left out of the comparison.)
TEST(Source, SubscriptionsMadeBetweenWritesEachGetExactlyTheLaterItemsTheyMatch) {
  TempDir dir;
  Node node = make_node(dir.path());
  const std::string contexts[] = {"", "http://example.org/ctx/a"};
  struct Made {
    std::string agent;
    Pattern pattern;
    std::vector<std::uint64_t> expected;
  };
  std::vector<Made> made;
  std::set<std::uint64_t> written;
  std::mt19937 rng(20261128);
  for (int round = 0; round < 40; ++round) {
    Pattern p;
    switch (round % 5) {
      case 0: p.p = ex("p" + std::to_string(rng() % 3)); break;
      case 1: p.o = Term::integer(static_cast<int>(rng() % 4)); break;
      case 2: p.context = contexts[1]; break;
      case 3: p.source = kNodeIri + "/w" + std::to_string(rng() % 2); break;
      default: p.s = Term::iri(kNodeIri + "/obs/" + std::to_string(rng() % 3)); p.p = ex("p0"); break;
    }
    made.push_back({"sub" + std::to_string(round), p, {}});
    ASSERT_TRUE(node.agent(made.back().agent)->subscribe(p));
    for (int k = 0; k < 3; ++k) {
      const std::string writer = "w" + std::to_string(rng() % 2);
      Item item;
      item.add(Term::iri(kNodeIri + "/obs/" + std::to_string(rng() % 3)), ex("p" + std::to_string(rng() % 3)),
               Term::integer(static_cast<int>(rng() % 4)));
      item.context = contexts[rng() % 2];
      const std::uint64_t id = node.agent(writer)->store(item).value();
      written.insert(id);
      const Triple& t = item.triples[0];
      for (Made& m : made) {
        const Pattern& q = m.pattern;
        if ((!q.s || *q.s == t.s) && (!q.p || *q.p == t.p) && (!q.o || *q.o == t.o) &&
            (!q.context || *q.context == item.context) && (!q.source || *q.source == kNodeIri + "/" + writer))
          m.expected.push_back(id);
      }
    }
  }
  for (Made& m : made) {
    Agent agent = node.agent(m.agent).value();
    std::vector<std::uint64_t> taken = taken_ids(agent);
    std::erase_if(taken, [&](std::uint64_t id) { return !written.contains(id); });
    EXPECT_EQ(taken, m.expected) << m.agent;
  }
}

// A room's state or a reasoner's conclusions are replaced, not removed then stored: a reader
// must never find neither the old records nor the new.
TEST(Replace, RemovesAndStoresInOneTransactionOrDoesNothing) {
  TempDir dir;
  Node node = make_node(dir.path(), {.max_literal_bytes = 64});
  Agent env = node.agent("environment").value();
  Agent ui = node.agent("ui").value();
  ASSERT_TRUE(ui.subscribe({.p = ex("temperature")}));
  Item old_state;
  old_state.add(ex("bedroom"), ex("temperature"), Term::integer(20));
  ASSERT_TRUE(env.store(old_state));
  ASSERT_TRUE(ui.take(0ms).value());
  const std::uint64_t before = node.snapshot().value().last_seq();

  Item new_state;
  new_state.add(ex("bedroom"), ex("temperature"), Term::integer(21));
  auto replaced = env.replace({{.s = ex("bedroom"), .p = ex("temperature")}}, {new_state});
  ASSERT_TRUE(replaced.has_value()) << replaced.error().message;
  ASSERT_EQ(replaced->size(), 1u);
  auto now = node.snapshot().value().list({.s = ex("bedroom")}).value();
  ASSERT_EQ(now.size(), 1u);
  EXPECT_EQ(now[0].triple.o.value, "21");
  // One commit: the change stream has the removal and the new record, and the new item is
  // routed like any stored item.
  auto changes = node.watch(before, 0ms).value();
  ASSERT_EQ(changes.size(), 2u);
  EXPECT_TRUE(changes[0].removed);
  EXPECT_FALSE(changes[1].removed);
  auto delivered = ui.take(0ms).value();
  ASSERT_TRUE(delivered.has_value());
  EXPECT_EQ(delivered->item, (*replaced)[0]);

  // A new item that is refused leaves the old records in place.
  Item too_large;
  too_large.add(ex("bedroom"), ex("temperature"), Term::literal(std::string(100, 'x')));
  auto refused = env.replace({{.s = ex("bedroom")}}, {too_large});
  ASSERT_FALSE(refused.has_value());
  EXPECT_EQ(refused.error().code, Errc::literal_too_large);
  EXPECT_EQ(node.snapshot().value().list({.s = ex("bedroom")}).value().size(), 1u);
  // A removal pattern with nothing bound is refused, as Node::remove refuses it.
  auto empty = env.replace({Pattern{}}, {new_state});
  ASSERT_FALSE(empty.has_value());
  EXPECT_EQ(empty.error().code, Errc::invalid_argument);
}

// A reasoner retracts conclusions as patterns giving s, p, o and its own source; those of one
// subject are found in one walk of its records (Query::collect_exact), and a subject with many
// more records than patterns pattern by pattern. Either way exactly the named records of that
// source go: not another writer's same triple, not a neighbour's.
TEST(Replace, ManyExactRemovalsTakeExactlyTheNamedRecordsOfTheirSource) {
  TempDir dir;
  Node node = make_node(dir.path());
  Agent reasoner = node.agent("reasoner").value();
  Agent other = node.agent("other").value();
  const Term reaches = ex("reaches");
  auto x = [](int i) { return ex("x" + std::to_string(i)); };
  Item closure, same;
  for (int i = 0; i < 40; ++i)
    for (int j = i + 1; j < 40; ++j) closure.add(x(i), reaches, x(j));
  for (int j = 1; j < 40; ++j) same.add(x(0), reaches, x(j));
  ASSERT_TRUE(reasoner.store(closure));
  ASSERT_TRUE(other.store(same));
  Item hub;  // x39 has 200 records: two patterns of it are looked up one by one
  for (int k = 0; k < 200; ++k) hub.add(x(39), ex("value"), Term::integer(k));
  ASSERT_TRUE(reasoner.store(hub));

  std::vector<Pattern> gone;
  std::set<std::pair<std::string, std::string>> expected_gone;
  for (int i = 0; i < 20; ++i)
    for (int j = 20; j < 40; ++j) {
      gone.push_back({.s = x(i), .p = reaches, .o = x(j), .source = reasoner.iri()});
      expected_gone.insert({x(i).value, x(j).value});
    }
  gone.push_back({.s = x(5), .p = reaches, .o = x(99), .source = reasoner.iri()});  // no such record
  gone.push_back({.s = x(39), .p = ex("value"), .o = Term::integer(7), .source = reasoner.iri()});
  gone.push_back({.s = x(39), .p = ex("value"), .o = Term::integer(8), .source = reasoner.iri()});
  ASSERT_TRUE(reasoner.replace(gone, {}).has_value());

  auto snap = node.snapshot().value();
  auto left = snap.list({.p = reaches, .source = reasoner.iri()}).value();
  EXPECT_EQ(left.size(), 40u * 39 / 2 - expected_gone.size());
  for (const Record& r : left)
    EXPECT_FALSE(expected_gone.count({r.triple.s.value, r.triple.o.value})) << r.triple.s.value << " " << r.triple.o.value;
  EXPECT_EQ(snap.list({.p = reaches, .source = other.iri()}).value().size(), 39u);
  auto values = snap.list({.s = x(39), .p = ex("value")}).value();
  EXPECT_EQ(values.size(), 198u);
  for (const Record& r : values) EXPECT_TRUE(r.triple.o.value != "7" && r.triple.o.value != "8") << r.triple.o.value;
}

TEST(Context, ItemAddressedToAnAgentLandsInItsInputBufferWithoutSubscription) {
  TempDir dir;
  Node node = make_node(dir.path());
  Agent hrv = node.agent("hrv").value();
  Agent child = node.agent("ecg1").value();
  Agent operator_ = node.agent("operator").value();
  std::uint64_t to_hrv = operator_.store(reading(1, kNodeIri + "/hrv")).value();
  // Below an agent's IRI (a node further down, reached through the link agent "ecg1").
  std::uint64_t to_grandchild = operator_.store(reading(2, kNodeIri + "/ecg1/source")).value();
  ASSERT_TRUE(operator_.store(reading(3, kNodeIri + "/*")));       // a subtree: no one agent
  ASSERT_TRUE(operator_.store(reading(4, kNodeIri)));              // the node itself
  ASSERT_TRUE(operator_.store(reading(5, "http://example.org/home10/hrv")));  // another node
  ASSERT_TRUE(operator_.store(reading(6, kNodeIri + "/operator")));  // the writer itself
  EXPECT_EQ(taken_ids(hrv), std::vector<std::uint64_t>{to_hrv});
  EXPECT_EQ(taken_ids(child), std::vector<std::uint64_t>{to_grandchild});
  EXPECT_TRUE(taken_ids(operator_).empty());
}

// A child node's store made again (a replaced disk) holds nothing of what came down: its link
// agent on the parent gets again the persistent items addressed to it (a setting written
// --persistent for the child's hrv), as it gets those its subscriptions match.
TEST(Context, PersistentItemsAddressedToAnAgentAreDeliveredAgainOnceTaken) {
  TempDir dir;
  Node node = make_node(dir.path());
  Agent child = node.agent("home1").value();
  Agent operator_ = node.agent("operator").value();
  Item setting = reading(1, kNodeIri + "/home1/hrv");
  setting.persistent = true;
  const std::uint64_t kept = operator_.store(setting).value();
  ASSERT_TRUE(operator_.store(reading(2, kNodeIri + "/home1/hrv")));  // not persistent
  Item elsewhere = reading(3, kNodeIri + "/home2/hrv");
  elsewhere.persistent = true;
  ASSERT_TRUE(operator_.store(elsewhere));
  Item subtree = reading(4, kNodeIri + "/*");
  subtree.persistent = true;
  ASSERT_TRUE(operator_.store(subtree));
  EXPECT_EQ(taken_ids(child).size(), 2u);
  EXPECT_EQ(child.deliver_persistent_again().value(), 0u) << "by its subscriptions alone: none";
  EXPECT_EQ(child.deliver_persistent_again(Redelivery::addressed_too).value(), 1u);
  EXPECT_EQ(taken_ids(child), std::vector<std::uint64_t>{kept});
  // Put back once more, and then not again while it waits in the buffer.
  EXPECT_EQ(child.deliver_persistent_again(Redelivery::addressed_too).value(), 1u);
  EXPECT_EQ(child.deliver_persistent_again(Redelivery::addressed_too).value(), 0u);
}

// A link sends again what its parent lost (docs/protocol.md P6c, P6d): only what the uplink's
// subscriptions gave it, never items stored before a pattern was added, which stay home (P5).
// Up to session 78 every item the patterns matched now went up at the next welcome.
TEST(Redelivery, OnlyWhatASubscriptionGaveTheAgentIsDeliveredAgain) {
  TempDir dir;
  Node node = make_node(dir.path());
  Agent uplink = node.agent("uplink").value();
  Agent writer = node.agent("writer").value();
  ASSERT_TRUE(uplink.receive_removals());
  Item kept_home = reading(1);
  kept_home.persistent = true;
  const std::uint64_t before_pattern = writer.store(kept_home).value();
  ASSERT_TRUE(writer.store(reading(2)));
  ASSERT_TRUE(uplink.subscribe({.p = ex("value")}));
  Item description = reading(3);
  description.persistent = true;
  const std::uint64_t persistent_after = writer.store(description).value();
  const std::uint64_t after = writer.store(reading(4)).value();
  ASSERT_EQ(taken_ids(uplink), (std::vector<std::uint64_t>{persistent_after, after}));
  ASSERT_TRUE(uplink.ack_through(after));
  EXPECT_EQ(uplink.deliver_again_between(0, std::numeric_limits<std::uint64_t>::max()).value(), 2u);
  EXPECT_EQ(taken_ids(uplink), (std::vector<std::uint64_t>{persistent_after, after}));
  EXPECT_EQ(uplink.deliver_persistent_again().value(), 1u);
  EXPECT_EQ(taken_ids(uplink), std::vector<std::uint64_t>{persistent_after});
  // Given when it subscribed (`earlier`): those went to it, and go again.
  Agent other = node.agent("other").value();
  ASSERT_TRUE(other.receive_removals());
  ASSERT_TRUE(other.subscribe({.p = ex("value")}, {.earlier = true}));
  ASSERT_EQ(taken_ids(other).size(), 4u);
  EXPECT_EQ(other.deliver_again_between(0, std::numeric_limits<std::uint64_t>::max()).value(), 4u);
  EXPECT_EQ(taken_ids(other).front(), before_pattern);
}

// A child's down queue on a parent (P11, P10b): the whole-subtree settings kept before the child
// joined went to it when it subscribed, and go down again to its store made again, also where a
// build before session 79 subscribed it before it received removal notices (so they were never
// remembered as given).
TEST(Redelivery, SubtreeSettingsKeptBeforeAChildJoinedGoDownAgainWhateverTheOrderItWasSetUpIn) {
  TempDir dir;
  Node node = make_node(dir.path());
  Agent operator_ = node.agent("operator").value();
  Item for_all = reading(1, kNodeIri + "/*");
  for_all.persistent = true;
  const std::uint64_t setting = operator_.store(for_all).value();
  Agent child = node.agent("home2").value();
  ASSERT_TRUE(child.subscribe({.context = kNodeIri + "/*"}, {.earlier = true, .persistent_only = true}));
  ASSERT_TRUE(child.receive_removals());
  ASSERT_EQ(taken_ids(child), std::vector<std::uint64_t>{setting});
  EXPECT_EQ(child.deliver_persistent_again(Redelivery::addressed_too).value(), 1u);
  EXPECT_EQ(taken_ids(child), std::vector<std::uint64_t>{setting});
}

TEST(Window, PeekLeavesItemsAndAckThroughRemovesUpToAnId) {
  TempDir dir;
  Node node = make_node(dir.path());
  Agent uplink = node.agent("uplink").value();
  Agent writer = node.agent("writer").value();
  ASSERT_TRUE(uplink.subscribe({.p = ex("value")}));
  std::vector<std::uint64_t> ids;
  for (int i = 0; i < 5; ++i) ids.push_back(writer.store(reading(i)).value());
  auto first = uplink.peek(0, 2, 0ms).value();
  ASSERT_EQ(first.size(), 2u);
  EXPECT_EQ(first[0].item, ids[0]);
  EXPECT_EQ(first[1].item, ids[1]);
  auto next = uplink.peek(ids[1], 10, 0ms).value();
  ASSERT_EQ(next.size(), 3u);
  EXPECT_EQ(next[0].item, ids[2]);
  EXPECT_EQ(uplink.pending().value(), 5u);
  EXPECT_EQ(uplink.ack_through(ids[2]).value(), 3u);
  EXPECT_EQ(uplink.pending().value(), 2u);
  EXPECT_EQ(uplink.peek(0, 0, 0ms).value().front().item, ids[3]);
  EXPECT_TRUE(uplink.peek(ids[4], 0, 10ms).value().empty());  // nothing after the last: timeout
}

// A link's down queue read from its end (docs/protocol.md P6f): the newest items between two ids,
// newest first, without waiting.
TEST(Window, PeekNewestReadsTheBufferFromItsEndBetweenTwoIds) {
  TempDir dir;
  Node node = make_node(dir.path());
  Agent queue = node.agent("home1").value();
  Agent writer = node.agent("writer").value();
  EXPECT_TRUE(queue.peek_newest(0, ~0ull, 3).value().empty());  // never seen: no buffer
  ASSERT_TRUE(queue.subscribe({.p = ex("value")}));
  std::vector<std::uint64_t> ids;
  for (int i = 0; i < 5; ++i) ids.push_back(writer.store(reading(i)).value());
  const auto items_of = [](const std::vector<Delivery>& ds) {
    std::vector<std::uint64_t> out;
    for (const Delivery& d : ds) out.push_back(d.item);
    return out;
  };
  EXPECT_EQ(items_of(queue.peek_newest(0, ~0ull, 2).value()), (std::vector<std::uint64_t>{ids[4], ids[3]}));
  EXPECT_EQ(items_of(queue.peek_newest(ids[1], ids[4], 0).value()), (std::vector<std::uint64_t>{ids[3], ids[2]}));
  EXPECT_EQ(items_of(queue.peek_newest(0, ids[1] + 1, 5).value()), (std::vector<std::uint64_t>{ids[1], ids[0]}));
  EXPECT_TRUE(queue.peek_newest(ids[4], ~0ull, 5).value().empty());
  EXPECT_TRUE(queue.peek_newest(ids[2], ids[3], 5).value().empty());
  ASSERT_TRUE(node.remove_item(ids[4]));  // removed: skipped
  EXPECT_EQ(items_of(queue.peek_newest(ids[2], ~0ull, 5).value()), (std::vector<std::uint64_t>{ids[3]}));
  EXPECT_EQ(queue.pending().value(), 4u);  // left in place
}

// A subscription written as plain data (R9: any agent may write one on the subscriber's behalf)
// is kept on a ring store: reclaimed, the subscriber stopped receiving, and nothing said so.
// A ring store of 5 records: a configurator writes subscriptions as plain data for a monitor,
// and a writer writes readings.
struct RingWithMonitor {
  TempDir dir;
  Node node = make_node(dir.path(), {.ring = 5});
  Agent configurator = node.agent("configurator").value();
  Agent monitor = node.agent("monitor").value();
  Agent writer = node.agent("writer").value();
};

TEST(Subscribe, ASubscriptionWrittenAsPlainDataIsNotReclaimedByTheRing) {
  RingWithMonitor ring;
  auto& [dir, node, configurator, monitor, writer] = ring;
  Item subscription;
  subscription.add(Term::blank("sub"), Term::iri("https://w3id.org/tahvel#subscriber"), Term::iri(monitor.iri()))
      .add(Term::blank("sub"), Term::iri("https://w3id.org/tahvel#predicate"), ex("value"));
  ASSERT_TRUE(configurator.store(subscription));  // not marked persistent
  for (int i = 0; i < 20; ++i) {
    ASSERT_TRUE(writer.store(reading(i)));
    ASSERT_TRUE(monitor.take(0ms).value()) << "reading " << i << " did not reach the monitor";
  }
  EXPECT_EQ(node.snapshot().value().list({.p = Term::iri("https://w3id.org/tahvel#subscriber")}).value().size(), 1u);
}

// A subscription whose pattern comes in an item of its own (a reasoner writes one item per
// predicate, RS12): that item is kept as the tv:subscriber one is. Reclaimed by the ring, it left
// a subscription without a pattern, which matches every item: an uplink then forwarded all.
TEST(Subscribe, ASubscriptionsPatternWrittenApartIsNotReclaimedByTheRing) {
  RingWithMonitor ring;
  auto& [dir, node, configurator, monitor, writer] = ring;
  const Term sub = Term::iri("http://example.org/subscriptions/1");
  Item who, what;
  who.add(sub, Term::iri("https://w3id.org/tahvel#subscriber"), Term::iri(monitor.iri()));
  what.add(sub, Term::iri("https://w3id.org/tahvel#predicate"), ex("value"));
  ASSERT_TRUE(configurator.store(what));  // the pattern first, then who it is for
  ASSERT_TRUE(configurator.store(who));
  for (int i = 0; i < 20; ++i) {
    ASSERT_TRUE(writer.store(reading(i)));
    Item other;
    other.add(ex("note" + std::to_string(i)), ex("private"), Term::literal("not for the monitor"));
    ASSERT_TRUE(writer.store(other));
    auto got = monitor.take(0ms).value();
    ASSERT_TRUE(got) << "reading " << i << " did not reach the monitor";
    EXPECT_EQ(got->records.front().triple.p, ex("value")) << "at reading " << i;
    EXPECT_FALSE(monitor.take(0ms).value()) << "the monitor got the private note " << i;
  }
  EXPECT_EQ(node.snapshot().value().list({.p = Term::iri("https://w3id.org/tahvel#predicate")}).value().size(), 1u);
}

// A link trims its outbox a run at a time: the whole buffer may go, while the buffers of other
// agents (stored beside it) keep theirs, and an item acknowledged by every buffer that held it
// is no longer kept from the ring.
TEST(Window, AckThroughEmptiesOneBufferLeavesTheOthersAndLetsTheRingTakeTheItems) {
  TempDir dir;
  Node node = make_node(dir.path(), {.ring = 4});
  Agent before = node.agent("a-buffer").value();  // agents interned before and after the uplink
  Agent uplink = node.agent("uplink").value();
  Agent after = node.agent("z-buffer").value();
  Agent writer = node.agent("writer").value();
  for (Agent* a : {&before, &uplink, &after}) ASSERT_TRUE(a->subscribe({.p = ex("value")}));
  std::vector<std::uint64_t> ids;
  for (int i = 0; i < 6; ++i) ids.push_back(writer.store(reading(i)).value());
  EXPECT_EQ(uplink.ack_through(ids.back() + 1000).value(), 6u);
  EXPECT_EQ(uplink.pending().value(), 0u);
  EXPECT_EQ(before.pending().value(), 6u);
  EXPECT_EQ(after.pending().value(), 6u);
  EXPECT_EQ(uplink.ack_through(ids.back()).value(), 0u);  // nothing left to acknowledge
  // Readings are not persistent (the subscriptions are): what the ring bounds.
  auto readings = [&] {
    const Stats st = node.stats().value();
    return st.records - st.persistent_records;
  };
  // The other two buffers still hold every item: the ring keeps them all.
  ASSERT_TRUE(writer.store(reading(6)));
  EXPECT_EQ(readings(), 7u);
  EXPECT_EQ(before.ack_through(ids[3]).value(), 4u);
  EXPECT_EQ(after.ack_through(ids[3]).value(), 4u);
  ASSERT_TRUE(writer.store(reading(7)));
  // Items 0-3 were released by all three buffers; the uplink's later items stay pending in the
  // other two (and the two new ones in all three), so the ring takes exactly the first four.
  EXPECT_EQ(readings(), 4u);
  EXPECT_EQ(before.peek(0, 0, 0ms).value().front().item, ids[4]);
}

// One thread serving many input buffers (a parent's link sending down to its children) reads
// each agent's buffer_version and sleeps in wait_for_commit until one of them moves.
TEST(Window, BufferVersionMovesWhenAnItemArrivesForThatAgent) {
  TempDir dir;
  Node node = make_node(dir.path());
  Agent child = node.agent("child").value();
  Agent writer = node.agent("writer").value();
  ASSERT_TRUE(child.subscribe({.p = ex("value")}));
  const std::uint32_t before = child.buffer_version();
  ASSERT_TRUE(writer.store(reading(1)));
  const std::uint32_t after_item = child.buffer_version();
  EXPECT_NE(after_item, before);
  ASSERT_TRUE(child.ack_through(~0ull));  // taking or acknowledging brings nothing new
  EXPECT_EQ(child.buffer_version(), after_item);
}

TEST(Window, WaitForCommitReturnsWhenAnyOfManyBuffersGetsAnItemOrWhenWoken) {
  TempDir dir;
  Node node = make_node(dir.path());
  std::vector<Agent> children;
  for (int i = 0; i < 50; ++i) {
    children.push_back(node.agent("child" + std::to_string(i)).value());
    ASSERT_TRUE(children.back().subscribe({.context = "http://example.org/group/" + std::to_string(i)}));
  }
  std::vector<std::uint32_t> seen;
  for (const Agent& c : children) seen.push_back(c.buffer_version());
  auto changed = [&] {
    for (std::size_t i = 0; i < children.size(); ++i)
      if (children[i].buffer_version() != seen[i]) return true;
    return false;
  };
  EXPECT_FALSE(node.wait_for_commit(changed, 1ms));  // nothing yet: times out
  // A writer in another thread (another process would do the same) stores an item for nobody,
  // which need not wake the waiter, then one for the 37th child, which must.
  std::thread writer([&] {
    Node other = Node::open(dir.path()).value();
    Agent w = other.agent("writer").value();
    std::this_thread::sleep_for(20ms);  // most likely asleep by now; correct either way
    ASSERT_TRUE(w.store(reading(2, "http://example.org/group/none")));  // routed nowhere
    ASSERT_TRUE(w.store(reading(1, "http://example.org/group/37")));
  });
  EXPECT_TRUE(node.wait_for_commit(changed, 60s));
  writer.join();
  EXPECT_NE(children[37].buffer_version(), seen[37]);
  EXPECT_EQ(children[37].peek(0, 0, 0ms).value().size(), 1u);
  // wake_waiters: a waiter whose own condition (here a flag) is set by another thread.
  std::atomic<bool> flag{false};
  std::thread waker([&] {
    std::this_thread::sleep_for(20ms);
    flag = true;
    node.wake_waiters();
  });
  EXPECT_TRUE(node.wait_for_commit([&] { return flag.load(); }, 60s));
  waker.join();
}

RelayedItem relayed(std::uint64_t seq, std::uint64_t prev, std::string source, int n) {
  return RelayedItem{seq, prev, std::move(source), reading(n)};
}

TEST(Relay, StoresEachSequenceOnceKeepsTheSourceAndStopsAtAGap) {
  TempDir dir;
  Node node = make_node(dir.path());
  Agent child = node.agent("child").value();
  const std::string source = kNodeIri + "/child/hrv";
  auto first = child.relay("up", {relayed(10, 0, source, 1), relayed(12, 10, source, 2)}).value();
  EXPECT_EQ(first.stored.size(), 2u);
  EXPECT_EQ(first.mark, 12u);
  // A resend of both plus a new one: only the new one is stored.
  auto again = child.relay("up", {relayed(10, 0, source, 1), relayed(12, 10, source, 2),
                                  relayed(15, 12, source, 3)}).value();
  EXPECT_EQ(again.duplicates, 2u);
  EXPECT_EQ(again.stored.size(), 1u);
  EXPECT_EQ(again.mark, 15u);
  // 20 follows 17, which never arrived: nothing is applied, the sender must resend from 15.
  auto gap = child.relay("up", {relayed(20, 17, source, 5)}).value();
  EXPECT_TRUE(gap.gap);
  EXPECT_TRUE(gap.stored.empty());
  EXPECT_EQ(gap.mark, 15u);
  EXPECT_EQ(child.relay_mark("up").value(), 15u);
  EXPECT_EQ(child.relay_mark("other").value(), 0u);

  auto records = node.snapshot().value().list({.p = ex("value")}).value();
  ASSERT_EQ(records.size(), 3u);
  for (const auto& r : records) EXPECT_EQ(r.meta.source, source);
}

// A run the store has room for in part: the items that fit are stored in order, the mark stops
// after the last of them, and why the rest was not applied is said. The whole run was refused,
// and a sender then probing one item at a time got one item stored per round trip.
TEST(Relay, AStoreWithRoomForPartOfARunStoresTheItemsThatFitAndSaysWhyNotTheRest) {
  TempDir dir;
  Node node = make_node(dir.path(), {.max_map_bytes = 1 << 20});
  Agent filler = node.agent("filler").value();
  std::vector<std::uint64_t> fills;
  for (std::size_t size : {2000, 200, 20})
    for (;;) {
      auto id = filler.store(Item{}.add(Term::iri(kNodeIri + "/f" + std::to_string(fills.size())), ex("fill"),
                                        Term::literal(std::string(size, 'f') + std::to_string(fills.size()))));
      if (!id) break;
      fills.push_back(*id);
    }
  // Room for part of the run, beyond the part of the maximum that items from below leave to the
  // node's own writers (kept_for_own_writers).
  for (std::size_t i = 0; i < 120; ++i) ASSERT_TRUE(node.remove({.s = Term::iri(kNodeIri + "/f" + std::to_string(i))}));
  Agent child = node.agent("child").value();
  const std::string source = kNodeIri + "/child/hrv";
  std::vector<RelayedItem> run;
  for (std::uint64_t seq = 1; seq <= 1000; ++seq) run.push_back(relayed(seq, seq - 1, source, static_cast<int>(seq)));
  auto relayed_part = child.relay("up", run);
  ASSERT_TRUE(relayed_part) << relayed_part.error().message;
  auto part = *relayed_part;
  ASSERT_FALSE(part.stored.empty()) << "the room freed took nothing";
  ASSERT_LT(part.stored.size(), run.size()) << "the case under test did not happen: the whole run fitted";
  EXPECT_EQ(part.mark, part.stored.size());
  ASSERT_TRUE(part.not_applied);
  EXPECT_EQ(part.not_applied->code, Errc::store_full);
  EXPECT_FALSE(part.gap);
  EXPECT_EQ(child.relay_mark("up").value(), part.mark);
  EXPECT_EQ(node.snapshot().value().count({.p = ex("value")}).value(), part.stored.size());
  // The rest, sent again from the mark once there is room, continues the stream.
  ASSERT_TRUE(node.remove({.p = ex("fill")}));
  auto rest = child.relay("up", std::vector<RelayedItem>(run.begin() + static_cast<std::ptrdiff_t>(part.mark), run.end())).value();
  EXPECT_FALSE(rest.not_applied);
  EXPECT_EQ(rest.mark, 1000u);
  EXPECT_EQ(node.snapshot().value().count({.p = ex("value")}).value(), 1000u);
}

// A full home whose operator removed old raw ECG: the sensor's backlog, relayed into the room
// made, took all of it, and the home's own agents (R-peaks, RR, HRV) could not write, the
// removal done for nothing (an integrator's probe of session 87). Items from below leave the
// last part of the maximum (kept_for_own_writers: a sixteenth) to this node's own writers.
TEST(Relay, ItemsFromBelowLeaveRoomForThisNodesOwnWriters) {
  TempDir dir;
  constexpr std::uint64_t kMax = 4 << 20;
  Node node = make_node(dir.path(), {.max_map_bytes = kMax});
  Agent child = node.agent("child").value();
  const std::string source = kNodeIri + "/child/ecg";
  std::uint64_t seq = 0;
  std::optional<Error> full;
  while (!full) {
    std::vector<RelayedItem> run;
    for (int k = 0; k < 50; ++k, ++seq)
      run.push_back(RelayedItem{seq + 1, seq, source, Item{}.add(Term::iri(source + "/c" + std::to_string(seq)), ex("samples"),
                                                                 Term::literal(std::string(900, 's') + std::to_string(seq)))});
    auto relayed_run = child.relay("up", run);
    ASSERT_TRUE(relayed_run) << relayed_run.error().message;
    full = relayed_run->not_applied;
    seq = relayed_run->mark;
  }
  EXPECT_EQ(full->code, Errc::store_full);
  EXPECT_NE(full->message.find("items relayed from below leave the last 262144 bytes of it to this node's own agents; they wait "
                               "in the child's outbox"),
            std::string::npos)
      << full->message;
  // This node's own agent still writes, 200 KB of items (beyond what is kept for it, it would not).
  Agent own = node.agent("rpeak").value();
  for (int k = 0; k < 200; ++k) {
    auto stored = own.store(Item{}.add(ex("peaks" + std::to_string(k)), ex("peaks"), Term::literal(std::string(900, 'p'))));
    ASSERT_TRUE(stored) << "own write " << k << ": " << stored.error().message;
  }
  // A parent's configuration relayed down (its source above this node) is this node's to write too.
  Agent uplink = node.agent("uplink").value();
  auto down = uplink.relay("down", {RelayedItem{1, 0, "http://example.org/hospital/cli", Item{}.add(ex("config"), ex("window"), Term::integer(300))}});
  ASSERT_TRUE(down) << down.error().message;
  EXPECT_FALSE(down->not_applied);
}

// A node's persistent items go up again on a new stream when a store on the way was made again
// or restored from a backup (docs/protocol.md P6c). A node above that holds them from the stream
// before drops them; anything that differs in what makes an item the same is stored.
TEST(Relay, APersistentItemHeldAlreadyFromTheSameSourceIsDroppedOnAnotherStream) {
  TempDir dir;
  Node node = make_node(dir.path());
  Agent child = node.agent("child").value();
  const std::string source = kNodeIri + "/child/ecg";
  auto description = [&](std::int64_t at, int n) {
    RelayedItem r = relayed(0, 0, source, n);
    r.item.persistent = true;
    r.item.asserted_at = at;
    // A blank node is renamed on the way, on each store: it matches any blank node.
    r.item.add(Term::blank("lead"), ex("name"), Term::literal("MLII"));
    r.item.add(Term::iri(kNodeIri + "/obs/" + std::to_string(n)), ex("lead"), Term::blank("lead"));
    return r;
  };
  auto on = [](RelayedItem r, std::uint64_t seq, std::uint64_t prev) {
    r.seq = seq;
    r.prev = prev;
    return r;
  };
  auto first = child.relay("child#old", {on(description(1000, 1), 1, 0), on(description(2000, 2), 2, 1)}).value();
  ASSERT_EQ(first.stored.size(), 2u);
  RelayedItem other_time = description(1001, 1), not_persistent = description(1000, 1), other_source = description(1000, 1);
  not_persistent.item.persistent = false;
  other_source.source = kNodeIri + "/child/other";
  auto again = child.relay("child#new", {on(description(1000, 1), 1, 0), on(description(2000, 2), 2, 1),
                                         on(other_time, 3, 2), on(not_persistent, 4, 3), on(other_source, 5, 4)}).value();
  EXPECT_EQ(again.already_held, 2u);
  EXPECT_EQ(again.duplicates, 0u);
  EXPECT_EQ(again.stored.size(), 3u) << "another time, a non-persistent item and another source are other items";
  EXPECT_EQ(again.mark, 5u) << "the mark moves past what was dropped";
  EXPECT_EQ(node.snapshot().value().list({.p = ex("value"), .o = Term::integer(2)}).value().size(), 1u);
  EXPECT_EQ(node.snapshot().value().list({.p = ex("value"), .o = Term::integer(1)}).value().size(), 4u);
  // One triple more or less is another item.
  RelayedItem longer = description(2000, 2);
  longer.item.add(Term::iri(kNodeIri + "/obs/2"), ex("note"), Term::literal("x"));
  EXPECT_EQ(child.relay("child#third", {on(longer, 1, 0)}).value().stored.size(), 1u);
}

// A child store restored from a backup sends again, on a new stream, what its backup's outbox
// held (docs/protocol.md P10c). Up to the seq said by relay_may_repeat, an item that repeats one
// held is dropped, persistent or not; beyond it, and on other streams, it is stored.
TEST(Relay, AnItemThatRepeatsOneHeldIsDroppedUpToWhereItsStreamMayRepeat) {
  TempDir dir;
  Node node = make_node(dir.path());
  Agent child = node.agent("child").value();
  const std::string source = kNodeIri + "/child/hrv";
  auto at = [&](std::uint64_t seq, std::int64_t time, int n) {
    RelayedItem r = relayed(seq, seq - 1, source, n);
    r.item.asserted_at = time;
    return r;
  };
  ASSERT_EQ(child.relay("child#old", {at(1, 1000, 1), at(2, 2000, 2), at(3, 3000, 3)}).value().stored.size(), 3u);
  ASSERT_TRUE(child.relay_may_repeat("child#new", 2));
  ASSERT_TRUE(child.relay_may_repeat("child#new", 1)) << "a lower bound is no error";
  auto again = child.relay("child#new", {at(1, 1000, 1), at(2, 2000, 2), at(3, 3000, 3), at(4, 2500, 2)}).value();
  EXPECT_EQ(again.already_held, 2u);
  EXPECT_EQ(again.stored.size(), 2u) << "seq 3 lies beyond where the stream may repeat; seq 4 was asserted at another time";
  EXPECT_EQ(again.mark, 4u);
  EXPECT_EQ(node.snapshot().value().list({.p = ex("value"), .o = Term::integer(1)}).value().size(), 1u);
  EXPECT_EQ(node.snapshot().value().list({.p = ex("value"), .o = Term::integer(2)}).value().size(), 2u);
  EXPECT_EQ(node.snapshot().value().list({.p = ex("value"), .o = Term::integer(3)}).value().size(), 2u);
  // Another stream repeats nothing unless said.
  EXPECT_EQ(child.relay("child#third", {at(1, 1000, 1)}).value().stored.size(), 1u);
  // What was said is kept in the store.
  Node reopened = Node::open(dir.path()).value();
  auto later = reopened.agent("child").value().relay("child#new", {at(5, 1000, 1)}).value();
  EXPECT_EQ(later.stored.size(), 1u) << "seq 5 lies beyond 2";
  EXPECT_FALSE(child.relay_may_repeat("", 1)) << "an empty stream name";
}

// A store that takes the place of another (a standby gateway with a store of its own) computes
// again what the one before had sent up, from inputs cut otherwise: an HRV window of the same
// name, source and time derived from RR items named otherwise (docs/protocol.md P10c). Where its
// stream may repeat, the parent keeps the one it held and drops the other; an item of that name
// that the new stream stored itself, or of another source, time or stream, is another item.
TEST(Relay, AnItemComputedAgainByAStoreInAnothersPlaceIsHeldByItsNameOnce) {
  TempDir dir;
  Node node = make_node(dir.path());
  Agent child = node.agent("child").value();
  const std::string source = kNodeIri + "/child/hrv";
  auto window = [&](std::uint64_t seq, int n, std::int64_t time, const std::string& derived_from) {
    RelayedItem r = relayed(seq, seq - 1, source, n);
    r.item.asserted_at = time;
    r.item.add(Term::iri(kNodeIri + "/obs/" + std::to_string(n)), ex("derivedFrom"), Term::iri(kNodeIri + "/rr/" + derived_from));
    return r;
  };
  ASSERT_EQ(child.relay("child#old", {window(1, 1, 1000, "a"), window(2, 2, 2000, "b")}).value().stored.size(), 2u);
  ASSERT_TRUE(child.relay_may_repeat("child#new", 0, 1'000'000));
  RelayedItem other_source = window(5, 2, 2000, "y");
  other_source.source = kNodeIri + "/child/other";
  RelayedItem blank_name = window(6, 1, 1000, "z");
  blank_name.item.triples.front().s = Term::blank("w");
  auto again = child.relay("child#new", {window(1, 1, 1000, "c"), window(2, 3, 2000, "d"), window(3, 4, 3000, "e"),
                                         window(4, 4, 3000, "f"), other_source, blank_name}).value();
  EXPECT_EQ(again.already_held, 1u);
  EXPECT_EQ(again.recomputed, 1u);
  EXPECT_EQ(again.stored.size(), 5u) << "another name at that time, an item of a name this stream stored itself, another "
                                        "source and a blank first subject are other items";
  EXPECT_EQ(again.mark, 6u);
  auto snapshot = node.snapshot().value();
  EXPECT_EQ(snapshot.list({.o = Term::iri(kNodeIri + "/rr/a")}).value().size(), 1u) << "the one held is kept";
  EXPECT_EQ(snapshot.list({.o = Term::iri(kNodeIri + "/rr/c")}).value().size(), 0u);
  EXPECT_EQ(snapshot.list({.o = Term::iri(kNodeIri + "/rr/f")}).value().size(), 1u);
  // A stream not said to repeat anything keeps every such item.
  EXPECT_EQ(child.relay("child#third", {window(1, 1, 1000, "g")}).value().stored.size(), 1u);
}

// A relayed item is in the output buffer of the link agent that relayed it, though its source is
// the writer below. When retention takes the item, its entry must go from that buffer too: an
// entry left behind would name an item that is gone, and a ring-bounded node's buffers would grow
// for ever.
TEST(Relay, RetentionTakesARelayedItemOutOfTheRelayingAgentsOutputBuffer) {
  TempDir dir;
  Node node = make_node(dir.path(), {.ring = 10});
  Agent child = node.agent("child").value();
  const std::string source = kNodeIri + "/child/hrv";
  std::vector<RelayedItem> items;
  for (std::uint64_t seq = 1; seq <= 40; ++seq) items.push_back(relayed(seq, seq - 1, source, static_cast<int>(seq)));
  for (std::size_t first = 0; first < items.size(); first += 8) {
    std::vector<RelayedItem> run(items.begin() + first, items.begin() + first + 8);
    ASSERT_TRUE(child.relay("up", run).has_value());
  }
  auto written = child.written(0, 0).value();
  auto snapshot = node.snapshot().value();
  EXPECT_LE(written.size(), 10u);
  for (std::uint64_t id : written) EXPECT_FALSE(snapshot.item(id).value().empty()) << "item " << id << " is gone";
}

TEST(Relay, MarkSurvivesReopeningTheStore) {
  TempDir dir;
  {
    Node node = make_node(dir.path());
    ASSERT_TRUE(node.agent("child").value().relay("up", {relayed(3, 0, kNodeIri + "/child", 1)}));
  }
  Node node = Node::open(dir.path()).value();
  Agent child = node.agent("child").value();
  EXPECT_EQ(child.relay_mark("up").value(), 3u);
  EXPECT_EQ(child.relay("up", {relayed(3, 0, kNodeIri + "/child", 1)}).value().duplicates, 1u);
  EXPECT_EQ(node.stats().value().items, 1u);
}

TEST(Relay, AnItemFromAnotherLocalWriterIsRefusedAndTheStreamGoesOnPastIt) {
  TempDir dir;
  Node node = make_node(dir.path());
  Agent child = node.agent("child").value();
  auto outcome = child.relay("up", {relayed(1, 0, kNodeIri + "/child/hrv", 1),
                                    relayed(2, 1, kNodeIri + "/operator", 2),
                                    relayed(3, 2, kNodeIri + "/child/hrv", 3)}).value();
  EXPECT_EQ(outcome.stored.size(), 2u);
  EXPECT_EQ(outcome.mark, 3u);
  ASSERT_EQ(outcome.refused.size(), 1u);
  EXPECT_EQ(outcome.refused[0].seq, 2u);
  EXPECT_EQ(outcome.refused[0].why.code, Errc::invalid_argument);
  EXPECT_NE(outcome.refused[0].why.message.find("/operator"), std::string::npos);
  EXPECT_NE(outcome.refused[0].why.message.find("seq 2"), std::string::npos);
  auto records = node.snapshot().value().list({.p = ex("value")}).value();
  ASSERT_EQ(records.size(), 2u);
  for (const auto& r : records) EXPECT_EQ(r.meta.source, kNodeIri + "/child/hrv");
  // The handle remembers the sources it accepted, never one it refused.
  EXPECT_EQ(child.relay("up", {relayed(4, 3, kNodeIri + "/operator", 4)}).value().refused.size(), 1u);
  EXPECT_EQ(child.relay_mark("up").value(), 4u);
  // A writer above this node (relayed down from the parent) is accepted.
  EXPECT_TRUE(child.relay("down", {relayed(1, 0, "http://example.org/hospital-operator", 1)}).value().refused.empty());
}

// The sender's node may allow what this one does not (a larger literal limit): resending such
// an item could never succeed, so it is passed over and the items after it are stored.
TEST(Relay, AnItemThisNodeCanNeverStoreIsPassedOverNotRetriedForEver) {
  TempDir dir;
  Node node = Node::init(dir.path(), {.iri = kNodeIri, .max_literal_bytes = 100}).value();
  Agent child = node.agent("child").value();
  const std::string source = kNodeIri + "/child/hrv";
  RelayedItem too_large = relayed(2, 1, source, 2);
  too_large.item.add(Term::iri(kNodeIri + "/obs/2"), ex("note"), Term::literal(std::string(101, 'x')));
  // An IRI is checked when the dictionary first meets it, inside the write: that refusal
  // aborts the transaction, which then runs again without the item.
  RelayedItem bad_iri = relayed(4, 3, source, 4);
  bad_iri.item.add(Term::iri(kNodeIri + "/obs/4"), ex("seeAlso"), Term::iri("http://exa mple.org/x"));
  auto outcome = child.relay("up", {relayed(1, 0, source, 1), too_large, relayed(3, 2, source, 3), bad_iri,
                                    relayed(5, 4, source, 5)}).value();
  EXPECT_EQ(outcome.mark, 5u);
  EXPECT_EQ(outcome.stored.size(), 3u);
  ASSERT_EQ(outcome.refused.size(), 2u);
  EXPECT_EQ(outcome.refused[0].seq, 2u);
  EXPECT_EQ(outcome.refused[0].why.code, Errc::literal_too_large);
  EXPECT_EQ(outcome.refused[1].seq, 4u);
  EXPECT_EQ(outcome.refused[1].why.code, Errc::invalid_iri);
  EXPECT_EQ(node.stats().value().items, 3u);
  EXPECT_EQ(node.snapshot().value().list({.p = ex("seeAlso")}).value().size(), 0u);
  EXPECT_EQ(node.snapshot().value().list({.p = ex("note")}).value().size(), 0u);
  // Sent again (the sender did not hear the ack): duplicates, not refused again.
  auto again = child.relay("up", {too_large}).value();
  EXPECT_EQ(again.duplicates, 1u);
  EXPECT_TRUE(again.refused.empty());
}

}  // namespace
}  // namespace tahvel::node::testing
