// Fuzz target: N-Triples and Turtle input through serd. Properties checked: no crash or
// sanitizer report; errors name a line and column; whatever parses writes out as N-Triples that
// parses again to as many triples.
#include <cstdint>
#include <sstream>
#include <string>
#include <string_view>
#include <vector>

#include "tahvel/node/format.h"
#include "require.h"

using namespace tahvel::node;

namespace {

void check(std::string_view text, Format format) {
  ParseOptions options;
  options.format = format;
  options.base_iri = "http://example.org/base/";
  options.source_name = "fuzz";
  auto triples = parse_rdf(text, options);
  if (!triples) {
    REQUIRE(triples.error().code == Errc::syntax || triples.error().code == Errc::invalid_iri);
    REQUIRE(triples.error().message.rfind("fuzz:", 0) == 0);
    return;
  }
  std::ostringstream out;
  {
    RecordWriter writer(out, Format::ntriples);
    for (const Triple& t : *triples) writer.write(t);
  }
  ParseOptions again;
  again.format = Format::ntriples;
  auto reparsed = parse_rdf(out.str(), again);
  REQUIRE(reparsed && reparsed->size() == triples->size());
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  std::string_view text(reinterpret_cast<const char*>(data), size);
  check(text, Format::ntriples);
  check(text, Format::turtle);
  return 0;
}

std::vector<std::string> fuzz_seeds() {
  return {
      "<http://x/a> <http://x/p> \"72\"^^<http://www.w3.org/2001/XMLSchema#integer> .\n"
      "_:b1 <http://x/p> \"s\\u00e9\\n\"@et .\n",
      "@prefix sosa: <http://www.w3.org/ns/sosa/> .\n@prefix ex: <http://example.org/> .\n"
      "ex:o a sosa:Observation ; sosa:hasSimpleResult 72.5 ; ex:tags ( \"a\" \"b\" ) ;\n"
      "  ex:by [ ex:model \"\"\"ECG\n1\"\"\" ] .\n",
      "<rel> <p> <o> .\n",
      "@base <http://e.org/> . <a> <b> true , false , 1e3 .\n"};
}
