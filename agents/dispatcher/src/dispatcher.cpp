// The dispatcher (dispatcher.h): commands from the input buffer (acknowledged only once the
// behaviour is started and its run recorded, so a crash in between starts it again), programs
// through the Supervisor, ends written back when poll() finds them reaped.
#include "tahvel/agents/dispatcher.h"

#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "tahvel/node/node.h"
#include "tahvel/uri/iri.h"

namespace tahvel::agents {

namespace {

const std::string kTv = "https://w3id.org/tahvel#";

std::vector<std::string> words(const std::string& text) {
  std::istringstream in(text);
  std::vector<std::string> out;
  for (std::string w; in >> w;) out.push_back(w);
  return out;
}

bool plain_file_name(const std::string& name) {
  return !name.empty() && name != "." && name != ".." && name.find('/') == std::string::npos;
}

bool is_word(const std::string& s) {
  if (s.empty() || !std::islower(static_cast<unsigned char>(s[0]))) return false;
  for (char c : s)
    if (!std::isalnum(static_cast<unsigned char>(c)) && c != '_') return false;
  return true;
}

// The output recorded of a run: its standard output's last non-empty line, at most `max` bytes (cut at a
// UTF-8 character boundary, "…" appended; bytes that are not UTF-8 as U+FFFD, which a store
// takes). Only the log's tail is read: a behaviour may log
// for days. A line longer than the store's literal limit would make the end unrecordable.
constexpr std::size_t kOutputMax = 4096;
constexpr std::streamoff kTailRead = 64 * 1024;

std::string last_line(const std::filesystem::path& file, std::size_t max) {
  std::ifstream in(file, std::ios::binary | std::ios::ate);
  if (!in) return "";
  const std::streamoff size = in.tellg();
  const std::streamoff from = size > kTailRead ? size - kTailRead : 0;
  in.seekg(from);
  std::string tail(static_cast<std::size_t>(size - from), '\0');
  in.read(tail.data(), static_cast<std::streamsize>(tail.size()));
  tail.resize(static_cast<std::size_t>(in.gcount()));
  while (!tail.empty() && (tail.back() == '\n' || tail.back() == '\r')) tail.pop_back();
  std::size_t start = tail.rfind('\n');
  std::string line = node::with_replacement_characters(tail.substr(start == std::string::npos ? 0 : start + 1));
  if (line.size() > max) {
    std::size_t cut = max - std::min<std::size_t>(max, 3);  // room for the 3 bytes of "…"
    while (cut > 0 && (static_cast<unsigned char>(line[cut]) & 0xC0) == 0x80) --cut;
    line = line.substr(0, cut) + (max >= 3 ? "\u2026" : "");
  }
  return line;
}

}  // namespace

struct Dispatcher::Impl {
  node::Node node;
  node::Agent agent;
  DispatcherOptions options;
  Supervisor& supervisor;
  std::string ns;
  struct Run {
    std::string iri, name, command, program;
    std::filesystem::path output;  // its standard output
    bool stop_requested = false;
  };
  std::map<std::string, Run> runs;  // by supervisor program name
  std::size_t output_max = kOutputMax;  // within the node's literal limit

  Impl(node::Node n, node::Agent a, DispatcherOptions o, Supervisor& s)
      : node(std::move(n)), agent(std::move(a)), options(std::move(o)), supervisor(s) {
    ns = options.default_ns.empty() ? node.iri() + "#" : options.default_ns;
    if (options.log_dir.empty()) options.log_dir = options.folder.parent_path() / "dispatcher-log";
  }

  // Stores `triples` as one item, first removing this dispatcher's records matching `replaced`
  // in the same transaction (a run has one state; a behaviour one latest result).
  Result<void> record(std::vector<node::Triple> triples, std::vector<node::Pattern> replaced = {}) {
    node::Item item;
    item.triples = std::move(triples);
    for (auto& pattern : replaced) pattern.source = agent.iri();
    auto ids = agent.replace(replaced, {item});
    if (!ids) return unexpected(ids.error());
    return {};
  }
  node::Pattern state_of(const std::string& run) const {
    return {.s = node::Term::iri(run), .p = node::Term::iri(kTv + "state")};
  }
  node::Triple t(const std::string& s, const std::string& p, node::Term o) {
    return {node::Term::iri(s), node::Term::iri(p), std::move(o)};
  }

