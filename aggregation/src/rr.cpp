// RR/NN series. The detected-beat rule is a small state machine over the RR series: a
// reference RR (median of recent accepted intervals) and a spread (median |ΔNN|) that widens
// the tolerances in irregular but normal rhythms (sinus arrhythmia) and keeps them tight in
// regular ones, where a slightly premature ectopic beat is still visible. Tuned on the MIT-BIH
// annotations with all beats unlabelled (docs/hrv.md gives the figures).
#include "tahvel/aggregation/rr.h"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <deque>

namespace tahvel::aggregation {

namespace {

double median_of(std::vector<double> v) {
  if (v.empty()) return 0.0;
  const std::size_t mid = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(mid), v.end());
  double m = v[mid];
  if (v.size() % 2 == 0) {
    m = (m + *std::max_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(mid))) / 2;
  }
  return m;
}

double median_of(const std::deque<double>& d) { return median_of(std::vector<double>(d.begin(), d.end())); }

// Answers "does (start, end) overlap any excluded range" in O(log R): ranges sorted by first,
// with the running maximum of last, so the ranges with first < end form a prefix.
std::vector<std::int64_t> prepare_ranges(std::vector<SampleRange>& ranges) {
  std::sort(ranges.begin(), ranges.end());
  std::vector<std::int64_t> max_last;
  max_last.reserve(ranges.size());
  std::int64_t m = INT64_MIN;
  for (const auto& r : ranges) max_last.push_back(m = std::max(m, r.second));
  return max_last;
}

bool overlaps_any(const std::vector<SampleRange>& ranges, const std::vector<std::int64_t>& max_last,
                  std::int64_t start, std::int64_t end) {
  auto it = std::lower_bound(ranges.begin(), ranges.end(), end,
                             [](const SampleRange& r, std::int64_t e) { return r.first < e; });
  if (it == ranges.begin()) return false;
  return max_last[static_cast<std::size_t>(it - ranges.begin()) - 1] > start;
}

std::size_t size_t_of(int v) { return static_cast<std::size_t>(std::max(v, 1)); }

}  // namespace

bool is_reference_normal(char code) noexcept {
  return code == 'N' || code == 'L' || code == 'R' || code == 'e' || code == 'j';
}

std::vector<Interval> reference_intervals(const std::vector<Beat>& beats,
                                          const std::vector<SampleRange>& excluded) {
  std::vector<Interval> out;
  if (beats.size() < 2) return out;
  std::vector<SampleRange> ranges(excluded);
  const std::vector<std::int64_t> max_last = prepare_ranges(ranges);
  out.reserve(beats.size() - 1);
  for (std::size_t i = 1; i < beats.size(); ++i) {
    const Beat& a = beats[i - 1];
    const Beat& b = beats[i];
    const bool nn = is_reference_normal(a.code) && is_reference_normal(b.code) &&
                    b.sample > a.sample && !overlaps_any(ranges, max_last, a.sample, b.sample);
    out.push_back({a.sample, b.sample, nn});
  }
  return out;
}

std::vector<Interval> intervals_from_peaks(const std::vector<std::int64_t>& peaks, double fs,
                                           const NnRule& rule,
                                           const std::vector<SampleRange>& excluded) {
  std::vector<Interval> out;
  if (peaks.size() < 2 || !(fs > 0)) return out;
  out.reserve(peaks.size() - 1);
  NnClassifier classifier(fs, rule, excluded);
  for (const std::int64_t p : peaks) classifier.push(p, out);
  classifier.finish(out);
  return out;
}

std::vector<Interval> intervals_from_peaks(const std::vector<std::int64_t>& peaks,
                                           const std::vector<std::int64_t>& empty_gap_ends,
                                           double fs, const NnRule& rule,
                                           const std::vector<SampleRange>& excluded) {
  return intervals_from_peaks(peaks, empty_gap_ends, {}, fs, rule, excluded);
}

std::vector<Interval> intervals_from_peaks(const std::vector<std::int64_t>& peaks,
                                           const std::vector<std::int64_t>& empty_gap_ends,
                                           const std::vector<std::int64_t>& p_wave_gap_ends,
                                           double fs, const NnRule& rule,
                                           const std::vector<SampleRange>& excluded) {
  std::vector<Interval> out;
  if (peaks.size() < 2 || !(fs > 0)) return out;
  out.reserve(peaks.size() - 1);
  NnClassifier classifier(fs, rule, excluded);
  // Both lists are ascending subsets of peaks: walk them alongside.
  auto gap = empty_gap_ends.begin();
  auto p_wave = p_wave_gap_ends.begin();
  for (const std::int64_t p : peaks) {
    while (gap != empty_gap_ends.end() && *gap < p) ++gap;
    while (p_wave != p_wave_gap_ends.end() && *p_wave < p) ++p_wave;
    classifier.push(p, gap != empty_gap_ends.end() && *gap == p,
                    p_wave != p_wave_gap_ends.end() && *p_wave == p, out);
  }
  classifier.finish(out);
  return out;
}

