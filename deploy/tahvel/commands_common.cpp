// Helpers shared by the `tahvel` subcommands: terms and patterns from the command line, the
// prefix table, input and output. Everything here runs once per invocation (not hot).
#include <algorithm>
#include <cctype>
#include <charconv>
#include <chrono>
#include <cerrno>
#include <cstring>
#include <ctime>
#include <climits>
#include <condition_variable>
#include <mutex>
#include <optional>
#include <deque>
#include <limits>
#include <poll.h>
#include <sys/stat.h>
#include <unistd.h>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <iterator>
#include <set>
#include <sstream>
#include <streambuf>
#include <thread>

#include "commands.h"
#include "topology.h"
#include "vocabulary.h"
#include "tahvel/spatial/wkt.h"
#include "tahvel/uri/unicode_escape.h"

namespace tahvel::cli {
namespace {

using node::Term;

[[noreturn]] void bad_value(std::string_view flag, std::string_view why) {
  usage_error(std::string(flag) + ": " + std::string(why));
}

bool all_digits(std::string_view s) {
  return !s.empty() && s.find_first_not_of("0123456789") == std::string_view::npos;
}

std::string_view strip_sign(std::string_view s) {
  return (!s.empty() && (s[0] == '+' || s[0] == '-')) ? s.substr(1) : s;
}

bool is_integer(std::string_view s) { return all_digits(strip_sign(s)); }

bool is_decimal(std::string_view s) {
  s = strip_sign(s);
  auto dot = s.find('.');
  if (dot == std::string_view::npos) return false;
  std::string_view whole = s.substr(0, dot), frac = s.substr(dot + 1);
  return all_digits(frac) && (whole.empty() || all_digits(whole));
}

bool is_double(std::string_view s) {
  auto e = s.find_first_of("eE");
  if (e == std::string_view::npos) return false;
  std::string_view mantissa = s.substr(0, e), exponent = s.substr(e + 1);
  bool mantissa_ok = is_integer(mantissa) || is_decimal(mantissa) ||
                     (mantissa.ends_with('.') && is_integer(mantissa.substr(0, mantissa.size() - 1)));
  return mantissa_ok && is_integer(exponent);
}

// A bare number or boolean, as Turtle abbreviates them.
std::optional<Term> bare_literal(std::string_view s) {
  if (is_integer(s)) return Term::literal(std::string(s), std::string(node::xsd::kInteger));
  if (is_decimal(s)) return Term::literal(std::string(s), std::string(node::xsd::kDecimal));
  if (is_double(s)) return Term::literal(std::string(s), std::string(node::xsd::kDouble));
  if (s == "true" || s == "false") {
    return Term::literal(std::string(s), std::string(node::xsd::kBoolean));
  }
  return std::nullopt;
}

// Decodes \uXXXX or \UXXXXXXXX at text[i] (the 'u' or 'U'); returns the characters consumed.
std::size_t unicode_escape(std::string_view text, std::size_t i, std::string& out,
                           std::string_view flag) {
  std::size_t n = text[i] == 'u' ? 4 : 8;
  if (i + n >= text.size()) bad_value(flag, "truncated \\u escape");
  auto c = uri::escaped_code_point(text.substr(i + 1, n));
  if (!c) bad_value(flag, "\\" + std::string(1, text[i]) + " escape: not " + std::to_string(n) + " hex digits of a character");
  uri::append_utf8(out, *c);
  return n;
}

char simple_escape(char c) {
  switch (c) {
    case 't': return '\t';
    case 'b': return '\b';
    case 'n': return '\n';
    case 'r': return '\r';
    case 'f': return '\f';
    case '"': return '"';
    case '\'': return '\'';
    case '\\': return '\\';
    default: return 0;
  }
}

// Reads the quoted part of "lexical"...; returns the lexical form and sets `end` after the
// closing quote.
std::string quoted_lexical(std::string_view text, std::size_t& end, std::string_view flag) {
  std::string lexical;
  for (std::size_t i = 1; i < text.size(); ++i) {
    char c = text[i];
    if (c == '"') {
      end = i + 1;
      return lexical;
    }
    if (c != '\\') {
      lexical += c;
      continue;
    }
    if (++i >= text.size()) break;
    if (text[i] == 'u' || text[i] == 'U') {
      i += unicode_escape(text, i, lexical, flag);
    } else if (char e = simple_escape(text[i])) {
      lexical += e;
    } else {
      bad_value(flag, std::string("unknown escape '\\") + text[i] + "' in literal");
    }
  }
  bad_value(flag, "literal " + std::string(text) + " has no closing quote");
}

bool valid_language(std::string_view tag) {
  std::size_t part = 0;
  for (std::size_t i = 0; i <= tag.size(); ++i) {
    if (i == tag.size() || tag[i] == '-') {
      if (part == 0 || part > 8) return false;
      part = 0;
      continue;
    }
    char c = tag[i];
    bool alpha = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z');
    bool digit = c >= '0' && c <= '9';
    if (!alpha && !(digit && i > tag.find('-'))) return false;
    ++part;
  }
  return !tag.empty();
}

std::string lower(std::string_view s) {
  std::string out(s);
  for (char& c : out) {
    if (c >= 'A' && c <= 'Z') c = static_cast<char>(c - 'A' + 'a');
  }
  return out;
}

Term quoted_literal(std::string_view text, const uri::PrefixMap& prefixes,
                    std::string_view flag) {
  std::size_t end = 0;
  std::string lexical = quoted_lexical(text, end, flag);
  std::string_view rest = text.substr(end);
  if (rest.empty()) return Term::literal(std::move(lexical));
  if (rest.starts_with("@")) {
    if (!valid_language(rest.substr(1))) {
      bad_value(flag, "invalid language tag '" + std::string(rest.substr(1)) + "'");
    }
    return Term::lang_literal(std::move(lexical), lower(rest.substr(1)));
  }
  if (rest.starts_with("^^")) {
    return Term::literal(std::move(lexical), parse_iri(rest.substr(2), prefixes, flag));
  }
  bad_value(flag, "unexpected '" + std::string(rest) + "' after literal (expected @lang or ^^type)");
}

// Schemes that are written without "//" and so cannot be told from a CURIE by shape alone.
bool opaque_scheme(std::string_view scheme) {
  // Schemes are case-insensitive (RFC 3986 3.1): "URN:example:x" is the IRI urn:example:x, not
  // a CURIE of an unknown prefix "URN".
  const auto same = [](std::string_view a, std::string_view b) {
    return a.size() == b.size() && std::equal(a.begin(), a.end(), b.begin(), [](char x, char y) {
             return std::tolower(static_cast<unsigned char>(x)) == y;
           });
  };
  for (std::string_view s : {"urn", "mailto", "tag", "did", "data", "uuid", "geo"}) {
    if (same(scheme, s)) return true;
  }
  return false;
}

void check_no_space(std::string_view text, std::string_view flag) {
  if (text.find_first_of(" \t\n") != std::string_view::npos) {
    bad_value(flag, "'" + std::string(text) + "' contains white space");
  }
}

bool has_flag_spec(const Args& args, std::string_view name) {
  for (const Flag& f : args.command().flags) {
    if (f.name == name) return true;
  }
  return false;
}

}  // namespace

void check(node::Result<void>&& result) {
  if (!result) fail(result.error().message);
}

node::Node open_node(const std::string& dir) { return check(node::Node::open(dir)); }

uri::PrefixMap prefixes_with_flags(uri::PrefixMap base, const Args& args) {
  for (const std::string& entry : args.all("--prefix")) {
    auto eq = entry.find('=');
    if (eq == std::string::npos) bad_value("--prefix", "'" + entry + "' is not P=IRI");
    auto added = base.add(std::string_view(entry).substr(0, eq),
                          std::string_view(entry).substr(eq + 1));
    if (!added) bad_value("--prefix", added.error().message);
  }
  return base;
}

bool board_knows_agent(const node::Snapshot& snapshot, const std::string& agent) {
  const node::Term who = node::Term::iri(agent);
  auto any = [&](const node::Pattern& pattern) {  // stops at the first: an index lookup
    bool found = false;
    auto read = snapshot.for_each(pattern, [&](const node::Record&) { return !(found = true); });
    return found || !read;  // a read error is not the user's mistake
  };
  // A subscription counts when the agent wrote it: one written for it by another (a parent's
  // forwarding policy with the uplink misspelt) routed items into a buffer nothing reads, unsaid.
  return any({.s = who}) ||
         any({.p = node::Term::iri(std::string(uri::kTahvelNs) + "subscriber"), .o = who, .source = agent}) ||
         any({.source = agent});
}

std::vector<std::string> child_nodes_known(const node::Node& node, const node::Snapshot& snapshot) {
  std::set<std::string> children;
  auto listed = snapshot.list({.p = node::Term::iri(std::string(uri::kTahvelNs) + "linkState")});
  if (listed)
    for (const node::Record& r : *listed)
      if (r.triple.s.is_iri() && node.addressee(r.triple.s.value) == r.triple.s.value)
        children.insert(r.triple.s.value.substr(node.iri().size() + (node.iri().ends_with('/') ? 0 : 1)));
  return {children.begin(), children.end()};
}

std::string agent_id(const Args& args, std::string_view fallback) {
  std::string id = args.get("--agent").value_or(std::string(fallback));
  auto checked = uri::check_id(id);
  if (!checked) bad_value("--agent", checked.error().message);
  // The board is open to every local process, so this is said, not refused (a test may write as
  // the supervisor on purpose); but an operator who borrowed such an id by chance would see the
  // items taken from or mixed with a running program's, or the supervisor's replaced within seconds.
  if (const char* owner = agent_id_in_use(id); owner && id != fallback && id != "cli")
    std::cerr << warning_prefix() << "--agent " << id << ": on a node that `tahvel up` runs, that agent is " << owner
              << "; what this command writes or takes as '" << id << "' mixes with that program's own\n";
  return id;
}

std::string parse_iri(std::string_view text, const uri::PrefixMap& prefixes,
                      std::string_view flag) {
  check_no_space(text, flag);
  if (text.starts_with("<")) {
    if (const auto close = text.find('>'); close != std::string_view::npos && close + 1 < text.size())
      bad_value(flag, "'" + std::string(text) + "' goes on after the '>' that ends the IRI, at column " + std::to_string(close + 2) +
                          " ('" + std::string(text.substr(close + 1)) + "'): write the whole IRI inside <…>");
    if (!text.ends_with(">") || text.size() < 2) bad_value(flag, "'" + std::string(text) + "' lacks '>'");
    std::string_view inner = text.substr(1, text.size() - 2);
    auto normal = uri::normalize(inner);
    if (!normal) bad_value(flag, normal.error().message);
    return std::string(inner);  // as written: stored terms are compared as written
  }
  auto colon = text.find(':');
  if (colon == std::string_view::npos) {
    bad_value(flag, "'" + std::string(text) + "' is not an IRI or CURIE");
  }
  std::string prefix(text.substr(0, colon));
  if (prefixes.entries().contains(prefix)) {
    auto expanded = prefixes.expand(text);
    if (!expanded) bad_value(flag, expanded.error().message);
    return *expanded;
  }
  if (text.substr(colon + 1).starts_with("//") || opaque_scheme(prefix)) {
    auto normal = uri::normalize(text);
    if (!normal) bad_value(flag, normal.error().message);
    return std::string(text);
  }
  // A command line can add the prefix; a topology file's pattern uses the node's own prefixes,
  // and there the full IRI is what was meant.
  if (!flag.starts_with("-")) {
    std::string known;
    for (const auto& [name, ns] : prefixes.entries()) known += (known.empty() ? "" : ", ") + (name.empty() ? "':'" : name);
    bad_value(flag, "unknown prefix '" + prefix + "' in '" + std::string(text) + "' (" +
                        (known.empty() ? "no prefix is known" : "known: " + known) + "; write the full IRI in <…> for any other)");
  }
  bad_value(flag, "unknown prefix '" + prefix + "' in '" + std::string(text) + "' (add --prefix " + prefix + "=IRI, or write <" +
                      std::string(text) + "> for an absolute IRI)");
}

std::string parse_node_iri(std::string_view text, const uri::PrefixMap& prefixes, std::string_view flag, std::string_view here) {
  // A node's id alone (`--at home1`): named as the whole IRI it most likely means.
  if (!here.empty() && !text.empty() && text.find(':') == std::string_view::npos && !text.starts_with("<") &&
      uri::node_iri(std::string(here) + "/" + std::string(text)))
    bad_value(flag, "'" + std::string(text) + "' is not an IRI or CURIE: a node is named by its whole IRI (did you mean " +
                        std::string(here) + "/" + std::string(text) + "?)");
  std::string iri = parse_iri(text, prefixes, flag);
  // A node IRI has no query or fragment and no trailing '/' (uri::node_iri): asked of the tree,
  // `…/home1?x=1` came back "unknown node" and `…/home1/` was taken for home1.
  if (auto node = uri::node_iri(iri); !node) bad_value(flag, "not a node IRI: " + node.error().message);
  return iri;
}

node::Term parse_term(std::string_view text, const uri::PrefixMap& prefixes,
                      std::string_view flag, Position position) {
  if (text.empty()) bad_value(flag, "empty term");
  Term term;
  if (text.starts_with("\"")) {
    term = quoted_literal(text, prefixes, flag);
  } else if (text.starts_with("_:")) {
    if (text.size() == 2) bad_value(flag, "blank node without a label");
    check_no_space(text, flag);
    term = Term::blank(std::string(text.substr(2)));
  } else if (text == "a") {
    term = Term::iri(std::string(node::kRdfType));
  } else if (auto literal = bare_literal(text)) {
    term = *literal;
  } else {
    term = Term::iri(parse_iri(text, prefixes, flag));
  }
  if (term.is_literal() && (position == Position::subject || position == Position::predicate)) {
    bad_value(flag, "a literal cannot be a subject or predicate");
  }
  if (!term.is_iri() && position == Position::predicate) {
    bad_value(flag, "a predicate must be an IRI");
  }
  return term;
}

unsigned cascade_flag(const Args& args) {
  return static_cast<unsigned>(std::min<std::uint64_t>(args.get_u64("--cascade", 0), 1u << 20));
}

std::string one_of(const std::vector<std::string>& named, std::size_t of) {
  std::string text;
  for (std::size_t i = 0; i < named.size(); ++i)
    text += (i == 0 ? "" : i + 1 == named.size() && of == named.size() ? " or " : ", ") + named[i];
  if (of > named.size()) text += " or " + std::to_string(of - named.size()) + " more as near";
  return text;
}

void warn_of_a_predicate_held_by_none(std::string_view command, const node::Pattern& pattern,
                                      const std::vector<node::PredicateSummary>& held, const uri::PrefixMap& prefixes,
                                      const std::string& where) {
  if (!pattern.p || !pattern.p->is_iri()) return;
  const std::string& asked = pattern.p->value;
  // More than 3 edits away is another word, not a slip.
  const node::PredicateMatch match = node::match_predicate(asked, held, 4);
  if (match.held) return;
  const node::PredicateSummary* nearest = match.nearest;
  auto shown = [&](const std::string& iri) {
    std::string curie = prefixes.compact(iri);
    return curie == iri ? "<" + iri + ">" : curie;
  };
  std::cerr << "tahvel: " << command << ": warning: " << where << " has no record with the predicate " << shown(asked);
  auto counted = [](const node::PredicateSummary& p) {
    return " (" + std::to_string(p.records) + (p.records == 1 ? " record)" : " records)");
  };
  if (nearest) {
    std::vector<std::string> named{shown(nearest->predicate) + counted(*nearest)};
    for (const node::PredicateSummary* other : match.as_near)
      if (named.size() < 3) named.push_back(shown(other->predicate) + counted(*other));
    std::cerr << "; did you mean " << one_of(named, match.as_near.size() + 1) << "?";
  }
  else std::cerr << ".";
  // Raw ECG asked where it is not (as `tahvel ecg` says it): it stays where HRV is computed.
  if (!nearest && asked == std::string(uri::kTahvelNs) + "samples")
    std::cerr << " Raw ECG stays on the node that computes its HRV (usually a home): `tahvel patients` at the hospital prints, "
                 "for each recording, the query that brings it (--at that node).";
  std::cerr << " 'tahvel stats DIR --predicates" << (where.starts_with("<") ? " --at NODE-IRI" : "") << "' lists what it holds\n";
}

node::Pattern pattern_from_args(const Args& args, const uri::PrefixMap& prefixes) {
  node::Pattern pattern;
  if (auto s = args.get("-s")) pattern.s = parse_term(*s, prefixes, "-s", Position::subject);
  if (auto p = args.get("-p")) pattern.p = parse_term(*p, prefixes, "-p", Position::predicate);
  if (auto o = args.get("-o")) pattern.o = parse_term(*o, prefixes, "-o", Position::object);
  if (has_flag_spec(args, "--context")) {
    if (auto c = args.get("--context")) {
      pattern.context = c->empty() ? std::string() : parse_iri(*c, prefixes, "--context");
    }
  }
  if (has_flag_spec(args, "--source")) {
    if (auto src = args.get("--source")) pattern.source = parse_iri(*src, prefixes, "--source");
  }
  if (has_flag_spec(args, "--under")) {
    if (auto under = args.get("--under")) pattern.under = parse_iri(*under, prefixes, "--under");
  }
  if (has_flag_spec(args, "--since")) {
    if (auto since = args.get("--since")) pattern.since = time_flag("--since", *since);
    if (auto until = args.get("--until")) pattern.until = time_flag("--until", *until);
    if (pattern.since && pattern.until)
      check_time_range(args, *pattern.since, *pattern.until,
                       " (records that held at some time at or after --since and before --until)");
  }
  return pattern;
}

bool pattern_has_triple(const node::Pattern& pattern) {
  return pattern.s || pattern.p || pattern.o;
}

bool matches(const node::Pattern& pattern, const node::Record& record) {
  const node::Triple& t = record.triple;
  if (pattern.s && *pattern.s != t.s) return false;
  if (pattern.p && *pattern.p != t.p) return false;
  if (pattern.o && *pattern.o != t.o) return false;
  if (pattern.context && *pattern.context != record.meta.context) return false;
  if (pattern.source && !uri::is_under(record.meta.source, *pattern.source)) return false;
  if (pattern.under && !(t.s.is_iri() && uri::is_under(t.s.value, *pattern.under))) return false;
  return true;
}

node::Format format_flag(const Args& args, node::Format fallback, bool allow_json) {
  auto name = args.get("--format");
  if (!name) return fallback;
  auto format = node::parse_format(*name);
  if (!format || (!allow_json && *format == node::Format::json)) {
    // CSV is asked of the raw ECG: `tahvel ecg` writes it.
    const bool csv = *name == "csv" || *name == "CSV";
    bad_value("--format", "unknown format '" + *name + "' (use " + (allow_json ? "nt, ttl or json)" : "nt or ttl)") +
                              (csv ? "; for raw ECG as numbers in CSV, 'tahvel ecg DIR --recording IRI'" : ""));
  }
  return *format;
}

std::string read_input(const std::string& path) {
  if (path == "-") {
    std::string text{std::istreambuf_iterator<char>(std::cin), std::istreambuf_iterator<char>()};
    if (std::cin.bad()) fail(std::string("cannot read standard input: ") + std::strerror(errno));
    return text;
  }
  // A directory opens as a stream that reads nothing: `load DIR /tmp` loaded 0 triples, status 0.
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) fail("cannot read '" + path + "': it is a directory");
  std::ifstream in(path, std::ios::binary);
  if (!in) fail("cannot open '" + path + "': " + std::strerror(errno));
  std::ostringstream text;
  // A read that fails part-way sets the failbit of `text` (operator<< of a streambuf), not of `in`.
  if (in.peek() != std::char_traits<char>::eof() && !(text << in.rdbuf())) fail("cannot read '" + path + "': " + std::strerror(errno));
  if (in.bad()) fail("cannot read '" + path + "': " + std::strerror(errno));
  return std::move(text).str();
}

