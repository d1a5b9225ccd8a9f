// Seeded, randomized failure schedules over a real hierarchy under `tahvel up` (hospital; two
// homes over Cyclone DDS; a sensor node below each home over LCM; one supervisor per node, as on
// separate machines), each case in its own network namespace. A load agent on every sensor and home node writes numbered items (load_writer.cpp)
// that the forwarding policies send all the way up, while a random schedule of faults hits the
// programs the supervisor runs:
//
//   kill-node     SIGKILL every program of a node (sensor, home or the hospital); its
//                 supervisor starts them again with back-off (0.5 s doubling)
//   crash-node    the node's machine goes down: its supervisor and programs SIGKILLed at once,
//                 then `tahvel up --node` again 0-2 s later (as systemd would)
//   kill-supervisor  only the node's supervisor SIGKILLed (its programs must go with it), then
//                 `tahvel up --node` again 0-2 s later
//   kill          SIGKILL one program (a node's link, which is both its uplink and the agent its
//                 children reach, or a load writer)
//   freeze        SIGSTOP a program or a whole node for 0.3-15 s, then SIGCONT (beyond 3.5 s the
//                 parent's child_silence declares a child down; beyond 10 s Cyclone's lease ends)
//   kill-repeat   SIGKILL a program, wait for the supervisor to start it again, SIGKILL it again
//                 0-800 ms after the supervisor reports it started (DDS discovery, hello,
//                 welcome: its handshake), 2-4 times
//
// Faults start at random times in the schedule and overlap freely. After the schedule the load
// stops, the system settles, and the checks are: every item written reaches the hospital (and a
// sensor's items its home) exactly once with its writer's IRI as source; no outbox (uplink) or
// child down queue holds anything; each parent keeps one state item per child, "up"; after
// `tahvel down` every store opens and no process of the deployment is left. TAHVEL_CHAOS_SEED=N replays a schedule (the faults and their times; the
// system's own timing is not replayed); the seed is printed at the start and with every failure.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <mutex>
#include <random>
#include <set>
#include <sstream>
#include <thread>

#include "tahvel/node/node.h"

namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;
using Clock = std::chrono::steady_clock;
using tahvel::node::Node;
using tahvel::node::Pattern;
using tahvel::node::Term;

const std::string kBin = TAHVEL_BIN_DIR;
const std::string kHospital = "http://example.org/hospital";
const std::string kLoadSeq = "https://w3id.org/tahvel#loadSeq";
const std::vector<std::string> kNodes = {"hospital", "home1", "home2", "ecg1", "ecg2"};
const std::vector<std::string> kWriters = {"home1", "home2", "ecg1", "ecg2"};  // nodes with a load agent
const std::map<std::string, std::string> kParent = {{"home1", "hospital"}, {"home2", "hospital"}, {"ecg1", "home1"}, {"ecg2", "home2"}};

std::string iri_of(const std::string& node) {
  if (node == "hospital") return kHospital;
  if (node.rfind("home", 0) == 0) return kHospital + "/" + node;
  return kHospital + "/home" + node.substr(3) + "/" + node;
}

std::vector<std::string> programs_of(const std::string& node) {
  if (node == "hospital") return {"hospital/link"};
  return {node + "/link", node + "/load"};
}

double seconds_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

template <class F>
bool eventually(F condition, std::chrono::milliseconds limit) {
  const auto deadline = Clock::now() + limit;
  while (Clock::now() < deadline) {
    if (condition()) return true;
    std::this_thread::sleep_for(100ms);
  }
  return condition();
}

struct ProgramRow {
  pid_t pid = 0;
  std::string state, last_exit;
};

enum class FaultKind { kill_node, kill, freeze, kill_repeat, crash_node, kill_supervisor };

struct Fault {
  FaultKind kind;
  std::vector<std::string> programs;  // what it hits (a node's programs, or one)
  std::string what;                   // the node or program, for the log
  std::chrono::milliseconds at{0};    // from the start of the schedule
  std::chrono::milliseconds hold{0};  // freeze: how long
  int times = 1;                      // kill-repeat: how many kills
  std::vector<std::chrono::milliseconds> gaps;  // kill-repeat: pause after each restart

