// The R-peak detector on the MIT-BIH Arrhythmia Database (the records in RECORDS, first
// channel), scored as bxb does (score_beats: 150 ms, from 5 minutes in, unreadable and flutter
// intervals skipped): the gross sensitivity and positive predictivity the project promises
// (docs/rpeak.md), RR intervals of normal beats as the annotations give them, and identical
// output under any chunking on real records.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstdint>
#include <cstdio>
#include <numbers>
#include <string>
#include <vector>

#include "../aggregation/mitdb_support.h"
#include "tahvel/aggregation/annotations.h"
#include "tahvel/aggregation/rpeak.h"
#include "tahvel/aggregation/rr.h"
#include "tahvel/aggregation/score.h"
#include "tahvel/aggregation/wfdb.h"

namespace tahvel::aggregation {
namespace {

using testing::mitdb_record;
using testing::mitdb_records;

struct Record {
  std::vector<std::int32_t> lead;  // first channel
  double fs = 0;
  double gain = 0;
};

Record load(const std::string& name) {
  auto signals = read_signals(mitdb_record(name));
  EXPECT_TRUE(signals.has_value()) << (signals ? "" : signals.error().message);
  if (!signals || signals->samples.empty()) return {};
  return {std::move(signals->samples[0]), signals->header.fs, signals->header.signals[0].gain};
}

DetectorOptions options_for(const Record& r) {
  DetectorOptions o;
  o.fs = r.fs;
  o.gain = r.gain;
  return o;
}

TEST(RPeakMitdb, GrossSensitivityAndPositivePredictivityAtLeast99_7Percent) {
  const std::vector<std::string> names = mitdb_records();
  if (names.empty()) GTEST_SKIP() << "MIT-BIH records not found (set TAHVEL_MITDB)";
  BeatScore gross;
  for (const std::string& name : names) {
    const Record r = load(name);
    ASSERT_FALSE(r.lead.empty()) << name;
    auto reference = read_annotations(mitdb_record(name));
    ASSERT_TRUE(reference.has_value()) << reference.error().message;
    const BeatScore s = score_beats(*reference, detect_r_peaks(r.lead, options_for(r)), r.fs);
    std::printf("%s  TP %5lld  FN %3lld  FP %3lld\n", name.c_str(), static_cast<long long>(s.tp),
                static_cast<long long>(s.fn), static_cast<long long>(s.fp));
    gross += s;
  }
  const double se = 100 * gross.sensitivity(), ppv = 100 * gross.positive_predictivity();
  std::printf("gross over %zu records: TP %lld FN %lld FP %lld  Se %.3f %%  +P %.3f %%\n",
              names.size(), static_cast<long long>(gross.tp), static_cast<long long>(gross.fn),
              static_cast<long long>(gross.fp), se, ppv);
  RecordProperty("gross_se_percent", std::to_string(se));
  RecordProperty("gross_ppv_percent", std::to_string(ppv));
  EXPECT_GE(se, 99.7) << "gross sensitivity";
  EXPECT_GE(ppv, 99.7) << "gross positive predictivity";
}

// Gross score of every record's lead `signal`, each first changed by `change`; prints it.
template <class Change>
BeatScore gross_score(const std::vector<std::string>& names, std::size_t signal, const char* what,
                      Change change) {
  BeatScore gross;
  for (const std::string& name : names) {
    auto signals = read_signals(mitdb_record(name));
    EXPECT_TRUE(signals.has_value()) << (signals ? "" : signals.error().message);
    if (!signals || signals->samples.size() <= signal) continue;
    Record r{std::move(signals->samples[signal]), signals->header.fs,
             signals->header.signals[signal].gain};
    change(r);
    auto reference = read_annotations(mitdb_record(name));
    EXPECT_TRUE(reference.has_value()) << reference.error().message;
    if (!reference) continue;
    gross += score_beats(*reference, detect_r_peaks(r.lead, options_for(r)), r.fs);
  }
  std::printf("gross%s: TP %lld FN %lld FP %lld  Se %.3f %%  +P %.3f %%\n", what,
              static_cast<long long>(gross.tp), static_cast<long long>(gross.fn),
              static_cast<long long>(gross.fp), 100 * gross.sensitivity(),
              100 * gross.positive_predictivity());
  return gross;
}

// The floor under which a peak is never a beat follows the lead's own amplitude
// (DetectorOptions::min_qrs_mv, docs/rpeak.md step 3). Every record's samples at a quarter of
// their amplitude (QRS of 0.2-0.5 mV, as on a low-voltage ECG; the header's gain unchanged)
// score nearly as at their own: 99.6 / 99.9 % against 99.86 / 99.86. With the fixed 0.15 mV
// floor before, 91.7 % of the beats were found.
TEST(RPeakMitdb, AQuarterOfTheAmplitudeStillFindsTheBeats) {
  const std::vector<std::string> names = mitdb_records();
  if (names.empty()) GTEST_SKIP() << "MIT-BIH records not found (set TAHVEL_MITDB)";
  const BeatScore s = gross_score(names, 0, " at a quarter of the amplitude", [](Record& r) {
    for (std::int32_t& x : r.lead) x = static_cast<std::int32_t>(std::lround(0.25 * x));
  });
  EXPECT_GE(100 * s.sensitivity(), 99.5);
  EXPECT_GE(100 * s.positive_predictivity(), 99.5);
}

// The floor follows the lead down when it drops in the middle of a record (an electrode moved,
// the patient turned): every record's second half at 0.3 of its amplitude. Measured on 100,
// 105, 119, 201 and 214 written out so: at most 4 beats of a record lost to the step.
TEST(RPeakMitdb, AnAmplitudeDropMidRecordLosesOnlyTheBeatsOfTheRelearning) {
  const std::vector<std::string> names = mitdb_records();
  if (names.empty()) GTEST_SKIP() << "MIT-BIH records not found (set TAHVEL_MITDB)";
  const BeatScore s = gross_score(names, 0, " with the second half at 0.3 of the amplitude", [](Record& r) {
    for (std::size_t i = r.lead.size() / 2; i < r.lead.size(); ++i) r.lead[i] = static_cast<std::int32_t>(std::lround(0.3 * r.lead[i]));
  });
  EXPECT_GE(100 * s.sensitivity(), 99.5);
  EXPECT_GE(100 * s.positive_predictivity(), 99.5);
}

// The second lead (V1 in most records: small, often rS complexes) is much weaker for every
// single-lead detector (docs/rpeak.md, section 2). With the fixed 0.15 mV floor, 101's V1 gave
// 3 of its 1523 beats and the database 95.6 % of them (+P 98.5 %); now about 98 / 97.8 %.
TEST(RPeakMitdb, TheSmallSecondLeadKeepsItsBeats) {
  const std::vector<std::string> names = mitdb_records();
  if (names.empty()) GTEST_SKIP() << "MIT-BIH records not found (set TAHVEL_MITDB)";
  const BeatScore s = gross_score(names, 1, " of the second lead", [](Record&) {});
  EXPECT_GE(100 * s.sensitivity(), 97.5);
  EXPECT_GE(100 * s.positive_predictivity(), 97.5);
}

// A sine of `mv` at `hz` added to the lead: mains hum, or (below a few Hz) baseline wander.
void add_sine(Record& r, double hz, double mv) {
  for (std::size_t i = 0; i < r.lead.size(); ++i)
    r.lead[i] += static_cast<std::int32_t>(
        std::lround(mv * r.gain * std::sin(2 * std::numbers::pi * hz * static_cast<double>(i) / r.fs + 0.7)));
}

// Detected RR interval minus the reference one, between consecutive reference beats that are
// both normal (N L R e j) and both detected (each within 150 ms of its own detection).
struct RrError {
  double sum_sq = 0;
  std::int64_t pairs = 0;
  double rms() const { return std::sqrt(sum_sq / static_cast<double>(pairs)); }
};

RrError rr_error(const Record& r, const std::vector<Annotation>& reference) {
  const std::vector<std::int64_t> peaks = detect_r_peaks(r.lead, options_for(r));
  const auto window = static_cast<std::int64_t>(0.150 * r.fs);
  // The detection nearest each normal beat, or -1.
  auto nearest = [&](std::int64_t at) -> std::int64_t {
    auto it = std::lower_bound(peaks.begin(), peaks.end(), at - window);
    std::int64_t best = -1;
    for (; it != peaks.end() && *it <= at + window; ++it)
      if (best < 0 || std::llabs(*it - at) < std::llabs(best - at)) best = *it;
    return best;
  };
  RrError err;
  std::int64_t prev_at = -1, prev_det = -1;
  for (const Annotation& a : reference) {
    if (!is_beat(a.code)) continue;
    const std::int64_t det = is_reference_normal(a.code) ? nearest(a.sample) : -1;
    if (det >= 0 && prev_det >= 0 && det != prev_det) {
      const double e = static_cast<double>((det - prev_det) - (a.sample - prev_at));
      err.sum_sq += e * e;
      ++err.pairs;
    }
    prev_at = a.sample;
    prev_det = det;
  }
  return err;
}

// The RR error over all records, each first changed by `change` (their first lead); prints the
// records' own figures. Records with no two normal beats in a row (107: paced) are left out.
struct RrErrors {
  RrError all;
  std::size_t scored = 0, within_one_sample = 0, within_half_a_sample = 0;
};

template <class Change>
RrErrors rr_errors(const std::vector<std::string>& names, const char* what, Change change) {
  RrErrors out;
  for (const std::string& name : names) {
    Record r = load(name);
    EXPECT_FALSE(r.lead.empty()) << name;
    if (r.lead.empty()) continue;
    change(r);
    auto reference = read_annotations(mitdb_record(name));
    EXPECT_TRUE(reference.has_value()) << reference.error().message;
    if (!reference) continue;
    const RrError e = rr_error(r, *reference);
    if (e.pairs == 0) continue;
    ++out.scored;
    std::printf("%s%s  RR error %.2f samples rms over %lld normal pairs\n", name.c_str(), what, e.rms(),
                static_cast<long long>(e.pairs));
    out.within_one_sample += e.rms() <= 1.0 ? 1 : 0;
    out.within_half_a_sample += e.rms() <= 0.5 ? 1 : 0;
    out.all.sum_sq += e.sum_sq;
    out.all.pairs += e.pairs;
  }
  std::printf("RR error%s over %zu records: %.3f samples rms; %zu records within 1 sample rms\n", what,
              out.scored, out.all.rms(), out.within_one_sample);
  return out;
}

// RR intervals are differences of reported beats, so HRV needs each beat at the same point of
// its QRS to the sample. Measured against the annotations (rr_error). The reference positions
// are whole samples, so even a perfect detector differs by about 0.4 sample rms. With the point
// taken as the arg max in a window cut 30 ms after the band-passed QRS (before the centroid,
// docs/rpeak.md step 3) this was 2.0 samples rms overall and above 1 sample in 13 records.
TEST(RPeakMitdb, RrIntervalsOfNormalBeatsMatchTheReferenceToAboutASample) {
  const std::vector<std::string> names = mitdb_records();
  if (names.empty()) GTEST_SKIP() << "MIT-BIH records not found (set TAHVEL_MITDB)";
  const RrErrors e = rr_errors(names, "", [](Record&) {});
  EXPECT_LE(e.all.rms(), 1.7);
  EXPECT_GE(static_cast<double>(e.within_one_sample), 0.8 * static_cast<double>(e.scored));
  // The cleanest records stay at the floor (5: 100, 201, 213, 233, 234). The notches against
  // mains hum spread the QRS; used on clean records too, they left 2 there (docs/rpeak.md).
  EXPECT_GE(e.within_half_a_sample, 4u);
}

// Mains hum is the commonest artefact of an ECG taken at home. 0.3 mV of it, at 50 Hz or at
// 60 Hz, leaves the beats where they were: before the reported point was found on a signal
// without the hum notched out, this took the RR error to 3.3 samples rms at 50 Hz (16 records
// within a sample) and 2.6 at 60 Hz, and raised the RMSSD of 117 by 14 %.
TEST(RPeakMitdb, MainsHumDoesNotMoveTheBeats) {
  const std::vector<std::string> names = mitdb_records();
  if (names.empty()) GTEST_SKIP() << "MIT-BIH records not found (set TAHVEL_MITDB)";
  const RrErrors clean = rr_errors(names, "", [](Record&) {});
  for (const double hz : {50.0, 60.0}) {
    const std::string what = " + 0.3 mV at " + std::to_string(static_cast<int>(hz)) + " Hz";
    const RrErrors e = rr_errors(names, what.c_str(), [&](Record& r) { add_sine(r, hz, 0.3); });
    EXPECT_LE(e.all.rms(), 1.7) << what;
    EXPECT_GE(e.within_one_sample + 2, clean.within_one_sample) << what;
  }
}

// Baseline wander (breathing, movement, electrodes shifting on the skin) puts a slope under the
// QRS. Measured from the mean of its window's ends, the reported point moved towards the
// window's higher end: 1 mV at 0.3 Hz took the RR error to 2.0 samples rms, 2 mV at 1 Hz to 5.8
// and 5 mV at 0.5 Hz to 10.5 (6 records within a sample; RMSSD of 100 +48 %), with no beat
// missed or added, so nothing warned. The baseline now follows the slope around the QRS.
TEST(RPeakMitdb, BaselineWanderDoesNotMoveTheBeats) {
  const std::vector<std::string> names = mitdb_records();
  if (names.empty()) GTEST_SKIP() << "MIT-BIH records not found (set TAHVEL_MITDB)";
  const RrErrors clean = rr_errors(names, "", [](Record&) {});
  for (const auto& [hz, mv] : {std::pair{0.3, 1.0}, std::pair{1.0, 2.0}, std::pair{0.5, 5.0}}) {
    char what[64];
    std::snprintf(what, sizeof what, " + %.0f mV of wander at %.1f Hz", mv, hz);
    const RrErrors e = rr_errors(names, what, [&](Record& r) { add_sine(r, hz, mv); });
    EXPECT_LE(e.all.rms(), clean.all.rms() + 0.6) << what;  // 2.0-10.5 before
    EXPECT_GE(e.within_one_sample + 6, clean.within_one_sample) << what;  // 6-35 before
  }
}

// Two records with many ectopic beats, noise and search-backs, and one with mains hum (the
// notched copy in use): the peaks are the same whether an agent pushes one sample, 7, one
// second, 4096 or the whole record at a time.
TEST(RPeakMitdb, OutputIsIdenticalWhateverTheChunking) {
  const std::vector<std::string> names = mitdb_records();
  for (const std::string name : {"105", "207", "100 + hum"}) {
    const std::string record = name.substr(0, 3);
    if (std::find(names.begin(), names.end(), record) == names.end()) continue;
    Record r = load(record);
    ASSERT_FALSE(r.lead.empty()) << name;
    if (name != record) add_sine(r, 50, 0.3);
    const DetectorOptions o = options_for(r);
    const std::vector<std::int64_t> whole = detect_r_peaks(r.lead, o);
    ASSERT_GT(whole.size(), 1000u) << name;
    for (std::size_t chunk : {std::size_t{1}, std::size_t{7}, std::size_t{360},
                              std::size_t{4096}, r.lead.size()}) {
      RPeakDetector d(o);
      std::vector<std::int64_t> peaks;
      for (std::size_t i = 0; i < r.lead.size(); i += chunk)
        d.push(r.lead.data() + i, std::min(chunk, r.lead.size() - i), peaks);
      d.finish(peaks);
      EXPECT_EQ(peaks, whole) << name << ", chunk " << chunk;
    }
  }
}

}  // namespace
}  // namespace tahvel::aggregation
