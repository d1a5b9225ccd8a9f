// Private to uri/: UTF-8 decoding, RFC 3987 character classes, and the one-line error messages
// every function of the library produces. Small, allocation-free helpers; no uriparser here.
#pragma once

#include <cstddef>
#include <optional>
#include <string>
#include <string_view>

#include "tahvel/uri/iri.h"

namespace tahvel::uri::detail {

// One decoded UTF-8 sequence. `length` is 0 when the bytes at the position are not well-formed
// UTF-8 (overlong forms, surrogates and values above U+10FFFF count as malformed).
struct CodePoint {
  char32_t value = 0;
  std::size_t length = 0;
};

CodePoint decode_utf8(std::string_view text, std::size_t pos);

// RFC 3987 ucschar or iprivate: the non-ASCII characters an IRI may hold.
bool is_iri_char(char32_t c);

bool has_non_ascii(std::string_view text);

// `text` (well-formed UTF-8) in Unicode normalization form C, when that differs from `text`;
// nothing when it is already in NFC (all ASCII text is).
std::optional<std::string> nfc_if_different(std::string_view text);

// An error found at `position` of `input`, before it is worded for one of the public functions.
struct Failure {
  std::size_t position;
  std::string cause;
};

// What is at `position` of `input`, worded as a cause: "unexpected character ' '",
// "unexpected end of input", "invalid UTF-8 byte 0xFF", ...
std::string unexpected_at(std::string_view input, std::size_t position);

// "<what> '<input>' at position <n>: <cause>", always one line: control characters and bytes
// that are not UTF-8 are shown as \xNN, and very long inputs are shortened.
IriError make_error(std::string_view what, std::string_view input, const Failure& failure);

}  // namespace tahvel::uri::detail
