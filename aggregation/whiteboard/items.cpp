// Items of the ECG/HRV chain; see items.h and docs/vocabulary.md.
#include "tahvel/aggregation/items.h"

#include <cmath>
#include <cstdio>

namespace tahvel::aggregation {
namespace {

using node::Item;
using node::Term;

Term tv(const char* local) { return Term::iri(std::string(kTv) + local); }

Term decimal(double value) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.6g", value);
  std::string text = buf;
  // xsd:decimal has no exponent: fall back to a fixed form for very small or large values.
  if (text.find_first_of("eE") != std::string::npos) {
    std::snprintf(buf, sizeof buf, "%.6f", value);
    text = buf;
  }
  if (text.find('.') == std::string::npos) text += ".0";
  return Term::literal(text, std::string(node::xsd::kDecimal));
}

Term text(const std::string& value) { return Term::literal(value); }

// RFC 4648 base64 of raw bytes.
std::string base64(const std::string& bytes) {
  static constexpr char kAlphabet[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  out.reserve((bytes.size() + 2) / 3 * 4);
  std::size_t i = 0;
  for (; i + 2 < bytes.size(); i += 3) {
    unsigned v = (static_cast<unsigned char>(bytes[i]) << 16) | (static_cast<unsigned char>(bytes[i + 1]) << 8) |
                 static_cast<unsigned char>(bytes[i + 2]);
    out += kAlphabet[v >> 18];
    out += kAlphabet[(v >> 12) & 63];
    out += kAlphabet[(v >> 6) & 63];
    out += kAlphabet[v & 63];
  }
  if (i < bytes.size()) {
    unsigned v = static_cast<unsigned char>(bytes[i]) << 16;
    if (i + 1 < bytes.size()) v |= static_cast<unsigned char>(bytes[i + 1]) << 8;
    out += kAlphabet[v >> 18];
    out += kAlphabet[(v >> 12) & 63];
    out += i + 1 < bytes.size() ? kAlphabet[(v >> 6) & 63] : '=';
    out += '=';
  }
  return out;
}

}  // namespace

Item recording_item(const RecordingInfo& info) {
  Item item;
  item.persistent = true;
  const Term rec = Term::iri(info.iri);
  item.add(rec, Term::iri(std::string(node::kRdfType)), tv("EcgRecording"))
      .add(rec, Term::iri("http://www.w3.org/ns/sosa/madeBySensor"), Term::iri(info.sensor_iri))
      .add(rec, tv("samplingRate"), decimal(info.fs))
      .add(rec, tv("gain"), decimal(info.gain))
      .add(rec, tv("baseline"), Term::integer(info.baseline))
      .add(rec, tv("unit"), text(info.unit))
      .add(rec, tv("sampleFormat"), text("int16le interleaved"));
  for (std::size_t i = 0; i < info.leads.size(); ++i)
    item.add(rec, tv("lead"), text(std::to_string(i) + " " + info.leads[i]));
  if (!info.maker.empty()) item.add(rec, tv("sensorMaker"), text(info.maker));
  if (!info.model.empty()) item.add(rec, tv("sensorModel"), text(info.model));
  if (!info.filters.empty()) item.add(rec, tv("filters"), text(info.filters));
  if (!info.source.empty()) item.add(rec, tv("replayedFrom"), text(info.source));
  return item;
}

Item ecg_chunk_item(const RecordingInfo& info, std::int64_t start_sample,
                    const std::vector<std::vector<std::int32_t>>& leads, std::size_t offset,
                    std::size_t frames) {
  std::string bytes;
  bytes.reserve(frames * leads.size() * 2);
  for (std::size_t f = offset; f < offset + frames; ++f) {
    for (const auto& lead : leads) {
      auto v = static_cast<std::uint16_t>(static_cast<std::int16_t>(lead[f]));
      bytes += static_cast<char>(v & 0xFF);
      bytes += static_cast<char>(v >> 8);
    }
  }
  Item item;
  const Term chunk = Term::blank("chunk");
  item.add(chunk, Term::iri(std::string(node::kRdfType)), tv("EcgChunk"))
      .add(chunk, tv("recording"), Term::iri(info.iri))
      .add(chunk, tv("startSample"), Term::integer(start_sample))
      .add(chunk, tv("frameCount"), Term::integer(static_cast<std::int64_t>(frames)))
      .add(chunk, tv("samples"), Term::literal(base64(bytes), std::string(node::xsd::kBase64Binary)));
  return item;
}

Item hrv_window_item(const RecordingInfo& info, const WindowMetrics& window,
                     const std::string& agent_iri) {
  Item item;
  const Term obs = Term::blank("hrv");
  item.add(obs, Term::iri(std::string(node::kRdfType)), Term::iri("http://www.w3.org/ns/sosa/Observation"))
      .add(obs, Term::iri("http://www.w3.org/ns/sosa/observedProperty"), tv("HeartRateVariability"))
      .add(obs, Term::iri("http://www.w3.org/ns/prov#wasDerivedFrom"), Term::iri(info.iri))
      .add(obs, Term::iri("http://www.w3.org/ns/prov#wasAttributedTo"), Term::iri(agent_iri))
      .add(obs, tv("windowStartS"), decimal(window.start_s))
      .add(obs, tv("windowEndS"), decimal(window.end_s));
  const HrvMetrics& m = window.metrics;
  const std::pair<const char*, const std::optional<double>*> results[] = {
      {"meanNnMs", &m.mean_nn_ms}, {"sdnnMs", &m.sdnn_ms},     {"rmssdMs", &m.rmssd_ms},
      {"pnn50Pct", &m.pnn50_pct},  {"meanHrBpm", &m.mean_hr_bpm}, {"lfMs2", &m.lf_ms2},
      {"hfMs2", &m.hf_ms2},        {"lfHf", &m.lf_hf},         {"sd1Ms", &m.sd1_ms},
      {"sd2Ms", &m.sd2_ms}};
  for (const auto& [name, value] : results)
    if (*value && std::isfinite(**value)) item.add(obs, tv(name), decimal(**value));
  item.add(obs, tv("nnCount"), Term::integer(static_cast<std::int64_t>(m.nn_count)))
      .add(obs, tv("rrCount"), Term::integer(static_cast<std::int64_t>(m.rr_count)));
  return item;
}

}  // namespace tahvel::aggregation
