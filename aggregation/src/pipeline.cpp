// The HRV chain; see pipeline.h.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <numbers>

#include "tahvel/aggregation/pipeline.h"

#include "tahvel/aggregation/annotations.h"
#include "tahvel/aggregation/wfdb.h"

namespace tahvel::aggregation {

Result<HrvReport> hrv_from_samples(const std::vector<std::int32_t>& samples, double fs,
                                   double gain, const ChainOptions& options) {
  if (auto problem = window_setting_problem(options.window_s, false)) return fail("window: " + *problem);
  if (options.step_s < 0) return fail("step: must not be negative");
  if (options.step_s > 0)
    if (auto problem = window_setting_problem(options.step_s, true)) return fail("step: " + *problem);
  if (auto problem = window_step_problem(options.window_s, options.step_s)) return fail("step: " + *problem);
  DetectorOptions detector = options.detector;
  detector.fs = fs;
  detector.gain = gain;
  if (auto valid = validate(detector); !valid) return unexpected(valid.error());
  HrvReport report;
  report.fs = fs;
  report.duration_s = static_cast<double>(samples.size()) / fs;
  Detection detection = detect_beats(samples, detector);
  report.beats = std::move(detection.peaks);
  report.intervals = intervals_from_peaks(report.beats, detection.empty_gap_ends,
                                          detection.p_wave_gap_ends, fs, options.nn);
  // A gap is what the NN rule takes for one: irregular_pct and the gaps warning agree.
  HrvOptions hrv = options.hrv;
  hrv.gap_s = options.nn.max_interval_s;
  report.metrics = compute_hrv(report.intervals, fs, hrv);
  const double step = options.step_s > 0 ? options.step_s : options.window_s;
  report.windows = windowed_hrv(report.intervals, fs, options.window_s, step, hrv, report.duration_s);
  return report;
}

std::size_t gap_count(const std::vector<Interval>& intervals, double fs, const NnRule& rule) {
  const double limit = rule.max_interval_s * fs;
  return static_cast<std::size_t>(std::count_if(intervals.begin(), intervals.end(), [&](const Interval& i) {
    return !i.nn && static_cast<double>(i.end - i.start) > limit;
  }));
}

std::optional<std::string> long_gaps_warning(const std::vector<Interval>& intervals, double fs, const NnRule& rule,
                                             const HrvOptions& hrv) {
  const std::size_t gaps = gap_count(intervals, fs, rule);
  if (gaps == 0 || !(fs > 0)) return std::nullopt;
  const double limit = rule.max_interval_s * fs;
  std::vector<Interval> with_them = intervals;
  const Interval* longest = nullptr;
  for (Interval& i : with_them)
    if (!i.nn && static_cast<double>(i.end - i.start) > limit) {
      i.nn = true;
      if (!longest || i.end - i.start > longest->end - longest->start) longest = &i;
    }
  const auto sdnn = [&](const std::vector<Interval>& series) {
    char text[32];
    if (const std::optional<double> v = compute_hrv(series, fs, hrv).sdnn_ms) std::snprintf(text, sizeof text, "%.1f ms", *v);
    else std::snprintf(text, sizeof text, "none");
    return std::string(text);
  };
  char text[700];
  std::snprintf(text, sizeof text,
                "%zu interval(s) longer than %g s are not NN (the longest %.1f s, from %.1f s into the signal): pauses "
                "of the heart (sinus arrest, AV block) or signal lost (a lead off, also one that leaves a quiet line), "
                "which RR alone cannot tell apart; HRV leaves them out: SDNN %s, and with them as NN %s "
                "(docs/hrv.md, \"Gaps\")",
                gaps, rule.max_interval_s, static_cast<double>(longest->end - longest->start) / fs,
                static_cast<double>(longest->start) / fs, sdnn(intervals).c_str(), sdnn(with_them).c_str());
  return std::string(text);
}

std::optional<std::string> irregular_rhythm_warning(const HrvMetrics& m, std::size_t gaps, double max_interval_s) {
  const auto pct = [&](std::size_t n) {
    return m.rr_count > 0 ? 100.0 * static_cast<double>(n) / static_cast<double>(m.rr_count) : 0;
  };
  const std::size_t rejected = m.rr_count - std::min(m.nn_count, m.rr_count);
  const double not_nn = pct(rejected);
  const double irregular = m.irregular_pct.value_or(0);
  if (irregular <= kIrregularPct && not_nn <= kIrregularPct) return std::nullopt;
  gaps = std::min(gaps, rejected);
  char text[600];
  // Intervals rejected for their length alone are no sign of ectopy: a rhythm slower than
  // 60 / max_interval_s bpm, pauses, or signal lost between two beats. Said as such when they
  // are most of what was rejected and the rhythm is otherwise regular.
  if (irregular <= kIrregularPct && 2 * gaps >= rejected) {
    std::snprintf(text, sizeof text,
                  "%zu of %zu intervals (%.0f %%) are longer than %g s and are not NN: pauses, signal lost between two "
                  "beats (a lead off, missed beats), or a heart rate below %.0f bpm; %.0f %% of intervals are not NN in "
                  "all, and HRV covers only the rest (docs/hrv.md, \"Gaps\")",
                  gaps, m.rr_count, pct(gaps), max_interval_s, 60 / max_interval_s, not_nn);
    return std::string(text);
  }
  std::snprintf(text, sizeof text,
                "an irregular rhythm (%.0f %% of successive intervals differ by more than 20 %%; %.0f %% of intervals are "
                "not NN): frequent ectopic beats, atrial fibrillation, beats the detector missed on a poor lead, or "
                "noise it took for beats, "
                "which the RR-only NN rule cannot tell apart; "
                "HRV of this record may be several times off (docs/hrv.md, \"Where the rule fails\")",
                irregular, not_nn);
  std::string out = text;
  if (gaps > 0) {
    std::snprintf(text, sizeof text, "; %zu of the intervals not NN are longer than %g s (pauses or lost signal)", gaps,
                  max_interval_s);
    out += text;
  }
  return out;
}

std::optional<std::string> fixed_rate_warning(const std::vector<Interval>& intervals, double fs) {
  if (!(fs > 0)) return std::nullopt;
  std::size_t nn = 0;
  std::int64_t shortest = 0, longest = 0;
  for (const Interval& i : intervals) {
    if (!i.nn || i.end <= i.start) continue;
    const std::int64_t length = i.end - i.start;
    shortest = nn == 0 ? length : std::min(shortest, length);
    longest = nn == 0 ? length : std::max(longest, length);
    ++nn;
  }
  // A sample of 8 ms (128 Hz) is wider than a calm heart's beat-to-beat changes: only intervals
  // of exactly one length are said there.
  const std::int64_t within = 1000 / fs <= kFixedRateSampleMs ? 1 : 0;
  if (nn < kFixedRateMinIntervals || longest - shortest > within) return std::nullopt;
  char text[400];
  std::snprintf(text, sizeof text,
                "all %zu NN intervals are %.0f ms to within %s (%.3g ms): a rhythm as fixed as a heart's rarely is; "
                "a fixed-rate pacemaker, a simulator or test signal, or a periodic artefact (a spike at a fixed rate)? "
                "Its HRV would say nothing of the heart",
                nn, static_cast<double>(shortest) * 1000 / fs, within ? "one sample" : "the sample", 1000 / fs);
  return std::string(text);
}

std::optional<std::string> detector_rate_warning(const std::vector<Interval>& intervals, double fs, double hold_ms) {
  if (intervals.size() < 10 || !(fs > 0)) return std::nullopt;
  const double fastest_ms = hold_ms + std::max(5.0, 1000 / fs);
  std::size_t at_hold = 0;
  double total_ms = 0;
  for (const Interval& i : intervals) {
    const double ms = static_cast<double>(i.end - i.start) * 1000 / fs;
    total_ms += ms;
    if (ms <= fastest_ms) ++at_hold;
  }
  const double share = 100.0 * static_cast<double>(at_hold) / static_cast<double>(intervals.size());
  if (share < kAtTheHoldPct) return std::nullopt;
  char text[480];
  std::snprintf(text, sizeof text,
                "%zu of %zu intervals (%.0f %%) are as short as the detector allows (%g ms, its hold between two beats), "
                "%.0f bpm on average: beats found as fast as it can find them, which no heart's rhythm is; a periodic "
                "signal faster than a heart (mains hum at 50 or 60 Hz, a test tone) or noise, not an ECG; its HRV means "
                "nothing",
                at_hold, intervals.size(), share, hold_ms, 60'000 / (total_ms / static_cast<double>(intervals.size())));
  return std::string(text);
}

MainsShare mains_share(const std::vector<std::int32_t>& samples, double fs) {
  const auto block = static_cast<std::size_t>(std::llround(fs));
  if (!(fs >= 122) || block == 0 || samples.size() < block) return {};
  double total = 0;  // sum over blocks of N * sum (x - mean)^2, which the DFT's bins add up to
  std::vector<double> x(block);
  auto bins_near = [&](double hz) {
    std::vector<std::size_t> bins;
    for (double f : {hz - 1, hz, hz + 1}) {
      const auto k = static_cast<std::size_t>(std::llround(f * static_cast<double>(block) / fs));
      if (k > 0 && 2 * k < block && std::find(bins.begin(), bins.end(), k) == bins.end()) bins.push_back(k);
    }
    return bins;
  };
  const std::vector<std::size_t> bins50 = bins_near(50), bins60 = bins_near(60);
  double power50 = 0, power60 = 0;
  auto goertzel = [&](std::size_t k) {  // |X_k|^2
    const double w = 2 * std::numbers::pi * static_cast<double>(k) / static_cast<double>(block);
    const double coeff = 2 * std::cos(w);
    double s1 = 0, s2 = 0;
    for (double v : x) {
      const double s0 = v + coeff * s1 - s2;
      s2 = s1;
      s1 = s0;
    }
    return s1 * s1 + s2 * s2 - coeff * s1 * s2;
  };
  for (std::size_t start = 0; start + block <= samples.size(); start += block) {
    double mean = 0;
    for (std::size_t i = 0; i < block; ++i) mean += samples[start + i];
    mean /= static_cast<double>(block);
    double squares = 0;
    for (std::size_t i = 0; i < block; ++i) {
      x[i] = samples[start + i] - mean;
      squares += x[i] * x[i];
    }
    total += static_cast<double>(block) * squares;
    for (std::size_t k : bins50) power50 += 2 * goertzel(k);  // a bin and its mirror
    for (std::size_t k : bins60) power60 += 2 * goertzel(k);
  }
  if (!(total > 0)) return {};
  const bool fifty = power50 >= power60;
  return {100 * std::min(1.0, (fifty ? power50 : power60) / total), fifty ? 50.0 : 60.0};
}

std::optional<std::string> mains_hum_warning(const std::vector<std::int32_t>& samples, const SignalInfo& info,
                                             std::size_t channel, double fs) {
  const MainsShare hum = mains_share(samples, fs);
  if (hum.percent < kMainsHumPct) return std::nullopt;
  char text[400];
  std::snprintf(text, sizeof text,
                "%.0f %% of signal %zu's power (%s) is mains hum at %g Hz: a lead off or unplugged picks up the mains, "
                "and the beats found may be the hum's, as regular as no heart; its HRV may mean nothing",
                hum.percent, channel, info.description.c_str(), hum.hz);
  return std::string(text);
}

std::optional<std::string> invalid_samples_warning(const std::vector<std::int32_t>& samples, const SignalInfo& info,
                                                   std::size_t channel, double fs) {
  const std::int32_t invalid = invalid_sample(info);
  const auto count = static_cast<std::size_t>(std::count(samples.begin(), samples.end(), invalid));
  if (count == 0) return std::nullopt;
  const auto first = static_cast<std::size_t>(std::find(samples.begin(), samples.end(), invalid) - samples.begin());
  char text[320];
  std::snprintf(text, sizeof text,
                "%zu sample(s) of signal %zu (%s) hold WFDB's no-value %d, the first at %.3f s: read as no signal "
                "(the last valid sample held, as over a lead off), not as a step to the least value",
                count, channel, info.description.c_str(), invalid, static_cast<double>(first) / fs);
  return std::string(text);
}

std::optional<std::string> flat_runs_warning(const std::vector<std::int32_t>& samples, const SignalInfo& info,
                                             std::size_t channel, double fs, double at_least_s) {
  if (!(fs > 0) || samples.empty()) return std::nullopt;
  const auto least = std::max<std::size_t>(2, static_cast<std::size_t>(std::ceil(at_least_s * fs)));
  const std::int32_t invalid = invalid_sample(info);
  std::size_t held = 0, runs = 0, first = 0;
  for (std::size_t start = 0; start < samples.size();) {
    std::size_t end = start + 1;
    while (end < samples.size() && samples[end] == samples[start]) ++end;
    if (end - start >= least && samples[start] != invalid) {
      if (runs == 0) first = start;
      held += end - start;
      ++runs;
    }
    start = end;
  }
  if (runs == 0) return std::nullopt;
  char text[400];
  std::snprintf(text, sizeof text,
                "%.1f s of signal %zu (%s) hold one value for %g s or more at a time (%zu run(s), the first at %.3f s): "
                "a lead off or a dropout shown as a flat line, read as no signal; windows over it have fewer intervals",
                static_cast<double>(held) / fs, channel, info.description.c_str(), at_least_s, runs,
                static_cast<double>(first) / fs);
  return std::string(text);
}

std::optional<std::string> paced_beats_warning(const std::string& record_path) {
  const std::string file = record_path + ".atr";
  std::error_code ec;
  if (!std::filesystem::is_regular_file(file, ec)) return std::nullopt;
  auto annotations = read_annotations(record_path, "atr");
  if (!annotations)
    return annotations.error().message + ": its beat labels were not read, so whether the rhythm is paced is not known";
  std::size_t beats = 0, paced = 0;
  for (const Annotation& a : *annotations) {
    if (!is_beat(a.code)) continue;
    ++beats;
    if (a.code == '/' || a.code == 'f') ++paced;
  }
  if (beats == 0 || 100.0 * static_cast<double>(paced) < kPacedPct * static_cast<double>(beats)) return std::nullopt;
  char text[400];
  std::snprintf(text, sizeof text,
                "%s labels %zu of its %zu beats (%.0f %%) paced ('/') or pacemaker fusion ('f'): the intervals of a "
                "paced rhythm are the pacemaker's, and their HRV says little of the heart's own regulation",
                file.c_str(), paced, beats, 100.0 * static_cast<double>(paced) / static_cast<double>(beats));
  return std::string(text);
}

namespace {

// One signal of a record, with the 16-bit sums of every signal (their checksums), read in
// blocks: read whole, a 12-lead record took twelve times the memory of the lead the chain
// reads (8 h at 128 Hz: 452 MB against 55).
struct OneSignal {
  RecordHeader header;
  std::size_t channel = 0;
  std::vector<std::int32_t> samples;
  std::vector<std::uint16_t> sums;
};

Result<OneSignal> read_one_signal(const std::string& record_path, std::size_t channel) {
  constexpr std::size_t kBlockFrames = std::size_t{1} << 16;
  auto reader = SignalReader::open(record_path);
  if (!reader) return fail(reader.error().message);
  OneSignal one;
  const auto count = static_cast<std::size_t>(std::max(0, reader->header().signal_count));
  if (count == 0) return fail(record_path + ".hea: the record has no signals, so no ECG");
  one.channel = channel == kEcgSignal ? ecg_signal(reader->header()) : channel;
  if (one.channel >= count)
    return fail(record_path + ".hea: no signal " + std::to_string(one.channel) + " (the record has " +
                std::to_string(count) + ")");
  if (auto why = not_an_ecg_signal(reader->header(), one.channel)) return fail(*why);
  if (reader->header().samples_per_signal > 0) one.samples.reserve(static_cast<std::size_t>(reader->header().samples_per_signal));
  one.sums.assign(count, 0);
  std::vector<std::vector<std::int32_t>> block(count);
  for (;;) {
    for (auto& samples : block) samples.clear();
    auto frames = reader->read(kBlockFrames, block);
    if (!frames) return fail(frames.error().message);
    if (*frames == 0) break;
    for (std::size_t i = 0; i < count; ++i)
      for (std::int32_t v : block[i]) one.sums[i] = static_cast<std::uint16_t>(one.sums[i] + static_cast<std::uint16_t>(v));
    one.samples.insert(one.samples.end(), block[one.channel].begin(), block[one.channel].end());
  }
  one.header = reader->header();
  return one;
}

}  // namespace

Result<HrvReport> hrv_from_record(const std::string& record_path, const ChainOptions& options,
                                  std::size_t channel) {
  auto signal = read_one_signal(record_path, channel);
  if (!signal) return unexpected(signal.error());
  channel = signal->channel;
  const RecordHeader& header = signal->header;
  const std::vector<std::int32_t>& samples = signal->samples;
  const SignalInfo& info = header.signals[channel];
  ChainOptions chain = options;
  chain.detector.invalid_sample = invalid_sample(info);
  auto report = hrv_from_samples(samples, header.fs, gain_per_mv(info), chain);
  if (!report) return fail(record_path + ": " + report.error().message);
  report->signal = channel;
  report->warnings = unread_samples(header);
  for (std::string& mismatch : checksum_mismatches(header, signal->sums)) report->warnings.push_back(std::move(mismatch));
  if (auto invalid = invalid_samples_warning(samples, info, channel, header.fs))
    report->warnings.push_back(*invalid);
  if (auto flat = flat_runs_warning(samples, info, channel, header.fs))
    report->warnings.push_back(*flat);
  if (auto hum = mains_hum_warning(samples, info, channel, header.fs))
    report->warnings.push_back(*hum);
  if (auto rate = default_rate_warning(header)) report->warnings.insert(report->warnings.begin(), *rate);
  if (auto units = non_voltage_warning(header, channel)) report->warnings.push_back(*units);
  if (auto fastest = detector_rate_warning(report->intervals, report->fs, chain.detector.hold_ms))
    report->warnings.push_back(*fastest);
  if (auto irregular = irregular_rhythm_warning(report->metrics, gap_count(report->intervals, report->fs, options.nn),
                                                options.nn.max_interval_s))
    report->rhythm_warnings.push_back(*irregular);  // which names the gaps
  else if (auto gaps = long_gaps_warning(report->intervals, report->fs, options.nn, options.hrv))
    report->rhythm_warnings.push_back(*gaps);
  if (auto paced = paced_beats_warning(record_path)) report->rhythm_warnings.push_back(*paced);
  if (auto fixed = fixed_rate_warning(report->intervals, report->fs)) report->rhythm_warnings.push_back(*fixed);
  // A flat signal (a lead off, a channel of zeros) gives no beat, and every metric null: said,
  // so that it is not read as a record without HRV for another reason.
  // With other signals in the record, the lead chosen may be the wrong one (an unnamed ECG after
  // a respiration signal): the caller can name another (`tahvel hrv --signal`).
  const auto signal_count = static_cast<std::size_t>(header.signal_count);
  const std::string others =
      signal_count > 1 ? " (the record has " + std::to_string(signal_count) + " signals: another may be the ECG: --signal N reads it)" : "";
  if (report->beats.size() < 2 && report->duration_s >= 10)
    report->warnings.push_back(std::to_string(report->beats.size()) + " beat(s) found in " +
                               std::to_string(static_cast<long long>(report->duration_s)) + " s of signal " +
                               std::to_string(channel) + " (" + info.description +
                               "): a flat or lead-off signal, a gain in its header off by far, or not an ECG; no HRV" + others);
  else if (samples.empty())
    report->warnings.push_back("the record holds no samples; no HRV");
  else if (report->beats.size() < 2) {
    char seconds[32];
    std::snprintf(seconds, sizeof seconds, "%.3g", report->duration_s);
    report->warnings.push_back(std::to_string(report->beats.size()) + " beat(s) found in " + seconds +
                               " s: too short a record for HRV");
  } else if (report->duration_s < kMinWindowS) {
    // Windows are refused below 10 s, for the handful of beats fewer seconds hold; a whole record
    // that short had its SDNN and RMSSD of 5 intervals printed without a word.
    char text[200];
    std::snprintf(text, sizeof text,
                  "the record is %.3g s long, %zu interval(s): HRV over fewer than %g s (the shortest window) says "
                  "little",
                  report->duration_s, report->intervals.size(), kMinWindowS);
    report->warnings.push_back(text);
  }
  return report;
}

}  // namespace tahvel::aggregation