// --- NnClassifier: the rule as a state machine over the RR stream ---------------------------
//
// The front of pending_ is the next interval to judge. Each judgement either decides it (and,
// for a short interval or a premature beat with its pause, the interval after it too) or, when
// the branch it falls into needs intervals not pushed yet, waits and is redone on the next
// push. A judgement changes no state before it knows it can finish, so redoing it is exact.

NnClassifier::NnClassifier(double fs, const NnRule& rule, std::vector<SampleRange> excluded)
    : fs_(fs), rule_(rule), max_rr_(rule.max_interval_s * fs), excluded_(std::move(excluded)) {
  excluded_max_ = prepare_ranges(excluded_);
}

void NnClassifier::push(std::int64_t peak, std::vector<Interval>& decided) {
  push(peak, false, decided);
}

void NnClassifier::push(std::int64_t peak, bool after_empty_gap, std::vector<Interval>& decided) {
  push(peak, after_empty_gap, false, decided);
}

void NnClassifier::push(std::int64_t peak, bool after_empty_gap, bool p_wave_in_gap,
                        std::vector<Interval>& decided) {
  if (!(fs_ > 0)) return;
  if (has_last_) {
    pending_.push_back({last_peak_, peak, static_cast<double>(peak - last_peak_), after_empty_gap,
                        after_empty_gap && p_wave_in_gap});
    advance(decided);
  }
  has_last_ = true;
  last_peak_ = peak;
}

void NnClassifier::finish(std::vector<Interval>& decided) {
  finishing_ = true;
  advance(decided);
  reset();
}

void NnClassifier::reset() {
  has_last_ = false;
  last_peak_ = 0;
  pending_.clear();
  finishing_ = false;
  seed_pending_ = true;
  skip_next_ = false;
  after_couplet_ = false;
  prev_ok_ = false;
  prev_rr_ = 0;
  prev_pause_ = false;
  rebased_short_ = false;
  hist_.clear();
  diffs_.clear();
  short_run_.clear();
  unaccepted_.clear();
  forget_prior();
  forget_ectopic_run();
}

void NnClassifier::advance(std::vector<Interval>& decided) {
  while (!pending_.empty()) {
    if (skip_next_) {
      skip_next_ = false;
      const double r = pending_.front().rr;
      const bool short_too = r < short_limit_;
      // The pair of a short interval that is short itself is a premature beat too (the second
      // of a couplet, N V V N): a pause after it is its compensatory pause, not NN either.
      after_couplet_ = rule_.pause_after_couplet && short_too && r > 0;
      decide(false, decided, short_too ? Track::short_interval : Track::other);
      continue;
    }
    if (after_couplet_) {
      after_couplet_ = false;
      const double r = pending_.front().rr;
      if (!hist_.empty() && r > median_of(hist_) + steady_tol_ && r <= max_rr_) {
        decide(false, decided);
        continue;
      }
    }
    if (seed_pending_ && !seed()) return;
    if (!step(decided)) return;
  }
}

// Restart the reference from the median of the next reference_beats usable intervals (those
// before the next gap; zero-length ones do not count). False while they are not all pushed.
bool NnClassifier::seed() {
  std::vector<double> next;
  const std::size_t want = size_t_of(rule_.reference_beats);
  bool complete = finishing_;
  for (const Pending& p : pending_) {
    if (p.rr > max_rr_ || next.size() >= want) {
      complete = true;
      break;
    }
    if (p.rr > 0) next.push_back(p.rr);
  }
  if (next.size() >= want) complete = true;
  if (!complete) return false;
  hist_.clear();
  diffs_.clear();
  forget_prior();
  forget_ectopic_run();
  if (!next.empty()) hist_.push_back(median_of(next));
  seed_pending_ = false;
  rebased_short_ = false;
  return true;
}

