// RDF syntax in and out through serd (DESIGN §3 "Formats"): N-Triples and Turtle are read by
// serd's reader and written by serd's writer; only JSON (no serd support) is written here.
//
// Workload: documents from the CLI (`tahvel put`/`load`, up to a few MB), single terms from the
// C API, and record streams for `dump`/`tail`. Correct positions in error messages matter more
// than the last few percent of parse speed.
//
// Decisions and the serd 0.30 behaviour they work around:
//  - serd reads the whole text as one string. Only when that fails is it read a second time, one
//    byte at a time through a source callback, so that we know the offset of the byte serd is
//    looking at when it fails again at the same place (a third of the speed, on errors only).
//    Error positions come from that offset rather than from SerdError: serd 0.30 counts columns
//    from 1 on the first line and from 0 on the others. Ours are 1-based, in code points.
//  - serd 0.30's reader hands CURIEs and relative IRIs to the sinks as written. CURIEs are
//    expanded with a SerdEnv holding the prefixes; relative IRIs are resolved by uri::resolve
//    (RFC 3986 §5.2, which serd does only partly: it keeps "g/../h"); with no base IRI they are
//    syntax errors.
//  - Blank-node labels are serd's: as written, except that serd's Turtle reader renames a label
//    "b<digit>..." to "B<digit>..." so that it cannot meet the labels it generates for [] and
//    lists ("b1", "b2", ...). The same reader merges "B1" and "b1" when "B1" comes first, so
//    the Turtle writer never writes a label that starts "B<digit>": it writes "x" + label for
//    labels matching x*B<digit>... (one-to-one, and the store's own labels, "b<n>", stay as
//    they are). A Turtle document that holds both "b1" and "B1" is refused by serd.
//  - serd's Turtle writer writes xsd:integer, xsd:boolean and xsd:decimal literals bare (72,
//    true, 1.5) without checking the lexical form, so "1"^^xsd:boolean would read back as an
//    integer and "abc"^^xsd:integer would not read back at all. Those literals get their
//    datatype as a CURIE, which serd writes verbatim (binding an xsd prefix if none is bound).
#include "tahvel/node/format.h"

#include "escape.h"

#include <serd/serd.h>

#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cstdarg>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <exception>
#include <iostream>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace tahvel::node {

