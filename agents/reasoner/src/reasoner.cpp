// The reasoner agent over a node (reasoner.h). A session: snapshot; the records after the last
// session's sequence number (from the snapshot itself, so a session never sees half an item)
// and the logged removals up to the snapshot's sequence number (Node::watch); a check that
// every sequence number in between is accounted for, else a resync; Engine::apply; one item of
// new conclusions per predicate; one removal per retracted conclusion.
#include "tahvel/agents/reasoner.h"

#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <chrono>
#include <map>
#include <set>
#include <thread>

#include "tahvel/agents/rule_file.h"
#include "tahvel/node/node.h"
#include "program.h"

namespace tahvel::reasoner {

namespace {

using Clock = std::chrono::steady_clock;

// How often rules that use `now` are evaluated on a board where nothing else changes.
constexpr auto kNowTick = std::chrono::seconds(1);

double ms_since(Clock::time_point t) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t).count();
}

std::int64_t wall_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::system_clock::now().time_since_epoch()).count();
}

std::string key_of(const node::Triple& t) {
  return t.s.to_ntriples() + " " + t.p.to_ntriples() + " " + t.o.to_ntriples();
}

// Reads `file` and parses it as load_rules does.
Result<std::shared_ptr<const Program>> parse_rule_file(RuleFile& file, ParseOptions options) {
  auto text = file.read();
  if (!text) return unexpected(text.error());
  options.file = file.path().string();
  return parse_rules(*text, options);
}

// Net effect of two updates in sequence.
void compose(Engine::Update& first, Engine::Update&& second) {
  if (first.added.empty() && first.removed.empty()) {
    first = std::move(second);
    return;
  }
  std::set<Atom> added(first.added.begin(), first.added.end());
  std::set<Atom> removed(first.removed.begin(), first.removed.end());
  for (const Atom& a : second.added) { if (!removed.erase(a)) added.insert(a); }
  for (const Atom& a : second.removed) { if (!added.erase(a)) removed.insert(a); }
  first.added.assign(added.begin(), added.end());
  first.removed.assign(removed.begin(), removed.end());
}

Error node_error(const node::Error& e) { return Error{e.message}; }

}  // namespace

struct Reasoner::Impl {
  node::Node node;
  node::Agent agent;
  ReasonerOptions options;
  ParseOptions parse;
  std::shared_ptr<const Program> program;
  const Program* warned_of = nullptr;  // the rules whose predicates held by none were said (once)
  bool uses_now() const {
    return std::any_of(program->strata.begin(), program->strata.end(), [](const Stratum& s) { return s.volatile_; });
  }
  RuleFile rule_file;
  Engine engine;
  bool started = false;
  std::uint64_t bookmark = 0;  // last seq of the previous session's snapshot
  // Its count of removal notices' seqs (Snapshot::notice_seqs): numbers after the bookmark that
  // are neither records nor logged removals, taken whenever an item routed to an agent that
  // receives notices (a link's) is removed.
  std::uint64_t bookmark_notices = 0;
  // Ids of the item the previous session wrote (after its snapshot): the next session need not
  // read its own conclusions back; the gap check still accounts for them.
  std::uint64_t own_first = 0, own_last = 0;
  // key_of of the own records the previous session's write removed: any other removal of an own
  // record is someone else's (`tahvel remove` by pattern takes the reasoner's copy of a fact
  // that is also derived), and the session runs from scratch so that what still holds is
  // written again.
  std::set<std::string> removing;
  std::uint64_t reclaimed = 0;
  // The store's reclaim count once the last session's write was done: a count that moves after
  // it is another writer's records pushing facts or conclusions out of a ring (run()).
  std::uint64_t reclaimed_after_write = 0;
  // The rule file changed and parsed, and no session has yet evaluated `program` on the board
  // (the engine runs the previous rules until one succeeds).
  bool rules_pending = false;

