// Hospital-side trends of one HRV metric over a patient's windows, and comparison of a
// patient's latest value with other patients'. Pure functions over small series (one point
// per window: 288 five-minute windows a day). Definitions in docs/hrv.md ("Trends").
#pragma once

#include <cstddef>
#include <optional>
#include <vector>

#include "tahvel/aggregation/hrv.h"

namespace tahvel::aggregation {

enum class HrvMetric { mean_nn, sdnn, rmssd, pnn50, mean_hr, lf, hf, lf_hf, sd1, sd2 };

// The value of one metric (nullopt when its guard failed).
std::optional<double> metric_value(const HrvMetrics& metrics, HrvMetric which) noexcept;

// The least change of a metric worth an alert's scale, in its unit: 1 ms (mean NN, SDNN, RMSSD,
// SD1, SD2), 1 bpm, 1 % (pNN50), 1 ms² (LF, HF), 0.05 (LF/HF). The trend agent floors the robust
// SD with it: a baseline of six equal values (a pNN50 of 0) has a MAD of 0, and then any change
// at all, one successive difference over 50 ms, was three robust SDs away.
double metric_resolution(HrvMetric which) noexcept;

// One point of a trend: time in seconds (any origin, ascending) and the metric's value.
struct TrendPoint {
  double time_s = 0;
  double value = 0;
};

// The points of one metric over windows, timed at each window's end; windows where the
// metric is nullopt are left out.
std::vector<TrendPoint> trend_points(const std::vector<WindowMetrics>& windows, HrvMetric which);

struct TrendOptions {
  std::size_t baseline_points = 6;  // baseline: median of the first K points (30 min of 5-min windows;
                                    // more points of overlapping ones: window_s)
  double alert_robust_sds = 3.0;    // departure threshold in robust SDs (1.4826 * MAD)
  std::size_t alert_consecutive = 3;  // points in a row beyond the threshold, on one side
  double min_robust_sd = 0.0;       // floor for the robust SD (a flat baseline has MAD 0)
  // The length of the windows the points are of, in s (0: not known). Windows that overlap (a
  // step shorter than the window) share most of their beats, so K and M points of them are
  // not K and M windows' worth of signal: the baseline then also spans (K - 1) window lengths
  // and an alert's run (M - 1), so that the step does not change what a series says. (Points
  // of 300-s windows every 60 s made the baseline 10 minutes and an alert one excursion of 7:
  // a stationary synthetic ECG of 2 hours alerted in 22 of 116 RMSSD items.)
  double window_s = 0.0;
  // The slope's reach, in s (0: every point): the slope is of the points that end at most this
  // long before the last one. A recording monitored for weeks is judged by its recent course,
  // and its trend agent keeps no more than that (tahvel-trend --horizon-h).
  double slope_horizon_s = 0.0;
};

// A series' baseline: the median and robust SD of its first points (TrendOptions), and the
// time of the last of them; the points after it are judged against it.
struct TrendBaseline {
  double value = 0;
  double robust_sd = 0;
  double until_s = 0;
};

// The baseline of a series from its first points (ascending in time); nullopt while it is too
// short. The trend agent keeps it when it forgets the points it was made of.
std::optional<TrendBaseline> trend_baseline(const std::vector<TrendPoint>& points, const TrendOptions& options = {});

// A change alert: points [first, last] (indices into the series) lie beyond the threshold on
// one side (direction +1 above, -1 below); raised at point first + alert_consecutive - 1.
struct TrendAlert {
  std::size_t first = 0, last = 0;
  int direction = 0;
};

struct TrendSummary {
  std::optional<double> baseline;        // median of the first K points, or more (window_s)
  std::optional<double> robust_sd;       // max(1.4826 * MAD of those points, min_robust_sd)
  std::optional<double> slope_per_hour;  // least-squares slope, value units per hour (>= 2 distinct
                                         // times within slope_horizon_s of the last point)
  std::optional<double> latest;          // value of the last point
  std::vector<TrendAlert> alerts;        // in order; points before K are not judged
  bool alerting = false;                 // the last alert runs to the last point
};

// Baseline, slope and alerts of one series (points ascending in time).
TrendSummary analyse_trend(const std::vector<TrendPoint>& points, const TrendOptions& options = {});
// The same with the series' baseline found earlier (trend_baseline), when `points` need not
// begin where the series does: a series that ends before the baseline's last point has none
// yet, and only the points after it are judged. Alert indices are into `points`.
TrendSummary analyse_trend(const std::vector<TrendPoint>& points, const TrendOptions& options,
                           const std::optional<TrendBaseline>& baseline);

// z-score of value against others: (value - mean) / SD (n - 1) of others, the SD floored at
// min_sd (the metric's resolution: two others 0.02 bpm apart made a z of 3,000 from a 6 bpm
// difference); nullopt with fewer than two others or when the SD, floored, is 0.
std::optional<double> cross_patient_z(double value, const std::vector<double>& others, double min_sd = 0) noexcept;

}  // namespace tahvel::aggregation
