// Unicode escapes as Turtle, N-Triples and SPARQL write them (\uXXXX, \UXXXXXXXX), for the
// readers of such text outside serd: the CLI's terms and the reasoner's rule files.
//
//   if (auto c = uri::escaped_code_point("00e9")) uri::append_utf8(out, *c);   // "é"
#pragma once

#include <optional>
#include <string>
#include <string_view>

namespace tahvel::uri {

// The character the hex digits of one escape name (4 after \u, 8 after \U; either case).
// nullopt when a digit is not hex, or the value is a surrogate (U+D800..U+DFFF) or above
// U+10FFFF: not a character, and not encodable as UTF-8.
std::optional<char32_t> escaped_code_point(std::string_view hex);

// Appends `c`, a Unicode scalar value (as escaped_code_point returns), to `out` as UTF-8.
void append_utf8(std::string& out, char32_t c);

}  // namespace tahvel::uri
