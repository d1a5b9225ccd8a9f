// The HRV pipeline as whiteboard agents gives exactly what `tahvel hrv` gives.
//
// Each case inits a node in a temporary directory, starts tahvel-rpeak, tahvel-rr and tahvel-hrv
// as processes, replays MIT-BIH record 100 with tahvel-ecg-source at full speed, waits (with a
// deadline, woken by Node::watch) until every HRV window is on the board, stops the agents with
// SIGTERM, and compares with hrv_from_record() over the same record: the peaks, the NN-marked
// intervals and, per window, the decimal strings of every metric as the item builder writes them.
// The record is found through $TAHVEL_MITDB or TAHVEL_SOURCE_DIR/../shared/data/mitdb; without
// it the cases are skipped.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <sys/file.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <optional>
#include <regex>
#include <sstream>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include "tahvel/aggregation/ecgsyn.h"
#include "tahvel/aggregation/items.h"
#include "tahvel/aggregation/pipeline.h"
#include "tahvel/aggregation/rpeak.h"
#include "tahvel/aggregation/wfdb.h"
#include "tahvel/node/node.h"
#include "agent_process.h"
#include "wfdb_record.h"

namespace {

namespace agg = tahvel::aggregation;
namespace fs = std::filesystem;
namespace tn = tahvel::node;
using namespace std::chrono_literals;

const std::string kNodeIri = "http://example.org/home1";
// Record 100's recording as items written by a test name it; the source names its take
// <this>-<UTC start> (PipelineTest::recording).
const std::string kRecording = kNodeIri + "/ecg/recording/100";
const std::string kSosa = "http://www.w3.org/ns/sosa/";

std::string record_path() {
  const char* env = std::getenv("TAHVEL_MITDB");
  const std::string dir = env && *env ? env : std::string(TAHVEL_SOURCE_DIR) + "/../shared/data/mitdb";
  return dir + "/100";
}

using Process = tahvel::test_support::AgentProcess;

std::string bin(const std::string& name) { return std::string(TAHVEL_BIN_DIR) + "/" + name; }

tn::Pattern hrv_items() {
  tn::Pattern p;
  p.p = tn::Term::iri(kSosa + "observedProperty");
  p.o = agg::tv_term("HeartRateVariability");
  return p;
}

class PipelineTest : public ::testing::Test {
 protected:
  void SetUp() override {
    record_ = record_path();
    if (!fs::exists(record_ + ".hea")) GTEST_SKIP() << "no MIT-BIH record at " << record_;
    char pattern[] = "/tmp/tahvel-agents-hrv-XXXXXX";
    ASSERT_NE(mkdtemp(pattern), nullptr);
    tmp_ = pattern;
    dir_ = tmp_ + "/home1";
    auto node = tn::Node::init(dir_, tn::InitOptions{.iri = kNodeIri});
    ASSERT_TRUE(node) << node.error().message;
    node_.emplace(std::move(*node));
  }
  void TearDown() override {
    agents_.clear();
    node_.reset();
    if (!tmp_.empty()) fs::remove_all(tmp_);
  }

  // Writes the hrv agent's configuration, as an operator would (the step only when > 0).
  void configure_window(double window_s, double step_s = 0) {
    auto op = node_->agent("operator");
    ASSERT_TRUE(op);
    tn::Item item;
    const auto integer = [](double v) {
      return tn::Term::literal(std::to_string(static_cast<int>(v)), std::string(tn::xsd::kInteger));
    };
    item.add(tn::Term::iri(kNodeIri + "/hrv"), agg::tv_term("windowSeconds"), integer(window_s));
    if (step_s > 0) item.add(tn::Term::iri(kNodeIri + "/hrv"), agg::tv_term("stepSeconds"), integer(step_s));
    ASSERT_TRUE(op->store(item));
  }

  // With `logs`, each agent's stderr goes to <tmp>/<program>.log (see agent_log); `warm_up`
  // is given to the R-peak agent as --warm-up.
  void start_agents(bool logs = false, std::optional<int> warm_up = std::nullopt) {
    agents_.clear();
    for (const char* name : {"tahvel-rpeak", "tahvel-rr", "tahvel-hrv"}) {
      std::vector<std::string> argv{bin(name), dir_, "--idle", "300"};
      if (warm_up && std::string(name) == "tahvel-rpeak") argv.insert(argv.end(), {"--warm-up", std::to_string(*warm_up)});
      agents_.push_back(std::make_unique<Process>(argv, logs ? tmp_ + "/" + name + ".log" : ""));
    }
  }

  std::string agent_log(const std::string& program) {
    std::ifstream in(tmp_ + "/" + program + ".log");
    std::ostringstream text;
    text << in.rdbuf();
    return text.str();
  }

  // Starts the three processing agents and waits until they have subscribed.
  void start_and_subscribe(bool logs = false) {
    const std::uint64_t before = node_->stats()->subscriptions;
    start_agents(logs);
    // rpeak: chunks and ends; rr: peaks; hrv: intervals and its configuration.
    wait_until("the agents' subscriptions", [&] { return node_->stats()->subscriptions >= before + 5; });
  }

  // The HRV windows on the board (start and end in s, as written), by start.
  std::vector<std::pair<double, double>> board_windows() {
    tn::Pattern p;
    p.p = agg::tv_term("windowStartS");
    auto records = node_->snapshot()->list(p);
    EXPECT_TRUE(records);
    std::vector<std::pair<double, double>> out;
    if (!records) return out;
    for (const auto& r : *records) {
      double end = -1;
      for (const auto& e : about(r.triple.s.value))
        if (e.triple.p == agg::tv_term("windowEndS")) end = std::stod(e.triple.o.value);
      out.emplace_back(std::stod(r.triple.o.value), end);
    }
    std::sort(out.begin(), out.end());
    return out;
  }

  // Starts the three processing agents, replays the record, waits for `windows` HRV items.
  // With crash_after > 0, kills the three agents (SIGKILL) once that many R-peak items are on
  // the board and starts them again; these log (agent_log) and take `warm_up` as start_agents
  // does. The source replays at `speed`.
  void run_pipeline(std::size_t windows, std::uint64_t crash_after = 0, std::optional<int> warm_up = std::nullopt,
                    const std::string& speed = "0") {
    const std::uint64_t before = node_->stats()->subscriptions;
    start_agents();
    // rpeak: chunks and ends; rr: peaks; hrv: intervals and its configuration.
    wait_until("the agents' subscriptions", [&] { return node_->stats()->subscriptions >= before + 5; });
    if (HasFatalFailure()) return;
    Process source({bin("tahvel-ecg-source"), dir_, "--record", record_, "--speed", speed});
    if (crash_after > 0) {
      tn::Pattern rpeaks;
      rpeaks.p = agg::tv_term("peaks");
      wait_until("R-peak items", [&] { return *node_->snapshot()->count(rpeaks) >= crash_after; });
      if (HasFatalFailure()) return;
      for (auto& a : agents_) a->crash();
      start_agents(true, warm_up);
    }
    wait_until(std::to_string(windows) + " HRV items", [&] { return *node_->snapshot()->count(hrv_items()) >= windows; });
    EXPECT_EQ(source.stop(), 0);
    for (auto& a : agents_) EXPECT_EQ(a->stop(), 0) << "an agent did not stop cleanly on SIGTERM";
  }

  // Waits until `done()` holds, woken by each commit on the board (Node::watch); fails after a
  // deadline or when an agent exits early.
  template <class Done>
  void wait_until(const std::string& what, Done done) {
    std::uint64_t bookmark = 0;
    const auto deadline = std::chrono::steady_clock::now() + 400s;
    while (!done()) {
      for (auto& a : agents_) ASSERT_LT(a->poll(), 0) << "an agent exited early, waiting for " << what;
      ASSERT_LT(std::chrono::steady_clock::now(), deadline) << "timed out waiting for " << what;
      auto changes = node_->watch(bookmark, 1000ms, 1000);
      ASSERT_TRUE(changes);
      if (!changes->empty()) bookmark = changes->back().seq;
    }
  }

  std::vector<tn::Record> about(const std::string& iri) {
    tn::Pattern p;
    p.s = tn::Term::iri(iri);
    auto records = node_->snapshot()->list(p);
    EXPECT_TRUE(records);
    return records ? *records : std::vector<tn::Record>{};
  }

  // The recording on the board: the take the source wrote (<kRecording>-<UTC start>), or
  // kRecording for the items a test writes itself.
  std::string recording() const {
    auto records = node_->snapshot()->list({.p = tn::Term::iri(std::string(tn::kRdfType)), .o = agg::tv_term("EcgRecording")});
    EXPECT_TRUE(records);
    return records && records->size() == 1 ? records->front().triple.s.value : kRecording;
  }

  // Record 100 as the recording kRecording, for the items a test writes itself.
  static agg::RecordingInfo recording_of(const agg::Signals& signals) {
    const auto& h = signals.header;
    agg::RecordingInfo info;
    info.iri = kRecording;
    info.sensor_iri = kNodeIri + "/ecg";
    info.fs = h.fs;
    info.gain = h.signals.empty() ? 200 : h.signals[0].gain;
    info.baseline = h.signals.empty() ? 0 : h.signals[0].baseline;
    for (const auto& sig : h.signals) info.leads.push_back(sig.description);
    info.source = "mitdb/100";
    return info;
  }

  // Every item whose subject lies under <recording>/<kind>/, read with `read`.
  template <class T, class Read>
  std::vector<T> derived(const char* kind, Read read) {
    const std::string rec = recording();
    tn::Pattern p;
    p.p = agg::tv_term("recording");
    p.o = tn::Term::iri(rec);
    std::vector<T> out;
    std::set<std::uint64_t> seen;
    auto snapshot = node_->snapshot();
    auto records = snapshot->list(p);  // kept: a range-for over *temporary would dangle
    EXPECT_TRUE(records);
    for (const auto& r : *records) {
      if (!r.triple.s.value.starts_with(rec + "/" + kind + "/") || !seen.insert(r.meta.item).second) continue;
      auto item = snapshot->item(r.meta.item);
      EXPECT_TRUE(item);
      if (!item) continue;
      auto value = read(*item);
      EXPECT_TRUE(value) << value.error().message;
      if (value) out.push_back(std::move(*value));
    }
    return out;
  }

  // Compares each window's metrics, as decimal strings, with the item builder's for `expected`.
  // The agents' windows and beats over record_ are those of the batch chain (`tahvel hrv`).
  void expect_agents_as_batch(const agg::HrvReport& expected) {
    run_pipeline(expected.windows.size());
    ASSERT_FALSE(HasFatalFailure());
    expect_windows(expected);
    auto peaks = derived<agg::RPeaks>("rpeaks", agg::read_rpeaks);
    std::vector<std::int64_t> beats;
    for (const auto& p : peaks) beats.insert(beats.end(), p.peaks.begin(), p.peaks.end());
    std::sort(beats.begin(), beats.end());
    EXPECT_EQ(beats, expected.beats);
  }
  void expect_windows(const agg::HrvReport& expected) { expect_windows(expected.windows); }
  void expect_windows(const std::vector<agg::WindowMetrics>& windows) {
    const std::string rec = recording();
    auto info = agg::read_recording(about(rec), rec);
    ASSERT_TRUE(info) << info.error().message;
    ASSERT_FALSE(windows.empty());
    for (const auto& window : windows) {
      const std::string iri = agg::hrv_iri(rec, window.start_s);
      std::multiset<std::string> want, got;
      for (const auto& t : agg::hrv_window_item(*info, window, kNodeIri + "/hrv").triples)
        if (t.p.value.starts_with(agg::kTv)) want.insert(t.p.value + " " + t.o.to_ntriples());
      for (const auto& r : about(iri))
        if (r.triple.p.value.starts_with(agg::kTv)) got.insert(r.triple.p.value + " " + r.triple.o.to_ntriples());
      EXPECT_EQ(got, want) << "window " << iri;
    }
    EXPECT_EQ(*node_->snapshot()->count(hrv_items()), windows.size());
  }

