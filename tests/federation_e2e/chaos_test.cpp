// Seeded, randomized failure schedules over a real hierarchy under `tahvel up`, each case in its
// own network namespace, on a layout the seed also chooses:
//
//   hospital                      the root, always
//   ├─ home1 .. home3             1-3 homes
//   │  └─ ecg1a ..                0-3 sensor nodes under each home
//   │     └─ patch1a              sometimes a fourth level: a node under one sensor
//   └─ ecg0a                      sometimes a sensor directly under the hospital
//
// Each node with children listens on a transport drawn at random: Cyclone DDS in a domain from
// 0-3 (parents may share a domain or not), or LCM on a URL of its own (another multicast port,
// clear of the ports Cyclone takes for the domains drawn; always ttl=0: loopback only). A gateway whose parent and children use one kind thus has two
// endpoints of it (layouts_test.cpp). One supervisor per node, as on separate machines. A load
// agent on a random non-empty subset of the non-root nodes writes numbered items
// (load_writer.cpp) that every forwarding policy on the way sends up, while a random schedule of
// faults hits the nodes of the layout and the programs their supervisors run:
//
//   kill-node     SIGKILL every program of a node (any node, the hospital too); its supervisor
//                 starts them again with back-off (0.5 s doubling)
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
// stops, the system settles, and the checks are: every item written reaches every ancestor of
// its writer (each stores what it relays) exactly once with its writer's IRI as source, and no
// node holds a load item whose source is not a writer at or below it; no outbox (uplink) or child
// down queue holds anything; each parent keeps one state item per child, "up"; after `tahvel
// down` every store opens and no process of the deployment is left.
//
// TAHVEL_CHAOS_SEED=N replays a layout and a schedule (the faults and their times; the system's
// own timing is not replayed); the seed is printed at the start and with every failure, the
// layout as a tree at the start and with every failure, and the topology file on failure.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <mutex>
#include <optional>
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

// How a parent's children reach it (the `listen` of the topology file).
struct Listen {
  std::string kind;  // "dds" or "lcm"
  int dds_domain = 0;
  std::string lcm_url;

  std::string toml(const std::string& dds_config) const {
    if (kind == "dds")
      return "{ kind = \"dds\", domain = " + std::to_string(dds_domain) + ", config = \"" + dds_config + "\" }";
    return "{ kind = \"lcm\", url = \"" + lcm_url + "\" }";
  }
  std::string describe() const { return kind == "dds" ? "dds domain " + std::to_string(dds_domain) : "lcm " + lcm_url; }
};

struct LayoutNode {
  std::string id, parent, tier;  // parent empty for the root
  std::optional<Listen> listen;  // set when the node has children
  bool writes = false;           // runs a load agent
};

