// How ECG and HRV travel on the whiteboard: the items the sensor, signal-processing and HRV
// agents write (vocabulary: docs/vocabulary.md), and the readers that turn delivered records
// back into values. Building and reading them in one place keeps the agents (aggregation/agents/),
// the command line, the tests and the benchmarks on the same shapes.
//
// The chain, each item naming what it was derived from (IRIs, so that provenance can be
// followed across items; blank nodes are local to their item):
//
//   <rec>                      tv:EcgRecording, persistent (recording_item)
//   <rec>/chunk/<start>        tv:EcgChunk, one second of samples (ecg_chunk_item)
//   <rec> tv:endSample N       the recording ended (recording_end_item, persistent)
//   <rec>/rpeaks/<from>        R peaks decided while reading one chunk (rpeak_item)
//   <rec>/rr/<first start>     RR intervals with the NN mark (rr_item)
//   <rec>/hrv/<start_s>        one HRV window (hrv_window_item)
//
// Readers return an Error naming the item's subject and the predicate that is missing or does
// not parse; they never throw.
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "tahvel/aggregation/error.h"
#include "tahvel/aggregation/hrv.h"
#include "tahvel/aggregation/rr.h"
#include "tahvel/node/node.h"
#include "tahvel/node/term.h"

namespace tahvel::aggregation {

// Tahvel's vocabulary namespace (tv:) and the LOINC codes used for HRV observations.
inline constexpr const char* kTv = "https://w3id.org/tahvel#";
inline constexpr const char* kLoinc = "http://loinc.org/rdf#";
inline constexpr const char* kProvDerivedFrom = "http://www.w3.org/ns/prov#wasDerivedFrom";

// tv:<local> as an IRI term.
node::Term tv_term(const char* local);

// What the ECG source states once per recording (a persistent item): format and provenance.
struct RecordingInfo {
  std::string iri;            // the recording: <sensor IRI>/recording/<name>
  std::string sensor_iri;     // the sensor agent
  double fs = 360;            // samples per second per lead
  double gain = 200;          // ADC units per mV
  int baseline = 0;           // ADC units at 0 mV
  // The ECG lead's no-value sample (tv:invalidSample; WFDB's, wfdb.h invalid_sample): the
  // R-peak agent reads a run of it as no signal. nullopt: every value is signal.
  std::optional<std::int32_t> invalid_sample;
  std::string unit = "mV";
  std::vector<std::string> leads;  // lead names in sample order ("MLII", "V1")
  // Per lead, in sample order, its own ADC units per `unit` and zero (tv:leadCalibration): a
  // record may hold blood pressure in mmHg beside the ECG in mV. Empty (recordings written
  // before it was kept): every lead at gain, baseline and unit.
  struct LeadCalibration {
    double gain = 200;
    int baseline = 0;
    std::string unit = "mV";
    // The lead's no-value sample (tv:leadInvalidSample; WFDB's for the lead's format), printed
    // as no value. nullopt: every value is a reading.
    std::optional<std::int32_t> invalid_sample;
  };
  std::vector<LeadCalibration> calibration;
  // Lead `lead`'s calibration: its own, or the recording's (the ECG lead's no-value on lead 0).
  LeadCalibration calibration_of(std::size_t lead) const {
    return lead < calibration.size()
               ? calibration[lead]
               : LeadCalibration{gain, baseline, unit, lead == 0 ? invalid_sample : std::nullopt};
  }
  std::string maker, model;   // sensor maker and model
  std::string filters;        // filters applied before digitising, as the source states them
  std::string source;         // where the samples come from ("mitdb/100", "ecgsyn seed 7")
  // Of a replayed file: a digest of its first samples, which tells two records apart that
  // `source` names alike (patientA/ecg/rec, patientB/ecg/rec); empty when not known.
  std::string sample_digest;
  // When sample 0 was taken, ns since the Unix epoch (tv:startedAt): chunks are asserted at
  // started_at + sample / fs, and what is derived from them (R-peaks, RR intervals, HRV
  // windows) at the signal time it describes, so that an operator can ask for the raw ECG
  // behind an HRV window by its time. Absent on recordings written before it was kept.
  std::optional<std::int64_t> started_at;
  // Bytes per sample in the chunks (tv:sampleFormat): 2, "int16le interleaved", for records
  // whose values fit 16 bits (WFDB formats up to 16 bits: every MIT-BIH one); 4, "int32le
  // interleaved", for formats 24 and 32 and format 8's running sums, which 16 bits would wrap.
  int sample_bytes = 2;
};

// started_at + `seconds` of the recording's own clock, when started_at is known.
std::optional<std::int64_t> signal_time_ns(const RecordingInfo& info, double seconds);

// The recording item. fs and gain are written with as many digits as it takes to read back
// the same double (so that agents downstream compute with exactly the source's values).
node::Item recording_item(const RecordingInfo& info);

// The recording from the records whose subject is `iri` (as Snapshot::list({.s = iri})
// returns them; other subjects are ignored). Errors: no tv:samplingRate or tv:gain, or one
// that does not parse as a positive number.
Result<RecordingInfo> read_recording(const std::vector<node::Record>& records,
                                     const std::string& iri);

// `<rec> tv:endSample N` (persistent): the recording ended after N frames (samples 0..N-1).
node::Item recording_end_item(const std::string& recording_iri, std::int64_t end_sample);

// IRIs of the derived items of a recording.
std::string chunk_iri(const std::string& recording_iri, std::int64_t start_sample);
std::string rpeaks_iri(const std::string& recording_iri, std::int64_t from_sample);
std::string rr_iri(const std::string& recording_iri, std::int64_t first_start);
std::string rr_end_iri(const std::string& recording_iri);  // an RR item with no interval
std::string hrv_iri(const std::string& recording_iri, double start_s);

// One chunk of samples (usually one second): frames of all leads interleaved, each sample a
// little-endian two's-complement integer of info.sample_bytes bytes, as an xsd:base64Binary
// literal; a chunk of 4-byte samples says so itself (tv:sampleFormat "int32le interleaved"),
// so that it reads back without its recording. The chunk is
// named chunk_iri(info.iri, start_sample). leads[i][offset .. offset + frames) are written.
// When info.started_at is known the chunk is asserted at its first frame's time and spans to
// the next chunk's (node::Item::span), so that a time-range query starting inside it gets it.
node::Item ecg_chunk_item(const RecordingInfo& info, std::int64_t start_sample,
                          const std::vector<std::vector<std::int32_t>>& leads,
                          std::size_t offset, std::size_t frames);

// A chunk read back: leads[i] holds `frames` samples of lead i.
struct EcgChunk {
  std::string iri;
  std::string recording;
  std::int64_t start_sample = 0;
  std::size_t frames = 0;
  std::vector<std::vector<std::int32_t>> leads;
};

// The first tv:EcgChunk in `records` (a delivered item). Errors: no chunk, a missing
// tv:recording, tv:startSample, tv:frameCount or tv:samples, bad base64, a tv:sampleFormat other
// than "int16le interleaved" (the default) or "int32le interleaved", or a byte count that is not
// frames x leads x the sample's bytes.
Result<EcgChunk> read_chunk(const std::vector<node::Record>& records);

// R peaks decided while the detector read the samples [from_sample, to_sample) of a recording
// (peaks may lie before from_sample: a beat is decided up to decision_delay_samples() after
// it). `peaks` is a plain literal of space-separated sample indices ("" for none). The final
// item of a recording carries end_sample (from the source's tv:endSample) and the peaks that
// finish() released.
struct RPeaks {
  std::string recording;
  std::int64_t from_sample = 0, to_sample = 0;
  std::vector<std::int64_t> peaks;
  // The peaks (a subset of `peaks`, ascending) that end a confirmed empty gap
  // (RPeakDetector::push with empty_gap_out): tv:emptyGapEnds, in the format of tv:peaks,
  // written only when not empty; an item without it has none.
  std::vector<std::int64_t> empty_gap_ends;
  // The empty-gap ends (a subset of them, ascending) whose gap held a blocked P wave
  // (RPeakDetector::push with p_wave_gap_out): tv:pWaveGapEnds, in the same format, written
  // only when not empty.
  std::vector<std::int64_t> p_wave_gap_ends;
  std::string derived_from;               // the chunk's IRI (or the recording's, for the end)
  std::optional<std::int64_t> end_sample;
  std::string iri;                        // filled by read_rpeaks; rpeak_item derives it
};

node::Item rpeak_item(const RPeaks& rpeaks);  // named rpeaks_iri(recording, from_sample)
Result<RPeaks> read_rpeaks(const std::vector<node::Record>& records);

// RR intervals with their NN mark, in order, as the compact literal "start end nn;..." (nn is
// 1 or 0; "" for none). derived_from: the R-peak items read since the previous RR item. The
// final item of a recording carries end_sample.
struct RrSeries {
  std::string recording;
  std::vector<Interval> intervals;
  std::vector<std::string> derived_from;
  std::optional<std::int64_t> end_sample;
  std::string iri;  // filled by read_rr; rr_item derives it (rr_iri, or rr_end_iri if empty)
};

node::Item rr_item(const RrSeries& rr);
Result<RrSeries> read_rr(const std::vector<node::Record>& records);

std::string format_intervals(const std::vector<Interval>& intervals);
Result<std::vector<Interval>> parse_intervals(const std::string& text);
std::string format_peaks(const std::vector<std::int64_t>& peaks);
Result<std::vector<std::int64_t>> parse_peaks(const std::string& text);

// One HRV window as a SOSA observation named hrv_iri(info.iri, window.start_s) with a result
// per metric (absent metrics are left out), derived from the recording and from each IRI in
// derived_from (the RR items of the window).
node::Item hrv_window_item(const RecordingInfo& info, const WindowMetrics& window,
                           const std::string& agent_iri,
                           const std::vector<std::string>& derived_from = {});

}  // namespace tahvel::aggregation

