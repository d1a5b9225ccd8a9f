// patients_on_board (tahvel/aggregation/patients.h): the hospital's view of its patients, read
// from HRV window and trend items as tahvel-hrv and tahvel-trend write them.
#include "tahvel/aggregation/patients.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <optional>
#include <string>
#include <thread>

#include "temp_dir.h"

namespace {

namespace agg = tahvel::aggregation;
namespace tn = tahvel::node;

const std::string kHospital = "http://example.org/hospital";
const std::string kRecA = kHospital + "/home1/ecg/recording/a";
const std::string kRecB = kHospital + "/home2/ecg/recording/b";

class PatientsOnBoard : public ::testing::Test {
 protected:
  void SetUp() override {
    auto made = tn::Node::init(dir_.path() / "hospital", {.iri = kHospital});
    ASSERT_TRUE(made) << made.error().message;
    node_.emplace(std::move(*made));
  }

  // The window [start, start + 60) of `recording` with SDNN `sdnn`, written by `writer`.
  void window(const std::string& writer, const std::string& recording, double start, double sdnn,
              std::optional<double> irregular_pct = std::nullopt, std::optional<std::int64_t> asserted_ns = std::nullopt) {
    agg::RecordingInfo info;
    info.iri = recording;
    agg::WindowMetrics w;
    w.start_s = start;
    w.end_s = start + 60;
    w.metrics.sdnn_ms = sdnn;
    w.metrics.rmssd_ms = sdnn / 2;
    w.metrics.mean_hr_bpm = 70;
    w.metrics.nn_count = w.metrics.rr_count = 70;
    w.metrics.irregular_pct = irregular_pct;
    tn::Item item = agg::hrv_window_item(info, w, kHospital + "/" + writer);
    item.asserted_at = asserted_ns;
    store(writer, item);
  }

  void trend(const std::string& recording, agg::HrvMetric metric, double start, bool alert,
             std::optional<std::int64_t> asserted_ns = std::nullopt) {
    agg::TrendUpdate u;
    u.recording = recording;
    u.metric = metric;
    u.window_start_s = start;
    u.window_iri = agg::hrv_iri(recording, start);
    u.windows = static_cast<std::size_t>(start / 60) + 1;
    u.latest = 50 + start;
    u.alert = alert;
    u.alert_direction = alert ? 1 : 0;
    tn::Item item = agg::trend_item(u, kHospital + "/trend");
    item.asserted_at = asserted_ns;
    store("trend", item);
  }

  void store(const std::string& writer, const tn::Item& item) {
    auto agent = node_->agent(writer);
    ASSERT_TRUE(agent) << agent.error().message;
    ASSERT_TRUE(agent->store(item));
  }

  agg::PatientsOnBoard read(std::optional<std::int64_t> since = std::nullopt) {
    auto snapshot = node_->snapshot();
    EXPECT_TRUE(snapshot);
    auto board = agg::patients_on_board(*snapshot, since);
    EXPECT_TRUE(board) << board.error().message;
    return board ? *board : agg::PatientsOnBoard{};
  }

