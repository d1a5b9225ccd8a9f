// tahvel-hrv: HRV per window as a whiteboard agent. Subscribes to RR items (tv:intervals) and
// to its configuration (triples whose subject is its own agent IRI); keeps one HrvWindower per
// recording and writes one HRV window item per completed window, <recording>/hrv/<start_s>,
// derived from the recording and the RR items whose intervals end in the window. The RR item
// with tv:endSample finishes the recording's windows.
//
//   tahvel-hrv DIR [--agent ID] [--idle S] [--window S] [--step S]
//
// Configuration (persistent or not, any writer):
//   <node>/hrv tv:windowSeconds 120 ; tv:stepSeconds 60 .     (step defaults to the window)
// read at start and again whenever an item with such a triple arrives; the latest value of each
// wins, over --window/--step (default 300 s, non-overlapping). A change applies from the next
// window not yet produced (HrvWindower::set_window).
// (Re)start: a recording seen for the first time is replayed from its earlier RR items on the
// board through a new windower, from the end of the last window it wrote (HrvWindower::
// resume_after), so windows open at a crash come out as they would have (with the
// configuration in force now), and none overlaps one already written.
#include <algorithm>
#include <chrono>
#include <charconv>
#include <cmath>
#include <deque>
#include <limits>
#include <map>
#include <optional>
#include <set>

#include <iostream>
#include <vector>

#include "agent_runtime.h"
#include "tahvel/aggregation/hrv.h"
#include "tahvel/uri/iri.h"

namespace {

namespace agg = tahvel::aggregation;
namespace rt = tahvel::agents::hrv;
namespace tn = tahvel::node;

constexpr const char* kProgram = "tahvel-hrv";

// `v` as an xsd:decimal lexical form ("120", "0.5").
std::string number_text(double v) {
  char buf[64];
  auto [end, ec] = std::to_chars(buf, buf + sizeof buf, v, std::chars_format::fixed);
  return ec == std::errc() ? std::string(buf, end) : std::to_string(v);
}

struct WindowConfig {
  double window_s = 300, step_s = 0;  // step 0: the window length
  double step() const { return step_s > 0 ? step_s : window_s; }
};

// An RR item and the span of its interval ends (samples): which windows it fed.
struct RrRef {
  std::string iri;
  std::int64_t first_end = 0, last_end = 0;
};

struct Stream {
  agg::RecordingInfo info;
  agg::HrvWindower windower;
  std::int64_t last_end = -1;  // end of the last interval pushed
  std::deque<RrRef> refs;
};

class HrvStage {
 public:
  HrvStage(rt::Session& session, WindowConfig defaults) : session_(session), defaults_(defaults), config_(defaults) {}

