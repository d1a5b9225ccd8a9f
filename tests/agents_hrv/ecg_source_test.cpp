// tahvel-ecg-source started again on a board that holds an earlier run: a source killed in the
// middle goes on after its last chunk, so every second of signal is on the board once and the
// same as an uninterrupted run wrote it; a recording that was ended is not written again.
#include <gtest/gtest.h>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <string>
#include <thread>
#include <vector>

#include "tahvel/aggregation/items.h"
#include "tahvel/node/node.h"
#include "agent_process.h"
#include "temp_dir.h"
#include "wfdb_record.h"

namespace {

namespace agg = tahvel::aggregation;
namespace fs = std::filesystem;
namespace tn = tahvel::node;
using namespace std::chrono_literals;

const std::string kNodeIri = "http://example.org/home1";
// A take of it is named <this>-<UTC start>: kBase-20261130T174900Z.
const std::string kBase = kNodeIri + "/ecg/recording/synthetic-5";
// `iri` is kBase-YYYYMMDDTHHMMSSZ.
bool is_take(const std::string& iri) {
  const std::string stamp = iri.starts_with(kBase + "-") ? iri.substr(kBase.size() + 1) : "";
  return stamp.size() == 16 && stamp[8] == 'T' && stamp[15] == 'Z' &&
         std::all_of(stamp.begin(), stamp.begin() + 8, ::isdigit) && std::all_of(stamp.begin() + 9, stamp.begin() + 15, ::isdigit);
}
constexpr std::int64_t kFrames = 60 * 360;  // --seconds 60 at the generator's 360 Hz

// The source on `dir`: 60 s of ECGSYN seed 5, paced at `speed` times real time (0: at once).
std::vector<std::string> source_argv(const std::string& dir, const std::string& speed) {
  return {std::string(TAHVEL_BIN_DIR) + "/tahvel-ecg-source", dir, "--synthetic", "--seed", "5",
          "--seconds", "60", "--speed", speed};
}

int run_source(const std::string& dir) {
  tahvel::test_support::AgentProcess source(source_argv(dir, "0"));
  return source.wait(std::chrono::seconds(60));
}

class EcgSourceTest : public ::testing::Test {
 protected:
  // What a file holds (a program's log, a header), "" when it cannot be read.
  static std::string text_of(const fs::path& file) {
    std::ifstream in(file);
    return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  }

  // A format-16 record of `samples` frames (write_format16_record) whose header's record line is
  // `record_line` instead ("NAME 1 RATE COUNT": another rate, another count): its path.
  std::string record_with_record_line(const std::string& name, std::size_t samples, const std::string& record_line) {
    const std::string record = tahvel::test_support::write_format16_record(tmp_.path(), name, std::vector<std::int32_t>(samples, 1024));
    std::string header = text_of(record + ".hea");
    header.replace(0, header.find('\n'), record_line);
    std::ofstream(record + ".hea") << header;
    return record;
  }

  // The source replaying `record` into `dir` at full speed, its stderr in tmp_/<log_name>.log:
  // its exit status and what it said.
  struct Replay {
    int status = -1;
    std::string said;
  };
  Replay replay_logged(const std::string& dir, const std::string& record, const std::string& log_name) {
    const fs::path log = tmp_ / (log_name + ".log");
    tahvel::test_support::AgentProcess source(
        {std::string(TAHVEL_BIN_DIR) + "/tahvel-ecg-source", dir, "--record", record, "--speed", "0"}, log.string());
    const int status = source.wait(std::chrono::seconds(60));
    return {status, text_of(log)};
  }

  std::string new_node(const std::string& name) {
    const std::string dir = (tmp_ / name).string();
    auto node = tn::Node::init(dir, tn::InitOptions{.iri = kNodeIri});
    EXPECT_TRUE(node) << node.error().message;
    return dir;
  }

  // Each chunk of `recording` on the board: start sample -> the samples literal, and how many
  // chunk items name that start, and the time its samples record says it covers.
  struct Chunks {
    std::map<std::int64_t, std::string> samples;
    std::map<std::int64_t, int> copies;
    std::map<std::int64_t, std::pair<std::int64_t, std::int64_t>> time;  // asserted-at, span
  };
  static Chunks chunks(const std::string& dir, const std::string& recording) {
    Chunks out;
    auto node = tn::Node::open(dir);
    EXPECT_TRUE(node) << node.error().message;
    auto snapshot = node->snapshot();
    EXPECT_TRUE(snapshot);
    tn::Pattern of;
    of.p = agg::tv_term("recording");
    of.o = tn::Term::iri(recording);
    auto named = snapshot->list(of);
    EXPECT_TRUE(named);
    for (const auto& r : *named) {
      auto fields = snapshot->list(tn::Pattern{.s = r.triple.s});
      EXPECT_TRUE(fields);
      std::int64_t start = -1;
      std::string samples;
      for (const auto& f : *fields) {
        if (f.triple.p == agg::tv_term("startSample")) start = std::stoll(f.triple.o.value);
        if (f.triple.p == agg::tv_term("samples")) samples = f.triple.o.value;
      }
      out.time[start] = {r.meta.asserted_at, r.meta.span};
      out.samples[start] = samples;
      ++out.copies[start];
    }
    return out;
  }