  // Held (flock) while this reasoner runs: see Reasoner::open.
  int agent_lock = -1;

  Impl(node::Node n, node::Agent a, ReasonerOptions o, ParseOptions p, std::shared_ptr<const Program> prog, RuleFile f)
      : node(std::move(n)), agent(std::move(a)), options(std::move(o)), parse(std::move(p)),
        program(prog), rule_file(std::move(f)), engine(new_engine()) {}
  // An engine of the current rules, with this reasoner's limit on a session's conclusions.
  Engine new_engine() const {
    Engine e(program);
    e.set_conclusion_limit(options.max_conclusions);
    return e;
  }
  ~Impl() {
    if (agent_lock >= 0) ::close(agent_lock);
  }
  Impl(const Impl&) = delete;
  Impl& operator=(const Impl&) = delete;

  std::string genid(const node::Term& t) const {
    return node.iri() + "/.well-known/genid/" + t.value;
  }
  // A fact as the engine reads it: the skolem IRI this node writes for a blank node of the board,
  // `<node IRI>/.well-known/genid/bN` (RS12), is that blank node again. Other agents can name the
  // node only by that IRI; read as an IRI, their facts did not join with the blank node's, and a
  // conclusion reached through each name was one triple written twice (and removed with the
  // first to lose its support). Only the store's own labels (b and digits): skolem() mints
  // `…/genid/s…` IRIs, which stay IRIs.
  node::Triple as_read(node::Triple t) const {
    const std::string prefix = node.iri() + "/.well-known/genid/b";
    for (node::Term* term : {&t.s, &t.o}) {
      const std::string& v = term->value;
      if (term->is_iri() && v.size() > prefix.size() && v.compare(0, prefix.size(), prefix) == 0 &&
          v.find_first_not_of("0123456789", prefix.size()) == std::string::npos)
        *term = node::Term::blank(v.substr(prefix.size() - 1));
    }
    return t;
  }
  std::vector<node::Triple> stored(const Atom& atom) const {
    Atom a = atom;
    for (node::Term& t : a.args) if (t.is_blank()) t = node::Term::iri(genid(t));
    return store_form(a, agent.iri() + "/c/");
  }
  // The reasoner's conclusions: its records, bar the problem it reports (node::kProblem).
  bool own(const node::Record& r) const {
    return r.meta.source == agent.iri() &&
           !(r.triple.s.is_iri() && r.triple.s.value == agent.iri() && r.triple.p.is_iri() &&
             (r.triple.p.value == node::kProblem || r.triple.p.value == node::kProblemPid));
  }
  // The problem on the board now, as this reasoner last wrote it (empty: none).
  std::string problem;
  Result<void> report_problem(const std::string& text);
  // report_problem in a session: a problem that cannot be written (a full store) is told in the
  // report, and the session goes on with the previous rules, as it would without it.
  void try_report_problem(const std::string& text, SessionReport& report) {
    if (auto r = report_problem(text); !r) report.problem_not_written = r.error().message;
  }

  void maybe_reload(SessionReport& report);
  Result<void> read_changes(const node::Snapshot& snap, std::vector<node::Triple>& in,
                            std::vector<node::Triple>& out, bool& gap);
  void say_predicates_held_by_none(const node::Snapshot& snap, SessionReport& report) const;
  Result<Engine::Update> first_session(const node::Snapshot& snap, std::int64_t now, SessionReport& report,
                                       std::vector<node::Triple>& extra_removals);
  Result<Engine::Update> resync(const node::Snapshot& snap, std::int64_t now, SessionReport& report,
                                std::vector<node::Triple>& extra_removals);
  // Leaves out of update.added what the node cannot hold (report.not_written).
  Result<void> write(Engine::Update& update, const std::vector<node::Triple>& extra_removals, std::int64_t now,
                     SessionReport& report);
  // The node's literal limit (init --max-literal; 0: none known), and the conclusions over it
  // said so far.
  std::uint64_t literal_limit = 0;
  std::set<std::string> said_not_written;
  Result<SessionReport> session();
};

