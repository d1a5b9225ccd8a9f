// Layouts other than the demo's, brought up with `tahvel up` in a private network namespace:
// a gateway that reaches its parent and its children over the same transport kind on different
// endpoints (another DDS domain, another LCM URL). Its link process then needs two endpoints of
// one kind; until the `--listen-` flags it shared the parent's, and its children never
// registered.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <iostream>
#include <map>
#include <regex>
#include <string>
#include <thread>

#include "e2e_support.h"
#include "tahvel/node/node.h"

namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;
using tahvel::node::Node;
using tahvel::node::Pattern;
using tahvel::node::Term;
using tahvel::e2e::eventually;
using tahvel::e2e::run;

const std::string kBin = TAHVEL_BIN_DIR;
const std::string kWard = "http://example.org/ward-7";

int shell(const std::string& command) {
  int status = std::system(command.c_str());
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

// The records `_ a tv:TYPE` on the node at `store`.
std::vector<tahvel::node::Record> of_type(const fs::path& store, const std::string& type) {
  auto node = Node::open(store);
  if (!node) return {};
  auto snap = node->snapshot();
  if (!snap) return {};
  auto records = snap->list(Pattern{.p = Term::iri("http://www.w3.org/1999/02/22-rdf-syntax-ns#type"),
                                    .o = Term::iri("https://w3id.org/tahvel#" + type)});
  return records ? std::move(*records) : std::vector<tahvel::node::Record>{};
}

std::size_t ecg_chunks_from(const fs::path& store, const std::string& source) {
  std::size_t n = 0;
  for (const auto& r : of_type(store, "EcgChunk")) n += r.triple.s.value.rfind(source + "/", 0) == 0;
  return n;
}

struct Endpoints {
  std::string name;
  std::string ward_listen, gateway_listen;  // TOML inline tables
};

void PrintTo(const Endpoints& e, std::ostream* out) { *out << e.name; }

class SameKindTwoEndpoints : public ::testing::TestWithParam<Endpoints> {};

// ward <- gateway <- sensor, the sensor's ECG chunks forwarded all the way up: they reach the
// ward only if the gateway's link serves its child on the gateway's own endpoint.
TEST_P(SameKindTwoEndpoints, ChunksFromTheSensorReachTheTopThroughTheGateway) {
  std::string pattern = (fs::temp_directory_path() / "tahvel-layout-XXXXXX").string();
  const fs::path root = mkdtemp(pattern.data());
  const fs::path state = root / "state";
  {
    std::ofstream toml(root / "topology.toml");
    toml << "[deployment]\nname = \"layout\"\n\n"
         << "[[node]]\nid = \"ward\"\niri = \"" << kWard << "\"\ntier = \"hospital\"\nlisten = "
         << GetParam().ward_listen << "\n\n"
         << "[[node]]\nid = \"gateway\"\ntier = \"home\"\nparent = \"ward\"\nlisten = " << GetParam().gateway_listen
         << "\nforward = [\"_ a tv:EcgChunk\"]\n\n"
         << "[[node]]\nid = \"bed\"\ntier = \"sensor\"\nparent = \"gateway\"\nforward = [\"_ a tv:EcgChunk\"]\n"
         << "[[node.agent]]\nid = \"source\"\nrestart = false\n"
         << "run = [\"{bin}/tahvel-ecg-source\", \"{store}\", \"--synthetic\", \"--seed\", \"3\", \"--seconds\", \"30\", "
            "\"--speed\", \"30\"]\n";
  }
  ASSERT_EQ(shell(kBin + "/tahvel up " + (root / "topology.toml").string() + " --state " + state.string()), 0);
  const std::string sensor = kWard + "/gateway/bed";
  const auto deadline = std::chrono::steady_clock::now() + 60s;
  while (ecg_chunks_from(state / "ward", sensor) < 30 && std::chrono::steady_clock::now() < deadline)
    std::this_thread::sleep_for(200ms);
  const std::size_t at_ward = ecg_chunks_from(state / "ward", sensor);
  const std::size_t at_sensor = ecg_chunks_from(state / "bed", sensor);
  shell(kBin + "/tahvel down --state " + state.string() + " >/dev/null");
  EXPECT_EQ(at_sensor, 30u) << "the sensor's 30 s of ECG in 1 s chunks";
  EXPECT_EQ(at_ward, at_sensor) << "logs in " << (state / "logs");
  // Nothing of the deployment's own refused: with the gateway's URL one port above the ward's,
  // its two LCM ends listen on one port, and its end up logged every child as "not the parent".
  for (const auto& entry : fs::recursive_directory_iterator(state / "logs" / "gateway")) {
    if (!entry.is_regular_file()) continue;
    std::ifstream log(entry.path());
    for (std::string line; std::getline(log, line);) EXPECT_EQ(line.find("is not the parent"), std::string::npos) << line;
  }
  std::error_code ec;
  if (!HasFailure()) fs::remove_all(root, ec);
}

const std::string kDdsConfig = std::string("config = \"") + TAHVEL_SOURCE_DIR + "/deploy/cyclonedds-loopback.xml\"";

INSTANTIATE_TEST_SUITE_P(
    Layouts, SameKindTwoEndpoints,
    ::testing::Values(Endpoints{"DdsDomains", "{ kind = \"dds\", domain = 3, " + kDdsConfig + " }",
                                "{ kind = \"dds\", domain = 4, " + kDdsConfig + " }"},
                      Endpoints{"LcmUrls", "{ kind = \"lcm\", url = \"udpm://239.255.76.67:7711?ttl=0\" }",
                                "{ kind = \"lcm\", url = \"udpm://239.255.76.68:7712?ttl=0\" }"},
                      // The gateway's port is the one the ward's link takes for frames down.
                      Endpoints{"LcmAdjacentPorts", "{ kind = \"lcm\", url = \"udpm://239.255.76.67:7713?ttl=0\" }",
                                "{ kind = \"lcm\", url = \"udpm://239.255.76.67:7714?ttl=0\" }"}),
    [](const auto& info) { return info.param.name; });

std::size_t count(const fs::path& store, const std::string& type) { return of_type(store, type).size(); }

class Deployment : public ::testing::Test {
 protected:
  Deployment() {
    std::string pattern = (fs::temp_directory_path() / "tahvel-layout-XXXXXX").string();
    root_ = mkdtemp(pattern.data());
    state_ = root_ / "state";
  }
  ~Deployment() override {
    shell(kBin + "/tahvel down --state " + state_.string() + " >/dev/null");
    std::error_code ec;
    if (!HasFailure()) fs::remove_all(root_, ec);
    else std::cerr << "state and logs kept in " << root_ << "\n";
  }
  void write_topology(const std::string& text) { std::ofstream(root_ / "topology.toml") << text; }
  std::string tahvel(const std::string& args) { return run(kBin + "/tahvel " + args + " 2>&1").out; }
  std::string up(const std::string& flags = "") {
    return tahvel("up " + (root_ / "topology.toml").string() + " --state " + state_.string() + " " + flags);
  }
  std::string status() { return tahvel("status --state " + state_.string()); }

  fs::path root_, state_;
};

// One machine per node (`up --node`). The ward's link writes the gateway's state; once the ward
// is stopped, that state is the link's last word, and `status` must not show it as current (an
// operator read "link up, last seen 45 s ago" for a link nobody was running). The gateway's own
// view is shown beside it (it showed the parent's "outbox 0" while items piled up).
TEST_F(Deployment, StatusDoesNotShowAStoppedParentsLastWordAsTheLinksState) {
  write_topology("[[node]]\nid = \"ward\"\niri = \"" + kWard + "\"\nlisten = { kind = \"dds\", domain = 6, " + kDdsConfig +
                 " }\n\n[[node]]\nid = \"gateway\"\nparent = \"ward\"\n");
  up("--node ward");
  up("--node gateway");
  std::string shown;
  ASSERT_TRUE(eventually([&] { return (shown = status()).find("gateway  <" + kWard + "/gateway>  link up, last seen") != std::string::npos; }))
      << shown;
  const std::string gateway_json = "{\"id\":\"gateway\",\"iri\":\"" + kWard + "/gateway\",\"depth\":1,\"parent\":\"" + kWard + "\",\"remote\":false,\"in_deployment\":true,\"moved_from\":null,\"link\":{\"parent\":\"" + kWard +
                                   "\",\"state\":\"up\",";
  shown = tahvel("status --json --state " + state_.string());
  EXPECT_NE(shown.find(gateway_json + "\"known\":true,\"unknown_because\":null,\"last_seen_ns\":"), std::string::npos) << shown;
  tahvel("down --state " + state_.string() + " --node ward");
  shown = status();
  EXPECT_EQ(shown.find("gateway>  link up"), std::string::npos) << shown;
  EXPECT_NE(shown.find("gateway  <" + kWard + "/gateway>  link state unknown: ward/link is stopped (it last said: link up"),
            std::string::npos)
      << shown;
  // Beside the parent's stale word, the gateway's own, current one (its outbox grows meanwhile).
  EXPECT_TRUE(eventually([&] {
    return (shown = status()).find("); its own link says: uplink to <" + kWard + "> down, parent last heard ") != std::string::npos;
  })) << shown;
  shown = tahvel("status --json --state " + state_.string());
  EXPECT_NE(shown.find(gateway_json + "\"known\":false,\"unknown_because\":\"ward/link is stopped\","), std::string::npos) << shown;
}

// Two machines, each with its own state directory (`up --node`). On the ward's machine `status`
// shows the gateway (known from the state the ward's link keeps of it) as a node on another
// machine; on the gateway's machine it shows the gateway's own view of its uplink, not "(root)";
// a frozen ward is seen on both sides within seconds instead of being shown "up".
TEST_F(Deployment, StatusOnEachMachineShowsWhatThatMachineKnowsOfTheLinkBetweenThem) {
  write_topology("[[node]]\nid = \"ward\"\niri = \"" + kWard + "\"\nlisten = { kind = \"dds\", domain = 6, " + kDdsConfig +
                 " }\n\n[[node]]\nid = \"gateway\"\nparent = \"ward\"\n");
  const fs::path ward_machine = root_ / "ward-machine", gateway_machine = root_ / "gateway-machine";
  const std::string file = (root_ / "topology.toml").string();
  tahvel("up " + file + " --node ward --state " + ward_machine.string());
  tahvel("up " + file + " --node gateway --state " + gateway_machine.string());
  auto status_of = [&](const fs::path& machine) { return tahvel("status --state " + machine.string()); };
  std::string ward_sees, gateway_sees;
  EXPECT_TRUE(eventually([&] {
    return (ward_sees = status_of(ward_machine)).find("  gateway  <" + kWard + "/gateway>  (on another machine)  link up, last seen") !=
           std::string::npos;
  })) << ward_sees;
  EXPECT_TRUE(eventually([&] {
    return (gateway_sees = status_of(gateway_machine)).find("gateway  <" + kWard + "/gateway>  uplink to <" + kWard +
                                                            "> up, parent last heard") != std::string::npos;
  })) << gateway_sees;
  EXPECT_EQ(gateway_sees.find("(root)"), std::string::npos) << gateway_sees;
  const std::string json = tahvel("status --json --state " + gateway_machine.string());
  EXPECT_NE(json.find("\"remote\":false,\"in_deployment\":true,\"moved_from\":null,\"link\":null,\"has_parent\":true,\"outbox_here\":0,\"uplink\":{\"parent\":\"" + kWard + "\",\"state\":\"up\",\"known\":true,"),
            std::string::npos)
      << json;

  // The ward's link frozen (SIGSTOP): it neither refreshes the gateway's state nor answers the
  // gateway's heartbeats. The ward's machine says why, naming the frozen program.
  const std::string ward_link = "pgrep -f '[t]ahvel link " + (ward_machine / "ward").string() + " '";  // not this shell
  ASSERT_EQ(shell("kill -STOP $(" + ward_link + ")"), 0);
  EXPECT_TRUE(eventually(
      [&] {
        return (ward_sees = status_of(ward_machine))
                   .find("gateway>  (on another machine)  link state unknown: ward/link is suspended (stopped by a signal: 'kill -CONT ") !=
               std::string::npos;
      },
      15s))
      << ward_sees;
  EXPECT_NE(ward_sees.find("\n  - link  suspended (stopped by a signal: 'kill -CONT "), std::string::npos) << ward_sees;
  EXPECT_TRUE(eventually(
      [&] { return (gateway_sees = status_of(gateway_machine)).find("uplink to <" + kWard + "> down, parent last heard") != std::string::npos; },
      15s))
      << gateway_sees;
  // A query asked on the ward's machine meanwhile waited out its whole timeout and said only
  // "timeout": it ends at once, unreachable, naming the frozen process.
  const std::string pids = run(ward_link).out, ward_pid = pids.substr(0, pids.find('\n'));
  const std::string ask_gateway = kBin + "/tahvel query " + (ward_machine / "ward").string() + " --at " + kWard + "/gateway -p a --timeout 20 2>&1";
  const auto frozen = run(ask_gateway);
  EXPECT_EQ(frozen.status, 5) << frozen.out;
  EXPECT_NE(frozen.out.find("is stopped by a signal or a debugger (state T or t in /proc/" + ward_pid + "/stat); 'kill -CONT " + ward_pid +
                            "' resumes it"),
            std::string::npos)
      << frozen.out;
  shell("kill -CONT $(" + ward_link + ")");
  // The gateway was not silent, the ward was: once resumed, the ward keeps it connected (it
  // declared it down at once, and a query asked then was refused as unreachable).
  const auto resumed = run(ask_gateway);
  EXPECT_EQ(resumed.status, 0) << resumed.out;
  std::ifstream ward_log(ward_machine / "logs" / "ward" / "link.log");
  const std::string logged((std::istreambuf_iterator<char>(ward_log)), std::istreambuf_iterator<char>());
  EXPECT_EQ(logged.find("silent for"), std::string::npos) << logged;
  EXPECT_TRUE(eventually([&] { return status_of(gateway_machine).find("> up, parent last heard") != std::string::npos; }, 15s));
  tahvel("down --state " + gateway_machine.string());
  tahvel("down --state " + ward_machine.string());
}

// Two `up`s of one new state directory at once (a service unit and an operator): one removed
// the store the other had just made, and both said all was well. They take turns: both succeed,
// every store is there, and one supervisor runs.
TEST_F(Deployment, TwoUpsAtOnceOnANewStateDirectoryTakeTurnsAndEveryStoreIsMade) {
  write_topology("[[node]]\nid = \"ward\"\niri = \"" + kWard + "\"\nlisten = { kind = \"dds\", domain = 8, " + kDdsConfig +
                 " }\n\n[[node]]\nid = \"gateway\"\nparent = \"ward\"\n\n[[node]]\nid = \"bed\"\nparent = \"ward\"\n");
  const std::string up_cmd = kBin + "/tahvel up " + (root_ / "topology.toml").string() + " --state " + state_.string();
  const auto both = run("(" + up_cmd + " > " + (root_ / "up1.out").string() + " 2>&1; echo $? > " + (root_ / "up1.rc").string() + ") & (" +
                        up_cmd + " > " + (root_ / "up2.out").string() + " 2>&1; echo $? > " + (root_ / "up2.rc").string() + ") & wait");
  for (const char* which : {"up1", "up2"}) {
    std::ifstream rc(root_ / (std::string(which) + ".rc")), out(root_ / (std::string(which) + ".out"));
    const std::string said((std::istreambuf_iterator<char>(out)), std::istreambuf_iterator<char>());
    int status = -1;
    rc >> status;
    EXPECT_EQ(status, 0) << which << ": " << said;
  }
  for (const char* node : {"ward", "gateway", "bed"}) EXPECT_TRUE(fs::exists(state_ / node / "data.mdb")) << node;
  std::string shown;
  EXPECT_TRUE(eventually([&] {
    shown = status();
    return shown.find("gateway  <" + kWard + "/gateway>  link up") != std::string::npos &&
           shown.find("bed  <" + kWard + "/bed>  link up") != std::string::npos;
  })) << shown;
  EXPECT_EQ(run("pgrep -fc '[t]ahvel up " + (root_ / "topology.toml").string() + "'").out, "1\n");
}

// Three machines, one node each (`up --node`). On the ward's machine `status` shows the whole
// tree: the gateway, known from the state the ward's link keeps of it, and, asked through the
// link, the sensor below the gateway and the programs of both, as their supervisors wrote them
// on their boards (a program that keeps failing shows its restarts and its last exit there).
// With --local nothing is asked; programs a frozen supervisor no longer rewrites are not shown
// as current; a machine that went down is shown as such, its programs unknown. A problem a
// program reports on its board (the gateway's reasoner, whose rule file no longer parses) is
// shown under it.
TEST_F(Deployment, StatusOnTheRootsMachineShowsTheNodesAndProgramsOfTheMachinesBelowIt) {
  const fs::path rule_file = root_ / "gateway.rules";
  std::ofstream(rule_file) << "alert(X) :- hot(X, _).\n";
  write_topology("[[node]]\nid = \"ward\"\niri = \"" + kWard + "\"\nlisten = { kind = \"dds\", domain = 6, " + kDdsConfig +
                 " }\n\n[[node]]\nid = \"gateway\"\nparent = \"ward\"\n"
                 "listen = { kind = \"lcm\", url = \"udpm://239.255.76.68:7712?ttl=0\" }\n\n"
                 "  [[node.agent]]\n  id = \"reasoner\"\n  run = [\"{bin}/tahvel\", \"reason\", \"{store}\", \"{dir}/gateway.rules\"]\n\n"
                 "[[node]]\nid = \"sensor\"\nparent = \"gateway\"\n\n  [[node.agent]]\n  id = \"flaky\"\n"
                 "  run = [\"sh\", \"-c\", \"exit 3\"]\n");
  const std::string file = (root_ / "topology.toml").string();
  std::map<std::string, fs::path> machine;
  for (const std::string id : {"ward", "gateway", "sensor"}) {
    machine[id] = root_ / (id + "-machine");
    tahvel("up " + file + " --node " + id + " --state " + machine[id].string());
  }
  auto status_of = [&](const std::string& id, const std::string& flags = "") {
    return tahvel("status --state " + machine[id].string() + flags);
  };
  const std::string sensor_line = "    sensor  <" + kWard + "/gateway/sensor>  (on another machine)  link up, last seen";
  std::string shown;
  ASSERT_TRUE(eventually([&] {
    shown = status_of("ward");
    return shown.find(sensor_line) != std::string::npos &&
           shown.find(" restarts, last: exited with status 3") != std::string::npos;
  })) << shown;
  EXPECT_NE(shown.find("  gateway  <" + kWard + "/gateway>  (on another machine)  link up, last seen"), std::string::npos) << shown;
  EXPECT_NE(shown.find("\n    - link  running (pid "), std::string::npos) << shown;  // the gateway's, under it
  EXPECT_NE(shown.find("      - link  running (pid "), std::string::npos) << shown;  // the sensor's
  EXPECT_NE(shown.find("      - flaky  "), std::string::npos) << shown;
  EXPECT_NE(shown.find("\n    - reasoner  running (pid "), std::string::npos) << shown;
  EXPECT_EQ(shown.find("PROBLEM"), std::string::npos) << shown;
  // The reasoner has read its rules once its first session is in its log ("running" is shown
  // from the fork on): a file broken before that is what it starts with, and it exits.
  const fs::path log = machine["gateway"] / "logs" / "gateway" / "reasoner.log";
  auto log_text = [&] {
    std::ifstream in(log);
    return std::string(std::istreambuf_iterator<char>(in), {});
  };
  ASSERT_TRUE(eventually([&] { return log_text().find("session at seq ") != std::string::npos; })) << log_text();
  std::ofstream(rule_file) << "alert(X :- hot(X, _).\n";
  const std::string problem = "rules not reloaded (the previous rules run): " + rule_file.string() + ":1:";
  EXPECT_TRUE(eventually([&] { return (shown = status_of("ward")).find("\n        PROBLEM " + problem) != std::string::npos; }))
      << shown;
  EXPECT_NE(status_of("ward", " --json").find("\"problem\":\"" + problem), std::string::npos);
  std::ofstream(rule_file) << "alert(X) :- hot(X, _).\n";
  EXPECT_TRUE(eventually([&] { return (shown = status_of("ward")).find("PROBLEM") == std::string::npos; })) << shown;
  const std::string json = status_of("ward", " --json");
  EXPECT_NE(json.find("{\"id\":\"sensor\",\"iri\":\"" + kWard + "/gateway/sensor\",\"depth\":2,\"parent\":\"" + kWard + "/gateway\",\"remote\":true,"), std::string::npos) << json;
  EXPECT_NE(json.find("\"programs_known\":true,\"programs_unknown_because\":null,\"programs_written_ns\":1"), std::string::npos) << json;

  // What the nodes below hold, without fetching it (`stats --predicates --at`), one and two hops
  // down: each keeps its own uplink's state, the gateway also its child's.
  const std::string ward_store = (machine["ward"] / "ward").string();
  // (The supervisor rewrites what its node holds every 5 s: the links' records come with the next.)
  std::string held;
  EXPECT_TRUE(eventually([&] {
    held = tahvel("stats " + ward_store + " --predicates --at " + kWard + "/gateway");
    return std::regex_search(held, std::regex("\ntv:linkState +1  20")) && std::regex_search(held, std::regex("\ntv:uplinkState +1  20"));
  }, 15s)) << held;
  EXPECT_NE(held.find("<" + kWard + "/gateway> holds (as its supervisor wrote it "), std::string::npos) << held;
  EXPECT_TRUE(eventually([&] {
    held = tahvel("stats " + ward_store + " --predicates --json --at " + kWard + "/gateway/sensor");
    return held.find("{\"predicate\":\"https://w3id.org/tahvel#uplinkState\",\"records\":1,") != std::string::npos;
  }, 15s)) << held;
  EXPECT_EQ(held.find("#linkState\""), std::string::npos) << held;  // the sensor has no child
  // A query of a predicate the node below holds no record of says so, with the nearest it
  // holds (a misspelt -p answered nothing, with no word); the answer stays empty, exit 0.
  const std::string misspelt = tahvel("query " + ward_store + " --at " + kWard + "/gateway -p tv:uplinkStat");
  EXPECT_NE(misspelt.find("tahvel: query: warning: <" + kWard + "/gateway> (as its supervisor wrote it "), std::string::npos) << misspelt;
  EXPECT_NE(misspelt.find(") has no record with the predicate tv:uplinkStat; did you mean tv:uplinkState (1 record)?"), std::string::npos)
      << misspelt;
  EXPECT_EQ(tahvel("query " + ward_store + " --at " + kWard + "/gateway -p tv:uplinkState -o tv:nothing").find("warning"), std::string::npos);

  shown = status_of("ward", " --local");
  EXPECT_EQ(shown.find("sensor"), std::string::npos) << shown;
  EXPECT_NE(shown.find("(on another machine)  link up, last seen"), std::string::npos) << shown;
  EXPECT_NE(shown.find("    programs and children unknown: not asked (--local)\n"), std::string::npos) << shown;
  // A timeout under a second is said as given ("0.001" was "no answer within 0.0 s").
  shown = status_of("ward", " --timeout 0.001");
  // (Every node below is asked several fields, each a round trip over DDS: not within 1 ms.)
  EXPECT_EQ(shown.find("within 0.0 s"), std::string::npos) << shown;
  EXPECT_NE(shown.find("no answer within 1 ms"), std::string::npos) << shown;

  // The sensor's supervisor frozen: its programs still run, but what its board says of them is
  // no longer rewritten, and status says so instead of showing it as current.
  const std::string supervisor_pid = "$(cat " + (machine["sensor"] / "supervisor-sensor.pid").string() + ")";
  ASSERT_EQ(shell("kill -STOP " + supervisor_pid), 0);
  EXPECT_TRUE(eventually([&] {
    shown = status_of("ward");
    return shown.find("      programs as last written, now unknown: its supervisor has not refreshed them for") != std::string::npos;
  }, 30s)) << shown;
  EXPECT_NE(shown.find("      - link  running (pid "), std::string::npos) << shown;
  // Its last write dated an hour ahead (the sensor's clock ahead, no NTP): a frozen supervisor's
  // programs looked fresh for that hour. Status says how far ahead, and that their age is unknown.
  const std::string ahead = std::to_string(std::chrono::duration_cast<std::chrono::nanoseconds>(
                                               std::chrono::system_clock::now().time_since_epoch() + std::chrono::hours(1))
                                               .count());
  ASSERT_EQ(shell("echo '<" + kWard + "/gateway/sensor> <https://w3id.org/tahvel#programsAt> " + ahead + " .' | " + kBin +
                  "/tahvel put " + (machine["sensor"] / "sensor").string() + " --agent supervisor --persistent"),
            0);
  EXPECT_TRUE(eventually([&] {
    shown = status_of("ward");
    return std::regex_search(shown, std::regex("      programs as last written, now unknown: its clock is (59 min [0-9]+ s|1 h 0 min) ahead of "
                                               "this machine's \\(its supervisor's last write is dated 20"));
  }, 15s)) << shown;
  shell("kill -CONT " + supervisor_pid);

  // An HRV window computed on the sensor reaches the ward (the default policy sends windows up).
  const std::string sensor_iri = kWard + "/gateway/sensor", rec = sensor_iri + "/ecg/recording/a";
  ASSERT_EQ(shell("printf '%s\\n' '@prefix tv: <https://w3id.org/tahvel#> .' '<" + rec + "/hrv/0> "
                  "<http://www.w3.org/ns/sosa/observedProperty> tv:HeartRateVariability ; "
                  "<http://www.w3.org/ns/prov#wasDerivedFrom> <" + rec + "> ; tv:windowStartS 0.0 ; tv:windowEndS 60.0 ; tv:sdnnMs 40.0 .' | " +
                  kBin + "/tahvel put " + (machine["sensor"] / "sensor").string() + " --agent hrv"),
            0);
  // And one computed on the gateway from ECG the sensor sends it (its recording lies below the
  // sensor): a sensor gone down stops it as surely, and `patients` showed its home "up".
  const std::string gateway_rec = sensor_iri + "/ecg/recording/b";
  ASSERT_EQ(shell("printf '%s\\n' '@prefix tv: <https://w3id.org/tahvel#> .' '<" + gateway_rec + "/hrv/0> "
                  "<http://www.w3.org/ns/sosa/observedProperty> tv:HeartRateVariability ; "
                  "<http://www.w3.org/ns/prov#wasDerivedFrom> <" + gateway_rec + "> ; tv:windowStartS 0.0 ; tv:windowEndS 60.0 ; tv:sdnnMs 40.0 .' | " +
                  kBin + "/tahvel put " + (machine["gateway"] / "gateway").string() + " --agent hrv"),
            0);
  std::string patients;
  ASSERT_TRUE(eventually([&] { return (patients = tahvel("patients " + ward_store)).find("2 patient(s)") != std::string::npos; }, 15s))
      << patients;
  EXPECT_EQ(patients.find("its windows come through"), std::string::npos) << "every link on the way is up:\n" << patients;
  EXPECT_EQ(patients.find("its ECG comes from"), std::string::npos) << patients;

  tahvel("down --state " + machine["sensor"].string());
  EXPECT_TRUE(eventually([&] {
    shown = status_of("ward");
    return shown.find("    sensor  <" + kWard + "/gateway/sensor>  (on another machine)  link down") != std::string::npos;
  }, 15s)) << shown;
  // The sensor is two hops down: its link state is on the gateway's board, not the ward's, and
  // `patients` at the ward showed its windows as if they were only late.
  patients = tahvel("patients " + ward_store);
  EXPECT_NE(patients.find("its windows come through <" + sensor_iri + ">, down at <" + kWard + "/gateway> (last heard "), std::string::npos)
      << patients;
  EXPECT_NE(patients.find("its ECG comes from <" + sensor_iri + ">, down at <" + kWard + "/gateway> (last heard "), std::string::npos)
      << patients;
  EXPECT_NE(tahvel("patients " + ward_store + " --json").find(",\"stale\":false,\"at\":\"" + kWard + "/gateway\",\"store_warning\":null}"),
            std::string::npos);
  EXPECT_NE(shown.find("      programs and children unknown: unreachable: "), std::string::npos) << shown;
  EXPECT_EQ(shown.find("flaky"), std::string::npos) << shown;
  tahvel("down --state " + machine["gateway"].string());
  tahvel("down --state " + machine["ward"].string());
}

// A home added to the file of a running deployment: `up` again starts the new node's link and
// restarts the parent's (its accepted children changed), and the new child registers; the
// gateway that was there keeps its link. Taken out again, it is shown as such.
TEST_F(Deployment, AChildAddedToTheFileOfARunningDeploymentRegistersAfterUpAgain) {
  const std::string ward = "[[node]]\nid = \"ward\"\niri = \"" + kWard + "\"\nlisten = { kind = \"dds\", domain = 6, " +
                           kDdsConfig + " }\n\n[[node]]\nid = \"gateway\"\nparent = \"ward\"\n";
  write_topology(ward);
  up();
  std::string shown;
  ASSERT_TRUE(eventually([&] { return (shown = status()).find("gateway  <" + kWard + "/gateway>  link up") != std::string::npos; }))
      << shown;
  write_topology(ward + "\n[[node]]\nid = \"gateway2\"\nparent = \"ward\"\n");
  const std::string applied = up();
  EXPECT_NE(applied.find("up:   restarted ward/link (its command changed from argument "), std::string::npos) << applied;
  EXPECT_NE(applied.find("up:   started gateway2/link"), std::string::npos) << applied;
  EXPECT_EQ(applied.find("gateway/link"), std::string::npos) << applied;
  EXPECT_TRUE(eventually([&] {
    shown = status();
    return shown.find("gateway2  <" + kWard + "/gateway2>  link up") != std::string::npos &&
           shown.find("gateway  <" + kWard + "/gateway>  link up") != std::string::npos;
  })) << shown;

  // Taken out again: its programs stop, its store stays, and status says so rather than show
  // what its parent's link last wrote of it as a link that went quiet.
  write_topology(ward);
  const std::string removed = up();
  EXPECT_NE(removed.find("up:   stopped gateway2/link (no longer in the file)"), std::string::npos) << removed;
  shown = status();
  EXPECT_NE(shown.find("gateway2  <" + kWard + "/gateway2>  not in the deployment (taken out of its file; the store is kept)\n"),
            std::string::npos)
      << shown;
  EXPECT_EQ(shown.find("gateway2/link"), std::string::npos) << shown;
  EXPECT_TRUE(fs::exists(state_ / "gateway2" / "data.mdb"));
  // Once the deployment is down, too: not shown as a node whose uplink went quiet.
  tahvel("down --state " + state_.string());
  shown = status();
  EXPECT_NE(shown.find("gateway2  <" + kWard + "/gateway2>  not in the deployment (taken out of its file; the store is kept)\n"),
            std::string::npos)
      << shown;
  // And while the nodes run as machines of their own (`up --node`), whose files do not have it:
  // it was shown as deployed, with the uplink its link last wrote.
  up("--node ward");
  up("--node gateway");
  shown = status();
  EXPECT_NE(shown.find("gateway2  <" + kWard + "/gateway2>  not in the deployment (taken out of its file; the store is kept)\n"),
            std::string::npos)
      << shown;
  tahvel("down --state " + state_.string() + " --node gateway");
  tahvel("down --state " + state_.string() + " --node ward");
}

// A child node named "-h" (an id like any other): its parent's link runs with `--child -h`,
// which that link took for a request for help, printing its usage and exiting 0, restarted for
// ever, so that the parent served no child at all. The child registers.
TEST_F(Deployment, AChildNodeNamedLikeAHelpFlagRegisters) {
  write_topology("[[node]]\nid = \"ward\"\niri = \"" + kWard + "\"\nlisten = { kind = \"lcm\", url = \"udpm://239.255.76.67:7715?ttl=0\" }\n\n"
                 "[[node]]\nid = \"-h\"\nparent = \"ward\"\n");
  const std::string said = up();
  std::string shown;
  EXPECT_TRUE(eventually([&] { return (shown = status()).find("-h  <" + kWard + "/-h>  link up") != std::string::npos; }))
      << said << shown;
  EXPECT_EQ(shown.find("restarts"), std::string::npos) << shown;  // neither link exited
}

// A forwarding pattern taken out of the topology file stops going up at the next `up`: the
// narrowed policy keeps that data on the node.
TEST_F(Deployment, AForwardPatternTakenOutOfTheFileStopsGoingUp) {
  const std::string top = "[[node]]\nid = \"ward\"\niri = \"" + kWard + "\"\nlisten = { kind = \"lcm\", url = \"udpm://239.255.76.67:7713?ttl=0\" }\n\n"
                          "[[node]]\nid = \"bed\"\nparent = \"ward\"\n";
  write_topology(top + "forward = [\"_ a tv:EcgChunk\", \"_ a tv:EcgRecording\"]\n");
  up();
  const std::string bed = (state_ / "bed").string();
  auto put = [&](const std::string& subject, const std::string& type) {
    return shell("echo '<" + kWard + "/bed/" + subject + "> <http://www.w3.org/1999/02/22-rdf-syntax-ns#type> <https://w3id.org/tahvel#" + type +
                 "> .' | " + kBin + "/tahvel put " + bed + " --format nt >/dev/null");
  };
  ASSERT_EQ(put("rec1", "EcgRecording"), 0);
  ASSERT_EQ(put("chunk1", "EcgChunk"), 0);
  ASSERT_TRUE(eventually([&] { return count(state_ / "ward", "EcgChunk") == 1; }));
  EXPECT_EQ(count(state_ / "ward", "EcgRecording"), 1u);
  tahvel("down --state " + state_.string());
  // Stored while the ward is away: queued in the bed's outbox under the old policy. The one
  // the narrowed policy leaves out went up all the same once the link was back.
  ASSERT_EQ(put("rec0", "EcgRecording"), 0);
  ASSERT_EQ(put("chunk0", "EcgChunk"), 0);
  write_topology(top + "forward = [\"_ a tv:EcgChunk\", \"_ a tv:HrvWindow\"]\n");
  const std::string said = up();
  EXPECT_NE(said.find("bed: added the forwarding pattern '_ a tv:HrvWindow'"), std::string::npos) << said;
  EXPECT_NE(said.find("bed: removed the forwarding pattern '_ rdf:type tv:EcgRecording', no longer in the file"), std::string::npos) << said;
  EXPECT_NE(said.find("bed: 1 item queued for 'ward' under the removed patterns stays on the node (out of the outbox)"), std::string::npos)
      << said;
  ASSERT_EQ(put("rec2", "EcgRecording"), 0);  // stored before the chunk: in order on the link
  ASSERT_EQ(put("chunk2", "EcgChunk"), 0);
  ASSERT_TRUE(eventually([&] { return count(state_ / "ward", "EcgChunk") == 3; }));
  EXPECT_EQ(count(state_ / "ward", "EcgRecording"), 1u);
  EXPECT_EQ(count(state_ / "bed", "EcgRecording"), 3u);

  // `forward = []` is nothing at all, not the default (HRV windows), applied to the running
  // deployment: the bed's link restarts with the new policy.
  write_topology(top + "forward = []\n");
  const std::string applied = up();
  EXPECT_NE(applied.find("bed: removed the forwarding pattern '_ rdf:type tv:EcgChunk', no longer in the file"), std::string::npos) << applied;
  EXPECT_NE(applied.find("up:   restarted bed/link (its command changed from argument "), std::string::npos) << applied;
  std::string shown;
  ASSERT_TRUE(eventually([&] { return (shown = status()).find("bed  <" + kWard + "/bed>  link up") != std::string::npos; })) << shown;
  ASSERT_EQ(put("chunk3", "EcgChunk"), 0);
  ASSERT_EQ(shell("echo '<" + kWard + "/bed/hrv1> <http://www.w3.org/ns/sosa/observedProperty> <https://w3id.org/tahvel#HeartRateVariability> .' | " +
                  kBin + "/tahvel put " + bed + " --format nt >/dev/null"),
            0);
  std::this_thread::sleep_for(3s);  // what would go up has long arrived on a link that is up
  EXPECT_EQ(count(state_ / "ward", "EcgChunk"), 3u);
  auto ward = Node::open(state_ / "ward");
  ASSERT_TRUE(ward);
  EXPECT_EQ(ward->snapshot()->count({.s = Term::iri(kWard + "/bed/hrv1")}).value(), 0u) << "the default policy came back";
}

}  // namespace