  std::string record_, tmp_, dir_;
  std::optional<tn::Node> node_;
  std::vector<std::unique_ptr<Process>> agents_;
};

TEST_F(PipelineTest, WindowsEqualTahvelHrv) {
  auto expected = agg::hrv_from_record(record_);
  ASSERT_TRUE(expected) << expected.error().message;
  run_pipeline(expected->windows.size());
  ASSERT_FALSE(HasFatalFailure());
  expect_windows(*expected);

  // The intermediate items carry the same beats and NN-marked intervals as the batch chain.
  auto peaks = derived<agg::RPeaks>("rpeaks", agg::read_rpeaks);
  std::sort(peaks.begin(), peaks.end(), [](auto& a, auto& b) { return a.from_sample < b.from_sample; });
  std::vector<std::int64_t> beats, empty_gaps, p_wave_gaps;
  for (const auto& p : peaks) {
    beats.insert(beats.end(), p.peaks.begin(), p.peaks.end());
    empty_gaps.insert(empty_gaps.end(), p.empty_gap_ends.begin(), p.empty_gap_ends.end());
    p_wave_gaps.insert(p_wave_gaps.end(), p.p_wave_gap_ends.begin(), p.p_wave_gap_ends.end());
  }
  EXPECT_EQ(beats, expected->beats);
  // And the detector's gap evidence (tv:emptyGapEnds, tv:pWaveGapEnds), which the NN rule
  // uses: the same as the batch detector's.
  auto signals = agg::read_signals(record_);
  ASSERT_TRUE(signals) << signals.error().message;
  agg::DetectorOptions detector;
  detector.fs = signals->header.fs;
  detector.gain = signals->header.signals[0].gain;
  const agg::Detection detection = agg::detect_beats(signals->samples[0], detector);
  EXPECT_EQ(empty_gaps, detection.empty_gap_ends);
  EXPECT_EQ(p_wave_gaps, detection.p_wave_gap_ends);
  EXPECT_FALSE(p_wave_gaps.empty());
  auto rr = derived<agg::RrSeries>("rr", agg::read_rr);
  std::sort(rr.begin(), rr.end(), [](auto& a, auto& b) {
    return (a.intervals.empty() ? INT64_MAX : a.intervals.front().start) <
           (b.intervals.empty() ? INT64_MAX : b.intervals.front().start);
  });
  std::vector<agg::Interval> intervals;
  for (const auto& r : rr) intervals.insert(intervals.end(), r.intervals.begin(), r.intervals.end());
  ASSERT_EQ(intervals.size(), expected->intervals.size());
  for (std::size_t i = 0; i < intervals.size(); ++i) {
    EXPECT_EQ(intervals[i].start, expected->intervals[i].start) << i;
    EXPECT_EQ(intervals[i].end, expected->intervals[i].end) << i;
    EXPECT_EQ(intervals[i].nn, expected->intervals[i].nn) << i;
  }
}

// WFDB's no-value samples (-32768 in format 16) where the lead had no signal: the agents read
// them as the batch chain does (tv:invalidSample on the recording, the R-peak agent holding the
// last valid sample over them), not as -160 mV steps that move beats.
TEST_F(PipelineTest, AgentsReadWfdbsNoValueSamplesAsTheBatchChainDoes) {
  auto ecg = agg::synthetic_ecg(600, agg::SyntheticEcgOptions{});
  ASSERT_TRUE(ecg) << ecg.error().message;
  for (std::size_t start = 30 * 360; start + 180 <= ecg->size(); start += 60 * 360)
    std::fill(ecg->begin() + static_cast<std::ptrdiff_t>(start), ecg->begin() + static_cast<std::ptrdiff_t>(start + 180), -32768);
  record_ = tahvel::test_support::write_format16_record(tmp_, "gaps", *ecg);
  auto expected = agg::hrv_from_record(record_);
  ASSERT_TRUE(expected) << expected.error().message;
  ASSERT_FALSE(expected->warnings.empty());  // the batch chain saw them as no-value samples
  expect_agents_as_batch(*expected);
}

// A lead recorded upside down (a negative gain in its header, which WFDB reads so) goes
// through the agents as through `tahvel hrv`: the recording item carried the gain, and the R-peak
// agent skipped every chunk ("tv:gain is not a positive number"; a review of session 85).
TEST_F(PipelineTest, ALeadRecordedUpsideDownGoesThroughTheAgentsAsThroughTahvelHrv) {
  auto ecg = agg::synthetic_ecg(360, agg::SyntheticEcgOptions{});
  ASSERT_TRUE(ecg) << ecg.error().message;
  for (std::int32_t& v : *ecg) v = -v;
  record_ = tahvel::test_support::write_format16_record(tmp_, "upside", *ecg);
  std::ostringstream header;
  header << std::ifstream(record_ + ".hea").rdbuf();
  std::string text = header.str();
  ASSERT_NE(text.find(" 16 200 16 "), std::string::npos) << text;
  text.replace(text.find(" 16 200 16 "), 11, " 16 -200 16 ");
  std::ofstream(record_ + ".hea") << text;
  auto expected = agg::hrv_from_record(record_);
  ASSERT_TRUE(expected) << expected.error().message;
  EXPECT_GT(expected->beats.size(), 300u);
  expect_agents_as_batch(*expected);
}

TEST_F(PipelineTest, ConfiguredWindowGivesThoseWindows) {
  configure_window(120);
  agg::ChainOptions options;
  options.window_s = 120;
  auto expected = agg::hrv_from_record(record_, options);
  ASSERT_TRUE(expected) << expected.error().message;
  run_pipeline(expected->windows.size());
  ASSERT_FALSE(HasFatalFailure());
  expect_windows(*expected);
  // Every window lasts 120 s but the last, which ends with the recording.
  for (const auto& window : expected->windows)
    EXPECT_DOUBLE_EQ(window.end_s, std::min(window.start_s + 120, expected->duration_s)) << window.start_s;
  ASSERT_FALSE(expected->windows.empty());
  EXPECT_LE(expected->windows.back().end_s, expected->duration_s);
}

// Agents killed in the middle of the record and started again: the windows are still exactly
// those of `tahvel hrv`, and no output is written twice.
TEST_F(PipelineTest, CrashAndRestartChangeNothing) {
  auto expected = agg::hrv_from_record(record_);
  ASSERT_TRUE(expected) << expected.error().message;
  run_pipeline(expected->windows.size(), 600);
  ASSERT_FALSE(HasFatalFailure());
  expect_windows(*expected);
  for (const char* predicate : {"peaks", "intervals", "windowStartS"}) {
    tn::Pattern p;
    p.p = agg::tv_term(predicate);
    auto records = node_->snapshot()->list(p);
    ASSERT_TRUE(records);
    std::set<std::string> subjects;
    for (const auto& r : *records) EXPECT_TRUE(subjects.insert(r.triple.s.value).second) << r.triple.s.value << " twice";
  }
}

// A restart two thirds into the record with --warm-up reads a warm-up of the signal before it
// again, not the record from its start (a week-long recording read whole took minutes and GBs at
// each restart), and here changes nothing: the R-peak agent resumes once the items its warm-up
// gives agree with the board's, the HRV agent reads from shortly before its next window, and the
// RR agent (whose input is small) replays its R-peak items.
TEST_F(PipelineTest, ARestartReadsAWarmUpOfTheSignalBeforeItAndChangesNothing) {
  auto expected = agg::hrv_from_record(record_);
  ASSERT_TRUE(expected) << expected.error().message;
  // The crash comes at 1,200 s of signal (R-peak items), and the replay at 120 times real time
  // leaves 5 s of record for the restarted agents, which keep pace with it.
  run_pipeline(expected->windows.size(), 1200, 120, "120");
  ASSERT_FALSE(HasFatalFailure());
  expect_windows(*expected);
  auto peaks = derived<agg::RPeaks>("rpeaks", agg::read_rpeaks);
  std::vector<std::int64_t> beats;
  for (const auto& p : peaks) beats.insert(beats.end(), p.peaks.begin(), p.peaks.end());
  std::sort(beats.begin(), beats.end());
  EXPECT_EQ(beats, expected->beats);
  const std::string log = agent_log("tahvel-rpeak");
  std::smatch resumed;
  ASSERT_TRUE(std::regex_search(log, resumed, std::regex("resumed at sample ([0-9]+) after reading ([0-9]+) chunk\\(s\\) again")))
      << log;
  // At the crash, or a chunk before it: one stored but not yet acknowledged comes again.
  EXPECT_GE(std::stoll(resumed[1]), 1100 * 360) << log;
  EXPECT_LE(std::stoll(resumed[2]), 121) << "a warm-up of 120 s reads about 120 one-second chunks:\n" << log;
  EXPECT_EQ(log.find("replayed"), std::string::npos) << log;
  EXPECT_NE(agent_log("tahvel-rr").find("replayed"), std::string::npos) << agent_log("tahvel-rr");
  // The HRV agent: from 300 s before the next window's start, not from 0 (the windows of 300 s
  // up to 900 s at least were written before the crash at 1,200 s).
  const std::string hrv_log = agent_log("tahvel-hrv");
  std::smatch m;
  ASSERT_TRUE(std::regex_search(hrv_log, m, std::regex("replayed ([0-9]+) earlier RR item\\(s\\) of <[^>]+> from the board, "
                                                       "from ([0-9.]+) s of signal")))
      << hrv_log;
  EXPECT_GE(std::stod(m[2]), 300) << hrv_log;
}

// tahvel-hrv restarted between the recording's last RR item and its end (the RR item with
// tv:endSample and no interval; a `down` stops hrv before the source) lost the recording's
// last window: the end, the first item the new run saw, finished an empty windower.
TEST_F(PipelineTest, AnHrvAgentRestartedJustBeforeTheRecordingsEndStillWritesItsLastWindow) {
  auto expected = agg::hrv_from_record(record_);
  ASSERT_TRUE(expected) << expected.error().message;
  ASSERT_GE(expected->windows.size(), 2u);
  {
    Process source({bin("tahvel-ecg-source"), dir_, "--record", record_, "--speed", "0"});
    ASSERT_EQ(source.wait(120s), 0);
  }
  const std::string rec = recording();
  // The RR item that carries the recording's end (and, here, its last intervals).
  auto end_of_rr = [&]() -> std::optional<tn::Record> {
    auto ends = node_->snapshot()->list({.p = agg::tv_term("endSample")});
    if (ends)
      for (const tn::Record& r : *ends)
        if (r.triple.s.value.starts_with(rec + "/rr/")) return r;
    return std::nullopt;
  };
  {
    std::vector<std::unique_ptr<Process>> stages;
    for (const char* name : {"tahvel-rpeak", "tahvel-rr"})
      stages.push_back(std::make_unique<Process>(std::vector<std::string>{bin(name), dir_, "--idle", "300"}));
    agents_.clear();
    wait_until("the RR item with the recording's end", [&] { return end_of_rr().has_value(); });
    ASSERT_FALSE(HasFatalFailure());
    for (auto& stage : stages) EXPECT_EQ(stage->stop(), 0);
  }
  // That item split as tahvel-rr writes it when the end brings no interval: its intervals, then
  // an item of the end alone (<rec>/rr/end), which comes once the first hrv run has done the rest.
  const tn::Record last = *end_of_rr();
  auto last_item = node_->snapshot()->item(last.meta.item);
  ASSERT_TRUE(last_item);
  auto series = agg::read_rr(*last_item);
  ASSERT_TRUE(series) << series.error().message;
  ASSERT_TRUE(node_->remove_item(last.meta.item));
  agg::RrSeries intervals = *series, end_alone = *series;
  intervals.end_sample.reset();
  end_alone.intervals.clear();
  auto rr = node_->agent("rr");
  ASSERT_TRUE(rr);
  // Asserted as tahvel-rr asserts its items, at the signal time of their first interval (the
  // end alone at its sample): a restarted stage reads its inputs again by that time.
  auto info = agg::read_recording(about(rec), rec);
  ASSERT_TRUE(info) << info.error().message;
  if (!intervals.intervals.empty()) {
    tn::Item item = agg::rr_item(intervals);
    item.asserted_at = agg::signal_time_ns(*info, static_cast<double>(intervals.intervals.front().start) / info->fs);
    ASSERT_TRUE(rr->store(item));
  }
  auto hrv = [&] { return std::make_unique<Process>(std::vector<std::string>{bin("tahvel-hrv"), dir_, "--idle", "300"}); };
  agents_.push_back(hrv());
  wait_until("all windows but the last", [&] { return *node_->snapshot()->count(hrv_items()) >= expected->windows.size() - 1; });
  ASSERT_FALSE(HasFatalFailure());
  EXPECT_EQ(agents_.back()->stop(), 0);
  agents_.clear();
  tn::Item end_item = agg::rr_item(end_alone);
  end_item.asserted_at = agg::signal_time_ns(*info, static_cast<double>(*end_alone.end_sample) / info->fs);
  ASSERT_TRUE(rr->store(end_item));
  agents_.push_back(hrv());
  const auto deadline = std::chrono::steady_clock::now() + 30s;
  while (*node_->snapshot()->count(hrv_items()) < expected->windows.size() && std::chrono::steady_clock::now() < deadline)
    std::this_thread::sleep_for(50ms);
  EXPECT_EQ(agents_.back()->stop(), 0);
  expect_windows(*expected);
}

// The whole record replayed before any processing agent was started: each stage's new
// subscription brings the items already on the board (R10a), so the windows are all there.
TEST_F(PipelineTest, AgentsStartedAfterTheRecordingEndedProcessAllOfIt) {
  auto expected = agg::hrv_from_record(record_);
  ASSERT_TRUE(expected) << expected.error().message;
  Process source({bin("tahvel-ecg-source"), dir_, "--record", record_, "--speed", "0"});
  ASSERT_EQ(source.wait(120s), 0);
  tn::Pattern ends;
  ends.s = tn::Term::iri(recording());
  ends.p = agg::tv_term("endSample");
  ASSERT_EQ(*node_->snapshot()->count(ends), 1u) << "the replay had not ended";
  start_agents();
  wait_until(std::to_string(expected->windows.size()) + " HRV items",
             [&] { return *node_->snapshot()->count(hrv_items()) >= expected->windows.size(); });
  ASSERT_FALSE(HasFatalFailure());
  for (auto& a : agents_) EXPECT_EQ(a->stop(), 0);
  expect_windows(*expected);
}

// prov:wasDerivedFrom leads from every HRV item, through RR and R-peak items, to ECG chunks.
TEST_F(PipelineTest, ProvenanceLeadsBackToChunks) {
  auto expected = agg::hrv_from_record(record_);
  ASSERT_TRUE(expected) << expected.error().message;
  run_pipeline(expected->windows.size());
  ASSERT_FALSE(HasFatalFailure());
  auto from = [&](const std::string& iri) {
    std::vector<std::string> out;
    for (const auto& r : about(iri))
      if (r.triple.p.value == agg::kProvDerivedFrom) out.push_back(r.triple.o.value);
    return out;
  };
  const std::string rec = recording();
  for (const auto& window : expected->windows) {
    const std::string hrv = agg::hrv_iri(rec, window.start_s);
    std::set<std::string> chunks;
    bool names_recording = false;
    for (const auto& rr : from(hrv)) {
      if (rr == rec) names_recording = true;
      if (!rr.starts_with(rec + "/rr/")) continue;
      for (const auto& rpeaks : from(rr)) {
        EXPECT_TRUE(rpeaks.starts_with(rec + "/rpeaks/")) << rr << " derived from " << rpeaks;
        for (const auto& chunk : from(rpeaks))
          if (chunk.starts_with(rec + "/chunk/")) chunks.insert(chunk);
      }
    }
    EXPECT_TRUE(names_recording) << hrv;
    ASSERT_FALSE(chunks.empty()) << hrv << " does not lead back to a chunk";
    for (const auto& chunk : chunks) {
      bool is_chunk = false;
      for (const auto& r : about(chunk))
        is_chunk |= r.triple.p.value == std::string(tn::kRdfType) && r.triple.o == agg::tv_term("EcgChunk");
      EXPECT_TRUE(is_chunk) << chunk << " is not an ECG chunk on the board";
    }
  }
}


// Every item of the chain is asserted at the signal time it describes, as the chunks are: the
// recording's tv:startedAt plus the offset of its first sample (a window: its start). So the
// time of an HRV window at the hospital finds its raw ECG (`tahvel query --since`); asserted
// when computed, it named a stretch of ECG tens of seconds away.
TEST_F(PipelineTest, EachItemIsAssertedAtTheSignalTimeItDescribes) {
  auto expected = agg::hrv_from_record(record_);
  ASSERT_TRUE(expected) << expected.error().message;
  run_pipeline(expected->windows.size());
  ASSERT_FALSE(HasFatalFailure());
  std::optional<std::int64_t> started;
  double fs = 0;
  for (const auto& r : about(recording())) {
    if (r.triple.p == agg::tv_term("startedAt")) started = std::stoll(r.triple.o.value);
    if (r.triple.p == agg::tv_term("samplingRate")) fs = std::stod(r.triple.o.value);
  }
  ASSERT_TRUE(started) << "the recording has no tv:startedAt";
  ASSERT_GT(fs, 0);
  auto asserted_at = [&](const std::string& iri) { return about(iri).at(0).meta.asserted_at; };
  auto at_sample = [&](std::int64_t sample) { return *started + std::llround(static_cast<double>(sample) * 1e9 / fs); };
  for (const auto& window : expected->windows) {
    const std::string hrv = agg::hrv_iri(recording(), window.start_s);
    EXPECT_EQ(asserted_at(hrv), *started + std::llround(window.start_s * 1e9)) << hrv;
  }
  const auto chunk = recording() + "/chunk/" + std::to_string(static_cast<std::int64_t>(std::round(fs)) * 10);
  EXPECT_EQ(asserted_at(chunk), at_sample(static_cast<std::int64_t>(std::round(fs)) * 10));
  std::size_t checked = 0;
  for (const auto& r : *node_->snapshot()->list({.p = agg::tv_term("fromSample")})) {
    if (r.triple.s.value.find("/rpeaks/") == std::string::npos) continue;
    EXPECT_EQ(r.meta.asserted_at, at_sample(std::stoll(r.triple.o.value))) << r.triple.s.value;
    ++checked;
  }
  EXPECT_GT(checked, 0u) << "no R-peak item checked";
}
}  // namespace