// When the rule file changed and parses, `program` is the new one, which the session evaluates
// on the whole board (RS15): the engine holds only the facts the old rules read (a new rule may
// read others; a file that was briefly empty read none).
void Reasoner::Impl::maybe_reload(SessionReport& report) {
  if (!rule_file.changed()) return;
  auto loaded = parse_rule_file(rule_file, parse);
  if (!loaded) {
    report.rules_error = loaded.error().message;
    return;
  }
  program = *loaded;
  report.rules_reloaded = true;
  rules_pending = true;
}

// Writes `text` as this reasoner's problem in place of the one before (empty: removes it). A
// parse error quotes the file's bytes, which need not be UTF-8: report_problem makes them text.
Result<void> Reasoner::Impl::report_problem(const std::string& text) {
  if (auto written = agent.report_problem(text); !written) return unexpected(node_error(written.error()));
  problem = text;
  return {};
}

// Insertions after the bookmark from the snapshot; removals up to its last seq from the log.
// `gap`: some sequence number in (bookmark, last] is neither a record, a logged removal nor a
// removal notice's.
Result<void> Reasoner::Impl::read_changes(const node::Snapshot& snap, std::vector<node::Triple>& in,
                                          std::vector<node::Triple>& out, bool& gap) {
  const std::uint64_t last = snap.last_seq();
  std::uint64_t present = 0, removals = 0, removed_new = 0;
  bool removed_by_others = false;
  const bool skip_own = own_first > bookmark && own_last >= own_first && own_last <= last;
  auto read_from = [&](std::uint64_t after, std::uint64_t stop_at) -> Result<void> {
    node::Pattern pattern;
    pattern.after_id = after;
    auto walked = snap.for_each(pattern, [&](const node::Record& r) {
      if (stop_at && r.meta.id >= stop_at) return false;
      ++present;
      if (!own(r) && r.triple.p.is_iri() && engine.relevant(r.triple.p.value)) in.push_back(as_read(r.triple));
      return true;
    });
    if (!walked) return unexpected(node_error(walked.error()));
    return {};
  };
  if (skip_own) {
    if (auto r = read_from(bookmark, own_first); !r) return r;
    present += own_last - own_first + 1;
    if (auto r = read_from(own_last, 0); !r) return r;
  } else if (auto r = read_from(bookmark, 0); !r) {
    return r;
  }
  if (last > bookmark + present) {  // something was removed: read the log
    auto changes = node.watch(bookmark, std::chrono::milliseconds(0));
    if (!changes) return unexpected(node_error(changes.error()));
    for (const node::Change& c : *changes) {
      if (!c.removed || c.seq > last) continue;
      if (!c.unreadable.empty()) continue;  // not counted: the gap below has the board read again
      if (own(c.record) && !removing.count(key_of(c.record.triple))) removed_by_others = true;
      ++removals;
      if (c.record.meta.id > bookmark) { ++removed_new; continue; }  // never seen
      if (!own(c.record) && c.record.triple.p.is_iri() && engine.relevant(c.record.triple.p.value))
        out.push_back(as_read(c.record.triple));  // as insertions are read: only what some rule reads
    }
  }
  const std::uint64_t notices = snap.notice_seqs() - std::min(bookmark_notices, snap.notice_seqs());
  gap = last - bookmark != present + removals + removed_new + notices || removed_by_others;
  removing.clear();
  return {};
}

