// tahvel-trend: hospital-side trends of HRV metrics as a whiteboard agent. Subscribes to HRV
// window items (sosa:observedProperty tv:HeartRateVariability), groups them per recording and,
// after each window, writes one trend item per metric, <recording>/trend/<metric>/<start_s>:
// baseline, slope per hour, change alert (trend.h, docs/hrv.md "Trends") over the recording's
// windows up to that one, and, when at least two other recordings have a window at the same
// time, the z-score of the window's value against theirs.
//
//   tahvel-trend DIR [--agent ID] [--idle S] [--horizon-h H] [--metric NAME ...]
//                                                                (agent id default "trend")
//
// NAME is a window result's local name (sdnnMs, rmssdMs, meanHrBpm, meanNnMs, pnn50Pct, lfMs2,
// hfMs2, lfHf, sd1Ms, sd2Ms); default sdnnMs rmssdMs meanHrBpm. Items are immutable: every
// update is a new item named by its window, written only if not on the board yet.
// A recording's slope is of its windows of the last H hours (default 24), and the agent keeps
// no more of a recording than that, and its baseline: a patient monitored for weeks costs as
// much memory as one of a day (it was about 1.3 MB per patient per day of 60-s windows, kept
// for ever, and every window read them all again).
// (Re)start: reads every HRV window on the board, a page at a time, and writes the trend items
// that are missing.
// A window it cannot read is logged and skipped, and is the agent's problem on the board while
// the windows of its writer are (docs/agents.md).
#include <algorithm>
#include <cmath>
#include <iostream>
#include <limits>
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

// What the agent keeps of a window: the values of its metrics, in the agent's order.
struct Window {
  double end_s = 0;
  double length_s = 0;  // its setting's (WindowMetrics::length_s)
  bool cut_short = false;
  std::vector<std::optional<double>> values;
  std::int64_t asserted_ns = 0;  // the window's signal time, which its trend items are asserted at
};

// When the window `iri` of `records` is asserted (tahvel-hrv: at the signal time of its start).
std::int64_t asserted_at(const std::vector<tn::Record>& records, const std::string& iri) {
  for (const tn::Record& r : records)
    if (r.triple.s.value == iri) return r.meta.asserted_at;
  return 0;
}

// Windows of one length are one series: SDNN and the spectrum grow with the window, so after a
// length change (tv:windowSeconds from the hospital) the longer windows are not judged by the
// shorter ones' baseline, nor one patient's against others' of another length. Lengths are
// written to the microsecond; a millisecond apart is another setting.
bool same_length(double a, double b) { return std::abs(a - b) < 1e-3; }

// What a recording's series of one window length keeps, per metric, of the windows it forgets:
// the baseline, made of its first points, and how many points went before those it holds.
struct Forgotten {
  double length_s = 0;
  std::vector<std::optional<agg::TrendBaseline>> baselines;
  std::vector<std::size_t> points;
};

// A recording's windows by start time, those of the last horizon (and a little more, for other
// patients' z-scores), and their start times by signal time, to find the window of another
// patient at a given moment.
struct Series {
  std::map<double, Window> windows;
  std::multimap<std::int64_t, double> starts_by_time;
  std::vector<Forgotten> forgotten;
  double newest_end_s = 0;

  void put(double start_s, Window window) {
    if (auto old = windows.find(start_s); old != windows.end()) {
      auto [first, last] = starts_by_time.equal_range(old->second.asserted_ns);
      for (auto it = first; it != last; ++it)
        if (it->second == start_s) {
          starts_by_time.erase(it);
          break;
        }
    }
    newest_end_s = std::max(newest_end_s, window.end_s);
    starts_by_time.emplace(window.asserted_ns, start_s);
    windows.insert_or_assign(start_s, std::move(window));
  }

  Forgotten& of_length(double length_s, std::size_t metrics) {
    for (Forgotten& f : forgotten)
      if (same_length(f.length_s, length_s)) return f;
    forgotten.push_back({length_s, std::vector<std::optional<agg::TrendBaseline>>(metrics), std::vector<std::size_t>(metrics)});
    return forgotten.back();
  }

  // The points of each of the `metrics` in the windows of `length_s` that start at or before
  // `until_start`, in one pass over the windows held.
  std::vector<std::vector<agg::TrendPoint>> points(double length_s, std::size_t metrics, double until_start) const {
    std::vector<std::vector<agg::TrendPoint>> out(metrics);
    for (const auto& [start, w] : windows) {
      if (start > until_start) break;
      if (!same_length(w.length_s, length_s) || w.cut_short) continue;
      for (std::size_t m = 0; m < metrics; ++m)
        if (w.values[m]) out[m].push_back({w.end_s, *w.values[m]});
    }
    return out;
  }

