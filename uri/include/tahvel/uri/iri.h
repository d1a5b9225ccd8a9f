// IRIs for Tahvel: parsing and normalisation (RFC 3986 §6, through uriparser), resolution of
// references, derivation of agent and child-node IRIs, the "is X under Y" test used by routing
// and authorisation, and CURIE (prefix) expansion.
//
// Every function is pure and thread-safe. Errors are values: an invalid IRI gives an IriError
// whose `position` is the 0-based byte offset in the input where parsing stopped.
#pragma once

#include <cstddef>
#include <map>
#include <string>
#include <string_view>

#include "tahvel/uri/expected.h"

namespace tahvel::uri {

struct IriError {
  std::string message;   // one line, names the cause and the position, e.g.
                         // "invalid IRI 'http://a b' at position 8: unexpected character ' '"
  std::size_t position;  // 0-based byte offset into the input where the error was found
};

template <class T>
using IriResult = Expected<T, IriError>;

// Parses `text` as an absolute IRI (scheme required) and returns its RFC 3986 §6 syntax-based
// normal form: lower-case scheme and host, upper-case percent-encoding hex digits, decoded
// unreserved characters, removed dot segments; and, scheme-based (§6.2.3), an empty port or
// the scheme's default one (http and ws 80, https and wss 443) dropped. Non-ASCII characters
// (RFC 3987) are kept as is.
IriResult<std::string> normalize(std::string_view text);

// True when `text` parses as an absolute IRI.
bool is_valid(std::string_view text);

// Resolves `reference` (relative or absolute) against the absolute IRI `base` (RFC 3986 §5.2)
// and normalises the result.
IriResult<std::string> resolve(std::string_view base, std::string_view reference);

// An id's most bytes: files are named after ids (an agent's lock and log files, a node's state
// directory and its supervisor's files), and a file name has at most 255 bytes.
inline constexpr std::size_t kMaxIdBytes = 200;

// Checks an agent or child-node id: non-empty, at most kMaxIdBytes bytes, no '/', '?', '#',
// whitespace or control characters, not "." or ".." or "*" (<X>/* is X's whole subtree), and in
// Unicode normalization form C (composed characters: ids that look alike are byte for byte
// alike). Returns the id unchanged, or an error naming the position. child_id, agent_iri and
// child_node_iri check ids so too.
IriResult<std::string> check_id(std::string_view id);

// The IRI of a node that has no parent here (a store's `init`, a topology's root): parsed and
// normalised as by `normalize`, and in Unicode normalization form C as ids are (check_id), so
// that two node IRIs that look alike are one. The error names the code points that differ.
// A node IRI has no query or fragment and does not end in '/': its agents' and children's IRIs
// are the node's + "/" + id. An http(s) node IRI names a host (`http:///x` is refused).
IriResult<std::string> node_iri(std::string_view text);

// Agent IRI = node IRI + "/" + id (DESIGN §2). A trailing '/' on the node IRI is not doubled.
// Errors: invalid node IRI, invalid id.
IriResult<std::string> agent_iri(std::string_view node_iri, std::string_view id);

// A child node's IRI is derived exactly as an agent's: a child node is an agent of its parent.
IriResult<std::string> child_node_iri(std::string_view parent_iri, std::string_view child_id);

// True when `iri` equals `ancestor` or lies below it: `ancestor` followed by '/', '#' or '?'
// (or `ancestor` itself ends in '/' or '#'). Both are compared in normal form; an invalid IRI
// is under nothing. Examples: under("http://h/home1/ecg", "http://h/home1") is true;
// under("http://h/home10", "http://h/home1") is false.
bool is_under(std::string_view iri, std::string_view ancestor);

// The id of `iri` relative to its direct parent `parent` ("ecg" for http://h/home1/ecg under
// http://h/home1), or an error when `iri` is not exactly one segment below `parent`.
IriResult<std::string> child_id(std::string_view iri, std::string_view parent);

// `text` with every "%HH" decoded to its byte: what a browser shows of an IRI given
// percent-encoded ("kodu-%C3%B5ie" reads "kodu-õie"; to RDF they are two IRIs). For telling a
// user which IRI they meant, not for comparing IRIs.
std::string percent_decoded(std::string_view text);

// Prefix table for CURIEs ("sosa:Observation"). Prefix names follow Turtle's PN_PREFIX
// (may be empty: ":x").
class PrefixMap {
 public:
  // Adds or replaces a prefix. Errors: invalid prefix name, namespace not an absolute IRI.
  Expected<void, IriError> add(std::string_view prefix, std::string_view namespace_iri);

  // Expands "p:local" to namespace + local. Input in angle brackets ("<http://x>") is returned
  // without them; an input that is already an absolute IRI whose scheme is not a known prefix is
  // returned normalised. Errors: unknown prefix (message names it), invalid result IRI.
  IriResult<std::string> expand(std::string_view curie_or_iri) const;

  // The shortest CURIE for `iri` whose local part is a valid Turtle PN_LOCAL, or `iri` itself.
  // `iri` is matched as written (namespaces are held normalised): expand() of the CURIE gives
  // back `iri` exactly, so an IRI not in normal form is returned as it is.
  std::string compact(std::string_view iri) const;

  const std::map<std::string, std::string>& entries() const { return entries_; }

  // rdf, rdfs, xsd, owl, sosa, ssn, prov, geo, tv (Tahvel's own vocabulary).
  static PrefixMap standard();

 private:
  std::map<std::string, std::string> entries_;
};

// Tahvel's vocabulary namespace.
inline constexpr std::string_view kTahvelNs = "https://w3id.org/tahvel#";

}  // namespace tahvel::uri