// True when standard output is a pipe whose reader has gone (Linux reports POLLERR).
bool stdout_reader_gone() {
  pollfd p{STDOUT_FILENO, 0, 0};
  return ::poll(&p, 1, 0) == 1 && (p.revents & POLLERR) != 0;
}

bool g_stdout_was_closed = false;

namespace {
// `error` (errno of a failed write to standard output, 0 when not known) as the command's failure.
std::string output_failure(int error) {
  return std::string("cannot write to standard output: ") +
         (g_stdout_was_closed ? "it was closed when tahvel started" : error ? std::strerror(error) : "write failed");
}

[[noreturn]] void fail_output(int error) {
  // A reader that went away (`tahvel tail | head`) is not worth a message; exit 1 quietly.
  if (error == EPIPE || stdout_reader_gone()) throw Failure{kExitFailure, ""};
  fail(output_failure(error));
}
}  // namespace

void refuse_when_output_was_closed() {
  if (g_stdout_was_closed) fail_output(0);
}

void finish_output(std::ostream& out) {
  out.flush();
  if (out) return;
  fail_output(errno);  // may be stale: the stream could have failed on an earlier write
}

void finish_output_after(std::ostream& out, const std::string& done, const std::string& again) {
  out.flush();
  if (out) return;
  const int error = errno;
  // Said even when the reader went away: the status alone (1) would read as "nothing done".
  fail(done + ", but " + (error == EPIPE || stdout_reader_gone() ? std::string("the reader of standard output went away") : output_failure(error)) +
       " (the write stands: " + again + ")");
}

