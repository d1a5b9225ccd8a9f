// String escaping for N-Triples and JSON output; see escape.h.
#include "escape.h"

namespace tahvel::node::detail {

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

void append_uchar(std::string& out, unsigned char c, EscapeDialect dialect) {
  const char* hex = dialect == EscapeDialect::json ? "0123456789abcdef" : "0123456789ABCDEF";
  out += "\\u00";
  out += hex[c >> 4];
  out += hex[c & 0xF];
}

std::size_t append_non_ascii(std::string& out, std::string_view text, std::size_t i,
                             EscapeDialect dialect) {
  const std::size_t n = utf8_sequence_length(text, i);
  if (n == 0) {
    out += dialect == EscapeDialect::json ? "\\ufffd" : "\\uFFFD";
    return i + 1;
  }
  const std::string_view seq = text.substr(i, n);
  if (dialect == EscapeDialect::json && (seq == "\xE2\x80\xA8" || seq == "\xE2\x80\xA9"))
    out += seq[2] == '\xA8' ? "\\u2028" : "\\u2029";
  else
    out += seq;
  return i + n;
}

void append_escaped(std::string& out, std::string_view text, EscapeDialect dialect) {
  for (std::size_t i = 0; i < text.size();) {
    const auto c = static_cast<unsigned char>(text[i]);
    if (c >= 0x80) {
      i = append_non_ascii(out, text, i, dialect);
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
          append_uchar(out, c, dialect);
        else
          out += static_cast<char>(c);
    }
    ++i;
  }
}

}  // namespace tahvel::node::detail
