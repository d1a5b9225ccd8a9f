// HRV metrics (hrv.h): hand-computed time-domain cases, guards, Lomb-Scargle against a naive
// implementation and on modulated series, windows batch vs streaming.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "tahvel/aggregation/hrv.h"

namespace tahvel::aggregation {
namespace {

constexpr double kPi = 3.14159265358979323846;

// A chain of intervals (samples) from a start sample; nn flags per interval.
std::vector<Interval> chain(const std::vector<std::int64_t>& rr, const std::vector<bool>& nn,
                            std::int64_t start = 0) {
  std::vector<Interval> v;
  for (std::size_t i = 0; i < rr.size(); ++i) {
    v.push_back({start, start + rr[i], nn.empty() ? true : nn[i]});
    start += rr[i];
  }
  return v;
}

// HF needs 60 s of NN data (HrvOptions::min_hf_s): 45 pairs of 230 and 250 samples at 360 Hz
// are exactly 21,600 samples, 60 s. Summed as seconds one interval at a time they came to
// 59.99999999999989, and a window of MIT-BIH 122 with 60.000 s of NN had no HF while another
// had it.
TEST(Hrv, ExactlyTheNnDataHfNeedsIsEnough) {
  std::vector<std::int64_t> rr;
  for (int i = 0; i < 45; ++i) rr.insert(rr.end(), {230, 250});
  const HrvMetrics m = compute_hrv(chain(rr, {}), 360);
  EXPECT_TRUE(m.hf_ms2.has_value());
  rr.back() -= 1;  // a sample short of 60 s
  EXPECT_FALSE(compute_hrv(chain(rr, {}), 360).hf_ms2.has_value());
}

TEST(Hrv, TimeDomainByHand) {
  // fs 1000: samples are ms. NN 800 810 790 830; mean 807.5; deviations -7.5 2.5 -17.5 22.5,
  // squares sum 875, / (n - 1) = 291.667; differences 10 -20 40, squares sum 2100, / 3 = 700.
  const HrvMetrics m = compute_hrv(chain({800, 810, 790, 830}, {}), 1000);
  EXPECT_EQ(m.nn_count, 4u);
  EXPECT_EQ(m.rr_count, 4u);
  EXPECT_DOUBLE_EQ(*m.mean_nn_ms, 807.5);
  EXPECT_NEAR(*m.sdnn_ms, std::sqrt(875.0 / 3), 1e-9);
  EXPECT_NEAR(*m.rmssd_ms, std::sqrt(700.0), 1e-9);
  EXPECT_NEAR(*m.mean_hr_bpm, 60000.0 / 807.5, 1e-9);
  EXPECT_DOUBLE_EQ(*m.pnn50_pct, 0.0);
  // SD1^2 = var(10, -20, 40) / 2 = 900 / 2; SD2^2 = 2 * 291.667 - 450.
  EXPECT_NEAR(*m.sd1_ms, std::sqrt(450.0), 1e-9);
  EXPECT_NEAR(*m.sd2_ms, std::sqrt(2 * 875.0 / 3 - 450), 1e-9);
  EXPECT_FALSE(m.lf_ms2);
  EXPECT_FALSE(m.hf_ms2);
  EXPECT_FALSE(m.lf_hf);
}

// Irregularity counts every adjacent pair, NN or not: bigeminy (short, long, short, ...) is
// irregular whatever the rule made of its intervals; a steady rhythm is not.
TEST(Hrv, IrregularPctCountsAdjacentPairsDifferingByMoreThanAFifth) {
  const HrvMetrics steady = compute_hrv(chain({800, 810, 790, 830, 800}, {}), 1000);
  ASSERT_TRUE(steady.irregular_pct);
  EXPECT_DOUBLE_EQ(*steady.irregular_pct, 0.0);
  const HrvMetrics bigeminy = compute_hrv(chain({500, 1100, 500, 1100, 500}, {true, true, true, true, true}), 1000);
  EXPECT_DOUBLE_EQ(*bigeminy.irregular_pct, 100.0);
  // 800 -> 1000 is 25 % longer (counted); 1000 -> 850 is 15 % shorter (not); 850 -> 850 not.
  const HrvMetrics some = compute_hrv(chain({800, 1000, 850, 850}, {false, false, false, false}), 1000);
  EXPECT_NEAR(*some.irregular_pct, 100.0 / 3, 1e-9);
  auto cut = chain({800, 1200}, {});
  cut[1].start += 5;
  cut[1].end += 5;
  EXPECT_FALSE(compute_hrv(cut, 1000).irregular_pct) << "intervals that share no beat are not a pair";
}

// A gap (an interval longer than gap_s: a lead off between two beats, a pause) is no irregular
// rhythm: each isolated one made two irregular pairs, and a regular record whose lead came off
// in 8 % of its intervals was warned of as ectopic beats or atrial fibrillation.
TEST(Hrv, PairsWithAGapAreNotCountedAsIrregular) {
  const HrvMetrics gapped = compute_hrv(chain({800, 810, 5000, 790, 800, 6000, 810, 800}, {}), 1000);
  ASSERT_TRUE(gapped.irregular_pct);
  EXPECT_DOUBLE_EQ(*gapped.irregular_pct, 0.0);  // 3 pairs without a gap, all regular
  HrvOptions longer;
  longer.gap_s = 10;  // the gaps are rhythm now: 4 of 7 pairs
  EXPECT_NEAR(*compute_hrv(chain({800, 810, 5000, 790, 800, 6000, 810, 800}, {}), 1000, longer).irregular_pct,
              100.0 * 4 / 7, 1e-9);
}

TEST(Hrv, RmssdOnlyOverAdjacentNn) {
  // The 300 between 810 and 790 is not NN: the difference 790 - 810 is not taken.
  const HrvMetrics m = compute_hrv(chain({800, 810, 300, 790, 830}, {true, true, false, true, true}), 1000);
  EXPECT_EQ(m.nn_count, 4u);
  EXPECT_EQ(m.rr_count, 5u);
  EXPECT_NEAR(*m.sdnn_ms, std::sqrt(875.0 / 3), 1e-9);
  EXPECT_NEAR(*m.rmssd_ms, std::sqrt((100.0 + 1600.0) / 2), 1e-9);
}

TEST(Hrv, IntervalsThatDoNotShareABeatAreNotAdjacent) {
  auto v = chain({800, 810, 790}, {});
  v[2].start += 5;  // a cut series: 790 does not start where 810 ended
  v[2].end += 5;
  const HrvMetrics m = compute_hrv(v, 1000);
  EXPECT_FALSE(m.rmssd_ms);  // one adjacent difference only
}

TEST(Hrv, Pnn50ComparesIntegerSamples) {
  // At 360 Hz, 50 ms is 18 samples: a difference of 18 does not count, 19 does.
  const HrvMetrics m = compute_hrv(chain({300, 318, 337}, {}), 360);
  EXPECT_DOUBLE_EQ(*m.pnn50_pct, 50.0);
  const HrvMetrics none = compute_hrv(chain({300, 318, 300}, {}), 360);
  EXPECT_DOUBLE_EQ(*none.pnn50_pct, 0.0);
  const HrvMetrics all = compute_hrv(chain({300, 319, 300}, {}), 360);
  EXPECT_DOUBLE_EQ(*all.pnn50_pct, 100.0);
}

TEST(Hrv, GuardsGiveNullopt) {
  const HrvMetrics empty = compute_hrv({}, 360);
  EXPECT_FALSE(empty.mean_nn_ms);
  EXPECT_FALSE(empty.sdnn_ms);
  const HrvMetrics one = compute_hrv(chain({300}, {}), 360);
  EXPECT_TRUE(one.mean_nn_ms);
  EXPECT_FALSE(one.sdnn_ms);
  EXPECT_FALSE(one.rmssd_ms);
  const HrvMetrics two = compute_hrv(chain({300, 310}, {}), 360);
  EXPECT_TRUE(two.sdnn_ms);
  EXPECT_FALSE(two.rmssd_ms);  // one difference
  EXPECT_FALSE(two.pnn50_pct);
  EXPECT_FALSE(two.sd1_ms);
  const HrvMetrics none_nn = compute_hrv(chain({300, 310}, {false, false}), 360);
  EXPECT_EQ(none_nn.nn_count, 0u);
  EXPECT_FALSE(none_nn.mean_hr_bpm);
  EXPECT_FALSE(compute_hrv(chain({300, 310, 320}, {}), 0).mean_nn_ms);
  // 90 s of NN data: HF yes, LF (2 min) no.
  std::vector<std::int64_t> rr(90, 1000);
  for (std::size_t i = 0; i < rr.size(); i += 2) rr[i] += 20;
  const HrvMetrics short_rec = compute_hrv(chain(rr, {}), 1000);
  EXPECT_TRUE(short_rec.hf_ms2);
  EXPECT_FALSE(short_rec.lf_ms2);
  EXPECT_FALSE(short_rec.lf_hf);
}

// Beats whose RR follows 800 + amp * sin(2 pi f t) ms (t in s), for duration_s, at 1000 Hz.
std::vector<Interval> modulated(double f_hz, double amp_ms, double duration_s) {
  std::vector<std::int64_t> rr;
  double t = 0;
  while (t < duration_s) {
    const double r = 800 + amp_ms * std::sin(2 * kPi * f_hz * t);
    rr.push_back(std::llround(r));
    t += static_cast<double>(rr.back()) / 1000;
  }
  return chain(rr, {});
}

TEST(LombScargle, PowerAt0_1HzIsLf) {
  const HrvMetrics m = compute_hrv(modulated(0.1, 50, 300), 1000);
  ASSERT_TRUE(m.lf_ms2 && m.hf_ms2);
  const double var = *m.sdnn_ms * *m.sdnn_ms;  // about 50^2 / 2
  EXPECT_NEAR(*m.lf_ms2 + *m.hf_ms2, var, 0.1 * var);
  EXPECT_GT(*m.lf_ms2, 20 * *m.hf_ms2);
  EXPECT_GT(*m.lf_hf, 20);
}

TEST(LombScargle, PowerAt0_25HzIsHf) {
  const HrvMetrics m = compute_hrv(modulated(0.25, 30, 300), 1000);
  ASSERT_TRUE(m.lf_ms2 && m.hf_ms2);
  const double var = *m.sdnn_ms * *m.sdnn_ms;
  EXPECT_NEAR(*m.lf_ms2 + *m.hf_ms2, var, 0.1 * var);
  EXPECT_GT(*m.hf_ms2, 20 * *m.lf_ms2);
}

// A steady breathing rhythm (0.25 Hz) is a peak about 1/span wide: on a grid capped at 1,024
// frequencies, a record longer than about 12 min put points too far apart to integrate it, and
// HF of a 2-h record came out 475 ms^2 for a true 225, of 8 h 14 (a researcher's synthetic
// records). At the step 1/(4 span), and over hours in parts, the band's power is the sine's
// whatever the length, and LF + HF never exceed the variance.
TEST(LombScargle, ABandsPowerDoesNotDependOnTheLengthOfTheRecord) {
  const double truth = 30.0 * 30.0 / 2;  // a sine of amplitude 30 ms
  for (const double seconds : {300.0, 1800.0, 7200.0, 28800.0}) {
    const HrvMetrics m = compute_hrv(modulated(0.2317, 30, seconds), 1000);
    ASSERT_TRUE(m.hf_ms2 && m.lf_ms2 && m.sdnn_ms) << seconds;
    EXPECT_NEAR(*m.hf_ms2, truth, 0.05 * truth) << seconds << " s";
    EXPECT_LE(*m.lf_ms2 + *m.hf_ms2, 1.02 * *m.sdnn_ms * *m.sdnn_ms) << seconds << " s";
  }
  // Cut into parts (a small work bound), the same: the parts are each still minutes long.
  HrvOptions parts;
  parts.max_work = 1e6;
  const HrvMetrics split = compute_hrv(modulated(0.2317, 30, 7200), 1000, parts);
  ASSERT_TRUE(split.hf_ms2);
  EXPECT_NEAR(*split.hf_ms2, truth, 0.05 * truth);
}

// Random RR with gaps: the density integrates to the (population) variance up to Nyquist.
TEST(LombScargle, TotalPowerIsTheVariance) {
  std::mt19937 gen(7);
  std::normal_distribution<double> noise(0, 40);
  std::vector<double> t, y;
  double now = 0;
  for (int i = 0; i < 600; ++i) {
    const double r = 800 + noise(gen);
    now += r / 1000;
    if (i % 37 == 5) continue;  // a gap: this interval is not NN
    t.push_back(now);
    y.push_back(r);
  }
  double m = 0, var = 0;
  for (double v : y) m += v;
  m /= static_cast<double>(y.size());
  for (double v : y) var += (v - m) * (v - m);
  var /= static_cast<double>(y.size());
  const double nyquist = 0.5 / 0.8, df = 1.0 / (4 * (t.back() - t.front()));
  const auto count = static_cast<std::size_t>(nyquist / df);
  const auto psd = lomb_scargle_density(t, y, df / 2, df, count);
  double total = 0;
  for (double p : psd) total += p * df;
  EXPECT_NEAR(total, var, 0.1 * var);
}

// A hole in the NN series (150 s of lead-off in 300 s) is no rhythm: the band powers stay
// those of the series without it. Scaled by the span, they doubled (LF 198.9 -> 394.9 ms^2 on a
// researcher's record), with SDNN unchanged, and a trend of them alerted.
TEST(LombScargle, AHoleInTheSeriesDoesNotInflateTheBandPowers) {
  std::mt19937 gen(5);
  std::normal_distribution<double> noise(0, 10);
  std::vector<double> t, y, t_hole, y_hole;
  double now = 0;
  while (now < 600) {
    const double r = 800 + 30 * std::sin(2 * kPi * 0.1 * now) + 20 * std::sin(2 * kPi * 0.25 * now) + noise(gen);
    now += r / 1000;
    t.push_back(now);
    y.push_back(r);
    if (now < 150 || now > 450) {
      t_hole.push_back(now);
      y_hole.push_back(r);
    }
  }
  const BandPowers whole = lomb_scargle_bands(t, y), holed = lomb_scargle_bands(t_hole, y_hole);
  EXPECT_NEAR(holed.lf_ms2, whole.lf_ms2, 0.15 * whole.lf_ms2);
  EXPECT_NEAR(holed.hf_ms2, whole.hf_ms2, 0.15 * whole.hf_ms2);
}

// Naive Lomb-Scargle straight from the definition, with trig calls at every point.
double naive_density(const std::vector<double>& t, const std::vector<double>& y, double f) {
  const std::size_t n = t.size();
  double mean = 0;
  for (double v : y) mean += v;
  mean /= static_cast<double>(n);
  const double w = 2 * kPi * f;
  double s2 = 0, c2 = 0;
  for (double tj : t) {
    s2 += std::sin(2 * w * (tj - t[0]));
    c2 += std::cos(2 * w * (tj - t[0]));
  }
  const double tau = std::atan2(s2, c2) / (2 * w);
  double yc = 0, ys = 0, cc = 0, ss = 0;
  for (std::size_t j = 0; j < n; ++j) {
    const double a = w * (t[j] - t[0] - tau);
    yc += (y[j] - mean) * std::cos(a);
    ys += (y[j] - mean) * std::sin(a);
    cc += std::cos(a) * std::cos(a);
    ss += std::sin(a) * std::sin(a);
  }
  const double p = 0.5 * (yc * yc / cc + ys * ys / ss);
  const double span = (t[n - 1] - t[0]) * static_cast<double>(n) / static_cast<double>(n - 1);
  return p * 2 * span / static_cast<double>(n);
}

TEST(LombScargle, MatchesNaiveImplementation) {
  std::mt19937 gen(11);
  std::uniform_real_distribution<double> rr(0.6, 1.1), val(700, 900);
  std::vector<double> t, y;
  double now = 0;
  for (int i = 0; i < 400; ++i) {
    now += rr(gen);
    t.push_back(now);
    y.push_back(val(gen));
  }
  const double f0 = 0.0123, df = 0.0017;
  const std::size_t count = 230;
  const auto fast = lomb_scargle_density(t, y, f0, df, count);
  for (std::size_t k = 0; k < count; ++k) {
    const double want = naive_density(t, y, f0 + static_cast<double>(k) * df);
    EXPECT_NEAR(fast[k], want, 1e-7 * std::max(1.0, want)) << k;
  }
}

std::vector<Interval> noisy_series(int n, unsigned seed) {
  std::mt19937 gen(seed);
  std::normal_distribution<double> noise(0, 30);
  std::uniform_int_distribution<int> pick(0, 19);
  std::vector<std::int64_t> rr;
  std::vector<bool> nn;
  for (int i = 0; i < n; ++i) {
    rr.push_back(std::llround(288 + noise(gen)));
    nn.push_back(pick(gen) != 0);
  }
  return chain(rr, nn, 4321);
}

void expect_same(const std::vector<WindowMetrics>& a, const std::vector<WindowMetrics>& b) {
  ASSERT_EQ(a.size(), b.size());
  for (std::size_t i = 0; i < a.size(); ++i) {
    EXPECT_EQ(a[i].start_s, b[i].start_s) << i;
    EXPECT_EQ(a[i].end_s, b[i].end_s) << i;
    EXPECT_EQ(a[i].metrics.rr_count, b[i].metrics.rr_count) << i;
    EXPECT_EQ(a[i].metrics.nn_count, b[i].metrics.nn_count) << i;
    EXPECT_EQ(a[i].metrics.sdnn_ms, b[i].metrics.sdnn_ms) << i;
    EXPECT_EQ(a[i].metrics.rmssd_ms, b[i].metrics.rmssd_ms) << i;
    EXPECT_EQ(a[i].metrics.hf_ms2, b[i].metrics.hf_ms2) << i;
    EXPECT_EQ(a[i].metrics.lf_ms2, b[i].metrics.lf_ms2) << i;
  }
}

TEST(Windows, StreamingEqualsBatch) {
  const auto series = noisy_series(1500, 3);
  for (auto [window, step] : {std::pair{60.0, 30.0}, std::pair{300.0, 60.0}, std::pair{45.0, 45.0}}) {
    const auto batch = windowed_hrv(series, 360, window, step);
    HrvWindower w(360, window, step);
    std::vector<WindowMetrics> streamed;
    for (const auto& iv : series) w.push(iv, streamed);
    w.finish(streamed);
    expect_same(batch, streamed);
  }
}

// A record that ends inside a window: that window, and every later one still open, ends with
// the record, streamed or not; the windows before keep their length.
TEST(Windows, TheLastWindowsEndWhereTheRecordEnds) {
  const auto series = chain(std::vector<std::int64_t>(10, 1000), {});  // interval ends at 1 .. 10 s
  const auto batch = windowed_hrv(series, 1000, 4.0, 2.0, {}, 10.5);
  std::vector<std::pair<double, double>> spans;
  for (const auto& m : batch) spans.emplace_back(m.start_s, m.end_s);
  using Spans = std::vector<std::pair<double, double>>;
  EXPECT_EQ(spans, (Spans{{0, 4}, {2, 6}, {4, 8}, {6, 10}, {8, 10.5}, {10, 10.5}}));
  EXPECT_EQ(batch.back().metrics.rr_count, 1u);  // the interval ending at 10 s
  HrvWindower w(1000, 4.0, 2.0);
  std::vector<WindowMetrics> streamed;
  for (const auto& iv : series) w.push(iv, streamed);
  w.finish(streamed, 10.5);
  expect_same(batch, streamed);
  // Without the record's end, the nominal length; with one past every window, no change.
  EXPECT_DOUBLE_EQ(windowed_hrv(series, 1000, 4.0, 2.0).back().end_s, 14.0);
  EXPECT_DOUBLE_EQ(windowed_hrv(series, 1000, 4.0, 2.0, {}, 20.0).back().end_s, 14.0);
}

TEST(Windows, IntervalBelongsToTheWindowOfItsEndBeat) {
  // fs 1000: intervals end at 0.9, 1.8 (window 1 s) and 2.7 s.
  const auto w = windowed_hrv(chain({900, 900, 900}, {}), 1000, 1.0, 1.0);
  ASSERT_EQ(w.size(), 3u);
  EXPECT_EQ(w[0].metrics.rr_count, 1u);
  EXPECT_EQ(w[1].metrics.rr_count, 1u);
  EXPECT_EQ(w[2].metrics.rr_count, 1u);
  EXPECT_DOUBLE_EQ(w[2].start_s, 2.0);
  EXPECT_TRUE(windowed_hrv(chain({900}, {}), 1000, 0, 1).empty());
}

// Windows of a length that is not a whole number of seconds, one after the other: an interval
// ending exactly on a boundary is in one window. With the end taken as start + length, 434.2 s
// (MIT-BIH 116, --window 0.2) was in no window, and with 1.1 s windows intervals were in two.
TEST(Windows, AnIntervalEndingOnABoundaryIsInExactlyOneWindow) {
  for (auto [length, samples] : {std::pair{1.1, std::int64_t{396}}, std::pair{0.2, std::int64_t{72}},
                                 std::pair{0.7, std::int64_t{252}}, std::pair{0.3, std::int64_t{108}}}) {
    const auto series = chain(std::vector<std::int64_t>(2000, samples), {});  // ends on every boundary at 360 Hz
    std::size_t counted = 0;
    for (const auto& m : windowed_hrv(series, 360, length, length)) counted += m.metrics.rr_count;
    EXPECT_EQ(counted, series.size()) << length;
    HrvWindower w(360, length, length);
    std::vector<WindowMetrics> streamed;
    for (const auto& iv : series) w.push(iv, streamed);
    w.finish(streamed);
    std::size_t streamed_count = 0;
    for (const auto& m : streamed) streamed_count += m.metrics.rr_count;
    EXPECT_EQ(streamed_count, series.size()) << length;
  }
}

// A window's end that is not a multiple of the step (60 s windows every 1.3 s) and a beat
// exactly on it (MIT-BIH 122: sample 609408 at 360 Hz is 1692.8 s, the end of the window from
// 1632.8 s): the beat is not in that window, as [start, end) says, streamed or not. Computed in
// seconds, the end came out a hair above 1692.8 and the beat was in it. Checked against exact
// arithmetic: window k is [1.3·k, 1.3·k + 60) s, so a beat at sample e is in it when
// 4680·k <= 10·e < 4680·k + 216000.
TEST(Windows, ABeatOnAWindowsEndIsNotInThatWindowWhateverTheStep) {
  const std::int64_t on_the_end = 609'408;
  const auto series = chain(std::vector<std::int64_t>(400, 432), {}, on_the_end - 200 * 432);
  auto expect_exact = [&](const std::vector<WindowMetrics>& windows, const char* how) {
    ASSERT_FALSE(windows.empty()) << how;
    bool saw_the_window = false;
    for (const WindowMetrics& m : windows) {
      const auto k = static_cast<std::int64_t>(std::llround(m.start_s / 1.3));
      std::size_t in = 0;
      for (const Interval& iv : series) in += 4680 * k <= 10 * iv.end && 10 * iv.end < 4680 * k + 216'000;
      EXPECT_EQ(m.metrics.rr_count, in) << how << ": window from " << m.start_s << " s";
      saw_the_window |= k == 1256;
    }
    EXPECT_TRUE(saw_the_window) << how;
  };
  expect_exact(windowed_hrv(series, 360, 60, 1.3), "batch");
  HrvWindower w(360, 60, 1.3);
  std::vector<WindowMetrics> streamed;
  for (const auto& iv : series) w.push(iv, streamed);
  w.finish(streamed);
  expect_exact(streamed, "streamed");
}

// Intervals that begin well into the recording (a gateway whose store was made again gets the
// sensor's chunks from where it is): no window for the minutes before the first one, which hold
// nothing and would be named as the windows the hospital has from the store before.
TEST(Windows, NoWindowEndsBeforeTheFirstInterval) {
  const auto series = chain(std::vector<std::int64_t>(200, 1000), {}, 319'500);  // ends at 320.5 s on, fs 1000
  for (auto [window, step, first_start] : {std::tuple{60.0, 60.0, 300.0}, std::tuple{300.0, 60.0, 60.0},
                                           std::tuple{1.1, 1.1, 320.1}}) {
    const auto batch = windowed_hrv(series, 1000, window, step);
    ASSERT_FALSE(batch.empty());
    EXPECT_NEAR(batch.front().start_s, first_start, 1e-9) << window << " " << step;
    EXPECT_GT(batch.front().metrics.rr_count, 0u) << window;
    HrvWindower w(1000, window, step);
    std::vector<WindowMetrics> streamed;
    for (const auto& iv : series) w.push(iv, streamed);
    w.finish(streamed);
    expect_same(batch, streamed);
  }
}

TEST(Windows, StreamingEmitsAWindowWhenAnIntervalPassesItsEnd) {
  HrvWindower w(1000, 1.0, 1.0);
  std::vector<WindowMetrics> done;
  const auto series = chain({900, 900, 900}, {});
  w.push(series[0], done);
  EXPECT_TRUE(done.empty());
  w.push(series[1], done);  // ends at 1.8 s: window [0, 1) is complete
  ASSERT_EQ(done.size(), 1u);
  EXPECT_EQ(done[0].metrics.rr_count, 1u);
  w.set_window(2.0, 2.0);  // from window [1, 3) on
  w.push(series[2], done);
  w.finish(done);
  ASSERT_EQ(done.size(), 2u);
  EXPECT_DOUBLE_EQ(done[1].start_s, 1.0);
  EXPECT_DOUBLE_EQ(done[1].end_s, 3.0);
  EXPECT_EQ(done[1].metrics.rr_count, 2u);
}

// After a restart with another setting: the next window ends one step after the last one
// written, so none overlaps it (non-overlapping windows continue where it ended; overlapping
// ones of the same setting continue their grid).
TEST(Windows, ResumingAfterAWrittenWindowProducesNoWindowOverlappingIt) {
  const auto series = chain(std::vector<std::int64_t>(10, 1000), {});  // interval ends at 1, 2, ... 10 s
  auto windows_of = [&](double window, double step, double written_end, double written_length) {
    HrvWindower w(1000, window, step);
    w.resume_after(written_end, written_length);
    std::vector<WindowMetrics> done;
    for (const auto& interval : series) w.push(interval, done);
    std::vector<std::pair<double, double>> out;
    for (const auto& m : done) out.emplace_back(m.start_s, m.end_s);
    return out;
  };
  using Spans = std::vector<std::pair<double, double>>;
  EXPECT_EQ(windows_of(2, 2, 6, 6), (Spans{{6, 8}, {8, 10}}));   // was 6 s windows up to 6 s
  EXPECT_EQ(windows_of(4, 2, 6, 4), (Spans{{4, 8}, {6, 10}}));   // overlapping: the grid goes on
  EXPECT_EQ(windows_of(3, 3, 0.5, 0.5), (Spans{{0.5, 3.5}, {3.5, 6.5}, {6.5, 9.5}}));
  // Longer, overlapping windows after shorter ones (2 s up to 4 s, then 5 s every 1 s): they
  // start where the written ones ended; the grid of the new setting from there would reach back
  // over them ([0, 5) overlaps [2, 4), and would take the name of the window written at 0).
  EXPECT_EQ(windows_of(5, 1, 4, 2), (Spans{{4, 9}, {5, 10}}));
}

}  // namespace
}  // namespace tahvel::aggregation
