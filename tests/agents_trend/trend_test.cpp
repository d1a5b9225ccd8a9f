// tahvel-trend as a process: synthetic HRV window items of three recordings in (written with
// hrv_window_item, as tahvel-hrv writes them), trend items out (read with read_trend).
//
// Recording A has a stable SDNN (baseline 50, robust SD 1.48) and then a step to 80: the alert
// must appear on the third window beyond the threshold and not before. B and C stay stable
// (about 40 and 60), so that A's latest value has a z-score against two others. Part of the
// windows is on the board before the agent starts (catch-up), the rest arrives while it runs,
// and one more while it is stopped; restarting it writes only that window's items, no doubles.
#include <gtest/gtest.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <map>
#include <memory>
#include <set>
#include <string>
#include <vector>

#include "tahvel/aggregation/items.h"
#include "tahvel/node/node.h"
#include "agent_process.h"

namespace {

namespace agg = tahvel::aggregation;
namespace fs = std::filesystem;
namespace tn = tahvel::node;
using namespace std::chrono_literals;

const std::string kNodeIri = "http://example.org/hospital";
const std::string kRecA = kNodeIri + "/ecg/recording/a";
const std::string kRecB = kNodeIri + "/ecg/recording/b";
const std::string kRecC = kNodeIri + "/ecg/recording/c";

// SDNN per 5-minute window: A stable then a step at window 8; B and C stable.
const std::vector<double> kSdnnA = {50, 52, 48, 51, 49, 50, 53, 47, 80, 81, 79, 82, 80};
const std::vector<double> kSdnnB = {40, 41, 39, 40, 42, 38, 40, 41, 39, 40, 41, 40};
const std::vector<double> kSdnnC = {60, 62, 58, 61, 59, 60, 61, 59, 60, 62, 58, 60};

// When the test's recordings start (2026-12-01T10:00:00Z).
constexpr std::int64_t kSignalStart = 1'796'119'200'000'000'000;

using Process = tahvel::test_support::AgentProcess;

tn::Pattern trend_items() {
  tn::Pattern p;
  p.p = tn::Term::iri(std::string(tn::kRdfType));
  p.o = agg::tv_term("HrvTrend");
  return p;
}

class TrendAgentTest : public ::testing::Test {
 protected:
  void SetUp() override {
    char pattern[] = "/tmp/tahvel-agents-trend-XXXXXX";
    ASSERT_NE(mkdtemp(pattern), nullptr);
    tmp_ = pattern;
    dir_ = tmp_ + "/hospital";
    auto node = tn::Node::init(dir_, tn::InitOptions{.iri = kNodeIri});
    ASSERT_TRUE(node) << node.error().message;
    node_.emplace(std::move(*node));
    auto hrv = node_->agent("hrv");
    ASSERT_TRUE(hrv);
    hrv_.emplace(std::move(*hrv));
  }
  void TearDown() override {
    agent_.reset();
    hrv_.reset();
    node_.reset();
    if (!tmp_.empty()) fs::remove_all(tmp_);
  }

  void start_agent(const std::string& idle) {
    agent_ = std::make_unique<Process>(
        std::vector<std::string>{std::string(TAHVEL_BIN_DIR) + "/tahvel-trend", dir_, "--idle", idle});
  }

  // Window k (300 s) of a recording with the given SDNN; RMSSD and mean HR vary a little.
  // Asserted at `asserted_ns` when given, else at kSignalStart + its start (tahvel-hrv: the
  // signal time of the window's start; the test's recordings run side by side).
  void store_window(const std::string& recording, std::size_t k, double sdnn,
                    std::optional<std::int64_t> asserted_ns = std::nullopt) {
    store_window_at(recording, 300.0 * static_cast<double>(k), 300, k, sdnn, asserted_ns);
  }
  // A window of `length_s` from `start_s`, as tahvel-hrv writes it under that window setting.
  void store_window_at(const std::string& recording, double start_s, double length_s, std::size_t k, double sdnn,
                       std::optional<std::int64_t> asserted_ns = std::nullopt) {
    agg::RecordingInfo info;
    info.iri = recording;
    agg::WindowMetrics w;
    w.start_s = start_s;
    w.end_s = start_s + length_s;
    w.length_s = length_s;
    w.metrics.sdnn_ms = sdnn;
    w.metrics.rmssd_ms = 30 + static_cast<double>(k % 3);
    w.metrics.mean_hr_bpm = 70 + static_cast<double>(k % 2);
    w.metrics.nn_count = w.metrics.rr_count = 350;
    tn::Item item = agg::hrv_window_item(info, w, hrv_->iri());
    item.asserted_at = asserted_ns.value_or(kSignalStart + static_cast<std::int64_t>(start_s * 1e9));
    ASSERT_TRUE(hrv_->store(item));
  }

