// The node's supervisor: starts agent processes, restarts the ones that die with exponential
// back-off, logs why each died (exit status or signal), and stops them on request. `tahvel up`
// runs one per deployment (or per node); the dispatcher starts behaviours through it too.
//
//   Supervisor sup(log);
//   sup.start({.name = "home1/hrv", .argv = {"tahvel-hrv", "state/home1"}, .log_file = "..."});
//   for (;;) { sup.poll(); std::this_thread::sleep_for(100ms); }   // reaps and restarts
//
// Threads: one thread at a time per Supervisor. It reaps only the children it started.
#pragma once

#include <sys/types.h>

#include <chrono>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "tahvel/node/error.h"
#include "tahvel/node/node.h"
#include "tahvel/node/term.h"
#include "tahvel/uri/iri.h"

namespace tahvel::agents {

using node::Result;

// When a program that ended is started again (after the back-off).
enum class Restart {
  on_failure,  // when it dies: a non-zero exit status or a signal. Status 0 means it finished
               // its work (a replay that reached its end) and it stays stopped.
  always,      // whenever it ends, status 0 included (a program meant to run until stopped)
  never,       // never (a behaviour the dispatcher started once)
};

// "on-failure", "always", "never" (as topology files write them).
std::string_view restart_name(Restart restart);

struct ProgramSpec {
  std::string name;                  // unique within the supervisor ("home1/hrv")
  std::vector<std::string> argv;     // argv[0] is looked up in PATH when it has no '/'
  std::filesystem::path log_file;    // stdout and stderr are appended here (empty: inherited)
  std::vector<std::pair<std::string, std::string>> env;  // added to the environment
  Restart restart = Restart::on_failure;
  // Caps this program's back-off below the supervisor's BackOff::max (zero: no cap of its own).
  // A node's link is what all else on it waits for: it is not left down for 30 s.
  std::chrono::milliseconds max_delay{0};
  // The log file's size past which poll() moves what it holds to `<log_file>.1` and empties it
  // (rotate_log), so that a program that runs for months, or crash-loops, does not fill the
  // disk: about twice this on disk per program, plus what it writes in the second between two
  // checks. Zero: no limit.
  std::uint64_t log_limit = 0;
  // When given, stdout is appended here instead (stderr stays in log_file): a program whose
  // output is its answer. Not rotated.
  std::filesystem::path out_file;
};

// Why a running program does not run (proc(5), the state letter of /proc/PID/stat).
enum class Suspension {
  none,
  signal,    // 'T': stopped by SIGSTOP (or SIGTSTP, SIGTTIN, SIGTTOU) until SIGCONT
  debugger,  // 't': stopped by a debugger that traces it, until the debugger lets it go
};

struct ProgramState {
  std::string name;
  pid_t pid = 0;                     // 0 while not running
  bool running = false;
  // A running program that is stopped, as poll() last saw it: it holds what it holds (a node's
  // link: its children and parent see the node as down) and does nothing, though alive.
  Suspension suspended = Suspension::none;
  std::uint32_t restarts = 0;
  // "exited with status 1", "killed by signal 9 (Killed)"; a non-zero status with the last line
  // of the program's log file: "exited with status 2 (its log ends: unknown flag '--windw')".
  std::string last_exit;
  std::optional<int> exit_status;    // of the last exit, when it exited normally
  // While a program that died waits out its back-off: when it is started again. Empty while it
  // runs, and for a program that stays stopped (finished, restart = never, or stopped on request).
  std::optional<std::chrono::steady_clock::time_point> restart_at;
};

struct BackOff {
  std::chrono::milliseconds first{500};
  std::chrono::milliseconds max{30'000};
  std::chrono::milliseconds stable{60'000};  // running this long resets the back-off
};

class Supervisor {
 public:
  using Log = std::function<void(std::string_view line)>;
  explicit Supervisor(Log log = {}, BackOff back_off = {});
  ~Supervisor();  // stops every program (SIGTERM, then SIGKILL after 5 s)
  Supervisor(const Supervisor&) = delete;
  Supervisor& operator=(const Supervisor&) = delete;

  // Starts a program now. Errors: exists (a program of that name), invalid_argument (empty
  // argv), io (fork or the log file failed). A program whose executable cannot be run exits with
  // status 127 and is reported as such. Programs get SIGKILL when the supervisor's process dies
  // (Linux PR_SET_PDEATHSIG: in fact when the thread that called start() or poll() ends; call
  // them from one thread that lives as long as the supervisor).
  Result<void> start(ProgramSpec spec);

  // Each program runs in a process group of its own, and what it started (a shell's children)
  // is stopped with it: signals go to the whole group. When a program ends by itself, what it
  // left running in its group gets SIGTERM and SIGCONT, then SIGKILL after 5 s or when the
  // program is started again, whichever comes first.

  // Stops a program: SIGTERM and SIGCONT to its group (a suspended program then handles the
  // SIGTERM, as under systemd), then SIGKILL after `grace` to what is left of the group; it is
  // not restarted. not_found when no program has that name.
  Result<void> stop(std::string_view name, std::chrono::milliseconds grace = std::chrono::seconds(5));
  // Stops several at once, signalled together, sharing one `grace`. Names no program has are
  // skipped.
  void stop(const std::vector<std::string>& names, std::chrono::milliseconds grace = std::chrono::seconds(5));
  // Stops a program as stop() does and forgets it: it leaves states(), and a program of that
  // name may be started again (a changed command), which takes its place in states() again.
  // not_found when no program has that name.
  Result<void> remove(std::string_view name, std::chrono::milliseconds grace = std::chrono::seconds(5));
  // Removes several at once: all are signalled together and share one `grace` (ten programs
  // that ignore SIGTERM take 5 s, not 50). Names no program has are skipped.
  void remove(const std::vector<std::string>& names, std::chrono::milliseconds grace = std::chrono::seconds(5));
  // Removes a program that will not be started again (a dispatcher's run, once recorded): as
  // remove(name, 0), without keeping its place for a successor of its name, which a supervisor
  // running for months would keep for every run. not_found when no program has that name.
  Result<void> forget(std::string_view name);
  void stop_all(std::chrono::milliseconds grace = std::chrono::seconds(5));

  // Changes when a program is started again, without stopping it: it applies from the program's
  // next end. A program waiting out its back-off that `restart` would leave stopped stays
  // stopped; one that finished (or failed under `never`) starts now when `restart` would have
  // started it again. A program stopped on request stays stopped. True when the program is not
  // running and starts again under `restart` (now, or at the end of its back-off); not_found when
  // no program has that name.
  Result<bool> set_restart(std::string_view name, Restart restart);

  // Called about every 100 ms while stop(), remove() and stop_all() wait for programs to end
  // (`tahvel up` rewrites its state file there, so that a stop taking its grace does not look
  // like a hung supervisor).
  void while_waiting(std::function<void()> tick) { while_waiting_ = std::move(tick); }

  // Reaps programs that died (logging why), restarts those due, and notes which running ones
  // are suspended (ProgramState::suspended). Call it regularly.
  void poll();

  // In the order the programs were started; one removed and started again keeps its place.
  std::vector<ProgramState> states() const;
  std::optional<ProgramState> state(std::string_view name) const;

 private:
  struct Program;
  void launch(Program& program);
  void reaped(Program& program, int status);
  void stop_programs(const std::vector<Program*>& programs, std::chrono::milliseconds grace);
  Log log_;
  std::function<void()> while_waiting_;
  BackOff back_off_;
  std::vector<Program*> programs_;                  // in the order of states()
  std::map<std::string, std::string> vacated_;      // a removed program's successor, by name
};

// Keeps a log that programs append to (O_APPEND) within `limit` bytes: when `file` is larger,
// its content goes to `<file>.1` (replacing the one before) and `file` is emptied in place, so
// the programs holding it open write on from its start. As with logrotate's copytruncate, a line
// written in the few microseconds between the last copy and the emptying is lost; the copy is
// repeated while the file grew during it. True when it rotated; errors: io (naming the file).
Result<bool> rotate_log(const std::filesystem::path& file, std::uint64_t limit);

// Programs that outlived a supervisor killed with SIGKILL. Its programs die with it
// (PR_SET_PDEATHSIG), but not what they started: a shell wrapper's children run on, out of reach
// of `tahvel down`, beside the next supervisor's copies. A program spec can carry a mark in its
// environment (`up` sets kLeftoverMark to the node's store directory), which what it starts
// inherits; once nothing supervises that mark any more (the caller holds the node's lock),
// kill_leftovers SIGKILLs every process of this user whose environment has kLeftoverMark=`mark`
// and returns them as "PID (COMMAND)". A process that cleared its environment is not found. A
// marked process whose parent is another `tahvel up` still running (it runs the node from a
// store directory removed or moved since) has that supervisor sent SIGTERM, listed too.
inline constexpr std::string_view kLeftoverMark = "TAHVEL_SUPERVISED_NODE";
std::vector<std::string> kill_leftovers(std::string_view mark);

// ---- on the board ------------------------------------------------------------------------
// What a supervisor runs for one node, as one persistent item on that node's board written by
// its agent `supervisor`, so that an operator on a machine above sees a node's programs through
// the link (`tahvel status` asks with a remote query; docs/deploy.md). Each program is named by
// its agent IRI (node IRI + "/" + its name on the node):
//
//   <N> tv:program <N/hrv> ; tv:programsAt 1763732000000000000 .   # ns since the Unix epoch
//   <N/hrv> tv:programState "running" ; tv:pid 4711 ; tv:restarts 0 ; tv:lastExit "…" .
//
// tv:programState is "running", "suspended" (running, but stopped by a signal or a debugger:
// ProgramState::suspended), "stopped" or "restarting" (waiting out its back-off); tv:pid (of a
// running or suspended program) and tv:lastExit are absent when unknown. A supervisor rewrites
// the item when it changes and every kProgramsRefresh, so an item much older than that was left
// by a supervisor that stopped or froze.
namespace vocab {
inline const std::string kProgram = std::string(uri::kTahvelNs) + "program";
inline const std::string kProgramsAt = std::string(uri::kTahvelNs) + "programsAt";
inline const std::string kProgramState = std::string(uri::kTahvelNs) + "programState";
inline const std::string kPid = std::string(uri::kTahvelNs) + "pid";
inline const std::string kRestarts = std::string(uri::kTahvelNs) + "restarts";
inline const std::string kLastExit = std::string(uri::kTahvelNs) + "lastExit";
// What the node's store holds (holdings_item).
inline const std::string kHoldingsAt = std::string(uri::kTahvelNs) + "holdingsAt";
inline const std::string kHolds = std::string(uri::kTahvelNs) + "holds";
inline const std::string kHeldPredicate = std::string(uri::kTahvelNs) + "heldPredicate";
inline const std::string kHeldRecords = std::string(uri::kTahvelNs) + "heldRecords";
inline const std::string kFirstAssertedAt = std::string(uri::kTahvelNs) + "firstAssertedAt";
inline const std::string kLastAssertedAt = std::string(uri::kTahvelNs) + "lastAssertedAt";
}  // namespace vocab

inline constexpr std::chrono::seconds kProgramsRefresh{5};

// "running", "suspended", "stopped" or "restarting", as the board says it.
std::string_view program_state_name(const ProgramState& state);

// The item above for node `node_iri`; `programs` carry their names on the node ("hrv", not
// "home1/hrv"). A name of several ids ("behavior/17", a dispatcher's run) is a path below the
// node (<N>/behavior/17). Errors: invalid_iri when a name cannot extend the node's IRI.
Result<node::Item> programs_item(const std::string& node_iri, const std::vector<ProgramState>& programs,
                                 std::int64_t now_ns);

// Beside it, what the node's store holds (Snapshot::predicates), so that an operator above can
// see what there is to ask for (`tahvel stats DIR --at NODE`) without fetching it:
//
//   <N> tv:holdingsAt 1763732000000000000 ; tv:holds _:h1, _:h2 .
//   _:h1 tv:heldPredicate tv:samples ; tv:heldRecords 86400 ;
//       tv:firstAssertedAt 1763645600000000000 ; tv:lastAssertedAt 1763731999000000000 .
node::Item holdings_item(const std::string& node_iri, const std::vector<node::PredicateSummary>& held, std::int64_t now_ns);

}  // namespace tahvel::agents