void Reasoner::Impl::say_predicates_held_by_none(const node::Snapshot& snap, SessionReport& report) const {
  auto held = snap.predicates();
  if (!held) return;  // a hint only: the session reads the board anyway and says its error
  for (const BasePredicate& read : base_predicates(*program)) {
    // More than two edits away is another word, not a slip.
    const node::PredicateMatch match = node::match_predicate(read.iri, *held, 3);
    const node::PredicateSummary* nearest = match.nearest;
    if (match.held) continue;
    // A slip of arity (a researcher's probe of session 89): `\+ ex:low(W, _)` beside rules of
    // ex:low/1 always held and alerted for every window, without a word.
    if (!read.concluded_arities.empty()) {
      std::string arities;
      for (std::uint32_t n : read.concluded_arities)
        arities += (arities.empty() ? "" : " and ") + std::to_string(n);
      report.warnings.push_back(read.where + ": <" + read.iri + "> with 2 arguments is concluded by no rule (its rules have arity " +
                                arities + ") and no fact on the board has it, so a call of it holds for nothing and its " +
                                "negation for everything: give the call its rules' arguments");
      continue;
    }
    // A predicate that nothing on the board is near may simply not have come yet, unless it is
    // a built-in of another language in the rules' own namespace (count(W, N) for an
    // aggregation), which held for nothing without a word (a researcher's probe of session 87).
    if (!nearest) {
      static const std::set<std::string> kOtherLanguages = {"count", "sum", "min", "max", "avg", "average", "length",
                                                            "findall", "aggregate_all", "bagof", "setof", "member", "abs",
                                                            "between", "succ", "plus", "atom_length", "sort", "msort"};
      if (read.iri.starts_with(parse.default_ns) && kOtherLanguages.count(read.iri.substr(parse.default_ns.size())))
        report.warnings.push_back(read.where + ": <" + read.iri + ">: no rule concludes it and no fact on the board has it, so " +
                                  "what the rules read of it holds for nothing; " + read.iri.substr(parse.default_ns.size()) +
                                  " is no built-in here (there is no aggregation; the built-ins are in docs/reasoner.md RS5)");
      continue;
    }
    auto counted = [](const node::PredicateSummary& p) {
      return "<" + p.predicate + "> (" + std::to_string(p.records) + (p.records == 1 ? " record)" : " records)");
    };
    std::string named = counted(*nearest);
    for (std::size_t i = 0; i < match.as_near.size() && i < 2; ++i)
      named += (i + 1 == match.as_near.size() ? " or " : ", ") + counted(*match.as_near[i]);
    if (match.as_near.size() > 2) named += " or " + std::to_string(match.as_near.size() - 2) + " more as near";
    report.warnings.push_back(read.where + ": <" + read.iri + ">: no fact on the board has this predicate; did you mean " +
                              named + "? Until one has it, what the rules read of it holds for nothing");
  }
}

Result<Engine::Update> Reasoner::Impl::first_session(const node::Snapshot& snap, std::int64_t now,
                                                     SessionReport& report,
                                                     std::vector<node::Triple>& extra_removals) {
  const auto read_start = Clock::now();
  std::vector<node::Triple> base;
  std::map<std::string, node::Triple> mine;
  auto walked = snap.for_each({}, [&](const node::Record& r) {
    if (own(r)) mine.emplace(key_of(r.triple), r.triple);
    else if (r.triple.p.is_iri() && engine.relevant(r.triple.p.value)) base.push_back(as_read(r.triple));
    return true;
  });
  if (!walked) return unexpected(node_error(walked.error()));
  report.facts_in = base.size();
  report.read_ms = ms_since(read_start);
  Engine::Update u = engine.apply(base, {}, now);
  // What is on the board from an earlier run stays; only the difference is written or removed.
  std::vector<Atom> fresh;
  for (const Atom& a : u.added) {
    bool all_there = true;
    for (const node::Triple& t : stored(a)) all_there &= mine.erase(key_of(t)) > 0;
    if (!all_there) fresh.push_back(a);
  }
  u.added = std::move(fresh);
  for (auto& [k, t] : mine) extra_removals.push_back(t);
  return u;
}

