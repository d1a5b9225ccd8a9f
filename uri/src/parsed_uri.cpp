// uriparser behind an owning C++ type, extended from URIs (ASCII) to IRIs (UTF-8).
//
// The encoded form. uriparser rejects bytes >= 0x80, so each non-ASCII character is written as
// percent-encoded UTF-8 ("é" -> "%C3%A9"), which uriparser accepts wherever RFC 3987 allows
// ucschar. On output those triplets are decoded back, so the caller's characters survive.
// To tell them apart from triplets the caller wrote (an RDF IRI "%C3%A9" is not the IRI "é"),
// the caller's own "%25" and "%80".."%FF" are escaped as "%25" + the two hex digits. uriparser
// never decodes "%25" and never creates triplets, so on output "%25HH" is the caller's "%HH" and
// any other high triplet is ours. Hex digits the caller wrote after an escaped '%' are hidden
// from uriparser, so the decoder upper-cases them as §6.2.2.1 asks.
// ASCII-only texts skip all this and reach uriparser unchanged.
#include "parsed_uri.h"

#include <cctype>

namespace tahvel::uri::detail {
namespace {

int hex_value(char ch) {
  if (ch >= '0' && ch <= '9') return ch - '0';
  if (ch >= 'a' && ch <= 'f') return ch - 'a' + 10;
  if (ch >= 'A' && ch <= 'F') return ch - 'A' + 10;
  return -1;
}

// The value of the triplet "%HH" at `pos`, or -1 when there is none.
int triplet_at(std::string_view text, std::size_t pos) {
  if (pos + 2 >= text.size() || text[pos] != '%') return -1;
  int high = hex_value(text[pos + 1]);
  int low = hex_value(text[pos + 2]);
  return high < 0 || low < 0 ? -1 : high * 16 + low;
}

char upper(char ch) { return static_cast<char>(std::toupper(static_cast<unsigned char>(ch))); }

void append_triplet(std::string& out, unsigned char byte) {
  static constexpr char kHex[] = "0123456789ABCDEF";
  out += '%';
  out += kHex[byte >> 4];
  out += kHex[byte & 0x0F];
}

struct Encoded {
  std::string ascii;
  std::vector<std::size_t> origin;
};

void append(Encoded& out, std::string_view piece, std::size_t from) {
  out.ascii.append(piece);
  out.origin.insert(out.origin.end(), piece.size(), from);
}

// The non-ASCII character at `pos` as triplets, or why it cannot be in an IRI.
std::optional<Failure> encode_character(std::string_view text, std::size_t& pos, Encoded& out) {
  CodePoint cp = decode_utf8(text, pos);
  if (cp.length == 0) return Failure{pos, unexpected_at(text, pos)};
  if (!is_iri_char(cp.value))
    return Failure{pos, unexpected_at(text, pos) + " (not allowed in an IRI)"};
  for (std::size_t k = 0; k < cp.length; ++k) {
    std::string triplet;
    append_triplet(triplet, static_cast<unsigned char>(text[pos + k]));
    append(out, triplet, pos);
  }
  pos += cp.length;
  return std::nullopt;
}

std::optional<Failure> encode(std::string_view text, Encoded& out) {
  for (std::size_t pos = 0; pos < text.size();) {
    if (static_cast<unsigned char>(text[pos]) >= 0x80) {
      if (auto failure = encode_character(text, pos, out)) return failure;
      continue;
    }
    int value = triplet_at(text, pos);
    if (value == 0x25 || value >= 0x80) {
      append(out, "%25", pos);
      append(out, text.substr(pos + 1, 1), pos + 1);
      append(out, text.substr(pos + 2, 1), pos + 2);
      pos += 3;
      continue;
    }
    append(out, text.substr(pos, 1), pos);
    ++pos;
  }
  out.origin.push_back(text.size());  // uriparser reports "end of input" one past the last byte
  return std::nullopt;
}

// uriparser's text back to the caller's form: upper-case hex in every triplet (uriparser
// lower-cases those in a host along with the host's letters, against §6.2.2.1), and in the
// encoded form, decode our triplets and unescape the caller's.
std::string finish(std::string_view ascii, bool encoded) {
  std::string out;
  out.reserve(ascii.size());
  for (std::size_t pos = 0; pos < ascii.size();) {
    int value = triplet_at(ascii, pos);
    if (value < 0) {
      out += ascii[pos++];
    } else if (encoded && value == 0x25 && pos + 4 < ascii.size()) {  // the caller's "%HH"
      out += '%';
      out += upper(ascii[pos + 3]);
      out += upper(ascii[pos + 4]);
      pos += 5;
    } else if (encoded && value >= 0x80) {  // one byte of a non-ASCII character
      out += static_cast<char>(value);
      pos += 3;
    } else {
      append_triplet(out, static_cast<unsigned char>(value));
      pos += 3;
    }
  }
  return out;
}

// uriparser stops one or two bytes after the '%' of a malformed triplet; point at the '%'.
std::optional<Failure> bad_triplet_before(std::string_view text, std::size_t pos) {
  for (std::size_t back = 1; back <= 2 && back <= pos; ++back) {
    std::size_t start = pos - back;
    if (text[start] == '%' && triplet_at(text, start) < 0) {
      std::string triplet(text.substr(start, 3));
      return Failure{start, "invalid percent-encoding '" + triplet + "'"};
    }
  }
  return std::nullopt;
}

}  // namespace

ParsedUri::~ParsedUri() {
  if (live_) uriFreeUriMembersA(&uri_);
}

std::size_t ParsedUri::origin(std::size_t ascii_pos) const {
  return encoded_ ? origin_[ascii_pos] : ascii_pos;
}

std::optional<Failure> ParsedUri::parse(std::string_view text, bool encode_text) {
  encoded_ = encode_text;
  if (encoded_) {
    Encoded encoded;
    if (auto failure = encode(text, encoded)) return failure;
    ascii_ = std::move(encoded.ascii);
    origin_ = std::move(encoded.origin);
  } else {
    ascii_.assign(text);
  }
  const char* first = ascii_.data();
  const char* error_pos = nullptr;
  int status = uriParseSingleUriExA(&uri_, first, first + ascii_.size(), &error_pos);
  if (status == URI_SUCCESS) {
    live_ = true;
    return std::nullopt;
  }
  if (status != URI_ERROR_SYNTAX || error_pos == nullptr) return Failure{0, "out of memory"};
  std::size_t pos = origin(static_cast<std::size_t>(error_pos - first));
  if (auto failure = bad_triplet_before(text, pos)) return failure;
  return Failure{pos, unexpected_at(text, pos)};
}

bool ParsedUri::resolve(const ParsedUri& base, const ParsedUri& reference) {
  encoded_ = base.encoded_;
  int status = uriAddBaseUriExA(&uri_, &reference.uri_, &base.uri_, URI_RESOLVE_STRICTLY);
  live_ = status == URI_SUCCESS;
  return live_;
}

bool ParsedUri::has_scheme() const { return live_ && uri_.scheme.first != nullptr; }

std::optional<std::pair<std::size_t, std::size_t>> ParsedUri::default_port() const {
  if (!live_ || !uri_.scheme.first || !uri_.portText.first) return std::nullopt;
  std::string scheme(uri_.scheme.first, uri_.scheme.afterLast);
  for (char& c : scheme) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  const std::string_view port(uri_.portText.first, static_cast<std::size_t>(uri_.portText.afterLast - uri_.portText.first));
  unsigned number = 0;
  for (char c : port) {
    if (c < '0' || c > '9' || number > 65535) return std::nullopt;
    number = number * 10 + static_cast<unsigned>(c - '0');
  }
  const unsigned usual = scheme == "http" || scheme == "ws" ? 80 : scheme == "https" || scheme == "wss" ? 443 : 0;
  if (!port.empty() && (usual == 0 || number != usual)) return std::nullopt;
  const std::size_t colon = static_cast<std::size_t>(uri_.portText.first - ascii_.data()) - 1;  // the ':' before it
  return std::pair(origin(colon), origin(static_cast<std::size_t>(uri_.portText.afterLast - ascii_.data())));
}

bool ParsedUri::normalize() { return uriNormalizeSyntaxA(&uri_) == URI_SUCCESS; }

std::string ParsedUri::to_string() const {
  int required = 0;
  if (uriToStringCharsRequiredA(&uri_, &required) != URI_SUCCESS) return {};
  std::string text(static_cast<std::size_t>(required) + 1, '\0');
  if (uriToStringA(text.data(), &uri_, required + 1, nullptr) != URI_SUCCESS) return {};
  text.resize(static_cast<std::size_t>(required));
  keep_ip6_literal_as_written(text);
  keep_path_out_of_authority(text);
  return finish(text, encoded_);
}

void ParsedUri::keep_ip6_literal_as_written(std::string& text) const {
  // uriparser writes an IPv6 host in full ("[::1]" becomes "[0000:...:0001]"), while the write
  // path keeps an IRI that needs no normalising as it is: the same node would have two IRIs,
  // and records written as "[::1]" would not be under it. The literal stays as written, in
  // lower case (hexadecimal digits are case-insensitive).
  if (uri_.hostData.ip6 == nullptr || uri_.hostText.first == nullptr) return;
  const std::size_t open = text.find('[');
  const std::size_t close = text.find(']', open);
  if (open == std::string::npos || close == std::string::npos) return;
  std::string literal(uri_.hostText.first, uri_.hostText.afterLast);
  for (char& c : literal) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  text.replace(open + 1, close - open - 1, literal);
}

void ParsedUri::keep_path_out_of_authority(std::string& text) const {
  // Removing dot segments can turn the path "/.//evil/x" of an IRI without authority into
  // "//evil/x", which would read back as the host "evil" (RFC 3986 §3.3 forbids such paths).
  // Keep a "/." in front, as the WHATWG URL standard does; the result is still a fixed point.
  bool has_authority = uri_.hostText.first != nullptr;
  if (has_authority || uri_.scheme.first == nullptr) return;
  std::size_t path_start = static_cast<std::size_t>(uri_.scheme.afterLast - uri_.scheme.first) + 1;
  if (text.compare(path_start, 2, "//") == 0) text.insert(path_start, "/.");
}

Expected<std::string, Failure> normal_form(std::string_view text) {
  ParsedUri uri;
  if (auto failure = uri.parse(text, has_non_ascii(text))) return unexpected(std::move(*failure));
  if (!uri.has_scheme()) return unexpected(Failure{0, "no scheme: not an absolute IRI"});
  // Rare, so the text without the port is parsed again rather than uriparser's owned ranges
  // edited: one node written "http://h:80/x" in one place and "http://h/x" in another was two.
  if (auto port = uri.default_port()) {
    std::string without(text.substr(0, port->first));
    without += text.substr(port->second);
    return normal_form(without);
  }
  if (!uri.normalize()) return unexpected(Failure{0, "out of memory"});
  return uri.to_string();
}

}  // namespace tahvel::uri::detail
