// NnClassifier (rr.h) on the MIT-BIH Arrhythmia Database: for every record in RECORDS, the
// peaks detected on lead 0 (detect_r_peaks) streamed into the classifier — one by one, and in
// the groups a 1-second chunked detector would hand over — give exactly intervals_from_peaks,
// each decision within the documented delay; and a decision taken on a prefix of the peaks
// (the record cut short) is never changed by the peaks after it, except in the last D
// positive-length intervals of the prefix that finish() decided without their look-ahead.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "../aggregation/mitdb_support.h"
#include "tahvel/aggregation/rpeak.h"
#include "tahvel/aggregation/rr.h"
#include "tahvel/aggregation/wfdb.h"

namespace tahvel::aggregation {
namespace {

using testing::mitdb_record;
using testing::mitdb_records;

struct Detected {
  std::vector<std::int64_t> peaks;
  double fs = 0;
};

Detected detect(const std::string& name) {
  auto signals = read_signals(mitdb_record(name));
  EXPECT_TRUE(signals.has_value()) << (signals ? "" : signals.error().message);
  if (!signals || signals->samples.empty()) return {};
  DetectorOptions o;
  o.fs = signals->header.fs;
  o.gain = signals->header.signals[0].gain;
  return {detect_r_peaks(signals->samples[0], o), o.fs};
}

std::size_t delay_bound(const NnRule& rule) {
  const auto at_least_1 = [](int v) { return static_cast<std::size_t>(std::max(v, 1)); };
  return std::max({at_least_1(rule.sustained_beats), at_least_1(rule.reference_beats) - 1,
                   std::size_t{1}});
}

// Index of the first interval that finish() may have decided without its full look-ahead when
// the stream ends at peaks[k - 1]: the D positive-length intervals before the end, and any
// zero-length ones among them.
std::size_t settled_before(const std::vector<std::int64_t>& peaks, std::size_t k, std::size_t d) {
  std::size_t i = k - 1;  // intervals 0 .. k - 2
  for (std::size_t positive = 0; i > 0 && positive < d + 1; --i) {
    positive += peaks[i] > peaks[i - 1] ? 1 : 0;
  }
  return i;
}

void expect_same(const std::vector<Interval>& got, const std::vector<Interval>& want,
                 std::size_t count, const std::string& what) {
  ASSERT_GE(got.size(), count) << what;
  ASSERT_GE(want.size(), count) << what;
  for (std::size_t i = 0; i < count; ++i) {
    ASSERT_TRUE(got[i].start == want[i].start && got[i].end == want[i].end &&
                got[i].nn == want[i].nn)
        << what << ": interval " << i << " (" << got[i].start << ", " << got[i].end << ") nn "
        << got[i].nn << " vs nn " << want[i].nn;
  }
}

TEST(NnClassifierMitdb, StreamingEqualsBatchOnDetectedPeaksOfEveryRecord) {
  const std::vector<std::string> names = mitdb_records();
  if (names.empty()) GTEST_SKIP() << "MIT-BIH records not found (set TAHVEL_MITDB)";
  const std::size_t d = delay_bound(NnRule{});
  for (const std::string& name : names) {
    SCOPED_TRACE("record " + name);
    const Detected r = detect(name);
    ASSERT_GT(r.peaks.size(), 100u);
    const std::vector<Interval> batch = intervals_from_peaks(r.peaks, r.fs);
    ASSERT_EQ(batch.size(), r.peaks.size() - 1);

    // One by one, with the decision delay and the held intervals checked after every push.
    NnClassifier one(r.fs);
    std::vector<Interval> streamed;
    std::size_t max_pending = 0;
    for (std::size_t k = 0; k < r.peaks.size(); ++k) {
      one.push(r.peaks[k], streamed);
      max_pending = std::max(max_pending, one.pending());
      if (k >= 1) {
        ASSERT_GE(streamed.size() + d, k) << "decisions late after peak " << k;
      }
    }
    one.finish(streamed);
    expect_same(streamed, batch, batch.size(), "one by one");
    EXPECT_EQ(streamed.size(), batch.size());
    EXPECT_LE(max_pending, d);

    // In the groups of 1-second chunks, the decided intervals collected per chunk.
    NnClassifier chunked(r.fs);
    std::vector<Interval> all, chunk;
    const auto second = static_cast<std::int64_t>(r.fs);
    std::size_t k = 0;
    for (std::int64_t end = second; k < r.peaks.size(); end += second) {
      chunk.clear();
      while (k < r.peaks.size() && r.peaks[k] < end) chunked.push(r.peaks[k++], chunk);
      all.insert(all.end(), chunk.begin(), chunk.end());
    }
    chunked.finish(all);
    expect_same(all, batch, batch.size(), "1-second chunks");

    // The record cut short at a few points: everything settled before the cut agrees.
    for (const std::size_t cut : {r.peaks.size() / 7, r.peaks.size() / 3, r.peaks.size() / 2}) {
      const std::vector<std::int64_t> prefix(r.peaks.begin(),
                                             r.peaks.begin() + static_cast<std::ptrdiff_t>(cut));
      expect_same(intervals_from_peaks(prefix, r.fs), batch, settled_before(r.peaks, cut, d),
                  "cut at peak " + std::to_string(cut));
    }
    if (HasFatalFailure()) return;
  }
}

// With the detector's gap evidence (empty gaps, blocked P waves), as `tahvel hrv` and the
// agents use it: the stream fed one peak at a time with its flags equals the batch function,
// within the same delay, on every record; and the evidence matters somewhere (231: its 2:1
// block), so the comparison is not the evidence-free one above again.
TEST(NnClassifierMitdb, StreamingWithGapEvidenceEqualsBatchOnEveryRecord) {
  const std::vector<std::string> names = mitdb_records();
  if (names.empty()) GTEST_SKIP() << "MIT-BIH records not found (set TAHVEL_MITDB)";
  const std::size_t d = delay_bound(NnRule{});
  std::size_t records_changed = 0;
  for (const std::string& name : names) {
    SCOPED_TRACE("record " + name);
    auto signals = read_signals(mitdb_record(name));
    ASSERT_TRUE(signals.has_value());
    DetectorOptions o;
    o.fs = signals->header.fs;
    o.gain = signals->header.signals[0].gain;
    const Detection det = detect_beats(signals->samples[0], o);
    ASSERT_GT(det.peaks.size(), 100u);
    const std::vector<Interval> batch =
        intervals_from_peaks(det.peaks, det.empty_gap_ends, det.p_wave_gap_ends, o.fs);
    ASSERT_EQ(batch.size(), det.peaks.size() - 1);
    const std::vector<Interval> empty_only =
        intervals_from_peaks(det.peaks, det.empty_gap_ends, o.fs);
    records_changed += std::equal(batch.begin(), batch.end(), empty_only.begin(),
                                  [](const Interval& a, const Interval& b) { return a.nn == b.nn; })
                           ? 0
                           : 1;
    NnClassifier one(o.fs);
    std::vector<Interval> streamed;
    std::size_t next_empty = 0, next_p = 0, max_pending = 0;
    for (std::size_t k = 0; k < det.peaks.size(); ++k) {
      const std::int64_t p = det.peaks[k];
      const bool empty =
          next_empty < det.empty_gap_ends.size() && det.empty_gap_ends[next_empty] == p;
      const bool p_wave = next_p < det.p_wave_gap_ends.size() && det.p_wave_gap_ends[next_p] == p;
      next_empty += empty ? 1 : 0;
      next_p += p_wave ? 1 : 0;
      one.push(p, empty, p_wave, streamed);
      max_pending = std::max(max_pending, one.pending());
      if (k >= 1) {
        ASSERT_GE(streamed.size() + d, k) << "decisions late after peak " << k;
      }
    }
    EXPECT_EQ(next_empty, det.empty_gap_ends.size()) << "empty-gap ends not a subset of the peaks";
    EXPECT_EQ(next_p, det.p_wave_gap_ends.size()) << "P-wave gap ends not a subset of the peaks";
    one.finish(streamed);
    expect_same(streamed, batch, batch.size(), "one by one with evidence");
    EXPECT_EQ(streamed.size(), batch.size());
    EXPECT_LE(max_pending, d);
    if (HasFatalFailure()) return;
  }
  EXPECT_GE(records_changed, 1u);
}

}  // namespace
}  // namespace tahvel::aggregation
