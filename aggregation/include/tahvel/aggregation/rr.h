// RR and NN interval series from beats: the reference rule for annotated beats (MIT-BIH
// labels) and an RR-only rule for detected, unlabelled beats. Pure functions, no I/O; a record
// of 30 minutes (about 2,000 beats) takes microseconds. Definitions and the reasons for each
// threshold are in docs/hrv.md ("NN rules").
#pragma once

#include <cstdint>
#include <utility>
#include <vector>

namespace tahvel::aggregation {

// One beat: its sample index (the fiducial point, usually the R peak) and, when known from
// annotations, its WFDB beat mnemonic ('N', 'L', 'V', ...). Detected beats keep the default.
struct Beat {
  std::int64_t sample = 0;
  char code = 'N';
};

// The interval between two consecutive beats. start and end are the samples of the two
// bounding beats (end > start for a valid series); nn says whether the interval is
// normal-to-normal by the rule that produced it. Consecutive entries of a series share a
// beat (series[k].end == series[k + 1].start) unless the series was cut.
struct Interval {
  std::int64_t start = 0;
  std::int64_t end = 0;
  bool nn = false;
};

// A closed range of samples [first, last] that no NN interval may overlap: an unreadable
// stretch of signal, a ventricular flutter episode ('[' ... ']'), or a single marker such as
// '!' given as [s, s]. An interval (start, end) overlaps [first, last] when
// first < end && last > start, i.e. when the range meets the open interval between the two
// beats; a range that only touches a bounding beat does not exclude it.
using SampleRange = std::pair<std::int64_t, std::int64_t>;

// True for the beat codes whose intervals the reference rule keeps: N, L, R, e, j (normal,
// left and right bundle branch block, atrial and nodal escape).
bool is_reference_normal(char code) noexcept;

// The reference rule (docs/hrv.md "Reference rule"), for annotated beats sorted by sample:
// one Interval per pair of consecutive beats; nn is true exactly when both beats are
// reference-normal (is_reference_normal) and the interval overlaps no range in excluded.
// The caller gives only beats (not rhythm, noise or flutter annotations) and derives excluded
// from the annotations. Fewer than two beats give an empty series. excluded need not be
// sorted.
std::vector<Interval> reference_intervals(const std::vector<Beat>& beats,
                                          const std::vector<SampleRange>& excluded = {});

// The RR-only rule for detected beats (docs/hrv.md "Rule for detected beats"). Each interval
// is compared with a reference RR, the median of the last reference_beats accepted NN
// intervals, with tolerances widened by the recent beat-to-beat spread (the median |ΔNN| of
// the last spread_diffs adjacent accepted pairs):
//   tol_short = max(short_fraction, spread_factor * spread / ref)
//   tol_long  = max(long_fraction,  spread_factor * spread / ref)
//   tol_prem  = max(premature_fraction, premature_spread_factor * spread / ref)
// An interval continuous with the accepted interval just before it (|RR - previous| <=
// tol_prem * ref) and within continuity_band * tol_short of ref is accepted (gradual rate
// change). Otherwise:
//  - shorter than (1 - tol_short) * ref: premature beat or spurious detection; it and the next
//    interval (the compensatory pause, or the other half of a split interval) are not NN;
//    after rebase_beats consecutive short intervals within tol_short * ref of each other the
//    reference restarts from them (a sustained rate change);
//  - longer than (1 + tol_long) * ref: a missed beat or pause, not NN, unless the next
//    sustained_beats intervals stay within tol_long / 2 of it (a new rhythm), which restarts
//    the reference;
//  - shorter than (1 - tol_prem) * ref and followed by one longer than (1 + tol_prem) * ref:
//    a premature beat with its compensatory pause; both are not NN.
// Whatever the comparison, an interval longer than max_interval_s or overlapping an excluded
// range is not NN, and the reference restarts after a gap longer than max_interval_s.
struct NnRule {
  double max_interval_s = 2.0;          // longer intervals are gaps (missed beats, lost signal)
  int reference_beats = 9;              // accepted intervals in the reference median
  double short_fraction = 0.12;         // a beat more than 12 % early is premature
  double long_fraction = 0.45;          // an interval more than 45 % long is a missed beat
  double premature_fraction = 0.06;     // early and followed by a late one: premature
  double spread_factor = 4.0;           // tolerance in multiples of the recent median |ΔNN|
  double premature_spread_factor = 2.0;
  double continuity_band = 1.5;         // how far a gradual change may stray from ref
  int sustained_beats = 3;              // intervals that confirm a new, longer rhythm
  int rebase_beats = 20;                // short intervals that confirm a new, faster rhythm
  int spread_diffs = 32;                // adjacent accepted pairs in the spread median
};

// Intervals between consecutive detected peaks (samples, sorted ascending; duplicates give a
// zero-length interval that is never NN), marked by NnRule. fs is the sampling frequency in Hz
// (> 0). excluded as for reference_intervals. Fewer than two peaks give an empty series.
std::vector<Interval> intervals_from_peaks(const std::vector<std::int64_t>& peaks, double fs,
                                           const NnRule& rule = {},
                                           const std::vector<SampleRange>& excluded = {});

// The fraction of intervals that are NN (0 for an empty series).
double nn_fraction(const std::vector<Interval>& intervals) noexcept;

}  // namespace tahvel::aggregation