  // A command for this node: no context, the dispatcher's, the node's own (configuration and
  // commands sent down from a node above are addressed to the node: P10), or the node's subtree
  // (`<node>/*`: sent to every node below one, it reaches each so; it was taken and dropped
  // without a trace).
  bool is_command(const node::Record& r) const {
    return r.triple.s.is_iri() && r.triple.s.value == node.iri() && r.triple.p.value == ns + "behavior" &&
           (r.meta.context.empty() || r.meta.context == agent.iri() || r.meta.context == node.iri() ||
            r.meta.context == node.iri() + "/*");
  }

  // `not_a_string`: the command's object is an IRI or a blank node (`text` its N-Triples form).
  Result<void> command(std::uint64_t item, const std::string& text, std::vector<DispatchEvent>& events,
                       bool not_a_string = false);
  Result<void> reap(std::vector<DispatchEvent>& events);
  Result<std::size_t> close_interrupted_runs();
};

// Runs recorded as running by an earlier dispatcher on this node: they ended with it (the
// supervisor that ran them stopped them, or died with them), unseen.
Result<std::size_t> Dispatcher::Impl::close_interrupted_runs() {
  std::vector<node::Record> running;
  {  // the snapshot is released before writing (a held snapshot pins the store)
    auto snap = node.snapshot();
    if (!snap) return unexpected(snap.error());
    auto listed = snap->list({.p = node::Term::iri(kTv + "state"), .o = node::Term::literal("running"),
                              .source = agent.iri()});
    if (!listed) return unexpected(listed.error());
    running = std::move(*listed);
  }
  for (const node::Record& r : running) {
    const std::string& run = r.triple.s.value;
    if (auto w = record({t(run, kTv + "state", node::Term::literal("interrupted")),
                         t(run, kTv + "output", node::Term::literal("the dispatcher stopped before this run ended"))},
                        {state_of(run)});
        !w)
      return unexpected(w.error());
  }
  return running.size();
}

Result<void> Dispatcher::Impl::command(std::uint64_t item, const std::string& text,
                                       std::vector<DispatchEvent>& events, bool not_a_string) {
  const std::string run = agent.iri() + "/run/" + std::to_string(item);
  std::vector<std::string> argv = not_a_string ? std::vector<std::string>{} : words(text);
  auto refuse = [&](const std::string& why) -> Result<void> {
    events.push_back({DispatchEvent::refused, run, text, why});
    return record({t(run, kTv + "command", node::Term::literal(text)),
                        t(run, kTv + "state", node::Term::literal("refused")),
                        t(run, kTv + "output", node::Term::literal(why))});
  };
  if (argv.size() == 2 && argv[0] == "stop") {
    std::vector<std::string> stopping;  // together: one grace for all, not 2 s each
    std::set<std::string> running;
    for (auto& [program, r] : runs) {
      running.insert(r.name);
      if (r.name != argv[1]) continue;
      r.stop_requested = true;
      stopping.push_back(program);
      events.push_back({DispatchEvent::stopped, r.iri, r.command, "stop command " + run});
    }
    // A stop that finds nothing to stop (a name mistyped, a run that has ended) said nothing.
    // Bounded (a name near the literal limit, many runs), and acknowledged even when its record
    // cannot be written: a stop never blocked the input before it was recorded.
    if (stopping.empty()) {
      std::string names;
      std::size_t listed = 0;
      for (const std::string& name : running)
        if (++listed <= 5) names += (names.empty() ? "" : ", ") + name.substr(0, 100);
      if (running.size() > 5) names += ", and " + std::to_string(running.size() - 5) + " more";
      const std::string name = argv[1].size() > 200 ? argv[1].substr(0, 200) + "…" : argv[1];
      if (auto recorded = refuse("no run of '" + name + "' is running, so none was stopped" +
                                 (names.empty() ? std::string(" (none is running)") : " (running: " + names + ")"));
          !recorded)
        events.push_back({DispatchEvent::refused, run, text, "its refusal could not be recorded: " + recorded.error().message});
      return {};
    }
    supervisor.stop(stopping, std::chrono::seconds(2));
    return {};
  }
  if (not_a_string)
    return refuse("the command " + text + " is not a string: write it quoted, behavior(me, \"name args\")");
  if (argv.empty() || !plain_file_name(argv[0])) return refuse("not a behaviour name: '" + text + "'");
  // Its result is written about <ns + name>: a name that cannot end an IRI ("a%zz", "a b")
  // could never have its end recorded.
  if (!uri::is_valid(ns + argv[0]))
    return refuse("not a behaviour name: '" + argv[0] + "' cannot end the IRI <" + ns + argv[0] + "> its result is written about");
  std::filesystem::path exe = options.folder / argv[0];
  std::error_code ec;
  if (access(exe.c_str(), X_OK) != 0 || std::filesystem::is_directory(exe, ec)) {
    if (argv == std::vector<std::string>{"stop"} && !std::filesystem::exists(exe, ec))
      return refuse("'stop' names no behaviour to stop: write \"stop NAME\"");
    if (std::filesystem::is_directory(exe, ec)) return refuse(exe.string() + ": a directory, not an executable behaviour");
    if (std::filesystem::exists(exe, ec))
      return refuse(exe.string() + ": not executable by this user (chmod +x it)");
    return refuse(exe.string() + ": no such executable behaviour");
  }
  ProgramSpec spec;
  spec.name = options.program_prefix + "behavior/" + std::to_string(item);
  spec.argv = argv;
  spec.argv[0] = exe.string();
  spec.log_file = options.log_dir / (std::to_string(item) + "-" + argv[0] + ".log");
  // The result is the last line of standard output: a warning on standard error after it
  // became the result.
  spec.out_file = options.log_dir / (std::to_string(item) + "-" + argv[0] + ".out");
  spec.restart = Restart::never;
  spec.env = {{"TAHVEL_NODE", node.dir().string()}, {"TAHVEL_RUN", run}};
  spec.env.insert(spec.env.end(), options.env.begin(), options.env.end());
  if (auto s = supervisor.start(spec); !s) return refuse(s.error().message);
  runs[spec.name] = Run{run, argv[0], text, spec.name, spec.out_file, false};
  events.push_back({DispatchEvent::started, run, text, ""});
  auto state = supervisor.state(spec.name);
  return record({t(run, kTv + "command", node::Term::literal(text)),
                      t(run, kTv + "state", node::Term::literal("running")),
                      t(run, kTv + "pid", node::Term::integer(state ? state->pid : 0))});
}

Result<void> Dispatcher::Impl::reap(std::vector<DispatchEvent>& events) {
  supervisor.poll();
  Result<void> failed;
  for (auto it = runs.begin(); it != runs.end();) {
    auto state = supervisor.state(it->first);
    if (state && state->running) { ++it; continue; }
    const Run& r = it->second;
    std::string output = last_line(r.output, output_max);
    std::string how = !state ? "gone" : r.stop_requested ? "stopped" : state->exit_status ? "exited" : "killed";
    std::vector<node::Triple> triples = {t(r.iri, kTv + "state", node::Term::literal(how)),
                                         t(r.iri, kTv + "output", node::Term::literal(output))};
    // The latest run's result replaces the one before, also when it has none: a run that printed
    // nothing, or did not end by itself (stopped, killed, gone), left the old result standing for
    // rules to fire on as if it were this run's.
    std::vector<node::Pattern> replaced = {state_of(r.iri), {.s = node::Term::iri(ns + r.name), .p = node::Term::iri(ns + "result")}};
    if (state && state->exit_status) triples.push_back(t(r.iri, kTv + "exitStatus", node::Term::integer(*state->exit_status)));
    if (!output.empty() && how == "exited")
      triples.push_back(t(ns + r.name, ns + "result", is_word(output) ? node::Term::iri(ns + output) : node::Term::literal(output)));
    // A run whose end cannot be written (a full store) stays to be tried again at the next
    // poll; the others' ends are written meanwhile.
    if (auto w = record(std::move(triples), std::move(replaced)); !w) {
      if (failed) failed = std::move(w);  // the first error is the one returned
      ++it;
      continue;
    }
    events.push_back({DispatchEvent::ended, r.iri, r.command, state ? state->last_exit : how});
    // Its end is on the board: the supervisor forgets it (every run stayed in its states, and in
    // `tahvel up`'s state file rewritten every 100 ms).
    (void)supervisor.forget(it->first);
    it = runs.erase(it);
  }
  return failed;
}

Result<Dispatcher> Dispatcher::open(const std::filesystem::path& dir, DispatcherOptions options,
                                    Supervisor& supervisor) {
  auto node = node::Node::open(dir);
  if (!node) return unexpected(node.error());
  auto agent = node->agent(options.agent_id);
  if (!agent) return unexpected(agent.error());
  auto impl = std::make_unique<Impl>(std::move(*node), std::move(*agent), std::move(options), supervisor);
  node::Pattern commands;
  commands.p = node::Term::iri(impl->ns + "behavior");
  if (auto s = impl->agent.subscribe(commands); !s) return unexpected(s.error());
  if (auto stats = impl->node.stats(); stats)
    impl->output_max = std::min<std::uint64_t>(kOutputMax, stats->max_literal_bytes);
  if (auto closed = impl->close_interrupted_runs(); !closed) return unexpected(closed.error());
  return Dispatcher(std::move(impl));
}

Dispatcher::Dispatcher(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
Dispatcher::Dispatcher(Dispatcher&&) noexcept = default;
Dispatcher& Dispatcher::operator=(Dispatcher&&) noexcept = default;
Dispatcher::~Dispatcher() = default;

const std::string& Dispatcher::iri() const { return impl_->agent.iri(); }

std::size_t Dispatcher::running() const { return impl_->runs.size(); }

Result<std::vector<DispatchEvent>> Dispatcher::stop_all(std::chrono::milliseconds grace) {
  std::vector<std::string> stopping;  // together, sharing `grace`: one at a time, 12 runs that
                                      // ignore SIGTERM took 24 s and `tahvel down` gave up
  for (auto& [program, r] : impl_->runs) {
    r.stop_requested = true;
    stopping.push_back(program);
  }
  impl_->supervisor.stop(stopping, grace);
  std::vector<DispatchEvent> events;
  if (auto r = impl_->reap(events); !r) return unexpected(r.error());
  return events;
}

Result<std::vector<DispatchEvent>> Dispatcher::poll(std::chrono::milliseconds wait) {
  std::vector<DispatchEvent> events;
  auto taken = impl_->agent.take(wait, node::Ack::manual);
  if (!taken) return unexpected(taken.error());
  if (*taken) {
    for (const node::Record& r : (*taken)->records) {
      if (!impl_->is_command(r)) continue;
      // A command written as an IRI (`behavior(me, echo1)` for `behavior(me, "echo1")`) was
      // passed over without a word: refused, as any other command that names no behaviour.
      const std::string text = r.triple.o.is_literal() ? r.triple.o.value : r.triple.o.to_ntriples();
      if (auto c = impl_->command(r.meta.id, text, events, !r.triple.o.is_literal()); !c) return unexpected(c.error());
    }
    if (auto a = impl_->agent.ack((*taken)->item); !a) return unexpected(a.error());
  }
  if (auto r = impl_->reap(events); !r) return unexpected(r.error());
  return events;
}

}  // namespace tahvel::agents
