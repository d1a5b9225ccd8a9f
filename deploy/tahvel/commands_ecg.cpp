// `tahvel ecg`: a recording's raw ECG for a time range, as numbers (CSV, one row per frame, each
// lead in its unit), from this node or any node below it. The samples travel as `tahvel query`
// brings them (the node that holds them answers, P13-P16): the recording's description, then its
// chunks in the range, decoded and written out as they come.
#include <unistd.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <limits>
#include <cstdio>
#include <iostream>
#include <iterator>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "commands.h"
#include "tahvel/aggregation/items.h"

namespace tahvel::cli {
namespace {

namespace agg = tahvel::aggregation;

// `text` as one CSV field (RFC 4180: quoted when it holds a comma, a quote or a line break).
std::string csv_field(const std::string& text) {
  if (text.find_first_of(",\"\r\n") == std::string::npos) return text;
  std::string out = "\"";
  for (char c : text) out += c == '"' ? std::string("\"\"") : std::string(1, c);
  return out + "\"";
}

// Writes each frame of the chunks given to it that falls in [since, until) (its time is the
// recording's start plus its sample over the rate), one row a piece of `out` (a Ctrl-C ends the
// output after a whole row), and keeps count of the frames made and of the samples of the range
// that no chunk held.
class FrameWriter {
 public:
  FrameWriter(const agg::RecordingInfo& info, std::optional<std::int64_t> since, std::optional<std::int64_t> until,
              PieceOutput& out)
      : info_(info), since_(since), until_(until), piece_(out), out_(out.stream()) {}

  void header() {
    out_ << "sample,unix_ns";
    for (std::size_t lead = 0; lead < info_.leads.size(); ++lead)
      out_ << ',' << csv_field(info_.leads[lead].empty() ? "lead " + std::to_string(lead) : info_.leads[lead]);
    out_ << '\n';
    piece_.end_piece(false);
  }

  void write(const agg::EcgChunk& chunk) {
    char value[32];
    for (std::size_t i = 0; i < chunk.frames; ++i) {
      const std::int64_t sample = chunk.start_sample + static_cast<std::int64_t>(i);
      const std::optional<std::int64_t> at = agg::signal_time_ns(info_, static_cast<double>(sample) / info_.fs);
      if (at && ((since_ && *at < *since_) || (until_ && *at >= *until_))) continue;
      // A chunk held twice (a dump loaded back, a store's items sent again on a new stream):
      // each frame is printed once. Its rows came again after the later ones, and the samples
      // between were said to be missing.
      if (!cover(sample)) {
        ++repeated_;
        continue;
      }
      out_ << sample << ',';
      if (at) out_ << *at;
      for (std::size_t l = 0; l < chunk.leads.size(); ++l) {
        // A lead's no-value (WFDB's, tv:leadInvalidSample) is no reading: an empty field, as
        // rdsamp prints "-" (it read as -164 mV).
        const auto c = info_.calibration_of(l);
        if (c.invalid_sample && chunk.leads[l][i] == *c.invalid_sample) {
          out_ << ',';
          continue;
        }
        // The shortest text that reads back as the same number: with 6 significant digits,
        // neighbouring ADC steps of a 24- or 32-bit lead printed alike (12.3457).
        value[0] = ',';
        const double v = (static_cast<double>(chunk.leads[l][i]) - c.baseline) / c.gain + 0.0;  // no "-0"
        out_.write(value, std::to_chars(value + 1, value + sizeof value, v).ptr - value);
      }
      out_ << '\n';
      piece_.end_piece();
      ++frames_;
    }
  }