  // Reads the agent's configuration triples from the board; the latest of each wins.
  void load_config() {
    auto snapshot = session_.node.snapshot();
    if (!snapshot) return rt::log_line(kProgram, "read configuration: " + snapshot.error().message);
    // By predicate, then by subject in normal form: a setting written for
    // <https://Haigla.Example.EE/…/hrv>, as a topology file may spell the node's IRI, reached
    // this agent and was read by none (its IRI is <https://haigla.example.ee/…/hrv>).
    std::vector<tn::Record> found;
    for (const char* setting : {"windowSeconds", "stepSeconds"}) {
      auto records = snapshot->list({.p = agg::tv_term(setting)});
      if (!records) return rt::log_line(kProgram, "read configuration: " + records.error().message);
      for (tn::Record& r : *records)
        if (is_me(r.triple.s)) found.push_back(std::move(r));
    }
    std::sort(found.begin(), found.end(), [](const tn::Record& a, const tn::Record& b) { return a.meta.id < b.meta.id; });
    auto records = &found;
    // The latest written wins, wherever it was written: by asserted-at (when the writer stored
    // it, kept as the item travels down), then by arrival. By arrival alone, a hospital's
    // setting held back by a cut link undid the home's newer one when the link came back.
    std::stable_sort(records->begin(), records->end(),
                     [](const tn::Record& a, const tn::Record& b) { return a.meta.asserted_at < b.meta.asserted_at; });
    // From --window and --step: a setting taken back (removed) leaves what the board still says,
    // or those, not the value it had set.
    WindowConfig next = defaults_;
    // Whether the window and the step in force came from records a ring or TTL may reclaim.
    bool window_evictable = false, step_evictable = false;
    // The last pair the records made, in their order, that can be used together (the flags'
    // at first): it stands when the latest pair cannot (a day's window over a second's step).
    // Taken from the board alone, so that a restart runs what ran before it.
    WindowConfig usable_pair = next;
    // The latest setting of the window and of the step when the agent cannot use it: its
    // problem, for `tahvel status` here and at the hospital that wrote it.
    std::string unusable[2];
    for (const tn::Record& r : *records) {  // later values win
      const bool window = r.triple.p.value == std::string(agg::kTv) + "windowSeconds";
      if (!window && r.triple.p.value != std::string(agg::kTv) + "stepSeconds") continue;
      // A decimal number as written in RDF ("120", "120.5", "1.2e2"), not what strtod also
      // takes ("0x78", " 120", "inf").
      const std::string& text = r.triple.o.value;
      const char* begin = text.data() + (text.starts_with('+') ? 1 : 0);
      double v = 0;
      const auto [end, ec] = std::from_chars(begin, text.data() + text.size(), v);
      // As --window and --step take them (agg::window_setting_problem): a window of a
      // millisecond made millions of windows out of one RR item (memory without bound, no stop
      // between items), and a setting may come from the hospital, where no one sees this log.
      const bool number = r.triple.o.is_literal() && ec == std::errc() && end == text.data() + text.size() &&
                          begin != end && std::isfinite(v);
      if (auto problem = agg::window_setting_problem(number ? v : std::nan(""), !window)) {
        // The value quoted as far as a line shows it: a problem is a literal within the node's limit.
        const std::string value = r.triple.o.value.size() > 80 ? r.triple.o.value.substr(0, 80) + "..." : r.triple.o.value;
        unusable[window] = "configuration <" + r.triple.s.value + "> " + r.triple.p.value + " '" + value +
                           "' (record " + std::to_string(r.meta.id) + ") " + *problem +
                           "; ignored, the value before it stands";
        if (warned_.insert(r.meta.id).second) rt::log_line(kProgram, unusable[window]);
        continue;
      }
      unusable[window].clear();
      (window ? next.window_s : next.step_s) = v;
      (window ? window_evictable : step_evictable) = !r.meta.persistent;
      if (!agg::window_step_problem(next.window_s, next.step())) usable_pair = next;
    }
    std::string problem = unusable[1] + (!unusable[1].empty() && !unusable[0].empty() ? "; " : "") + unusable[0];
    // Each value usable, the two together not (a day's window from the hospital over the step
    // of a minute's): the last pair that could be used stands, until a setting makes one again.
    if (auto pair = agg::window_step_problem(next.window_s, next.step())) {
      const std::string said = "configuration of <" + session_.agent.iri() + ">: " + *pair + "; ignored, the window (" +
                               number_text(usable_pair.window_s) + " s) and step (" + number_text(usable_pair.step()) +
                               " s) before stand";
      if (said != pair_warned_) rt::log_line(kProgram, said);
      pair_warned_ = said;
      problem += (problem.empty() ? "" : "; ") + said;
      next = usable_pair;
      // Not kept as the agent's own below: written after the refused setting, the kept pair
      // would be the latest, and the refusal would vanish from the board unanswered.
      window_evictable = step_evictable = false;
    } else {
      pair_warned_.clear();
    }
    const bool evictable = window_evictable || step_evictable;
    if (auto said = session_.agent.report_problem(problem); !said)
      rt::log_line(kProgram, "report the configuration's problem on the board: " + said.error().message);
    const bool changed = next.window_s != config_.window_s || next.step() != config_.step();
    if (changed)
      rt::log_line(kProgram, "window " + std::to_string(next.window_s) + " s, step " + std::to_string(next.step()) + " s");
    config_ = next;
    if (changed || !in_force_said_) say_in_force();
    // A setting relayed from the hospital keeps its flag: on a home with a ring it would be
    // reclaimed, and after a restart the agent would go back to --window without a word. The
    // setting in force is kept as a persistent item of the agent's own (the latest wins).
    if (evictable && reclaims_configuration()) {
      tn::Item kept;
      kept.persistent = true;
      const tn::Term self = tn::Term::iri(session_.agent.iri());
      kept.add(self, agg::tv_term("windowSeconds"), tn::Term::literal(number_text(config_.window_s), std::string(tn::xsd::kDecimal)));
      if (config_.step_s > 0)
        kept.add(self, agg::tv_term("stepSeconds"), tn::Term::literal(number_text(config_.step_s), std::string(tn::xsd::kDecimal)));
      // Asserted no earlier than the latest setting it copies: one relayed from a hospital whose
      // clock is ahead sorted after a copy stamped now, stayed the latest (and reclaimable), and
      // each copy, delivered back to the agent, made another: 4,072 persistent copies in 15 s of
      // a clock 15 s ahead (a review of session 85).
      const std::int64_t latest = records->empty() ? 0 : records->back().meta.asserted_at;
      const std::int64_t now = std::chrono::duration_cast<std::chrono::nanoseconds>(
                                   std::chrono::system_clock::now().time_since_epoch()).count();
      kept.asserted_at = std::max(now, latest + 1);
      if (auto stored = session_.agent.store(kept); !stored)
        rt::log_line(kProgram, "keep the configuration: " + stored.error().message);
    }
    for (auto& [iri, s] : streams_) s.windower.set_window(config_.window_s, config_.step());
  }

