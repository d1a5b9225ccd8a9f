// The hierarchy of issue 4 end to end: `tahvel up` of a hospital, two homes over Cyclone DDS and
// an ECG sensor node per home over LCM, each case in its own network namespace. The checks read
// the stores directly (node API) and drive the deployment with the `tahvel` command line, as an
// operator would. Waits are bounded by deadlines; the figures a case depends on are counted in
// the stores, not timed.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <map>
#include <regex>
#include <set>
#include <sstream>
#include <thread>

#include "e2e_support.h"
#include "tahvel/federation/link.h"
#include "tahvel/node/format.h"
#include "tahvel/node/node.h"

namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;
using tahvel::node::Node;
using tahvel::node::Pattern;
using tahvel::node::Record;
using tahvel::node::Term;

const std::string kBin = TAHVEL_BIN_DIR;
const std::string kHospital = "http://example.org/hospital";
const std::string kHome1 = kHospital + "/home1";
const std::string kHome2 = kHospital + "/home2";
const std::string kTv = "https://w3id.org/tahvel#";
const std::string kSosa = "http://www.w3.org/ns/sosa/";
const std::string kRdfType = "http://www.w3.org/1999/02/22-rdf-syntax-ns#type";

using tahvel::e2e::eventually;
using tahvel::e2e::run;

std::vector<Record> list(const fs::path& store, const Pattern& pattern) {
  auto node = Node::open(store);
  if (!node) return {};
  auto snap = node->snapshot();
  if (!snap) return {};
  auto records = snap->list(pattern);
  return records ? std::move(*records) : std::vector<Record>{};
}

const Pattern kHrvWindows{.p = Term::iri(kSosa + "observedProperty"), .o = Term::iri(kTv + "HeartRateVariability")};
const Pattern kEcgChunks{.p = Term::iri(kRdfType), .o = Term::iri(kTv + "EcgChunk")};

// A deployment in a temporary state directory: up in the constructor, down in the destructor.
class Deployment {
 public:
  // `seconds` of synthetic ECG per sensor at `speed` times real time; HRV windows of `window` s.
  Deployment(int seconds, int speed, int window) {
    std::string pattern = (fs::temp_directory_path() / "tahvel-e2e-XXXXXX").string();
    root_ = mkdtemp(pattern.data());
    state_ = root_ / "state";
    std::ofstream toml(root_ / "topology.toml");
    const std::string dds = std::string(TAHVEL_SOURCE_DIR) + "/deploy/cyclonedds-loopback.xml";
    toml << "[deployment]\nname = \"e2e\"\n\n"
         << "[[node]]\nid = \"hospital\"\niri = \"" << kHospital << "\"\ntier = \"hospital\"\n"
         << "listen = { kind = \"dds\", domain = 0, config = \"" << dds << "\" }\n\n";
    for (int home = 1; home <= 2; ++home) {
      const std::string h = std::to_string(home);
      toml << "[[node]]\nid = \"home" << h << "\"\ntier = \"home\"\nparent = \"hospital\"\n"
           << "listen = { kind = \"lcm\" }\n"
           << "[[node.agent]]\nid = \"rpeak\"\nrun = [\"{bin}/tahvel-rpeak\", \"{store}\"]\n"
           << "[[node.agent]]\nid = \"rr\"\nrun = [\"{bin}/tahvel-rr\", \"{store}\"]\n"
           << "[[node.agent]]\nid = \"hrv\"\nrun = [\"{bin}/tahvel-hrv\", \"{store}\", \"--window\", \"" << window << "\"]\n\n"
           << "[[node]]\nid = \"ecg" << h << "\"\ntier = \"sensor\"\nparent = \"home" << h << "\"\n"
           << "forward = [\"_ a tv:EcgRecording\", \"_ a tv:EcgChunk\", \"_ tv:endSample _\"]\n"
           << "[[node.agent]]\nid = \"source\"\nrestart = false\n"
           << "run = [\"{bin}/tahvel-ecg-source\", \"{store}\", \"--synthetic\", \"--seed\", \"" << (10 + home)
           << "\", \"--hr\", \"" << (60 + 15 * home) << "\", \"--seconds\", \"" << seconds << "\", \"--speed\", \"" << speed
           << "\"]\n\n";
    }
    toml.close();
    auto up = run(kBin + "/tahvel up " + (root_ / "topology.toml").string() + " --state " + state_.string());
    up_ok_ = up.status == 0;
    EXPECT_TRUE(up_ok_) << up.out;
  }

