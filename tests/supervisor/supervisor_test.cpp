// The supervisor (agents/supervisor): which programs it starts again, with what back-off, and
// what it logs about each end. The programs are /bin/sh one-liners.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <string>
#include <thread>
#include <vector>

#include "tahvel/agents/supervisor.h"
#include "tahvel/node/process.h"
#include "temp_dir.h"

namespace tahvel::agents {
namespace {

using namespace std::chrono_literals;

class SupervisorTest : public ::testing::Test {
 protected:
  SupervisorTest()
      : supervisor_([this](std::string_view line) { log_.emplace_back(line); },
                    BackOff{.first = 20ms, .max = 80ms, .stable = 60s}) {}

  void start(const std::string& name, const std::string& script, Restart restart) {
    ProgramSpec spec;
    spec.name = name;
    spec.argv = {"/bin/sh", "-c", script};
    spec.restart = restart;
    ASSERT_TRUE(supervisor_.start(spec).has_value());
  }

  // Polls the supervisor until `done` holds or `limit` passes.
  bool poll_until(const std::function<bool()>& done, std::chrono::milliseconds limit = 5000ms) {
    const auto deadline = std::chrono::steady_clock::now() + limit;
    while (std::chrono::steady_clock::now() < deadline) {
      supervisor_.poll();
      if (done()) return true;
      std::this_thread::sleep_for(5ms);
    }
    return false;
  }

  // Polls for `span` and returns the program's state at the end.
  ProgramState after(const std::string& name, std::chrono::milliseconds span) {
    poll_until([] { return false; }, span);
    return *supervisor_.state(name);
  }

  // After 300 ms of polling: `name` ended with `status`, was not started again, and the log
  // says why (`why`, after the status).
  void expect_left_stopped(const std::string& name, int status, const std::string& why) {
    const ProgramState s = after(name, 300ms);
    EXPECT_FALSE(s.running);
    EXPECT_EQ(s.restarts, 0u);
    EXPECT_EQ(s.exit_status, status);
    EXPECT_TRUE(logged(name + " exited with status " + std::to_string(status) + " " + why));
  }

  bool logged(const std::string& text) const {
    for (const auto& line : log_)
      if (line.find(text) != std::string::npos) return true;
    return false;
  }

