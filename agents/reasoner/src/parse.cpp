// The rule file parser: a hand-written lexer and recursive-descent parser for the thesis'
// Prolog-like rules (a small grammar, no RDF inside, so no serd). Produces rules as written;
// compile.cpp rewrites ranking and demand and checks safety. Every error names file:line:col.
#include <algorithm>
#include <cctype>
#include <charconv>
#include <cstdio>
#include <functional>
#include <map>
#include <optional>

#include <unictype.h>
#include <unistr.h>

#include "program.h"
#include "value.h"
#include "tahvel/uri/spelling.h"
#include "tahvel/uri/unicode_escape.h"

namespace tahvel::reasoner {

std::string where(const Program& program, Pos pos) {
  return program.file + ":" + std::to_string(pos.line) + ":" + std::to_string(pos.col);
}

namespace {

constexpr std::size_t kMaxArity = 15;  // the engine's rows hold at most 15 arguments
// Parsing, evaluating and freeing an expression recurse once per level (parenthesis, sign or
// operator): a bound keeps a hostile or generated rule file from overflowing the stack, which
// on a reload would end the running reasoner rather than report the file.
constexpr std::uint32_t kMaxExpressionDepth = 1000;
constexpr std::size_t kMaxBodyLiterals = 256;

enum class Tok { var, name, iri, literal, punct, end };

struct Token {
  Tok kind = Tok::end;
  std::string text;   // var/name: the identifier; iri: the IRI; punct: the symbol
  node::Term term;    // literal
  Pos pos;
  // punct '<' that begins "<foo>", an IRI reference without a scheme: "<foo>", for the error
  std::string relative_iri;
  // The token as the file has it ("ex:c", "<http://x/p>"), for errors: an IRI shown expanded
  // was not what the author wrote.
  std::string written;
};

// Bytes of non-ASCII UTF-8 count as letters: IRIs are Unicode (ex:lämpötila, #café).
bool is_name_char(char c) {
  return std::isalnum(static_cast<unsigned char>(c)) || c == '_' || static_cast<unsigned char>(c) >= 0x80;
}


// The code point of the UTF-8 sequence at `i` with its length, or {0, 1} for a byte that does
// not start one (a name takes such bytes as it always has: the store checks UTF-8).
std::pair<char32_t, std::size_t> code_point_at(std::string_view text, std::size_t i) {
  const auto b = [&](std::size_t k) { return i + k < text.size() ? static_cast<unsigned char>(text[i + k]) : 0u; };
  const unsigned lead = b(0);
  const auto cont = [&](std::size_t k) { return (b(k) & 0xC0u) == 0x80u; };
  if (lead >= 0xC2 && lead < 0xE0 && cont(1)) return {((lead & 0x1Fu) << 6) | (b(1) & 0x3Fu), 2};
  if (lead >= 0xE0 && lead < 0xF0 && cont(1) && cont(2))
    return {((lead & 0x0Fu) << 12) | ((b(1) & 0x3Fu) << 6) | (b(2) & 0x3Fu), 3};
  if (lead >= 0xF0 && lead < 0xF5 && cont(1) && cont(2) && cont(3))
    return {((lead & 0x07u) << 18) | ((b(1) & 0x3Fu) << 12) | ((b(2) & 0x3Fu) << 6) | (b(3) & 0x3Fu), 4};
  return {0, 1};
}

// Spaces and invisible marks outside ASCII: in a name they made a different IRI that looks
// the same (a no-break space, a byte-order mark), so a name ends at one and it is an error.
const char* invisible_name(char32_t c) {
  switch (c) {
    case 0x00A0: return "no-break space";
    case 0x1680: return "Ogham space mark";
    case 0x180E: return "Mongolian vowel separator";
    case 0x2028: return "line separator";
    case 0x2029: return "paragraph separator";
    case 0x202F: return "narrow no-break space";
    case 0x205F: return "medium mathematical space";
    case 0x2060: return "word joiner";
    case 0x3000: return "ideographic space";
    case 0xFEFF: return "byte-order mark (zero-width no-break space)";
    default: return c >= 0x2000 && c <= 0x200F ? "space or zero-width mark" : nullptr;
  }
}

// Why `text` is not an absolute IRI, or nothing.
std::optional<std::string> not_an_iri(const std::string& text) {
  if (uri::is_valid(text)) return std::nullopt;
  auto parsed = uri::normalize(text);
  return parsed ? std::string("not an absolute IRI") : parsed.error().message;
}

class Lexer {
 public:
  Lexer(std::string_view text, const ParseOptions& options, uri::PrefixMap& prefixes)
      : text_(text), options_(options), prefixes_(prefixes) {
    // A byte-order mark some editors write at the start is not part of the first name.
    if (text_.starts_with("\xEF\xBB\xBF")) i_ = 3;
  }

  // The next token, with what the file has of it.
  Result<Token> next() {
    if (auto s = skip_space(); !s) return unexpected(s.error());
    const std::size_t from = i_;
    auto t = token();
    if (t && i_ > from) t->written = std::string(text_.substr(from, i_ - from));
    return t;
  }
  Pos pos() const { return {line_, col_}; }
  struct State { std::size_t i; int line, col; };
  State state() const { return {i_, line_, col_}; }
  void restore(State s) { i_ = s.i; line_ = s.line; col_ = s.col; }
  // Turtle's "p:" of @prefix (directly after the keyword).
  Result<std::string> prefix_name() {
    if (auto s = skip_space(); !s) return unexpected(s.error());
    Pos start = pos();
    std::string name;
    while (name_char()) { name += at(); advance(); }
    if (at() != ':') return error(start, "expected a prefix name followed by ':' after @prefix");
    advance();
    return name;
  }
  // A namespace declared in the rule file, as written: its CURIEs expand to exactly the IRIs the
  // data written with the same @prefix holds (the store compares IRIs as written, R1).
  void declare(const std::string& prefix, const std::string& namespace_iri) { written_[prefix] = namespace_iri; }

 private:
  char at(std::size_t k = 0) const { return i_ + k < text_.size() ? text_[i_ + k] : '\0'; }
  // is_name_char / is_local_char of the byte at i_ + k, but not the first byte of an invisible
  // character (invisible_name).
  bool name_char(std::size_t k = 0) const {
    return is_name_char(at(k)) && !(static_cast<unsigned char>(at(k)) >= 0x80 && invisible_name(code_point_at(text_, i_ + k).first));
  }
  bool local_char() const { return at() == '-' || at() == '.' || name_char(); }
  // Columns count characters, as editors show them: a UTF-8 continuation byte adds none.
  void advance(std::size_t n = 1) {
    for (; n > 0 && i_ < text_.size(); --n, ++i_) {
      // A lone '\r' ends a line too (old Mac files), as in put's input: a '%' comment ran on
      // to the file's end and took every rule after it.
      if (text_[i_] == '\n' || (text_[i_] == '\r' && (i_ + 1 >= text_.size() || text_[i_ + 1] != '\n'))) { ++line_; col_ = 1; }
      else if ((static_cast<unsigned char>(text_[i_]) & 0xC0) != 0x80) { ++col_; }
    }
  }
  Unexpected<Error> error(Pos pos, const std::string& what) const {
    return unexpected(Error{options_.file + ":" + std::to_string(pos.line) + ":" +
                            std::to_string(pos.col) + ": " + what});
  }
  Result<void> skip_space();
  Result<Token> token();  // after the space before it
  Result<Token> identifier(Pos start);
  Result<Token> iri_ref(Pos start);
  Result<Token> number(Pos start);
  Result<Token> string_literal(Pos start, char quote);
  Result<std::string> curie(Pos start, std::string prefix);

