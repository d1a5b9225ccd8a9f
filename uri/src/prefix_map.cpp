// CURIE expansion and compaction with Turtle's name rules (PN_PREFIX, PN_LOCAL), for
// configuration files, the CLI and printing. A table holds a dozen prefixes; linear scans do.
#include <array>
#include <cassert>
#include <optional>
#include <vector>

#include "parsed_uri.h"
#include "tahvel/uri/iri.h"
#include "text.h"

namespace tahvel::uri {
namespace {

using detail::Failure;
using detail::make_error;
using detail::normal_form;

bool in(char32_t c, char32_t low, char32_t high) { return c >= low && c <= high; }

// Turtle PN_CHARS_BASE.
bool is_pn_chars_base(char32_t c) {
  return in(c, 'A', 'Z') || in(c, 'a', 'z') || in(c, 0xC0, 0xD6) || in(c, 0xD8, 0xF6) ||
         in(c, 0xF8, 0x2FF) || in(c, 0x370, 0x37D) || in(c, 0x37F, 0x1FFF) ||
         in(c, 0x200C, 0x200D) || in(c, 0x2070, 0x218F) || in(c, 0x2C00, 0x2FEF) ||
         in(c, 0x3001, 0xD7FF) || in(c, 0xF900, 0xFDCF) || in(c, 0xFDF0, 0xFFFD) ||
         in(c, 0x10000, 0xEFFFF);
}

bool is_pn_chars_u(char32_t c) { return is_pn_chars_base(c) || c == '_'; }

// Turtle PN_CHARS.
bool is_pn_chars(char32_t c) {
  return is_pn_chars_u(c) || c == '-' || in(c, '0', '9') || c == 0xB7 || in(c, 0x300, 0x36F) ||
         in(c, 0x203F, 0x2040);
}

// Why `name` is not a Turtle PN_PREFIX (the empty prefix is allowed), or nothing.
std::optional<Failure> prefix_failure(std::string_view name) {
  for (std::size_t pos = 0; pos < name.size();) {
    detail::CodePoint cp = detail::decode_utf8(name, pos);
    bool ok = cp.length != 0 &&
              (pos == 0 ? is_pn_chars_base(cp.value) : is_pn_chars(cp.value) || cp.value == '.');
    if (!ok) return Failure{pos, detail::unexpected_at(name, pos) + " in a prefix name"};
    pos += cp.length;
  }
  if (name.ends_with('.')) return Failure{name.size() - 1, "a prefix name cannot end with '.'"};
  return std::nullopt;
}

bool is_hex(char ch) {
  return in(static_cast<unsigned char>(ch), '0', '9') ||
         in(static_cast<unsigned char>(ch), 'A', 'F') ||
         in(static_cast<unsigned char>(ch), 'a', 'f');
}

// True when `local` is a Turtle PN_LOCAL written without backslash escapes (empty is allowed:
// "p:" names the namespace itself).
bool is_plain_pn_local(std::string_view local) {
  for (std::size_t pos = 0; pos < local.size();) {
    if (local[pos] == '%') {
      if (pos + 2 >= local.size() || !is_hex(local[pos + 1]) || !is_hex(local[pos + 2]))
        return false;
      pos += 3;
      continue;
    }
    detail::CodePoint cp = detail::decode_utf8(local, pos);
    if (cp.length == 0) return false;
    bool first_ok = is_pn_chars_u(cp.value) || cp.value == ':' || in(cp.value, '0', '9');
    bool later_ok = is_pn_chars(cp.value) || cp.value == '.' || cp.value == ':';
    if (!(pos == 0 ? first_ok : later_ok)) return false;
    pos += cp.length;
  }
  return !local.ends_with('.');
}

// A local part with Turtle's backslash escapes removed ("a\/b" -> "a/b"), and for each byte of
// it the offset of the byte it came from, so errors point into the caller's text.
struct Unescaped {
  std::string text;
  std::vector<std::size_t> origin;
};

Unescaped unescape_local(std::string_view curie, std::size_t start) {
  static constexpr std::string_view kEscapable = "_~.-!$&'()*+,;=/?#@%";
  Unescaped out;
  for (std::size_t pos = start; pos < curie.size(); ++pos) {
    bool escape = curie[pos] == '\\' && pos + 1 < curie.size() &&
                  kEscapable.find(curie[pos + 1]) != std::string_view::npos;
    if (escape) ++pos;
    out.text += curie[pos];
    out.origin.push_back(pos);
  }
  out.origin.push_back(curie.size());
  return out;
}

// Schemes that are recognised as IRIs without "//" when no prefix of that name is defined. Any
// other "name:rest" is taken as a CURIE, so a misspelt prefix is an error, not a new IRI.
bool is_known_opaque_scheme(std::string_view scheme) {
  static constexpr std::array<std::string_view, 8> kSchemes = {"urn",  "mailto", "tag", "did",
                                                               "data", "tel",    "geo", "about"};
  for (std::string_view known : kSchemes) {
    bool same = known.size() == scheme.size();
    for (std::size_t i = 0; same && i < known.size(); ++i) {
      same = known[i] == (scheme[i] | 0x20);  // ASCII lower case; schemes are ASCII
    }
    if (same) return true;
  }
  return false;
}

bool looks_like_iri(std::string_view text, std::size_t colon) {
  return text.substr(colon + 1).starts_with("//") || is_known_opaque_scheme(text.substr(0, colon));
}

IriResult<std::string> normalize_as(std::string_view what, std::string_view text) {
  auto normal = normal_form(text);
  if (!normal) return unexpected(make_error(what, text, normal.error()));
  return std::move(*normal);
}

// "<iri>" -> the IRI inside, normalised.
IriResult<std::string> expand_bracketed(std::string_view text) {
  if (!text.ends_with('>') || text.size() < 2) {
    return unexpected(make_error("invalid IRI", text, {text.size(), "missing '>'"}));
  }
  auto normal = normal_form(text.substr(1, text.size() - 2));
  if (!normal) {
    Failure failure = normal.error();
    failure.position += 1;
    return unexpected(make_error("invalid IRI", text, failure));
  }
  return std::move(*normal);
}

IriResult<std::string> expand_local(std::string_view curie, std::size_t colon,
                                    const std::string& ns) {
  Unescaped local = unescape_local(curie, colon + 1);
  auto normal = normal_form(ns + local.text);
  if (!normal) {
    Failure failure = normal.error();
    failure.position =
        failure.position >= ns.size() ? local.origin[failure.position - ns.size()] : colon + 1;
    return unexpected(make_error("invalid CURIE", curie, failure));
  }
  return std::move(*normal);
}

}  // namespace

Expected<void, IriError> PrefixMap::add(std::string_view prefix, std::string_view namespace_iri) {
  if (auto failure = prefix_failure(prefix)) {
    return unexpected(make_error("invalid prefix name", prefix, *failure));
  }
  // Stored in normal form so that compact() matches normalised IRIs.
  auto ns = normalize_as("invalid namespace IRI", namespace_iri);
  if (!ns) return unexpected(std::move(ns).error());
  entries_.insert_or_assign(std::string(prefix), std::move(*ns));
  return {};
}

IriResult<std::string> PrefixMap::expand(std::string_view curie_or_iri) const {
  std::string_view text = curie_or_iri;
  if (text.starts_with('<')) return expand_bracketed(text);
  std::size_t colon = text.find(':');
  if (colon == std::string_view::npos) {
    return unexpected(
        make_error("invalid CURIE", text, {text.size(), "no ':', so neither a CURIE nor an IRI"}));
  }
  if (auto it = entries_.find(std::string(text.substr(0, colon))); it != entries_.end()) {
    return expand_local(text, colon, it->second);
  }
  if (looks_like_iri(text, colon)) return normalize_as("invalid IRI", text);
  std::string cause = "unknown prefix '" + std::string(text.substr(0, colon)) + "'";
  return unexpected(make_error("invalid CURIE", text, {0, cause}));
}

std::string PrefixMap::compact(std::string_view iri) const {
  // Matched as written, not normalised: a CURIE must expand to the very IRI it stands for, or
  // two IRIs a store holds apart (case of the host, ":80") would print as one.
  std::string_view target = iri;
  std::optional<std::string> best;
  for (const auto& [prefix, ns] : entries_) {
    if (!target.starts_with(ns)) continue;
    std::string_view local = target.substr(ns.size());
    if (!is_plain_pn_local(local)) continue;
    // Ties go to the first prefix in map order, so the result does not depend on insertion.
    if (!best || prefix.size() + 1 + local.size() < best->size()) {
      best = prefix + ":" + std::string(local);
    }
  }
  return best ? *best : std::string(iri);
}

PrefixMap PrefixMap::standard() {
  static constexpr std::array<std::pair<std::string_view, std::string_view>, 9> kStandard = {{
      {"rdf", "http://www.w3.org/1999/02/22-rdf-syntax-ns#"},
      {"rdfs", "http://www.w3.org/2000/01/rdf-schema#"},
      {"xsd", "http://www.w3.org/2001/XMLSchema#"},
      {"owl", "http://www.w3.org/2002/07/owl#"},
      {"sosa", "http://www.w3.org/ns/sosa/"},
      {"ssn", "http://www.w3.org/ns/ssn/"},
      {"prov", "http://www.w3.org/ns/prov#"},
      {"geo", "http://www.opengis.net/ont/geosparql#"},
      {"tv", kTahvelNs},
  }};
  PrefixMap map;
  for (const auto& [prefix, ns] : kStandard) {
    [[maybe_unused]] auto added = map.add(prefix, ns);
    assert(added.has_value());
  }
  return map;
}

}  // namespace tahvel::uri
