// NnClassifier (rr.h), the streaming form of the detected-beat rule: whatever the peaks and
// however they arrive, what it decides equals intervals_from_peaks, and both equal a model —
// the batch implementation as it was before the streaming form existed (commit d9741e7), kept
// here verbatim with a plain scan for the excluded ranges. Decisions come within the documented
// delay: D = max(sustained_beats, reference_beats - 1, 1) positive-length intervals after an
// interval's own (one more after a zero-length one).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <random>
#include <string>
#include <vector>

#include "tahvel/aggregation/rr.h"

namespace tahvel::aggregation {
namespace {

// --- The model: the pre-streaming batch rule, verbatim but for names ------------------------

double model_median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  const std::size_t mid = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(mid), v.end());
  double m = v[mid];
  if (v.size() % 2 == 0) {
    m = (m + *std::max_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(mid))) / 2;
  }
  return m;
}

double model_median(const std::deque<double>& d) {
  return model_median(std::vector<double>(d.begin(), d.end()));
}

class ModelRule {
 public:
  ModelRule(const std::vector<double>& rr, double fs, const NnRule& rule)
      : rr_(rr), rule_(rule), max_rr_(rule.max_interval_s * fs), ok_(rr.size(), false) {}

  std::vector<bool> run() {
    const std::size_t n = rr_.size();
    seed(0);
    for (std::size_t i = 0; i < n;) i = step(i);
    return std::move(ok_);
  }

