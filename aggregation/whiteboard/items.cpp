// Items of the ECG/HRV chain and their readers; see items.h and docs/vocabulary.md.
#include "tahvel/aggregation/items.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <map>
#include <sstream>
#include <system_error>

namespace tahvel::aggregation {
namespace {

using node::Item;
using node::Record;
using node::Term;

const std::string kSosa = "http://www.w3.org/ns/sosa/";

Term tv(const char* local) { return tv_term(local); }
Term rdf_type() { return Term::iri(std::string(node::kRdfType)); }
Term derived_from() { return Term::iri(kProvDerivedFrom); }

Term decimal_literal(std::string text) {
  if (text.find('.') == std::string::npos) text += ".0";
  return Term::literal(text, std::string(node::xsd::kDecimal));
}

// 6 significant digits: the HRV results (plenty for ms and ms^2, stable across platforms).
Term decimal(double value) {
  char buf[48];
  std::snprintf(buf, sizeof buf, "%.6g", value);
  std::string text = buf;
  // xsd:decimal has no exponent: fall back to a fixed form for very small or large values.
  if (text.find_first_of("eE") != std::string::npos) {
    std::snprintf(buf, sizeof buf, "%.6f", value);
    text = buf;
  }
  return decimal_literal(text);
}

// The shortest fixed form that reads back as the same double (fs, gain).
Term exact_decimal(double value) {
  char buf[400];
  auto [end, ec] = std::to_chars(buf, buf + sizeof buf, value, std::chars_format::fixed);
  if (ec != std::errc()) return decimal(value);
  return decimal_literal(std::string(buf, end));
}

// A header's units and lead names may be in another encoding (Latin-1 "\xB5V"): the store takes
// only UTF-8, so such bytes become U+FFFD rather than the recording going unrecorded.
Term text(const std::string& value) { return Term::literal(node::with_replacement_characters(value)); }

// A time in seconds inside an IRI, to the microsecond, without trailing zeros ("300", "150.5",
// "10000080"). Six significant digits ("%.6g") named two windows a minute apart alike after
// 1e6 s (11.6 days): the later one was taken for a repeat and never written.
std::string seconds_label(double s) {
  char buf[400];  // "%.6f" of the largest double: 309 digits, the point and six decimals
  std::snprintf(buf, sizeof buf, "%.6f", s);
  std::string label(buf);
  if (const auto point = label.find('.'); point != std::string::npos) {
    label.erase(label.find_last_not_of('0') + 1);
    if (label.back() == '.') label.pop_back();
  }
  return label == "-0" ? "0" : label;
}

// A time in seconds as an xsd:decimal, to the microsecond as seconds_label names it: window
// and trend times. 6 significant digits wrote 100093.5 s as 100094 and a 100,100 s record's
// last window as [100100, 100100). Not the shortest round trip: a start of 1636 steps of 1.1 s
// is 1799.6000000000001 as a double, and its window is named .../hrv/1799.6. Fixed, never an
// exponent (xsd:decimal has none).
Term seconds_decimal(double s) { return decimal_literal(seconds_label(s)); }

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

int base64_value(char c) {
  if (c >= 'A' && c <= 'Z') return c - 'A';
  if (c >= 'a' && c <= 'z') return c - 'a' + 26;
  if (c >= '0' && c <= '9') return c - '0' + 52;
  if (c == '+') return 62;
  if (c == '/') return 63;
  return -1;
}

// Decodes base64 (padding optional, no whitespace). nullopt on a character outside the
// alphabet or a stray length.
std::optional<std::string> unbase64(const std::string& in) {
  std::string out;
  out.reserve(in.size() / 4 * 3);
  unsigned acc = 0;
  int bits = 0;
  std::size_t i = 0;
  for (; i < in.size() && in[i] != '='; ++i) {
    const int v = base64_value(in[i]);
    if (v < 0) return std::nullopt;
    acc = (acc << 6) | static_cast<unsigned>(v);
    bits += 6;
    if (bits >= 8) {
      bits -= 8;
      out += static_cast<char>((acc >> bits) & 0xFF);
    }
  }
  for (; i < in.size(); ++i)
    if (in[i] != '=') return std::nullopt;
  if (bits >= 6) return std::nullopt;
  return out;
}

std::optional<std::int64_t> to_int(std::string_view s) {
  std::int64_t v = 0;
  auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
  if (ec != std::errc() || end != s.data() + s.size()) return std::nullopt;
  return v;
}

std::optional<double> to_double(std::string_view s) {
  double v = 0;
  auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
  if (ec != std::errc() || end != s.data() + s.size()) return std::nullopt;
  return v;
}

// The objects of predicate tv:<local> among records with subject `subject`.
std::vector<const Term*> objects(const std::vector<Record>& records, const std::string& subject,
                                 const char* local) {
  const std::string p = std::string(kTv) + local;
  std::vector<const Term*> out;
  for (const Record& r : records)
    if (r.triple.s.value == subject && r.triple.p.value == p) out.push_back(&r.triple.o);
  return out;
}

const Term* object(const std::vector<Record>& records, const std::string& subject, const char* local) {
  auto all = objects(records, subject, local);
  return all.empty() ? nullptr : all.front();
}

// tv:sampleFormat of a recording's (and a wide chunk's) samples, by bytes per sample.
std::string sample_format_name(int bytes) { return bytes == 4 ? "int32le interleaved" : "int16le interleaved"; }
std::optional<int> sample_bytes_of(const std::string& name) {
  if (name == "int16le interleaved") return 2;
  if (name == "int32le interleaved") return 4;
  return std::nullopt;
}

Unexpected<Error> missing(const std::string& subject, const char* local, const char* what) {
  return fail("<" + subject + ">: tv:" + local + " " + what);
}

Result<std::int64_t> int_of(const std::vector<Record>& records, const std::string& subject,
                            const char* local) {
  const Term* t = object(records, subject, local);
  if (!t) return missing(subject, local, "missing");
  auto v = to_int(t->value);
  if (!v) return missing(subject, local, ("is not an integer: '" + t->value + "'").c_str());
  return *v;
}

// The subject of the first record whose predicate is tv:<local>; empty if none.
std::string subject_with(const std::vector<Record>& records, const char* local) {
  const std::string p = std::string(kTv) + local;
  for (const Record& r : records)
    if (r.triple.p.value == p && r.triple.s.is_iri()) return r.triple.s.value;
  return {};
}

std::vector<std::string> derivations(const std::vector<Record>& records, const std::string& subject) {
  std::vector<std::string> out;
  for (const Record& r : records)
    if (r.triple.s.value == subject && r.triple.p.value == kProvDerivedFrom && r.triple.o.is_iri())
      out.push_back(r.triple.o.value);
  return out;
}

}  // namespace

Term tv_term(const char* local) { return Term::iri(std::string(kTv) + local); }

std::string chunk_iri(const std::string& recording, std::int64_t start) {
  return recording + "/chunk/" + std::to_string(start);
}
std::string rpeaks_iri(const std::string& recording, std::int64_t from) {
  return recording + "/rpeaks/" + std::to_string(from);
}
std::string rr_iri(const std::string& recording, std::int64_t first_start) {
  return recording + "/rr/" + std::to_string(first_start);
}
std::string rr_end_iri(const std::string& recording) { return recording + "/rr/end"; }
std::string hrv_iri(const std::string& recording, double start_s) {
  return recording + "/hrv/" + seconds_label(start_s);
}

Item recording_item(const RecordingInfo& info) {
  Item item;
  item.persistent = true;
  const Term rec = Term::iri(info.iri);
  item.add(rec, rdf_type(), tv("EcgRecording"))
      .add(rec, Term::iri(kSosa + "madeBySensor"), Term::iri(info.sensor_iri))
      .add(rec, tv("samplingRate"), exact_decimal(info.fs))
      .add(rec, tv("gain"), exact_decimal(info.gain))
      .add(rec, tv("baseline"), Term::integer(info.baseline))
      .add(rec, tv("unit"), text(info.unit))
      .add(rec, tv("sampleFormat"), text(sample_format_name(info.sample_bytes)));
  if (info.invalid_sample) item.add(rec, tv("invalidSample"), Term::integer(*info.invalid_sample));
  for (std::size_t i = 0; i < info.leads.size(); ++i)
    item.add(rec, tv("lead"), text(std::to_string(i) + " " + info.leads[i]));
  // "<lead> <gain> <baseline> <unit>": the gain as exactly as tv:gain.
  for (std::size_t i = 0; i < info.calibration.size(); ++i) {
    const auto& c = info.calibration[i];
    item.add(rec, tv("leadCalibration"),
             text(std::to_string(i) + " " + exact_decimal(c.gain).value + " " + std::to_string(c.baseline) + " " + c.unit));
    if (c.invalid_sample)
      item.add(rec, tv("leadInvalidSample"), text(std::to_string(i) + " " + std::to_string(*c.invalid_sample)));
  }
  if (!info.maker.empty()) item.add(rec, tv("sensorMaker"), text(info.maker));
  if (!info.model.empty()) item.add(rec, tv("sensorModel"), text(info.model));
  if (!info.filters.empty()) item.add(rec, tv("filters"), text(info.filters));
  if (!info.source.empty()) item.add(rec, tv("replayedFrom"), text(info.source));
  if (!info.sample_digest.empty()) item.add(rec, tv("sampleDigest"), text(info.sample_digest));
  if (info.started_at) item.add(rec, tv("startedAt"), Term::integer(*info.started_at));
  return item;
}

std::optional<std::int64_t> signal_time_ns(const RecordingInfo& info, double seconds) {
  if (!info.started_at || !std::isfinite(seconds)) return std::nullopt;
  return *info.started_at + static_cast<std::int64_t>(std::llround(seconds * 1e9));
}

Result<RecordingInfo> read_recording(const std::vector<Record>& records, const std::string& iri) {
  RecordingInfo info;
  info.iri = iri;
  for (const char* local : {"samplingRate", "gain"}) {
    const Term* t = object(records, iri, local);
    if (!t) return missing(iri, local, "missing (is it a tv:EcgRecording?)");
    auto v = to_double(t->value);
    // A gain may be negative (a lead recorded upside down: WFDB, and the R-peak detector, read
    // it so), not 0; a sampling rate is positive.
    const bool gain = std::string(local) == "gain";
    if (!v || !std::isfinite(*v) || (gain ? *v == 0 : !(*v > 0)))
      return missing(iri, local, (gain ? "is not a number other than 0: '" + t->value + "'"
                                       : "is not a positive number: '" + t->value + "'").c_str());
    (gain ? info.gain : info.fs) = *v;
  }
  if (const Term* t = object(records, iri, "baseline"))
    info.baseline = static_cast<int>(to_int(t->value).value_or(0));
  if (const Term* t = object(records, iri, "unit")) info.unit = t->value;
  if (const Term* t = object(records, iri, "invalidSample"))
    if (auto v = to_int(t->value)) info.invalid_sample = static_cast<std::int32_t>(*v);
  if (const Term* t = object(records, iri, "sampleFormat")) {
    auto bytes = sample_bytes_of(t->value);
    if (!bytes) return missing(iri, "sampleFormat", ("is not one this build reads: '" + t->value + "'").c_str());
    info.sample_bytes = *bytes;
  }
  std::map<long, std::string> leads;
  for (const Term* t : objects(records, iri, "lead")) {
    const auto space = t->value.find(' ');
    auto index = to_int(std::string_view(t->value).substr(0, space));
    if (index) leads[static_cast<long>(*index)] = space == std::string::npos ? "" : t->value.substr(space + 1);
  }
  for (auto& [index, name] : leads) info.leads.push_back(name);
  // Per-lead calibrations matter to `tahvel ecg` only, not to the agents reading the ECG lead at
  // tv:gain: a set that is not whole and readable (one per lead from 0, each "<lead> <gain>
  // <baseline> <unit>" with a gain that is a number other than 0; WFDB allows a negative one)
  // is read as none, every lead at tv:gain, rather than making the recording unreadable.
  std::map<long, RecordingInfo::LeadCalibration> calibrations;
  bool readable = true;
  for (const Term* t : objects(records, iri, "leadCalibration")) {
    std::istringstream in(t->value);
    long index = -1;
    std::string gain;
    RecordingInfo::LeadCalibration c;
    auto g = (in >> index >> gain >> c.baseline) ? to_double(gain) : std::nullopt;
    if (index < 0 || !g || *g == 0 || !std::isfinite(*g) || calibrations.count(index)) {
      readable = false;
      break;
    }
    c.gain = *g;
    std::getline(in >> std::ws, c.unit);
    calibrations[index] = c;
  }
  if (readable && !calibrations.empty() && calibrations.rbegin()->first + 1 == static_cast<long>(calibrations.size()))
    for (auto& [index, c] : calibrations) info.calibration.push_back(c);
  // "<lead> <value>"; one that does not read, or names no lead, is passed over (a reading then
  // prints as a number, as it did before this was kept). The ECG lead's is tv:invalidSample
  // when the recording has no leadInvalidSample of its own for it (written before it was kept).
  for (const Term* t : objects(records, iri, "leadInvalidSample")) {
    std::istringstream in(t->value);
    long index = -1;
    std::int64_t value = 0;
    if ((in >> index >> value) && (in >> std::ws).eof() && index >= 0 &&
        static_cast<std::size_t>(index) < info.calibration.size() && value >= INT32_MIN && value <= INT32_MAX)
      info.calibration[static_cast<std::size_t>(index)].invalid_sample = static_cast<std::int32_t>(value);
  }
  if (!info.calibration.empty() && !info.calibration[0].invalid_sample) info.calibration[0].invalid_sample = info.invalid_sample;
  for (const Record& r : records)
    if (r.triple.s.value == iri && r.triple.p.value == kSosa + "madeBySensor") info.sensor_iri = r.triple.o.value;
  if (const Term* t = object(records, iri, "sensorMaker")) info.maker = t->value;
  if (const Term* t = object(records, iri, "sensorModel")) info.model = t->value;
  if (const Term* t = object(records, iri, "filters")) info.filters = t->value;
  if (const Term* t = object(records, iri, "replayedFrom")) info.source = t->value;
  if (const Term* t = object(records, iri, "sampleDigest")) info.sample_digest = t->value;
  if (const Term* t = object(records, iri, "startedAt")) info.started_at = to_int(t->value);
  return info;
}

Item recording_end_item(const std::string& recording_iri, std::int64_t end_sample) {
  Item item;
  item.persistent = true;
  item.add(Term::iri(recording_iri), tv("endSample"), Term::integer(end_sample));
  return item;
}

Item ecg_chunk_item(const RecordingInfo& info, std::int64_t start_sample,
                    const std::vector<std::vector<std::int32_t>>& leads, std::size_t offset,
                    std::size_t frames) {
  const int width = info.sample_bytes == 4 ? 4 : 2;
  std::string bytes;
  bytes.reserve(frames * leads.size() * static_cast<std::size_t>(width));
  for (std::size_t f = offset; f < offset + frames; ++f) {
    for (const auto& lead : leads) {
      auto v = static_cast<std::uint32_t>(lead[f]);
      for (int k = 0; k < width; ++k, v >>= 8) bytes += static_cast<char>(v & 0xFF);
    }
  }
  Item item;
  const Term chunk = Term::iri(chunk_iri(info.iri, start_sample));
  item.add(chunk, rdf_type(), tv("EcgChunk"))
      .add(chunk, tv("recording"), Term::iri(info.iri))
      .add(chunk, tv("startSample"), Term::integer(start_sample))
      .add(chunk, tv("frameCount"), Term::integer(static_cast<std::int64_t>(frames)))
      .add(chunk, tv("samples"), Term::literal(base64(bytes), std::string(node::xsd::kBase64Binary)));
  if (width == 4) item.add(chunk, tv("sampleFormat"), text(sample_format_name(width)));
  if (info.started_at) {
    const auto frame_time = [&](std::int64_t sample) {
      return *info.started_at + std::llround(static_cast<double>(sample) * 1e9 / info.fs);
    };
    // Up to the next chunk's first frame, to the ns: adjacent chunks neither overlap nor leave
    // a gap, so a range from one chunk's start does not take the chunk before.
    const std::int64_t end_sample = start_sample + static_cast<std::int64_t>(frames);
    item.asserted_at = frame_time(start_sample);
    item.span = frame_time(end_sample) - *item.asserted_at;
  }
  return item;
}

Result<EcgChunk> read_chunk(const std::vector<Record>& records) {
  EcgChunk chunk;
  chunk.iri = subject_with(records, "samples");
  if (chunk.iri.empty()) return fail("no tv:samples in the item (not an ECG chunk)");
  const Term* rec = object(records, chunk.iri, "recording");
  if (!rec || !rec->is_iri()) return missing(chunk.iri, "recording", "missing");
  chunk.recording = rec->value;
  auto start = int_of(records, chunk.iri, "startSample");
  if (!start) return unexpected(start.error());
  auto frames = int_of(records, chunk.iri, "frameCount");
  if (!frames) return unexpected(frames.error());
  if (*frames <= 0) return missing(chunk.iri, "frameCount", "is not positive");
  chunk.start_sample = *start;
  chunk.frames = static_cast<std::size_t>(*frames);
  int width = 2;
  if (const Term* format = object(records, chunk.iri, "sampleFormat")) {
    auto bytes = sample_bytes_of(format->value);
    if (!bytes) return missing(chunk.iri, "sampleFormat", ("is not one this build reads: '" + format->value + "'").c_str());
    width = *bytes;
  }
  auto bytes = unbase64(object(records, chunk.iri, "samples")->value);
  if (!bytes) return missing(chunk.iri, "samples", "is not base64");
  const auto w = static_cast<std::size_t>(width);
  const std::size_t per_frame = bytes->size() / chunk.frames;
  if (per_frame == 0 || per_frame % w != 0 || per_frame * chunk.frames != bytes->size())
    return missing(chunk.iri, "samples",
                   ("holds " + std::to_string(bytes->size()) + " bytes, not frames x leads x " + std::to_string(w)).c_str());
  const std::size_t leads = per_frame / w;
  chunk.leads.assign(leads, std::vector<std::int32_t>(chunk.frames));
  const auto* b = reinterpret_cast<const unsigned char*>(bytes->data());
  for (std::size_t f = 0; f < chunk.frames; ++f)
    for (std::size_t l = 0; l < leads; ++l, b += w) {
      std::uint32_t v = 0;
      for (std::size_t k = 0; k < w; ++k) v |= static_cast<std::uint32_t>(b[k]) << (8 * k);
      chunk.leads[l][f] = w == 2 ? static_cast<std::int16_t>(static_cast<std::uint16_t>(v)) : static_cast<std::int32_t>(v);
    }
  return chunk;
}

std::string format_peaks(const std::vector<std::int64_t>& peaks) {
  std::string out;
  for (std::size_t i = 0; i < peaks.size(); ++i) {
    if (i) out += ' ';
    out += std::to_string(peaks[i]);
  }
  return out;
}

Result<std::vector<std::int64_t>> parse_peaks(const std::string& text) {
  std::vector<std::int64_t> out;
  std::size_t at = 0;
  while (at < text.size()) {
    const std::size_t space = std::min(text.find(' ', at), text.size());
    auto v = to_int(std::string_view(text).substr(at, space - at));
    if (!v) return fail("peaks: '" + text.substr(at, space - at) + "' is not a sample index");
    out.push_back(*v);
    at = space + 1;
  }
  return out;
}

Item rpeak_item(const RPeaks& p) {
  Item item;
  const Term s = Term::iri(rpeaks_iri(p.recording, p.from_sample));
  item.add(s, rdf_type(), tv("RPeaks"))
      .add(s, tv("recording"), Term::iri(p.recording))
      .add(s, tv("fromSample"), Term::integer(p.from_sample))
      .add(s, tv("toSample"), Term::integer(p.to_sample))
      .add(s, tv("peaks"), text(format_peaks(p.peaks)));
  if (!p.empty_gap_ends.empty()) item.add(s, tv("emptyGapEnds"), text(format_peaks(p.empty_gap_ends)));
  if (!p.p_wave_gap_ends.empty())
    item.add(s, tv("pWaveGapEnds"), text(format_peaks(p.p_wave_gap_ends)));
  if (!p.derived_from.empty()) item.add(s, derived_from(), Term::iri(p.derived_from));
  if (p.end_sample) item.add(s, tv("endSample"), Term::integer(*p.end_sample));
  return item;
}

Result<RPeaks> read_rpeaks(const std::vector<Record>& records) {
  RPeaks p;
  p.iri = subject_with(records, "peaks");
  if (p.iri.empty()) return fail("no tv:peaks in the item (not an R-peak item)");
  const Term* rec = object(records, p.iri, "recording");
  if (!rec || !rec->is_iri()) return missing(p.iri, "recording", "missing");
  p.recording = rec->value;
  auto from = int_of(records, p.iri, "fromSample");
  if (!from) return unexpected(from.error());
  auto to = int_of(records, p.iri, "toSample");
  if (!to) return unexpected(to.error());
  p.from_sample = *from;
  p.to_sample = *to;
  auto peaks = parse_peaks(object(records, p.iri, "peaks")->value);
  if (!peaks) return fail("<" + p.iri + ">: tv:" + peaks.error().message);
  p.peaks = std::move(*peaks);
  if (const Term* gaps = object(records, p.iri, "emptyGapEnds")) {
    auto ends = parse_peaks(gaps->value);
    if (!ends) return fail("<" + p.iri + ">: tv:emptyGapEnds: " + ends.error().message);
    p.empty_gap_ends = std::move(*ends);
  }
  if (const Term* gaps = object(records, p.iri, "pWaveGapEnds")) {
    auto ends = parse_peaks(gaps->value);
    if (!ends) return fail("<" + p.iri + ">: tv:pWaveGapEnds: " + ends.error().message);
    p.p_wave_gap_ends = std::move(*ends);
  }
  auto from_items = derivations(records, p.iri);
  if (!from_items.empty()) p.derived_from = from_items.front();
  if (object(records, p.iri, "endSample")) {
    auto end = int_of(records, p.iri, "endSample");
    if (!end) return unexpected(end.error());
    p.end_sample = *end;
  }
  return p;
}

std::string format_intervals(const std::vector<Interval>& intervals) {
  std::string out;
  for (std::size_t i = 0; i < intervals.size(); ++i) {
    if (i) out += ';';
    out += std::to_string(intervals[i].start) + ' ' + std::to_string(intervals[i].end) +
           (intervals[i].nn ? " 1" : " 0");
  }
  return out;
}

Result<std::vector<Interval>> parse_intervals(const std::string& text) {
  std::vector<Interval> out;
  std::size_t at = 0;
  while (at < text.size()) {
    const std::size_t semi = std::min(text.find(';', at), text.size());
    const std::string entry = text.substr(at, semi - at);
    auto fields = parse_peaks(entry);
    if (!fields || fields->size() != 3 || ((*fields)[2] != 0 && (*fields)[2] != 1))
      return fail("intervals: '" + entry + "' is not 'start end nn'");
    out.push_back({(*fields)[0], (*fields)[1], (*fields)[2] == 1});
    at = semi + 1;
  }
  return out;
}

Item rr_item(const RrSeries& rr) {
  Item item;
  const Term s = Term::iri(rr.intervals.empty() ? rr_end_iri(rr.recording)
                                                : rr_iri(rr.recording, rr.intervals.front().start));
  item.add(s, rdf_type(), tv("RrSeries"))
      .add(s, tv("recording"), Term::iri(rr.recording))
      .add(s, tv("intervals"), text(format_intervals(rr.intervals)));
  for (const std::string& from : rr.derived_from) item.add(s, derived_from(), Term::iri(from));
  if (rr.end_sample) item.add(s, tv("endSample"), Term::integer(*rr.end_sample));
  return item;
}

Result<RrSeries> read_rr(const std::vector<Record>& records) {
  RrSeries rr;
  rr.iri = subject_with(records, "intervals");
  if (rr.iri.empty()) return fail("no tv:intervals in the item (not an RR item)");
  const Term* rec = object(records, rr.iri, "recording");
  if (!rec || !rec->is_iri()) return missing(rr.iri, "recording", "missing");
  rr.recording = rec->value;
  auto intervals = parse_intervals(object(records, rr.iri, "intervals")->value);
  if (!intervals) return fail("<" + rr.iri + ">: tv:" + intervals.error().message);
  rr.intervals = std::move(*intervals);
  rr.derived_from = derivations(records, rr.iri);
  if (object(records, rr.iri, "endSample")) {
    auto end = int_of(records, rr.iri, "endSample");
    if (!end) return unexpected(end.error());
    rr.end_sample = *end;
  }
  return rr;
}

Item hrv_window_item(const RecordingInfo& info, const WindowMetrics& window,
                     const std::string& agent_iri, const std::vector<std::string>& from) {
  Item item;
  const Term obs = Term::iri(hrv_iri(info.iri, window.start_s));
  // In this order: patients_on_board finds a window's start and recording in its first five
  // records, before the RR items it is derived from (patients.cpp, window_facts).
  item.add(obs, rdf_type(), Term::iri(kSosa + "Observation"))
      .add(obs, Term::iri(kSosa + "observedProperty"), tv("HeartRateVariability"))
      .add(obs, derived_from(), Term::iri(info.iri))
      .add(obs, Term::iri("http://www.w3.org/ns/prov#wasAttributedTo"), Term::iri(agent_iri))
      .add(obs, tv("windowStartS"), seconds_decimal(window.start_s))
      .add(obs, tv("windowEndS"), seconds_decimal(window.end_s));
  if (window.length_s > 0) item.add(obs, tv("windowLengthS"), seconds_decimal(window.length_s));
  for (const std::string& iri : from) item.add(obs, derived_from(), Term::iri(iri));
  const HrvMetrics& m = window.metrics;
  const std::pair<const char*, const std::optional<double>*> results[] = {
      {"meanNnMs", &m.mean_nn_ms}, {"sdnnMs", &m.sdnn_ms},     {"rmssdMs", &m.rmssd_ms},
      {"pnn50Pct", &m.pnn50_pct},  {"meanHrBpm", &m.mean_hr_bpm}, {"lfMs2", &m.lf_ms2},
      {"hfMs2", &m.hf_ms2},        {"lfHf", &m.lf_hf},         {"sd1Ms", &m.sd1_ms},
      {"sd2Ms", &m.sd2_ms}, {"irregularPct", &m.irregular_pct}};
  for (const auto& [name, value] : results)
    if (*value && std::isfinite(**value)) item.add(obs, tv(name), decimal(**value));
  item.add(obs, tv("nnCount"), Term::integer(static_cast<std::int64_t>(m.nn_count)))
      .add(obs, tv("rrCount"), Term::integer(static_cast<std::int64_t>(m.rr_count)))
      .add(obs, tv("gapCount"), Term::integer(static_cast<std::int64_t>(m.gap_count)));
  return item;
}

}  // namespace tahvel::aggregation