namespace {

// While record 100 is being replayed (paced: about 36 s), the hrv agent's window is changed to
// 120 s once the first 300 s window is on the board. The windows produced before the change
// keep 300 s; from the first window not yet produced (the boundary, read from the board) they
// last 120 s, with exactly the metrics of an HrvWindower whose set_window(120, 120) is called
// at that boundary.
TEST_F(PipelineTest, WindowChangeMidStreamAppliesFromTheNextWindow) {
  auto batch = agg::hrv_from_record(record_);
  ASSERT_TRUE(batch) << batch.error().message;
  start_and_subscribe();
  ASSERT_FALSE(HasFatalFailure());
  Process source({bin("tahvel-ecg-source"), dir_, "--record", record_, "--speed", "50"});
  wait_until("the first HRV window", [&] { return *node_->snapshot()->count(hrv_items()) >= 1; });
  ASSERT_FALSE(HasFatalFailure());
  configure_window(120, 120);
  ASSERT_FALSE(HasFatalFailure());
  const auto is_short = [](const std::pair<double, double>& w) { return w.second - w.first == 120; };
  wait_until("a 120 s window", [&] {
    auto windows = board_windows();
    return std::any_of(windows.begin(), windows.end(), is_short);
  });
  ASSERT_FALSE(HasFatalFailure());
  // Windows are written in order: the first 120 s window starts where the change applied.
  double boundary = -1;
  for (const auto& w : board_windows())
    if (is_short(w)) {
      boundary = w.first;
      break;
    }
  ASSERT_GT(boundary, 0) << "the change applied before the first window";

  agg::HrvWindower windower(batch->fs, 300, 300);
  std::vector<agg::WindowMetrics> expected;
  bool changed = false;
  for (const auto& interval : batch->intervals) {
    windower.push(interval, expected);
    if (!changed && !expected.empty() && expected.back().end_s >= boundary) {
      ASSERT_DOUBLE_EQ(expected.back().end_s, boundary) << "no 300 s window ends at the boundary";
      windower.set_window(120, 120);
      changed = true;
    }
  }
  windower.finish(expected, batch->duration_s);
  ASSERT_TRUE(changed);

  wait_until(std::to_string(expected.size()) + " HRV items",
             [&] { return *node_->snapshot()->count(hrv_items()) >= expected.size(); });
  ASSERT_FALSE(HasFatalFailure());
  EXPECT_EQ(source.stop(), 0);
  for (auto& a : agents_) EXPECT_EQ(a->stop(), 0) << "an agent did not stop cleanly on SIGTERM";

  std::size_t before = 0, after = 0;
  for (const auto& [start, end] : board_windows()) {
    if (start < boundary) {
      ++before;
      EXPECT_DOUBLE_EQ(end - start, 300) << "window at " << start << " s, before the change at " << boundary << " s";
    } else {
      ++after;
      // The board's decimals have two places.
      EXPECT_NEAR(end, std::min(start + 120, batch->duration_s), 0.006)
          << "window at " << start << " s, after the change at " << boundary << " s";
    }
  }
  EXPECT_GE(before, 1u);
  EXPECT_GE(after, 1u);
  expect_windows(expected);
}

// A window change, then a restart of the agents (a crash, `down`/`up`, a reboot): the restarted
// hrv agent replays the recording's RR items with the new setting, but goes on after the last
// window it wrote. It used to start the new grid at 0, writing 120 s windows inside the 300 s
// ones already written (and sent up to the hospital).
TEST_F(PipelineTest, ARestartAfterAWindowChangeWritesNoWindowOverlappingOneWritten) {
  start_and_subscribe();
  ASSERT_FALSE(HasFatalFailure());
  Process source({bin("tahvel-ecg-source"), dir_, "--record", record_, "--speed", "60"});
  wait_until("two HRV windows", [&] { return *node_->snapshot()->count(hrv_items()) >= 2; });
  ASSERT_FALSE(HasFatalFailure());
  for (auto& a : agents_) a->crash();
  configure_window(120, 120);
  ASSERT_FALSE(HasFatalFailure());
  start_agents();
  wait_until("the recording's last window", [&] {
    auto windows = board_windows();
    return !windows.empty() && windows.back().second >= 1800;
  });
  ASSERT_FALSE(HasFatalFailure());
  EXPECT_EQ(source.stop(), 0);
  const auto windows = board_windows();
  ASSERT_GE(windows.size(), 3u);
  bool changed = false;
  for (std::size_t i = 0; i < windows.size(); ++i) {
    const auto [start, end] = windows[i];
    if (i > 0) {
      EXPECT_GE(start, windows[i - 1].second - 1e-9) << "window " << start << "-" << end << " overlaps the one before";
    }
    if (end - start < 300 - 1e-9 && end < 1800) changed = true;
    if (changed && end < 1800) {
      EXPECT_DOUBLE_EQ(end - start, 120) << "window at " << start;
    }
  }
  EXPECT_TRUE(changed) << "no 120 s window: the test proves nothing";
}

// The chunks of the first two minutes of record 100, stored directly, with the second
// [60 s, 61 s) missing. tahvel-rpeak logs the gap and restarts its detector at the next chunk:
// no agent fails, R-peak items continue after the gap, none covers the missing second, and the
// peaks on either side are those of a detector that saw only that side.
TEST_F(PipelineTest, GapInTheChunksIsLoggedAndRestartsTheDetectorKeepingTheBeatsItHeld) {
  auto signals = agg::read_signals(record_);
  ASSERT_TRUE(signals) << signals.error().message;
  const agg::RecordingInfo info = recording_of(*signals);
  const auto fs = static_cast<std::int64_t>(std::llround(info.fs));
  // Second 45 is missing; record 100 has a beat 17 samples before it, which the detector still
  // holds when the gap comes.
  const std::int64_t seconds = 120, missing = 45;
  const std::int64_t gap_start = missing * fs, gap_end = gap_start + fs, end = seconds * fs;
  ASSERT_GE(static_cast<std::int64_t>(signals->samples[0].size()), end);

  start_and_subscribe(true);
  ASSERT_FALSE(HasFatalFailure());
  auto ecg = node_->agent("ecg");
  ASSERT_TRUE(ecg);
  ASSERT_TRUE(ecg->store(agg::recording_item(info)));
  for (std::int64_t k = 0; k < seconds; ++k) {
    if (k == missing) continue;
    ASSERT_TRUE(ecg->store(agg::ecg_chunk_item(info, k * fs, signals->samples, static_cast<std::size_t>(k * fs),
                                               static_cast<std::size_t>(fs))));
  }
  ASSERT_TRUE(ecg->store(agg::recording_end_item(kRecording, end)));

  // The whole chain gets through: the R-peak end item, then the (one, partial) HRV window.
  wait_until("the R-peak end item", [&] { return !about(agg::rpeaks_iri(kRecording, end)).empty(); });
  ASSERT_FALSE(HasFatalFailure()) << agent_log("tahvel-rpeak");
  wait_until("the HRV window", [&] { return *node_->snapshot()->count(hrv_items()) >= 1; });
  ASSERT_FALSE(HasFatalFailure());
  for (auto& a : agents_) EXPECT_EQ(a->stop(), 0) << "an agent did not stop cleanly on SIGTERM";

  const std::string log = agent_log("tahvel-rpeak");
  EXPECT_NE(log.find("gap from sample " + std::to_string(gap_start) + " to " + std::to_string(gap_end)),
            std::string::npos)
      << "tahvel-rpeak's log:\n" << log;

  auto items = derived<agg::RPeaks>("rpeaks", agg::read_rpeaks);
  std::sort(items.begin(), items.end(), [](auto& a, auto& b) { return a.from_sample < b.from_sample; });
  ASSERT_EQ(items.size(), static_cast<std::size_t>(seconds));  // one per chunk given, and the end item
  std::vector<std::int64_t> before_gap, after_gap;
  std::size_t items_after = 0;
  for (const auto& item : items) {
    EXPECT_TRUE(item.to_sample <= gap_start || item.from_sample >= gap_end)
        << item.iri << " covers [" << item.from_sample << ", " << item.to_sample << ")";
    for (auto p : item.peaks) EXPECT_TRUE(p < gap_start || p >= gap_end) << item.iri << ": peak " << p;
    // The beats held at the gap come in the first item after it, before its from_sample.
    for (auto p : item.peaks) (p < gap_start ? before_gap : after_gap).push_back(p);
    if (item.from_sample >= gap_end) ++items_after;
  }
  EXPECT_EQ(items_after, static_cast<std::size_t>(seconds - missing));  // 74 chunks and the end
  EXPECT_EQ(items.back().end_sample, end);

  std::sort(before_gap.begin(), before_gap.end());
  std::sort(after_gap.begin(), after_gap.end());

  // Each side as a detector that saw only that side, in the same one-second pushes and then
  // finished: nothing the detector held at the gap is lost.
  agg::DetectorOptions options;
  options.fs = info.fs;
  options.gain = info.gain;
  const auto& lead = signals->samples[0];
  std::vector<std::int64_t> want_before, want_after;
  std::size_t held_at_gap = 0;
  {
    agg::RPeakDetector detector(options);
    for (std::int64_t k = 0; k < missing; ++k)
      detector.push(lead.data() + k * fs, static_cast<std::size_t>(fs), want_before);
    held_at_gap = want_before.size();
    detector.finish(want_before);
    held_at_gap = want_before.size() - held_at_gap;
  }
  {
    agg::RPeakDetector detector(options);
    for (std::int64_t k = missing + 1; k < seconds; ++k)
      detector.push(lead.data() + k * fs, static_cast<std::size_t>(fs), want_after);
    detector.finish(want_after);
    for (auto& p : want_after) p += gap_end;
  }
  EXPECT_GE(held_at_gap, 1u);  // the case this checks: a beat was still held at the gap
  EXPECT_EQ(before_gap, want_before);
  EXPECT_EQ(after_gap, want_after);
  EXPECT_GT(after_gap.size(), 50u);  // record 100 beats about 75 per minute
}

// A restarted R-peak agent takes the state of a warm-up only when the R-peak items it gives
// agree with the board's: an item on the board that the detector would not give (here one
// tampered with) makes it read further back, and at last replay the recording from its start;
// either way each R-peak item is the one an uninterrupted detector gives.
TEST_F(PipelineTest, ARestartedRPeakAgentReadsFurtherBackWhenItsWarmUpDisagreesWithTheBoard) {
  auto signals = agg::read_signals(record_);
  ASSERT_TRUE(signals) << signals.error().message;
  agg::RecordingInfo info = recording_of(*signals);
  info.started_at = std::int64_t{1'796'000'000} * 1'000'000'000;  // warm-ups read chunks by their signal time
  const auto fs = static_cast<std::int64_t>(std::llround(info.fs));
  const std::int64_t seconds = 1500;
  ASSERT_GE(static_cast<std::int64_t>(signals->samples[0].size()), seconds * fs);

  // What an uninterrupted detector gives per one-second chunk, and at the end.
  agg::DetectorOptions options;
  options.fs = info.fs;
  options.gain = info.gain;
  std::vector<std::vector<std::int64_t>> want(static_cast<std::size_t>(seconds + 1));
  {
    agg::RPeakDetector detector(options);
    for (std::int64_t k = 0; k < seconds; ++k)
      detector.push(signals->samples[0].data() + k * fs, static_cast<std::size_t>(fs), want[static_cast<std::size_t>(k)]);
    detector.finish(want.back());
  }

  auto ecg = node_->agent("ecg");
  ASSERT_TRUE(ecg);
  ASSERT_TRUE(ecg->store(agg::recording_item(info)));
  const auto write_chunks = [&](std::int64_t from, std::int64_t to) {
    for (std::int64_t k = from; k < to; ++k) {
      tn::Item chunk = agg::ecg_chunk_item(info, k * fs, signals->samples, static_cast<std::size_t>(k * fs), static_cast<std::size_t>(fs));
      chunk.asserted_at = agg::signal_time_ns(info, static_cast<double>(k));
      ASSERT_TRUE(ecg->store(chunk));
    }
  };
  const auto run_rpeak_until = [&](std::int64_t chunks, const std::string& log) {
    agents_.clear();
    agents_.push_back(std::make_unique<Process>(
        std::vector<std::string>{bin("tahvel-rpeak"), dir_, "--idle", "300", "--warm-up", "120"}, tmp_ + "/" + log));
    wait_until("the R-peak item of chunk " + std::to_string(chunks - 1),
               [&] { return !about(agg::rpeaks_iri(kRecording, (chunks - 1) * fs)).empty(); });
    ASSERT_FALSE(HasFatalFailure());
    EXPECT_EQ(agents_.back()->stop(), 0);
    agents_.clear();
  };
  const auto log_of = [&](const std::string& name) {
    std::ifstream in(tmp_ + "/" + name);
    std::ostringstream text;
    text << in.rdbuf();
    return text.str();
  };

  write_chunks(0, 900);
  run_rpeak_until(900, "first.log");
  ASSERT_FALSE(HasFatalFailure());
  // Stopped and started again: the warm-up of 120 s agrees, and is all it reads.
  write_chunks(900, 1200);
  run_rpeak_until(1200, "second.log");
  ASSERT_FALSE(HasFatalFailure());
  const std::string second = log_of("second.log");
  EXPECT_NE(second.find("resumed at sample 324000 after reading 120 chunk(s) again from sample 280800"), std::string::npos) << second;

  // The item of chunk 1190 changed on the board (in the half of the warm-up it compares): no
  // warm-up agrees with it, so the agent reads further back and then replays the recording.
  const std::string tampered = agg::rpeaks_iri(kRecording, 1190 * fs);
  auto on_board = about(tampered);
  ASSERT_FALSE(on_board.empty());
  auto original = node_->snapshot()->item(on_board.front().meta.item);
  ASSERT_TRUE(original);
  auto changed = agg::read_rpeaks(*original);
  ASSERT_TRUE(changed) << changed.error().message;
  changed->peaks.push_back(1190 * fs + 5);
  ASSERT_TRUE(node_->remove_item(on_board.front().meta.item));
  auto writer = node_->agent("rpeak");
  ASSERT_TRUE(writer);
  tn::Item replaced = agg::rpeak_item(*changed);
  replaced.asserted_at = agg::signal_time_ns(info, 1190);
  ASSERT_TRUE(writer->store(replaced));
  write_chunks(1200, seconds);
  ASSERT_FALSE(HasFatalFailure());
  ASSERT_TRUE(ecg->store(agg::recording_end_item(kRecording, seconds * fs)));
  run_rpeak_until(seconds + 1, "third.log");
  ASSERT_FALSE(HasFatalFailure());
  const std::string third = log_of("third.log");
  EXPECT_NE(third.find("a warm-up from sample 388800 found other peaks than <" + tampered + "> on the board; reading further back"),
            std::string::npos)
      << third;
  EXPECT_NE(third.find("replayed 1200 earlier chunk(s) of <" + kRecording + "> from the board, up to sample 432000"),
            std::string::npos)
      << third;
  EXPECT_EQ(third.find("resumed at sample"), std::string::npos) << third;

  // Every item but the one changed is the uninterrupted detector's, each once.
  auto items = derived<agg::RPeaks>("rpeaks", agg::read_rpeaks);
  ASSERT_EQ(items.size(), static_cast<std::size_t>(seconds + 1));
  for (const auto& item : items) {
    const std::size_t k = item.end_sample ? want.size() - 1 : static_cast<std::size_t>(item.from_sample / fs);
    if (item.iri == tampered) continue;
    EXPECT_EQ(item.peaks, want[k]) << item.iri;
  }
}

// `--help` is how an operator finds an agent's flags: the usage on standard output, status 0
// (it used to be "unknown flag --help" and status 2).
TEST(AgentPrograms, HelpPrintsTheUsageOnStandardOutputAndExitsZero) {
  for (const std::string name : {"tahvel-ecg-source", "tahvel-rpeak", "tahvel-rr", "tahvel-hrv", "tahvel-trend",
                                 "tahvel-environment", "tahvel-env-motes"}) {
    FILE* out = popen((bin(name) + " --help 2>/dev/null").c_str(), "r");
    ASSERT_NE(out, nullptr);
    std::string text;
    char buffer[512];
    while (std::fgets(buffer, sizeof buffer, out)) text += buffer;
    const int status = pclose(out);
    EXPECT_EQ(status, 0) << name;
    EXPECT_EQ(text.rfind("usage: " + name + " DIR", 0), 0u) << name << ": " << text;
  }
}

// A flag given twice is a usage error naming it, as in `tahvel` (docs/cli.md, Conventions): the
// programs took the last value without a word (`--signal 1 --signal 0` recorded lead 0).
TEST(AgentPrograms, AFlagGivenTwiceIsAUsageErrorNamingIt) {
  for (const std::string name : {"tahvel-ecg-source", "tahvel-rpeak", "tahvel-rr", "tahvel-hrv", "tahvel-trend",
                                 "tahvel-environment", "tahvel-env-motes"}) {
    const std::string flag = name == "tahvel-env-motes" ? "--seed" : "--agent";  // one each program has
    FILE* out = popen((bin(name) + " /nonexistent " + flag + " 1 " + flag + " 2 2>&1").c_str(), "r");
    ASSERT_NE(out, nullptr);
    std::string text;
    char buffer[512];
    while (std::fgets(buffer, sizeof buffer, out)) text += buffer;
    const int status = pclose(out);
    EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 2) << name << ": " << text;
    EXPECT_NE(text.find(name + ": flag '" + flag + "' given twice"), std::string::npos) << name << ": " << text;
    // `--flag=VALUE` is the flag with its value, as `tahvel` reads it: refused as unknown up to
    // session 85, though docs/deploy.md named `--agent=ID` (an integrator's probe).
    FILE* attached = popen((bin(name) + " /nonexistent " + flag + "=1 " + flag + " 2 2>&1").c_str(), "r");
    ASSERT_NE(attached, nullptr);
    std::string said;
    while (std::fgets(buffer, sizeof buffer, attached)) said += buffer;
    pclose(attached);
    EXPECT_NE(said.find(name + ": flag '" + flag + "' given twice"), std::string::npos) << name << ": " << said;
  }
  // tahvel-trend's --metric is repeatable: the command line is taken (the store is what fails).
  FILE* out = popen((bin("tahvel-trend") + " /nonexistent --metric sdnnMs --metric rmssdMs 2>&1").c_str(), "r");
  ASSERT_NE(out, nullptr);
  std::string text;
  char buffer[512];
  while (std::fgets(buffer, sizeof buffer, out)) text += buffer;
  const int status = pclose(out);
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 1) << text;
  EXPECT_EQ(text.find("given twice"), std::string::npos) << text;
}

