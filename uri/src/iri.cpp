// IRI normalisation, resolution, and the node/agent hierarchy built on IRIs: deriving a child's
// IRI from its parent's, and deciding whether one IRI lies under another. Routing and
// authorisation call is_under and child_id on every message, so both compare normal forms:
// "http://H/home1/./ecg" must not escape a rule written for "http://h/home1", and a sibling
// sharing a string prefix ("home10" next to "home1") must never count as a child.
#include "tahvel/uri/iri.h"

#include <algorithm>
#include <array>
#include <charconv>
#include <cstdio>
#include <string>

#include "parsed_uri.h"
#include "text.h"

namespace tahvel::uri {
namespace {

using detail::Failure;
using detail::make_error;
using detail::normal_form;

constexpr std::string_view kInvalidIri = "invalid IRI";

// Unicode White_Space characters outside ASCII; ASCII whitespace is caught as control or ' '.
bool is_unicode_space(char32_t c) {
  return c == 0x85 || c == 0xA0 || c == 0x1680 || (c >= 0x2000 && c <= 0x200A) || c == 0x2028 ||
         c == 0x2029 || c == 0x202F || c == 0x205F || c == 0x3000;
}

bool forbidden_in_id(char32_t c) {
  bool control = c < 0x20 || (c >= 0x7F && c <= 0x9F);
  bool separator = c == '/' || c == '?' || c == '#';
  return control || separator || c == ' ' || is_unicode_space(c);
}

// "U+0065 U+0301" for well-formed UTF-8 `text`.
std::string code_points(std::string_view text) {
  std::string out;
  for (std::size_t pos = 0; pos < text.size();) {
    detail::CodePoint cp = detail::decode_utf8(text, pos);
    if (cp.length == 0) break;
    char buf[16];
    std::snprintf(buf, sizeof buf, "%sU+%04X", out.empty() ? "" : " ", static_cast<unsigned>(cp.value));
    out += buf;
    pos += cp.length;
  }
  return out;
}

// Why `text` is not in Unicode normalization form C, or nothing when it is. Two names that
// look the same must name the same node or agent: "café" with a combining accent (as some
// editors and file systems write it) and "café" precomposed are different bytes, so only the
// composed form (NFC, RFC 3987 §5.3.2.2) names one. `what` and `whats` word the message.
std::optional<Failure> nfc_failure(std::string_view text, std::string_view what, std::string_view whats) {
  auto nfc = detail::nfc_if_different(text);
  if (!nfc) return std::nullopt;
  // The part that differs, by code point: on screen both forms look the same.
  std::size_t at = 0, tail = 0;
  while (at < text.size() && at < nfc->size() && text[at] == (*nfc)[at]) ++at;
  while (at > 0 && detail::decode_utf8(text, at).length == 0) --at;  // a character's start
  while (tail < text.size() - at && tail < nfc->size() - at &&
         text[text.size() - 1 - tail] == (*nfc)[nfc->size() - 1 - tail])
    ++tail;
  while (tail > 0 && detail::decode_utf8(text, text.size() - tail).length == 0) --tail;
  return Failure{at, "not in Unicode normalization form C (NFC): " + code_points(text.substr(at, text.size() - tail - at)) +
                         " is composed " + code_points(std::string_view(*nfc).substr(at, nfc->size() - tail - at)) +
                         " ('" + *nfc + "'); " + std::string(what) + " is written composed, so that " +
                         std::string(whats) + " that look alike are one"};
}

// Why `id` cannot name one path segment below a node, or nothing when it can.
std::optional<Failure> id_failure(std::string_view id) {
  if (id.empty()) return Failure{0, "an id cannot be empty"};
  if (id == "." || id == "..") return Failure{0, "'.' and '..' are path steps, not ids"};
  // A child "*" would have the IRI <parent>/*, which addresses the parent's whole subtree.
  if (id == "*") return Failure{0, "'*' is not an id: <X>/* addresses the whole subtree of node X (docs/protocol.md P11)"};
  // Files are named after ids (an agent's lock and log, a node's state directory): a longer one
  // made an agent that could not start, over and over ("File name too long").
  if (id.size() > kMaxIdBytes)
    return Failure{kMaxIdBytes, "an id is at most " + std::to_string(kMaxIdBytes) + " bytes (files are named after ids); this one has " +
                                    std::to_string(id.size())};
  for (std::size_t pos = 0; pos < id.size();) {
    detail::CodePoint cp = detail::decode_utf8(id, pos);
    if (cp.length == 0 || forbidden_in_id(cp.value)) {
      return Failure{pos, detail::unexpected_at(id, pos) + " in an id"};
    }
    pos += cp.length;
  }
  return nfc_failure(id, "an id", "ids");
}

// is_under for texts already in normal form.
bool normal_is_under(std::string_view iri, std::string_view ancestor) {
  if (!iri.starts_with(ancestor)) return false;
  if (iri.size() == ancestor.size()) return true;
  char last = ancestor.back();
  if (last == '/' || last == '#') return true;
  char next = iri[ancestor.size()];
  return next == '/' || next == '#' || next == '?';
}

std::size_t common_prefix(std::string_view a, std::string_view b) {
  std::size_t n = 0;
  while (n < a.size() && n < b.size() && a[n] == b[n]) ++n;
  return n;
}

// child_id for texts already in normal form. Positions refer to `iri`'s normal form, which is
// the caller's text whenever it was already normal (the usual case for stored IRIs).
Expected<std::string, Failure> normal_child_id(std::string_view iri, std::string_view parent) {
  std::string below = "not one path segment below '" + std::string(parent) + "'";
  if (!normal_is_under(iri, parent)) {
    return unexpected(
        Failure{common_prefix(iri, parent), "not under '" + std::string(parent) + "'"});
  }
  std::size_t start = parent.size();
  if (parent.back() != '/') {
    if (start == iri.size() || iri[start] != '/') return unexpected(Failure{start, below});
    ++start;
  }
  std::string_view rest = iri.substr(start);
  if (rest.empty()) return unexpected(Failure{start, below + ": nothing follows it"});
  if (auto failure = id_failure(rest)) {
    return unexpected(Failure{start + failure->position, below + ": " + failure->cause});
  }
  return std::string(rest);
}

// The error for an id that made the IRI it was appended to (at `id_start`) invalid.
IriError id_error(std::string_view id, std::size_t id_start, Failure failure) {
  failure.position = failure.position >= id_start ? failure.position - id_start : 0;
  return make_error("invalid id", id, failure);
}

// Shared by agent_iri and child_node_iri: `parent` + "/" + `id`, in normal form.
IriResult<std::string> derive_child(std::string_view parent_iri, std::string_view id,
                                    std::string_view parent_kind) {
  std::string kind = "invalid " + std::string(parent_kind) + " IRI";
  auto parent = normal_form(parent_iri);
  if (!parent) return unexpected(make_error(kind, parent_iri, parent.error()));
  // A child under a query or fragment would not be a path below its parent.
  if (auto cut = parent_iri.find_first_of("?#"); cut != std::string_view::npos) {
    return unexpected(
        make_error(kind, parent_iri, {cut, "a query or fragment cannot have children"}));
  }
  if (auto failure = id_failure(id)) return unexpected(make_error("invalid id", id, *failure));

  std::string joined = *parent;
  if (joined.back() != '/') joined += '/';
  std::size_t id_start = joined.size();
  joined += id;
  auto child = normal_form(joined);
  if (!child) return unexpected(id_error(id, id_start, child.error()));
  // Percent-encoded dots ("%2E%2E") pass id_failure but normalise into a path step.
  if (auto below = normal_child_id(*child, *parent); !below) {
    return unexpected(
        make_error("invalid id", id, {0, "it normalises to '" + *child + "', not a child"}));
  }
  return std::move(*child);
}

}  // namespace

IriResult<std::string> normalize(std::string_view text) {
  auto normal = normal_form(text);
  if (!normal) return unexpected(make_error(kInvalidIri, text, normal.error()));
  return std::move(*normal);
}

namespace {

bool is_unreserved(char c) {
  return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '-' || c == '.' ||
         c == '_' || c == '~';
}

// Prefixes up to a last '/' of IRIs that parsed with only unreserved characters after it, the
// last few, per thread. Sensor data names each observation by a fixed prefix and a counter
// (".../hrv/41"), and checking every new one with the full parser was a tenth of a hospital's
// ingest. Unreserved characters are allowed alike in a host, a path segment, a query and a
// fragment (RFC 3986 §3.2.2, §3.3, §3.4, §3.5), so whatever component the last '/' leaves them
// in, any other non-empty run of them after the same prefix parses too.
class ValidPrefixes {
 public:
  bool contains(std::string_view prefix) const {
    for (const std::string& p : prefixes_)
      if (p == prefix) return true;
    return false;
  }
  void add(std::string_view prefix) { prefixes_[next_++ % prefixes_.size()].assign(prefix); }

