// R-peak (QRS) detection on one ECG lead: a streaming detector in the Hamilton–Tompkins family
// (band-pass, slope, moving-window integration, adaptive thresholds from the medians of recent
// QRS and noise peaks, 200 ms hold, T-wave and baseline-shift rejection, search-back, restart
// after a long silence). Tuned for ambulatory ECG sampled at 100–1000 Hz, fed in chunks of any
// size by an agent; it runs well above 10 M samples/s on one core (docs/rpeak.md).
//
// Output: absolute sample indices (0 = first sample pushed) of the fiducial point of each
// detected beat, in increasing order: the centre (centroid of the squared deviation from the
// local baseline, over ±42 ms) of the QRS's main deflection, which is the dominant extremum of
// the original signal within ±60 ms of the band-passed QRS, of the lead's usual polarity unless
// the other is 1.5 times as large. Beats of one morphology thus share a fiducial point to the
// sample, which RR intervals and HRV need (on MIT-BIH the point lies within a sample of the
// reference annotation for most records; EC57 scoring allows 150 ms). docs/rpeak.md, step 3.
//
// Determinism: the detector is a per-sample state machine; every decision uses only samples
// already pushed, so the peaks reported are IDENTICAL whatever the chunking of the input.
// Memory: three history rings of at least 4 s of samples, allocated at construction.
// Latency: the beats of the first `relearn_s` seconds (8) are reported once the thresholds are
// learned, at the end of those seconds. After that, a beat is reported at most
// `decision_delay_samples()` samples after the stream passed it (514 ms with the defaults:
// fiducial shift, band-pass delay, integration window, peak release and the 200 ms hold), unless
// ever larger candidates keep arriving; a beat found by search-back is reported when the search
// fires, 1.5 median RR after the previous beat. finish() reports the candidate still held.
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <memory>
#include <vector>

#include "tahvel/aggregation/error.h"

namespace tahvel::aggregation {

// Detector parameters. Times are in milliseconds or seconds, amplitudes in mV; the detector
// converts them to samples with `fs` and to ADC units with `gain`, so the same defaults serve
// every sampling rate. The defaults are the ones scored in docs/rpeak.md; none is fitted to a
// record.
struct DetectorOptions {
  double fs = 360;     // sampling frequency, Hz (> 0; filters are designed for 100–1000 Hz)
  double gain = 200;   // ADC units per mV; scales `min_qrs_mv` and the hum level. Negative: a
                       // lead recorded upside down (WFDB), whose samples are turned over
  // The record's "no value" sample (WFDB: -32768 in format 16, -2048 in 212; wfdb.h
  // invalid_sample): the detector holds the last valid sample over a run of them, as a flat
  // lead, rather than read a step of -160 mV into the QRS band. nullopt: every value is signal.
  std::optional<std::int32_t> invalid_sample;

  // Band-pass of the QRS energy: 2nd-order Butterworth high-pass then low-pass (Hz). The band
  // keeps the QRS (most energy 5–20 Hz) and drops baseline wander, P and T waves (< 5 Hz) and
  // muscle noise and mains (> 25 Hz).
  double highpass_hz = 5;
  double lowpass_hz = 15;
  // Moving-window integration of |slope| of the band-passed signal: about one QRS width.
  double integration_ms = 80;

