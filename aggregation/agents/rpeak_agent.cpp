// tahvel-rpeak: R-peak detection as a whiteboard agent. Subscribes to ECG chunks (tv:samples)
// and to recording ends (tv:endSample); keeps one streaming RPeakDetector per recording (fs and
// gain from the recording item, lead 0) and writes, per chunk, the R-peak item
// <recording>/rpeaks/<first sample> derived from the chunk; at the end of a recording, one more
// with the peaks finish() releases and tv:endSample.
//
//   tahvel-rpeak DIR [--agent ID] [--idle S] [--warm-up S]
//
// Chunks must follow each other (tv:startSample = the previous chunk's end): an earlier one is
// a repeat (skipped), a later one a gap (logged; the detector restarts at the new chunk).
// A recording it cannot use (no recording item, an unusable fs or gain) has its chunks logged
// and skipped, and is the agent's problem on the board while they are (docs/agents.md).
// (Re)start: the first chunk of a recording that does not start at sample 0 makes the agent
// rebuild its detector from the board: it replays the recording's earlier chunks (ten minutes
// of signal in memory at a time) through a new detector, writing only the R-peak items that are
// not on the board yet, so its peaks are those an uninterrupted run gives (after a restart
// nothing is repeated; after a late start the early items are written). With --warm-up S it
// first reads only the last S seconds again and compares the R-peak items of their second half
// with the board's: when they agree it goes on from there (a restart costs S seconds of signal,
// not the recording), when they do not it tries four times as far back, and an item missing
// (a late start) means the replay. A warm-up that agrees almost always leaves the detector as
// the run before left it, not always (docs/agents.md, "Restart").
#include <algorithm>
#include <cmath>
#include <map>
#include <optional>

#include <iostream>

#include "agent_runtime.h"
#include "tahvel/aggregation/rpeak.h"

namespace {

namespace agg = tahvel::aggregation;
namespace rt = tahvel::agents::hrv;
namespace tn = tahvel::node;

constexpr const char* kProgram = "tahvel-rpeak";

struct Stream {
  agg::RecordingInfo info;
  agg::RPeakDetector detector;
  std::int64_t offset = 0;  // sample index of the detector's first sample
  std::int64_t next = 0;    // start of the chunk expected next
  // The last beat found, or where the signal without one began (the stream's start, a gap).
  std::int64_t beat_or_start = 0;
};

// Signal without a beat for this long is said as the agent's problem: a lead off, a gain off by
// far, a channel that is not an ECG give R-peak items without peaks, and so no RR and no HRV,
// and the recording was nowhere to be seen (a probe); so does an asystole, which is worth
// saying too. The detector decides on a beat up to about a second after it: 12 s of signal
// without one is at least 10 s of none.
constexpr double kSilentSeconds = 12;

class RPeakStage {
 public:
  RPeakStage(rt::Session& session, double warm_up_s)
      : session_(session), skipped_(session, "recording(s)"), warm_up_s_(warm_up_s) {}

  rt::Outcome handle(const tn::Delivery& delivery) {
    const auto& records = delivery.records;
    if (rt::has_predicate(records, "samples")) return on_chunk(records);
    // tv:endSample also closes the derived items (ours included): only the source's counts.
    if (rt::has_predicate(records, "peaks") || rt::has_predicate(records, "intervals")) return rt::Outcome::ok();
    if (rt::has_predicate(records, "endSample")) return on_end(records);
    return rt::Outcome::ok();  // another triple of a subscribed shape: nothing to do
  }

 private:
  static agg::DetectorOptions detector_options(const agg::RecordingInfo& info) {
    agg::DetectorOptions options;
    options.fs = info.fs;
    options.gain = info.gain;
    options.invalid_sample = info.invalid_sample;
    return options;
  }

  // The stream of a recording, created on first use and brought up to `upto` from the board.
  Stream* stream_for(const std::string& recording, std::int64_t upto, rt::Outcome& outcome) {
    if (auto it = streams_.find(recording); it != streams_.end()) return &it->second;
    auto info = rt::load_recording(session_.node, recording);
    if (!info) {
      unusable(recording, info.error().message);
      return nullptr;
    }
    if (auto valid = agg::validate(detector_options(*info)); !valid) {
      unusable(recording, "<" + recording + ">: " + valid.error().message);
      return nullptr;
    }
    Stream& s = streams_.emplace(recording, Stream{*info, agg::RPeakDetector(detector_options(*info))}).first->second;
    if (upto > 0) outcome = catch_up(s, upto);
    return &s;
  }