  std::string describe() const {
    std::ostringstream out;
    out << "t=" << at.count() / 1000.0 << "s ";
    switch (kind) {
      case FaultKind::kill_node: out << "kill-node " << what; break;
      case FaultKind::kill: out << "kill " << what; break;
      case FaultKind::freeze: out << "freeze " << what << " for " << hold.count() << " ms"; break;
      case FaultKind::crash_node: out << "crash-node " << what << ", up again after " << hold.count() << " ms"; break;
      case FaultKind::kill_supervisor:
        out << "kill-supervisor " << what << ", up again after " << hold.count() << " ms";
        break;
      case FaultKind::kill_repeat:
        out << "kill-repeat " << what << " x" << times << " (gaps";
        for (auto g : gaps) out << " " << g.count();
        out << " ms)";
        break;
    }
    return out.str();
  }
};

std::vector<Fault> make_schedule(std::uint64_t seed, int count, std::chrono::milliseconds span) {
  std::mt19937_64 rng(seed);
  auto pick = [&](int n) { return static_cast<int>(std::uniform_int_distribution<int>(0, n - 1)(rng)); };
  auto ms = [&](int lo, int hi) { return std::chrono::milliseconds(std::uniform_int_distribution<int>(lo, hi)(rng)); };
  std::vector<std::string> all_programs;
  for (const auto& n : kNodes)
    for (const auto& p : programs_of(n)) all_programs.push_back(p);
  std::vector<Fault> out;
  for (int i = 0; i < count; ++i) {
    Fault f;
    const int roll = pick(100);
    f.kind = roll < 18   ? FaultKind::kill_node
             : roll < 29 ? FaultKind::crash_node
             : roll < 36 ? FaultKind::kill_supervisor
             : roll < 50 ? FaultKind::kill
             : roll < 75 ? FaultKind::freeze
                         : FaultKind::kill_repeat;
    const bool whole_node = f.kind == FaultKind::kill_node || f.kind == FaultKind::crash_node ||
                            f.kind == FaultKind::kill_supervisor ||
                            (f.kind == FaultKind::freeze && pick(3) == 0);
    if (whole_node) {
      f.what = kNodes[pick(static_cast<int>(kNodes.size()))];
      f.programs = programs_of(f.what);
    } else {
      // Links are what the protocol is about: two in three single-program faults hit one.
      std::string node = kNodes[pick(static_cast<int>(kNodes.size()))];
      f.what = (node == "hospital" || pick(3) != 0) ? node + "/link" : node + "/load";
      f.programs = {f.what};
    }
    f.at = ms(0, static_cast<int>(span.count()));
    if (f.kind == FaultKind::freeze) {
      // Short; beyond the parent's child_silence (3.5 s); beyond Cyclone's participant lease
      // (10 s), after which the other side has forgotten the frozen participant.
      const int tier = pick(4);
      f.hold = tier < 2 ? ms(300, 1500) : tier == 2 ? ms(1500, 6000) : ms(6000, 15000);
    }
    if (f.kind == FaultKind::crash_node || f.kind == FaultKind::kill_supervisor) f.hold = ms(0, 2000);
    if (f.kind == FaultKind::kill_repeat) {
      f.times = 2 + pick(3);
      for (int k = 1; k < f.times; ++k) f.gaps.push_back(ms(0, 800));
    }
    out.push_back(std::move(f));
  }
  std::sort(out.begin(), out.end(), [](const Fault& a, const Fault& b) { return a.at < b.at; });
  return out;
}

std::uint64_t chosen_seed() {
  if (const char* s = std::getenv("TAHVEL_CHAOS_SEED"); s && *s) return std::strtoull(s, nullptr, 10);
  return std::random_device{}() ^ (static_cast<std::uint64_t>(std::random_device{}()) << 32);
}

