// Terms as values: the RDF 1.1 datatype defaults and the N-Triples form of a single term.
//
// to_ntriples() is written here by hand rather than through serd's writer because it serialises
// one term, not a statement, and is called on hot paths (the C API, logs) where setting up a
// serd writer per term would dominate. Its output is canonical N-Triples (RDF 1.1 N-Triples
// §7 for literals, UCHAR for characters IRIREF forbids) and always valid UTF-8: serd reads it
// back to the same term, which the format tests check.
#include "tahvel/node/term.h"

#include <cstdint>
#include <string>
#include <string_view>

namespace tahvel::node {
namespace detail {

// Length (2-4) of the well-formed UTF-8 sequence that starts with the non-ASCII byte at
// text[i], or 0 when it is ill-formed (Unicode 15 Table 3-7: no overlong forms, no surrogates,
// nothing above U+10FFFF). Shared with format.cpp.
std::size_t utf8_sequence_length(std::string_view text, std::size_t i) noexcept {
  const auto byte = [&](std::size_t k) -> unsigned {
    return i + k < text.size() ? static_cast<unsigned char>(text[i + k]) : 0x100u;
  };
  const auto tail = [&](std::size_t k, unsigned lo = 0x80, unsigned hi = 0xBF) {
    return byte(k) >= lo && byte(k) <= hi;
  };
  const unsigned b0 = byte(0);
  if (b0 >= 0xC2 && b0 <= 0xDF) return tail(1) ? 2 : 0;
  if (b0 == 0xE0) return tail(1, 0xA0) && tail(2) ? 3 : 0;
  if ((b0 >= 0xE1 && b0 <= 0xEC) || b0 == 0xEE || b0 == 0xEF) return tail(1) && tail(2) ? 3 : 0;
  if (b0 == 0xED) return tail(1, 0x80, 0x9F) && tail(2) ? 3 : 0;
  if (b0 == 0xF0) return tail(1, 0x90) && tail(2) && tail(3) ? 4 : 0;
  if (b0 >= 0xF1 && b0 <= 0xF3) return tail(1) && tail(2) && tail(3) ? 4 : 0;
  if (b0 == 0xF4) return tail(1, 0x80, 0x8F) && tail(2) && tail(3) ? 4 : 0;
  return 0;
}

}  // namespace detail

namespace {

constexpr std::string_view kReplacementUchar = "\\uFFFD";

void append_uchar(std::string& out, unsigned char c) {
  static constexpr char kHex[] = "0123456789ABCDEF";
  out += "\\u00";
  out += kHex[c >> 4];
  out += kHex[c & 0xF];
}

// Copies the UTF-8 sequence at text[i] to `out` (or U+FFFD for an ill-formed one) and returns
// the index after it.
std::size_t append_non_ascii(std::string& out, std::string_view text, std::size_t i) {
  const std::size_t n = detail::utf8_sequence_length(text, i);
  if (n == 0) {
    out += kReplacementUchar;
    return i + 1;
  }
  out.append(text.substr(i, n));
  return i + n;
}

// IRIREF body: UCHAR for the characters the production excludes ([^#x00-#x20<>"{}|^`\]).
void append_iri(std::string& out, std::string_view iri) {
  static constexpr std::string_view kForbidden = "<>\"{}|^`\\";
  out += '<';
  for (std::size_t i = 0; i < iri.size();) {
    const auto c = static_cast<unsigned char>(iri[i]);
    if (c >= 0x80) {
      i = append_non_ascii(out, iri, i);
      continue;
    }
    if (c <= 0x20 || kForbidden.find(static_cast<char>(c)) != std::string_view::npos)
      append_uchar(out, c);
    else
      out += static_cast<char>(c);
    ++i;
  }
  out += '>';
}

// STRING_LITERAL_QUOTE body: ECHAR for " \ and the named controls, UCHAR for other controls.
void append_string(std::string& out, std::string_view text) {
  out += '"';
  for (std::size_t i = 0; i < text.size();) {
    const auto c = static_cast<unsigned char>(text[i]);
    if (c >= 0x80) {
      i = append_non_ascii(out, text, i);
      continue;
    }
    switch (c) {
      case '"': out += "\\\""; break;
      case '\\': out += "\\\\"; break;
      case '\n': out += "\\n"; break;
      case '\r': out += "\\r"; break;
      case '\t': out += "\\t"; break;
      case '\b': out += "\\b"; break;
      case '\f': out += "\\f"; break;
      default:
        if (c < 0x20 || c == 0x7F)
          append_uchar(out, c);
        else
          out += static_cast<char>(c);
    }
    ++i;
  }
  out += '"';
}

}  // namespace

std::string_view Term::effective_datatype() const {
  if (kind != TermKind::literal) return {};
  if (!language.empty()) return kRdfLangString;
  if (datatype.empty()) return xsd::kString;
  return datatype;
}

std::string Term::to_ntriples() const {
  std::string out;
  out.reserve(value.size() + 8);
  switch (kind) {
    case TermKind::iri: append_iri(out, value); break;
    case TermKind::blank:
      out += "_:";
      out += value;
      break;
    case TermKind::literal:
      append_string(out, value);
      if (!language.empty()) {
        out += '@';
        out += language;
      } else if (!datatype.empty() && datatype != xsd::kString) {
        out += "^^";
        append_iri(out, datatype);
      }
      break;
  }
  return out;
}

}  // namespace tahvel::node
