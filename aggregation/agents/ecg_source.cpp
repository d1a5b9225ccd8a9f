// tahvel-ecg-source: an ECG sensor on the whiteboard. Replays a WFDB record (MIT-BIH) or
// generates a synthetic ECG (ECGSYN), and writes the recording item (persistent), one chunk
// item per second of signal (all leads), and at the end `<recording> tv:endSample N`. A
// recording is named by its agent, record and start: <agent>/recording/<name>-<UTC start>,
// e.g. http://example.org/home1/ecg/recording/100-20261130T174900Z.
//
//   tahvel-ecg-source DIR --record PATH | --synthetic [--seed N] [--hr BPM] [--seconds S]
//                     [--speed X] [--agent ID]
//
// --speed 1 (default) paces the chunks at real time, X at X times real time, 0 as fast as
// possible. Pacing follows a monotonic clock from the start (chunk k is written at
// t0 + (k + 1) s / X), so time does not drift however long the run. SIGINT/SIGTERM stop it
// after the current chunk: a signal of known length (a record, --seconds) is left open for the
// next run to go on with, a live one (--synthetic alone) is ended (the end item written).
#include <algorithm>
#include <charconv>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <filesystem>
#include <iostream>
#include <map>
#include <memory>
#include <optional>
#include <string_view>
#include <thread>

#include "agent_runtime.h"
#include "tahvel/aggregation/ecgsyn.h"
#include "tahvel/aggregation/rpeak.h"
#include "tahvel/aggregation/wfdb.h"

