// RR and NN interval series from beats: the reference rule for annotated beats (MIT-BIH
// labels) and an RR-only rule for detected, unlabelled beats. Pure functions, no I/O; a record
// of 30 minutes (about 2,000 beats) takes microseconds. Definitions and the reasons for each
// threshold are in docs/hrv.md ("NN rules").
#pragma once

#include <cstddef>
#include <cstdint>
#include <deque>
#include <optional>
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
// tol_prem * ref + half a sample, for the rounding of the fiducials) and within
// continuity_band * tol_short of ref is accepted (gradual rate change). Otherwise:
//  - shorter than (1 - tol_short) * ref: premature beat or spurious detection; it and the next
//    interval (the compensatory pause, or the other half of a split interval) are not NN;
//    when that next one is short too (a couplet, N V V N: pause_after_couplet), the one after
//    it is not NN either if longer than (1 + tol_prem) * ref (the couplet's pause);
//    after rebase_beats consecutive short intervals within tol_short * ref of each other the
//    reference restarts from them (a sustained rate change);
//  - longer than (1 + tol_long) * ref: a missed beat or pause, not NN, unless the next
//    sustained_beats intervals stay within tol_long / 2 of it (a new rhythm), which restarts
//    the reference from it and those sustained_beats intervals; but a confirmed pause is NN:
//    the detector found its gap empty (the end beat is in empty_gap_ends, see
//    DetectorOptions::empty_gap_fraction), the interval before it was NN (or a confirmed pause
//    itself), and the reference does not come from a run of short intervals (in bigeminy the
//    reference is the coupling interval and every compensatory pause looks long). A confirmed
//    pause is NN but moves neither the reference nor the spread (keep_confirmed_pauses);
//  - shorter than (1 - tol_prem) * ref and followed by one longer than (1 + tol_prem) * ref:
//    a premature beat with its compensatory pause; both are not NN. So too for an interval
//    continuous with the one before but shorter than it (premature_pause_when_continuous),
//    when the pause is within (1 + tol_long) * ref and the interval after it is shorter than
//    the pause by more than tol_prem * ref (a pause, not a slower rhythm);
//  - a return to the rhythm before a block (return_to_prior_rhythm): when the reference
//    restarts from a new, slower rhythm, the reference before it is remembered (unless it
//    came from a run of short intervals); a later short interval within tol_short of that
//    remembered reference is NN and restores it with its spread (the block ends, conduction is
//    1:1 again) when the slower rhythm was a block: at least two, and at least a third, of the
//    intervals kept at it ended at gaps that held a P wave and nothing QRS-like
//    (p_wave_gap_ends: 2:1 AV block). A gap, a run of short intervals or the next slower
//    rhythm forgets it;
//  - an ectopic run out of a regular rhythm (hold_after_ectopic_run): after ectopic_run_beats
//    consecutive short intervals (below (1 - tol_short) * ref), each within tol_short * ref of
//    the one before (a focus firing at its own rate; noise that splits intervals gives
//    unrelated lengths), when the rhythm before them was regular (spread < regular_spread *
//    ref), an interval that is still early, below (1 - tol_prem) * ref, though not short
//    enough to be rejected, is not NN and moves neither the reference nor the spread. An
//    accelerated junctional or atrial focus takes over only while it fires faster than the
//    sinus node, so after its run it goes on a little faster than the sinus rhythm; the
//    reference rule drops those beats, the RR rule alone kept them. The first interval at
//    the sinus rate, or sinus_return_beats intervals in a row each within tol_prem * ref of
//    the one before (a steady new rhythm), ends this; so does a gap.
//  - a stale reference (stale_reference_beats): when that many intervals in a row (gaps and
//    zero-length ones not counted) were not NN and their median lies outside the fixed
//    tolerances, below (1 - short_fraction) * ref or above (1 + long_fraction) * ref, the
//    reference no longer describes the rhythm: it restarts from the last reference_beats of
//    them. In atrial fibrillation a run of long intervals taken as a slower rhythm left the
//    reference at 1.5 s, and every interval after it was short and irregular, so neither a
//    run of agreeing short intervals nor a steady rhythm restarted it: MIT-BIH 219 had 0 NN of
//    the 450 intervals of its last 6 minutes, and windows before them a heart rate of 39 bpm
//    from a few intervals (the reference rule: 70). In bigeminy the compensatory intervals
//    keep the median near the reference, and ventricular runs rebase sooner (above).
// Whatever the comparison, an interval longer than max_interval_s or overlapping an excluded
// range is not NN, and the reference restarts after a gap longer than max_interval_s.
// max_interval_s is 3.5 s, not the 2 s of filters tuned for adults in sinus rhythm (PhysioNet's
// HRV toolkit, the 200-2000 ms "physiological range" of Wessel et al.'s adaptive filter):
// bradycardia in complete AV block or sick sinus syndrome goes down to 20 bpm (RR 3 s), and
// with 2 s every interval of a regular 28 bpm rhythm was a gap (no HRV) and at 30 bpm half of
// them (SDNN 6.1 ms against 35.1). 3.5 s keeps a rhythm of 20 bpm with its variability; what
// is longer is a pause of clinical size (Holter reports pauses of 3 s and more) or lost signal.
struct NnRule {
  double max_interval_s = 3.5;          // longer intervals are gaps (lost signal, long pauses)
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
  bool keep_confirmed_pauses = true;    // a long interval over an empty gap is NN (above)
  bool return_to_prior_rhythm = true;   // the end of a blocked run is NN (above)
  bool hold_after_ectopic_run = true;   // early intervals after an ectopic run are not NN (above)
  bool pause_after_couplet = true;      // the pause after two short intervals is not NN (above)
  bool premature_pause_when_continuous = true;  // also an interval near the one before (above)
  int ectopic_run_beats = 3;            // consecutive short intervals that make a run
  double regular_spread = 0.03;         // a rhythm is regular below this spread / ref
  int sinus_return_beats = 4;           // steady intervals that end the ectopic rhythm
  int stale_reference_beats = 32;       // intervals in a row not NN whose median is off the
                                        // reference: it restarts from them (0: never; below)
};