// A ward that listens on LCM for the bed monitors of its own LAN and on DDS for a home further
// away: each child links over the kind its `up` names, items come up from both, and a query
// from the ward reaches each over its own link.
TEST_F(Deployment, AParentListeningOnLcmAndDdsServesAChildOnEach) {
  write_topology("[[node]]\nid = \"ward\"\niri = \"" + kWard + "\"\n"
                 "listen = [{ kind = \"dds\", domain = 7, " + kDdsConfig + " }, { kind = \"lcm\", url = \"udpm://239.255.76.67:7714?ttl=0\" }]\n\n"
                 "[[node]]\nid = \"home\"\nparent = \"ward\"\nup = \"dds\"\nforward = [\"_ a tv:EcgChunk\"]\n\n"
                 "[[node]]\nid = \"bed\"\nparent = \"ward\"\nup = \"lcm\"\nforward = [\"_ a tv:EcgChunk\"]\n");
  const std::string said = up();
  std::string shown;
  ASSERT_TRUE(eventually([&] {
    shown = status();
    return shown.find("home  <" + kWard + "/home>  link up") != std::string::npos &&
           shown.find("bed  <" + kWard + "/bed>  link up") != std::string::npos;
  })) << said << shown;
  auto put = [&](const std::string& node, const std::string& subject) {
    return shell("echo '<" + kWard + "/" + node + "/" + subject +
                 "> <http://www.w3.org/1999/02/22-rdf-syntax-ns#type> <https://w3id.org/tahvel#EcgChunk> .' | " + kBin +
                 "/tahvel put " + (state_ / node).string() + " --format nt >/dev/null");
  };
  for (int i = 0; i < 5; ++i) {
    ASSERT_EQ(put("home", "chunk" + std::to_string(i)), 0);
    ASSERT_EQ(put("bed", "chunk" + std::to_string(i)), 0);
  }
  ASSERT_TRUE(eventually([&] { return count(state_ / "ward", "EcgChunk") == 10; })) << count(state_ / "ward", "EcgChunk");
  for (const std::string node : {"home", "bed"}) {
    const auto answer = run(kBin + "/tahvel query " + (state_ / "ward").string() + " --at " + kWard + "/" + node +
                            " -p rdf:type -o tv:EcgChunk --format nt --timeout 20 2>/dev/null");
    EXPECT_EQ(answer.status, 0) << node << ": " << answer.out;
    EXPECT_EQ(std::count(answer.out.begin(), answer.out.end(), '\n'), 5) << node << ": " << answer.out;
  }
}