namespace {

constexpr std::string_view kXsdNs = "http://www.w3.org/2001/XMLSchema#";

std::string_view view_of(const SerdNode* node) {
  if (node == nullptr || node->buf == nullptr) return {};
  return {reinterpret_cast<const char*>(node->buf), node->n_bytes};
}

std::string_view view_of(const SerdChunk& chunk) {
  if (chunk.buf == nullptr) return {};
  return {reinterpret_cast<const char*>(chunk.buf), chunk.len};
}

// A serd node over `text` (which must outlive it). Built by hand rather than with
// serd_node_from_substring, which stops at an embedded NUL byte.
//
// The flags decide whether serd's Turtle writer uses a long string ("""..."""). serd 0.30 cannot
// read back some long strings it writes with quotes in them (a value ending in "" comes out as
// """a"\"""" which its reader refuses), so only quote-free multi-line text gets the long form;
// everything else is a short string with escapes, which both sides handle.
SerdNode make_node(SerdType type, const std::string& text) {
  SerdNode node{reinterpret_cast<const uint8_t*>(text.c_str()), text.size(), 0, 0, type};
  bool newline = false, quote = false;
  for (const char c : text) {
    if ((static_cast<unsigned char>(c) & 0xC0) != 0x80) ++node.n_chars;
    newline = newline || c == '\n' || c == '\r';
    quote = quote || c == '"';
  }
  if (newline && !quote) node.flags = SERD_HAS_NEWLINE;
  return node;
}

// RFC 3986 scheme ":" at the start: ALPHA *( ALPHA / DIGIT / "+" / "-" / "." ) ":".
bool has_scheme(std::string_view iri) {
  const auto alpha = [](char c) { return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z'); };
  if (iri.empty() || !alpha(iri[0])) return false;
  for (std::size_t i = 1; i < iri.size(); ++i) {
    const char c = iri[i];
    if (c == ':') return true;
    if (!alpha(c) && !(c >= '0' && c <= '9') && c != '+' && c != '-' && c != '.') return false;
  }
  return false;
}

std::string ascii_lower(std::string_view text) {
  std::string out(text);
  for (char& c : out)
    if (c >= 'A' && c <= 'Z') c = static_cast<char>(c - 'A' + 'a');
  return out;
}

// printf-style formatting of a SerdError's message, without its trailing newline.
std::string format_serd_message(const SerdError& error) {
  std::string message;
  if (error.fmt != nullptr && error.args != nullptr) {
    va_list args;
    va_copy(args, *error.args);
    const int n = std::vsnprintf(nullptr, 0, error.fmt, args);
    va_end(args);
    if (n > 0) {
      message.resize(static_cast<std::size_t>(n) + 1);
      va_copy(args, *error.args);
      std::vsnprintf(message.data(), message.size(), error.fmt, args);
      va_end(args);
      message.resize(static_cast<std::size_t>(n));
    }
  }
  while (!message.empty() && (message.back() == '\n' || message.back() == '\r')) message.pop_back();
  if (message.empty()) message = reinterpret_cast<const char*>(serd_strerror(error.status));
  return message;
}

struct EnvDeleter {
  void operator()(SerdEnv* env) const { serd_env_free(env); }
};
struct ReaderDeleter {
  void operator()(SerdReader* reader) const { serd_reader_free(reader); }
};
struct WriterDeleter {
  void operator()(SerdWriter* writer) const { serd_writer_free(writer); }
};

// ---------------------------------------------------------------------------------------------
// Reading

// How deep blank node property lists `[ … ]` and collections `( … )` may nest in Turtle. serd
// reads each level with a frame of recursion, and 20,000 levels overflowed the stack of the
// process (put, load, an agent's store); real data nests a handful deep.
constexpr std::size_t kMaxTurtleNesting = 1000;

// The offset of the bracket that opens level kMaxTurtleNesting + 1 of `text` (Turtle), or npos.
// Brackets inside IRIs, strings and comments are not structure and are not counted; the scan
// need not check the syntax, which serd does after it.
std::size_t too_deep_at(std::string_view text) {
  std::size_t depth = 0;
  for (std::size_t i = 0; i < text.size(); ++i) {
    const char c = text[i];
    if (c == '\\') {  // an escape in a prefixed name (ex:a\#b, ex:f\(): the next character is a name's
      ++i;
    } else if (c == '[' || c == '(') {
      if (++depth > kMaxTurtleNesting) return i;
    } else if (c == ']' || c == ')') {
      if (depth > 0) --depth;
    } else if (c == '#') {
      while (i < text.size() && text[i] != '\n' && text[i] != '\r') ++i;
    } else if (c == '<') {
      while (i + 1 < text.size() && text[i + 1] != '>' && text[i + 1] != '\n') ++i;
      ++i;
    } else if (c == '"' || c == '\'') {
      const bool long_quote = i + 2 < text.size() && text[i + 1] == c && text[i + 2] == c;
      i += long_quote ? 3 : 1;
      for (; i < text.size(); ++i) {
        if (text[i] == '\\') {
          ++i;
        } else if (text[i] == c && (!long_quote || (i + 2 < text.size() && text[i + 1] == c && text[i + 2] == c))) {
          if (long_quote) i += 2;
          break;
        } else if (!long_quote && (text[i] == '\n' || text[i] == '\r')) {
          break;  // a short string ends at its line (serd says so, later)
        }
      }
    }
  }
  return std::string_view::npos;
}

class Parser {
 public:
  enum class Pass { fast, locate };  // locate: byte by byte, to know where an error is

  Parser(std::string_view text, const ParseOptions& options, Pass pass)
      : text_(text), options_(options), pass_(pass) {}

  // Pass::locate: where serd was when each triple came, in `*ends` (just past its object).
  void record_ends(std::vector<std::size_t>* ends) { ends_ = ends; }

  // "<source>:LINE:COL" of byte `at`.
  std::string position(std::size_t at) const {
    std::string out = located(at, "");
    out.resize(out.size() - 2);  // the ": " before a reason
    return out;
  }

  Result<std::vector<Triple>> run() {
    if (options_.format == Format::json)
      return fail(Errc::invalid_argument,
                  "cannot parse format json: parse_rdf reads ntriples or turtle");
    if (!options_.base_iri.empty() && !has_scheme(options_.base_iri))
      return fail(Errc::invalid_iri, "base IRI '" + options_.base_iri + "' is not an absolute IRI");
    // Nothing to read; serd would look past the end of an empty string (the copy below is
    // then the string's own buffer, whose bytes after the NUL are not set).
    if (text_.empty()) return std::vector<Triple>{};
    // serd takes a NUL byte for the end of its input and would silently stop there.
    if (const auto nul = text_.find('\0'); nul != std::string_view::npos)
      return fail(Errc::syntax, located(nul, "NUL byte in input"));
    // Before serd, whose own check names the byte after the bad one, at the next column (R1a).
    if (const auto bad = ill_formed_utf8_at(text_); bad != std::string_view::npos) {
      char byte[8];
      std::snprintf(byte, sizeof byte, "0x%02X", static_cast<unsigned char>(text_[bad]));
      return fail(Errc::syntax, located(bad, std::string("not UTF-8: byte ") + byte +
                                                 " does not begin a well-formed sequence (the input must be UTF-8)"));
    }

    if (options_.format == Format::turtle)
      if (const auto deep = too_deep_at(text_); deep != std::string_view::npos)
        return fail(Errc::syntax, located(deep, "[ ] and ( ) nested more than " + std::to_string(kMaxTurtleNesting) +
                                                    " levels deep (the parser's limit)"));

    base_ = options_.base_iri;
    env_.reset(serd_env_new(nullptr));
    if (options_.format == Format::turtle)
      for (const auto& [name, ns] : options_.prefixes.entries())
        serd_env_set_prefix_from_strings(env_.get(), reinterpret_cast<const uint8_t*>(name.c_str()),
                                         reinterpret_cast<const uint8_t*>(ns.c_str()));

    const SerdSyntax syntax = options_.format == Format::ntriples ? SERD_NTRIPLES : SERD_TURTLE;
    std::unique_ptr<SerdReader, ReaderDeleter> reader(
        serd_reader_new(syntax, this, nullptr, on_base, on_prefix, on_statement, nullptr));
    serd_reader_set_strict(reader.get(), true);  // lax mode skips bad lines and goes on
    serd_reader_set_error_sink(reader.get(), on_error, this);
    SerdStatus status = SERD_SUCCESS;
    if (pass_ == Pass::fast) {
      const std::string terminated(text_);  // serd wants a NUL-terminated string
      status = serd_reader_read_string(reader.get(),
                                       reinterpret_cast<const uint8_t*>(terminated.c_str()));
    } else {
      status = serd_reader_read_source(
          reader.get(), read_bytes, stream_error, this,
          reinterpret_cast<const uint8_t*>(options_.source_name.c_str()), 1);
    }

    if (pending_) std::rethrow_exception(pending_);
    if (error_) return fail(error_->code, std::move(error_->message));
    if (status > SERD_FAILURE)
      return fail(Errc::syntax,
                  located(offset(), reinterpret_cast<const char*>(serd_strerror(status))));
    return std::move(triples_);
  }

 private:
  // serd's byte source: one byte per call (page size 1), so delivered_ tracks serd's position.
  static size_t read_bytes(void* buf, size_t size, size_t count, void* stream) {
    auto& self = *static_cast<Parser*>(stream);
    const std::size_t n = std::min(size * count, self.text_.size() - self.delivered_);
    if (n == 0) {
      self.at_end_ = true;
      return 0;
    }
    std::memcpy(buf, self.text_.data() + self.delivered_, n);
    self.delivered_ += n;
    return n;
  }
  static int stream_error(void*) { return 0; }

  // Offset of the byte serd is looking at: serd reads one byte ahead of what it has consumed.
  std::size_t offset() const {
    if (at_end_ || delivered_ == 0) return at_end_ ? text_.size() : 0;
    return delivered_ - 1;
  }

  // "<source>:LINE:COL: reason" for byte `at`; line and column 1-based, column in code points.
  std::string located(std::size_t at, std::string_view reason) const {
    at = std::min(at, text_.size());
    // Lines end at "\n", "\r\n" and a lone "\r" (old Mac files; N-Triples' EOL, and editors, count
    // it), which counted as no line end put every error on line 1.
    std::size_t line = 1, line_start = 0;
    for (std::size_t i = 0; i < at; ++i)
      if (text_[i] == '\n' || (text_[i] == '\r' && (i + 1 >= text_.size() || text_[i + 1] != '\n'))) {
        ++line;
        line_start = i + 1;
      }
    const std::string_view line_text = text_.substr(line_start, at - line_start);
    std::size_t column = 1;
    for (const char c : line_text)
      if ((static_cast<unsigned char>(c) & 0xC0) != 0x80) ++column;
    std::string out = options_.source_name;
    out += ':';
    out += std::to_string(line);
    out += ':';
    out += std::to_string(column);
    out += ": ";
    out += reason;
    return out;
  }

  // serd's message, or what it means where serd's words mislead.
  std::string explained(std::string message) const {
    // serd reads the end of the input as the character -1.
    if (message.find("escape %FFFFFFFF") != std::string::npos) return "the input ends inside an IRI (no closing '>')";
    // A bare number or boolean, as Turtle writes it, where N-Triples wants a quoted literal (a
    // setting copied from a Turtle example into a .nt file): serd says only what it expected.
    if (options_.format == Format::ntriples) {
      const std::size_t at = offset();
      const std::string_view rest = at < text_.size() ? text_.substr(at) : std::string_view();
      const std::size_t end = std::min(rest.find_first_of(" \t\r\n"), rest.size());
      const std::string_view token = rest.substr(0, end);
      const bool number = !token.empty() && token.find_first_not_of("0123456789+-.eE") == std::string_view::npos &&
                          token.find_first_of("0123456789") != std::string_view::npos;
      if (number || token == "true" || token == "false")
        return message + " (N-Triples writes every literal in quotes, \"" + std::string(token) + "\"^^<http://www.w3.org/2001/XMLSchema#" +
               (!number                                               ? "boolean"
                : token.find_first_of("eE") != std::string_view::npos ? "double"
                : token.find('.') != std::string_view::npos           ? "decimal"
                                                                      : "integer") +
               ">; Turtle, a .ttl file or --format ttl, takes a bare " + std::string(token) + ")";
    }
    // A statement ended where its object goes ("ex:a ex:b ." or "ex:c , ."): serd reads the '.'
    // as the start of a decimal number and says only that a digit should follow.
    if (message.ends_with("expected digit")) {
      const std::size_t at = std::min(offset(), text_.size());
      const std::size_t dot = at > 0 && text_[at - 1] == '.' ? at - 1 : at < text_.size() && text_[at] == '.' ? at : std::string_view::npos;
      if (dot != std::string_view::npos && dot > 0 && std::string_view(" \t\r\n,;").find(text_[dot - 1]) != std::string_view::npos &&
          (dot + 1 >= text_.size() || std::string_view(" \t\r\n").find(text_[dot + 1]) != std::string_view::npos))
        return "an object is missing before this '.' (a statement is subject, predicate and object, then '.')";
    }
    // "x"@ with no tag: serd says only what it met.
    if (message.starts_with("unexpected")) {
      const std::size_t at = std::min(offset(), text_.size());
      if (at > 0 && text_[at - 1] == '@' && at > 1 && (text_[at - 2] == '"' || text_[at - 2] == '\''))
        return message + " (a language tag is missing after '@': \"text\"@en)";
    }
    // In N-Triples an object is one of three, and serd names Turtle's prefixed names among them.
    if (options_.format == Format::ntriples && message.find("expected: ':', '<', or '_'") != std::string::npos)
      return message + " (an N-Triples term is an <IRI>, a _:blank node, or, as an object, a \"quoted literal\")";
    // A literal where a subject goes: serd, reading it as a subject that is no term, says only
    // "bad verb" at the statement's start.
    if (message.ends_with("bad verb")) {
      const std::size_t at = std::min(offset(), text_.size());
      const std::size_t line = text_.substr(0, at).rfind('\n');
      const std::size_t begin = text_.find_first_not_of(" \t", line == std::string_view::npos ? 0 : line + 1);
      const std::string_view statement = begin == std::string_view::npos ? std::string_view() : text_.substr(begin);
      if (!statement.empty() && (std::string_view("\"'0123456789+-.").find(statement[0]) != std::string_view::npos ||
                                 statement.starts_with("true") || statement.starts_with("false")))
        return message + " (a literal cannot be a subject: a statement begins with an IRI or a blank node)";
    }
    // A fourth term where a statement ends: N-Quads' graph name (a .nq file), of which serd says
    // only what it expected.
    if (message.ends_with("missing ';' or '.'")) {
      const std::size_t at = std::min(offset(), text_.size());
      const std::size_t term = text_.find_first_not_of(" \t", at);
      const std::size_t line_end = std::min(text_.find('\n', at), text_.size());
      if (term < line_end && (text_[term] == '<' || text_.substr(term, 2) == "_:")) {
        const std::string_view rest = text_.substr(term, line_end - term);
        const std::size_t last = rest.find_last_not_of(" \t\r");
        if (last != std::string_view::npos && rest[last] == '.' && rest.find_first_of(" \t") < last)
          return message + " (a fourth term, as N-Quads writes a triple's graph: Tahvel reads Turtle and N-Triples, "
                           "whose triples are in no graph; leave the graph names out)";
      }
    }
    // The records `list --format json` writes, put back: '{' starts a graph block to serd, whose
    // words ("syntax does not support graphs") are about that, not about the input.
    const std::size_t first = text_.find_first_not_of(" \t\r\n");
    if (first != std::string_view::npos && text_.substr(first, 2) == "{\"")
      return "the input reads as JSON, which is not read here: N-Triples and Turtle are, as `list --format nt` writes them";
    return message;
  }

  // Records the first error, at serd's current position, and returns a status that stops serd.
  SerdStatus stop(std::string_view reason) { return stop_at(offset(), reason); }

  SerdStatus stop_at(std::size_t at, std::string_view reason) {
    if (!error_) error_ = Error{Errc::syntax, located(at, reason)};
    return SERD_ERR_BAD_ARG;
  }

  // Our sinks see a statement only once serd has read all of it. To point at the offending
  // token rather than at the end of its statement, look for it as written, backwards from
  // where serd is; when it was written with escapes, the statement's end has to do.
  SerdStatus stop_at_token(std::string_view token, std::string_view reason) {
    const std::size_t found = text_.substr(0, offset()).rfind(token);
    return stop_at(found == std::string_view::npos ? offset() : found, reason);
  }

  // An absolute IRI for `ref`, resolved against the current base when it is relative.
  std::optional<std::string> absolute(std::string_view ref) {
    if (has_scheme(ref)) return std::string(ref);
    const std::string token = "<" + std::string(ref) + ">";
    if (base_.empty()) {
      stop_at_token(token, "relative IRI " + token + " and no base IRI to resolve it against");
      return std::nullopt;
    }
    auto resolved = uri::resolve(base_, ref);
    if (!resolved) {
      stop_at_token(token, "cannot resolve " + token + " against <" + base_ +
                               ">: " + resolved.error().message);
      return std::nullopt;
    }
    return std::move(*resolved);
  }

  std::optional<std::string> iri_of(const SerdNode& node) {
    if (node.type != SERD_CURIE) return absolute(view_of(&node));
    const std::string_view curie = view_of(&node);
    if (options_.format == Format::ntriples) {  // serd 0.30 lets them through
      stop_at_token(curie, "prefixed name " + std::string(curie) + " in N-Triples");
      return std::nullopt;
    }
    SerdChunk ns{}, local{};
    if (serd_env_expand(env_.get(), &node, &ns, &local) != SERD_SUCCESS) {
      stop_at_token(curie, "undefined prefix '" + std::string(curie.substr(0, curie.find(':'))) +
                               "' in " + std::string(curie));
      return std::nullopt;
    }
    std::string iri(view_of(ns));
    iri += view_of(local);
    return iri;
  }

  std::optional<Term> term_of(const SerdNode* node, const SerdNode* datatype,
                              const SerdNode* lang) {
    switch (node->type) {
      case SERD_URI:
      case SERD_CURIE: {
        auto iri = iri_of(*node);
        if (!iri) return std::nullopt;
        return Term::iri(std::move(*iri));
      }
      case SERD_BLANK: return Term::blank(std::string(view_of(node)));
      case SERD_LITERAL: {
        Term literal = Term::literal(std::string(view_of(node)));
        if (!view_of(lang).empty()) {
          literal.language = ascii_lower(view_of(lang));
        } else if (datatype != nullptr && datatype->buf != nullptr) {
          auto iri = iri_of(*datatype);
          if (!iri) return std::nullopt;
          if (*iri != xsd::kString) literal.datatype = std::move(*iri);  // one form per literal
        }
        return literal;
      }
      default: stop("serd produced a node of unknown type"); return std::nullopt;
    }
  }

  SerdStatus statement(const SerdNode* s, const SerdNode* p, const SerdNode* o,
                       const SerdNode* datatype, const SerdNode* lang) {
    auto subject = term_of(s, nullptr, nullptr);
    if (!subject) return SERD_ERR_BAD_ARG;
    auto predicate = term_of(p, nullptr, nullptr);
    if (!predicate) return SERD_ERR_BAD_ARG;
    auto object = term_of(o, datatype, lang);
    if (!object) return SERD_ERR_BAD_ARG;
    // The input is UTF-8 (checked before serd), but serd writes a \u escape of a surrogate
    // (\uD800) as the bytes of one, which are not UTF-8: refused here, where the statement is
    // known, rather than by the store without a place (R1a).
    for (const Term* t : {&*subject, &*predicate, &*object})
      if (ill_formed_utf8_at(t->value) != std::string_view::npos || ill_formed_utf8_at(t->datatype) != std::string_view::npos)
        return stop("an escape gives a surrogate code point (U+D800 to U+DFFF), which is not a character "
                    "(write the character itself, or one \\U escape of its code point)");
    triples_.push_back({std::move(*subject), std::move(*predicate), std::move(*object)});
    if (ends_) ends_->push_back(offset());
    return SERD_SUCCESS;
  }

  SerdStatus set_base(const SerdNode* uri) {
    auto base = absolute(view_of(uri));
    if (!base) return SERD_ERR_BAD_ARG;
    base_ = std::move(*base);
    return SERD_SUCCESS;
  }

  SerdStatus set_prefix(const SerdNode* name, const SerdNode* uri) {
    auto ns = absolute(view_of(uri));
    if (!ns) return SERD_ERR_BAD_ARG;
    const std::string prefix(view_of(name));
    return serd_env_set_prefix_from_strings(env_.get(),
                                            reinterpret_cast<const uint8_t*>(prefix.c_str()),
                                            reinterpret_cast<const uint8_t*>(ns->c_str()));
  }

  // Runs a sink body; an exception (bad_alloc) must not unwind through serd's C frames, so it
  // stops serd and is rethrown by run().
  template <class F>
  static SerdStatus guarded(void* handle, F&& body) {
    auto& self = *static_cast<Parser*>(handle);
    if (self.pending_) return SERD_ERR_INTERNAL;
    try {
      return body(self);
    } catch (...) {
      self.pending_ = std::current_exception();
      return SERD_ERR_INTERNAL;
    }
  }

  static SerdStatus on_statement(void* handle, SerdStatementFlags, const SerdNode* graph,
                                 const SerdNode* s, const SerdNode* p, const SerdNode* o,
                                 const SerdNode* datatype, const SerdNode* lang) {
    return guarded(handle, [&](Parser& self) {
      // serd 0.30 reads a TriG graph block (`<g> { ... }`) in Turtle and N-Triples too: its
      // triples were stored with the graph's name dropped.
      if (graph && graph->type != SERD_NOTHING) {
        const std::string name(view_of(graph));
        const std::string as_written = graph->type == SERD_URI ? "<" + name + ">" : graph->type == SERD_BLANK ? "_:" + name : name;
        return self.stop("a named graph block (" + as_written +
                         " { ... }): Tahvel reads Turtle and N-Triples, whose triples are in no graph; put the block's "
                         "triples without it (an item's context, put --context, may say what they are about)");
      }
      return self.statement(s, p, o, datatype, lang);
    });
  }
  static SerdStatus on_base(void* handle, const SerdNode* uri) {
    return guarded(handle, [&](Parser& self) { return self.set_base(uri); });
  }
  static SerdStatus on_prefix(void* handle, const SerdNode* name, const SerdNode* uri) {
    return guarded(handle, [&](Parser& self) { return self.set_prefix(name, uri); });
  }
  static SerdStatus on_error(void* handle, const SerdError* error) {
    return guarded(handle, [&](Parser& self) {
      if (!self.error_) self.stop(self.explained(format_serd_message(*error)));
      return SERD_SUCCESS;
    });
  }

  std::string_view text_;
  const ParseOptions& options_;
  Pass pass_;
  std::size_t delivered_ = 0;  // Pass::locate: bytes handed to serd so far
  bool at_end_ = false;        // serd asked for more after the last byte
  std::string base_;           // current base IRI (absolute) or empty
  std::unique_ptr<SerdEnv, EnvDeleter> env_;
  std::vector<Triple> triples_;
  std::vector<std::size_t>* ends_ = nullptr;
  std::optional<Error> error_;
  std::exception_ptr pending_;  // thrown inside a sink, rethrown once serd has returned
};

// ---------------------------------------------------------------------------------------------
// Writing

void append_json_string(std::string& out, std::string_view text) {
  out += '"';
  out += json_escape(text);
  out += '"';
}

// A SPARQL 1.1 JSON results term object.
void append_json_term(std::string& out, const Term& term) {
  out += "{\"type\":";
  out += term.is_iri() ? "\"uri\"" : term.is_blank() ? "\"bnode\"" : "\"literal\"";
  out += ",\"value\":";
  append_json_string(out, term.value);
  if (term.is_literal()) {
    if (!term.language.empty()) {
      out += ",\"xml:lang\":";
      append_json_string(out, term.language);
    } else if (!term.datatype.empty() && term.datatype != xsd::kString) {
      out += ",\"datatype\":";
      append_json_string(out, term.datatype);
    }
  }
  out += '}';
}

// The Turtle label for blank node `label`: see the note on blank-node labels at the top.
std::string turtle_label(const std::string& label) {
  const std::size_t xs = label.find_first_not_of('x');
  const bool risky = xs != std::string::npos && xs + 1 < label.size() && label[xs] == 'B' &&
                     label[xs + 1] >= '0' && label[xs + 1] <= '9';
  return risky ? "x" + label : label;
}

bool all_digits(std::string_view text) {
  return !text.empty() &&
         std::all_of(text.begin(), text.end(), [](char c) { return c >= '0' && c <= '9'; });
}

std::string_view without_sign(std::string_view text) {
  if (!text.empty() && (text[0] == '+' || text[0] == '-')) text.remove_prefix(1);
  return text;
}

// True when serd's Turtle writer would write `lexical` bare (as it does for these three XSD
// datatypes) and the bare token would not read back as the same literal.
bool bare_form_unfaithful(std::string_view datatype, std::string_view lexical) {
  if (!datatype.starts_with(kXsdNs)) return false;
  const std::string_view local = datatype.substr(kXsdNs.size());
  if (local == "integer") return !all_digits(without_sign(lexical));  // INTEGER [+-]?[0-9]+
  if (local == "boolean") return lexical != "true" && lexical != "false";
  if (local == "decimal") {
    // serd goes bare when there is a '.' that is not last; DECIMAL is [+-]?[0-9]*\.[0-9]+.
    const bool serd_bare = lexical.find('.') != std::string_view::npos && lexical.back() != '.';
    const std::string_view body = without_sign(lexical);
    const std::size_t dot = body.find('.');
    const bool decimal = dot != std::string_view::npos &&
                         (dot == 0 || all_digits(body.substr(0, dot))) &&
                         all_digits(body.substr(dot + 1));
    return serd_bare && !decimal;
  }
  return false;
}

}  // namespace

Result<Format> parse_format(std::string_view name) {
  const std::string lower = ascii_lower(name);
  if (lower == "nt" || lower == "ntriples") return Format::ntriples;
  if (lower == "ttl" || lower == "turtle") return Format::turtle;
  if (lower == "json") return Format::json;
  return fail(Errc::invalid_argument, "unknown format '" + std::string(name) +
                                          "' (expected nt, ntriples, ttl, turtle or json)");
}

Result<std::vector<Triple>> parse_rdf(std::string_view text, const ParseOptions& options) {
  auto triples = Parser(text, options, Parser::Pass::fast).run();
  if (triples || triples.error().code != Errc::syntax) return triples;
  return Parser(text, options, Parser::Pass::locate).run();  // same input: fails at the same place
}

std::string locate_triple(std::string_view text, const ParseOptions& options, std::size_t index) {
  Parser parser(text, options, Parser::Pass::locate);
  std::vector<std::size_t> ends;
  parser.record_ends(&ends);
  auto triples = parser.run();
  if (!triples || index >= ends.size()) return {};
  return parser.position(ends[index]);
}

std::string utc_text(std::int64_t ns) {
  // Floor division: a time before 1970 still has its milliseconds in 0..999.
  std::int64_t ms = ns / 1'000'000 - (ns % 1'000'000 < 0 ? 1 : 0);
  std::int64_t s = ms / 1000 - (ms % 1000 < 0 ? 1 : 0);
  const auto milli = static_cast<int>(ms - s * 1000);
  const std::time_t seconds = static_cast<std::time_t>(s);
  std::tm utc{};
  gmtime_r(&seconds, &utc);
  char text[64];
  std::snprintf(text, sizeof text, "%04d-%02d-%02dT%02d:%02d:%02d.%03dZ", utc.tm_year + 1900, utc.tm_mon + 1, utc.tm_mday,
                utc.tm_hour, utc.tm_min, utc.tm_sec, milli);
  return text;
}

std::string log_stamp() {
  const auto now = std::chrono::system_clock::now();
  return utc_text(std::chrono::duration_cast<std::chrono::nanoseconds>(now.time_since_epoch()).count());
}

void write_log_line(std::string_view line) noexcept {
  static std::atomic<bool> last_cut{false};
  try {
    std::string text = (last_cut.load() ? "\n" : "") + log_stamp() + " ";
    text.append(line);
    text += '\n';
    std::size_t done = 0;
    while (done < text.size()) {
      const ssize_t n = ::write(STDERR_FILENO, text.data() + done, text.size() - done);
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) break;
      done += static_cast<std::size_t>(n);
    }
    last_cut = done > 0 && done < text.size() ? true : done == text.size() ? false : last_cut.load();
  } catch (...) {  // out of memory: the line is lost, the process goes on
  }
  static std::mutex clearing;  // the link logs from several threads
  std::lock_guard lock(clearing);
  if (!std::cerr) std::cerr.clear();
}

