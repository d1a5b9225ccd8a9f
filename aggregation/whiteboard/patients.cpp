// The patients on a board; see patients.h.
#include "tahvel/aggregation/patients.h"

#include <algorithm>
#include <array>
#include <charconv>
#include <cmath>
#include <map>
#include <limits>
#include <optional>
#include <set>
#include <utility>

namespace tahvel::aggregation {

bool PatientView::alerting() const {
  return std::any_of(trends.begin(), trends.end(), [](const TrendUpdate& t) { return t.alert; });
}

// No mean heart rate either: a window written without its counts (another version) has beats.
bool PatientView::no_beats() const { return latest.window.metrics.rr_count == 0 && !latest.window.metrics.mean_hr_bpm; }

namespace {

// The node of an agent's IRI: the last path segment goes: "http://h/home1/hrv" ->
// "http://h/home1", and an IRI without an authority as well ("urn:tahvel:h/home1/hrv" ->
// "urn:tahvel:h/home1"). Nothing is left of "http://hrv" or "urn:hrv" once the segment goes.
std::string node_of(const std::string& source) {
  const std::size_t colon = source.find(':');
  const std::size_t slash = source.rfind('/');
  if (colon == std::string::npos || slash == std::string::npos || slash < colon) return {};
  const bool authority = source.compare(colon, 3, "://") == 0;
  if (authority && slash <= colon + 2) return {};
  if (source.compare(colon + 1, slash - colon - 1, std::string(slash - colon - 1, '/')) == 0) return {};
  return source.substr(0, slash);
}

// How near the node of writer `source` is to `recording`: the length of its IRI when the
// recording lies below it (a sensor of that node or below), else -1.
long nearness(const std::string& source, const std::string& recording) {
  const std::string node = node_of(source);
  if (node.empty() || recording.size() <= node.size() || recording.compare(0, node.size(), node) != 0 ||
      recording[node.size()] != '/')
    return -1;
  return static_cast<long>(node.size());
}

}  // namespace

std::string PatientView::source_node() const { return node_of(source); }

bool PatientView::irregular() const {
  const auto& pct = latest.window.metrics.irregular_pct;
  return pct && *pct > kIrregularPct;
}

namespace {

using node::Pattern;
using node::Record;
using node::Snapshot;
using node::Term;

// How far behind its windows a trend agent may be, in signal time: the first pass over trend
// updates reaches back this much before the earliest of the patients' latest windows.
constexpr std::int64_t kTrendLagNs = 15ll * 60 * 1'000'000'000;

Error store_error(const node::Error& e) { return Error{"reading the board: " + e.message}; }

std::optional<double> number_in(const std::optional<Term>& term) {
  if (!term || !term->is_literal()) return std::nullopt;
  double v = 0;
  const std::string& s = term->value;
  auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
  if (ec != std::errc() || end != s.data() + s.size() || !std::isfinite(v)) return std::nullopt;
  return v;
}

std::optional<std::string> iri_in(const std::optional<Term>& term) {
  if (!term || !term->is_iri()) return std::nullopt;
  return term->value;
}

// The objects of the first records <subject> tv:<local> ?o (in record order), for each of
// `locals`, in one walk of the subject's records that stops once it has them all.
template <std::size_t N>
Result<std::array<std::optional<Term>, N>> objects_on_board(const Snapshot& snapshot, const std::string& subject,
                                                            const std::array<const char*, N>& locals) {
  std::array<std::string, N> predicates;
  for (std::size_t i = 0; i < N; ++i) predicates[i] = std::string(kTv) + locals[i];
  std::array<std::optional<Term>, N> found;
  std::size_t left = N;
  Pattern pattern;
  pattern.s = Term::iri(subject);
  auto walked = snapshot.for_each(pattern, [&](const Record& r) {
    for (std::size_t i = 0; i < N; ++i)
      if (!found[i] && r.triple.p.value == predicates[i]) {
        found[i] = r.triple.o;
        --left;
      }
    return left > 0;
  });
  if (!walked) return unexpected(store_error(walked.error()));
  return found;
}

// What the windows are grouped and ordered by: a window's start and its recording.
struct WindowFacts {
  std::optional<double> start_s;
  std::optional<std::string> recording;
};

// The facts of window `iri`, in one walk of its records: its first tv:windowStartS, and as its
// recording the one its IRI <rec>/hrv/<start> extends when the window is derived from it, else
// its tv:recording (read_hrv_window's rule). For tahvel-hrv's windows the walk stops at the
// item's fifth record: a window is also derived from each of its RR items, sixty a minute, and
// looking each fact up apart, with tv:recording first (a walk of all of a window's records),
// took 0.91 s for 100 patients of 120 windows each against 0.50 s now (`tahvel bench hrv`).
Result<WindowFacts> window_facts(const Snapshot& snapshot, const std::string& iri) {
  const std::size_t at = iri.rfind("/hrv/");
  const std::string extended = at != std::string::npos && at != 0 ? iri.substr(0, at) : std::string();
  const std::string start_p = std::string(kTv) + "windowStartS", recording_p = std::string(kTv) + "recording";
  std::optional<Term> start, named;
  bool derived = false;
  Pattern pattern;
  pattern.s = Term::iri(iri);
  auto walked = snapshot.for_each(pattern, [&](const Record& r) {
    const std::string& p = r.triple.p.value;
    if (!start && p == start_p) start = r.triple.o;
    else if (!named && p == recording_p) named = r.triple.o;
    else if (!derived && !extended.empty() && p == kProvDerivedFrom && r.triple.o.is_iri() && r.triple.o.value == extended)
      derived = true;
    return !(start && derived);
  });
  if (!walked) return unexpected(store_error(walked.error()));
  return WindowFacts{number_in(start), derived ? std::optional<std::string>(extended) : iri_in(named)};
}

// Items that cannot be read, per writer.
class Unreadable {
 public:
  void add(const std::string& source, const std::string& error) {
    UnreadableItems& u = by_source_[source];
    if (u.count++ == 0) {
      u.source = source;
      u.first_error = error;
    }
  }
  std::vector<UnreadableItems> list() const {
    std::vector<UnreadableItems> out;
    for (const auto& [source, u] : by_source_) out.push_back(u);
    return out;
  }

