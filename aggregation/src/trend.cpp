// Trends: a median baseline with a MAD scale is robust to the odd artefactual window, which
// a mean and SD would let drag the baseline; alerts need several windows in a row so one
// noisy window does not page anyone.
#include "tahvel/aggregation/trend.h"

#include <algorithm>
#include <cmath>

namespace tahvel::aggregation {

namespace {

double median_of(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  const std::size_t m = v.size() / 2;
  return v.size() % 2 ? v[m] : (v[m - 1] + v[m]) / 2;
}

std::optional<double> least_squares_slope(const std::vector<TrendPoint>& p) {
  if (p.size() < 2) return std::nullopt;
  double mt = 0, mv = 0;
  for (const auto& x : p) mt += x.time_s, mv += x.value;
  mt /= static_cast<double>(p.size());
  mv /= static_cast<double>(p.size());
  double stt = 0, stv = 0;
  for (const auto& x : p) {
    stt += (x.time_s - mt) * (x.time_s - mt);
    stv += (x.time_s - mt) * (x.value - mv);
  }
  if (!(stt > 0)) return std::nullopt;
  return stv / stt * 3600.0;
}

}  // namespace

std::optional<double> metric_value(const HrvMetrics& m, HrvMetric which) noexcept {
  switch (which) {
    case HrvMetric::mean_nn: return m.mean_nn_ms;
    case HrvMetric::sdnn: return m.sdnn_ms;
    case HrvMetric::rmssd: return m.rmssd_ms;
    case HrvMetric::pnn50: return m.pnn50_pct;
    case HrvMetric::mean_hr: return m.mean_hr_bpm;
    case HrvMetric::lf: return m.lf_ms2;
    case HrvMetric::hf: return m.hf_ms2;
    case HrvMetric::lf_hf: return m.lf_hf;
    case HrvMetric::sd1: return m.sd1_ms;
    case HrvMetric::sd2: return m.sd2_ms;
  }
  return std::nullopt;
}

std::vector<TrendPoint> trend_points(const std::vector<WindowMetrics>& windows, HrvMetric which) {
  std::vector<TrendPoint> out;
  for (const auto& w : windows) {
    if (auto v = metric_value(w.metrics, which)) out.push_back({w.end_s, *v});
  }
  return out;
}

double metric_resolution(HrvMetric which) noexcept {
  switch (which) {
    case HrvMetric::mean_hr: return 1.0;   // bpm
    case HrvMetric::pnn50: return 1.0;     // %
    case HrvMetric::lf:
    case HrvMetric::hf: return 1.0;        // ms²
    case HrvMetric::lf_hf: return 0.05;
    default: return 1.0;                   // ms
  }
}

std::optional<TrendBaseline> trend_baseline(const std::vector<TrendPoint>& points, const TrendOptions& o) {
  // The first K points, and as many more as make them span (K - 1) window lengths; not yet one
  // while the series is shorter.
  const std::size_t k_least = std::max<std::size_t>(o.baseline_points, 1);
  // Less a millisecond: window times are kept to the microsecond, and lengths a millisecond
  // apart are one setting (the trend agent's same_length).
  const double span = o.window_s > 0 ? static_cast<double>(k_least - 1) * o.window_s - 1e-3 : 0.0;
  std::size_t k = k_least;
  while (k <= points.size() && points[k - 1].time_s - points.front().time_s < span) ++k;
  if (points.size() < k) return std::nullopt;
  std::vector<double> first;
  for (std::size_t i = 0; i < k; ++i) first.push_back(points[i].value);
  const double base = median_of(first);
  for (double& v : first) v = std::abs(v - base);
  return TrendBaseline{base, std::max(1.4826 * median_of(first), o.min_robust_sd), points[k - 1].time_s};
}

TrendSummary analyse_trend(const std::vector<TrendPoint>& points, const TrendOptions& o) {
  return analyse_trend(points, o, trend_baseline(points, o));
}

TrendSummary analyse_trend(const std::vector<TrendPoint>& points, const TrendOptions& o,
                           const std::optional<TrendBaseline>& baseline) {
  TrendSummary s;
  if (points.empty()) return s;
  s.latest = points.back().value;
  if (o.slope_horizon_s > 0) {
    const double from = points.back().time_s - o.slope_horizon_s - 1e-3;
    const auto first = std::find_if(points.begin(), points.end(), [&](const TrendPoint& p) { return p.time_s >= from; });
    s.slope_per_hour = least_squares_slope({first, points.end()});
  } else {
    s.slope_per_hour = least_squares_slope(points);
  }
  if (!baseline || points.back().time_s < baseline->until_s) return s;
  const double base = baseline->value;
  const double rsd = baseline->robust_sd;
  s.baseline = base;
  s.robust_sd = rsd;
  // An alert: M points in a row beyond the threshold on one side, spanning (M - 1) window
  // lengths when those are known.
  const std::size_t need = std::max<std::size_t>(o.alert_consecutive, 1);
  const double run_span = o.window_s > 0 ? static_cast<double>(need - 1) * o.window_s - 1e-3 : 0.0;
  std::size_t run = 0;
  int side = 0;
  bool raised = false;
  const std::size_t k = static_cast<std::size_t>(
      std::upper_bound(points.begin(), points.end(), baseline->until_s,
                       [](double t, const TrendPoint& p) { return t < p.time_s; }) -
      points.begin());
  for (std::size_t i = k; i < points.size(); ++i) {
    const double dev = points[i].value - base;
    const int here = std::abs(dev) > o.alert_robust_sds * rsd ? (dev > 0 ? 1 : -1) : 0;
    run = (here != 0 && here == side) ? run + 1 : (here != 0 ? 1 : 0);
    side = here;
    if (run <= 1) raised = false;
    if (run == 0) continue;
    const std::size_t from = i + 1 - run;
    if (!raised && run >= need && points[i].time_s - points[from].time_s >= run_span) {
      s.alerts.push_back({from, i, side});
      raised = true;
    } else if (raised) {
      s.alerts.back().last = i;
    }
  }
  s.alerting = !s.alerts.empty() && s.alerts.back().last == points.size() - 1;
  return s;
}

std::optional<double> cross_patient_z(double value, const std::vector<double>& others, double min_sd) noexcept {
  if (others.size() < 2) return std::nullopt;
  double m = 0;
  for (double x : others) m += x;
  m /= static_cast<double>(others.size());
  double ss = 0;
  for (double x : others) ss += (x - m) * (x - m);
  const double sd = std::max(std::sqrt(ss / static_cast<double>(others.size() - 1)), min_sd);
  if (!(sd > 0)) return std::nullopt;
  return (value - m) / sd;
}

}  // namespace tahvel::aggregation