// From scratch under `program`, after a gap, a reclaim or a reload: the conclusions that changed,
// and also the board checked against them, since a ring or TTL may have reclaimed this
// reasoner's own records (a conclusion that still holds is written again) or left part of an
// n-ary one. The board is read for the facts `program` reads, which after a reload are not
// only those the engine held.
Result<Engine::Update> Reasoner::Impl::resync(const node::Snapshot& snap, std::int64_t now, SessionReport& report,
                                              std::vector<node::Triple>& extra_removals) {
  const auto read_start = Clock::now();
  Engine fresh = new_engine();
  std::vector<node::Triple> base;
  std::map<std::string, node::Triple> mine;
  auto walked = snap.for_each({}, [&](const node::Record& r) {
    if (own(r)) mine.emplace(key_of(r.triple), r.triple);
    else if (r.triple.p.is_iri() && fresh.relevant(r.triple.p.value)) base.push_back(as_read(r.triple));
    return true;
  });
  if (!walked) return unexpected(node_error(walked.error()));
  report.read_ms += ms_since(read_start);
  report.facts_in = base.size();
  std::vector<Atom> before = engine.conclusions();
  fresh.apply(base, {}, now);
  engine = std::move(fresh);
  std::vector<Atom> after = engine.conclusions();
  Engine::Update u;
  std::set_difference(after.begin(), after.end(), before.begin(), before.end(), std::back_inserter(u.added));
  std::set_difference(before.begin(), before.end(), after.begin(), after.end(), std::back_inserter(u.removed));
  const std::size_t changed = u.added.size();
  for (const Atom& a : after) {
    bool all_there = true;
    for (const node::Triple& t : stored(a)) all_there &= mine.erase(key_of(t)) > 0;
    if (!all_there && !std::binary_search(u.added.begin(), u.added.begin() + static_cast<long>(changed), a))
      u.added.push_back(a);  // reclaimed from the board: written again
  }
  for (const Atom& a : u.removed)
    for (const node::Triple& t : stored(a)) mine.erase(key_of(t));
  for (auto& [k, t] : mine) extra_removals.push_back(t);
  return u;
}

// A session's conclusions change in one transaction (Agent::replace): a reader sees the
// conclusions before the session or after it, never a mix.
Result<void> Reasoner::Impl::write(Engine::Update& update, const std::vector<node::Triple>& extra_removals,
                                   std::int64_t now, SessionReport& report) {
  own_first = own_last = 0;
  // One item per predicate, and per class for rdf:type: a node's forwarding policy routes whole
  // items (P5), and one item of everything a session concluded sent a home-only conclusion (a
  // helper relation, a private note) up with the alert that matched the policy; every class
  // shares rdf:type, and a policy forwarding one class sent the session's other classes too.
  std::vector<node::Item> items;
  std::map<std::string, std::size_t> item_of;
  std::vector<bool> left_out(update.added.size(), false);
  for (std::size_t i = 0; i < update.added.size(); ++i) {
    const Atom& a = update.added[i];
    std::vector<node::Triple> form = stored(a);
    const auto too_long = std::find_if(form.begin(), form.end(), [&](const node::Triple& t) {
      return literal_limit > 0 && t.o.is_literal() && t.o.value.size() > literal_limit;
    });
    if (too_long != form.end()) {
      std::string text = a.to_string();
      if (text.size() > 200) text = text.substr(0, 200) + "…";
      if (said_not_written.insert(a.predicate).second)
        report.not_written.push_back("the conclusion " + text + " is not written: its literal of " +
                                     std::to_string(too_long->o.value.size()) + " bytes is over this node's limit of " +
                                     std::to_string(literal_limit) + " (tahvel init --max-literal); the rest of the session is written");
      left_out[i] = true;
      continue;
    }
    std::string key = a.predicate;
    if (a.predicate == node::kRdfType && a.args.size() == 2) key += ' ' + a.args[1].value;
    auto [at, is_new] = item_of.emplace(key, items.size());
    if (is_new) {
      items.emplace_back();
      items.back().asserted_at = now;
      items.back().persistent = options.persistent;
    }
    for (node::Triple& t : form) items[at->second].triples.push_back(std::move(t));
  }
  std::size_t kept = 0;
  for (std::size_t i = 0; i < update.added.size(); ++i)
    if (!left_out[i]) {
      if (kept != i) update.added[kept] = std::move(update.added[i]);  // not onto itself: a moved-from vector
      ++kept;
    }
  update.added.resize(kept);
  std::vector<node::Triple> gone = extra_removals;
  for (const Atom& a : update.removed) {
    auto form = stored(a);
    gone.insert(gone.end(), form.begin(), form.end());
  }
  std::vector<node::Pattern> removals;
  removals.reserve(gone.size());
  removing.clear();
  for (const node::Triple& t : gone) {
    removing.insert(key_of(t));
    node::Pattern p;
    p.s = t.s;
    p.p = t.p;
    p.o = t.o;
    p.source = agent.iri();
    removals.push_back(std::move(p));
  }
  if (items.empty() && removals.empty()) return {};
  auto ids = agent.replace(removals, items);
  if (!ids) return unexpected(node_error(ids.error()));
  // One item's records have consecutive ids, which the next session need not read back. With
  // several items a ring's reclaim may log removals between them: those are read.
  if (ids->size() == 1) {
    own_first = ids->front();
    own_last = ids->front() + items.front().triples.size() - 1;
  }
  return {};
}