// A parent that declares both kinds listens on both, whichever kinds its own file's children use:
// a child on another machine whose file links it over the other kind (added there before the
// parent's file was) was met with silence, "never connected", and no reason anywhere.
TEST_F(Deployment, AParentListensOnEveryKindItDeclaresAndRefusesAChildItDoesNotKnowOnEither) {
  const std::string ward = "[[node]]\nid = \"ward\"\niri = \"" + kWard + "\"\n"
                           "listen = [{ kind = \"dds\", domain = 7, " + kDdsConfig +
                           " }, { kind = \"lcm\", url = \"udpm://239.255.76.67:7714?ttl=0\" }]\n\n";
  write_topology(ward + "[[node]]\nid = \"bed\"\nparent = \"ward\"\nup = \"lcm\"\n");
  const std::string said = up();
  std::ofstream(root_ / "home.toml") << ward + "[[node]]\nid = \"home\"\nparent = \"ward\"\nup = \"dds\"\n";
  const fs::path other = root_ / "state-home";
  const std::string home_said = tahvel("up " + (root_ / "home.toml").string() + " --node home --state " + other.string());
  std::string shown;
  EXPECT_TRUE(eventually([&] {
    shown = tahvel("status --state " + other.string());
    return shown.find("refused (<" + kWard + "/home> is not among the children configured for <" + kWard + ">)") !=
           std::string::npos;
  })) << said << home_said << shown;
  shell(kBin + "/tahvel down --state " + other.string() + " >/dev/null");
}