// The configuration of tahvel-hrv as an operator at the hospital sends it: a setting that is
// not a number of seconds (or under a millisecond, which made millions of windows out of one
// RR item) is logged and ignored; a valid one that a ring may reclaim (relayed items keep their
// flag) is kept by the agent as a persistent item of its own, so a restart still has it.
TEST(AgentPrograms, TheHrvConfigurationIsCheckedLoggedAndKeptPastTheRing) {
  char pattern[] = "/tmp/tahvel-agents-hrv-config-XXXXXX";
  ASSERT_NE(mkdtemp(pattern), nullptr);
  const std::string tmp = pattern, dir = tmp + "/home1", log = tmp + "/hrv.log";
  auto made = tn::Node::init(dir, tn::InitOptions{.iri = kNodeIri, .ring = 50});
  ASSERT_TRUE(made) << made.error().message;
  std::optional<tn::Node> node(std::move(*made));
  auto op = node->agent("operator");
  ASSERT_TRUE(op);
  const tn::Term hrv = tn::Term::iri(kNodeIri + "/hrv");
  const auto setting = [&](const char* value) {
    return tn::Item{}.add(hrv, agg::tv_term("windowSeconds"), tn::Term::literal(value));
  };
  ASSERT_TRUE(op->store(setting("120")));
  for (const char* bad : {"0", "-120", "2 minutes", "1e-7", "0x78", " 120"}) ASSERT_TRUE(op->store(setting(bad)));
  auto kept = [&] {
    auto records = node->snapshot()->list({.s = hrv, .p = agg::tv_term("windowSeconds")});
    for (const auto& r : *records)
      if (r.meta.persistent) return r.triple.o.value;
    return std::string();
  };
  {
    Process agent({bin("tahvel-hrv"), dir, "--idle", "30"}, log);
    const auto deadline = std::chrono::steady_clock::now() + 60s;
    while (kept().empty() && std::chrono::steady_clock::now() < deadline) std::this_thread::sleep_for(50ms);
    EXPECT_EQ(agent.stop(), 0);
  }
  EXPECT_EQ(kept(), "120") << "the setting in force, kept";
  // The ring reclaims the operator's settings; the kept one stays.
  auto noise = node->agent("noise");
  for (int i = 0; i < 100; ++i) ASSERT_TRUE(noise->store(tn::Item{}.add(tn::Term::iri(kNodeIri + "/x"), agg::tv_term("n"), tn::Term::integer(i))));
  EXPECT_EQ(node->snapshot()->list({.s = hrv, .p = agg::tv_term("windowSeconds")})->size(), 1u);
  EXPECT_EQ(kept(), "120");
  std::ifstream in(log);
  std::ostringstream text;
  text << in.rdbuf();
  for (const char* bad : {"'0'", "'-120'", "'2 minutes'", "'1e-7'", "'0x78'", "' 120'"})
    EXPECT_NE(text.str().find(std::string("windowSeconds ") + bad), std::string::npos) << bad << " not logged:\n" << text.str();
  EXPECT_NE(text.str().find("window 120.000000 s"), std::string::npos) << text.str();
  node.reset();
  fs::remove_all(tmp);
}

