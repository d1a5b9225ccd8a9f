// Trends (trend.h): baseline, slope, alerts and the cross-patient z-score on synthetic series.
#include <gtest/gtest.h>

#include <cmath>

#include "tahvel/aggregation/trend.h"

namespace tahvel::aggregation {
namespace {

std::vector<TrendPoint> series(const std::vector<double>& values, double step_s = 300) {
  std::vector<TrendPoint> p;
  for (std::size_t i = 0; i < values.size(); ++i) p.push_back({static_cast<double>(i) * step_s, values[i]});
  return p;
}

TEST(Trend, BaselineIsTheMedianWithMadScale) {
  const auto s = analyse_trend(series({50, 52, 48, 51, 49, 100, 50, 51}));
  ASSERT_TRUE(s.baseline);
  EXPECT_DOUBLE_EQ(*s.baseline, 50.5);  // median of the first 6: the 100 does not drag it
  // |deviations| 0.5 1.5 2.5 0.5 1.5 49.5 -> MAD 1.5
  EXPECT_DOUBLE_EQ(*s.robust_sd, 1.4826 * 1.5);
  EXPECT_DOUBLE_EQ(*s.latest, 51);
  EXPECT_TRUE(s.alerts.empty());
}

TEST(Trend, SlopePerHourByLeastSquares) {
  // 5-minute points rising 1 unit per point: 12 per hour.
  std::vector<double> v;
  for (int i = 0; i < 20; ++i) v.push_back(40 + i);
  const auto s = analyse_trend(series(v));
  EXPECT_NEAR(*s.slope_per_hour, 12.0, 1e-9);
  EXPECT_FALSE(analyse_trend(series({3})).slope_per_hour);
  EXPECT_FALSE(analyse_trend(series({3})).baseline);
}

TEST(Trend, AlertNeedsConsecutiveDepartures) {
  // Baseline 50, MAD 1 -> robust SD 1.4826, threshold 4.45 away.
  std::vector<double> v{49, 51, 50, 49, 51, 50};
  for (double x : {56.0, 50.0, 57.0, 58.0, 59.0, 60.0, 50.0, 40.0, 41.0, 40.0}) v.push_back(x);
  const auto s = analyse_trend(series(v));
  ASSERT_EQ(s.alerts.size(), 2u);
  EXPECT_EQ(s.alerts[0].first, 8u);
  EXPECT_EQ(s.alerts[0].last, 11u);
  EXPECT_EQ(s.alerts[0].direction, 1);
  EXPECT_EQ(s.alerts[1].first, 13u);
  EXPECT_EQ(s.alerts[1].last, 15u);
  EXPECT_EQ(s.alerts[1].direction, -1);
  EXPECT_TRUE(s.alerting);
}

// Windows of 300 s every 60 s share most of their beats: six of them are 10 minutes of signal,
// not 30, and three in a row one excursion. With their length known the baseline spans five
// window lengths and an alert's run two, as for windows that do not overlap (a stationary
// synthetic ECG of 2 hours alerted in 22 of 116 RMSSD items: an exploratory run of session 84).
TEST(Trend, OverlappingWindowsSpanTheBaselineAndAnAlertsRunInWindowLengths) {
  // Points every 60 s: 6 at 41 ± 1, then 20 at 50 ± 1, then a step to 60.
  std::vector<double> v;
  for (int i = 0; i < 6; ++i) v.push_back(i % 2 ? 42.0 : 40.0);
  for (int i = 0; i < 20; ++i) v.push_back(i % 2 ? 51.0 : 49.0);
  for (int i = 0; i < 4; ++i) v.push_back(60.0);
  const TrendOptions by_count;
  const auto counted = analyse_trend(series(v, 60), by_count);
  ASSERT_TRUE(counted.baseline);
  EXPECT_EQ(*counted.baseline, 41.0) << "six points: 6 minutes of signal";
  EXPECT_FALSE(counted.alerts.empty());
  TrendOptions by_length;
  by_length.window_s = 300;
  EXPECT_FALSE(analyse_trend(series({v.begin(), v.begin() + 25}, 60), by_length).baseline) << "25 points span 24 minutes";
  const auto spanned = analyse_trend(series(v, 60), by_length);
  ASSERT_TRUE(spanned.baseline);
  EXPECT_EQ(*spanned.baseline, 49.0) << "26 points: they span five window lengths";
  EXPECT_TRUE(spanned.alerts.empty()) << "four points above span less than two window lengths";
  v.resize(v.size() + 7, 60.0);  // eleven in a row: two window lengths
  const auto longer = analyse_trend(series(v, 60), by_length);
  ASSERT_EQ(longer.alerts.size(), 1u);
  EXPECT_EQ(longer.alerts[0].first, 26u);
  EXPECT_EQ(longer.alerts[0].last, 36u);
  EXPECT_EQ(longer.alerts[0].direction, 1);
  EXPECT_TRUE(longer.alerting);
  // Windows that do not overlap: as without their length.
  const std::vector<double> plain{49, 51, 50, 49, 51, 50, 56, 50, 57, 58, 59};
  EXPECT_EQ(analyse_trend(series(plain), by_length).alerts.size(), 1u);
  EXPECT_EQ(analyse_trend(series(plain), by_count).alerts.size(), 1u);
}

// A recording monitored for weeks: the trend agent keeps its baseline and forgets the points it
// was made of, and the slope reaches back a horizon. Judged with the baseline kept, the points
// of the last hours alert as the whole series does; the slope is of those hours alone.
TEST(Trend, ABaselineKeptJudgesTheLaterPointsAsTheWholeSeriesDoes) {
  std::vector<double> v{49, 51, 50, 49, 51, 50};
  for (int i = 0; i < 30; ++i) v.push_back(50 + (i % 3) - 1);
  for (int i = 0; i < 12; ++i) v.push_back(60 + i);  // the last hour: above, and rising 12 an hour
  const auto all = series(v);
  const auto baseline = trend_baseline(all);
  ASSERT_TRUE(baseline);
  EXPECT_DOUBLE_EQ(baseline->value, 50);
  EXPECT_DOUBLE_EQ(baseline->until_s, 5 * 300);
  EXPECT_FALSE(trend_baseline({all.begin(), all.begin() + 5}));
  const std::vector<TrendPoint> recent(all.end() - 14, all.end());
  const auto whole = analyse_trend(all);
  const auto kept = analyse_trend(recent, {}, baseline);
  ASSERT_TRUE(kept.baseline);
  EXPECT_DOUBLE_EQ(*kept.baseline, *whole.baseline);
  EXPECT_DOUBLE_EQ(*kept.robust_sd, *whole.robust_sd);
  EXPECT_TRUE(whole.alerting);
  EXPECT_TRUE(kept.alerting);
  ASSERT_FALSE(kept.alerts.empty());
  EXPECT_EQ(kept.alerts.back().first, 2u) << "indices into the points given";
  EXPECT_EQ(kept.alerts.back().direction, 1);
  // Points that end before the baseline's last point have none yet, and are not judged.
  const auto early = analyse_trend({all.begin(), all.begin() + 3}, {}, baseline);
  EXPECT_FALSE(early.baseline);
  EXPECT_TRUE(early.alerts.empty());
  // The slope: of every point, or of those within the horizon of the last.
  TrendOptions hour;
  hour.slope_horizon_s = 3600;
  const auto horizon = analyse_trend(all, hour);
  ASSERT_TRUE(horizon.slope_per_hour);
  const auto last_hour = analyse_trend({all.end() - 13, all.end()});  // 13 points: 51, then 60..71
  EXPECT_DOUBLE_EQ(*horizon.slope_per_hour, *last_hour.slope_per_hour);
  EXPECT_GT(*horizon.slope_per_hour, 12.0);
  ASSERT_TRUE(whole.slope_per_hour);
  EXPECT_LT(*whole.slope_per_hour, *horizon.slope_per_hour);
  EXPECT_EQ(*analyse_trend(recent, hour, baseline).slope_per_hour, *horizon.slope_per_hour)
      << "the horizon's points, whatever came before them";
}

TEST(Trend, SideChangeRestartsTheRun) {
  std::vector<double> v{49, 51, 50, 49, 51, 50, 60, 40, 60, 40};
  EXPECT_TRUE(analyse_trend(series(v)).alerts.empty());
}

TEST(Trend, PointsFromWindowsSkipMissingMetrics) {
  std::vector<WindowMetrics> w(3);
  w[0].end_s = 300;
  w[0].metrics.sdnn_ms = 40;
  w[2].end_s = 900;
  w[2].metrics.sdnn_ms = 42;
  const auto p = trend_points(w, HrvMetric::sdnn);
  ASSERT_EQ(p.size(), 2u);
  EXPECT_DOUBLE_EQ(p[1].time_s, 900);
  EXPECT_DOUBLE_EQ(p[1].value, 42);
  EXPECT_FALSE(metric_value(w[1].metrics, HrvMetric::rmssd));
}

TEST(Trend, CrossPatientZ) {
  // others 10 20 30: mean 20, SD 10.
  EXPECT_DOUBLE_EQ(*cross_patient_z(35, {10, 20, 30}), 1.5);
  EXPECT_FALSE(cross_patient_z(35, {10}));
  EXPECT_FALSE(cross_patient_z(35, {10, 10}));
}

TEST(Trend, CrossPatientZHoldsOthersThatAgreeCloselyToTheMetricsResolution) {
  // Others that happen to agree closely are held to the metric's resolution, not to their SD:
  // 73.6498 and 73.6743 bpm (SD 0.017) made 76.48 bpm a z of +162.
  EXPECT_DOUBLE_EQ(*cross_patient_z(76.5, {73.5, 73.5}, 1.0), 3.0);
  EXPECT_NEAR(*cross_patient_z(76.48, {73.6498, 73.6743}, 1.0), 2.8180, 1e-4);
  EXPECT_DOUBLE_EQ(*cross_patient_z(35, {10, 20, 30}, 1.0), 1.5);  // an SD above the floor is the SD
}

}  // namespace
}  // namespace tahvel::aggregation