// The hierarchy with a load agent on every sensor and home node; `tahvel up` in the
// constructor, `tahvel down` by down() or the destructor.
class ChaosDeployment {
 public:
  explicit ChaosDeployment(int every_ms) {
    std::string pattern = (fs::temp_directory_path() / "tahvel-chaos-XXXXXX").string();
    root_ = mkdtemp(pattern.data());
    state_ = root_ / "state";
    stop_file_ = root_ / "stop-load";
    std::ofstream toml(root_ / "topology.toml");
    const std::string dds = std::string(TAHVEL_SOURCE_DIR) + "/deploy/cyclonedds-loopback.xml";
    auto load = [&] {
      std::ostringstream a;
      a << "[[node.agent]]\nid = \"load\"\nrun = [\"" << kBin << "/tahvel-e2e-load\", \"{store}\", \"--every-ms\", \""
        << every_ms << "\", \"--stop-file\", \"" << stop_file_.string() << "\"]\n\n";
      return a.str();
    };
    toml << "[deployment]\nname = \"chaos\"\n\n"
         << "[[node]]\nid = \"hospital\"\niri = \"" << kHospital << "\"\ntier = \"hospital\"\n"
         << "store = { durability = \"durable\" }\n"
         << "listen = { kind = \"dds\", domain = 0, config = \"" << dds << "\" }\n\n";
    for (int home = 1; home <= 2; ++home) {
      const std::string h = std::to_string(home);
      toml << "[[node]]\nid = \"home" << h << "\"\ntier = \"home\"\nparent = \"hospital\"\n"
           << "listen = { kind = \"lcm\" }\n"
           << "forward = [\"_ sosa:observedProperty tv:HeartRateVariability\", \"_ tv:loadSeq _\"]\n"
           << load()
           << "[[node]]\nid = \"ecg" << h << "\"\ntier = \"sensor\"\nparent = \"home" << h << "\"\n"
           << "forward = [\"_ tv:loadSeq _\"]\n"
           << load();
    }
    toml.close();
    // One supervisor per node, as one machine each of a real deployment runs it (docs/deploy.md).
    for (const auto& n : kNodes) EXPECT_TRUE(bring_up(n)) << n;
  }

  // `tahvel up --node`, as systemd starts a node's supervisor again after a crash.
  bool bring_up(const std::string& node) {
    auto up = run(kBin + "/tahvel up " + (root_ / "topology.toml").string() + " --node " + node + " --state " + state_.string());
    if (up.first != 0) {
      std::cerr << "chaos: tahvel up --node " << node << ": " << up.second;
      return false;
    }
    return true;
  }

  pid_t supervisor(const std::string& node) const {
    pid_t pid = 0;
    std::ifstream(state_ / ("supervisor-" + node + ".pid")) >> pid;
    return pid;
  }

  ~ChaosDeployment() {
    down();
    std::error_code ec;
    if (!::testing::Test::HasFailure()) fs::remove_all(root_, ec);
    else std::cerr << "chaos: state and logs kept in " << root_ << "\n";
  }

  int down() {
    if (down_) return 0;
    down_ = true;
    return run(kBin + "/tahvel down --state " + state_.string()).first;
  }

  static std::pair<int, std::string> run(const std::string& command) {
    std::string out;
    FILE* pipe = popen((command + " 2>&1").c_str(), "r");
    if (!pipe) return {-1, out};
    char buffer[4096];
    std::size_t n;
    while ((n = fread(buffer, 1, sizeof buffer, pipe)) > 0) out.append(buffer, n);
    int status = pclose(pipe);
    return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, out};
  }

  // The programs of every supervisor, from their state files (a crashed supervisor's file keeps
  // the pids it last wrote).
  std::map<std::string, ProgramRow> programs() const {
    std::map<std::string, ProgramRow> rows;
    for (const auto& n : kNodes) read_state(state_ / ("supervisor-" + n + ".state"), rows);
    return rows;
  }

  static void read_state(const fs::path& file, std::map<std::string, ProgramRow>& rows) {
    std::ifstream in(file);
    std::string line;
    while (std::getline(in, line)) {
      std::istringstream fields(line);
      std::string name, pid, state, restarts, last_exit;
      std::getline(fields, name, '\t');
      std::getline(fields, pid, '\t');
      std::getline(fields, state, '\t');
      std::getline(fields, restarts, '\t');
      std::getline(fields, last_exit);
      rows[name] = {static_cast<pid_t>(std::atoi(pid.c_str())), state, last_exit};
    }
  }

  pid_t pid_of(const std::string& program) const {
    auto rows = programs();
    auto it = rows.find(program);
    return it == rows.end() ? 0 : it->second.pid;
  }

  fs::path store(const std::string& node) const { return state_ / node; }
  const fs::path& root() const { return root_; }
  const fs::path& stop_file() const { return stop_file_; }

 private:
  fs::path root_, state_, stop_file_;
  bool down_ = false;
};

