// Unit tests of tahvel/uri/iri.h: RFC 3986 §6 normalisation, §5.4 resolution examples, RFC 3987
// (UTF-8) IRIs, ids, agent and child IRIs, the "is under" test that routing and authorisation
// rely on, and CURIE expansion. Each test names the behaviour it checks.
#include "tahvel/uri/iri.h"
#include "tahvel/uri/spelling.h"
#include "tahvel/uri/unicode_escape.h"

#include <gtest/gtest.h>

#include <random>
#include <string>
#include <utility>
#include <vector>

namespace tahvel::uri {
namespace {

// The value of a result that must succeed, or a failure showing the error.
template <class T>
T ok(const IriResult<T>& result) {
  EXPECT_TRUE(result.has_value()) << (result.has_value() ? "" : result.error().message);
  return result.has_value() ? result.value() : T{};
}

// The error of a result that must fail.
template <class T>
IriError err(const IriResult<T>& result) {
  EXPECT_FALSE(result.has_value()) << "unexpected success: " << (result ? result.value() : "");
  return result.has_value() ? IriError{"", 0} : result.error();
}

bool contains(const std::string& text, const std::string& part) {
  return text.find(part) != std::string::npos;
}

// --- normalize: RFC 3986 §6.2.2 -------------------------------------------------------------

TEST(Iri, NormalizeLowercasesSchemeAndHost) {
  EXPECT_EQ(ok(normalize("HTTP://Example.COM/Path/File")), "http://example.com/Path/File");
}

TEST(Iri, NormalizeKeepsCaseOfPathQueryAndFragment) {
  EXPECT_EQ(ok(normalize("http://h/A/b?Q=V#Frag")), "http://h/A/b?Q=V#Frag");
}

TEST(Iri, NormalizeUppercasesPercentEncodingHexDigits) {
  EXPECT_EQ(ok(normalize("http://h/a%2fb%3f%c3%a9")), "http://h/a%2Fb%3F%C3%A9");
}

TEST(Iri, NormalizeUppercasesPercentEncodingHexDigitsInHost) {
  EXPECT_EQ(ok(normalize("http://%c3%89X.com/")), "http://%C3%89x.com/");
}

TEST(Iri, NormalizeDecodesPercentEncodedUnreservedCharacters) {
  EXPECT_EQ(ok(normalize("http://%41b.com/%7Euser/%41%2D%5F%2E%30")), "http://ab.com/~user/A-_.0");
}

TEST(Iri, NormalizeKeepsPercentEncodedReservedCharacters) {
  EXPECT_EQ(ok(normalize("http://h/a%2Fb%3Fc%23d%25")), "http://h/a%2Fb%3Fc%23d%25");
}

TEST(Iri, NormalizeRemovesDotSegments) {
  EXPECT_EQ(ok(normalize("http://a/b/c/./../../g")), "http://a/g");
  EXPECT_EQ(ok(normalize("http://a/b/./c/.")), "http://a/b/c/");
  EXPECT_EQ(ok(normalize("http://a/b/../../../c")), "http://a/c");
}

TEST(Iri, NormalizeRemovesPercentEncodedDotSegments) {
  EXPECT_EQ(ok(normalize("http://h/home1/%2E%2E/home2")), "http://h/home2");
  EXPECT_EQ(ok(normalize("http://h/home1/%2e/x")), "http://h/home1/x");
}

TEST(Iri, NormalizeKeepsDotsInQuery) {
  EXPECT_EQ(ok(normalize("http://h/a?b=../c")), "http://h/a?b=../c");
}

TEST(Iri, NormalizeAcceptsUrnAndLowercasesOnlyItsScheme) {
  EXPECT_EQ(ok(normalize("URN:Ex:A")), "urn:Ex:A");
}

// RFC 3986 §6.2.3: a node written "http://h:80/x" in one place and "http://h/x" in another was
// two nodes (a query --at the one missed the other: "unknown node").
TEST(Iri, NormalizeDropsTheSchemesDefaultPortAndAnEmptyOne) {
  EXPECT_EQ(ok(normalize("http://h:80/x")), "http://h/x");
  EXPECT_EQ(ok(normalize("HTTPS://H:443/x")), "https://h/x");
  EXPECT_EQ(ok(normalize("http://h:080/x")), "http://h/x");
  EXPECT_EQ(ok(normalize("http://h:/x")), "http://h/x");
  EXPECT_EQ(ok(normalize("http://user@h:80")), "http://user@h");
  EXPECT_EQ(ok(normalize("http://[::1]:80/x")), "http://[::1]/x");
  EXPECT_EQ(ok(normalize("http://hé.example:80/é")), "http://hé.example/é");
  EXPECT_EQ(ok(normalize("http://h:8080/x")), "http://h:8080/x");
  EXPECT_EQ(ok(normalize("https://h:80/x")), "https://h:80/x");
  EXPECT_EQ(ok(normalize("coap://h:5683/x")), "coap://h:5683/x");
  EXPECT_TRUE(is_under("http://h:80/home1/ecg", "http://h/home1"));
  EXPECT_EQ(ok(child_node_iri("http://h:80/hospital", "home1")), "http://h/hospital/home1");
  EXPECT_EQ(ok(node_iri("http://h:80/hospital")), "http://h/hospital");
}

TEST(Iri, NormalizeIsIdempotent) {
  for (const char* text : {"HTTP://H/a/./b/../%7e%c3%a9", "http://h/é/%c3%a9/%25", "urn:x:y#z",
                           "http://%c3%89x.com/?q=%2f", "http://[::1]/a"}) {
    SCOPED_TRACE(text);
    std::string once = ok(normalize(text));
    EXPECT_EQ(ok(normalize(once)), once);
  }
}

// uriparser writes IPv6 hosts in full; a node made as http://[::1]:8080/ward then had the IRI
// http://[0000:...:0001]:8080/ward while its records kept [::1], so they were not under it.
TEST(Iri, NormalizeKeepsAnIpv6HostAsWrittenInLowerCase) {
  EXPECT_EQ(ok(normalize("http://[::1]:8080/ward/./x")), "http://[::1]:8080/ward/x");
  EXPECT_EQ(ok(normalize("HTTP://[FE80::A]/b")), "http://[fe80::a]/b");
  EXPECT_EQ(ok(resolve("http://[::1]/ward/", "bed")), "http://[::1]/ward/bed");
  EXPECT_TRUE(is_under(ok(normalize("http://[::1]/ward/bed")), "http://[::1]/ward"));
}

TEST(Iri, NormalizeNeverTurnsPathIntoAuthority) {
  // Without "/." the path "//evil/x" would read back as the host "evil" (RFC 3986 §3.3).
  EXPECT_EQ(ok(normalize("http:/.//evil/x")), "http:/.//evil/x");
  EXPECT_EQ(ok(normalize("urn:/a/..//b")), "urn:/.//b");
  EXPECT_FALSE(is_under("http:/.//evil/x", "http://evil"));
  EXPECT_EQ(ok(normalize("file:///a/./b")), "file:///a/b");  // an empty authority stays
}

TEST(Iri, NormalizeIsIdempotentOnGeneratedIris) {
  // Differential check against normalize itself: the normal form is a fixed point. Pieces are
  // chosen to meet the tricky paths: dot segments, triplets, UTF-8, empty segments, '//'.
  const std::vector<std::string> pieces = {"/", ".",   "..", "%25",  "%c3%a9", "%2e", "%41",
                                           "é", "?",   "#",  ":",    "@",      "a",   "Z",
                                           "~", "%2F", "ü",  "/../", "/./",    "//",  "%7e"};
  std::mt19937 random(20240501);  // fixed seed: the same cases on every run
  int checked = 0;
  for (int i = 0; i < 20000; ++i) {
    std::string text = i % 3 == 0 ? "urn:" : i % 3 == 1 ? "http://H" : "x:";
    for (std::size_t n = random() % 8; n > 0; --n) text += pieces[random() % pieces.size()];
    auto once = normalize(text);
    if (!once) continue;
    ++checked;
    auto twice = normalize(*once);
    ASSERT_TRUE(twice.has_value()) << text << " -> " << *once << ": " << twice.error().message;
    ASSERT_EQ(*twice, *once) << text;
  }
  EXPECT_GT(checked, 1000);
}

// --- normalize: RFC 3987 (UTF-8) ------------------------------------------------------------

TEST(Iri, NormalizeKeepsUtf8CharactersAsIs) {
  EXPECT_EQ(ok(normalize("http://h/é/ü?q=ä#fragmént")), "http://h/é/ü?q=ä#fragmént");
}

TEST(Iri, NormalizeOfUtf8IriStillNormalisesAsciiParts) {
  EXPECT_EQ(ok(normalize("HTTP://H/München/./x/../%7Ey")), "http://h/München/~y");
}

TEST(Iri, NormalizeLowercasesOnlyAsciiLettersOfUtf8Host) {
  EXPECT_EQ(ok(normalize("http://ÉXAMPLE.com/é")), "http://Éxample.com/é");
}

TEST(Iri, NormalizeKeepsPercentEncodedUtf8DistinctFromRawUtf8) {
  // RDF compares IRIs as strings: "%C3%A9" and "é" are different IRIs, so neither is rewritten.
  EXPECT_EQ(ok(normalize("http://h/é/%c3%a9")), "http://h/é/%C3%A9");
}

TEST(Iri, NormalizeKeepsLiteralPercent25NextToUtf8) {
  EXPECT_EQ(ok(normalize("http://h/é/%25/%2541/%25c3")), "http://h/é/%25/%2541/%25c3");
}

TEST(Iri, NormalizeKeepsFourByteUtf8Characters) {
  EXPECT_EQ(ok(normalize("http://h/\xF0\x9F\x98\x80")), "http://h/\xF0\x9F\x98\x80");
}

// --- normalize: errors ----------------------------------------------------------------------

TEST(Iri, InvalidIriErrorNamesInputPositionAndCause) {
  IriError e = err(normalize("http://a b"));
  EXPECT_EQ(e.message, "invalid IRI 'http://a b' at position 8: unexpected character ' '");
  EXPECT_EQ(e.position, 8u);
}

TEST(Iri, InvalidIriErrorPositionCountsUtf8Bytes) {
  IriError e = err(normalize("http://h/é é"));
  EXPECT_EQ(e.position, 11u);
  EXPECT_TRUE(contains(e.message, "at position 11")) << e.message;
}

TEST(Iri, InvalidIriErrorIsOneLineForControlCharacters) {
  IriError e = err(normalize("http://h/a\nb"));
  EXPECT_EQ(e.position, 10u);
  EXPECT_FALSE(contains(e.message, "\n")) << e.message;
  EXPECT_TRUE(contains(e.message, "0x0A")) << e.message;
}

TEST(Iri, NormalizeRejectsRelativeReferenceForLackOfScheme) {
  IriError e = err(normalize("rel/path"));
  EXPECT_EQ(e.position, 0u);
  EXPECT_TRUE(contains(e.message, "no scheme")) << e.message;
}

TEST(Iri, NormalizeRejectsEmptyText) { EXPECT_EQ(err(normalize("")).position, 0u); }

TEST(Iri, InvalidPercentEncodingErrorPointsAtPercentSign) {
  IriError e = err(normalize("http://h/a%zz"));
  EXPECT_EQ(e.position, 10u);
  EXPECT_TRUE(contains(e.message, "invalid percent-encoding '%zz'")) << e.message;
  EXPECT_EQ(err(normalize("http://h/%4")).position, 9u);
}

TEST(Iri, UnterminatedIpLiteralIsUnexpectedEndOfInput) {
  IriError e = err(normalize("http://[::1"));
  EXPECT_EQ(e.position, 11u);
  EXPECT_TRUE(contains(e.message, "unexpected end of input")) << e.message;
}

TEST(Iri, MalformedUtf8IsRejectedAtItsFirstByte) {
  IriError e = err(normalize("http://h/a\xFF"));
  EXPECT_EQ(e.position, 10u);
  EXPECT_TRUE(contains(e.message, "invalid UTF-8 byte 0xFF")) << e.message;
  EXPECT_EQ(err(normalize("http://h/\xC3")).position, 9u);          // truncated sequence
  EXPECT_EQ(err(normalize("http://h/\xC0\xAF")).position, 9u);      // overlong '/'
  EXPECT_EQ(err(normalize("http://h/\xED\xA0\x80")).position, 9u);  // surrogate
}

TEST(Iri, NonAsciiCharacterOutsideRfc3987IsRejected) {
  IriError e = err(normalize("http://h/\xC2\x85"));  // U+0085, a C1 control
  EXPECT_EQ(e.position, 9u);
  EXPECT_TRUE(contains(e.message, "U+0085")) << e.message;
}

TEST(Iri, NonAsciiCharacterInSchemeIsRejected) {
  // "hé" cannot be a scheme, so uriparser reads a relative path and stops at the ':'.
  IriError e = err(normalize("hé:x"));
  EXPECT_EQ(e.position, 3u);
  EXPECT_FALSE(is_valid("hé:x"));
}

TEST(Iri, IsValidAcceptsAbsoluteIrisOnly) {
  EXPECT_TRUE(is_valid("http://h/a"));
  EXPECT_TRUE(is_valid("urn:a:b"));
  EXPECT_TRUE(is_valid("http://h/é"));
  EXPECT_FALSE(is_valid("/a/b"));
  EXPECT_FALSE(is_valid(""));
  EXPECT_FALSE(is_valid("http://a b"));
  EXPECT_FALSE(is_valid("http://h/\xFF"));
}

// is_valid remembers prefixes after which a run of unreserved characters parsed, and skips the
// parser for the next such run. Whatever came before, its answer must be the parser's: random
// prefixes (valid, invalid, "http://" with the tail as the host, the '/' in a query or a
// fragment, after an IP literal or a port) with random tails of unreserved, reserved and forbidden characters, asked in an order
// that has many tails follow a prefix already remembered.
TEST(Iri, IsValidAnswersAsTheParserWhateverItRememberedBefore) {
  const std::vector<std::string> prefixes = {
      "http://h/home1/hrv/", "http://h/", "http://", "http:/", "http:", "urn:a/", "file:///", "http://h/a?q=/",
      "http://h/a#f/", "http://[::1]/", "http://h:80/", "http://h:8x/", "http://h/%zz/", "http://h/a b/",
      "//h/", "/a/", "a/", "http://h/é/", "http://h/a/../", "mailto:x@y/", "http://[::1/", "http://h/{x}/"};
  const std::string tail_chars = "az09-._~AZ/?#[]@!$&'()*+,;=%: {}<>\\"
                                 "\x7f\xc3\xa9";
  std::mt19937 rng(20261128);
  for (int round = 0; round < 20000; ++round) {
    std::string text = prefixes[rng() % prefixes.size()];
    const bool unreserved_tail = rng() % 2;
    const std::size_t length = rng() % 6;  // 0: the prefix alone
    for (std::size_t i = 0; i < length; ++i)
      text += unreserved_tail ? "az09-._~AZ"[rng() % 10] : tail_chars[rng() % tail_chars.size()];
    ASSERT_EQ(is_valid(text), normalize(text).has_value()) << "<" << text << "> after round " << round;
  }
}

// --- resolve: RFC 3986 §5.4 -----------------------------------------------------------------

constexpr const char* kRfcBase = "http://a/b/c/d;p?q";

TEST(Iri, ResolveRfc3986NormalExamples) {
  const std::vector<std::pair<const char*, const char*>> examples = {
      {"g:h", "g:h"},
      {"g", "http://a/b/c/g"},
      {"./g", "http://a/b/c/g"},
      {"g/", "http://a/b/c/g/"},
      {"/g", "http://a/g"},
      {"//g", "http://g"},
      {"?y", "http://a/b/c/d;p?y"},
      {"g?y", "http://a/b/c/g?y"},
      {"#s", "http://a/b/c/d;p?q#s"},
      {"g#s", "http://a/b/c/g#s"},
      {";x", "http://a/b/c/;x"},
      {"", "http://a/b/c/d;p?q"},
      {".", "http://a/b/c/"},
      {"..", "http://a/b/"},
      {"../g", "http://a/b/g"},
      {"../..", "http://a/"},
      {"../../g", "http://a/g"},
  };
  for (const auto& [reference, expected] : examples) {
    SCOPED_TRACE(reference);
    EXPECT_EQ(ok(resolve(kRfcBase, reference)), expected);
  }
}

TEST(Iri, ResolveRfc3986AbnormalDotSegmentExamples) {
  EXPECT_EQ(ok(resolve(kRfcBase, "../../../g")), "http://a/g");
  EXPECT_EQ(ok(resolve(kRfcBase, "/./g")), "http://a/g");
  EXPECT_EQ(ok(resolve(kRfcBase, "g.")), "http://a/b/c/g.");
  EXPECT_EQ(ok(resolve(kRfcBase, "..g")), "http://a/b/c/..g");
  EXPECT_EQ(ok(resolve(kRfcBase, "g;x=1/../y")), "http://a/b/c/y");
}

TEST(Iri, ResolveNormalisesTheResult) {
  EXPECT_EQ(ok(resolve("HTTP://A/b/", "C/%7e/%2f")), "http://a/b/C/~/%2F");
}

TEST(Iri, ResolveKeepsUtf8OfBaseAndReference) {
  EXPECT_EQ(ok(resolve("http://h/é/x", "ü?q=ä")), "http://h/é/ü?q=ä");
  EXPECT_EQ(ok(resolve("http://h/é/", "%c3%a9")), "http://h/é/%C3%A9");
}

TEST(Iri, ResolveNeverTurnsPathIntoAuthority) {
  EXPECT_EQ(ok(resolve("urn:/a/b", "..//x")), "urn:/.//x");
}

TEST(Iri, ResolveRejectsRelativeBase) {
  IriError e = err(resolve("a/b", "c"));
  EXPECT_TRUE(contains(e.message, "invalid base IRI 'a/b'")) << e.message;
}

TEST(Iri, ResolveInvalidReferenceErrorPointsIntoReference) {
  IriError e = err(resolve("http://h/", "x/a b"));
  EXPECT_EQ(e.position, 3u);
  EXPECT_TRUE(contains(e.message, "invalid IRI reference 'x/a b' at position 3")) << e.message;
}

// --- check_id -------------------------------------------------------------------------------

TEST(Iri, CheckIdReturnsValidIdUnchanged) {
  for (const char* id : {"ecg", "sensor-1", "a.b", ".hidden", "a..b", "café", "x:y", "%41"}) {
    EXPECT_EQ(ok(check_id(id)), id);
  }
}

TEST(Iri, CheckIdRejectsEmpty) { EXPECT_EQ(err(check_id("")).position, 0u); }

TEST(Iri, CheckIdRejectsSlashNamingItsPosition) {
  IriError e = err(check_id("a/b"));
  EXPECT_EQ(e.position, 1u);
  EXPECT_EQ(e.message, "invalid id 'a/b' at position 1: unexpected character '/' in an id");
}

TEST(Iri, CheckIdRejectsQueryAndFragmentMarks) {
  EXPECT_EQ(err(check_id("a?b")).position, 1u);
  EXPECT_EQ(err(check_id("ab#")).position, 2u);
}

// An id whose percent-escape is none passed check_id and failed only when an IRI was made of it:
// `tahvel put --agent %zz` was a failure of the store's (exit 1), not a bad command line.
TEST(Iri, CheckIdRejectsAnIdThatMakesNoIri) {
  const IriError e = err(check_id("%zz"));
  EXPECT_TRUE(contains(e.message, "invalid percent-encoding '%zz'")) << e.message;
  EXPECT_TRUE(contains(e.message, "invalid id '%zz'")) << e.message;
  EXPECT_FALSE(check_id("a%2"));
  EXPECT_FALSE(check_id("%2E%2E"));
  EXPECT_TRUE(check_id("a%20b"));
}

TEST(Iri, CheckIdRejectsDotAndDotDot) {
  EXPECT_TRUE(contains(err(check_id(".")).message, "path steps"));
  EXPECT_TRUE(contains(err(check_id("..")).message, "path steps"));
}

// A child node "*" had the IRI <parent>/*, the address of the parent's whole subtree (P11):
// what was sent to it went nowhere, and a query --at it went to a sibling.
TEST(Iri, CheckIdRejectsTheSubtreeStarButNotAStarInAnId) {
  EXPECT_TRUE(contains(err(check_id("*")).message, "addresses the whole subtree")) << err(check_id("*")).message;
  EXPECT_TRUE(check_id("a*"));
  EXPECT_FALSE(child_node_iri("http://h", "*"));
}

// Files are named after ids: an agent of 250 bytes could not make its lock file and restarted
// for ever, and one of 253 never started while `up` said it had.
TEST(Iri, CheckIdRejectsAnIdLongerThanAFileNameCanCarry) {
  EXPECT_TRUE(check_id(std::string(kMaxIdBytes, 'a')));
  const auto long_one = err(check_id(std::string(kMaxIdBytes + 1, 'a')));
  EXPECT_EQ(long_one.position, kMaxIdBytes);
  EXPECT_TRUE(contains(long_one.message, "an id is at most 200 bytes (files are named after ids); this one has 201")) << long_one.message;
  EXPECT_FALSE(agent_iri("http://h", std::string(250, 'a')));
}

TEST(Iri, CheckIdRejectsWhitespace) {
  EXPECT_EQ(err(check_id(" ")).position, 0u);
  EXPECT_EQ(err(check_id("a b")).position, 1u);
  EXPECT_EQ(err(check_id("ab\t")).position, 2u);
  EXPECT_EQ(err(check_id("a\xC2\xA0")).position, 1u);      // U+00A0 no-break space
  EXPECT_EQ(err(check_id("a\xE2\x80\xA8")).position, 1u);  // U+2028 line separator
}

TEST(Iri, CheckIdRejectsControlCharacters) {
  EXPECT_EQ(err(check_id("a\nb")).position, 1u);
  EXPECT_EQ(err(check_id(std::string("a\0b", 3))).position, 1u);
  EXPECT_EQ(err(check_id("a\x7F")).position, 1u);
  EXPECT_EQ(err(check_id("\xC2\x85")).position, 0u);  // U+0085, a C1 control
}

TEST(Iri, CheckIdRejectsMalformedUtf8) { EXPECT_EQ(err(check_id("ok\xFF")).position, 2u); }

// "café" written with a combining accent (e + U+0301) looks like "café" precomposed (U+00E9):
// as ids they would name two nodes that an operator cannot tell apart.
TEST(Iri, CheckIdRejectsAnIdNotInNfcNamingTheComposedForm) {
  IriError e = err(check_id("kodu-cafe\xCC\x81"));
  EXPECT_EQ(e.position, 8u);  // the 'e' the accent combines with
  EXPECT_TRUE(contains(e.message, "not in Unicode normalization form C (NFC): U+0065 U+0301 is composed U+00E9 ('kodu-caf\xC3\xA9')"))
      << e.message;
  EXPECT_EQ(ok(check_id("kodu-caf\xC3\xA9")), "kodu-caf\xC3\xA9");
  // Hangul syllables decomposed into jamo are not NFC either.
  EXPECT_FALSE(check_id("\xE1\x84\x80\xE1\x85\xA1").has_value());  // U+1100 U+1161, NFC: U+AC00
  EXPECT_EQ(ok(check_id("\xEA\xB0\x80")), "\xEA\xB0\x80");
}

TEST(Iri, AChildIriOrAgentIriWithAnIdNotInNfcIsRefused) {
  EXPECT_TRUE(contains(err(child_id("http://h/kodu/cafe\xCC\x81", "http://h/kodu")).message, "NFC"));
  EXPECT_EQ(ok(child_id("http://h/kodu/caf\xC3\xA9", "http://h/kodu")), "caf\xC3\xA9");
  EXPECT_TRUE(contains(err(agent_iri("http://h/kodu", "cafe\xCC\x81")).message, "NFC"));
  EXPECT_TRUE(contains(err(child_node_iri("http://h", "o\xCC\x88lle")).message, "NFC"));  // o + U+0308
}

TEST(Iri, ANodeIriNotInNfcIsRefusedAndOneInNfcIsNormalised) {
  // "https://kodu.example/cafe" + U+0301: looks like the precomposed one, is other bytes.
  IriError e = err(node_iri("https://kodu.example/cafe\xCC\x81"));
  EXPECT_EQ(e.position, 24u);  // the 'e' the accent combines with
  EXPECT_TRUE(contains(e.message, "U+0065 U+0301 is composed U+00E9")) << e.message;
  EXPECT_TRUE(contains(e.message, "a node IRI is written composed")) << e.message;
  EXPECT_EQ(ok(node_iri("HTTPS://Kodu.Example/caf\xC3\xA9")), "https://kodu.example/caf\xC3\xA9");
  EXPECT_TRUE(contains(err(node_iri("kodu")).message, "invalid IRI 'kodu'"));
}

// A node's agents are its IRI + "/" + id: an IRI that cannot have them made a store that
// could hold nothing (a query or fragment), or one whose addressed items never arrived ('/').
TEST(Iri, ANodeIriWithAQueryAFragmentOrATrailingSlashIsRefused) {
  IriError query = err(node_iri("http://example.org/n?x=1"));
  EXPECT_EQ(query.position, 20u);
  EXPECT_TRUE(contains(query.message, "a node IRI cannot have a query or fragment")) << query.message;
  EXPECT_TRUE(contains(err(node_iri("http://example.org/n#me")).message, "query or fragment"));
  IriError slash = err(node_iri("http://example.org/home1/"));
  EXPECT_TRUE(contains(slash.message, "a node IRI cannot end in '/'")) << slash.message;
  EXPECT_TRUE(contains(err(node_iri("http://example.org/")).message, "cannot end in '/'"));
  EXPECT_EQ(ok(node_iri("http://example.org")), "http://example.org");
}

// `http:///x` parses (an empty host), but no machine can be named by it: a node under it could
// not be told apart from another deployment's, so it is refused where node IRIs are given.
TEST(Iri, AnHttpNodeIriWithoutAHostIsRefused) {
  for (const char* text : {"http:///home1", "https:///h/home1", "http://:8080/home1", "http://user@/home1"}) {
    IriError e = err(node_iri(text));
    EXPECT_TRUE(contains(e.message, "needs a host")) << text << ": " << e.message;
    EXPECT_EQ(e.position, std::string_view(text).find("//") + 2) << text;
  }
  EXPECT_EQ(ok(node_iri("http://[::1]:8080/home1")), "http://[::1]:8080/home1");
  EXPECT_EQ(ok(node_iri("urn:tahvel:h/home1")), "urn:tahvel:h/home1");
  EXPECT_EQ(ok(node_iri("file:///var/home1")), "file:///var/home1");
}

// --- agent_iri and child_node_iri -----------------------------------------------------------

TEST(Iri, AgentIriAppendsSlashAndId) {
  EXPECT_EQ(ok(agent_iri("http://h/home1", "ecg")), "http://h/home1/ecg");
}

TEST(Iri, AgentIriAppendsIdWithoutDoublingSlash) {
  EXPECT_EQ(ok(agent_iri("http://h/home1/", "ecg")), "http://h/home1/ecg");
}

TEST(Iri, AgentIriOfHostOnlyNodeIsAPathOnTheHost) {
  EXPECT_EQ(ok(agent_iri("http://h", "ecg")), "http://h/ecg");
}

TEST(Iri, AgentIriIsInNormalForm) {
  EXPECT_EQ(ok(agent_iri("HTTP://H/a/./home1", "ecg")), "http://h/a/home1/ecg");
}

TEST(Iri, AgentIriKeepsUtf8Id) {
  EXPECT_EQ(ok(agent_iri("http://h/kodu", "südamerütm")), "http://h/kodu/südamerütm");
}

TEST(Iri, AgentIriRejectsInvalidNodeIri) {
  IriError e = err(agent_iri("http://a b", "ecg"));
  EXPECT_EQ(e.position, 8u);
  EXPECT_TRUE(contains(e.message, "invalid node IRI 'http://a b'")) << e.message;
}

TEST(Iri, AgentIriRejectsNodeIriWithQueryOrFragment) {
  EXPECT_EQ(err(agent_iri("http://h/n#x", "ecg")).position, 10u);
  EXPECT_EQ(err(agent_iri("http://h/n?x", "ecg")).position, 10u);
}

TEST(Iri, AgentIriRejectsInvalidIdNamingIt) {
  IriError e = err(agent_iri("http://h/n", "a/b"));
  EXPECT_EQ(e.position, 1u);
  EXPECT_TRUE(contains(e.message, "invalid id 'a/b'")) << e.message;
}

TEST(Iri, AgentIriRejectsIdWithCharacterInvalidInIriAtItsPositionInId) {
  IriError e = err(agent_iri("http://h/n", "ab<c"));
  EXPECT_EQ(e.position, 2u);
  EXPECT_TRUE(contains(e.message, "invalid id 'ab<c' at position 2")) << e.message;
}

TEST(Iri, AgentIriRejectsPercentEncodedDotSegmentId) {
  // "%2E%2E" passes check_id but normalises to "..": it would climb out of the node.
  EXPECT_FALSE(agent_iri("http://h/n/", "%2E%2E").has_value());
  EXPECT_FALSE(agent_iri("http://h/n", "%2e").has_value());
}

TEST(Iri, ChildNodeIriIsDerivedLikeAgentIri) {
  EXPECT_EQ(ok(child_node_iri("http://h/gw", "home1")), "http://h/gw/home1");
  EXPECT_EQ(ok(child_node_iri("http://h/gw/", "home1")), ok(agent_iri("http://h/gw/", "home1")));
  EXPECT_TRUE(contains(err(child_node_iri("rel", "x")).message, "invalid parent IRI"));
  EXPECT_FALSE(child_node_iri("http://h/gw", "..").has_value());
}

// --- is_under -------------------------------------------------------------------------------

TEST(Iri, IsUnderAcceptsDescendants) {
  EXPECT_TRUE(is_under("http://h/home1/ecg", "http://h/home1"));
  EXPECT_TRUE(is_under("http://h/home1/ecg/lead2", "http://h/home1"));
  EXPECT_TRUE(is_under("http://h/home1", "http://h"));
}

TEST(Iri, IsUnderAcceptsTheIriItself) { EXPECT_TRUE(is_under("http://h/home1", "http://h/home1")); }

TEST(Iri, IsUnderRejectsSiblingWithCommonPrefix) {
  EXPECT_FALSE(is_under("http://h/home10", "http://h/home1"));
  EXPECT_FALSE(is_under("http://h/home1-b/x", "http://h/home1"));
  EXPECT_FALSE(is_under("http://h.evil/x", "http://h"));
}

TEST(Iri, IsUnderAcceptsQueryAndFragmentOfAncestor) {
  EXPECT_TRUE(is_under("http://h/home1#ecg", "http://h/home1"));
  EXPECT_TRUE(is_under("http://h/home1?since=3", "http://h/home1"));
}

TEST(Iri, IsUnderAncestorEndingInSlashOrHashIsANamespace) {
  EXPECT_TRUE(is_under("http://h/home1/ecg", "http://h/home1/"));
  EXPECT_TRUE(is_under("https://w3id.org/tahvel#Node", std::string(kTahvelNs)));
  EXPECT_FALSE(is_under("http://h/home1", "http://h/home1/"));
}

TEST(Iri, IsUnderRejectsAncestorOfTheAncestor) {
  EXPECT_FALSE(is_under("http://h", "http://h/home1"));
  EXPECT_FALSE(is_under("http://h/other", "http://h/home1"));
}

TEST(Iri, IsUnderComparesNormalForms) {
  EXPECT_TRUE(is_under("HTTP://H/home1/./ecg", "http://h/home1"));
  EXPECT_TRUE(is_under("http://h/home1/ecg", "http://H/x/../home1"));
  EXPECT_FALSE(is_under("http://h/home1/../home2", "http://h/home1"));
  EXPECT_FALSE(is_under("http://h/home1/%2E%2E/home2", "http://h/home1"));
}

TEST(Iri, IsUnderInvalidIriIsUnderNothing) {
  EXPECT_FALSE(is_under("http://h/home1/a b", "http://h/home1"));
  EXPECT_FALSE(is_under("home1/ecg", "home1"));
  EXPECT_FALSE(is_under("http://h/home1/ecg", "not an iri"));
}

// --- child_id -------------------------------------------------------------------------------

TEST(Iri, ChildIdReturnsTheSegmentBelowParent) {
  EXPECT_EQ(ok(child_id("http://h/home1/ecg", "http://h/home1")), "ecg");
  EXPECT_EQ(ok(child_id("http://h/home1/ecg", "http://h/home1/")), "ecg");
  EXPECT_EQ(ok(child_id("HTTP://H/home1/./ecg", "http://h/home1")), "ecg");
}

TEST(Iri, ChildIdRejectsGrandchild) {
  IriError e = err(child_id("http://h/home1/ecg/lead2", "http://h/home1"));
  EXPECT_EQ(e.position, 18u);
  EXPECT_TRUE(contains(e.message, "not one path segment below 'http://h/home1'")) << e.message;
}

TEST(Iri, ChildIdRejectsSiblingWithCommonPrefix) {
  IriError e = err(child_id("http://h/home10", "http://h/home1"));
  EXPECT_TRUE(contains(e.message, "not under 'http://h/home1'")) << e.message;
}

TEST(Iri, ChildIdRejectsParentItselfAndFragmentOrQueryBelowIt) {
  EXPECT_FALSE(child_id("http://h/home1", "http://h/home1").has_value());
  EXPECT_FALSE(child_id("http://h/home1/", "http://h/home1").has_value());
  EXPECT_FALSE(child_id("http://h/home1#ecg", "http://h/home1").has_value());
  EXPECT_FALSE(child_id("http://h/home1/ecg?x", "http://h/home1").has_value());
}

TEST(Iri, ChildIdRejectsInvalidIris) {
  EXPECT_TRUE(contains(err(child_id("http://a b/x", "http://a")).message, "invalid IRI"));
  EXPECT_TRUE(contains(err(child_id("http://h/x", "h")).message, "invalid parent IRI"));
}

TEST(Iri, ChildIdInvertsAgentIri) {
  for (const char* node : {"http://h/gw/home1", "http://h/gw/home1/", "urn:tahvel:gw"}) {
    for (const char* id : {"ecg", "südamerütm", "a.b", "x:y"}) {
      SCOPED_TRACE(std::string(node) + " " + id);
      EXPECT_EQ(ok(child_id(ok(agent_iri(node, id)), node)), id);
    }
  }
}

// --- PrefixMap ------------------------------------------------------------------------------

TEST(IriPrefixMap, StandardHasTheNineVocabularies) {
  PrefixMap map = PrefixMap::standard();
  const std::vector<std::pair<const char*, const char*>> expected = {
      {"rdf", "http://www.w3.org/1999/02/22-rdf-syntax-ns#"},
      {"rdfs", "http://www.w3.org/2000/01/rdf-schema#"},
      {"xsd", "http://www.w3.org/2001/XMLSchema#"},
      {"owl", "http://www.w3.org/2002/07/owl#"},
      {"sosa", "http://www.w3.org/ns/sosa/"},
      {"ssn", "http://www.w3.org/ns/ssn/"},
      {"prov", "http://www.w3.org/ns/prov#"},
      {"geo", "http://www.opengis.net/ont/geosparql#"},
      {"tv", "https://w3id.org/tahvel#"},
  };
  EXPECT_EQ(map.entries().size(), expected.size());
  for (const auto& [prefix, ns] : expected) {
    ASSERT_EQ(map.entries().count(prefix), 1u) << prefix;
    EXPECT_EQ(map.entries().at(prefix), ns);
  }
}

TEST(IriPrefixMap, ExpandReplacesPrefixWithNamespace) {
  PrefixMap map = PrefixMap::standard();
  EXPECT_EQ(ok(map.expand("sosa:Observation")), "http://www.w3.org/ns/sosa/Observation");
  EXPECT_EQ(ok(map.expand("rdf:type")), "http://www.w3.org/1999/02/22-rdf-syntax-ns#type");
  EXPECT_EQ(ok(map.expand("tv:")), "https://w3id.org/tahvel#");
}

TEST(IriPrefixMap, ExpandStripsAngleBrackets) {
  EXPECT_EQ(ok(PrefixMap::standard().expand("<http://x>")), "http://x");
  EXPECT_EQ(ok(PrefixMap::standard().expand("<HTTP://X/a/./b>")), "http://x/a/b");
}

TEST(IriPrefixMap, ExpandAngleBracketsErrorsPointIntoTheInput) {
  PrefixMap map = PrefixMap::standard();
  EXPECT_EQ(err(map.expand("<http://x")).position, 9u);
  EXPECT_EQ(err(map.expand("<http://a b>")).position, 9u);
}

TEST(IriPrefixMap, ExpandReturnsAbsoluteIriWithUnknownSchemeNormalised) {
  PrefixMap map = PrefixMap::standard();
  EXPECT_EQ(ok(map.expand("http://x/y")), "http://x/y");
  EXPECT_EQ(ok(map.expand("HTTP://X/a/../y")), "http://x/y");
  EXPECT_EQ(ok(map.expand("urn:a:b")), "urn:a:b");
}

TEST(IriPrefixMap, ExpandUnknownPrefixIsError) {
  IriError e = err(PrefixMap::standard().expand("nope:Thing"));
  EXPECT_EQ(e.message, "invalid CURIE 'nope:Thing' at position 0: unknown prefix 'nope'");
}

TEST(IriPrefixMap, ExpandWithoutColonIsError) {
  EXPECT_FALSE(PrefixMap::standard().expand("Observation").has_value());
}

TEST(IriPrefixMap, ExpandKnownPrefixWinsOverScheme) {
  PrefixMap map;
  ASSERT_TRUE(map.add("urn", "http://example.org/urn/"));
  EXPECT_EQ(ok(map.expand("urn:x")), "http://example.org/urn/x");
}

TEST(IriPrefixMap, ExpandEmptyPrefix) {
  PrefixMap map;
  ASSERT_TRUE(map.add("", "http://example.org/"));
  EXPECT_EQ(ok(map.expand(":thing")), "http://example.org/thing");
}

TEST(IriPrefixMap, ExpandRemovesTurtleLocalEscapes) {
  EXPECT_EQ(ok(PrefixMap::standard().expand("sosa:a\\/b\\.c")), "http://www.w3.org/ns/sosa/a/b.c");
}

TEST(IriPrefixMap, ExpandInvalidLocalPartErrorPointsIntoCurie) {
  IriError e = err(PrefixMap::standard().expand("sosa:a b"));
  EXPECT_EQ(e.position, 6u);
  EXPECT_TRUE(contains(e.message, "invalid CURIE 'sosa:a b' at position 6")) << e.message;
}

TEST(IriPrefixMap, AddRejectsInvalidPrefixNames) {
  PrefixMap map;
  for (const char* name : {"1x", "_x", "a.", "a b", "a:b", "-x"}) {
    SCOPED_TRACE(name);
    auto added = map.add(name, "http://x/");
    ASSERT_FALSE(added.has_value());
    EXPECT_TRUE(contains(added.error().message, "invalid prefix name")) << added.error().message;
  }
  EXPECT_TRUE(map.entries().empty());
}

TEST(IriPrefixMap, AddAcceptsTurtlePrefixNames) {
  PrefixMap map;
  for (const char* name : {"a", "a.b", "a-b_c1", "é", "ex2"}) {
    EXPECT_TRUE(map.add(name, "http://x/").has_value()) << name;
  }
}

TEST(IriPrefixMap, AddRejectsNamespaceThatIsNotAbsolute) {
  PrefixMap map;
  auto added = map.add("ex", "relative/ns#");
  ASSERT_FALSE(added.has_value());
  EXPECT_TRUE(contains(added.error().message, "invalid namespace IRI")) << added.error().message;
}

TEST(IriPrefixMap, AddReplacesExistingPrefix) {
  PrefixMap map;
  ASSERT_TRUE(map.add("ex", "http://one/"));
  ASSERT_TRUE(map.add("ex", "http://two/"));
  EXPECT_EQ(ok(map.expand("ex:x")), "http://two/x");
}

TEST(IriPrefixMap, CompactUsesShortestCurie) {
  PrefixMap map;
  ASSERT_TRUE(map.add("longprefix", "http://ex/"));
  ASSERT_TRUE(map.add("p", "http://ex/ab"));
  EXPECT_EQ(map.compact("http://ex/abc"), "p:c");
  EXPECT_EQ(map.compact("http://ex/xyz"), "longprefix:xyz");
}

TEST(IriPrefixMap, CompactReturnsIriWhenLocalPartIsNotPnLocal) {
  PrefixMap map = PrefixMap::standard();
  EXPECT_EQ(map.compact("http://www.w3.org/ns/sosa/a/b"), "http://www.w3.org/ns/sosa/a/b");
  EXPECT_EQ(map.compact("http://www.w3.org/ns/sosa/a."), "http://www.w3.org/ns/sosa/a.");
}

TEST(IriPrefixMap, CompactReturnsIriWhenNoNamespaceMatches) {
  EXPECT_EQ(PrefixMap::standard().compact("http://example.org/x"), "http://example.org/x");
}

// A store holds "HTTP://www.w3.org/..." and "http://www.w3.org:80/..." apart from the normal
// form; printed under one CURIE they would look like one IRI.
TEST(IriPrefixMap, CompactLeavesAnIriNotInNormalFormAsWritten) {
  PrefixMap map = PrefixMap::standard();
  for (const char* iri : {"HTTP://www.w3.org/ns/sosa/Observation", "http://WWW.W3.ORG/ns/sosa/Observation",
                          "http://www.w3.org:80/ns/sosa/Observation"})
    EXPECT_EQ(map.compact(iri), iri);
  EXPECT_EQ(map.compact("http://www.w3.org/ns/sosa/Observation"), "sosa:Observation");
}

TEST(IriPrefixMap, CompactThenExpandRoundTrips) {
  PrefixMap map = PrefixMap::standard();
  for (const char* iri :
       {"http://www.w3.org/ns/sosa/Observation", "https://w3id.org/tahvel#Node",
        "http://www.w3.org/2001/XMLSchema#dateTime", "https://w3id.org/tahvel#"}) {
    SCOPED_TRACE(iri);
    std::string curie = map.compact(iri);
    EXPECT_NE(curie, iri);
    EXPECT_EQ(ok(map.expand(curie)), iri);
  }
}

// \u and \U escapes name characters; surrogates, values past U+10FFFF and non-hex digits are
// refused rather than written as bytes that are not UTF-8.
TEST(UnicodeEscape, EscapesBecomeUtf8AndNonCharactersAreRefused) {
  std::string out;
  for (const char* hex : {"0041", "00e9", "20AC", "0001F600"}) append_utf8(out, escaped_code_point(hex).value());
  EXPECT_EQ(out, "A\u00e9\u20ac\U0001F600");
  EXPECT_FALSE(escaped_code_point("D800"));      // a surrogate
  EXPECT_FALSE(escaped_code_point("00110000"));  // past U+10FFFF
  EXPECT_FALSE(escaped_code_point("00g1"));
  EXPECT_FALSE(escaped_code_point(""));
}

}  // namespace
}  // namespace tahvel::uri