  // After the last chunk: the samples of the range that no frame written covers. Before the
  // first frame (from the recording's first sample when no --since was given: a ring reclaims
  // the oldest chunks, and minutes of them missing went unsaid), between frames, and, when the
  // recording's end is known (`end_sample`, tv:endSample), after the last. (Without its end,
  // samples after the last chunk may not have been taken yet.) With no frame written, the
  // samples of the range that lie before that end are missing: the range fell wholly inside
  // removed or reclaimed chunks.
  void finish(std::optional<std::int64_t> end_sample) {
    if (covered_.empty()) {
      if (!end_sample) return;
      // Without a start the range does not apply (write() keeps every frame).
      const bool timed = info_.started_at.has_value();
      const std::int64_t from = since_ && timed ? first_at_or_after(*since_) : 0;
      const std::int64_t to = until_ && timed ? std::min(*end_sample, first_at_or_after(*until_)) : *end_sample;
      if (from < to) gaps_.push_back({from, to});
      return;
    }
    if (!since_ || info_.started_at) {
      const std::int64_t from = since_ ? first_at_or_after(*since_) : 0;
      if (from < *first()) gaps_.push_back({from, *first()});
    }
    for (auto run = covered_.begin(); std::next(run) != covered_.end(); ++run) gaps_.push_back({run->second, std::next(run)->first});
    if (end_sample) {
      const std::int64_t to = until_ && info_.started_at ? std::min(*end_sample, first_at_or_after(*until_)) : *end_sample;
      if (*next() < to) gaps_.push_back({*next(), to});
    }
  }

  std::uint64_t frames() const { return frames_; }
  // Frames of chunks held more than once, written once.
  std::uint64_t repeated() const { return repeated_; }
  // The first sample written, and the one after the last.
  std::optional<std::int64_t> first() const {
    return covered_.empty() ? std::nullopt : std::optional<std::int64_t>(covered_.begin()->first);
  }
  std::optional<std::int64_t> next() const {
    return covered_.empty() ? std::nullopt : std::optional<std::int64_t>(covered_.rbegin()->second);
  }
  // [from, to) sample ranges of the range asked that no chunk held (after finish()).
  const std::vector<std::pair<std::int64_t, std::int64_t>>& gaps() const { return gaps_; }

 private:
  // The first sample (0 or later) taken at or after `time`, as write() times samples.
  // A sample whose time an int64 cannot hold comes after any `time`: --until 2^63-1 ("no end")
  // made the time of the samples near it overflow, and this loop spin for ever.
  std::int64_t first_at_or_after(std::int64_t time) const {
    const double started = static_cast<double>(*info_.started_at);
    const double estimate = std::ceil((static_cast<double>(time) - started) * info_.fs / 1e9);
    std::int64_t sample = std::max<std::int64_t>(0, static_cast<std::int64_t>(estimate) - 1);
    const double last_ns = static_cast<double>(std::numeric_limits<std::int64_t>::max()) - started;
    for (;; ++sample) {
      const double seconds = static_cast<double>(sample) / info_.fs;
      if (seconds * 1e9 >= last_ns || *agg::signal_time_ns(info_, seconds) >= time) return sample;
    }
  }

  // Adds `sample` to the samples written; false when it is there already.
  bool cover(std::int64_t sample) {
    auto after = covered_.upper_bound(sample);  // the first run starting after it
    if (after != covered_.begin()) {
      auto run = std::prev(after);
      if (sample < run->second) return false;
      if (sample == run->second) {
        run->second = sample + 1;
        if (after != covered_.end() && after->first == run->second) {
          run->second = after->second;
          covered_.erase(after);
        }
        return true;
      }
    }
    if (after != covered_.end() && after->first == sample + 1) {
      const std::int64_t end = after->second;
      covered_.erase(after);
      covered_.emplace(sample, end);
    } else {
      covered_.emplace(sample, sample + 1);
    }
    return true;
  }

