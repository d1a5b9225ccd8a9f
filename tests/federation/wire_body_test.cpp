// The item body (docs/protocol.md, "Bodies"): what an up or down frame carries, a removal notice
// (P7a) told from an item by its flags.
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
  bytes[at] = 4;
  auto decoded = wire::decode_item(bytes);
  ASSERT_FALSE(decoded);
  EXPECT_NE(decoded.error().message.find("'flags'"), std::string::npos) << decoded.error().message;
  EXPECT_NE(decoded.error().message.find("unknown flag bits 4"), std::string::npos) << decoded.error().message;
}

}  // namespace
}  // namespace tahvel::federation
