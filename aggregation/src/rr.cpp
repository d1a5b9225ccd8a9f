// RR/NN series. The detected-beat rule is a small state machine over the RR series: a
// reference RR (median of recent accepted intervals) and a spread (median |ΔNN|) that widens
// the tolerances in irregular but normal rhythms (sinus arrhythmia) and keeps them tight in
// regular ones, where a slightly premature ectopic beat is still visible. Tuned on the MIT-BIH
// annotations with all beats unlabelled (docs/hrv.md gives the figures).
#include "tahvel/aggregation/rr.h"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <deque>

namespace tahvel::aggregation {

namespace {

double median_of(std::vector<double> v) {
  if (v.empty()) return 0.0;
  const std::size_t mid = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(mid), v.end());
  double m = v[mid];
  if (v.size() % 2 == 0) {
    m = (m + *std::max_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(mid))) / 2;
  }
  return m;
}

double median_of(const std::deque<double>& d) { return median_of(std::vector<double>(d.begin(), d.end())); }

// Answers "does (start, end) overlap any excluded range" in O(log R): ranges sorted by first,
// with the running maximum of last, so the ranges with first < end form a prefix.
class ExclusionIndex {
 public:
  explicit ExclusionIndex(std::vector<SampleRange> ranges) : ranges_(std::move(ranges)) {
    std::sort(ranges_.begin(), ranges_.end());
    std::int64_t m = INT64_MIN;
    for (const auto& r : ranges_) max_last_.push_back(m = std::max(m, r.second));
  }
  bool overlaps(std::int64_t start, std::int64_t end) const {
    auto it = std::lower_bound(ranges_.begin(), ranges_.end(), end,
                               [](const SampleRange& r, std::int64_t e) { return r.first < e; });
    if (it == ranges_.begin()) return false;
    return max_last_[static_cast<std::size_t>(it - ranges_.begin()) - 1] > start;
  }

 private:
  std::vector<SampleRange> ranges_;
  std::vector<std::int64_t> max_last_;
};

// The state machine of NnRule over rr (in samples); returns the accepted flags.
class DetectedRule {
 public:
  DetectedRule(const std::vector<double>& rr, double fs, const NnRule& rule)
      : rr_(rr), rule_(rule), max_rr_(rule.max_interval_s * fs), ok_(rr.size(), false) {}

  std::vector<bool> run() {
    const std::size_t n = rr_.size();
    seed(0);
    for (std::size_t i = 0; i < n;) i = step(i);
    return std::move(ok_);
  }

 private:
  // Restart the reference from the median of the next reference_beats usable intervals.
  void seed(std::size_t from) {
    hist_.clear();
    diffs_.clear();
    std::vector<double> next;
    for (std::size_t j = from; j < rr_.size() && next.size() < size_t_of(rule_.reference_beats); ++j) {
      if (rr_[j] > max_rr_) break;
      if (rr_[j] > 0) next.push_back(rr_[j]);
    }
    if (!next.empty()) hist_.push_back(median_of(next));
  }

  static std::size_t size_t_of(int v) { return static_cast<std::size_t>(std::max(v, 1)); }

  std::size_t step(std::size_t i) {
    const double r = rr_[i];
    if (r <= 0) return i + 1;
    if (r > max_rr_) {
      seed(i + 1);
      short_run_.clear();
      return i + 1;
    }
    if (hist_.empty()) hist_.push_back(r);
    const double ref = median_of(hist_);
    const double spread = diffs_.size() >= 8 ? median_of(diffs_) : 0.0;
    const double tol_short = std::max(rule_.short_fraction, rule_.spread_factor * spread / ref);
    const double tol_long = std::max(rule_.long_fraction, rule_.spread_factor * spread / ref);
    const double tol_prem =
        std::max(rule_.premature_fraction, rule_.premature_spread_factor * spread / ref);
    const bool continuous = i > 0 && ok_[i - 1] && std::abs(r - rr_[i - 1]) <= tol_prem * ref &&
                            std::abs(r - ref) <= rule_.continuity_band * tol_short * ref;
    if (!continuous && r < (1 - tol_short) * ref) return short_beat(i, tol_short * ref);
    short_run_.clear();
    if (!continuous && r > (1 + tol_long) * ref) {
      if (sustained(i, tol_long)) {
        hist_.assign(1, r);
        diffs_.clear();
        ok_[i] = true;
      }
      return i + 1;
    }
    if (!continuous && r < (1 - tol_prem) * ref && i + 1 < rr_.size() &&
        rr_[i + 1] > (1 + tol_prem) * ref) {
      return i + 2;
    }
    accept(i);
    return i + 1;
  }

