// How ECG and HRV travel on the whiteboard: the items the sensor, signal-processing and HRV
// agents write (vocabulary: docs/vocabulary.md). Building them in one place keeps the agents,
// the command line and the benchmarks writing the same shapes.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "tahvel/aggregation/hrv.h"
#include "tahvel/node/term.h"

namespace tahvel::aggregation {

// Tahvel's vocabulary namespace (tv:) and the LOINC codes used for HRV observations.
inline constexpr const char* kTv = "https://w3id.org/tahvel#";
inline constexpr const char* kLoinc = "http://loinc.org/rdf#";

// What the ECG source states once per recording (a persistent item): format and provenance.
struct RecordingInfo {
  std::string iri;            // the recording: <sensor IRI>/recording/<name>
  std::string sensor_iri;     // the sensor agent
  double fs = 360;            // samples per second per lead
  double gain = 200;          // ADC units per mV
  int baseline = 0;           // ADC units at 0 mV
  std::string unit = "mV";
  std::vector<std::string> leads;  // lead names in sample order ("MLII", "V1")
  std::string maker, model;   // sensor maker and model
  std::string filters;        // filters applied before digitising, as the source states them
  std::string source;         // where the samples come from ("mitdb/100", "ecgsyn seed 7")
};

node::Item recording_item(const RecordingInfo& info);

// One chunk of samples (usually one second): frames of all leads interleaved, each sample a
// 16-bit little-endian two's-complement integer, as an xsd:base64Binary literal.
node::Item ecg_chunk_item(const RecordingInfo& info, std::int64_t start_sample,
                          const std::vector<std::vector<std::int32_t>>& leads,
                          std::size_t offset, std::size_t frames);

// One HRV window as a SOSA observation with a result per metric (absent metrics are left
// out), derived from the recording.
node::Item hrv_window_item(const RecordingInfo& info, const WindowMetrics& window,
                           const std::string& agent_iri);

}  // namespace tahvel::aggregation