  // The recordings on the board, in the order they were written.
  static std::vector<std::string> recordings(const std::string& dir) {
    auto node = tn::Node::open(dir);
    EXPECT_TRUE(node) << node.error().message;
    auto records = node->snapshot()->list(
        tn::Pattern{.p = tn::Term::iri("http://www.w3.org/1999/02/22-rdf-syntax-ns#type"), .o = agg::tv_term("EcgRecording")});
    EXPECT_TRUE(records);
    std::vector<std::string> out;
    for (const auto& r : *records) out.push_back(r.triple.s.value);
    return out;
  }
  static std::string the_recording(const std::string& dir) {
    const auto all = recordings(dir);
    EXPECT_EQ(all.size(), 1u);
    return all.empty() ? std::string() : all.front();
  }

  static std::vector<std::string> objects(const std::string& dir, const std::string& s, const std::string& p) {
    auto node = tn::Node::open(dir);
    auto snapshot = node->snapshot();
    auto records = snapshot->list(tn::Pattern{.s = tn::Term::iri(s), .p = tn::Term::iri(p)});
    std::vector<std::string> out;
    for (const auto& r : *records) out.push_back(r.triple.o.value);
    return out;
  }

  static void expect_each_chunk_ends_where_the_next_begins(const Chunks& chunks) {
    for (auto it = chunks.time.begin(); std::next(it) != chunks.time.end(); ++it) {
      const auto [asserted_at, span] = it->second;
      EXPECT_GT(span, 0) << "chunk at " << it->first;
      EXPECT_EQ(asserted_at + span, std::next(it)->second.first) << "chunk at " << it->first;
    }
  }

  // A record of two signals in one format-16 file, `frames` frames of the values `first` and
  // `second`, under `header_lines` (the record line and both signal lines); its path.
  fs::path two_signal_record(const std::string& name, const std::string& header_lines, int frames, int first, int second) {
    const fs::path record = tmp_ / name;
    std::ofstream(record.string() + ".hea") << header_lines;
    std::ofstream dat(record.string() + ".dat", std::ios::binary);
    for (int f = 0; f < frames; ++f)
      for (const int v : {first, second}) dat.put(static_cast<char>(v & 0xff)).put(static_cast<char>(v >> 8 & 0xff));
    return record;
  }

  // Runs the source on `dir` at 20 times real time (3 s of wall time for the 60 s), kills it
  // with SIGKILL once it has written 10 chunks; `before`: the chunks it wrote, 10 or more and
  // fewer than the signal's 60 (the source was killed midway, or the test fails here).
  void kill_the_source_after_ten_chunks(const std::string& dir, std::size_t& before) {
    tahvel::test_support::AgentProcess source(source_argv(dir, "20"));
    const auto deadline = std::chrono::steady_clock::now() + 20s;
    auto written = [&] { return recordings(dir).empty() ? 0 : chunks(dir, recordings(dir).front()).samples.size(); };
    while (written() < 10 && std::chrono::steady_clock::now() < deadline) std::this_thread::sleep_for(20ms);
    source.crash();
    before = written();
    ASSERT_GE(before, 10u);
    ASSERT_LT(before, 60u) << "the source ended before it was killed";
  }

  // What the one recording on `dir` says of itself.
  static agg::RecordingInfo recording_info(const std::string& dir) {
    const std::string rec = the_recording(dir);
    auto node = tn::Node::open(dir);
    auto about = node->snapshot()->list(tn::Pattern{.s = tn::Term::iri(rec)});
    EXPECT_TRUE(about);
    auto info = agg::read_recording(*about, rec);
    EXPECT_TRUE(info) << info.error().message;
    return info ? *info : agg::RecordingInfo{};
  }