namespace {

namespace agg = tahvel::aggregation;
namespace rt = tahvel::agents::hrv;
using Frames = std::vector<std::vector<std::int32_t>>;

constexpr const char* kProgram = "tahvel-ecg-source";
constexpr const char* kUsage =
    "usage: tahvel-ecg-source DIR (--record PATH [--signal N] | --synthetic [--seed N] [--hr BPM] [--seconds S])\n"
    "                         [--speed X] [--agent ID]";

// Where the frames come from: fills `out` (one vector per lead) with up to n frames; 0 at end.
struct Signal {
  agg::RecordingInfo info;  // iri and sensor_iri are filled by the caller
  std::string name;         // recording name
  std::optional<std::int64_t> frames;  // how many the signal holds, when its source says
  std::function<agg::Result<std::size_t>(std::size_t n, Frames& out)> read;
};

// The digest of a record's samples that tells records apart which tv:replayedFrom names alike
// ("ecg/rec" of patientA/ecg/rec and of patientB/ecg/rec): FNV-1a (64 bits) over the values of
// every signal of its first kDigestFrames frames, read by a reader of its own. Identity, not
// security: recordings of two people do not begin with the same 4,096 frames of samples (records
// that begin flat, a lead off, may: they are told apart by name, rate, gain and leads only).
constexpr std::size_t kDigestFrames = 4096;

agg::Result<std::string> sample_digest(const std::string& path) {
  auto reader = agg::SignalReader::open(path);
  if (!reader) return tahvel::unexpected(reader.error());
  Frames frames(reader->header().signals.size());
  std::size_t taken = 0;
  while (taken < kDigestFrames) {
    auto got = reader->read(kDigestFrames - taken, frames);
    if (!got) return tahvel::unexpected(got.error());
    if (*got == 0) break;
    taken += *got;
  }
  std::uint64_t hash = 0xcbf29ce484222325ull;
  for (const auto& lead : frames)
    for (const std::int32_t v : lead)
      for (int byte = 0; byte < 4; ++byte) {
        hash ^= (static_cast<std::uint32_t>(v) >> (8 * byte)) & 0xffu;
        hash *= 0x100000001b3ull;
      }
  char text[40];
  std::snprintf(text, sizeof text, "fnv1a64:%016llx", static_cast<unsigned long long>(hash));
  return std::string(text);
}

// `signal`: the record's signal that is the ECG (0 the first), or nullopt for the one
// agg::ecg_signal chooses.
agg::Result<Signal> record_signal(const std::string& path, std::optional<std::size_t> signal) {
  auto reader = agg::SignalReader::open(path);
  if (!reader) return tahvel::unexpected(reader.error());
  auto shared = std::make_shared<agg::SignalReader>(std::move(*reader));
  const agg::RecordHeader& h = shared->header();
  if (auto rate = agg::default_rate_warning(h)) std::cerr << "tahvel-ecg-source: warning: " << *rate << "\n";
  // Samples the header's count leaves unread are said, as `tahvel hrv` says them: a header that
  // counts too few made a short recording without a word.
  for (const std::string& unread : agg::unread_samples(h)) std::cerr << "tahvel-ecg-source: warning: " << unread << "\n";
  Signal s;
  s.name = h.name;
  s.info.fs = h.fs;
  if (h.samples_per_signal > 0) s.frames = h.samples_per_signal;
  s.info.source = std::filesystem::path(h.directory).filename().string() + "/" + h.name;
  auto digest = sample_digest(path);
  if (!digest) return tahvel::unexpected(digest.error());
  s.info.sample_digest = std::move(*digest);
  // As `tahvel hrv`: a header without signals has no ECG (it wrote an empty recording, exit 0).
  if (h.signals.empty()) return agg::fail(h.path + ": the record has no signals, so no ECG");
  // The chunks carry the record's ECG lead first, whatever its place in the record (a record
  // may begin with respiration or blood pressure), with its gain per millivolt: the R-peak
  // agent reads the first lead at the recording's gain (agg::ecg_signal, as `tahvel hrv`).
  if (signal && *signal >= h.signals.size())
    return agg::fail(h.path + ": no signal " + std::to_string(*signal) + " (the record has " +
                     std::to_string(h.signals.size()) + "; --signal counts from 0)");
  const std::size_t ecg = signal ? *signal : agg::ecg_signal(h);
  if (auto why = agg::not_an_ecg_signal(h, ecg)) return agg::fail(*why);
  std::vector<std::size_t> order{ecg};
  for (std::size_t i = 0; i < h.signals.size(); ++i)
    if (i != ecg) order.push_back(i);
  if (auto units = agg::non_voltage_warning(h, ecg)) std::cerr << "tahvel-ecg-source: warning: " << *units << "\n";
  s.info.gain = agg::gain_per_mv(h.signals[ecg]);
  s.info.invalid_sample = agg::invalid_sample(h.signals[ecg]);
  // Chunks of 16-bit samples would wrap values of 24- and 32-bit formats, and format 8's
  // running sums, which no bound holds to 16 bits.
  for (const agg::SignalInfo& sig : h.signals)
    if (sig.format == 8 || sig.format == 24 || sig.format == 32) s.info.sample_bytes = 4;
  s.info.baseline = h.signals[ecg].baseline;
  s.info.unit = h.signals[ecg].units;
  if (s.info.gain != h.signals[ecg].gain) s.info.unit = "mV";  // converted from uV or V
  // A rate the R-peak detector refuses (too low for its QRS band, or beyond its buffers): the
  // recording is replayed all the same (it can be queried), but no beat will come of it, and the
  // R-peak agent says so only in its own log.
  agg::DetectorOptions detector;
  detector.fs = h.fs;
  detector.gain = s.info.gain != 0 ? s.info.gain : 200;
  if (auto usable = agg::validate(detector); !usable)
    std::cerr << "tahvel-ecg-source: warning: " << h.path << ": the R-peak agent will find no beat in this record: "
              << usable.error().message << "\n";
  for (std::size_t i : order) s.info.leads.push_back(h.signals[i].description);
  // Each lead's own calibration: beside the ECG a record may hold blood pressure (10 per mmHg)
  // or respiration, which the ECG lead's gain made wrong numbers of.
  for (std::size_t i : order) {
    const agg::SignalInfo& sig = h.signals[i];
    agg::RecordingInfo::LeadCalibration c{sig.gain == 0 ? 200 : sig.gain, sig.baseline, sig.units.empty() ? "mV" : sig.units,
                                          agg::invalid_sample(sig)};
    if (agg::gain_per_mv(sig) != c.gain) {  // uV or V: in mV, as the ECG lead (a negative gain kept)
      c.gain = agg::gain_per_mv(sig);
      c.unit = "mV";
    }
    s.info.calibration.push_back(c);
  }
  // What `tahvel hrv` warns of, said as the record streams: samples holding WFDB's no-value in
  // the ECG lead (the R-peak agent reads them as no signal: tv:invalidSample), and, at the end
  // of a record read from its start, checksums that do not add up.
  s.read = [shared, order, in_record = Frames(), sums = std::vector<std::uint16_t>(h.signals.size()),
            whole = shared->position() == 0, invalid_count = std::uint64_t{0},
            first_invalid = std::int64_t{-1}](std::size_t n, Frames& out) mutable -> agg::Result<std::size_t> {
    const agg::RecordHeader& header = shared->header();
    in_record.assign(order.size(), {});
    auto got = shared->read(n, in_record);
    if (!got) return got;
    for (std::size_t i = 0; i < sums.size() && i < in_record.size(); ++i)
      for (std::int32_t v : in_record[i]) sums[i] = static_cast<std::uint16_t>(sums[i] + static_cast<std::uint16_t>(v));
    const std::vector<std::int32_t>& ecg_lead = in_record[order[0]];
    const std::int32_t invalid = agg::invalid_sample(header.signals[order[0]]);
    const std::string lead = "signal " + std::to_string(order[0]) + " (" + header.signals[order[0]].description + ")";
    auto at_sample = [&](std::int64_t sample) {
      char text[64];
      std::snprintf(text, sizeof text, "sample %lld (%.3f s)", static_cast<long long>(sample), static_cast<double>(sample) / header.fs);
      return std::string(text);
    };
    // Said at the first (the agents downstream may be read meanwhile), and counted at the end:
    // "from sample N on" read as a lead lost for the rest of the record, when a few runs of
    // half a second were.
    if (const auto count = static_cast<std::uint64_t>(std::count(ecg_lead.begin(), ecg_lead.end(), invalid)); count > 0) {
      if (first_invalid < 0) {
        first_invalid = shared->position() - static_cast<std::int64_t>(ecg_lead.size()) +
                        (std::find(ecg_lead.begin(), ecg_lead.end(), invalid) - ecg_lead.begin());
        std::cerr << "tahvel-ecg-source: warning: " << header.path << ": " << lead << " holds WFDB's no-value " << invalid
                  << ", the first at " << at_sample(first_invalid)
                  << ": the R-peak agent reads such samples as no signal (the last valid sample held); how many is said at the "
                     "record's end\n";
      }
      invalid_count += count;
    }
    if (*got == 0 && invalid_count > 0) {
      std::cerr << "tahvel-ecg-source: warning: " << header.path << ": " << invalid_count << " sample(s) of " << lead
                << (whole ? "" : " sent") << " held WFDB's no-value " << invalid << ", the first at " << at_sample(first_invalid)
                << "\n";
      invalid_count = 0;  // said once, however often the end is read
      first_invalid = -1;
    }
    if (*got == 0 && whole)
      for (const std::string& mismatch : agg::checksum_mismatches(header, sums))
        std::cerr << "tahvel-ecg-source: warning: " << mismatch << "\n";
    out.resize(order.size());
    for (std::size_t k = 0; k < order.size(); ++k) out[k].insert(out[k].end(), in_record[order[k]].begin(), in_record[order[k]].end());
    return got;
  };
  return s;
}

agg::Result<Signal> synthetic_signal(const rt::Args& args) {
  agg::SyntheticEcgOptions options;
  options.seed = static_cast<std::uint64_t>(args.number("--seed", 1));
  // ECGSYN's range (SyntheticEcgOptions), said of the flag: the generator's own error named
  // its option mean_hr_bpm and exited 1 without the usage.
  const auto hr_out_of_range = [&] {
    return rt::UsageError("--hr: '" + args.text("--hr", "") + "' is not a heart rate from 30 to 180 beats per minute");
  };
  try {
    options.mean_hr_bpm = args.number("--hr", options.mean_hr_bpm, 30);
  } catch (const rt::UsageError&) {
    throw hr_out_of_range();
  }
  if (options.mean_hr_bpm > 180) throw hr_out_of_range();
  auto generator = agg::SyntheticEcg::create(options);
  if (!generator) return tahvel::unexpected(generator.error());
  const double seconds = args.number("--seconds", 0);
  const std::int64_t total = args.has("--seconds") ? std::llround(seconds * options.fs) : -1;
  // 0 read as "no limit" generated without end, and is no number of seconds to generate.
  if (args.has("--seconds") && total < 1)
    throw rt::UsageError("--seconds: '" + args.text("--seconds", "") +
                         "' is less than one sample; give the seconds to generate, or leave --seconds out to "
                         "generate until stopped");
  auto shared = std::make_shared<agg::SyntheticEcg>(std::move(*generator));
  Signal s;
  s.name = "synthetic-" + std::to_string(options.seed);
  if (total >= 0) s.frames = total;
  s.info.fs = options.fs;
  s.info.gain = options.gain;
  s.info.baseline = options.adc_zero;
  s.info.leads = {"ECGSYN"};
  s.info.source = "ecgsyn seed " + std::to_string(options.seed) + " hr " + args.text("--hr", "70");
  s.read = [shared, total](std::size_t n, Frames& out) -> agg::Result<std::size_t> {
    const std::int64_t left = total < 0 ? static_cast<std::int64_t>(n) : total - shared->samples_generated();
    const auto count = static_cast<std::size_t>(std::max<std::int64_t>(0, std::min<std::int64_t>(left, n)));
    out.resize(1);
    shared->generate(count, out[0]);
    return count;
  };
  return s;
}

// Sleeps until `deadline`, in short slices so that a signal ends the wait promptly.
void wait_until(std::chrono::steady_clock::time_point deadline) {
  while (!rt::stop_requested()) {
    const auto now = std::chrono::steady_clock::now();
    if (now >= deadline) return;
    std::this_thread::sleep_for(std::min<std::chrono::steady_clock::duration>(deadline - now,
                                                                             std::chrono::milliseconds(100)));
  }
}

// What an earlier run of this source left of a recording on the board.
struct EarlierRun {
  bool recording = false;                // the recording item is there
  std::optional<std::int64_t> end;       // its tv:endSample: that run ended it
  std::int64_t next = 0;                 // the frame after its last chunk
  std::optional<std::int64_t> start_ns;  // asserted-at of its frame 0 (from a chunk's time, else
                                         // its tv:startedAt)
  std::string replayed_from;             // its tv:replayedFrom (the record, or the generator's settings)
  std::string sample_digest;             // its tv:sampleDigest; empty in takes of older builds
  std::optional<double> fs, gain;        // its tv:samplingRate and tv:gain
  std::map<long, std::string> leads;     // its tv:lead values ("0 MLII"), by index
  bool ended_here = false;               // this run wrote its tv:endSample (another signal's take)
  std::string written_on;                // its tv:takeStore: the store it was written on, when said
};

// Whether a take with these settings holds `signal`: the same record or generator settings,
// read at the same rate and gain, and a record beginning with the same samples (a take of a
// build before tv:sampleDigest is judged without them).
bool same_signal(const EarlierRun& run, const Signal& signal) {
  const auto same = [](std::optional<double> a, double b) { return a && std::abs(*a - b) <= 1e-9 * std::abs(b); };
  // The leads in their order: MIT-BIH leads share a gain, and `--signal 1` of a record is
  // another signal than its lead 0 under the same name.
  std::vector<std::string> leads;
  for (const auto& [index, name] : run.leads) leads.push_back(name);
  const bool same_samples = run.sample_digest.empty() || run.sample_digest == signal.info.sample_digest;
  return run.replayed_from == signal.info.source && same_samples && same(run.fs, signal.info.fs) &&
         same(run.gain, signal.info.gain) && leads == signal.info.leads;
}

// What an earlier run left of the take `iri`; without `chunks_too` only what the recording item
// and its end say (not where its chunks stop).
tahvel::node::Result<EarlierRun> earlier_run(const rt::Session& session, const std::string& iri, double fs,
                                             bool chunks_too = true) {
  using tahvel::node::Term;
  const std::string tv = agg::kTv;
  auto snapshot = session.node.snapshot();
  if (!snapshot) return tahvel::unexpected(snapshot.error());
  EarlierRun run;
  tahvel::node::Pattern of_recording;
  of_recording.s = Term::iri(iri);
  of_recording.source = session.agent.iri();
  auto records = snapshot->list(of_recording);
  if (!records) return tahvel::unexpected(records.error());
  for (const auto& r : *records) {
    if (r.triple.p.value == tv + "endSample") run.end = std::strtoll(r.triple.o.value.c_str(), nullptr, 10);
    if (r.triple.p.value == tv + "samplingRate") {
      run.recording = true;
      run.fs = std::strtod(r.triple.o.value.c_str(), nullptr);
    }
    if (r.triple.p.value == tv + "gain") run.gain = std::strtod(r.triple.o.value.c_str(), nullptr);
    if (r.triple.p.value == tv + "lead") {
      const std::string& text = r.triple.o.value;
      const auto space = text.find(' ');
      run.leads[std::strtol(text.c_str(), nullptr, 10)] = space == std::string::npos ? "" : text.substr(space + 1);
    }
    if (r.triple.p.value == tv + "replayedFrom") run.replayed_from = r.triple.o.value;
    if (r.triple.p.value == tv + "sampleDigest") run.sample_digest = r.triple.o.value;
    if (r.triple.p.value == tv + "takeStore") run.written_on = r.triple.o.value;
    // The take's time axis before any chunk is on the board: a run killed before its first chunk
    // left the recording item alone, and the next one, going on under its name, stamped its
    // chunks from its own start, seconds after this: a time range of the take found no chunk.
    if (r.triple.p.value == tv + "startedAt") {
      std::int64_t at = 0;
      const std::string& v = r.triple.o.value;
      if (auto [end, ec] = std::from_chars(v.data(), v.data() + v.size(), at); ec == std::errc() && end == v.data() + v.size())
        run.start_ns = at;
    }
  }
  if (!chunks_too) return run;
  // Chunks name the recording (tv:recording) and say where they start and how many frames they
  // hold; the last one (by start) is where this run goes on.
  tahvel::node::Pattern chunks;
  chunks.p = Term::iri(tv + "recording");
  chunks.o = Term::iri(iri);
  chunks.source = session.agent.iri();
  auto named = snapshot->list(chunks);
  if (!named) return tahvel::unexpected(named.error());
  for (const auto& r : *named) {
    tahvel::node::Pattern chunk;
    chunk.s = r.triple.s;
    auto fields = snapshot->list(chunk);
    if (!fields) return tahvel::unexpected(fields.error());
    std::int64_t start = -1, frames = -1;
    for (const auto& f : *fields) {
      if (f.triple.p.value == tv + "startSample") start = std::strtoll(f.triple.o.value.c_str(), nullptr, 10);
      if (f.triple.p.value == tv + "frameCount") frames = std::strtoll(f.triple.o.value.c_str(), nullptr, 10);
    }
    if (start < 0 || frames < 0 || start + frames <= run.next) continue;
    run.next = start + frames;
    run.start_ns = r.meta.asserted_at - std::llround(static_cast<double>(start) * 1e9 / fs);
  }
  return run;
}

// Reads and drops `frames` frames (to where an earlier run stopped). False at the signal's end.
agg::Result<bool> skip(Signal& signal, std::int64_t frames) {
  Frames scratch;
  while (frames > 0) {
    for (auto& lead : scratch) lead.clear();
    auto got = signal.read(static_cast<std::size_t>(std::min<std::int64_t>(frames, 1 << 16)), scratch);
    if (!got) return tahvel::unexpected(got.error());
    if (*got == 0) return false;
    frames -= static_cast<std::int64_t>(*got);
  }
  return true;
}

// Whether `iri` is a take of the recording `base` (take_iri), or `base` itself, as sources named
// a first take before takes had a start.
bool is_take_of(const std::string& iri, const std::string& base) {
  if (iri == base) return true;
  if (iri.size() <= base.size() + 1 || iri.compare(0, base.size(), base) != 0 || iri[base.size()] != '-') return false;
  const std::string_view rest = std::string_view(iri).substr(base.size() + 1);
  auto digits = [](std::string_view t) {
    return !t.empty() && std::all_of(t.begin(), t.end(), [](char c) { return c >= '0' && c <= '9'; });
  };
  // YYYYMMDDTHHMMSSZ, then -N for a second take in the same second.
  if (rest.size() < 16 || !digits(rest.substr(0, 8)) || rest[8] != 'T' || !digits(rest.substr(9, 6)) || rest[15] != 'Z')
    return false;
  return rest.size() == 16 || (rest[16] == '-' && digits(rest.substr(17)));
}

// A take's IRI: the recording's base IRI and the UTC second it starts, <base>-20261130T174900Z.
std::string take_iri(const std::string& base, std::int64_t start_ns) {
  const std::time_t seconds = static_cast<std::time_t>(start_ns / 1'000'000'000);
  std::tm utc{};
  gmtime_r(&seconds, &utc);
  char stamp[32];
  std::strftime(stamp, sizeof stamp, "%Y%m%dT%H%M%SZ", &utc);
  return base + "-" + stamp;
}

// This source's takes of the recording `base` on the board, in the order they were written.
tahvel::node::Result<std::vector<std::string>> takes_on_board(const rt::Session& session, const std::string& base) {
  using tahvel::node::Term;
  auto snapshot = session.node.snapshot();
  if (!snapshot) return tahvel::unexpected(snapshot.error());
  tahvel::node::Pattern recordings;
  recordings.p = Term::iri("http://www.w3.org/1999/02/22-rdf-syntax-ns#type");
  recordings.o = agg::tv_term("EcgRecording");
  recordings.source = session.agent.iri();
  auto records = snapshot->list(recordings);
  if (!records) return tahvel::unexpected(records.error());
  std::vector<std::pair<std::uint64_t, std::string>> found;
  for (const auto& r : *records)
    if (is_take_of(r.triple.s.value, base)) found.emplace_back(r.meta.item, r.triple.s.value);
  std::sort(found.begin(), found.end());
  std::vector<std::string> takes;
  for (auto& [item, iri] : found)
    if (std::find(takes.begin(), takes.end(), iri) == takes.end()) takes.push_back(std::move(iri));
  return takes;
}

void say_nothing_more(const std::string& take, const Signal& signal) {
  rt::log_line(kProgram, "<" + take + "> holds the whole of " + signal.name + " (" + std::to_string(*signal.frames) +
                             " frames), replayed by an earlier run: nothing more to replay (remove that take, "
                             "tahvel remove --under its IRI, to replay it again)");
}

int replay(rt::Session& session, Signal& signal, double speed) {
  auto& agent = session.agent;
  // Each take of a recording has an IRI of its own, from its start: a source whose store was
  // made again (a sensor replaced) records under a name its parent has not seen, rather than
  // under the old take's, whose chunks the home holds and its R-peak agent has done. A restart
  // must not write the same seconds twice: a take an earlier run left without an end (the
  // source was killed) goes on after its last chunk, on the same time axis; one it ended (its
  // tv:endSample is there: it was stopped) is over, and this run takes anew; one that holds the
  // whole of this signal (same_signal: the same tv:replayedFrom, first samples, rate, gain and
  // leads; another --hr or a corrected header is another signal), the latest take or an older
  // one, is left as it is, and this run has nothing to do. A run stopped by a signal leaves a
  // take of known length open, as a kill does (below).
  const std::string base_iri = signal.info.iri;
  auto store_id_read = session.node.store_id();
  if (!store_id_read) {
    rt::log_line(kProgram, "reading the store's id: " + store_id_read.error().message);
    return rt::kExitError;
  }
  const std::string store_id = *store_id_read;
  const std::int64_t now_ns =
      std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch()).count();
  auto takes = takes_on_board(session, base_iri);
  if (!takes) {
    rt::log_line(kProgram, "reading the board: " + takes.error().message);
    return rt::kExitError;
  }
  EarlierRun earlier;
  if (!takes->empty()) {
    auto found = earlier_run(session, takes->back(), signal.info.fs);
    if (!found) {
      rt::log_line(kProgram, "reading the board: " + found.error().message);
      return rt::kExitError;
    }
    earlier = *found;
    // A take an earlier run left unended, of another signal (another record or lead, a
    // corrected header's rate or gain, other generator settings), is not this one's to go on
    // with: its frames would follow another signal's under the other's rate. It is ended where
    // it stops, and this run takes anew.
    if (!earlier.end && earlier.recording && !same_signal(earlier, signal)) {
      if (auto s = session.agent.store(agg::recording_end_item(takes->back(), earlier.next)); !s) {
        rt::log_line(kProgram, "store end item: " + s.error().message);
        return rt::kExitError;
      }
      const bool renamed = earlier.replayed_from == signal.info.source && !earlier.sample_digest.empty() &&
                           earlier.sample_digest != signal.info.sample_digest;
      rt::log_line(kProgram, "<" + takes->back() + ">, left unended by an earlier run, holds another signal (" +
                                 earlier.replayed_from + (renamed ? ", another record of that name: its first samples differ" : "") +
                                 "): ended at frame " + std::to_string(earlier.next) +
                                 "; recording anew");
      earlier.end = earlier.next;
      earlier.ended_here = true;
    }
    // A take left unended in a store that has since become a copy (restored from a backup, a
    // file copy; docs/protocol.md P6a) may have gone on in the store it was copied from, and
    // been ended there: its node above holds more of it, and its end. Going on from the copy's
    // last chunk gave that node a second end and a take that went on after it (its chain reset,
    // its HRV windows shifted and overlapping). This run takes anew; the end, if any, is the
    // other store's to have said.
    if (!earlier.end && earlier.recording && !earlier.written_on.empty() && earlier.written_on != store_id) {
      rt::log_line(kProgram, "<" + takes->back() + ">, left unended, was written on store " + earlier.written_on +
                                 ", and this store (" + store_id +
                                 ") is a copy of it or made again: the take may have gone on there after the copy; "
                                 "recording anew");
      earlier.end = earlier.next;
      earlier.ended_here = true;
    }
    if (!earlier.end) signal.info.iri = takes->back();
    // An earlier run replayed the whole signal (under an earlier supervisor, before a reboot or
    // a down and up): replaying it again would give the node above the same patient twice,
    // under a second take.
    if (earlier.end && signal.frames && *earlier.end >= *signal.frames && same_signal(earlier, signal)) {
      say_nothing_more(takes->back(), signal);
      return rt::kExitOk;
    }
    // Nor when an older take holds it whole (this record, then another, then this one again).
    if (earlier.end && signal.frames)
      for (auto take = std::next(takes->rbegin()); take != takes->rend(); ++take) {
        auto older = earlier_run(session, *take, signal.info.fs, false);
        if (!older) {
          rt::log_line(kProgram, "reading the board: " + older.error().message);
          return rt::kExitError;
        }
        if (older->end && *older->end >= *signal.frames && same_signal(*older, signal)) {
          say_nothing_more(*take, signal);
          return rt::kExitOk;
        }
      }
  }
  if (takes->empty() || earlier.end) {
    const std::string ended = takes->empty() || earlier.ended_here ? std::string() : takes->back();
    earlier = {};
    const std::string fresh = take_iri(base_iri, now_ns);  // the second of its tv:startedAt
    signal.info.iri = fresh;
    for (int again = 2; std::find(takes->begin(), takes->end(), signal.info.iri) != takes->end(); ++again)
      signal.info.iri = fresh + "-" + std::to_string(again);
    if (!ended.empty())
      rt::log_line(kProgram, "<" + ended + "> was ended by an earlier run; recording anew as <" + signal.info.iri + ">");
  }
  // A chunk holds when its first sample was taken: the replay's start plus the sample's offset
  // on the recording's own clock (at --speed N that clock runs N times faster than the wall's).
  const std::int64_t start_ns = earlier.start_ns.value_or(now_ns);
  signal.info.started_at = start_ns;
  if (!earlier.recording) {
    if (auto s = agent.store(agg::recording_item(signal.info)); !s) {
      rt::log_line(kProgram, "store recording item: " + s.error().message);
      return rt::kExitError;
    }
  }
  // The store the take is written on (local: the forwarding policy sends the recording's
  // description, not this), once per take and store; a take of a build before it was kept gets
  // it when this run goes on with it.
  if (earlier.written_on != store_id) {
    tahvel::node::Item written_on;
    written_on.persistent = true;
    written_on.add(tahvel::node::Term::iri(signal.info.iri), agg::tv_term("takeStore"), tahvel::node::Term::literal(store_id));
    if (auto s = agent.store(written_on); !s) {
      rt::log_line(kProgram, "store the take's store: " + s.error().message);
      return rt::kExitError;
    }
  }
  std::int64_t position = 0;
  if (earlier.next > 0) {
    auto more = skip(signal, earlier.next);
    if (!more) {
      rt::log_line(kProgram, "read: " + more.error().message);
      return rt::kExitError;
    }
    position = earlier.next;
    rt::log_line(kProgram, "<" + signal.info.iri + "> goes on from frame " + std::to_string(position) +
                               ", after the chunks an earlier run wrote");
  }
  const auto chunk = static_cast<std::size_t>(std::max(1.0, std::round(signal.info.fs)));
  // Pacing restarts here: the next chunk is due one chunk period from now.
  const auto t0 = std::chrono::steady_clock::now() -
                  std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                      std::chrono::duration<double>(static_cast<double>(position) / signal.info.fs / (speed > 0 ? speed : 1)));
  Frames frames;
  while (!rt::stop_requested()) {
    for (auto& lead : frames) lead.clear();
    auto got = signal.read(chunk, frames);
    if (!got) {
      rt::log_line(kProgram, "read: " + got.error().message);
      return rt::kExitError;
    }
    if (*got == 0) break;
    if (speed > 0)
      wait_until(t0 + std::chrono::duration_cast<std::chrono::steady_clock::duration>(std::chrono::duration<double>(
                          static_cast<double>(position + static_cast<std::int64_t>(*got)) / signal.info.fs / speed)));
    if (rt::stop_requested()) break;  // stopped while waiting: this chunk's time has not come
    // Asserted at its frames' time from signal.info.started_at (= start_ns), with their span.
    const tahvel::node::Item item = agg::ecg_chunk_item(signal.info, position, frames, 0, *got);
    if (auto s = agent.store(item); !s) {
      rt::log_line(kProgram, "store chunk " + std::to_string(position) + ": " + s.error().message);
      return rt::kExitError;
    }
    position += static_cast<std::int64_t>(*got);
  }
  // A replay stopped before its end (a `down` for maintenance, an operator's kill) is left
  // open, as a kill leaves it: the next run goes on from here under the same take. Ended, it
  // was over, and the next run replayed the record again from its start as a second take: the
  // hospital showed the patient twice, the same minutes under two names (a reliability
  // engineer's probe, session 89). A signal whose length is not known (a live source) ends.
  if (rt::stop_requested() && signal.frames && position < *signal.frames) {
    rt::log_line(kProgram, "stopped by signal at frame " + std::to_string(position) + " of " + std::to_string(*signal.frames) +
                               ": <" + signal.info.iri + "> is left open, and the next run goes on from there");
    return rt::kExitOk;
  }
  if (auto s = agent.store(agg::recording_end_item(signal.info.iri, position)); !s) {
    rt::log_line(kProgram, "store end item: " + s.error().message);
    return rt::kExitError;
  }
  rt::log_line(kProgram, "wrote " + std::to_string(position) + " frames of <" + signal.info.iri + ">" +
                             (rt::stop_requested() ? " (stopped by signal)" : ""));
  return rt::kExitOk;
}

}  // namespace