 private:
  std::map<std::string, UnreadableItems> by_source_;
};

// One window or trend item as the indexes give it: where it lies in its series.
struct Entry {
  std::string iri;  // the window's or the trend update's
  double start_s = 0;
  std::uint64_t item = 0;
  std::string source;
  std::int64_t stored_ns = 0;
  std::int64_t asserted_ns = 0;
};

// The item of `entry`, its records about entry.iri (an item may hold several windows: `tahvel
// put` of a file) read by `reader`; nullopt when the item was removed since the listing or
// cannot be read (then counted for its writer).
template <class T>
Result<std::optional<T>> read_whole(const Snapshot& snapshot, const Entry& entry,
                                    Result<T> (*reader)(const std::vector<Record>&), Unreadable& unreadable) {
  auto records = snapshot.item(entry.item);
  if (!records) {
    if (records.error().code == node::Errc::not_found) return std::optional<T>();
    return unexpected(store_error(records.error()));
  }
  std::erase_if(*records, [&](const Record& r) { return r.triple.s.value != entry.iri; });
  auto value = reader(*records);
  if (!value) {
    unreadable.add(entry.source, value.error().message);
    return std::optional<T>();
  }
  return std::optional<T>(std::move(*value));
}

}  // namespace

// How far before `since` a recording's newest whole window is looked for: a day and a window,
// the longest step and window the chain takes (hrv.h).
constexpr double kMaxLookBackS = 2 * 86400 + 1;

Result<PatientsOnBoard> patients_on_board(const Snapshot& snapshot, std::optional<std::int64_t> since) {
  Unreadable unreadable;

  // Every window: its recording and start through the indexes (window_facts); a window
  // whose recording or start cannot be found so is read whole.
  // recording -> writer -> window IRI -> entry
  std::map<std::string, std::map<std::string, std::map<std::string, Entry>>> windows;
  Pattern hrv;
  hrv.p = Term::iri("http://www.w3.org/ns/sosa/observedProperty");
  hrv.o = tv_term("HeartRateVariability");
  hrv.since = since;
  auto listed = snapshot.list(hrv);
  if (!listed) return unexpected(store_error(listed.error()));
  for (const Record& r : *listed) {
    if (!r.triple.s.is_iri()) continue;
    const std::string& iri = r.triple.s.value;
    auto facts = window_facts(snapshot, iri);
    if (!facts) return unexpected(facts.error());
    Entry entry{iri, 0, r.meta.item, r.meta.source, r.meta.stored_at, r.meta.asserted_at};
    std::string rec;
    const std::optional<double>& s = facts->start_s;
    const std::optional<std::string>& name = facts->recording;
    if (s && name) {
      entry.start_s = *s;
      rec = *name;
    } else {
      auto w = read_whole(snapshot, entry, read_hrv_window, unreadable);
      if (!w) return unexpected(w.error());
      if (!*w) continue;
      entry.start_s = (*w)->window.start_s;
      rec = (*w)->recording;
    }
    windows[rec][entry.source].emplace(iri, std::move(entry));
  }

  std::map<std::string, PatientView> patients;
  // Per recording, when the first and the last of its windows read here were stored on this board.
  std::map<std::string, std::pair<std::int64_t, std::int64_t>> stored_span;
  for (auto& [recording, by_writer] : windows) {
    // One tahvel-hrv per recording (docs/agents.md). Writers that wrote windows under the same
    // names (a hospital computing HRV from a home's RR intervals beside the home's own windows)
    // are two agents on one recording: of those, the writer nearest the recording stands, whose
    // node holds its raw ECG, then the one with more windows; the others are named, not mixed
    // in. Writers that share no name (an agent renamed, one after the other) are one series.
    std::set<std::string> clashing;
    std::map<std::string, std::string> named_by;  // window IRI -> its first writer
    for (const auto& [writer, its] : by_writer)
      for (const auto& [iri, entry] : its)
        if (auto [at, fresh] = named_by.emplace(iri, writer); !fresh) clashing.insert({at->second, writer});
    std::string chosen;
    for (const std::string& writer : clashing) {
      const long near = nearness(writer, recording), best = chosen.empty() ? -2 : nearness(chosen, recording);
      if (near > best || (near == best && by_writer[writer].size() > by_writer[chosen].size())) chosen = writer;
    }
    std::map<std::string, Entry> by_iri;
    std::vector<std::pair<std::string, std::size_t>> others;
    for (auto& [writer, its] : by_writer) {
      if (clashing.count(writer) && writer != chosen) {
        others.emplace_back(writer, its.size());
        continue;
      }
      by_iri.merge(its);
    }
    std::vector<const Entry*> newest_first;
    for (const auto& [iri, entry] : by_iri) newest_first.push_back(&entry);
    std::sort(newest_first.begin(), newest_first.end(),
              [](const Entry* a, const Entry* b) { return a->start_s > b->start_s; });
    // The latest window is the newest the record's end did not cut short (1800-1805.6 s with 8
    // NN is no patient's state); when every one is (a record shorter than a window), the one
    // that measured the longest, the newest of those.
    std::optional<std::pair<const Entry*, HrvWindowItem>> shown;
    auto measured = [](const HrvWindowItem& w) { return w.window.end_s - w.window.start_s; };
    for (const Entry* entry : newest_first) {
      auto w = read_whole(snapshot, *entry, read_hrv_window, unreadable);
      if (!w) return unexpected(w.error());
      if (!*w) continue;
      const bool whole = !cut_short((*w)->window);
      if (whole || !shown || measured(**w) > measured(shown->second)) shown.emplace(entry, std::move(**w));
      if (whole) break;
    }
    // With --since after a recording's last whole window (it ended), the window since then is
    // only its cut-short end, and it was shown, its trend update without the alert. Its newest
    // whole window, asserted before `since` (one window's length back at most), is its state.
    // The window before starts a step back, which may be longer than the window: looked for a
    // window's length back, then twice as far, up to a day (the longest step the chain takes).
    std::optional<std::pair<Entry, HrvWindowItem>> before_since;
    const double length_s = shown ? shown->second.window.length_s : 0;
    for (double back_s = std::isfinite(length_s) ? std::clamp(length_s, 1.0, kMaxLookBackS) + 1 : kMaxLookBackS;
         since && shown && cut_short(shown->second.window) && !before_since; back_s *= 2) {
      back_s = std::min(back_s, kMaxLookBackS);
      Pattern earlier = hrv;
      earlier.since = shown->first->asserted_ns - static_cast<std::int64_t>(back_s * 1e9);
      earlier.until = *since;
      auto listed_before = snapshot.list(earlier);
      if (!listed_before) return unexpected(store_error(listed_before.error()));
      for (const Record& r : *listed_before) {
        if (!r.triple.s.is_iri() || (clashing.count(r.meta.source) && r.meta.source != chosen)) continue;
        auto facts = window_facts(snapshot, r.triple.s.value);
        if (!facts) return unexpected(facts.error());
        if (facts->recording && *facts->recording != recording) continue;
        Entry entry{r.triple.s.value, 0, r.meta.item, r.meta.source, r.meta.stored_at, r.meta.asserted_at};
        auto w = read_whole(snapshot, entry, read_hrv_window, unreadable);
        if (!w) return unexpected(w.error());
        if (!*w || (*w)->recording != recording || cut_short((*w)->window)) continue;
        entry.start_s = (*w)->window.start_s;
        if (!before_since || before_since->second.window.start_s < entry.start_s) before_since.emplace(entry, std::move(**w));
      }
      if (before_since) shown.emplace(&before_since->first, std::move(before_since->second));
      if (back_s >= kMaxLookBackS) break;
    }
    if (shown) {
      auto& [first, last] = stored_span[recording];
      first = std::numeric_limits<std::int64_t>::max();
      for (const auto& [iri, entry] : by_iri) {
        first = std::min(first, entry.stored_ns);
        last = std::max(last, entry.stored_ns);
      }
      PatientView& p = patients[recording];
      p.recording = recording;
      p.source = shown->first->source;
      p.windows = by_iri.size();
      p.latest = std::move(shown->second);
      p.latest_stored_ns = shown->first->stored_ns;
      p.latest_asserted_ns = shown->first->asserted_ns;
      p.other_writers = std::move(others);
    }
  }

  // Trends: the latest update per recording and metric, found through the indexes. The chain
  // asserts a trend update at its window's signal time, so the updates since the earliest of
  // the patients' latest windows (less kTrendLagNs) hold each patient's latest ones: the first
  // pass reads only those, and the older ones are read only for a patient that lacks there a
  // metric some update on the board has (a trend agent that stopped, or no longer writes that
  // metric). Updates are three times the windows at the hospital: reading all of them took the
  // view of 100 patients of 720 windows 3.8 s, against 1.2 s now (`tahvel bench hrv`). It takes
  // an update's asserted-at to rise with its window's start, as tahvel-trend writes them.
  std::map<std::pair<std::string, std::string>, Entry> latest_trend;  // (recording, metric IRI)
  std::int64_t recent_from = std::numeric_limits<std::int64_t>::max();
  for (const auto& [recording, p] : patients) recent_from = std::min(recent_from, p.latest_asserted_ns);
  recent_from = recent_from < std::numeric_limits<std::int64_t>::min() + kTrendLagNs ? std::numeric_limits<std::int64_t>::min()
                                                                                       : recent_from - kTrendLagNs;
  // Not after a patient's shown window, which may be asserted before `since` (above).
  if (since) {
    std::int64_t earliest_shown = std::numeric_limits<std::int64_t>::max();
    for (const auto& [recording, p] : patients) earliest_shown = std::min(earliest_shown, p.latest_asserted_ns);
    recent_from = std::max(recent_from, std::min(*since, earliest_shown));
  }
  // Reads the trend updates asserted in [from, until) and keeps, per recording and metric, the
  // one of the largest start that `wanted` accepts.
  auto read_trends = [&](std::optional<std::int64_t> from, std::optional<std::int64_t> until,
                         const auto& wanted) -> Result<void> {
    Pattern trends;
    trends.p = Term::iri(std::string(node::kRdfType));
    trends.o = tv_term("HrvTrend");
    trends.since = from;
    trends.until = until;
    auto listed = snapshot.list(trends);
    if (!listed) return unexpected(store_error(listed.error()));
    for (const Record& r : *listed) {
      if (!r.triple.s.is_iri()) continue;
      const std::string& iri = r.triple.s.value;
      auto facts = objects_on_board(snapshot, iri, std::array{"recording", "metric", "windowStartS"});
      if (!facts) return unexpected(facts.error());
      const auto& [recording, metric, start] = *facts;
      auto rec = iri_in(recording), which = iri_in(metric);
      auto s = number_in(start);
      Entry entry{iri, 0, r.meta.item, r.meta.source, r.meta.stored_at, r.meta.asserted_at};
      if (!rec || !which || !s) {
        auto t = read_whole(snapshot, entry, read_trend, unreadable);
        if (!t) return unexpected(t.error());
        if (!*t) continue;
        rec = (*t)->recording;
        which = std::string(kTv) + metric_local_name((*t)->metric);
        s = (*t)->window_start_s;
      }
      const auto patient = patients.find(*rec);
      if (patient == patients.end()) continue;  // its windows are gone (removed) or unreadable
      // Of a window after the one shown, which the record's end cut short: such an update has
      // no latest value and no alert (trend_agent.cpp), and would hide the shown window's.
      if (*s > patient->second.latest.window.start_s) continue;
      if (!wanted(*rec, *which)) continue;
      entry.start_s = *s;
      auto [it, fresh] = latest_trend.emplace(std::make_pair(*rec, *which), entry);
      if (!fresh && it->second.start_s < *s) it->second = entry;
    }
    return {};
  };
  if (!patients.empty()) {
    const auto from = recent_from > std::numeric_limits<std::int64_t>::min() ? std::optional(recent_from) : std::nullopt;
    auto recent = read_trends(from, std::nullopt, [](const std::string&, const std::string&) { return true; });
    if (!recent) return unexpected(recent.error());
  }
  // Before that, only what the recent updates leave out: per patient, a metric that some update
  // on the board has (a trend agent that stopped, or that no longer writes that metric).
  std::set<std::string> board_metrics;
  for (int m = 0; m <= static_cast<int>(HrvMetric::sd2); ++m) {
    Pattern named;
    named.p = tv_term("metric");
    named.o = Term::iri(std::string(kTv) + metric_local_name(static_cast<HrvMetric>(m)));
    bool any = false;
    auto walked = snapshot.for_each(named, [&](const Record&) { return !(any = true); });
    if (!walked) return unexpected(store_error(walked.error()));
    if (any) board_metrics.insert(named.o->value);
  }
  std::set<std::pair<std::string, std::string>> recent_found;
  for (const auto& [key, entry] : latest_trend) recent_found.insert(key);
  auto lacks = [&](const std::string& recording, const std::string& metric) {
    return board_metrics.count(metric) > 0 && recent_found.count({recording, metric}) == 0;
  };
  const bool some_lack = std::any_of(patients.begin(), patients.end(), [&](const auto& p) {
    return std::any_of(board_metrics.begin(), board_metrics.end(), [&](const std::string& m) { return lacks(p.first, m); });
  });
  const bool older_exist = since ? recent_from > *since : recent_from > std::numeric_limits<std::int64_t>::min();
  if (!patients.empty() && some_lack && older_exist) {
    auto older = read_trends(since, recent_from, lacks);
    if (!older) return unexpected(older.error());
  }
  for (const auto& [key, entry] : latest_trend) {
    auto t = read_whole(snapshot, entry, read_trend, unreadable);
    if (!t) return unexpected(t.error());
    if (*t) patients[key.first].trends.push_back(std::move(**t));
  }

  // The newest recording of each sensor, by when it started (its latest window's signal time
  // less that window's start in the recording; then when its last window was stored here).
  // Not by the latest window's signal time: a replay at --speed 10 asserts up to half an hour
  // ahead of the clock, and a finished replay passed for newer than the live recording after it.
  const auto started = [](const PatientView& p) {
    return p.latest_asserted_ns - static_cast<std::int64_t>(std::llround(p.latest.window.start_s * 1e9));
  };
  const auto newer = [&](const PatientView& a, const PatientView& b) {
    return std::pair(started(a), stored_span[a.recording].second) > std::pair(started(b), stored_span[b.recording].second);
  };
  std::map<std::string, const PatientView*> newest_of_sensor;
  const auto sensor_of = [](const std::string& recording) {
    const std::size_t at = recording.rfind("/recording/");
    return at == std::string::npos ? std::string() : recording.substr(0, at);
  };
  for (const auto& [recording, p] : patients) {
    const std::string sensor = sensor_of(recording);
    if (sensor.empty()) continue;
    const PatientView*& newest = newest_of_sensor[sensor];
    if (!newest || newer(p, *newest)) newest = &p;
  }
  // Superseded: this one's windows stopped while the newest one's came (not two recordings at
  // once). In signal time: the newest one's latest window starts more than a window after this
  // one's, unless the newest runs ahead of the clock (a replay at --speed 10, its window asserted
  // after it was stored here: a live recording beside it was taken for stopped). On this board:
  // none of this one's windows was stored since the newest one's first, and the newest went on
  // storing for more than two of this one's periods (the time between its windows stored here,
  // or its window's length when one is read) since this one's last: two recordings at once store
  // in turn, and one that started a little later had seemed to supersede the other.
  for (auto& [recording, p] : patients) {
    const std::string sensor = sensor_of(recording);
    if (sensor.empty()) continue;
    const PatientView* newest = newest_of_sensor[sensor];
    if (newest == &p) continue;
    const double window_ns = std::max(0.0, (p.latest.window.end_s - p.latest.window.start_s) * 1e9);
    // A window is asserted at its start and stored after its end, unless its signal runs ahead.
    const double newest_window_ns = std::max(0.0, (newest->latest.window.end_s - newest->latest.window.start_s) * 1e9);
    const bool newest_on_the_clock =
        static_cast<double>(newest->latest_asserted_ns) + newest_window_ns <= static_cast<double>(newest->latest_stored_ns);
    const auto& [first, last] = stored_span[recording];
    const auto& [newest_first, newest_last] = stored_span[newest->recording];
    const double period_ns =
        p.windows > 1 ? static_cast<double>(last - first) / static_cast<double>(p.windows - 1) : window_ns;
    if ((newest_on_the_clock && static_cast<double>(newest->latest_asserted_ns - p.latest_asserted_ns) > window_ns) ||
        (last < newest_first && static_cast<double>(newest_last - last) > 2 * period_ns))
      p.superseded_by = newest->recording;
  }

  PatientsOnBoard out;
  for (auto& [recording, p] : patients) {
    std::sort(p.trends.begin(), p.trends.end(),
              [](const TrendUpdate& a, const TrendUpdate& b) { return a.metric < b.metric; });
    out.patients.push_back(std::move(p));
  }
  // Alerting (or without beats) first: of a superseded recording (its source stopped) neither
  // counts.
  const auto alert_now = [](const PatientView& p) { return (p.alerting() || p.no_beats()) && p.superseded_by.empty(); };
  std::stable_sort(out.patients.begin(), out.patients.end(),
                   [&](const PatientView& a, const PatientView& b) { return alert_now(a) && !alert_now(b); });
  out.unreadable = unreadable.list();
  return out;
}

}  // namespace tahvel::aggregation