  // After a (re)start at `upto`: brings the new detector to where the run before left it,
  // from a warm-up that agrees with the board, or else by replaying the recording.
  rt::Outcome catch_up(Stream& s, std::int64_t upto) {
    std::optional<Stream> agreed;
    auto resumed = rt::resume_by_warm_up(kProgram, s.info, upto, warm_up_s_, "chunk(s)", [&](std::int64_t start) {
      return warm_up(s.info, start, upto, agreed);
    });
    if (!resumed) return rt::Outcome::error(resumed.error().message);
    if (!*resumed) return replay(s, upto);
    s = std::move(*agreed);
    return rt::Outcome::ok();
  }

  // Reads the chunks [start, upto) through a new detector, writing nothing, and compares the
  // R-peak items of the second half with the board's. Equal items there mean the detector has
  // forgotten where it began (its adaptive state is of the last beats and seconds) and is in
  // the state the run before was in at `upto`: then `agreed` holds it.
  agg::Result<rt::WarmUp> warm_up(const agg::RecordingInfo& info, std::int64_t start, std::int64_t upto,
                                  std::optional<Stream>& agreed) {
    rt::WarmUp w;
    Stream s{info, agg::RPeakDetector(detector_options(info))};
    const std::int64_t check_from = start + (upto - start) / 2;
    auto since = agg::signal_time_ns(info, static_cast<double>(start) / info.fs);
    auto until = agg::signal_time_ns(info, static_cast<double>(upto) / info.fs);
    if (!since || !until) return w;  // missing: the replay reads it all
    bool differs = false, missing = false;
    auto read = rt::for_each_recording_item(session_.node, info.iri, *since, *until, [&](const std::vector<tn::Record>& records) {
      auto chunk = agg::read_chunk(records);
      if (!chunk || chunk->start_sample < start || chunk->start_sample >= upto) return true;
      if (w.read++ == 0) s.offset = s.next = s.beat_or_start = chunk->start_sample;
      if (chunk->start_sample < s.next) return true;  // a repeat
      const agg::RPeaks out = detect(s, *chunk, true);
      if (out.from_sample < check_from) return true;
      const std::string iri = agg::rpeaks_iri(info.iri, out.from_sample);
      auto on_board = rt::item_about(session_.node, iri);
      auto theirs = on_board ? agg::read_rpeaks(*on_board) : agg::Result<agg::RPeaks>(agg::fail("none"));
      if (!theirs) {
        missing = true;
        return false;
      }
      if (theirs->peaks != out.peaks || theirs->empty_gap_ends != out.empty_gap_ends ||
          theirs->p_wave_gap_ends != out.p_wave_gap_ends || theirs->to_sample != out.to_sample) {
        w.why = "found other peaks than <" + iri + "> on the board";
        differs = true;
        return false;
      }
      ++w.compared;
      return true;
    });
    if (!read) return agg::fail(read.error().message);
    if (differs) w.verdict = rt::WarmUp::Verdict::differs;
    else if (!missing && w.compared > 0) {
      w.verdict = rt::WarmUp::Verdict::agreed;
      agreed.emplace(std::move(s));
    }
    return w;
  }