  std::vector<std::string> log_;
  Supervisor supervisor_;
};

TEST_F(SupervisorTest, AProgramThatFinishesWithStatusZeroStaysStopped) {
  start("replay", "exit 0", Restart::on_failure);
  expect_left_stopped("replay", 0, "(finished; restart = on-failure)");
}

// A program gets none of the supervisor's files, also those it opened without close-on-exec
// (LMDB's data file of every store: a restarted agent held the whole deployment's stores open).
TEST_F(SupervisorTest, AProgramInheritsNoFileTheSupervisorHasOpen) {
  const int fd = ::open("/dev/null", O_RDONLY);  // no O_CLOEXEC, as LMDB opens a data file
  ASSERT_GE(fd, 3);
  start("agent", "[ -e /proc/$$/fd/" + std::to_string(fd) + " ] && exit 7; exit 0", Restart::on_failure);
  expect_left_stopped("agent", 0, "(finished; restart = on-failure)");
  ::close(fd);
}

TEST_F(SupervisorTest, AProgramThatFailsIsStartedAgainWithBackOffAndTheLogSaysWhy) {
  start("agent", "exit 3", Restart::on_failure);
  ASSERT_TRUE(poll_until([&] { return supervisor_.state("agent")->restarts >= 3; }));
  EXPECT_TRUE(logged("agent exited with status 3; restarting in 20 ms"));
  EXPECT_TRUE(logged("agent exited with status 3; restarting in 40 ms"));  // doubled
  EXPECT_TRUE(logged("agent exited with status 3; restarting in 80 ms"));  // up to the cap
}

// A program may cap its own back-off below the supervisor's (a node's link: all else waits for it).
TEST_F(SupervisorTest, AProgramsOwnBackOffCapHoldsBelowTheSupervisors) {
  ASSERT_TRUE(supervisor_.start({.name = "link", .argv = {"/bin/sh", "-c", "exit 3"}, .restart = Restart::always,
                                 .max_delay = 40ms}).has_value());
  ASSERT_TRUE(poll_until([&] { return supervisor_.state("link")->restarts >= 4; }));
  EXPECT_TRUE(logged("link exited with status 3; restarting in 20 ms"));
  EXPECT_TRUE(logged("link exited with status 3; restarting in 40 ms"));
  EXPECT_FALSE(logged("link exited with status 3; restarting in 80 ms"));
}

// A program that fails most often says why as it goes: the last line of its log goes with its
// exit (to `status`, and through the board to the machines above), cut to a line's length.
TEST_F(SupervisorTest, AFailedProgramsLastExitEndsWithTheLastLineOfItsLog) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / ("tahvel-sup-" + std::to_string(getpid()));
  std::filesystem::create_directories(dir);
  auto run_to_end = [&](const std::string& name, const std::string& script) {
    EXPECT_TRUE(supervisor_.start({.name = name, .argv = {"/bin/sh", "-c", script}, .log_file = dir / (name + ".log"),
                                   .restart = Restart::never}).has_value());
    EXPECT_TRUE(poll_until([&] { return !supervisor_.state(name)->running && supervisor_.state(name)->pid == 0; }));
    return supervisor_.state(name)->last_exit;
  };
  EXPECT_EQ(run_to_end("bad-flag", "echo starting; echo \"tahvel-hrv: unknown flag '--windw'\" >&2; echo; exit 2"),
            "exited with status 2 (its log ends: tahvel-hrv: unknown flag '--windw')");
  const std::string said = run_to_end("long", "printf 'x%.0s' $(seq 300) >&2; exit 1");
  EXPECT_EQ(said, "exited with status 1 (its log ends: " + std::string(240, 'x') + "...)");
  EXPECT_EQ(run_to_end("silent", "exit 4"), "exited with status 4");
  EXPECT_EQ(run_to_end("fine", "echo all done; exit 0"), "exited with status 0");  // not a failure
  EXPECT_EQ(run_to_end("tabs", "printf 'a\\tb\\n' >&2; exit 1"), "exited with status 1 (its log ends: a b)");
  // Cut at a character, not inside one: 239 bytes and a 2-byte "é" that would end at 241.
  EXPECT_EQ(run_to_end("accents", "printf '%239s\\303\\251tail' x >&2; exit 1"),
            "exited with status 1 (its log ends: " + std::string(238, ' ') + "x...)");
  // Bytes that are not UTF-8 (a binary dump, Latin-1 text) go on the board and onto a terminal as
  // U+FFFD; an escape sequence's ESC as a space.
  EXPECT_EQ(run_to_end("latin1", "printf 'caf\\351 \\377\\033[2J ok\\n' >&2; exit 1"),
            "exited with status 1 (its log ends: caf\xEF\xBF\xBD \xEF\xBF\xBD [2J ok)");
  // Each run appends to the same log: a run that wrote nothing has nothing to say, not the line
  // of a run before it.
  std::ofstream(dir / "quiet.log") << "connected to the hospital\n";
  EXPECT_EQ(run_to_end("quiet", "exit 5"), "exited with status 5");
  std::filesystem::remove_all(dir);
}

// The same with the programs `tahvel up` runs: a mistyped flag shows, with the exit, as the
// error naming it. The agents used to print their usage after the error, and the supervisor
// showed the usage line.
TEST_F(SupervisorTest, ABundledProgramGivenAnUnknownFlagEndsItsLogWithTheErrorNamingTheFlag) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / ("tahvel-sup-bad-flag-" + std::to_string(getpid()));
  std::filesystem::create_directories(dir);
  const std::string bin = TAHVEL_BIN_DIR, store = (dir / "store").string();
  std::vector<std::pair<std::vector<std::string>, std::string>> cases = {  // argv, the end of the last line
      {{bin + "/tahvel", "link", store, "--windw", "300"}, "tahvel: link: unknown flag '--windw' (see 'tahvel link --help')"},
      {{bin + "/example_agent", store, "--windw", "300"}, "example_agent: bad argument '--windw'"},
      {{bin + "/example_agent_cpp", store, "--windw", "300"}, "example_agent_cpp: bad argument '--windw'"},
  };
  // Built with the signal processing and the spatial libraries (tests/CMakeLists.txt).
  for (const std::string name : {"tahvel-ecg-source", "tahvel-rpeak", "tahvel-rr", "tahvel-hrv", "tahvel-trend",
                                 "tahvel-environment", "tahvel-env-motes"})
    if (std::filesystem::exists(bin + "/" + name)) cases.push_back({{bin + "/" + name, store, "--windw", "300"}, name + ": unknown flag '--windw'"});
  for (const auto& [argv, said] : cases) {
    const std::string name = std::filesystem::path(argv[0]).filename().string();
    ASSERT_TRUE(supervisor_.start({.name = name, .argv = argv, .log_file = dir / (name + ".log"), .restart = Restart::never}).has_value());
    ASSERT_TRUE(poll_until([&] { return !supervisor_.state(name)->running; })) << name;
    const std::string last_exit = supervisor_.state(name)->last_exit;
    EXPECT_TRUE(last_exit.starts_with("exited with status 2 (its log ends: ")) << last_exit;
    EXPECT_TRUE(last_exit.ends_with(said + ")")) << last_exit;
  }
  std::filesystem::remove_all(dir);
}

