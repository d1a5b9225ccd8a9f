// UTF-8 decoding, RFC 3987 character classes and error wording for uri/. Inputs are IRIs and
// ids, tens to hundreds of bytes; clarity wins over speed here.
#include "text.h"

#include <uninorm.h>

#include <cstdio>
#include <cstdlib>
#include <memory>

namespace tahvel::uri::detail {
namespace {

// Long inputs are cut in messages so one bad IRI cannot flood a log line.
constexpr std::size_t kMaxQuoted = 200;

bool is_continuation(unsigned char byte) { return (byte & 0xC0) == 0x80; }

std::string hex_byte(unsigned char byte) {
  char buf[8];
  std::snprintf(buf, sizeof buf, "0x%02X", byte);
  return buf;
}

std::string code_point_name(char32_t c) {
  char buf[16];
  std::snprintf(buf, sizeof buf, "U+%04X", static_cast<unsigned>(c));
  return buf;
}

// Appends `input` to `out` with everything that could break a line or a terminal escaped.
void append_printable(std::string& out, std::string_view input) {
  for (std::size_t i = 0; i < input.size();) {
    auto byte = static_cast<unsigned char>(input[i]);
    if (byte >= 0x80) {
      CodePoint cp = decode_utf8(input, i);
      if (cp.length != 0 && cp.value >= 0xA0) {
        out.append(input.substr(i, cp.length));
        i += cp.length;
        continue;
      }
    }
    if (byte < 0x20 || byte >= 0x7F) {
      char buf[8];
      std::snprintf(buf, sizeof buf, "\\x%02X", byte);
      out += buf;
    } else {
      out += static_cast<char>(byte);
    }
    ++i;
  }
}

}  // namespace

CodePoint decode_utf8(std::string_view text, std::size_t pos) {
  auto lead = static_cast<unsigned char>(text[pos]);
  if (lead < 0x80) return {lead, 1};
  std::size_t length = lead >= 0xF0 ? 4 : lead >= 0xE0 ? 3 : lead >= 0xC0 ? 2 : 0;
  if (length == 0 || lead > 0xF4 || pos + length > text.size()) return {};
  char32_t value = lead & (0x7F >> length);
  for (std::size_t k = 1; k < length; ++k) {
    auto byte = static_cast<unsigned char>(text[pos + k]);
    if (!is_continuation(byte)) return {};
    value = (value << 6) | (byte & 0x3F);
  }
  static constexpr char32_t kMinimum[] = {0, 0, 0x80, 0x800, 0x10000};
  bool overlong = value < kMinimum[length];
  bool surrogate = value >= 0xD800 && value <= 0xDFFF;
  if (overlong || surrogate || value > 0x10FFFF) return {};
  return {value, length};
}

bool is_iri_char(char32_t c) {
  // RFC 3987 §2.2: ucschar, then iprivate. Planes 1-14 exclude their last two code points,
  // and plane 14 starts at E1000.
  if (c >= 0xA0 && c <= 0xD7FF) return true;
  if (c >= 0xF900 && c <= 0xFDCF) return true;
  if (c >= 0xFDF0 && c <= 0xFFEF) return true;
  if (c >= 0x10000 && c <= 0xEFFFD) return (c & 0xFFFF) <= 0xFFFD && !(c >= 0xE0000 && c < 0xE1000);
  if (c >= 0xE000 && c <= 0xF8FF) return true;
  if (c >= 0xF0000 && c <= 0x10FFFD) return (c & 0xFFFF) <= 0xFFFD;
  return false;
}

bool has_non_ascii(std::string_view text) {
  for (char ch : text) {
    if (static_cast<unsigned char>(ch) >= 0x80) return true;
  }
  return false;
}

std::optional<std::string> nfc_if_different(std::string_view text) {
  if (!has_non_ascii(text)) return std::nullopt;
  std::size_t length = 0;
  std::unique_ptr<uint8_t, decltype(&std::free)> nfc(
      u8_normalize(UNINORM_NFC, reinterpret_cast<const uint8_t*>(text.data()), text.size(), nullptr, &length),
      &std::free);
  if (!nfc) return std::nullopt;  // out of memory, or not UTF-8: the callers have checked that
  std::string_view normal(reinterpret_cast<const char*>(nfc.get()), length);
  if (normal == text) return std::nullopt;
  return std::string(normal);
}

std::string unexpected_at(std::string_view input, std::size_t position) {
  if (position >= input.size()) return "unexpected end of input";
  auto byte = static_cast<unsigned char>(input[position]);
  if (byte < 0x20 || byte == 0x7F) return "unexpected control character " + hex_byte(byte);
  if (byte < 0x80) return std::string("unexpected character '") + static_cast<char>(byte) + "'";
  CodePoint cp = decode_utf8(input, position);
  if (cp.length == 0) return "invalid UTF-8 byte " + hex_byte(byte);
  if (cp.value < 0xA0) return "unexpected character " + code_point_name(cp.value);
  return "unexpected character '" + std::string(input.substr(position, cp.length)) + "' (" +
         code_point_name(cp.value) + ")";
}

IriError make_error(std::string_view what, std::string_view input, const Failure& failure) {
  std::string message(what);
  message += " '";
  if (input.size() > kMaxQuoted) {
    append_printable(message, input.substr(0, kMaxQuoted));
    message += "...";
  } else {
    append_printable(message, input);
  }
  message += "' at position " + std::to_string(failure.position) + ": ";
  append_printable(message, failure.cause);
  return {std::move(message), failure.position};
}

}  // namespace tahvel::uri::detail