 private:
  std::array<std::string, 16> prefixes_;
  std::size_t next_ = 0;
};

}  // namespace

bool is_valid(std::string_view text) {
  const std::size_t cut = text.rfind('/');
  std::string_view prefix;
  if (cut != std::string_view::npos && cut + 1 < text.size() &&
      std::all_of(text.begin() + static_cast<std::ptrdiff_t>(cut) + 1, text.end(), is_unreserved))
    prefix = text.substr(0, cut + 1);
  thread_local ValidPrefixes known;
  if (!prefix.empty() && known.contains(prefix)) return true;
  detail::ParsedUri uri;
  const bool valid = !uri.parse(text, detail::has_non_ascii(text)) && uri.has_scheme();
  if (valid && !prefix.empty()) known.add(prefix);
  return valid;
}

IriResult<std::string> resolve(std::string_view base, std::string_view reference) {
  // Both sides must use the same form (see parsed_uri.cpp), whichever one needs encoding.
  bool encode = detail::has_non_ascii(base) || detail::has_non_ascii(reference);
  detail::ParsedUri base_uri;
  if (auto failure = base_uri.parse(base, encode)) {
    return unexpected(make_error("invalid base IRI", base, *failure));
  }
  if (!base_uri.has_scheme()) {
    return unexpected(make_error("invalid base IRI", base, {0, "no scheme: not an absolute IRI"}));
  }
  detail::ParsedUri reference_uri;
  if (auto failure = reference_uri.parse(reference, encode)) {
    return unexpected(make_error("invalid IRI reference", reference, *failure));
  }
  detail::ParsedUri resolved;  // points into base_uri and reference_uri: declared after them
  if (!resolved.resolve(base_uri, reference_uri) || !resolved.normalize()) {
    return unexpected(make_error("invalid IRI reference", reference, {0, "out of memory"}));
  }
  return resolved.to_string();
}

IriResult<std::string> check_id(std::string_view id) {
  if (auto failure = id_failure(id)) return unexpected(make_error("invalid id", id, *failure));
  // What only an IRI made of it shows: a percent-escape that is none ('%zz'), escaped dots that
  // normalise into a path step. Found here, `tahvel put --agent %zz` is a bad command line, not
  // a failure of the store's.
  if (auto child = derive_child("http://id.invalid", id, "node"); !child) return unexpected(child.error());
  return std::string(id);
}

IriResult<std::string> node_iri(std::string_view text) {
  auto normal = normal_form(text);
  if (!normal) return unexpected(make_error(kInvalidIri, text, normal.error()));
  if (auto failure = nfc_failure(text, "a node IRI", "node IRIs")) return unexpected(make_error(kInvalidIri, text, *failure));
  // Its agents' and children's IRIs are the node's + "/" + id: a store under an IRI that cannot
  // have them could hold nothing.
  if (auto cut = text.find_first_of("?#"); cut != std::string_view::npos)
    return unexpected(make_error(kInvalidIri, text, {cut, "a node IRI cannot have a query or fragment: its agents' IRIs are "
                                                         "the node's + \"/\" + their id"}));
  // RFC 9110 §4.2: an http(s) IRI names a host. Without one, `http:///x` would be a node that
  // nothing on a network can name the same way.
  for (std::string_view scheme : {"http://", "https://"}) {
    if (!normal->starts_with(scheme)) continue;
    std::string_view authority = std::string_view(*normal).substr(scheme.size());
    authority = authority.substr(0, authority.find('/'));
    if (auto at = authority.rfind('@'); at != std::string_view::npos) authority.remove_prefix(at + 1);
    if (!authority.starts_with('[')) authority = authority.substr(0, authority.find(':'));
    if (authority.empty())
      return unexpected(make_error(kInvalidIri, text, {text.find("//") + 2, "an http(s) node IRI needs a host after \"//\""}));
  }
  if (normal->ends_with('/'))
    return unexpected(make_error(kInvalidIri, text, {text.size() - 1, "a node IRI cannot end in '/': its agents' and "
                                                                      "children's IRIs are the node's + \"/\" + their id; "
                                                                      "write it without the '/'"}));
  return std::move(*normal);
}

IriResult<std::string> agent_iri(std::string_view node_iri, std::string_view id) {
  return derive_child(node_iri, id, "node");
}

IriResult<std::string> child_node_iri(std::string_view parent_iri, std::string_view id) {
  return derive_child(parent_iri, id, "parent");
}

bool is_under(std::string_view iri, std::string_view ancestor) {
  auto normal_iri = normal_form(iri);
  auto normal_ancestor = normal_form(ancestor);
  return normal_iri && normal_ancestor && normal_is_under(*normal_iri, *normal_ancestor);
}

IriResult<std::string> child_id(std::string_view iri, std::string_view parent) {
  auto normal_iri = normal_form(iri);
  if (!normal_iri) return unexpected(make_error(kInvalidIri, iri, normal_iri.error()));
  auto normal_parent = normal_form(parent);
  if (!normal_parent)
    return unexpected(make_error("invalid parent IRI", parent, normal_parent.error()));
  auto id = normal_child_id(*normal_iri, *normal_parent);
  if (!id) return unexpected(make_error("IRI", iri, id.error()));
  return std::move(*id);
}

std::string percent_decoded(std::string_view text) {
  std::string out;
  for (std::size_t i = 0; i < text.size(); ++i) {
    unsigned value = 0;
    if (text[i] == '%' && i + 2 < text.size() &&
        std::from_chars(text.data() + i + 1, text.data() + i + 3, value, 16).ptr == text.data() + i + 3) {
      out.push_back(static_cast<char>(value));
      i += 2;
    } else {
      out.push_back(text[i]);
    }
  }
  return out;
}

}  // namespace tahvel::uri