  // The window and step in force, on the board as the agent's own state (the latest only), so
  // that whoever sent a setting can read what came of it, from the hospital too (`tahvel query
  // --at HOME -s <HOME/hrv> -p tv:windowSecondsInForce`): the settings sent were there, every
  // one, in the order they came, and the one in force (the latest written, or one before it
  // when the latest cannot be used) was in the agent's log only (an exploratory run of
  // session 85).
  void say_in_force() {
    const tn::Term self = tn::Term::iri(session_.agent.iri());
    tn::Item state;
    state.persistent = true;  // a ring would take it, and the board would say nothing in force
    state.add(self, agg::tv_term("windowSecondsInForce"), tn::Term::literal(number_text(config_.window_s), std::string(tn::xsd::kDecimal)));
    state.add(self, agg::tv_term("stepSecondsInForce"), tn::Term::literal(number_text(config_.step()), std::string(tn::xsd::kDecimal)));
    std::vector<tn::Pattern> old;
    for (const char* predicate : {"windowSecondsInForce", "stepSecondsInForce"})
      old.push_back({.s = self, .p = agg::tv_term(predicate), .source = session_.agent.iri()});
    if (auto written = session_.agent.replace(old, {state}); !written)
      rt::log_line(kProgram, "say the window in force on the board: " + written.error().message);
    else
      in_force_said_ = true;
  }

  // The agent's IRI, however written: settings are about it.
  bool is_me(const tn::Term& subject) const {
    if (!subject.is_iri()) return false;
    if (subject.value == session_.agent.iri()) return true;
    auto normal = tahvel::uri::normalize(subject.value);
    return normal && *normal == session_.agent.iri();
  }

  rt::Outcome handle(const tn::Delivery& delivery) {
    for (const tn::Record& r : delivery.records)
      if (is_me(r.triple.s)) {
        if (delivery.removal) forget_kept_settings(delivery.records);
        load_config();
        break;
      }
    // A removal (a setting taken back, so the problem it was may be over; or RR records removed,
    // whose windows stand) has nothing more to process.
    if (delivery.removal || !rt::has_predicate(delivery.records, "intervals")) return rt::Outcome::ok();
    auto rr = agg::read_rr(delivery.records);
    if (!rr) {
      rt::log_line(kProgram, rr.error().message + "; skipped");
      return rt::Outcome::ok();
    }
    rt::Outcome outcome;
    Stream* s = stream_for(*rr, outcome);
    if (!s || outcome.fatal) return outcome;
    if (!rr->intervals.empty() && rr->intervals.front().end <= s->last_end) {
      rt::log_line(kProgram, "<" + rr->iri + ">: already processed; skipped");
      return rt::Outcome::ok();
    }
    return process(*s, *rr, false);
  }

