// tahvel-rr: RR intervals and the NN mark as a whiteboard agent. Subscribes to R-peak items
// (tv:peaks); keeps one streaming NnClassifier per recording (fs from the recording item) and
// writes, whenever intervals are decided, the RR item <recording>/rr/<first start> with
// tv:intervals "start end nn;..." derived from the R-peak items read since the previous RR item.
// The R-peak item that carries tv:endSample finishes the classifier; the RR item written then
// carries tv:endSample too (named <recording>/rr/end when it holds no interval).
//
//   tahvel-rr DIR [--agent ID] [--idle S]
//
// R-peak items must follow each other (tv:fromSample = the previous tv:toSample): an earlier
// one is a repeat (skipped), a later one a gap (logged; the classifier restarts).
// An R-peak item it cannot read, or of a recording without a recording item, is logged and
// skipped, and is the agent's problem on the board while such items are (docs/agents.md).
// (Re)start: the first R-peak item of a recording that does not start at sample 0 makes the
// agent replay the recording's earlier R-peak items from the board (ten minutes of signal in
// memory at a time) through a new classifier, writing only the RR items that are not on the
// board yet.
#include <map>
#include <optional>

#include <iostream>

#include "agent_runtime.h"
#include "tahvel/aggregation/rr.h"

namespace {

namespace agg = tahvel::aggregation;
namespace rt = tahvel::agents::hrv;
namespace tn = tahvel::node;

constexpr const char* kProgram = "tahvel-rr";

struct Stream {
  std::string recording;
  agg::NnClassifier classifier;
  std::int64_t next = 0;                // tv:fromSample expected next
  std::vector<std::string> read_since;  // R-peak items read since the last RR item
  agg::RecordingInfo info{};            // for the signal time its items are asserted at
};

class RrStage {
 public:
  explicit RrStage(rt::Session& session) : session_(session), skipped_(session, "recording(s) or writer(s)") {}

  rt::Outcome handle(const tn::Delivery& delivery) {
    // Unreadable items are a cause per writer: a detector of another version writes them all so.
    const std::string writer = delivery.records.empty() ? std::string() : delivery.records.front().meta.source;
    auto peaks = agg::read_rpeaks(delivery.records);
    if (!peaks) {
      skipped_.skip("writer " + writer, peaks.error().message, "the R-peak items of <" + writer + "> it cannot read");
      return rt::Outcome::ok();
    }
    skipped_.resume("writer " + writer);
    rt::Outcome outcome;
    Stream* s = stream_for(peaks->recording, peaks->from_sample, outcome);
    // Without its description a recording's intervals cannot be timed: a cause until it is
    // used or ends.
    if (s || peaks->end_sample) skipped_.resume("recording " + peaks->recording);
    if (!s || outcome.fatal) return outcome;
    if (peaks->from_sample < s->next) {
      rt::log_line(kProgram, "<" + peaks->iri + ">: already processed; skipped");
      return rt::Outcome::ok();
    }
    return process(*s, *peaks, false);
  }

 private:
  Stream* stream_for(const std::string& recording, std::int64_t upto, rt::Outcome& outcome) {
    if (auto it = streams_.find(recording); it != streams_.end()) return &it->second;
    auto info = rt::load_recording(session_.node, recording);
    if (!info) {
      skipped_.skip("recording " + recording, info.error().message, "its R-peak items");
      return nullptr;
    }
    Stream& s = streams_.emplace(recording, Stream{recording, agg::NnClassifier(info->fs), 0, {}, *info}).first->second;
    if (upto > 0) outcome = catch_up(s, upto);
    return &s;
  }

  // The recording's R-peak items from `start` (not the end's) before `upto`, in order, each
  // once: `each` returns false to stop.
  agg::Result<void> for_each_rpeaks(const Stream& s, std::int64_t start, std::int64_t upto,
                                    const std::function<bool(const agg::RPeaks&)>& each) {
    auto since = agg::signal_time_ns(s.info, static_cast<double>(start) / s.info.fs);
    auto until = agg::signal_time_ns(s.info, static_cast<double>(upto) / s.info.fs);
    if (since && until)
      return rt::for_each_recording_item(session_.node, s.recording, *since, *until, [&](const std::vector<tn::Record>& records) {
        auto p = agg::read_rpeaks(records);
        return !p || p->end_sample || p->from_sample < start || p->from_sample >= upto || each(*p);
      });
    // A recording without its start time: its items are not at signal times.
    auto items = rt::recording_items(session_.node, s.recording);
    if (!items) return agg::fail(items.error().message);
    std::map<std::int64_t, agg::RPeaks> earlier;
    for (const auto& records : *items)
      if (auto p = agg::read_rpeaks(records); p && p->from_sample >= start && p->from_sample < upto && !p->end_sample)
        earlier.emplace(p->from_sample, std::move(*p));
    for (const auto& [from, p] : earlier)
      if (!each(p)) break;
    return {};
  }

