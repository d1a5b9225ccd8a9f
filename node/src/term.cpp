// Terms as values: the RDF 1.1 datatype defaults and the N-Triples form of a single term.
//
// to_ntriples() is written here by hand rather than through serd's writer because it serialises
// one term, not a statement, and is called on hot paths (the C API, logs) where setting up a
// serd writer per term would dominate. Its output is canonical N-Triples (RDF 1.1 N-Triples
// §7 for literals, UCHAR for characters IRIREF forbids) and always valid UTF-8: serd reads it
// back to the same term, which the format tests check.
#include "tahvel/node/term.h"

#include "escape.h"

#include <cstdint>
#include <cstring>
#include <string>
#include <string_view>

namespace tahvel::node {
namespace {

using detail::EscapeDialect;

// IRIREF body: UCHAR for the characters the production excludes ([^#x00-#x20<>"{}|^`\]).
void append_iri(std::string& out, std::string_view iri) {
  static constexpr std::string_view kForbidden = "<>\"{}|^`\\";
  out += '<';
  for (std::size_t i = 0; i < iri.size();) {
    const auto c = static_cast<unsigned char>(iri[i]);
    if (c >= 0x80) {
      i = detail::append_non_ascii(out, iri, i, EscapeDialect::ntriples);
      continue;
    }
    if (c <= 0x20 || kForbidden.find(static_cast<char>(c)) != std::string_view::npos)
      detail::append_uchar(out, c, EscapeDialect::ntriples);
    else
      out += static_cast<char>(c);
    ++i;
  }
  out += '>';
}

// STRING_LITERAL_QUOTE: ECHAR for " \ and the named controls, UCHAR for other controls.
void append_string(std::string& out, std::string_view text) {
  out += '"';
  detail::append_escaped(out, text, EscapeDialect::ntriples);
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

std::size_t ill_formed_utf8_at(std::string_view text) noexcept {
  for (std::size_t i = 0; i < text.size();) {
    // ASCII 32 and then 8 bytes at a time: IRIs and most literals are ASCII, and every string
    // of every frame a hospital takes is checked here (a byte at a time it was ~5% of its CPU).
    if (text.size() - i >= 32) {
      std::uint64_t words[4];
      std::memcpy(words, text.data() + i, 32);
      if (((words[0] | words[1] | words[2] | words[3]) & 0x8080808080808080ull) == 0) {
        i += 32;
        continue;
      }
    }
    if (text.size() - i >= 8) {
      std::uint64_t word;
      std::memcpy(&word, text.data() + i, 8);
      if ((word & 0x8080808080808080ull) == 0) {
        i += 8;
        continue;
      }
    }
    if (static_cast<unsigned char>(text[i]) < 0x80) {
      ++i;
      continue;
    }
    const std::size_t n = detail::utf8_sequence_length(text, i);
    if (n == 0) return i;
    i += n;
  }
  return std::string_view::npos;
}

std::string with_replacement_characters(std::string_view text) {
  std::string out;
  out.reserve(text.size());
  for (std::size_t i = 0; i < text.size();) {
    const std::size_t n = static_cast<unsigned char>(text[i]) < 0x80 ? 1 : detail::utf8_sequence_length(text, i);
    if (n == 0) {
      out += "\xEF\xBF\xBD";
      ++i;
      continue;
    }
    out.append(text.substr(i, n));
    i += n;
  }
  return out;
}

}  // namespace tahvel::node