// A Cyclone DDS file edited in place (the file's path, and so the link's command, unchanged) is
// applied by the next `up`: the links that read it restart (it used to say "nothing to change").
TEST_F(Deployment, UpAgainRestartsTheLinksThatReadAnEditedDdsConfiguration) {
  fs::copy_file(std::string(TAHVEL_SOURCE_DIR) + "/deploy/cyclonedds-loopback.xml", root_ / "dds.xml");
  write_topology("[[node]]\nid = \"ward\"\niri = \"" + kWard + "\"\nlisten = { kind = \"dds\", domain = 8, config = \"dds.xml\" }\n\n"
                 "[[node]]\nid = \"bed\"\nparent = \"ward\"\n");
  up();
  std::string shown;
  ASSERT_TRUE(eventually([&] { return (shown = status()).find("bed  <" + kWard + "/bed>  link up") != std::string::npos; })) << shown;
  EXPECT_NE(up().find("nothing to change"), std::string::npos);
  std::ofstream(root_ / "dds.xml", std::ios::app) << "<!-- edited -->\n";
  const std::string applied = up();
  EXPECT_NE(applied.find("up:   restarted ward/link (a file it reads at start changed)"), std::string::npos) << applied;
  EXPECT_NE(applied.find("up:   restarted bed/link (a file it reads at start changed)"), std::string::npos) << applied;
  EXPECT_TRUE(eventually([&] { return (shown = status()).find("bed  <" + kWard + "/bed>  link up") != std::string::npos; })) << shown;
}

