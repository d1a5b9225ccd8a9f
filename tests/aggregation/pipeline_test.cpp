// The chain as one function (pipeline.h): what it refuses, and what it warns of, on synthetic
// ECG (ecgsyn.h) whose true beats are known.
#include <gtest/gtest.h>

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>

#include "tahvel/aggregation/ecgsyn.h"
#include "tahvel/aggregation/pipeline.h"

namespace tahvel::aggregation {
namespace {

struct SyntheticRun {
  std::vector<std::int32_t> samples;
  std::vector<Interval> truth;  // the true beats' intervals, all NN
};

SyntheticRun synthetic(double seconds, double bpm, double hr_std_bpm) {
  SyntheticEcgOptions o;
  o.mean_hr_bpm = bpm;
  o.hr_std_bpm = hr_std_bpm;
  o.seed = 7;
  auto ecg = SyntheticEcg::create(o);
  EXPECT_TRUE(ecg) << ecg.error().message;
  SyntheticRun run;
  ecg->generate(static_cast<std::size_t>(seconds * o.fs), run.samples);
  const auto beats = ecg->take_beats().samples;
  for (std::size_t i = 1; i < beats.size(); ++i) run.truth.push_back({beats[i - 1], beats[i], true});
  return run;
}

// A regular bradycardia of 30 bpm (RR 2 s, ECGSYN's slowest) is a rhythm: its intervals are NN
// and its SDNN is the true beats'. With gaps from 2 s on, half of its intervals were gaps and
// its SDNN 6.1 ms against 35.1; at 28 bpm none was NN (a probe's WFDB records).
TEST(HrvChain, ABradycardiaOf30BpmKeepsItsIntervalsAsNn) {
  const SyntheticRun run = synthetic(600, 30, 0.5);
  auto report = hrv_from_samples(run.samples, 360, 200);
  ASSERT_TRUE(report) << report.error().message;
  const HrvMetrics truth = compute_hrv(run.truth, 360);
  ASSERT_GT(report->metrics.rr_count, 250u);
  EXPECT_GE(static_cast<double>(report->metrics.nn_count), 0.95 * static_cast<double>(report->metrics.rr_count))
      << report->metrics.nn_count << " NN of " << report->metrics.rr_count;
  ASSERT_TRUE(report->metrics.sdnn_ms);
  EXPECT_NEAR(*report->metrics.sdnn_ms, *truth.sdnn_ms, 0.05 * *truth.sdnn_ms);
  EXPECT_FALSE(irregular_rhythm_warning(report->metrics, gap_count(report->intervals, 360)));
}

// A small beat the detector misses at a fast rate leaves an interval of twice the rhythm's, which
// its gap's evidence confirmed as a pause: it was kept as NN (a researcher's probe, 2 % of
// beats at 12-20 % of the QRS height: SDNN x3-4 at 150-200 bpm, with no warning). Those
// intervals are rejected, and SDNN and RMSSD are the true beats'.
TEST(HrvChain, SmallMissedBeatsAtFastRatesAreNotKeptAsPauses) {
  for (double bpm : {150.0, 165.0, 180.0}) {  // ECGSYN's fastest is 180
    SyntheticRun run = synthetic(300, bpm, 3);
    std::vector<Interval> truth;  // the intervals of beats not shrunk, all NN
    std::vector<bool> shrunk(run.truth.size() + 1, false);
    for (std::size_t k = 25; k < shrunk.size(); k += 50) shrunk[k] = true;
    const auto beat = [&](std::size_t k) { return k == 0 ? run.truth[0].start : run.truth[k - 1].end; };
    for (std::size_t k = 0; k < shrunk.size(); ++k) {
      if (!shrunk[k]) continue;
      for (std::int64_t i = std::max<std::int64_t>(0, beat(k) - 18); i < beat(k) + 18 && i < static_cast<std::int64_t>(run.samples.size()); ++i) {
        auto& x = run.samples[static_cast<std::size_t>(i)];
        x = 1024 + static_cast<std::int32_t>(std::lround((x - 1024) * 0.12));  // ECGSYN's zero
      }
    }
    for (std::size_t k = 1; k < shrunk.size(); ++k)
      if (!shrunk[k - 1] && !shrunk[k]) truth.push_back(run.truth[k - 1]);
    auto report = hrv_from_samples(run.samples, 360, 200);
    ASSERT_TRUE(report) << report.error().message;
    const HrvMetrics want = compute_hrv(truth, 360);
    ASSERT_TRUE(report->metrics.sdnn_ms && report->metrics.rmssd_ms && want.sdnn_ms && want.rmssd_ms);
    EXPECT_NEAR(*report->metrics.sdnn_ms, *want.sdnn_ms, 0.1 * *want.sdnn_ms) << bpm << " bpm";
    EXPECT_NEAR(*report->metrics.rmssd_ms, *want.rmssd_ms, 0.15 * *want.rmssd_ms) << bpm << " bpm";
  }
}

// Sinus arrests of 4 and 6 s, beats left out with the baseline and its noise going on. RR alone
// cannot tell them from a lead off that leaves a quiet line (kept as NN, such a lead-off took
// SDNN from 35.5 ms to 246): they are gaps, not NN, and said, with the SDNN they would give as
// NN, which is the true one. Dropped without a word, pauses of 3.6 s every 80 beats took SDNN
// from 285 ms to 20 (a researcher's probe).
TEST(HrvChain, SinusArrestsLongerThanTheGapBoundAreGapsAndSaidWithTheSdnnTheyWouldGive) {
  SyntheticRun run = synthetic(600, 60, 2);
  std::vector<std::int64_t> beats = {run.truth[0].start};
  for (const Interval& i : run.truth) beats.push_back(i.end);
  std::vector<bool> left_out(beats.size(), false);
  std::uint32_t noise = 1;
  for (std::size_t k = 100; k + 6 < beats.size(); k += 200) {
    const std::size_t missing = k % 400 == 100 ? 3 : 5;  // pauses of about 4 and 6 s
    // From after the T wave of the beat before to before the P wave of the beat after: the
    // baseline, drawn straight, with a few ADC steps of noise (not a flat line).
    const std::int64_t from = beats[k - 1] + 200, to = beats[k + missing] - 120;
    const double a = run.samples[static_cast<std::size_t>(from)], b = run.samples[static_cast<std::size_t>(to)];
    for (std::int64_t i = from; i < to; ++i) {
      noise = noise * 1664525u + 1013904223u;
      run.samples[static_cast<std::size_t>(i)] = static_cast<std::int32_t>(
          std::lround(a + (b - a) * static_cast<double>(i - from) / static_cast<double>(to - from))) + static_cast<std::int32_t>(noise >> 30) - 2;
    }
    for (std::size_t j = k; j < k + missing; ++j) left_out[j] = true;
  }
  std::vector<Interval> truth;
  for (std::size_t k = 0, last = 0; ++k < beats.size();)
    if (!left_out[k]) {
      truth.push_back({beats[last], beats[k], true});
      last = k;
    }
  auto report = hrv_from_samples(run.samples, 360, 200);
  ASSERT_TRUE(report) << report.error().message;
  const HrvMetrics want = compute_hrv(truth, 360);
  EXPECT_EQ(report->metrics.nn_count + 3, want.nn_count);
  EXPECT_EQ(gap_count(report->intervals, 360), 3u);
  EXPECT_EQ(report->metrics.gap_count, 3u);  // what a window on the board says (tv:gapCount)
  const std::optional<std::string> said = long_gaps_warning(report->intervals, 360);
  ASSERT_TRUE(said);
  EXPECT_EQ(said->rfind("3 interval(s) longer than 3.5 s are not NN (the longest 6.", 0), 0u) << *said;
  const std::size_t with = said->find("with them as NN ");
  ASSERT_NE(with, std::string::npos) << *said;
  ASSERT_TRUE(want.sdnn_ms);
  EXPECT_NEAR(std::stod(said->substr(with + 16)), *want.sdnn_ms, 0.02 * *want.sdnn_ms) << *said;
  EXPECT_FALSE(long_gaps_warning(truth, 360));  // no gap, nothing said
}

// Intervals rejected for their length alone (a rhythm slower than the bound, pauses, signal
// lost) are not ectopy: the warning names them, and the irregular rhythm keeps its own.
TEST(IrregularRhythmWarning, NamesLongIntervalsAsPausesOrBradycardiaNotEctopicBeats) {
  HrvMetrics slow;  // 15 bpm, regular: every interval a gap
  slow.rr_count = 40;
  slow.nn_count = 0;
  slow.irregular_pct = 0;
  auto said = irregular_rhythm_warning(slow, 40, 3.5);
  ASSERT_TRUE(said);
  EXPECT_NE(said->find("40 of 40 intervals (100 %) are longer than 3.5 s"), std::string::npos) << *said;
  EXPECT_NE(said->find("a heart rate below 17 bpm"), std::string::npos) << *said;
  EXPECT_EQ(said->find("ectopic"), std::string::npos) << *said;
  EXPECT_EQ(said->find("fibrillation"), std::string::npos) << *said;
  // Rejected for other reasons (no gaps): the irregular-rhythm warning, as before.
  HrvMetrics af;
  af.rr_count = 100;
  af.nn_count = 50;
  af.irregular_pct = 40;
  said = irregular_rhythm_warning(af, 3, 3.5);
  ASSERT_TRUE(said);
  EXPECT_NE(said->find("atrial fibrillation"), std::string::npos) << *said;
  EXPECT_NE(said->find("3 of the intervals not NN are longer than 3.5 s"), std::string::npos) << *said;
  // A few gaps among many rejected intervals in a regular rhythm are not the cause.
  HrvMetrics ectopy = af;
  ectopy.irregular_pct = 10;
  said = irregular_rhythm_warning(ectopy, 5, 3.5);
  ASSERT_TRUE(said);
  EXPECT_NE(said->find("ectopic"), std::string::npos) << *said;
}

// A 50 Hz sine (mains hum on an unplugged lead) was read as a rhythm of 299 bpm, its HRV printed
// without a word: the detector fired at every hold it allows. Said; a fast real rhythm is not.
TEST(DetectorRateWarning, BeatsAtTheDetectorsHoldAreSaidToBeNoHeartsRhythm) {
  constexpr double fs = 360;
  std::vector<std::int32_t> hum(static_cast<std::size_t>(120 * fs));
  for (std::size_t i = 0; i < hum.size(); ++i)
    hum[i] = static_cast<std::int32_t>(std::lround(200 * std::sin(2 * M_PI * 50 * static_cast<double>(i) / fs)));
  auto report = hrv_from_samples(hum, fs, 200);
  ASSERT_TRUE(report) << report.error().message;
  const double hold_ms = DetectorOptions{}.hold_ms;
  auto said = detector_rate_warning(report->intervals, fs, hold_ms);
  ASSERT_TRUE(said) << report->intervals.size() << " intervals";
  EXPECT_NE(said->find("are as short as the detector allows (200 ms, its hold between two beats)"), std::string::npos) << *said;
  EXPECT_NE(said->find("mains hum"), std::string::npos) << *said;
  // A tachycardia of 180 bpm (333 ms) and the ECGSYN rhythm are rhythms.
  std::vector<Interval> fast;
  for (std::int64_t i = 0; i < 100; ++i) fast.push_back({i * 120, (i + 1) * 120, true});
  EXPECT_FALSE(detector_rate_warning(fast, fs, hold_ms));
  const SyntheticRun run = synthetic(120, 70, 3);
  auto ecg = hrv_from_samples(run.samples, 360, 200);
  ASSERT_TRUE(ecg) << ecg.error().message;
  EXPECT_FALSE(detector_rate_warning(ecg->intervals, 360, hold_ms));
  // At the hold itself, 72 samples: said.
  std::vector<Interval> pinned;
  for (std::int64_t i = 0; i < 100; ++i) pinned.push_back({i * 72, (i + 1) * 72, true});
  EXPECT_TRUE(detector_rate_warning(pinned, fs, hold_ms));
}

// A spike once a second (a test signal, a periodic artefact) gave 119 "beats", SDNN 0 and no
// word: a rhythm held to the sample, which a heart rarely keeps. Said; the ECGSYN rhythm, and
// too few intervals to tell, are not.
TEST(FixedRateWarning, IntervalsAllOneLengthToTheSampleAreSaidToBeNoHeartsRhythm) {
  constexpr double fs = 360;
  std::vector<std::int32_t> spikes(static_cast<std::size_t>(120 * fs), 0);
  for (std::size_t i = 180; i < spikes.size(); i += 360) spikes[i] = 2000;
  auto report = hrv_from_samples(spikes, fs, 200);
  ASSERT_TRUE(report) << report.error().message;
  auto said = fixed_rate_warning(report->intervals, fs);
  ASSERT_TRUE(said) << report->intervals.size() << " intervals";
  EXPECT_NE(said->find("NN intervals are 1000 ms to within one sample (2.78 ms)"), std::string::npos) << *said;
  EXPECT_NE(said->find("Its HRV would say nothing of the heart"), std::string::npos) << *said;
  // One sample either way is within it; two are not.
  auto series = [](std::int64_t odd_length) {  // 300 samples, every other one `odd_length`
    std::vector<Interval> out;
    for (std::int64_t i = 0, at = 0; i < 80; ++i) {
      const std::int64_t length = i % 2 ? odd_length : 300;
      out.push_back({at, at + length, true});
      at += length;
    }
    return out;
  };
  EXPECT_TRUE(fixed_rate_warning(series(301), fs));
  EXPECT_FALSE(fixed_rate_warning(series(302), fs));
  // At 128 Hz a sample is 7.8 ms, more than a calm heart varies: only one length exactly.
  EXPECT_FALSE(fixed_rate_warning(series(301), 128));
  EXPECT_TRUE(fixed_rate_warning(series(300), 128));
  std::vector<Interval> few;
  for (std::int64_t i = 0; i + 1 < static_cast<std::int64_t>(kFixedRateMinIntervals); ++i) few.push_back({i * 300, (i + 1) * 300, true});
  EXPECT_FALSE(fixed_rate_warning(few, fs));
  const SyntheticRun run = synthetic(120, 70, 3);
  auto ecg = hrv_from_samples(run.samples, 360, 200);
  ASSERT_TRUE(ecg) << ecg.error().message;
  EXPECT_FALSE(fixed_rate_warning(ecg->intervals, 360));
}

// A 50 Hz sine at 250 Hz locked the detector to every 12th cycle: 250 bpm, as regular as no heart
// (SDNN 3 ms), with intervals longer than the hold, so that nothing was said. The share of the
// signal's power at the mains frequency tells; an ECG with a little hum on it is not said.
TEST(MainsHumWarning, ASignalThatIsMostlyMainsHumIsSaidAndAnEcgWithSomeHumIsNot) {
  auto sine = [](double fs, double hz, double amplitude, std::size_t seconds) {
    std::vector<std::int32_t> out(static_cast<std::size_t>(static_cast<double>(seconds) * fs));
    for (std::size_t i = 0; i < out.size(); ++i)
      out[i] = static_cast<std::int32_t>(std::lround(amplitude * std::sin(2 * M_PI * hz * static_cast<double>(i) / fs)));
    return out;
  };
  SignalInfo lead;
  lead.description = "MLII";
  for (const auto& [fs, hz] : {std::pair{250.0, 50.0}, {360.0, 49.8}, {500.0, 60.0}, {128.0, 60.2}}) {
    const MainsShare hum = mains_share(sine(fs, hz, 200, 60), fs);
    EXPECT_GT(hum.percent, 95) << fs << " Hz, " << hz << " Hz hum";
    EXPECT_EQ(hum.hz, std::round(hz / 10) * 10) << fs << " Hz, " << hz << " Hz hum";
    auto said = mains_hum_warning(sine(fs, hz, 200, 60), lead, 0, fs);
    ASSERT_TRUE(said) << fs << " Hz";
    EXPECT_NE(said->find("of signal 0's power (MLII) is mains hum at"), std::string::npos) << *said;
  }
  // A synthetic ECG (200 units per mV at 360 Hz), alone and under a hum of 0.1 mV.
  const SyntheticRun run = synthetic(60, 70, 3);
  EXPECT_LT(mains_share(run.samples, 360).percent, 1);
  EXPECT_FALSE(mains_hum_warning(run.samples, lead, 0, 360));
  std::vector<std::int32_t> humming = run.samples;
  const std::vector<std::int32_t> hum = sine(360, 50, 20, 60);
  for (std::size_t i = 0; i < humming.size() && i < hum.size(); ++i) humming[i] += hum[i];
  const double share = mains_share(humming, 360).percent;
  EXPECT_GT(share, 1);
  EXPECT_LT(share, kMainsHumPct);
  EXPECT_FALSE(mains_hum_warning(humming, lead, 0, 360));
  // Below 122 Hz, 61 Hz is past half the rate: not measured. Shorter than a second: neither.
  EXPECT_EQ(mains_share(sine(100, 50, 200, 60), 100).percent, 0);
  EXPECT_EQ(mains_share(std::vector<std::int32_t>(359, 5), 360).percent, 0);
}

// A whole record shorter than the shortest window had the SDNN and RMSSD of its 5 intervals
// printed without a word, where a window that short is refused: said; 10 s is not.
TEST(HrvFromRecord, ARecordShorterThanTheShortestWindowIsSaidToSayLittle) {
  char pattern[] = "/tmp/tahvel-pipeline-XXXXXX";
  ASSERT_NE(mkdtemp(pattern), nullptr);
  const std::filesystem::path dir = pattern;
  auto write_record = [&](const std::string& name, double seconds) {
    const SyntheticRun run = synthetic(seconds, 70, 3);
    std::ofstream(dir / (name + ".hea")) << name << " 1 360 " << run.samples.size() << "\n"
                                         << name << ".dat 16 200 16 0 0 0 0 MLII\n";
    std::ofstream dat(dir / (name + ".dat"), std::ios::binary);
    for (std::int32_t v : run.samples) {
      const auto u = static_cast<std::uint16_t>(static_cast<std::int16_t>(v));
      dat.put(static_cast<char>(u & 0xff)).put(static_cast<char>(u >> 8));
    }
    return (dir / name).string();
  };
  auto said_short = [](const HrvReport& r) {
    return std::any_of(r.warnings.begin(), r.warnings.end(),
                       [](const std::string& w) { return w.find("says little") != std::string::npos; });
  };
  auto five = hrv_from_record(write_record("five", 5));
  ASSERT_TRUE(five) << five.error().message;
  ASSERT_GE(five->intervals.size(), 3u);
  EXPECT_TRUE(said_short(*five));
  EXPECT_NE(five->warnings.back().find("the record is 5 s long"), std::string::npos) << five->warnings.back();
  auto ten = hrv_from_record(write_record("ten", 10));
  ASSERT_TRUE(ten) << ten.error().message;
  EXPECT_FALSE(said_short(*ten));
  std::filesystem::remove_all(dir);
}

// A record of several signals: the chain reads the ECG lead alone (read whole, a 12-lead
// record took twelve times the memory of the lead it reads), still checks every signal's
// checksum, and says a file shorter than its header.
TEST(HrvFromRecord, ReadsTheEcgOfSeveralSignalsAndChecksEverySignalsSum) {
  char pattern[] = "/tmp/tahvel-pipeline-XXXXXX";
  ASSERT_NE(mkdtemp(pattern), nullptr);
  const std::filesystem::path dir = pattern;
  const SyntheticRun run = synthetic(60, 70, 3);
  const std::size_t n = run.samples.size();
  // Respiration first, then the ECG, then a signal whose checksum is wrong in the header.
  const auto other = [&](std::size_t signal, std::size_t i) {
    return static_cast<std::int32_t>((i * (signal + 3)) % 500) - 250;
  };
  std::uint16_t sums[3] = {0, 0, 0};
  std::ofstream dat(dir / "three.dat", std::ios::binary);
  for (std::size_t i = 0; i < n; ++i) {
    for (std::size_t signal = 0; signal < 3; ++signal) {
      const std::int32_t v = signal == 1 ? run.samples[i] : other(signal, i);
      sums[signal] = static_cast<std::uint16_t>(sums[signal] + static_cast<std::uint16_t>(v));
      const auto u = static_cast<std::uint16_t>(static_cast<std::int16_t>(v));
      dat.put(static_cast<char>(u & 0xff)).put(static_cast<char>(u >> 8));
    }
  }
  dat.close();
  const auto sum_text = [](std::uint16_t sum) { return std::to_string(static_cast<std::int16_t>(sum)); };
  std::ofstream(dir / "three.hea") << "three 3 360 " << n << "\n"
                                   << "three.dat 16 200 16 0 0 " << sum_text(sums[0]) << " 0 Resp\n"
                                   << "three.dat 16 200 16 0 0 " << sum_text(sums[1]) << " 0 MLII\n"
                                   << "three.dat 16 200 16 0 0 " << sum_text(static_cast<std::uint16_t>(sums[2] + 1)) << " 0 ABP\n";
  const std::string record = (dir / "three").string();
  auto report = hrv_from_record(record);
  ASSERT_TRUE(report) << report.error().message;
  EXPECT_EQ(report->signal, 1u);
  auto alone = hrv_from_samples(run.samples, 360, 200, {});
  ASSERT_TRUE(alone) << alone.error().message;
  EXPECT_EQ(report->beats, alone->beats);
  const auto said = [&](const std::string& text) {
    return std::any_of(report->warnings.begin(), report->warnings.end(),
                       [&](const std::string& w) { return w.find(text) != std::string::npos; });
  };
  EXPECT_TRUE(said("three.hea: signal 2 (ABP): its samples add up to")) << ::testing::PrintToString(report->warnings);
  EXPECT_FALSE(said("signal 1 (MLII)"));
  EXPECT_FALSE(said("signal 0 (Resp)"));
  // A file cut short is refused, naming it.
  std::filesystem::resize_file(dir / "three.dat", n * 6 - 600);
  auto cut = hrv_from_record(record);
  ASSERT_FALSE(cut);
  EXPECT_NE(cut.error().message.find("truncated"), std::string::npos) << cut.error().message;
  EXPECT_NE(cut.error().message.find("three.dat"), std::string::npos) << cut.error().message;
  std::filesystem::remove_all(dir);
}

// A window or step too short for HRV is refused, naming the setting and its bounds; a window
// of 0.0001 s made 18 million windows of MIT-BIH 100 (std::bad_alloc).
TEST(HrvChain, RefusesAWindowShorterThan10sOrAStepShorterThan1s) {
  const SyntheticRun run = synthetic(30, 70, 3);
  for (const double window : {0.0001, 5.0, 1e6}) {
    ChainOptions o;
    o.window_s = window;
    auto report = hrv_from_samples(run.samples, 360, 200, o);
    ASSERT_FALSE(report) << "window " << window;
    EXPECT_NE(report.error().message.find("window: must be a number of seconds in [10, 86400]"), std::string::npos)
        << report.error().message;
  }
  ChainOptions o;
  o.window_s = 10;
  o.step_s = 0.5;
  auto report = hrv_from_samples(run.samples, 360, 200, o);
  ASSERT_FALSE(report);
  EXPECT_NE(report.error().message.find("step: must be a number of seconds in [1, 86400]"), std::string::npos)
      << report.error().message;
  o.step_s = 1;
  EXPECT_TRUE(hrv_from_samples(run.samples, 360, 200, o));
  EXPECT_FALSE(window_setting_problem(10, false));
  EXPECT_FALSE(window_setting_problem(1, true));
  EXPECT_TRUE(window_setting_problem(std::nan(""), false));
}

// A day's window stepped by a second was taken: 86,400 windows over each moment, each computed
// whole (about a second of CPU for a day of beats), a second of CPU per second of signal. Refused
// above kMaxWindowsPerMoment, naming the least step for that window.
TEST(HrvChain, RefusesAStepThatLaysMoreThan3600WindowsOverAMoment) {
  const SyntheticRun run = synthetic(30, 70, 3);
  ChainOptions o;
  o.window_s = 86400;
  o.step_s = 1;
  auto report = hrv_from_samples(run.samples, 360, 200, o);
  ASSERT_FALSE(report);
  EXPECT_NE(report.error().message.find("step: a window of 86400 s stepped by 1 s lays 86400 windows over each moment of "
                                        "signal, at most 3600 (each is computed whole): a step of at least 24 s for this window"),
            std::string::npos)
      << report.error().message;
  o.step_s = 24;
  EXPECT_TRUE(hrv_from_samples(run.samples, 360, 200, o));
  EXPECT_FALSE(window_step_problem(3600, 1));
  EXPECT_TRUE(window_step_problem(3601, 1));
  EXPECT_FALSE(window_step_problem(300, 0));  // no step: the window's own
}

}  // namespace
}  // namespace tahvel::aggregation
