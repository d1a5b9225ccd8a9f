// Private to uri/: the one place that talks to uriparser. Everything RFC 3986 (syntax, §5
// resolution, §6 normalisation) is uriparser's; this wrapper adds ownership, RFC 3987 non-ASCII
// characters, and error positions that refer to the caller's text.
#pragma once

#include <uriparser/Uri.h>

#include <cstddef>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "text.h"

namespace tahvel::uri::detail {

// An IRI reference parsed by uriparser. uriparser reads ASCII only, so a text with non-ASCII
// characters is parsed in an encoded ASCII form and decoded again by to_string() (see the .cpp).
// Neither copyable nor movable: uriparser's structure points into `ascii_`, and a resolved
// ParsedUri points into the base and reference it came from, which must outlive it.
class ParsedUri {
 public:
  ParsedUri() = default;
  ~ParsedUri();
  ParsedUri(const ParsedUri&) = delete;
  ParsedUri& operator=(const ParsedUri&) = delete;

  // Parses `text` as an IRI reference (relative or absolute). `encode` selects the encoded
  // ASCII form; it is required when `text` has non-ASCII bytes, and the base and reference of
  // one resolution must agree on it. The failure's position is an offset into `text`.
  std::optional<Failure> parse(std::string_view text, bool encode);

  // Makes this `reference` resolved against the absolute `base` (RFC 3986 §5.2.2, strict).
  // Precondition: this is empty, both arguments parsed with the same `encode`. False on failure.
  bool resolve(const ParsedUri& base, const ParsedUri& reference);

  bool has_scheme() const;

  // Where in the parsed text ":port" is when it is its scheme's default (http 80, https 443,
  // ws 80, wss 443) or empty: [begin, end) of the text to drop for RFC 3986 §6.2.3's
  // scheme-based normal form ("http://h:80/x" is "http://h/x"). Nothing otherwise.
  std::optional<std::pair<std::size_t, std::size_t>> default_port() const;

  // RFC 3986 §6.2.2 syntax-based normalisation, in place. False when out of memory.
  bool normalize();

  // The IRI as text, non-ASCII characters decoded back to UTF-8; empty only when out of memory.
  std::string to_string() const;

 private:
  std::size_t origin(std::size_t ascii_pos) const;
  void keep_path_out_of_authority(std::string& text) const;
  void keep_ip6_literal_as_written(std::string& text) const;

  std::string ascii_;                // what uriparser parsed
  std::vector<std::size_t> origin_;  // encoded form only: ascii_[i] came from text[origin_[i]]
  UriUriA uri_{};
  bool live_ = false;     // uri_ has members to free
  bool encoded_ = false;  // ascii_ is the encoded form, so output must be decoded
};

// `text` as an absolute IRI in RFC 3986 §6 normal form (syntax-based, and a default port
// dropped), or where and why it is not one.
Expected<std::string, Failure> normal_form(std::string_view text);

}  // namespace tahvel::uri::detail