  // A premature (or spurious) beat: this interval and the next are not NN.
  std::size_t short_beat(std::size_t i, double tol) {
    short_run_.push_back(rr_[i]);
    const std::size_t want = size_t_of(rule_.rebase_beats);
    if (short_run_.size() >= want) {
      auto [lo, hi] = std::minmax_element(short_run_.end() - static_cast<std::ptrdiff_t>(want),
                                          short_run_.end());
      if (*hi - *lo < tol) {
        const std::size_t keep = std::min(short_run_.size(), size_t_of(rule_.reference_beats));
        hist_.assign(short_run_.end() - static_cast<std::ptrdiff_t>(keep), short_run_.end());
        diffs_.clear();
        short_run_.clear();
      }
    }
    return i + 2;
  }

  bool sustained(std::size_t i, double tol_long) const {
    const std::size_t k = size_t_of(rule_.sustained_beats);
    if (i + k >= rr_.size()) return false;
    for (std::size_t j = i + 1; j <= i + k; ++j) {
      if (std::abs(rr_[j] - rr_[i]) > tol_long * rr_[i] * 0.5) return false;
    }
    return true;
  }

  void accept(std::size_t i) {
    ok_[i] = true;
    if (i > 0 && ok_[i - 1]) {
      diffs_.push_back(std::abs(rr_[i] - rr_[i - 1]));
      if (diffs_.size() > size_t_of(rule_.spread_diffs)) diffs_.pop_front();
    }
    hist_.push_back(rr_[i]);
    if (hist_.size() > size_t_of(rule_.reference_beats)) hist_.pop_front();
  }

  const std::vector<double>& rr_;
  const NnRule& rule_;
  double max_rr_;
  std::vector<bool> ok_;
  std::deque<double> hist_, diffs_;
  std::vector<double> short_run_;
};

}  // namespace

bool is_reference_normal(char code) noexcept {
  return code == 'N' || code == 'L' || code == 'R' || code == 'e' || code == 'j';
}

std::vector<Interval> reference_intervals(const std::vector<Beat>& beats,
                                          const std::vector<SampleRange>& excluded) {
  std::vector<Interval> out;
  if (beats.size() < 2) return out;
  const ExclusionIndex index(excluded);
  out.reserve(beats.size() - 1);
  for (std::size_t i = 1; i < beats.size(); ++i) {
    const Beat& a = beats[i - 1];
    const Beat& b = beats[i];
    const bool nn = is_reference_normal(a.code) && is_reference_normal(b.code) &&
                    b.sample > a.sample && !index.overlaps(a.sample, b.sample);
    out.push_back({a.sample, b.sample, nn});
  }
  return out;
}

std::vector<Interval> intervals_from_peaks(const std::vector<std::int64_t>& peaks, double fs,
                                           const NnRule& rule,
                                           const std::vector<SampleRange>& excluded) {
  std::vector<Interval> out;
  if (peaks.size() < 2 || !(fs > 0)) return out;
  std::vector<double> rr(peaks.size() - 1);
  for (std::size_t i = 1; i < peaks.size(); ++i) rr[i - 1] = static_cast<double>(peaks[i] - peaks[i - 1]);
  const std::vector<bool> ok = DetectedRule(rr, fs, rule).run();
  const ExclusionIndex index(excluded);
  out.reserve(rr.size());
  for (std::size_t i = 0; i < rr.size(); ++i) {
    const bool nn = ok[i] && !index.overlaps(peaks[i], peaks[i + 1]);
    out.push_back({peaks[i], peaks[i + 1], nn});
  }
  return out;
}

double nn_fraction(const std::vector<Interval>& intervals) noexcept {
  if (intervals.empty()) return 0.0;
  std::size_t nn = 0;
  for (const Interval& iv : intervals) nn += iv.nn ? 1 : 0;
  return static_cast<double>(nn) / static_cast<double>(intervals.size());
}

}  // namespace tahvel::aggregation