  tahvel::test_support::TempDir tmp_{"tahvel-ecg-source"};
};

// A record whose leads are calibrated apart (blood pressure at 10 per mmHg beside the ECG at 200
// per mV from 1024): the recording said only the ECG lead's gain, and every lead was read by it.
TEST_F(EcgSourceTest, EachLeadOfARecordKeepsItsOwnCalibration) {
  const std::string dir = new_node("calibrated");
  const fs::path record = two_signal_record("mix", "mix 2 360 720\nmix.dat 16 10(0)/mmHg 16 0 0 0 0 ABP\n"
                                                   "mix.dat 16 200(1024)/mV 16 0 1024 0 0 MLII\n", 720, 900, 1024 + 100);
  tahvel::test_support::AgentProcess source({std::string(TAHVEL_BIN_DIR) + "/tahvel-ecg-source", dir, "--record", record.string(), "--speed", "0"});
  ASSERT_EQ(source.wait(std::chrono::seconds(60)), 0);
  const agg::RecordingInfo info = recording_info(dir);
  ASSERT_EQ(info.leads, (std::vector<std::string>{"MLII", "ABP"}));  // the ECG lead first
  ASSERT_EQ(info.calibration.size(), 2u);
  EXPECT_EQ(info.calibration[0].gain, 200);
  EXPECT_EQ(info.calibration[0].baseline, 1024);
  EXPECT_EQ(info.calibration[0].unit, "mV");
  EXPECT_EQ(info.calibration[1].gain, 10);
  EXPECT_EQ(info.calibration[1].baseline, 0);
  EXPECT_EQ(info.calibration[1].unit, "mmHg");
  // The ECG lead's no-value (format 16), for the R-peak agent to read as no signal, and each
  // lead's own, for `tahvel ecg` to print as no value.
  EXPECT_EQ(info.invalid_sample, -32768);
  EXPECT_EQ(info.calibration[0].invalid_sample, -32768);
  EXPECT_EQ(info.calibration[1].invalid_sample, -32768);
}

// A 24-bit recorder's samples (here 100,000 per mV, values beyond 16 bits) reach the board
// whole, in chunks of 4-byte samples that say so: 16-bit chunks would wrap them, and the
// R-peak agent and an operator's query would read noise.
TEST_F(EcgSourceTest, SamplesOfA24BitRecordReachTheBoardWholeInFourByteChunks) {
  const std::string dir = new_node("wide");
  const fs::path record = tmp_ / "wide";
  std::ofstream(record.string() + ".hea") << "wide 1 250 750\nwide.dat 24 100000(0)/mV 24 0 0 0 0 ECG\n";
  std::vector<std::int32_t> values;
  {
    std::ofstream dat(record.string() + ".dat", std::ios::binary);
    for (int k = 0; k < 750; ++k) {
      values.push_back((k % 50 - 25) * 4001);
      for (int b = 0; b < 3; ++b) dat.put(static_cast<char>(static_cast<std::uint32_t>(values.back()) >> (8 * b) & 0xff));
    }
  }
  const auto [status, said] = replay_logged(dir, record.string(), "wide");
  ASSERT_EQ(status, 0) << said;
  const std::string rec = the_recording(dir);
  EXPECT_EQ(recording_info(dir).sample_bytes, 4);
  auto node = tn::Node::open(dir);
  ASSERT_TRUE(node) << node.error().message;
  auto snapshot = node->snapshot();
  ASSERT_TRUE(snapshot);
  auto named = snapshot->list(tn::Pattern{.p = agg::tv_term("recording"), .o = tn::Term::iri(rec)});
  ASSERT_TRUE(named);
  std::vector<std::int32_t> stored(values.size());
  std::size_t frames = 0;
  for (const auto& r : *named) {
    auto fields = snapshot->list(tn::Pattern{.s = r.triple.s});
    ASSERT_TRUE(fields);
    auto chunk = agg::read_chunk(*fields);
    ASSERT_TRUE(chunk) << chunk.error().message;
    ASSERT_EQ(chunk->leads.size(), 1u);
    ASSERT_LE(chunk->start_sample + static_cast<std::int64_t>(chunk->frames), 750);
    std::copy(chunk->leads[0].begin(), chunk->leads[0].end(), stored.begin() + chunk->start_sample);
    frames += chunk->frames;
  }
  EXPECT_EQ(frames, values.size());
  EXPECT_EQ(stored, values);
}

// Runs of WFDB's no-value in the ECG lead: said at the first, where it is, and counted at the
// record's end, as `tahvel hrv` counts them. "from sample N on" alone read as a lead lost for
// the rest of the record, when two short runs were.
TEST_F(EcgSourceTest, NoValueSamplesAreSaidAtTheFirstAndCountedAtTheEnd) {
  const std::string dir = new_node("novalue");
  std::vector<std::int32_t> samples(3600, 1024);
  std::fill(samples.begin() + 720, samples.begin() + 730, -32768);    // 10 at 2 s
  std::fill(samples.begin() + 1800, samples.begin() + 1805, -32768);  // 5 at 5 s
  const std::string record = tahvel::test_support::write_format16_record(tmp_.path(), "novalue", samples);
  const auto [status, said] = replay_logged(dir, record, "novalue");
  ASSERT_EQ(status, 0) << said;
  EXPECT_NE(said.find("signal 0 (ECG) holds WFDB's no-value -32768, the first at sample 720 (2.000 s)"), std::string::npos)
      << said;
  EXPECT_NE(said.find("15 sample(s) of signal 0 (ECG) held WFDB's no-value -32768, the first at sample 720 (2.000 s)"),
            std::string::npos)
      << said;
  EXPECT_EQ(said.find(" on:"), std::string::npos) << said;
}

// A record at a rate the R-peak detector refuses (20 Hz: its QRS band needs more than 30) was
// replayed without a word, and no beat ever came of it: the R-peak agent said why only in its
// own log. The source replays it (its ECG can be queried) and says so.
TEST_F(EcgSourceTest, ARecordAtARateTheDetectorRefusesIsReplayedWithAWarningThatNoBeatWillComeOfIt) {
  const std::string dir = new_node("lowrate");
  const std::string record = record_with_record_line("slow", 200, "slow 1 20 200");
  const auto [status, said] = replay_logged(dir, record, "lowrate");
  ASSERT_EQ(status, 0) << said;
  EXPECT_NE(said.find("tahvel-ecg-source: warning: " + record + ".hea: the R-peak agent will find no beat in this record: rpeak: a "
                      "sampling rate of 20 Hz is too low for R-peak detection"),
            std::string::npos)
      << said;
  EXPECT_EQ(recordings(dir).size(), 1u);
  // At 360 Hz, nothing of the kind.
  const std::string usual = tahvel::test_support::write_format16_record(tmp_.path(), "usual", std::vector<std::int32_t>(720, 1024));
  const Replay plain = replay_logged(dir, usual, "usual");
  ASSERT_EQ(plain.status, 0) << plain.said;
  EXPECT_EQ(plain.said.find("R-peak agent will find no beat"), std::string::npos) << plain.said;
}

// A header whose sample count is short of its file: the source replayed that many samples and
// said only "wrote N frames" (a researcher's probe of session 88), where `tahvel hrv` says the
// rest is not read. It says so too.
TEST_F(EcgSourceTest, AHeaderThatCountsFewerSamplesThanItsFileHoldsIsSaidAsTheRestNotRead) {
  const std::string dir = new_node("short");
  const std::string record = record_with_record_line("short", 720, "short 1 360 360");
  const auto [status, said] = replay_logged(dir, record, "short");
  ASSERT_EQ(status, 0) << said;
  EXPECT_NE(said.find("tahvel-ecg-source: warning: " + record + ".dat holds 720 samples per signal, the header " + record +
                      ".hea says 360: the last 360 are not read"),
            std::string::npos)
      << said;
}

// A record whose ECG is not the lead the source would choose (an unnamed signal after a named
// respiration signal): `tahvel hrv --signal 1` read it, but the streaming chain could not.
TEST_F(EcgSourceTest, SignalNamesTheRecordsEcgLeadWhenItIsNotTheOneChosen) {
  const std::string dir = new_node("chosen");
  const fs::path record = two_signal_record("resp", "resp 2 360 720\nresp.dat 16 100(0)/mV 16 0 0 0 0 resp\n"
                                                    "resp.dat 16 200(0)/mV 16 0 0 0 0\n", 720, 5, 7);
  const std::string bin = std::string(TAHVEL_BIN_DIR) + "/tahvel-ecg-source";
  tahvel::test_support::AgentProcess beyond({bin, dir, "--record", record.string(), "--signal", "2", "--speed", "0"});
  EXPECT_EQ(beyond.wait(std::chrono::seconds(60)), 1);
  EXPECT_TRUE(recordings(dir).empty());
  tahvel::test_support::AgentProcess source({bin, dir, "--record", record.string(), "--signal", "1", "--speed", "0"});
  ASSERT_EQ(source.wait(std::chrono::seconds(60)), 0);
  const agg::RecordingInfo info = recording_info(dir);
  ASSERT_EQ(info.leads, (std::vector<std::string>{"", "resp"}));  // signal 1 first: the R-peak agent reads it
  EXPECT_EQ(info.gain, 200);
}

TEST_F(EcgSourceTest, ARestartAfterAKillGoesOnAfterTheLastChunkAndWritesEachSecondOnce) {
  const std::string whole = new_node("whole");
  ASSERT_EQ(run_source(whole), 0);
  const Chunks reference = chunks(whole, the_recording(whole));
  ASSERT_EQ(reference.samples.size(), 60u);

  const std::string crashed = new_node("crashed");
  std::size_t before = 0;
  ASSERT_NO_FATAL_FAILURE(kill_the_source_after_ten_chunks(crashed, before));
  const std::string recording = the_recording(crashed);
  EXPECT_TRUE(is_take(recording)) << recording;

  ASSERT_EQ(run_source(crashed), 0);
  EXPECT_EQ(recordings(crashed), std::vector<std::string>{recording}) << "the take the kill left goes on";
  const Chunks after = chunks(crashed, recording);
  for (const auto& [start, n] : after.copies) EXPECT_EQ(n, 1) << "chunk at " << start;
  EXPECT_EQ(after.samples, reference.samples);
  EXPECT_EQ(objects(crashed, recording, std::string(agg::kTv) + "endSample"),
            std::vector<std::string>{std::to_string(kFrames)});
  EXPECT_EQ(objects(crashed, recording, std::string(agg::kTv) + "samplingRate").size(), 1u)
      << "one recording item";
  // The run after the kill goes on at the signal time where the first left off.
  expect_each_chunk_ends_where_the_next_begins(after);
}

// A sensor's store restored from a backup holds a take left unended at the copy, which the
// store it was copied from went on with (and ended, at a `down`): its home holds those chunks and
// that end. Going on from the copy's last chunk gave the home a take that went on after its end
// (its chain reset, HRV windows shifted and overlapping; an exploratory run of session 81). The
// source records anew instead, and leaves the copied take as it is.
TEST_F(EcgSourceTest, ATakeLeftUnendedInAStoreRestoredFromABackupIsNotContinued) {
  const std::string dir = new_node("sensor");
  std::size_t before = 0;
  ASSERT_NO_FATAL_FAILURE(kill_the_source_after_ten_chunks(dir, before));
  const std::string take = the_recording(dir);
  const fs::path backup = tmp_ / "sensor-backup";
  ASSERT_TRUE(tn::Node::open(dir)->back_up(backup));
  ASSERT_EQ(run_source(dir), 0);  // the take goes on in the store backed up, and ends there
  ASSERT_EQ(recordings(dir), std::vector<std::string>{take});
  ASSERT_EQ(chunks(dir, take).samples.size(), 60u);
  // A take is named to the second: the new one is not named as the first.
  const auto second = std::chrono::floor<std::chrono::seconds>(std::chrono::system_clock::now());
  std::this_thread::sleep_until(second + 1100ms);
  fs::remove_all(dir);
  fs::rename(backup, dir);
  ASSERT_EQ(run_source(dir), 0);
  const std::vector<std::string> takes = recordings(dir);
  ASSERT_EQ(takes.size(), 2u) << "the copied take was gone on with";
  const std::string fresh = takes[0] == take ? takes[1] : takes[0];
  EXPECT_EQ(chunks(dir, take).samples.size(), before) << "the copied take is left as the copy holds it";
  EXPECT_TRUE(objects(dir, take, std::string(agg::kTv) + "endSample").empty()) << "its end is the other store's to say";
  EXPECT_EQ(chunks(dir, fresh).samples.size(), 60u);
}

// A source killed before its first chunk leaves the recording item alone. The next run went on
// under the take's name but stamped its chunks from its own start, seconds after the take's
// tv:startedAt: `tahvel ecg` found nothing in a range of the take, and an HRV window's samples
// were "not at the node". It goes on on the take's axis, as after a chunk.
TEST_F(EcgSourceTest, ATakeKilledBeforeItsFirstChunkGoesOnOnItsOwnTimeAxis) {
  const std::string whole = new_node("whole");
  ASSERT_EQ(run_source(whole), 0);
  agg::RecordingInfo info = recording_info(whole);
  ASSERT_TRUE(info.started_at);
  const std::int64_t started_at = *info.started_at - 5'000'000'000;  // killed five seconds ago
  info.started_at = started_at;

  const std::string dir = new_node("early");
  {
    auto node = tn::Node::open(dir);
    ASSERT_TRUE(node);
    auto source = node->agent("ecg");
    ASSERT_TRUE(source);
    ASSERT_TRUE(source->store(agg::recording_item(info)));
  }
  ASSERT_EQ(run_source(dir), 0);
  EXPECT_EQ(recordings(dir), std::vector<std::string>{info.iri}) << "the take goes on";
  const Chunks written = chunks(dir, info.iri);
  ASSERT_EQ(written.time.size(), 60u);
  EXPECT_EQ(written.time.at(0).first, started_at) << "chunk 0 is asserted at the take's tv:startedAt";
  expect_each_chunk_ends_where_the_next_begins(written);
}

// Each chunk is asserted at its first frame and spans to the next chunk's first frame, to the
// ns: a time range from inside a second gets that second's chunk, and one from a chunk's start
// not the chunk before.
TEST_F(EcgSourceTest, EachChunkSpansItsSecondSoATimeRangeFromInsideItGetsIt) {
  const std::string dir = new_node("home1");
  ASSERT_EQ(run_source(dir), 0);
  const Chunks written = chunks(dir, the_recording(dir));
  ASSERT_EQ(written.time.size(), 60u);
  expect_each_chunk_ends_where_the_next_begins(written);
  const auto [tenth, span] = written.time.at(10 * 360);
  EXPECT_NEAR(static_cast<double>(span), 1e9, 1.0);
  auto node = tn::Node::open(dir);
  ASSERT_TRUE(node);
  auto from_inside = node->snapshot()->list(tn::Pattern{.p = agg::tv_term("startSample"),
                                                        .since = tenth + span / 2,
                                                        .until = written.time.at(12 * 360).first});
  ASSERT_TRUE(from_inside);
  std::vector<std::string> starts;
  for (const auto& r : *from_inside) starts.push_back(r.triple.o.value);
  EXPECT_EQ(starts, (std::vector<std::string>{"3600", "3960"}));
}

TEST_F(EcgSourceTest, AReplayStoppedBySignalIsLeftOpenAndTheNextRunGoesOnWhereItStopped) {
  // Stopped by its supervisor (a `down` for maintenance) or an operator's kill, a replay of
  // known length was ended, and the next run replayed it from its start as a second take: the
  // hospital showed the patient twice (a reliability engineer's probe, session 89). It is left
  // open, as a kill leaves it, and the next run goes on from there.
  const std::string dir = new_node("home1");
  const std::string log = dir + ".log";
  auto stopped_after = [&](std::vector<std::string> argv, std::size_t chunks_at_least) {
    const std::string at = argv[1], take_before = recordings(at).empty() ? "" : recordings(at).back();
    tahvel::test_support::AgentProcess source(std::move(argv), log);
    const auto deadline = std::chrono::steady_clock::now() + 20s;
    while ((recordings(at).empty() || recordings(at).back() == take_before ||
            chunks(at, recordings(at).back()).samples.size() < chunks_at_least) &&
           std::chrono::steady_clock::now() < deadline)
      std::this_thread::sleep_for(20ms);
    return source.stop();
  };
  ASSERT_EQ(stopped_after(source_argv(dir, "10"), 5), 0);  // 6 s of wall time for the 60 s
  const std::vector<std::string> first = recordings(dir);
  ASSERT_EQ(first.size(), 1u);
  const std::size_t before = chunks(dir, first[0]).samples.size();
  ASSERT_GE(before, 5u);
  ASSERT_LT(before, 60u) << "the source ended before it was stopped";
  EXPECT_TRUE(objects(dir, first[0], std::string(agg::kTv) + "endSample").empty()) << "left open";
  ASSERT_EQ(run_source(dir), 0);
  EXPECT_EQ(recordings(dir), first) << "the stopped take goes on";
  const Chunks whole = chunks(dir, first[0]);
  ASSERT_EQ(whole.samples.size(), 60u);
  for (const auto& [start, n] : whole.copies) EXPECT_EQ(n, 1) << "chunk at " << start;
  EXPECT_EQ(objects(dir, first[0], std::string(agg::kTv) + "endSample"), std::vector<std::string>{std::to_string(kFrames)});
  expect_each_chunk_ends_where_the_next_begins(whole);
  EXPECT_NE(text_of(log).find("stopped by signal at frame "), std::string::npos) << text_of(log);

  // A live source (no length to go on to) ends its take when stopped; the next run records anew.
  const std::string live = new_node("live");
  const std::vector<std::string> live_argv = {std::string(TAHVEL_BIN_DIR) + "/tahvel-ecg-source", live, "--synthetic", "--seed", "5",
                                              "--speed", "10"};
  ASSERT_EQ(stopped_after(live_argv, 3), 0);
  const std::vector<std::string> taken = recordings(live);
  ASSERT_EQ(taken.size(), 1u);
  EXPECT_EQ(objects(live, taken[0], std::string(agg::kTv) + "endSample").size(), 1u);
  ASSERT_EQ(stopped_after(live_argv, 3), 0);
  const std::vector<std::string> retaken = recordings(live);
  ASSERT_EQ(retaken.size(), 2u);
  EXPECT_NE(retaken[0], retaken[1]);
}

// A take that holds the whole signal was replayed again as a second take whenever the source was
// started anew (a supervisor restarted, a reboot, a down and up): the hospital saw the patient
// twice. The next run finds nothing more to replay and exits with status 0, writing nothing.
TEST_F(EcgSourceTest, ASignalAnEarlierRunReplayedWholeIsNotReplayedAgain) {
  const std::string dir = new_node("home1");
  ASSERT_EQ(run_source(dir), 0);
  const std::vector<std::string> takes = recordings(dir);
  ASSERT_EQ(takes.size(), 1u);
  const auto items = tn::Node::open(dir).value().stats().value().items;
  const fs::path log = tmp_ / "again.log";
  tahvel::test_support::AgentProcess again(source_argv(dir, "0"), log.string());
  EXPECT_EQ(again.wait(60s), 0);
  EXPECT_EQ(recordings(dir), takes);
  EXPECT_EQ(tn::Node::open(dir).value().stats().value().items, items) << "the second run wrote";
  const std::string said = text_of(log);
  EXPECT_NE(said.find("holds the whole of synthetic-5 (21600 frames), replayed by an earlier run: nothing more to replay"),
            std::string::npos) << said;
  // Another signal under the same name (the generator at another heart rate) is a new take.
  std::vector<std::string> argv = source_argv(dir, "0");
  argv.insert(argv.end(), {"--hr", "90"});
  tahvel::test_support::AgentProcess other(argv);
  EXPECT_EQ(other.wait(60s), 0);
  EXPECT_EQ(recordings(dir).size(), 2u);
}

// A header corrected in place of a wrong one (its sampling rate) names the same record: the
// take the wrong one gave was said to hold "the whole" of the corrected signal, and nothing
// more was replayed.
TEST_F(EcgSourceTest, ARecordReadAtAnotherRateOrLeadIsAnotherSignalAndIsReplayed) {
  const std::string dir = new_node("rates");
  const fs::path wrong = two_signal_record("r", "r 2 36 720\nr.dat 16 200/mV 16 0 0 0 0 MLII\nr.dat 16 200/mV 16 0 0 0 0 V1\n",
                                           720, 5, 7);
  const fs::path right = tmp_ / "fixed";
  std::ofstream(right.string() + ".hea") << "r 2 360 720\nr.dat 16 200/mV 16 0 0 0 0 MLII\nr.dat 16 200/mV 16 0 0 0 0 V1\n";
  const std::string bin = std::string(TAHVEL_BIN_DIR) + "/tahvel-ecg-source";
  tahvel::test_support::AgentProcess first({bin, dir, "--record", wrong.string(), "--speed", "0"});
  ASSERT_EQ(first.wait(std::chrono::seconds(60)), 0);
  ASSERT_EQ(recordings(dir).size(), 1u);
  tahvel::test_support::AgentProcess again({bin, dir, "--record", right.string(), "--speed", "0"});
  ASSERT_EQ(again.wait(std::chrono::seconds(60)), 0);
  const auto takes = recordings(dir);
  ASSERT_EQ(takes.size(), 2u) << "the corrected header was not replayed";
  EXPECT_EQ(objects(dir, takes[1], std::string(agg::kTv) + "samplingRate"), std::vector<std::string>{"360.0"});
  // The record's other lead first (`--signal 1`): the leads share a gain, and it was taken for
  // the signal replayed whole.
  tahvel::test_support::AgentProcess lead({bin, dir, "--record", right.string(), "--signal", "1", "--speed", "0"});
  ASSERT_EQ(lead.wait(std::chrono::seconds(60)), 0);
  ASSERT_EQ(recordings(dir).size(), 3u) << "the other lead was not replayed";
  EXPECT_EQ(objects(dir, recordings(dir)[2], std::string(agg::kTv) + "lead"), (std::vector<std::string>{"0 V1", "1 MLII"}));
}

// tv:replayedFrom names a record by its directory and name ("ecg/rec"): the record of another
// patient under the same layout (patientB/ecg/rec after patientA/ecg/rec) was "the whole of rec,
// replayed by an earlier run" and never recorded (or, after a kill, spliced onto A's take).
TEST_F(EcgSourceTest, AnotherRecordUnderTheSameDirectoryAndNameIsAnotherSignal) {
  const std::string dir = new_node("patients");
  const std::string header = "rec 2 360 720\nrec.dat 16 200/mV 16 0 0 0 0 MLII\nrec.dat 16 200/mV 16 0 0 0 0 V1\n";
  fs::create_directories(tmp_ / "patientA" / "ecg");
  fs::create_directories(tmp_ / "patientB" / "ecg");
  const fs::path a = two_signal_record("patientA/ecg/rec", header, 720, 5, 7);
  const fs::path b = two_signal_record("patientB/ecg/rec", header, 720, 6, 8);
  const std::string bin = std::string(TAHVEL_BIN_DIR) + "/tahvel-ecg-source";
  tahvel::test_support::AgentProcess first({bin, dir, "--record", a.string(), "--speed", "0"});
  ASSERT_EQ(first.wait(60s), 0);
  ASSERT_EQ(recordings(dir).size(), 1u);
  tahvel::test_support::AgentProcess second({bin, dir, "--record", b.string(), "--speed", "0"});
  ASSERT_EQ(second.wait(60s), 0);
  const auto takes = recordings(dir);
  ASSERT_EQ(takes.size(), 2u) << "patient B's record was taken for patient A's";
  EXPECT_EQ(chunks(dir, takes[1]).samples.size(), 2u);
  // Patient A's record again is the same signal: nothing more to replay.
  tahvel::test_support::AgentProcess again({bin, dir, "--record", a.string(), "--speed", "0"});
  ASSERT_EQ(again.wait(60s), 0);
  EXPECT_EQ(recordings(dir).size(), 2u);
}

// A take an earlier run left unended (the source killed) goes on only with the same signal: the
// generator at another heart rate went on with the killed take, its frames after the other's.
TEST_F(EcgSourceTest, ATakeLeftUnendedIsEndedNotContinuedByAnotherSignal) {
  const std::string dir = new_node("other");
  std::size_t before = 0;
  ASSERT_NO_FATAL_FAILURE(kill_the_source_after_ten_chunks(dir, before));
  const std::string killed = the_recording(dir);

  std::vector<std::string> argv = source_argv(dir, "0");
  argv.insert(argv.end(), {"--hr", "90"});
  tahvel::test_support::AgentProcess other(argv);
  ASSERT_EQ(other.wait(60s), 0);
  const auto takes = recordings(dir);
  ASSERT_EQ(takes.size(), 2u);
  EXPECT_EQ(takes[0], killed);
  EXPECT_EQ(chunks(dir, killed).samples.size(), before) << "the killed take was continued";
  EXPECT_EQ(objects(dir, killed, std::string(agg::kTv) + "endSample"),
            std::vector<std::string>{std::to_string(before * 360)});
  EXPECT_EQ(chunks(dir, takes[1]).samples.size(), 60u);
}

// `--seconds 0` was read as no limit: the generator ran until stopped (65 MB in 20 s).
TEST_F(EcgSourceTest, ZeroSecondsOfSyntheticEcgIsRefused) {
  const std::string dir = new_node("zero");
  const fs::path log = tmp_ / "zero.log";
  tahvel::test_support::AgentProcess source({std::string(TAHVEL_BIN_DIR) + "/tahvel-ecg-source", dir, "--synthetic",
                                             "--seconds", "0", "--speed", "0"},
                                            log.string());
  EXPECT_EQ(source.wait(10s), 2);
  EXPECT_TRUE(recordings(dir).empty());
  const std::string said = text_of(log);
  EXPECT_NE(said.find("--seconds: '0' is less than one sample"), std::string::npos) << said;
}

// Given both, the source said "give --record PATH or --synthetic", which the user had done.
TEST_F(EcgSourceTest, ARecordAndSyntheticTogetherAreRefusedAsTwoSourcesNotAsNone) {
  const std::string dir = new_node("both");
  const fs::path log = tmp_ / "both.log";
  tahvel::test_support::AgentProcess source({std::string(TAHVEL_BIN_DIR) + "/tahvel-ecg-source", dir, "--synthetic", "--record",
                                             (tmp_ / "none").string(), "--speed", "0"},
                                            log.string());
  EXPECT_EQ(source.wait(10s), 2);
  const std::string said = text_of(log);
  EXPECT_NE(said.find("--record and --synthetic: give one of them, not both"), std::string::npos) << said;
  EXPECT_TRUE(recordings(dir).empty());
}

// A heart rate outside ECGSYN's 30..180 exited 1 without the usage, naming the generator's
// option (mean_hr_bpm) rather than the flag; 'abc' was "not a number >= 0.000000".
TEST_F(EcgSourceTest, AHeartRateTheGeneratorCannotMakeIsAUsageErrorNamingTheFlag) {
  const std::string dir = new_node("hr");
  for (const std::string hr : {"200", "0", "abc"}) {
    const fs::path log = tmp_ / ("hr-" + hr + ".log");
    tahvel::test_support::AgentProcess source({std::string(TAHVEL_BIN_DIR) + "/tahvel-ecg-source", dir, "--synthetic", "--hr", hr,
                                               "--seconds", "5", "--speed", "0"},
                                              log.string());
    EXPECT_EQ(source.wait(10s), 2) << hr;
    const std::string said = text_of(log);
    EXPECT_NE(said.find("--hr: '" + hr + "' is not a heart rate from 30 to 180 beats per minute"), std::string::npos) << said;
  }
  EXPECT_TRUE(recordings(dir).empty());
}

// A sensor whose store is made again (replaced) remembers nothing of its takes, while its home
// holds the old take's chunks and has run R-peaks on them. Each take is named by its start, so
// the new one is not the old one's name again: the home would have taken its chunks for done.
TEST_F(EcgSourceTest, ASourceOnAStoreMadeAgainRecordsUnderANameOfItsOwn) {
  const std::string dir = new_node("sensor");
  ASSERT_EQ(run_source(dir), 0);
  const std::string before = the_recording(dir);
  // A take is named to the second; a sensor replaced takes longer than that.
  const auto second = std::chrono::floor<std::chrono::seconds>(std::chrono::system_clock::now());
  std::this_thread::sleep_until(second + 1100ms);
  fs::remove_all(dir);
  new_node("sensor");
  ASSERT_EQ(run_source(dir), 0);
  const std::string after = the_recording(dir);
  EXPECT_NE(after, before);
  EXPECT_TRUE(is_take(before) && is_take(after)) << before << " " << after;
}

}  // namespace