// A second deployment of the same file on one network (another state directory, the same DDS
// domain): every node has a twin under its IRI. The links see two stores taking turns (P6b),
// status says CONFLICT, and neither ward takes the other deployment's items; each home keeps
// what it could not send.
TEST_F(Deployment, ASecondDeploymentOfTheSameFileOnOneNetworkIsAConflictAndMixesNothing) {
  write_topology("[[node]]\nid = \"ward\"\niri = \"" + kWard + "\"\nlisten = { kind = \"dds\", domain = 9, " + kDdsConfig + " }\n\n"
                 "[[node]]\nid = \"home\"\nparent = \"ward\"\nforward = [\"_ a tv:EcgChunk\"]\n");
  const fs::path other = root_ / "state-b";
  auto put = [&](const fs::path& state, const std::string& subject) {
    return shell("echo '<" + kWard + "/home/" + subject + "> <http://www.w3.org/1999/02/22-rdf-syntax-ns#type> " +
                 "<https://w3id.org/tahvel#EcgChunk> .' | " + kBin + "/tahvel put " + (state / "home").string() +
                 " --format nt >/dev/null");
  };
  auto chunks = [&](const fs::path& state, char deployment) {
    std::size_t n = 0;
    for (const auto& r : of_type(state / "ward", "EcgChunk")) n += r.triple.s.value.rfind(kWard + "/home/" + deployment, 0) == 0;
    return n;
  };
  up();
  std::string shown;
  ASSERT_TRUE(eventually([&] { return (shown = status()).find("home  <" + kWard + "/home>  link up") != std::string::npos; })) << shown;
  for (int i = 0; i < 5; ++i) ASSERT_EQ(put(state_, "a" + std::to_string(i)), 0);
  ASSERT_TRUE(eventually([&] { return chunks(state_, 'a') == 5; }));

  tahvel("up " + (root_ / "topology.toml").string() + " --state " + other.string());
  for (int i = 0; i < 5; ++i) ASSERT_EQ(put(other, "b" + std::to_string(i)), 0);
  for (int i = 5; i < 10; ++i) ASSERT_EQ(put(state_, "a" + std::to_string(i)), 0);
  std::string shown_b;
  EXPECT_TRUE(eventually([&] {
    shown = status();
    shown_b = tahvel("status --state " + other.string());
    return shown.find("CONFLICT: two stores") != std::string::npos && shown_b.find("CONFLICT: two stores") != std::string::npos;
  })) << shown << shown_b;
  std::this_thread::sleep_for(std::chrono::seconds(3));
  EXPECT_EQ(chunks(state_, 'b'), 0u) << shown;
  EXPECT_EQ(chunks(other, 'a'), 0u) << shown_b;
  tahvel("down --state " + other.string());
}
