// tahvel-trend: hospital-side trends of HRV metrics as a whiteboard agent. Subscribes to HRV
// window items (sosa:observedProperty tv:HeartRateVariability), groups them per recording and,
// after each window, writes one trend item per metric, <recording>/trend/<metric>/<start_s>:
// baseline, slope per hour, change alert (trend.h, docs/hrv.md "Trends") over the recording's
// windows up to that one, and, when at least two other recordings have a window at the same
// time, the z-score of the window's value against theirs.
//
//   tahvel-trend DIR [--agent ID] [--idle S] [--metric NAME ...]     (agent id default "trend")
//
// NAME is a window result's local name (sdnnMs, rmssdMs, meanHrBpm, meanNnMs, pnn50Pct, lfMs2,
// hfMs2, lfHf, sd1Ms, sd2Ms); default sdnnMs rmssdMs meanHrBpm. Items are immutable: every
// update is a new item named by its window, written only if not on the board yet.
// (Re)start: reads every HRV window on the board and writes the trend items that are missing.
// A window it cannot read is logged and skipped, and is the agent's problem on the board while
// the windows of its writer are (docs/agents.md).
#include <algorithm>
#include <cmath>
#include <iostream>
#include <map>
#include <set>

#include "agent_runtime.h"
#include "tahvel/aggregation/trend.h"

namespace {

namespace agg = tahvel::aggregation;
namespace rt = tahvel::agents::hrv;
namespace tn = tahvel::node;

constexpr const char* kProgram = "tahvel-trend";

// The recording a take is of: tahvel-ecg-source names each take <recording>-<UTC start>
// (-YYYYMMDDTHHMMSSZ, then -N for a second take in the same second); two takes of one
// recording are one sensor's, one patient's. Another IRI is its own.
std::string_view take_of(std::string_view iri) {
  auto digits = [](std::string_view t) {
    return !t.empty() && std::all_of(t.begin(), t.end(), [](char c) { return c >= '0' && c <= '9'; });
  };
  std::string_view rest = iri;
  if (const std::size_t dash = rest.rfind('-'); dash != std::string_view::npos && digits(rest.substr(dash + 1)) &&
                                                 dash >= 17 && rest[dash - 1] == 'Z')
    rest = rest.substr(0, dash);  // -N
  if (rest.size() < 17) return iri;
  const std::string_view stamp = rest.substr(rest.size() - 16);
  if (rest[rest.size() - 17] != '-' || !digits(stamp.substr(0, 8)) || stamp[8] != 'T' || !digits(stamp.substr(9, 6)) ||
      stamp[15] != 'Z')
    return iri;
  return rest.substr(0, rest.size() - 17);
}
const std::string kSosa = "http://www.w3.org/ns/sosa/";

tn::Pattern hrv_windows() {
  tn::Pattern p;
  p.p = tn::Term::iri(kSosa + "observedProperty");
  p.o = agg::tv_term("HeartRateVariability");
  return p;
}

struct Window {
  std::string iri;
  agg::WindowMetrics metrics;
  std::int64_t asserted_ns = 0;  // the window's signal time, which its trend items are asserted at
};

// When the window `iri` of `records` is asserted (tahvel-hrv: at the signal time of its start).
std::int64_t asserted_at(const std::vector<tn::Record>& records, const std::string& iri) {
  for (const tn::Record& r : records)
    if (r.triple.s.value == iri) return r.meta.asserted_at;
  return 0;
}

// A recording's windows by start time, and their start times by signal time, to find the
// window of another patient at a given moment.
struct Series {
  std::map<double, Window> windows;
  std::multimap<std::int64_t, double> starts_by_time;