  std::string_view text_;
  const ParseOptions& options_;
  uri::PrefixMap& prefixes_;
  std::map<std::string, std::string> written_;  // the file's own prefixes, as written
  std::size_t i_ = 0;
  int line_ = 1, col_ = 1;
};

Result<void> Lexer::skip_space() {
  for (;;) {
    char c = at();
    if (c == '%') {
      while (at() && at() != '\n' && at() != '\r') advance();
    } else if (c == '/' && at(1) == '*') {
      Pos start = pos();
      advance(2);
      while (at() && !(at() == '*' && at(1) == '/')) advance();
      if (!at()) return error(start, "comment not closed (missing */)");
      advance(2);
    } else if (std::isspace(static_cast<unsigned char>(c))) {
      advance();
    } else {
      return {};
    }
  }
}

Result<std::string> Lexer::curie(Pos start, std::string prefix) {
  advance();  // ':'
  std::string local;
  // Turtle's local names hold %HH as written (`ex:a%20b`, as `tahvel put` stores it); a '%'
  // there started a comment, and the error fell on a later line.
  auto hex = [&](std::size_t k) { return std::isxdigit(static_cast<unsigned char>(at(k))) != 0; };
  while (local_char() || (at() == '%' && hex(1) && hex(2))) {
    const int n = at() == '%' ? 3 : 1;
    for (int k = 0; k < n; ++k) { local += at(); advance(); }
  }
  while (!local.empty() && local.back() == '.') {  // the clause's full stop, not the name's
    local.pop_back();
    --i_;
    --col_;
  }
  // Turtle's blank node: no term of a rule ("unknown prefix '_'" sent the author to declare it).
  if (prefix == "_")
    return error(start, "_:" + local + ": a blank node is not a term of a rule: a variable stands for any node, and "
                        "skolem(L, …) makes an IRI per conclusion (RS5)");
  if (auto declared = written_.find(prefix); declared != written_.end()) {
    std::string iri = declared->second + local;
    if (auto why = not_an_iri(iri)) return error(start, "CURIE " + prefix + ":" + local + ": " + *why);
    return iri;
  }
  // The node's prefixes and the standard ones, kept in normal form (init --prefix).
  auto iri = prefixes_.expand(prefix + ":" + local);
  if (!iri) return error(start, "CURIE " + prefix + ":" + local + ": " + iri.error().message);
  return *iri;
}

namespace {
// RS4: a name whose first character is '_' or an upper-case letter (Unicode's Lu or Lt, as
// SWI-Prolog reads them: `Ärsyke` is a variable) names a variable.
bool starts_a_variable(const std::string& id) {
  if (id.empty()) return false;
  if (id[0] == '_') return true;
  ucs4_t first = 0;
  u8_mbtouc(&first, reinterpret_cast<const std::uint8_t*>(id.data()), id.size());
  return uc_is_general_category(first, UC_UPPERCASE_LETTER) || uc_is_general_category(first, UC_TITLECASE_LETTER);
}

// A datatype in XSD's namespace that XSD does not define ("10"^^xsd:integr): a constant of it
// equals no value the data holds, so its rule never fired, without a word. Says so, with the
// type it is a slip from when one is within two edits.
std::optional<std::string> unknown_xsd_datatype(std::string_view datatype) {
  constexpr std::string_view kXsd = "http://www.w3.org/2001/XMLSchema#";
  if (!datatype.starts_with(kXsd)) return std::nullopt;
  const std::string_view local = datatype.substr(kXsd.size());
  // XSD 1.1 Part 2's built-in datatypes.
  static constexpr std::string_view kTypes[] = {
      "anyAtomicType", "anySimpleType", "anyType", "anyURI", "base64Binary", "boolean", "byte", "date", "dateTime",
      "dateTimeStamp", "dayTimeDuration", "decimal", "double", "duration", "ENTITIES", "ENTITY", "float", "gDay",
      "gMonth", "gMonthDay", "gYear", "gYearMonth", "hexBinary", "ID", "IDREF", "IDREFS", "int", "integer",
      "language", "long", "Name", "NCName", "negativeInteger", "NMTOKEN", "NMTOKENS", "nonNegativeInteger",
      "nonPositiveInteger", "normalizedString", "NOTATION", "positiveInteger", "QName", "short", "string", "time",
      "token", "unsignedByte", "unsignedInt", "unsignedLong", "unsignedShort", "yearMonthDuration"};
  std::string_view nearest;
  std::size_t nearest_edits = 3;
  for (std::string_view type : kTypes) {
    if (type == local) return std::nullopt;
    if (const std::size_t e = uri::edit_distance(local, type); e < nearest_edits) nearest_edits = e, nearest = type;
  }
  std::string why = "xsd:" + std::string(local) + " is no XSD datatype";
  if (!nearest.empty()) why += " (did you mean xsd:" + std::string(nearest) + "?)";
  return why + ": a constant of it would equal no value the data holds";
}
}  // namespace

Result<Token> Lexer::identifier(Pos start) {
  std::string id;
  while (name_char()) { id += at(); advance(); }
  // `ex:` alone is the namespace IRI itself, as Turtle reads it (not `p:-`, a rule's neck).
  const char after = at(1);
  const bool empty_local = after == ',' || after == ')' || after == '.' || after == ']' ||
                           std::isspace(static_cast<unsigned char>(after)) != 0;
  if (at() == ':' && (name_char(1) || empty_local)) {
    auto iri = curie(start, id);
    if (!iri) return unexpected(iri.error());
    return Token{Tok::iri, *iri, {}, start};
  }
  return Token{starts_a_variable(id) ? Tok::var : Tok::name, id, {}, start};
}

Result<Token> Lexer::iri_ref(Pos start) {
  advance();  // '<'
  std::string iri;
  while (at() && at() != '>') { iri += at(); advance(); }
  advance();
  // As written, as put and load store it (R1): normalised, <http://Device.example.org/x> or
  // <http://e/a/./b> matched nothing the board held under it.
  if (auto why = not_an_iri(iri)) return error(start, "IRI <" + iri + ">: " + *why);
  return Token{Tok::iri, iri, {}, start};
}

// Turtle's LANGTAG: [a-zA-Z]+ ('-' [a-zA-Z0-9]+)*.
bool is_language_tag(std::string_view tag) {
  std::size_t i = 0;
  while (i < tag.size() && std::isalpha(static_cast<unsigned char>(tag[i]))) ++i;
  if (i == 0) return false;
  while (i < tag.size()) {
    if (tag[i++] != '-') return false;
    const std::size_t from = i;
    while (i < tag.size() && std::isalnum(static_cast<unsigned char>(tag[i]))) ++i;
    if (i == from) return false;
  }
  return true;
}

Result<Token> Lexer::number(Pos start) {
  std::string digits;
  bool decimal = false, exponent = false;
  while (std::isdigit(static_cast<unsigned char>(at()))) { digits += at(); advance(); }
  if (at() == '.' && std::isdigit(static_cast<unsigned char>(at(1)))) {
    decimal = true;
    digits += at(); advance();
    while (std::isdigit(static_cast<unsigned char>(at()))) { digits += at(); advance(); }
  }
  if ((at() == 'e' || at() == 'E') &&
      (std::isdigit(static_cast<unsigned char>(at(1))) ||
       ((at(1) == '-' || at(1) == '+') && std::isdigit(static_cast<unsigned char>(at(2)))))) {
    exponent = true;
    digits += at(); advance();
    if (at() == '-' || at() == '+') { digits += at(); advance(); }
    while (std::isdigit(static_cast<unsigned char>(at()))) { digits += at(); advance(); }
  }
  std::string_view dt = exponent ? node::xsd::kDouble : decimal ? node::xsd::kDecimal
                                                                 : node::xsd::kInteger;
  if (!exponent && !decimal) {  // canonical integer: no leading zeros
    std::size_t z = 0;
    while (z + 1 < digits.size() && digits[z] == '0') ++z;
    digits.erase(0, z);
    std::int64_t fits;
    auto [end, ec] = std::from_chars(digits.data(), digits.data() + digits.size(), fits);
    if (ec != std::errc()) return error(start, "integer " + digits + " is out of range: integers are 64-bit, from -9223372036854775808 to "
                                                      "9223372036854775807 (-9223372036854775808 is not read as a literal; in arithmetic it is "
                                                      "-9223372036854775807 - 1)");
  }
  return Token{Tok::literal, {}, node::Term::literal(digits, std::string(dt)), start};
}

Result<Token> Lexer::string_literal(Pos start, char quote) {
  advance();
  std::string value;
  for (;;) {
    char c = at();
    if (!c || c == '\n') return error(start, "string not closed (missing " + std::string(1, quote) + ")");
    advance();
    if (c == quote) break;
    if (c == '\\') {
      char e = at();
      advance();
      switch (e) {
        case 'n': value += '\n'; break;
        case 't': value += '\t'; break;
        case 'r': value += '\r'; break;
        case '\\': case '"': case '\'': value += e; break;
        case 'u': case 'U': {  // \uXXXX, \UXXXXXXXX as in Turtle
          Pos at_escape = pos();
          const std::size_t digits = e == 'u' ? 4 : 8;
          std::string hex;
          for (std::size_t k = 0; k < digits && std::isxdigit(static_cast<unsigned char>(at())); ++k) {
            hex += at();
            advance();
          }
          if (hex.size() != digits)
            return error(at_escape, std::string("\\") + e + " needs " + std::to_string(digits) + " hex digits");
          auto c = uri::escaped_code_point(hex);
          if (!c) return error(at_escape, "\\" + std::string(1, e) + " escape is not a Unicode character");
          uri::append_utf8(value, *c);
          break;
        }
        default: return error(pos(), std::string("unknown escape \\") + e + " in a string");
      }
    } else {
      value += c;
    }
  }
  node::Term term = node::Term::literal(value);
  if (at() == '^' && at(1) == '^') {
    advance(2);
    Pos dpos = pos();
    auto dt = next();
    if (!dt) return dt;
    if (dt->kind != Tok::iri) return error(dpos, "expected a datatype IRI after ^^");
    term.datatype = dt->text;
    if (term.datatype == node::xsd::kString) term.datatype.clear();
    if (auto why = unknown_xsd_datatype(term.datatype)) return error(dpos, *why);
    // Such a constant compares with nothing and its rule never fires, without a word.
    if (auto type = valued_type_name(term); !type.empty() && value_of(term).kind == Value::none) {
      if (type.find("dateTime") != std::string::npos && datetime_beyond_range(value))
        return error(start, "\"" + value + "\" is an " + type +
                                " outside the times the built-ins read (1677-09-21 to 2262-04-11: nanoseconds in 64 bits); "
                                "as a constant of a rule it would compare with no time");
      std::string why = type.find("dateTime") != std::string::npos
                            ? " (YYYY-MM-DDThh:mm:ss, then optional .fraction and Z or ±hh:mm, the offset within ±14:00)"
                            : type == "xsd:decimal" ? " (digits with at most one '.': no exponent)"
                            : type == "xsd:double" || type == "xsd:float"
                                  ? ""
                                  : " (or does not fit in 64 bits, or is outside its type's range)";
      return error(start, "\"" + value + "\" is not a valid " + type + why);
    }
  } else if (at() == '@') {
    advance();
    const Pos tag_at = pos();
    std::string lang;
    while (name_char() || at() == '-') { lang += static_cast<char>(std::tolower(at())); advance(); }
    if (lang.empty()) return error(pos(), "expected a language tag after @");
    if (!is_language_tag(lang))
      return error(tag_at, "'" + lang + "' is not a language tag (letters, then '-' and letters or digits: en, en-gb)");
    term = node::Term::lang_literal(value, lang);
  }
  return Token{Tok::literal, {}, std::move(term), start};
}

Result<Token> Lexer::token() {
  Pos start = pos();
  char c = at();
  if (!c) return Token{Tok::end, {}, {}, start};
  if (name_char() && !std::isdigit(static_cast<unsigned char>(c))) return identifier(start);
  if (std::isdigit(static_cast<unsigned char>(c))) return number(start);
  if (c == '"' || c == '\'') return string_literal(start, c);
  if (c == '<') {
    // An IRI reference when a scheme (RFC 3986: a letter, then letters, digits, + - .) and ':'
    // start a run without spaces that reaches '>'; else "less than", as in N<T,ex:a(T,Z),Z>3.
    std::size_t k = 1;
    while (std::isalnum(static_cast<unsigned char>(at(k))) || at(k) == '+' || at(k) == '-' || at(k) == '.') ++k;
    const bool scheme = k > 1 && std::isalpha(static_cast<unsigned char>(at(1))) && at(k) == ':';
    while (at(k) && at(k) != '>' && !std::isspace(static_cast<unsigned char>(at(k))) && at(k) != '<') ++k;
    if (at(k) == '>' && scheme) return iri_ref(start);
    const std::string_view run = text_.substr(i_ + 1, k > 1 ? k - 1 : 0);
    if (at(k) == '>' && k > 1 && !std::isspace(static_cast<unsigned char>(at(1))) && at(1) != '=' &&
        run.find_first_of("(),") == std::string_view::npos) {
      advance();
      return Token{Tok::punct, "<", {}, start, "<" + std::string(text_.substr(i_, k - 1)) + ">"};
    }
  }
  if (c == '#' && name_char(1)) {
    advance();
    std::string local;
    auto hex = [&](std::size_t k) { return std::isxdigit(static_cast<unsigned char>(at(k))) != 0; };
    while (name_char() || at() == '-' || (at() == '%' && hex(1) && hex(2))) {
      const int n = at() == '%' ? 3 : 1;
      for (int k = 0; k < n; ++k) { local += at(); advance(); }
    }
    return Token{Tok::iri, options_.default_ns + local, {}, start};
  }
  if (c == ':' && name_char(1)) {
    auto iri = curie(start, "");
    if (!iri) return unexpected(iri.error());
    return Token{Tok::iri, *iri, {}, start};
  }
  if (c == '@' && std::isalpha(static_cast<unsigned char>(at(1)))) {
    advance();
    std::string kw = "@";
    while (name_char()) { kw += at(); advance(); }
    return Token{Tok::punct, kw, {}, start};
  }
  static const char* kSymbols[] = {"=:=", "=\\=", "\\==", ":-", "\\+", "=<", ">=", "\\=", "==",
                                   "(", ")", ",", ".", "!", "=", "<", ">", "+", "-", "*", "/"};
  for (const char* s : kSymbols) {
    std::string_view sym(s);
    if (text_.substr(i_, sym.size()) == sym) {
      advance(sym.size());
      return Token{Tok::punct, std::string(sym), {}, start};
    }
  }
  if (static_cast<unsigned char>(c) >= 0x80) {
    const char32_t cp = code_point_at(text_, i_).first;
    char hex[16];
    std::snprintf(hex, sizeof hex, "U+%04X", static_cast<unsigned>(cp));
    if (const char* name = invisible_name(cp))
      return error(start, std::string("unexpected ") + name + " (" + hex + "): write a plain space, or nothing");
    if (cp != 0) return error(start, std::string("unexpected character ") + hex);
    return error(start, "invalid UTF-8 (byte 0x" + [&] { char b[4]; std::snprintf(b, sizeof b, "%02X", static_cast<unsigned char>(c)); return std::string(b); }() + ")");
  }
  // Prolog's disjunction and if-then-else: named, not left as an unknown character.
  if (c == ';' || c == '|')
    return error(start, std::string("'") + c + "' (or) is not part of the rule language: a body is literals joined by ','; "
                        "write one rule for each alternative");
  if (static_cast<unsigned char>(c) < 0x20 || c == 0x7f) {  // printed raw it showed as ''
    char hex[8];
    std::snprintf(hex, sizeof hex, "0x%02X", static_cast<unsigned char>(c));
    return error(start, std::string("unexpected control character ") + hex);
  }
  return error(start, std::string("unexpected character '") + c + "'");
}

// ---------------------------------------------------------------------------------------------

class Parser {
 public:
  Parser(std::string_view text, const ParseOptions& options, Program& program)
      : options_(options), prefixes_(options.prefixes), lexer_(text, options, prefixes_),
        program_(program) {}