 private:
  Stream* stream_for(const agg::RrSeries& rr, rt::Outcome& outcome) {
    if (auto it = streams_.find(rr.recording); it != streams_.end()) return &it->second;
    auto info = rt::load_recording(session_.node, rr.recording);
    if (!info) {
      rt::log_line(kProgram, info.error().message + "; skipped");
      return nullptr;
    }
    Stream s{*info, agg::HrvWindower(info->fs, config_.window_s, config_.step()), -1, {}};
    Stream& stream = streams_.emplace(rr.recording, std::move(s)).first->second;
    // An item without intervals (the recording's end, tv:endSample) first after a restart: the
    // recording's open windows are those of every RR item before it, which the run before read
    // and a new windower has not; without them the end finished an empty windower, and the
    // recording's last window was lost.
    const std::int64_t upto = !rr.intervals.empty() ? rr.intervals.front().start
                                                    : rr.end_sample.value_or(std::numeric_limits<std::int64_t>::max());
    outcome = catch_up(stream, upto);
    // The catch-up may have met the recording's end on the board (an end item written twice,
    // after a crash of tahvel-rr) and closed the stream: nothing is left to go on with.
    auto it = streams_.find(rr.recording);
    return it == streams_.end() ? nullptr : &it->second;
  }

  // The last window this agent wrote of the recording (the one ending last), if any: found by
  // the recording (its windows derive from it), only their ends read, then that window.
  agg::Result<std::optional<agg::WindowMetrics>> last_window_written(const Stream& s) {
    auto snapshot = session_.node.snapshot();
    if (!snapshot) return agg::fail("snapshot: " + snapshot.error().message);
    auto derived = snapshot->list({.p = tn::Term::iri(agg::kProvDerivedFrom), .o = tn::Term::iri(s.info.iri),
                                   .source = session_.agent.iri()});
    if (!derived) return agg::fail("list: " + derived.error().message);
    std::optional<std::uint64_t> last;
    double last_end = 0;
    for (const tn::Record& r : *derived) {
      auto ends = snapshot->list({.s = r.triple.s, .p = agg::tv_term("windowEndS"), .source = session_.agent.iri()}, {.limit = 1});
      if (!ends) return agg::fail("list: " + ends.error().message);
      if (ends->empty()) continue;
      char* stop = nullptr;
      const std::string& text = ends->front().triple.o.value;
      const double end = std::strtod(text.c_str(), &stop);
      if (stop == text.c_str() || (last && !(end > last_end))) continue;
      last = r.meta.item;
      last_end = end;
    }
    if (!last) return std::optional<agg::WindowMetrics>();
    auto item = snapshot->item(*last);
    if (!item) return agg::fail("item " + std::to_string(*last) + ": " + item.error().message);
    auto window = agg::read_hrv_window(*item);
    if (!window) return agg::fail(window.error().message);
    return std::optional<agg::WindowMetrics>(window->window);
  }