// ---- HRV windows read back, and trends over them (tahvel-trend, docs/agents.md) ----
//
//   <rec>/trend/<metric>/<start_s>   one trend update after the window starting at start_s
//                                    (trend_item)

#include "tahvel/aggregation/trend.h"

namespace tahvel::aggregation {

// An HRV window item read back. recording: the prov:wasDerivedFrom that the window's IRI
// extends (<rec>/hrv/<start_s>), else its tv:recording.
struct HrvWindowItem {
  std::string iri;
  std::string recording;
  WindowMetrics window;  // start_s, end_s and the metrics present (counts 0 when absent)
};

// The first sosa:Observation of tv:HeartRateVariability in `records`. Errors: none, no
// tv:windowStartS / tv:windowEndS, a result that does not parse, or no recording.
Result<HrvWindowItem> read_hrv_window(const std::vector<node::Record>& records);

// The local name of a metric as the window item writes it ("sdnnMs", "meanHrBpm", ...), and
// back (nullopt for an unknown name).
const char* metric_local_name(HrvMetric which) noexcept;
std::optional<HrvMetric> metric_from_local_name(const std::string& local) noexcept;

// One update of a recording's trend of one metric, after the window starting at
// window_start_s (computed over the recording's windows up to that one).
struct TrendUpdate {
  std::string recording;
  HrvMetric metric = HrvMetric::sdnn;
  double window_start_s = 0;
  std::string window_iri;                 // the window item it follows (prov:wasDerivedFrom)
  std::size_t windows = 0;                // points in the series (windows with the metric)
  std::optional<double> latest, baseline, robust_sd, slope_per_hour;
  std::optional<double> slope_horizon_s;  // the slope's reach (TrendOptions::slope_horizon_s), when set
  bool alert = false;                     // TrendSummary::alerting
  int alert_direction = 0;                // +1 above the baseline, -1 below (when alert)
  std::optional<double> z_against_others; // cross_patient_z of latest against other recordings
  std::size_t others = 0;                 // how many other recordings z was computed against
  std::string iri;                        // filled by read_trend; trend_item derives it
};

std::string trend_iri(const std::string& recording_iri, HrvMetric metric, double window_start_s);
node::Item trend_item(const TrendUpdate& update, const std::string& agent_iri);
// The first tv:HrvTrend in `records`. Errors name the subject and the predicate.
Result<TrendUpdate> read_trend(const std::vector<node::Record>& records);

}  // namespace tahvel::aggregation