bool NnClassifier::step(std::vector<Interval>& decided) {
  const double r = pending_.front().rr;
  if (r <= 0) {
    decide(false, decided);
    return true;
  }
  if (r > max_rr_) {  // a gap: not NN, and the reference restarts after it
    short_run_.clear();
    seed_pending_ = true;
    decide(false, decided);
    return true;
  }
  if (hist_.empty()) hist_.push_back(r);
  if (const auto stale = stale_reference()) {
    const std::size_t keep = std::min(unaccepted_.size(), size_t_of(rule_.reference_beats));
    hist_.assign(unaccepted_.end() - static_cast<std::ptrdiff_t>(keep), unaccepted_.end());
    diffs_.clear();
    short_run_.clear();
    unaccepted_.clear();
    forget_prior();
    forget_ectopic_run();
    // From faster intervals, as a rebase on a run of short ones (short_beat): not a rhythm to
    // return to, nor one whose long intervals are pauses.
    rebased_short_ = *stale == Stale::faster;
  }
  const double ref = median_of(hist_);
  const double spread = diffs_.size() >= 8 ? median_of(diffs_) : 0.0;
  const double tol_short = std::max(rule_.short_fraction, rule_.spread_factor * spread / ref);
  const double tol_long = std::max(rule_.long_fraction, rule_.spread_factor * spread / ref);
  const double tol_prem =
      std::max(rule_.premature_fraction, rule_.premature_spread_factor * spread / ref);
  // For the ectopic-run state, which follows every decided interval (track()).
  short_limit_ = (1 - tol_short) * ref;
  short_tol_ = tol_short * ref;
  steady_tol_ = tol_prem * ref;
  regular_ = diffs_.size() >= 8 && spread < rule_.regular_spread * ref;
  // Half a sample more than the tolerance: the difference of two intervals carries the rounding
  // of three fiducials, and at 128 Hz a rhythm quickening by just the tolerance a beat went over
  // it, and was taken for premature beats until it slowed again (103 at 128 Hz, 28 in a row).
  const bool continuous = prev_ok_ && std::abs(r - prev_rr_) <= tol_prem * ref + 0.5 &&
                          std::abs(r - ref) <= rule_.continuity_band * tol_short * ref;
  if (!continuous && r < (1 - tol_short) * ref && returns_to_prior(r, tol_short)) {
    // The slower rhythm was a block and conduction is back: the interval is NN, and the
    // reference and spread are those of the rhythm before the block again.
    hist_ = std::move(prior_hist_);
    diffs_ = std::move(prior_diffs_);
    forget_prior();
    short_run_.clear();
    decide(true, decided);
    return true;
  }
  if (!continuous && r < (1 - tol_short) * ref) {  // premature or spurious: it and the next
    short_beat(r, tol_short * ref);
    skip_next_ = true;
    decide(false, decided, Track::short_interval);
    return true;
  }
  if (!continuous && r > (1 + tol_long) * ref) {  // long: NN only if a new rhythm follows
    if (confirmed_pause()) {
      // A sinus pause or a blocked P wave: real intervals between normal beats, NN by the
      // reference rule. Not a sinus interval either: it stays out of the reference and the
      // spread, and the next interval is judged against the reference alone.
      short_run_.clear();
      count_slow(pending_.front());
      decide(true, decided);
      prev_ok_ = false;
      prev_pause_ = true;
      return true;
    }
    const std::size_t k = size_t_of(rule_.sustained_beats);
    if (pending_.size() <= k && !finishing_) return false;
    bool sustained = pending_.size() > k;
    for (std::size_t j = 1; sustained && j <= k; ++j) {
      if (std::abs(pending_[j].rr - r) > tol_long * r * 0.5) sustained = false;
    }
    short_run_.clear();
    if (sustained) {
      remember_prior();
      rebased_short_ = false;
      // The reference restarts from the new rhythm: the long interval and the k that confirmed
      // it. From the long interval alone the median would sit at that one value, and in sinus
      // arrhythmia the next shorter intervals were all rejected as premature until
      // rebase_beats of them agreed (113, 115 on MIT-BIH).
      hist_.clear();
      for (std::size_t j = 0; j <= k; ++j) hist_.push_back(pending_[j].rr);
      while (hist_.size() > size_t_of(rule_.reference_beats)) hist_.pop_front();
      diffs_.clear();
    }
    decide(sustained, decided);
    return true;
  }
  // Slightly early: a pause must not follow. An interval near the one before it (continuous)
  // is looked at too, when it is also shorter than that one: a PVC only 8 % early after an
  // interval that was itself a little short, with its compensatory pause, was two NN intervals
  // (MIT-BIH 114 at 242 s: 1014, 936, 1331 ms; its first 5 minutes' RMSSD +22 %). There the
  // pause must be one (the interval after it shorter again: not a slower rhythm beginning) and
  // within the long limit (longer, it is judged as a long interval: a blocked beat's pause,
  // NN, 231).
  const bool early_after_near = continuous && rule_.premature_pause_when_continuous && r < prev_rr_;
  if ((!continuous || early_after_near) && r < (1 - tol_prem) * ref) {
    if (pending_.size() < 2 && !finishing_) return false;
    const bool pause_follows = pending_.size() >= 2 && pending_[1].rr > (1 + tol_prem) * ref;
    // The interval after the pause is waited for only when there is a pause within the limit
    // to judge (an early interval near the one before waited for it whatever came next, and
    // 4 % of MIT-BIH's intervals were decided two beats later for nothing).
    const bool pause_in_limit = pause_follows && pending_[1].rr <= (1 + tol_long) * ref;
    if (continuous && pause_in_limit && pending_.size() < 3 && !finishing_) return false;
    const bool a_pause_alone = !continuous || (pause_in_limit && pending_.size() >= 3 && pending_[2].rr < pending_[1].rr - tol_prem * ref);
    if (pause_follows && a_pause_alone) {
      short_run_.clear();
      skip_next_ = true;
      decide(false, decided);
      return true;
    }
  }
  short_run_.clear();
  if (ectopic_) {
    // After an ectopic run, an interval still early against the sinus reference is the focus
    // going on (it took over because it fires faster): not NN, and kept out of the reference,
    // until an interval at the sinus rate or a steady rhythm.
    if (r < (1 - tol_prem) * ref && steady_with(r) < rule_.sinus_return_beats) {
      decide(false, decided, Track::candidate);
      return true;
    }
    ectopic_ = false;
  }
  accept(r);
  count_slow(pending_.front());
  decide(true, decided, Track::candidate);
  return true;
}