// What the agent `agent` says on the board of `node` is its problem ("": none).
std::string problem_of(tn::Node& node, const tn::Term& agent) {
  auto records = node.snapshot()->list({.s = agent, .p = tn::Term::iri(tn::kProblem), .source = agent.value});
  return records->empty() ? std::string() : records->front().triple.o.value;
}

// Whether the log file at `log` holds `line` (anywhere in it).
bool log_holds(const std::string& log, const std::string& line) {
  std::ifstream in(log);
  std::ostringstream text;
  text << in.rdbuf();
  return text.str().find(line) != std::string::npos;
}

// Whether `holds` comes true within a minute (an agent process answers in milliseconds).
bool within_a_minute(const std::function<bool()>& holds) {
  const auto deadline = std::chrono::steady_clock::now() + 60s;
  while (!holds() && std::chrono::steady_clock::now() < deadline) std::this_thread::sleep_for(20ms);
  return holds();
}

// A store of its own in a new temporary directory, for one agent program's test.
struct ScratchNode {
  std::string tmp, dir;
  std::optional<tn::Node> node;
  explicit ScratchNode(const std::string& name) {
    std::string pattern = "/tmp/tahvel-agents-" + name + "-XXXXXX";
    if (mkdtemp(pattern.data()) == nullptr) return;
    tmp = pattern;
    dir = tmp + "/home1";
    if (auto made = tn::Node::init(dir, tn::InitOptions{.iri = kNodeIri})) node.emplace(std::move(*made));
  }
  ~ScratchNode() {
    node.reset();
    if (!tmp.empty()) fs::remove_all(tmp);
  }
  // What the agent `agent_id` of this node says is its problem ("": none).
  std::string problem(const std::string& agent_id) { return problem_of(*node, tn::Term::iri(kNodeIri + "/" + agent_id)); }

  // The node's HRV agent, which tell_hrv's settings are about.
  const tn::Term hrv = tn::Term::iri(kNodeIri + "/hrv");
  // Stores settings of the HRV agent (tv:windowSeconds, tv:stepSeconds) in one item, as an
  // operator of this node would; false when the store refused them.
  bool tell_hrv(std::initializer_list<std::pair<const char*, tn::Term>> settings) {
    auto op = node->agent("operator");
    if (!op) return false;
    tn::Item item;
    for (const auto& [setting, value] : settings) item.add(hrv, agg::tv_term(setting), value);
    return op->store(item).has_value();
  }
};

// kRecording's description at 250 Hz, as the problem tests' ECG source states it.
agg::RecordingInfo recording_at_250_hz() {
  agg::RecordingInfo info;
  info.iri = kRecording;
  info.sensor_iri = kNodeIri + "/ecg";
  info.fs = 250;
  return info;
}

// A setting taken back (removed) leaves --window in force again at once, not the value it had
// set until the next restart; on a store with a ring, the copy the agent kept of it goes too.
TEST(AgentPrograms, AnHrvSettingRemovedGivesBackTheCommandLinesWindow) {
  for (const std::uint64_t ring : {std::uint64_t{0}, std::uint64_t{50}}) {
    SCOPED_TRACE("ring " + std::to_string(ring));
    char pattern[] = "/tmp/tahvel-agents-hrv-removed-XXXXXX";
    ASSERT_NE(mkdtemp(pattern), nullptr);
    const std::string tmp = pattern, dir = tmp + "/home1", log = tmp + "/hrv.log";
    auto made = tn::Node::init(dir, tn::InitOptions{.iri = kNodeIri, .ring = ring});
    ASSERT_TRUE(made) << made.error().message;
    std::optional<tn::Node> node(std::move(*made));
    const tn::Term hrv = tn::Term::iri(kNodeIri + "/hrv");
    auto logged = [&](const std::string& line) { return log_holds(log, line); };
    {
      Process agent({bin("tahvel-hrv"), dir, "--window", "30", "--idle", "30"}, log);
      ASSERT_TRUE(node->agent("operator")->store(tn::Item{}.add(hrv, agg::tv_term("windowSeconds"), tn::Term::integer(60))));
      ASSERT_TRUE(within_a_minute([&] { return logged("window 60.000000 s"); }));
      ASSERT_TRUE(node->remove({.s = hrv, .p = agg::tv_term("windowSeconds"), .source = kNodeIri + "/operator"}));
      EXPECT_TRUE(within_a_minute([&] { return logged("window 30.000000 s"); })) << "the removed setting still stands";
      EXPECT_EQ(node->snapshot()->count({.s = hrv, .p = agg::tv_term("windowSeconds")}).value(), 0u) << "a kept copy is left";
      EXPECT_EQ(agent.stop(), 0);
    }
    node.reset();
    fs::remove_all(tmp);
  }
}

// Two processes of one stage under one agent id shared its input as a pool of takers: each saw
// half of every recording and wrote wrong R-peaks, intervals and windows, some twice. The second
// is refused, naming the agent; once the first has ended, the id is free again.
TEST(AgentPrograms, ASecondProcessOfAnAgentIdIsRefusedWhileTheFirstRuns) {
  ScratchNode scratch("one-per-id");
  ASSERT_TRUE(scratch.node) << "cannot make a store under /tmp";
  const std::string lock = scratch.dir + "/.agent-rpeak.lock";
  auto held = [&] {
    const int fd = ::open(lock.c_str(), O_RDWR | O_CLOEXEC);
    if (fd < 0) return false;
    const bool locked = ::flock(fd, LOCK_EX | LOCK_NB) != 0;
    ::close(fd);
    return locked;
  };
  Process first({bin("tahvel-rpeak"), scratch.dir, "--idle", "60"}, scratch.tmp + "/first.log");
  ASSERT_TRUE(within_a_minute(held)) << "the first never held " << lock;
  {
    Process second({bin("tahvel-rpeak"), scratch.dir, "--idle", "60"}, scratch.tmp + "/second.log");
    EXPECT_NE(second.wait(60s), 0);
  }
  std::ifstream in(scratch.tmp + "/second.log");
  std::ostringstream text;
  text << in.rdbuf();
  EXPECT_NE(text.str().find("another process runs as agent <" + kNodeIri + "/rpeak>"), std::string::npos) << text.str();
  EXPECT_EQ(first.poll(), -1) << "the first stopped";
  EXPECT_EQ(first.stop(), 0);
  Process again({bin("tahvel-rpeak"), scratch.dir, "--idle", "60"}, scratch.tmp + "/again.log");
  EXPECT_TRUE(within_a_minute(held)) << "the id stayed taken after the first ended";
  EXPECT_EQ(again.stop(), 0);
}

