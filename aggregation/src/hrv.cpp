// HRV metrics. The Lomb-Scargle periodogram runs over the NN series as it is (unevenly timed,
// with gaps where intervals were not NN) instead of interpolating and resampling: resampling
// invents values across gaps and low-pass filters the HF band. The inner loop keeps cos/sin
// of omega * t for every sample and advances them by one frequency step with the angle-sum
// recurrence, so each frequency costs a few multiply-adds per sample and no trig calls.
#include "tahvel/aggregation/hrv.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <limits>

namespace tahvel::aggregation {

namespace {

constexpr double kTwoPi = 6.283185307179586476925286766559;

struct NnSeries {
  std::vector<double> t_s, nn_ms;   // NN intervals timed at their end beat
  std::vector<double> diffs_samples;  // differences of adjacent NN intervals, in samples
  double nn_seconds = 0;  // summed in samples, then divided: 21,600 samples at 360 Hz are 60 s
};

NnSeries collect(const std::vector<Interval>& intervals, double fs) {
  NnSeries s;
  std::uint64_t nn_samples = 0;
  for (std::size_t i = 0; i < intervals.size(); ++i) {
    const Interval& iv = intervals[i];
    if (!iv.nn || iv.end <= iv.start) continue;
    const double len = static_cast<double>(iv.end - iv.start);
    s.t_s.push_back(static_cast<double>(iv.end) / fs);
    s.nn_ms.push_back(len * 1000.0 / fs);
    nn_samples += static_cast<std::uint64_t>(iv.end - iv.start);
    if (i > 0) {
      const Interval& prev = intervals[i - 1];
      if (prev.nn && prev.end == iv.start && prev.end > prev.start) {
        s.diffs_samples.push_back(len - static_cast<double>(prev.end - prev.start));
      }
    }
  }
  s.nn_seconds = static_cast<double>(nn_samples) / fs;
  return s;
}

double mean(const std::vector<double>& v) {
  double sum = 0;
  for (double x : v) sum += x;
  return sum / static_cast<double>(v.size());
}

// Sample variance (n - 1); v.size() >= 2.
double sample_variance(const std::vector<double>& v) {
  const double m = mean(v);
  double ss = 0;
  for (double x : v) ss += (x - m) * (x - m);
  return ss / static_cast<double>(v.size() - 1);
}

void time_domain(const NnSeries& s, double fs, HrvMetrics& out) {
  if (s.nn_ms.empty()) return;
  out.mean_nn_ms = mean(s.nn_ms);
  out.mean_hr_bpm = 60000.0 / *out.mean_nn_ms;
  if (s.nn_ms.size() >= 2) out.sdnn_ms = std::sqrt(sample_variance(s.nn_ms));
  const std::size_t nd = s.diffs_samples.size();
  if (nd < 2) return;
  const double to_ms = 1000.0 / fs;
  const double limit = 50.0 * fs / 1000.0;  // 50 ms in samples: 18 at 360 Hz
  double ss = 0;
  std::size_t over = 0;
  for (double d : s.diffs_samples) {
    ss += d * d;
    over += std::abs(d) > limit ? 1 : 0;
  }
  out.rmssd_ms = std::sqrt(ss / static_cast<double>(nd)) * to_ms;
  out.pnn50_pct = 100.0 * static_cast<double>(over) / static_cast<double>(nd);
  if (!out.sdnn_ms) return;
  const double sd1_sq = 0.5 * sample_variance(s.diffs_samples) * to_ms * to_ms;
  const double sd2_sq = 2.0 * *out.sdnn_ms * *out.sdnn_ms - sd1_sq;
  out.sd1_ms = std::sqrt(sd1_sq);
  if (sd2_sq >= 0) out.sd2_ms = std::sqrt(sd2_sq);
}

// Band power by the midpoint rule on a grid that divides the band exactly, its step no coarser
// than df_target: a peak about 1/span wide needs a few points across it.
double band_power(const std::vector<double>& t, const std::vector<double>& y, double lo,
                  double hi, double df_target, double hole_s) {
  if (!(hi > lo)) return 0;
  const auto count = std::max<std::size_t>(1, static_cast<std::size_t>(std::ceil((hi - lo) / df_target)));
  const double df = (hi - lo) / static_cast<double>(count);
  const std::vector<double> psd = lomb_scargle_density(t, y, lo + df / 2, df, count, hole_s);
  double sum = 0;
  for (double p : psd) sum += p;
  return sum * df;
}

}  // namespace

std::vector<double> lomb_scargle_density(const std::vector<double>& t_s,
                                         const std::vector<double>& nn_ms, double f0_hz,
                                         double df_hz, std::size_t count, double hole_s) {
  std::vector<double> psd(count, 0.0);
  const std::size_t n = std::min(t_s.size(), nn_ms.size());
  if (n < 3 || count == 0) return psd;
  double covered = 0;
  std::size_t spacings = 0;
  for (std::size_t j = 1; j < n; ++j) {
    const double d = t_s[j] - t_s[j - 1];
    if (d > hole_s) continue;
    covered += d;
    ++spacings;
  }
  if (spacings == 0) return psd;
  const double span = covered * static_cast<double>(n) / static_cast<double>(spacings);
  if (!(span > 0)) return psd;
  const double ym = mean(std::vector<double>(nn_ms.begin(), nn_ms.begin() + static_cast<std::ptrdiff_t>(n)));
  // Times relative to the first sample keep the recurrence's angles small.
  std::vector<double> y(n), c(n), s(n), dc(n), ds(n);
  for (std::size_t j = 0; j < n; ++j) {
    const double tj = t_s[j] - t_s[0];
    y[j] = nn_ms[j] - ym;
    c[j] = std::cos(kTwoPi * f0_hz * tj);
    s[j] = std::sin(kTwoPi * f0_hz * tj);
    dc[j] = std::cos(kTwoPi * df_hz * tj);
    ds[j] = std::sin(kTwoPi * df_hz * tj);
  }
  const double nd = static_cast<double>(n);
  const double scale = 2.0 * span / nd;  // periodogram -> one-sided density integrating to var
  for (std::size_t k = 0; k < count; ++k) {
    double yc = 0, ys = 0, c2 = 0, s2 = 0;
    for (std::size_t j = 0; j < n; ++j) {
      yc += y[j] * c[j];
      ys += y[j] * s[j];
      c2 += c[j] * c[j] - s[j] * s[j];
      s2 += 2 * c[j] * s[j];
    }
    // tau: tan(2 omega tau) = S2 / C2; rotate the sums by omega * tau.
    const double h = std::hypot(c2, s2);
    const double two_wt = std::atan2(s2, c2);
    const double cw = std::cos(two_wt / 2), sw = std::sin(two_wt / 2);
    const double cc = (nd + h) / 2, ss = (nd - h) / 2;  // sums of cos^2, sin^2 at omega(t - tau)
    const double a = yc * cw + ys * sw, b = ys * cw - yc * sw;
    double p = 0;
    if (cc > 1e-12 * nd) p += a * a / cc;
    if (ss > 1e-12 * nd) p += b * b / ss;
    psd[k] = 0.5 * p * scale;
    for (std::size_t j = 0; j < n; ++j) {  // advance omega by one step
      const double cn = c[j] * dc[j] - s[j] * ds[j];
      s[j] = s[j] * dc[j] + c[j] * ds[j];
      c[j] = cn;
    }
  }
  return psd;
}

BandPowers lomb_scargle_bands(const std::vector<double>& t_s, const std::vector<double>& nn_ms,
                              const HrvOptions& o) {
  BandPowers out;
  const std::size_t n = std::min(t_s.size(), nn_ms.size());
  if (n < 3) return out;
  const double span = t_s[n - 1] - t_s[0];
  if (!(span > 0)) return out;
  const double oversampling = std::max(o.oversampling, 1.0);
  const double width = (o.lf_high_hz - o.lf_low_hz) + (o.hf_high_hz - o.hf_low_hz);
  const double work = static_cast<double>(n) * width * oversampling * span;  // O(N * F)
  const auto parts = static_cast<std::size_t>(std::clamp(std::ceil(work / std::max(o.max_work, 1.0)), 1.0, static_cast<double>(n / 3)));
  if (parts <= 1) {
    const double df = 1.0 / (oversampling * span);
    out.lf_ms2 = band_power(t_s, nn_ms, o.lf_low_hz, o.lf_high_hz, df, o.gap_s);
    out.hf_ms2 = band_power(t_s, nn_ms, o.hf_low_hz, o.hf_high_hz, df, o.gap_s);
    return out;
  }
  // Too long for one periodogram at that step (a day of Holter ECG): equal parts of time, each
  // hours long, each at its own fine step, their band powers averaged by how many intervals each
  // holds. Parts that long lose nothing of LF and HF (a 25 s period at most), only of slower ones.
  double lf = 0, hf = 0, weight = 0;
  std::size_t begin = 0;
  for (std::size_t k = 1; k <= parts && begin < n; ++k) {
    const double until = t_s[0] + span * static_cast<double>(k) / static_cast<double>(parts);
    std::size_t end = begin;
    while (end < n && (k == parts || t_s[end] < until)) ++end;
    const std::vector<double> t(t_s.begin() + static_cast<std::ptrdiff_t>(begin), t_s.begin() + static_cast<std::ptrdiff_t>(end));
    const std::vector<double> y(nn_ms.begin() + static_cast<std::ptrdiff_t>(begin), nn_ms.begin() + static_cast<std::ptrdiff_t>(end));
    begin = end;
    if (t.size() < 3 || !(t.back() > t.front())) continue;
    HrvOptions one = o;
    one.max_work = std::numeric_limits<double>::infinity();
    const BandPowers piece = lomb_scargle_bands(t, y, one);
    const double w = static_cast<double>(t.size());
    lf += piece.lf_ms2 * w;
    hf += piece.hf_ms2 * w;
    weight += w;
  }
  if (weight > 0) {
    out.lf_ms2 = lf / weight;
    out.hf_ms2 = hf / weight;
  }
  return out;
}

HrvMetrics compute_hrv(const std::vector<Interval>& intervals, double fs, const HrvOptions& o) {
  HrvMetrics out;
  out.rr_count = intervals.size();
  if (!(fs > 0)) return out;
  std::size_t pairs = 0, irregular = 0;
  for (std::size_t i = 0; i + 1 < intervals.size(); ++i) {
    const Interval& a = intervals[i];
    const Interval& b = intervals[i + 1];
    if (a.end != b.start || a.end <= a.start || b.end <= b.start) continue;
    const double gap = o.gap_s * fs;
    if (static_cast<double>(a.end - a.start) > gap || static_cast<double>(b.end - b.start) > gap) continue;
    ++pairs;
    const double first = static_cast<double>(a.end - a.start), second = static_cast<double>(b.end - b.start);
    if (std::abs(second - first) > 0.2 * first) ++irregular;
  }
  if (pairs > 0) out.irregular_pct = 100.0 * static_cast<double>(irregular) / static_cast<double>(pairs);
  out.gap_count = static_cast<std::size_t>(std::count_if(intervals.begin(), intervals.end(), [&](const Interval& i) {
    return !i.nn && static_cast<double>(i.end - i.start) > o.gap_s * fs;
  }));
  const NnSeries s = collect(intervals, fs);
  out.nn_count = s.nn_ms.size();
  time_domain(s, fs, out);
  if (s.nn_ms.size() < 3 || s.nn_seconds < std::min(o.min_hf_s, o.min_lf_s)) return out;
  const BandPowers bands = lomb_scargle_bands(s.t_s, s.nn_ms, o);
  if (s.nn_seconds >= o.min_hf_s) out.hf_ms2 = bands.hf_ms2;
  if (s.nn_seconds >= o.min_lf_s) out.lf_ms2 = bands.lf_ms2;
  if (out.lf_ms2 && out.hf_ms2 && *out.hf_ms2 > 0) out.lf_hf = *out.lf_ms2 / *out.hf_ms2;
  return out;
}

// A window's end, or the record's when the record ends first (never before the window's start:
// a record end given wrongly short does not make a window of negative length).
double ended_by_record(double start, double end, std::optional<double> record_end_s) {
  if (!record_end_s || *record_end_s >= end) return end;
  return std::max(start, *record_end_s);
}

// Window k is [origin + k·step, origin + (k + steps_per_window)·step): its end is computed as the
// start of window k + window/step when that is a whole number (window = step: the next window's
// start), so that an interval ending exactly on the boundary falls in one window. As start +
// window, with a step of 1.1 s, k·1.1 + 1.1 and (k + 1)·1.1 differ in the last bit, and such an
// interval fell in neither window or in both.
//
// A beat at a window's boundary, computed in seconds two ways (its sample over fs; the window's
// start times the step), may differ in the last bits: 609408 / 360 and (1256 + 60 / 1.3) · 1.3
// are both 1692.8. `reached` takes times within a few parts in 10^12 as equal, everywhere a
// time is compared with a boundary, so that such a beat ends the window before it and is in the
// one it starts, in the batch and the streaming windows alike. Distinct beats are at least a
// sample apart, far more than that.
namespace {
bool reached(double t, double boundary) { return t >= boundary - 1e-12 * std::max(1.0, std::abs(boundary)); }

double steps_per_window(double window_s, double step_s) {
  const double ratio = window_s / step_s;
  const double whole = std::round(ratio);
  return whole >= 1 && std::abs(ratio - whole) <= 1e-9 * whole ? whole : ratio;
}

// The first window, of those starting at origin + k·step, that ends after `t`: the windows
// before it end at or before the first interval and hold nothing. A recording's start that a
// node never received (a gateway whose store was made again gets the sensor's chunks from
// where it is) gave a window of no intervals for each minute of it, named as the windows the
// hospital had from the store before.
std::size_t first_window_after(double origin, double window_s, double step_s, double t) {
  const double span = steps_per_window(window_s, step_s);
  auto end_of = [&](std::size_t k) { return origin + (static_cast<double>(k) + span) * step_s; };
  const double estimate = std::floor((t - origin) / step_s - span);
  if (!(estimate < 0x1p52)) return estimate > 0 ? static_cast<std::size_t>(std::min(estimate, 0x1p62)) : 0;  // past exact steps
  std::size_t k = estimate > 0 ? static_cast<std::size_t>(estimate) : 0;
  while (k > 0 && !reached(t, end_of(k - 1))) --k;
  while (reached(t, end_of(k))) ++k;
  return k;
}
}  // namespace

std::optional<std::string> window_setting_problem(double seconds, bool is_step) {
  const double least = is_step ? kMinStepS : kMinWindowS;
  if (std::isfinite(seconds) && seconds >= least && seconds <= kMaxWindowS) return std::nullopt;
  char text[240];
  std::snprintf(text, sizeof text, "must be a number of seconds in [%g, %g] (%s)", least, kMaxWindowS,
                is_step ? "at most one window per second of signal" : "an HRV window needs at least 10 s of beats");
  return std::string(text);
}

std::optional<std::string> window_step_problem(double window_s, double step_s) {
  if (!(step_s > 0) || window_s / step_s <= kMaxWindowsPerMoment) return std::nullopt;
  char text[300];
  std::snprintf(text, sizeof text,
                "a window of %g s stepped by %g s lays %g windows over each moment of signal, at most %g (each is "
                "computed whole): a step of at least %g s for this window",
                window_s, step_s, window_s / step_s, kMaxWindowsPerMoment, std::ceil(window_s / kMaxWindowsPerMoment));
  return std::string(text);
}

std::vector<WindowMetrics> windowed_hrv(const std::vector<Interval>& intervals, double fs,
                                        double window_s, double step_s, const HrvOptions& o,
                                        std::optional<double> record_end_s) {
  std::vector<WindowMetrics> out;
  if (!(window_s > 0) || !(step_s > 0) || !(fs > 0) || intervals.empty()) return out;
  const double last = static_cast<double>(intervals.back().end) / fs;
  const double span = steps_per_window(window_s, step_s);
  std::size_t first = 0;  // first interval that can belong to window k or later
  const double first_end = static_cast<double>(intervals.front().end) / fs;
  for (std::size_t k = first_window_after(0, window_s, step_s, first_end); reached(last, static_cast<double>(k) * step_s); ++k) {
    const double start = static_cast<double>(k) * step_s, end = (static_cast<double>(k) + span) * step_s;
    while (first < intervals.size() && !reached(static_cast<double>(intervals[first].end) / fs, start)) ++first;
    std::vector<Interval> in;
    for (std::size_t i = first; i < intervals.size(); ++i) {
      if (reached(static_cast<double>(intervals[i].end) / fs, end)) break;
      in.push_back(intervals[i]);
    }
    out.push_back({start, ended_by_record(start, end, record_end_s), compute_hrv(in, fs, o), end - start});
  }
  return out;
}

HrvWindower::HrvWindower(double fs, double window_s, double step_s, const HrvOptions& options)
    : fs_(fs), window_s_(window_s), step_s_(step_s), options_(options) {}

void HrvWindower::set_window(double window_s, double step_s) {
  if (!(window_s > 0) || !(step_s > 0)) return;
  origin_s_ += static_cast<double>(next_) * step_s_;
  next_ = 0;
  window_s_ = window_s;
  step_s_ = step_s;
}

void HrvWindower::resume_after(double end_s, double length_s) {
  const bool same_length = std::abs(length_s - window_s_) <= 1e-9 * std::max(1.0, window_s_);
  origin_s_ = same_length ? std::max(0.0, end_s - window_s_ + step_s_) : end_s;
  next_ = 0;
}

double HrvWindower::front_end() const {
  return origin_s_ + (static_cast<double>(next_) + steps_per_window(window_s_, step_s_)) * step_s_;
}

void HrvWindower::emit_front(std::vector<WindowMetrics>& completed, std::optional<double> record_end_s) {
  const double start = origin_s_ + static_cast<double>(next_) * step_s_, end = front_end();
  std::vector<Interval> in;
  for (const Interval& iv : buffer_) {
    const double t = static_cast<double>(iv.end) / fs_;
    if (reached(t, end)) break;
    if (reached(t, start)) in.push_back(iv);
  }
  completed.push_back({start, ended_by_record(start, end, record_end_s), compute_hrv(in, fs_, options_), end - start});
  ++next_;
  const double next_start = origin_s_ + static_cast<double>(next_) * step_s_;
  while (!buffer_.empty() && !reached(static_cast<double>(buffer_.front().end) / fs_, next_start)) buffer_.pop_front();
}

void HrvWindower::push(const Interval& interval, std::vector<WindowMetrics>& completed) {
  if (!(fs_ > 0) || !(window_s_ > 0) || !(step_s_ > 0)) return;
  const double t = static_cast<double>(interval.end) / fs_;
  if (last_end_s_ < 0 && buffer_.empty()) next_ = std::max(next_, first_window_after(origin_s_, window_s_, step_s_, t));
  while (reached(t, front_end())) emit_front(completed);
  buffer_.push_back(interval);
  last_end_s_ = t;
}

void HrvWindower::finish(std::vector<WindowMetrics>& completed, std::optional<double> record_end_s) {
  if (last_end_s_ >= 0) {
    while (reached(last_end_s_, origin_s_ + static_cast<double>(next_) * step_s_)) emit_front(completed, record_end_s);
  }
  origin_s_ = 0;
  next_ = 0;
  last_end_s_ = -1;
  buffer_.clear();
}

}  // namespace tahvel::aggregation