  // The recording's RR items with intervals, each once and in order, whose intervals end by
  // `upto`, from those asserted at `from_s` seconds of signal on (0: all of them).
  agg::Result<void> for_each_rr(const Stream& s, double from_s, std::int64_t upto,
                                const std::function<bool(const agg::RrSeries&)>& each) {
    auto since = agg::signal_time_ns(s.info, from_s);
    // No bound (an RR item without intervals or end first after a restart): read whole, not page
    // by empty page up to the year 2262.
    const auto until = upto == std::numeric_limits<std::int64_t>::max()
                           ? std::nullopt
                           : agg::signal_time_ns(s.info, static_cast<double>(upto) / s.info.fs + 1);
    const auto usable = [&](const agg::Result<agg::RrSeries>& rr) {
      return rr && !rr->intervals.empty() && rr->intervals.back().end <= upto;
    };
    if (since && until)
      return rt::for_each_recording_item(session_.node, s.info.iri, *since, *until, [&](const std::vector<tn::Record>& records) {
        auto rr = agg::read_rr(records);
        return !usable(rr) || each(*rr);
      });
    // A recording without its start time (its items are not at signal times), or no bound: its
    // RR items read whole (the RR items alone, not the recording's chunks with them).
    auto items = rt::items_matching(session_.node, {.p = agg::tv_term("intervals"), .under = s.info.iri});
    if (!items) return agg::fail(items.error().message);
    std::map<std::int64_t, agg::RrSeries> earlier;
    for (const auto& records : *items)
      if (auto rr = agg::read_rr(records); usable(rr)) earlier.emplace(rr->intervals.front().start, std::move(*rr));
    for (const auto& [start, rr] : earlier)
      if (!each(rr)) break;
    return {};
  }

  // After a (re)start: feeds the intervals of the recording's RR items on the board that end by
  // `upto` through the new windower, from the end of the last window it wrote, writing the
  // window items that are missing. Intervals that end before the next window's start are in
  // none of the windows to come, so it reads from a little before that start (a margin ending
  // in an interval, so that the windower counts its windows as from the recording's start),
  // and from the start when no interval ends in the margin or no window was written.
  rt::Outcome catch_up(Stream& s, std::int64_t upto) {
    auto last_written = last_window_written(s);
    if (!last_written) return rt::Outcome::error("catch up <" + s.info.iri + ">: " + last_written.error().message);
    // The windows on the board were made with the setting of their time; the replay goes on
    // after the last of them with today's (a shorter window from 0 would overlap them).
    if (*last_written) s.windower.resume_after((*last_written)->end_s, (*last_written)->length_s);
    constexpr double kMarginS = 300;
    // Where the next window starts at the earliest (HrvWindower::resume_after).
    const double next_start = *last_written ? (*last_written)->end_s - config_.window_s : 0;
    const bool paged = s.info.started_at && upto != std::numeric_limits<std::int64_t>::max();  // for_each_rr
    double from_s = paged ? std::max(0.0, next_start - kMarginS) : 0;
    std::size_t replayed = 0;
    rt::Outcome outcome;
    const std::string recording = s.info.iri;  // the recording's end closes its stream, s with it
    for (;;) {
      bool too_late = false;
      auto read = for_each_rr(s, from_s, upto, [&](const agg::RrSeries& rr) {
        if (replayed == 0 && from_s > 0 && static_cast<double>(rr.intervals.front().end) / s.info.fs >= next_start) {
          too_late = true;  // no interval ends in the margin: read from the start
          return false;
        }
        // An item held twice (a dump loaded back), skipped as the live path skips it.
        if (rr.intervals.front().end <= s.last_end) return true;
        ++replayed;
        outcome = process(s, rr, true);
        return !outcome.fatal && streams_.count(recording) != 0;
      });
      if (!read) return rt::Outcome::error("catch up <" + recording + ">: " + read.error().message);
      // Nothing read after the margin's start is nothing known of it: an interval longer than
      // the margin (a flat signal for minutes) began before it and may end in the next window.
      if (!too_late && (replayed > 0 || from_s == 0)) break;
      from_s = 0;
    }
    if (outcome.fatal || replayed == 0) return outcome;
    rt::log_line(kProgram, "replayed " + std::to_string(replayed) + " earlier RR item(s) of <" + recording +
                               "> from the board" + (from_s > 0 ? ", from " + number_text(from_s) + " s of signal" : std::string()));
    return rt::Outcome::ok();
  }