std::vector<pid_t> children_of(pid_t parent);

// Runs the faults of a schedule, each in its own thread at its time, and logs what it did.
class FaultRunner {
 public:
  FaultRunner(ChaosDeployment& d, Clock::time_point t0) : d_(d), t0_(t0) {}

  void log(const std::string& line) {
    std::lock_guard lock(mu_);
    std::ostringstream out;
    out.precision(2);
    out << std::fixed << "chaos " << seconds_since(t0_) << "s: " << line << "\n";
    std::cout << out.str() << std::flush;
  }

  // After f.hold, `tahvel up --node` again, as systemd would restart the node's unit.
  void bring_back_up(const Fault& f, const std::string& after) {
    std::this_thread::sleep_for(f.hold);
    const bool up = d_.bring_up(f.what);
    log(std::string(up ? "up again: " : "NOT up again: ") + f.what);
    if (!up) ADD_FAILURE() << "tahvel up --node " << f.what << " failed after " << after;
  }

  void signal_program(const std::string& program, int sig, std::vector<pid_t>* hit = nullptr) {
    pid_t pid = d_.pid_of(program);
    if (pid <= 0) {
      // Its restart is pending (the supervisor's back-off): the fault lands once it runs again,
      // in the middle of its start-up, unless that takes more than 5 s.
      eventually([&] { return (pid = d_.pid_of(program)) > 0; }, 5s);
      if (pid <= 0) return log(program + " not running (restart pending): " + strsignal(sig) + " skipped");
      log(program + " restarted meanwhile (pid " + std::to_string(pid) + ")");
    }
    if (kill(pid, sig) != 0) return log(program + " pid " + std::to_string(pid) + ": " + strsignal(sig) + " failed");
    if (sig == SIGSTOP) {
      std::lock_guard lock(mu_);
      frozen_.insert(pid);
    }
    if (hit) hit->push_back(pid);
    log(std::string(strsignal(sig)) + " " + program + " (pid " + std::to_string(pid) + ")");
  }

  void run(const Fault& f) {
    std::this_thread::sleep_until(t0_ + f.at);
    switch (f.kind) {
      case FaultKind::kill_node:
      case FaultKind::kill:
        for (const auto& p : f.programs) signal_program(p, SIGKILL);
        break;
      case FaultKind::crash_node: {
        // The node's machine goes down: its supervisor and all its programs at once; systemd
        // starts the supervisor again (`tahvel up --node`) a moment later.
        std::unique_lock lock(crash_mu_);  // one `up` at a time; a node crashes once at a time
        pid_t sup = d_.supervisor(f.what);
        // Stopped first, so that it starts nothing more; then it and all its children at once.
        if (sup > 0 && kill(sup, SIGSTOP) == 0) {
          std::string killed;
          for (pid_t child : children_of(sup)) {
            kill(child, SIGKILL);
            killed += " " + std::to_string(child);
          }
          kill(sup, SIGKILL);
          log("crashed " + f.what + ": supervisor " + std::to_string(sup) + " and its programs" + killed);
        } else {
          log("supervisor of " + f.what + " not running");
        }
        bring_back_up(f, "a crash");
        break;
      }
      case FaultKind::kill_supervisor: {
        // Only the node's supervisor dies (its programs must not run on without it), and is
        // started again.
        std::unique_lock lock(crash_mu_);
        pid_t sup = d_.supervisor(f.what);
        if (sup > 0 && kill(sup, SIGKILL) == 0) log("SIGKILL the supervisor of " + f.what + " (pid " + std::to_string(sup) + ")");
        else log("supervisor of " + f.what + " not running");
        bring_back_up(f, "its supervisor was killed");
        break;
      }
      case FaultKind::freeze: {
        std::vector<pid_t> stopped;
        for (const auto& p : f.programs) signal_program(p, SIGSTOP, &stopped);
        std::this_thread::sleep_for(f.hold);
        for (pid_t pid : stopped) kill(pid, SIGCONT);
        log("SIGCONT " + f.what);
        break;
      }
      case FaultKind::kill_repeat: {
        const std::string& p = f.programs.front();
        for (int k = 0; k < f.times; ++k) {
          pid_t old = d_.pid_of(p);
          signal_program(p, SIGKILL);
          if (k + 1 == f.times) break;
          // Back-off doubles with each kill (0.5 s, 1 s, 2 s ...): wait for the restart.
          if (!eventually([&] { pid_t now = d_.pid_of(p); return now > 0 && now != old; }, 40s)) {
            log(p + " was not restarted within 40 s");
            break;
          }
          std::this_thread::sleep_for(f.gaps[k]);
        }
        break;
      }
    }
  }

