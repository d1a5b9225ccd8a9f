// String escaping shared by the N-Triples form of terms (term.cpp) and JSON output
// (format.cpp). Both write backslash escapes for '"', '\' and the named controls, \u00XX for the
// other controls, and U+FFFD for each byte of ill-formed UTF-8, so output is always valid
// UTF-8. They differ in hex case and in JSON's escapes for U+2028/U+2029 (line separators that
// break JavaScript).
#pragma once

#include <cstddef>
#include <string>
#include <string_view>

namespace tahvel::node::detail {

enum class EscapeDialect { ntriples, json };

// Length (2-4) of the well-formed UTF-8 sequence that starts with the non-ASCII byte at
// text[i], or 0 when it is ill-formed (Unicode 15 Table 3-7: no overlong forms, no surrogates,
// nothing above U+10FFFF).
std::size_t utf8_sequence_length(std::string_view text, std::size_t i) noexcept;

// Appends \u00XX for an ASCII control byte.
void append_uchar(std::string& out, unsigned char c, EscapeDialect dialect);

// Appends the UTF-8 sequence at text[i] (or the dialect's U+FFFD escape when it is ill-formed)
// and returns the index after it. Precondition: text[i] >= 0x80.
std::size_t append_non_ascii(std::string& out, std::string_view text, std::size_t i,
                             EscapeDialect dialect);

// Appends the body of a string literal (no quotes).
void append_escaped(std::string& out, std::string_view text, EscapeDialect dialect);

}  // namespace tahvel::node::detail