  ~Deployment() {
    run(kBin + "/tahvel down --state " + state_.string() + " >/dev/null");
    std::error_code ec;
    if (!::testing::Test::HasFailure()) fs::remove_all(root_, ec);
    else std::cerr << "e2e: state and logs kept in " << root_ << "\n";
  }

  fs::path store(const std::string& id) const { return state_ / id; }
  const fs::path& state() const { return state_; }

  // The pid of a supervised program ("home1/link"), from the supervisor's state file.
  pid_t pid_of(const std::string& program) const {
    std::ifstream in(state_ / "supervisor-all.state");
    std::string line;
    while (std::getline(in, line)) {
      std::istringstream fields(line);
      std::string name;
      pid_t pid = 0;
      fields >> name >> pid;
      if (name == program) return pid;
    }
    return 0;
  }

  // Waits for the supervisor to report `program` running with a pid other than `old`.
  bool restarted(const std::string& program, pid_t old) const {
    return eventually([&] {
      pid_t now = pid_of(program);
      return now != 0 && now != old;
    }, 60s);
  }

  std::string tahvel(const std::string& args, int* status = nullptr) const {
    auto r = run(kBin + "/tahvel " + args);
    if (status) *status = r.status;
    return r.out;
  }

 private:
  fs::path root_, state_;
  bool up_ok_ = false;
};

std::size_t hrv_from(const std::vector<Record>& records, const std::string& home) {
  std::size_t n = 0;
  for (const auto& r : records)
    if (r.meta.source == home + "/hrv") ++n;
  return n;
}

// The windows' lengths (end - start, s) of one home's HRV items on a board.
std::multiset<double> window_lengths(const fs::path& store, const std::string& home) {
  std::multiset<double> out;
  auto node = Node::open(store);
  if (!node) return out;
  auto snap = node->snapshot().value();
  const std::vector<Record> windows = snap.list(kHrvWindows).value();
  for (const auto& r : windows) {
    if (r.meta.source != home + "/hrv") continue;
    auto start = snap.list({.s = r.triple.s, .p = Term::iri(kTv + "windowStartS")}).value();
    auto end = snap.list({.s = r.triple.s, .p = Term::iri(kTv + "windowEndS")}).value();
    if (start.empty() || end.empty()) continue;
    out.insert(std::stod(end[0].triple.o.value) - std::stod(start[0].triple.o.value));
  }
  return out;
}