// --- PieceOutput ----------------------------------------------------------------------------

struct PieceOutput::Impl {
  // The stream's text, appended to `text` a put area at a time (a CSV row is many small puts).
  struct Gather : std::streambuf {
    explicit Gather(std::string& to) : text(to) { setp(area, area + sizeof area); }
    int_type overflow(int_type c) override {
      sync();
      if (!traits_type::eq_int_type(c, traits_type::eof())) {
        *pptr() = traits_type::to_char_type(c);
        pbump(1);
      }
      return traits_type::not_eof(c);
    }
    int sync() override {
      text.append(pbase(), pptr());
      setp(area, area + sizeof area);
      return 0;
    }
    std::string& text;
    char area[4096];
  };

  static constexpr std::size_t kGather = 8192;  // written out when this much is gathered

  std::string text;                // gathered, from `sent` on not yet written out
  Gather gather{text};
  std::ostream stream{&gather};
  std::size_t sent = 0;            // bytes of `text` written out
  std::deque<std::pair<std::size_t, bool>> ends;  // the unwritten pieces' ends in `text`, counted
  std::size_t piece_start = 0;     // where the piece being written out begins in `text`
  std::uint64_t written = 0;
  bool at_once = isatty(STDOUT_FILENO) != 0;  // a terminal shows each record as it comes
  bool stopped = false;
  bool cut = false;                // the output ends inside a piece: its reader took nothing for kCutAfter
  bool dropped = false;            // some text made was not written out, and will not be
  // Once stopped, how long the rest of a piece the stop cut may wait for standard output: a
  // reader that is there but not reading (stopped with Ctrl-Z, a stalled connection) must not
  // keep a stopped command from ending.
  static constexpr std::chrono::seconds kCutAfter{2};
  std::chrono::steady_clock::time_point stopped_at{};
  int error = 0;                   // errno of a failed write
  std::optional<std::chrono::steady_clock::time_point> deadline;
  bool timed_out = false;
  // A regular file takes every write at once; a pipe or terminal only as much as it has room for.
  bool to_a_file = [] {
    struct stat st{};
    return ::fstat(STDOUT_FILENO, &st) == 0 && S_ISREG(st.st_mode);
  }();