// Intervals between consecutive detected peaks (samples, sorted ascending; duplicates give a
// zero-length interval that is never NN), marked by NnRule. fs is the sampling frequency in Hz
// (> 0; otherwise the series is empty). excluded as for reference_intervals. Fewer than two
// peaks give an empty series. The same as NnClassifier fed every peak and then finished.
std::vector<Interval> intervals_from_peaks(const std::vector<std::int64_t>& peaks, double fs,
                                           const NnRule& rule = {},
                                           const std::vector<SampleRange>& excluded = {});
// The same with the detector's empty-gap evidence: empty_gap_ends are the peaks (a subset of
// peaks, ascending: Detection::empty_gap_ends) that end a confirmed empty gap.
std::vector<Interval> intervals_from_peaks(const std::vector<std::int64_t>& peaks,
                                           const std::vector<std::int64_t>& empty_gap_ends,
                                           double fs, const NnRule& rule = {},
                                           const std::vector<SampleRange>& excluded = {});
// The same with the blocked-P-wave evidence too: p_wave_gap_ends are the empty-gap ends (a
// subset of them, ascending: Detection::p_wave_gap_ends) whose gap held a P wave. This is what
// `tahvel hrv` and the agents use.
std::vector<Interval> intervals_from_peaks(const std::vector<std::int64_t>& peaks,
                                           const std::vector<std::int64_t>& empty_gap_ends,
                                           const std::vector<std::int64_t>& p_wave_gap_ends,
                                           double fs, const NnRule& rule = {},
                                           const std::vector<SampleRange>& excluded = {});

// The streaming form of intervals_from_peaks, for peaks that arrive as a detector emits them.
// Push the peaks in ascending order; each push appends to `decided` the intervals whose NN
// decision has become final, oldest first, and finish() appends the rest. Everything appended,
// concatenated, equals intervals_from_peaks(all peaks, fs, rule, excluded) exactly, whatever
// the calls in between (the batch function is this class run over all peaks).
//
// Delay. The rule looks ahead: an interval far from the reference waits for the next one
// (premature beat with a pause) or the next sustained_beats (a new, slower rhythm), and after
// the start or a gap the reference is seeded from the next reference_beats intervals. An
// interval's decision is therefore final once
//     D = max(sustained_beats, reference_beats - 1, 1, and 2 with
//             premature_pause_when_continuous)            (8 with the defaults)
// further intervals of positive length have been pushed (zero-length ones, from duplicate
// peaks, do not count, and a zero-length interval itself may wait for D + 1). The bound is
// reached only after the start and after a gap; in a steady rhythm most intervals are decided
// when their end beat is pushed, an early one after the next beat (one continuous with the
// interval before it and followed by a pause, after two: premature_pause_when_continuous), a
// long one after sustained_beats more. Decisions come out in order. pending() is at most D after any push
// when no two peaks are equal.
//
// Memory is bounded for an endless stream: the undecided intervals (pending()), the reference
// window (reference_beats), the spread window (spread_diffs), the run of short intervals
// (max(rebase_beats, reference_beats)), the intervals not NN since the last NN one
// (stale_reference_beats), a remembered reference and spread from before a block,
// a few scalars for the ectopic-run state and the excluded ranges given at construction.
// excluded need not be sorted. With fs <= 0 nothing is ever decided, as the batch function
// returns nothing. Peaks out of order give an interval of non-positive length, never NN.
// finish() returns the classifier to its constructed state, ready for a new stream. Not
// thread-safe; no call throws except on allocation failure.
class NnClassifier {
 public:
  NnClassifier(double fs, const NnRule& rule = {}, std::vector<SampleRange> excluded = {});