 private:
  void seed(std::size_t from) {
    hist_.clear();
    diffs_.clear();
    std::vector<double> next;
    for (std::size_t j = from; j < rr_.size() && next.size() < size_t_of(rule_.reference_beats); ++j) {
      if (rr_[j] > max_rr_) break;
      if (rr_[j] > 0) next.push_back(rr_[j]);
    }
    if (!next.empty()) hist_.push_back(model_median(next));
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
    const double ref = model_median(hist_);
    const double spread = diffs_.size() >= 8 ? model_median(diffs_) : 0.0;
    const double tol_short = std::max(rule_.short_fraction, rule_.spread_factor * spread / ref);
    const double tol_long = std::max(rule_.long_fraction, rule_.spread_factor * spread / ref);
    const double tol_prem =
        std::max(rule_.premature_fraction, rule_.premature_spread_factor * spread / ref);
    const bool continuous = i > 0 && ok_[i - 1] && std::abs(r - rr_[i - 1]) <= tol_prem * ref + 0.5 &&
                            std::abs(r - ref) <= rule_.continuity_band * tol_short * ref;
    if (!continuous && r < (1 - tol_short) * ref) return short_beat(i, tol_short * ref);
    short_run_.clear();
    if (!continuous && r > (1 + tol_long) * ref) {
      if (sustained(i, tol_long)) {
        const std::size_t k = size_t_of(rule_.sustained_beats);
        hist_.assign(rr_.begin() + static_cast<std::ptrdiff_t>(i),
                     rr_.begin() + static_cast<std::ptrdiff_t>(i + k + 1));
        while (hist_.size() > size_t_of(rule_.reference_beats)) hist_.pop_front();
        diffs_.clear();
        ok_[i] = true;
      }
      return i + 1;
    }
    if (!continuous && r < (1 - tol_prem) * ref && i + 1 < rr_.size() &&
        rr_[i + 1] > (1 + tol_prem) * ref) {
      return i + 2;
    }
    // premature_pause_when_continuous: shorter than the interval before, and a pause alone after it.
    if (continuous && rule_.premature_pause_when_continuous && r < rr_[i - 1] && r < (1 - tol_prem) * ref && i + 2 < rr_.size() &&
        rr_[i + 1] > (1 + tol_prem) * ref && rr_[i + 1] <= (1 + tol_long) * ref && rr_[i + 2] < rr_[i + 1] - tol_prem * ref) {
      return i + 2;
    }
    accept(i);
    return i + 1;
  }

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

std::vector<Interval> model(const std::vector<std::int64_t>& peaks, double fs, const NnRule& rule,
                            const std::vector<SampleRange>& excluded) {
  std::vector<Interval> out;
  if (peaks.size() < 2 || !(fs > 0)) return out;
  std::vector<double> rr(peaks.size() - 1);
  for (std::size_t i = 1; i < peaks.size(); ++i) rr[i - 1] = static_cast<double>(peaks[i] - peaks[i - 1]);
  const std::vector<bool> ok = ModelRule(rr, fs, rule).run();
  for (std::size_t i = 0; i < rr.size(); ++i) {
    bool hit = false;
    for (const auto& [a, b] : excluded) hit = hit || (a < peaks[i + 1] && b > peaks[i]);
    out.push_back({peaks[i], peaks[i + 1], ok[i] && !hit});
  }
  return out;
}

// --- Feeding the classifier -----------------------------------------------------------------

std::size_t delay_bound(const NnRule& rule) {
  const auto at_least_1 = [](int v) { return static_cast<std::size_t>(std::max(v, 1)); };
  return std::max({at_least_1(rule.sustained_beats), at_least_1(rule.reference_beats) - 1,
                   std::size_t{rule.premature_pause_when_continuous ? 2u : 1u}});
}

struct Streamed {
  std::vector<Interval> intervals;
  std::vector<std::size_t> decided_at;  // per interval: peaks pushed when it came out (0: finish)
  std::size_t max_pending = 0;
};

// Peaks pushed one by one; pending() and what came out are looked at after every push.
Streamed stream(NnClassifier& c, const std::vector<std::int64_t>& peaks) {
  Streamed s;
  for (std::size_t k = 0; k < peaks.size(); ++k) {
    c.push(peaks[k], s.intervals);
    s.decided_at.resize(s.intervals.size(), k + 1);
    s.max_pending = std::max(s.max_pending, c.pending());
  }
  c.finish(s.intervals);
  s.decided_at.resize(s.intervals.size(), 0);
  return s;
}

// What arrives per 1-second chunk of a detector with a delay: the peaks are handed over in
// groups of the chunk they were detected in; the decided intervals are collected per group.
std::vector<Interval> stream_in_chunks(const std::vector<std::int64_t>& peaks, double fs,
                                       const NnRule& rule, const std::vector<SampleRange>& excluded,
                                       std::int64_t chunk) {
  NnClassifier c(fs, rule, excluded);
  std::vector<Interval> all, batch;
  std::size_t k = 0;
  for (std::int64_t t = chunk; k < peaks.size(); t += chunk) {
    batch.clear();
    while (k < peaks.size() && peaks[k] < t) c.push(peaks[k++], batch);
    all.insert(all.end(), batch.begin(), batch.end());
  }
  c.finish(all);
  return all;
}

bool same(const std::vector<Interval>& a, const std::vector<Interval>& b, std::string& why) {
  if (a.size() != b.size()) {
    why = "sizes " + std::to_string(a.size()) + " vs " + std::to_string(b.size());
    return false;
  }
  for (std::size_t i = 0; i < a.size(); ++i) {
    if (a[i].start != b[i].start || a[i].end != b[i].end || a[i].nn != b[i].nn) {
      why = "interval " + std::to_string(i) + " (" + std::to_string(a[i].start) + ", " +
            std::to_string(a[i].end) + ") nn " + std::to_string(a[i].nn) + " vs (" +
            std::to_string(b[i].start) + ", " + std::to_string(b[i].end) + ") nn " +
            std::to_string(b[i].nn);
      return false;
    }
  }
  return true;
}

// Every check on one series: model == batch with the rules the model knows (it predates
// hold_after_ectopic_run, pause_after_couplet and stale_reference_beats, which are turned off
// for that comparison), batch == one-by-one
// stream == chunked streams with the rule as given; each
// interval decided by the time D + 1 positive-length intervals from it (itself included) are
// pushed, and one left for finish() only when fewer were; pending() <= D
// when no peaks repeat; and a finished classifier starts a new stream afresh.
void check_series(const std::vector<std::int64_t>& peaks, double fs, const NnRule& rule = {},
                  const std::vector<SampleRange>& excluded = {}) {
  NnRule known = rule;
  known.hold_after_ectopic_run = false;
  known.pause_after_couplet = false;
  known.stale_reference_beats = 0;
  std::string why;
  EXPECT_TRUE(same(intervals_from_peaks(peaks, fs, known, excluded),
                   model(peaks, fs, known, excluded), why))
      << "batch vs model: " << why;
  const std::vector<Interval> expected = intervals_from_peaks(peaks, fs, rule, excluded);

  NnClassifier c(fs, rule, excluded);
  for (int round = 0; round < 2; ++round) {  // the second round checks the reset by finish()
    const Streamed s = stream(c, peaks);
    EXPECT_TRUE(same(s.intervals, expected, why))
        << "stream vs batch, round " << round << ": " << why;
    EXPECT_EQ(c.pending(), 0u);
    if (!(fs > 0) || peaks.size() < 2) continue;
    const std::size_t d = delay_bound(rule);
    bool duplicates = false;
    for (std::size_t i = 0; i + 1 < peaks.size(); ++i) {
      duplicates = duplicates || peaks[i + 1] <= peaks[i];
      // Positive-length intervals from interval i (itself included) pushed before it came out.
      std::size_t seen = 0;
      const std::size_t until = s.decided_at[i] == 0 ? peaks.size() : s.decided_at[i];
      for (std::size_t k = i + 1; k < until; ++k) seen += peaks[k] > peaks[k - 1] ? 1 : 0;
      if (s.decided_at[i] != 0) {
        ASSERT_LE(seen, d + 1) << "interval " << i << " decided late";
      } else {
        ASSERT_LE(seen, d) << "interval " << i << " left for finish() with " << seen
                           << " intervals from it";
      }
    }
    if (!duplicates) {
      EXPECT_LE(s.max_pending, d);
    }
  }
  const auto second = static_cast<std::int64_t>(fs);
  for (const std::int64_t chunk : {std::int64_t{1}, second, std::int64_t{7919}}) {
    if (chunk <= 0) continue;
    EXPECT_TRUE(same(stream_in_chunks(peaks, fs, rule, excluded, chunk), expected, why))
        << "chunks of " << chunk << ": " << why;
  }
}

std::vector<std::int64_t> peaks_from_rr(const std::vector<int>& rr, std::int64_t first = 1000) {
  std::vector<std::int64_t> p{first};
  for (int r : rr) p.push_back(p.back() + r);
  return p;
}

std::vector<int> repeat(int rr, int n) { return std::vector<int>(static_cast<std::size_t>(n), rr); }

std::vector<int> join(std::initializer_list<std::vector<int>> parts) {
  std::vector<int> out;
  for (const auto& p : parts) out.insert(out.end(), p.begin(), p.end());
  return out;
}

// --- Synthetic series -----------------------------------------------------------------------

// The empty-gap evidence pushed with each peak gives the batch result with the same evidence,
// one peak at a time: confirmed pauses need no look-ahead.
TEST(NnClassifier, ConfirmedPausesMatchBatch) {
  const auto peaks = peaks_from_rr(join({repeat(300, 12), {600}, repeat(300, 5), {600, 600, 600},
                                         repeat(300, 6), {600}, repeat(300, 4), {200, 450},
                                         repeat(300, 4)}));
  std::vector<std::int64_t> empty;
  for (std::size_t i = 1; i < peaks.size(); ++i)
    if (peaks[i] - peaks[i - 1] > 400 && i != 30) empty.push_back(peaks[i]);  // i = 30: unconfirmed
  const auto batch = intervals_from_peaks(peaks, empty, 360);
  NnClassifier c(360);
  std::vector<Interval> streamed;
  std::size_t next = 0;
  for (const std::int64_t p : peaks) {
    const bool gap = next < empty.size() && empty[next] == p;
    next += gap ? 1 : 0;
    c.push(p, gap, streamed);
  }
  c.finish(streamed);
  std::string why;
  EXPECT_TRUE(same(streamed, batch, why)) << why;
  EXPECT_LT(nn_fraction(intervals_from_peaks(peaks, 360)), nn_fraction(batch));
}

// The blocked-P-wave evidence pushed with each peak gives the batch result with the same
// evidence (a 2:1 block adopted as a slower rhythm, then the return to 1:1, twice), one peak at
// a time and within the delay bound: the return needs no look-ahead.
TEST(NnClassifier, ReturnAfterABlockMatchesBatch) {
  const auto peaks = peaks_from_rr(join({repeat(300, 14), repeat(600, 10), repeat(300, 8),
                                         {600}, repeat(600, 6), {200, 400}, repeat(300, 9)}));
  std::vector<std::int64_t> empty, p_wave;
  for (std::size_t i = 1; i < peaks.size(); ++i)
    if (peaks[i] - peaks[i - 1] > 400 && i != 15 && i != 33) {
      empty.push_back(peaks[i]);
      if (i % 4 != 0) p_wave.push_back(peaks[i]);
    }
  const auto batch = intervals_from_peaks(peaks, empty, p_wave, 360);
  NnClassifier c(360);
  std::vector<Interval> streamed;
  std::size_t next_empty = 0, next_p = 0;
  for (const std::int64_t peak : peaks) {
    const bool gap = next_empty < empty.size() && empty[next_empty] == peak;
    const bool p = next_p < p_wave.size() && p_wave[next_p] == peak;
    next_empty += gap ? 1 : 0;
    next_p += p ? 1 : 0;
    c.push(peak, gap, p, streamed);
    EXPECT_LE(c.pending(), 8u);
  }
  c.finish(streamed);
  std::string why;
  EXPECT_TRUE(same(streamed, batch, why)) << why;
  EXPECT_LT(nn_fraction(intervals_from_peaks(peaks, empty, 360)), nn_fraction(batch));
}

TEST(NnClassifier, PrematureBeatsMatchBatch) {
  check_series(peaks_from_rr(join({repeat(300, 12), {200, 400}, repeat(300, 6), {270, 330},
                                   repeat(300, 5), {200, 400}, {200, 400}, repeat(300, 4)})),
               360);
}

TEST(NnClassifier, MissedBeatsAndSpuriousDetectionsMatchBatch) {
  check_series(peaks_from_rr(join({repeat(300, 12), {600}, repeat(300, 8), {120, 180},
                                   repeat(300, 3), {600, 600}, repeat(300, 4), {600}})),
               360);
}

// The hold after an ectopic run (early intervals after it, until the sinus rate or a steady
// rhythm) needs no look-ahead: streamed, one peak at a time or in chunks, it decides as the
// batch does, and the series does exercise it (the batch differs with the option off).
TEST(NnClassifier, EctopicRunsMatchBatch) {
  std::vector<int> rr;
  for (int i = 0; i < 30; ++i) rr.push_back(i % 2 ? 302 : 298);
  for (int r : {220, 230, 215, 225, 272, 268, 277, 300, 302, 298}) rr.push_back(r);
  for (int r : {220, 230, 215, 225, 276, 276, 276, 276, 276, 2000, 300, 300}) rr.push_back(r);
  for (int i = 0; i < 12; ++i) rr.push_back(i % 2 ? 302 : 298);
  for (int r : {215, 225, 220, 270, 0, 271, 300}) rr.push_back(r);
  const auto peaks = peaks_from_rr(rr);
  check_series(peaks, 360);
  NnRule off;
  off.hold_after_ectopic_run = false;
  std::string why;
  EXPECT_FALSE(same(intervals_from_peaks(peaks, 360), intervals_from_peaks(peaks, 360, off), why));
}

TEST(NnClassifier, RateChangesMatchBatch) {
  std::vector<int> ramp;
  for (int r = 300; r > 200; r -= 3) ramp.push_back(r);
  // A gradual ramp, an abrupt sustained fast run (rebased after rebase_beats), an abrupt
  // slower rhythm (adopted after sustained_beats), and a slower one that ends too early.
  check_series(peaks_from_rr(join({repeat(300, 12), ramp, repeat(200, 10), repeat(140, 30),
                                   repeat(300, 10), repeat(480, 8), repeat(300, 10), {480, 480},
                                   {480}})),
               360);
  check_series(peaks_from_rr(join({repeat(300, 12), {480, 480, 480}})), 360);  // ends long
}

TEST(NnClassifier, GapsLongerThanMaxIntervalMatchBatch) {
  check_series(peaks_from_rr(join({{800}, repeat(300, 5), {900}, repeat(300, 3), {721, 720},
                                   repeat(250, 12), {5000}, {300}, {2000}})),
               360);
  check_series(peaks_from_rr({900, 900, 300, 900}), 360);  // gaps right at the start
  // A gap that is the second half of a short interval is skipped, not a restart.
  check_series(peaks_from_rr(join({repeat(300, 10), {150, 1000}, repeat(200, 12)})), 360);
}

TEST(NnClassifier, DuplicatesAndDegenerateInputMatchBatch) {
  check_series(peaks_from_rr(join({{0, 0}, repeat(300, 6), {0}, repeat(300, 6), {0, 0, 0},
                                   {900}, {0, 300, 0, 300, 300, 0}, repeat(300, 12)})),
               360);
  check_series({}, 360);
  check_series({5}, 360);
  check_series({5, 5}, 360);
  check_series({5, 300}, 360);
  check_series(peaks_from_rr(repeat(300, 10)), 0);   // no fs: nothing, as the batch
  check_series(peaks_from_rr(repeat(300, 10)), -1);
  check_series({1000, 900, 1200, 1500}, 360);        // out of order: a negative interval
}

TEST(NnClassifier, ExcludedRangesMatchBatch) {
  const auto peaks = peaks_from_rr(join({repeat(300, 20), {200, 400}, repeat(300, 20)}));
  check_series(peaks, 360, {}, {{2000, 2000}, {4000, 4600}, {peaks[30], peaks[30]}, {9000, 8000}});
}

TEST(NnClassifier, UnusualRulesMatchBatch) {
  const auto peaks = peaks_from_rr(join({repeat(300, 12), {200, 400}, repeat(480, 6),
                                         repeat(150, 10), {600}, repeat(300, 4)}));
  for (const NnRule& rule : {NnRule{.reference_beats = 1}, NnRule{.sustained_beats = 0},
                             NnRule{.rebase_beats = 3, .spread_diffs = 1},
                             NnRule{.reference_beats = 25, .sustained_beats = 10}}) {
    check_series(peaks, 360, rule);
  }
  // A PVC continuous with the short interval before it waits two intervals for its pause to be
  // one (premature_pause_when_continuous): D is 2 even where the rule's other look-aheads are 1.
  const auto near = peaks_from_rr(join({repeat(410, 40), {385, 480, 410}, repeat(410, 6)}));
  const NnRule short_look = {.reference_beats = 1, .sustained_beats = 1};
  check_series(near, 360, short_look);
  const auto decided = intervals_from_peaks(near, 360, short_look);
  EXPECT_FALSE(decided[40].nn);
  EXPECT_FALSE(decided[41].nn);
}

// --- Random series --------------------------------------------------------------------------

// A few thousand beats of a rhythm that wanders (sinus arrhythmia, slow rate drift, abrupt
// rate steps) with premature beats and their pauses, missed and spurious detections, gaps and
// duplicates, at a sampling rate drawn per seed.
std::vector<std::int64_t> random_peaks(std::uint32_t seed, std::size_t n, bool duplicates) {
  std::mt19937 g(seed);
  std::uniform_real_distribution<double> u(0, 1);
  std::normal_distribution<double> z(0, 1);
  const double fs = seed % 2 ? 360 : 250;
  double base = 0.8 * fs;
  std::vector<std::int64_t> p{static_cast<std::int64_t>(u(g) * fs)};
  const auto add = [&](double rr) {
    p.push_back(p.back() + std::max<std::int64_t>(1, std::llround(rr)));
  };
  while (p.size() < n) {
    const double x = u(g);
    base = std::clamp(base * (1 + 0.01 * z(g)), 0.3 * fs, 1.6 * fs);
    const double rr = base * (1 + 0.05 * std::sin(static_cast<double>(p.size()) / 4)) + 2 * z(g);
    if (x < 0.04) {  // premature beat and compensatory pause
      const double early = 0.55 + 0.4 * u(g);
      add(rr * early);
      add(rr * (2 - early));
    } else if (x < 0.06) {
      add(rr * 2);  // missed beat
    } else if (x < 0.08) {  // spurious detection
      const double split = 0.2 + 0.6 * u(g);
      add(rr * split);
      add(rr * (1 - split));
    } else if (x < 0.085) {
      add(fs * (2 + 8 * u(g)));  // gap
    } else if (x < 0.09) {
      base *= 0.5 + u(g);  // abrupt rate step
      add(rr);
    } else if (duplicates && x < 0.1) {
      p.push_back(p.back());
    } else {
      add(rr);
    }
  }
  return p;
}

TEST(NnClassifier, RandomSeriesFedOneByOneMatchBatch) {
  for (std::uint32_t seed = 1; seed <= 8; ++seed) {
    SCOPED_TRACE("seed " + std::to_string(seed));
    const auto peaks = random_peaks(seed, 3000, seed > 4);
    const double fs = seed % 2 ? 360 : 250;
    check_series(peaks, fs);
    std::mt19937 g(seed * 7919);
    std::vector<SampleRange> excluded;
    for (int k = 0; k < 20; ++k) {
      const auto span = static_cast<std::uint32_t>(peaks.back() - peaks.front());
      const std::int64_t a = peaks.front() + static_cast<std::int64_t>(g() % span);
      excluded.push_back({a, a + static_cast<std::int64_t>(g() % 2 ? 0 : g() % 5000)});
    }
    check_series(peaks, fs, NnRule{}, excluded);
    if (HasFailure()) return;
  }
}

TEST(NnClassifier, EndlessStreamKeepsPendingBounded) {
  // 200,000 beats, one by one, never finished: what is held stays within D intervals, and
  // everything but those has come out.
  const auto peaks = random_peaks(99, 200000, false);
  NnClassifier c(360);
  std::vector<Interval> out;
  std::size_t worst = 0;
  for (const std::int64_t p : peaks) {
    c.push(p, out);
    worst = std::max(worst, c.pending());
    if (out.size() > 4096) out.clear();
  }
  EXPECT_LE(worst, delay_bound(NnRule{}));
}

}  // namespace
}  // namespace tahvel::aggregation