  // Drops the windows that end more than `keep_s` (and two of their lengths) before the newest,
  // counting their points; each metric's baseline is made before its points go, when it can be.
  template <typename OptionsFor>  // agg::TrendOptions (std::size_t metric, double length_s)
  void forget_older(double keep_s, std::size_t metrics, const OptionsFor& options_for) {
    auto it = windows.begin();
    while (it != windows.end() && it->second.end_s + 2 * it->second.length_s < newest_end_s - keep_s) {
      const Window& w = it->second;
      for (std::size_t m = 0; m < metrics; ++m) (void)baseline_of(w.length_s, m, metrics, options_for(m, w.length_s));
      Forgotten& f = of_length(w.length_s, metrics);
      for (std::size_t m = 0; m < metrics; ++m)
        if (!w.cut_short && w.values[m]) ++f.points[m];
      auto [first, last] = starts_by_time.equal_range(w.asserted_ns);
      for (auto t = first; t != last; ++t)
        if (t->second == it->first) {
          starts_by_time.erase(t);
          break;
        }
      it = windows.erase(it);
    }
  }

  // The baseline of metric `m` in the windows of `length_s`: kept once made, of the first points
  // (of the first held, when the metric had too few points before a horizon's windows went).
  std::optional<agg::TrendBaseline> baseline_of(double length_s, std::size_t m, std::size_t metrics,
                                                const agg::TrendOptions& options) {
    Forgotten& f = of_length(length_s, metrics);
    if (!f.baselines[m])
      f.baselines[m] = agg::trend_baseline(points(length_s, metrics, std::numeric_limits<double>::infinity())[m], options);
    return f.baselines[m];
  }

  std::size_t points_forgotten(double length_s, std::size_t m) const {
    for (const Forgotten& f : forgotten)
      if (same_length(f.length_s, length_s)) return f.points[m];
    return 0;
  }
};

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
struct ValueBeside {
  double value = 0;
  std::int64_t gap_ns = 0;  // between the two windows' signal times
};
std::optional<ValueBeside> value_beside(const Series& other, const Window& window, std::size_t m) {
  const auto reach = static_cast<std::int64_t>(std::llround(2 * window.length_s * 1e9));
  // Later by half a window at most: of the same time, give or take how two homes' windows fall;
  // a later one is neither that nor the one before (in a catch-up, where every window is there,
  // the nearest either way took a window of minute 15 for one of minute 10: session 84).
  const auto ahead = static_cast<std::int64_t>(std::llround(0.5 * window.length_s * 1e9));
  std::optional<ValueBeside> nearest;
  for (auto it = other.starts_by_time.upper_bound(window.asserted_ns - reach);
       it != other.starts_by_time.end() && it->first <= window.asserted_ns + ahead; ++it) {
    const Window& candidate = other.windows.at(it->second);
    const auto& v = candidate.values[m];
    if (!v || candidate.cut_short || !same_length(candidate.length_s, window.length_s)) continue;
    const std::int64_t gap = std::abs(it->first - window.asserted_ns);
    if (!nearest || gap <= nearest->gap_ns) nearest = ValueBeside{*v, gap};  // of two as near, the later
  }
  return nearest;
}

std::string described(const tn::Error& e) { return std::string(tn::errc_name(e.code)) + " (" + e.message + ")"; }

class TrendStage {
 public:
  TrendStage(rt::Session& session, std::vector<agg::HrvMetric> metrics, double horizon_s)
      : session_(session), metrics_(std::move(metrics)), horizon_s_(horizon_s), skipped_(session, "writer(s)") {}