  void put(double start_s, Window window) {
    if (auto old = windows.find(start_s); old != windows.end()) {
      auto [first, last] = starts_by_time.equal_range(old->second.asserted_ns);
      for (auto it = first; it != last; ++it)
        if (it->second == start_s) {
          starts_by_time.erase(it);
          break;
        }
    }
    starts_by_time.emplace(window.asserted_ns, start_s);
    windows.insert_or_assign(start_s, std::move(window));
  }
};

// Windows of one length are one series: SDNN and the spectrum grow with the window, so after a
// length change (tv:windowSeconds from the hospital) the longer windows are not judged by the
// shorter ones' baseline, nor one patient's against others' of another length. Lengths are
// written to the microsecond; a millisecond apart is another setting.
bool same_length(const agg::WindowMetrics& a, const agg::WindowMetrics& b) {
  return std::abs(a.length_s - b.length_s) < 1e-3;
}

// A window the record's end cut short (agg::cut_short) is no point of the series (its items
// have no tv:latest and no alert), nor another patient's latest value to compare with. Three
// such windows below the baseline at the end of every recording with overlapping windows made
// an alert of the record's end.
using agg::cut_short;

// `metric` in the window of `other` nearest in signal time to `window`, of its length and not cut
// short, among those that start less than two window lengths from it: the other patient's
// window of the same time, or while that has not arrived (it ends when this one does, and
// another home sends it), the one before; nullopt when there is none. Up to session 73 it was
// the other's latest window, whatever its time: replays at --speed 0 held one patient's minute
// 27 against another's minute 5, and a recording that ended hours ago counted as a patient of now.
std::optional<double> value_beside(const Series& other, const Window& window, agg::HrvMetric metric) {
  const auto reach = static_cast<std::int64_t>(std::llround(2 * window.metrics.length_s * 1e9));
  // Later by half a window at most: of the same time, give or take how two homes' windows fall;
  // a later one is neither that nor the one before (in a catch-up, where every window is there,
  // the nearest either way took a window of minute 15 for one of minute 10: session 84).
  const auto ahead = static_cast<std::int64_t>(std::llround(0.5 * window.metrics.length_s * 1e9));
  std::optional<double> nearest;
  std::int64_t nearest_gap = 0;
  for (auto it = other.starts_by_time.upper_bound(window.asserted_ns - reach);
       it != other.starts_by_time.end() && it->first <= window.asserted_ns + ahead; ++it) {
    const Window& candidate = other.windows.at(it->second);
    const auto v = agg::metric_value(candidate.metrics.metrics, metric);
    if (!v || cut_short(candidate.metrics) || !same_length(candidate.metrics, window.metrics)) continue;
    const std::int64_t gap = std::abs(it->first - window.asserted_ns);
    if (!nearest || gap <= nearest_gap) {  // of two as near, the later
      nearest = v;
      nearest_gap = gap;
    }
  }
  return nearest;
}

class TrendStage {
 public:
  TrendStage(rt::Session& session, std::vector<agg::HrvMetric> metrics)
      : session_(session), metrics_(std::move(metrics)), skipped_(session, "writer(s)") {}

  // Reads every HRV window on the board and writes the trend items that are missing.
  rt::Outcome catch_up() {
    auto items = rt::items_matching(session_.node, hrv_windows());
    if (!items) return rt::Outcome::error("catch up: " + items.error().message);
    std::size_t windows = 0;
    for (const auto& records : *items)
      if (auto w = read_window(records)) {
        recordings_[w->recording].put(w->window.start_s, {w->iri, w->window, asserted_at(records, w->iri)});
        ++windows;
      }
    for (const auto& [recording, series] : recordings_)
      for (const auto& [start, window] : series.windows)
        if (auto o = write_updates(recording, start, true); o.fatal) return o;
    if (windows) rt::log_line(kProgram, "read " + std::to_string(windows) + " HRV window(s) of " +
                                         std::to_string(recordings_.size()) + " recording(s) from the board");
    return rt::Outcome::ok();
  }

  rt::Outcome handle(const tn::Delivery& delivery) {
    auto w = read_window(delivery.records);
    if (!w) return rt::Outcome::ok();
    recordings_[w->recording].put(w->window.start_s, {w->iri, w->window, asserted_at(delivery.records, w->iri)});
    return write_updates(w->recording, w->window.start_s, false);
  }

 private:
  // The window in `records`; nullopt when it cannot be read. Unreadable windows are a cause per
  // writer (a home whose HRV agent writes another version's windows has no trend here): the
  // agent's problem until a window of that writer is read.
  std::optional<agg::HrvWindowItem> read_window(const std::vector<tn::Record>& records) {
    const std::string writer = records.empty() ? std::string() : records.front().meta.source;
    auto w = agg::read_hrv_window(records);
    if (!w) {
      skipped_.skip(writer, w.error().message, "the HRV windows of <" + writer + "> it cannot read");
      return std::nullopt;
    }
    skipped_.resume(writer);
    return std::move(*w);
  }