  // Whether a write of up to PIPE_BUF bytes goes out within `wait_ms` (0: now): a pipe with
  // room for them, a file.
  static bool takes_now(int wait_ms = 0) {
    pollfd p{STDOUT_FILENO, POLLOUT, 0};
    return ::poll(&p, 1, wait_ms) == 1 && (p.revents & POLLOUT) != 0;
  }

  // Writes out `text` up to `to`, the end of a piece. A signal that interrupts a write stops
  // the output, at the end of the piece it cut; once stopped, whole pieces go out only as far as
  // standard output takes them at once, and the rest are dropped.
  void write_out(std::size_t to) {
    while (error == 0 && sent < to) {
      if (!stopped && stop_requested()) {
        stopped = true;
        stopped_at = std::chrono::steady_clock::now();
      }
      std::size_t n = to - sent;
      if (stopped && sent == piece_start) {
        if (!takes_now()) break;
        // Whole pieces that fit in one write a pipe with room takes whole (PIPE_BUF), or the
        // first piece alone when it is longer.
        n = ends.front().first - sent;
        for (const auto& piece : ends)
          if (piece.first <= to && piece.first - sent <= PIPE_BUF) n = piece.first - sent;
      } else if (stopped) {
        // The rest of the piece the signal cut, PIPE_BUF at a time as standard output takes
        // them (a write that fits the room poll saw does not block), for at most kCutAfter.
        const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(stopped_at + kCutAfter - std::chrono::steady_clock::now());
        if (!takes_now(static_cast<int>(std::max<std::int64_t>(0, left.count())))) {
          cut = true;
          break;
        }
        n = std::min<std::size_t>(ends.front().first - sent, PIPE_BUF);
      }
      if (!stopped && deadline && !to_a_file) {
        // Room for PIPE_BUF bytes by the deadline, and no more written at once: the write does
        // not block past it.
        const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(*deadline - std::chrono::steady_clock::now());
        pollfd p{STDOUT_FILENO, POLLOUT, 0};
        const int ready = ::poll(&p, 1, static_cast<int>(std::clamp<std::int64_t>(left.count(), 0, std::numeric_limits<int>::max())));
        if (ready < 0 && errno == EINTR) continue;  // the stop it brought is seen at the loop's top
        if (ready == 0) {
          timed_out = stopped = true;
          stopped_at = std::chrono::steady_clock::now();
          continue;  // as a stop: a piece cut here is finished if the reader takes it within kCutAfter
        }
        n = std::min<std::size_t>(n, PIPE_BUF);  // POLLERR, POLLHUP: the write says what
      }
      const ssize_t put = ::write(STDOUT_FILENO, text.data() + sent, n);
      if (put < 0 && errno == EINTR) continue;  // the stop it brought is seen at the loop's top
      if (put < 0) {
        error = errno;
        break;
      }
      sent += static_cast<std::size_t>(put);
      for (; !ends.empty() && ends.front().first <= sent; ends.pop_front()) {
        piece_start = ends.front().first;
        if (ends.front().second) ++written;
      }
    }
    if (stopped || error != 0) {  // what has not gone out never will
      dropped = dropped || sent < text.size();
      ends.clear();
      text.clear();
      sent = piece_start = 0;
    } else if (sent == piece_start && sent > 0) {  // between pieces: what went out is forgotten
      text.erase(0, sent);
      for (auto& end : ends) end.first -= sent;
      sent = piece_start = 0;
    }
  }
};