// A slower rhythm is adopted from the front interval (and the intervals that sustained it).
// The rhythm before it is remembered for returns_to_prior(), unless the reference came from a
// run of short intervals (bigeminy: its "rhythm" is the coupling interval); from here on
// count_slow() counts the intervals kept at the slower rhythm and those that ended at a gap
// with a P wave and nothing QRS-like, which decide whether the slowdown was a block.
void NnClassifier::remember_prior() {
  forget_prior();
  if (!rule_.return_to_prior_rhythm || rebased_short_) return;
  prior_hist_ = hist_;
  prior_diffs_ = diffs_;
  slow_kept_ = 1;
  slow_p_waves_ = pending_.front().p_wave ? 1 : 0;
}

void NnClassifier::forget_prior() {
  prior_hist_.clear();
  prior_diffs_.clear();
  slow_kept_ = slow_p_waves_ = 0;
}

void NnClassifier::count_slow(const Pending& p) {
  if (prior_hist_.empty()) return;
  ++slow_kept_;
  slow_p_waves_ += p.p_wave ? 1 : 0;
}

// Whether a short interval (rr) is a return to the remembered rhythm: the slower rhythm was a
// block — at least two of its intervals, and at least a third, ended at a gap that held a P
// wave and no QRS — and rr is within tol (a fraction) of the remembered reference. Not all
// gaps show the blocked P wave: one in the T wave, or under empty_gap_fraction, is not seen
// (on MIT-BIH, 424 of the 426 gaps of 231's 2:1 runs show it, and 0 of the 132 long gaps of
// 219, atrial fibrillation: empty, but no P wave).
bool NnClassifier::returns_to_prior(double rr, double tol) const {
  if (prior_hist_.empty() || slow_p_waves_ < 2 || 3 * slow_p_waves_ < slow_kept_) return false;
  const double back = median_of(prior_hist_);
  return std::abs(rr - back) <= tol * back;
}

// A premature (or spurious) beat. After rebase_beats consecutive short intervals that agree
// within tol, the reference restarts from them. Only the last max(rebase_beats,
// reference_beats) of the run are ever looked at, so only those are kept.
void NnClassifier::short_beat(double rr, double tol) {
  const std::size_t want = size_t_of(rule_.rebase_beats);
  const std::size_t ref_beats = size_t_of(rule_.reference_beats);
  short_run_.push_back(rr);
  if (short_run_.size() > std::max(want, ref_beats)) short_run_.pop_front();
  if (short_run_.size() < want) return;
  auto [lo, hi] =
      std::minmax_element(short_run_.end() - static_cast<std::ptrdiff_t>(want), short_run_.end());
  if (*hi - *lo < tol) {
    const std::size_t keep = std::min(short_run_.size(), ref_beats);
    hist_.assign(short_run_.end() - static_cast<std::ptrdiff_t>(keep), short_run_.end());
    diffs_.clear();
    short_run_.clear();
    forget_prior();
    rebased_short_ = true;
  }
}