  std::size_t count_trends() {
    auto n = node_->snapshot()->count(trend_items());
    EXPECT_TRUE(n);
    return n ? static_cast<std::size_t>(*n) : 0;
  }

  void wait_for_trends(std::size_t n) {
    std::uint64_t bookmark = 0;
    const auto deadline = std::chrono::steady_clock::now() + 120s;
    while (count_trends() < n) {
      ASSERT_LT(agent_->poll(), 0) << "tahvel-trend exited early";
      ASSERT_LT(std::chrono::steady_clock::now(), deadline) << "timed out waiting for " << n << " trend items";
      auto changes = node_->watch(bookmark, 1000ms, 1000);
      ASSERT_TRUE(changes);
      if (!changes->empty()) bookmark = changes->back().seq;
    }
  }

  // Every trend item on the board, by IRI; fails on a subject written twice.
  std::map<std::string, agg::TrendUpdate> trends() {
    std::map<std::string, agg::TrendUpdate> out;
    auto records = node_->snapshot()->list(trend_items());
    EXPECT_TRUE(records);
    if (!records) return out;
    for (const auto& r : *records) {
      auto item = node_->snapshot()->item(r.meta.item);
      EXPECT_TRUE(item);
      if (!item) continue;
      auto t = agg::read_trend(*item);
      EXPECT_TRUE(t) << t.error().message;
      if (!t) continue;
      EXPECT_TRUE(out.emplace(t->iri, *t).second) << "written twice: " << t->iri;
    }
    return out;
  }