  const agg::RecordingInfo& info_;
  std::optional<std::int64_t> since_, until_;
  PieceOutput& piece_;
  std::ostream& out_;
  std::map<std::int64_t, std::int64_t> covered_;  // samples written, as runs [from, to)
  std::uint64_t frames_ = 0, repeated_ = 0;
  std::vector<std::pair<std::int64_t, std::int64_t>> gaps_;
};

}  // namespace

const Command kEcgCommand{
    "ecg",
    "DIR --recording IRI [--at NODE-IRI] [--since T] [--until T] [--timeout S]",
    "Print a recording's raw ECG as CSV: one row per frame, each lead in its unit.",
    "Asks the node at --at (default: DIR's own node; any node below it, as 'tahvel query' does)\n"
    "for the recording's description and its chunks of signal in [--since, --until), decodes\n"
    "them and prints, per frame: its sample number in the recording, its time (ns since the\n"
    "epoch, from the recording's tv:startedAt; empty when the recording does not say it) and\n"
    "each lead's value, (ADC - baseline) / gain, in its unit (tv:leadCalibration per lead; else\n"
    "the recording's gain, baseline and unit). Samples no chunk\n"
    "holds inside the range (a ring reclaimed them) are named on standard error. Times as\n"
    "'tahvel query' takes them. 'tahvel patients' prints the command for each patient's latest\n"
    "HRV window. Exit status as 'tahvel query' (3 timeout, 4 unknown node, 5 unreachable), and 1\n"
    "when the node holds no such recording.",
    {{"--recording", "", "IRI", "the recording (its IRI: <sensor agent>/recording/<name>)"},
     {"--at", "", "NODE-IRI", "the node that holds the samples (default: DIR's node)"},
     {"--since", "", "T", "frames taken at or after T"},
     {"--until", "", "T", "frames taken before T"},
     {"--timeout", "", "S", "give up after S seconds (default 30; a fraction allowed: 2.5)"}},
    1, 1};

int run_ecg(const Args& args) {
  node::Node node = open_node(args.positional(0));
  uri::PrefixMap prefixes = prefixes_with_flags(node.prefixes(), args);
  const std::string recording = parse_iri(args.required("--recording"), prefixes, "--recording");
  federation::RemoteQuery ask;
  ask.target = args.has("--at") ? parse_node_iri(*args.get("--at"), prefixes, "--at", node.iri()) : node.iri();
  std::optional<std::int64_t> since, until;
  if (auto text = args.get("--since")) since = time_flag("--since", *text);
  if (auto text = args.get("--until")) until = time_flag("--until", *text);
  if (since && until) check_time_range(args, *since, *until);
  const std::chrono::milliseconds timeout = seconds_flag(args, "ecg", std::chrono::seconds(30), std::chrono::hours(24));
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  // The two queries (the description, then the chunks) share the one --timeout: the second
  // gets what the first left, and a timeout names the whole, not what was left of it, and counts
  // the frames written out, not the query's records (a chunk of hundreds of frames is a few).
  PieceOutput out;
  auto ask_in_time = [&](const std::function<void(const node::Record&)>& each, const std::function<void()>& answered) {
    const auto left = std::max(std::chrono::milliseconds(1),
                               std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now()));
    try {
      ask_below("ecg", node, ask, left, out, each, answered, "frame");
    } catch (Failure& f) {
      if (f.status == kExitTimeout && !out.timed_out()) {  // a reader that took no more says so itself
        const std::uint64_t n = out.written();
        f.message = "ecg: timeout: no complete answer from <" + ask.target + "> within --timeout " +
                    (args.get("--timeout") ? *args.get("--timeout") + " s" : std::string("30 s (the default)")) +
                    " (the description and the chunks share it); " + std::to_string(n) + " frame" + (n == 1 ? "" : "s") +
                    " written out";
      }
      throw;
    }
  };

  // The description: rate, gain, baseline, leads, start (docs/vocabulary.md).
  ask.pattern = {.s = node::Term::iri(recording)};
  std::vector<node::Record> description;
  ask_in_time([&](const node::Record& r) { description.push_back(r); }, {});
  const std::string where = "<" + ask.target + ">";
  if (description.empty()) {
    // Which recordings the node does hold, for the operator who mistyped one or asked the wrong
    // node (the raw ECG stays where HRV is computed, usually a home).
    ask.pattern = {.p = node::Term::iri(std::string(node::kRdfType)), .o = agg::tv_term("EcgRecording")};
    constexpr std::size_t kNamed = 5;
    ask.limit = kNamed + 1;
    std::vector<std::string> held;
    bool listed = true;
    try {  // a hint only: the answer stays "no such recording" (exit 1) if it cannot be had
      ask_in_time([&](const node::Record& r) { held.push_back(r.triple.s.value); }, {});
    } catch (const Failure&) {
      listed = false;
    }
    std::string hint;
    if (!listed) {
    } else if (held.empty()) {
      hint = "; it holds no recording at all: the raw ECG stays on the node that computes its HRV (`tahvel patients` "
             "at the hospital prints it for each recording, as --at)";
    } else {
      hint = "; it holds ";
      for (std::size_t i = 0; i < held.size() && i < kNamed; ++i) hint += (i ? ", <" : "<") + held[i] + ">";
      if (held.size() > kNamed)
        hint += " and more (tahvel query " + args.positional(0) + " --at " + ask.target +
                " -p rdf:type -o tv:EcgRecording lists them)";
    }
    fail("ecg: " + where + " holds no recording <" + recording + "> (nothing has it as subject)" + hint);
  }
  auto info = agg::read_recording(description, recording);
  if (!info) {
    // An IRI below a recording's (an HRV window's, <rec>/hrv/4440, pasted from `patients`): the
    // recording it belongs to is named.
    std::string belongs;
    if (const auto at = recording.find("/recording/"); at != std::string::npos)
      if (const auto end = recording.find('/', at + std::string_view("/recording/").size()); end != std::string::npos)
        belongs = " (<" + recording + "> lies below the recording <" + recording.substr(0, end) + ">: give that to --recording)";
    fail("ecg: the description of <" + recording + "> at " + where + ": " + info.error().message + belongs);
  }
  if (info->leads.empty()) fail("ecg: the description of <" + recording + "> at " + where + " names no tv:lead");

