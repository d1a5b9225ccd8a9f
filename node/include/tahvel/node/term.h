// RDF 1.1 terms, triples and items as values. These are plain owning types: they carry no
// reference into any store and stay valid as long as the caller keeps them.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace tahvel::node {

namespace xsd {
inline constexpr std::string_view kString = "http://www.w3.org/2001/XMLSchema#string";
inline constexpr std::string_view kInteger = "http://www.w3.org/2001/XMLSchema#integer";
inline constexpr std::string_view kDecimal = "http://www.w3.org/2001/XMLSchema#decimal";
inline constexpr std::string_view kDouble = "http://www.w3.org/2001/XMLSchema#double";
inline constexpr std::string_view kBoolean = "http://www.w3.org/2001/XMLSchema#boolean";
inline constexpr std::string_view kDateTime = "http://www.w3.org/2001/XMLSchema#dateTime";
inline constexpr std::string_view kBase64Binary = "http://www.w3.org/2001/XMLSchema#base64Binary";
}  // namespace xsd
inline constexpr std::string_view kRdfLangString =
    "http://www.w3.org/1999/02/22-rdf-syntax-ns#langString";
inline constexpr std::string_view kRdfType = "http://www.w3.org/1999/02/22-rdf-syntax-ns#type";

enum class TermKind : std::uint8_t { iri = 1, blank = 2, literal = 3 };

struct Term {
  TermKind kind = TermKind::iri;
  std::string value;     // the IRI, the blank-node label (without "_:") or the lexical form
  std::string datatype;  // literals: datatype IRI; empty means xsd:string (or rdf:langString
                         // when `language` is set)
  std::string language;  // literals: BCP 47 language tag, lower-cased; empty if none

  static Term iri(std::string iri) { return {TermKind::iri, std::move(iri), {}, {}}; }
  static Term blank(std::string label) { return {TermKind::blank, std::move(label), {}, {}}; }
  static Term literal(std::string lexical, std::string datatype = {}) {
    return {TermKind::literal, std::move(lexical), std::move(datatype), {}};
  }
  static Term lang_literal(std::string lexical, std::string language) {
    return {TermKind::literal, std::move(lexical), {}, std::move(language)};
  }
  static Term integer(std::int64_t v) { return literal(std::to_string(v), std::string(xsd::kInteger)); }

  bool is_iri() const { return kind == TermKind::iri; }
  bool is_blank() const { return kind == TermKind::blank; }
  bool is_literal() const { return kind == TermKind::literal; }
  // Datatype with the RDF 1.1 defaults applied (xsd:string, rdf:langString).
  std::string_view effective_datatype() const;

  // N-Triples form: <iri>, _:label, "lexical"^^<dt>, "lexical"@lang (xsd:string omitted).
  std::string to_ntriples() const;

  friend bool operator==(const Term&, const Term&) = default;
};

// RDF terms are Unicode strings, stored as UTF-8. The offset of the first byte of `text` that
// does not begin a well-formed UTF-8 sequence (RFC 3629: no overlong forms, surrogates or code
// points past U+10FFFF), or npos when there is none. A store refuses terms with one.
std::size_t ill_formed_utf8_at(std::string_view text) noexcept;
// `text` with each such byte as U+FFFD: for text from outside (a program's output, a peer's
// message) that is to be stored or printed.
std::string with_replacement_characters(std::string_view text);

struct Triple {
  Term s, p, o;
  friend bool operator==(const Triple&, const Triple&) = default;
};

// An item: triples written together, atomically (DESIGN §2). Blank nodes are local to the item
// and are renamed on write so that two items never share one. Also the item builder:
//   Item item;
//   item.add(Term::blank("o"), Term::iri(std::string(kRdfType)), Term::iri(sosa + "Observation"))
//       .add(Term::blank("o"), Term::iri(sosa + "hasSimpleResult"), Term::integer(72));
struct Item {
  std::vector<Triple> triples;
  std::string context;                      // IRI of addressee or data group; empty for none
  bool persistent = false;                  // never expires by ring or time-to-live
  std::optional<std::int64_t> asserted_at;  // ns since the epoch when the facts held;
                                            // default: the stored-at time
  // How long the facts held from asserted_at, ns: a second of ECG covers a second. 0: an
  // instant. A time-range query takes an item whose span overlaps the range (Pattern::since).
  std::int64_t span = 0;

  Item& add(Term s, Term p, Term o) {
    triples.push_back({std::move(s), std::move(p), std::move(o)});
    return *this;
  }
};

}  // namespace tahvel::node