std::string json_escape(std::string_view text) {
  std::string out;
  out.reserve(text.size() + 2);
  detail::append_escaped(out, text, detail::EscapeDialect::json);
  return out;
}

struct RecordWriter::Impl {
  Impl(std::ostream& stream, Format syntax, const uri::PrefixMap& prefixes)
      : out(stream), format(syntax) {
    if (format == Format::json) return;
    const bool turtle = format == Format::turtle;
    env.reset(serd_env_new(nullptr));
    const auto style = turtle ? static_cast<SerdStyle>(SERD_STYLE_ABBREVIATED | SERD_STYLE_CURIED)
                              : static_cast<SerdStyle>(0);
    writer.reset(serd_writer_new(turtle ? SERD_TURTLE : SERD_NTRIPLES, style, env.get(), nullptr,
                                 sink, this));
    // serd reports ill-formed UTF-8 (which it replaces with U+FFFD) here; a library does not
    // print to stderr on its own, and write() has no error to return.
    serd_writer_set_error_sink(writer.get(), ignore_error, nullptr);
    if (turtle)
      for (const auto& [name, ns] : prefixes.entries()) bind(name, ns);
    rethrow();
  }

  static size_t sink(const void* buf, size_t len, void* stream) {
    auto& self = *static_cast<Impl*>(stream);
    if (self.pending) return 0;
    try {  // an exception must not unwind through serd's C frames
      self.out.write(static_cast<const char*>(buf), static_cast<std::streamsize>(len));
    } catch (...) {
      self.pending = std::current_exception();
      return 0;
    }
    return self.out ? len : 0;
  }

