// RDF syntax in and out, through serd: N-Triples and Turtle in; N-Triples, Turtle and JSON out.
// Parsing never stores anything: it yields triples that the caller stores as an item, so a
// syntax error anywhere leaves the store untouched.
#pragma once

#include <ostream>
#include <string>
#include <string_view>
#include <vector>

#include "tahvel/node/error.h"
#include "tahvel/node/node.h"
#include "tahvel/node/term.h"
#include "tahvel/uri/iri.h"

namespace tahvel::node {

enum class Format { ntriples, turtle, json };

// "nt"/"ntriples", "ttl"/"turtle", "json". Error invalid_argument naming the value.
Result<Format> parse_format(std::string_view name);

struct ParseOptions {
  Format format = Format::turtle;  // ntriples or turtle
  std::string base_iri;            // for relative IRIs in Turtle; empty: relative IRIs are errors
  std::string source_name = "<input>";  // used in error messages: "<source>:3:14: ..."
  uri::PrefixMap prefixes;         // prefixes known before the document's own @prefix lines
};

// Parses a whole document. Errors: syntax, with message "<source>:LINE:COL: <serd's reason>".
// Blank-node labels are kept as written (the store renames them on write).
Result<std::vector<Triple>> parse_rdf(std::string_view text, const ParseOptions& options);

// Where triple `index` (0-based, in the order parse_rdf gives them) of `text` is written,
// "<source>:LINE:COL" just past its object, to name an error found in it after parsing (the
// store's checks say "triple N, object: ..."). Reads the text again, byte by byte. Empty when
// the text does not parse or has fewer triples.
std::string locate_triple(std::string_view text, const ParseOptions& options, std::size_t index);

// Writes records one at a time.
//   ntriples: one line per triple.
//   turtle:   @prefix lines for `prefixes`, then triples abbreviated by serd.
//   json:     one JSON object per line per record, with its metadata:
//     {"id":7,"item":7,"s":{"type":"uri","value":"http://x/a"},
//      "p":{"type":"uri","value":"..."},
//      "o":{"type":"literal","value":"72","datatype":"http://www.w3.org/2001/XMLSchema#integer"},
//      "stored_at":1763719200000000000,"asserted_at":...,"source":"http://x/node/cli",
//      "context":"","persistent":false}
//     and "span" (ns, after asserted_at) on a record that holds for a time (RecordMeta::span).
//     Term objects follow SPARQL 1.1 JSON results: type uri|bnode|literal, "xml:lang" for tags.
class RecordWriter {
 public:
  RecordWriter(std::ostream& out, Format format, const uri::PrefixMap& prefixes = {});
  ~RecordWriter();  // calls finish()
  RecordWriter(const RecordWriter&) = delete;
  RecordWriter& operator=(const RecordWriter&) = delete;

  void write(const Record& record);
  void write(const Triple& triple);  // json: metadata keys omitted
  // A change of Node::watch: an insertion as its record; a removal as "# removed ID" in
  // N-Triples and Turtle, and in JSON as the record's object led by "removed":true,"seq":N; one
  // that cannot be read (Change::unreadable) as "# unreadable record|removal SEQ: why", and in
  // JSON as {"seq":N,"removed":…,"unreadable":"why"}.
  void write(const Change& change);
  void finish();                     // flushes serd's pending abbreviations (Turtle)

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// Escapes `text` as the body of a JSON string (no quotes added).
std::string json_escape(std::string_view text);

// Now in UTC to the millisecond, "2026-11-22T10:53:01.123Z": the start of a log line of a
// long-running process (agents, links, the supervisor), so that the logs of several processes
// and machines can be read side by side.
std::string log_stamp();
// Writes "<log_stamp()> <line>\n" to standard error with one write(2), the way the long-running
// processes log. Not through std::cerr: a stream whose write failed once (a full disk under the
// log) drops every later line until it is cleared, and such a process logged nothing more for
// the rest of its life. A line after one that could not be written whole starts on a line of its
// own. std::cerr is cleared too, for the messages written through it.
void write_log_line(std::string_view line) noexcept;
// `ns` since the Unix epoch as an RFC 3339 UTC time with milliseconds ("2026-11-27T20:40:00.123Z"),
// the form `--since` and `--until` take.
std::string utc_text(std::int64_t ns);

}  // namespace tahvel::node