Result<SessionReport> Reasoner::Impl::session() {
  const auto t0 = Clock::now();
  SessionReport report;
  const std::int64_t now = wall_ns();
  Engine::Update update;
  maybe_reload(report);
  if (report.rules_error) {
    const std::string said = "rules not reloaded (the previous rules run): " + *report.rules_error;
    if (said != problem) try_report_problem(said, report);
  } else if (report.rules_reloaded && !problem.empty()) {
    try_report_problem("", report);
  }
  if (rules_pending && !started) {  // the first session reads the whole board anyway
    engine = new_engine();
    rules_pending = false;
  }
  // Rows of facts that went accumulate (a ring store): rebuild when they dominate (new rules
  // get a new engine anyway).
  if (started && !rules_pending) {
    EngineStats es = engine.stats();
    if (es.rows > 4 * (es.base_facts + es.conclusions) + 65536) compose(update, engine.compact(now));
  }
  // Retention removes records without logging them: a change of the counter read before the
  // snapshot means the mirror may hold reclaimed records.
  auto stats = node.stats();
  if (!stats) return unexpected(node_error(stats.error()));
  std::optional<node::Snapshot> snap;
  if (auto s = node.snapshot(); s) snap.emplace(std::move(*s));
  else return unexpected(node_error(s.error()));
  report.seq = snap->last_seq();
  const std::uint64_t notice_seqs = snap->notice_seqs();
  report.time_ns = now;
  std::vector<node::Triple> in, out, extra_removals;
  bool gap = false;
  const auto t1 = Clock::now();
  try {
  if (warned_of != program.get()) {
    say_predicates_held_by_none(*snap, report);
    warned_of = program.get();
  }
  if (!started) {
    auto u = first_session(*snap, now, report, extra_removals);
    if (!u) return unexpected(u.error());
    compose(update, std::move(*u));
  } else {
    if (!rules_pending) {
      if (auto r = read_changes(*snap, in, out, gap); !r) return unexpected(r.error());
      report.read_ms = ms_since(t1);
      report.resynced = gap || stats->reclaimed_records != reclaimed;
    }
    if (rules_pending || report.resynced) {
      auto u = resync(*snap, now, report, extra_removals);
      if (!u) return unexpected(u.error());
      compose(update, std::move(*u));
    } else {
      report.facts_in = in.size();
      report.facts_out = out.size();
      compose(update, engine.apply(in, out, now));
    }
  }
  } catch (const RunawayDerivation& runaway) {
    // Nothing of the session is written; the rules say why on the board, and the reasoner ends
    // (under `tahvel up` its supervisor starts it again after a back-off, to the same end until
    // the rule file is mended).
    started = false;
    engine = new_engine();
    try_report_problem(runaway.what(), report);
    return unexpected(Error{runaway.what()});
  }
  report.derive_ms = ms_since(t1) - report.read_ms;
  report.engine = engine.stats();
  report.stale_records_removed = extra_removals.size();
  // Released before writing: a snapshot held by this process keeps the store from growing
  // (Env::grow), and the write may need it to (it failed with store_full, for ever).
  snap.reset();
  const auto t2 = Clock::now();
  if (auto w = write(update, extra_removals, now, report); !w) {
    // The engine moved on but the board did not: the next session starts from scratch and
    // writes the difference between the board and the rules.
    started = false;
    engine = new_engine();
    rules_pending = false;
    return unexpected(w.error());
  }
  report.write_ms = ms_since(t2);
  if (auto after = node.stats(); after) reclaimed_after_write = after->reclaimed_records;
  started = true;
  rules_pending = false;
  bookmark = report.seq;
  bookmark_notices = notice_seqs;
  reclaimed = stats->reclaimed_records;
  report.added = std::move(update.added);
  report.removed = std::move(update.removed);
  report.total_ms = ms_since(t0);
  return report;
}

