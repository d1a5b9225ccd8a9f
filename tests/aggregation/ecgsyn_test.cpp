// Tests of the synthetic ECG generator (ecgsyn.h): determinism and chunking, the statistics
// of the true RR series against the options (mean, SD, LF/HF), the true R peaks against the
// signal, ectopic beats, and option checking. Spectral power is computed here, independently
// of the generator: a plain DFT of the RR series resampled evenly at 4 Hz.
#include "tahvel/aggregation/ecgsyn.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <functional>
#include <numbers>
#include <numeric>
#include <string>
#include <vector>

namespace tahvel::aggregation {
namespace {

struct EcgRun {
  std::vector<std::int32_t> samples;
  std::vector<std::int64_t> beats;
  std::vector<char> codes;
};

EcgRun generate(const SyntheticEcgOptions& options, double seconds) {
  auto ecg = SyntheticEcg::create(options);
  EXPECT_TRUE(ecg.has_value()) << ecg.error().message;
  EcgRun run;
  ecg->generate(static_cast<std::size_t>(seconds * options.fs), run.samples);
  run.beats = ecg->beats();
  run.codes = ecg->beat_codes();
  return run;
}

// RR intervals (s) between consecutive true beats, and the time (s) each one ends.
struct RrSeries {
  std::vector<double> rr, t;
};

RrSeries rr_series(const EcgRun& run, double fs) {
  RrSeries s;
  for (std::size_t i = 1; i < run.beats.size(); ++i) {
    s.rr.push_back(static_cast<double>(run.beats[i] - run.beats[i - 1]) / fs);
    s.t.push_back(static_cast<double>(run.beats[i]) / fs);
  }
  return s;
}

double mean(const std::vector<double>& v) {
  return std::accumulate(v.begin(), v.end(), 0.0) / static_cast<double>(v.size());
}

double sd(const std::vector<double>& v) {
  const double m = mean(v);
  double ss = 0;
  for (double x : v) ss += (x - m) * (x - m);
  return std::sqrt(ss / static_cast<double>(v.size() - 1));
}

// LF (0.04–0.15 Hz) over HF (0.15–0.4 Hz) power of the RR series: linear resampling at 4 Hz,
// mean removed, Hann window, DFT at every bin in the two bands.
double lf_over_hf(const RrSeries& s) {
  constexpr double kHz = 4;
  std::vector<double> even;
  std::size_t j = 0;
  for (double t = s.t.front(); t <= s.t.back(); t += 1 / kHz) {
    while (s.t[j + 1] < t) ++j;
    const double f = (t - s.t[j]) / (s.t[j + 1] - s.t[j]);
    even.push_back(s.rr[j] + f * (s.rr[j + 1] - s.rr[j]));
  }
  const double m = mean(even);
  const auto n = even.size();
  for (std::size_t i = 0; i < n; ++i) {
    even[i] = (even[i] - m) * (0.5 - 0.5 * std::cos(2 * std::numbers::pi * i / (n - 1)));
  }
  auto band = [&](double lo, double hi) {
    double power = 0;
    for (auto k = static_cast<std::size_t>(std::ceil(lo * n / kHz)); k * kHz < hi * n; ++k) {
      double re = 0, im = 0;
      for (std::size_t i = 0; i < n; ++i) {
        const double a = 2 * std::numbers::pi * static_cast<double>(k * i % n) / n;
        re += even[i] * std::cos(a);
        im -= even[i] * std::sin(a);
      }
      power += re * re + im * im;
    }
    return power;
  };
  return band(0.04, 0.15) / band(0.15, 0.4);
}

SyntheticEcgOptions quiet_rhythm() {
  SyntheticEcgOptions o;
  o.fs = 128;  // the RR statistics do not need more; the integrator still runs at 512 Hz
  return o;
}

TEST(Ecgsyn, SameSeedGivesIdenticalSamplesAndBeats) {
  SyntheticEcgOptions o;
  o.ectopic_rate = 0.1;
  o.seed = 42;
  const EcgRun a = generate(o, 30), b = generate(o, 30);
  EXPECT_EQ(a.samples, b.samples);
  EXPECT_EQ(a.beats, b.beats);
  EXPECT_EQ(a.codes, b.codes);
  EXPECT_GT(a.beats.size(), 25u);
}

TEST(Ecgsyn, DifferentSeedGivesDifferentSamplesAndBeats) {
  SyntheticEcgOptions o;
  const EcgRun a = generate(o, 60);
  o.seed = 2;
  const EcgRun b = generate(o, 60);
  EXPECT_NE(a.samples, b.samples);
  EXPECT_NE(a.beats, b.beats);
}

TEST(Ecgsyn, OutputIsIdenticalWhateverTheChunkSizes) {
  SyntheticEcgOptions o;
  o.ectopic_rate = 0.15;
  o.seed = 7;
  const EcgRun whole = generate(o, 40);

  auto ecg = SyntheticEcg::create(o);
  ASSERT_TRUE(ecg.has_value());
  EcgRun chunked;
  const std::size_t sizes[] = {1, 0, 359, 360, 7, 1000, 2, 4321, 360};
  std::size_t i = 0;
  while (chunked.samples.size() < whole.samples.size()) {
    const std::size_t n = std::min(sizes[i++ % std::size(sizes)],
                                   whole.samples.size() - chunked.samples.size());
    ecg->generate(n, chunked.samples);
    if (i % 5 == 0) {  // hand beats over now and then: indices stay absolute
      SyntheticBeats taken = ecg->take_beats();
      EXPECT_TRUE(ecg->beats().empty());
      chunked.beats.insert(chunked.beats.end(), taken.samples.begin(), taken.samples.end());
      chunked.codes.insert(chunked.codes.end(), taken.codes.begin(), taken.codes.end());
    }
  }
  SyntheticBeats rest = ecg->take_beats();
  chunked.beats.insert(chunked.beats.end(), rest.samples.begin(), rest.samples.end());
  chunked.codes.insert(chunked.codes.end(), rest.codes.begin(), rest.codes.end());

  EXPECT_EQ(chunked.samples, whole.samples);
  EXPECT_EQ(chunked.beats, whole.beats);
  EXPECT_EQ(chunked.codes, whole.codes);
  EXPECT_EQ(ecg->samples_generated(), static_cast<std::int64_t>(whole.samples.size()));
}

TEST(Ecgsyn, BeatsAreIncreasingAndInsideTheGeneratedSamples) {
  auto ecg = SyntheticEcg::create({});
  ASSERT_TRUE(ecg.has_value());
  std::vector<std::int32_t> out;
  for (int second = 0; second < 20; ++second) {
    ecg->generate(360, out);
    ASSERT_FALSE(ecg->beats().empty());
    EXPECT_LT(ecg->beats().back(), ecg->samples_generated());
  }
  EXPECT_TRUE(std::is_sorted(ecg->beats().begin(), ecg->beats().end()));
  EXPECT_EQ(ecg->beat_codes().size(), ecg->beats().size());
}

TEST(Ecgsyn, ConvenienceFunctionEqualsTheStreamingGenerator) {
  SyntheticEcgOptions o;
  o.seed = 9;
  auto samples = synthetic_ecg(10, o);
  ASSERT_TRUE(samples.has_value()) << samples.error().message;
  EXPECT_EQ(*samples, generate(o, 10).samples);
}

TEST(Ecgsyn, MeanHeartRateOfTrueBeatsMatchesTheOptionWithin2Percent) {
  for (const double hr : {45.0, 70.0, 120.0}) {
    SyntheticEcgOptions o = quiet_rhythm();
    o.mean_hr_bpm = hr;
    o.hr_std_bpm = 0.05 * hr;
    const EcgRun run = generate(o, 300);
    const double span_s = static_cast<double>(run.beats.back() - run.beats.front()) / o.fs;
    const double measured = 60 * static_cast<double>(run.beats.size() - 1) / span_s;
    EXPECT_NEAR(measured, hr, 0.02 * hr) << "mean_hr_bpm " << hr;
  }
}

TEST(Ecgsyn, RrStandardDeviationMatchesTheOptionWithin20PercentOver10Minutes) {
  for (const double hr_std : {3.0, 6.0}) {
    SyntheticEcgOptions o = quiet_rhythm();
    o.hr_std_bpm = hr_std;
    const RrSeries s = rr_series(generate(o, 600), o.fs);
    const double expected = 60 * hr_std / (o.mean_hr_bpm * o.mean_hr_bpm);  // ECGSYN's rule
    EXPECT_NEAR(sd(s.rr), expected, 0.2 * expected) << "hr_std_bpm " << hr_std;
  }
}

TEST(Ecgsyn, LfHfOfTrueRrSeriesFollowsTheRatioOption) {
  SyntheticEcgOptions o = quiet_rhythm();
  o.lf_hf_ratio = 2.0;
  const double more_lf = lf_over_hf(rr_series(generate(o, 600), o.fs));
  o.lf_hf_ratio = 0.5;
  const double more_hf = lf_over_hf(rr_series(generate(o, 600), o.fs));
  EXPECT_GT(more_lf, 1.0);
  EXPECT_LT(more_hf, 1.0);
  EXPECT_GT(more_lf / more_hf, 2.0);
  // Within a factor 2 of the option: ten minutes hold only a few dozen LF cycles, and linear
  // resampling of an RR series sampled once a beat damps HF (0.25 Hz) by about 1.4 in power.
  EXPECT_NEAR(std::log(more_lf / 2.0), 0, std::log(2.0));
  EXPECT_NEAR(std::log(more_hf / 0.5), 0, std::log(2.0));
}

TEST(Ecgsyn, TrueBeatIsTheMaximumOfTheSignalWithin20Ms) {
  SyntheticEcgOptions o;  // default noise and baseline wander, 360 Hz
  o.ectopic_rate = 0.1;
  const EcgRun run = generate(o, 120);
  const auto window = static_cast<std::int64_t>(0.15 * o.fs);
  const auto tolerance = static_cast<std::int64_t>(0.020 * o.fs);
  int ectopic = 0;
  for (std::size_t i = 0; i < run.beats.size(); ++i) {
    const std::int64_t beat = run.beats[i];
    if (beat < window || beat + window >= static_cast<std::int64_t>(run.samples.size())) continue;
    const auto first = run.samples.begin() + (beat - window);
    const auto peak = std::max_element(first, first + 2 * window + 1) - run.samples.begin();
    EXPECT_LE(std::abs(peak - beat), tolerance) << "beat " << i << " (" << run.codes[i] << ")";
    ectopic += run.codes[i] == 'V';
  }
  EXPECT_GT(ectopic, 3);
}

TEST(Ecgsyn, ZeroMillivoltIsAdcZeroAndRWavesAreAboutOneMillivolt) {
  SyntheticEcgOptions o;
  o.noise_mv = 0;
  o.baseline_wander_mv = 0;
  o.adc_zero = 0;
  o.gain = 1000;
  const EcgRun run = generate(o, 30);
  std::vector<std::int32_t> sorted = run.samples;
  std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
  EXPECT_NEAR(sorted[sorted.size() / 2], 0, 100);  // the isoelectric line, within 0.1 mV
  for (std::int64_t beat : run.beats) {
    EXPECT_GT(run.samples[beat], 900);
    EXPECT_LT(run.samples[beat], 1600);
  }
}

TEST(Ecgsyn, EctopicBeatsComeAtTheRequestedRateWithCompensatoryPause) {
  SyntheticEcgOptions o = quiet_rhythm();
  o.ectopic_rate = 0.1;
  o.seed = 3;
  const EcgRun run = generate(o, 1200);
  const RrSeries s = rr_series(run, o.fs);
  const auto n = static_cast<double>(run.codes.size());
  const double v = static_cast<double>(std::count(run.codes.begin(), run.codes.end(), 'V'));
  EXPECT_NEAR(v / n, 0.1, 0.025) << v << " of " << n;  // 1400 beats: SD of the rate 0.008
  const double normal_rr = 60 / o.mean_hr_bpm;
  for (std::size_t i = 1; i + 1 < run.codes.size(); ++i) {
    if (run.codes[i] != 'V') continue;
    EXPECT_NE(run.codes[i + 1], 'V') << "two ectopic beats in a row at " << i;
    const double before = s.rr[i - 1], after = s.rr[i];
    EXPECT_LT(before, 0.75 * normal_rr);  // premature
    EXPECT_GT(after, 1.2 * normal_rr);    // then a pause
    EXPECT_NEAR(before + after, 2 * normal_rr, 0.25 * normal_rr);  // fully compensatory
  }
}

TEST(Ecgsyn, NoEctopicBeatsWhenTheRateIsZero) {
  const EcgRun run = generate(quiet_rhythm(), 120);
  EXPECT_EQ(std::count(run.codes.begin(), run.codes.end(), 'V'), 0);
}

TEST(Ecgsyn, AnHourLongRunKeepsItsRateAndItsBeatsOnTheRPeaks) {
  SyntheticEcgOptions o;
  o.fs = 50;  // the cheapest rate: the integrator still runs at 500 Hz
  auto ecg = SyntheticEcg::create(o);
  ASSERT_TRUE(ecg.has_value());
  std::vector<std::int32_t> last;
  std::size_t beats = 0;
  for (int minute = 0; minute < 60; ++minute) {
    last.clear();
    ecg->generate(60 * 50, last);
    if (minute < 59) beats += ecg->take_beats().samples.size();
  }
  // The last minute: the rate is still the option's and each beat still sits on its R wave.
  const std::vector<std::int64_t> final_beats = ecg->take_beats().samples;
  beats += final_beats.size();
  EXPECT_EQ(ecg->samples_generated(), 3600 * 50);
  EXPECT_NEAR(static_cast<double>(beats), 70 * 60, 0.02 * 70 * 60);
  const std::int64_t offset = ecg->samples_generated() - static_cast<std::int64_t>(last.size());
  for (std::int64_t beat : final_beats) {
    const std::int64_t at = beat - offset;
    if (at < 5 || at + 5 >= static_cast<std::int64_t>(last.size())) continue;
    const auto peak = std::max_element(last.begin() + (at - 5), last.begin() + (at + 6));
    EXPECT_LE(std::abs(peak - last.begin() - at), 1) << "beat at " << beat;
  }
}

TEST(Ecgsyn, InvalidOptionsAreRejectedWithAnErrorNamingTheOption) {
  const std::vector<std::pair<std::string, std::function<void(SyntheticEcgOptions&)>>> cases = {
      {"fs", [](auto& o) { o.fs = 0; }},
      {"fs", [](auto& o) { o.fs = std::nan(""); }},
      {"mean_hr_bpm", [](auto& o) { o.mean_hr_bpm = -70; }},
      {"mean_hr_bpm", [](auto& o) { o.mean_hr_bpm = 400; }},
      {"hr_std_bpm", [](auto& o) { o.hr_std_bpm = -1; }},
      {"hr_std_bpm", [](auto& o) { o.hr_std_bpm = 30; }},
      {"lf_hf_ratio", [](auto& o) { o.lf_hf_ratio = -0.5; }},
      {"lf_hz", [](auto& o) { o.lf_hz = 0.3; }},
      {"lf_hz", [](auto& o) { o.lf_hz = 0.25; }},
      {"hf_hz", [](auto& o) { o.hf_hz = 2; }},
      {"noise_mv", [](auto& o) { o.noise_mv = -0.01; }},
      {"baseline_wander_mv", [](auto& o) { o.baseline_wander_mv = INFINITY; }},
      {"ectopic_rate", [](auto& o) { o.ectopic_rate = 0.8; }},
      {"gain", [](auto& o) { o.gain = 0; }},
  };
  for (const auto& [name, spoil] : cases) {
    SyntheticEcgOptions o;
    spoil(o);
    auto ecg = SyntheticEcg::create(o);
    ASSERT_FALSE(ecg.has_value()) << name;
    EXPECT_NE(ecg.error().message.find(name), std::string::npos) << ecg.error().message;
    auto samples = synthetic_ecg(1, o);
    ASSERT_FALSE(samples.has_value()) << name;
    EXPECT_NE(samples.error().message.find(name), std::string::npos);
  }
  auto negative = synthetic_ecg(-1, {});
  ASSERT_FALSE(negative.has_value());
  EXPECT_NE(negative.error().message.find("seconds"), std::string::npos);
  EXPECT_TRUE(validate(SyntheticEcgOptions{}).has_value());
}

}  // namespace
}  // namespace tahvel::aggregation