// `tahvel status` shows a program waiting out its back-off as restarting, with when, rather than
// as stopped; one that finished has no restart time.
TEST_F(SupervisorTest, AProgramWaitingOutItsBackOffSaysWhenItStartsAgain) {
  Supervisor slow([](std::string_view) {}, BackOff{.first = 10s, .max = 10s, .stable = 60s});
  ASSERT_TRUE(slow.start({.name = "agent", .argv = {"/bin/sh", "-c", "exit 3"}}).has_value());
  ASSERT_TRUE(slow.start({.name = "replay", .argv = {"/bin/sh", "-c", "exit 0"}}).has_value());
  const auto deadline = std::chrono::steady_clock::now() + 5s;
  while ((slow.state("agent")->running || slow.state("replay")->running) && std::chrono::steady_clock::now() < deadline) {
    slow.poll();
    std::this_thread::sleep_for(5ms);
  }
  const ProgramState agent = *slow.state("agent");
  ASSERT_FALSE(agent.running);
  ASSERT_TRUE(agent.restart_at.has_value());
  const auto wait = *agent.restart_at - std::chrono::steady_clock::now();
  EXPECT_GT(wait, 5s);
  EXPECT_LE(wait, 10s);
  EXPECT_FALSE(slow.state("replay")->restart_at.has_value());
  ASSERT_TRUE(slow.stop("agent").has_value());
  EXPECT_FALSE(slow.state("agent")->restart_at.has_value());
}

TEST_F(SupervisorTest, AProgramKilledByASignalIsStartedAgainAndTheLogNamesTheSignal) {
  start("agent", "kill -9 $$", Restart::on_failure);
  ASSERT_TRUE(poll_until([&] { return supervisor_.state("agent")->restarts >= 1; }));
  EXPECT_TRUE(logged("agent killed by signal 9"));
}

TEST_F(SupervisorTest, RestartAlwaysStartsAProgramAgainAfterStatusZero) {
  start("loop", "exit 0", Restart::always);
  ASSERT_TRUE(poll_until([&] { return supervisor_.state("loop")->restarts >= 2; }));
  EXPECT_TRUE(logged("loop exited with status 0; restarting in"));
}

TEST_F(SupervisorTest, RestartNeverLeavesAFailedProgramStopped) {
  start("behaviour", "exit 1", Restart::never);
  expect_left_stopped("behaviour", 1, "(not restarted: restart = never)");
}

TEST_F(SupervisorTest, AStoppedProgramIsNotStartedAgain) {
  start("agent", "sleep 30", Restart::always);
  ASSERT_TRUE(poll_until([&] { return supervisor_.state("agent")->running; }));
  ASSERT_TRUE(supervisor_.stop("agent", 2000ms).has_value());
  const ProgramState s = after("agent", 200ms);
  EXPECT_FALSE(s.running);
  EXPECT_EQ(s.restarts, 0u);
  EXPECT_TRUE(logged("agent killed by signal 15"));
  EXPECT_TRUE(logged("(stopped)"));
}

// A program stopped with SIGSTOP is alive and does nothing (a node's link: its parent says it is
// down): it is suspended, not running, until SIGCONT. Stopped while so, it gets SIGCONT after
// SIGTERM and ends by the SIGTERM, not by the SIGKILL at the end of the grace.
TEST_F(SupervisorTest, AProgramStoppedWithSigstopIsSuspendedUntilSigcontAndStopsOnSigterm) {
  start("link", "exec sleep 600", Restart::always);
  ASSERT_TRUE(poll_until([&] { return supervisor_.state("link")->running; }));
  const pid_t pid = supervisor_.state("link")->pid;
  ASSERT_EQ(kill(pid, SIGSTOP), 0);
  ASSERT_TRUE(poll_until([&] { return supervisor_.state("link")->suspended == Suspension::signal; }));
  EXPECT_TRUE(supervisor_.state("link")->running);
  EXPECT_EQ(program_state_name(*supervisor_.state("link")), "suspended");
  ASSERT_EQ(kill(pid, SIGCONT), 0);
  ASSERT_TRUE(poll_until([&] { return supervisor_.state("link")->suspended == Suspension::none; }));
  EXPECT_EQ(program_state_name(*supervisor_.state("link")), "running");
  EXPECT_EQ(supervisor_.state("link")->pid, pid);
  ASSERT_EQ(kill(pid, SIGSTOP), 0);
  ASSERT_TRUE(poll_until([&] { return supervisor_.state("link")->suspended == Suspension::signal; }));
  ASSERT_TRUE(supervisor_.stop("link", 30s).has_value());
  EXPECT_EQ(supervisor_.state("link")->last_exit, "killed by signal 15 (Terminated)");
  EXPECT_EQ(supervisor_.state("link")->suspended, Suspension::none);
}