Result<Reasoner> Reasoner::open(const std::filesystem::path& dir, ReasonerOptions options) {
  // run() computes with the interval in nanoseconds: a larger one would overflow (and a
  // session a day apart is already no longer a reaction to changes).
  if (options.interval < std::chrono::milliseconds(0) || options.interval > kMaxInterval)
    return unexpected(Error{"the interval between sessions (--interval) must be 0 to " +
                            std::to_string(kMaxInterval.count()) + " ms (one day)"});
  auto node = node::Node::open(dir);
  if (!node) return unexpected(node_error(node.error()));
  auto agent = node->agent(options.agent_id);
  if (!agent) return unexpected(node_error(agent.error()));
  ParseOptions parse;
  parse.me = node->iri();
  parse.default_ns = options.default_ns.empty() ? node->iri() + "#" : options.default_ns;
  parse.prefixes = node->prefixes();
  RuleFile rule_file(options.rules);
  auto program = parse_rule_file(rule_file, parse);
  if (!program) return unexpected(program.error());
  // One process per agent: a reasoner owns every record of its agent, and at its first session
  // removes those it did not derive, so a second one writing as the same agent (two `tahvel
  // reason` with the default --agent) deleted the first one's live conclusions, and one run as
  // another program's agent (`--agent ecg` beside tahvel-ecg-source) would delete its records.
  // The lock is the one the shipped agents hold (agent_runtime.h), named by the id as the
  // agent's IRI has it.
  const std::filesystem::path lock_file =
      node->dir() / (".agent-" + agent->iri().substr(node->iri().size() + 1) + ".lock");
  const int lock = ::open(lock_file.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
  if (lock < 0) return unexpected(Error{lock_file.string() + ": " + std::strerror(errno)});
  if (flock(lock, LOCK_EX | LOCK_NB) != 0) {
    char text[32] = {};
    const ssize_t n = pread(lock, text, sizeof text - 1, 0);
    ::close(lock);
    return unexpected(Error{"another process runs as agent <" + agent->iri() + "> on this node" +
                            (n > 0 && std::atoi(text) > 0 ? " (pid " + std::to_string(std::atoi(text)) + ")" : std::string()) +
                            ", " + lock_file.string() + " is locked: give each reasoner its own --agent (a reasoner removes "
                            "the records of its agent that it did not derive)"});
  }
  const std::string pid = std::to_string(getpid()) + "\n";
  if (ftruncate(lock, 0) == 0) (void)!pwrite(lock, pid.data(), pid.size(), 0);  // for the message above only
  auto impl = std::make_unique<Impl>(std::move(*node), std::move(*agent), std::move(options), std::move(parse), std::move(*program),
                                     std::move(rule_file));
  impl->agent_lock = lock;
  if (auto st = impl->node.stats()) impl->literal_limit = st->max_literal_bytes;
  // A problem an earlier run reported is over: this one's rules parse. One that cannot go now
  // (a full store) goes once a changed rule file parses.
  if (!impl->agent.report_problem("")) impl->problem = "(left by an earlier run)";
  return Reasoner(std::move(impl));
}

Reasoner::Reasoner(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
Reasoner::Reasoner(Reasoner&&) noexcept = default;
Reasoner& Reasoner::operator=(Reasoner&&) noexcept = default;
Reasoner::~Reasoner() = default;

const std::string& Reasoner::iri() const { return impl_->agent.iri(); }

Result<SessionReport> Reasoner::session() { return impl_->session(); }

Result<void> Reasoner::run(const std::function<bool(const SessionReport&)>& on_session,
                           const std::function<bool()>& stop) {
  auto report = session();
  if (!report) return unexpected(report.error());
  if (!on_session(*report)) return {};
  std::uint64_t watched = report->seq;
  auto last = Clock::now();
  bool pending = false;
  while (!stop()) {
    auto wait = std::chrono::milliseconds(100);
    if (pending) {
      auto left = std::chrono::duration_cast<std::chrono::milliseconds>(impl_->options.interval - (Clock::now() - last));
      wait = std::clamp(left, std::chrono::milliseconds(0), wait);
    }
    auto changes = impl_->node.watch(watched, wait, 4096);
    if (!changes) return unexpected(node_error(changes.error()));
    for (const node::Change& c : *changes) {
      watched = std::max(watched, c.seq);
      const node::Record& r = c.record;
      // A change that cannot be read may be relevant: a session reads the board as it is.
      // Records reclaimed before they were read are not such a change: reclaims are counted
      // below, where the reasoner's own write's are told apart (each made a session, for ever).
      if ((!c.unreadable.empty() && !c.reclaimed) ||
          (!impl_->own(r) && r.triple.p.is_iri() && impl_->engine.relevant(r.triple.p.value)))
        pending = true;
      // A conclusion someone else removed is written again if it still holds (read_changes).
      if (c.removed && impl_->own(r) && !impl_->removing.count(key_of(r.triple))) pending = true;
    }
    if (impl_->rule_file.changed()) pending = true;
    // A ring or a TTL reclaims without a change in the stream (R17): conclusions pushed out by
    // other writers' records are written again (and facts that went are retracted from) at
    // once, not at the next relevant change. Reclaims by this reasoner's own write do not start
    // a session: a ring too small for the conclusions would have it write for ever.
    if (auto st = impl_->node.stats(); st && st->reclaimed_records != impl_->reclaimed_after_write) pending = true;
    // Rules on `now` change their conclusions as time passes: "no reading for 5 minutes" holds
    // once the 5 minutes are over, with nothing on the board changing. They are evaluated again
    // every kNowTick when nothing else starts a session.
    const bool clocked = !pending && impl_->uses_now() && Clock::now() - last >= kNowTick;
    if (clocked) pending = true;
    if (!pending || Clock::now() - last < impl_->options.interval) continue;
    last = Clock::now();
    pending = false;
    auto next = session();
    if (!next) return unexpected(next.error());
    next->clocked = clocked;
    // The session read every change up to its snapshot: those the watch has not returned yet
    // (a bulk change comes back in batches) must not start sessions with nothing to do.
    watched = std::max(watched, next->seq);
    if (!on_session(*next)) return {};
  }
  return {};
}

}  // namespace tahvel::reasoner
