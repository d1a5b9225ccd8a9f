// Plumbing shared by the HRV pipeline agents (aggregation/agents/, docs/agents.md): the command line,
// opening the node as one agent, the take -> process -> store -> ack loop with manual
// acknowledgement, SIGINT/SIGTERM, the idle timeout, one-line errors, and reading a
// recording's description from the board. Each executable keeps only its own stage.
//
// Error lines on stderr have one shape: "<program>: <what>: <cause>" (cause names the item or
// file). Exit status: 0 done (end of input, idle, signal), 1 a Tahvel error, 2 usage.
#pragma once

#include <chrono>
#include <functional>
#include <map>
#include <optional>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "tahvel/aggregation/items.h"
#include "tahvel/node/node.h"

namespace tahvel::agents::hrv {

inline constexpr int kExitOk = 0, kExitError = 1, kExitUsage = 2;

// A bad command line; main() prints the usage and then the message and exits with kExitUsage.
struct UsageError : std::runtime_error {
  using std::runtime_error::runtime_error;
};
// Thrown by Args for -h / --help: guarded_main prints the usage on standard output, status 0.
struct HelpRequested {};

// `tahvel up` runs a program of its own build with kCheckArgsEnv=1 in its environment to check
// its command line before it starts it (a refused flag was otherwise a program restarted for
// ever): the program stops, status 0, where it would first touch the node or the signal, every
// flag checked by then. stop_here_when_only_checking() is that place (open_session calls it).
inline constexpr const char* kCheckArgsEnv = "TAHVEL_CHECK_ARGS";
void stop_here_when_only_checking();

// Runs an agent's `body` as its main(): a UsageError prints `usage` and then, as the last line,
// "<program>: <message>" on standard error (the line a supervisor shows of a failed program)
// and gives kExitUsage; otherwise the body's exit status.
int guarded_main(const char* program, const char* usage, const std::function<int()>& body);

// The command line: one positional argument (the node directory) and "--name value" or
// "--name" flags, each of which must be declared. A flag given twice is an error unless it is
// declared `repeatable` (valued; values() has each). Throws UsageError.
class Args {
 public:
  Args(int argc, char** argv, const std::vector<std::string>& valued,
       const std::vector<std::string>& boolean, const std::vector<std::string>& repeatable = {});
  // Every value of a repeatable flag, in command-line order.
  std::vector<std::string> values(const std::string& flag) const;
  const std::string& dir() const { return dir_; }
  bool has(const std::string& flag) const { return values_.count(flag) != 0; }
  std::string text(const std::string& flag, const std::string& fallback) const;
  // A finite number >= minimum, or fallback when the flag is absent. Throws UsageError.
  double number(const std::string& flag, double fallback, double minimum = 0) const;

 private:
  std::string dir_;
  std::map<std::string, std::string> values_;
  std::vector<std::pair<std::string, std::string>> repeated_;
};

// SIGINT and SIGTERM set a flag that the loops below test; the current item is finished first.
void install_stop_handlers();
bool stop_requested();
// Sleeps for `duration`, or until SIGINT/SIGTERM; false when stopped. A plain sleep_for goes on
// sleeping after the signal, and the supervisor kills what has not ended within 5 s.
bool pause_unless_stopped(std::chrono::nanoseconds duration);
// Takes the next item of `agent`'s input buffer within `timeout`, in slices that notice a stop
// request; nullopt after the timeout or a stop.
node::Result<std::optional<node::Delivery>> take_unless_stopped(node::Agent& agent, std::chrono::milliseconds timeout);

// "<UTC time> <program>: <message>" on stderr, one line (node::log_stamp).
void log_line(const std::string& program, const std::string& message);

// An opened node with one agent handle.
// An exclusive flock held while the object lives (moved, not copied).
class HeldLock {
 public:
  HeldLock() = default;
  explicit HeldLock(int fd) : fd_(fd) {}
  HeldLock(HeldLock&& other) noexcept : fd_(std::exchange(other.fd_, -1)) {}
  HeldLock& operator=(HeldLock&& other) noexcept;
  HeldLock(const HeldLock&) = delete;
  HeldLock& operator=(const HeldLock&) = delete;
  ~HeldLock();