TEST_F(SupervisorTest, AProgramThatCannotBeRunExitsWithStatus127) {
  ProgramSpec spec;
  spec.name = "missing";
  spec.argv = {"/nonexistent/tahvel-agent"};
  spec.restart = Restart::never;
  ASSERT_TRUE(supervisor_.start(spec).has_value());
  ASSERT_TRUE(poll_until([&] { return !supervisor_.state("missing")->running; }));
  EXPECT_EQ(supervisor_.state("missing")->exit_status, 127);
}

TEST_F(SupervisorTest, TwoProgramsOfOneNameAreRefused) {
  start("agent", "sleep 30", Restart::on_failure);
  ProgramSpec again;
  again.name = "agent";
  again.argv = {"/bin/true"};
  auto second = supervisor_.start(again);
  ASSERT_FALSE(second.has_value());
  EXPECT_EQ(second.error().code, node::Errc::exists);
}

// `tahvel up` applying a changed file replaces a program whose command changed: the old one
// stops and is forgotten, and one of the same name starts with the new command.
TEST_F(SupervisorTest, ARemovedProgramIsStoppedAndForgottenAndItsNameCanBeStartedAgain) {
  start("agent", "sleep 30", Restart::always);
  ASSERT_TRUE(poll_until([&] { return supervisor_.state("agent")->running; }));
  const pid_t old_pid = supervisor_.state("agent")->pid;
  ASSERT_TRUE(supervisor_.remove("agent", 2000ms).has_value());
  EXPECT_FALSE(supervisor_.state("agent").has_value());
  EXPECT_TRUE(supervisor_.states().empty());
  EXPECT_NE(kill(old_pid, 0), 0) << "the removed program still runs";
  start("agent", "sleep 31", Restart::always);
  ASSERT_TRUE(poll_until([&] { return supervisor_.state("agent")->running; }));
  EXPECT_NE(supervisor_.state("agent")->pid, old_pid);
  EXPECT_EQ(supervisor_.remove("nobody").error().code, node::Errc::not_found);
}

// `up` applies a changed command by removing the program and starting it again: it stays where
// it was in states(), and so in `tahvel status`, instead of moving to the end of its node.
TEST_F(SupervisorTest, AProgramRemovedAndStartedAgainKeepsItsPlace) {
  for (const char* name : {"link", "ecg", "hrv", "rr"}) start(name, "sleep 30", Restart::always);
  auto names = [&] {
    std::vector<std::string> out;
    for (const auto& s : supervisor_.states()) out.push_back(s.name);
    return out;
  };
  ASSERT_TRUE(supervisor_.remove("ecg", 2000ms).has_value());
  start("ecg", "sleep 31", Restart::always);
  start("trend", "sleep 30", Restart::always);
  EXPECT_EQ(names(), (std::vector<std::string>{"link", "ecg", "hrv", "rr", "trend"}));
  // Two removed before either starts again: each goes back before its old successor.
  ASSERT_TRUE(supervisor_.remove("ecg", 2000ms).has_value());
  ASSERT_TRUE(supervisor_.remove("rr", 2000ms).has_value());
  start("ecg", "sleep 32", Restart::always);
  start("rr", "sleep 32", Restart::always);
  EXPECT_EQ(names(), (std::vector<std::string>{"link", "ecg", "hrv", "rr", "trend"}));
}