void NnClassifier::accept(double rr) {
  if (prev_ok_) {
    diffs_.push_back(std::abs(rr - prev_rr_));
    if (diffs_.size() > size_t_of(rule_.spread_diffs)) diffs_.pop_front();
  }
  hist_.push_back(rr);
  if (hist_.size() > size_t_of(rule_.reference_beats)) hist_.pop_front();
}

// A long front interval is a confirmed pause when the detector found its gap empty, the
// interval before it was NN (or a confirmed pause: a run of blocked beats), and the reference
// is not a run of short intervals (bigeminy: there the reference is the coupling interval, and
// an ectopic beat's compensatory pause is long and empty).
bool NnClassifier::confirmed_pause() const {
  return rule_.keep_confirmed_pauses && pending_.front().empty_gap && (prev_ok_ || prev_pause_) &&
         !rebased_short_;
}

// The ectopic-run state (NnRule::hold_after_ectopic_run), updated with every decided interval
// of positive length up to max_interval_s. kind says how the rule saw it: short_interval
// (rejected as short, or the interval after such a one and short itself), candidate (within
// the tolerances: accepted, or held after an ectopic run) or other (long, premature with a
// pause, a return after a block). A run is ectopic_run_beats short intervals in a row, each
// within tol_short of the one before: an ectopic focus firing at its own steady rate. Noise that
// splits intervals gives short intervals too, but of unrelated lengths (a fragment, then the
// rest of the interval), and the run starts again. Only a run out of a regular rhythm counts:
// in atrial fibrillation or marked sinus arrhythmia the reference rule keeps intervals of every
// length, and an irregular rhythm after a run is what the rhythm was before it.
void NnClassifier::track(double rr, Track kind) {
  if (!rule_.hold_after_ectopic_run) return;
  if (kind != Track::short_interval) {
    run_ = 0;
  } else {
    if (run_ > 0 && std::abs(rr - run_last_) > short_tol_) run_ = 0;
    run_last_ = rr;
    if (++run_ >= std::max(rule_.ectopic_run_beats, 1) && regular_) ectopic_ = true;
  }
  if (kind == Track::candidate) steady_ = steady_with(rr);
  last_rr_ = rr;
}

// How many candidate intervals in a row (rr included; see track()) each stayed within tol_prem
// of the interval decided just before it. A short interval between them breaks the count, since
// the next one is then far from it.
int NnClassifier::steady_with(double rr) const {
  return last_rr_ > 0 && std::abs(rr - last_rr_) <= steady_tol_ ? steady_ + 1 : 1;
}

void NnClassifier::forget_ectopic_run() {
  run_ = steady_ = 0;
  run_last_ = last_rr_ = 0;
  ectopic_ = false;
}

// Whether stale_reference_beats intervals in a row were not NN and their median lies outside
// the fixed tolerances of the reference, and on which side (NnRule::stale_reference_beats).
std::optional<NnClassifier::Stale> NnClassifier::stale_reference() const {
  if (rule_.stale_reference_beats <= 0 || hist_.empty()) return std::nullopt;
  if (unaccepted_.size() < size_t_of(rule_.stale_reference_beats)) return std::nullopt;
  const double ref = median_of(hist_);
  const double typical = median_of(unaccepted_);
  if (typical < (1 - rule_.short_fraction) * ref) return Stale::faster;
  if (typical > (1 + rule_.long_fraction) * ref) return Stale::slower;
  return std::nullopt;
}

// Emits the front interval with the rule's decision, excluded ranges applied.
void NnClassifier::decide(bool ok, std::vector<Interval>& decided, Track kind) {
  const Pending p = pending_.front();
  pending_.pop_front();
  if (p.rr > 0 && p.rr <= max_rr_) track(p.rr, kind);
  if (ok) {
    unaccepted_.clear();
  } else if (p.rr > 0 && p.rr <= max_rr_ && rule_.stale_reference_beats > 0) {
    unaccepted_.push_back(p.rr);
    if (unaccepted_.size() > size_t_of(rule_.stale_reference_beats)) unaccepted_.pop_front();
  }
  prev_pause_ = false;
  prev_ok_ = ok;
  prev_rr_ = p.rr;
  decided.push_back({p.start, p.end, ok && !overlaps_excluded(p.start, p.end)});
}

bool NnClassifier::overlaps_excluded(std::int64_t start, std::int64_t end) const {
  return overlaps_any(excluded_, excluded_max_, start, end);
}

double nn_fraction(const std::vector<Interval>& intervals) noexcept {
  if (intervals.empty()) return 0.0;
  std::size_t nn = 0;
  for (const Interval& iv : intervals) nn += iv.nn ? 1 : 0;
  return static_cast<double>(nn) / static_cast<double>(intervals.size());
}

}  // namespace tahvel::aggregation