  std::string tmp_, dir_;
  std::optional<tn::Node> node_;
  std::optional<tn::Agent> hrv_;
  std::unique_ptr<Process> agent_;
};

TEST_F(TrendAgentTest, BaselineSlopeAlertZAndNoDoublesAfterRestart) {
  // Windows 0..3 of each recording before the agent starts: the catch-up writes their trends.
  for (std::size_t k = 0; k < 4; ++k) {
    store_window(kRecA, k, kSdnnA[k]);
    store_window(kRecB, k, kSdnnB[k]);
    store_window(kRecC, k, kSdnnC[k]);
  }
  start_agent("120");
  wait_for_trends(4 * 3 * 3);
  // The rest while it runs, interleaved across recordings (A's window 12 comes later).
  for (std::size_t k = 4; k < 12; ++k) {
    store_window(kRecA, k, kSdnnA[k]);
    store_window(kRecB, k, kSdnnB[k]);
    store_window(kRecC, k, kSdnnC[k]);
  }
  wait_for_trends(12 * 3 * 3);
  EXPECT_EQ(agent_->stop(), 0);

  auto all = trends();
  ASSERT_EQ(all.size(), 12u * 3 * 3);
  for (std::size_t k = 0; k < 12; ++k) {
    const std::string iri = agg::trend_iri(kRecA, agg::HrvMetric::sdnn, 300.0 * static_cast<double>(k));
    ASSERT_TRUE(all.count(iri)) << iri;
    const agg::TrendUpdate& t = all.at(iri);
    SCOPED_TRACE(iri);
    EXPECT_EQ(t.recording, kRecA);
    EXPECT_EQ(t.window_iri, agg::hrv_iri(kRecA, 300.0 * static_cast<double>(k)));
    EXPECT_EQ(t.windows, k + 1);
    ASSERT_TRUE(t.latest);
    EXPECT_DOUBLE_EQ(*t.latest, kSdnnA[k]);
    if (k < 5) {
      EXPECT_FALSE(t.baseline);  // 6 points needed
    } else {
      ASSERT_TRUE(t.baseline);
      EXPECT_DOUBLE_EQ(*t.baseline, 50);
      ASSERT_TRUE(t.robust_sd);
      EXPECT_NEAR(*t.robust_sd, 1.4826, 1e-4);
    }
    EXPECT_EQ(t.slope_per_hour.has_value(), k >= 1);
    // The step starts at window 8; three in a row beyond 3 robust SDs: alert from window 10.
    EXPECT_EQ(t.alert, k >= 10);
    if (t.alert) {
      EXPECT_EQ(t.alert_direction, 1);
    }
  }
  const auto& last_a = all.at(agg::trend_iri(kRecA, agg::HrvMetric::sdnn, 3300));
  ASSERT_TRUE(last_a.slope_per_hour);
  EXPECT_GT(*last_a.slope_per_hour, 0);
  const auto& stable_a = all.at(agg::trend_iri(kRecA, agg::HrvMetric::sdnn, 2100));
  ASSERT_TRUE(stable_a.slope_per_hour);
  EXPECT_LT(std::abs(*stable_a.slope_per_hour), 2.0);  // ±3 ms noise around 50 over 40 min
  // B and C never alert.
  for (const auto& [iri, t] : all)
    if (t.recording != kRecA && t.metric == agg::HrvMetric::sdnn) {
      EXPECT_FALSE(t.alert) << iri;
    }
  // Across patients: the latest item of each recording carries z against the other two.
  const auto& last_b = all.at(agg::trend_iri(kRecB, agg::HrvMetric::sdnn, 3300));
  const auto& last_c = all.at(agg::trend_iri(kRecC, agg::HrvMetric::sdnn, 3300));
  ASSERT_TRUE(last_a.z_against_others);
  ASSERT_TRUE(last_b.z_against_others);
  ASSERT_TRUE(last_c.z_against_others);
  EXPECT_EQ(last_a.others, 2u);
  EXPECT_GT(*last_a.z_against_others, 1.0);   // 82 against about 40 and 60
  EXPECT_LT(*last_b.z_against_others, -1.0);  // 40 against about 60 and 80
  // The other metrics are there too, with their own series.
  const auto& hr = all.at(agg::trend_iri(kRecB, agg::HrvMetric::mean_hr, 3300));
  EXPECT_EQ(hr.windows, 12u);
  ASSERT_TRUE(hr.baseline);
  EXPECT_TRUE(all.count(agg::trend_iri(kRecC, agg::HrvMetric::rmssd, 0)));

  // While the agent is stopped, one more window of A; the restart writes its three trend
  // items (catch-up, or the delivery waiting in its buffer) and nothing else.
  store_window(kRecA, 12, kSdnnA[12]);
  const auto before = node_->snapshot()->count(tn::Pattern{});
  ASSERT_TRUE(before);
  start_agent("3");
  EXPECT_EQ(agent_->wait(60s), 0);
  all = trends();
  EXPECT_EQ(all.size(), 12u * 3 * 3 + 3);
  const auto after = node_->snapshot()->count(tn::Pattern{});
  ASSERT_TRUE(after);
  EXPECT_GT(*after, *before);
  const auto& a12 = all.at(agg::trend_iri(kRecA, agg::HrvMetric::sdnn, 3600));
  EXPECT_EQ(a12.windows, 13u);
  EXPECT_TRUE(a12.alert);
  EXPECT_TRUE(a12.z_against_others);

  // A second restart has nothing to write.
  const auto settled = node_->snapshot()->count(tn::Pattern{});
  start_agent("2");
  EXPECT_EQ(agent_->wait(60s), 0);
  EXPECT_EQ(*node_->snapshot()->count(tn::Pattern{}), *settled);
  EXPECT_EQ(trends().size(), 12u * 3 * 3 + 3);
}

// A recording's second take (its source restarted) is the same patient: its z-score counted the
// patient's own first take among the "other patients".
TEST_F(TrendAgentTest, AnotherTakeOfTheSameRecordingIsNotAnotherPatientForTheZScore) {
  // Two takes of recording d, as tahvel-ecg-source names them (the second after a restart).
  const std::string take1 = kNodeIri + "/ecg/recording/d-20261201T101500Z", take2 = kNodeIri + "/ecg/recording/d-20261201T113000Z-2";
  for (std::size_t k = 0; k < 2; ++k) {
    store_window(take1, k, 50);
    store_window(kRecB, k, 40);
    store_window(kRecC, k, 60);
  }
  start_agent("120");
  wait_for_trends(2 * 3 * 3);
  store_window(take2, 0, 80);
  wait_for_trends(2 * 3 * 3 + 3);
  EXPECT_EQ(agent_->stop(), 0);
  const auto all = trends();
  const agg::TrendUpdate& t = all.at(agg::trend_iri(take2, agg::HrvMetric::sdnn, 0));
  ASSERT_TRUE(t.z_against_others);
  EXPECT_EQ(t.others, 2u) << "B and C; not d's first take";
}

// Two takes of another patient that overlap in signal time (a replay started again from its
// first sample after a `down` and `up`) are one other patient: they were two, and a home's
// z-score said "against 2 other patients" where there was one (an exploratory run of session 85).
TEST_F(TrendAgentTest, TwoTakesOfAnotherPatientAreOneOtherPatientForTheZScore) {
  const std::string e1 = kNodeIri + "/ecg/recording/e-20261201T100000Z", e2 = kNodeIri + "/ecg/recording/e-20261201T100000Z-2";
  for (std::size_t k = 0; k < 2; ++k) {
    store_window(e1, k, 40);
    store_window(e2, k, 44);
    store_window(kRecC, k, 60);
  }
  store_window(kRecA, 1, 80);
  start_agent("2");
  wait_for_trends(7 * 3);
  ASSERT_FALSE(HasFatalFailure());
  EXPECT_EQ(agent_->wait(30s), 0);
  const auto all = trends();
  const agg::TrendUpdate& a = all.at(agg::trend_iri(kRecA, agg::HrvMetric::sdnn, 300));
  ASSERT_TRUE(a.z_against_others);
  EXPECT_EQ(a.others, 2u) << "e and C: e's two takes are one patient";
  const agg::TrendUpdate& c = all.at(agg::trend_iri(kRecC, agg::HrvMetric::sdnn, 0));
  EXPECT_FALSE(c.z_against_others) << "e alone is one other patient, and a z needs two";
}

// Two other patients whose values happen to agree closely: their SD (0.007 ms) made a 3 ms
// difference a z of 420; the SD is held to the metric's resolution (1 ms for SDNN).
TEST_F(TrendAgentTest, TheZScoreAgainstOthersThatAgreeCloselyIsHeldToTheMetricsResolution) {
  store_window(kRecA, 0, 43);
  store_window(kRecB, 0, 40);
  store_window(kRecC, 0, 40.01);
  start_agent("120");
  wait_for_trends(3 * 3);
  EXPECT_EQ(agent_->stop(), 0);
  const agg::TrendUpdate& t = trends().at(agg::trend_iri(kRecA, agg::HrvMetric::sdnn, 0));
  ASSERT_TRUE(t.z_against_others);
  EXPECT_EQ(t.others, 2u);
  EXPECT_NEAR(*t.z_against_others, 2.995, 1e-6);
}

// Patients are compared at the same moment: each window against the other recordings' windows
// that overlap it in signal time. Against the others' latest windows, whatever their time, a
// replay at --speed 0 held one patient's minute 27 against another's minute 5, and a recording
// that ended long ago counted as a patient of now.
TEST_F(TrendAgentTest, TheZScoreComparesEachWindowWithTheOtherPatientsWindowsOfTheSameTime) {
  const std::vector<double> sdnn_b = {40, 40, 90, 90, 90, 90, 90};
  for (std::size_t k = 0; k < sdnn_b.size(); ++k) store_window(kRecB, k, sdnn_b[k]);
  for (std::size_t k = 0; k < 2; ++k) store_window(kRecC, k, 60);  // C's recording ends at 10 min
  for (std::size_t k = 0; k < 6; ++k) store_window(kRecA, k, 50);
  // D's only window is of minute 15: no window "of the same time, or the one before" for A's of
  // minute 10, where up to session 84 the nearest either way was taken (in a catch-up).
  const std::string rec_d = kRecA + "-d";
  store_window(rec_d, 3, 200);
  start_agent("120");
  wait_for_trends((sdnn_b.size() + 2 + 6 + 1) * 3);
  store_window(kRecA, 6, 50);  // arrives while the agent runs
  wait_for_trends((sdnn_b.size() + 2 + 7 + 1) * 3);
  EXPECT_EQ(agent_->stop(), 0);
  const auto all = trends();
  // Minute 5: B's 40 and C's 60 of minute 5, not B's later 90.
  const agg::TrendUpdate& a1 = all.at(agg::trend_iri(kRecA, agg::HrvMetric::sdnn, 300));
  ASSERT_TRUE(a1.z_against_others);
  EXPECT_EQ(a1.others, 2u);
  EXPECT_NEAR(*a1.z_against_others, 0.0, 1e-9);
  const agg::TrendUpdate& b1 = all.at(agg::trend_iri(kRecB, agg::HrvMetric::sdnn, 300));
  ASSERT_TRUE(b1.z_against_others);
  EXPECT_NEAR(*b1.z_against_others, (40.0 - 55.0) / std::sqrt(50.0), 1e-5);  // against 50 and 60
  // Minute 30: C's last window began 25 minutes before; B alone is no group to compare with.
  const agg::TrendUpdate& a6 = all.at(agg::trend_iri(kRecA, agg::HrvMetric::sdnn, 1800));
  EXPECT_FALSE(a6.z_against_others.has_value()) << *a6.z_against_others << " against " << a6.others;
  EXPECT_FALSE(all.at(agg::trend_iri(kRecA, agg::HrvMetric::sdnn, 1500)).z_against_others.has_value());
  // Minute 10: C's window of minute 5 is the one before (C's of minute 10 had not arrived).
  EXPECT_EQ(all.at(agg::trend_iri(kRecA, agg::HrvMetric::sdnn, 600)).others, 2u);
}

// A window with no beats (lead off) has no value: its trend items must not show the window
// before's as "the metric in this window", nor carry on that window's alert.
// A trend update describes the patient at its window's time: it is asserted at the window's
// signal time, as everything the chain derives, so that a time range takes both together.
TEST_F(TrendAgentTest, TrendItemsAreAssertedAtTheirWindowsSignalTime) {
  const std::int64_t signal_start = 1'700'000'000'000'000'000;  // a recording of 2023, replayed now
  for (std::size_t k = 0; k < 2; ++k)
    store_window(kRecA, k, kSdnnA[k], signal_start + static_cast<std::int64_t>(k) * 300'000'000'000);
  start_agent("120");
  wait_for_trends(6);  // three metrics after each of two windows
  auto records = node_->snapshot()->list(trend_items());
  ASSERT_TRUE(records);
  ASSERT_EQ(records->size(), 6u);
  for (const auto& r : *records) {
    auto item = node_->snapshot()->item(r.meta.item);
    ASSERT_TRUE(item);
    auto t = agg::read_trend(*item);
    ASSERT_TRUE(t) << t.error().message;
    EXPECT_EQ(r.meta.asserted_at, signal_start + static_cast<std::int64_t>(t->window_start_s) * 1'000'000'000) << t->iri;
  }
  EXPECT_EQ(agent_->stop(), 0);
}

TEST_F(TrendAgentTest, AWindowWithoutTheMetricHasNoLatestValueAndNoAlert) {
  for (std::size_t k = 0; k < 11; ++k) store_window(kRecA, k, kSdnnA[k]);
  agg::RecordingInfo info;
  info.iri = kRecA;
  agg::WindowMetrics empty;  // window 11: no beats, no metrics
  empty.start_s = 3300;
  empty.end_s = 3600;
  ASSERT_TRUE(hrv_->store(agg::hrv_window_item(info, empty, hrv_->iri())));
  start_agent("2");
  wait_for_trends(12 * 3);
  ASSERT_FALSE(HasFatalFailure());
  EXPECT_EQ(agent_->wait(30s), 0);
  const auto all = trends();
  const auto alerting = all.at(agg::trend_iri(kRecA, agg::HrvMetric::sdnn, 3000));
  ASSERT_TRUE(alerting.alert) << "the step at window 8 alerts by window 10";
  const auto lead_off = all.at(agg::trend_iri(kRecA, agg::HrvMetric::sdnn, 3300));
  EXPECT_FALSE(lead_off.latest.has_value()) << *lead_off.latest;
  EXPECT_FALSE(lead_off.alert);
  EXPECT_EQ(lead_off.windows, 11u);
  EXPECT_TRUE(lead_off.baseline.has_value());
}

// Six equal baseline values have a MAD of 0: without a floor any change at all was an alert.
// The robust SD is floored at the metric's resolution (1 ms for SDNN): 1.5 ms off is no alert,
// 10 ms off three times is.
TEST_F(TrendAgentTest, AFlatBaselineAlertsOnAChangeThatMattersNotOnAnyChange) {
  const std::vector<double> sdnn = {50, 50, 50, 50, 50, 50, 51.5, 51.5, 51.5, 60, 60, 60};
  for (std::size_t k = 0; k < sdnn.size(); ++k) store_window(kRecA, k, sdnn[k]);
  start_agent("2");
  wait_for_trends(sdnn.size() * 3);
  ASSERT_FALSE(HasFatalFailure());
  EXPECT_EQ(agent_->wait(30s), 0);
  const auto all = trends();
  EXPECT_FALSE(all.at(agg::trend_iri(kRecA, agg::HrvMetric::sdnn, 300.0 * 8)).alert);
  EXPECT_EQ(*all.at(agg::trend_iri(kRecA, agg::HrvMetric::sdnn, 300.0 * 8)).robust_sd, 1.0);
  EXPECT_TRUE(all.at(agg::trend_iri(kRecA, agg::HrvMetric::sdnn, 300.0 * 11)).alert);
}

// Windows of 5 minutes every minute: the baseline spans 30 minutes of signal (26 windows), not
// the first 6 (10 minutes), and an alert needs a run spanning 10 minutes. Six windows at 41 ms,
// then twenty at 50: from six, every later window was an alert (an exploratory run of session
// 84 found 22 of 116 items alerting on a stationary synthetic ECG at such steps).
TEST_F(TrendAgentTest, OverlappingWindowsMakeABaselineOfHalfAnHourAndAlertsOfTenMinutes) {
  std::vector<double> sdnn;
  for (int i = 0; i < 6; ++i) sdnn.push_back(i % 2 ? 42.0 : 40.0);
  for (int i = 0; i < 20; ++i) sdnn.push_back(i % 2 ? 51.0 : 49.0);
  for (int i = 0; i < 4; ++i) sdnn.push_back(60.0);
  for (std::size_t k = 0; k < sdnn.size(); ++k) store_window_at(kRecA, 60.0 * static_cast<double>(k), 300, k, sdnn[k]);
  start_agent("2");
  wait_for_trends(sdnn.size() * 3);
  ASSERT_FALSE(HasFatalFailure());
  EXPECT_EQ(agent_->wait(30s), 0);
  const auto all = trends();
  EXPECT_FALSE(all.at(agg::trend_iri(kRecA, agg::HrvMetric::sdnn, 60.0 * 24)).baseline.has_value()) << "25 windows span 24 minutes";
  const auto last = all.at(agg::trend_iri(kRecA, agg::HrvMetric::sdnn, 60.0 * 29));
  ASSERT_TRUE(last.baseline.has_value());
  EXPECT_EQ(*last.baseline, 49.0);
  EXPECT_FALSE(last.alert) << "four windows above span less than two window lengths";
}

// The hospital lengthens a home's windows from 5 to 10 minutes: SDNN grows with the window
// (50 ms to 65 here), and judged by the 5-minute baseline every longer window was an alert
// "above". Windows of another length start a series of their own: no baseline before six of
// them, no alert, and no z-score against patients whose windows are still 5 minutes long.
TEST_F(TrendAgentTest, AChangeOfWindowLengthStartsASeriesOfItsOwnAndRaisesNoAlert) {
  for (std::size_t k = 0; k < 8; ++k) store_window(kRecA, k, kSdnnA[k]);
  for (std::size_t k = 0; k < 8; ++k) store_window(kRecB, k, kSdnnB[k]);
  for (std::size_t k = 0; k < 8; ++k) store_window(kRecC, k, kSdnnC[k]);
  const std::vector<double> longer = {65, 66, 64, 65};
  for (std::size_t i = 0; i < longer.size(); ++i)
    store_window_at(kRecA, 2400 + 600.0 * static_cast<double>(i), 600, 8 + i, longer[i]);
  start_agent("2");
  wait_for_trends((8 * 3 + longer.size()) * 3);
  ASSERT_FALSE(HasFatalFailure());
  EXPECT_EQ(agent_->wait(30s), 0);
  const auto all = trends();
  const auto last_short = all.at(agg::trend_iri(kRecA, agg::HrvMetric::sdnn, 2100));
  EXPECT_EQ(last_short.windows, 8u);
  ASSERT_TRUE(last_short.baseline.has_value());
  for (std::size_t i = 0; i < longer.size(); ++i) {
    const auto t = all.at(agg::trend_iri(kRecA, agg::HrvMetric::sdnn, 2400 + 600.0 * static_cast<double>(i)));
    EXPECT_EQ(t.windows, i + 1) << t.iri;
    EXPECT_FALSE(t.baseline.has_value()) << t.iri << ": " << *t.baseline;
    EXPECT_FALSE(t.alert) << t.iri;
    EXPECT_FALSE(t.z_against_others.has_value()) << t.iri;
  }
}

// The last windows of a recording end with it, shorter than their length: they measured less
// (SDNN grows with the window), and three of them below the baseline, as overlapping windows
// give at every recording's end, made an alert of the end itself. They are no points of the
// series: no latest value, no alert, and the series' baseline and count as before them.
// Up to session 84 a cut-short window that ends where the last whole one ends (a record whose
// end falls on a window's, with overlapping windows: here the one from 2160 s) was taken for
// that one, by its end time, and got its value, alert and z-score.
TEST_F(TrendAgentTest, WindowsCutShortByTheRecordsEndAreNoPointsOfTheSeries) {
  for (std::size_t k = 0; k < 8; ++k) store_window(kRecA, k, kSdnnA[k]);
  const std::vector<double> cut_starts{2160, 2400, 2460, 2520};
  for (const double start : cut_starts) {
    agg::RecordingInfo info;
    info.iri = kRecA;
    agg::WindowMetrics cut;
    cut.start_s = start;
    cut.end_s = start < 2400 ? 2400 : 2580;  // the record ends here
    cut.length_s = 300;
    cut.metrics.sdnn_ms = 30;
    cut.metrics.rmssd_ms = 30;
    cut.metrics.mean_hr_bpm = 70;
    cut.metrics.nn_count = cut.metrics.rr_count = 100;
    ASSERT_TRUE(hrv_->store(agg::hrv_window_item(info, cut, hrv_->iri())));
  }
  start_agent("2");
  wait_for_trends((8 + cut_starts.size()) * 3);
  ASSERT_FALSE(HasFatalFailure());
  EXPECT_EQ(agent_->wait(30s), 0);
  const auto all = trends();
  for (const double start : cut_starts) {
    const auto t = all.at(agg::trend_iri(kRecA, agg::HrvMetric::sdnn, start));
    EXPECT_FALSE(t.alert) << t.iri;
    EXPECT_FALSE(t.latest.has_value()) << t.iri;
    EXPECT_EQ(t.windows, 8u) << t.iri;
    EXPECT_TRUE(t.baseline.has_value()) << t.iri;
  }
}

// A patient monitored for weeks: the agent keeps a recording's baseline and the windows of the
// last hours (--horizon-h), not every window since the start (about 1.3 MB per patient per day
// of 60-s windows up to session 84, each read again for every new window). The slope is of the
// horizon's windows; the baseline, the count and the alerts are the whole series', whether the
// windows were on the board before the agent started (read a page at a time) or came one by one.
TEST_F(TrendAgentTest, ARecordingLongerThanTheHorizonKeepsItsBaselineAndCountAndSlopesOverTheHorizon) {
  // 1,100 windows of 60 s: more than a page of the catch-up (1,024), with windows forgotten
  // between its pages; the last hour above the baseline, and rising.
  constexpr double kLength = 60;
  std::vector<double> sdnn{49, 51, 50, 49, 51, 50};
  while (sdnn.size() < 1040) sdnn.push_back(50 + static_cast<double>(sdnn.size() % 3) - 1);
  while (sdnn.size() < 1100) sdnn.push_back(60 + 0.2 * static_cast<double>(sdnn.size() - 1040));
  auto start_of = [&](std::size_t k) { return kLength * static_cast<double>(k); };
  for (std::size_t k = 0; k < sdnn.size(); ++k) store_window_at(kRecA, start_of(k), kLength, k, sdnn[k]);
  agent_ = std::make_unique<Process>(std::vector<std::string>{std::string(TAHVEL_BIN_DIR) + "/tahvel-trend", dir_,
                                                              "--idle", "120", "--horizon-h", "1"});
  wait_for_trends(sdnn.size() * 3);
  for (std::size_t k = 0; k < sdnn.size(); ++k) store_window_at(kRecB, start_of(k), kLength, k, sdnn[k]);
  wait_for_trends(sdnn.size() * 3 * 2);
  ASSERT_FALSE(HasFatalFailure());
  EXPECT_EQ(agent_->stop(), 0);
  const auto all = trends();
  const std::size_t last = sdnn.size() - 1;
  std::vector<agg::TrendPoint> hour;  // the windows that end within the hour of the last one's end
  for (std::size_t k = 0; k < sdnn.size(); ++k)
    if (start_of(k + 1) >= start_of(last + 1) - 3600) hour.push_back({start_of(k + 1), sdnn[k]});
  ASSERT_EQ(hour.size(), 61u);
  const auto expected_slope = agg::analyse_trend(hour).slope_per_hour;
  ASSERT_TRUE(expected_slope);
  for (const std::string& recording : {kRecA, kRecB}) {
    SCOPED_TRACE(recording);
    const auto t = all.at(agg::trend_iri(recording, agg::HrvMetric::sdnn, start_of(last)));
    EXPECT_EQ(t.windows, sdnn.size());
    ASSERT_TRUE(t.baseline);
    EXPECT_DOUBLE_EQ(*t.baseline, 50) << "the first six windows', gone from the agent's memory by now";
    ASSERT_TRUE(t.robust_sd);
    EXPECT_NEAR(*t.robust_sd, 1.4826, 1e-4);
    ASSERT_TRUE(t.slope_per_hour);
    EXPECT_NEAR(*t.slope_per_hour, *expected_slope, 1e-3);  // kept to 4 decimals on the board
    EXPECT_EQ(t.slope_horizon_s, 3600.0) << "how far back the slope reaches, on the item";
    EXPECT_TRUE(t.alert);
    EXPECT_EQ(t.alert_direction, 1);
  }
  // Read at start a page at a time, or taken one by one as they came: the same items.
  for (std::size_t k = 0; k < sdnn.size(); ++k) {
    const auto a = all.at(agg::trend_iri(kRecA, agg::HrvMetric::sdnn, start_of(k)));
    const auto b = all.at(agg::trend_iri(kRecB, agg::HrvMetric::sdnn, start_of(k)));
    ASSERT_EQ(a.windows, k + 1) << k;
    ASSERT_EQ(a.windows, b.windows) << k;
    ASSERT_EQ(a.baseline, b.baseline) << k;
    ASSERT_EQ(a.slope_per_hour, b.slope_per_hour) << k;
    ASSERT_EQ(a.alert, b.alert) << k;
  }
}

// Windows that came while the agent was stopped wait in its input buffer, and are on the board
// too: read at start, they are not taken in again from the buffer. A window older than the
// horizon would come back into memory and count twice among the series' points (tv:windows).
TEST_F(TrendAgentTest, WindowsReadAtStartAreNotTakenInAgainFromTheInputBuffer) {
  auto run_with_horizon = [&](const char* idle) {
    agent_ = std::make_unique<Process>(std::vector<std::string>{std::string(TAHVEL_BIN_DIR) + "/tahvel-trend", dir_,
                                                                "--idle", idle, "--horizon-h", "1"});
  };
  run_with_horizon("1");  // subscribes, then stops: what comes next waits for it
  EXPECT_EQ(agent_->wait(30s), 0);
  for (std::size_t k = 0; k < 30; ++k) store_window(kRecA, k, 50 + static_cast<double>(k % 3));
  run_with_horizon("120");
  wait_for_trends(30 * 3);
  store_window(kRecA, 30, 51);
  wait_for_trends(31 * 3);
  ASSERT_FALSE(HasFatalFailure());
  EXPECT_EQ(agent_->stop(), 0);
  const auto all = trends();
  EXPECT_EQ(all.at(agg::trend_iri(kRecA, agg::HrvMetric::sdnn, 300.0 * 29)).windows, 30u);
  EXPECT_EQ(all.at(agg::trend_iri(kRecA, agg::HrvMetric::sdnn, 300.0 * 30)).windows, 31u);
}

// A window says how many of its intervals it left out as gaps (pauses or signal lost), and reads
// back with its counts; one written before tv:gapCount reads as none.
TEST(HrvWindowItems, AWindowKeepsItsCountsOfNnIntervalsAndGapsThroughTheBoard) {
  agg::RecordingInfo info;
  info.iri = "http://example.org/home1/ecg/recording/116";
  agg::WindowMetrics w;
  w.start_s = 1200;
  w.end_s = w.length_s = 1500;
  w.metrics.sdnn_ms = 22.6;
  w.metrics.nn_count = 360;
  w.metrics.rr_count = 371;
  w.metrics.gap_count = 2;
  tn::Item item = agg::hrv_window_item(info, w, "http://example.org/home1/hrv");
  const auto records_of = [](const tn::Item& i) {
    std::vector<tn::Record> records;
    for (const auto& t : i.triples) records.push_back(tn::Record{.triple = t});
    return records;
  };
  auto read = agg::read_hrv_window(records_of(item));
  ASSERT_TRUE(read) << read.error().message;
  EXPECT_EQ(read->window.metrics.nn_count, 360u);
  EXPECT_EQ(read->window.metrics.rr_count, 371u);
  EXPECT_EQ(read->window.metrics.gap_count, 2u);
  std::erase_if(item.triples, [](const tn::Triple& t) { return t.p.value == std::string(agg::kTv) + "gapCount"; });
  read = agg::read_hrv_window(records_of(item));
  ASSERT_TRUE(read) << read.error().message;
  EXPECT_EQ(read->window.metrics.gap_count, 0u);
}

// An integrator's agent wrote its windows on blank nodes; the trend agent said the item had no
// sosa:observedProperty tv:HeartRateVariability, which it had.
TEST(HrvWindowItems, AWindowOnABlankNodeIsRefusedNamingTheBlankNodeNotAMissingTriple) {
  tn::Record r;
  r.triple = {tn::Term::blank("w"), tn::Term::iri("http://www.w3.org/ns/sosa/observedProperty"),
              tn::Term::iri("https://w3id.org/tahvel#HeartRateVariability")};
  auto window = agg::read_hrv_window({r});
  ASSERT_FALSE(window);
  EXPECT_NE(window.error().message.find("the HRV window's subject is a blank node"), std::string::npos) << window.error().message;
}

// Windows a minute apart after 115 days (1.00001e+07 s with six significant digits) were
// named alike, and the later one was taken for a repeat and never written.
TEST(ItemNames, WindowAndTrendNamesTellApartStartsOnLongRecordingsAndKeepShortOnesShort) {
  EXPECT_NE(agg::hrv_iri(kRecA, 10000080), agg::hrv_iri(kRecA, 10000140));
  EXPECT_EQ(agg::hrv_iri(kRecA, 10000080), kRecA + "/hrv/10000080");
  EXPECT_NE(agg::trend_iri(kRecA, agg::HrvMetric::sdnn, 10000080), agg::trend_iri(kRecA, agg::HrvMetric::sdnn, 10000140));
  EXPECT_EQ(agg::hrv_iri(kRecA, 300), kRecA + "/hrv/300");
  EXPECT_EQ(agg::hrv_iri(kRecA, 150.5), kRecA + "/hrv/150.5");
  EXPECT_EQ(agg::hrv_iri(kRecA, 0), kRecA + "/hrv/0");
  EXPECT_EQ(agg::hrv_iri(kRecA, 0.1 + 0.2), kRecA + "/hrv/0.3");
}

}  // namespace
