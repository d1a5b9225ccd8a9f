// The HRV chain as one function: ECG samples -> R peaks -> RR intervals with the NN mask (the
// RR-only rule) -> HRV for the whole series and per window. `tahvel hrv` and the whiteboard
// agents both run it, so the same record gives the same metrics whichever way it goes.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "tahvel/aggregation/error.h"
#include "tahvel/aggregation/hrv.h"
#include "tahvel/aggregation/rpeak.h"
#include "tahvel/aggregation/rr.h"
#include "tahvel/aggregation/wfdb.h"

namespace tahvel::aggregation {

struct ChainOptions {
  DetectorOptions detector;  // fs and gain are taken from the record or the caller
  NnRule nn;
  HrvOptions hrv;
  double window_s = 300;     // HRV windows (Task Force short-term: 5 min)
  double step_s = 0;         // 0: the window length (windows do not overlap)
};

struct HrvReport {
  double fs = 0;
  double duration_s = 0;             // the signal's length: where its last windows end
  std::size_t signal = 0;            // hrv_from_record: the record's signal that was read
  std::vector<std::string> warnings; // hrv_from_record: what was read wrong or not at all (a
                                     // checksum, no-value samples, flat runs, no beats): what
                                     // both HRV and beat scoring must know
  std::vector<std::string> rhythm_warnings;  // hrv_from_record: why the HRV of this rhythm may
                                     // not mean what HRV means (irregular_rhythm_warning of the
                                     // whole record, paced_beats_warning), beats aside
  std::vector<std::int64_t> beats;   // detected R peaks, sample indices
  std::vector<Interval> intervals;   // consecutive beats, NN-marked
  HrvMetrics metrics;                // the whole series
  std::vector<WindowMetrics> windows;
};

// When the record's reference annotations ("<record_path>.atr", if there is one) label at least
// kPacedPct percent of its beats paced ('/') or pacemaker fusion ('f'): how many, and that the
// intervals of a paced rhythm are the pacemaker's, which RR alone cannot tell. Nullopt without
// such a file or below the share; a file that cannot be read is said.
inline constexpr double kPacedPct = 10;
std::optional<std::string> paced_beats_warning(const std::string& record_path);

// How many intervals of a series are longer than rule.max_interval_s at fs Hz and not NN: the
// gaps, which intervals_from_peaks never takes as NN, whatever the rhythm.
std::size_t gap_count(const std::vector<Interval>& intervals, double fs, const NnRule& rule = {});

// When some intervals are gaps (gap_count) and no other warning names them: how many, the
// longest and where, that they may be pauses of the heart (sinus arrest, AV block) or signal
// lost (a lead off, also one that leaves a quiet line), which RR alone cannot tell apart, and
// SDNN with them taken as NN beside the SDNN without them. A few pauses of 3.6 s took SDNN from
// 285 ms to 20, with nothing said; kept as NN instead, a lead off with a quiet line made it 246
// ms against 35.5 (docs/hrv.md, "Gaps"). Nullopt without gaps.
std::optional<std::string> long_gaps_warning(const std::vector<Interval>& intervals, double fs, const NnRule& rule = {},
                                             const HrvOptions& hrv = {});

// Why HRV of a series with these metrics may be far off (HrvMetrics::irregular_pct or the
// share of intervals not NN above kIrregularPct), or nullopt. `gaps` of the intervals not NN
// were rejected for being longer than max_interval_s (gap_count): when they are at least half
// of those rejected and the rhythm is regular (irregular_pct not above kIrregularPct), the
// warning names them (pauses, lost signal, a heart rate below 60 / max_interval_s bpm) rather
// than ectopic beats or atrial fibrillation, which the irregular-rhythm warning names.
// When at least kAtTheHoldPct percent of the intervals are as short as the detector allows
// (its hold, DetectorOptions::hold_ms, plus a sample or 5 ms): beats found as fast as it can
// find them, which no heart's rhythm is (a 200 ms hold is 300 bpm) but a periodic signal
// faster than one is (mains hum at 50 or 60 Hz, a test tone); how many, the rate, and that
// HRV of it means nothing. Nullopt below that share, or with fewer than 10 intervals.
inline constexpr double kAtTheHoldPct = 50;
std::optional<std::string> detector_rate_warning(const std::vector<Interval>& intervals, double fs, double hold_ms);

std::optional<std::string> irregular_rhythm_warning(const HrvMetrics& metrics, std::size_t gaps = 0,
                                                    double max_interval_s = NnRule{}.max_interval_s);

// When at least kFixedRateMinIntervals NN intervals (a minute at 60 bpm) are all one length to
// within a sample no longer than kFixedRateSampleMs (at coarser rates: all exactly one length):
// a rhythm held that still, which a heart rarely keeps (a resting adult's SDNN is tens of ms,
// a transplanted heart's some ms) but a fixed-rate pacemaker, a simulator or test signal, or a
// periodic artefact (a spike a second) does; how many, how long, and that HRV of it says
// nothing of the heart. nullopt otherwise.
inline constexpr std::size_t kFixedRateMinIntervals = 60;
inline constexpr double kFixedRateSampleMs = 4;
std::optional<std::string> fixed_rate_warning(const std::vector<Interval>& intervals, double fs);

// The share of a signal's power (its mean taken out second by second) within 1 Hz of the mains
// frequency, 50 or 60 Hz, whichever holds more, and that frequency; {0, 0} when the signal is
// shorter than a second or sampled below 122 Hz (61 Hz must be under half the rate). Measured on whole seconds with
// the Goertzel algorithm at the three DFT bins nearest f-1, f and f+1 Hz.
struct MainsShare {
  double percent = 0;
  double hz = 0;
};
MainsShare mains_share(const std::vector<std::int32_t>& samples, double fs);

// When at least kMainsHumPct percent of signal `channel`'s power is mains hum (mains_share):
// how much, at which frequency, and that an unplugged lead picks up the mains, so that the beats
// found in it may be the hum's. A 50 Hz sine at 250 Hz locks the detector to every 12th cycle,
// 250 bpm as regular as no heart, and detector_rate_warning does not see it (its intervals are
// longer than the hold). MIT-BIH's records have at most a few percent.
inline constexpr double kMainsHumPct = 50;
std::optional<std::string> mains_hum_warning(const std::vector<std::int32_t>& samples, const SignalInfo& info,
                                             std::size_t channel, double fs);

// Samples of signal `channel` that hold WFDB's no-value (invalid_sample, wfdb.h): how many and
// where the first is, and that the detector read them as no signal. nullopt when none.
std::optional<std::string> invalid_samples_warning(const std::vector<std::int32_t>& samples, const SignalInfo& info,
                                                   std::size_t channel, double fs);

// Runs of one value held longer than `at_least_s` in signal `channel`, other than WFDB's
// no-value (invalid_samples_warning says those): how long in all, in how many runs, and where
// the first starts. The detector reads a run of DetectorOptions::flat_run_ms as no signal, as it
// does no-value samples, so a lead off or a dropout shown as a flat line or zeros leaves windows
// with fewer intervals. Only runs longer than a beat at 40 bpm are said: a noise-free signal
// (a synthetic one) is flat between its beats. nullopt when there is none.
std::optional<std::string> flat_runs_warning(const std::vector<std::int32_t>& samples, const SignalInfo& info,
                                             std::size_t channel, double fs, double at_least_s = 1.5);

// The chain over one lead sampled at fs Hz with `gain` ADC units per mV. Errors: invalid
// detector options or window settings (the message names the option).
Result<HrvReport> hrv_from_samples(const std::vector<std::int32_t>& samples, double fs,
                                   double gain, const ChainOptions& options = {});

// `channel` of hrv_from_record: the record's ECG lead (ecg_signal in wfdb.h).
inline constexpr std::size_t kEcgSignal = static_cast<std::size_t>(-1);

// The chain over signal `channel` of a WFDB record given without extension: by default the
// record's ECG lead (MLII in MIT-BIH, signal 0), its gain taken per millivolt whatever its
// units. Errors: those of read_signals, a channel the record does not have, and a sampling
// rate the detector cannot work at (naming the header).
Result<HrvReport> hrv_from_record(const std::string& record_path, const ChainOptions& options = {},
                                  std::size_t channel = kEcgSignal);

}  // namespace tahvel::aggregation