// What a browser shows of a percent-encoded IRI, for naming the IRI a user meant: every %HH
// decoded to its byte, anything else (a '%' without two hex digits) as written.
TEST(IriPercentDecoded, DecodesEachEscapeAndKeepsWhatIsNotOne) {
  EXPECT_EQ(tahvel::uri::percent_decoded("http://h/kodu-%C3%B5ie"), "http://h/kodu-\xC3\xB5ie");
  EXPECT_EQ(tahvel::uri::percent_decoded("http://h/a%2fb%zz%4"), "http://h/a/b%zz%4");
  EXPECT_EQ(tahvel::uri::percent_decoded(""), "");
}

// The "did you mean" of a misspelt term counts a dropped, an added, a changed and two swapped
// characters each as one slip (`tahvel lsit` is "list", not "init").
TEST(Spelling, EditDistanceCountsTheOneCharacterEditsBetweenTwoNames) {
  EXPECT_EQ(tahvel::uri::edit_distance("integer", "integer"), 0u);
  EXPECT_EQ(tahvel::uri::edit_distance("integr", "integer"), 1u);
  EXPECT_EQ(tahvel::uri::edit_distance("integerr", "integer"), 1u);
  EXPECT_EQ(tahvel::uri::edit_distance("intager", "integer"), 1u);
  EXPECT_EQ(tahvel::uri::edit_distance("itneger", "integer"), 1u);
  EXPECT_EQ(tahvel::uri::edit_distance("lsit", "list"), 1u);
  EXPECT_EQ(tahvel::uri::edit_distance("lsit", "init"), 2u);
  EXPECT_EQ(tahvel::uri::edit_distance("ab", "ba"), 1u);
  EXPECT_EQ(tahvel::uri::edit_distance("ca", "abc"), 3u);  // no edit of a swapped pair again
  EXPECT_EQ(tahvel::uri::edit_distance("", "abc"), 3u);
  EXPECT_EQ(tahvel::uri::edit_distance("abc", ""), 3u);
}
