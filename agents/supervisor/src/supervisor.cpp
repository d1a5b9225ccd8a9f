#include "tahvel/agents/supervisor.h"

#include <fcntl.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cstring>
#include <fstream>
#include <iostream>
#include <set>
#include <sstream>
#include <thread>

#include "tahvel/node/process.h"
#include "tahvel/uri/iri.h"

namespace tahvel::agents {

using Clock = std::chrono::steady_clock;
using node::Errc;
using node::fail;

struct Supervisor::Program {
  ProgramSpec spec;
  ProgramState state;
  Clock::time_point started{};
  std::optional<Clock::time_point> restart_at;
  std::chrono::milliseconds delay{0};
  bool stopping = false;
  off_t log_start = 0;  // where this run's output begins in the log file
  // The process group of the last run, while what it left there may still run; SIGKILL goes to
  // it at group_kill_at (or at the next launch).
  pid_t group = 0;
  std::optional<Clock::time_point> group_kill_at;
  Clock::time_point log_checked{};
};

namespace {

// What a program that failed wrote last is most often why, and an operator reading `status` on
// the machine above should not need the log on this one to know it: a failed run's last line
// goes with its exit, at most this long.
constexpr std::size_t kLastLineBytes = 240;

// The size of `file` now (0 when it is not there): where the output of a run about to start
// begins, since every run of a program appends to the same log.
off_t size_of(const std::filesystem::path& file) {
  std::error_code ec;
  const auto size = file.empty() ? 0 : std::filesystem::file_size(file, ec);
  return ec ? 0 : static_cast<off_t>(size);
}

// `text` cut to at most `bytes` without splitting a UTF-8 sequence.
std::string utf8_prefix(std::string_view text, std::size_t bytes) {
  if (text.size() <= bytes) return std::string(text);
  std::size_t end = bytes;
  while (end > 0 && (static_cast<unsigned char>(text[end]) & 0xC0) == 0x80) --end;  // back to a sequence's start
  return std::string(text.substr(0, end));
}

// The last line the run that began at `from` wrote to `log_file` (cut to kLastLineBytes,
// control characters as spaces, bytes that are not UTF-8 as U+FFFD), or "" when it wrote none.
std::string last_line_of(const std::filesystem::path& log_file, off_t from) {
  if (log_file.empty()) return {};
  const int fd = ::open(log_file.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return {};
  char tail[4096];
  const off_t size = lseek(fd, 0, SEEK_END);
  const off_t start = std::max<off_t>(from, size - static_cast<off_t>(sizeof tail));
  const ssize_t n = size > start ? pread(fd, tail, static_cast<std::size_t>(size - start), start) : 0;
  ::close(fd);
  if (n <= 0) return {};
  std::string_view text(tail, static_cast<std::size_t>(n));
  while (!text.empty() && std::isspace(static_cast<unsigned char>(text.back()))) text.remove_suffix(1);
  if (const std::size_t newline = text.rfind('\n'); newline != std::string_view::npos) text.remove_prefix(newline + 1);
  std::string line = node::with_replacement_characters(utf8_prefix(text, kLastLineBytes));
  if (utf8_prefix(text, kLastLineBytes).size() < text.size()) line += "...";
  for (char& c : line)
    if (static_cast<unsigned char>(c) < 0x20 || c == 0x7F) c = ' ';
  return line;
}

// How often poll() compares a program's log with its limit: a log grows by at most what a
// program writes in this time past it.
constexpr std::chrono::seconds kLogCheckEvery{1};

// How long what a program left running in its group gets after SIGTERM, when the program ended
// by itself.
constexpr std::chrono::seconds kGroupGrace{5};

// `sig` to the process group `group` (a program's pid: it leads its own group); to the process
// alone when the group is not there yet (the child has not reached setpgid).
void signal_group(pid_t group, int sig) {
  if (kill(-group, sig) != 0) kill(group, sig);
}

// SIGTERM, then SIGCONT: a program stopped with SIGSTOP would otherwise keep the SIGTERM
// pending until SIGKILL came at the end of the grace (systemd stops services the same way).
void term_and_cont(pid_t group) {
  signal_group(group, SIGTERM);
  signal_group(group, SIGCONT);
}

// Whether process group `group` has a member that is not a zombie. Zombies are left out: a
// program's orphaned children are reaped by whoever adopts them (init, or a namespace's first
// process that may never reap), and a zombie runs nothing.
bool group_has_live_members(pid_t group) {
  std::error_code ec;
  for (const auto& entry : std::filesystem::directory_iterator("/proc", ec)) {
    const std::string name = entry.path().filename().string();
    if (name.empty() || !std::all_of(name.begin(), name.end(), [](char c) { return c >= '0' && c <= '9'; })) continue;
    std::ifstream in(entry.path() / "stat");
    std::string stat;
    if (!std::getline(in, stat)) continue;
    // "PID (COMM) S PPID PGRP ...": COMM may hold spaces and parentheses.
    const std::size_t close = stat.rfind(')');
    if (close == std::string::npos) continue;
    std::istringstream fields(stat.substr(close + 1));
    char state = 0;
    long ppid = 0, pgrp = 0;
    if (fields >> state >> ppid >> pgrp && pgrp == group && state != 'Z') return true;
  }
  return false;
}

std::string describe(int status) {
  if (WIFEXITED(status)) return "exited with status " + std::to_string(WEXITSTATUS(status));
  if (WIFSIGNALED(status)) {
    int sig = WTERMSIG(status);
    return "killed by signal " + std::to_string(sig) + " (" + strsignal(sig) + ")";
  }
  return "ended (wait status " + std::to_string(status) + ")";
}

}  // namespace

std::string_view restart_name(Restart restart) {
  switch (restart) {
    case Restart::on_failure: return "on-failure";
    case Restart::always: return "always";
    case Restart::never: return "never";
  }
  return "?";
}

Supervisor::Supervisor(Log log, BackOff back_off) : log_(std::move(log)), back_off_(back_off) {
  if (!log_) log_ = [](std::string_view line) { std::cerr << "tahvel supervisor: " << line << "\n"; };
}

Result<bool> rotate_log(const std::filesystem::path& file, std::uint64_t limit) {
  const int fd = ::open(file.c_str(), O_RDWR | O_CLOEXEC);
  if (fd < 0) {
    if (errno == ENOENT) return false;
    return fail(Errc::io, "cannot open the log " + file.string() + ": " + std::strerror(errno));
  }
  struct stat st {};
  if (fstat(fd, &st) != 0 || static_cast<std::uint64_t>(st.st_size) <= limit) {
    ::close(fd);
    return false;
  }
  std::filesystem::path kept = file;
  kept += ".1";
  std::filesystem::path tmp = file;
  tmp += ".1.tmp";
  const int out = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (out < 0) {
    const int err = errno;
    ::close(fd);
    return fail(Errc::io, "cannot write " + tmp.string() + ": " + std::strerror(err));
  }
  // Copy until the end of the file, again while it grew meanwhile (a busy writer), at most a
  // few times; then empty it. A write that lands after the last look is the one that is lost.
  off_t copied = 0;
  std::string failed;
  char buffer[1 << 16];
  for (int round = 0; round < 4 && failed.empty(); ++round) {
    const off_t end = lseek(fd, 0, SEEK_END);
    if (end <= copied) break;
    while (copied < end) {
      const ssize_t n = pread(fd, buffer, static_cast<std::size_t>(std::min<off_t>(end - copied, sizeof buffer)), copied);
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) {
        failed = "cannot read " + file.string() + (n < 0 ? std::string(": ") + std::strerror(errno) : std::string());
        break;
      }
      for (ssize_t done = 0; done < n;) {
        const ssize_t w = write(out, buffer + done, static_cast<std::size_t>(n - done));
        if (w < 0 && errno == EINTR) continue;
        if (w < 0) {
          failed = "cannot write " + tmp.string() + ": " + std::strerror(errno);
          break;
        }
        done += w;
      }
      if (!failed.empty()) break;
      copied += n;
    }
  }
  if (::close(out) != 0 && failed.empty()) failed = "cannot write " + tmp.string() + ": " + std::strerror(errno);
  // Emptied only once the copy is whole and in its place: a full disk keeps the log as it was.
  std::error_code ec;
  if (failed.empty()) {
    std::filesystem::rename(tmp, kept, ec);
    if (ec) failed = "cannot rename " + tmp.string() + " to " + kept.string() + ": " + ec.message();
  }
  if (failed.empty() && ftruncate(fd, 0) != 0) failed = "cannot empty " + file.string() + ": " + std::strerror(errno);
  ::close(fd);
  if (!failed.empty()) {
    std::filesystem::remove(tmp, ec);
    return fail(Errc::io, failed);
  }
  return true;
}

Supervisor::~Supervisor() {
  stop_all();
  for (Program* p : programs_) delete p;
}

Result<void> Supervisor::start(ProgramSpec spec) {
  if (spec.argv.empty() || spec.argv[0].empty()) return fail(Errc::invalid_argument, "program '" + spec.name + "': empty command");
  for (Program* p : programs_)
    if (p->spec.name == spec.name) return fail(Errc::exists, "a program named '" + spec.name + "' is already supervised");
  if (!spec.log_file.empty()) {
    std::error_code ec;
    std::filesystem::create_directories(spec.log_file.parent_path(), ec);
    int fd = ::open(spec.log_file.c_str(), O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0644);
    if (fd < 0) return fail(Errc::io, spec.log_file.string() + ": " + std::strerror(errno));
    ::close(fd);
  }
  auto* program = new Program{std::move(spec), {}, {}, {}, back_off_.first, false};
  program->state.name = program->spec.name;
  // A program removed and started again (a changed command) goes back before the program that
  // followed it, when that one is still there: it keeps its place in states().
  auto place = programs_.end();
  if (auto v = vacated_.find(program->spec.name); v != vacated_.end()) {
    place = std::find_if(programs_.begin(), programs_.end(), [&](const Program* p) { return p->spec.name == v->second; });
    vacated_.erase(v);
  }
  programs_.insert(place, program);
  launch(*program);
  return {};
}

void Supervisor::launch(Program& program) {
  program.restart_at.reset();
  std::vector<std::string> argv = program.spec.argv;
  std::vector<char*> args;
  for (auto& a : argv) args.push_back(a.data());
  args.push_back(nullptr);
  // Built before fork: the child may only make async-signal-safe calls.
  const std::string exec_failed = "tahvel supervisor: " + program.spec.name + ": cannot run " + argv[0] + "\n";
  const pid_t supervisor = getpid();
  program.log_start = size_of(program.spec.log_file);
  // What the last run left in its group must not run beside the new run (two writers).
  if (program.group != 0) {
    kill(-program.group, SIGKILL);
    program.group = 0;
    program.group_kill_at.reset();
  }
  pid_t pid = fork();
  if (pid < 0) {
    log_("cannot start " + program.spec.name + ": fork: " + std::strerror(errno));
    program.restart_at = Clock::now() + program.delay;
    return;
  }
  if (pid == 0) {
    // In the child: only async-signal-safe calls until exec.
    setpgid(0, 0);
    // A clean start: `tahvel up` ignores SIGPIPE and blocks nothing a program should inherit
    // (a pipeline inside an agent would otherwise see EPIPE where it expects to die quietly).
    struct sigaction default_action {};
    default_action.sa_handler = SIG_DFL;
    sigemptyset(&default_action.sa_mask);
    sigaction(SIGPIPE, &default_action, nullptr);
    sigset_t none;
    sigemptyset(&none);
    sigprocmask(SIG_SETMASK, &none, nullptr);
    // A program does not outlive its supervisor: SIGKILLed with it, it would run on unsupervised,
    // `tahvel down` (which signals supervisors) would not stop it, and the supervisor started
    // again would run a second copy beside it (two links of one node, two writers). The signal
    // comes when the thread that forked ends, so programs are started from a thread that lives
    // as long as the supervisor (the main thread of `tahvel up`). If the supervisor already died
    // before prctl, the program does not start.
    prctl(PR_SET_PDEATHSIG, SIGKILL);
    if (getppid() != supervisor) _exit(1);
    if (!program.spec.log_file.empty()) {
      int fd = ::open(program.spec.log_file.c_str(), O_WRONLY | O_CREAT | O_APPEND, 0644);
      if (fd >= 0) {
        dup2(fd, 1);
        dup2(fd, 2);
        if (fd > 2) ::close(fd);
      }
    }
    if (!program.spec.out_file.empty()) {
      int fd = ::open(program.spec.out_file.c_str(), O_WRONLY | O_CREAT | O_APPEND, 0644);
      if (fd >= 0) {
        dup2(fd, 1);
        if (fd > 2) ::close(fd);
      }
    }
    // None of the supervisor's files: LMDB opens a store's data file without close-on-exec, and a
    // program restarted after the supervisor had opened the stores held every store of the
    // deployment open (a removed store's space stayed taken while it ran).
    if (close_range(3, ~0U, 0) != 0)
      for (int fd = 3; fd < 4096; ++fd) ::close(fd);
    // `up`'s check of an agent's flags (it stops before it works) is not for a program run here.
    unsetenv("TAHVEL_CHECK_ARGS");
    for (auto& [k, v] : program.spec.env) setenv(k.c_str(), v.c_str(), 1);
    execvp(args[0], args.data());
    (void)!write(2, exec_failed.data(), exec_failed.size());
    _exit(127);
  }
  setpgid(pid, pid);  // here too, so that a stop right after the fork reaches the group
  program.group = pid;
  program.state.pid = pid;
  program.state.running = true;
  program.started = Clock::now();
  log_("started " + program.spec.name + " (pid " + std::to_string(pid) + ")");
}

void Supervisor::reaped(Program& program, int status) {
  program.state.running = false;
  program.state.pid = 0;
  program.state.suspended = Suspension::none;
  program.state.last_exit = describe(status);
  if (WIFEXITED(status) && WEXITSTATUS(status) != 0) {
    if (std::string said = last_line_of(program.spec.log_file, program.log_start); !said.empty())
      program.state.last_exit += " (its log ends: " + said + ")";
  }
  program.state.exit_status = WIFEXITED(status) ? std::optional<int>(WEXITSTATUS(status)) : std::nullopt;
  if (program.group != 0 && group_has_live_members(program.group)) {
    term_and_cont(program.group);
    program.group_kill_at = Clock::now() + kGroupGrace;
  } else {
    program.group = 0;
  }
  const bool finished = WIFEXITED(status) && WEXITSTATUS(status) == 0;
  const Restart policy = program.spec.restart;
  if (program.stopping || policy == Restart::never || (policy == Restart::on_failure && finished)) {
    std::string why = program.stopping ? " (stopped)"
                      : policy == Restart::never ? " (not restarted: restart = never)"
                                                 : " (finished; restart = on-failure)";
    log_(program.spec.name + " " + program.state.last_exit + why);
    return;
  }
  if (Clock::now() - program.started >= back_off_.stable) program.delay = back_off_.first;
  program.restart_at = Clock::now() + program.delay;
  log_(program.spec.name + " " + program.state.last_exit + "; restarting in " +
       std::to_string(program.delay.count()) + " ms");
  const auto cap = program.spec.max_delay.count() > 0 ? std::min(program.spec.max_delay, back_off_.max) : back_off_.max;
  program.delay = std::min(program.delay * 2, cap);
}

void Supervisor::poll() {
  for (Program* p : programs_) {
    if (!p->state.running) continue;
    int status = 0;
    pid_t r = waitpid(p->state.pid, &status, WNOHANG);
    if (r == p->state.pid) {
      reaped(*p, status);
      continue;
    }
    // A program stopped with SIGSTOP (or held by a debugger) is alive and does nothing: shown
    // as "running" it hid why its node's link was down. Read from /proc rather than from
    // waitpid(WUNTRACED), which does not see a debugger's stops.
    const std::optional<char> now = node::process_state(p->state.pid);
    p->state.suspended = now == 'T' ? Suspension::signal : now == 't' ? Suspension::debugger : Suspension::none;
  }
  const auto now = Clock::now();
  for (Program* p : programs_) {
    if (p->state.running || p->group == 0 || !p->group_kill_at || now < *p->group_kill_at) continue;
    if (group_has_live_members(p->group)) kill(-p->group, SIGKILL);
    p->group = 0;
    p->group_kill_at.reset();
  }
  for (Program* p : programs_) {
    if (p->spec.log_limit == 0 || p->spec.log_file.empty() || now - p->log_checked < kLogCheckEvery) continue;
    p->log_checked = now;
    auto rotated = rotate_log(p->spec.log_file, p->spec.log_limit);
    if (!rotated) {
      log_(p->spec.name + ": " + rotated.error().message);
    } else if (*rotated) {
      p->log_start = 0;  // what the run wrote before is in the .1 file now
      log_(p->spec.name + ": its log passed " + std::to_string(p->spec.log_limit) + " bytes; what it held is " +
           p->spec.log_file.string() + ".1 now");
    }
  }
  for (Program* p : programs_) {
    if (!p->state.running && !p->stopping && p->restart_at && now >= *p->restart_at) {
      ++p->state.restarts;
      launch(*p);
    }
  }
}

Result<bool> Supervisor::set_restart(std::string_view name, Restart restart) {
  auto it = std::find_if(programs_.begin(), programs_.end(), [&](const Program* p) { return p->spec.name == name; });
  if (it == programs_.end()) return fail(Errc::not_found, "no program named '" + std::string(name) + "'");
  Program& p = **it;
  p.spec.restart = restart;
  if (p.state.running || p.stopping) return false;
  const bool finished = p.state.exit_status == 0;
  const bool wanted = restart == Restart::always || (restart == Restart::on_failure && !finished);
  if (!wanted) p.restart_at.reset();
  else if (!p.restart_at) p.restart_at = Clock::now();
  return wanted;
}

void Supervisor::stop_programs(const std::vector<Program*>& programs, std::chrono::milliseconds grace) {
  for (Program* p : programs) {
    p->stopping = true;
    p->restart_at.reset();
    if (p->state.running) term_and_cont(p->state.pid);
    else if (p->group != 0) term_and_cont(p->group);
  }
  const auto deadline = Clock::now() + grace;
  auto ticked = Clock::now();
  for (;;) {
    bool all_ended = true;
    for (Program* p : programs) {
      if (p->state.running) {
        int status = 0;
        if (waitpid(p->state.pid, &status, WNOHANG) == p->state.pid) reaped(*p, status);
        else all_ended = false;
      }
      if (!p->state.running && p->group != 0) {
        if (group_has_live_members(p->group)) {
          all_ended = false;
        } else {
          p->group = 0;
          p->group_kill_at.reset();
        }
      }
    }
    if (all_ended) return;
    if (Clock::now() >= deadline) break;
    if (while_waiting_ && Clock::now() - ticked >= std::chrono::milliseconds(100)) {
      while_waiting_();
      ticked = Clock::now();
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  for (Program* p : programs) {  // the grace is over
    if (p->state.running) {
      signal_group(p->state.pid, SIGKILL);
      int status = 0;
      waitpid(p->state.pid, &status, 0);
      reaped(*p, status);
    }
    if (p->group != 0) kill(-p->group, SIGKILL);
    p->group = 0;
    p->group_kill_at.reset();
  }
}

Result<void> Supervisor::stop(std::string_view name, std::chrono::milliseconds grace) {
  for (Program* p : programs_) {
    if (p->spec.name != name) continue;
    stop_programs({p}, grace);
    return {};
  }
  return fail(Errc::not_found, "no program named '" + std::string(name) + "'");
}

void Supervisor::stop(const std::vector<std::string>& names, std::chrono::milliseconds grace) {
  std::vector<Program*> stopping;
  for (Program* p : programs_)
    if (std::find(names.begin(), names.end(), p->spec.name) != names.end()) stopping.push_back(p);
  stop_programs(stopping, grace);
}

Result<void> Supervisor::remove(std::string_view name, std::chrono::milliseconds grace) {
  if (auto stopped = stop(name, grace); !stopped) return stopped;
  remove(std::vector<std::string>{std::string(name)}, std::chrono::milliseconds(0));
  return {};
}

void Supervisor::remove(const std::vector<std::string>& names, std::chrono::milliseconds grace) {
  std::vector<Program*> leaving;
  for (Program* p : programs_)
    if (std::find(names.begin(), names.end(), p->spec.name) != names.end()) leaving.push_back(p);
  stop_programs(leaving, grace);
  for (Program* gone : leaving) {
    auto it = std::find(programs_.begin(), programs_.end(), gone);
    // Its place goes to the first program after it that stays.
    auto next = std::find_if(std::next(it), programs_.end(),
                             [&](const Program* p) { return std::find(leaving.begin(), leaving.end(), p) == leaving.end(); });
    vacated_[gone->spec.name] = next == programs_.end() ? std::string() : (*next)->spec.name;
    programs_.erase(it);
    delete gone;
  }
}

Result<void> Supervisor::forget(std::string_view name) {
  if (auto removed = remove(name, std::chrono::milliseconds(0)); !removed) return removed;
  vacated_.erase(std::string(name));
  return {};
}

void Supervisor::stop_all(std::chrono::milliseconds grace) { stop_programs(programs_, grace); }

std::vector<ProgramState> Supervisor::states() const {
  std::vector<ProgramState> out;
  for (const Program* p : programs_) {
    out.push_back(p->state);
    out.back().restart_at = p->restart_at;
  }
  return out;
}

std::optional<ProgramState> Supervisor::state(std::string_view name) const {
  for (const Program* p : programs_)
    if (p->spec.name == name) {
      ProgramState s = p->state;
      s.restart_at = p->restart_at;
      return s;
    }
  return std::nullopt;
}

}  // namespace tahvel::agents

namespace tahvel::agents {

namespace {

// The parent of `pid` (/proc/PID/stat's fourth field), or 0.
pid_t parent_of(pid_t pid) {
  std::ifstream in("/proc/" + std::to_string(pid) + "/stat");
  std::string stat;
  std::getline(in, stat);
  const auto close = stat.rfind(')');  // the command may hold spaces and parentheses
  if (close == std::string::npos) return 0;
  std::istringstream rest(stat.substr(close + 1));
  char state = 0;
  long parent = 0;
  rest >> state >> parent;
  return static_cast<pid_t>(parent);
}

// Whether `pid` runs `tahvel up` (its first two arguments).
bool is_supervisor(pid_t pid) {
  std::ifstream in("/proc/" + std::to_string(pid) + "/cmdline", std::ios::binary);
  std::string program, command;
  std::getline(in, program, '\0');
  std::getline(in, command, '\0');
  return std::filesystem::path(program).filename() == "tahvel" && command == "up";
}

}  // namespace

std::vector<std::string> kill_leftovers(std::string_view mark) {
  const std::string wanted = std::string(kLeftoverMark) + "=" + std::string(mark);
  std::vector<std::string> killed;
  std::set<pid_t> signalled;
  // Twice: a leftover shell loop may fork again while the first pass reads /proc.
  for (int pass = 0; pass < 2; ++pass) {
    std::error_code ec;
    for (const auto& entry : std::filesystem::directory_iterator("/proc", ec)) {
      const std::string name = entry.path().filename().string();
      if (name.empty() || !std::all_of(name.begin(), name.end(), [](char c) { return c >= '0' && c <= '9'; })) continue;
      const pid_t pid = static_cast<pid_t>(std::stol(name));
      if (pid == getpid() || signalled.count(pid)) continue;
      std::ifstream in(entry.path() / "environ", std::ios::binary);  // unreadable for other users' processes
      bool marked = false;
      for (std::string variable; std::getline(in, variable, '\0');)
        if (variable == wanted) {
          marked = true;
          break;
        }
      if (!marked || node::process_state(pid) == 'Z') continue;
      // A parent that is another supervisor, alive (`tahvel up`: its programs die with it, and
      // this one holds the node's lock): it runs the node from a store directory removed or
      // moved since, and would start the program again. It stops itself within a second of
      // noticing; asked now, so that the node does not run twice meanwhile.
      if (const pid_t parent = parent_of(pid); parent > 1 && parent != getpid() && !signalled.count(parent) &&
                                              is_supervisor(parent) && kill(parent, SIGTERM) == 0) {
        signalled.insert(parent);
        killed.push_back(std::to_string(parent) + " (tahvel up, a supervisor still running them: asked to stop)");
      }
      if (kill(pid, SIGKILL) != 0) continue;
      signalled.insert(pid);
      std::ifstream comm(entry.path() / "comm");
      std::string command;
      std::getline(comm, command);
      killed.push_back(std::to_string(pid) + " (" + command + ")");
    }
  }
  return killed;
}

std::string_view program_state_name(const ProgramState& state) {
  if (state.running) return state.suspended == Suspension::none ? "running" : "suspended";
  return state.restart_at ? "restarting" : "stopped";
}

Result<node::Item> programs_item(const std::string& node_iri, const std::vector<ProgramState>& programs,
                                 std::int64_t now_ns) {
  using node::Term;
  node::Item item;
  item.persistent = true;  // a ring store must not reclaim what an operator reads the tree from
  const Term node = Term::iri(node_iri);
  item.add(node, Term::iri(vocab::kProgramsAt), Term::integer(now_ns));
  for (const ProgramState& p : programs) {
    // A name of several ids is a path below the node: the dispatcher's runs are
    // "behavior/<item>" (as one id, its '/' refused, every program's write failed while one ran).
    std::string iri = node_iri;
    for (std::size_t from = 0;;) {
      const std::size_t slash = std::min(p.name.find('/', from), p.name.size());
      auto below = uri::agent_iri(iri, std::string_view(p.name).substr(from, slash - from));
      if (!below) return fail(Errc::invalid_iri, "program '" + p.name + "' of <" + node_iri + ">: " + below.error().message);
      iri = *below;
      if (slash == p.name.size()) break;
      from = slash + 1;
    }
    const Term program = Term::iri(iri);
    item.add(node, Term::iri(vocab::kProgram), program);
    item.add(program, Term::iri(vocab::kProgramState), Term::literal(std::string(program_state_name(p))));
    if (p.running && p.pid > 0) item.add(program, Term::iri(vocab::kPid), Term::integer(p.pid));
    item.add(program, Term::iri(vocab::kRestarts), Term::integer(p.restarts));
    if (!p.last_exit.empty()) item.add(program, Term::iri(vocab::kLastExit), Term::literal(p.last_exit));
  }
  return item;
}

node::Item holdings_item(const std::string& node_iri, const std::vector<node::PredicateSummary>& held, std::int64_t now_ns) {
  using node::Term;
  node::Item item;
  item.persistent = true;  // as the programs: what an operator reads the tree from
  const Term node = Term::iri(node_iri);
  item.add(node, Term::iri(vocab::kHoldingsAt), Term::integer(now_ns));
  for (std::size_t k = 0; k < held.size(); ++k) {
    const Term h = Term::blank("h" + std::to_string(k));
    item.add(node, Term::iri(vocab::kHolds), h);
    item.add(h, Term::iri(vocab::kHeldPredicate), Term::iri(held[k].predicate));
    item.add(h, Term::iri(vocab::kHeldRecords), Term::integer(static_cast<std::int64_t>(held[k].records)));
    item.add(h, Term::iri(vocab::kFirstAssertedAt), Term::integer(held[k].first_asserted_at));
    item.add(h, Term::iri(vocab::kLastAssertedAt), Term::integer(held[k].last_asserted_at));
  }
  return item;
}

}  // namespace tahvel::agents