  // A candidate peak of the integrated slope must stay the largest for `hold_ms` (no two QRS
  // complexes lie closer: the refractory period); a larger one within that time replaces it.
  double hold_ms = 200;
  // Detection threshold = noise + threshold_fraction × (QRS − noise), where QRS and noise are
  // the medians of the last 8 QRS and the last 8 noise peak heights.
  double threshold_fraction = 0.3125;
  // Within `twave_ms` of the previous QRS, a candidate whose steepest slope is below
  // twave_slope_ratio × that of the previous QRS is taken for a T wave.
  double twave_ms = 360;
  double twave_slope_ratio = 0.5;
  // Search-back: when no QRS came for searchback_rr × the median RR interval, the largest
  // peak since the last QRS (at least `twave_ms` after it) above searchback_fraction × the
  // threshold is taken for a missed QRS.
  double searchback_rr = 1.5;
  double searchback_fraction = 0.5;
  // The floor: a peak whose band-passed peak-to-peak amplitude is below it is never a beat.
  // It follows the lead, so that a small lead (V1, a low-voltage ECG, a wrong gain: QRS of
  // 0.1-0.5 mV) keeps its beats and a large one does not count its baseline's ripple:
  //   max(min_qrs_mv, min(min_qrs_fraction × QRS, min_qrs_baseline × ripple))
  // where QRS is the median peak-to-peak of the last 8 beats and ripple that of the last 32
  // local maxima of the integrated slope (mostly the baseline's own bumps). min_qrs_mv is the
  // absolute floor, above amplifier noise (tens of µV rms), under which a flat line or a lead
  // off gives nothing whatever its gain; it alone applies while no QRS is known (the learning
  // seconds). On MIT-BIH this scores the same from a fifth to five times the recorded
  // amplitude (docs/rpeak.md, step 3). The floor was a fixed 0.15 mV (OSEA's) before.
  double min_qrs_mv = 0.055;
  double min_qrs_fraction = 0.5;
  double min_qrs_baseline = 0.9;
  // The first `relearn_s` seconds (whole seconds, 1–8) teach the thresholds (the peaks seen
  // meanwhile are classified afterwards, so the first beats are not lost); after as long
  // without a QRS, the thresholds are relearned from the per-second maxima.
  double relearn_s = 8;
  // Empty-gap evidence for the NN rule (docs/hrv.md, "Confirmed pauses"): a beat is reported
  // as ending a confirmed empty gap when, between the end of the previous beat's T wave
  // (`twave_ms` after it, or later at slow rates: `twave_qtc`) and `hold_ms` before this one,
  // no local maximum of the integrated slope (counting those below the floor, which never
  // become candidates) reached this fraction of the median QRS height (a P wave aside:
  // `pwave_fraction`). A long interval whose gap holds nothing QRS-like is a pause (sinus pause, blocked
  // P wave), not a missed beat. 0 disables the evidence. On MIT-BIH the missed beats left
  // after search-back reach 0.06 and more (one, in noise, reached nothing). A gap after a
  // candidate above the threshold that the T-wave test rejected (an early beat) is never
  // empty; at fast rates the gap starts by 0.7 of the median interval at the latest, and below
  // 0.5 s intervals the P-wave cue is off (docs/rpeak.md step 8, "Early beats and fast rates").
  double empty_gap_fraction = 0.05;
  // A wave in the gap that is the record's own P wave does not count against an empty gap: a
  // blocked P wave (second-degree AV block) is no QRS. The detector keeps a running template
  // of the P wave, the original signal from 250 to 90 ms before each accepted beat (PR
  // interval 120-200 ms); a gap maximum at or above empty_gap_fraction is ignored when it
  // stays below `pwave_fraction` of the median QRS height and the signal around it (160 ms,
  // best of the centres within 80 ms) correlates with that template at `pwave_correlation`
  // or more (Pearson, after removing the line between the window ends: amplitude and baseline
  // do not matter, shape does). A missed QRS, even a small one, has the shape of a QRS, not
  // of a P wave. The P wave is well under 0.25 mV against a QRS of 1 mV or more, so 0.15 of
  // the QRS height in the integrated slope (where a P wave, mostly below 5 Hz, is smaller
  // still) leaves P waves in and keeps out anything the search-back could have taken for a
  // beat (it looks from half the threshold, 0.16-0.24). pwave_fraction 0 disables the cue.
  // docs/rpeak.md step 8, docs/hrv.md.
  double pwave_fraction = 0.15;
  double pwave_correlation = 0.9;
  // The gap of the empty-gap evidence starts after the previous beat's T wave, which ends
  // later at slower rates: max(twave_ms, twave_qtc * sqrt(RR)) after that beat, RR in seconds
  // the interval before it (Bazett: QT = QTc sqrt(RR)). 0.40 s: an upper-normal QTc of 0.44 s
  // counted from the QRS onset, less the ~40 ms from onset to the reported point. At RR 0.81 s
  // it equals twave_ms; in 2:1 AV block the T wave of the beat before a blocked P wave reached
  // past 360 ms (MIT-BIH 231). 0 keeps twave_ms alone.
  double twave_qtc = 0.40;
  // The gap ends `hold_ms` before the beat, but the beat's own P wave may lie earlier: its
  // peak comes about one PR interval before the R wave, up to 200 ms normally and more with
  // first-degree AV block. A maximum below `pwave_fraction` of the median QRS height within
  // this many ms before the beat is taken for that P wave and does not count against the gap,
  // whatever its shape (after a pause the P wave may differ from the template). 300 ms covers a
  // PR interval up to about 300 ms; MIT-BIH 108 (borderline first-degree block) has the P
  // waves of two pause-ending beats at 230-260 ms. A missed QRS there would be 300 ms or less
  // before a detected one; above pwave_fraction it still counts. At or below hold_ms (or with
  // pwave_fraction 0) nothing changes. docs/rpeak.md step 8.
  double own_pwave_ms = 300;
  // A run of this many ms of one value repeated (a value held over lost samples, a dropout
  // written as zeros, a lead off or at its rail) is no signal: a gap that holds one is not
  // confirmed empty (`empty_gap_fraction`), as a gap with invalid samples is not, since a beat
  // may have been lost in it. Recorded ECG, even at a coarse ADC step, changes within a few
  // samples; an interval kept as a pause across such a run counted a lost beat's two
  // intervals as one NN interval (SDNN x4, RMSSD x8 with ten 0.1 s holds in five minutes).
  // A run counts against the gap it overlaps, between the beat before and the beat after.
  // 0 disables the check; at most 10000.
  double flat_run_ms = 80;
};

// Checks that the options are usable (fs positive, gain not 0, band 0 < highpass < lowpass <
// fs/2, windows positive). Nothing else can fail.
Result<void> validate(const DetectorOptions& options);

// A streaming R-peak detector for one lead. Move-only; not thread-safe (one per stream).
class RPeakDetector {
 public:
  // Throws std::invalid_argument with validate()'s message if the options are not usable.
  explicit RPeakDetector(const DetectorOptions& options);
  RPeakDetector(RPeakDetector&&) noexcept;
  RPeakDetector& operator=(RPeakDetector&&) noexcept;
  RPeakDetector(const RPeakDetector&) = delete;
  RPeakDetector& operator=(const RPeakDetector&) = delete;
  ~RPeakDetector();