// A supervisor SIGKILLed (a crash) takes its programs with it: none runs on unsupervised, beside
// the copy a restarted supervisor would start. (Found with the chaos tests: a killed supervisor
// left its programs running after `tahvel down`.)
TEST(SupervisorDeath, ProgramsDieWithAKilledSupervisor) {
  int pipe_fds[2];
  ASSERT_EQ(pipe(pipe_fds), 0);
  pid_t helper = fork();
  if (helper == 0) {  // the supervisor's process
    close(pipe_fds[0]);
    Supervisor supervisor([](std::string_view) {});
    ProgramSpec spec;
    spec.name = "idle";
    spec.argv = {"/bin/sleep", "600"};
    if (!supervisor.start(spec)) _exit(1);
    const pid_t program = supervisor.state("idle")->pid;
    if (write(pipe_fds[1], &program, sizeof program) != sizeof program) _exit(1);
    for (;;) pause();
  }
  close(pipe_fds[1]);
  pid_t program = 0;
  ASSERT_EQ(read(pipe_fds[0], &program, sizeof program), static_cast<ssize_t>(sizeof program));
  close(pipe_fds[0]);
  ASSERT_GT(program, 0);
  EXPECT_EQ(kill(program, 0), 0) << "the program should run";
  kill(helper, SIGKILL);
  waitpid(helper, nullptr, 0);
  // The program is reparented and reaped by init; it must be gone within a few seconds.
  bool gone = false;
  for (int i = 0; i < 500 && !gone; ++i) {
    gone = kill(program, 0) != 0;
    if (!gone) {
      // A zombie still answers kill(0); its /proc state says Z.
      FILE* f = fopen(("/proc/" + std::to_string(program) + "/stat").c_str(), "r");
      char state = '?';
      if (f) {
        (void)!fscanf(f, "%*d %*s %c", &state);
        fclose(f);
      }
      gone = state == 'Z';
      if (!gone) std::this_thread::sleep_for(10ms);
    }
  }
  EXPECT_TRUE(gone) << "the program of a killed supervisor is still running";
  if (!gone) kill(program, SIGKILL);
}

// Whether `item` holds the triple (s, p, o), terms by their values.
bool holds(const node::Item& item, const std::string& s, const std::string& p, const std::string& o) {
  return std::any_of(item.triples.begin(), item.triples.end(),
                     [&](const node::Triple& t) { return t.s.value == s && t.p.value == p && t.o.value == o; });
}

// What a machine above reads of a node's programs (tahvel status, docs/deploy.md): each program
// under its agent IRI, with the state, pid, restarts and last exit the supervisor knows.
TEST(ProgramsOnTheBoard, EachProgramIsNamedByItsAgentIriWithWhatItsSupervisorKnows) {
  ProgramState link{.name = "link", .pid = 4711, .running = true};
  ProgramState flaky{.name = "flaky", .restarts = 2, .last_exit = "exited with status 3",
                     .restart_at = std::chrono::steady_clock::now() + 1s};
  ProgramState replay{.name = "replay", .restarts = 0, .last_exit = "exited with status 0"};
  ProgramState frozen{.name = "hrv", .pid = 4712, .running = true, .suspended = Suspension::signal};
  auto item = programs_item("http://h/home1", {link, flaky, replay, frozen}, 1234);
  ASSERT_TRUE(item.has_value()) << item.error().message;
  EXPECT_TRUE(item->persistent);
  auto has = [&](const std::string& s, const std::string& p, const std::string& o) { return holds(*item, s, p, o); };
  EXPECT_TRUE(has("http://h/home1", vocab::kProgramsAt, "1234"));
  EXPECT_TRUE(has("http://h/home1", vocab::kProgram, "http://h/home1/link"));
  EXPECT_TRUE(has("http://h/home1/link", vocab::kProgramState, "running"));
  EXPECT_TRUE(has("http://h/home1/link", vocab::kPid, "4711"));
  EXPECT_TRUE(has("http://h/home1/flaky", vocab::kProgramState, "restarting"));
  EXPECT_TRUE(has("http://h/home1/flaky", vocab::kRestarts, "2"));
  EXPECT_TRUE(has("http://h/home1/flaky", vocab::kLastExit, "exited with status 3"));
  EXPECT_TRUE(has("http://h/home1/replay", vocab::kProgramState, "stopped"));
  EXPECT_TRUE(has("http://h/home1/hrv", vocab::kProgramState, "suspended"));  // alive, with its pid
  EXPECT_TRUE(has("http://h/home1/hrv", vocab::kPid, "4712"));
  for (const auto& t : item->triples) EXPECT_FALSE(t.s.value == "http://h/home1/flaky" && t.p.value == vocab::kPid);

  auto bad = programs_item("http://h/home1", {ProgramState{.name = "a b"}}, 1);
  ASSERT_FALSE(bad.has_value());
  EXPECT_NE(bad.error().message.find("program 'a b' of <http://h/home1>"), std::string::npos) << bad.error().message;
  for (const char* name : {"behavior/", "/x", "behavior//17"})
    EXPECT_FALSE(programs_item("http://h/home1", {ProgramState{.name = name}}, 1).has_value()) << name;
}