  // Feeds the recording's chunks [0, upto) that are on the board through the new detector,
  // writing the R-peak items that are missing (the early ones after a late start).
  rt::Outcome replay(Stream& s, std::int64_t upto) {
    std::size_t replayed = 0;
    rt::Outcome outcome;
    const auto each = [&](const agg::EcgChunk& chunk) {
      if (chunk.start_sample >= upto || (replayed > 0 && chunk.start_sample < s.next)) return true;
      ++replayed;
      outcome = process(s, chunk, true);
      return !outcome.fatal;
    };
    auto since = agg::signal_time_ns(s.info, 0);
    auto until = agg::signal_time_ns(s.info, static_cast<double>(upto) / s.info.fs);
    if (since && until) {
      auto read = rt::for_each_recording_item(session_.node, s.info.iri, *since, *until, [&](const std::vector<tn::Record>& records) {
        auto chunk = agg::read_chunk(records);
        return !chunk || each(*chunk);
      });
      if (!read) return rt::Outcome::error("catch up <" + s.info.iri + ">: " + read.error().message);
    } else {  // a recording without its start time: its items are not at signal times
      auto items = rt::recording_items(session_.node, s.info.iri);
      if (!items) return rt::Outcome::error("catch up <" + s.info.iri + ">: " + items.error().message);
      std::map<std::int64_t, agg::EcgChunk> chunks;
      for (const auto& records : *items)
        if (auto chunk = agg::read_chunk(records)) chunks.emplace(chunk->start_sample, std::move(*chunk));
      for (auto& [start, chunk] : chunks)
        if (!each(chunk)) break;
    }
    if (outcome.fatal) return outcome;
    rt::log_line(kProgram, "replayed " + std::to_string(replayed) + " earlier chunk(s) of <" + s.info.iri +
                               "> from the board, up to sample " + std::to_string(s.next));
    return rt::Outcome::ok();
  }

  // Feeds one chunk (lead 0) to the stream's detector, restarting it at a gap (said unless
  // quiet), and returns the chunk's R-peak item.
  agg::RPeaks detect(Stream& s, const agg::EcgChunk& chunk, bool quiet) {
    agg::RPeaks out;
    out.recording = s.info.iri;
    out.from_sample = chunk.start_sample;
    if (chunk.start_sample != s.next) {
      if (!quiet)
        rt::log_line(kProgram, "<" + s.info.iri + ">: gap from sample " + std::to_string(s.next) + " to " +
                                   std::to_string(chunk.start_sample) + "; the detector restarts");
      // The old detector still holds the beats of its last half second (its decision delay);
      // they belong to the signal before the gap, so they are released and go in this item
      // (an item's peaks may lie before its from_sample) rather than being dropped.
      std::vector<std::int64_t> held, held_gaps, held_p_waves;
      s.detector.finish(held, held_gaps, held_p_waves);
      for (auto p : held) out.peaks.push_back(p + s.offset);
      for (auto p : held_gaps) out.empty_gap_ends.push_back(p + s.offset);
      for (auto p : held_p_waves) out.p_wave_gap_ends.push_back(p + s.offset);
      s.detector = agg::RPeakDetector(detector_options(s.info));
      s.offset = chunk.start_sample;
      s.beat_or_start = chunk.start_sample;
    }
    std::vector<std::int64_t> found, gaps, p_waves;
    s.detector.push(chunk.leads[0].data(), chunk.frames, found, gaps, p_waves);
    for (auto p : found) out.peaks.push_back(p + s.offset);
    for (auto p : gaps) out.empty_gap_ends.push_back(p + s.offset);
    for (auto p : p_waves) out.p_wave_gap_ends.push_back(p + s.offset);
    s.next = out.to_sample = chunk.start_sample + static_cast<std::int64_t>(chunk.frames);
    if (!out.peaks.empty()) s.beat_or_start = std::max(s.beat_or_start, *std::max_element(out.peaks.begin(), out.peaks.end()));
    out.derived_from = chunk.iri;
    return out;
  }

  // Feeds one chunk and writes its R-peak item.
  rt::Outcome process(Stream& s, const agg::EcgChunk& chunk, bool catching_up) {
    const agg::RPeaks out = detect(s, chunk, false);
    note_beats(s, !out.peaks.empty());
    tn::Item item = agg::rpeak_item(out);
    item.asserted_at = agg::signal_time_ns(s.info, static_cast<double>(out.from_sample) / s.info.fs);
    return rt::store_output(session_, item, catching_up);
  }

  // Its own key: a chunk used resumes the recording's key (its chunks are not skipped), and a
  // silence goes on through many used chunks.
  static std::string silent_key(const std::string& recording) { return "no beat in " + recording; }