  // After a (re)start: feeds the recording's R-peak items before `upto` that are on the board
  // through the new classifier, writing the RR items that are missing (the early ones after a
  // late start). Not from a warm-up, as tahvel-rpeak may: a classifier fed from the middle of a
  // recording took another state than the run before while the RR items of its last minutes
  // agreed with the board's (record 221: windows after the restart otherwise), and the R-peak
  // items are small.
  rt::Outcome catch_up(Stream& s, std::int64_t upto) {
    std::size_t replayed = 0;
    rt::Outcome outcome;
    auto read = for_each_rpeaks(s, 0, upto, [&](const agg::RPeaks& p) {
      if (replayed > 0 && p.from_sample < s.next) return true;  // a repeat
      ++replayed;
      outcome = process(s, p, true);
      return !outcome.fatal;
    });
    if (!read) return rt::Outcome::error("catch up <" + s.recording + ">: " + read.error().message);
    if (outcome.fatal) return outcome;
    rt::log_line(kProgram, "replayed " + std::to_string(replayed) + " earlier R-peak item(s) of <" + s.recording +
                               "> from the board, up to sample " + std::to_string(s.next));
    return rt::Outcome::ok();
  }

  // Pushes the peaks of one R-peak item; returns the RR item when intervals were decided or
  // the recording ended.
  std::optional<agg::RrSeries> decide(Stream& s, const agg::RPeaks& p) {
    agg::RrSeries out;
    out.recording = s.recording;
    if (p.from_sample != s.next) {
      rt::log_line(kProgram, "<" + p.recording + ">: gap from sample " + std::to_string(s.next) + " to " +
                                 std::to_string(p.from_sample) + "; the NN classifier restarts");
      s.classifier.finish(out.intervals);
    }
    // The detector's gap evidence (empty gaps, blocked P waves) travels with the peaks, so the
    // classifier decides as intervals_from_peaks does in `tahvel hrv`.
    auto gap = p.empty_gap_ends.begin();
    auto p_wave = p.p_wave_gap_ends.begin();
    for (std::int64_t peak : p.peaks) {
      while (gap != p.empty_gap_ends.end() && *gap < peak) ++gap;
      while (p_wave != p.p_wave_gap_ends.end() && *p_wave < peak) ++p_wave;
      s.classifier.push(peak, gap != p.empty_gap_ends.end() && *gap == peak,
                        p_wave != p.p_wave_gap_ends.end() && *p_wave == peak, out.intervals);
    }
    s.next = p.to_sample;
    s.read_since.push_back(p.iri);
    if (p.end_sample) {
      s.classifier.finish(out.intervals);
      out.end_sample = p.end_sample;
    }
    if (out.intervals.empty() && !out.end_sample) return std::nullopt;
    out.derived_from = std::move(s.read_since);
    s.read_since.clear();
    return out;
  }

  // Pushes the peaks of one R-peak item; writes an RR item when intervals were decided or the
  // recording ended (then the stream is closed).
  rt::Outcome process(Stream& s, const agg::RPeaks& p, bool catching_up) {
    auto out = decide(s, p);
    if (!out) return rt::Outcome::ok();
    tn::Item item = agg::rr_item(*out);
    const std::int64_t first = out->intervals.empty() ? p.from_sample : out->intervals.front().start;
    item.asserted_at = agg::signal_time_ns(s.info, static_cast<double>(first) / s.info.fs);
    if (p.end_sample) streams_.erase(p.recording);  // s is gone from here on
    return rt::store_output(session_, item, catching_up);
  }

  rt::Session& session_;
  std::map<std::string, Stream> streams_;
  rt::SkippedInputs skipped_;
};

}  // namespace

int main(int argc, char** argv) {
  return rt::guarded_main(kProgram, "usage: tahvel-rr DIR [--agent ID] [--idle S]", [&]() -> int {
    const rt::Args args(argc, argv, {"--agent", "--idle"}, {});
    const double idle = args.number("--idle", 0);
    rt::install_stop_handlers();
    auto session = rt::open_session(kProgram, args.dir(), args.text("--agent", "rr"));
    if (!session) return rt::kExitError;
    if (!rt::subscribe_predicates(*session, {std::string(agg::kTv) + "peaks"})) return rt::kExitError;
    RrStage stage(*session);
    return rt::run_take_loop(*session, idle, [&](const tn::Delivery& d) { return stage.handle(d); });
  });
}