  static SerdStatus ignore_error(void*, const SerdError*) { return SERD_SUCCESS; }

  void rethrow() {
    if (pending) std::rethrow_exception(std::exchange(pending, nullptr));
  }

  void bind(const std::string& name, const std::string& ns) {
    const SerdNode name_node = make_node(SERD_LITERAL, name);
    const SerdNode ns_node = make_node(SERD_URI, ns);
    if (serd_writer_set_prefix(writer.get(), &name_node, &ns_node) == SERD_SUCCESS)
      bound[name] = ns;
  }

  // A CURIE for the XSD datatype `local`, binding a prefix for the XSD namespace if none is.
  std::string xsd_curie(std::string_view local) {
    if (xsd_prefix.empty()) {
      for (const auto& [name, ns] : bound)
        if (ns == kXsdNs && !name.empty()) xsd_prefix = name;
      if (xsd_prefix.empty()) {
        std::string name = "xsd";
        for (int n = 1; bound.count(name) != 0; ++n) name = "xsd" + std::to_string(n);
        bind(name, std::string(kXsdNs));
        xsd_prefix = name;
      }
    }
    return xsd_prefix + ":" + std::string(local);
  }

  // A serd node for `term`; `storage` keeps a rewritten blank label alive.
  SerdNode node_of(const Term& term, std::string& storage) {
    if (term.is_blank() && format == Format::turtle) {
      storage = turtle_label(term.value);
      return make_node(SERD_BLANK, storage);
    }
    const SerdType type = term.is_iri() ? SERD_URI : term.is_blank() ? SERD_BLANK : SERD_LITERAL;
    return make_node(type, term.value);
  }

