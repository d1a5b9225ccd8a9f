// The bodies (docs/protocol.md, "Bodies"): what an up or down frame carries, a removal notice
// (P7a) told from an item by its flags; an answer's records; a query in each version's layout.
#include <gtest/gtest.h>

#include "tahvel/federation/wire.h"

namespace tahvel::federation {
namespace {

using node::Term;

wire::ItemBody window(bool persistent, bool removal) {
  wire::ItemBody body;
  body.source = "http://example.org/hospital/home1/hrv";
  body.item.context = "http://example.org/hospital/home1/*";
  body.item.asserted_at = 1'700'000'000'000'000'000;
  body.item.persistent = persistent;
  body.item.add(Term::iri("http://example.org/w/1"), Term::iri("http://example.org/ns#rmssd"), Term::integer(42));
  body.removal = removal;
  return body;
}

TEST(ItemBody, PersistenceAndRemovalSurviveTheWireInEveryCombination) {
  for (bool persistent : {false, true})
    for (bool removal : {false, true}) {
      auto decoded = wire::decode_item(wire::encode_item(window(persistent, removal)));
      ASSERT_TRUE(decoded) << decoded.error().message;
      EXPECT_EQ(decoded->item.persistent, persistent);
      EXPECT_EQ(decoded->removal, removal);
      EXPECT_EQ(decoded->source, "http://example.org/hospital/home1/hrv");
      EXPECT_EQ(decoded->item.asserted_at, 1'700'000'000'000'000'000);
      ASSERT_EQ(decoded->item.triples.size(), 1u);
      EXPECT_EQ(decoded->item.triples[0].o, Term::integer(42));
    }
}

TEST(ItemBody, ANoticeCarriesEachTriplesPositionInItsItem) {
  wire::ItemBody notice = window(false, true);
  notice.item.add(Term::blank("b"), Term::iri("http://example.org/ns#n"), Term::integer(7));
  notice.positions = {3, 9};
  auto decoded = wire::decode_item(wire::encode_item(notice));
  ASSERT_TRUE(decoded) << decoded.error().message;
  EXPECT_EQ(decoded->positions, (std::vector<std::uint32_t>{3, 9}));
  // An item carries none; a notice cut short of its positions is refused.
  EXPECT_TRUE(wire::decode_item(wire::encode_item(window(false, false)))->positions.empty());
  std::string bytes = wire::encode_item(notice);
  bytes.resize(bytes.size() - 2);
  auto cut = wire::decode_item(bytes);
  ASSERT_FALSE(cut);
  EXPECT_NE(cut.error().message.find("'position'"), std::string::npos) << cut.error().message;
}

TEST(ItemBody, AFlagThisBuildDoesNotKnowIsRefusedNamingTheField) {
  std::string bytes = wire::encode_item(window(false, false));
  // The flags byte follows the source and the context (u32 length + bytes each).
  const std::size_t at = 4 + std::string("http://example.org/hospital/home1/hrv").size() + 4 +
                         std::string("http://example.org/hospital/home1/*").size();
  ASSERT_EQ(bytes[at], 0);
  bytes[at] = 8;
  auto decoded = wire::decode_item(bytes);
  ASSERT_FALSE(decoded);
  EXPECT_NE(decoded.error().message.find("'flags'"), std::string::npos) << decoded.error().message;
  EXPECT_NE(decoded.error().message.find("unknown flag bits 8"), std::string::npos) << decoded.error().message;
}

// A chunk of signal goes up (or answers a query) with the time it covers, so that the parent's
// copy is in the same time ranges as the child's.
TEST(ItemBody, AnItemsSpanSurvivesTheWireAndAnInstantIsEncodedAsBefore) {
  wire::ItemBody chunk = window(false, false);
  chunk.item.span = 1'000'000'000;
  auto decoded = wire::decode_item(wire::encode_item(chunk));
  ASSERT_TRUE(decoded) << decoded.error().message;
  EXPECT_EQ(decoded->item.span, 1'000'000'000);
  EXPECT_EQ(decoded->item.asserted_at, 1'700'000'000'000'000'000);
  // An instant sets no flag and carries no span: 8 bytes less.
  EXPECT_EQ(wire::encode_item(window(false, false)).size() + 8, wire::encode_item(chunk).size());
  EXPECT_EQ(wire::decode_item(wire::encode_item(window(false, false)))->item.span, 0);
  // A span that is not positive is a malformed body, refused naming its field.
  chunk.item.span = -3;
  auto negative = wire::decode_item(wire::encode_item(chunk));
  ASSERT_FALSE(negative);
  EXPECT_NE(negative.error().message.find("'span'"), std::string::npos) << negative.error().message;
}

TEST(AnswerBody, EachRecordsSpanSurvivesTheWire) {
  wire::AnswerBody answer;
  answer.origin = "http://example.org/hospital";
  node::Record chunk, instant;
  chunk.triple = {Term::iri("http://example.org/c/0"), Term::iri("http://example.org/ns#samples"), Term::literal("AAA=")};
  chunk.meta.asserted_at = 1'700'000'000'000'000'000;
  chunk.meta.span = 2'777'778;
  instant.triple = {Term::iri("http://example.org/w/1"), Term::iri("http://example.org/ns#rmssd"), Term::integer(42)};
  answer.records = {chunk, instant};
  auto decoded = wire::decode_answer(wire::encode_answer(answer));
  ASSERT_TRUE(decoded) << decoded.error().message;
  ASSERT_EQ(decoded->records.size(), 2u);
  EXPECT_EQ(decoded->records[0].meta.span, 2'777'778);
  EXPECT_EQ(decoded->records[0].meta.asserted_at, 1'700'000'000'000'000'000);
  EXPECT_EQ(decoded->records[1].meta.span, 0);
  answer.records[0].meta.span = -1;
  auto negative = wire::decode_answer(wire::encode_answer(answer));
  ASSERT_FALSE(negative);
  EXPECT_NE(negative.error().message.find("'span'"), std::string::npos) << negative.error().message;
}

// Version 4 added a query's source and subject (--source, --under) at the end of its body: a
// body of version 3 reads as before, and a query with either cannot be put in version 3's
// layout (the link then tells the asker, P3).
TEST(QueryBody, SourceAndUnderSurviveVersion4AndVersion3HasNeither) {
  wire::QueryBody query;
  query.origin = "http://example.org/hospital";
  query.target = "http://example.org/hospital/home1";
  query.p = Term::iri("https://w3id.org/tahvel#samples");
  query.since = 5;
  query.source = "http://example.org/hospital/home1/ecg1";
  query.under = "http://example.org/hospital/home1/ecg1/source/recording/100";
  auto decoded = wire::decode_query(wire::encode_query(query).value());
  ASSERT_TRUE(decoded) << decoded.error().message;
  EXPECT_EQ(decoded->source, query.source);
  EXPECT_EQ(decoded->under, query.under);
  EXPECT_EQ(decoded->since, 5);
  auto in_version_3 = wire::encode_query(query, 3);
  ASSERT_FALSE(in_version_3);
  EXPECT_NE(in_version_3.error().message.find("protocol version 4"), std::string::npos) << in_version_3.error().message;
  query.source.clear();
  query.under.clear();
  const std::string old = wire::encode_query(query, 3).value();
  EXPECT_EQ(old.size() + 8, wire::encode_query(query).value().size()) << "two empty strings more";
  ASSERT_TRUE(wire::decode_query(old, 3));
  EXPECT_FALSE(wire::decode_query(old)) << "a version 3 body read as version 4 is short";
  EXPECT_FALSE(wire::decode_query(wire::encode_query(query).value(), 3)) << "trailing bytes";
}

// P12: a child's hello and heartbeat say how full its store is, from version 5; a body of an
// earlier version with those bytes is malformed, and one without them has no room.
TEST(StateBody, AStoresRoomSurvivesVersion5AndAnEarlierVersionHasNone) {
  wire::StateBody state{"tahvel 0.1.0", 7, std::string(32, 'a'), "", wire::StoreRoom{19398656, 17891328, 20000000, 51234816}};
  auto decoded = wire::decode_state(wire::encode_state(state));
  ASSERT_TRUE(decoded) << decoded.error().message;
  ASSERT_TRUE(decoded->room);
  EXPECT_EQ(*decoded->room, *state.room);
  EXPECT_EQ(decoded->store_id, state.store_id);
  EXPECT_EQ(decoded->outbox_depth, 7u);
  auto in_version_4 = wire::decode_state(wire::encode_state(state), 4);
  ASSERT_FALSE(in_version_4);
  EXPECT_NE(in_version_4.error().message.find("stray bytes"), std::string::npos) << in_version_4.error().message;
  // Without a store id (a peer of before store ids would send none) the room still has its place.
  state.store_id.clear();
  ASSERT_TRUE(wire::decode_state(wire::encode_state(state)).value().room);
  state.room.reset();
  EXPECT_FALSE(wire::decode_state(wire::encode_state(state)).value().room);
  state.store_id = std::string(32, 'b');
  EXPECT_FALSE(wire::decode_state(wire::encode_state(state)).value().room);
  EXPECT_TRUE(wire::decode_state(wire::encode_state(state), 4)) << "a version 4 body reads as before";
  // Cut short inside the room: malformed, naming the field.
  state.room = wire::StoreRoom{1, 2, 3, 4};
  std::string bytes = wire::encode_state(state);
  bytes.resize(bytes.size() - 4);
  auto cut = wire::decode_state(bytes);
  ASSERT_FALSE(cut);
  EXPECT_NE(cut.error().message.find("disk_free_bytes"), std::string::npos) << cut.error().message;
}

}  // namespace
}  // namespace tahvel::federation