// ---- HRV windows read back, and trends (appended; see items.h) ----
namespace tahvel::aggregation {
namespace {

struct MetricName {
  HrvMetric metric;
  const char* local;
  std::optional<double> HrvMetrics::*field;
};

constexpr MetricName kMetricNames[] = {
    {HrvMetric::mean_nn, "meanNnMs", &HrvMetrics::mean_nn_ms}, {HrvMetric::sdnn, "sdnnMs", &HrvMetrics::sdnn_ms},
    {HrvMetric::rmssd, "rmssdMs", &HrvMetrics::rmssd_ms},      {HrvMetric::pnn50, "pnn50Pct", &HrvMetrics::pnn50_pct},
    {HrvMetric::mean_hr, "meanHrBpm", &HrvMetrics::mean_hr_bpm}, {HrvMetric::lf, "lfMs2", &HrvMetrics::lf_ms2},
    {HrvMetric::hf, "hfMs2", &HrvMetrics::hf_ms2},             {HrvMetric::lf_hf, "lfHf", &HrvMetrics::lf_hf},
    {HrvMetric::sd1, "sd1Ms", &HrvMetrics::sd1_ms},            {HrvMetric::sd2, "sd2Ms", &HrvMetrics::sd2_ms}};

Result<double> double_of(const std::vector<Record>& records, const std::string& subject, const char* local) {
  const Term* t = object(records, subject, local);
  if (!t) return missing(subject, local, "missing");
  auto v = to_double(t->value);
  if (!v || !std::isfinite(*v)) return missing(subject, local, ("is not a number: '" + t->value + "'").c_str());
  return *v;
}

// An optional decimal: absent is fine, present must parse.
Result<std::optional<double>> optional_double(const std::vector<Record>& records, const std::string& subject,
                                              const char* local) {
  if (!object(records, subject, local)) return std::optional<double>{};
  auto v = double_of(records, subject, local);
  if (!v) return unexpected(v.error());
  return std::optional<double>{*v};
}

}  // namespace

const char* metric_local_name(HrvMetric which) noexcept {
  for (const auto& m : kMetricNames)
    if (m.metric == which) return m.local;
  return "";
}

std::optional<HrvMetric> metric_from_local_name(const std::string& local) noexcept {
  for (const auto& m : kMetricNames)
    if (local == m.local) return m.metric;
  return std::nullopt;
}

Result<HrvWindowItem> read_hrv_window(const std::vector<Record>& records) {
  HrvWindowItem w;
  const std::string observed = kSosa + "observedProperty";
  const std::string hrv = std::string(kTv) + "HeartRateVariability";
  bool blank = false;  // the triple is there, on a blank node
  for (const Record& r : records)
    if (r.triple.p.value == observed && r.triple.o.value == hrv) {
      if (!r.triple.s.is_iri()) {
        blank = true;
        continue;
      }
      w.iri = r.triple.s.value;
      break;
    }
  if (w.iri.empty() && blank)
    return fail("the HRV window's subject is a blank node: a window is named by an IRI (the recording's + \"/hrv/\" + its "
                "start), so that its trend and its copies up the tree name the same window");
  if (w.iri.empty()) return fail("no sosa:observedProperty tv:HeartRateVariability in the item (not an HRV window)");
  // The recording the IRI extends first, as patients_on_board groups windows by it without
  // reading past the derivation (patients.cpp, window_facts).
  for (const std::string& from : derivations(records, w.iri))
    if (w.iri.size() > from.size() + 5 && w.iri.compare(0, from.size(), from) == 0 &&
        w.iri.compare(from.size(), 5, "/hrv/") == 0)
      w.recording = from;
  if (const Term* rec = object(records, w.iri, "recording"); w.recording.empty() && rec && rec->is_iri())
    w.recording = rec->value;
  if (w.recording.empty()) return missing(w.iri, "recording", "missing (nor prov:wasDerivedFrom the recording)");
  auto start = double_of(records, w.iri, "windowStartS");
  if (!start) return unexpected(start.error());
  auto end = double_of(records, w.iri, "windowEndS");
  if (!end) return unexpected(end.error());
  w.window.start_s = *start;
  w.window.end_s = *end;
  // Windows written before tv:windowLengthS: their length, cut short by the record's end or not.
  auto length = optional_double(records, w.iri, "windowLengthS");
  if (!length) return unexpected(length.error());
  w.window.length_s = length->value_or(*end - *start);
  for (const auto& m : kMetricNames) {
    auto v = optional_double(records, w.iri, m.local);
    if (!v) return unexpected(v.error());
    w.window.metrics.*m.field = *v;
  }
  auto irregular = optional_double(records, w.iri, "irregularPct");
  if (!irregular) return unexpected(irregular.error());
  w.window.metrics.irregular_pct = *irregular;
  if (object(records, w.iri, "nnCount")) {
    auto n = int_of(records, w.iri, "nnCount");
    if (!n) return unexpected(n.error());
    w.window.metrics.nn_count = static_cast<std::size_t>(std::max<std::int64_t>(0, *n));
  }
  if (object(records, w.iri, "rrCount")) {
    auto n = int_of(records, w.iri, "rrCount");
    if (!n) return unexpected(n.error());
    w.window.metrics.rr_count = static_cast<std::size_t>(std::max<std::int64_t>(0, *n));
  }
  if (object(records, w.iri, "gapCount")) {  // windows written before session 83 have none
    auto n = int_of(records, w.iri, "gapCount");
    if (!n) return unexpected(n.error());
    w.window.metrics.gap_count = static_cast<std::size_t>(std::max<std::int64_t>(0, *n));
  }
  return w;
}

std::string trend_iri(const std::string& recording, HrvMetric metric, double window_start_s) {
  return recording + "/trend/" + metric_local_name(metric) + "/" + seconds_label(window_start_s);
}

Item trend_item(const TrendUpdate& u, const std::string& agent_iri) {
  Item item;
  const Term s = Term::iri(trend_iri(u.recording, u.metric, u.window_start_s));
  item.add(s, rdf_type(), tv("HrvTrend"))
      .add(s, tv("recording"), Term::iri(u.recording))
      .add(s, tv("metric"), tv(metric_local_name(u.metric)))
      .add(s, tv("windowStartS"), seconds_decimal(u.window_start_s))
      .add(s, tv("windows"), Term::integer(static_cast<std::int64_t>(u.windows)))
      .add(s, tv("alert"), Term::literal(u.alert ? "true" : "false", std::string(node::xsd::kBoolean)));
  if (!u.window_iri.empty()) item.add(s, derived_from(), Term::iri(u.window_iri));
  if (!agent_iri.empty()) item.add(s, Term::iri("http://www.w3.org/ns/prov#wasAttributedTo"), Term::iri(agent_iri));
  if (u.latest) item.add(s, tv("latest"), decimal(*u.latest));
  if (u.baseline) item.add(s, tv("baseline"), decimal(*u.baseline));
  if (u.robust_sd) item.add(s, tv("robustSd"), decimal(*u.robust_sd));
  if (u.slope_per_hour) item.add(s, tv("slopePerHour"), decimal(*u.slope_per_hour));
  if (u.slope_per_hour && u.slope_horizon_s) item.add(s, tv("slopeHorizonS"), decimal(*u.slope_horizon_s));
  if (u.alert) item.add(s, tv("alertDirection"), text(u.alert_direction > 0 ? "above" : "below"));
  if (u.z_against_others) {
    item.add(s, tv("zAgainstOthers"), decimal(*u.z_against_others))
        .add(s, tv("othersCount"), Term::integer(static_cast<std::int64_t>(u.others)));
  }
  return item;
}

Result<TrendUpdate> read_trend(const std::vector<Record>& records) {
  TrendUpdate u;
  const std::string type = std::string(kTv) + "HrvTrend";
  for (const Record& r : records)
    if (r.triple.p.value == node::kRdfType && r.triple.o.value == type && r.triple.s.is_iri()) {
      u.iri = r.triple.s.value;
      break;
    }
  if (u.iri.empty()) return fail("no tv:HrvTrend in the item (not a trend item)");
  const Term* rec = object(records, u.iri, "recording");
  if (!rec || !rec->is_iri()) return missing(u.iri, "recording", "missing");
  u.recording = rec->value;
  const Term* metric = object(records, u.iri, "metric");
  const std::string prefix = kTv;
  if (!metric || metric->value.compare(0, prefix.size(), prefix) != 0) return missing(u.iri, "metric", "missing");
  auto which = metric_from_local_name(metric->value.substr(prefix.size()));
  if (!which) return missing(u.iri, "metric", ("is not an HRV metric: <" + metric->value + ">").c_str());
  u.metric = *which;
  auto start = double_of(records, u.iri, "windowStartS");
  if (!start) return unexpected(start.error());
  u.window_start_s = *start;
  auto windows = int_of(records, u.iri, "windows");
  if (!windows) return unexpected(windows.error());
  u.windows = static_cast<std::size_t>(std::max<std::int64_t>(0, *windows));
  const Term* alert = object(records, u.iri, "alert");
  if (!alert || (alert->value != "true" && alert->value != "false"))
    return missing(u.iri, "alert", "missing or not true/false");
  u.alert = alert->value == "true";
  if (const Term* d = object(records, u.iri, "alertDirection")) u.alert_direction = d->value == "above" ? 1 : -1;
  for (auto [local, field] : {std::pair{"latest", &TrendUpdate::latest}, std::pair{"baseline", &TrendUpdate::baseline},
                              std::pair{"robustSd", &TrendUpdate::robust_sd},
                              std::pair{"slopePerHour", &TrendUpdate::slope_per_hour},
                              std::pair{"slopeHorizonS", &TrendUpdate::slope_horizon_s},
                              std::pair{"zAgainstOthers", &TrendUpdate::z_against_others}}) {
    auto v = optional_double(records, u.iri, local);
    if (!v) return unexpected(v.error());
    u.*field = *v;
  }
  if (object(records, u.iri, "othersCount")) {
    auto n = int_of(records, u.iri, "othersCount");
    if (!n) return unexpected(n.error());
    u.others = static_cast<std::size_t>(std::max<std::int64_t>(0, *n));
  }
  auto from = derivations(records, u.iri);
  if (!from.empty()) u.window_iri = from.front();
  return u;
}

}  // namespace tahvel::aggregation