  void write_serd(const Triple& triple) {
    const Term& o = triple.o;
    std::string datatype_curie, s_label, o_label, unused;
    SerdNode datatype{}, lang{};
    const SerdNode* datatype_ptr = nullptr;
    const SerdNode* lang_ptr = nullptr;
    if (o.is_literal() && !o.language.empty()) {
      lang = make_node(SERD_LITERAL, o.language);
      lang_ptr = &lang;
    } else if (o.is_literal() && !o.datatype.empty() && o.datatype != xsd::kString) {
      if (format == Format::turtle && bare_form_unfaithful(o.datatype, o.value)) {
        datatype_curie = xsd_curie(std::string_view(o.datatype).substr(kXsdNs.size()));
        datatype = make_node(SERD_CURIE, datatype_curie);
      } else {
        datatype = make_node(SERD_URI, o.datatype);
      }
      datatype_ptr = &datatype;
    }
    const SerdNode s = node_of(triple.s, s_label), p = node_of(triple.p, unused),
                   object = node_of(o, o_label);
    serd_writer_write_statement(writer.get(), 0, nullptr, &s, &p, &object, datatype_ptr, lang_ptr);
    rethrow();
  }

  void write_json(const Triple& triple, const RecordMeta* meta, std::string_view head = {}) {
    line.clear();
    line += '{';
    line += head;
    if (meta != nullptr) {
      line +=
          "\"id\":" + std::to_string(meta->id) + ",\"item\":" + std::to_string(meta->item) + ',';
    }
    line += "\"s\":";
    append_json_term(line, triple.s);
    line += ",\"p\":";
    append_json_term(line, triple.p);
    line += ",\"o\":";
    append_json_term(line, triple.o);
    if (meta != nullptr) {
      line += ",\"stored_at\":" + std::to_string(meta->stored_at);
      line += ",\"asserted_at\":" + std::to_string(meta->asserted_at);
      // Only on records that hold for a time (RecordMeta::span): other lines stay as they were.
      if (meta->span != 0) line += ",\"span\":" + std::to_string(meta->span);
      line += ",\"source\":";
      append_json_string(line, meta->source);
      line += ",\"context\":";
      append_json_string(line, meta->context);
      line += meta->persistent ? ",\"persistent\":true" : ",\"persistent\":false";
    }
    line += "}\n";
    out.write(line.data(), static_cast<std::streamsize>(line.size()));
  }