  // Pushes the intervals of one RR item and writes the windows they complete; the item with
  // tv:endSample finishes the recording (then the stream is closed).
  rt::Outcome process(Stream& s, const agg::RrSeries& rr, bool catching_up) {
    std::vector<agg::WindowMetrics> completed;
    for (const agg::Interval& interval : rr.intervals) s.windower.push(interval, completed);
    if (!rr.intervals.empty()) {
      s.last_end = rr.intervals.back().end;
      s.refs.push_back({rr.iri, rr.intervals.front().end, rr.intervals.back().end});
    }
    if (rr.end_sample) s.windower.finish(completed, static_cast<double>(*rr.end_sample) / s.info.fs);
    for (const auto& window : completed)
      if (auto o = store_window(s, window, catching_up); o.fatal) return o;
    if (rr.end_sample) streams_.erase(rr.recording);  // s is gone from here on
    return rt::Outcome::ok();
  }

  rt::Outcome store_window(Stream& s, const agg::WindowMetrics& window, bool catching_up) {
    std::vector<std::string> from;
    for (const RrRef& ref : s.refs)
      if (static_cast<double>(ref.last_end) / s.info.fs >= window.start_s &&
          static_cast<double>(ref.first_end) / s.info.fs < window.end_s)
        from.push_back(ref.iri);
    // Later windows start later: RR items that ended before this one are no longer needed.
    while (!s.refs.empty() && static_cast<double>(s.refs.front().last_end) / s.info.fs < window.start_s)
      s.refs.pop_front();
    tn::Item item = agg::hrv_window_item(s.info, window, session_.agent.iri(), from);
    // At the signal time of the window's start, as its chunks: an operator asks for the raw
    // ECG behind a window with --since and --until from its time and length.
    item.asserted_at = agg::signal_time_ns(s.info, window.start_s);
    // Windows are named by recording and start: a window of that start already on the board
    // that ends elsewhere was written by another HRV agent (or setting) on this recording. It
    // stands, and this one is not written: said, not silently dropped.
    if (auto taken = taken_by_other(item.triples.front().s.value, window.end_s)) {
      rt::log_line(kProgram, "window <" + item.triples.front().s.value + "> [" + number_text(window.start_s) + ", " +
                                 number_text(window.end_s) + ") s not written: the board has a window of that name ending at " +
                                 *taken + " s (another agent or setting on this recording; one tahvel-hrv per recording)");
      return rt::Outcome::ok();
    }
    return rt::store_output(session_, item, catching_up);
  }

  // A setting removed by its writer takes with it the copy this agent kept of it (load_config),
  // which would otherwise stand for it.
  void forget_kept_settings(const std::vector<tn::Record>& removed) {
    for (const tn::Record& r : removed) {
      if (r.meta.source == session_.agent.iri()) continue;
      if (r.triple.p != agg::tv_term("windowSeconds") && r.triple.p != agg::tv_term("stepSeconds")) continue;
      if (auto gone = session_.node.remove({.s = tn::Term::iri(session_.agent.iri()), .p = r.triple.p, .source = session_.agent.iri()}, 0, tn::Reach::this_node);
          !gone)
        rt::log_line(kProgram, "remove the kept copy of a removed setting: " + gone.error().message);
    }
  }

  // Whether this store's retention could take a configuration record: a ring, or a TTL on
  // tv:windowSeconds or tv:stepSeconds.
  bool reclaims_configuration() {
    auto stats = session_.node.stats();
    if (stats && stats->ring > 0) return true;
    auto ttls = session_.node.ttls();
    if (!ttls) return false;
    for (const auto& [predicate, ttl] : *ttls)
      if (predicate == std::string(agg::kTv) + "windowSeconds" || predicate == std::string(agg::kTv) + "stepSeconds") return true;
    return false;
  }

  // The tv:windowEndS of a window named `iri` already on the board when it is not `end_s`.
  std::optional<std::string> taken_by_other(const std::string& iri, double end_s) {
    auto snapshot = session_.node.snapshot();
    if (!snapshot) return std::nullopt;
    auto ends = snapshot->list({.s = tn::Term::iri(iri), .p = agg::tv_term("windowEndS")});
    if (!ends || ends->empty()) return std::nullopt;
    const std::string& text = ends->front().triple.o.value;
    char* stop = nullptr;
    const double there = std::strtod(text.c_str(), &stop);
    if (std::abs(there - end_s) <= 1e-6) return std::nullopt;
    return text;
  }