// The tree a seed chose. Nodes are in creation order: every parent before its children.
class Layout {
 public:
  // Draws a layout from `rng` (see the header comment for its shape).
  static Layout random(std::mt19937_64& rng) {
    auto pick = [&](int n) { return static_cast<int>(std::uniform_int_distribution<int>(0, n - 1)(rng)); };
    Layout l;
    l.add({"hospital", "", "hospital"});
    const int homes = 1 + pick(3);
    for (int h = 1; h <= homes; ++h) {
      const std::string home = "home" + std::to_string(h);
      l.add({home, "hospital", "home"});
      const int sensors = pick(4);
      for (int k = 0; k < sensors; ++k) l.add({"ecg" + std::to_string(h) + char('a' + k), home, "sensor"});
    }
    if (pick(3) == 0) l.add({"ecg0a", "hospital", "sensor"});
    if (pick(3) == 0) {
      // A fourth level (third below the hospital when under ecg0a): a node under one sensor.
      std::vector<std::string> sensors;
      for (const auto& n : l.nodes_)
        if (n.tier == "sensor") sensors.push_back(n.id);
      if (!sensors.empty()) {
        const std::string under = sensors[pick(static_cast<int>(sensors.size()))];
        l.add({"patch" + under.substr(3), under, "patch"});
      }
    }
    // Each parent its own transport; LCM parents each their own URL (a port of its own, and a
    // group of three). The ports count up from LCM's default 7667, skipping those Cyclone takes
    // for the DDS domains drawn (7400 + 250 D, 250 each), which `tahvel up` refuses.
    std::set<int> dds_domains;
    for (auto& n : l.nodes_) {
      if (l.children(n.id).empty()) continue;
      Listen listen;
      listen.kind = pick(2) == 0 ? "dds" : "lcm";
      if (listen.kind == "dds") dds_domains.insert(listen.dds_domain = pick(4));
      n.listen = listen;
    }
    auto taken_by_dds = [&](int port) {
      for (int d : dds_domains)
        if (port >= 7400 + 250 * d && port < 7400 + 250 * (d + 1)) return true;
      return false;
    };
    int next_lcm_port = 7667;
    for (auto& n : l.nodes_) {
      if (!n.listen || n.listen->kind != "lcm") continue;
      while (taken_by_dds(next_lcm_port)) ++next_lcm_port;
      n.listen->lcm_url = "udpm://239.255.76." + std::to_string(67 + pick(3)) + ":" + std::to_string(next_lcm_port++) + "?ttl=0";
    }
    for (auto& n : l.nodes_)
      if (!n.parent.empty() && pick(2) == 0) n.writes = true;
    if (l.writers().empty()) l.nodes_[1 + pick(static_cast<int>(l.nodes_.size()) - 1)].writes = true;
    return l;
  }

  std::vector<std::string> ids() const {
    std::vector<std::string> out;
    for (const auto& n : nodes_) out.push_back(n.id);
    return out;
  }
  std::vector<std::string> writers() const {
    std::vector<std::string> out;
    for (const auto& n : nodes_)
      if (n.writes) out.push_back(n.id);
    return out;
  }
  const LayoutNode& node(const std::string& id) const { return nodes_[index_.at(id)]; }
  std::vector<std::string> children(const std::string& id) const {
    std::vector<std::string> out;
    for (const auto& n : nodes_)
      if (n.parent == id) out.push_back(n.id);
    return out;
  }
  // Parent first, the hospital last.
  std::vector<std::string> ancestors(const std::string& id) const {
    std::vector<std::string> out;
    for (std::string at = node(id).parent; !at.empty(); at = node(at).parent) out.push_back(at);
    return out;
  }
  // Every (child, parent) link.
  std::vector<std::pair<std::string, std::string>> links() const {
    std::vector<std::pair<std::string, std::string>> out;
    for (const auto& n : nodes_)
      if (!n.parent.empty()) out.emplace_back(n.id, n.parent);
    return out;
  }
  std::string iri(const std::string& id) const {
    const auto& n = node(id);
    return n.parent.empty() ? kHospital : iri(n.parent) + "/" + id;
  }
  std::vector<std::string> programs(const std::string& id) const {
    if (node(id).writes) return {id + "/link", id + "/load"};
    return {id + "/link"};
  }

  // One line per node, children below their parent, indented by depth:
  // "    home1 (home) load; children over dds domain 2".
  std::string tree(const std::string& from = "hospital") const {
    const LayoutNode& n = node(from);
    std::ostringstream out;
    out << std::string(2 * (ancestors(n.id).size() + 1), ' ') << n.id << " (" << n.tier << ")";
    if (n.writes) out << " load";
    if (n.listen) out << "; children over " << n.listen->describe();
    out << "\n";
    for (const auto& child : children(n.id)) out << tree(child);
    return out.str();
  }

 private:
  void add(LayoutNode n) {
    index_[n.id] = nodes_.size();
    nodes_.push_back(std::move(n));
  }

  std::vector<LayoutNode> nodes_;
  std::map<std::string, std::size_t> index_;
};

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