PieceOutput::PieceOutput() : impl_(std::make_unique<Impl>()) {}
PieceOutput::~PieceOutput() = default;

std::ostream& PieceOutput::stream() { return impl_->stream; }

void PieceOutput::end_piece(bool counted) {
  Impl& o = *impl_;
  o.gather.pubsync();
  if (o.stopped || o.error != 0) {  // made after the output ended: never written
    o.dropped = o.dropped || !o.text.empty();
    o.text.clear();
    return;
  }
  const std::size_t end = o.text.size();
  if (end == (o.ends.empty() ? o.piece_start : o.ends.back().first)) return;  // nothing made
  o.ends.emplace_back(end, counted);
  if (o.at_once || end - o.sent >= Impl::kGather) o.write_out(end);
}

void PieceOutput::finish() {
  Impl& o = *impl_;
  o.gather.pubsync();
  if (o.error != 0) return;
  // The text after the last piece (what closes a Turtle document) goes out after the pieces,
  // uncounted; once stopped, it is all there is (the pieces were dropped), and closes the last
  // piece that went out, if one did: a few bytes, waited for as the rest of a cut piece is
  // (taken as a piece of its own, it went out only if standard output had room at once, and
  // Turtle cut on a full pipe ended without its " .").
  if (o.stopped && (o.written == 0 || o.cut)) o.text.clear();
  const std::size_t end = o.text.size();
  if (end > (o.ends.empty() ? o.piece_start : o.ends.back().first)) o.ends.emplace_back(end, false);
  if (o.stopped && !o.ends.empty() && o.sent == o.piece_start) o.piece_start = o.sent + 1;  // "inside" it: waited for
  if (!o.ends.empty()) o.write_out(end);
}

std::uint64_t PieceOutput::written() const { return impl_->written; }

bool PieceOutput::good() const { return !impl_->dropped && impl_->error == 0; }

bool PieceOutput::cut() const { return impl_->cut; }

int PieceOutput::error() const { return impl_->error; }

void PieceOutput::set_deadline(std::chrono::steady_clock::time_point deadline) { impl_->deadline = deadline; }

bool PieceOutput::timed_out() const { return impl_->timed_out; }

void PieceOutput::check() const {
  if (impl_->error != 0) fail_output(impl_->error);
}

uri::PrefixMap used_prefixes(const uri::PrefixMap& prefixes,
                             const std::vector<node::Record>& records) {
  auto uses = [](const node::Term& t, const std::string& ns) {
    return (t.is_iri() && t.value.starts_with(ns)) || (t.is_literal() && t.datatype.starts_with(ns));
  };
  uri::PrefixMap used;
  for (const auto& [prefix, ns] : prefixes.entries()) {
    bool any = std::any_of(records.begin(), records.end(), [&](const node::Record& r) {
      return uses(r.triple.s, ns) || uses(r.triple.p, ns) || uses(r.triple.o, ns);
    });
    if (any) (void)used.add(prefix, ns);  // copied from a valid map: cannot fail
  }
  return used;
}

