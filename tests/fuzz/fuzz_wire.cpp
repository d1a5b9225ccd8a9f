// Fuzz target: the link's wire formats, which arrive from other machines (docs/protocol.md P4,
// P17): the frame envelope of the byte-oriented bindings and the bodies of items, queries,
// answers, errors and states. The first byte picks the decoder, the rest is its input.
// Properties checked: no crash or sanitizer report; a refusal is a syntax error that names the
// body (or the frame field) and a byte offset; what decodes encodes to bytes that decode again
// and encode to the same bytes (nothing is lost or invented on the way through a node).
#include <cstdint>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "tahvel/federation/transport.h"
#include "tahvel/federation/wire.h"
#include "require.h"

using namespace tahvel;
using namespace tahvel::federation;

namespace {

template <class Decode, class Encode>
void round_trip(std::string_view bytes, Decode decode, Encode encode) {
  auto first = decode(bytes);
  if (!first) {
    REQUIRE(first.error().code == node::Errc::syntax);
    REQUIRE(first.error().message.find("byte") != std::string::npos);
    return;
  }
  const std::string encoded = encode(*first);
  auto second = decode(encoded);
  REQUIRE(second.has_value());
  REQUIRE(encode(*second) == encoded);
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size == 0) return 0;
  const std::string_view bytes(reinterpret_cast<const char*>(data) + 1, size - 1);
  // An answer in each version a parent hears (P3).
  const auto answer_in = [](std::uint16_t version) {
    return std::pair{[version](std::string_view b) { return wire::decode_answer(b, version); },
                     [version](const wire::AnswerBody& a) { return wire::encode_answer(a, version); }};
  };
  // A query in each layout (P3): version 4 added source and under.
  const auto query_in = [](std::uint16_t version) {
    return std::pair{[version](std::string_view b) { return wire::decode_query(b, version); },
                     [version](const wire::QueryBody& q) { return wire::encode_query(q, version).value(); }};
  };
  switch (data[0] % 8) {
    case 0: round_trip(bytes, wire::decode_item, wire::encode_item); break;
    case 1: {
      auto [decode, encode] = query_in(kProtocolVersion);
      round_trip(bytes, decode, encode);
      break;
    }
    case 7: {
      auto [decode, encode] = query_in(3);
      round_trip(bytes, decode, encode);
      break;
    }
    case 2: {
      auto [decode, encode] = answer_in(kProtocolVersion);
      round_trip(bytes, decode, encode);
      break;
    }
    case 6: {
      auto [decode, encode] = answer_in(kOldestProtocolVersion);
      round_trip(bytes, decode, encode);
      break;
    }
    case 3: round_trip(bytes, wire::decode_error, wire::encode_error); break;
    case 4: {  // version 5 added a child's store room; the next bit picks the version before
      const std::uint16_t version = (data[0] / 8) % 2 ? kProtocolVersion - 1 : kProtocolVersion;
      round_trip(bytes, [version](std::string_view b) { return wire::decode_state(b, version); }, wire::encode_state);
      break;
    }
    default: {
      auto frame = decode_frame(bytes);
      if (!frame) {
        REQUIRE(!frame.error().message.empty());
        return 0;
      }
      const std::string encoded = encode_frame(*frame);
      auto again = decode_frame(encoded);
      REQUIRE(again.has_value() && encode_frame(*again) == encoded);
      (void)frame_refusal(*frame, "http://example.org/hospital");
    }
  }
  return 0;
}

std::vector<std::string> fuzz_seeds() {
  using node::Term;
  wire::ItemBody item;
  item.source = "http://example.org/hospital/home1/hrv";
  item.item.context = "http://example.org/hospital/home1";
  item.item.asserted_at = 1'795'333'242'856'028'883;
  item.item.add(Term::iri("http://example.org/hospital/home1/rec/hrv/0"), Term::iri("https://w3id.org/tahvel#rmssdMs"),
                Term::literal("29.6", "http://www.w3.org/2001/XMLSchema#decimal"));
  item.item.add(Term::blank("b1"), Term::iri("http://www.w3.org/2000/01/rdf-schema#label"), Term::lang_literal("kodu", "et"));
  wire::QueryBody query;
  query.origin = "http://example.org/hospital";
  query.target = "http://example.org/hospital/home2";
  query.p = Term::iri("https://w3id.org/tahvel#samples");
  query.since = 1;
  query.until = 2;
  query.cascade = 1;
  query.limit = 10;
  query.area = "POLYGON((0 0, 1 0, 1 1, 0 0))";
  query.floor = 0;
  wire::QueryBody by_subject = query;
  by_subject.source = "http://example.org/hospital/home1/ecg1";
  by_subject.under = "http://example.org/hospital/home1/ecg1/source/recording/100";
  wire::AnswerBody answer;
  answer.origin = "http://example.org/hospital";
  answer.last = true;
  node::Record record;
  record.triple = item.item.triples[0];
  record.meta.id = 7;
  record.meta.source = item.source;
  answer.records.push_back(record);
  Frame frame;
  frame.kind = FrameKind::up;
  frame.from = "http://example.org/hospital/home1";
  frame.to = "http://example.org/hospital";
  frame.seq = 12;
  frame.prev = 11;
  frame.body = wire::encode_item(item);
  auto with = [](char selector, std::string body) { return std::string(1, selector) + body; };
  return {with(0, wire::encode_item(item)),
          with(1, wire::encode_query(query).value()),
          with(7, wire::encode_query(query, 3).value()),
          with(1, wire::encode_query(by_subject).value()),
          with(2, wire::encode_answer(answer)),
          with(3, wire::encode_error({"item_refused", "literal of 300 bytes exceeds the node's limit of 200", ""})),
          with(4, wire::encode_state({"0.1.0", 3})),
          with(4, wire::encode_state({"0.1.0", 3, "5f0c8e3b27a14d9c9b2f6a1e0d4c7b38", "a9e1f04d3c2b1a09e8d7c6b5a4938271"})),
          with(5, encode_frame(frame))};
}
