// `tahvel bench hrv`: speed of the detector and of the whole chain (samples -> HRV) as a
// multiple of real time on one core, over real MIT-BIH records; and what stays home against
// what goes up: bytes of raw ECG kept in a node store per patient-hour, against bytes of HRV
// items (N-Triples, as on the wire) sent up per patient-hour; and the hospital operator's view
// (`tahvel patients`) over a board of many patients' windows and trend updates, against a plain
// listing of the same windows and updates.
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "args.h"
#include "bench.h"
#include "bench_measure.h"
#include "tahvel/aggregation/items.h"
#include "tahvel/aggregation/patients.h"
#include "tahvel/aggregation/pipeline.h"
#include "tahvel/aggregation/wfdb.h"
#include "tahvel/node/format.h"
#include "tahvel/node/node.h"

namespace tahvel::cli {
namespace {

namespace agg = tahvel::aggregation;
namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

const char* kUsage =
    "usage: tahvel bench hrv [--json] [--quick] [--records N] [--board-patients N] [--board-windows N]\n"
    "  --json              print one JSON object instead of the table\n"
    "  --quick             three records and a board of 10 patients x 20 windows, for smoke tests\n"
    "  --records N         the first N records of $TAHVEL_MITDB/RECORDS (default: all)\n"
    "  --board-patients N  patients on the operator's board (default 100)\n"
    "  --board-windows N   60 s windows per patient on it, each with three trend updates (default 120)\n"
    "Records are read from $TAHVEL_MITDB (default ../shared/data/mitdb).\n";

struct Options {
  bool json = false;
  std::size_t records = 0;  // 0: all
  // The operator's board: patients, each with this many 60 s windows (each derived from 60 RR
  // items, as tahvel-hrv writes them) and three trend updates per window (as tahvel-trend).
  std::size_t board_patients = 100, board_windows = 120;
};

fs::path mitdb_dir() {
  const char* env = std::getenv("TAHVEL_MITDB");
  return env && *env ? fs::path(env) : fs::path("../shared/data/mitdb");
}

std::vector<std::string> record_names(const fs::path& dir, std::size_t limit) {
  std::ifstream in(dir / "RECORDS");
  if (!in) fail("bench hrv: no " + (dir / "RECORDS").string() + " (set TAHVEL_MITDB to the MIT-BIH directory)");
  std::vector<std::string> names;
  for (std::string line; std::getline(in, line) && (limit == 0 || names.size() < limit);) {
    while (!line.empty() && (line.back() == '\r' || line.back() == ' ')) line.pop_back();
    if (!line.empty()) names.push_back(line);
  }
  return names;
}

double seconds_since(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

struct Speed {
  double signal_s = 0, detector_s = 0, chain_s = 0;
};

Speed measure_speed(const std::vector<agg::Signals>& records) {
  Speed speed;
  for (const agg::Signals& r : records) {
    const auto& lead = r.samples[0];
    speed.signal_s += static_cast<double>(lead.size()) / r.header.fs;
    // As `tahvel hrv` and the R-peak agent read a record: WFDB's no-value samples as no signal.
    agg::ChainOptions chain;
    chain.detector.invalid_sample = agg::invalid_sample(r.header.signals[0]);
    agg::DetectorOptions detector = chain.detector;
    detector.fs = r.header.fs;
    detector.gain = r.header.signals[0].gain;
    auto start = Clock::now();
    auto peaks = agg::detect_r_peaks(lead, detector);
    speed.detector_s += seconds_since(start);
    start = Clock::now();
    auto report = agg::hrv_from_samples(lead, r.header.fs, r.header.signals[0].gain, chain);
    speed.chain_s += seconds_since(start);
    if (!report || report->beats.size() != peaks.size()) fail("bench hrv: the chain and the detector disagree");
  }
  return speed;
}

agg::RecordingInfo recording_of(const agg::Signals& r, const std::string& name) {
  agg::RecordingInfo info;
  info.sensor_iri = "http://example.org/home1/ecg";
  info.iri = info.sensor_iri + "/recording/" + name;
  info.fs = r.header.fs;
  info.gain = r.header.signals[0].gain;
  info.baseline = r.header.signals[0].baseline;
  for (const auto& s : r.header.signals) info.leads.push_back(s.description);
  info.source = "mitdb/" + name;
  return info;
}

// Bytes a home node keeps for the record's raw ECG (1-second chunks of every lead, as the ECG
// source agent stores them), scaled to one hour.
double raw_bytes_per_hour(const agg::Signals& r, const agg::RecordingInfo& info) {
  char pattern[] = "/tmp/tahvel-bench-hrv-XXXXXX";
  if (!mkdtemp(pattern)) fail("bench hrv: cannot make a scratch directory");
  const fs::path dir = fs::path(pattern) / "home";
  double per_hour = 0;
  {
    auto node = node::Node::init(dir, node::InitOptions{.iri = "http://example.org/home1"});
    if (!node) fail(node.error().message);
    auto agent = node->agent("ecg");
    if (!agent) fail(agent.error().message);
    if (auto s = agent->store(agg::recording_item(info)); !s) fail(s.error().message);
    const auto before = node->stats()->used_bytes;
    const std::size_t frames = r.samples[0].size(), chunk = static_cast<std::size_t>(r.header.fs);
    for (std::size_t at = 0; at < frames; at += chunk) {
      auto stored = agent->store(agg::ecg_chunk_item(info, static_cast<std::int64_t>(at), r.samples, at,
                                                     std::min(chunk, frames - at)));
      if (!stored) fail(stored.error().message);
    }
    const double hours = static_cast<double>(frames) / r.header.fs / 3600;
    per_hour = static_cast<double>(node->stats()->used_bytes - before) / hours;
  }
  fs::remove_all(pattern);
  return per_hour;
}

// Bytes of the HRV window items (5-minute windows) as N-Triples, scaled to one hour.
double up_bytes_per_hour(const agg::Signals& r, const agg::RecordingInfo& info) {
  auto report = agg::hrv_from_samples(r.samples[0], r.header.fs, r.header.signals[0].gain);
  if (!report) fail(report.error().message);
  std::ostringstream wire;
  {
    node::RecordWriter writer(wire, node::Format::ntriples);
    for (const auto& window : report->windows)
      for (const auto& t : agg::hrv_window_item(info, window, "http://example.org/home1/hrv").triples)
        writer.write(t);
  }
  const double hours = static_cast<double>(r.samples[0].size()) / r.header.fs / 3600;
  return static_cast<double>(wire.str().size()) / hours;
}

struct OperatorView {
  std::size_t patients = 0, windows = 0, trend_updates = 0;
  double view_s = 0, listing_s = 0;  // best of three each
};

// Fills the hospital store `node` with o.board_patients patients' windows, each derived from 60
// RR items as tahvel-hrv writes them, and three trend updates per window as tahvel-trend writes
// them (each with its metric's value); counts them into `v`. As the chain does, each window and
// its updates are asserted at the window's signal time: the recordings began board_windows
// minutes ago, a second apart.
void build_operator_board(node::Node& node, const std::string& hospital, const Options& o, OperatorView& v) {
  auto trend = node.agent("trend");
  if (!trend) fail(trend.error().message);
  const agg::HrvMetric metrics[] = {agg::HrvMetric::sdnn, agg::HrvMetric::rmssd, agg::HrvMetric::mean_hr};
  const std::int64_t began = std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch()).count() -
                             static_cast<std::int64_t>(o.board_windows) * 60'000'000'000;
  for (std::size_t p = 0; p < o.board_patients; ++p) {
    const std::string home = "home" + std::to_string(p + 1);
    auto hrv = node.agent(home + "-hrv");
    if (!hrv) fail(hrv.error().message);
    agg::RecordingInfo info;
    info.iri = hospital + "/" + home + "/ecg/recording/r";
    info.started_at = began + static_cast<std::int64_t>(p) * 1'000'000'000;
    for (std::size_t w = 0; w < o.board_windows; ++w) {
      agg::WindowMetrics window;
      window.start_s = 60.0 * static_cast<double>(w);
      window.end_s = window.start_s + 60;
      window.metrics.sdnn_ms = 40 + static_cast<double>((p + w) % 11);
      window.metrics.rmssd_ms = 30 + static_cast<double>((p * 3 + w) % 7);
      window.metrics.mean_hr_bpm = 60 + static_cast<double>(p % 30);
      window.metrics.nn_count = window.metrics.rr_count = 70;
      std::vector<std::string> from;
      for (std::size_t k = 0; k < 60; ++k) from.push_back(info.iri + "/rr/" + std::to_string(w * 60 + k));
      node::Item window_item = agg::hrv_window_item(info, window, hrv->iri(), from);
      window_item.asserted_at = agg::signal_time_ns(info, window.start_s);
      if (auto s = hrv->store(window_item); !s) fail(s.error().message);
      ++v.windows;
      for (agg::HrvMetric metric : metrics) {
        agg::TrendUpdate u;
        u.recording = info.iri;
        u.metric = metric;
        u.window_start_s = window.start_s;
        u.window_iri = agg::hrv_iri(info.iri, window.start_s);
        u.windows = w + 1;
        u.latest = agg::metric_value(window.metrics, metric);
        node::Item update = agg::trend_item(u, trend->iri());
        update.asserted_at = window_item.asserted_at;
        if (auto s = trend->store(update); !s) fail(s.error().message);
        ++v.trend_updates;
      }
    }
  }
  v.patients = o.board_patients;
}

// `tahvel patients` on a hospital board (build_operator_board); the peer is listing the same
// windows and updates, which the view cannot do without.
OperatorView measure_operator_view(const Options& o) {
  bench::ScratchDir scratch{fs::path{}};
  const std::string hospital = "http://example.org/hospital";
  auto node = node::Node::init(scratch.sub("hospital"), node::InitOptions{.iri = hospital});
  if (!node) fail(node.error().message);
  OperatorView v;
  build_operator_board(*node, hospital, o, v);
  node::Pattern windows, updates;
  windows.p = node::Term::iri("http://www.w3.org/ns/sosa/observedProperty");
  windows.o = agg::tv_term("HeartRateVariability");
  updates.p = node::Term::iri(std::string(node::kRdfType));
  updates.o = agg::tv_term("HrvTrend");
  v.view_s = v.listing_s = 1e30;
  for (int round = 0; round < 3; ++round) {
    auto snapshot = node->snapshot();
    if (!snapshot) fail(snapshot.error().message);
    auto start = Clock::now();
    auto board = agg::patients_on_board(*snapshot, std::nullopt);
    v.view_s = std::min(v.view_s, seconds_since(start));
    if (!board) fail(board.error().message);
    if (board->patients.size() != o.board_patients) fail("bench hrv: the operator's view lost patients");
    for (const agg::PatientView& p : board->patients)
      if (p.windows != o.board_windows || p.trends.size() != 3 || p.latest.window.start_s != 60.0 * static_cast<double>(o.board_windows - 1))
        fail("bench hrv: the operator's view of <" + p.recording + "> lost windows or trends");
    start = Clock::now();
    auto listed_windows = snapshot->list(windows);
    auto listed_updates = snapshot->list(updates);
    v.listing_s = std::min(v.listing_s, seconds_since(start));
    if (!listed_windows || !listed_updates || listed_windows->size() != v.windows || listed_updates->size() != v.trend_updates)
      fail("bench hrv: listing the operator's board did not find what was stored");
  }
  return v;
}

}  // namespace

int bench_hrv_main(const std::vector<std::string>& args) {
  Options options;
  bool quick = false;
  std::optional<std::uint64_t> board_patients, board_windows;  // given on the command line
  for (std::size_t i = 0; i < args.size(); ++i) {
    if (args[i] == "--help" || args[i] == "-h") {
      std::fputs(kUsage, stdout);
      return kExitOk;
    } else if (args[i] == "--json") {
      options.json = true;
    } else if (args[i] == "--quick") {
      quick = true;
    } else if (args[i] == "--records" && i + 1 < args.size()) {
      auto n = parse_u64(args[++i]);
      if (!n || *n == 0) usage_error("bench hrv: --records: expected a positive integer");
      options.records = *n;
    } else if ((args[i] == "--board-patients" || args[i] == "--board-windows") && i + 1 < args.size()) {
      const std::string& flag = args[i];
      auto n = parse_u64(args[++i]);
      if (!n || *n == 0 || *n > 1'000'000) usage_error("bench hrv: " + flag + ": expected an integer 1..1000000");
      (flag == "--board-patients" ? board_patients : board_windows) = *n;
    } else {
      usage_error("bench hrv: unknown argument '" + args[i] + "'\n" + kUsage);
    }
  }
  if (quick) {
    if (options.records == 0) options.records = 3;
    options.board_patients = 10;
    options.board_windows = 20;
  }
  if (board_patients) options.board_patients = *board_patients;
  if (board_windows) options.board_windows = *board_windows;
  const fs::path dir = mitdb_dir();
  const auto names = record_names(dir, options.records);
  std::vector<agg::Signals> records;
  for (const auto& name : names) {
    auto signals = agg::read_signals((dir / name).string());
    if (!signals) fail(signals.error().message);
    records.push_back(std::move(*signals));
  }
  if (records.empty()) fail("bench hrv: no records in " + dir.string());
  const Speed speed = measure_speed(records);
  const auto info = recording_of(records.front(), names.front());
  const double raw = raw_bytes_per_hour(records.front(), info);
  const double up = up_bytes_per_hour(records.front(), info);
  const double detector_x = speed.signal_s / speed.detector_s, chain_x = speed.signal_s / speed.chain_s;
  const double samples_per_s = speed.signal_s * records.front().header.fs / speed.chain_s;
  const OperatorView view = measure_operator_view(options);
  if (options.json) {
    std::printf(
        "{\"records\":%zu,\"signal_hours\":%.4f,\"detector_x_realtime\":%.0f,\"chain_x_realtime\":%.0f,"
        "\"chain_samples_per_s\":%.0f,\"raw_bytes_per_patient_hour\":%.0f,\"up_bytes_per_patient_hour\":%.0f,"
        "\"reduction_ratio\":%.1f,\"target_chain_x_realtime\":20000,\"target_chain_met\":%d,"
        "\"patients_view_patients\":%zu,\"patients_view_windows\":%zu,\"patients_view_trend_updates\":%zu,"
        "\"patients_view_s\":%.4f,\"patients_view_listing_s\":%.4f,\"ratio_patients_view_vs_listing\":%.2f}\n",
        records.size(), speed.signal_s / 3600, detector_x, chain_x, samples_per_s, raw, up, raw / up,
        chain_x >= 20000 ? 1 : 0, view.patients, view.windows, view.trend_updates, view.view_s, view.listing_s,
        view.view_s / view.listing_s);
  } else {
    std::printf("tahvel bench hrv: %zu records, %.2f hours of ECG (first lead), one core\n\n", records.size(),
                speed.signal_s / 3600);
    std::printf("detector            %10.0f x real time\n", detector_x);
    std::printf("whole chain         %10.0f x real time (%.1f M samples/s)   target >= 20000  %s\n", chain_x,
                samples_per_s / 1e6, chain_x >= 20000 ? "met" : "NOT met");
    std::printf("raw ECG at home     %10.0f bytes per patient-hour (record %s, all leads, 1 s chunks)\n", raw,
                names.front().c_str());
    std::printf("HRV items sent up   %10.0f bytes per patient-hour (5-min windows, N-Triples)\n", up);
    std::printf("reduction           %10.1f x\n", raw / up);
    std::printf("operator's view     %10.3f s for %zu patients, %zu windows, %zu trend updates (tahvel patients)\n",
                view.view_s, view.patients, view.windows, view.trend_updates);
    std::printf("  listing them      %10.3f s (%.2f x)\n", view.listing_s, view.view_s / view.listing_s);
  }
  return kExitOk;
}

}  // namespace tahvel::cli