  Result<void> run();

 private:
  Result<void> advance() {
    auto t = lexer_.next();
    if (!t) return unexpected(t.error());
    tok_ = std::move(*t);
    return {};
  }
  bool is(std::string_view punct) const { return tok_.kind == Tok::punct && tok_.text == punct; }
  Unexpected<Error> error(Pos pos, const std::string& what) const {
    return unexpected(Error{where(program_, pos) + ": " + what});
  }
  Unexpected<Error> expected(const std::string& what) const {
    std::string got = tok_.kind == Tok::end ? "end of file" : "'" + token_text() + "'";
    return error(tok_.pos, "expected " + what + ", found " + got);
  }
  std::string token_text() const {
    if (tok_.kind == Tok::iri && !tok_.written.empty()) return tok_.written;
    return tok_.kind == Tok::literal ? tok_.term.to_ntriples() : tok_.text;
  }
  Result<void> expect(std::string_view punct, const std::string& what) {
    if (!is(punct)) return expected(what);
    return advance();
  }

  Result<void> directive();
  bool operator_follows();
  std::string without_value(const node::Term& constant) const;
  // The current token, a name where an arithmetic or comparison operator would go (S mod 2).
  Unexpected<Error> not_an_operator() const {
    return error(tok_.pos, "'" + tok_.text + "' is not an operator here: arithmetic is + - * / and parentheses (no mod, rem or //; "
                                              "a body's literals are joined by ',')");
  }
  Result<void> clause();
  Result<std::vector<Literal>> body();
  std::optional<Error> foreign_operator();
  Result<Literal> literal();
  Result<Literal> callable(bool negated);
  Result<Expr> expression();
  Result<Expr> product();
  Result<Expr> unary();
  Result<Expr> nested(Pos pos, const std::function<Result<Expr>()>& parse_inner);
  Result<Expr> combine(Expr::Kind kind, Pos pos, Expr a, std::optional<Expr> b);
  Result<Arg> term(bool allow_now);
  Arg constant(const node::Term& term);
  Arg variable(const std::string& name, Pos pos);
  std::uint32_t pred(const std::string& iri, std::uint32_t arity);
  std::string name_iri(const std::string& name) const {
    return name == "me" ? options_.me : options_.default_ns + name;
  }