 private:
  int fd_ = -1;
};

struct Session {
  std::string program;
  node::Node node;
  node::Agent agent;
  HeldLock running;  // DIR/.agent-<id>.lock: one process per agent id
};

// Opens DIR and makes the handle for `agent_id`. On error prints one line and returns nullopt.
// One process at a time runs as an agent id (a flock on DIR/.agent-<id>.lock, held until the
// process ends): each stage keeps its recordings' state in memory, and a second process of the
// same id took every other item (a pool of takers) and wrote wrong R-peaks, intervals and
// windows, some twice. A second is refused, naming the agent.
std::optional<Session> open_session(const std::string& program, const std::string& dir,
                                    const std::string& agent_id);

// Subscribes to each predicate (idempotent). A new subscription also brings the matching items
// already on the board (SubscribeOptions::earlier). False after printing the error.
bool subscribe_predicates(Session& session, const std::vector<std::string>& predicate_iris);

// What the handler of one delivered item decided. fatal: the item is not acknowledged (it is
// delivered again after a restart) and the loop stops with kExitError; the message is printed.
struct Outcome {
  std::optional<std::string> fatal;
  static Outcome ok() { return {}; }
  static Outcome error(std::string message) { return {std::move(message)}; }
};
using Handler = std::function<Outcome(const node::Delivery&)>;

// Takes items (Ack::manual), calls `handle`, and acknowledges each item after the handler
// returned ok (its outputs are stored by then): at-least-once, crash-safe. Stops on a signal,
// after idle_s seconds without input (0: never), or on a fatal outcome or a take/ack error.
int run_take_loop(Session& session, double idle_s, const Handler& handle);

// The recording's description from the board (the persistent recording item). Errors name
// the recording.
aggregation::Result<aggregation::RecordingInfo> load_recording(const node::Node& node,
                                                              const std::string& recording_iri);

// The full items (all their records) of every record matching `pattern`, in id order, once
// per item: what an agent replays from the board to rebuild its state after a restart.
aggregation::Result<std::vector<std::vector<node::Record>>> items_matching(
    const node::Node& node, const node::Pattern& pattern);

// items_matching for the items of one recording (those with tv:recording <recording_iri>).
aggregation::Result<std::vector<std::vector<node::Record>>> recording_items(
    const node::Node& node, const std::string& recording_iri);

// Every item of one recording (those with tv:recording <recording_iri>) asserted in
// [since_ns, until_ns), each once, in order of asserted time (then id), read ten minutes of
// that time per snapshot, and each page handed on after its snapshot is let go (`each` may
// store): what a restarted stage reads again, holding a page in memory rather than the
// recording (13.6 hours of ECG chunks read at once took 940 MB). `each` returns false to stop.
aggregation::Result<void> for_each_recording_item(const node::Node& node, const std::string& recording_iri,
                                                  std::int64_t since_ns, std::int64_t until_ns,
                                                  const std::function<bool(const std::vector<node::Record>&)>& each);
// The records of the item that has a record about `iri` (an output, named by its subject);
// nullopt when there is none, or on a read error.
std::optional<std::vector<node::Record>> item_about(const node::Node& node, const std::string& iri);
// What a stage's warm-up from one sample came to (resume_by_warm_up): its outputs over the
// second half of the inputs it read again agreed with those on the board, one differed (`why`
// names it), or one was not on the board (a late start, a removal: a replay writes it).
struct WarmUp {
  enum class Verdict { agreed, differs, missing } verdict = Verdict::missing;
  std::size_t read = 0, compared = 0;  // inputs read again, outputs compared
  std::string why;
};
// --warm-up S: seconds of signal a restarted stage reads again before where it stopped (0, the
// default: it replays the recording from its start). At least 60: a shorter warm-up would
// compare the outputs of a new detector's first seconds, in which it learns its thresholds.
// Throws UsageError.
double warm_up_seconds(const Args& args);
// After a restart at sample `upto` of a recording: tries `warm_up(start)` from warm_up_s seconds
// of signal before `upto`, then from four times as far back while its outputs differ from the
// board's, and logs how it ended. True when one agreed (the stage has taken its state), false
// when the stage must replay the recording from its start: warm_up_s 0 (--warm-up not given),
// a warm-up reaching the start, an output missing, or a recording without its start time (its
// items are not at signal times).
aggregation::Result<bool> resume_by_warm_up(const std::string& program, const aggregation::RecordingInfo& info,
                                            std::int64_t upto, double warm_up_s, const std::string& inputs,
                                            const std::function<aggregation::Result<WarmUp>(std::int64_t start)>& warm_up);
// A decimal integer, all of `text`; nullopt otherwise.
std::optional<std::int64_t> parse_int(const std::string& text);

// Whether any record has `iri` as its subject (an output already written).
bool on_board(const node::Node& node, const std::string& iri);

// Stores `item` unless its first subject (the output's IRI) is on the board already: every
// output of the pipeline is named by its recording and position, so an input delivered again
// (a crash between store and ack) or replayed after a (re)start writes nothing twice.
// catching_up only makes the write logged.
Outcome store_output(Session& session, const node::Item& item, bool catching_up);

// True when one of the records has predicate tv:<local>.
bool has_predicate(const std::vector<node::Record>& records, const char* local);

// Input an agent skips because it cannot use it (a recording without a usable description, an
// item it cannot read), kept as the agent's problem on the board (node::Agent::report_problem)
// while it is being skipped. Without it an operator sees only that no HRV comes; with it
// `tahvel status` says why, under the program, at the node and at the hospital. A key groups
// what one cause skips (a recording, a writer); the problem names the latest key's cause and
// counts the others. Made at the agent's start, it clears a problem an earlier run left.
class SkippedInputs {
 public:
  // `others` names the keys in the count ("recording(s)"): "... (and those of 2 other recording(s))".
  SkippedInputs(Session& session, std::string others);
  // Makes `key` a cause, "<why>; <what> are skipped", and logs "<why>; skipped" when that is
  // new for the key: a recording at a rate the detector refuses logged a line per chunk, one a
  // second for as long as its sensor ran. The skips after are counted, and logged when the key
  // is resumed.
  void skip(const std::string& key, const std::string& why, const std::string& what);
  // Makes `key` a cause with `text` as it is (input used, but nothing comes of it: a flat
  // signal), logged when new for the key.
  void hold(const std::string& key, const std::string& text);
  // What `key` skipped is used again, or over (a recording ended): no longer a cause.
  void resume(const std::string& key);

 private:
  struct Cause {
    std::string text;
    std::uint64_t skipped_since = 0;  // skips after the one logged
  };
  void report();
  Session& session_;
  std::string others_;
  std::map<std::string, Cause> causes_;
  std::string latest_;
};

}  // namespace tahvel::agents::hrv
