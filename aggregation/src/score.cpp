// bxb's beat-by-beat comparison, restated over two sorted arrays instead of two annotation
// streams. The structure (prologue at the start of the test period, then one of four actions
// per step) is kept step for step so results can be checked against bxb's.
#include "tahvel/aggregation/score.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <utility>

namespace tahvel::aggregation {

namespace {

using Interval = std::pair<std::int64_t, std::int64_t>;

// bxb's "huge_time": the time of a sequence that has run out.
constexpr std::int64_t kHuge = std::numeric_limits<std::int64_t>::max() / 4;

bool inside(const std::vector<Interval>& intervals, std::int64_t t) {
  // Few intervals per record (at most a handful in MIT-BIH): a scan is enough.
  for (const auto& [from, to] : intervals)
    if (from <= t && t <= to) return true;
  return false;
}

struct Sequence {
  std::vector<std::int64_t> times;
  std::int64_t at(std::ptrdiff_t i) const {
    return i >= 0 && i < static_cast<std::ptrdiff_t>(times.size())
               ? times[static_cast<std::size_t>(i)]
               : kHuge;
  }
  std::ptrdiff_t first_at_or_after(std::int64_t t) const {
    return std::lower_bound(times.begin(), times.end(), t) - times.begin();
  }
};

std::int64_t dist(std::int64_t a, std::int64_t b) { return a > b ? a - b : b - a; }

}  // namespace

double BeatScore::sensitivity() const {
  return tp + fn == 0 ? std::numeric_limits<double>::quiet_NaN()
                      : static_cast<double>(tp) / static_cast<double>(tp + fn);
}

double BeatScore::positive_predictivity() const {
  return tp + fp == 0 ? std::numeric_limits<double>::quiet_NaN()
                      : static_cast<double>(tp) / static_cast<double>(tp + fp);
}

BeatScore& BeatScore::operator+=(const BeatScore& other) {
  tp += other.tp;
  fn += other.fn;
  fp += other.fp;
  return *this;
}

BeatScore score_beats(const std::vector<Annotation>& reference,
                      const std::vector<std::int64_t>& detected, double fs,
                      const ScoreOptions& options) {
  const std::int64_t w = std::llround(options.match_window_s * fs);
  const std::int64_t start = std::llround(options.start_s * fs);
  const bool has_end = options.end_s.has_value();
  const std::int64_t end = has_end ? std::llround(*options.end_s * fs) : kHuge;

  Sequence test{detected};
  std::sort(test.times.begin(), test.times.end());

  // Where an open interval ends: the end of scoring, or the last thing there is to score.
  std::int64_t last = has_end ? end : 0;
  if (!reference.empty()) last = std::max(last, reference.back().sample);
  if (!test.times.empty()) last = std::max(last, test.times.back());
  const std::vector<Interval> unreadable = unreadable_intervals(reference, last);
  const std::vector<Interval> flutter =
      options.exclude_flutter ? flutter_intervals(reference, last) : std::vector<Interval>{};
  auto excluded = [&](std::int64_t t) { return inside(unreadable, t) || inside(flutter, t); };

  Sequence ref;
  for (const Annotation& a : reference)
    if (is_beat(a.code) && !excluded(a.sample)) ref.times.push_back(a.sample);
  std::sort(ref.times.begin(), ref.times.end());  // file order is time order; be safe

  BeatScore score;
  std::ptrdiff_t r = ref.first_at_or_after(start);  // current reference beat T = ref.at(r)
  std::ptrdiff_t d = test.first_at_or_after(start);  // current detection t = test.at(d)

  // Prologue (bxb): the last detection before `start` may pair with the first reference beat.
  const std::int64_t T0 = ref.at(r);
  if (d > 0 && T0 - test.at(d - 1) < dist(T0, test.at(d)) && T0 - test.at(d - 1) <= w) {
    ++score.tp;
    ++r;
  } else if (test.at(d) - start <= w && dist(T0, test.at(d + 1)) < dist(T0, test.at(d))) {
    ++d;  // a detection just after start that belongs to a beat before it: not counted
  }

  auto running = [&] {
    std::int64_t T = ref.at(r), t = test.at(d);
    if (has_end) return T <= end || t <= end;
    return T != kHuge || t != kHuge;
  };
  while (running()) {
    const std::int64_t T = ref.at(r), Tn = ref.at(r + 1);
    const std::int64_t t = test.at(d), tn = test.at(d + 1);
    if (t < T) {
      if (T - t <= w && (T - t < dist(T, tn) || dist(Tn, tn) < dist(T, tn))) {
        ++score.tp, ++r, ++d;  // (1) t pairs with T
      } else {
        if (!excluded(t)) ++score.fp;  // (2) t has no reference beat
        ++d;
      }
    } else {
      if (t - T <= w && (t - T < dist(t, Tn) || dist(tn, Tn) < dist(t, Tn))) {
        ++score.tp, ++r, ++d;  // (3) T pairs with t
      } else {
        ++score.fn;  // (4) T has no detection
        ++r;
      }
    }
  }
  return score;
}

}  // namespace tahvel::aggregation