int main(int argc, char** argv) {
  return rt::guarded_main(kProgram, kUsage, [&]() -> int {
    const rt::Args args(argc, argv, {"--record", "--signal", "--seed", "--hr", "--seconds", "--speed", "--agent"},
                        {"--synthetic"});
    if (args.has("--record") && args.has("--synthetic"))
      throw rt::UsageError("--record and --synthetic: give one of them, not both (a record is replayed, or a synthetic signal made)");
    if (!args.has("--record") && !args.has("--synthetic")) throw rt::UsageError("give --record PATH or --synthetic");
    if (args.has("--signal") && !args.has("--record")) throw rt::UsageError("--signal is for --record");
    std::optional<std::size_t> ecg_lead;
    if (args.has("--signal")) {
      const double n = args.number("--signal", 0);
      if (n != std::floor(n) || n > 1e6)
        throw rt::UsageError("--signal must be a whole number from 0 (the first signal) to 1000000");
      ecg_lead = static_cast<std::size_t>(n);
    }
    const double speed = args.number("--speed", 1);
    if (args.has("--record")) rt::stop_here_when_only_checking();  // before it is read (`up` opened it)
    rt::install_stop_handlers();
    auto signal = args.has("--record") ? record_signal(args.text("--record", ""), ecg_lead) : synthetic_signal(args);
    rt::stop_here_when_only_checking();  // a synthetic signal's flags are checked as it is made
    if (!signal) {
      rt::log_line(kProgram, signal.error().message);
      return rt::kExitError;
    }
    auto session = rt::open_session(kProgram, args.dir(), args.text("--agent", "ecg"));
    if (!session) return rt::kExitError;
    signal->info.sensor_iri = session->agent.iri();
    signal->info.iri = session->agent.iri() + "/recording/" + signal->name;
    return replay(*session, *signal, speed);
  });
}
