// The dispatcher (the thesis' Paper 2 §7.1): a command record on the whiteboard starts a
// behaviour, a small executable from a configured folder, through the node's supervisor (one
// mechanism: the Supervisor of `tahvel up`), and its end is written back as records.
//
// A command is a triple  <me> <ns>behavior "name arg1 … argN"  (me = the node IRI, ns = the
// rules' default namespace, node IRI + "#" by default) whose context is the dispatcher's IRI or
// empty (so that the reasoner's conclusion behavior(me, "goAhead 200") is one). The value
// "stop name" ends the running behaviours called `name`. Commands are read from the
// dispatcher's input buffer (a subscription to the behavior predicate), so each command
// starts once, even across restarts of the dispatcher.
//
// Written back, per run R = <dispatcher IRI>/run/<id of the command record>:
//   R tv:command "name args";
//   R tv:state "running", replaced at its end by "exited" | "killed" | "stopped" | "refused",
//     or "interrupted" (it was running when the dispatcher stopped; written when it next opens);
//   R tv:exitStatus N (when it exited); R tv:output "last line of its output" (at most 4 KiB);
//   <ns>name <ns>result <ns>word  — the last output line when it is one lower-case word
//   (the thesis' result(solveObstacle, fail)), else the line as a string. It replaces the
//   result of the behaviour's previous run (a rule reads the latest one).
//
//   Supervisor sup;
//   auto d = Dispatcher::open("state/robot3", {.folder = "behaviours"}, sup);
//   for (;;) d->poll(100ms);
#pragma once

#include <chrono>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "tahvel/agents/supervisor.h"

namespace tahvel::agents {

struct DispatcherOptions {
  std::filesystem::path folder;          // behaviours: executables here, by file name only
  std::string agent_id = "dispatcher";   // IRI = node IRI + "/" + agent_id
  std::string default_ns;                // of `behavior` and `result`; empty: node IRI + "#"
  std::filesystem::path log_dir;         // behaviours' output; empty: folder/../dispatcher-log
  // Runs are the supervisor's programs `program_prefix` + "behavior/" + the command's item id.
  // Item ids are a store's own: where one supervisor runs several nodes (`tahvel up`), the
  // prefix ("<node id>/") keeps their runs apart, and `tahvel status` shows them under their node.
  std::string program_prefix;
  // Added to each run's environment (`tahvel up`: agents::kLeftoverMark, so that what a run left
  // behind a killed supervisor is found and stopped by the next `up` or `down`, as an agent's is).
  std::vector<std::pair<std::string, std::string>> env;
};

struct DispatchEvent {
  enum Kind { started, refused, stopped, ended } kind = started;
  std::string run;      // the run's IRI
  std::string command;  // "name args"
  std::string detail;   // why refused, how it ended
};

class Dispatcher {
 public:
  // Opens the node, subscribes to commands. `supervisor` must outlive the dispatcher.
  static Result<Dispatcher> open(const std::filesystem::path& dir, DispatcherOptions options,
                                 Supervisor& supervisor);
  Dispatcher(Dispatcher&&) noexcept;
  Dispatcher& operator=(Dispatcher&&) noexcept;
  ~Dispatcher();

  const std::string& iri() const;

  // Takes the next command (waiting up to `wait`), starts or stops behaviours, reaps ended
  // ones and writes their records. Returns what happened. Errors: the store's.
  Result<std::vector<DispatchEvent>> poll(std::chrono::milliseconds wait);

  // Number of behaviours running now.
  std::size_t running() const;

  // Stops every running behaviour (SIGTERM, SIGKILL after `grace`) and records them "stopped":
  // what `tahvel up` does when it is stopped. Returns their ends.
  Result<std::vector<DispatchEvent>> stop_all(std::chrono::milliseconds grace);

 private:
  struct Impl;
  explicit Dispatcher(std::unique_ptr<Impl>);
  std::unique_ptr<Impl> impl_;
};

}  // namespace tahvel::agents