// A topology file may spell a node's IRI with an upper-case host; the node's IRI, and its
// agents', are in normal form. A setting written for <HTTP://EXAMPLE.ORG/home1/hrv> reached the
// HRV agent and was read by none: the window stayed as it was, and nothing said so.
TEST(AgentPrograms, AnHrvSettingForTheAgentsIriInAnotherSpellingIsItsSetting) {
  ScratchNode scratch("hrv-spelling");
  ASSERT_TRUE(scratch.node) << "cannot make a store under /tmp";
  const std::string log = scratch.tmp + "/hrv.log";
  auto logged = [&](const std::string& line) { return log_holds(log, line); };
  ASSERT_EQ(kNodeIri.rfind("http://example.org/", 0), 0u);
  const tn::Term spelt = tn::Term::iri("HTTP://Example.ORG/" + kNodeIri.substr(19) + "/hrv");
  Process agent({bin("tahvel-hrv"), scratch.dir, "--idle", "30", "--window", "60"}, log);
  ASSERT_TRUE(scratch.node->agent("operator")->store(tn::Item{}.add(spelt, agg::tv_term("windowSeconds"), tn::Term::integer(90))));
  EXPECT_TRUE(within_a_minute([&] { return logged("window 90.000000 s"); })) << "the setting was not read";
  // Another agent's setting is not this one's.
  ASSERT_TRUE(scratch.node->agent("operator")->store(
      tn::Item{}.add(tn::Term::iri(kNodeIri + "/hrv2"), agg::tv_term("windowSeconds"), tn::Term::integer(120))));
  ASSERT_TRUE(scratch.node->agent("operator")->store(tn::Item{}.add(spelt, agg::tv_term("stepSeconds"), tn::Term::integer(45))));
  ASSERT_TRUE(within_a_minute([&] { return logged("step 45.000000 s"); }));
  EXPECT_FALSE(logged("window 120.000000 s")) << "another agent's setting was taken";
  EXPECT_EQ(agent.stop(), 0);
}

// The setting written last holds, wherever it was written and whenever it arrives: a hospital's
// setting held back by a cut link (asserted before the home's own, arriving after it) undid the
// home's newer one when the link came back.
TEST(AgentPrograms, TheHrvSettingWrittenLastHoldsWhicheverArrivesLast) {
  ScratchNode scratch("hrv-latest");
  ASSERT_TRUE(scratch.node) << "cannot make a store under /tmp";
  const tn::Term hrv = tn::Term::iri(kNodeIri + "/hrv");
  const std::string log = scratch.tmp + "/hrv.log";
  auto logged = [&](const std::string& line) { return log_holds(log, line); };
  const std::int64_t now = std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch()).count();
  Process agent({bin("tahvel-hrv"), scratch.dir, "--idle", "30"}, log);
  tn::Item home = tn::Item{}.add(hrv, agg::tv_term("windowSeconds"), tn::Term::integer(200));
  home.asserted_at = now;
  ASSERT_TRUE(scratch.node->agent("operator")->store(home));
  ASSERT_TRUE(within_a_minute([&] { return logged("window 200.000000 s"); }));
  tn::Item hospital = tn::Item{}.add(hrv, agg::tv_term("windowSeconds"), tn::Term::integer(100));
  hospital.asserted_at = now - 1'000'000'000;
  hospital.context = hrv.value;
  ASSERT_TRUE(scratch.node->agent("uplink")->store(hospital));
  tn::Item marker = tn::Item{}.add(hrv, agg::tv_term("stepSeconds"), tn::Term::integer(50));
  ASSERT_TRUE(scratch.node->agent("operator")->store(marker));
  ASSERT_TRUE(within_a_minute([&] { return logged("step 50.000000 s"); })) << "the agent did not read its settings again";
  EXPECT_FALSE(logged("window 100.000000 s")) << "the older setting, arriving later, took over";
  EXPECT_EQ(agent.stop(), 0);
}

// A setting the agent cannot use is its problem on its board (for `tahvel status`, here and at
// the hospital that sent it) until a usable one follows; the problem is over then.
TEST(AgentPrograms, AnHrvSettingItCannotUseIsItsProblemOnTheBoardUntilAUsableOneFollows) {
  ScratchNode scratch("hrv-problem");
  ASSERT_TRUE(scratch.node) << "cannot make a store under /tmp";
  const std::string &tmp = scratch.tmp, &dir = scratch.dir;
  std::optional<tn::Node>& node = scratch.node;
  const tn::Term& hrv = scratch.hrv;
  ASSERT_TRUE(scratch.tell_hrv({{"windowSeconds", tn::Term::literal("2 minutes")}}));
  auto problem = [&] { return scratch.problem("hrv"); };
  const auto& eventually = within_a_minute;
  {
    Process agent({bin("tahvel-hrv"), dir, "--idle", "30"}, tmp + "/hrv.log");
    ASSERT_TRUE(eventually([&] { return !problem().empty(); })) << "no problem on the board";
    EXPECT_NE(problem().find("windowSeconds '2 minutes'"), std::string::npos) << problem();
    EXPECT_NE(problem().find("the value before it stands"), std::string::npos) << problem();
    EXPECT_EQ(node->snapshot()->count({.s = hrv, .p = tn::Term::iri(tn::kProblemPid)}).value(), 1u);
    ASSERT_TRUE(scratch.tell_hrv({{"windowSeconds", tn::Term::integer(120)}}));
    EXPECT_TRUE(eventually([&] { return problem().empty(); })) << "still: " << problem();
    // Another unusable setting, then taken back: the problem comes and goes with it.
    ASSERT_TRUE(scratch.tell_hrv({{"stepSeconds", tn::Term::literal("-1")}}));
    ASSERT_TRUE(eventually([&] { return problem().find("stepSeconds '-1'") != std::string::npos; })) << problem();
    ASSERT_TRUE(node->remove({.s = hrv, .p = agg::tv_term("stepSeconds")}));
    EXPECT_TRUE(eventually([&] { return problem().empty(); })) << "still: " << problem();
    EXPECT_EQ(agent.stop(), 0);
  }
  EXPECT_EQ(node->snapshot()->count({.s = hrv, .p = tn::Term::iri(tn::kProblemPid)}).value(), 0u);
}

// A setting relayed from a hospital whose clock is ahead, on a store whose retention could take
// it: the agent keeps one persistent copy of it. The copy was stamped now, before the setting,
// which stayed the latest and reclaimable, and each copy, delivered back to the agent, made
// another: 4,072 copies in 15 s of a clock 15 s ahead (a review of session 85).
TEST(AgentPrograms, ASettingFromAClockAheadIsKeptOnceNotOverAndOver) {
  ScratchNode scratch("hrv-ahead");
  ASSERT_TRUE(scratch.node) << "cannot make a store under /tmp";
  ASSERT_TRUE(scratch.node->set_ttl(std::string(agg::kTv) + "windowSeconds", std::chrono::hours(1)));
  const std::int64_t now = std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch()).count();
  tn::Item ahead = tn::Item{}.add(scratch.hrv, agg::tv_term("windowSeconds"), tn::Term::integer(120));
  ahead.asserted_at = now + 20'000'000'000;
  ahead.context = scratch.hrv.value;
  ASSERT_TRUE(scratch.node->agent("uplink")->store(ahead));
  const std::string log = scratch.tmp + "/hrv.log";
  Process agent({bin("tahvel-hrv"), scratch.dir, "--idle", "30"}, log);
  ASSERT_TRUE(within_a_minute([&] { return log_holds(log, "window 120.000000 s"); }));
  std::this_thread::sleep_for(3s);
  auto kept = scratch.node->snapshot()->count({.s = scratch.hrv, .p = agg::tv_term("windowSeconds"), .source = kNodeIri + "/hrv"});
  ASSERT_TRUE(kept);
  EXPECT_EQ(*kept, 1u) << "copies of the setting kept";
  EXPECT_EQ(agent.stop(), 0);
}

// RR items written as tahvel-rr writes them (asserted at the signal time of their first
// interval), for a recording at 360 Hz: one item per second of beat starts, one interval of
// `long_from` to `long_to` s (no beat between: a flat signal for minutes) if given.
struct RrLayout {
  agg::RecordingInfo info;
  std::vector<agg::RrSeries> items;
  tn::Item end;
  explicit RrLayout(double seconds, double long_from = -1, double long_to = -1) {
    info.iri = kRecording;
    info.sensor_iri = kNodeIri + "/ecg";
    info.fs = 360;
    info.started_at = std::int64_t{1'796'000'000} * 1'000'000'000;
    std::vector<agg::Interval> intervals;
    bool long_done = long_from < 0;
    for (std::int64_t at = 0, next = 0; at < static_cast<std::int64_t>(seconds * 360); at = next) {
      const bool long_one = !long_done && at >= static_cast<std::int64_t>(long_from * 360);
      long_done = long_done || long_one;
      next = long_one ? static_cast<std::int64_t>(long_to * 360) : at + 288;  // 0.8 s
      intervals.push_back({at, next, !long_one});
    }
    for (const agg::Interval& iv : intervals) {
      if (items.empty() || iv.start / 360 != items.back().intervals.front().start / 360) {
        items.emplace_back();
        items.back().recording = kRecording;
      }
      items.back().intervals.push_back(iv);
    }
    agg::RrSeries ends;
    ends.recording = kRecording;
    ends.end_sample = intervals.back().end;
    end = agg::rr_item(ends);
    end.asserted_at = agg::signal_time_ns(info, static_cast<double>(*ends.end_sample) / 360);
  }
  tn::Item item(std::size_t i) const {
    tn::Item out = agg::rr_item(items[i]);
    out.asserted_at = agg::signal_time_ns(info, static_cast<double>(items[i].intervals.front().start) / 360);
    return out;
  }
};

// Every HRV window on the board: its IRI and its tv: triples.
std::map<std::string, std::multiset<std::string>> windows_on(const tn::Node& node) {
  std::map<std::string, std::multiset<std::string>> out;
  auto starts = node.snapshot()->list({.p = agg::tv_term("windowStartS")});
  EXPECT_TRUE(starts);
  for (const tn::Record& r : *starts)
    for (const tn::Record& e : *node.snapshot()->list({.s = r.triple.s}))
      if (e.triple.p.value.starts_with(agg::kTv)) out[r.triple.s.value].insert(e.triple.p.value + " " + e.triple.o.to_ntriples());
  return out;
}

// tahvel-hrv restarted within a recording reads its RR items from shortly before its next
// window, and gives the windows an uninterrupted run gives: also when an interval began before
// that (a flat signal for minutes: the first read found nothing and the window lost the gap),
// and when the board holds an RR item twice (read twice, it counted its intervals twice; both
// found by a review of session 86).
TEST(AgentPrograms, AnHrvAgentRestartedGivesTheWindowsOfAnUninterruptedRun) {
  struct Case {
    const char* name;
    RrLayout layout;
    double first_run_until_s;        // RR items starting before this are there for the first run
    std::vector<double> held_twice;  // items (by their start, s) stored twice, before the first run
  };
  const Case cases[] = {{"long interval", RrLayout(3000, 1250, 2250.4), 1250.5, {}},
                        {"items twice", RrLayout(3000), 2250, {2150, 2151, 2152, 2153, 2154}}};
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    ScratchNode whole("hrv-whole"), restarted("hrv-restarted");
    ASSERT_TRUE(whole.node && restarted.node);
    for (ScratchNode* scratch : {&whole, &restarted}) ASSERT_TRUE(scratch->node->agent("ecg")->store(agg::recording_item(c.layout.info)));
    auto rr_whole = whole.node->agent("rr").value();
    auto rr = restarted.node->agent("rr").value();
    for (std::size_t i = 0; i < c.layout.items.size(); ++i) ASSERT_TRUE(rr_whole.store(c.layout.item(i)));
    ASSERT_TRUE(rr_whole.store(c.layout.end));
    const auto run_hrv = [](ScratchNode& scratch) {
      Process agent({bin("tahvel-hrv"), scratch.dir, "--idle", "2", "--window", "300"}, scratch.tmp + "/hrv.log");
      return agent.wait(60s);
    };
    ASSERT_EQ(run_hrv(whole), 0);
    // The restarted one: subscribed first, then the first part (and the items held twice), a
    // run, the rest, a second run.
    ASSERT_EQ(run_hrv(restarted), 0);
    std::size_t i = 0;
    for (; i < c.layout.items.size() && c.layout.items[i].intervals.front().start < c.first_run_until_s * 360; ++i) {
      ASSERT_TRUE(rr.store(c.layout.item(i)));
      for (double twice : c.held_twice)
        if (c.layout.items[i].intervals.front().start / 360 == static_cast<std::int64_t>(twice)) ASSERT_TRUE(rr.store(c.layout.item(i)));
    }
    ASSERT_EQ(run_hrv(restarted), 0);
    const std::size_t written_before = windows_on(*restarted.node).size();
    EXPECT_GE(written_before, 3u);
    for (; i < c.layout.items.size(); ++i) ASSERT_TRUE(rr.store(c.layout.item(i)));
    ASSERT_TRUE(rr.store(c.layout.end));
    ASSERT_EQ(run_hrv(restarted), 0);
    const auto want = windows_on(*whole.node), got = windows_on(*restarted.node);
    EXPECT_GE(want.size(), 10u);
    std::ostringstream log;
    log << std::ifstream(restarted.tmp + "/hrv.log").rdbuf();
    EXPECT_EQ(got, want) << "the restarted agent's log:\n" << log.str();
  }
}