// A dispatcher's run is the program "behavior/<item>": as one id its '/' was refused, and while
// any behaviour ran the supervisor wrote none of the node's programs, nor its holdings, to the
// board (a remote status showed them stale; an exploratory run of session 81). Its IRI is the
// path below the node.
TEST(ProgramsOnTheBoard, ARunOfADispatchedBehaviourIsAPathBelowTheNode) {
  ProgramState run{.name = "behavior/17", .pid = 4713, .running = true};
  ProgramState link{.name = "link", .pid = 4711, .running = true};
  auto item = programs_item("http://h/ward", {link, run}, 1);
  ASSERT_TRUE(item.has_value()) << item.error().message;
  auto has = [&](const std::string& s, const std::string& p, const std::string& o) { return holds(*item, s, p, o); };
  EXPECT_TRUE(has("http://h/ward", vocab::kProgram, "http://h/ward/behavior/17"));
  EXPECT_TRUE(has("http://h/ward/behavior/17", vocab::kPid, "4713"));
  EXPECT_TRUE(has("http://h/ward", vocab::kProgram, "http://h/ward/link"));
}

// Beside the programs, what the node's store holds: one blank node per predicate under the
// node's IRI, so that `stats --at` reads them with one query (cascade 1).
TEST(ProgramsOnTheBoard, HoldingsAreOneNodePerPredicateWithItsRecordsAndTimeRange) {
  node::Item item = holdings_item("http://h/home1",
                                  {{.predicate = "http://h/v#samples", .records = 86400, .first_asserted_at = 10, .last_asserted_at = 20},
                                   {.predicate = "http://h/v#lead", .records = 1, .first_asserted_at = 5, .last_asserted_at = 5}},
                                  1234);
  EXPECT_TRUE(item.persistent);
  std::map<std::string, std::map<std::string, std::string>> holding;  // by blank label: predicate -> object
  int holds = 0;
  for (const auto& t : item.triples) {
    if (t.s.value == "http://h/home1") {
      if (t.p.value == vocab::kHoldingsAt) EXPECT_EQ(t.o.value, "1234");
      else if (t.p.value == vocab::kHolds && t.o.is_blank()) ++holds;
      else ADD_FAILURE() << "unexpected " << t.p.value;
    } else {
      ASSERT_TRUE(t.s.is_blank()) << t.s.value;
      holding[t.s.value][t.p.value] = t.o.value;
    }
  }
  EXPECT_EQ(holds, 2);
  ASSERT_EQ(holding.size(), 2u);
  bool samples = false;
  for (auto& [label, h] : holding) {
    if (h[vocab::kHeldPredicate] != "http://h/v#samples") continue;
    samples = true;
    EXPECT_EQ(h[vocab::kHeldRecords], "86400");
    EXPECT_EQ(h[vocab::kFirstAssertedAt], "10");
    EXPECT_EQ(h[vocab::kLastAssertedAt], "20");
  }
  EXPECT_TRUE(samples);
}


// ---- what a program starts, and how it starts ----------------------------------------------

// The pid a program's script wrote to `file`, once it has.
pid_t pid_written_to(const std::filesystem::path& file) {
  std::ifstream in(file);
  pid_t pid = 0;
  in >> pid;
  return pid;
}

// No process `pid` runs now (gone, or a zombie waiting for whoever adopted it to reap it).
bool gone(pid_t pid) {
  const auto state = node::process_state(pid);
  return !state || *state == 'Z';
}

TEST_F(SupervisorTest, StoppingAProgramStopsWhatItStartedToo) {
  test_support::TempDir dir("tahvel-sup-group");
  start("wrapper", "sleep 1001 & echo $! > " + (dir / "child").string() + "; wait", Restart::on_failure);
  pid_t child = 0;
  ASSERT_TRUE(poll_until([&] { return (child = pid_written_to(dir / "child")) > 0; }));
  ASSERT_TRUE(supervisor_.stop("wrapper").has_value());
  EXPECT_TRUE(gone(child)) << "the wrapper's child " << child << " outlived the stop";
}