  const ParseOptions& options_;
  uri::PrefixMap prefixes_;
  Lexer lexer_;
  Program& program_;
  Token tok_;
  Rule* rule_ = nullptr;  // the clause being parsed
  std::uint32_t nesting_ = 0;  // parentheses and signs open around the expression being parsed
  // The constants of the literal being parsed that are operands of arithmetic or a comparison
  // (where each was written): one with no value makes the literal never hold (literal()).
  std::vector<std::pair<Pos, Arg>> operands_;
  std::map<std::string, std::uint32_t> var_index_;
  std::map<std::string, std::uint32_t> const_index_;
  std::map<std::pair<std::string, std::uint32_t>, std::uint32_t> pred_index_;
};

Arg Parser::constant(const node::Term& term) {
  std::string key = std::to_string(static_cast<int>(term.kind)) + term.to_ntriples();
  auto [it, fresh] = const_index_.try_emplace(key, static_cast<std::uint32_t>(program_.constants.size()));
  if (fresh) program_.constants.push_back(term);
  return Arg{false, it->second};
}

Arg Parser::variable(const std::string& name, Pos pos) {
  if (name != "_") {
    auto it = var_index_.find(name);
    if (it != var_index_.end()) return Arg{true, it->second};
  }
  std::uint32_t index = rule_->vars++;
  rule_->var_names.push_back(name);
  rule_->var_pos.push_back(pos);
  if (name != "_") var_index_[name] = index;
  return Arg{true, index};
}

std::uint32_t Parser::pred(const std::string& iri, std::uint32_t arity) {
  auto [it, fresh] = pred_index_.try_emplace({iri, arity}, static_cast<std::uint32_t>(program_.preds.size()));
  if (fresh) program_.preds.push_back(Pred{iri, arity, false, false});
  return it->second;
}

Result<Arg> Parser::term(bool allow_now) {
  Token t = tok_;
  if (t.kind == Tok::var) {
    if (auto a = advance(); !a) return unexpected(a.error());
    return variable(t.text, t.pos);
  }
  if (t.kind == Tok::literal) {
    if (auto a = advance(); !a) return unexpected(a.error());
    return constant(t.term);
  }
  if (t.kind == Tok::name && (t.text == "true" || t.text == "false")) {
    // As Turtle and the command line read them: the trend agent's `tv:alert true` is a boolean,
    // and `tv:alert(T, true)` read as the IRI <default-ns#true> matched nothing, silently.
    if (auto a = advance(); !a) return unexpected(a.error());
    if (is("(")) return error(t.pos, "a compound term such as " + t.text + "(...) cannot be an argument");
    return constant(node::Term::literal(t.text, std::string(node::xsd::kBoolean)));
  }
  if (t.kind == Tok::iri || (t.kind == Tok::name && (allow_now || t.text != "now"))) {
    if (auto a = advance(); !a) return unexpected(a.error());
    // `N is max(V, 2)` and `N is count(W)` came here: said as the comparison's function is.
    if (is("("))
      return error(t.pos, "a compound term such as " + t.text +
                              "(...) cannot be an argument, and there are no functions: arithmetic is + - * / and "
                              "parentheses on numbers and times (no abs, min, max, count, ...: there is no aggregation)");
    return constant(node::Term::iri(t.kind == Tok::iri ? t.text : name_iri(t.text)));
  }
  if (is("-")) {  // a negative number
    if (auto a = advance(); !a) return unexpected(a.error());
    if (tok_.kind != Tok::literal || tok_.term.datatype.empty() || tok_.term.datatype == node::xsd::kString ||
        tok_.term.value.empty() || !std::isdigit(static_cast<unsigned char>(tok_.term.value[0])))
      return expected("a number after '-'");
    node::Term neg = tok_.term;
    neg.value = "-" + neg.value;
    if (neg.value == "-0") neg.value = "0";
    if (auto a = advance(); !a) return unexpected(a.error());
    return constant(neg);
  }
  // '<' is read as an IRI only when a scheme and ':' start a run without spaces up to '>'; an
  // IRI with a space or no scheme was "found '<'" and nothing more.
  if (is("<") && !tok_.relative_iri.empty())
    return error(tok_.pos, "expected a term, found " + tok_.relative_iri +
                               ", an IRI without a scheme: rules are not resolved against a base, so write an absolute "
                               "IRI (<http://...>), a prefixed name (ex:name), #name in the default namespace, or me");
  if (is("<"))
    return error(tok_.pos, "expected a term, found '<' that starts no IRI: an IRI is <scheme:...> up to '>' without "
                           "spaces (escape a space as %20), and '<' alone is 'less than'");
  return expected("a term (variable, IRI, atom, string or number)");
}

Unexpected<Error> too_deep(const Program& program, Pos pos) {
  return unexpected(Error{where(program, pos) + ": expression nested deeper than " +
                          std::to_string(kMaxExpressionDepth) +
                          " levels (each parenthesis, sign and operator is one)"});
}

// The inner expression of a parenthesis or a sign at `pos`, one level deeper.
Result<Expr> Parser::nested(Pos pos, const std::function<Result<Expr>()>& parse_inner) {
  if (nesting_ >= kMaxExpressionDepth) return too_deep(program_, pos);
  ++nesting_;
  auto inner = parse_inner();
  --nesting_;
  return inner;
}

// The node `kind` over `a` (and `b`), unless the tree grows deeper than the bound.
Result<Expr> Parser::combine(Expr::Kind kind, Pos pos, Expr a, std::optional<Expr> b) {
  Expr e;
  e.kind = kind;
  e.depth = 1 + std::max(a.depth, b ? b->depth : 0);
  if (e.depth > kMaxExpressionDepth) return too_deep(program_, pos);
  e.a = std::make_shared<Expr>(std::move(a));
  if (b) e.b = std::make_shared<Expr>(std::move(*b));
  return e;
}

Result<Expr> Parser::unary() {
  const Pos pos = tok_.pos;
  if (is("-")) {
    if (auto a = advance(); !a) return unexpected(a.error());
    auto inner = nested(pos, [&] { return unary(); });
    if (!inner) return inner;
    return combine(Expr::neg, pos, std::move(*inner), std::nullopt);
  }
  if (is("(")) {
    if (auto a = advance(); !a) return unexpected(a.error());
    auto inner = nested(pos, [&] { return expression(); });
    if (!inner) return inner;
    if (tok_.kind == Tok::name) return not_an_operator();  // (S mod 2)
    if (auto c = expect(")", "')' closing the expression"); !c) return unexpected(c.error());
    return inner;
  }
  if (tok_.kind == Tok::name && tok_.text == "now") {
    if (auto a = advance(); !a) return unexpected(a.error());
    rule_->uses_now = true;
    Expr e;
    e.kind = Expr::now;
    return e;
  }
  auto arg = term(false);
  if (!arg) return unexpected(arg.error());
  if (!arg->is_var) operands_.emplace_back(pos, *arg);
  Expr e;
  e.leaf = *arg;
  return e;
}

Result<Expr> Parser::product() {
  auto left = unary();
  if (!left) return left;
  while (is("*") || is("/")) {
    const Pos pos = tok_.pos;
    const Expr::Kind kind = is("*") ? Expr::mul : Expr::div;
    if (auto a = advance(); !a) return unexpected(a.error());
    if (kind == Expr::div && is("/"))
      return error(pos, "'//' is not an operator: write X / Y, an integer when it divides exactly (a double otherwise)");
    auto right = unary();
    if (!right) return right;
    left = combine(kind, pos, std::move(*left), std::move(*right));
    if (!left) return left;
  }
  return left;
}

Result<Expr> Parser::expression() {
  auto left = product();
  if (!left) return left;
  while (is("+") || is("-")) {
    const Pos pos = tok_.pos;
    const Expr::Kind kind = is("+") ? Expr::add : Expr::sub;
    if (auto a = advance(); !a) return unexpected(a.error());
    auto right = product();
    if (!right) return right;
    left = combine(kind, pos, std::move(*left), std::move(*right));
    if (!left) return left;
  }
  return left;
}

// An atom: name, name(args), fact(S, P, O) and the built-ins now/1, lesstime/2, not/1.
Result<Literal> Parser::callable(bool negated) {
  Token head = tok_;
  if (head.kind != Tok::name && head.kind != Tok::iri) return expected("a predicate");
  if (auto a = advance(); !a) return unexpected(a.error());
  Literal lit;
  lit.pos = head.pos;
  lit.kind = negated ? Literal::negation : Literal::atom;
  if (head.kind == Tok::name && head.text == "not" && is("(")) {
    if (negated) return error(head.pos, "not(...) inside a negation");
    if (auto a = advance(); !a) return unexpected(a.error());
    auto inner = callable(true);
    if (!inner) return inner;
    if (auto c = expect(")", "')' closing not("); !c) return unexpected(c.error());
    return inner;
  }
  std::vector<Arg> args;
  if (is("(")) {
    if (auto a = advance(); !a) return unexpected(a.error());
    for (;;) {
      auto arg = term(false);
      if (!arg) return unexpected(arg.error());
      args.push_back(*arg);
      if (is(")")) break;
      if (auto c = expect(",", "',' or ')' in the arguments of " + head.text); !c) return unexpected(c.error());
    }
    if (auto a = advance(); !a) return unexpected(a.error());
  }
  if (args.size() > kMaxArity) return error(head.pos, head.text + ": at most " + std::to_string(kMaxArity) + " arguments");
  // A built-in's name with other arguments was an atom no rule defines, which never held: the
  // rule derived nothing, without a word (RS5).
  if (head.kind == Tok::name) {
    const std::string written = std::to_string(args.size()) + (args.size() == 1 ? " argument" : " arguments");
    if (head.text == "now" && args.size() != 1)
      return error(head.pos, "now is a built-in of one argument, now(T) (or 'now' inside an expression); written with " + written);
    if (head.text == "lesstime" && args.size() != 2)
      return error(head.pos, "lesstime is a built-in of two arguments, lesstime(A, B) (A before B); written with " + written);
    if (head.text == "skolem" && args.size() < 2)
      return error(head.pos, "skolem is a built-in of two or more arguments, skolem(L, A1, ...); written with " + written);
    // Negated, each was an atom of that name that no rule defines, so the negation always held.
    if (negated && head.text == "lesstime")
      return error(head.pos, "lesstime cannot be negated (it would hold for arguments that are not times); write the opposite "
                             "comparison, B =< A for \\+ lesstime(A, B)");
    if (negated && (head.text == "now" || head.text == "skolem"))
      return error(head.pos, head.text + " cannot be negated: it binds its first argument and always holds");
  }
  if (head.kind == Tok::name && !negated) {
    if (head.text == "now" && args.size() == 1) {
      rule_->uses_now = true;
      lit.kind = Literal::assign;
      lit.lhs.leaf = args[0];
      lit.rhs.kind = Expr::now;
      return lit;
    }
    if (head.text == "skolem" && args.size() >= 2) {
      lit.kind = Literal::skolem;
      lit.args = std::move(args);
      return lit;
    }
    if (head.text == "lesstime" && args.size() == 2) {
      lit.kind = Literal::compare;
      lit.op = Literal::lt;
      lit.lhs.leaf = args[0];
      lit.rhs.leaf = args[1];
      return lit;
    }
  }
  if (head.kind == Tok::name && head.text == "fact" && args.size() == 3) {
    const Arg& p = args[1];
    if (p.is_var) {
      lit.pred = kAnyBinary;
      lit.args = args;
      return lit;
    }
    const node::Term& pt = program_.constants[p.index];
    if (!pt.is_iri()) return error(head.pos, "the predicate of fact(S, P, O) must be an IRI, not " + pt.to_ntriples());
    lit.pred = pred(pt.value, 2);
    lit.args = {args[0], args[2]};
    return lit;
  }
  std::string iri = head.kind == Tok::iri ? head.text : options_.default_ns + head.text;
  lit.pred = pred(iri, static_cast<std::uint32_t>(args.size()));
  lit.args = std::move(args);
  return lit;
}

Result<Literal> Parser::literal() {
  Pos start = tok_.pos;
  if (is("!")) {
    if (auto a = advance(); !a) return unexpected(a.error());
    Literal cut;
    cut.kind = Literal::cut;
    cut.pos = start;
    return cut;
  }
  if (is("\\+")) {
    if (auto a = advance(); !a) return unexpected(a.error());
    bool paren = is("(");
    if (paren) { if (auto a = advance(); !a) return unexpected(a.error()); }
    // \+ Y = X: a comparison is negated by the operator of the opposite.
    if (tok_.kind == Tok::var || tok_.kind == Tok::literal || (tok_.kind != Tok::end && operator_follows()))
      return error(tok_.pos, "\\+ negates an atom (\\+ p(X)); a comparison is negated by its opposite operator: "
                             "\\= for =, \\== for ==, =\\= for =:=, >= for <, =< for >");
    auto inner = callable(true);
    if (!inner) return inner;
    if (paren && is(","))
      return error(tok_.pos, "\\+ negates one atom, not a conjunction: give the conjunction a predicate of its own "
                             "(both(X) :- a(X), b(X).) and negate that (\\+ both(X))");
    if (paren) { if (auto c = expect(")", "')' after the negated atom"); !c) return unexpected(c.error()); }
    return inner;
  }
  // not p(X), negation written as an operator, parsed as the atom not followed by another.
  if (tok_.kind == Tok::name && tok_.text == "not") {
    auto saved = lexer_.state();
    auto next = lexer_.next();
    lexer_.restore(saved);
    if (next && (next->kind == Tok::iri || (next->kind == Tok::name && next->text != "is")))
      return error(start, "'not' negates in parentheses only: write not(p(X)) or \\+ p(X)");
  }
  // (fact(X, p, Y)) or (X > 3 ; …): a literal in parentheses, which an arithmetic expression
  // cannot start with ((Y + 1) > 3 is one).
  if (is("(")) {
    static const char* kComparisons[] = {"<", ">", "=<", ">=", "=:=", "=\\=", "=", "\\=", "==", "\\=="};
    auto saved = lexer_.state();
    bool literal_inside = false;
    if (auto first = lexer_.next(); first && first->kind != Tok::punct && first->kind != Tok::end)
      if (auto second = lexer_.next(); second) {
        const bool name = first->kind == Tok::name || first->kind == Tok::iri;
        literal_inside = (name && second->kind == Tok::punct && second->text == "(") ||
                         (second->kind == Tok::name && second->text == "is");
        for (const char* op : kComparisons) literal_inside |= second->kind == Tok::punct && second->text == op;
      }
    lexer_.restore(saved);
    if (literal_inside)
      return error(start, "a literal in parentheses: write it without them (a body is literals joined by ','; for "
                          "alternatives, one rule each)");
  }
  // A name starts an atom unless an operator follows it (then it is a constant in a term).
  bool name_like = tok_.kind == Tok::name || tok_.kind == Tok::iri;
  if (name_like && !operator_follows()) return callable(false);
  operands_.clear();
  auto left = expression();
  if (!left) return unexpected(left.error());
  const std::size_t left_operands = operands_.size();
  Literal lit;
  lit.pos = start;
  lit.lhs = std::move(*left);
  struct OpName { const char* text; Literal::Kind kind; Literal::Op op; };
  static const OpName kOps[] = {
      {"<", Literal::compare, Literal::lt},   {">", Literal::compare, Literal::gt},
      {"=<", Literal::compare, Literal::le},  {">=", Literal::compare, Literal::ge},
      {"=:=", Literal::compare, Literal::eq}, {"=\\=", Literal::compare, Literal::ne},
      {"=", Literal::unify, Literal::eq},     {"\\=", Literal::not_unify, Literal::ne},
      {"==", Literal::identical, Literal::eq}, {"\\==", Literal::not_unify, Literal::ne}};
  const OpName* found = nullptr;
  for (const OpName& op : kOps) if (is(op.text)) found = &op;
  // Operators of other languages lex as two of ours ("<=" as "<" then "="): named whole, with
  // the one meant, rather than reported as a term missing after the first.
  if (auto other = foreign_operator()) return unexpected(*other);
  if (tok_.kind == Tok::name && tok_.text == "is") {
    if (lit.lhs.kind != Expr::arg) return error(start, "the left side of 'is' must be a variable or constant");
    lit.kind = Literal::assign;
  } else if (found) {
    lit.kind = found->kind;
    lit.op = found->op;
  } else {
    if (tok_.kind == Tok::name) return not_an_operator();  // S mod 2 =:= 0
    return expected("a comparison operator (< > =< >= =:= =\\= = \\= == \\==) or 'is'");
  }
  if (auto a = advance(); !a) return unexpected(a.error());
  auto right = expression();
  if (!right) return unexpected(right.error());
  lit.rhs = std::move(*right);
  bool terms_only = lit.kind == Literal::unify || lit.kind == Literal::not_unify || lit.kind == Literal::identical;
  if (terms_only && (lit.lhs.kind != Expr::arg || lit.rhs.kind != Expr::arg))
    return error(start, "=, \\=, == and \\== compare terms; use 'is' or =:= for arithmetic");
  // A string or an IRI compares with nothing and adds to nothing: `S < "50"` was accepted and its
  // rule never fired, without a word (a researcher's probe of session 87). The left side of
  // 'is' is a term to match, not an operand.
  if (!terms_only) {
    for (std::size_t k = lit.kind == Literal::assign ? left_operands : 0; k < operands_.size(); ++k) {
      const auto& [at, operand] = operands_[k];
      const node::Term& constant = program_.constants[operand.index];
      if (value_of(constant).kind != Value::none) continue;
      return error(at, without_value(constant) + ", not a number or a time: " +
                           (lit.kind == Literal::assign ? "'is' computes nothing from it" : "a comparison with it never holds"));
    }
  }
  return lit;
}

// What a constant without a value is, for the error above: "\"50\" is a string (write 50 for the
// number)", "<…#limit> is an IRI".
std::string Parser::without_value(const node::Term& constant) const {
  if (constant.is_iri()) return "<" + constant.value + "> is an IRI";
  if (!constant.is_literal()) return constant.to_ntriples() + " is a blank node";
  const std::string written = constant.to_ntriples();
  if (!constant.datatype.empty() && constant.datatype != node::xsd::kString) return written + " is of a datatype the built-ins do not read";
  for (std::string_view type : {node::xsd::kInteger, node::xsd::kDecimal, node::xsd::kDouble})
    if (value_of(node::Term::literal(constant.value, std::string(type))).kind != Value::none)
      return written + " is a string (write " + constant.value + " for the number)";
  return written + " is a string";
}

// Whether a comparison or arithmetic operator, or 'is', follows the current token: a name then
// is a constant in a term, not an atom.
bool Parser::operator_follows() {
  auto saved = lexer_.state();
  auto peek = lexer_.next();
  lexer_.restore(saved);
  if (!peek) return false;  // the lexer's error comes again when the token is read
  static const char* kOps[] = {"<", ">", "=<", ">=", "=:=", "=\\=", "=", "\\=", "==", "\\==", "+", "-", "*", "/"};
  bool follows = peek->kind == Tok::name && peek->text == "is";
  for (const char* op : kOps) follows |= peek->kind == Tok::punct && peek->text == op;
  return follows;
}

// An operator as other languages write it, at the current token: "<=", "=>", "!=".
std::optional<Error> Parser::foreign_operator() {
  static const std::pair<std::string_view, std::string_view> kForeign[] = {
      {"<=", "less than or equal is written =<"},
      {"=>", "greater than or equal is written >="},
      {"!=", "write \\= (terms differ) or =\\= (numbers differ)"}};
  if (tok_.kind != Tok::punct) return std::nullopt;
  auto saved = lexer_.state();
  auto next = lexer_.next();
  lexer_.restore(saved);
  if (!next || next->kind != Tok::punct || next->pos.line != tok_.pos.line ||
      next->pos.col != tok_.pos.col + static_cast<int>(tok_.text.size()))
    return std::nullopt;
  for (const auto& [text, advice] : kForeign)
    if (tok_.text + next->text == text)
      return Error{where(program_, tok_.pos) + ": '" + std::string(text) + "' is not an operator: " + std::string(advice)};
  return std::nullopt;
}

Result<std::vector<Literal>> Parser::body() {
  std::vector<Literal> out;
  for (;;) {
    // Each delta variant of a rule is planned afresh, in time that grows with the cube of the
    // body's length: 800 literals took 1.6 s and 3,000 over a minute, on every reload.
    if (out.size() == kMaxBodyLiterals)
      return error(tok_.pos, "a rule body has at most " + std::to_string(kMaxBodyLiterals) +
                                 " literals; split it with a predicate of its own for a part");
    const Token first = tok_;
    auto lit = literal();
    if (!lit) return unexpected(lit.error());
    if (!is(",") && !is(".")) {
      // Functions and operators of other languages: abs(S) < 50 read as the atom abs(S), and
      // S mod 2 as S then a stray name, said as "expected ',' or '.' after the literal".
      static const char* kOperators[] = {"<", ">", "=<", ">=", "=:=", "=\\=", "+", "-", "*", "/"};
      bool operator_next = tok_.kind == Tok::name && tok_.text == "is";
      for (const char* op : kOperators) operator_next |= is(op);
      if (lit->kind == Literal::atom && first.kind == Tok::name && operator_next)
        return error(first.pos, first.text + "(...) is not a function here: arithmetic is + - * / and parentheses on "
                                             "numbers and times, with no functions (abs, min, max, ...)");
      if ((lit->kind == Literal::compare || lit->kind == Literal::assign) && tok_.kind == Tok::name) {
        // A name and '(' begins an atom: a ',' left out before it, not an operator.
        auto saved = lexer_.state();
        auto next = lexer_.next();
        lexer_.restore(saved);
        if (next && next->kind == Tok::punct && next->text == "(")
          return error(tok_.pos, "expected ',' before " + tok_.text + "(...): a body's literals are joined by ','");
        return not_an_operator();
      }
    }
    out.push_back(std::move(*lit));
    if (!is(",")) return out;
    if (auto a = advance(); !a) return unexpected(a.error());
  }
}

Result<void> Parser::clause() {
  program_.rules.emplace_back();
  rule_ = &program_.rules.back();
  rule_->pos = tok_.pos;
  var_index_.clear();
  Token head = tok_;
  auto h = callable(false);
  if (!h) return unexpected(h.error());
  if (h->kind != Literal::atom) return error(head.pos, "a built-in cannot be a conclusion");
  if (h->pred == kAnyBinary) return error(head.pos, "the predicate of a conclusion must be a constant, not a variable");
  rule_->head = h->pred;
  rule_->head_args = h->args;
  if (is(":-")) {
    if (auto a = advance(); !a) return unexpected(a.error());
    auto b = body();
    if (!b) return unexpected(b.error());
    rule_ = &program_.rules.back();
    rule_->body = std::move(*b);
  }
  ++program_.written_rules;
  return expect(".", "',' or '.' after the literal");
}

// :- prefix(name, <iri>).   :- ranked(pred/N).
Result<void> Parser::directive() {
  Pos start = tok_.pos;
  if (auto a = advance(); !a) return a;
  if (tok_.kind != Tok::name) return expected("a directive (prefix or ranked)");
  std::string which = tok_.text;
  if (which != "prefix" && which != "ranked") {
    // Prolog's directives: what they ask for holds here already, or has no meaning.
    if (which == "table" || which == "dynamic" || which == "discontiguous")
      return error(start, "':- " + which + "' is a Prolog directive with no use here: rules are evaluated bottom-up to a "
                          "fixpoint, every predicate as if tabled and open to new facts; remove it");
    return error(start, "unknown directive '" + which + "' (known: prefix, ranked)");
  }
  if (auto a = advance(); !a) return a;
  if (auto c = expect("(", "'(' after " + which); !c) return c;
  if (which == "prefix") {
    if (tok_.kind != Tok::name && tok_.kind != Tok::var) return expected("a prefix name");
    std::string name = tok_.text;
    if (auto a = advance(); !a) return a;
    if (auto c = expect(",", "',' after the prefix name"); !c) return c;
    std::string ns;
    if (tok_.kind == Tok::iri) ns = tok_.text;
    else if (tok_.kind == Tok::literal) ns = tok_.term.value;
    else return expected("the namespace IRI as <iri> or \"iri\"");
    if (auto added = prefixes_.add(name, ns); !added)
      return error(start, "prefix " + name + ": " + added.error().message);
    lexer_.declare(name, ns);
    if (auto a = advance(); !a) return a;
  } else {  // ranked
    Token name = tok_;
    if (name.kind != Tok::name && name.kind != Tok::iri) return expected("a predicate name");
    if (auto a = advance(); !a) return a;
    if (auto c = expect("/", "'/' and the arity after the predicate"); !c) return c;
    if (tok_.kind != Tok::literal || tok_.term.datatype != node::xsd::kInteger) return expected("the arity");
    std::uint32_t arity = 0;
    auto [end, ec] = std::from_chars(tok_.term.value.data(), tok_.term.value.data() + tok_.term.value.size(), arity);
    if (ec != std::errc() || arity > kMaxArity)
      return error(tok_.pos, "arity " + tok_.term.value + " is out of range (at most " + std::to_string(kMaxArity) + ")");
    std::string iri = name.kind == Tok::iri ? name.text : options_.default_ns + name.text;
    const std::uint32_t ranked = pred(iri, arity);
    program_.preds[ranked].ranked = true;
    program_.ranked_declarations.emplace_back(ranked, name.pos);
    if (auto a = advance(); !a) return a;
  }
  if (auto c = expect(")", "')' closing the directive"); !c) return c;
  return expect(".", "'.' after the directive");
}

Result<void> Parser::run() {
  if (auto a = advance(); !a) return a;
  while (tok_.kind != Tok::end) {
    Result<void> r;
    if (is(":-")) {
      r = directive();
    } else if (is("@prefix")) {
      // Turtle's form: @prefix p: <iri> .
      Pos start = tok_.pos;
      auto name = lexer_.prefix_name();
      if (!name) return unexpected(name.error());
      if (auto a = advance(); !a) return a;
      if (tok_.kind != Tok::iri) return expected("the namespace <iri> of @prefix " + *name + ":");
      if (auto added = prefixes_.add(*name, tok_.text); !added)
        return error(start, "prefix " + *name + ": " + added.error().message);
      lexer_.declare(*name, tok_.text);
      if (auto a = advance(); !a) return a;
      r = expect(".", "'.' after @prefix");
    } else {
      r = clause();
    }
    if (!r) return r;
  }
  return {};
}

}  // namespace

Result<std::shared_ptr<Program>> parse_program(std::string_view text, const ParseOptions& options) {
  auto program = std::make_shared<Program>();
  program->file = options.file;
  program->me = options.me;
  if (!uri::normalize(options.default_ns)) return unexpected(Error{options.file + ": the default namespace '" + options.default_ns + "' is not an absolute IRI"});
  if (!uri::normalize(options.me)) return unexpected(Error{options.file + ": the node IRI '" + options.me + "' (me) is not an absolute IRI"});
  // The store refuses a term that is not UTF-8 only when a conclusion is written: a running
  // reasoner given such a file ended there, instead of naming the place and keeping its rules.
  const auto where = [&](std::size_t bad) {  // "FILE:LINE:COL" of byte `bad` (columns in characters), as the lexer counts
    std::size_t line = 1, line_start = 0;
    for (std::size_t k = 0; k < bad; ++k)
      if (text[k] == '\n' || (text[k] == '\r' && (k + 1 >= text.size() || text[k + 1] != '\n'))) {
        ++line;
        line_start = k + 1;
      }
    std::size_t col = 1;
    for (std::size_t k = line_start; k < bad; ++k)
      if ((static_cast<unsigned char>(text[k]) & 0xC0) != 0x80) ++col;
    return options.file + ":" + std::to_string(line) + ":" + std::to_string(col);
  };
  if (const std::size_t bad = node::ill_formed_utf8_at(text); bad != std::string_view::npos) {
    char byte[8];
    std::snprintf(byte, sizeof byte, "0x%02X", static_cast<unsigned char>(text[bad]));
    return unexpected(Error{where(bad) + ": not UTF-8: byte " + byte + " begins no UTF-8 character"});
  }
  // The parser reads a NUL as the end of the text: the rules after one (a file padded with NULs
  // by a crash, say) were dropped without a word, and their conclusions withdrawn.
  if (const std::size_t nul = text.find('\0'); nul != std::string_view::npos)
    return unexpected(Error{where(nul) + ": a NUL byte (0x00): a rule file is text, and nothing after it would be read"});
  Parser parser(text, options, *program);
  if (auto r = parser.run(); !r) return unexpected(r.error());
  return program;
}

}  // namespace tahvel::reasoner