void write_records(std::ostream& out, node::Format format, const uri::PrefixMap& prefixes,
                   const std::vector<node::Record>& records) {
  node::RecordWriter writer(out, format, used_prefixes(prefixes, records));
  for (const node::Record& r : records) writer.write(r);
  writer.finish();
}

std::string base_iri_of(const node::Node& node) {
  const std::string& iri = node.iri();
  return iri.ends_with('/') ? iri : iri + "/";
}

std::string caught_up_text(const spatial::AreaSyncReport& report) {
  if (report.caught_up == 0) return {};
  return ", " + std::to_string(report.caught_up) + (report.caught_up == 1 ? " item" : " items") +
         " stored since a sensor came into an area delivered";
}

// A store's directory holds its own files only: one made inside it would be copied by every
// copy of the outer store, and taken for the outer's leftovers by whoever tidies it.
void refuse_inside_a_store(std::string_view command, const std::string& path, std::string_view instead) {
  std::error_code ec;
  std::filesystem::path dir = std::filesystem::absolute(path, ec).lexically_normal();
  if (!dir.has_filename()) dir = dir.parent_path();  // "state/home1/", as a shell completes it
  for (std::filesystem::path up = dir.parent_path(); !ec && !up.empty(); up = up.parent_path()) {
    if (std::filesystem::is_regular_file(up / "data.mdb", ec) && std::filesystem::file_size(up / "data.mdb", ec) > 0 && !ec)
      fail(std::string(command) + ": " + path + " lies inside the store at " + up.string() + " (it holds a data.mdb); " +
           std::string(instead));
    ec.clear();
    if (up == up.root_path()) break;
  }
}

spatial::AreaSpec area_flag(const Args& args, const uri::PrefixMap& prefixes) {
  std::string text = args.required("--area");
  spatial::AreaSpec spec;
  if (!spatial::looks_like_wkt(text)) {
    if (args.has("--floor")) usage_error("--floor: only with a WKT --area (a room has its own floor)");
    // A plan's relative IRIs ("room/bedroom") resolve against the node's IRI when it is put; on
    // the command line the room's whole IRI is what names it.
    if (!text.starts_with("<") && text.find(':') == std::string::npos)
      bad_value("--area", "'" + text + "' is not an IRI or CURIE: name the room by its whole IRI (a plan's relative '" + text +
                              "' is the node's IRI + \"/" + text + "\"), or give a WKT POLYGON");
    spec.room_iri = parse_iri(text, prefixes, "--area");
    return spec;
  }
  auto shape = spatial::parse_shape(text);
  if (!shape) usage_error("--area: " + shape.error().message);
  // As `put` says of a plan's geometry: degrees of EPSG:4326 would be compared with metres.
  if (const std::string_view crs = spatial::wkt_crs(text); !crs.empty() && crs != spatial::kCrs84)
    std::cerr << warning_prefix() << "--area: its CRS <" << crs
              << "> is not applied: the area's coordinates are read as the floor plan's own, planar (docs/spatial.md S1)\n";
  spec.shape = std::move(*shape);
  if (auto floor = args.get("--floor")) spec.floor = floor_flag(*floor);
  return spec;
}

int floor_flag(const std::string& text) {
  // A floor the area keeper would refuse (1000000001) was taken, and the subscription then got
  // nothing, with a problem only in the keeper's log.
  const std::optional<int> floor = spatial::parse_floor(node::Term::literal(text));
  if (!floor) usage_error("--floor: expected a whole number from -1000000000 to 1000000000, found '" + text + "'");
  return *floor;
}

void check_time_range(const Args& args, std::int64_t since, std::int64_t until, std::string_view meaning) {
  if (until > since) return;
  // Two times written apart that round up to one ns (they differ past the ninth fraction digit)
  // hold no record between them: "is not after" alone read as false.
  const std::string same_ns = until == since && *args.get("--until") != *args.get("--since")
                                  ? " once both are rounded up to whole ns, as records are stamped: no record lies between them"
                                  : "";
  usage_error("--until " + *args.get("--until") + " is not after --since " + *args.get("--since") + same_ns +
              std::string(meaning));
}