TEST(Hierarchy, HrvFromBothHomesReachesTheHospitalWithTheirSourcesAndRawEcgStaysHome) {
  Deployment d(/*seconds=*/600, /*speed=*/30, /*window=*/60);
  ASSERT_TRUE(eventually([&] {
    auto hrv = list(d.store("hospital"), kHrvWindows);
    return hrv_from(hrv, kHome1) >= 2 && hrv_from(hrv, kHome2) >= 2;
  })) << "HRV windows at the hospital: " << list(d.store("hospital"), kHrvWindows).size();
  for (const auto& r : list(d.store("hospital"), kHrvWindows))
    EXPECT_TRUE(r.meta.source == kHome1 + "/hrv" || r.meta.source == kHome2 + "/hrv") << r.meta.source;
  EXPECT_GT(list(d.store("home1"), kEcgChunks).size(), 0u) << "raw ECG should reach the home";
  EXPECT_EQ(list(d.store("hospital"), kEcgChunks).size(), 0u) << "raw ECG went up to the hospital";
  EXPECT_EQ(list(d.store("hospital"), {.p = Term::iri(kTv + "samples")}).size(), 0u);
  // The hospital keeps its children's state as triples; status prints the tree.
  int status = -1;
  std::string tree = d.tahvel("status --state " + d.state().string(), &status);
  EXPECT_EQ(status, 0);
  EXPECT_NE(tree.find("home1  <" + kHome1 + ">  link up"), std::string::npos) << tree;
  EXPECT_NE(tree.find("ecg2  <" + kHome2 + "/ecg2>  link up"), std::string::npos) << tree;

  // The operator's view at the hospital: one patient per home, and the query it prints for the
  // raw ECG behind home2's latest window brings that window's chunks from home2.
  const std::string hospital = d.store("hospital").string();
  std::string patients = d.tahvel("patients " + hospital, &status);
  EXPECT_EQ(status, 0);
  EXPECT_NE(patients.find("2 patient(s) with HRV on <" + kHospital + ">"), std::string::npos) << patients;
  EXPECT_NE(patients.find(" HRV window(s) from <" + kHome1 + "/hrv>"), std::string::npos) << patients;
  std::smatch m;
  ASSERT_TRUE(std::regex_search(patients, m, std::regex("\\n<(" + kHome2 + "/[^>]*)>[^<]*<" + kHome2 +
                                                      "/hrv>; the latest ([0-9]+)-([0-9]+) s[^\\n]*\\n[^\\n]*\\n"
                                                      "  its raw ECG, at <" + kHome2 + ">: tahvel query [^ ]+ --at " + kHome2 +
                                                      " --under ([^ ]+) -p tv:samples --since ([0-9]+) --until ([0-9]+)")))
      << patients;
  const std::string recording = m[1];
  EXPECT_EQ(m[4].str(), recording);
  const double seconds = std::stod(m[3]) - std::stod(m[2]);
  const std::string raw = d.tahvel("query " + hospital + " --at " + kHome2 + " --under " + recording +
                                   " -p tv:samples --since " + m[5].str() + " --until " + m[6].str(), &status);
  EXPECT_EQ(status, 0);
  std::size_t chunks = 0, others = 0;
  std::istringstream lines(raw);
  for (std::string line; std::getline(lines, line);) (line.rfind("<" + recording + "/", 0) == 0 ? chunks : others)++;
  // One-second chunks covering the window: as many as its seconds, one more when the window
  // does not start on a chunk's start.
  EXPECT_GE(chunks, static_cast<std::size_t>(seconds)) << raw.substr(0, 600);
  EXPECT_LE(chunks, static_cast<std::size_t>(seconds) + 1);
  EXPECT_EQ(others, 0u) << "home2 has one sensor";
  // The same samples as numbers (`tahvel ecg`, the line patients prints after the query): from
  // the hospital, byte for byte what home2's own store gives, a row per frame of the window.
  const std::string range = " --recording " + recording + " --since " + m[5].str() + " --until " + m[6].str();
  EXPECT_NE(patients.find("  as numbers (CSV): tahvel ecg " + hospital + " --at " + kHome2 + range + "\n"), std::string::npos)
      << patients;
  const std::string remote = d.tahvel("ecg " + hospital + " --at " + kHome2 + range, &status);
  EXPECT_EQ(status, 0);
  const std::string local = d.tahvel("ecg " + d.store("home2").string() + range, &status);
  EXPECT_EQ(status, 0);
  EXPECT_EQ(remote, local);
  const auto rows = static_cast<double>(std::count(remote.begin(), remote.end(), '\n') - 1);
  EXPECT_GE(rows, seconds * 100) << remote.substr(0, 300);  // at least 100 Hz
  EXPECT_EQ(remote.rfind("sample,unix_ns,", 0), 0u) << remote.substr(0, 300);
  // A timeout names the --timeout typed and counts frames, not what was left of it for the
  // chunks and the query's records ("within 239 ms (146 records received)" for --timeout 0.3).
  const std::string late = d.tahvel("ecg " + hospital + " --at " + kHome2 + range + " --timeout 0.001 2>&1 >/dev/null", &status);
  EXPECT_EQ(status, 3) << late;
  EXPECT_NE(late.find("ecg: timeout: no complete answer from <" + kHome2 +
                      "> within --timeout 0.001 s (the description and the chunks share it); 0 frames written out"),
            std::string::npos)
      << late;
}

