// `tahvel hrv`: the HRV chain over a WFDB record (R peaks, RR/NN, HRV for the record and per
// window), and with --eval the beat-by-beat score of the detector against the record's
// reference annotations. `tahvel patients`: what a node's board says of each patient's HRV.
#include <algorithm>
#include <chrono>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <iostream>
#include <map>
#include <optional>
#include <sstream>
#include <string>
#include <system_error>
#include <utility>
#include <vector>

#include "commands.h"
#include "tahvel/aggregation/annotations.h"
#include "tahvel/aggregation/patients.h"
#include "tahvel/aggregation/pipeline.h"
#include "tahvel/aggregation/score.h"
#include "tahvel/aggregation/wfdb.h"
#include "tahvel/federation/link.h"

namespace tahvel::cli {
namespace {

namespace agg = tahvel::aggregation;

// A number as JSON (null for a metric whose guard failed); 6 significant digits are plenty
// for milliseconds and ms^2 and keep the output stable across platforms.
std::string json_number(std::optional<double> value) {
  if (!value || !std::isfinite(*value)) return "null";
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.6g", *value);
  return buf;
}

// A rate exactly: the shortest text that reads back as the same double.
std::string exact_number(double value) {
  if (!std::isfinite(value)) return "null";
  char buf[400];
  auto [end, ec] = std::to_chars(buf, buf + sizeof buf, value);
  return ec == std::errc() ? std::string(buf, end) : json_number(value);
}

// A time in seconds to the microsecond, without trailing zeros, as the board writes window
// times and names windows ("100093.5", "1799.6"): 6 significant digits made 100093.5 s
// "100094", and a 100,100 s record's last window (100100, 100100).
std::string seconds_number(double s) {
  if (!std::isfinite(s)) return "null";
  char buf[400];  // "%.6f" of the largest double: 309 digits, the point and six decimals
  std::snprintf(buf, sizeof buf, "%.6f", s);
  std::string text(buf);
  text.erase(text.find_last_not_of('0') + 1);
  if (text.back() == '.') text.pop_back();
  return text == "-0" ? "0" : text;
}

std::string metrics_json(const agg::HrvMetrics& m) {
  std::ostringstream out;
  out << "{\"mean_nn_ms\":" << json_number(m.mean_nn_ms) << ",\"sdnn_ms\":" << json_number(m.sdnn_ms)
      << ",\"rmssd_ms\":" << json_number(m.rmssd_ms) << ",\"pnn50_pct\":" << json_number(m.pnn50_pct)
      << ",\"mean_hr_bpm\":" << json_number(m.mean_hr_bpm) << ",\"lf_ms2\":" << json_number(m.lf_ms2)
      << ",\"hf_ms2\":" << json_number(m.hf_ms2) << ",\"lf_hf\":" << json_number(m.lf_hf)
      << ",\"sd1_ms\":" << json_number(m.sd1_ms) << ",\"sd2_ms\":" << json_number(m.sd2_ms)
      << ",\"nn_count\":" << m.nn_count << ",\"rr_count\":" << m.rr_count << ",\"gap_count\":" << m.gap_count
      << ",\"irregular_pct\":" << json_number(m.irregular_pct) << "}";
  return out.str();
}

void print_report_json(const std::string& record, const agg::HrvReport& report) {
  std::ostringstream out;
  out << "{\"record\":\"" << node::json_escape(record) << "\",\"signal\":" << report.signal
      << ",\"fs\":" << exact_number(report.fs) << ",\"beats\":[";
  for (std::size_t i = 0; i < report.beats.size(); ++i) out << (i ? "," : "") << report.beats[i];
  out << "],\"metrics\":" << metrics_json(report.metrics) << ",\"windows\":[";
  for (std::size_t i = 0; i < report.windows.size(); ++i) {
    const auto& w = report.windows[i];
    out << (i ? "," : "") << "{\"start_s\":" << seconds_number(w.start_s)
        << ",\"end_s\":" << seconds_number(w.end_s) << ",\"metrics\":" << metrics_json(w.metrics) << "}";
  }
  out << "]}\n";
  std::cout << out.str();
}

void print_metrics_line(const char* label, const agg::HrvMetrics& m) {
  auto v = [](std::optional<double> x) { return json_number(x); };
  std::cout << label << "  NN " << m.nn_count << "/" << m.rr_count << "  meanNN " << v(m.mean_nn_ms)
            << " ms  SDNN " << v(m.sdnn_ms) << " ms  RMSSD " << v(m.rmssd_ms) << " ms  pNN50 "
            << v(m.pnn50_pct) << " %  HR " << v(m.mean_hr_bpm) << " bpm  LF " << v(m.lf_ms2)
            << " ms2  HF " << v(m.hf_ms2) << " ms2  LF/HF " << v(m.lf_hf) << "  SD1 " << v(m.sd1_ms)
            << " ms  SD2 " << v(m.sd2_ms) << " ms  irregular " << v(m.irregular_pct) << " %";
  if (m.gap_count > 0) std::cout << "  gaps " << m.gap_count;  // intervals over the gap bound, not NN
  std::cout << "\n";
}

void print_report_text(const std::string& record, const agg::HrvReport& report) {
  std::cout << "record " << record << ": " << report.beats.size() << " beats at " << report.fs << " Hz (signal "
            << report.signal << ")\n";
  print_metrics_line("whole record", report.metrics);
  for (const auto& w : report.windows) {
    char label[900];
    std::snprintf(label, sizeof label, "%7s-%-7s s", seconds_number(w.start_s).c_str(), seconds_number(w.end_s).c_str());
    print_metrics_line(label, w.metrics);
  }
}

// A percentage for text ("-" when nothing was scored) or JSON (null then).
std::string percent(double fraction, bool json = false) {
  if (!std::isfinite(fraction)) return json ? "null" : "-";
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.2f", 100 * fraction);
  return buf;
}

// The signal the user named, checked against the record's header, so that an error names the
// number typed (kEcgSignal, the largest size_t, is also "the ECG lead" to hrv_from_record).
std::size_t checked_signal(const std::string& record, std::size_t signal) {
  if (signal == agg::kEcgSignal) return signal;
  auto header = agg::read_header(record);
  if (!header) fail(header.error().message);
  if (signal >= header->signals.size())
    fail(record + ".hea: no signal " + std::to_string(signal) + " (the record has " +
         std::to_string(header->signals.size()) + ")");
  if (auto why = agg::not_an_ecg_signal(*header, signal)) fail(*why);
  return signal;
}

// Why a record scored nothing with scoring from `from_s` on, or nullopt: shorter than the start
// (by default bxb's learning period, 5 minutes; `from_given`: --eval-from's), or no reference
// beat after it (its detections then false positives, as bxb scores them: said, since they pull
// the gross totals down, and an annotation file that stops early is the likelier cause).
std::optional<std::string> nothing_scored(const agg::BeatScore& score, double duration_s, double from_s, bool from_given) {
  if (score.tp + score.fn > 0) return std::nullopt;
  const std::string length = seconds_number(std::round(duration_s * 10) / 10), from = seconds_number(from_s);
  if (duration_s <= from_s)
    return "the record is " + length + " s long, no longer than the scoring start (" + from +
           (from_given ? " s, --eval-from" : " s, bxb's learning period") + "): nothing scored; --eval-from 0 scores it from its start";
  if (score.fp > 0)
    return "no reference beat from " + from + " s on (the record is " + length + " s long): its " + std::to_string(score.fp) +
           " detected beat(s) there are scored as false positives, in the gross totals too (an annotation file that stops early?)";
  return "no reference beat from " + from + " s on (the record is " + length + " s long): nothing scored";
}

// A RECORD argument as WFDB names records: without extension. A path to one of its files
// (…/100.hea, as a shell completes it) names the record, when there is no record of that name
// (whose header a missing one is then: "…/100.hea", not "…/100.dat.hea").
std::string record_path(const std::string& arg) {
  if (arg.empty()) usage_error("hrv: RECORD is empty: a WFDB record path without extension, as …/mitdb/100");
  for (const char* extension : {".hea", ".dat", ".atr"}) {
    if (!arg.ends_with(extension)) continue;
    std::error_code ec;
    if (!std::filesystem::exists(arg + ".hea", ec)) return arg.substr(0, arg.size() - 4);
  }
  return arg;
}

std::vector<std::string> record_paths(const Args& args) {
  std::vector<std::string> records;
  for (const std::string& arg : args.positional()) records.push_back(record_path(arg));
  return records;
}

// The median of the intervals between successive samples (nullopt with fewer than 20).
std::optional<double> median_interval(std::vector<std::int64_t> samples) {
  if (samples.size() < 21) return std::nullopt;
  std::sort(samples.begin(), samples.end());
  std::vector<std::int64_t> intervals;
  for (std::size_t i = 1; i < samples.size(); ++i) intervals.push_back(samples[i] - samples[i - 1]);
  std::nth_element(intervals.begin(), intervals.begin() + static_cast<std::ptrdiff_t>(intervals.size() / 2), intervals.end());
  return static_cast<double>(intervals[intervals.size() / 2]);
}

// Why the reference's beats and the detected ones seem counted at two sampling rates: their
// median intervals, in samples, a quarter or more apart. An annotation file kept from a record
// before it was resampled (360 Hz beats on a record of 500 Hz) scored Se 38 % and +P 35 % with
// no word of why (an exploratory run of session 85); a detector that finds most beats keeps
// the medians within a few percent, ectopic beats and all.
std::optional<std::string> rates_apart(const std::vector<agg::Annotation>& reference, const std::vector<std::int64_t>& detected, double fs) {
  std::vector<std::int64_t> beats;
  for (const agg::Annotation& a : reference)
    if (agg::is_beat(a.code)) beats.push_back(a.sample);
  const auto of_reference = median_interval(std::move(beats));
  const auto of_detected = median_interval(detected);
  if (!of_reference || !of_detected || !(*of_reference > 0) || !(*of_detected > 0)) return std::nullopt;
  const double ratio = *of_reference / *of_detected;
  if (ratio > 0.8 && ratio < 1.25) return std::nullopt;
  char text[512];
  std::snprintf(text, sizeof text,
                "the reference beats' median interval is %.0f samples and the detected beats' %.0f (%.2f times): "
                "annotations made at another sampling rate than the record's %s Hz (one it was resampled from, "
                "%.0f Hz if the detected beats are right)? An annotation file at another rate says so in a "
                "'## time resolution' note at its start; without one, the scores below compare beats of other times",
                *of_reference, *of_detected, ratio, seconds_number(fs).c_str(), fs * ratio);
  return std::string(text);
}

// Scores each record and prints one line per record and the gross totals.
int run_eval(const Args& args, const agg::ChainOptions& options, std::size_t signal, double from_s, const std::string& annotator) {
  const bool json = args.has("--json");
  agg::ScoreOptions scoring;
  scoring.start_s = from_s;
  agg::BeatScore gross;
  std::ostringstream rows;
  // A record that cannot be read is said and left out; the others are scored, and the gross
  // totals are theirs (one missing record of a list stopped the whole run, unscored).
  std::vector<std::string> not_scored;
  const std::vector<std::string> records = record_paths(args);
  for (const std::string& record : records) {
    auto leave_out = [&](const std::string& why) {
      std::cerr << "tahvel: " << why << " (" << record << " not scored)\n";
      not_scored.push_back(record);
    };
    auto report = agg::hrv_from_record(record, options, checked_signal(record, signal));
    if (!report) {
      leave_out(report.error().message);
      continue;
    }
    // Several records: each warning says whose it is (a checksum's names its header already).
    // What the signal's rhythm means for HRV (irregular, paced) says nothing of the scoring.
    for (const std::string& warning : report->warnings)
      std::cerr << warning_prefix() << (warning.starts_with(record) ? "" : record + ": ") << warning << "\n";
    auto reference = agg::read_annotations(record, annotator, report->fs);
    if (!reference) {
      leave_out(reference.error().message);
      continue;
    }
    // To the record's end, as bxb: a reference file that goes on past the signal (a header cut
    // short) does not count the beats after it as missed.
    scoring.end_s = report->duration_s;
    agg::BeatScore score = agg::score_beats(*reference, report->beats, report->fs, scoring);
    if (auto why = nothing_scored(score, report->duration_s, from_s, args.has("--eval-from"))) std::cerr << warning_prefix() << record << ": " << *why << "\n";
    // Not scored, as bxb, and not silently: 1,132 beats after a signal cut to half were
    // neither missed nor mentioned, which hides an annotation file of another record or rate.
    // Past the sample score_beats scores to (its end, rounded as it rounds it).
    std::size_t after_end = 0;
    std::int64_t last_after = 0;
    const std::int64_t scored_to = std::llround(report->duration_s * report->fs);
    for (const agg::Annotation& a : *reference)
      if (agg::is_beat(a.code) && a.sample > scored_to) {
        ++after_end;
        last_after = std::max(last_after, a.sample);
      }
    if (after_end > 0)
      std::cerr << warning_prefix() << record << ": " << after_end << " reference beat(s) lie after the signal's end ("
                << seconds_number(std::round(report->duration_s * 10) / 10) << " s; the last at "
                << seconds_number(std::round(static_cast<double>(last_after) / report->fs * 10) / 10)
                << " s) and are not scored: a header or signal file cut short, or annotations of another record or rate?\n";
    if (auto why = rates_apart(*reference, report->beats, report->fs)) std::cerr << warning_prefix() << record << ": " << *why << "\n";
    if (auto open = agg::unclosed_unreadable(*reference))
      std::cerr << warning_prefix() << record << ": the unreadable interval opened by the '~' at "
                << seconds_number(std::round(static_cast<double>(open->opened_at) / report->fs * 10) / 10)
                << " s is never closed by another '~': the " << open->beats_after
                << " reference beat(s) after it are not scored (the scoring convention: a '~' with subtype bits 4 and 5 set "
                   "opens an unreadable interval, the next '~' closes it; a file that marks a short shutdown with one '~', "
                   "as AHA files do, loses the rest of the record)\n";
    gross += score;
    if (json) {
      rows << (rows.tellp() > 0 ? "," : "") << "{\"record\":\"" << node::json_escape(record)
           << "\",\"tp\":" << score.tp << ",\"fn\":" << score.fn << ",\"fp\":" << score.fp
           << ",\"sensitivity_pct\":" << percent(score.sensitivity(), true)
           << ",\"positive_predictivity_pct\":" << percent(score.positive_predictivity(), true) << "}";
    } else {
      std::printf("%-24s TP %7lld  FN %5lld  FP %5lld  Se %6s %%  +P %6s %%\n", record.c_str(),
                  static_cast<long long>(score.tp), static_cast<long long>(score.fn),
                  static_cast<long long>(score.fp), percent(score.sensitivity()).c_str(),
                  percent(score.positive_predictivity()).c_str());
    }
  }
  if (json) {
    std::string unread;
    for (const std::string& record : not_scored) unread += (unread.empty() ? "\"" : ",\"") + node::json_escape(record) + "\"";
    std::cout << "{\"eval_from_s\":" << seconds_number(from_s) << ",\"annotator\":\"" << node::json_escape(annotator) << "\",\"records\":[" << rows.str() << "],\"tp\":" << gross.tp << ",\"fn\":" << gross.fn
              << ",\"fp\":" << gross.fp << ",\"sensitivity_pct\":" << percent(gross.sensitivity(), true)
              << ",\"positive_predictivity_pct\":" << percent(gross.positive_predictivity(), true)
              << ",\"not_scored\":[" << unread << "]}\n";
  } else if (records.size() > 1) {
    std::printf("%-24s TP %7lld  FN %5lld  FP %5lld  Se %6s %%  +P %6s %%\n", "gross",
                static_cast<long long>(gross.tp), static_cast<long long>(gross.fn),
                static_cast<long long>(gross.fp), percent(gross.sensitivity()).c_str(),
                percent(gross.positive_predictivity()).c_str());
  }
  finish_output(std::cout);
  if (!not_scored.empty()) {
    std::cerr << "tahvel: " << not_scored.size() << " of " << records.size() << " record(s) could not be read and were not scored"
              << (records.size() > not_scored.size() ? "; the totals are those of the others" : "") << "\n";
    return kExitFailure;
  }
  return kExitOk;
}

// A number of seconds as a person writes one: decimal digits, a point, an exponent. strtod also
// takes hexadecimal ("0x10" is 16), "inf" and "nan", which no one means as seconds.
std::optional<double> decimal_seconds(const std::string& text) {
  if (text.empty() || text.find_first_not_of("0123456789.+-eE") != std::string::npos) return std::nullopt;
  char* end = nullptr;
  const double value = std::strtod(text.c_str(), &end);
  if (end == text.c_str() || *end != '\0') return std::nullopt;
  return value;
}

// --window (is_step false) or --step: seconds within the chain's bounds
// (agg::window_setting_problem), else a usage error naming the flag and the bounds.
double seconds_flag(const Args& args, std::string_view flag, double fallback, bool is_step) {
  auto text = args.get(flag);
  if (!text) return fallback;
  if (args.has("--eval"))
    usage_error(std::string(flag) + ": not with --eval (scoring the beats uses no HRV windows)");
  const std::optional<double> parsed = decimal_seconds(*text);
  if (!parsed) usage_error(std::string(flag) + ": expected seconds, a decimal number, got '" + *text + "'");
  const double value = *parsed;
  if (auto problem = agg::window_setting_problem(value, is_step))
    usage_error(std::string(flag) + ": " + *problem + ", got '" + *text + "'");
  return value;
}

// --eval-from: seconds from the record's start, 0 allowed (default 300, bxb's).
double eval_from_flag(const Args& args) {
  auto text = args.get("--eval-from");
  if (!text) return agg::ScoreOptions{}.start_s;
  if (!args.has("--eval")) usage_error("--eval-from: only with --eval");
  const std::optional<double> parsed = decimal_seconds(*text);
  const double value = parsed.value_or(-1);
  if (!(value >= 0) || value > 1e9)
    usage_error("--eval-from: expected seconds from the record's start, a number >= 0, got '" + *text + "'");
  return value;
}

// --annotator: the reference annotation file's extension, as WFDB names annotators ("atr",
// "qrs", "ecg"); with --eval only. A name that is no plain extension (a path, a dot) is a usage
// error: it would open another file than RECORD.<name>.
std::string annotator_flag(const Args& args) {
  auto text = args.get("--annotator");
  if (!text) return "atr";
  if (!args.has("--eval")) usage_error("--annotator: only with --eval");
  if (text->empty() || text->find_first_not_of("ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789_-") != std::string::npos)
    usage_error("--annotator: expected an annotator name, the annotation file's extension (atr, qrs, ...), got '" + *text + "'");
  return *text;
}

// ---- tahvel patients ----------------------------------------------------------------------

// Where an alert's values lie from the baseline; nullptr when the trend does not say.
const char* direction_name(int direction) { return direction > 0 ? "above" : direction < 0 ? "below" : nullptr; }
// The same for text: "above its baseline", or "off its baseline" when the trend does not say.
std::string off_baseline(int direction) {
  const char* name = direction_name(direction);
  return std::string(name ? name : "off") + " its baseline";
}

std::string trend_json(const agg::TrendUpdate& t) {
  std::ostringstream out;
  const char* direction = t.alert ? direction_name(t.alert_direction) : nullptr;
  out << "{\"metric\":\"" << agg::metric_local_name(t.metric) << "\",\"window_start_s\":" << seconds_number(t.window_start_s)
      << ",\"windows\":" << t.windows << ",\"latest\":" << json_number(t.latest) << ",\"baseline\":" << json_number(t.baseline)
      << ",\"robust_sd\":" << json_number(t.robust_sd) << ",\"slope_per_hour\":" << json_number(t.slope_per_hour)
      << ",\"slope_horizon_s\":" << json_number(t.slope_horizon_s)
      << ",\"alert\":" << (t.alert ? "true" : "false") << ",\"direction\":"
      << (direction ? std::string("\"") + direction + "\"" : std::string("null"))
      << ",\"z_against_others\":" << json_number(t.z_against_others) << ",\"others\":" << t.others << "}";
  return out.str();
}

// The window's signal time as a query range: from its start for its length.
std::pair<std::int64_t, std::int64_t> signal_range_ns(const agg::PatientView& p) {
  const double length_s = std::max(0.0, p.latest.window.end_s - p.latest.window.start_s);
  return {p.latest_asserted_ns, p.latest_asserted_ns + static_cast<std::int64_t>(std::llround(length_s * 1e9))};
}

// What this node's link says (P12) of the child a patient's windows come through, when they
// come from below: an operator reading a home's latest window must know that the home is down
// here, and the windows computed there since have not come, or that its store refuses writes.
struct LinkOnTheWay {
  std::string at;     // the node whose link says this state: this one, or a node on the way
  std::string child;  // its child on the way to the node that computed the windows
  // tv:linkState: "up", "down" or "never connected"; or "not a child" when the link keeps
  // states of its children and none of this one (taken out of the file, or refused).
  std::string state;
  std::optional<std::int64_t> last_seen_ns;
  std::int64_t written_ns = 0;  // when the link wrote the state (its record's asserted-at)
  std::string store_warning;    // the child's store near full, as it said (store_warning_from_state)
  // The link rewrites an "up" state every 2 s (P12): one much older was left by a link that
  // no longer runs, and says nothing of the child now.
  bool stale() const { return state == "up" && written_ns > 0 && seconds_since(written_ns) > 15; }
  bool worth_saying() const { return state != "up" || stale() || !store_warning.empty(); }