  // Adds the next peak (sample index); appends the intervals decided by it to `decided`.
  void push(std::int64_t peak, std::vector<Interval>& decided);
  // The same for a peak that the detector reports as ending a confirmed empty gap
  // (after_empty_gap), which lets a long interval ending there be a confirmed pause.
  void push(std::int64_t peak, bool after_empty_gap, std::vector<Interval>& decided);
  // The same for a peak whose empty gap also held a P wave (p_wave_in_gap, meaningful only
  // with after_empty_gap: Detection::p_wave_gap_ends), the evidence of a blocked beat that
  // lets the rule return to the rhythm before a block.
  void push(std::int64_t peak, bool after_empty_gap, bool p_wave_in_gap,
            std::vector<Interval>& decided);

  // Ends the stream: decides every pending interval (the look-ahead stops at the last peak, as
  // in the batch function), appends them and resets.
  void finish(std::vector<Interval>& decided);

  // Intervals pushed but not yet decided.
  std::size_t pending() const noexcept { return pending_.size(); }

 private:
  struct Pending {
    std::int64_t start = 0;
    std::int64_t end = 0;
    double rr = 0;  // end - start, in samples
    bool empty_gap = false;  // the detector found nothing QRS-like between the two beats
    bool p_wave = false;     // ... but a P wave: a blocked beat
  };

  void advance(std::vector<Interval>& decided);
  bool seed();
  bool step(std::vector<Interval>& decided);
  bool confirmed_pause() const;
  enum class Stale { faster, slower };
  std::optional<Stale> stale_reference() const;
  void remember_prior();
  void forget_prior();
  void count_slow(const Pending& p);
  bool returns_to_prior(double rr, double tol) const;
  void short_beat(double rr, double tol);
  void accept(double rr);
  enum class Track { other, short_interval, candidate };  // see track()
  void decide(bool ok, std::vector<Interval>& decided, Track kind = Track::other);
  void track(double rr, Track kind);
  int steady_with(double rr) const;
  void forget_ectopic_run();
  bool overlaps_excluded(std::int64_t start, std::int64_t end) const;
  void reset();

  double fs_;
  NnRule rule_;
  double max_rr_;
  std::vector<SampleRange> excluded_;       // sorted by first
  std::vector<std::int64_t> excluded_max_;  // running maximum of last over excluded_
  bool has_last_ = false;
  std::int64_t last_peak_ = 0;
  std::deque<Pending> pending_;  // undecided intervals; the front is the next to judge
  bool finishing_ = false;       // inside finish(): look-ahead stops at the last peak
  bool seed_pending_ = true;     // the reference restarts at the front interval
  bool skip_next_ = false;       // the next interval is the pair of a short one: not NN
  bool after_couplet_ = false;   // that pair was short too: a pause after it is not NN
  bool prev_ok_ = false;         // the decision and RR of the interval before the front
  double prev_rr_ = 0;
  bool prev_pause_ = false;      // the interval before the front was a confirmed pause
  bool rebased_short_ = false;   // the reference restarted from a run of short intervals
  std::deque<double> hist_, diffs_, short_run_;
  // Usable intervals decided not NN since the last NN one, the last stale_reference_beats.
  std::deque<double> unaccepted_;
  // The reference and spread before a slower rhythm adopted over empty gaps (empty: none).
  std::deque<double> prior_hist_, prior_diffs_;
  // Since then: the intervals kept at the slower rhythm, and how many ended at a P-wave gap.
  std::size_t slow_kept_ = 0, slow_p_waves_ = 0;
  // The ectopic-run state (hold_after_ectopic_run). The limits are those of the last judgement,
  // for the interval skipped after a short one; tracked over every decided interval.
  double short_limit_ = 0, short_tol_ = 0, steady_tol_ = 0;
  bool regular_ = false;       // the spread of the accepted rhythm is below regular_spread
  int run_ = 0;                // consecutive short intervals that agree, up to the last decided
  double run_last_ = 0;        // the last of them
  int steady_ = 0;             // candidate intervals in a row within steady_tol_ of the last
  double last_rr_ = 0;         // the last decided interval (0: none since the reference restarted)
  bool ectopic_ = false;       // an ectopic run, and since then no sinus rate nor steady rhythm
};

// The fraction of intervals that are NN (0 for an empty series).
double nn_fraction(const std::vector<Interval>& intervals) noexcept;

}  // namespace tahvel::aggregation
