// The `tahvel` subcommands and the helpers they share: opening a node, the prefix table, terms
// and patterns from the command line, reading input and writing records.
//
// Each subcommand is a Command (its flags and help, see args.h) and a function from the parsed
// Args to an exit status. Helpers report errors by throwing Failure (caught in main()).
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <iosfwd>
#include <map>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "args.h"
#include "tahvel/federation/link.h"
#include "tahvel/node/format.h"
#include "tahvel/node/node.h"
#include "tahvel/spatial/area_subscriptions.h"
#include "tahvel/spatial/board.h"
#include "tahvel/uri/iri.h"

namespace tahvel::cli {

struct Subcommand {
  const Command* spec;
  int (*run)(const Args&);
};

// Every subcommand in the order `tahvel --help` lists them (bench is handled in main.cpp).
std::span<const Subcommand> subcommands();

// Flags shared by several subcommands.
inline const Flag kFlagS{"-s", "--subject", "TERM", "match this subject: <iri>, IRI, CURIE or _:label"};
inline const Flag kFlagP{"-p", "--predicate", "TERM", "match this predicate: <iri>, IRI, CURIE or 'a'"};
inline const Flag kFlagO{"-o", "--object", "TERM",
                         "match this object: IRI, CURIE, _:b, \"x\", \"x\"@en, \"x\"^^type, 72"};
inline const Flag kFlagSource{"--source", "", "IRI", "only records written by this agent or node (or below it)"};
inline const Flag kFlagUnder{"--under", "", "IRI",
                             "only records whose subject is this IRI or below it (a recording's chunks: <rec>/chunk/N)"};
// A time range by asserted-at (Pattern::since, until): ns since the epoch or RFC 3339 times.
inline const Flag kFlagSince{"--since", "", "T", "records asserted at or after T (or whose span reaches past T)"};
inline const Flag kFlagUntil{"--until", "", "T", "records asserted before T"};
inline const Flag kFlagArea{"--area", "", "IRI|WKT",
                            "only records of features located in a room (IRI) or (MULTI)POLYGON, or from its sensors"};
inline const Flag kFlagFloor{"--floor", "", "N", "with a WKT --area: only that floor (default: every floor)"};
inline const Flag kFlagCascade{"--cascade", "", "N",
                               "follow each match's object to its triples, N levels deep"};
inline const Flag kFlagFormat{"--format", "", "nt|ttl|json",
                              "output: N-Triples (default), Turtle, JSON lines + metadata"};
inline const Flag kFlagAgentWriter{"--agent", "", "ID",
                                   "write as agent ID (IRI: node IRI/ID); default \"cli\""};

// --- errors ---------------------------------------------------------------------------------

// The value of `result`, or Failure(kExitFailure) with the library's message.
template <class T>
T check(node::Result<T>&& result) {
  if (!result) fail(std::move(result).error().message);
  return std::move(result).value();
}
void check(node::Result<void>&& result);

// --- node and prefixes ----------------------------------------------------------------------

node::Node open_node(const std::string& dir);
// `base` plus every --prefix P=IRI of `args` (usage error naming --prefix when malformed).
uri::PrefixMap prefixes_with_flags(uri::PrefixMap base, const Args& args);
// The agent id of --agent (default `fallback`), checked (usage error naming --agent).
std::string agent_id(const Args& args, std::string_view fallback);

// Whether anything on `node`'s board (read in `snapshot`) knows its agent `agent` (an IRI): it
// subscribes (itself: a subscription another wrote for it does not count), anything is said of
// it (a child node's state, a problem), or it or an agent under it has written. An item addressed (R18) to an agent nothing knows waits in its input buffer
// until one comes: a home not yet deployed, or a typo, waits for ever. True when the board
// cannot be read (the store itself says what is wrong).
bool board_knows_agent(const node::Snapshot& snapshot, const std::string& agent);
// The ids of the child nodes whose states `node`'s board keeps (docs/protocol.md P12).
std::vector<std::string> child_nodes_known(const node::Node& node, const node::Snapshot& snapshot);

// --- terms and patterns ---------------------------------------------------------------------

enum class Position { subject, predicate, object, any };

// A term written on the command line: <iri>, absolute IRI with "//" (or urn:, mailto:, ...),
// CURIE, _:label, "lexical", "lexical"@lang, "lexical"^^dt, a bare number or true/false, and
// "a" for rdf:type. Usage error naming `flag` when malformed or not allowed at `position`.
node::Term parse_term(std::string_view text, const uri::PrefixMap& prefixes,
                      std::string_view flag, Position position = Position::any);
// An IRI (absolute, <iri> or CURIE) given to `flag`.
std::string parse_iri(std::string_view text, const uri::PrefixMap& prefixes,
                      std::string_view flag);
// As parse_iri, for a node's IRI (--at): one with a query, a fragment or a trailing '/' is a
// usage error naming `flag`. `here`: the node asked (DIR's), whose IRI + "/" + `text` the error
// for an id alone suggests.
std::string parse_node_iri(std::string_view text, const uri::PrefixMap& prefixes, std::string_view flag,
                           std::string_view here = {});
// The pattern of -s, -p, -o (and --context, --source, --under when the command has them).
node::Pattern pattern_from_args(const Args& args, const uri::PrefixMap& prefixes);
// After an empty answer to a pattern with -p: a warning on standard error when no record of
// `held` (what the store that answered holds per predicate) has that predicate, naming the
// nearest it holds (a misspelt `-p sosa:hasSimpleReslt` answered nothing, with exit 0 and no word).
// `where` names the store ("this store", "<iri> (as its supervisor wrote it 3 s ago)").
void warn_of_a_predicate_held_by_none(std::string_view command, const node::Pattern& pattern,
                                      const std::vector<node::PredicateSummary>& held, const uri::PrefixMap& prefixes,
                                      const std::string& where);
// --cascade N; depths beyond 2^20 (deeper than any store's sub-trees) are taken as 2^20.
unsigned cascade_flag(const Args& args);
// The time `text` given to `flag` (--since, --until), ns since the epoch: an integer (ns) or an
// RFC 3339 time "2026-11-21T10:00:00Z" (optional fractional seconds; Z or an offset ±HH:MM; 't'
// and 'z' in either case, or a space for the 't'). Out-of-range numbers and dates that do not exist (February 30) are
// usage errors naming the flag, not times moved elsewhere.
std::int64_t time_flag(std::string_view flag, const std::string& text);
// "a", "a or b", "a, b or c"; with `of` more than named, "a, b, c or 2 more as near".
std::string one_of(const std::vector<std::string>& named, std::size_t of);
// A usage error unless `until` (of --until) is after `since` (of --since), both as time_flag read
// them from `args`; `meaning` is added to the message (what the range selects).
void check_time_range(const Args& args, std::int64_t since, std::int64_t until, std::string_view meaning = "");
// "tahvel: COMMAND: warning: ", COMMAND the subcommand that runs (main sets it): a warning names
// its command, as an error does, for a script's log that holds the output of several.
std::string warning_prefix();
void set_running_command(std::string_view name);
// "4.2 s" below a minute, then "12 min 5 s", "3 h 12 min", "2 d 3 h" (a NaN as a long time).
std::string seconds_text(double seconds);
// Now, ns since the epoch (the clock records are stamped with).
std::int64_t unix_now_ns();
// Seconds from `unix_ns` to `at_ns` (0: now).
double seconds_since(std::int64_t unix_ns, std::int64_t at_ns = 0);
// "4.2 s ago", "0.3 s ahead of this machine's clock" (a time written on another machine), or
// "never" for 0; as of `at_ns` (0: now), the moment it was read.
std::string age_of(std::int64_t unix_ns, std::int64_t at_ns = 0);
// What an operator must know of a store before anything else: writes to it are refused or soon
// will be (at 90% of its maximum, or under 64 MB free on its disk; its programs then fail, and
// its link cannot even write its children's state). Empty when there is room. `used`: bytes up
// to its last page in use; `data`: the pages holding data; `disk_free`: nullopt when not known.
std::string store_room_warning(std::uint64_t used, std::uint64_t data, std::uint64_t max, std::optional<std::uint64_t> disk_free);
// store_room_warning of a store on another machine, as its parent's state of it says (fields by
// the predicates' local names: storeUsedBytes, storeDataBytes, storeMaxBytes, diskFreeBytes, from
// its last hello or heartbeat, docs/protocol.md P12), with how old that is (lastSeen, as of
// `read_ns`); empty when it says no such figures, or there is room.
std::string store_warning_from_state(const std::map<std::string, std::string>& state, std::int64_t read_ns = 0);

// Fails (`command: PATH lies inside the store at …; instead`) when a directory above `path`
// holds a store: a store's directory holds its own files only.
void refuse_inside_a_store(std::string_view command, const std::string& path, std::string_view instead);

// The area of --area (and --floor): WKT when it reads as WKT, else a room's IRI or CURIE.
spatial::AreaSpec area_flag(const Args& args, const uri::PrefixMap& prefixes);
// --floor N: a floor as the board reads one (spatial::parse_floor: a whole number within ±1e9);
// a usage error naming the flag otherwise.
int floor_flag(const std::string& text);
// ", N items caught up" for a sync that delivered readings stored before it (S9), else "".
std::string caught_up_text(const spatial::AreaSyncReport& report);
bool pattern_has_triple(const node::Pattern& pattern);
// True when `record` matches every bound field of `pattern` (s, p, o, context, source, under).
bool matches(const node::Pattern& pattern, const node::Record& record);

// --- input and output -----------------------------------------------------------------------

// The format of --format (or `fallback`); usage error when the value is unknown or json is not
// allowed (input).
node::Format format_flag(const Args& args, node::Format fallback, bool allow_json = true);
// The whole of FILE, or of standard input for "-". Failure naming the file.
std::string read_input(const std::string& path);
// Flushes `out` and fails (naming standard output) when anything could not be written; quietly
// (status 1, no message) when standard output is a pipe whose reader has gone.
void finish_output(std::ostream& out);
// finish_output for what a command prints after its write committed: a failure names what was
// done (`done`, "item 42 is stored"), so that status 1 is not read as "nothing was written".
void finish_output_after(std::ostream& out, const std::string& done,
                         const std::string& again = "running the command again would repeat it");
// Set by main when standard output was closed at start (it is /dev/full then: output fails).
extern bool g_stdout_was_closed;
// For a command that writes to the store and then prints: fails (as finish_output would) before
// anything is written when standard output was closed at start, so that status 1 never follows a
// write that was done (a caller trusting the status would write again).
void refuse_when_output_was_closed();
// True when standard output is a pipe whose reader has gone (`tahvel … | head`).
bool stdout_reader_gone();
// True once SIGINT or SIGTERM came to a command that cancels on them (install_stop_handlers in
// commands_federation.cpp: `query`, `ecg`, `up --foreground`, `link`).
bool stop_requested();

// Says on standard error, once, that a small write not done after `after` most likely waits
// for the store's writer lock: LMDB has one writer at a time, and a writer stopped inside its
// transaction (Ctrl-Z, SIGSTOP, a debugger) holds it until it goes on or ends. A `put` that hung
// there said nothing. For writes that are quick once they begin (an item, a subscription).
class SaidIfSlow {
 public:
  SaidIfSlow(std::string command, std::string dir, std::chrono::milliseconds after = std::chrono::seconds(5));
  ~SaidIfSlow();
  SaidIfSlow(const SaidIfSlow&) = delete;
  SaidIfSlow& operator=(const SaidIfSlow&) = delete;