  // A recording whose signal has had no beat for kSilentSeconds is the agent's problem until a
  // beat is found or the recording ends.
  void note_beats(const Stream& s, bool found_beats) {
    if (found_beats) {
      skipped_.resume(silent_key(s.info.iri));
      return;
    }
    const double silent = static_cast<double>(s.next - s.beat_or_start) / s.info.fs;
    if (silent < kSilentSeconds) return;
    skipped_.hold(silent_key(s.info.iri), "<" + s.info.iri + ">: no beat found in " +
                                  (s.beat_or_start == s.offset ? "its signal since sample " : "its signal after the beat at sample ") +
                                  std::to_string(s.beat_or_start) +
                                  " (a flat or lead-off signal, a gain in its description off by far, or not an ECG; or an "
                                  "asystole): no R-peaks, RR intervals or HRV come of it until a beat is found again");
  }

  // A recording whose chunks cannot be used (no recording item, a sampling rate or gain the
  // detector cannot take) yields no R-peaks, so no RR and no HRV at home or at the hospital:
  // the agent's problem while they are skipped, until a chunk of it is used or it ends.
  void unusable(const std::string& recording, const std::string& why) {
    skipped_.skip(recording, why, "its ECG chunks");
  }

  rt::Outcome on_chunk(const std::vector<tn::Record>& records) {
    auto chunk = agg::read_chunk(records);
    if (!chunk) {
      rt::log_line(kProgram, chunk.error().message + "; skipped");
      return rt::Outcome::ok();
    }
    rt::Outcome outcome;
    Stream* s = stream_for(chunk->recording, chunk->start_sample, outcome);
    if (!s || outcome.fatal) return outcome;
    skipped_.resume(chunk->recording);
    if (chunk->start_sample < s->next) {
      rt::log_line(kProgram, "<" + chunk->iri + ">: already processed; skipped");
      return rt::Outcome::ok();
    }
    return process(*s, *chunk, false);
  }

  rt::Outcome on_end(const std::vector<tn::Record>& records) {
    for (const tn::Record& r : records) {
      if (r.triple.p.value != std::string(agg::kTv) + "endSample" || !r.triple.s.is_iri()) continue;
      const std::string recording = r.triple.s.value;
      const auto end = rt::parse_int(r.triple.o.value);
      if (!end) {
        rt::log_line(kProgram, "<" + recording + ">: tv:endSample '" + r.triple.o.value + "' is not an integer; skipped");
        continue;
      }
      rt::Outcome outcome;
      Stream* s = stream_for(recording, *end, outcome);
      skipped_.resume(recording);  // used, or over: its chunks are not being skipped any more
      skipped_.resume(silent_key(recording));
      if (!s || outcome.fatal) return outcome;
      agg::RPeaks out;
      out.recording = recording;
      out.from_sample = out.to_sample = s->next;
      s->detector.finish(out.peaks, out.empty_gap_ends, out.p_wave_gap_ends);
      for (auto& p : out.peaks) p += s->offset;
      for (auto& p : out.empty_gap_ends) p += s->offset;
      for (auto& p : out.p_wave_gap_ends) p += s->offset;
      out.derived_from = recording;
      out.end_sample = *end;
      tn::Item item = agg::rpeak_item(out);
      item.asserted_at = agg::signal_time_ns(s->info, static_cast<double>(out.from_sample) / s->info.fs);
      if (auto o = rt::store_output(session_, item, false); o.fatal) return o;
      streams_.erase(recording);
    }
    return rt::Outcome::ok();
  }

  rt::Session& session_;
  std::map<std::string, Stream> streams_;
  rt::SkippedInputs skipped_;
  const double warm_up_s_;  // --warm-up
};

}  // namespace

int main(int argc, char** argv) {
  return rt::guarded_main(kProgram, "usage: tahvel-rpeak DIR [--agent ID] [--idle S] [--warm-up S]", [&]() -> int {
    const rt::Args args(argc, argv, {"--agent", "--idle", "--warm-up"}, {});
    const double idle = args.number("--idle", 0);
    const double warm_up = rt::warm_up_seconds(args);
    rt::install_stop_handlers();
    auto session = rt::open_session(kProgram, args.dir(), args.text("--agent", "rpeak"));
    if (!session) return rt::kExitError;
    if (!rt::subscribe_predicates(*session, {std::string(agg::kTv) + "samples", std::string(agg::kTv) + "endSample"}))
      return rt::kExitError;
    RPeakStage stage(*session, warm_up);
    return rt::run_take_loop(*session, idle, [&](const tn::Delivery& d) { return stage.handle(d); });
  });
}
