// Beat-by-beat scoring (bxb rule): small synthetic cases at 1000 Hz, where one sample is one
// millisecond, so the 150 ms window edges are exact; a differential check against a naive
// closest-match model where beats are far apart; and record 100 scored against itself.
#include "tahvel/aggregation/score.h"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <random>
#include <vector>

#include "mitdb_support.h"

namespace tahvel::aggregation {
namespace {

constexpr double kFs = 1000;  // 1 sample = 1 ms

Annotation ann(std::int64_t sample, char code, int subtype = 0) {
  Annotation a;
  a.sample = sample;
  a.code = code;
  a.type = annotation_type(code);
  a.subtype = subtype;
  return a;
}

std::vector<Annotation> beats(const std::vector<std::int64_t>& samples, char code = 'N') {
  std::vector<Annotation> out;
  for (auto s : samples) out.push_back(ann(s, code));
  return out;
}

ScoreOptions from_zero() {
  ScoreOptions o;
  o.start_s = 0;
  return o;
}

void expect_score(const BeatScore& s, std::int64_t tp, std::int64_t fn, std::int64_t fp) {
  EXPECT_EQ(s.tp, tp);
  EXPECT_EQ(s.fn, fn);
  EXPECT_EQ(s.fp, fp);
}

TEST(Score, ExactMatchesAreAllTruePositives) {
  auto ref = beats({1000, 2000, 3000, 4000});
  auto s = score_beats(ref, {1000, 2000, 3000, 4000}, kFs, from_zero());
  expect_score(s, 4, 0, 0);
  EXPECT_DOUBLE_EQ(s.sensitivity(), 1.0);
  EXPECT_DOUBLE_EQ(s.positive_predictivity(), 1.0);
}

TEST(Score, DetectionOff149msMatchesEitherSide) {
  auto ref = beats({1000, 2000});
  expect_score(score_beats(ref, {1149, 1851}, kFs, from_zero()), 2, 0, 0);
}

TEST(Score, DetectionOffExactly150msStillMatches) {
  expect_score(score_beats(beats({1000}), {1150}, kFs, from_zero()), 1, 0, 0);
}

TEST(Score, DetectionOff151msIsOneMissAndOneFalsePositive) {
  expect_score(score_beats(beats({1000}), {1151}, kFs, from_zero()), 0, 1, 1);
  expect_score(score_beats(beats({1000}), {849}, kFs, from_zero()), 0, 1, 1);
}

TEST(Score, ExtraDetectionIsAFalsePositive) {
  auto s = score_beats(beats({1000, 2000}), {1000, 1500, 2000}, kFs, from_zero());
  expect_score(s, 2, 0, 1);
  EXPECT_DOUBLE_EQ(s.positive_predictivity(), 2.0 / 3.0);
}

TEST(Score, MissingDetectionIsAFalseNegative) {
  auto s = score_beats(beats({1000, 2000, 3000}), {1000, 3000}, kFs, from_zero());
  expect_score(s, 2, 1, 0);
  EXPECT_DOUBLE_EQ(s.sensitivity(), 2.0 / 3.0);
}

TEST(Score, DuplicateDetectionIsUsedOnceAndTheOtherIsAFalsePositive) {
  expect_score(score_beats(beats({1000}), {1000, 1000}, kFs, from_zero()), 1, 0, 1);
}

TEST(Score, ClosestOfTwoDetectionsInTheWindowMatches) {
  // 950 and 990 are both within 150 ms of 1000; 990 is closer, 950 is the extra one.
  expect_score(score_beats(beats({1000}), {950, 990}, kFs, from_zero()), 1, 0, 1);
  expect_score(score_beats(beats({1000}), {1010, 1100}, kFs, from_zero()), 1, 0, 1);
}

TEST(Score, OneDetectionBetweenTwoCloseBeatsMatchesOnlyTheCloserOne) {
  // Beats 200 ms apart, one detection 80 ms after the first: it pairs with the first (closer),
  // the second beat is missed.
  expect_score(score_beats(beats({1000, 1200}), {1080}, kFs, from_zero()), 1, 1, 0);
}

TEST(Score, BxbLookAheadPairsWhenNextPairIsCloser) {
  // bxb's 2002 refinement (scaled from its comment: window 37, ref 96/160, test 128/185): both
  // pairs match although test1 is equally far from ref1 and ref2.
  ScoreOptions o = from_zero();
  o.match_window_s = 0.037;
  expect_score(score_beats(beats({96, 160}), {128, 185}, kFs, o), 2, 0, 0);
}

TEST(Score, DetectionsInOrderOrNotScoreTheSame) {
  auto ref = beats({1000, 2000, 3000});
  expect_score(score_beats(ref, {3000, 1000, 2000}, kFs, from_zero()), 3, 0, 0);
}

TEST(Score, OnlyBeatAnnotationsAreReferenceBeats) {
  std::vector<Annotation> ref = {ann(500, '+'), ann(1000, 'N'), ann(1500, '!'), ann(2000, 'V'),
                                 ann(2500, '|'), ann(3000, 'x')};
  // detections at the non-beat annotations are false positives
  expect_score(score_beats(ref, {1000, 2000, 2500, 3000}, kFs, from_zero()), 2, 0, 2);
}

TEST(Score, UnreadableIntervalExcludesReferenceBeatsAndDetectionsInside) {
  std::vector<Annotation> ref = {ann(1000, 'N'),      ann(2000, 'N'), ann(2500, '~', 0x30),
                                 ann(3000, 'N'),      ann(4000, 'N'), ann(4500, '~', 0),
                                 ann(5000, 'N'),      ann(6000, 'N')};
  // Inside [2500, 4500]: beats 3000 and 4000 are not scored, nor the detections at 3300, 3600.
  auto s = score_beats(ref, {1000, 2000, 3300, 3600, 5000, 6000}, kFs, from_zero());
  expect_score(s, 4, 0, 0);
  // Without the detections inside, nothing is missed either.
  expect_score(score_beats(ref, {1000, 2000, 5000, 6000}, kFs, from_zero()), 4, 0, 0);
}

TEST(Score, NoiseWithoutBothBits4And5DoesNotExclude) {
  std::vector<Annotation> ref = {ann(1000, 'N'), ann(1500, '~', 0x20), ann(2000, 'N'),
                                 ann(2500, '~', 0)};
  expect_score(score_beats(ref, {1000, 1700}, kFs, from_zero()), 1, 1, 1);
}

TEST(Score, UnreadableIntervalLeftOpenExcludesToTheEnd) {
  std::vector<Annotation> ref = {ann(1000, 'N'), ann(1500, '~', 0x30), ann(2000, 'N')};
  expect_score(score_beats(ref, {1000, 2500, 9000}, kFs, from_zero()), 1, 0, 0);
}

TEST(Score, FlutterEpisodeExcludedByDefaultAsInBxb) {
  std::vector<Annotation> ref = {ann(1000, 'N'), ann(1500, '['), ann(1600, '!'),
                                 ann(1800, 'V'), ann(2000, ']'), ann(3000, 'N')};
  expect_score(score_beats(ref, {1000, 1600, 1900, 3000}, kFs, from_zero()), 2, 0, 0);
  ScoreOptions o = from_zero();
  o.exclude_flutter = false;  // then 1800 'V' is a beat: 1900 pairs with it, 1600 is extra
  expect_score(score_beats(ref, {1000, 1600, 1900, 3000}, kFs, o), 3, 0, 1);
}

TEST(Score, ScoringStartsAtFiveMinutesByDefault) {
  const double fs = 360;
  const std::int64_t five_min = 300 * 360;
  auto ref = beats({1000, 50000, five_min - 200, five_min, five_min + 300, five_min + 600});
  // Missing and extra detections before 5 min do not count; from 5 min on all match.
  auto s = score_beats(ref, {1000, 20000, 30000, five_min, five_min + 300, five_min + 600}, fs);
  expect_score(s, 3, 0, 0);
  // A missed beat after 5 min counts.
  expect_score(score_beats(ref, {five_min, five_min + 600}, fs), 2, 1, 0);
}

TEST(Score, DetectionJustBeforeStartMayPairWithTheFirstBeatAfterIt) {
  ScoreOptions o;
  o.start_s = 10;  // 10000 samples at 1 kHz
  expect_score(score_beats(beats({10020, 11000}), {9990, 11000}, kFs, o), 2, 0, 0);
}

TEST(Score, DetectionJustAfterStartBelongingToABeatBeforeItIsNotCounted) {
  ScoreOptions o;
  o.start_s = 10;
  // Beat 9960 is before start; its detection 10010 lands after start. The first beat after
  // start (10400) is closer to the next detection (10400): 10010 is dropped uncounted.
  expect_score(score_beats(beats({9960, 10400}), {10010, 10400}, kFs, o), 1, 0, 0);
}

TEST(Score, EndStopsScoring) {
  ScoreOptions o = from_zero();
  o.end_s = 2.5;
  expect_score(score_beats(beats({1000, 2000, 3000, 4000}), {1000, 2000, 5000}, kFs, o), 2, 0, 0);
}

TEST(Score, EmptyInputsGiveZeroCountsAndUndefinedRates) {
  auto s = score_beats({}, {}, kFs, from_zero());
  expect_score(s, 0, 0, 0);
  EXPECT_TRUE(std::isnan(s.sensitivity()));
  EXPECT_TRUE(std::isnan(s.positive_predictivity()));
  expect_score(score_beats({}, {1000, 2000}, kFs, from_zero()), 0, 0, 2);
  expect_score(score_beats(beats({100, 200}), {}, kFs, from_zero()), 0, 2, 0);
}

TEST(Score, PlusEqualsSumsCountsForGrossStatistics) {
  BeatScore a{90, 10, 0}, b{10, 0, 10};
  a += b;
  expect_score(a, 100, 10, 10);
  EXPECT_DOUBLE_EQ(a.sensitivity(), 100.0 / 110.0);
  EXPECT_DOUBLE_EQ(a.positive_predictivity(), 100.0 / 110.0);
}

// Differential: with reference beats at least 4 windows apart, bxb's rule reduces to "a
// detection matches the closest beat within the window, the closest detection wins".
TEST(Score, AgreesWithNaiveClosestMatchWhenBeatsAreFarApart) {
  std::mt19937_64 rng(12345);
  for (int trial = 0; trial < 200; ++trial) {
    std::vector<std::int64_t> ref_times, det;
    std::int64_t t = 0;
    for (int k = 0; k < 50; ++k) {
      t += 700 + static_cast<std::int64_t>(rng() % 600);
      ref_times.push_back(t);
      int what = static_cast<int>(rng() % 10);
      if (what == 0) continue;  // missed
      det.push_back(t + static_cast<std::int64_t>(rng() % 341) - 170);  // maybe out of window
      if (what == 1) det.push_back(t + 300 + static_cast<std::int64_t>(rng() % 50));  // extra
    }
    BeatScore naive;
    std::vector<bool> used(det.size(), false);
    for (auto T : ref_times) {
      std::ptrdiff_t best = -1;
      for (std::size_t i = 0; i < det.size(); ++i)
        if (!used[i] && std::llabs(det[i] - T) <= 150 &&
            (best < 0 || std::llabs(det[i] - T) < std::llabs(det[static_cast<std::size_t>(best)] - T)))
          best = static_cast<std::ptrdiff_t>(i);
      if (best >= 0) used[static_cast<std::size_t>(best)] = true, ++naive.tp;
      else ++naive.fn;
    }
    for (bool u : used) naive.fp += u ? 0 : 1;
    auto s = score_beats(beats(ref_times), det, kFs, from_zero());
    ASSERT_EQ(s.tp, naive.tp) << "trial " << trial;
    ASSERT_EQ(s.fn, naive.fn) << "trial " << trial;
    ASSERT_EQ(s.fp, naive.fp) << "trial " << trial;
  }
}

TEST(ScoreRecord100, ReferenceAgainstItselfIsPerfectAndShiftedBy50msStillMatches) {
  namespace fs = std::filesystem;
  if (!fs::exists(testing::mitdb_dir() / "100.atr")) GTEST_SKIP() << "MIT-BIH not found";
  auto a = read_annotations(testing::mitdb_record("100"));
  ASSERT_TRUE(a) << a.error().message;
  std::vector<std::int64_t> det;
  std::int64_t after_start = 0;
  for (const auto& x : *a)
    if (is_beat(x.code)) {
      det.push_back(x.sample);
      if (x.sample >= 300 * 360) ++after_start;
    }
  expect_score(score_beats(*a, det, 360), after_start, 0, 0);
  for (auto& s : det) s += 18;  // 50 ms late
  expect_score(score_beats(*a, det, 360), after_start, 0, 0);
  for (auto& s : det) s += 37;  // 152.8 ms late: nothing matches
  expect_score(score_beats(*a, det, 360), 0, after_start, after_start);
}

}  // namespace
}  // namespace tahvel::aggregation
