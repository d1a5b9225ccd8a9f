#include "tahvel/agents/supervisor.h"

#include <fcntl.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cstring>
#include <fstream>
#include <iostream>
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

// SIGTERM, then SIGCONT: a program stopped with SIGSTOP would otherwise keep the SIGTERM
// pending until SIGKILL came at the end of the grace (systemd stops services the same way).
void term_and_cont(pid_t pid) {
  kill(pid, SIGTERM);
  kill(pid, SIGCONT);
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
  pid_t pid = fork();
  if (pid < 0) {
    log_("cannot start " + program.spec.name + ": fork: " + std::strerror(errno));
    program.restart_at = Clock::now() + program.delay;
    return;
  }
  if (pid == 0) {
    // In the child: only async-signal-safe calls until exec.
    setpgid(0, 0);
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
    for (auto& [k, v] : program.spec.env) setenv(k.c_str(), v.c_str(), 1);
    execvp(args[0], args.data());
    (void)!write(2, exec_failed.data(), exec_failed.size());
    _exit(127);
  }
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
    if (!p->state.running && !p->stopping && p->restart_at && now >= *p->restart_at) {
      ++p->state.restarts;
      launch(*p);
    }
  }
}

Result<void> Supervisor::stop(std::string_view name, std::chrono::milliseconds grace) {
  for (Program* p : programs_) {
    if (p->spec.name != name) continue;
    p->stopping = true;
    p->restart_at.reset();
    if (!p->state.running) return {};
    term_and_cont(p->state.pid);
    const auto deadline = Clock::now() + grace;
    for (;;) {
      int status = 0;
      pid_t r = waitpid(p->state.pid, &status, WNOHANG);
      if (r == p->state.pid) {
        reaped(*p, status);
        return {};
      }
      if (Clock::now() >= deadline) {
        kill(p->state.pid, SIGKILL);
        waitpid(p->state.pid, &status, 0);
        reaped(*p, status);
        return {};
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
  }
  return fail(Errc::not_found, "no program named '" + std::string(name) + "'");
}

Result<void> Supervisor::remove(std::string_view name, std::chrono::milliseconds grace) {
  if (auto stopped = stop(name, grace); !stopped) return stopped;
  for (auto it = programs_.begin(); it != programs_.end(); ++it) {
    if ((*it)->spec.name != name) continue;
    vacated_[std::string(name)] = std::next(it) == programs_.end() ? std::string() : (*std::next(it))->spec.name;
    delete *it;
    programs_.erase(it);
    break;
  }
  return {};
}

void Supervisor::stop_all(std::chrono::milliseconds grace) {
  for (Program* p : programs_) {
    p->stopping = true;
    p->restart_at.reset();
    if (p->state.running) term_and_cont(p->state.pid);
  }
  const auto deadline = Clock::now() + grace;
  for (Program* p : programs_) {
    while (p->state.running) {
      int status = 0;
      pid_t r = waitpid(p->state.pid, &status, WNOHANG);
      if (r == p->state.pid) {
        reaped(*p, status);
        break;
      }
      if (Clock::now() >= deadline) {
        kill(p->state.pid, SIGKILL);
        waitpid(p->state.pid, &status, 0);
        reaped(*p, status);
        break;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
  }
}

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
    auto iri = uri::agent_iri(node_iri, p.name);
    if (!iri) return fail(Errc::invalid_iri, "program '" + p.name + "' of <" + node_iri + ">: " + iri.error().message);
    const Term program = Term::iri(*iri);
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
