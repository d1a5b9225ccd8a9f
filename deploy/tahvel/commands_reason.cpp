// `tahvel reason DIR RULES`: the reasoner agent (agents/reasoner, docs/reasoner.md) from the
// command line. One session with --once; otherwise a session whenever relevant records change,
// until SIGINT or SIGTERM. Prints, per session, what was derived and retracted and how long it
// took: a text block, or one JSON object per line with --json.
#include <algorithm>
#include <cstdio>
#include <iostream>
#include <sstream>

#include "commands.h"
#include "tahvel/agents/reasoner.h"
#include "tahvel/node/stop_signal.h"

namespace tahvel::cli {

namespace {


std::string fixed(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.3f", v);
  return buf;
}

std::string short_term(const node::Term& t, const uri::PrefixMap& prefixes) {
  if (t.is_iri()) {
    std::string c = prefixes.compact(t.value);
    return c == t.value ? "<" + t.value + ">" : c;
  }
  return t.to_ntriples();
}

std::string short_atom(const reasoner::Atom& a, const uri::PrefixMap& prefixes) {
  std::string out = short_term(node::Term::iri(a.predicate), prefixes) + "(";
  for (std::size_t i = 0; i < a.args.size(); ++i) out += (i ? ", " : "") + short_term(a.args[i], prefixes);
  return out + ")";
}

std::string json_atoms(const std::vector<reasoner::Atom>& atoms) {
  std::string out = "[";
  for (std::size_t i = 0; i < atoms.size(); ++i) {
    out += i ? ",{" : "{";
    out += "\"predicate\":\"" + node::json_escape(atoms[i].predicate) + "\",\"args\":[";
    for (std::size_t k = 0; k < atoms[i].args.size(); ++k)
      out += (k ? ",\"" : "\"") + node::json_escape(atoms[i].args[k].to_ntriples()) + "\"";
    out += "]}";
  }
  return out + "]";
}

// Rules on `now` are evaluated every second on a quiet board: only what changed is told, and a
// session that read the whole board again (its cost is what an operator looks for in the log).
bool quiet_clock_tick(const reasoner::SessionReport& r) {
  return r.clocked && r.added.empty() && r.removed.empty() && !r.rules_error && !r.problem_not_written && !r.resynced;
}

void print_json(const reasoner::SessionReport& r) {
  if (quiet_clock_tick(r)) return;  // as print_text
  std::ostringstream out;
  out << "{\"seq\":" << r.seq << ",\"time_ns\":" << r.time_ns << ",\"facts_in\":" << r.facts_in
      << ",\"facts_out\":" << r.facts_out << ",\"resynced\":" << (r.resynced ? "true" : "false")
      << ",\"rules_reloaded\":" << (r.rules_reloaded ? "true" : "false") << ",\"rules_error\":"
      << (r.rules_error ? "\"" + node::json_escape(*r.rules_error) + "\"" : std::string("null"))
      << ",\"added\":" << json_atoms(r.added) << ",\"removed\":" << json_atoms(r.removed)
      << ",\"stale_records_removed\":" << r.stale_records_removed << ",\"total_ms\":" << fixed(r.total_ms) << ",\"read_ms\":" << fixed(r.read_ms)
      << ",\"derive_ms\":" << fixed(r.derive_ms) << ",\"write_ms\":" << fixed(r.write_ms)
      << ",\"conclusions\":" << r.engine.conclusions << ",\"base_facts\":" << r.engine.base_facts << ",\"not_written\":[";
  for (std::size_t i = 0; i < r.not_written.size(); ++i) out << (i ? ",\"" : "\"") << node::json_escape(r.not_written[i]) << "\"";
  out << "],\"warnings\":[";
  for (std::size_t i = 0; i < r.warnings.size(); ++i) out << (i ? ",\"" : "\"") << node::json_escape(r.warnings[i]) << "\"";
  out << "]}\n";
  std::cout << out.str() << std::flush;
}

void print_text(const reasoner::SessionReport& r, const uri::PrefixMap& prefixes) {
  if (quiet_clock_tick(r)) return;
  if (r.rules_error) std::cerr << "tahvel: rules not reloaded (the previous rules run): " << *r.rules_error << "\n";
  // A resynchronised session reads the whole board again, not what changed: its count is not
  // "new" facts (3 facts and one conclusion record removed by hand read "3 new").
  std::cout << "session at seq " << r.seq << ": "
            << (r.resynced ? "resynchronised, " + std::to_string(r.facts_in) + " facts read again"
                           : std::to_string(r.facts_in) + " new and " + std::to_string(r.facts_out) + " removed facts")
            << (r.rules_reloaded ? ", rules reloaded" : "") << "; derived " << r.added.size()
            << ", retracted " << r.removed.size()
            << (r.stale_records_removed ? " and " + std::to_string(r.stale_records_removed) +
                                              " records of an earlier run's conclusions that no longer hold"
                                        : std::string())
            << " in " << fixed(r.total_ms) << " ms (read "
            << fixed(r.read_ms) << ", derive " << fixed(r.derive_ms) << ", write " << fixed(r.write_ms)
            << "); " << r.engine.conclusions << " conclusions over " << r.engine.base_facts << " facts\n";
  for (const auto& a : r.added) std::cout << "+ " << short_atom(a, prefixes) << "\n";
  for (const auto& a : r.removed) std::cout << "- " << short_atom(a, prefixes) << "\n";
  std::cout << std::flush;
}

}  // namespace

const Command kReasonCommand{
    "reason",
    "DIR RULES [--once] [--json] [--default-ns IRI] [--agent ID] [--interval MS] [--persistent] [--max-conclusions N]",
    "Apply a rule file to the whiteboard in incremental sessions (the reasoner agent).",
    "Runs a session now and then one whenever records that some rule reads change (at most one\n"
    "per --interval), until interrupted; with --once, one session. Each session derives from\n"
    "what changed since the previous one, writes each new conclusion once (source: the node\n"
    "IRI/ID of --agent, default 'reasoner') and removes those that lost all support. The rule\n"
    "file is reloaded when it changes; a broken file is reported (file:line:col) and the\n"
    "previous rules keep running. On a ring store give --persistent: a conclusion the ring\n"
    "reclaims while it holds is written again, a new item each time (sent up again by a\n"
    "forwarding policy, a command it states run again). #name and bare atoms are IRIs in --default-ns (default: the\n"
    "node IRI followed by '#'); 'me' is the node IRI. Language: docs/reasoner.md.",
    {{"--once", "", "", "one session, then exit"},
     {"--json", "", "", "one JSON object per session instead of text"},
     {"--default-ns", "", "IRI", "namespace of #name and bare atoms (default: node IRI + '#')"},
     {"--agent", "", "ID", "write as agent ID (IRI: node IRI/ID); default \"reasoner\""},
     {"--interval", "", "MS", "at most one session per MS milliseconds (default 100)"},
     {"--persistent", "", "", "conclusions as persistent items: a ring does not reclaim them; they go when they lose support"},
     {"--max-conclusions", "", "N", "conclusions one session may derive before the rules are taken to derive without end (default 2000000)"}},
    2, 2};

int run_reason(const Args& args) {
  reasoner::ReasonerOptions options;
  options.rules = args.positional(1);
  options.agent_id = agent_id(args, "reasoner");
  const std::uint64_t interval_ms = args.get_u64("--interval", 100);
  if (interval_ms > static_cast<std::uint64_t>(reasoner::kMaxInterval.count()))
    usage_error("--interval: " + std::to_string(interval_ms) + " ms is more than a day (at most " +
                std::to_string(reasoner::kMaxInterval.count()) + ")");
  options.interval = std::chrono::milliseconds(interval_ms);
  options.persistent = args.has("--persistent");
  options.max_conclusions = args.get_u64("--max-conclusions", reasoner::kDefaultMaxConclusions);
  if (options.max_conclusions == 0) usage_error("--max-conclusions: must be at least 1");
  std::string dir = args.positional(0);
  node::Node node = open_node(dir);
  // Rewritten after each reclaim, a conclusion that holds all along is a new item each time: a
  // forwarding policy sends it up again (an alert repeated at the hospital), and a behaviour it
  // commands runs again.
  if (const auto stats = node.stats(); stats && stats->ring > 0 && !options.persistent)
    std::cerr << warning_prefix() << dir << " is a ring of " << stats->ring
              << " records: conclusions it reclaims are written again while they hold (and sent up again, commands run "
                 "again); --persistent keeps them until they lose support\n";
  uri::PrefixMap prefixes = prefixes_with_flags(node.prefixes(), args);
  if (auto ns = args.get("--default-ns")) options.default_ns = parse_iri(*ns, prefixes, "--default-ns");
  // Printing: the default namespace as the empty prefix (":stateIdle"), unless one is set.
  if (!prefixes.entries().count("")) (void)prefixes.add("", options.default_ns.empty() ? node.iri() + "#" : options.default_ns);
  auto reasoner = reasoner::Reasoner::open(dir, options);
  if (!reasoner) fail(reasoner.error().message);
  const bool json = args.has("--json");
  auto print = [&](reasoner::SessionReport r) {
    std::sort(r.added.begin(), r.added.end());
    std::sort(r.removed.begin(), r.removed.end());
    // A write to standard error that failed once (a full disk under the log) leaves std::cerr
    // failed, and every later line was dropped: cleared before each report. A report that cannot
    // be written to standard output ends the run (false), as a closed pipe does; the supervisor
    // starts it again.
    std::cerr.clear();
    if (r.problem_not_written) std::cerr << "tahvel: the rules' problem is not on the board: " << *r.problem_not_written << "\n";
    for (const std::string& said : r.not_written) std::cerr << warning_prefix() << said << "\n";
    for (const std::string& said : r.warnings) std::cerr << warning_prefix() << said << "\n";
    if (json) print_json(r); else print_text(r, prefixes);
    return static_cast<bool>(std::cout);
  };
  if (args.has("--once")) {
    auto report = reasoner->session();
    if (!report) fail(report.error().message);
    print(*report);
    finish_output_after(std::cout, "the session's conclusions are on the board",
                        "running it again writes nothing twice, and says 'derived 0' for them");
    return kExitOk;
  }
  // Stopped by its supervisor it ends with 0; by an operator's `kill`, with 143, and its
  // supervisor starts it again (node/stop_signal.h).
  node::install_stop_signal_handlers();
  auto ran = reasoner->run(print, [] { return node::stop_signal_received(); });
  if (!ran) fail(ran.error().message);
  finish_output(std::cout);
  return node::stop_exit_status();
}

}  // namespace tahvel::cli