  // Reads every HRV window on the board, a page at a time in the order they came, and writes
  // the trend items that are missing. A page's windows are all in before any is written, so
  // that windows of the same time from several homes have each other for their z-scores.
  rt::Outcome catch_up() {
    tn::Pattern pattern = hrv_windows();
    std::size_t windows = 0;
    std::set<std::string> recordings;
    for (;;) {
      std::vector<Arrived> arrived;
      std::set<std::string> in_page;
      {
        // A snapshot per page, let go before the page's writes: a store cannot grow while its
        // writer holds one (the first version of this held one throughout, and a catch-up of
        // 144,000 windows stopped at its 165th item: "must grow, and cannot").
        auto snapshot = session_.node.snapshot();
        if (!snapshot) return rt::Outcome::error("catch up: snapshot: " + described(snapshot.error()));
        auto page = snapshot->list(pattern, tn::ListOptions{.limit = kCatchUpPage});
        if (!page) return rt::Outcome::error("catch up: list: " + described(page.error()));
        if (page->empty()) break;
        pattern.after_id = page->back().meta.id;
        std::set<std::uint64_t> seen;
        for (const tn::Record& r : *page) {
          if (!seen.insert(r.meta.item).second) continue;
          auto records = snapshot->item(r.meta.item);
          if (!records) continue;  // removed meanwhile
          if (auto a = put(*records)) {
            in_page.insert(a->recording);
            arrived.push_back(std::move(*a));
            ++windows;
          }
        }
      }
      recordings.insert(in_page.begin(), in_page.end());
      caught_up_through_ = pattern.after_id.value_or(0);
      std::stable_sort(arrived.begin(), arrived.end(), [this](const Arrived& a, const Arrived& b) {
        return recordings_.at(a.recording).windows.at(a.start_s).asserted_ns <
               recordings_.at(b.recording).windows.at(b.start_s).asserted_ns;
      });
      for (const Arrived& a : arrived)
        if (auto o = write_updates(a, true); o.fatal) return o;
      for (const std::string& recording : in_page) forget_older(recording);
    }
    if (windows) rt::log_line(kProgram, "read " + std::to_string(windows) + " HRV window(s) of " +
                                         std::to_string(recordings.size()) + " recording(s) from the board");
    return rt::Outcome::ok();
  }

  rt::Outcome handle(const tn::Delivery& delivery) {
    // Delivered while the agent was away, and read at start already: a window gone from memory
    // since (older than the horizon) would come back, and count twice among the points forgotten.
    if (delivery.item <= caught_up_through_) return rt::Outcome::ok();
    auto a = put(delivery.records);
    if (!a) return rt::Outcome::ok();
    auto o = write_updates(*a, false);
    forget_older(a->recording);
    return o;
  }

 private:
  static constexpr std::size_t kCatchUpPage = 1024;

  // A window taken in: where it is kept, and the item it came in.
  struct Arrived {
    std::string recording;
    double start_s = 0;
    std::string iri;
  };

  // Takes in the window in `records`; nullopt when it cannot be read. Unreadable windows are a
  // cause per writer (a home whose HRV agent writes another version's windows has no trend
  // here): the agent's problem until a window of that writer is read.
  std::optional<Arrived> put(const std::vector<tn::Record>& records) {
    const std::string writer = records.empty() ? std::string() : records.front().meta.source;
    auto w = agg::read_hrv_window(records);
    if (!w) {
      skipped_.skip(writer, w.error().message, "the HRV windows of <" + writer + "> it cannot read");
      return std::nullopt;
    }
    skipped_.resume(writer);
    Window kept;
    kept.end_s = w->window.end_s;
    kept.length_s = w->window.length_s;
    kept.cut_short = cut_short(w->window);
    for (agg::HrvMetric metric : metrics_) kept.values.push_back(agg::metric_value(w->window.metrics, metric));
    kept.asserted_ns = asserted_at(records, w->iri);
    recordings_[w->recording].put(w->window.start_s, std::move(kept));
    return Arrived{std::move(w->recording), w->window.start_s, std::move(w->iri)};
  }

  agg::TrendOptions options_for(std::size_t m, double length_s) const {
    agg::TrendOptions options = options_;
    options.min_robust_sd = std::max(options.min_robust_sd, agg::metric_resolution(metrics_[m]));
    options.window_s = length_s;  // the series is of windows of one length
    options.slope_horizon_s = horizon_s_;
    return options;
  }

  void forget_older(const std::string& recording) {
    recordings_.at(recording).forget_older(horizon_s_, metrics_.size(),
                                           [this](std::size_t m, double length_s) { return options_for(m, length_s); });
  }

