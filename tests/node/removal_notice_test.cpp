// Removal notices (docs/record-model.md R21): an agent that asks for them gets, in its input
// buffer, the records removed from items that were routed to it, so that a link can take a
// removal where it sent the item; and a relayed notice removes the copies it names (R19).
#include <gtest/gtest.h>

#include "test_support.h"

namespace tahvel::node::testing {
namespace {

using namespace std::chrono_literals;

Item hrv_window(int n, std::int64_t at, std::string context = {}) {
  Item item;
  const Term window = Term::iri(kNodeIri + "/hrv/" + std::to_string(n));
  item.add(window, ex("property"), ex("HRV"));
  item.add(window, ex("rmssd"), Term::integer(40 + n));
  item.asserted_at = at;
  item.context = std::move(context);
  return item;
}

std::vector<Delivery> drain(Agent& agent) {
  std::vector<Delivery> out;
  while (auto d = agent.take(0ms).value()) out.push_back(std::move(*d));
  return out;
}

// The one delivery an agent has, which must be a removal notice; nothing, and a failure, else.
std::optional<Delivery> one_notice(Agent& agent) {
  auto got = drain(agent);
  if (got.size() != 1u || !got[0].removal) {
    ADD_FAILURE() << got.size() << " deliveries where one removal notice was wanted";
    return std::nullopt;
  }
  return std::move(got[0]);
}

RelayedItem notice_of(std::uint64_t seq, const std::string& source, Item item, std::vector<std::uint32_t> positions) {
  RelayedItem notice{seq, seq - 1, source, std::move(item)};
  notice.removal = true;
  notice.positions = std::move(positions);
  return notice;
}

// A gateway's store: agent `child` relays its child's items, agent `uplink` forwards HRV
// windows to its parent and receives removal notices, as the link sets them up.
struct Gateway {
  TempDir dir;
  Node node = make_node(dir.path());
  Agent child = node.agent("child").value();
  Agent uplink = node.agent("uplink").value();
  const std::string source = kNodeIri + "/child/hrv";
  std::uint64_t forwarding = uplink.subscribe({.p = ex("property"), .o = ex("HRV")}).value();  // the policy
  Gateway() { EXPECT_TRUE(uplink.receive_removals()); }
};

TEST(RemovalNotice, AnAgentThatAskedGetsTheRecordsRemovedFromAnItemRoutedToIt) {
  Gateway g;  // its uplink asked already
  Node& node = g.node;
  Agent& uplink = g.uplink;
  ASSERT_TRUE(uplink.receive_removals());  // asking again changes nothing
  Agent plain = node.agent("plain").value();  // subscribed alike, never asked
  ASSERT_TRUE(plain.subscribe({.p = ex("property"), .o = ex("HRV")}));
  Agent writer = node.agent("hrv").value();
  const std::uint64_t item = writer.store(hrv_window(1, 1'000)).value();
  ASSERT_EQ(drain(uplink).size(), 1u);
  ASSERT_EQ(drain(plain).size(), 1u);

  // The record removed is not the one the subscription matched: the item was routed by another.
  Pattern rmssd{.p = ex("rmssd")};
  ASSERT_EQ(node.remove(rmssd).value(), 1u);
  auto notices = drain(uplink);
  ASSERT_EQ(notices.size(), 1u);
  EXPECT_TRUE(notices[0].removal);
  EXPECT_GT(notices[0].item, item);
  ASSERT_EQ(notices[0].records.size(), 1u);
  const Record& removed = notices[0].records[0];
  EXPECT_EQ(removed.triple.p, ex("rmssd"));
  EXPECT_EQ(removed.triple.o, Term::integer(41));
  EXPECT_EQ(removed.meta.source, writer.iri());
  EXPECT_EQ(removed.meta.asserted_at, 1'000);
  EXPECT_EQ(removed.meta.item, item);
  // An agent that did not ask sees nothing of it.
  EXPECT_TRUE(drain(plain).empty());

  // The rest of the item, in one notice.
  ASSERT_EQ(node.remove_item(item).value(), 1u);
  notices = drain(uplink);
  ASSERT_EQ(notices.size(), 1u);
  EXPECT_EQ(notices[0].records.size(), 1u);
  EXPECT_EQ(notices[0].records[0].triple.p, ex("property"));
}

TEST(RemovalNotice, NothingIsNoticedForAnItemNeverRoutedToTheAgentNorForRetention) {
  TempDir dir;
  Node node = make_node(dir.path(), {.ring = 4});
  Agent uplink = node.agent("uplink").value();
  Agent writer = node.agent("ecg").value();
  ASSERT_TRUE(uplink.subscribe({.p = ex("property"), .o = ex("HRV")}));
  ASSERT_TRUE(uplink.receive_removals());
  Item raw;
  raw.add(Term::iri(kNodeIri + "/ecg/1"), ex("samples"), Term::literal("AAAA"));
  const std::uint64_t raw_id = writer.store(raw).value();
  ASSERT_TRUE(node.remove_item(raw_id));
  EXPECT_EQ(uplink.pending().value(), 0u);
  // The ring reclaims routed items once they have left the buffer: no notice (each node keeps
  // its own retention).
  for (int n = 0; n < 6; ++n) ASSERT_TRUE(writer.store(hrv_window(n, 1'000 + n)));
  ASSERT_EQ(drain(uplink).size(), 6u);
  for (int n = 6; n < 10; ++n) ASSERT_TRUE(writer.store(hrv_window(n, 1'000 + n)));
  EXPECT_GT(node.stats().value().reclaimed_records, 0u);
  for (const Delivery& d : drain(uplink)) EXPECT_FALSE(d.removal);
}

TEST(RemovalNotice, AReplaceNoticesTheOldRecordsBeforeTheNewItem) {
  Gateway g;
  Agent& uplink = g.uplink;
  Agent reasoner = g.node.agent("reasoner").value();
  ASSERT_TRUE(reasoner.store(hrv_window(1, 1'000)));
  drain(uplink);
  auto ids = reasoner.replace({Pattern{.s = Term::iri(kNodeIri + "/hrv/1")}}, {hrv_window(2, 2'000)}).value();
  auto got = drain(uplink);
  ASSERT_EQ(got.size(), 2u);
  EXPECT_TRUE(got[0].removal);
  EXPECT_EQ(got[0].records.size(), 2u);
  EXPECT_FALSE(got[1].removal);
  EXPECT_EQ(got[1].item, ids[0]);
}

TEST(RemovalNotice, TheAddresseeOfAnItemsContextIsNoticedWhenItAsked) {
  TempDir dir;
  Node node = make_node(dir.path());
  Agent child = node.agent("home1").value();  // a child's link agent: items addressed below it
  Agent operator_ = node.agent("operator").value();
  ASSERT_TRUE(child.receive_removals());
  const std::uint64_t setting = operator_.store(hrv_window(1, 5'000, kNodeIri + "/home1/hrv")).value();
  ASSERT_EQ(drain(child).size(), 1u);
  ASSERT_TRUE(node.remove_item(setting));
  auto got = one_notice(child);
  ASSERT_TRUE(got);
  EXPECT_EQ(got->records[0].meta.context, kNodeIri + "/home1/hrv");
}

// Two agents get one notice: the uplink (a link's window) and a second one that takes.
TEST(RemovalNotice, ANoticeLeavesTheStoreWithTheLastBufferThatHeldIt) {
  Gateway g;
  Node& node = g.node;
  Agent& a = g.uplink;
  Agent b = node.agent("b").value();
  ASSERT_TRUE(b.subscribe({.p = ex("rmssd")}));
  ASSERT_TRUE(b.receive_removals());
  Agent writer = node.agent("w").value();
  const std::uint64_t item = writer.store(hrv_window(1, 1)).value();
  ASSERT_TRUE(a.ack_through(item));
  ASSERT_TRUE(b.ack_through(item));
  ASSERT_TRUE(node.remove_item(item));
  // Peeked, then acknowledged through, by the uplink; taken by the other.
  auto peeked = a.peek(item, 10, 0ms).value();
  ASSERT_EQ(peeked.size(), 1u);
  EXPECT_TRUE(peeked[0].removal);
  EXPECT_EQ(a.ack_through(peeked[0].item).value(), 1u);
  EXPECT_EQ(a.pending().value(), 0u);
  // Still there for b.
  auto taken = b.take(0ms).value();
  ASSERT_TRUE(taken);
  EXPECT_TRUE(taken->removal);
  EXPECT_EQ(taken->records.size(), 2u);
  EXPECT_EQ(node.stats().value().pending_deliveries, 0u);
}

TEST(RemovalNotice, ARelayedNoticeRemovesTheCopiesOfThatSourceAndNoOthers) {
  TempDir dir;
  Node node = make_node(dir.path());
  Agent child = node.agent("child").value();
  const std::string source = kNodeIri + "/child/hrv";
  // Two copies from the child: windows 1 and 2; and the same triples written here by another
  // agent, and by the child's source at another time: neither is the copy named.
  auto relayed = child.relay("child#s", {{1, 0, source, hrv_window(1, 1'000)}, {2, 1, source, hrv_window(2, 2'000)},
                                         {3, 2, source, hrv_window(1, 3'000)}});
  ASSERT_TRUE(relayed.has_value()) << relayed.error().message;
  Agent local = node.agent("local").value();
  ASSERT_TRUE(local.store(hrv_window(1, 1'000)));
  Item removal = hrv_window(1, 1'000);
  removal.triples.pop_back();  // only the rmssd record was removed below
  removal.triples.erase(removal.triples.begin());
  removal.add(Term::iri(kNodeIri + "/hrv/1"), ex("rmssd"), Term::integer(41));
  const RelayedItem notice = notice_of(4, source, removal, {1});  // the rmssd record is its item's second
  auto applied = child.relay("child#s", {notice});
  ASSERT_TRUE(applied.has_value()) << applied.error().message;
  EXPECT_EQ(applied->mark, 4u);
  EXPECT_EQ(applied->removals, 1u);
  EXPECT_EQ(applied->records_removed, 1u);
  EXPECT_TRUE(applied->stored.empty());
  auto snap = node.snapshot().value();
  EXPECT_EQ(snap.count({.p = ex("rmssd"), .source = source}).value(), 2u);
  EXPECT_EQ(snap.count({.p = ex("rmssd"), .source = local.iri()}).value(), 1u);
  EXPECT_EQ(snap.count({.p = ex("rmssd"), .source = source, .since = 1'000, .until = 1'001}).value(), 0u);
  // Sent again (a resend): a duplicate, dropped by the mark; a notice of a copy no longer held
  // is no error.
  EXPECT_EQ(child.relay("child#s", {notice}).value().duplicates, 1u);
  auto none = child.relay("child#s", {notice_of(5, source, removal, {1})});
  ASSERT_TRUE(none.has_value());
  EXPECT_EQ(none->records_removed, 0u);
  EXPECT_EQ(none->mark, 5u);
}

// What a child's removal takes away from a gateway goes on to the gateway's parent.
TEST(RemovalNotice, ARelayedRemovalIsNoticedOnwardWhereTheCopyWent) {
  // Also when the gateway's policy was narrowed after the copy went up: the parent's copy is
  // still there to be removed.
  for (const bool narrowed : {false, true}) {
    SCOPED_TRACE(narrowed ? "the policy narrowed since" : "the policy as it was");
    Gateway g;
    auto& [dir, node, child, uplink, source, forwarding] = g;
    Item window = hrv_window(1, 1'000);
    window.span = 300;  // what the removed records held for goes on with them
    ASSERT_TRUE(child.relay("child#s", {{1, 0, source, window}}));
    ASSERT_EQ(drain(uplink).size(), 1u);
    if (narrowed) {
      ASSERT_TRUE(uplink.unsubscribe(forwarding));
      drain(uplink);
    }
    ASSERT_EQ(child.relay("child#s", {notice_of(2, source, window, {0, 1})}).value().records_removed, 2u);
    auto got = one_notice(uplink);
    ASSERT_TRUE(got);
    EXPECT_EQ(got->records.size(), 2u);
    EXPECT_EQ(got->records[0].meta.source, source);
    EXPECT_EQ(got->records[0].meta.span, 300);
  }
}

// An item and its notice in one run (a parent that was paused while both were sent): the
// notice removes the copy the same transaction stored.
TEST(RemovalNotice, ANoticeInTheSameRunAsItsItemRemovesTheCopyJustStored) {
  Gateway g;
  auto& [dir, node, child, uplink, source, forwarding] = g;
  auto applied = child.relay("child#s", {{1, 0, source, hrv_window(1, 1'000)}, notice_of(2, source, hrv_window(1, 1'000), {0, 1})});
  ASSERT_TRUE(applied.has_value()) << applied.error().message;
  EXPECT_EQ(applied->stored.size(), 1u);
  EXPECT_EQ(applied->records_removed, 2u);
  EXPECT_EQ(node.snapshot().value().count({.source = source}).value(), 0u);
}

// A gateway whose ring took its copy still passes the removal on: the hospital has one.
TEST(RemovalNotice, ARelayedNoticeGoesOnWhereNoCopyIsHeld) {
  Gateway g;
  auto& [dir, node, child, uplink, source, forwarding] = g;
  auto applied = child.relay("child#s", {notice_of(1, source, hrv_window(1, 1'000), {0, 1})});
  ASSERT_TRUE(applied.has_value()) << applied.error().message;
  EXPECT_EQ(applied->records_removed, 0u);
  auto got = one_notice(uplink);
  ASSERT_TRUE(got);
  ASSERT_EQ(got->records.size(), 2u);
  EXPECT_EQ(got->records[1].meta.id - got->records[1].meta.item, 1u);  // its position, kept
  EXPECT_EQ(got->records[0].meta.source, source);
  EXPECT_EQ(got->records[0].meta.asserted_at, 1'000);
  // A notice that matches nothing here is not passed on.
  Item other;
  other.add(Term::iri(kNodeIri + "/x"), ex("note"), Term::literal("n"));
  other.asserted_at = 5;
  ASSERT_TRUE(child.relay("child#s", {notice_of(2, source, other, {0})}));
  EXPECT_TRUE(drain(uplink).empty());
  // One position per triple, or the notice is refused.
  auto refused = child.relay("child#s", {notice_of(3, source, hrv_window(2, 2'000), {0})});
  ASSERT_TRUE(refused.has_value());
  ASSERT_EQ(refused->refused.size(), 1u);
  EXPECT_NE(refused->refused[0].why.message.find("position"), std::string::npos);
}

// Blank nodes are renamed on the way; a notice names records by their place in the item, so a
// removal of one blank node's records leaves another's with the same triples.
TEST(RemovalNotice, ARelayedNoticeRemovesTheRecordsOfOneBlankNodeAndNotAnothers) {
  TempDir dir;
  Node node = make_node(dir.path());
  Agent child = node.agent("child").value();
  const std::string source = kNodeIri + "/child/ward";
  Item two;
  two.add(Term::blank("o1"), ex("type"), ex("Observation")).add(Term::blank("o1"), ex("result"), Term::integer(72));
  two.add(Term::blank("o2"), ex("type"), ex("Observation")).add(Term::blank("o2"), ex("result"), Term::integer(80));
  two.asserted_at = 7;
  ASSERT_TRUE(child.relay("child#s", {{1, 0, source, two}}));
  Item gone;
  gone.add(Term::blank("b"), ex("type"), ex("Observation")).add(Term::blank("b"), ex("result"), Term::integer(72));
  gone.asserted_at = 7;
  EXPECT_EQ(child.relay("child#s", {notice_of(2, source, gone, {0, 1})}).value().records_removed, 2u);
  auto left = node.snapshot().value().list({.source = source}).value();
  ASSERT_EQ(left.size(), 2u);
  EXPECT_EQ(left[0].triple.p, ex("type"));
  EXPECT_EQ(left[1].triple.o, Term::integer(80));
  EXPECT_EQ(left[0].triple.s, left[1].triple.s);
}

// Items are addressed by their context in normal form; so are their notices.
TEST(RemovalNotice, AnItemAddressedByAContextNotInNormalFormIsNoticedToItsAddressee) {
  TempDir dir;
  Node node = make_node(dir.path());
  Agent child = node.agent("home1").value();
  Agent operator_ = node.agent("operator").value();
  ASSERT_TRUE(child.receive_removals());
  const std::string written = "http://EXAMPLE.org/home1/x/../home1/hrv";
  const std::uint64_t setting = operator_.store(hrv_window(1, 5'000, written)).value();
  ASSERT_EQ(drain(child).size(), 1u);
  ASSERT_TRUE(node.remove_item(setting));
  auto got = one_notice(child);
  ASSERT_TRUE(got);
}

// An operator pruning this node only (tahvel remove --local): the copies sent stay.
TEST(RemovalNotice, ARemovalOfThisNodeOnlyNoticesNobodyButIsInTheChangeStream) {
  Gateway g;
  Node& node = g.node;
  Agent& uplink = g.uplink;
  Agent writer = node.agent("hrv").value();
  const std::uint64_t one = writer.store(hrv_window(1, 1)).value();
  ASSERT_TRUE(writer.store(hrv_window(2, 2)));
  const std::uint64_t three = writer.store(hrv_window(3, 3)).value();
  drain(uplink);
  const std::uint64_t bookmark = node.snapshot().value().last_seq();
  EXPECT_EQ(node.remove_item(one, 0, Reach::this_node).value(), 2u);
  EXPECT_EQ(node.remove({.s = Term::iri(kNodeIri + "/hrv/2")}, 0, Reach::this_node).value(), 2u);
  EXPECT_EQ(node.remove_items({three}, Reach::this_node).value(), 2u);
  EXPECT_TRUE(drain(uplink).empty());
  EXPECT_EQ(node.watch(bookmark, 0ms).value().size(), 6u);  // watchers still see them go
}

// A forwarding policy narrowed after an item went up: the item's removal still reaches the
// agent that got it (its copy above is still there), and an item it never got is not noticed.
TEST(RemovalNotice, AnAgentWhosePolicyNarrowedAfterItGotAnItemIsStillNoticedOfItsRemoval) {
  TempDir dir;
  Node node = make_node(dir.path());
  Agent uplink = node.agent("uplink").value();
  Agent writer = node.agent("hrv").value();
  const std::uint64_t wide = uplink.subscribe({.p = ex("property"), .o = ex("HRV")}).value();
  ASSERT_TRUE(uplink.receive_removals());
  const std::uint64_t sent = writer.store(hrv_window(1, 1'000)).value();
  ASSERT_EQ(drain(uplink).size(), 1u);
  // Narrowed: from now on only windows with an rmssd of 99.
  ASSERT_TRUE(uplink.unsubscribe(wide));
  ASSERT_TRUE(uplink.subscribe({.p = ex("rmssd"), .o = Term::integer(99)}));
  const std::uint64_t kept = writer.store(hrv_window(2, 2'000)).value();
  drain(uplink);  // whatever the unsubscription itself noticed
  ASSERT_TRUE(node.remove_item(sent));
  ASSERT_TRUE(node.remove_item(kept));
  auto got = one_notice(uplink);
  ASSERT_TRUE(got);
  ASSERT_EQ(got->records.size(), 2u);
  EXPECT_EQ(got->records[0].meta.item, sent);
}

// `tahvel up` withdraws from the uplink what a narrowed policy no longer forwards: such an item's
// removal is not noticed there, for a notice carries its records up.
TEST(RemovalNotice, AnItemWithdrawnFromABufferByANarrowedPolicyIsNotNoticedThere) {
  Gateway g;
  auto& [dir, node, child, uplink, source, forwarding] = g;
  Agent writer = node.agent("hrv").value();
  const std::uint64_t queued = writer.store(hrv_window(1, 1'000)).value();
  ASSERT_EQ(uplink.pending().value(), 1u);
  ASSERT_TRUE(uplink.unsubscribe(forwarding));
  ASSERT_EQ(uplink.withdraw_unrouted().value(), 1u);
  drain(uplink);
  ASSERT_TRUE(node.remove_item(queued));
  EXPECT_TRUE(drain(uplink).empty());
}

TEST(RemovalNotice, AStoreMadeBeforeNoticesGetsTheirTableAtItsFirstOpen) {
  TempDir dir;
  { make_node(dir.path() / "n"); }
  // Drop the table, as a store made by an earlier build has none.
  ASSERT_TRUE(change_with_lmdb(dir.path() / "n", [](MDB_txn* txn) {
    MDB_dbi notices = 0;
    return mdb_dbi_open(txn, "notices", 0, &notices) == 0 && mdb_drop(txn, notices, 1) == 0;
  })) << "could not take the table away";
  auto node = Node::open(dir.path() / "n");
  ASSERT_TRUE(node.has_value()) << node.error().message;
  Agent uplink = node->agent("uplink").value();
  Agent writer = node->agent("w").value();
  ASSERT_TRUE(uplink.subscribe({.p = ex("rmssd")}));
  ASSERT_TRUE(uplink.receive_removals());
  const std::uint64_t item = writer.store(hrv_window(1, 1)).value();
  ASSERT_TRUE(node->remove_item(item));
  // The item left the buffer with the store; its notice took its place.
  auto got = uplink.take(0ms).value();
  ASSERT_TRUE(got);
  EXPECT_TRUE(got->removal);
  EXPECT_EQ(uplink.pending().value(), 0u);
}

}  // namespace
}  // namespace tahvel::node::testing