  void finish() {
    if (writer) {
      serd_writer_finish(writer.get());
      rethrow();
    }
    out.flush();
  }

  std::ostream& out;
  Format format;
  // Declared before the writer, which refers to it, so that it is destroyed after it.
  std::unique_ptr<SerdEnv, EnvDeleter> env;
  std::unique_ptr<SerdWriter, WriterDeleter> writer;
  std::map<std::string, std::string> bound;  // Turtle: prefixes written so far
  std::string xsd_prefix;                    // Turtle: a prefix bound to the XSD namespace
  std::exception_ptr pending;                // thrown by the stream inside serd's sink
  std::string line;                          // JSON: the line being built, reused
};

RecordWriter::RecordWriter(std::ostream& out, Format format, const uri::PrefixMap& prefixes)
    : impl_(std::make_unique<Impl>(out, format, prefixes)) {}

RecordWriter::~RecordWriter() {
  try {
    finish();
  } catch (...) {
    // A destructor must not throw; call finish() first to see stream errors.
  }
}

void RecordWriter::write(const Record& record) {
  if (impl_->format == Format::json)
    impl_->write_json(record.triple, &record.meta);
  else
    impl_->write_serd(record.triple);
}

void RecordWriter::write(const Triple& triple) {
  if (impl_->format == Format::json)
    impl_->write_json(triple, nullptr);
  else
    impl_->write_serd(triple);
}

void RecordWriter::write(const Change& change) {
  if (!change.unreadable.empty()) {
    if (impl_->format == Format::json) {
      impl_->out << "{\"seq\":" << change.seq << ",\"removed\":" << (change.removed ? "true" : "false")
                 << (change.reclaimed ? ",\"reclaimed\":true" : "") << ",\"unreadable\":\"" << json_escape(change.unreadable)
                 << "\"}\n";
    } else {
      impl_->finish();
      // One line: the reason is the store's message, which names what and where.
      std::string why = change.unreadable;
      std::replace(why.begin(), why.end(), '\n', ' ');
      impl_->out << "# unreadable " << (change.removed ? "removal " : "record ") << change.seq << ": " << why << "\n";
    }
    return;
  }
  if (!change.removed) return write(change.record);
  if (impl_->format == Format::json) {
    impl_->write_json(change.record.triple, &change.record.meta,
                      "\"removed\":true,\"seq\":" + std::to_string(change.seq) + ",");
    return;
  }
  impl_->finish();  // pending Turtle abbreviations end before the comment
  impl_->out << "# removed " << change.record.meta.id << "\n";
}

void RecordWriter::finish() { impl_->finish(); }

}  // namespace tahvel::node
