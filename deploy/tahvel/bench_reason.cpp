// `tahvel bench reason`: the reasoner's session times and derivation rate (docs/reasoner.md),
// with SWI-Prolog evaluating the same rules on the same facts in the same run.
//
//  - SpO2 (Paper 5 §5.1, agents/reasoner/rules/spo2.rules) and heart rate in context
//    (heart_rate.rules) over 7,500 facts on a node: a session after 10 new facts
//    (incremental: snapshot, read, derive, write) and a first session from scratch;
//  - the same from-scratch evaluation in memory (no store), the like-for-like figure against
//    SWI-Prolog, which runs the same rules as a Prolog program over the same facts as fact/3;
//  - a class hierarchy closure (rdf:type through rdfs:subClassOf) over 1M facts in memory:
//    derived facts per second.
// Targets (issue 5): incremental session <= 1 ms; >= 20x faster than SWI-Prolog.
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <random>
#include <sstream>

#include "bench.h"
#include "commands.h"
#include "tahvel/agents/reasoner.h"
#include "tahvel/agents/shipped_rules.h"

namespace tahvel::cli {

namespace {

namespace fs = std::filesystem;
namespace tr = tahvel::reasoner;
using Clock = std::chrono::steady_clock;

const std::string kNode = "http://example.org/home1";
const std::string kNs = kNode + "#";

// The rule files of agents/reasoner/rules/, compiled into the library: the rules the tests check.
const std::string kSpo2Rules(tr::shipped_rules("spo2"));
const std::string kHeartRateRules(tr::shipped_rules("heart_rate"));

double ms(Clock::duration d) { return std::chrono::duration<double, std::milli>(d).count(); }

node::Term iri(const std::string& local) { return node::Term::iri(kNs + local); }

struct Workload {
  std::vector<node::Triple> facts;      // 7,500
  std::vector<node::Triple> increment;  // 10 more
};

// A patient with a profile and COPD, a doctor's record on another patient, 1,820 PPG samples
// (SpO2, heart rate, unix timestamp: 4 facts each, one a minute) and 100 movement events.
Workload spo2_workload(std::size_t total) {
  Workload w;
  auto add = [&](std::vector<node::Triple>& to, const std::string& s, const std::string& p, node::Term o) {
    to.push_back({iri(s), iri(p), std::move(o)});
  };
  add(w.facts, "patient_uri", "profile_uri", iri("profile1"));
  add(w.facts, "profile1", "thresholds_uri", iri("thresholds1"));
  add(w.facts, "profile1", "diseases_uri", iri("d1"));
  add(w.facts, "d1", "disease_uri", iri("copd_uri"));
  w.facts.push_back({iri("copd_uri"), node::Term::iri("http://www.w3.org/2000/01/rdf-schema#subClassOf"), iri("lung_disease_uri")});
  add(w.facts, "patient2", "profile_uri", iri("profile2"));
  add(w.facts, "profile2", "thresholds_uri", iri("thresholds2"));
  add(w.facts, "thresholds2", "lower_SpO2_limit_uri", iri("l2"));
  add(w.facts, "l2", "set_by_uri", iri("dr_tamm"));
  add(w.facts, "dr_tamm", "belongs_to_class", iri("medical_personnel_uri"));
  add(w.facts, "l2", "threshold_value_uri", node::Term::integer(90));
  std::mt19937 rng(5);
  const std::int64_t t0 = 1264423298;
  std::size_t events = 100, sample = 0;
  auto add_sample = [&](std::vector<node::Triple>& to) {
    std::string x = "sample" + std::to_string(sample);
    add(to, "ppg_sensor_uri", "sample_uri", iri(x));
    add(to, x, "spo2_uri", node::Term::integer(84 + static_cast<int>(rng() % 16)));
    add(to, x, "heart_rate_uri", node::Term::integer(45 + static_cast<int>(rng() % 60)));
    add(to, x, "timestamp_uri", node::Term::integer(t0 + 60 * static_cast<std::int64_t>(sample)));
    ++sample;
  };
  auto add_event = [&](std::vector<node::Triple>& to, std::size_t i) {
    std::string e = "move" + std::to_string(i);
    add(to, e, "movement_uri", iri("patient_uri"));
    add(to, e, "timestamp_uri", node::Term::integer(t0 + static_cast<std::int64_t>(rng() % (60 * 1820))));
  };
  for (std::size_t i = 0; i < events; ++i) add_event(w.facts, i);
  while (w.facts.size() + 4 <= total) add_sample(w.facts);
  while (w.facts.size() < total) add(w.facts, "filler" + std::to_string(w.facts.size()), "note_uri", node::Term::literal("x"));
  add_sample(w.increment);
  add_sample(w.increment);
  add_event(w.increment, events);
  return w;
}

std::string prolog_atom(const node::Term& t) {
  if (t.is_iri()) {
    std::string v = t.value.rfind(kNs, 0) == 0 ? t.value.substr(kNs.size()) : t.value;
    if (v == "http://www.w3.org/2000/01/rdf-schema#subClassOf") v = "rdfs_subClassOf";
    return v.find_first_not_of("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_") == std::string::npos &&
                   std::islower(static_cast<unsigned char>(v[0]))
               ? v
               : "'" + v + "'";
  }
  if (t.datatype == node::xsd::kInteger) return t.value;
  return "'" + t.value + "'";
}

// The same rules for SWI-Prolog: Paper 5's SpO2 rules as written (they are Prolog), the rule
// system's record under the profile, and the heart-rate rules; `session` collects every
// conclusion the reasoner derives (all solutions of each derived predicate).
const char* kPrologRules = R"PL(
:- dynamic fact/3.
spo2_emergency_condition :- get_spo2_threshold(patient_uri, T), fact(ppg_sensor_uri, sample_uri, X), fact(X, spo2_uri, N), N<T.
get_spo2_threshold(P, T) :- fact(P, profile_uri, Y), fact(Y, thresholds_uri, Z), fact(Z, lower_SpO2_limit_uri, L), fact(L, set_by_uri, W), belongs_to_class(W, medical_personnel_uri), fact(L, threshold_value_uri, T),!.
get_spo2_threshold(P, T) :- fact(P, profile_uri, Y), fact(Y, thresholds_uri, Z), rule_limit(Z, L), rule_set_by(L, W), belongs_to_class(W, rule_system_uri), rule_value(L, T),!.
get_spo2_threshold(_P, T) :- T = 97.
calculate_lower_spo2_limit(P,V) :- fact(P, profile_uri, X), fact(X, diseases_uri, Y), fact(Y, disease_uri, copd_uri), V=88.
calculate_lower_spo2_limit(P,V) :- fact(P, profile_uri, X), fact(X, diseases_uri, Y), fact(Y, disease_uri, D), is_subclass_of(D, lung_disease_uri), V=92.
calculate_lower_spo2_limit(_P,V) :- V=96.
rule_limit(Z, l(P)) :- fact(P, profile_uri, Y), fact(Y, thresholds_uri, Z).
rule_set_by(l(_), rule_system).
rule_value(l(P), V) :- once(calculate_lower_spo2_limit(P, V)).
belongs_to_class(W, C) :- fact(W, belongs_to_class, C).
belongs_to_class(rule_system, rule_system_uri).
is_subclass_of(C, D) :- fact(C, rdfs_subClassOf, D).
is_subclass_of(C, E) :- fact(C, rdfs_subClassOf, D), is_subclass_of(D, E).
spo2_below_threshold(X, N) :- get_spo2_threshold(patient_uri, T), fact(ppg_sensor_uri, sample_uri, X), fact(X, spo2_uri, N), N<T.
hr_alarm(X, low_heart_rate) :- fact(ppg_sensor_uri, sample_uri, X), fact(X, heart_rate_uri, H), H < 50.
moved_before(X) :- fact(ppg_sensor_uri, sample_uri, X), fact(X, heart_rate_uri, H), H > 90, fact(X, timestamp_uri, T), fact(E, movement_uri, patient_uri), fact(E, timestamp_uri, TE), TE < T, TE >= T - 600.
hr_alarm(X, high_heart_rate_at_rest) :- fact(ppg_sensor_uri, sample_uri, X), fact(X, heart_rate_uri, H), H > 90, \+ moved_before(X).
patient(P) :- fact(P, profile_uri, _).
session(Counts) :-
  findall(P-T, (patient(P), once(get_spo2_threshold(P, T))), Th),
  findall(x, (patient(P), once(calculate_lower_spo2_limit(P, _))), Lim),
  ( spo2_emergency_condition -> E = 1 ; E = 0 ),
  findall(X-N, spo2_below_threshold(X, N), Below),
  findall(X-K, hr_alarm(X, K), Alarms),
  findall(X, (fact(ppg_sensor_uri, sample_uri, X), once(moved_before(X))), Moved),
  findall(C-D, is_subclass_of(C, D), Sub),
  maplist(length, [Th, Lim, Below, Alarms, Moved, Sub], Ls),
  Counts = [E|Ls].
bench :-
  session(Counts), format("COUNTS ~w~n", [Counts]),
  findall(Ms, (between(1, 15, _), get_time(T0), session(_), get_time(T1), Ms is (T1 - T0) * 1000), Times),
  msort(Times, Sorted), nth0(7, Sorted, Median),
  format("SESSION_MS ~6f~n", [Median]).
)PL";

struct PeerResult {
  bool ran = false;
  double session_ms = 0;
  std::string counts, note;
};

PeerResult run_swipl(const std::vector<node::Triple>& facts, const fs::path& dir) {
  PeerResult r;
  fs::path pl = dir / "spo2.pl";
  {
    std::ofstream out(pl);
    out << kPrologRules;
    for (const auto& f : facts)
      out << "fact(" << prolog_atom(f.s) << ", " << prolog_atom(f.p) << ", " << prolog_atom(f.o) << ").\n";
  }
  std::string cmd = "swipl -q -g bench -t halt " + pl.string() + " 2>&1";
  FILE* p = popen(cmd.c_str(), "r");
  if (!p) { r.note = "cannot start swipl"; return r; }
  char line[512];
  std::string all;
  while (std::fgets(line, sizeof line, p)) all += line;
  int status = pclose(p);
  std::istringstream in(all);
  for (std::string l; std::getline(in, l);) {
    if (l.rfind("SESSION_MS ", 0) == 0) { r.session_ms = std::stod(l.substr(11)); r.ran = true; }
    if (l.rfind("COUNTS ", 0) == 0) r.counts = l.substr(7);
  }
  if (!r.ran) r.note = "swipl did not run (status " + std::to_string(status) + "): " + all.substr(0, 200);
  return r;
}

// Our counts in the order of the Prolog session: emergency, thresholds, rule limits, below,
// alarms, moved, subclass pairs.
std::string our_counts(const std::vector<tr::Atom>& atoms) {
  std::size_t e = 0, th = 0, lim = 0, below = 0, alarms = 0, moved = 0, sub = 0;
  for (const auto& a : atoms) {
    std::string p = a.predicate.substr(kNs.size());
    e += p == "spo2_emergency_condition";
    th += p == "get_spo2_threshold";
    lim += p == "calculate_lower_spo2_limit";
    below += p == "spo2_below_threshold";
    alarms += p == "hr_alarm";
    moved += p == "moved_before";
    sub += p == "is_subclass_of";
  }
  return "[" + std::to_string(e) + "," + std::to_string(th) + "," + std::to_string(lim) + "," +
         std::to_string(below) + "," + std::to_string(alarms) + "," + std::to_string(moved) + "," +
         std::to_string(sub) + "]";
}

tr::ParseOptions parse_options() {
  tr::ParseOptions o;
  o.default_ns = kNs;
  o.me = kNode;
  return o;
}

struct SessionFigures {
  double incremental_ms = 0, incremental_derive_ms = 0, incremental_read_ms = 0, incremental_write_ms = 0;
  double full_ms = 0, full_derive_ms = 0;
  std::size_t conclusions = 0, incremental_added = 0;
  std::string counts;
};

// Median of `runs` fresh nodes: first session from scratch, then one after 10 new facts.
SessionFigures node_sessions(const Workload& w, const fs::path& dir, int runs) {
  std::vector<double> inc, inc_derive, inc_read, inc_write, full, full_derive;
  SessionFigures f;
  fs::path rules = dir / "bench.rules";
  std::ofstream(rules) << kSpo2Rules << kHeartRateRules;
  for (int run = 0; run < runs; ++run) {
    fs::path store = dir / ("node" + std::to_string(run));
    node::InitOptions io;
    io.iri = kNode;
    auto node = check(node::Node::init(store, io));
    auto agent = check(node.agent("ppg"));
    std::vector<node::Item> items;
    for (const auto& t : w.facts) { node::Item i; i.triples = {t}; items.push_back(std::move(i)); }
    check(agent.store_all(items));
    tr::ReasonerOptions ro;
    ro.rules = rules;
    auto reasoner = tr::Reasoner::open(store, ro);
    if (!reasoner) fail(reasoner.error().message);
    auto first = reasoner->session();
    if (!first) fail(first.error().message);
    full.push_back(first->total_ms);
    full_derive.push_back(first->derive_ms);
    f.conclusions = first->engine.conclusions;
    node::Item more;
    more.triples = w.increment;
    check(agent.store(more));
    auto next = reasoner->session();
    if (!next) fail(next.error().message);
    inc.push_back(next->total_ms);
    inc_derive.push_back(next->derive_ms);
    inc_read.push_back(next->read_ms);
    inc_write.push_back(next->write_ms);
    f.incremental_added = next->added.size();
    fs::remove_all(store);
  }
  auto median = [](std::vector<double> v) { std::sort(v.begin(), v.end()); return v[v.size() / 2]; };
  f.incremental_ms = median(inc);
  f.incremental_derive_ms = median(inc_derive);
  f.incremental_read_ms = median(inc_read);
  f.incremental_write_ms = median(inc_write);
  f.full_ms = median(full);
  f.full_derive_ms = median(full_derive);
  return f;
}

// From scratch in memory (every stratum derived again from the facts held): the like-for-like
// figure against the Prolog session, whose facts are consulted before it is timed.
double engine_from_scratch_ms(const Workload& w, std::string& counts, int runs) {
  auto program = tr::parse_rules(std::string(kSpo2Rules) + kHeartRateRules, parse_options());
  if (!program) fail(program.error().message);
  std::vector<double> times;
  tr::Engine engine(*program);
  engine.apply(w.facts, {}, 0);  // the facts in memory, as consulted facts are in Prolog
  counts = our_counts(engine.conclusions());
  for (int run = 0; run < runs; ++run) {
    auto t0 = Clock::now();
    engine.recompute(0);
    times.push_back(ms(Clock::now() - t0));
  }
  std::sort(times.begin(), times.end());
  return times[times.size() / 2];
}

struct Closure {
  std::size_t facts = 0, derived = 0;
  double seconds = 0;
};

// rdf:type through rdfs:subClassOf: a class tree (10 roots, branching 10, 4 levels: 11,110
// classes, 11,100 subclass facts) and instances typed with leaf classes, 1M facts in all, given
// to the engine in batches of 100,000 (the first session from scratch, the others semi-naive).
Closure closure(std::size_t total) {
  const char* rules =
      "rdf:type(X, D) :- rdf:type(X, C), rdfs:subClassOf(C, D).\n"
      "rdfs:subClassOf(C, E) :- rdfs:subClassOf(C, D), rdfs:subClassOf(D, E).\n";
  auto program = tr::parse_rules(rules, parse_options());
  if (!program) fail(program.error().message);
  tr::Engine engine(*program);
  const node::Term type = node::Term::iri(std::string(node::kRdfType));
  const node::Term sub = node::Term::iri("http://www.w3.org/2000/01/rdf-schema#subClassOf");
  auto cls = [](std::size_t level, std::size_t i) {
    return node::Term::iri("http://example.org/class/L" + std::to_string(level) + "_" + std::to_string(i));
  };
  std::vector<node::Triple> batch;
  Closure c;
  auto flush = [&] {
    auto t0 = Clock::now();
    auto u = engine.apply(batch, {}, 0);
    c.seconds += std::chrono::duration<double>(Clock::now() - t0).count();
    c.derived += u.added.size();
    c.facts += batch.size();
    batch.clear();
  };
  std::size_t width = 10;
  for (std::size_t level = 2; level <= 4; ++level, width *= 10)
    for (std::size_t i = 0; i < width * 10; ++i) batch.push_back({cls(level, i), sub, cls(level - 1, i / 10)});
  const std::size_t leaves = 10000;
  std::mt19937 rng(11);
  for (std::size_t i = 0; c.facts + batch.size() < total; ++i) {
    batch.push_back({node::Term::iri("http://example.org/thing/" + std::to_string(i)), type, cls(4, rng() % leaves)});
    if (batch.size() == 100000) flush();
  }
  flush();
  return c;
}

const Command kBenchReasonCommand{
    "bench reason",
    "[--json] [--quick]",
    "Reasoner session times and derivation rate, against SWI-Prolog in the same run.",
    "SpO2 and heart-rate-in-context rules over 7,500 facts: a session after 10 new facts and one\n"
    "from scratch, on a node; the same rules and facts in SWI-Prolog (swipl); a class hierarchy\n"
    "closure over 1M facts. Targets: incremental session <= 1 ms, >= 20x SWI-Prolog.",
    {{"--json", "", "", "print one JSON object"}, {"--quick", "", "", "fewer runs, a 100k-fact closure"}},
    0, 0, false};

std::string json_num(double v) {
  char buf[48];
  std::snprintf(buf, sizeof buf, "%.4g", v);
  return buf;
}

}  // namespace