  // Feeds the next n samples (raw ADC units) of the stream and appends to peaks_out the beats
  // decided so far, as absolute sample indices, increasing across calls. Never throws; does
  // not allocate except to grow peaks_out (and, in the learning seconds, if more than 128
  // candidates are held back, which the 200 ms hold rules out). A moved-from detector may only
  // be destroyed or assigned to.
  void push(const std::int32_t* samples, std::size_t n, std::vector<std::int64_t>& peaks_out);
  // The same, and appends to empty_gap_out those of the beats appended to peaks_out that end a
  // confirmed empty gap (DetectorOptions::empty_gap_fraction), in the same order: a subset of
  // the peaks, as sample indices. Both overloads decide identically.
  void push(const std::int32_t* samples, std::size_t n, std::vector<std::int64_t>& peaks_out,
            std::vector<std::int64_t>& empty_gap_out);
  // The same, and appends to p_wave_gap_out those of the beats appended to empty_gap_out whose
  // empty gap held a P wave (DetectorOptions::pwave_fraction): a blocked P wave, the sign of
  // second-degree AV block. A subset of the empty-gap ends, in the same order.
  void push(const std::int32_t* samples, std::size_t n, std::vector<std::int64_t>& peaks_out,
            std::vector<std::int64_t>& empty_gap_out, std::vector<std::int64_t>& p_wave_gap_out);
  // Ends the stream: appends the beats still held. Afterwards push() starts nothing new:
  // further calls are ignored.
  void finish(std::vector<std::int64_t>& peaks_out);
  void finish(std::vector<std::int64_t>& peaks_out, std::vector<std::int64_t>& empty_gap_out);
  void finish(std::vector<std::int64_t>& peaks_out, std::vector<std::int64_t>& empty_gap_out,
              std::vector<std::int64_t>& p_wave_gap_out);

  // The most samples between a beat (after the learning seconds, not found by search-back)
  // and the push() that reports it.
  std::int64_t decision_delay_samples() const noexcept;

 private:
  class Impl;
  std::unique_ptr<Impl> impl_;
};

// The whole record at once: push(samples) then finish().
std::vector<std::int64_t> detect_r_peaks(const std::vector<std::int32_t>& samples,
                                         const DetectorOptions& options);

// The whole record at once, with the gap evidence: `peaks` as detect_r_peaks returns them,
// `empty_gap_ends` the subset of them that end a confirmed empty gap, `p_wave_gap_ends` the
// subset of those whose gap held a blocked P wave.
struct Detection {
  std::vector<std::int64_t> peaks;
  std::vector<std::int64_t> empty_gap_ends;
  std::vector<std::int64_t> p_wave_gap_ends;
};
Detection detect_beats(const std::vector<std::int32_t>& samples, const DetectorOptions& options);

}  // namespace tahvel::aggregation