TEST(Hierarchy, WindowChangeWrittenAtTheHospitalTakesEffectAtThatHomeOnly) {
  Deployment d(/*seconds=*/900, /*speed=*/20, /*window=*/60);
  ASSERT_TRUE(eventually([&] {
    auto hrv = list(d.store("hospital"), kHrvWindows);
    return hrv_from(hrv, kHome1) >= 1 && hrv_from(hrv, kHome2) >= 1;
  }));
  // The operator at the hospital addresses home1's HRV agent (context = its IRI).
  std::string ttl = (d.state() / "window.ttl").string();
  std::ofstream(ttl) << "<" << kHome1 << "/hrv> <" << kTv << "windowSeconds> 30 .\n";
  int status = -1;
  d.tahvel("put " + d.store("hospital").string() + " --agent operator --context " + kHome1 + "/hrv --format ttl " + ttl,
           &status);
  ASSERT_EQ(status, 0);
  ASSERT_TRUE(eventually([&] { return window_lengths(d.store("hospital"), kHome1).count(30.0) >= 2; }))
      << "no 30 s windows from home1 at the hospital";
  // home2 keeps its 60 s windows, and never saw the configuration.
  EXPECT_TRUE(eventually([&] { return window_lengths(d.store("hospital"), kHome2).count(60.0) >= 2; }));
  EXPECT_EQ(window_lengths(d.store("hospital"), kHome2).count(30.0), 0u);
  EXPECT_EQ(list(d.store("home2"), {.p = Term::iri(kTv + "windowSeconds")}).size(), 0u);
  EXPECT_EQ(list(d.store("home1"), {.p = Term::iri(kTv + "windowSeconds")}).size(), 1u);

  // The setting removed at the hospital goes from the home's board too (P10a), over DDS.
  d.tahvel("remove " + d.store("hospital").string() + " -p tv:windowSeconds", &status);
  ASSERT_EQ(status, 0);
  EXPECT_TRUE(eventually([&] { return list(d.store("home1"), {.p = Term::iri(kTv + "windowSeconds")}).empty(); }))
      << "the window setting removed at the hospital stays at home1";
  // An HRV window removed at a home goes from the hospital's board (P7a).
  auto windows = list(d.store("home1"), kHrvWindows);
  ASSERT_FALSE(windows.empty());
  const Term window = windows.front().triple.s;
  ASSERT_FALSE(list(d.store("hospital"), {.s = window}).empty());
  d.tahvel("remove " + d.store("home1").string() + " -s '" + window.to_ntriples() + "'", &status);
  ASSERT_EQ(status, 0);
  EXPECT_TRUE(eventually([&] { return list(d.store("hospital"), {.s = window}).empty(); }))
      << window.value << " removed at home1 stays at the hospital";
  EXPECT_FALSE(list(d.store("hospital"), kHrvWindows).empty()) << "the other windows should stay";
}

TEST(Hierarchy, RemoteQueryOfHomeTwoRawEcgForATimeRangeReturnsExactlyTheStoredBytes) {
  Deployment d(/*seconds=*/120, /*speed=*/20, /*window=*/60);
  ASSERT_TRUE(eventually([&] { return list(d.store("home2"), kEcgChunks).size() >= 60; }));
  auto samples = list(d.store("home2"), {.p = Term::iri(kTv + "samples")});
  ASSERT_GE(samples.size(), 60u);
  // A range that covers chunks 10..39 by their asserted-at times.
  const std::int64_t since = samples[10].meta.asserted_at;
  const std::int64_t until = samples[40].meta.asserted_at;
  Pattern range{.p = Term::iri(kTv + "samples"), .since = since, .until = until};
  std::ostringstream expected;
  {
    tahvel::node::RecordWriter writer(expected, tahvel::node::Format::ntriples);
    for (const auto& r : list(d.store("home2"), range)) writer.write(r);
  }
  ASSERT_FALSE(expected.str().empty());
  int status = -1;
  std::string got = d.tahvel("query " + d.store("hospital").string() + " --at " + kHome2 + " -p tv:samples --since " +
                                 std::to_string(since) + " --until " + std::to_string(until),
                             &status);
  ASSERT_EQ(status, 0);
  EXPECT_EQ(got, expected.str());
  // Chunks 10..39: chunk 9 ends where the range starts and is not in it.
  EXPECT_EQ(std::count(got.begin(), got.end(), '\n'), 30);
  // An operator asking from the middle of chunk 10's second gets chunk 10 as well: each chunk
  // holds for its second (RecordMeta::span), which home2's copies, relayed from its sensor
  // node over LCM, keep.
  ASSERT_GT(samples[10].meta.span, 0);
  const std::int64_t inside = since + samples[10].meta.span / 2;
  EXPECT_EQ(d.tahvel("query " + d.store("hospital").string() + " --at " + kHome2 + " -p tv:samples --since " +
                         std::to_string(inside) + " --until " + std::to_string(until),
                     &status),
            expected.str());
  EXPECT_EQ(status, 0);
  // And the sensor node below home2, two hops down, answers too.
  auto sensor = list(d.store("ecg2"), range);
  std::string from_sensor = d.tahvel("query " + d.store("hospital").string() + " --at " + kHome2 + "/ecg2 -p tv:samples --since " +
                                         std::to_string(since) + " --until " + std::to_string(until) + " --format json",
                                     &status);
  ASSERT_EQ(status, 0);
  EXPECT_EQ(static_cast<std::size_t>(std::count(from_sensor.begin(), from_sensor.end(), '\n')), sensor.size());
  // Turtle: the same triples (printed as they come, with DIR's prefixes declared first).
  std::string turtle = d.tahvel("query " + d.store("hospital").string() + " --at " + kHome2 + " -p tv:samples --since " +
                                    std::to_string(since) + " --until " + std::to_string(until) + " --format ttl",
                                &status);
  ASSERT_EQ(status, 0);
  auto parsed = tahvel::node::parse_rdf(turtle, {});
  ASSERT_TRUE(parsed) << parsed.error().message;
  const std::string lines = expected.str();
  EXPECT_EQ(parsed->size(), static_cast<std::size_t>(std::count(lines.begin(), lines.end(), '\n')));
  // Errors are distinct: unknown node (4), unreachable is covered by the unit tests.
  d.tahvel("query " + d.store("hospital").string() + " --at " + kHospital + "/home9 --timeout 5 2>/dev/null", &status);
  EXPECT_EQ(status, 4);
}

