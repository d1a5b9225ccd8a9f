// RR/NN rules (rr.h): the reference rule on annotated beats and the RR-only rule on peaks.
#include <gtest/gtest.h>

#include <cmath>

#include "tahvel/aggregation/rr.h"

namespace tahvel::aggregation {
namespace {

std::vector<bool> flags(const std::vector<Interval>& v) {
  std::vector<bool> f;
  for (const auto& i : v) f.push_back(i.nn);
  return f;
}

TEST(ReferenceRule, BothBeatsMustBeNormal) {
  const std::vector<Beat> beats{{0, 'N'}, {300, 'L'}, {600, 'V'}, {800, 'R'}, {1100, 'e'},
                                {1400, 'j'}, {1700, 'A'}};
  const auto iv = reference_intervals(beats);
  ASSERT_EQ(iv.size(), 6u);
  EXPECT_EQ(flags(iv), (std::vector<bool>{true, false, false, true, true, false}));
  EXPECT_EQ(iv[1].start, 300);
  EXPECT_EQ(iv[1].end, 600);
}

TEST(ReferenceRule, ExcludedRangesOverlapTheOpenInterval) {
  const std::vector<Beat> beats{{0}, {300}, {600}, {900}, {1200}};
  // A marker strictly inside (450), a range touching only beat 900 from the right side,
  // and an unreadable stretch covering beat 1200's interval.
  const auto iv = reference_intervals(beats, {{450, 450}, {900, 900}, {1000, 5000}});
  EXPECT_EQ(flags(iv), (std::vector<bool>{true, false, true, false}));
}

TEST(ReferenceRule, FewerThanTwoBeatsGiveNothing) {
  EXPECT_TRUE(reference_intervals({}).empty());
  EXPECT_TRUE(reference_intervals({{5, 'N'}}).empty());
  EXPECT_DOUBLE_EQ(nn_fraction({}), 0.0);
}

std::vector<std::int64_t> peaks_from_rr(const std::vector<int>& rr) {
  std::vector<std::int64_t> p{1000};
  for (int r : rr) p.push_back(p.back() + r);
  return p;
}

TEST(DetectedRule, RegularRhythmIsAllNn) {
  std::vector<int> rr;
  for (int i = 0; i < 60; ++i) rr.push_back(300 + (i % 5) - 2);
  const auto iv = intervals_from_peaks(peaks_from_rr(rr), 360);
  EXPECT_DOUBLE_EQ(nn_fraction(iv), 1.0);
}

TEST(DetectedRule, PrematureBeatExcludesBothIntervals) {
  std::vector<int> rr(40, 300);
  rr[20] = 200;  // premature beat
  rr[21] = 400;  // compensatory pause
  const auto iv = intervals_from_peaks(peaks_from_rr(rr), 360);
  for (std::size_t i = 0; i < iv.size(); ++i) EXPECT_EQ(iv[i].nn, i != 20 && i != 21) << i;
}

// At 128 Hz an interval is known to 7.8 ms: a rhythm quickening from 116 samples (906 ms) by
// 8 and then 7 samples a beat differs from the interval before by more than the 6 % allowed
// (6.96 samples) through rounding alone, and the second step, below the premature limit too,
// was taken for a premature beat; every faster interval after it with it, until the rhythm
// slowed again (MIT-BIH 103 resampled to 128 Hz: 28 sinus intervals in a row at 1202 s).
TEST(DetectedRule, ARhythmQuickeningAtACoarseRateIsNotTakenForPrematureBeats) {
  std::vector<int> rr(30, 116);
  for (int r : {108, 101, 100, 99, 98, 98, 97, 97, 96, 96, 96, 96, 96, 96, 96, 96, 96, 96, 96, 96}) rr.push_back(r);
  const auto iv = intervals_from_peaks(peaks_from_rr(rr), 128);
  ASSERT_EQ(iv.size(), rr.size());
  for (std::size_t i = 0; i < iv.size(); ++i) EXPECT_TRUE(iv[i].nn) << i << ": " << rr[i] << " samples";
  // A step of 9 samples is no rounding: that early a beat is premature, and its pause with it.
  rr.assign(30, 116);
  for (int r : {108, 99, 124, 116, 116, 116, 116, 116, 116, 116, 116}) rr.push_back(r);
  const auto premature = intervals_from_peaks(peaks_from_rr(rr), 128);
  EXPECT_FALSE(premature[31].nn);
}

// N V V N: the first short interval and its pair (V-V, short too) are rejected by the pair
// rule; the pause after the couplet is its compensatory pause (MIT-BIH 116 at 1551 s: 1042 ms
// against a reference of 735, below the long limit) and is not NN either.
TEST(DetectedRule, PauseAfterACoupletIsNotNn) {
  std::vector<int> rr(40, 265);
  rr[20] = 150;  // N-V
  rr[21] = 145;  // V-V
  rr[22] = 375;  // V-N: the pause, 1.42 x the reference
  const auto iv = intervals_from_peaks(peaks_from_rr(rr), 360);
  for (std::size_t i = 0; i < iv.size(); ++i) EXPECT_EQ(iv[i].nn, i < 20 || i > 22) << i;
}

// A split interval (two short halves) followed by an interval at the reference keeps that one.
TEST(DetectedRule, AnIntervalAtTheReferenceAfterTwoShortOnesIsNn) {
  std::vector<int> rr(40, 300);
  rr[15] = 140;
  rr[16] = 160;
  rr[17] = 305;
  const auto iv = intervals_from_peaks(peaks_from_rr(rr), 360);
  EXPECT_FALSE(iv[15].nn);
  EXPECT_FALSE(iv[16].nn);
  EXPECT_TRUE(iv[17].nn);
}

TEST(DetectedRule, SlightlyPrematureBeatWithPauseIsCaught) {
  std::vector<int> rr(40, 300);
  rr[20] = 275;  // 8 % early: below short_fraction, but followed by a pause
  rr[21] = 325;
  const auto iv = intervals_from_peaks(peaks_from_rr(rr), 360);
  EXPECT_FALSE(iv[20].nn);
  EXPECT_FALSE(iv[21].nn);
  EXPECT_TRUE(iv[22].nn);
}

// A PVC only a little early after an interval that was itself a little short is continuous
// with it, and was NN with its compensatory pause (MIT-BIH 114 at 242 s: 1014, 936, 1331,
// 1089 ms; the first 5 minutes' RMSSD +22 % against the reference rule, with no warning). Both
// are not NN when the pause is one: the interval after it shorter again. A pause the rhythm
// keeps is a slower rhythm beginning, and stays NN with the interval before it.
TEST(DetectedRule, APrematureBeatNearTheIntervalBeforeItIsCaughtByItsPause) {
  std::vector<int> rr(40, 389);  // 1080 ms at 360 Hz
  for (int r : {370, 350, 470, 390, 389, 389, 389, 389, 389, 389}) rr.push_back(r);
  const auto iv = intervals_from_peaks(peaks_from_rr(rr), 360);
  ASSERT_EQ(iv.size(), rr.size());
  for (std::size_t i = 0; i < iv.size(); ++i) EXPECT_EQ(iv[i].nn, i != 41 && i != 42) << i << ": " << rr[i] << " samples";
  rr.assign(40, 389);
  for (int r : {370, 350, 470, 468, 472, 470, 469, 471, 470, 470}) rr.push_back(r);
  const auto slower = intervals_from_peaks(peaks_from_rr(rr), 360);
  EXPECT_TRUE(slower[41].nn);
  EXPECT_TRUE(slower[42].nn);
  NnRule before;  // the rule without it, as up to session 83
  before.premature_pause_when_continuous = false;
  rr.assign(40, 389);
  for (int r : {370, 350, 470, 390, 389, 389, 389, 389, 389, 389}) rr.push_back(r);
  EXPECT_TRUE(intervals_from_peaks(peaks_from_rr(rr), 360, before)[41].nn);
}

TEST(DetectedRule, MissedBeatAndGapAreNotNn) {
  std::vector<int> rr(40, 300);
  rr[10] = 600;   // a missed beat
  rr[25] = 1440;  // 4 s at 360 Hz: a gap (NnRule::max_interval_s 3.5 s)
  const auto iv = intervals_from_peaks(peaks_from_rr(rr), 360);
  EXPECT_FALSE(iv[10].nn);
  EXPECT_FALSE(iv[25].nn);
  EXPECT_TRUE(iv[11].nn);
  EXPECT_TRUE(iv[26].nn);
}

// Bradycardia down to 20 bpm (complete AV block, sick sinus) is a rhythm, not a series of
// gaps: with max_interval_s 2 s every interval of a regular 28 bpm rhythm was a gap and none NN,
// and at 30 bpm those above 2 s, half of them (SDNN 6.1 ms against 35.1).
TEST(DetectedRule, ARegularRhythmDownTo20BpmIsNnNotGaps) {
  for (const double bpm : {20.0, 25.0, 28.0, 30.0}) {
    const int mean = static_cast<int>(360 * 60 / bpm);
    std::vector<int> rr;
    // Sinus arrhythmia of +-4 %: the 20 bpm intervals reach 3.1 s.
    for (int i = 0; i < 120; ++i) rr.push_back(mean + static_cast<int>(mean * 0.04 * std::sin(i * 0.9)));
    const auto iv = intervals_from_peaks(peaks_from_rr(rr), 360);
    EXPECT_DOUBLE_EQ(nn_fraction(iv), 1.0) << bpm << " bpm";
  }
}

// Beyond the bound an interval is a gap whatever the rhythm: a pause of 4 s in a 60 bpm rhythm,
// and every interval of a rhythm of 15 bpm (below what the bound keeps).
TEST(DetectedRule, IntervalsLongerThanTheBoundAreGaps) {
  std::vector<int> rr(40, 360);
  rr[20] = 4 * 360;
  auto iv = intervals_from_peaks(peaks_from_rr(rr), 360);
  for (std::size_t i = 0; i < iv.size(); ++i) EXPECT_EQ(iv[i].nn, i != 20) << i;
  iv = intervals_from_peaks(peaks_from_rr(std::vector<int>(40, 4 * 360)), 360);
  EXPECT_DOUBLE_EQ(nn_fraction(iv), 0.0);
}

TEST(DetectedRule, SpuriousDetectionSplitsAnInterval) {
  std::vector<int> rr(40, 300);
  rr[15] = 120;  // a T wave taken for a beat
  rr[16] = 180;
  const auto iv = intervals_from_peaks(peaks_from_rr(rr), 360);
  EXPECT_FALSE(iv[15].nn);
  EXPECT_FALSE(iv[16].nn);
  EXPECT_TRUE(iv[17].nn);
}

TEST(DetectedRule, GradualRateChangeIsFollowed) {
  std::vector<int> rr;
  for (int i = 0; i < 30; ++i) rr.push_back(300);
  for (int i = 0; i < 30; ++i) rr.push_back(300 - 4 * i);  // 300 -> 184 in 4-sample steps
  for (int i = 0; i < 30; ++i) rr.push_back(184);
  const auto iv = intervals_from_peaks(peaks_from_rr(rr), 360);
  EXPECT_GE(nn_fraction(iv), 0.98);
}

TEST(DetectedRule, SustainedFastRunIsExcludedThenAdopted) {
  std::vector<int> rr(20, 300);
  for (int i = 0; i < 60; ++i) rr.push_back(200);  // an abrupt run 33 % faster
  const auto iv = intervals_from_peaks(peaks_from_rr(rr), 360);
  EXPECT_FALSE(iv[20].nn);
  EXPECT_FALSE(iv[30].nn);
  EXPECT_TRUE(iv.back().nn);  // after rebase_beats short intervals the run is the new rhythm
}

// Sinus arrhythmia after a slower rhythm sets in: the reference restarts from the long
// interval and the ones that confirmed it, so the shorter beats of the new rhythm are not
// taken for premature beats. (Restarted from the long interval alone, the reference after
// 600, 540 was 570, and the 500 was rejected as premature, with the 540 after it.)
TEST(DetectedRule, IrregularSlowerRhythmIsAdoptedWhole) {
  std::vector<int> rr(20, 400);
  const int cycle[] = {600, 540, 500, 540};  // a breathing cycle of four beats
  for (int i = 0; i < 40; ++i) rr.push_back(cycle[i % 4]);
  const auto iv = intervals_from_peaks(peaks_from_rr(rr), 360);
  ASSERT_EQ(iv.size(), rr.size());
  for (std::size_t i = 20; i < iv.size(); ++i) EXPECT_TRUE(iv[i].nn) << "interval " << i;
}

// A long interval over a gap the detector found empty (a sinus pause, a blocked P wave) is NN,
// as the reference rule keeps it between two normal beats; the same interval without that
// evidence may hide a missed beat and is not (the old rule rejected both). The pause moves
// neither the reference nor the spread: the intervals after it are judged as before.
TEST(DetectedRule, ConfirmedPauseIsNnAndAnUnconfirmedOneIsNot) {
  std::vector<int> rr(40, 300);
  rr[10] = 600;  // a blocked beat: nothing in the gap
  rr[12] = 300;
  rr[25] = 600;  // the same length, but the detector saw something in the gap
  const auto peaks = peaks_from_rr(rr);
  const auto iv = intervals_from_peaks(peaks, {peaks[11]}, 360);
  ASSERT_EQ(iv.size(), rr.size());
  EXPECT_TRUE(iv[10].nn);
  EXPECT_FALSE(iv[25].nn);
  for (std::size_t i = 0; i < iv.size(); ++i)
    if (i != 25) {
      EXPECT_TRUE(iv[i].nn) << "interval " << i;
    }
  // Without the evidence, or with the rule's option off, the pause is rejected as before.
  EXPECT_FALSE(intervals_from_peaks(peaks, 360)[10].nn);
  NnRule off;
  off.keep_confirmed_pauses = false;
  EXPECT_FALSE(intervals_from_peaks(peaks, {peaks[11]}, 360, off)[10].nn);
}

// Consecutive blocked beats (2:1 conduction for a few beats) are all confirmed pauses, and the
// return to 1:1 is not taken for a premature beat: the reference stayed at the sinus rate.
TEST(DetectedRule, RunOfConfirmedPausesKeepsTheSinusReference) {
  std::vector<int> rr(30, 300);
  for (int i = 10; i < 14; ++i) rr[static_cast<std::size_t>(i)] = 600;
  const auto peaks = peaks_from_rr(rr);
  std::vector<std::int64_t> empty;
  for (int i = 11; i <= 14; ++i) empty.push_back(peaks[static_cast<std::size_t>(i)]);
  const auto iv = intervals_from_peaks(peaks, empty, 360);
  EXPECT_DOUBLE_EQ(nn_fraction(iv), 1.0);
}

// 2:1 AV block as in MIT-BIH 231: the first blocked interval hides its P wave (no evidence),
// so the slower rhythm is adopted from it and the three after it; the gaps of the slower
// rhythm held blocked P waves. When conduction returns to 1:1, the intervals are NN at once:
// the rule remembered the sinus reference. Without the P-wave evidence (an empty gap alone, as
// in a slow stretch of atrial fibrillation), with it behind too few of the slow intervals, or
// with the option off, the return is taken for premature beats until a run of them rebases
// the reference, as before.
TEST(DetectedRule, EndOfABlockedRunReturnsToTheRhythmBeforeIt) {
  std::vector<int> rr(20, 300);
  for (int i = 0; i < 12; ++i) rr.push_back(600);  // intervals 20..31: 2:1 conduction
  for (int i = 0; i < 25; ++i) rr.push_back(300 + (i % 3) * 4);  // 32..: 1:1 again
  const auto peaks = peaks_from_rr(rr);
  std::vector<std::int64_t> blocked;  // ends of intervals 21..31: a P wave in an empty gap
  for (std::size_t i = 22; i <= 32; ++i) blocked.push_back(peaks[i]);
  const auto iv = intervals_from_peaks(peaks, blocked, blocked, 360);
  ASSERT_EQ(iv.size(), rr.size());
  for (std::size_t i = 0; i < iv.size(); ++i) EXPECT_TRUE(iv[i].nn) << "interval " << i;

  const auto empty_only = intervals_from_peaks(peaks, blocked, 360);
  EXPECT_FALSE(empty_only[32].nn);
  EXPECT_FALSE(empty_only[33].nn);
  NnRule off;
  off.return_to_prior_rhythm = false;
  EXPECT_FALSE(intervals_from_peaks(peaks, blocked, blocked, 360, off)[32].nn);
  // A blocked P wave behind one of the twelve slow intervals is not enough (at least two, and a
  // third of them); behind four of them it is.
  const std::vector<std::int64_t> one(blocked.begin() + 5, blocked.begin() + 6);
  EXPECT_FALSE(intervals_from_peaks(peaks, blocked, one, 360)[32].nn);
  const std::vector<std::int64_t> three(blocked.begin() + 2, blocked.begin() + 5);
  EXPECT_FALSE(intervals_from_peaks(peaks, blocked, three, 360)[32].nn);
  const std::vector<std::int64_t> four(blocked.begin() + 2, blocked.begin() + 6);
  EXPECT_TRUE(intervals_from_peaks(peaks, blocked, four, 360)[32].nn);
}

// Atrial fibrillation after a slow stretch: the reference sat at the slow rhythm, and the
// faster, irregular intervals after it were each rejected as short, so that neither a run of
// agreeing short intervals nor a steady rhythm ever restarted it (MIT-BIH 219: no NN in its
// last 6 minutes, windows before them at 39 bpm against 70). After stale_reference_beats
// intervals in a row not NN and off the reference, it restarts from them.
TEST(DetectedRule, AReferenceNoIntervalComesNearRestartsFromTheRhythmThatFollows) {
  std::vector<int> rr(20, 540);  // 40 bpm at 360 Hz
  std::uint32_t state = 12345;
  for (int i = 0; i < 200; ++i) {  // irregular, 0.56 to 1.05 s: none agrees with the next within 12 %
    state = state * 1664525u + 1013904223u;
    rr.push_back(200 + static_cast<int>((state >> 8) % 181));
  }
  const auto peaks = peaks_from_rr(rr);
  auto nn_in_last = [&](const std::vector<Interval>& iv, std::size_t n) {
    return std::count_if(iv.end() - static_cast<std::ptrdiff_t>(n), iv.end(), [](const Interval& i) { return i.nn; });
  };
  const auto restarted = intervals_from_peaks(peaks, 360);
  ASSERT_EQ(restarted.size(), rr.size());
  EXPECT_GE(nn_in_last(restarted, 100), 80) << "the reference did not follow the new rhythm";
  NnRule never;
  never.stale_reference_beats = 0;
  EXPECT_LE(nn_in_last(intervals_from_peaks(peaks, 360, never), 100), 10) << "the case under test did not happen";
}

// A reference rebased on a run of short intervals is not remembered: in bigeminy it is the
// coupling interval, and a later "return" to it would be an ectopic beat.
TEST(DetectedRule, ReferenceFromShortIntervalsIsNotReturnedTo) {
  std::vector<int> rr(10, 400);
  for (int i = 0; i < 60; ++i) rr.push_back(250);  // a fast run, adopted after 20 short beats
  for (int i = 0; i < 8; ++i) rr.push_back(500);   // 70..77: slower, over blocked P waves
  for (int i = 0; i < 6; ++i) rr.push_back(250);
  const auto peaks = peaks_from_rr(rr);
  std::vector<std::int64_t> blocked;
  for (std::size_t i = 71; i <= 78; ++i) blocked.push_back(peaks[i]);
  const auto iv = intervals_from_peaks(peaks, blocked, blocked, 360);
  ASSERT_EQ(iv.size(), rr.size());
  EXPECT_TRUE(iv[69].nn);   // the fast run was adopted
  EXPECT_TRUE(iv[70].nn);   // and so is the slower rhythm
  EXPECT_FALSE(iv[78].nn);  // but the 250 after it is not a return
}

// A pause only counts after a normal interval: after a premature beat the long interval is its
// compensatory pause, empty or not, and after a reference rebased on a run of short intervals
// (bigeminy: the coupling interval) every compensatory pause is long and empty.
TEST(DetectedRule, PauseAfterAnEctopicBeatOrInBigeminyIsNotConfirmed) {
  std::vector<int> rr(30, 300);
  rr[10] = 200;  // premature
  rr[11] = 400;  // its pause, empty
  auto peaks = peaks_from_rr(rr);
  auto iv = intervals_from_peaks(peaks, {peaks[12]}, 360);
  EXPECT_FALSE(iv[11].nn);

  std::vector<int> big(10, 400);
  for (int i = 0; i < 30; ++i) big.push_back(i % 2 == 0 ? 250 : 550);  // N-V, V-N
  peaks = peaks_from_rr(big);
  std::vector<std::int64_t> all_empty(peaks.begin() + 1, peaks.end());
  iv = intervals_from_peaks(peaks, all_empty, 360);
  for (std::size_t i = 30; i < iv.size(); ++i)
    if (big[i] == 550) {
      EXPECT_FALSE(iv[i].nn) << "interval " << i;
    }
}

// An ectopic focus (junctional, atrial) that takes over from a regular sinus rhythm fires
// faster than the sinus node; after its run of premature beats it may go on only a little
// faster, no longer short enough to be rejected. Those intervals are not NN (the reference rule
// drops the ectopic beats) and do not move the reference, so the sinus rhythm is NN again as
// soon as it returns. Without the option they were kept as NN, and the reference drifted down.
TEST(DetectedRule, EarlyIntervalsAfterAnEctopicRunAreNotNn) {
  std::vector<int> rr;
  for (int i = 0; i < 30; ++i) rr.push_back(i % 2 ? 302 : 298);  // regular: spread 4 of 300
  for (int r : {220, 230, 215, 225}) rr.push_back(r);              // 30..33: the ectopic run
  for (int r : {272, 268, 277}) rr.push_back(r);                   // 34..36: the focus goes on
  for (int i = 0; i < 10; ++i) rr.push_back(i % 2 ? 302 : 298);  // 37..: sinus again
  const auto peaks = peaks_from_rr(rr);
  const auto iv = intervals_from_peaks(peaks, 360);
  ASSERT_EQ(iv.size(), rr.size());
  for (std::size_t i = 0; i < iv.size(); ++i) EXPECT_EQ(iv[i].nn, i < 30 || i > 36) << i;

  NnRule off;
  off.hold_after_ectopic_run = false;
  const auto kept = intervals_from_peaks(peaks, 360, off);
  for (std::size_t i = 34; i <= 36; ++i) EXPECT_TRUE(kept[i].nn) << i;
}

// The hold ends at the first interval at the sinus rate, and also after a steady rhythm
// (sinus_return_beats intervals in a row within tol_prem of each other), so a new, slightly
// faster rhythm is not held for long.
TEST(DetectedRule, HoldAfterAnEctopicRunEndsAtTheSinusRateOrASteadyRhythm) {
  std::vector<int> rr;
  for (int i = 0; i < 30; ++i) rr.push_back(i % 2 ? 302 : 298);
  for (int r : {220, 230, 215, 225}) rr.push_back(r);        // 30..33: the run
  for (int r : {270, 300, 272}) rr.push_back(r);             // 34 held, 35 sinus, 36 NN again
  for (int r : {220, 230, 215, 225}) rr.push_back(r);        // 37..40: another run
  for (int i = 0; i < 12; ++i) rr.push_back(276);            // 41..: a steady, faster rhythm
  const auto iv = intervals_from_peaks(peaks_from_rr(rr), 360);
  ASSERT_EQ(iv.size(), rr.size());
  EXPECT_FALSE(iv[34].nn);
  EXPECT_TRUE(iv[35].nn);
  EXPECT_TRUE(iv[36].nn);
  for (std::size_t i = 41; i <= 43; ++i) EXPECT_FALSE(iv[i].nn) << i;  // not steady yet
  for (std::size_t i = 44; i < iv.size(); ++i) EXPECT_TRUE(iv[i].nn) << i;
}

// What is not an ectopic run: short intervals of unrelated lengths (noise detections that split
// intervals), and a run out of an irregular rhythm (atrial fibrillation, marked sinus
// arrhythmia), where the reference rule keeps intervals of every length. An early interval
// after either is judged as before.
TEST(DetectedRule, SplitIntervalsOrAnIrregularRhythmAreNoEctopicRun) {
  std::vector<int> rr;
  for (int i = 0; i < 30; ++i) rr.push_back(i % 2 ? 302 : 298);
  for (int r : {80, 220, 170, 130, 60, 240}) rr.push_back(r);  // 30..35: noise splits three
  for (int r : {272, 300, 300}) rr.push_back(r);               // 36: early but not short
  auto iv = intervals_from_peaks(peaks_from_rr(rr), 360);
  ASSERT_EQ(iv.size(), rr.size());
  EXPECT_TRUE(iv[36].nn);

  rr.clear();
  for (int i = 0; i < 30; ++i) rr.push_back(i % 2 ? 306 : 294);  // spread 12: 4 % of 300
  for (int r : {200, 205, 195, 200}) rr.push_back(r);            // 30..33: short, agreeing
  for (int r : {265, 300, 294}) rr.push_back(r);                 // 34: early but not short
  const auto peaks = peaks_from_rr(rr);
  iv = intervals_from_peaks(peaks, 360);
  ASSERT_EQ(iv.size(), rr.size());
  EXPECT_TRUE(iv[34].nn);
  NnRule wider;  // the same rhythm counted as regular: the interval is held
  wider.regular_spread = 0.05;
  EXPECT_FALSE(intervals_from_peaks(peaks, 360, wider)[34].nn);
}

TEST(DetectedRule, ExcludedRangesApply) {
  const std::vector<int> rr(20, 300);
  const auto peaks = peaks_from_rr(rr);
  const auto iv = intervals_from_peaks(peaks, 360, {}, {{peaks[5] + 1, peaks[5] + 2}});
  EXPECT_FALSE(iv[5].nn);
  EXPECT_TRUE(iv[4].nn);
  EXPECT_TRUE(iv[6].nn);
}

TEST(DetectedRule, DegenerateInput) {
  EXPECT_TRUE(intervals_from_peaks({}, 360).empty());
  EXPECT_TRUE(intervals_from_peaks({7}, 360).empty());
  EXPECT_TRUE(intervals_from_peaks({1, 2, 3}, 0).empty());
  const auto iv = intervals_from_peaks({100, 100, 400}, 360);
  ASSERT_EQ(iv.size(), 2u);
  EXPECT_FALSE(iv[0].nn);
}

}  // namespace
}  // namespace tahvel::aggregation