  // Its chunks (<recording>/chunk/<first sample>) that held in the range, in the order stored:
  // a chunk's records come together, and a chunk is written out when the next one begins.
  ask.pattern = {.under = recording + "/chunk", .since = since, .until = until};  // as agg::chunk_iri names them
  FrameWriter frames(*info, since, until, out);
  frames.header();
  std::vector<node::Record> chunk;
  std::uint64_t unreadable = 0;
  std::string first_error;
  auto flush = [&] {
    if (chunk.empty()) return;
    auto read = agg::read_chunk(chunk);
    std::string why = read ? "" : read.error().message;
    if (read && read->leads.size() != info->leads.size())
      why = "holds " + std::to_string(read->leads.size()) + " lead(s), the recording names " + std::to_string(info->leads.size());
    if (why.empty()) frames.write(*read);
    // read_chunk's errors name the chunk already ("<…/chunk/0>: tv:samples is not base64").
    else if (unreadable++ == 0)
      first_error = why.starts_with("<" + chunk.front().triple.s.value + ">") ? why : "<" + chunk.front().triple.s.value + ">: " + why;
    chunk.clear();
  };
  ask_in_time([&](const node::Record& r) {
    if (!chunk.empty() && chunk.front().triple.s != r.triple.s) flush();
    chunk.push_back(r);
  }, [&] {
    flush();
    out.finish();
  });
  out.check();
  std::optional<std::int64_t> end_sample;
  for (const node::Record& r : description)
    if (r.triple.p.value == agg::tv_term("endSample").value) {
      std::int64_t n = 0;
      const std::string& text = r.triple.o.value;
      if (std::from_chars(text.data(), text.data() + text.size(), n).ec == std::errc()) end_sample = n;
    }
  frames.finish(end_sample);

  for (const auto& [from, to] : frames.gaps())
    std::cerr << "tahvel: ecg: samples " << from << " to " << to - 1 << " (" << seconds_text((to - from) / info->fs)
              << ") are not at " << where << ": no readable chunk holds them (removed, or reclaimed by a ring)\n";
  if (unreadable > 0)
    std::cerr << "tahvel: ecg: " << unreadable << " chunk(s) could not be read, left out; the first: " << first_error << "\n";
  if (frames.repeated() > 0)
    std::cerr << "tahvel: ecg: " << frames.repeated() << " frame(s) of the range are held more than once at " << where
              << " (a chunk stored twice); each is printed once\n";
  if (frames.frames() == 0) {
    std::cerr << "tahvel: ecg: " << where << " holds no sample of <" << recording << ">"
              << (since || until ? " in that range" : "") << "\n";
  } else if (isatty(STDERR_FILENO)) {  // what came, for the operator at a terminal
    std::cerr << "tahvel: ecg: " << frames.frames() << " frame(s) of " << info->leads.size() << " lead(s) at "
              << info->fs << " Hz from " << where << ", samples " << *frames.first() << " to " << *frames.next() - 1
              << "\n";
  }
  return kExitOk;
}

}  // namespace tahvel::cli