// Drawn from `rng` after the layout, so that one seed gives both.
std::vector<Fault> make_schedule(std::mt19937_64& rng, const Layout& layout, int count, std::chrono::milliseconds span) {
  auto pick = [&](int n) { return static_cast<int>(std::uniform_int_distribution<int>(0, n - 1)(rng)); };
  auto ms = [&](int lo, int hi) { return std::chrono::milliseconds(std::uniform_int_distribution<int>(lo, hi)(rng)); };
  const std::vector<std::string> nodes = layout.ids();
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
      f.what = nodes[pick(static_cast<int>(nodes.size()))];
      f.programs = layout.programs(f.what);
    } else {
      // Links are what the protocol is about: two in three single-program faults hit one.
      std::string node = nodes[pick(static_cast<int>(nodes.size()))];
      f.what = (!layout.node(node).writes || pick(3) != 0) ? node + "/link" : node + "/load";
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

// The layout as a topology file (docs/deploy.md); the load agents stop once `stop_file` exists.
std::string topology_toml(const Layout& layout, int every_ms, const fs::path& stop_file) {
  const std::string dds_config = std::string(TAHVEL_SOURCE_DIR) + "/deploy/cyclonedds-loopback.xml";
  std::ostringstream toml;
  toml << "[deployment]\nname = \"chaos\"\n";
  for (const auto& id : layout.ids()) {
    const LayoutNode& n = layout.node(id);
    toml << "\n[[node]]\nid = \"" << n.id << "\"\ntier = \"" << n.tier << "\"\n";
    if (n.parent.empty()) {
      toml << "iri = \"" << kHospital << "\"\nstore = { durability = \"durable\" }\n";
    } else {
      toml << "parent = \"" << n.parent << "\"\n";
      // Every node on the way forwards the load, so that each item goes all the way up.
      toml << "forward = [\"_ tv:loadSeq _\"]\n";
    }
    if (n.listen) toml << "listen = " << n.listen->toml(dds_config) << "\n";
    if (n.writes)
      toml << "\n  [[node.agent]]\n  id = \"load\"\n  run = [\"" << kBin << "/tahvel-e2e-load\", \"{store}\", \"--every-ms\", \""
           << every_ms << "\", \"--stop-file\", \"" << stop_file.string() << "\"]\n";
  }
  return toml.str();
}

// The layout under `tahvel up` (its topology file in the case's folder), a load agent on each
// of its writers; `tahvel up` in the constructor, `tahvel down` by down() or the destructor.
class ChaosDeployment {
 public:
  ChaosDeployment(const Layout& layout, int every_ms) : layout_(layout) {
    std::string pattern = (fs::temp_directory_path() / "tahvel-chaos-XXXXXX").string();
    root_ = mkdtemp(pattern.data());
    state_ = root_ / "state";
    stop_file_ = root_ / "stop-load";
    std::ofstream(topology()) << topology_toml(layout_, every_ms, stop_file_);
    // One supervisor per node, as one machine each of a real deployment runs it (docs/deploy.md).
    for (const auto& n : layout_.ids()) EXPECT_TRUE(bring_up(n)) << n;
  }

  // `tahvel up --node`, as systemd starts a node's supervisor again after a crash.
  bool bring_up(const std::string& node) {
    auto up = run(kBin + "/tahvel up " + topology().string() + " --node " + node + " --state " + state_.string());
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
    if (!::testing::Test::HasFailure()) {
      fs::remove_all(root_, ec);
      return;
    }
    std::ifstream toml(topology());
    std::cerr << "chaos: the layout's topology file " << topology() << ":\n" << toml.rdbuf() << "\n"
              << "chaos: state and logs kept in " << root_ << "\n";
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
    for (const auto& n : layout_.ids()) read_state(state_ / ("supervisor-" + n + ".state"), rows);
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
  fs::path topology() const { return root_ / "topology.toml"; }

 private:
  const Layout& layout_;
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

// The load items on a store: for each source, the numbers there with how often each is there.
using LoadCensus = std::map<std::string, std::map<std::int64_t, int>>;

LoadCensus load_items(const fs::path& store) {
  LoadCensus out;
  auto node = Node::open(store);
  if (!node) return out;
  auto snap = node->snapshot();
  if (!snap) return out;
  auto records = snap->list({.p = Term::iri(kLoadSeq)});
  if (!records) return out;
  for (const auto& r : *records) ++out[r.meta.source][std::stoll(r.triple.o.value)];
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
  int every_ms;                       // load: one item per writer every so often, with four writers
                                      // (with more, each writes less often)
};

std::string some(const std::vector<std::int64_t>& v) {
  std::ostringstream out;
  for (std::size_t i = 0; i < v.size() && i < 12; ++i) out << " " << v[i];
  if (v.size() > 12) out << " ...";
  return out.str();
}

void run_chaos(ChaosPlan plan) {
  const std::uint64_t seed = chosen_seed();
  const std::string replay = "TAHVEL_CHAOS_SEED=" + std::to_string(seed);
  std::mt19937_64 rng(seed);
  const Layout layout = Layout::random(rng);
  const std::vector<Fault> schedule = make_schedule(rng, layout, plan.faults, plan.span);
  std::cout << "chaos seed " << seed << " (replay with " << replay << ")\nchaos layout:\n" << layout.tree();
  SCOPED_TRACE("chaos seed " + std::to_string(seed) + " (replay with " + replay + "), layout:\n" + layout.tree());
  for (const auto& f : schedule) std::cout << "chaos schedule: " << f.describe() << "\n";
  const std::vector<std::string> writers = layout.writers();
  // Much the same load in all, whatever the number of writers: every_ms is for four.
  int every_ms = plan.every_ms * std::max<int>(4, static_cast<int>(writers.size())) / 4;
  if (const char* s = std::getenv("TAHVEL_CHAOS_EVERY_MS"); s && *s) every_ms = std::atoi(s);
  std::map<std::string, std::string> source;  // writer node -> its load agent's IRI
  for (const auto& w : writers) source[w] = layout.iri(w) + "/load";

  ChaosDeployment d(layout, every_ms);
  for (const auto& n : layout.ids()) ASSERT_GT(d.supervisor(n), 0) << n;
  // Every link registered and items flowing before the first fault.
  ASSERT_TRUE(eventually([&] {
    auto at_hospital = load_items(d.store("hospital"));
    for (const auto& w : writers)
      if (at_hospital[source[w]].empty()) return false;
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
    for (const auto& w : writers) {
      const auto& r = rows[w + "/load"];
      if (r.state != "stopped" || r.last_exit != "exited with status 0") return false;
    }
    return true;
  }, 90s)) << "the load writers did not finish";

  // What each writer stored: exactly 1..M, whatever it went through.
  std::map<std::string, std::int64_t> written;
  for (const auto& w : writers) {
    auto mine = load_items(d.store(w))[source[w]];
    ASSERT_FALSE(mine.empty()) << w;
    written[w] = mine.rbegin()->first;
    EXPECT_EQ(mine.size(), static_cast<std::size_t>(written[w])) << w << ": the writer's own numbering has holes";
    runner.log(w + " wrote " + std::to_string(written[w]) + " items");
  }

  // Every link runs again before anything is judged: a program killed often late in the
  // schedule waits out its back-off (up to 30 s), and a node with no load on its way (a leaf
  // without a writer) would otherwise still be down, rightly so, when its parent's state of it
  // is checked.
  std::vector<std::string> not_running;
  EXPECT_TRUE(eventually([&] {
    auto rows = d.programs();
    not_running.clear();
    for (const auto& n : layout.ids())
      if (rows[n + "/link"].state != "running") not_running.push_back(n + "/link");
    return not_running.empty();
  }, 60s)) << "links not started again within 60 s of the schedule's end: " << testing::PrintToString(not_running);

  // Settle: everything at every ancestor of its writer, every outbox and down queue empty.
  auto settled = [&] {
    for (const auto& w : writers)
      for (const auto& a : layout.ancestors(w))
        if (load_items(d.store(a))[source[w]].size() < static_cast<std::size_t>(written[w])) return false;
    for (const auto& [child, parent] : layout.links())
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
    auto records = snap->list({.s = Term::iri(layout.iri(child)), .p = Term::iri("https://w3id.org/tahvel#linkState")});
    if (records)
      for (const auto& r : *records) states.push_back(r.triple.o.value);
    return states;
  };
  for (const auto& [child, parent] : layout.links()) {
    std::vector<std::string> states;
    EXPECT_TRUE(eventually([&] {
      states = link_states(child, parent);
      return states.size() == 1 && states[0] == "up";
    }, 15s)) << parent << " keeps " << states.size() << " state item(s) of " << child << ", the first: "
             << (states.empty() ? std::string("none") : states[0]);
  }
  for (const auto& [child, parent] : layout.links()) {
    EXPECT_EQ(pending(d.store(child), "uplink"), 0u) << "items stuck in the outbox of " << child;
    EXPECT_EQ(pending(d.store(parent), child), 0u) << "items stuck in " << parent << "'s down queue of " << child;
  }
  // Every writer's items exactly once at each of its ancestors; on every node, no load item whose
  // source is not a writer at or below it (a source rewritten on the way, or an item gone astray).
  for (const auto& at : layout.ids()) {
    const LoadCensus census = load_items(d.store(at));
    std::set<std::string> expected_sources;
    for (const auto& w : writers) {
      auto up = layout.ancestors(w);
      if (w != at && std::find(up.begin(), up.end(), at) == up.end()) continue;
      expected_sources.insert(source[w]);
      if (w == at) continue;  // checked above
      auto found = census.find(source[w]);
      const std::map<std::int64_t, int> got = found == census.end() ? std::map<std::int64_t, int>{} : found->second;
      std::vector<std::int64_t> lost, doubled, unknown;
      for (std::int64_t n = 1; n <= written[w]; ++n) {
        auto it = got.find(n);
        if (it == got.end()) lost.push_back(n);
        else if (it->second > 1) doubled.push_back(n);
      }
      for (const auto& [n, count] : got)
        if (n < 1 || n > written[w]) unknown.push_back(n);
      EXPECT_TRUE(lost.empty()) << w << " -> " << at << ": " << lost.size() << " of " << written[w] << " lost:" << some(lost);
      EXPECT_TRUE(doubled.empty()) << w << " -> " << at << ": " << doubled.size() << " doubled:" << some(doubled);
      EXPECT_TRUE(unknown.empty()) << w << " -> " << at << ": " << unknown.size() << " never written:" << some(unknown);
    }
    std::size_t foreign = 0;
    for (const auto& [src, numbers] : census)
      if (!expected_sources.count(src)) foreign += numbers.size();
    EXPECT_EQ(foreign, 0u) << "load items at " << at << " with a source that is not a writer at or below it";
  }

  EXPECT_EQ(d.down(), 0) << "tahvel down failed";
  std::vector<std::string> left;
  eventually([&] { left = leftover_processes(d.root()); return left.empty(); }, 10s);
  for (const auto& p : left) ADD_FAILURE() << "still running after tahvel down: " << p;
  for (const auto& n : layout.ids()) {
    auto node = Node::open(d.store(n));
    ASSERT_TRUE(node.has_value()) << n << "'s store does not open: " << node.error().message;
    auto snap = node->snapshot();
    ASSERT_TRUE(snap.has_value()) << n << ": " << snap.error().message;
    EXPECT_TRUE(snap->count({}).has_value()) << n << "'s store cannot be read";
  }
  runner.log("checked");
}

// The layouts themselves, without bringing any up: one seed gives one layout, `tahvel up`
// accepts its file, and over many seeds every shape the header comment promises is drawn, so a
// change to the generator cannot quietly narrow what the chaos cases cover.
TEST(ChaosLayout, SeedsReplayTheirLayoutAndDrawEveryShape) {
  std::set<int> home_counts, sensor_counts;
  bool sensor_under_hospital = false, fourth_level = false, shared_domain = false, dds_to_dds = false,
       lcm_to_lcm = false, lcm_parent = false, dds_parent = false;
  for (std::uint64_t seed = 0; seed < 500; ++seed) {
    std::mt19937_64 rng(seed), again(seed);
    const Layout layout = Layout::random(rng);
    ASSERT_EQ(layout.tree(), Layout::random(again).tree()) << "seed " << seed;
    SCOPED_TRACE("seed " + std::to_string(seed) + ":\n" + layout.tree());
    ASSERT_EQ(layout.ids().front(), "hospital");
    ASSERT_FALSE(layout.writers().empty());
    EXPECT_FALSE(layout.node("hospital").writes);
    int homes = 0;
    std::set<std::string> lcm_urls;
    std::map<int, int> parents_in_domain;
    std::vector<int> lcm_ports;
    for (const auto& id : layout.ids()) {
      const LayoutNode& n = layout.node(id);
      if (n.tier == "home") {
        ++homes;
        sensor_counts.insert(static_cast<int>(layout.children(id).size()));
      }
      if (id == "ecg0a") sensor_under_hospital = true;
      if (layout.ancestors(id).size() == 3) fourth_level = true;
      ASSERT_EQ(layout.children(id).empty(), !n.listen.has_value()) << id;
      if (!n.listen) continue;
      if (n.listen->kind == "lcm") {
        lcm_parent = true;
        lcm_ports.push_back(std::stoi(n.listen->lcm_url.substr(n.listen->lcm_url.rfind(':') + 1)));
        EXPECT_TRUE(lcm_urls.insert(n.listen->lcm_url).second) << "two parents on " << n.listen->lcm_url;
        EXPECT_TRUE(n.listen->lcm_url.ends_with("?ttl=0")) << n.listen->lcm_url;
      } else {
        dds_parent = true;
        shared_domain |= ++parents_in_domain[n.listen->dds_domain] > 1;
      }
      if (n.parent.empty()) continue;
      const Listen& up = *layout.node(n.parent).listen;
      dds_to_dds |= up.kind == "dds" && n.listen->kind == "dds" && up.dds_domain != n.listen->dds_domain;
      lcm_to_lcm |= up.kind == "lcm" && n.listen->kind == "lcm";
    }
    home_counts.insert(homes);
    for (int port : lcm_ports)
      for (const auto& [domain, parents] : parents_in_domain)
        EXPECT_FALSE(port >= 7400 + 250 * domain && port < 7400 + 250 * (domain + 1))
            << "LCM port " << port << " among DDS domain " << domain << "'s ports (tahvel up refuses it)";
  }
  // `tahvel up` accepts every layout's file (it checks a file before it looks up --node, so a
  // node that is not in it starts nothing).
  std::string pattern = (fs::temp_directory_path() / "tahvel-chaos-layouts-XXXXXX").string();
  const fs::path dir = mkdtemp(pattern.data());
  for (std::uint64_t seed = 0; seed < 100; ++seed) {
    std::mt19937_64 rng(seed);
    const Layout layout = Layout::random(rng);
    std::ofstream(dir / "topology.toml") << topology_toml(layout, 10, dir / "stop");
    auto up = ChaosDeployment::run(kBin + "/tahvel up " + (dir / "topology.toml").string() + " --state " +
                                   (dir / "state").string() + " --node nobody");
    EXPECT_NE(up.second.find("--node 'nobody': no such node"), std::string::npos)
        << "seed " << seed << ": " << up.second << "\n" << layout.tree();
  }
  std::error_code ec;
  fs::remove_all(dir, ec);

  EXPECT_EQ(home_counts, (std::set<int>{1, 2, 3}));
  EXPECT_EQ(sensor_counts, (std::set<int>{0, 1, 2, 3}));
  EXPECT_TRUE(sensor_under_hospital);
  EXPECT_TRUE(fourth_level);
  EXPECT_TRUE(lcm_parent && dds_parent);
  EXPECT_TRUE(shared_domain) << "no two parents ever share a DDS domain";
  EXPECT_TRUE(dds_to_dds) << "no gateway ever has two DDS domains";
  EXPECT_TRUE(lcm_to_lcm) << "no gateway ever has two LCM URLs";
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
