// What the MIT-BIH tests share: the reference side of HRV, computed from a record's .atr
// annotations, and the record moved to another sampling rate (other databases and devices
// record at 128 Hz: Holter, nsrdb; 250 Hz: afdb, many patches; 500 or 1000 Hz: 12-lead carts).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <numbers>
#include <numeric>
#include <vector>

#include "tahvel/aggregation/annotations.h"
#include "tahvel/aggregation/rr.h"

namespace tahvel::aggregation::testing {

struct Reference {
  std::vector<Interval> intervals;
  std::vector<SampleRange> unreadable;
};

// The reference rule from the annotations: beats by is_beat(); excluded are the unreadable
// intervals, the flutter episodes ('[' to ']') and every '[', ']' and '!' marker.
inline Reference reference_from(const std::vector<Annotation>& ann, std::int64_t record_end) {
  Reference ref;
  ref.unreadable = unreadable_intervals(ann, record_end);
  std::vector<SampleRange> excluded = ref.unreadable;
  for (const auto& r : flutter_intervals(ann, record_end)) excluded.push_back(r);
  std::vector<Beat> beats;
  for (const Annotation& a : ann) {
    if (is_beat(a.code)) beats.push_back({a.sample, a.code});
    if (a.code == '!' || a.code == '[' || a.code == ']') excluded.push_back({a.sample, a.sample});
  }
  ref.intervals = reference_intervals(beats, excluded);
  return ref;
}

// Resamples `x` from fs_in to fs_out (whole hertz): each output sample is the input convolved
// with a Blackman-windowed sinc whose cut-off (0.45 of the lower of the two rates) keeps the
// ECG band and removes what would alias when the rate goes down. The output grid falls on
// fs_out / gcd phases of the input grid, so one kernel per phase serves the whole record.
inline std::vector<std::int32_t> resample(const std::vector<std::int32_t>& x, int fs_in, int fs_out) {
  const double cutoff = 0.45 * std::min(fs_in, fs_out);  // Hz
  const double step = 2 * cutoff / fs_in;                // the sinc's argument per input sample
  const int half = static_cast<int>(std::ceil(8 / step));  // eight zero crossings each side
  const int phases = fs_out / std::gcd(fs_in, fs_out);
  std::vector<std::vector<double>> kernels(static_cast<std::size_t>(phases));
  for (int p = 0; p < phases; ++p) {
    const double frac = static_cast<double>(static_cast<std::int64_t>(p) * fs_in % fs_out) / fs_out;
    std::vector<double>& h = kernels[static_cast<std::size_t>(p)];
    double weight = 0;
    for (int k = -half + 1; k <= half; ++k) {
      const double d = frac - k;  // distance from input sample centre + k to the output point
      const double u = step * d;
      const double sinc = u == 0 ? 1 : std::sin(std::numbers::pi * u) / (std::numbers::pi * u);
      const double r = d / (half + 1);  // -1..1 over the window
      h.push_back(sinc * (0.42 + 0.5 * std::cos(std::numbers::pi * r) +
                          0.08 * std::cos(2 * std::numbers::pi * r)));
      weight += h.back();
    }
    for (double& v : h) v /= weight;  // unit gain at DC
  }
  const auto n_in = static_cast<std::int64_t>(x.size());
  std::vector<std::int32_t> y(static_cast<std::size_t>(n_in * fs_out / fs_in));
  for (std::size_t j = 0; j < y.size(); ++j) {
    const auto scaled = static_cast<std::int64_t>(j) * fs_in;
    const std::int64_t centre = scaled / fs_out;
    const std::vector<double>& h = kernels[j % static_cast<std::size_t>(phases)];
    double sum = 0;
    for (int k = -half + 1; k <= half; ++k)
      sum += h[static_cast<std::size_t>(k + half - 1)] *
             x[static_cast<std::size_t>(std::clamp<std::int64_t>(centre + k, 0, n_in - 1))];
    y[j] = static_cast<std::int32_t>(std::lround(sum));
  }
  return y;
}

inline std::vector<Annotation> moved(std::vector<Annotation> annotations, int fs_in, int fs_out) {
  for (Annotation& a : annotations)
    a.sample = std::llround(static_cast<double>(a.sample) * fs_out / fs_in);
  return annotations;
}

}  // namespace tahvel::aggregation::testing
