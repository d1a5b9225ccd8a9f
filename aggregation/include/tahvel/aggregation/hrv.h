// Heart-rate variability from an RR/NN series (rr.h): time domain, Lomb-Scargle frequency
// domain and Poincaré descriptors, for one series, for fixed windows, and as a streaming
// windower for agents. Pure functions; a 30-minute record (about 2,000 intervals) takes well
// under a millisecond. Every definition and guard is written out in docs/hrv.md.
#pragma once

#include <cstddef>
#include <deque>
#include <optional>
#include <string>
#include <limits>
#include <vector>

#include "tahvel/aggregation/rr.h"

namespace tahvel::aggregation {

// The metrics of one series or window. A metric is nullopt when its guard fails:
//   mean_nn_ms, mean_hr_bpm    >= 1 NN interval
//   sdnn_ms                    >= 2 NN intervals (sample SD, n - 1)
//   rmssd_ms, pnn50_pct        >= 2 differences of adjacent NN intervals (two NN intervals
//                              sharing a beat)
//   sd1_ms, sd2_ms             >= 2 adjacent differences and >= 2 NN (and SD2^2 >= 0)
//   hf_ms2                     NN data (sum of NN intervals) >= HrvOptions::min_hf_s and
//                              >= 3 NN intervals
//   lf_ms2                     NN data >= HrvOptions::min_lf_s and >= 3 NN intervals
//   lf_hf                      lf_ms2 and hf_ms2 present and hf_ms2 > 0
// nn_count counts NN intervals, rr_count all intervals given.
struct HrvMetrics {
  std::optional<double> mean_nn_ms, sdnn_ms, rmssd_ms, pnn50_pct, mean_hr_bpm, lf_ms2, hf_ms2,
      lf_hf, sd1_ms, sd2_ms;
  std::size_t nn_count = 0, rr_count = 0;
  // Intervals longer than HrvOptions::gap_s that are not NN: pauses of the heart or signal lost
  // between two beats, which RR alone cannot tell apart and HRV leaves out (docs/hrv.md, "Gaps").
  std::size_t gap_count = 0;
  // How irregular the rhythm is, NN or not: the share (%) of adjacent RR pairs whose second
  // differs from the first by more than 20 % of it (nullopt without a pair). Pairs with an
  // interval longer than HrvOptions::gap_s are not counted: a gap (signal lost between two
  // beats, a pause) is no irregular rhythm, and each isolated one made two irregular pairs, so
  // that a regular record with a lead coming off was warned of as ectopy or AF. Above
  // kIrregularPct the RR-only NN rule is not to be trusted: frequent ectopic beats in bigeminy
  // or trigeminy and atrial fibrillation look alike to it, and HRV can be off several times
  // (docs/hrv.md, "Where the rule fails"). A paced rhythm is regular and does not show here.
  std::optional<double> irregular_pct;
};

// Above this irregular_pct (or this share of intervals not NN) `tahvel hrv` warns that HRV of
// the record is unreliable; normal-rhythm records of the MIT-BIH set stay below 14 %.
inline constexpr double kIrregularPct = 15.0;

// Options of the frequency domain, with the Task Force (1996) bands.
struct HrvOptions {
  double lf_low_hz = 0.04, lf_high_hz = 0.15;   // LF band [low, high)
  double hf_low_hz = 0.15, hf_high_hz = 0.40;   // HF band [low, high]
  double min_hf_s = 60.0;                       // NN data needed for HF (Task Force: 1 min)
  double min_lf_s = 120.0;                      // NN data needed for LF (Task Force: 2 min)
  double oversampling = 4.0;                    // frequency step = 1 / (oversampling * span)
  // Work of one periodogram, samples x frequencies, beyond which the series is cut into equal
  // parts of time whose band powers are averaged (about 4.5 h of NN intervals in one piece): the
  // step above, not a coarser one, is what keeps a narrow peak's power (a grid capped at 1,024
  // frequencies made a 2-h record's HF twice what it is).
  double max_work = 5e8;
  double gap_s = NnRule{}.max_interval_s;       // longer intervals are gaps, not rhythm (irregular_pct)
};

// Metrics of a series. fs is the sampling frequency of the sample indices in Hz (> 0;
// otherwise every metric is nullopt). Intervals need not be sorted for the time domain, but
// adjacency (RMSSD, pNN50, SD1/SD2) is judged between consecutive entries
// (a.end == b.start, both NN) and the frequency domain takes the NN intervals in the order
// given, timed at their end beat.
HrvMetrics compute_hrv(const std::vector<Interval>& intervals, double fs,
                       const HrvOptions& options = {});

// LF and HF band powers (ms^2) of an uneven series: times t_s (seconds, ascending) and values
// nn_ms, by the Lomb-Scargle periodogram scaled to a one-sided density whose integral over
// all frequencies is the variance. Exposed for tests; returns {lf, hf}.
struct BandPowers {
  double lf_ms2 = 0, hf_ms2 = 0;
};
BandPowers lomb_scargle_bands(const std::vector<double>& t_s, const std::vector<double>& nn_ms,
                              const HrvOptions& options = {});

// The one-sided Lomb-Scargle density (ms^2/Hz) at the given frequencies (Hz), same scaling as
// lomb_scargle_bands; O(N * F) with trigonometric recurrences when freqs is an even grid. The
// scale is N times the mean spacing of the times, gaps longer than `hole_s` (signal lost, not
// rhythm) left out: scaled by the span, a series with a hole integrated to its variance times
// span / time covered (a 150 s lead-off in a 300 s window doubled LF and HF).
std::vector<double> lomb_scargle_density(const std::vector<double>& t_s,
                                         const std::vector<double>& nn_ms, double f0_hz,
                                         double df_hz, std::size_t count,
                                         double hole_s = std::numeric_limits<double>::infinity());

// A window [start_s, end_s) of the record (times from sample 0) and its metrics.
struct WindowMetrics {
  double start_s = 0, end_s = 0;
  HrvMetrics metrics;
  // The length of the setting the window was made under: end_s - start_s unless the record's
  // end cut the window short. Windows of one length are one series to a trend (0: not known).
  double length_s = 0;
};

// Whether the record's end cut the window short (the last windows of a recording): it measured
// less time than its setting's length, so it is no point of a series for a trend, nor a
// patient's latest window (`tahvel patients`). A window of unknown length (0) is not.
inline bool cut_short(const WindowMetrics& w) { return w.length_s > 0 && w.end_s - w.start_s < w.length_s - 1e-3; }

// The window settings the chain takes from outside: `tahvel hrv --window/--step`, tahvel-hrv's
// --window/--step and its tv:windowSeconds/tv:stepSeconds configuration, hrv_from_samples. A
// window shorter than 10 s holds a handful of beats (ultra-short RMSSD is studied from 10 s
// on; SDNN and the spectrum need minutes); a step below 1 s makes windows that differ by no
// beat at resting rates, and more than one per second of signal (a step of 0.0001 s made 18
// million windows of MIT-BIH 100 and ran out of memory). windowed_hrv and HrvWindower
// themselves take any positive values.
inline constexpr double kMinWindowS = 10;
inline constexpr double kMinStepS = 1;
inline constexpr double kMaxWindowS = 86400;  // the longest window or step: a day

// Why `seconds` cannot be the window length (is_step false) or the step (true): the text
// names the bounds ("must be a number of seconds in [10, 86400] (...)"); nullopt when it can.
std::optional<std::string> window_setting_problem(double seconds, bool is_step);

// At most this many windows over any moment of signal (window / step). Each window is computed
// whole, its spectrum up to about a second of CPU for a day of beats (HrvOptions::max_work): a
// day's window stepped by a second took a second of CPU per second of signal, per patient, and
// an agent given it from the hospital would fall behind for good.
inline constexpr double kMaxWindowsPerMoment = 3600;

// Why a window of window_s stepped by step_s cannot be used (more than kMaxWindowsPerMoment
// windows over a moment): the text names the least step for that window; nullopt when it can.
std::optional<std::string> window_step_problem(double window_s, double step_s);

// Windows k = 0, 1, ... start at k * step_s and last window_s; an interval belongs to every
// window whose [start_s, end_s) contains its end beat (end / fs). Windows are produced from the
// first one that ends after the first interval's end up to the last one starting at or before
// the end of the last interval, empty ones between included (nn_count 0). window_s > 0 and
// step_s > 0, else the result is empty. Intervals must be in order of end. Given the record's
// end (`record_end_s`, s from sample 0), a window that would run past it ends there: the last
// windows of a record cover only what was recorded, and say so by their length.
std::vector<WindowMetrics> windowed_hrv(const std::vector<Interval>& intervals, double fs,
                                        double window_s, double step_s,
                                        const HrvOptions& options = {},
                                        std::optional<double> record_end_s = std::nullopt);

// The streaming form of windowed_hrv: push intervals in order of end; each push appends to
// completed the windows that the interval's end time closes (end_s <= its end time). finish()
// appends the windows still open, exactly as windowed_hrv would for the same input, and
// resets the windower. Memory holds only the intervals of the open windows.
class HrvWindower {
 public:
  HrvWindower(double fs, double window_s, double step_s, const HrvOptions& options = {});
  void push(const Interval& interval, std::vector<WindowMetrics>& completed);
  // New window length and step, from the next window on (window k keeps counting from the
  // first window start not yet produced). Non-positive values are ignored.
  void set_window(double window_s, double step_s);
  // After a restart: the window that ended at `end_s`, `length_s` long, was produced before,
  // under whatever setting held then. With the same window length the next window ends one step
  // after it (so with step = window, it starts there); with another length (the setting changed
  // while the agent was down) the next one starts at `end_s`, so that none overlaps a window
  // produced before. No window ending at or before it is produced again.
  void resume_after(double end_s, double length_s);
  // `record_end_s`: the record's end, where the windows still open end (as windowed_hrv).
  void finish(std::vector<WindowMetrics>& completed, std::optional<double> record_end_s = std::nullopt);

 private:
  void emit_front(std::vector<WindowMetrics>& completed, std::optional<double> record_end_s = std::nullopt);
  double front_end() const;  // where the next window to complete ends
  double fs_, window_s_, step_s_;
  HrvOptions options_;
  double origin_s_ = 0;      // start of window 0 of the current setting
  std::size_t next_ = 0;     // index of the next window to produce
  double last_end_s_ = -1;   // end time of the last interval pushed (-1: none)
  std::deque<Interval> buffer_;
};

}  // namespace tahvel::aggregation