TEST_F(SupervisorTest, WhatAProgramLeftRunningWhenItDiedIsStoppedAndDoesNotRunBesideItsNextRun) {
  test_support::TempDir dir("tahvel-sup-left");
  // Each run leaves a child behind and fails; the next run must not find the last one's child.
  start("leaver", "sleep 1002 & echo $! >> " + (dir / "children").string() + "; exit 1", Restart::on_failure);
  ASSERT_TRUE(poll_until([&] { return supervisor_.state("leaver")->restarts >= 2; }));
  std::ifstream in(dir / "children");
  std::vector<pid_t> children;
  for (pid_t pid; in >> pid;) children.push_back(pid);
  ASSERT_GE(children.size(), 2u);
  for (std::size_t k = 0; k + 1 < children.size(); ++k)
    EXPECT_TRUE(poll_until([&] { return gone(children[k]); }, 1000ms)) << "run " << k << " left " << children[k] << " running";
  ASSERT_TRUE(supervisor_.stop("leaver").has_value());
  EXPECT_TRUE(gone(children.back()));
}

TEST_F(SupervisorTest, ProgramsStartWithSigpipeAtItsDefaultWhateverTheSupervisorIgnores) {
  test_support::TempDir dir("tahvel-sup-sigpipe");
  struct sigaction ignore {}, before {};
  ignore.sa_handler = SIG_IGN;
  sigaction(SIGPIPE, &ignore, &before);  // as `tahvel up` does
  start("reader", "grep SigIgn /proc/self/status > " + (dir / "sigign").string(), Restart::never);
  sigaction(SIGPIPE, &before, nullptr);
  ASSERT_TRUE(poll_until([&] { return !supervisor_.state("reader")->running; }));
  std::ifstream in(dir / "sigign");
  std::string label, mask;
  ASSERT_TRUE(in >> label >> mask);
  EXPECT_EQ(std::stoull(mask, nullptr, 16) & (1ull << (SIGPIPE - 1)), 0u) << "SigIgn " << mask;
}

TEST_F(SupervisorTest, WaitingForProgramsToStopCallsTheWaitingHook) {
  int ticks = 0;
  supervisor_.while_waiting([&] { ++ticks; });
  start("stubborn1", "trap '' TERM; sleep 1003", Restart::on_failure);
  start("stubborn2", "trap '' TERM; sleep 1003", Restart::on_failure);
  poll_until([] { return false; }, 200ms);  // the traps are set
  supervisor_.remove(std::vector<std::string>{"stubborn1", "stubborn2"}, 600ms);
  EXPECT_FALSE(supervisor_.state("stubborn1"));
  EXPECT_FALSE(supervisor_.state("stubborn2"));
  EXPECT_GE(ticks, 2) << "the hook was not called while the grace ran";
}

TEST(KillLeftovers, KillsTheProcessesCarryingTheMarkAndNoOther) {
  auto spawn_marked = [](const std::string& mark) {
    pid_t pid = fork();
    if (pid == 0) {
      setenv(std::string(kLeftoverMark).c_str(), mark.c_str(), 1);
      execl("/bin/sleep", "sleep", "1004", static_cast<char*>(nullptr));
      _exit(127);
    }
    return pid;
  };
  const std::string mine = "/tmp/tahvel-leftover-test-" + std::to_string(getpid());
  const pid_t marked = spawn_marked(mine), other = spawn_marked(mine + "-other");
  ASSERT_GT(marked, 0);
  ASSERT_GT(other, 0);
  // Until the child has exec'd, /proc shows the test's environment.
  for (int k = 0; k < 200; ++k) {
    std::ifstream comm("/proc/" + std::to_string(marked) + "/comm"), comm2("/proc/" + std::to_string(other) + "/comm");
    std::string a, b;
    std::getline(comm, a);
    std::getline(comm2, b);
    if (a == "sleep" && b == "sleep") break;
    std::this_thread::sleep_for(10ms);
  }
  const auto killed = kill_leftovers(mine);
  ASSERT_EQ(killed.size(), 1u);
  EXPECT_EQ(killed[0], std::to_string(marked) + " (sleep)");
  int status = 0;
  ASSERT_EQ(waitpid(marked, &status, 0), marked);
  EXPECT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL);
  EXPECT_EQ(waitpid(other, &status, WNOHANG), 0) << "a process with another mark was killed";
  kill(other, SIGKILL);
  waitpid(other, &status, 0);
}