  tahvel::test_support::TempDir dir_{"tahvel-patients"};
  std::optional<tn::Node> node_;
};

TEST_F(PatientsOnBoard, EachRecordingIsOnePatientWithItsLatestWindowAndItsLatestTrendPerMetric) {
  // Windows arrive out of order (a link that went back): the latest is the latest start.
  window("home2-hrv", kRecB, 0, 40);
  window("home1-hrv", kRecA, 120, 80);
  window("home1-hrv", kRecA, 0, 50);
  window("home1-hrv", kRecA, 60, 52);
  window("home2-hrv", kRecB, 60, 41);
  trend(kRecA, agg::HrvMetric::sdnn, 120, true);
  trend(kRecA, agg::HrvMetric::sdnn, 0, false);
  trend(kRecA, agg::HrvMetric::sdnn, 60, false);
  trend(kRecA, agg::HrvMetric::rmssd, 0, false);

  const agg::PatientsOnBoard board = read();
  ASSERT_EQ(board.patients.size(), 2u);
  EXPECT_TRUE(board.unreadable.empty());
  // B sorts first by IRI; A comes first because its SDNN trend alerts.
  const agg::PatientView& a = board.patients[0];
  EXPECT_EQ(a.recording, kRecA);
  EXPECT_TRUE(a.alerting());
  EXPECT_EQ(a.windows, 3u);
  EXPECT_EQ(a.source, kHospital + "/home1-hrv");
  EXPECT_EQ(a.latest.window.start_s, 120);
  EXPECT_EQ(a.latest.window.metrics.sdnn_ms, 80);
  EXPECT_GT(a.latest_stored_ns, 0);
  ASSERT_EQ(a.trends.size(), 2u);
  EXPECT_EQ(a.trends[0].metric, agg::HrvMetric::sdnn);
  EXPECT_EQ(a.trends[0].window_start_s, 120);
  EXPECT_TRUE(a.trends[0].alert);
  EXPECT_EQ(a.trends[1].metric, agg::HrvMetric::rmssd);
  EXPECT_EQ(a.trends[1].window_start_s, 0);

  const agg::PatientView& b = board.patients[1];
  EXPECT_EQ(b.recording, kRecB);
  EXPECT_FALSE(b.alerting());
  EXPECT_EQ(b.windows, 2u);
  EXPECT_EQ(b.source, kHospital + "/home2-hrv");
  EXPECT_EQ(b.latest.window.start_s, 60);
  EXPECT_TRUE(b.trends.empty());
}

// The last windows of a recording end where the record ends: [1800, 1805.6) of a 300 s setting
// holds a handful of beats, and is no patient's state. The newest whole window is the latest;
// a recording with only a cut-short window still shows that one.
TEST_F(PatientsOnBoard, AWindowTheRecordsEndCutShortIsNotThePatientsLatest) {
  // As the chain asserts them: at the window's signal time.
  const std::int64_t t0 = 1'700'000'000'000'000'000, second = 1'000'000'000;
  auto window_of = [&](const std::string& recording, double start, double end, double sdnn) {
    agg::RecordingInfo info;
    info.iri = recording;
    agg::WindowMetrics w;
    w.start_s = start;
    w.end_s = end;
    w.length_s = 300;
    w.metrics.sdnn_ms = sdnn;
    w.metrics.mean_hr_bpm = 70;
    w.metrics.nn_count = w.metrics.rr_count = 8;
    tn::Item item = agg::hrv_window_item(info, w, kHospital + "/home1-hrv");
    item.asserted_at = t0 + static_cast<std::int64_t>(start) * second;
    store("home1-hrv", item);
  };
  window_of(kRecA, 1200, 1500, 50);
  window_of(kRecA, 1500, 1800, 52);
  window_of(kRecA, 1800, 1805.6, 9);
  window_of(kRecB, 0, 20, 30);  // a record of 20 s
  // The trend's update of the cut-short window has no latest value and no alert: the one shown
  // is the update of the window shown, with its alert.
  trend(kRecA, agg::HrvMetric::sdnn, 1500, true, t0 + 1500 * second);
  trend(kRecA, agg::HrvMetric::sdnn, 1800, false, t0 + 1800 * second);
  const agg::PatientsOnBoard board = read();
  ASSERT_EQ(board.patients.size(), 2u);
  for (const agg::PatientView& p : board.patients) {
    if (p.recording == kRecA) {
      EXPECT_EQ(p.windows, 3u);
      EXPECT_EQ(p.latest.window.start_s, 1500);
      EXPECT_EQ(p.latest.window.metrics.sdnn_ms, 52);
      ASSERT_EQ(p.trends.size(), 1u);
      EXPECT_EQ(p.trends[0].window_start_s, 1500);
      EXPECT_TRUE(p.alerting());
    } else {
      EXPECT_EQ(p.latest.window.start_s, 0);
      EXPECT_EQ(p.latest.window.end_s, 20);
    }
  }
  // Since a time after the last whole window: the cut-short one is all there is since then, and
  // it showed with its update's "no alert". The patient is the same as without --since.
  const agg::PatientsOnBoard since = read(t0 + 1750 * second);
  ASSERT_EQ(since.patients.size(), 1u);
  const agg::PatientView& a = since.patients[0];
  EXPECT_EQ(a.latest.window.start_s, 1500);
  EXPECT_EQ(a.latest.window.metrics.sdnn_ms, 52);
  ASSERT_EQ(a.trends.size(), 1u);
  EXPECT_EQ(a.trends[0].window_start_s, 1500);
  EXPECT_TRUE(a.alerting());
}

// Window times of a long recording keep their fraction on the board, as xsd:decimal (fixed, no
// exponent): with 6 significant digits a window at 100093.5 s of a 100,100 s record was written
// as 100094, and the last one, [100098.5, 100100), as (100099, 100100) — the one before as
// (100098, 100100): a patient's latest window and its trend were a second off.
TEST_F(PatientsOnBoard, WindowTimesOfALongRecordingKeepTheirFractionOnTheBoard) {
  agg::RecordingInfo info;
  info.iri = kRecA;
  agg::WindowMetrics w;
  w.start_s = 100093.5;
  w.end_s = 100096.5;
  w.metrics.nn_count = w.metrics.rr_count = 3;
  const tn::Item item = agg::hrv_window_item(info, w, kHospital + "/home1-hrv");
  for (const tn::Triple& t : item.triples) {
    if (t.p.value == std::string(agg::kTv) + "windowStartS") {
      EXPECT_EQ(t.o.value, "100093.5");
    } else if (t.p.value == std::string(agg::kTv) + "windowEndS") {
      EXPECT_EQ(t.o.value, "100096.5");
    }
  }
  store("home1-hrv", item);
  // 1636 steps of 1.1 s: 1799.6000000000001 as a double; written as the window is named.
  window("home1-hrv", kRecB, 1636 * 1.1, 40);
  trend(kRecA, agg::HrvMetric::sdnn, 100093.5, false);
  const agg::PatientsOnBoard board = read();
  ASSERT_EQ(board.patients.size(), 2u);
  const agg::PatientView& a = board.patients[0];
  EXPECT_EQ(a.latest.window.start_s, 100093.5);
  EXPECT_EQ(a.latest.window.end_s, 100096.5);
  ASSERT_EQ(a.trends.size(), 1u);
  EXPECT_EQ(a.trends[0].window_start_s, 100093.5);
  EXPECT_EQ(board.patients[1].latest.window.start_s, 1799.6);
  EXPECT_EQ(board.patients[1].latest.iri, kRecB + "/hrv/1799.6");
  auto starts = node_->snapshot()->list({.s = tn::Term::iri(kRecB + "/hrv/1799.6"), .p = agg::tv_term("windowStartS")});
  ASSERT_EQ(starts->size(), 1u);
  EXPECT_EQ(starts->front().triple.o.value, "1799.6");
  EXPECT_EQ(starts->front().triple.o.datatype, std::string(tn::xsd::kDecimal));
}

// A home of another version writes windows this node cannot read: they are counted for that
// writer, with the reason, and the patient's latest readable window stands.
TEST_F(PatientsOnBoard, AWindowThatCannotBeReadIsCountedForItsWriterAndTheLatestReadableOneStands) {
  window("home1-hrv", kRecA, 0, 50);
  agg::RecordingInfo info;
  info.iri = kRecA;
  agg::WindowMetrics w;
  w.start_s = 60;
  w.end_s = 120;
  w.metrics.sdnn_ms = 51;
  tn::Item odd = agg::hrv_window_item(info, w, kHospital + "/home1-hrv");
  for (tn::Triple& t : odd.triples)
    if (t.p.value == std::string(agg::kTv) + "sdnnMs") t.o = tn::Term::literal("fifty-one");
  store("home1-hrv", odd);

  const agg::PatientsOnBoard board = read();
  ASSERT_EQ(board.patients.size(), 1u);
  EXPECT_EQ(board.patients[0].latest.window.start_s, 0);
  EXPECT_EQ(board.patients[0].windows, 2u);
  ASSERT_EQ(board.unreadable.size(), 1u);
  EXPECT_EQ(board.unreadable[0].source, kHospital + "/home1-hrv");
  EXPECT_EQ(board.unreadable[0].count, 1u);
  EXPECT_NE(board.unreadable[0].first_error.find("sdnnMs"), std::string::npos) << board.unreadable[0].first_error;
}

// tahvel-hrv names a window's recording by provenance (<rec>/hrv/<start> derived from <rec>);
// another writer may say tv:recording with an IRI of its own: both are the patient's windows.
// A rhythm too irregular for the NN rule is flagged.
TEST_F(PatientsOnBoard, AWindowIsItsRecordingsByProvenanceOrByTvRecordingAndAnIrregularRhythmIsFlagged) {
  window("home1-hrv", kRecA, 0, 50);
  const tn::Term other = tn::Term::iri("http://example.org/elsewhere/window/7");
  tn::Item named;
  named.add(other, tn::Term::iri("http://www.w3.org/ns/sosa/observedProperty"), agg::tv_term("HeartRateVariability"))
      .add(other, agg::tv_term("recording"), tn::Term::iri(kRecA))
      .add(other, agg::tv_term("windowStartS"), tn::Term::literal("60.0", std::string(tn::xsd::kDecimal)))
      .add(other, agg::tv_term("windowEndS"), tn::Term::literal("120.0", std::string(tn::xsd::kDecimal)))
      .add(other, agg::tv_term("sdnnMs"), tn::Term::literal("90.0", std::string(tn::xsd::kDecimal)))
      .add(other, agg::tv_term("irregularPct"), tn::Term::literal("40.0", std::string(tn::xsd::kDecimal)));
  store("other-hrv", named);

  const agg::PatientsOnBoard board = read();
  ASSERT_EQ(board.patients.size(), 1u);
  const agg::PatientView& a = board.patients[0];
  EXPECT_EQ(a.recording, kRecA);
  EXPECT_EQ(a.windows, 2u);
  EXPECT_EQ(a.latest.iri, other.value);
  EXPECT_EQ(a.source, kHospital + "/other-hrv");
  EXPECT_TRUE(a.irregular());
  EXPECT_TRUE(board.unreadable.empty());
}

// A window that names a recording both ways, differently (its IRI extends <A> and it is derived
// from <A>; its tv:recording says <B>), is <A>'s, as read_hrv_window reads it whole, whatever
// order its triples come in: the count, the latest window and the trend all go to one patient.
TEST_F(PatientsOnBoard, AWindowThatNamesTwoRecordingsIsTheOneItsIriExtendsWhenDerivedFromIt) {
  window("home1-hrv", kRecA, 0, 50);
  const tn::Term both = tn::Term::iri(agg::hrv_iri(kRecA, 60));
  tn::Item named;
  named.add(both, agg::tv_term("sdnnMs"), tn::Term::literal("70.0", std::string(tn::xsd::kDecimal)))
      .add(both, agg::tv_term("recording"), tn::Term::iri(kRecB))
      .add(both, agg::tv_term("windowEndS"), tn::Term::literal("120.0", std::string(tn::xsd::kDecimal)))
      .add(both, tn::Term::iri("http://www.w3.org/ns/sosa/observedProperty"), agg::tv_term("HeartRateVariability"))
      .add(both, tn::Term::iri("http://www.w3.org/ns/prov#wasDerivedFrom"), tn::Term::iri(kRecA + "/rr/1"))
      .add(both, tn::Term::iri("http://www.w3.org/ns/prov#wasDerivedFrom"), tn::Term::iri(kRecA))
      .add(both, agg::tv_term("windowStartS"), tn::Term::literal("60.0", std::string(tn::xsd::kDecimal)));
  store("other-hrv", named);
  trend(kRecA, agg::HrvMetric::sdnn, 60, false);

  const agg::PatientsOnBoard board = read();
  ASSERT_EQ(board.patients.size(), 1u) << "no patient for <B>";
  const agg::PatientView& a = board.patients[0];
  EXPECT_EQ(a.recording, kRecA);
  EXPECT_EQ(a.windows, 2u);
  EXPECT_EQ(a.latest.iri, both.value);
  EXPECT_EQ(a.latest.recording, kRecA);
  EXPECT_EQ(a.latest.window.start_s, 60);
  ASSERT_EQ(a.trends.size(), 1u);
  EXPECT_EQ(a.trends[0].window_start_s, 60);
}

// The chain asserts a window and the trend after it at the window's signal time: --since keeps
// the patients with a window since then, and of each only what is that recent.
TEST_F(PatientsOnBoard, SinceKeepsOnlyWindowsAndTrendsOfSignalTimeSinceThen) {
  const std::int64_t t0 = 1'700'000'000'000'000'000, minute = 60'000'000'000;
  window("home1-hrv", kRecA, 0, 50, std::nullopt, t0);
  window("home1-hrv", kRecA, 60, 52, std::nullopt, t0 + minute);
  window("home2-hrv", kRecB, 0, 40, std::nullopt, t0);
  trend(kRecA, agg::HrvMetric::sdnn, 0, true, t0);
  trend(kRecA, agg::HrvMetric::sdnn, 60, false, t0 + minute);
  trend(kRecA, agg::HrvMetric::rmssd, 0, false, t0);

  const agg::PatientsOnBoard all = read();
  ASSERT_EQ(all.patients.size(), 2u);
  const agg::PatientsOnBoard recent = read(t0 + minute / 2);
  ASSERT_EQ(recent.patients.size(), 1u) << "B has no window since then";
  const agg::PatientView& a = recent.patients[0];
  EXPECT_EQ(a.recording, kRecA);
  EXPECT_EQ(a.windows, 1u);
  EXPECT_EQ(a.latest.window.start_s, 60);
  EXPECT_EQ(a.latest_asserted_ns, t0 + minute);
  ASSERT_EQ(a.trends.size(), 1u) << "the RMSSD trend is of the earlier window";
  EXPECT_EQ(a.trends[0].window_start_s, 60);
}

// The view reads the trend updates of the last windows first (those since the earliest of the
// patients' latest windows, less a quarter of an hour) and the older ones only for what those
// leave out; the answer is the latest update per metric either way.
TEST_F(PatientsOnBoard, ATrendOlderThanThePatientsLatestWindowsIsStillTheirLatest) {
  const std::int64_t t0 = 1'700'000'000'000'000'000, hour = 3'600'000'000'000;
  // A: the trend agent stopped two hours before A's latest window.
  window("home1-hrv", kRecA, 0, 50, std::nullopt, t0);
  window("home1-hrv", kRecA, 7200, 52, std::nullopt, t0 + 2 * hour);
  trend(kRecA, agg::HrvMetric::sdnn, 0, true, t0);
  trend(kRecA, agg::HrvMetric::rmssd, 0, false, t0);
  // B: its RMSSD was last updated an hour before its latest window, its SDNN at it.
  window("home2-hrv", kRecB, 0, 40, std::nullopt, t0 + hour);
  window("home2-hrv", kRecB, 3600, 41, std::nullopt, t0 + 2 * hour);
  trend(kRecB, agg::HrvMetric::rmssd, 0, false, t0 + hour);
  trend(kRecB, agg::HrvMetric::sdnn, 0, false, t0 + hour);
  trend(kRecB, agg::HrvMetric::sdnn, 3600, false, t0 + 2 * hour);

  const agg::PatientsOnBoard board = read();
  ASSERT_EQ(board.patients.size(), 2u);
  const agg::PatientView& a = board.patients[0];
  ASSERT_EQ(a.recording, kRecA);
  ASSERT_EQ(a.trends.size(), 2u);
  EXPECT_EQ(a.trends[0].metric, agg::HrvMetric::sdnn);
  EXPECT_EQ(a.trends[0].window_start_s, 0);
  EXPECT_TRUE(a.alerting());
  EXPECT_EQ(a.trends[1].metric, agg::HrvMetric::rmssd);
  const agg::PatientView& b = board.patients[1];
  ASSERT_EQ(b.recording, kRecB);
  ASSERT_EQ(b.trends.size(), 2u);
  EXPECT_EQ(b.trends[0].metric, agg::HrvMetric::sdnn);
  EXPECT_EQ(b.trends[0].window_start_s, 3600);
  EXPECT_EQ(b.trends[1].metric, agg::HrvMetric::rmssd);
  EXPECT_EQ(b.trends[1].window_start_s, 0);

  // With --since, the older updates are looked for only since then.
  const agg::PatientsOnBoard since = read(t0 + hour);
  ASSERT_EQ(since.patients.size(), 2u);
  EXPECT_TRUE(since.patients[0].trends.empty()) << "A has no update since then";
  EXPECT_EQ(since.patients[1].trends.size(), 2u);
}

// A metric the trend agent no longer writes (--metric changed) still shows its latest update:
// the older updates are read for it.
TEST_F(PatientsOnBoard, AMetricNoLongerWrittenStillShowsItsLatestUpdate) {
  const std::int64_t t0 = 1'700'000'000'000'000'000, hour = 3'600'000'000'000;
  for (const std::string& rec : {kRecA, kRecB}) {
    window(rec == kRecA ? "home1-hrv" : "home2-hrv", rec, 0, 50, std::nullopt, t0);
    window(rec == kRecA ? "home1-hrv" : "home2-hrv", rec, 3600, 50, std::nullopt, t0 + hour);
    trend(rec, agg::HrvMetric::pnn50, 0, false, t0);
    trend(rec, agg::HrvMetric::sdnn, 3600, false, t0 + hour);
  }
  const agg::PatientsOnBoard board = read();
  ASSERT_EQ(board.patients.size(), 2u);
  for (const agg::PatientView& p : board.patients) {
    ASSERT_EQ(p.trends.size(), 2u) << p.recording;
    EXPECT_EQ(p.trends[0].metric, agg::HrvMetric::sdnn);
    EXPECT_EQ(p.trends[0].window_start_s, 3600);
    EXPECT_EQ(p.trends[1].metric, agg::HrvMetric::pnn50);
    EXPECT_EQ(p.trends[1].window_start_s, 0);
  }
}

// Where the raw ECG behind a window is: the writer's node, its IRI less the agent's id, for an
// IRI with an authority or without one (a deployment rooted at a URN).
// Two HRV agents on one recording: the hospital's own from a home's RR intervals, and the
// home's, relayed, under the same window names. The patient is the home's windows (its node
// holds the raw ECG), and the hospital's are named with their count, not mixed in.
TEST_F(PatientsOnBoard, WindowsOfTwoWritersShowTheWriterNearestTheRecordingAndNameTheOther) {
  const std::string home_hrv = kHospital + "/home1/hrv";
  std::vector<tn::RelayedItem> relayed;
  for (int k = 0; k < 3; ++k) {
    agg::RecordingInfo info;
    info.iri = kRecA;
    agg::WindowMetrics w;
    w.start_s = 60.0 * k;
    w.end_s = w.start_s + 60;
    w.metrics.sdnn_ms = 40 + k;
    w.metrics.nn_count = w.metrics.rr_count = 70;
    relayed.push_back({.seq = static_cast<std::uint64_t>(k + 1), .prev = static_cast<std::uint64_t>(k), .source = home_hrv,
                       .item = agg::hrv_window_item(info, w, home_hrv)});
  }
  window("hrv", kRecA, 0, 90);
  window("hrv", kRecA, 60, 91);
  auto home1 = node_->agent("home1");
  ASSERT_TRUE(home1);
  ASSERT_TRUE(home1->relay("up", relayed));
  window("hrv", kRecA, 120, 92);  // the hospital's latest, stored last
  window("hrv", kRecA, 180, 93);  // and one the home has not

  const agg::PatientsOnBoard board = read();
  ASSERT_EQ(board.patients.size(), 1u);
  const agg::PatientView& a = board.patients[0];
  EXPECT_EQ(a.source, home_hrv);
  EXPECT_EQ(a.source_node(), kHospital + "/home1");
  EXPECT_EQ(a.windows, 3u);
  EXPECT_EQ(a.latest.window.start_s, 120);
  EXPECT_EQ(a.latest.window.metrics.sdnn_ms, 42);
  ASSERT_EQ(a.other_writers.size(), 1u);
  EXPECT_EQ(a.other_writers[0].first, kHospital + "/hrv");
  EXPECT_EQ(a.other_writers[0].second, 4u);
}

// A sensor restarted (or taken out of a deployment and put back) starts a new recording: the
// same bed showed as two patients, the earlier one still with its alert, and nothing said which
// was current. The earlier is now named superseded by the later (whose latest window starts more
// than a window after the earlier's, in signal time); one whose windows came at the same time,
// and another sensor's recording, are not.
TEST_F(PatientsOnBoard, AnEarlierRecordingOfTheSameSensorIsSupersededByTheLater) {
  const std::string earlier = kHospital + "/home3/ecg/recording/synthetic-1";  // after kRecB by IRI
  const std::string later = kHospital + "/home3/ecg/recording/synthetic-2";
  const std::int64_t t0 = 1'700'000'000'000'000'000;  // 2023: windows of the past, as live ones are
  window("home3-hrv", later, 0, 45, std::nullopt, t0 + 600'000'000'000);
  window("home3-hrv", earlier, 0, 40, std::nullopt, t0);
  window("home3-hrv", earlier, 60, 41, std::nullopt, t0 + 60'000'000'000);
  trend(earlier, agg::HrvMetric::sdnn, 60, true, t0 + 60'000'000'000);
  window("home2-hrv", kRecB, 0, 50, std::nullopt, t0);
  // A recording of the sensor whose windows come at the same time as the later one's (within a
  // window): two at once, neither superseded.
  const std::string beside = kHospital + "/home3/ecg/recording/synthetic-3";
  window("home3-hrv", beside, 0, 44, std::nullopt, t0 + 590'000'000'000);
  // Two recordings of a sensor started 10 s apart, each with its first window, stored in the
  // order they started: two at once (the later one's first window came after the other's last).
  const std::string first_of_two = kHospital + "/home6/ecg/recording/a";
  const std::string second_of_two = kHospital + "/home6/ecg/recording/b";
  window("home6-hrv", first_of_two, 0, 33, std::nullopt, t0);
  window("home6-hrv", second_of_two, 0, 34, std::nullopt, t0 + 10'000'000'000);
  // A replay at --speed 10 started during a live recording of its sensor: its windows are
  // asserted ahead of the clock, the live one's go on coming. The live one is not superseded.
  const std::int64_t now = std::chrono::duration_cast<std::chrono::nanoseconds>(
                               std::chrono::system_clock::now().time_since_epoch()).count();
  const std::string live_beside = kHospital + "/home5/ecg/recording/synthetic-1";
  const std::string ahead = kHospital + "/home5/ecg/recording/100";
  window("home5-hrv", live_beside, 0, 35, std::nullopt, now - 120'000'000'000);
  window("home5-hrv", ahead, 1740, 36, std::nullopt, now + 3'600'000'000'000);
  window("home5-hrv", live_beside, 60, 37, std::nullopt, now - 60'000'000'000);
  // A replay that finished, then a live recording of its sensor, started after it. The replay's
  // windows are the later in signal time, but it is the one whose windows stopped being stored.
  const std::string replay = kHospital + "/home4/ecg/recording/100";
  const std::string live = kHospital + "/home4/ecg/recording/synthetic-1";
  window("home4-hrv", replay, 0, 30, std::nullopt, t0);
  window("home4-hrv", replay, 1740, 31, std::nullopt, t0 + 1'740'000'000'000);
  std::this_thread::sleep_for(std::chrono::milliseconds(300));  // many times the replay's pace
  window("home4-hrv", live, 0, 32, std::nullopt, t0 + 2'000'000'000'000);
  const agg::PatientsOnBoard board = read();
  ASSERT_EQ(board.patients.size(), 10u);
  EXPECT_EQ(board.patients[0].recording, kRecB) << "an alert of a superseded recording does not put it first";
  for (const agg::PatientView& p : board.patients) {
    if (p.recording == earlier) {
      EXPECT_EQ(p.superseded_by, later);
      EXPECT_TRUE(p.alerting()) << "its alert is still its own";
    } else if (p.recording == replay) {
      EXPECT_EQ(p.superseded_by, live);
    } else {
      EXPECT_EQ(p.superseded_by, "") << p.recording;
    }
  }
}

// A window without beats (a lead off) has trend updates without a value or an alert: the alert
// of the windows before it left the patient's view as the beats stopped, with nothing said (an
// exploratory run of session 84). Such a patient is shown with the alerting ones.
TEST_F(PatientsOnBoard, APatientWhoseLatestWindowHasNoBeatsComesWithTheAlertingOnes) {
  window("home1-hrv", kRecA, 0, 50);
  window("home2-hrv", kRecB, 0, 40);
  window("home2-hrv", kRecB, 60, 20);
  trend(kRecB, agg::HrvMetric::sdnn, 60, true);
  agg::RecordingInfo info;
  info.iri = kRecB;
  agg::WindowMetrics silent;  // no beats: no metrics, no intervals
  silent.start_s = 120;
  silent.end_s = 180;
  store("home2-hrv", agg::hrv_window_item(info, silent, kHospital + "/home2-hrv"));
  agg::TrendUpdate lead_off;
  lead_off.recording = kRecB;
  lead_off.metric = agg::HrvMetric::sdnn;
  lead_off.window_start_s = 120;
  lead_off.window_iri = agg::hrv_iri(kRecB, 120);
  lead_off.windows = 2;
  store("trend", agg::trend_item(lead_off, kHospital + "/trend"));
  const agg::PatientsOnBoard board = read();
  ASSERT_EQ(board.patients.size(), 2u);
  EXPECT_EQ(board.patients[0].recording, kRecB);
  EXPECT_FALSE(board.patients[0].alerting());
  EXPECT_TRUE(board.patients[0].no_beats());
  EXPECT_FALSE(board.patients[1].no_beats());
}

TEST(PatientView, TheSourceNodeIsTheWritersIriLessItsLastSegment) {
  agg::PatientView p;
  auto node_of = [&](const std::string& source) {
    p.source = source;
    return p.source_node();
  };
  EXPECT_EQ(node_of("http://example.org/hospital/home1/hrv"), "http://example.org/hospital/home1");
  EXPECT_EQ(node_of("urn:tahvel:h/home1/hrv"), "urn:tahvel:h/home1");
  EXPECT_EQ(node_of("https://h.example:8443/care/north/hrv"), "https://h.example:8443/care/north");
  EXPECT_EQ(node_of("http://example.org/hrv"), "http://example.org");
  EXPECT_EQ(node_of("http://hrv"), "");
  EXPECT_EQ(node_of("urn:hrv"), "");
  EXPECT_EQ(node_of("urn:/hrv"), "");
  EXPECT_EQ(node_of("hrv"), "");
}

TEST_F(PatientsOnBoard, ABoardWithoutHrvHasNoPatients) {
  store("cli", tn::Item{}.add(tn::Term::iri(kHospital + "/x"), agg::tv_term("note"), tn::Term::literal("hello")));
  const agg::PatientsOnBoard board = read();
  EXPECT_TRUE(board.patients.empty());
  EXPECT_TRUE(board.unreadable.empty());
}

}  // namespace