  // The trend items of the window `a`, over the windows of its length up to it.
  rt::Outcome write_updates(const Arrived& a, bool catching_up) {
    Series& series = recordings_.at(a.recording);
    const Window& window = series.windows.at(a.start_s);
    std::vector<std::vector<agg::TrendPoint>> series_points;  // made when an item is missing
    for (std::size_t m = 0; m < metrics_.size(); ++m) {
      const agg::HrvMetric metric = metrics_[m];
      const std::string iri = agg::trend_iri(a.recording, metric, a.start_s);
      if (rt::on_board(session_.node, iri)) continue;
      if (series_points.empty()) series_points = series.points(window.length_s, metrics_.size(), a.start_s);
      const std::vector<agg::TrendPoint>& points = series_points[m];
      const agg::TrendOptions options = options_for(m, window.length_s);
      const agg::TrendSummary summary =
          agg::analyse_trend(points, options, series.baseline_of(window.length_s, m, metrics_.size(), options));
      agg::TrendUpdate u;
      u.recording = a.recording;
      u.metric = metric;
      u.window_start_s = a.start_s;
      u.window_iri = a.iri;
      u.windows = series.points_forgotten(window.length_s, m) + points.size();
      // A window without the metric (no beats: lead off, asystole), or one the record's end cut
      // short, is no point of the series: it has no latest value and no alert of its own, the
      // series' last value being an earlier window's. (Compared by end time, a cut-short window
      // ending where the last whole one ends took that one's value, alert and z-score.)
      const bool window_has_it = !window.cut_short && window.values[m].has_value();
      if (window_has_it) u.latest = summary.latest;
      u.baseline = summary.baseline;
      u.robust_sd = summary.robust_sd;
      u.slope_per_hour = summary.slope_per_hour;
      u.slope_horizon_s = horizon_s_;
      u.alert = window_has_it && summary.alerting;
      if (u.alert && !summary.alerts.empty()) u.alert_direction = summary.alerts.back().direction;
      // Across patients: against each other patient's value at the same time, when this
      // window has the metric itself.
      if (window_has_it) {
        // One value per other patient: of their takes (<recording>-<start>, a source started
        // again), the window nearest in time. Two takes of one patient that overlap in signal
        // time (a replay restarted from its first sample) were two "other patients": a home's
        // down and up made its z-score "against 2 other patients" where there was one (an
        // exploratory run of session 85).
        std::map<std::string_view, ValueBeside> by_patient;
        for (const auto& [other, other_series] : recordings_) {
          // Another take of the same recording is the same patient: against their own earlier
          // values the z-score said "other patients" of one (a probe: 3 of the 7 "others" were
          // the patient's own).
          if (other == a.recording || take_of(other) == take_of(a.recording)) continue;
          if (auto v = value_beside(other_series, window, m)) {
            auto [it, first] = by_patient.emplace(take_of(other), *v);
            // Of two takes as near, the later (names hold the take's start: in name order).
            if (!first && v->gap_ns <= it->second.gap_ns) it->second = *v;
          }
        }
        std::vector<double> others;
        for (const auto& [patient, v] : by_patient) others.push_back(v.value);
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
  double horizon_s_;
  agg::TrendOptions options_;
  std::map<std::string, Series> recordings_;
  rt::SkippedInputs skipped_;
  // The last record catch_up read: items up to it were taken in at start (record ids rise with
  // every write, an item's records together).
  std::uint64_t caught_up_through_ = 0;
};

}  // namespace

int main(int argc, char** argv) {
  return rt::guarded_main(kProgram, "usage: tahvel-trend DIR [--agent ID] [--idle S] [--horizon-h H] [--metric NAME ...]", [&]() -> int {
    const rt::Args args(argc, argv, {"--agent", "--idle", "--horizon-h"}, {}, {"--metric"});
    std::vector<agg::HrvMetric> metrics;
    for (const std::string& name : args.values("--metric")) {
      auto m = agg::metric_from_local_name(name);
      if (!m) throw rt::UsageError("--metric: unknown metric '" + name + "'");
      if (std::find(metrics.begin(), metrics.end(), *m) == metrics.end()) metrics.push_back(*m);
    }
    if (metrics.empty()) metrics = {agg::HrvMetric::sdnn, agg::HrvMetric::rmssd, agg::HrvMetric::mean_hr};
    const double idle = args.number("--idle", 0);
    const double horizon_h = args.number("--horizon-h", 24);
    if (!(horizon_h > 0) || horizon_h > 24 * 365)
      throw rt::UsageError("--horizon-h: the slope's reach in hours must be above 0 and at most a year, not " +
                           args.text("--horizon-h", ""));
    rt::install_stop_handlers();
    auto session = rt::open_session(kProgram, args.dir(), args.text("--agent", "trend"));
    if (!session) return rt::kExitError;
    if (auto s = session->agent.subscribe(hrv_windows()); !s) {
      rt::log_line(kProgram, "subscribe to HRV windows: " + s.error().message);
      return rt::kExitError;
    }
    TrendStage stage(*session, metrics, horizon_h * 3600);
    if (auto o = stage.catch_up(); o.fatal) {
      rt::log_line(kProgram, *o.fatal);
      return rt::kExitError;
    }
    return rt::run_take_loop(*session, idle, [&](const tn::Delivery& d) { return stage.handle(d); });
  });
}