// What a setting came to is on the board, for whoever sent it to read (from the hospital too,
// with `tahvel query --at`): the window and step in force, once, the latest only. The settings
// sent were all there in the order they came, and which stood (the latest written, or the one
// before when the latest cannot be used) was in the agent's log alone (an exploratory run of
// session 85).
TEST(AgentPrograms, TheHrvWindowAndStepInForceAreOnTheBoard) {
  ScratchNode scratch("hrv-in-force");
  ASSERT_TRUE(scratch.node) << "cannot make a store under /tmp";
  const tn::Term& hrv = scratch.hrv;
  auto in_force = [&](const char* predicate) -> std::string {
    auto snapshot = scratch.node->snapshot();
    if (!snapshot) return "no snapshot";
    auto records = snapshot->list({.s = hrv, .p = agg::tv_term(predicate)});
    if (!records) return "unreadable";
    if (records->size() != 1) return std::to_string(records->size()) + " records";
    return records->front().triple.o.value;
  };
  Process agent({bin("tahvel-hrv"), scratch.dir, "--idle", "30", "--window", "60"}, scratch.tmp + "/hrv.log");
  EXPECT_TRUE(within_a_minute([&] { return in_force("windowSecondsInForce") == "60" && in_force("stepSecondsInForce") == "60"; }))
      << in_force("windowSecondsInForce") << " / " << in_force("stepSecondsInForce");
  ASSERT_TRUE(scratch.tell_hrv({{"windowSeconds", tn::Term::integer(120)}, {"stepSeconds", tn::Term::integer(30)}}));
  EXPECT_TRUE(within_a_minute([&] { return in_force("windowSecondsInForce") == "120" && in_force("stepSecondsInForce") == "30"; }))
      << in_force("windowSecondsInForce") << " / " << in_force("stepSecondsInForce");
  // One it cannot use: the one before stands, and the board says so.
  ASSERT_TRUE(scratch.tell_hrv({{"windowSeconds", tn::Term::literal("2 minutes")}}));
  ASSERT_TRUE(within_a_minute([&] { return !scratch.problem("hrv").empty(); }));
  EXPECT_EQ(in_force("windowSecondsInForce"), "120");
  EXPECT_EQ(agent.stop(), 0);
}

