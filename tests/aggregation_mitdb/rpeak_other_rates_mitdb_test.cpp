// The R-peak detector on real ECG at sampling rates other than MIT-BIH's 360 Hz. Other
// databases and devices record at 128 Hz (Holter, nsrdb), 250 Hz (afdb, many patches),
// 500 or 1000 Hz (12-lead carts): the detector's filters and windows are defined in seconds,
// so it must find the same beats there. Every shared record is band-limited and resampled
// (windowed-sinc interpolation, cut-off at 0.45 of the lower rate) to each rate, its
// annotations moved to the new sample grid, and scored as at 360 Hz (score_beats: bxb's rule).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <numbers>
#include <numeric>
#include <string>
#include <vector>

#include "../aggregation/mitdb_support.h"
#include "mitdb_eval.h"
#include "tahvel/aggregation/annotations.h"
#include "tahvel/aggregation/rpeak.h"
#include "tahvel/aggregation/score.h"
#include "tahvel/aggregation/wfdb.h"

namespace tahvel::aggregation {
namespace {

using testing::mitdb_record;
using testing::mitdb_records;
using testing::moved;
using testing::resample;

class RPeakAtOtherRates : public ::testing::TestWithParam<int> {};

TEST_P(RPeakAtOtherRates, GrossSensitivityAndPositivePredictivityAtLeast99_5Percent) {
  const int fs = GetParam();
  const std::vector<std::string> names = mitdb_records();
  if (names.empty()) GTEST_SKIP() << "MIT-BIH records not found (set TAHVEL_MITDB)";
  BeatScore gross;
  for (const std::string& name : names) {
    auto signals = read_signals(mitdb_record(name));
    ASSERT_TRUE(signals.has_value()) << signals.error().message;
    auto reference = read_annotations(mitdb_record(name));
    ASSERT_TRUE(reference.has_value()) << reference.error().message;
    const auto fs_in = static_cast<int>(signals->header.fs);
    ASSERT_EQ(fs_in, signals->header.fs) << name << ": a whole-hertz rate";
    DetectorOptions o;
    o.fs = fs;
    o.gain = signals->header.signals[0].gain;
    const std::vector<std::int32_t> lead = resample(signals->samples[0], fs_in, fs);
    const BeatScore s = score_beats(moved(*reference, fs_in, fs), detect_r_peaks(lead, o), fs);
    std::printf("%s at %d Hz  TP %5lld  FN %3lld  FP %3lld\n", name.c_str(), fs,
                static_cast<long long>(s.tp), static_cast<long long>(s.fn),
                static_cast<long long>(s.fp));
    gross += s;
  }
  const double se = 100 * gross.sensitivity(), ppv = 100 * gross.positive_predictivity();
  std::printf("gross at %d Hz over %zu records: TP %lld FN %lld FP %lld  Se %.3f %%  +P %.3f %%\n",
              fs, names.size(), static_cast<long long>(gross.tp),
              static_cast<long long>(gross.fn), static_cast<long long>(gross.fp), se, ppv);
  EXPECT_GE(se, 99.5) << "gross sensitivity at " << fs << " Hz";
  EXPECT_GE(ppv, 99.5) << "gross positive predictivity at " << fs << " Hz";
}

INSTANTIATE_TEST_SUITE_P(Rates, RPeakAtOtherRates, ::testing::Values(128, 250, 500, 1000),
                         [](const auto& info) { return std::to_string(info.param) + "Hz"; });

}  // namespace
}  // namespace tahvel::aggregation