  // The trend items of the window starting at `start` of `recording`, over the windows of its
  // length up to it.
  rt::Outcome write_updates(const std::string& recording, double start, bool catching_up) {
    const Series& series = recordings_.at(recording);
    const Window& window = series.windows.at(start);
    std::vector<agg::WindowMetrics> upto;
    for (const auto& [s, w] : series.windows) {
      if (s > start) break;
      if (same_length(w.metrics, window.metrics) && !cut_short(w.metrics)) upto.push_back(w.metrics);
    }
    for (agg::HrvMetric metric : metrics_) {
      const std::string iri = agg::trend_iri(recording, metric, start);
      if (rt::on_board(session_.node, iri)) continue;
      const auto points = agg::trend_points(upto, metric);
      agg::TrendOptions options = options_;
      options.min_robust_sd = std::max(options.min_robust_sd, agg::metric_resolution(metric));
      options.window_s = window.metrics.length_s;  // the series is of windows of one length
      const agg::TrendSummary summary = agg::analyse_trend(points, options);
      agg::TrendUpdate u;
      u.recording = recording;
      u.metric = metric;
      u.window_start_s = start;
      u.window_iri = window.iri;
      u.windows = points.size();
      // A window without the metric (no beats: lead off, asystole), or one the record's end cut
      // short, is no point of the series: it has no latest value and no alert of its own, the
      // series' last value being an earlier window's. (Compared by end time, a cut-short window
      // ending where the last whole one ends took that one's value, alert and z-score.)
      const bool window_has_it = !cut_short(window.metrics) && agg::metric_value(window.metrics.metrics, metric).has_value();
      if (window_has_it) u.latest = summary.latest;
      u.baseline = summary.baseline;
      u.robust_sd = summary.robust_sd;
      u.slope_per_hour = summary.slope_per_hour;
      u.alert = window_has_it && summary.alerting;
      if (u.alert && !summary.alerts.empty()) u.alert_direction = summary.alerts.back().direction;
      // Across patients: against each other patient's value at the same time, when this
      // window has the metric itself.
      if (window_has_it) {
        std::vector<double> others;
        for (const auto& [other, other_series] : recordings_) {
          // Another take of the same recording (<recording>-<start>, its source restarted) is
          // the same patient: against their own earlier values the z-score said "other
          // patients" of one (a probe: 3 of the 7 "others" were the patient's own).
          if (other == recording || take_of(other) == take_of(recording)) continue;
          if (auto v = value_beside(other_series, window, metric)) others.push_back(*v);
        }
        u.z_against_others = agg::cross_patient_z(points.back().value, others, options.min_robust_sd);
        if (u.z_against_others) u.others = others.size();
      }
      // At the window's signal time, as everything the chain derives: a time range selects a
      // window and the trend after it together (tahvel patients --since).
      tn::Item item = agg::trend_item(u, session_.agent.iri());
      if (window.asserted_ns != 0) item.asserted_at = window.asserted_ns;
      if (auto o = rt::store_output(session_, item, catching_up); o.fatal)
        return o;
    }
    return rt::Outcome::ok();
  }

  rt::Session& session_;
  std::vector<agg::HrvMetric> metrics_;
  agg::TrendOptions options_;
  std::map<std::string, Series> recordings_;
  rt::SkippedInputs skipped_;
};

}  // namespace

int main(int argc, char** argv) {
  return rt::guarded_main(kProgram, "usage: tahvel-trend DIR [--agent ID] [--idle S] [--metric NAME ...]", [&]() -> int {
    const rt::Args args(argc, argv, {"--agent", "--idle"}, {}, {"--metric"});
    std::vector<agg::HrvMetric> metrics;
    for (const std::string& name : args.values("--metric")) {
      auto m = agg::metric_from_local_name(name);
      if (!m) throw rt::UsageError("--metric: unknown metric '" + name + "'");
      if (std::find(metrics.begin(), metrics.end(), *m) == metrics.end()) metrics.push_back(*m);
    }
    if (metrics.empty()) metrics = {agg::HrvMetric::sdnn, agg::HrvMetric::rmssd, agg::HrvMetric::mean_hr};
    const double idle = args.number("--idle", 0);
    rt::install_stop_handlers();
    auto session = rt::open_session(kProgram, args.dir(), args.text("--agent", "trend"));
    if (!session) return rt::kExitError;
    if (auto s = session->agent.subscribe(hrv_windows()); !s) {
      rt::log_line(kProgram, "subscribe to HRV windows: " + s.error().message);
      return rt::kExitError;
    }
    TrendStage stage(*session, metrics);
    if (auto o = stage.catch_up(); o.fatal) {
      rt::log_line(kProgram, *o.fatal);
      return rt::kExitError;
    }
    return rt::run_take_loop(*session, idle, [&](const tn::Delivery& d) { return stage.handle(d); });
  });
}
