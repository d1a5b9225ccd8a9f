// The reasoner agent: rules (rules.h) applied to a node's whiteboard in incremental sessions
// (docs/reasoner.md). Each session reads one snapshot; takes the records newer than the
// previous session's snapshot and the removals logged since; derives; writes the new
// conclusions as one item (source = the reasoner's agent IRI, asserted_at = the session time)
// and removes those that lost all support. A conclusion is written once while it holds, across
// sessions and restarts (on start the reasoner compares its records with what the rules give).
//
//   auto r = tahvel::reasoner::Reasoner::open("state/home1", {.rules = "spo2.rules"});
//   auto report = r->session();                       // one session now
//   r->run(on_session, stop);                         // sessions on relevant changes
//
// Blank nodes of other items cannot be named in a new item (the store renames them, R5), so a
// conclusion about a blank node _:bN is written about its skolem IRI
// <node IRI>/.well-known/genid/bN (RDF 1.1 §3.5).
#pragma once

#include <chrono>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "tahvel/agents/rules.h"
#include "tahvel/uri/iri.h"

namespace tahvel::reasoner {

// A running reasoner reports a changed rule file that does not parse (the previous rules run
// on) as its problem on its board (node::Agent::report_problem, for `tahvel status`), and
// removes it once a rule file parses and when it starts (it starts only with rules that parse).

// The longest interval between sessions that Reasoner::open accepts: one day.
inline constexpr std::chrono::milliseconds kMaxInterval{86'400'000};

inline constexpr std::size_t kDefaultMaxConclusions = 2'000'000;

struct ReasonerOptions {
  std::filesystem::path rules;        // the rule file (required); reloaded when it changes
  std::string agent_id = "reasoner";  // IRI = node IRI + "/" + agent_id: the conclusions' source
  std::string default_ns;             // #name and bare atoms; empty: node IRI + "#"
  std::chrono::milliseconds interval{100};  // run(): at most one session per interval;
                                            // 0 to kMaxInterval
  bool persistent = false;            // write conclusions as persistent items (ring/TTL-proof)
  // Conclusions one session may derive before the rules are taken to derive without end (the
  // session is written off and the reasoner ends, RS10). A finite closure may need more, and a
  // restart derives everything in its first session.
  std::size_t max_conclusions = kDefaultMaxConclusions;
};

struct SessionReport {
  std::uint64_t seq = 0;         // last sequence number of the session's snapshot
  std::int64_t time_ns = 0;      // the session time (asserted_at of what it wrote)
  std::size_t facts_in = 0;      // base records read as new (resynced: every one read again)
  std::size_t facts_out = 0;     // base records read as removed (resynced: 0)
  bool resynced = false;         // the change stream had a gap (retention, trimmed log): the
                                 // rules ran from scratch on the snapshot, the difference applied
  std::vector<Atom> added;       // conclusions written
  std::vector<Atom> removed;     // conclusions retracted
  std::size_t stale_records_removed = 0;  // at the first session: records of conclusions an
                                          // earlier run wrote that no longer hold
  std::optional<std::string> rules_error;  // the rule file changed but does not parse: the
                                           // message (file:line:col); the previous rules ran
  bool rules_reloaded = false;
  // Started by the clock alone (rules that use `now`, on a quiet board): a session that then
  // changes nothing is not worth a line of the log.
  bool clocked = false;
  std::optional<std::string> problem_not_written;  // why the rules' problem could not be put on
                                                   // the board (or taken off it)
  // Conclusions this node cannot hold (a literal over its `init --max-literal`), each said once:
  // left out, and the rest of the session written. One such conclusion failed the whole
  // session's write, and the reasoner ended, its other conclusions with it.
  std::vector<std::string> not_written;
  // At the first session and after the rules are reloaded: each predicate the rules read as
  // triples that no fact on the board has, while one a slip away does ("file:line:col: ex:rmsd:
  // no fact on the board has this predicate; did you mean ex:rmssd (12 records)? ..."). A rule
  // on a misspelt predicate holds for nothing, and an alert of it never fires, without a word.
  std::vector<std::string> warnings;
  double read_ms = 0, derive_ms = 0, write_ms = 0, total_ms = 0;
  EngineStats engine;
};

class Reasoner {
 public:
  // Opens the node in `dir` and loads the rules. Errors: the node cannot be opened, the rule
  // file cannot be read or does not parse (message file:line:col), a bad agent id, an
  // interval below 0 or above kMaxInterval.
  static Result<Reasoner> open(const std::filesystem::path& dir, ReasonerOptions options);

  Reasoner(Reasoner&&) noexcept;
  Reasoner& operator=(Reasoner&&) noexcept;
  ~Reasoner();

  const std::string& iri() const;  // the agent IRI, source of the conclusions

  // One session now (reloading the rule file first when it changed: new rules are evaluated
  // on the whole board, as at start, and the difference written). Errors: the store's
  // (reading the snapshot, writing or removing conclusions); a failed write leaves the
  // reasoner's state as before the session, so the next session retries it.
  Result<SessionReport> session();

  // Runs a session now, then one whenever records that some rule reads change (or the rule
  // file does), at most one per options.interval, until `stop()` returns true (checked at
  // least every 100 ms). `on_session` gets each report; returning false also stops.
  Result<void> run(const std::function<bool(const SessionReport&)>& on_session,
                   const std::function<bool()>& stop);

 private:
  struct Impl;
  explicit Reasoner(std::unique_ptr<Impl>);
  std::unique_ptr<Impl> impl_;
};

}  // namespace tahvel::reasoner
