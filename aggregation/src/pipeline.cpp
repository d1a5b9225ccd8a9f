// The HRV chain; see pipeline.h.
#include <cstdio>

#include "tahvel/aggregation/pipeline.h"

#include "tahvel/aggregation/wfdb.h"

namespace tahvel::aggregation {

Result<HrvReport> hrv_from_samples(const std::vector<std::int32_t>& samples, double fs,
                                   double gain, const ChainOptions& options) {
  if (!(options.window_s > 0)) return fail("window: must be a positive number of seconds");
  if (options.step_s < 0) return fail("step: must not be negative");
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
  report.metrics = compute_hrv(report.intervals, fs, options.hrv);
  const double step = options.step_s > 0 ? options.step_s : options.window_s;
  report.windows = windowed_hrv(report.intervals, fs, options.window_s, step, options.hrv, report.duration_s);
  return report;
}

std::optional<std::string> irregular_rhythm_warning(const HrvMetrics& m) {
  const double not_nn = m.rr_count > 0 ? 100.0 * static_cast<double>(m.rr_count - m.nn_count) / static_cast<double>(m.rr_count) : 0;
  const double irregular = m.irregular_pct.value_or(0);
  if (irregular <= kIrregularPct && not_nn <= kIrregularPct) return std::nullopt;
  char text[400];
  std::snprintf(text, sizeof text,
                "an irregular rhythm (%.0f %% of successive intervals differ by more than 20 %%; %.0f %% of intervals are "
                "not NN): frequent ectopic beats or atrial fibrillation, which the RR-only NN rule cannot tell apart; "
                "HRV of this record may be several times off (docs/hrv.md, \"Where the rule fails\")",
                irregular, not_nn);
  return std::string(text);
}

Result<HrvReport> hrv_from_record(const std::string& record_path, const ChainOptions& options,
                                  std::size_t channel) {
  auto signals = read_signals(record_path);
  if (!signals) return unexpected(signals.error());
  if (channel == kEcgSignal) channel = ecg_signal(signals->header);
  if (channel >= signals->samples.size())
    return fail(record_path + ".hea: no signal " + std::to_string(channel) + " (the record has " +
                std::to_string(signals->samples.size()) + ")");
  const SignalInfo& info = signals->header.signals[channel];
  auto report = hrv_from_samples(signals->samples[channel], signals->header.fs, gain_per_mv(info), options);
  if (!report) return fail(record_path + ": " + report.error().message);
  report->signal = channel;
  report->warnings = checksum_mismatches(*signals);
  if (auto rate = default_rate_warning(signals->header)) report->warnings.insert(report->warnings.begin(), *rate);
  if (auto irregular = irregular_rhythm_warning(report->metrics)) report->warnings.push_back(*irregular);
  // A flat signal (a lead off, a channel of zeros) gives no beat, and every metric null: said,
  // so that it is not read as a record without HRV for another reason.
  if (report->beats.size() < 2 && report->duration_s >= 10)
    report->warnings.push_back(std::to_string(report->beats.size()) + " beat(s) found in " +
                               std::to_string(static_cast<long long>(report->duration_s)) + " s of signal " +
                               std::to_string(channel) + " (" + info.description +
                               "): a flat or lead-off signal, or not an ECG; no HRV");
  return report;
}

}  // namespace tahvel::aggregation
