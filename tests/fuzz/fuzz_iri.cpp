// Fuzz target: the IRI parser and everything built on it. Properties checked: no crash or
// sanitizer report; normalisation is idempotent and yields a valid IRI; what is_under accepts
// as a child is under its parent.
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "tahvel/uri/iri.h"
#include "require.h"

using namespace tahvel::uri;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  std::string_view text(reinterpret_cast<const char*>(data), size);
  if (auto n = normalize(text)) {
    REQUIRE(is_valid(*n));
    auto again = normalize(*n);
    REQUIRE(again && *again == *n);
    REQUIRE(is_under(*n, *n));
  } else {
    REQUIRE(n.error().position <= size);
  }
  (void)resolve("http://example.org/a/b?q#f", text);
  if (auto agent = agent_iri("http://example.org/home1", text)) {
    REQUIRE(is_under(*agent, "http://example.org/home1"));
    auto id = child_id(*agent, "http://example.org/home1");
    REQUIRE(id.has_value());
  }
  static const PrefixMap prefixes = PrefixMap::standard();
  if (auto expanded = prefixes.expand(text)) (void)prefixes.compact(*expanded);
  return 0;
}

std::vector<std::string> fuzz_seeds() {
  return {"http://example.org/home1/ecg",
          "HTTP://Example.ORG:80/a/./b/../c?x=%7e#frag",
          "urn:uuid:f81d4fae-7dec-11d0-a765-00a0c91e6bf6",
          "http://h/%C3%A9/\xC3\xA9",
          "sosa:Observation",
          "<http://x/y>",
          "ecg-1",
          "../up/./here"};
}