 private:
  struct State;
  std::shared_ptr<State> state_;
};

// Standard output in whole pieces (a record, a CSV row), for the commands that print an answer
// as it comes (`query`, `ecg`). A stop (SIGINT, SIGTERM) ends the output at the end of a piece,
// never inside one, and written() counts the pieces that went out: what the command says it
// printed. Through std::cout, a signal that interrupted a write to a full pipe left the last
// line cut at the edge of stdio's buffer, and the count took in what was still in the buffer.
//
// Pieces are gathered and written out 8 KiB at a time (each one at once on a terminal). Once
// stopped, a piece cut by the interrupted write is finished (the reader must take those few
// bytes), and the pieces not yet written go out only as far as standard output takes them
// without waiting; the rest are dropped. A write that fails (EPIPE: the reader went away) ends
// the output too; check() then says so.
class PieceOutput {
 public:
  PieceOutput();
  ~PieceOutput();
  PieceOutput(const PieceOutput&) = delete;
  PieceOutput& operator=(const PieceOutput&) = delete;

  // Where the text of the piece being made goes.
  std::ostream& stream();
  // The text made since the last end_piece() is one piece; `counted`: one that written()
  // counts (not a CSV header). May write out what was gathered.
  void end_piece(bool counted = true);
  // Writes out every piece, and then any text after the last one (what RecordWriter::finish
  // closes a Turtle document with); once stopped, only what goes out without waiting.
  void finish();
  // The counted pieces written out whole.
  std::uint64_t written() const;
  // True while everything made so far has been written out or may still be.
  bool good() const;
  // True when, after a stop, standard output took nothing for 2 s while a piece was half
  // written: the output ends inside it (a reader stopped or stalled; a stopped command ends).
  bool cut() const;
  // errno of the write that failed (EPIPE: the reader went away), 0 when none did.
  int error() const;
  // From now on a write waits for standard output no later than `deadline` (a `--timeout` that
  // bounds the whole answer): past it the output ends as at a stop, and timed_out() says so. A
  // reader that stops reading (a pager left open) held the command in write() for as long.
  void set_deadline(std::chrono::steady_clock::time_point deadline);
  bool timed_out() const;
  // Fails, as finish_output does, when a write failed (quietly when the reader went away).
  void check() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};
// `stats DIR --predicates [--at IRI] [--timeout S] [--json]` (the stats command is in
// commands_read.cpp; this, in commands_federation.cpp): what the store, or the node at IRI below
// it (from its board, through the link), holds per predicate.
int print_predicates(node::Node& node, const Args& args);
// The entries of `prefixes` that some IRI or datatype of `records` uses (for Turtle output).
uri::PrefixMap used_prefixes(const uri::PrefixMap& prefixes,
                             const std::vector<node::Record>& records);
// Writes `records` as one document (Turtle: with the @prefix lines it uses).
void write_records(std::ostream& out, node::Format format, const uri::PrefixMap& prefixes,
                   const std::vector<node::Record>& records);
// The base IRI for relative references in input: the node IRI followed by "/".
std::string base_iri_of(const node::Node& node);

// --- subcommands ----------------------------------------------------------------------------

extern const Command kInitCommand;
extern const Command kPutCommand;
extern const Command kLoadCommand;
extern const Command kRemoveCommand;
extern const Command kSubscribeCommand;
extern const Command kAreasCommand;
extern const Command kListCommand;
extern const Command kDumpCommand;
extern const Command kBackupCommand;
extern const Command kTakeCommand;
extern const Command kTailCommand;
extern const Command kStatsCommand;
extern const Command kCheckCommand;  // commands_check.cpp
extern const Command kHrvCommand;
extern const Command kPatientsCommand;
extern const Command kEcgCommand;  // commands_ecg.cpp

int run_init(const Args& args);
int run_put(const Args& args);
int run_load(const Args& args);
int run_remove(const Args& args);
int run_subscribe(const Args& args);
int run_areas(const Args& args);
int run_list(const Args& args);
int run_dump(const Args& args);
int run_backup(const Args& args);
int run_take(const Args& args);
int run_tail(const Args& args);
int run_stats(const Args& args);
int run_check(const Args& args);
int run_hrv(const Args& args);
int run_patients(const Args& args);
int run_ecg(const Args& args);

// The reasoner (commands_reason.cpp).
extern const Command kReasonCommand;
int run_reason(const Args& args);

// Federation (commands_federation.cpp).
extern const Command kLinkCommand;
extern const Command kQueryCommand;
extern const Command kUpCommand;
extern const Command kDownCommand;
extern const Command kStatusCommand;
int run_link(const Args& args);
int run_query(const Args& args);
int run_up(const Args& args);
int run_down(const Args& args);
int run_status(const Args& args);

// `query` of the node at --at below `node` (or `node` itself) as `tahvel query` asks it: Ctrl-C,
// SIGTERM and a closed standard output cancel it (P18). Calls `each` per record, which writes
// to `out` (or keeps the record), and `answered` once the answer has ended, whichever way (it
// writes out the rest: PieceOutput::finish); returns the number of records. On failure exits,
// the message prefixed with `command`: 3 timeout, 4 unknown node, 5 unreachable, 1 anything
// else, 130 when interrupted, with the number of `piece`s ("record", "frame") written out.
std::uint64_t ask_below(std::string_view command, node::Node& node, const federation::RemoteQuery& query,
                        std::chrono::milliseconds timeout, PieceOutput& out, const std::function<void(const node::Record&)>& each,
                        const std::function<void()>& answered, std::string_view piece);
// --timeout S of `command`: seconds, a fraction allowed ("2.5"), at least 1 ms and at most
// `at_most`; `fallback` when the flag is not given.
std::chrono::milliseconds seconds_flag(const Args& args, std::string_view command, std::chrono::milliseconds fallback,
                                       std::chrono::seconds at_most);

// Groups triples into items for `load`: one item per subject group (see docs/cli.md).
// `*places` gets, for each group, the place in `triples` of each of its triples.
std::vector<std::vector<node::Triple>> group_by_subject(std::vector<node::Triple> triples,
                                                        std::vector<std::vector<std::size_t>>* places);

}  // namespace tahvel::cli