int bench_reason_main(const std::vector<std::string>& argv) {
  if (wants_help(kBenchReasonCommand, argv)) { print_help(std::cout, kBenchReasonCommand); return kExitOk; }
  Args args = parse_args(kBenchReasonCommand, argv);
  const bool quick = args.has("--quick"), json = args.has("--json");
  std::string templ = (fs::temp_directory_path() / "tahvel-bench-reason-XXXXXX").string();
  if (!mkdtemp(templ.data())) fail("cannot create a temporary directory in " + fs::temp_directory_path().string());
  fs::path dir = templ;
  Workload w = spo2_workload(7500);
  SessionFigures s = node_sessions(w, dir, quick ? 3 : 9);
  std::string counts;
  double scratch_ms = engine_from_scratch_ms(w, counts, quick ? 3 : 15);
  PeerResult peer = run_swipl(w.facts, dir);
  Closure c = closure(quick ? 100000 : 1000000);
  fs::remove_all(dir);
  const double per_s = c.seconds > 0 ? static_cast<double>(c.derived) / c.seconds : 0;
  const double ratio = peer.ran && scratch_ms > 0 ? peer.session_ms / scratch_ms : 0;
  const double ratio_inc = peer.ran && s.incremental_ms > 0 ? peer.session_ms / s.incremental_ms : 0;
  const bool inc_met = s.incremental_ms <= 1.0, ratio_met = ratio >= 20;
  const bool agree = peer.ran && peer.counts == counts;
  if (json) {
    std::cout << "{\"facts\":" << w.facts.size() << ",\"new_facts\":" << w.increment.size()
              << ",\"conclusions\":" << s.conclusions << ",\"incremental_session_ms\":" << json_num(s.incremental_ms)
              << ",\"incremental_derive_ms\":" << json_num(s.incremental_derive_ms)
              << ",\"incremental_read_ms\":" << json_num(s.incremental_read_ms)
              << ",\"incremental_write_ms\":" << json_num(s.incremental_write_ms)
              << ",\"full_session_ms\":" << json_num(s.full_ms) << ",\"full_derive_ms\":" << json_num(s.full_derive_ms)
              << ",\"engine_from_scratch_ms\":" << json_num(scratch_ms)
              << ",\"swipl_session_ms\":" << (peer.ran ? json_num(peer.session_ms) : "null")
              << ",\"ratio_vs_swipl\":" << (peer.ran ? json_num(ratio) : "null")
              << ",\"ratio_incremental_vs_swipl\":" << (peer.ran ? json_num(ratio_inc) : "null")
              << ",\"swipl_agrees\":" << (agree ? "true" : "false")
              << ",\"closure_facts\":" << c.facts << ",\"closure_derived\":" << c.derived
              << ",\"closure_seconds\":" << json_num(c.seconds) << ",\"closure_derived_per_s\":" << json_num(per_s)
              << ",\"target_incremental_ms\":1,\"target_incremental_met\":" << (inc_met ? "true" : "false")
              << ",\"target_ratio_vs_swipl\":20,\"target_ratio_met\":" << (ratio_met ? "true" : "false") << "}\n";
  } else {
    std::printf("reasoner, SpO2 + heart rate rules over %zu facts (%zu conclusions)\n", w.facts.size(), s.conclusions);
    std::printf("  session after %zu new facts   %9.3f ms (read %.3f, derive %.3f, write %.3f ms)   target <= 1 ms  %s\n",
                w.increment.size(), s.incremental_ms, s.incremental_read_ms, s.incremental_derive_ms,
                s.incremental_write_ms, inc_met ? "met" : "NOT met");
    std::printf("  session from scratch          %9.3f ms (derive %.3f ms)\n", s.full_ms, s.full_derive_ms);
    std::printf("  engine from scratch (memory)  %9.3f ms\n", scratch_ms);
    if (peer.ran) {
      std::printf("  SWI-Prolog, same rules/facts  %9.3f ms   ratio %.1fx (incremental: %.0fx)   target >= 20x  %s\n",
                  peer.session_ms, ratio, ratio_inc, ratio_met ? "met" : "NOT met");
      std::printf("  conclusions agree with SWI-Prolog: %s (ours %s, swipl %s)\n", agree ? "yes" : "NO", counts.c_str(),
                  peer.counts.c_str());
    } else {
      std::printf("  SWI-Prolog: %s\n", peer.note.c_str());
    }
    std::printf("class hierarchy closure over %zu facts: %zu derived in %.3f s = %.3g derived facts/s\n", c.facts,
                c.derived, c.seconds, per_s);
  }
  return kExitOk;
}

}  // namespace tahvel::cli