std::int64_t time_flag(std::string_view flag, const std::string& text) {
  const std::string what = std::string(flag) + " '" + text + "': ";
  if (!text.empty() && std::all_of(text.begin(), text.end(), [](char c) { return c >= '0' && c <= '9'; })) {
    auto n = parse_u64(text);
    if (!n || *n > static_cast<std::uint64_t>(std::numeric_limits<std::int64_t>::max()))
      usage_error(what + "out of range (ns since the epoch, at most " + std::to_string(std::numeric_limits<std::int64_t>::max()) + ")");
    // Seconds, milliseconds or microseconds since the epoch (a shell's `date +%s`) read as ns are
    // a time in 1970, before every record: the answer is empty with no word why.
    if (*n >= 100'000'000 && *n < 10'000'000'000'000'000) {
      const char* unit = *n < 10'000'000'000 ? "seconds" : *n < 10'000'000'000'000 ? "milliseconds" : "microseconds";
      const std::uint64_t scale = *n < 10'000'000'000 ? 1'000'000'000 : *n < 10'000'000'000'000 ? 1'000'000 : 1'000;
      std::cerr << warning_prefix() << what << "is read as ns since the epoch, a time in 1970; if it is " << unit
                << ", give " << text << std::string(scale == 1'000'000'000 ? 9 : scale == 1'000'000 ? 6 : 3, '0') << "\n";
    }
    return static_cast<std::int64_t>(*n);
  }
  const std::string form = "give ns since the epoch or an RFC 3339 time like 2026-11-21T10:00:00Z";
  // Seconds with a fraction (`date +%s.%N`), or a number with a unit, are neither form: said with
  // the ns they would be, not as a date that lacks its '-' after the year.
  const std::size_t digits_end = text.find_first_not_of("0123456789");
  if (digits_end != 0 && digits_end != std::string::npos) {
    const std::string whole = text.substr(0, digits_end), rest = text.substr(digits_end);
    const bool fraction = rest.size() > 1 && rest[0] == '.' && rest.size() <= 10 &&
                          rest.find_first_not_of("0123456789", 1) == std::string::npos;
    if (fraction)
      usage_error(what + "seconds with a fraction are not read: give ns since the epoch (" + whole + rest.substr(1) +
                  std::string(10 - rest.size(), '0') + " for these seconds) or an RFC 3339 time like 2026-11-21T10:00:00.5Z");
    static const std::pair<const char*, std::size_t> units[] = {{"ns", 0}, {"us", 3}, {"ms", 6}, {"s", 9}};
    for (const auto& [unit, zeros] : units)
      if (rest == unit)
        usage_error(what + "a unit is not read: give ns since the epoch as digits alone (" + whole + std::string(zeros, '0') +
                    ") or an RFC 3339 time like 2026-11-21T10:00:00Z");
  }
  std::size_t at = 0;
  // Where the text leaves the form, and what was wanted there: "+0200" (what `date +%z` prints)
  // or a time without seconds got the form alone, and the operator had to find the fault.
  auto not_the_form = [&](std::string_view wanted) {
    const std::string found = at < text.size() ? "'" + text.substr(at, 1) + "'" : "the end";
    usage_error(what + "at column " + std::to_string(at + 1) + ": expected " + std::string(wanted) + ", found " + found + "; " + form);
  };
  auto digits = [&](std::size_t count, std::string_view name) -> int {
    int value = 0;
    for (std::size_t i = 0; i < count; ++i, ++at) {
      if (at >= text.size() || text[at] < '0' || text[at] > '9')
        not_the_form(std::string(name) + " (" + std::to_string(count) + " digits" + (i ? ", " + std::to_string(i) + " given" : "") + ")");
      value = value * 10 + (text[at] - '0');
    }
    return value;
  };
  auto expect = [&](std::string_view one_of, std::string_view name) {
    if (at >= text.size() || one_of.find(text[at]) == std::string_view::npos) not_the_form(name);
    ++at;
  };
  struct tm tm {};
  tm.tm_year = digits(4, "the year") - 1900;
  expect("-", "'-' after the year");
  tm.tm_mon = digits(2, "the month");
  tm.tm_mon -= 1;
  expect("-", "'-' after the month");
  tm.tm_mday = digits(2, "the day");
  // RFC 3339 (5.6, NOTE) lets a space stand for the 'T', as `date --rfc-3339=s` prints it.
  expect("Tt ", "'T' (or one space) after the date");
  tm.tm_hour = digits(2, "the hour");
  expect(":", "':' after the hour");
  tm.tm_min = digits(2, "the minute");
  expect(":", "':' and the seconds after the minute");
  tm.tm_sec = digits(2, "the second");
  // A leap second (23:59:60Z; RFC 3339 allows second 60) is the second after :59, as POSIX time,
  // which has no leap seconds, counts it.
  const int leap = tm.tm_sec == 60 ? 1 : 0;
  tm.tm_sec -= leap;
  const struct tm asked = tm;
  const time_t seconds = timegm(&tm) + leap;
  if (tm.tm_year != asked.tm_year || tm.tm_mon != asked.tm_mon || tm.tm_mday != asked.tm_mday ||
      tm.tm_hour != asked.tm_hour || tm.tm_min != asked.tm_min || tm.tm_sec != asked.tm_sec)
    usage_error(what + "no such date or time");
  std::int64_t fraction = 0;
  if (at < text.size() && text[at] == '.') {
    ++at;
    std::int64_t scale = 100'000'000;
    const std::size_t first = at;
    bool below_ns = false;  // a digit past the ninth that is not 0
    for (; at < text.size() && text[at] >= '0' && text[at] <= '9'; ++at, scale /= 10) {
      fraction += (text[at] - '0') * scale;
      below_ns = below_ns || (scale == 0 && text[at] != '0');
    }
    if (at == first) usage_error(what + "a '.' needs digits after it");
    // Records are stamped in whole ns: the first at or after T (--since), and the first not
    // before T (--until's bound), is T rounded up; cut off, --since took a record before T.
    if (below_ns) ++fraction;
  } else if (at < text.size() && text[at] == ',') {
    usage_error(what + "write the fraction after a '.', not a ','");
  }
  std::int64_t offset_s = 0;
  if (at < text.size() && (text[at] == 'Z' || text[at] == 'z')) {
    ++at;
  } else if (at < text.size() && (text[at] == '+' || text[at] == '-')) {
    const int sign = text[at++] == '+' ? 1 : -1;
    const int hours = digits(2, "the offset's hours");
    expect(":", "':' between the offset's hours and minutes (±HH:MM)");
    const int minutes = digits(2, "the offset's minutes");
    if (hours > 23 || minutes > 59) usage_error(what + "no such offset");
    offset_s = sign * (hours * 3600 + minutes * 60);
  } else {
    usage_error(what + "give the offset: Z for UTC, or ±HH:MM");
  }
  if (at != text.size()) not_the_form("the end after the offset");
  const std::int64_t utc_s = static_cast<std::int64_t>(seconds) - offset_s;
  constexpr std::int64_t kLast = std::numeric_limits<std::int64_t>::max();  // 2262-04-11T23:47:16.854775807Z
  if (utc_s < 0 || utc_s > kLast / 1'000'000'000 || (utc_s == kLast / 1'000'000'000 && fraction > kLast % 1'000'000'000))
    usage_error(what + "outside the times a record can have (1970 to 2262-04-11T23:47:16.854775807Z)");
  // Second 60 exists only as a leap second: one of the 27 inserted until this was written (IERS
  // Bulletin C; none since 2016), or one yet to be announced at the end of a June or December.
  if (leap) {
    // The midnights (UTC) that followed each leap second, in POSIX seconds.
    static constexpr std::int64_t kAfterLeapSeconds[] = {78796800, 94694400, 126230400, 157766400, 189302400, 220924800, 252460800, 283996800, 315532800, 362793600, 394329600, 425865600, 489024000, 567993600, 631152000, 662688000, 709948800, 741484800, 773020800, 820454400, 867715200, 915148800, 1136073600, 1230768000, 1341100800, 1435708800, 1483228800};
    constexpr std::int64_t kAnnouncedUntil = 1798761600;  // 2027-01-01T00:00:00Z
    const bool known = std::find(std::begin(kAfterLeapSeconds), std::end(kAfterLeapSeconds), utc_s) != std::end(kAfterLeapSeconds);
    bool possible = false;
    if (utc_s > kAnnouncedUntil && utc_s % 86400 == 0) {
      const time_t midnight = static_cast<time_t>(utc_s);
      std::tm next{};
      gmtime_r(&midnight, &next);
      possible = next.tm_mday == 1 && (next.tm_mon == 0 || next.tm_mon == 6);
    }
    if (!known && !possible)
      usage_error(what + "second 60 exists only as a leap second (23:59:60 UTC on a day one was inserted, such as 2016-12-31)");
  }
  return utc_s * 1'000'000'000 + fraction;  // a fraction rounded up to 1 s carries into the seconds
}

namespace {
std::string g_running_command;  // set once, before the command runs
}  // namespace

void set_running_command(std::string_view name) { g_running_command = name; }

std::string warning_prefix() { return g_running_command.empty() ? "tahvel: warning: " : "tahvel: " + g_running_command + ": warning: "; }

std::string seconds_text(double seconds) {
  std::ostringstream out;
  if (!(seconds < 60)) {  // a home silent since yesterday reads as such, not as "93784.2 s"
    const auto whole = seconds < 1e15 ? static_cast<std::int64_t>(seconds) : std::int64_t{1'000'000'000'000'000};
    const std::int64_t days = whole / 86400, hours = whole % 86400 / 3600, minutes = whole % 3600 / 60;
    if (days > 0) out << days << " d " << hours << " h";
    else if (hours > 0) out << hours << " h " << minutes << " min";
    else out << minutes << " min " << whole % 60 << " s";
    return out.str();
  }
  out.precision(1);
  out << std::fixed << seconds << " s";
  return out.str();
}

std::int64_t unix_now_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch()).count();
}

double seconds_since(std::int64_t unix_ns, std::int64_t at_ns) {
  return static_cast<double>((at_ns > 0 ? at_ns : unix_now_ns()) - unix_ns) / 1e9;
}

std::string age_of(std::int64_t unix_ns, std::int64_t at_ns) {
  if (unix_ns <= 0) return "never";
  const double age = seconds_since(unix_ns, at_ns);
  // A time written on another machine may be ahead of this one's clock: said so, not as "-0.4 s ago".
  return age < -0.05 ? seconds_text(-age) + " ahead of this machine's clock" : seconds_text(std::max(age, 0.0)) + " ago";
}

std::string store_room_warning(std::uint64_t used, std::uint64_t data, std::uint64_t max, std::optional<std::uint64_t> disk_free) {
  constexpr double kMB = 1 << 20;
  std::ostringstream said;
  said.precision(1);
  said << std::fixed;
  // By the file's high-water mark, not the pages holding data: copy on write needs fresh pages
  // beyond what the last write freed, so a store refuses writes with a third of its pages free.
  // But pages freed below the mark are used again: a store emptied with `tahvel remove` takes
  // writes, its file as large as before (it was called full with 0.1 MB of 2 holding data). A
  // removal may take the mark past the maximum, into the reserve kept for removals.
  // In 128 bits: figures a child sends may be anything, and `used * 10` wrapped near 2^64.
  using Wide = unsigned __int128;
  if (max > 0 && Wide{used} * 10 >= Wide{max} * 9 && Wide{data} * 2 >= Wide{max}) {
    // MiB, as said: the errors give bytes, and "MB" beside them read as another figure.
    if (used > max)
      said << used / kMB << " MiB used, " << (used - max) / 1024 << " KiB past its maximum of " << max / kMB
           << " MiB, into the reserve kept for removals (";
    else
      said << used / kMB << " MiB of its maximum " << max / kMB << " MiB used (";
    said << data / kMB << " MiB holding data): writes that do not fit are refused; remove records, the oldest "
         << "first (tahvel remove --until T)";
  }
  if (disk_free && *disk_free / kMB < 64)
    said << (said.tellp() > 0 ? "; " : "") << "the disk holding it has " << *disk_free / kMB << " MB free";
  return said.str();
}

std::string store_warning_from_state(const std::map<std::string, std::string>& state, std::int64_t read_ns) {
  const auto field = [&](const char* name) -> std::optional<std::uint64_t> {
    auto it = state.find(name);
    return it == state.end() ? std::nullopt : parse_u64(it->second);
  };
  const auto used = field("storeUsedBytes"), data = field("storeDataBytes"), max = field("storeMaxBytes");
  if (!used || !data || !max) return {};
  std::string said = store_room_warning(*used, *data, *max, field("diskFreeBytes"));
  if (said.empty()) return said;
  const auto seen = field("lastSeen");
  return said + (seen ? " (as its link said " + age_of(static_cast<std::int64_t>(*seen), read_ns) + ")" : std::string());
}

}  // namespace tahvel::cli

namespace tahvel::cli {

struct SaidIfSlow::State {
  std::mutex mu;
  std::condition_variable done_cv;
  bool done = false;
  std::thread watcher;
};

SaidIfSlow::SaidIfSlow(std::string command, std::string dir, std::chrono::milliseconds after)
    : state_(std::make_shared<State>()) {
  try {
    state_->watcher = std::thread([state = state_, command = std::move(command), dir = std::move(dir), after] {
    std::unique_lock lock(state->mu);
    if (state->done_cv.wait_for(lock, after, [&] { return state->done; })) return;
    std::cerr << "tahvel: " << command << ": not written after " << seconds_text(std::chrono::duration<double>(after).count())
              << ", most likely waiting for the writer lock of " << dir
              << ", which another process holds (one stopped inside a write holds it until it goes on or ends); "
                 "still waiting\n";
    });
  } catch (const std::system_error&) {
    // No thread to be had (the process's limit): the write goes on without the word.
  }
}

SaidIfSlow::~SaidIfSlow() {
  {
    std::lock_guard lock(state_->mu);
    state_->done = true;
  }
  state_->done_cv.notify_all();
  if (state_->watcher.joinable()) state_->watcher.join();
}

}  // namespace tahvel::cli
