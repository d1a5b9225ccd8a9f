// Beat-by-beat scoring of a QRS detector against reference annotations, for the gross QRS
// sensitivity and positive predictivity of ANSI/AAMI EC38 and EC57, following WFDB's `bxb`.
// Pure function, linear in the number of beats (after sorting the detections).
//
// The matching rule (bxb's, with the project's convention for unreadable signal):
//  * Reference beats are the annotations with is_beat(code). Those inside an unreadable
//    interval (unreadable_intervals()) are dropped, and, when exclude_flutter is set (the
//    default, as in bxb), so are those inside a ventricular flutter episode ('[' to ']').
//  * The two sequences are merged in time order, always looking at the earliest unpaired
//    reference beat T and detection t, and at the next of each (T', t'). Let w be the match
//    window in samples (round(match_window_s * fs); 54 samples at 360 Hz).
//      - if t < T: t and T are paired when T - t <= w and t is the better partner for T, that is
//        T - t < |T - t'| or the next detection t' is closer to the next reference T'
//        (|T' - t'| < |T - t'|); otherwise t is a false positive.
//      - if t >= T: symmetrically, paired when t - T <= w and (t - T < |t - T'| or
//        |t' - T'| < |t - T'|); otherwise T is a false negative (missed beat).
//    So each reference beat and each detection is used at most once, and a beat goes to the
//    closest detection within the window (a difference of exactly w still matches).
//  * Scoring starts at start = round(start_s * fs) (bxb: 5 minutes): reference beats before it
//    are ignored. As in bxb, the last detection before `start` may still pair with the first
//    reference beat at or after it (and then counts as a true positive), and a detection within
//    w after `start` that is a worse partner for the first reference beat than the detection
//    after it is dropped uncounted (it belongs to a reference beat before `start`).
//  * Scoring stops once both the reference beat and the detection under consideration are
//    after end = round(*end_s * fs) (bxb's -t; pairs straddling the end are still counted);
//    without end_s, once both sequences are used up.
//  * A detection left unpaired inside an unreadable interval, or (with exclude_flutter) inside a
//    flutter episode, is not counted. Here the project's convention differs from bxb, which
//    counts detections during reference-marked shutdown against positive predictivity; bxb does
//    not count them during flutter. An unreadable interval still open at the last annotation
//    runs to the end of scoring (end, or the last reference annotation or detection).
#pragma once

#include <cstdint>
#include <optional>
#include <vector>

#include "tahvel/aggregation/annotations.h"

namespace tahvel::aggregation {

struct ScoreOptions {
  double match_window_s = 0.150;  // EC38/EC57: 150 ms
  double start_s = 300;           // EC38/EC57: the first 5 minutes are a learning period
  std::optional<double> end_s;    // none: to the end of both sequences
  bool exclude_flutter = true;    // bxb: ignore reference beats in '[' ... ']', and unpaired
                                  // detections there
};

struct BeatScore {
  std::int64_t tp = 0;  // reference beats paired with a detection
  std::int64_t fn = 0;  // reference beats without a detection
  std::int64_t fp = 0;  // detections without a reference beat

  // tp / (tp + fn) and tp / (tp + fp), as fractions; NaN when the denominator is 0
  // (bxb prints "-").
  double sensitivity() const;
  double positive_predictivity() const;

  // Adds another record's counts: gross statistics are computed from the summed counts.
  BeatScore& operator+=(const BeatScore& other);
};

// Scores `detected` (sample indices of detected beats, in any order; duplicates count as extra
// detections) against the beat annotations of `reference` (in file order, as read_annotations()
// returns them), at sampling frequency fs (> 0). See the rule above.
BeatScore score_beats(const std::vector<Annotation>& reference,
                      const std::vector<std::int64_t>& detected, double fs,
                      const ScoreOptions& options = {});

}  // namespace tahvel::aggregation