  void thaw_all() {
    std::lock_guard lock(mu_);
    for (pid_t pid : frozen_) kill(pid, SIGCONT);
  }

 private:
  ChaosDeployment& d_;
  Clock::time_point t0_;
  std::mutex mu_, crash_mu_;
  std::set<pid_t> frozen_;
};

// The processes whose parent is `parent` (/proc/PID/stat, field 4).
std::vector<pid_t> children_of(pid_t parent) {
  std::vector<pid_t> out;
  std::error_code ec;
  for (const auto& entry : fs::directory_iterator("/proc", ec)) {
    const std::string name = entry.path().filename().string();
    if (name.find_first_not_of("0123456789") != std::string::npos) continue;
    std::ifstream in(entry.path() / "stat");
    std::string stat((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    auto close = stat.rfind(')');  // the command name may hold spaces and parentheses
    if (close == std::string::npos) continue;
    std::istringstream fields(stat.substr(close + 1));
    std::string state;
    pid_t ppid = 0;
    fields >> state >> ppid;
    if (ppid == parent) out.push_back(static_cast<pid_t>(std::stol(name)));
  }
  return out;
}

// The numbers of the load items on `store` written by `writer_node`'s load agent, with how often
// each is there.
std::map<std::int64_t, int> load_items(const fs::path& store, const std::string& writer_node, std::string* problem = nullptr) {
  std::map<std::int64_t, int> out;
  auto node = Node::open(store);
  if (!node) {
    if (problem) *problem = store.string() + ": " + node.error().message;
    return out;
  }
  auto snap = node->snapshot();
  if (!snap) return out;
  auto records = snap->list({.p = Term::iri(kLoadSeq)});
  if (!records) return out;
  const std::string source = iri_of(writer_node) + "/load";
  for (const auto& r : *records)
    if (r.meta.source == source) ++out[std::stoll(r.triple.o.value)];
  return out;
}

std::uint64_t pending(const fs::path& store, const std::string& agent) {
  auto node = Node::open(store);
  if (!node) return ~0ull;
  auto a = node->agent(agent);
  if (!a) return ~0ull;
  auto n = a->pending();
  return n ? *n : ~0ull;
}

// The deployment's processes still alive: any whose command line names the deployment's folder.
std::vector<std::string> leftover_processes(const fs::path& root) {
  std::vector<std::string> out;
  std::error_code ec;
  for (const auto& entry : fs::directory_iterator("/proc", ec)) {
    const std::string pid = entry.path().filename().string();
    if (pid.find_first_not_of("0123456789") != std::string::npos || pid == std::to_string(getpid())) continue;
    std::ifstream in(entry.path() / "cmdline");
    std::string cmdline((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    std::replace(cmdline.begin(), cmdline.end(), '\0', ' ');
    if (cmdline.find(root.string()) != std::string::npos) out.push_back(pid + ": " + cmdline);
  }
  return out;
}

struct ChaosPlan {
  int faults;
  std::chrono::milliseconds span;     // faults start within this time
  std::chrono::milliseconds settle;   // then at most this long for everything to arrive
  int every_ms;                       // load: one item per writer every so often
};

void run_chaos(ChaosPlan plan) {
  if (const char* s = std::getenv("TAHVEL_CHAOS_EVERY_MS"); s && *s) plan.every_ms = std::atoi(s);
  const std::uint64_t seed = chosen_seed();
  const std::string replay = "TAHVEL_CHAOS_SEED=" + std::to_string(seed);
  std::cout << "chaos seed " << seed << " (replay with " << replay << ")\n";
  SCOPED_TRACE("chaos seed " + std::to_string(seed) + " (replay with " + replay + ")");
  const std::vector<Fault> schedule = make_schedule(seed, plan.faults, plan.span);
  for (const auto& f : schedule) std::cout << "chaos schedule: " << f.describe() << "\n";

  ChaosDeployment d(plan.every_ms);
  for (const auto& n : kNodes) ASSERT_GT(d.supervisor(n), 0) << n;
  // Every link registered and items flowing before the first fault.
  ASSERT_TRUE(eventually([&] {
    for (const auto& w : kWriters)
      if (load_items(d.store("hospital"), w).empty()) return false;
    return true;
  }, 60s)) << "no load items from every writer at the hospital before the schedule";

  const auto t0 = Clock::now();
  FaultRunner runner(d, t0);
  {
    std::vector<std::thread> threads;
    for (const auto& f : schedule) threads.emplace_back([&runner, &f] { runner.run(f); });
    for (auto& t : threads) t.join();
  }
  runner.thaw_all();
  const auto schedule_end = Clock::now();
  runner.log("schedule done; stopping the load");
  std::ofstream(d.stop_file()) << "stop\n";
  // The writers finish (status 0) once they see the stop file, also after a restart pending now.
  ASSERT_TRUE(eventually([&] {
    auto rows = d.programs();
    for (const auto& w : kWriters) {
      const auto& r = rows[w + "/load"];
      if (r.state != "stopped" || r.last_exit != "exited with status 0") return false;
    }
    return true;
  }, 90s)) << "the load writers did not finish";

  // What each writer stored: exactly 1..M, whatever it went through.
  std::map<std::string, std::int64_t> written;
  for (const auto& w : kWriters) {
    auto mine = load_items(d.store(w), w);
    ASSERT_FALSE(mine.empty()) << w;
    written[w] = mine.rbegin()->first;
    EXPECT_EQ(mine.size(), static_cast<std::size_t>(written[w])) << w << ": the writer's own numbering has holes";
    runner.log(w + " wrote " + std::to_string(written[w]) + " items");
  }

  // Settle: everything at the hospital, every outbox and down queue empty.
  auto settled = [&] {
    for (const auto& w : kWriters)
      if (load_items(d.store("hospital"), w).size() < static_cast<std::size_t>(written[w])) return false;
    for (const auto& [child, parent] : kParent)
      if (pending(d.store(child), "uplink") != 0 || pending(d.store(parent), child) != 0) return false;
    return true;
  };
  const bool ok = eventually(settled, plan.settle);
  runner.log(std::string(ok ? "settled " : "did not settle ") + "after " +
             std::to_string(seconds_since(schedule_end)) + " s");
  std::this_thread::sleep_for(1s);  // anything late (a resend, a duplicate) would land now

  // Each parent keeps one state item per child (P12), and it says "up" again once all is well.
  auto link_states = [&](const std::string& child, const std::string& parent) {
    std::vector<std::string> states;
    auto node = Node::open(d.store(parent));
    if (!node) return states;
    auto snap = node->snapshot();
    if (!snap) return states;
    auto records = snap->list({.s = Term::iri(iri_of(child)), .p = Term::iri("https://w3id.org/tahvel#linkState")});
    if (records)
      for (const auto& r : *records) states.push_back(r.triple.o.value);
    return states;
  };
  for (const auto& [child, parent] : kParent) {
    std::vector<std::string> states;
    EXPECT_TRUE(eventually([&] {
      states = link_states(child, parent);
      return states.size() == 1 && states[0] == "up";
    }, 15s)) << parent << " keeps " << states.size() << " state item(s) of " << child << ", the first: "
             << (states.empty() ? std::string("none") : states[0]);
  }
  for (const auto& [child, parent] : kParent) {
    EXPECT_EQ(pending(d.store(child), "uplink"), 0u) << "items stuck in the outbox of " << child;
    EXPECT_EQ(pending(d.store(parent), child), 0u) << "items stuck in " << parent << "'s down queue of " << child;
  }
  auto expect_exactly_once = [&](const std::string& at, const std::string& w) {
    auto got = load_items(d.store(at), w);
    std::vector<std::int64_t> lost, doubled, unknown;
    for (std::int64_t n = 1; n <= written[w]; ++n) {
      auto it = got.find(n);
      if (it == got.end()) lost.push_back(n);
      else if (it->second > 1) doubled.push_back(n);
    }
    for (const auto& [n, count] : got)
      if (n < 1 || n > written[w]) unknown.push_back(n);
    auto some = [](const std::vector<std::int64_t>& v) {
      std::ostringstream out;
      for (std::size_t i = 0; i < v.size() && i < 12; ++i) out << " " << v[i];
      if (v.size() > 12) out << " ...";
      return out.str();
    };
    EXPECT_TRUE(lost.empty()) << w << " -> " << at << ": " << lost.size() << " of " << written[w] << " lost:" << some(lost);
    EXPECT_TRUE(doubled.empty()) << w << " -> " << at << ": " << doubled.size() << " doubled:" << some(doubled);
    EXPECT_TRUE(unknown.empty()) << w << " -> " << at << ": " << unknown.size() << " never written:" << some(unknown);
  };
  for (const auto& w : kWriters) expect_exactly_once("hospital", w);
  expect_exactly_once("home1", "ecg1");
  expect_exactly_once("home2", "ecg2");
  // Nothing at the hospital under a source that is not a writer's (a source rewritten on the way).
  {
    std::set<std::string> sources;
    for (const auto& w : kWriters) sources.insert(iri_of(w) + "/load");
    auto node = Node::open(d.store("hospital"));
    ASSERT_TRUE(node.has_value());
    std::size_t foreign = 0;
    auto snap = node->snapshot();
    ASSERT_TRUE(snap.has_value());
    auto records = snap->list({.p = Term::iri(kLoadSeq)});
    ASSERT_TRUE(records.has_value());
    for (const auto& r : *records)
      if (!sources.count(r.meta.source)) ++foreign;
    EXPECT_EQ(foreign, 0u) << "load items at the hospital with a source that is not their writer";
  }

  EXPECT_EQ(d.down(), 0) << "tahvel down failed";
  std::vector<std::string> left;
  eventually([&] { left = leftover_processes(d.root()); return left.empty(); }, 10s);
  for (const auto& p : left) ADD_FAILURE() << "still running after tahvel down: " << p;
  for (const auto& n : kNodes) {
    auto node = Node::open(d.store(n));
    ASSERT_TRUE(node.has_value()) << n << "'s store does not open: " << node.error().message;
    auto snap = node->snapshot();
    ASSERT_TRUE(snap.has_value()) << n << ": " << snap.error().message;
    EXPECT_TRUE(snap->count({}).has_value()) << n << "'s store cannot be read";
  }
  runner.log("checked");
}

// The default-suite variant: five faults within 15 s (all kinds can be drawn), under 60 s in all.
TEST(Chaos, RandomFaultScheduleLosesNothingAndDoublesNothing) {
  run_chaos({.faults = 5, .span = 15s, .settle = 60s, .every_ms = 10});
}

// The soak (label soak, outside the default suite): sixty faults within four minutes.
TEST(ChaosSoak, LongRandomFaultScheduleLosesNothingAndDoublesNothing) {
  int faults = 60;
  if (const char* s = std::getenv("TAHVEL_CHAOS_FAULTS"); s && *s) faults = std::atoi(s);
  run_chaos({.faults = faults, .span = std::chrono::milliseconds(faults * 4000), .settle = 120s, .every_ms = 10});
}

}  // namespace