// The whole of the file at `path` (an agent's log); "" when it cannot be read.
std::string text_of(const std::string& path) {
  std::ifstream in(path);
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

// A day's window sent down over the step of a minute's (each usable alone) made the agent lay
// 1,440 windows over each moment, and with a second's step 86,400, each computed whole: it
// would fall behind for good. The pair is refused as `tahvel hrv` refuses it, the window and
// step before standing, until a pair that fits follows.
TEST(AgentPrograms, AnHrvWindowAndStepThatLayTooManyWindowsOverAMomentAreRefusedTogether) {
  ScratchNode scratch("hrv-pair");
  ASSERT_TRUE(scratch.node) << "cannot make a store under /tmp";
  ASSERT_TRUE(scratch.tell_hrv({{"stepSeconds", tn::Term::integer(1)}}));
  ASSERT_TRUE(scratch.tell_hrv({{"windowSeconds", tn::Term::integer(86400)}}));
  auto problem = [&] { return scratch.problem("hrv"); };
  const std::string log = scratch.tmp + "/hrv.log";
  {
    Process agent({bin("tahvel-hrv"), scratch.dir, "--idle", "30", "--window", "60"}, log);
    ASSERT_TRUE(within_a_minute([&] { return !problem().empty(); })) << "no problem on the board";
    EXPECT_NE(problem().find("a window of 86400 s stepped by 1 s lays 86400 windows over each moment of signal, at most 3600"),
              std::string::npos) << problem();
    // The last pair the settings made that could be used: the flag's window, the board's step.
    EXPECT_NE(problem().find("ignored, the window (60 s) and step (1 s) before stand"), std::string::npos) << problem();
    EXPECT_EQ(agent.stop(), 0);
  }
  {  // Restarted, it runs what it ran before: the board decides, not what the process had.
    Process agent({bin("tahvel-hrv"), scratch.dir, "--idle", "30", "--window", "60"}, log);
    ASSERT_TRUE(within_a_minute([&] { return problem().find("before stand") != std::string::npos; })) << problem();
    EXPECT_NE(problem().find("ignored, the window (60 s) and step (1 s) before stand"), std::string::npos) << problem();
    ASSERT_TRUE(scratch.tell_hrv({{"stepSeconds", tn::Term::integer(60)}}));
    EXPECT_TRUE(within_a_minute([&] { return problem().empty(); })) << "still: " << problem();
    EXPECT_EQ(agent.stop(), 0);
  }
  const std::string said = text_of(log);
  EXPECT_NE(said.find("lays 86400 windows over each moment"), std::string::npos) << said;
  EXPECT_NE(said.find("window 86400.000000 s, step 60.000000 s"), std::string::npos) << said;
}

// A window or step from the board (the hospital may send it) that is too short for HRV is
// refused with its reason and the bounds, on the board and in the log, and the agent runs on
// with the setting before it: a window of 0.5 s or a step of 0.01 s was taken, and made a
// window item per step out of every RR item.
TEST(AgentPrograms, AnHrvWindowOrStepTooShortForHrvIsRefusedWithTheBoundsAndTheAgentRunsOn) {
  ScratchNode scratch("hrv-short");
  ASSERT_TRUE(scratch.node) << "cannot make a store under /tmp";
  ASSERT_TRUE(scratch.tell_hrv({{"windowSeconds", tn::Term::literal("0.5")}, {"stepSeconds", tn::Term::literal("0.01")}}));
  auto problem = [&] { return scratch.problem("hrv"); };
  const std::string log = scratch.tmp + "/hrv.log";
  {
    Process agent({bin("tahvel-hrv"), scratch.dir, "--idle", "30", "--window", "60"}, log);
    ASSERT_TRUE(within_a_minute([&] { return problem().find("windowSeconds '0.5'") != std::string::npos; })) << problem();
    EXPECT_NE(problem().find("must be a number of seconds in [10, 86400]"), std::string::npos) << problem();
    EXPECT_NE(problem().find("stepSeconds '0.01'"), std::string::npos) << problem();
    EXPECT_NE(problem().find("must be a number of seconds in [1, 86400]"), std::string::npos) << problem();
    EXPECT_EQ(agent.stop(), 0) << "the agent did not run on";
  }
  EXPECT_NE(text_of(log).find("windowSeconds '0.5'"), std::string::npos) << text_of(log);
  // The same bounds on its command line.
  Process flag({bin("tahvel-hrv"), scratch.dir, "--window", "5"}, scratch.tmp + "/flag.log");
  ASSERT_TRUE(within_a_minute([&] { return flag.poll() >= 0; })) << "--window 5 was taken";
  EXPECT_NE(flag.poll(), 0);
  const std::string said = text_of(scratch.tmp + "/flag.log");
  EXPECT_NE(said.find("--window: must be a number of seconds in [10, 86400]"), std::string::npos) << said;
  // A step of 0 given is refused too (without --step, the step is the window): it was taken.
  Process zero_step({bin("tahvel-hrv"), scratch.dir, "--step", "0"}, scratch.tmp + "/zero_step.log");
  ASSERT_TRUE(within_a_minute([&] { return zero_step.poll() >= 0; })) << "--step 0 was taken";
  EXPECT_EQ(zero_step.poll(), 2);
  const std::string zero_said = text_of(scratch.tmp + "/zero_step.log");
  EXPECT_NE(zero_said.find("--step: must be a number of seconds in [1, 86400] (at most one window per second of signal), got 0"), std::string::npos) << zero_said;
}

// A recording whose chunks tahvel-rpeak cannot use gives no HRV anywhere: the agent says why on
// its board (for `tahvel status`) while it skips them, and the problem is over once a chunk of
// the recording is used, or its end comes.
TEST(AgentPrograms, ARecordingTheRPeakAgentCannotUseIsItsProblemWhileItsChunksAreSkipped) {
  ScratchNode scratch("rpeak-problem");
  ASSERT_TRUE(scratch.node) << "cannot make a store under /tmp";
  std::optional<tn::Node>& node = scratch.node;
  auto ecg = node->agent("ecg");
  ASSERT_TRUE(ecg);
  auto problem = [&] { return scratch.problem("rpeak"); };
  const auto& eventually = within_a_minute;
  agg::RecordingInfo info = recording_at_250_hz();
  info.gain = 200;
  const std::vector<std::vector<std::int32_t>> flat(1, std::vector<std::int32_t>(250 * 4, 0));
  auto chunk = [&](int second) { return agg::ecg_chunk_item(info, second * 250, flat, static_cast<std::size_t>(second * 250), 250); };
  {
    // A problem an earlier run left on the board is over when the agent starts again.
    ASSERT_TRUE(node->agent("rpeak")->report_problem("left by an earlier run"));
    Process agent({bin("tahvel-rpeak"), scratch.dir, "--idle", "30"}, scratch.tmp + "/rpeak.log");
    ASSERT_TRUE(eventually([&] { return problem().empty(); })) << "still: " << problem();
    // Chunks come before their recording's description: nothing says what their samples are.
    ASSERT_TRUE(ecg->store(chunk(0)));
    ASSERT_TRUE(eventually([&] { return !problem().empty(); })) << "no problem on the board";
    EXPECT_NE(problem().find("no recording item <" + kRecording + ">"), std::string::npos) << problem();
    EXPECT_NE(problem().find("its ECG chunks are skipped"), std::string::npos) << problem();
    // The description comes; the next chunk is used and the problem is over.
    ASSERT_TRUE(ecg->store(agg::recording_item(info)));
    ASSERT_TRUE(ecg->store(chunk(1)));
    EXPECT_TRUE(eventually([&] { return problem().empty(); })) << "still: " << problem();
    EXPECT_TRUE(eventually([&] { return node->snapshot()->count({.s = tn::Term::iri(agg::rpeaks_iri(kRecording, 250))}).value() > 0; }))
        << "the chunk after the description was used";
    // A second recording with a gain the detector cannot take: a problem until its end.
    agg::RecordingInfo zero_gain = info;
    zero_gain.iri = kRecording + "-b";
    zero_gain.gain = 0;  // a negative one is a lead upside down, which it takes
    ASSERT_TRUE(ecg->store(agg::recording_item(zero_gain)));
    ASSERT_TRUE(ecg->store(agg::ecg_chunk_item(zero_gain, 0, flat, 0, 250)));
    ASSERT_TRUE(eventually([&] { return problem().find("<" + zero_gain.iri + ">") != std::string::npos; })) << problem();
    EXPECT_NE(problem().find("gain"), std::string::npos) << problem();
    ASSERT_TRUE(ecg->store(agg::recording_end_item(zero_gain.iri, 250)));
    EXPECT_TRUE(eventually([&] { return problem().empty(); })) << "still: " << problem();
    EXPECT_EQ(agent.stop(), 0);
  }
}

// A recording whose signal has no beat (a lead off from the start, a gain in its description
// off by a hundred, a channel that is not an ECG) gave R-peak items without peaks, so no RR and
// no HRV, and no word anywhere: the operator could not tell it from no patient at all (a probe).
// Twelve seconds of signal without a beat are the R-peak agent's problem, said once in its log,
// until a beat is found; a line per chunk was not written for it.
TEST(AgentPrograms, ASignalWithoutBeatsIsTheRPeakAgentsProblemUntilABeatIsFound) {
  agg::SyntheticEcgOptions options;
  options.fs = 250;
  options.adc_zero = 0;
  auto beating = agg::synthetic_ecg(40, options);
  ScratchNode scratch("rpeak-silent");
  ASSERT_TRUE(scratch.node) << "cannot make a store under /tmp";
  auto ecg = scratch.node->agent("ecg");
  ASSERT_TRUE(ecg);
  auto problem = [&] { return scratch.problem("rpeak"); };
  agg::RecordingInfo info = recording_at_250_hz();
  info.gain = options.gain;
  ASSERT_TRUE(beating) << beating.error().message;
  std::vector<std::int32_t> signal(250 * 20, 0);  // 20 s flat, then 40 s of ECG
  signal.insert(signal.end(), beating->begin(), beating->end());
  const std::vector<std::vector<std::int32_t>> leads(1, signal);
  auto chunk = [&](int second) { return agg::ecg_chunk_item(info, second * 250, leads, static_cast<std::size_t>(second * 250), 250); };
  const std::string log = scratch.tmp + "/rpeak.log";
  Process agent({bin("tahvel-rpeak"), scratch.dir, "--idle", "30"}, log);
  ASSERT_TRUE(ecg->store(agg::recording_item(info)));
  for (int second = 0; second < 20; ++second) ASSERT_TRUE(ecg->store(chunk(second)));
  ASSERT_TRUE(within_a_minute([&] { return problem().find("no beat found") != std::string::npos; })) << "no problem: " << problem();
  EXPECT_NE(problem().find("<" + kRecording + ">"), std::string::npos) << problem();
  EXPECT_NE(problem().find("no R-peaks, RR intervals or HRV come of it"), std::string::npos) << problem();
  for (int second = 20; second < 60; ++second) ASSERT_TRUE(ecg->store(chunk(second)));
  EXPECT_TRUE(within_a_minute([&] { return problem().empty(); })) << "still: " << problem();
  EXPECT_EQ(agent.stop(), 0);
  std::ifstream in(log);
  std::ostringstream text;
  text << in.rdbuf();
  std::size_t lines = 0;
  for (std::size_t at = text.str().find("no beat found"); at != std::string::npos; at = text.str().find("no beat found", at + 1)) ++lines;
  EXPECT_EQ(lines, 1u) << text.str();
}

// R-peak items tahvel-rr cannot use give no RR and no HRV: a recording without its description,
// or items it cannot read (a detector of another version). Each is its problem on the board
// while such items are skipped: the recording's until it is used, the writer's until an item
// of that writer is read.
TEST(AgentPrograms, RPeakItemsTheRrAgentCannotUseAreItsProblemWhileTheyAreSkipped) {
  ScratchNode scratch("rr-problem");
  ASSERT_TRUE(scratch.node) << "cannot make a store under /tmp";
  std::optional<tn::Node>& node = scratch.node;
  auto rpeak = node->agent("rpeak");
  auto other_detector = node->agent("detector2");
  ASSERT_TRUE(rpeak && other_detector);
  const tn::Term rr = tn::Term::iri(kNodeIri + "/rr");
  auto problem = [&] { return scratch.problem("rr"); };
  const auto& eventually = within_a_minute;
  agg::RecordingInfo info = recording_at_250_hz();
  // Beats a second apart over [from, to), the last item of the recording when `end`.
  auto peaks = [](const std::string& recording, std::int64_t from, std::int64_t to, bool end) {
    agg::RPeaks p;
    p.recording = recording;
    p.from_sample = from;
    p.to_sample = to;
    for (std::int64_t at = from + 100; at < to; at += 250) p.peaks.push_back(at);
    p.derived_from = recording;
    if (end) p.end_sample = to;
    return agg::rpeak_item(p);
  };
  auto intervals_of = [&](const std::string& recording) {  // an RR item of the recording
    for (const auto& r : node->snapshot()->list({.p = agg::tv_term("intervals"), .source = rr.value}).value())
      if (r.triple.s.value.rfind(recording + "/rr/", 0) == 0) return true;
    return false;
  };
  {
    ASSERT_TRUE(node->agent("rr")->report_problem("left by an earlier run"));
    Process agent({bin("tahvel-rr"), scratch.dir, "--idle", "30"}, scratch.tmp + "/rr.log");
    ASSERT_TRUE(eventually([&] { return problem().empty(); })) << "still: " << problem();
    // R-peaks before their recording's description: nothing says the sampling rate.
    ASSERT_TRUE(rpeak->store(peaks(kRecording, 0, 2500, false)));
    ASSERT_TRUE(eventually([&] { return !problem().empty(); })) << "no problem on the board";
    EXPECT_NE(problem().find("no recording item <" + kRecording + ">"), std::string::npos) << problem();
    EXPECT_NE(problem().find("its R-peak items are skipped"), std::string::npos) << problem();
    // The description comes; the next item is used (the first replayed from the board) and
    // the problem is over.
    ASSERT_TRUE(rpeak->store(agg::recording_item(info)));
    ASSERT_TRUE(rpeak->store(peaks(kRecording, 2500, 5000, true)));
    EXPECT_TRUE(eventually([&] { return problem().empty(); })) << "still: " << problem();
    EXPECT_TRUE(eventually([&] { return intervals_of(kRecording); })) << "no RR item of the recording";
    // An item another detector writes that this one cannot read names that writer.
    const tn::Term odd = tn::Term::iri(kRecording + "/rpeaks/odd");
    ASSERT_TRUE(other_detector->store(tn::Item{}
                                          .add(odd, agg::tv_term("peaks"), tn::Term::literal("100 350 six hundred"))
                                          .add(odd, agg::tv_term("recording"), tn::Term::iri(kRecording))));
    ASSERT_TRUE(eventually([&] { return problem().find("<" + other_detector->iri() + ">") != std::string::npos; })) << problem();
    EXPECT_NE(problem().find("cannot read"), std::string::npos) << problem();
    // A readable item of that writer: the problem is over.
    agg::RecordingInfo second = info;
    second.iri = kRecording + "-b";
    ASSERT_TRUE(other_detector->store(agg::recording_item(second)));
    ASSERT_TRUE(other_detector->store(peaks(second.iri, 0, 2500, true)));
    EXPECT_TRUE(eventually([&] { return problem().empty(); })) << "still: " << problem();
    EXPECT_TRUE(eventually([&] { return intervals_of(second.iri); })) << "no RR item of the second recording";
    EXPECT_EQ(agent.stop(), 0);
  }
}

// An HRV window tahvel-trend cannot read (a home whose HRV agent is of another version) gives
// no trend of that patient at the hospital: the writer is named in the agent's problem on the
// board until a window of that writer is read.
TEST(AgentPrograms, HrvWindowsTheTrendAgentCannotReadAreItsProblemUntilTheirWriterSendsOneItCan) {
  ScratchNode scratch("trend-problem");
  ASSERT_TRUE(scratch.node) << "cannot make a store under /tmp";
  std::optional<tn::Node>& node = scratch.node;
  auto home_hrv = node->agent("hrv");
  ASSERT_TRUE(home_hrv);
  auto problem = [&] { return scratch.problem("trend"); };
  const auto& eventually = within_a_minute;
  agg::RecordingInfo info = recording_at_250_hz();
  agg::WindowMetrics window;
  window.start_s = 0;
  window.end_s = 60;
  window.metrics.sdnn_ms = 42;
  tn::Item unreadable = agg::hrv_window_item(info, window, home_hrv->iri());
  std::erase_if(unreadable.triples, [](const tn::Triple& t) { return t.p.value == std::string(agg::kTv) + "windowStartS"; });
  // Stored before the agent starts: its catch-up reads it from the board.
  ASSERT_TRUE(home_hrv->store(unreadable));
  {
    Process agent({bin("tahvel-trend"), scratch.dir, "--idle", "30"}, scratch.tmp + "/trend.log");
    ASSERT_TRUE(eventually([&] { return problem().find("<" + home_hrv->iri() + ">") != std::string::npos; })) << problem();
    EXPECT_NE(problem().find("windowStartS"), std::string::npos) << problem();
    EXPECT_NE(problem().find("cannot read"), std::string::npos) << problem();
    window.start_s = 60;
    window.end_s = 120;
    ASSERT_TRUE(home_hrv->store(agg::hrv_window_item(info, window, home_hrv->iri())));
    EXPECT_TRUE(eventually([&] { return problem().empty(); })) << "still: " << problem();
    const tn::Term trend_of_it = tn::Term::iri(agg::trend_iri(kRecording, agg::HrvMetric::sdnn, 60));
    EXPECT_TRUE(eventually([&] { return node->snapshot()->count({.s = trend_of_it}).value() > 0; }))
        << "no trend of the readable window";
    EXPECT_EQ(agent.stop(), 0);
  }
}

// Windows are named by recording and start: a window of another length already holding the name
// (a second HRV agent on the recording) stands, and the one that cannot be written is said.
TEST(AgentPrograms, AWindowWhoseNameAnotherWindowHoldsIsLoggedNotSilentlyDropped) {
  char pattern[] = "/tmp/tahvel-agents-hrv-taken-XXXXXX";
  ASSERT_NE(mkdtemp(pattern), nullptr);
  const std::string tmp = pattern, dir = tmp + "/home1", log = tmp + "/hrv.log";
  auto made = tn::Node::init(dir, tn::InitOptions{.iri = kNodeIri});
  ASSERT_TRUE(made) << made.error().message;
  std::optional<tn::Node> node(std::move(*made));
  agg::RecordingInfo info;
  info.iri = kRecording;
  info.sensor_iri = kNodeIri + "/ecg";
  info.fs = 1000;
  auto source = node->agent("ecg");
  auto other = node->agent("hrv60");
  ASSERT_TRUE(source && other);
  ASSERT_TRUE(source->store(agg::recording_item(info)));
  agg::WindowMetrics sixty;  // another agent's 60 s window at 0
  sixty.start_s = 0;
  sixty.end_s = 60;
  ASSERT_TRUE(other->store(agg::hrv_window_item(info, sixty, other->iri())));
  agg::RrSeries rr;  // 400 s of beats a second apart, then the end
  rr.recording = kRecording;
  for (std::int64_t k = 0; k < 400; ++k) rr.intervals.push_back({k * 1000, (k + 1) * 1000, true});
  rr.end_sample = 400'000;
  ASSERT_TRUE(source->store(agg::rr_item(rr)));
  {
    Process agent({bin("tahvel-hrv"), dir, "--idle", "3", "--window", "300"}, log);
    EXPECT_EQ(agent.wait(60s), 0);
  }
  std::ifstream in(log);
  std::ostringstream text;
  text << in.rdbuf();
  EXPECT_NE(text.str().find("window <" + agg::hrv_iri(kRecording, 0) + "> [0, 300) s not written: the board has a window of that name ending at 60"),
            std::string::npos)
      << text.str();
  auto ends = node->snapshot()->list({.s = tn::Term::iri(agg::hrv_iri(kRecording, 0)), .p = agg::tv_term("windowEndS")});
  ASSERT_EQ(ends->size(), 1u);
  EXPECT_EQ(ends->front().triple.o.value, "60.0") << "the window that held the name stands";
  EXPECT_EQ(node->snapshot()->count({.s = tn::Term::iri(agg::hrv_iri(kRecording, 300))}).value() > 0, true)
      << "the next window, whose name is free, is written";
  node.reset();
  fs::remove_all(tmp);
}

}  // namespace