  rt::Session& session_;
  const WindowConfig defaults_;  // --window, --step
  WindowConfig config_;
  bool in_force_said_ = false;  // say_in_force() has written the window in force since the start
  std::set<std::uint64_t> warned_;  // configuration records already logged as ignored
  std::string pair_warned_;  // the window-and-step problem last logged, said once until it changes
  std::map<std::string, Stream> streams_;
};

// States once per node which HRV results have a LOINC code (persistent, written if absent).
void state_loinc_codes(rt::Session& session) {
  const tn::Term loinc = agg::tv_term("loinc");
  auto snapshot = session.node.snapshot();
  if (!snapshot) return;
  tn::Pattern pattern;
  pattern.s = agg::tv_term("sdnnMs");
  pattern.p = loinc;
  if (auto n = snapshot->count(pattern); !n || *n > 0) return;
  tn::Item item;
  item.persistent = true;
  item.add(agg::tv_term("sdnnMs"), loinc, tn::Term::literal("80404-7"))
      .add(agg::tv_term("meanHrBpm"), loinc, tn::Term::literal("8867-4"));
  if (auto s = session.agent.store(item); !s) rt::log_line(kProgram, "store LOINC codes: " + s.error().message);
}

}  // namespace

int main(int argc, char** argv) {
  return rt::guarded_main(kProgram, "usage: tahvel-hrv DIR [--agent ID] [--idle S] [--window S] [--step S]", [&]() -> int {
    const rt::Args args(argc, argv, {"--agent", "--idle", "--window", "--step"}, {});
    const double idle = args.number("--idle", 0);
    WindowConfig defaults{args.number("--window", 300), args.number("--step", 0)};
    // As the board's settings and `tahvel hrv` take them; without --step the step is the window
    // (step_s 0), and a --step 0 given is refused as `tahvel hrv` refuses it.
    if (auto problem = agg::window_setting_problem(defaults.window_s, false))
      throw rt::UsageError("--window: " + *problem + ", got " + number_text(defaults.window_s));
    if (args.has("--step"))
      if (auto problem = agg::window_setting_problem(defaults.step_s, true))
        throw rt::UsageError("--step: " + *problem + ", got " + number_text(defaults.step_s));
    if (auto problem = agg::window_step_problem(defaults.window_s, defaults.step()))
      throw rt::UsageError("--step: " + *problem + ", got " + number_text(defaults.step_s));
    rt::install_stop_handlers();
    auto session = rt::open_session(kProgram, args.dir(), args.text("--agent", "hrv"));
    if (!session) return rt::kExitError;
    if (!rt::subscribe_predicates(*session, {std::string(agg::kTv) + "intervals"})) return rt::kExitError;
    tn::Pattern config;
    config.s = tn::Term::iri(session->agent.iri());
    // And the settings by predicate: one written with the node's IRI in another spelling
    // (upper-case host) is about this agent too (HrvStage::is_me), and no subscription by
    // subject delivers it.
    for (const tn::Pattern& pattern : {config, tn::Pattern{.p = agg::tv_term("windowSeconds")}, tn::Pattern{.p = agg::tv_term("stepSeconds")}})
      if (auto s = session->agent.subscribe(pattern); !s) {
        rt::log_line(kProgram, "subscribe to the configuration: " + s.error().message);
        return rt::kExitError;
      }
    // A setting removed is read as the configuration changing: an unusable one taken back is no
    // longer the agent's problem.
    if (auto r = session->agent.receive_removals(); !r) {
      rt::log_line(kProgram, "receive removals of the configuration: " + r.error().message);
      return rt::kExitError;
    }
    state_loinc_codes(*session);
    HrvStage stage(*session, defaults);
    stage.load_config();
    return rt::run_take_loop(*session, idle, [&](const tn::Delivery& d) { return stage.handle(d); });
  });
}