std::string contents(const std::filesystem::path& file) {
  std::ifstream in(file, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

// A new restart policy takes effect without a stop: a program that finished starts under
// "always", and one waiting out its back-off stays stopped under "never".
TEST_F(SupervisorTest, ANewRestartPolicyAppliesWithoutStoppingTheProgram) {
  start("runs", "sleep 1001", Restart::on_failure);
  const pid_t pid = supervisor_.state("runs")->pid;
  EXPECT_EQ(supervisor_.set_restart("runs", Restart::always).value(), false) << "a running program does not start again";
  EXPECT_EQ(after("runs", 100ms).pid, pid) << "the running program was stopped";

  start("done", "exit 0", Restart::on_failure);
  ASSERT_TRUE(poll_until([&] { return !supervisor_.state("done")->running; }));
  EXPECT_EQ(after("done", 100ms).restarts, 0u);
  EXPECT_EQ(supervisor_.set_restart("done", Restart::always).value(), true) << "says that it starts";
  EXPECT_TRUE(poll_until([&] { return supervisor_.state("done")->restarts >= 1; })) << "a finished program did not start under always";

  start("fails", "exit 3", Restart::on_failure);
  ASSERT_TRUE(poll_until([&] { return supervisor_.state("fails")->restart_at.has_value(); }));
  EXPECT_EQ(supervisor_.set_restart("fails", Restart::never).value(), false);
  const ProgramState left = after("fails", 300ms);
  EXPECT_FALSE(left.running);
  EXPECT_FALSE(left.restart_at) << "still waiting to start again under never";
  EXPECT_FALSE(supervisor_.set_restart("nothing", Restart::never).has_value());
}

// A log over its limit moves to `.1` whole and starts again empty, and a writer that holds it
// open (with O_APPEND, as a program's stdout) writes on at its start, not at its old end.
TEST(RotateLog, ALogOverItsLimitMovesToDotOneAndItsWriterWritesOnAtTheStart) {
  test_support::TempDir dir("tahvel-rotate");
  const auto log = dir / "hrv.log";
  const int fd = ::open(log.c_str(), O_WRONLY | O_CREAT | O_APPEND, 0644);
  ASSERT_GE(fd, 0);
  const std::string first(3000, 'a');
  ASSERT_EQ(write(fd, first.data(), first.size()), static_cast<ssize_t>(first.size()));
  EXPECT_FALSE(*rotate_log(log, 4096)) << "rotated a log under its limit";
  EXPECT_EQ(contents(log), first);
  ASSERT_EQ(write(fd, first.data(), first.size()), static_cast<ssize_t>(first.size()));
  ASSERT_TRUE(*rotate_log(log, 4096));
  EXPECT_EQ(contents(dir / "hrv.log.1"), first + first);
  EXPECT_EQ(contents(log), "");
  ASSERT_EQ(write(fd, "after\n", 6), 6);
  EXPECT_EQ(contents(log), "after\n") << "the writer did not go on at the start";
  // The next rotation replaces the .1 of the one before.
  const std::string second(5000, 'b');
  ASSERT_EQ(write(fd, second.data(), second.size()), static_cast<ssize_t>(second.size()));
  ASSERT_TRUE(*rotate_log(log, 4096));
  EXPECT_EQ(contents(dir / "hrv.log.1"), "after\n" + second);
  ::close(fd);
  EXPECT_FALSE(*rotate_log(dir / "none.log", 4096)) << "a log not there is nothing to rotate";
  EXPECT_FALSE(std::filesystem::exists(dir / "hrv.log.1.tmp"));
}

// A program that writes without end (a crash loop's messages, a chatty agent over months) keeps
// its log within the limit the supervisor was given, and the supervisor says when it rotated.
TEST_F(SupervisorTest, AProgramsLogIsKeptWithinItsLimit) {
  test_support::TempDir dir("tahvel-sup-log");
  const auto log = dir / "chatty.log";
  ASSERT_TRUE(supervisor_.start({.name = "chatty", .argv = {"/bin/sh", "-c", "while :; do echo 0123456789abcdef; done"},
                                 .log_file = log, .restart = Restart::never, .log_limit = 64 * 1024}).has_value());
  EXPECT_TRUE(poll_until([&] { return std::filesystem::exists(dir / "chatty.log.1"); }, 10s)) << "never rotated";
  poll_until([] { return false; }, 2500ms);  // more checks while it writes on
  ASSERT_TRUE(supervisor_.stop("chatty").has_value());
  // Checked once a second: what it wrote in a second past the limit, at most.
  EXPECT_GE(std::filesystem::file_size(dir / "chatty.log.1"), 64u * 1024);
  std::size_t rotations = 0;
  for (const auto& line : log_) rotations += line.find("chatty: its log passed 65536 bytes") != std::string::npos;
  EXPECT_GE(rotations, 2u) << "the supervisor did not rotate it again, or did not say so";
  const std::string rest = contents(log);
  EXPECT_EQ(rest.find_first_not_of("0123456789abcdef\n"), std::string::npos) << "the log holds something else";
}

}  // namespace
}  // namespace tahvel::agents