  // From the records of the child's state that the link of `at` wrote.
  void read(const std::vector<node::Record>& records) {
    std::map<std::string, std::string> fields;  // by the predicate's local name
    for (const node::Record& r : records) {
      if (r.triple.s.value != child) continue;
      fields[r.triple.p.value.substr(r.triple.p.value.find('#') + 1)] = r.triple.o.value;
      if (r.triple.p.value == federation::vocab::kLinkState) written_ns = r.meta.asserted_at;
    }
    state = fields["linkState"];
    std::int64_t ns = 0;
    if (const std::string& seen = fields["lastSeen"]; std::from_chars(seen.data(), seen.data() + seen.size(), ns).ec == std::errc())
      last_seen_ns = ns;
    store_warning = store_warning_from_state(fields);
  }
};

// The node a recording lies below, at or below `computed_at` (the node that computed its
// windows): recording IRIs are <sensor>/recording/<name>, the sensor an agent of its node; the
// first "/recording/" past `computed_at` is the sensor's. Empty when the IRI is not of that shape.
std::string recording_node(const std::string& recording, const std::string& computed_at) {
  if (!uri::is_under(recording, computed_at)) return {};
  const auto at = recording.find("/recording/", computed_at.size());
  if (at == std::string::npos || at <= computed_at.size()) return {};
  const auto slash = recording.rfind('/', at - 1);
  return slash == std::string::npos || slash < computed_at.size() ? std::string() : recording.substr(0, slash);
}

std::optional<LinkOnTheWay> link_on_the_way(const node::Snapshot& snap, const std::string& node_iri,
                                            const std::string& computed_at) {
  if (computed_at.size() <= node_iri.size() + 1 || computed_at.compare(0, node_iri.size(), node_iri) != 0 ||
      computed_at[node_iri.size()] != '/')
    return std::nullopt;
  LinkOnTheWay link;
  link.at = node_iri;
  link.child = computed_at.substr(0, computed_at.find('/', node_iri.size() + 1));
  auto writer = uri::agent_iri(link.at, "link");
  if (!writer) return std::nullopt;
  auto records = snap.list({.s = node::Term::iri(link.child), .source = *writer});
  if (!records) return std::nullopt;
  link.read(*records);
  if (link.state.empty()) {
    // A link that keeps its children's states removes the state of a child taken out of its
    // children (P12): a home taken out of the file, or refused, showed its windows as if they
    // were merely late (an integrator's probe of session 89).
    auto states = snap.list({.p = node::Term::iri(federation::vocab::kLinkState), .source = *writer}, {.limit = 1});
    if (!states || states->empty()) return std::nullopt;
    link.state = "not a child";
  }
  return link;
}

// The first link below this node's child, on the way to `computed_at`, that is not up or whose
// child's store is near full: each node on the way keeps its children's state on its own
// board, and this node holds only its own children's. Asked of each such node in turn (a
// remote query, within `deadline`), while the hop above it is up; nullopt when every hop is up
// with room, or a node does not answer.
std::optional<LinkOnTheWay> link_below(node::Node& node, const LinkOnTheWay& first, const std::string& computed_at,
                                       std::chrono::steady_clock::time_point deadline) {
  LinkOnTheWay above = first;
  while (computed_at.size() > above.child.size() + 1 && computed_at.compare(0, above.child.size(), above.child) == 0 &&
         computed_at[above.child.size()] == '/') {
    LinkOnTheWay link;
    link.at = above.child;
    link.child = computed_at.substr(0, computed_at.find('/', link.at.size() + 1));
    auto writer = uri::agent_iri(link.at, "link");
    if (!writer) return std::nullopt;
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
    if (left.count() <= 0) return std::nullopt;
    // The child's whole state in one question: only its link's records of it.
    std::vector<node::Record> records;
    auto answered = federation::remote_query(node, {.target = link.at, .pattern = {.s = node::Term::iri(link.child)}, .restart_grace = {}},
                                             left, [&](const node::Record& r) {
                                               if (r.meta.source == *writer) records.push_back(r);
                                             });
    if (!answered) return std::nullopt;
    link.read(records);
    if (link.state.empty()) return std::nullopt;
    if (link.worth_saying()) return link;
    above = std::move(link);
  }
  return std::nullopt;
}

void print_patients_json(const std::string& node_iri, const agg::PatientsOnBoard& board,
                         const std::vector<const agg::PatientView*>& shown,
                         const std::vector<std::optional<LinkOnTheWay>>& links, const std::vector<bool>& ecg_held_here,
                         const std::vector<std::optional<std::uint64_t>>& ended) {
  std::ostringstream out;
  out << "{\"node\":\"" << node::json_escape(node_iri) << "\",\"patients\":[";
  for (std::size_t i = 0; i < shown.size(); ++i) {
    const agg::PatientView& p = *shown[i];
    out << (i ? "," : "") << "{\"recording\":\"" << node::json_escape(p.recording) << "\",\"source\":\""
        << node::json_escape(p.source) << "\",\"windows\":" << p.windows << ",\"alerting\":" << (p.alerting() ? "true" : "false")
        << ",\"no_beats\":" << (p.no_beats() ? "true" : "false")
        << ",\"irregular\":" << (p.irregular() ? "true" : "false") << ",\"other_writers\":[";
    for (std::size_t k = 0; k < p.other_writers.size(); ++k)
      out << (k ? "," : "") << "{\"source\":\"" << node::json_escape(p.other_writers[k].first)
          << "\",\"windows\":" << p.other_writers[k].second << "}";
    out << "],\"superseded_by\":";
    if (p.superseded_by.empty()) out << "null";
    else out << "\"" << node::json_escape(p.superseded_by) << "\"";
    out << ",\"recording_ended_at_sample\":" << (ended[i] ? std::to_string(*ended[i]) : "null");
    out << ",\"latest\":{\"iri\":\"" << node::json_escape(p.latest.iri)
        << "\",\"start_s\":" << seconds_number(p.latest.window.start_s) << ",\"end_s\":" << seconds_number(p.latest.window.end_s)
        << ",\"stored_ns\":" << p.latest_stored_ns << ",\"asserted_ns\":" << p.latest_asserted_ns << ",\"metrics\":" << metrics_json(p.latest.window.metrics) << "}";
    // Where the raw ECG behind the latest window is, for `tahvel ecg` or `tahvel query`.
    if (const std::string at = p.source_node(); !at.empty()) {
      const auto [since, until] = signal_range_ns(p);
      out << ",\"raw_ecg\":{\"node\":\"" << node::json_escape(at) << "\",\"since_ns\":" << since << ",\"until_ns\":" << until
          << ",\"held_here\":" << (ecg_held_here[i] ? "true" : "false") << "}";
    } else {
      out << ",\"raw_ecg\":null";
    }
    if (const auto& link = links[i]) {
      out << ",\"link\":{\"child\":\"" << node::json_escape(link->child) << "\",\"state\":\"" << node::json_escape(link->state)
          << "\",\"last_seen_ns\":" << (link->last_seen_ns ? std::to_string(*link->last_seen_ns) : "null")
          << ",\"stale\":" << (link->stale() ? "true" : "false") << ",\"at\":\"" << node::json_escape(link->at) << "\",\"store_warning\":";
      if (link->store_warning.empty()) out << "null}";
      else out << "\"" << node::json_escape(link->store_warning) << "\"}";
    } else {
      out << ",\"link\":null";
    }
    out << ",\"trends\":[";
    for (std::size_t k = 0; k < p.trends.size(); ++k) out << (k ? "," : "") << trend_json(p.trends[k]);
    out << "]}";
  }
  out << "],\"unreadable\":[";
  for (std::size_t i = 0; i < board.unreadable.size(); ++i) {
    const agg::UnreadableItems& u = board.unreadable[i];
    out << (i ? "," : "") << "{\"source\":\"" << node::json_escape(u.source) << "\",\"count\":" << u.count
        << ",\"first_error\":\"" << node::json_escape(u.first_error) << "\"}";
  }
  out << "]}\n";
  std::cout << out.str();
}

// A value for text: up to 4 significant digits, "-" when absent.
std::string text_number(std::optional<double> value, const char* format = "%.4g") {
  if (!value || !std::isfinite(*value)) return "-";
  char buf[32];
  std::snprintf(buf, sizeof buf, format, *value);
  return buf;
}

// `text` as one word for a POSIX shell: as it is when it holds nothing the shell would read,
// else in single quotes (a quote inside as '\'').
std::string shell_word(const std::string& text) {
  const bool plain = !text.empty() && std::all_of(text.begin(), text.end(), [](unsigned char c) {
    return std::isalnum(c) || (c != 0 && std::strchr("_./:@%+=,-", c) != nullptr);
  });
  if (plain) return text;
  std::string out = "'";
  for (char c : text) out += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return out + "'";
}

void print_patient_text(const std::string& dir, const std::string& node_iri, const agg::PatientView& p, bool ecg_held_here,
                        const std::optional<LinkOnTheWay>& link, std::optional<std::uint64_t> ended_at) {
  std::cout << "\n<" << p.recording << ">";
  for (const agg::TrendUpdate& t : p.trends)
    if (t.alert) std::cout << "  ALERT: " << agg::metric_local_name(t.metric) << " " << off_baseline(t.alert_direction);
  if (p.no_beats()) std::cout << "  NO BEATS in the latest window";
  std::cout << "\n  " << p.windows << " HRV window(s) from <" << p.source << ">; the latest "
            << seconds_number(p.latest.window.start_s) << "-" << seconds_number(p.latest.window.end_s)
            << " s into the recording, stored " << node::utc_text(p.latest_stored_ns) << " ("
            << age_of(p.latest_stored_ns) << ")\n";
  // A hop below the node that computed the windows is the sensor's, which its ECG comes from.
  const std::string computed_at = p.source_node();
  const bool sensor_hop = link && !computed_at.empty() && link->child.size() > computed_at.size() && uri::is_under(link->child, computed_at);
  if (link && link->worth_saying() && sensor_hop && (link->state != "up" || link->stale())) {
    const std::string heard = link->last_seen_ns ? "last heard " + age_of(*link->last_seen_ns) : "never heard";
    if (link->stale())
      std::cout << "  its ECG comes from <" << link->child << ">, up at <" << link->at << "> as "
                << (link->at == node_iri ? "this" : "that") << " node's link said "
                << age_of(link->written_ns) << " (it says so every 2 s while it runs): is that link running? (tahvel status)\n";
    else if (link->state == "not a child")
      std::cout << "  its ECG comes from <" << link->child << ">, which is no child of <" << link->at
                << "> now (its link keeps no state of it: taken out of the deployment, or refused; tahvel status): "
                << "no window is made without it\n";
    else
      std::cout << "  its ECG comes from <" << link->child << ">, " << link->state << " at <" << link->at << "> (" << heard
                << "): no window is made without it\n";
    if (!link->store_warning.empty()) std::cout << "  its store, as it last said: " << link->store_warning << "\n";
  } else if (link && link->worth_saying() && sensor_hop) {
    std::cout << "  its ECG comes from <" << link->child << ">, whose store is near full or refuses writes: " << link->store_warning
              << "\n";
  } else if (link && link->worth_saying()) {
    const std::string heard = link->last_seen_ns ? "last heard " + age_of(*link->last_seen_ns) : "never heard";
    if (link->state == "up" && !link->stale())
      std::cout << "  its windows come through <" << link->child << ">, whose store is near full or refuses writes: "
                << link->store_warning << "\n";
    else if (link->stale())
      std::cout << "  its windows come through <" << link->child << ">, up at <" << link->at << "> as " << (link->at == node_iri ? "this" : "that") << " node's link said "
                << age_of(link->written_ns) << " (it says so every 2 s while it runs): is that link running? (tahvel status)\n";
    else if (link->state == "not a child")
      std::cout << "  its windows come through <" << link->child << ">, which is no child of <" << link->at
                << "> now (its link keeps no state of it: taken out of the deployment, or refused; tahvel status): "
                << "windows computed there since have not come\n";
    else
      std::cout << "  its windows come through <" << link->child << ">, " << link->state << " at <" << link->at << "> ("
                << heard << "): windows computed since have not come\n";
    if (link->state != "up" || link->stale())
      if (!link->store_warning.empty()) std::cout << "  its store, as it last said: " << link->store_warning << "\n";
  }
  if (ended_at)
    std::cout << "  its recording ended at sample " << *ended_at << " (its source wrote tv:endSample): no window comes after "
              << "the last\n";
  if (!p.superseded_by.empty())
    std::cout << "  a later recording of the same sensor, <" << p.superseded_by
              << ">, has windows since: this one's source stopped or started again as that one\n";
  for (const auto& [writer, count] : p.other_writers)
    std::cout << "  also " << count << " window(s) of it from <" << writer
              << ">, not shown: two HRV agents on one recording (run one tahvel-hrv per recording)\n";
  const agg::HrvMetrics& m = p.latest.window.metrics;
  std::cout << "  latest window: SDNN " << text_number(m.sdnn_ms) << " ms, RMSSD " << text_number(m.rmssd_ms)
            << " ms, mean HR " << text_number(m.mean_hr_bpm) << " bpm, " << m.nn_count << " NN of " << m.rr_count
            << " RR intervals\n";
  if (p.no_beats())
    std::cout << "  no beats were found in it: a lead off, a flat line, or asystole? Its trends have no value and no alert "
                 "of their own; an alert of the windows before it no longer runs to the latest\n";
  // The chunks of that window's time at the node that computed it, of this recording only (a
  // node with two sensors holds another patient's chunks of the same time; a chunk's subject is
  // <recording>/chunk/N).
  const bool cut_off = link && link->state == "not a child" && link->at == node_iri;
  if (const std::string node = p.source_node(); !node.empty() && cut_off) {
    // The query would answer "unknown node": the way down goes through a child this node no
    // longer has.
    std::cout << "  its raw ECG, at <" << node << ">, cannot be asked from here: <" << link->child
              << "> is no child of this node\n";
    if (ecg_held_here) {
      const auto [since, until] = signal_range_ns(p);
      std::cout << "  some of its raw ECG is held here (forwarded up): tahvel ecg " << shell_word(dir) << " --recording "
                << shell_word(p.recording) << " --since " << since << " --until " << until << "\n";
    }
  } else if (!node.empty()) {
    const auto [since, until] = signal_range_ns(p);
    std::cout << "  its raw ECG, at <" << node << ">: tahvel query " << shell_word(dir) << " --at "
              << shell_word(node) << " --under " << shell_word(p.recording) << " -p tv:samples --since " << since
              << " --until " << until << "\n";
    std::cout << "  as numbers (CSV): tahvel ecg " << shell_word(dir) << " --at " << shell_word(node) << " --recording "
              << shell_word(p.recording) << " --since " << since << " --until " << until << "\n";
    // A forward policy that sends raw ECG up (docs/deploy.md) leaves a copy here: read without
    // a remote query, and while the way down is cut.
    if (ecg_held_here && node != node_iri)
      std::cout << "  some of its raw ECG is held here too (forwarded up): tahvel ecg " << shell_word(dir) << " --recording "
                << shell_word(p.recording) << " --since " << since << " --until " << until << "\n";
  }
  if (p.irregular())
    std::cout << "  irregular rhythm: " << text_number(m.irregular_pct, "%.0f")
              << " % of successive RR intervals differ by more than 20 %: its HRV may be off (docs/hrv.md)\n";
  if (p.trends.empty()) std::cout << "  no trend of it on this node (tahvel-trend writes them)\n";
  for (const agg::TrendUpdate& t : p.trends) {
    char line[256];
    std::snprintf(line, sizeof line, "  trend %-10s latest %-7s baseline %-7s", agg::metric_local_name(t.metric),
                  text_number(t.latest).c_str(), text_number(t.baseline).c_str());
    std::cout << line;
    // The slope is of the last hours' windows (tahvel-trend --horizon-h), the count of all of
    // them: "slope … over N window(s)" said the slope was of every window since the start.
    if (t.slope_per_hour) {
      std::cout << " slope " << text_number(t.slope_per_hour, "%+.3g") << "/h";
      if (t.slope_horizon_s) std::cout << " over the last " << text_number(*t.slope_horizon_s / 3600, "%.3g") << " h";
      std::cout << ",";
    }
    std::cout << " " << t.windows << " window(s)";
    if (t.alert) std::cout << ", ALERT " << off_baseline(t.alert_direction);
    if (t.z_against_others)
      std::cout << ", z " << text_number(t.z_against_others, "%+.2f") << " against " << t.others << " other patient(s)";
    std::cout << "\n";
  }
}

}  // namespace

const Command kHrvCommand{
    "hrv",
    "RECORD [--signal N] [--window S] [--step S] [--json] | RECORD... --eval [--eval-from S] [--annotator NAME] [--signal N] [--json]",
    "Run the HRV chain over a WFDB record, or score its beat detection.",
    "RECORD is a WFDB record path without extension (…/mitdb/100; or …/100.hea): its header\n"
    "(.hea) and signal files are read, and its ECG lead goes through the chain (the first signal\n"
    "named as an ECG lead, MLII, V1, II, ECG, ...; else the first in volts; else the first;\n"
    "--signal N names another, 0 the first): R-peak detection, RR intervals\n"
    "with the NN mask (docs/hrv.md), HRV for the whole record and for windows of --window\n"
    "seconds (default 300, at least 10) every --step seconds (default: the window, at least 1).\n"
    "--json prints one object:\n"
    "{record, signal, fs, beats: [sample indices], metrics: {...}, windows: [{start_s, end_s, metrics}]};\n"
    "a metric whose minimum-length guard fails is null.\n"
    "\n"
    "With --eval, each RECORD's detected beats are scored against its reference annotations\n"
    "(.atr; --annotator NAME: RECORD.NAME) as WFDB's bxb does: 150 ms match window, from 5 minutes in (--eval-from S: from S\n"
    "seconds; a record no longer than that scores nothing, with a warning), unreadable intervals\n"
    "skipped (docs/wfdb.md). Prints TP, FN, FP, sensitivity and positive predictivity per record\n"
    "and, for several records, the gross totals.",
    {{"--window", "", "S", "HRV window length in seconds, 10 to 86400 (default 300)"},
     {"--step", "", "S", "start of one window to the next, seconds, 1 to 86400 (default: the window)"},
     {"--signal", "", "N", "the record's signal to read, 0 the first (default: its ECG lead)"},
     {"--eval", "", "", "score the detected beats against RECORD.atr"},
     {"--eval-from", "", "S", "with --eval: score from S seconds in (default 300, bxb's; 0: the whole record)"},
     {"--annotator", "", "NAME", "with --eval: the reference annotations' extension (default atr)"},
     {"--json", "", "", "print JSON instead of text"}},
    1, SIZE_MAX, false};

int run_hrv(const Args& args) {
  agg::ChainOptions options;
  options.window_s = seconds_flag(args, "--window", 300, false);
  options.step_s = seconds_flag(args, "--step", options.window_s, true);
  if (auto problem = agg::window_step_problem(options.window_s, options.step_s))
    usage_error("--step: " + *problem + ", got '" + *args.get("--step") + "'");
  // Any number: checked_signal names it as typed when the record lacks it.
  std::optional<std::uint64_t> typed;
  if (args.has("--signal")) typed = args.get_u64("--signal", 0);
  const double from_s = eval_from_flag(args);
  const std::string annotator = annotator_flag(args);
  if (typed && *typed >= agg::kEcgSignal) {  // only on a machine whose size_t is narrower, or the largest value
    const std::string record = record_path(args.positional(0));
    auto header = agg::read_header(record);
    if (!header) fail(header.error().message);
    fail(record + ".hea: no signal " + std::to_string(*typed) + " (the record has " +
         std::to_string(header->signals.size()) + ")");
  }
  const std::size_t signal = typed ? static_cast<std::size_t>(*typed) : agg::kEcgSignal;
  if (args.has("--eval")) return run_eval(args, options, signal, from_s, annotator);
  if (args.positional().size() != 1) usage_error("hrv: one RECORD at a time (several only with --eval)");
  const std::string record = record_path(args.positional(0));
  auto report = agg::hrv_from_record(record, options, checked_signal(record, signal));
  if (!report) fail(report.error().message);
  // Said as with --eval: whose warning it is, when the warning does not name the file itself.
  for (const auto* warnings : {&report->warnings, &report->rhythm_warnings})
    for (const std::string& warning : *warnings)
      std::cerr << warning_prefix() << (warning.starts_with(record) ? "" : record + ": ") << warning << "\n";
  if (args.has("--json")) {
    print_report_json(record, *report);
  } else {
    print_report_text(record, *report);
  }
  finish_output(std::cout);
  return kExitOk;
}

const Command kPatientsCommand{
    "patients",
    "DIR [--since T] [--alerts] [--json]",
    "Print each patient whose HRV reached this node: latest window, trends, alerts.",
    "The operator's view of the patients on a node's board (at the hospital: every home's): per\n"
    "recording whose HRV windows are on the board, who sent them and how many, the latest\n"
    "window's SDNN, RMSSD and mean heart rate (with a warning when the rhythm is too irregular\n"
    "for its HRV to be trusted), the query that brings the raw ECG behind it and, where\n"
    "tahvel-trend runs, each metric's latest trend: baseline, slope per hour, change alert and\n"
    "z-score against the other patients. Patients\n"
    "with an alert come first. Windows or trends that cannot be read are counted per writer.\n"
    "--since T counts only the windows (and trends) of signal time T or later: ns since the\n"
    "epoch or an RFC 3339 time such as 2026-11-21T10:00:00Z, as tahvel query takes it.\n"
    "--json prints one object: {node, patients: [{recording, source, windows, alerting, no_beats,\n"
    "irregular, other_writers: [{source, windows}], superseded_by, recording_ended_at_sample, latest: {iri,\n"
    "start_s, end_s, stored_ns, asserted_ns, metrics}, raw_ecg: {node, since_ns, until_ns, held_here} or null,\n"
    "link: {child, state, last_seen_ns, stale, at, store_warning} or null, trends: [{metric, window_start_s, windows, latest,\n"
    "baseline, robust_sd, slope_per_hour, slope_horizon_s, alert, direction, z_against_others,\n"
    "others}]}],\n"
    "unreadable: [{source, count, first_error}]}.",
    {{"--since", "", "T", "only windows and trends of signal time T or later"},
     {"--alerts", "", "", "only the patients with an alert, or without beats in their latest window"},
     {"--json", "", "", "print JSON instead of text"}},
    1, 1, false};

int run_patients(const Args& args) {
  node::Node node = open_node(args.positional(0));
  auto snapshot = check(node.snapshot());
  std::optional<std::int64_t> since;
  if (auto text = args.get("--since")) since = time_flag("--since", *text);
  auto board = agg::patients_on_board(snapshot, since);
  if (!board) fail(board.error().message);
  std::vector<const agg::PatientView*> shown;
  std::size_t alerting = 0, silent = 0;  // with an alert; without beats in the latest window
  for (const agg::PatientView& p : board->patients) {
    // An alert of a recording a later one of its sensor supersedes is of a source that stopped:
    // shown with it, not counted nor listed by --alerts as the patient's.
    const bool alert_now = p.alerting() && p.superseded_by.empty();
    const bool silent_now = p.no_beats() && p.superseded_by.empty();
    if (alert_now) ++alerting;
    if (silent_now) ++silent;
    if (!args.has("--alerts") || alert_now || silent_now) shown.push_back(&p);
  }
  std::vector<std::optional<LinkOnTheWay>> links;
  // Below this node's children the links' states are on the boards of the nodes on the way:
  // asked, once per hop, within 3 s in all (a home behind a gateway that went down was shown
  // as if its windows were just late). The way goes on to the sensor node the recording lies
  // below, where that is below the node that computed the windows: a sensor whose link is down
  // stops the windows as surely (its home showed "up", its windows merely late).
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(3);
  std::map<std::string, std::optional<LinkOnTheWay>> asked;  // by the node at the end of the way
  for (const agg::PatientView* p : shown) {
    const std::string computed_at = p->source_node();
    std::string way_to = computed_at;
    if (const std::string sensor = computed_at.empty() ? std::string() : recording_node(p->recording, computed_at);
        !computed_at.empty() && sensor.size() > computed_at.size() && uri::is_under(sensor, computed_at))
      way_to = sensor;
    auto link = link_on_the_way(snapshot, node.iri(), way_to);
    if (link && !link->worth_saying()) {
      auto [it, fresh] = asked.try_emplace(way_to);
      if (fresh) it->second = link_below(node, *link, way_to, deadline);
      if (it->second) link = it->second;
    }
    links.push_back(std::move(link));
  }
  // Whether each late patient's recording has ended (its source's `<rec> tv:endSample N`, kept
  // where its windows are computed): a replay that finished looked like a home whose windows
  // were late (an operator's probe of session 88). Read here when they are computed here; else
  // asked of the node that computes them for a patient whose latest window was stored longer
  // ago than a window lasts (at least a minute), within what is left of the 3 s.
  std::vector<std::optional<std::uint64_t>> ended(shown.size());
  for (std::size_t i = 0; i < shown.size(); ++i) {
    const agg::PatientView& p = *shown[i];
    const std::string computed_at = p.source_node().empty() ? node.iri() : p.source_node();
    const double length_s = std::max(60.0, p.latest.window.end_s - p.latest.window.start_s);
    if (computed_at != node.iri() && seconds_since(p.latest_stored_ns) < length_s) continue;
    const node::Pattern end{.s = node::Term::iri(p.recording), .p = node::Term::iri(std::string(agg::kTv) + "endSample")};
    auto take_end = [&](const node::Record& r) {
      if (auto n = parse_u64(r.triple.o.value)) ended[i] = *n;
    };
    if (computed_at == node.iri()) {
      for (const node::Record& r : check(snapshot.list(end, {.limit = 1}))) take_end(r);
    } else if (!links[i] || !links[i]->worth_saying()) {
      const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
      if (left.count() <= 0) break;
      (void)federation::remote_query(node, {.target = computed_at, .pattern = end, .restart_grace = {}}, left, take_end);
    }
  }
  // Whether this node holds raw ECG of each latest window's time (a chunk of it), beside the
  // node that computed the window.
  // `tahvel ecg` reads the recording's description too: without it here (a policy that sends
  // chunks alone, a ring that took it), the command offered would fail.
  std::vector<bool> ecg_held_here;
  for (const agg::PatientView* p : shown) {
    bool held = false;
    if (!p->source_node().empty()) {
      const auto [since_ns, until_ns] = signal_range_ns(*p);
      node::Pattern chunks;
      chunks.p = node::Term::iri(std::string(agg::kTv) + "samples");
      chunks.under = p->recording;
      chunks.since = since_ns;
      chunks.until = until_ns;
      held = !check(snapshot.list(chunks, {.limit = 1})).empty() &&
             !check(snapshot.list({.s = node::Term::iri(p->recording)}, {.limit = 1})).empty();
    }
    ecg_held_here.push_back(held);
  }
  if (args.has("--json")) {
    print_patients_json(node.iri(), *board, shown, links, ecg_held_here, ended);
  } else {
    std::cout << board->patients.size() << " patient(s) with HRV on <" << node.iri() << ">"
              << (since ? " since " + node::utc_text(*since) : std::string()) << ", " << alerting << " with an alert"
              << (silent ? ", " + std::to_string(silent) + " without beats in the latest window" : std::string()) << "\n";
    for (std::size_t i = 0; i < shown.size(); ++i)
      print_patient_text(args.positional(0), node.iri(), *shown[i], ecg_held_here[i], links[i], ended[i]);
    for (const agg::UnreadableItems& u : board->unreadable)
      std::cout << "\n" << u.count << " HRV window or trend item(s) from <" << u.source
                << "> could not be read; the first: " << u.first_error << "\n";
  }
  finish_output(std::cout);
  return kExitOk;
}

}  // namespace tahvel::cli