// Every item of `from` (by subject, for the predicate of `pattern`) is on `to` exactly once.
void expect_each_once(const fs::path& from, const fs::path& to, const Pattern& pattern, const std::string& what) {
  std::map<std::string, int> sent, got;
  for (const auto& r : list(from, pattern)) ++sent[r.triple.s.value];
  for (const auto& r : list(to, pattern)) ++got[r.triple.s.value];
  std::size_t lost = 0, doubled = 0;
  for (const auto& [s, n] : sent) {
    if (!got.count(s)) ++lost;
    else if (got[s] > n) ++doubled;
  }
  EXPECT_EQ(lost, 0u) << what << ": " << lost << " of " << sent.size() << " lost";
  EXPECT_EQ(doubled, 0u) << what << ": " << doubled << " doubled";
  EXPECT_GT(sent.size(), 0u) << what;
}

TEST(Hierarchy, CutLinksAndAKilledHomeLoseNothingAndDoubleNothing) {
  Deployment d(/*seconds=*/900, /*speed=*/30, /*window=*/30);
  ASSERT_TRUE(eventually([&] { return hrv_from(list(d.store("hospital"), kHrvWindows), kHome1) >= 1; }));
  // The hospital node's link stopped for a while (DDS side), under load.
  pid_t hospital_link = d.pid_of("hospital/link");
  ASSERT_GT(hospital_link, 0);
  kill(hospital_link, SIGSTOP);
  std::this_thread::sleep_for(4s);
  kill(hospital_link, SIGCONT);
  // The sensor's uplink (LCM side) stopped for a while.
  pid_t sensor_link = d.pid_of("ecg1/link");
  ASSERT_GT(sensor_link, 0);
  kill(sensor_link, SIGSTOP);
  std::this_thread::sleep_for(4s);
  kill(sensor_link, SIGCONT);
  // Home 2 killed outright (its link and agents, SIGKILL); the supervisor restarts them.
  std::map<std::string, pid_t> home2;
  for (const std::string program : {"home2/link", "home2/rpeak", "home2/rr", "home2/hrv"}) {
    home2[program] = d.pid_of(program);
    ASSERT_GT(home2[program], 0) << program;
  }
  for (const auto& [program, pid] : home2) kill(pid, SIGKILL);
  for (const auto& [program, pid] : home2) ASSERT_TRUE(d.restarted(program, pid)) << program;
  // Wait until the sources are done and everything has drained (outboxes empty).
  ASSERT_TRUE(eventually([&] {
    for (const std::string& s : {"ecg1/source", "ecg2/source"})
      if (d.pid_of(s) != 0) return false;
    return true;
  }, 200s)) << "the ECG sources did not finish";
  ASSERT_TRUE(eventually([&] {
    for (const std::string& node : {"home1", "home2", "ecg1", "ecg2"}) {
      auto n = Node::open(d.store(node));
      if (!n || n->agent("uplink").value().pending().value() != 0) return false;
    }
    return true;
  }, 120s)) << "outboxes did not drain";
  std::this_thread::sleep_for(2s);
  expect_each_once(d.store("ecg1"), d.store("home1"), kEcgChunks, "ECG chunks sensor 1 -> home 1 (LCM)");
  expect_each_once(d.store("ecg2"), d.store("home2"), kEcgChunks, "ECG chunks sensor 2 -> home 2 (LCM)");
  expect_each_once(d.store("home1"), d.store("hospital"), kHrvWindows, "HRV home 1 -> hospital (DDS)");
  expect_each_once(d.store("home2"), d.store("hospital"), kHrvWindows, "HRV home 2 -> hospital (DDS)");
}

}  // namespace
