// WFDB header and signal reading: MIT-BIH record 100 read in place (never copied), checked
// against values decoded by hand from its first bytes and against the header's checksums; and
// malformed records written to a temporary directory.
#include "tahvel/aggregation/wfdb.h"
#include "tahvel/aggregation/pipeline.h"
#include "tahvel/aggregation/ecgsyn.h"

#include <gtest/gtest.h>

#include <tuple>
#include <unistd.h>
#include <sys/stat.h>

#include <algorithm>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>
#include <vector>

#include "mitdb_support.h"
#include "wfdb_record.h"

namespace tahvel::aggregation {
namespace {

namespace fs = std::filesystem;
using testing::mitdb_dir;
using testing::mitdb_record;

bool have_mitdb() { return fs::exists(mitdb_dir() / "100.hea"); }

#define REQUIRE_MITDB() \
  if (!have_mitdb()) GTEST_SKIP() << "MIT-BIH records not found at " << mitdb_dir()

// A scratch directory per test, removed afterwards.
class WfdbTemp : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    dir_ = fs::temp_directory_path() /
           ("tahvel-wfdb-" + std::to_string(::getpid()) + "-" + info->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string record(const std::string& name) const { return (dir_ / name).string(); }
  void write(const std::string& name, const std::string& bytes) const {
    std::ofstream(dir_ / name, std::ios::binary) << bytes;
  }
  fs::path dir_;
};

std::string bytes_of(std::initializer_list<int> v) {
  std::string s;
  for (int b : v) s.push_back(static_cast<char>(b));
  return s;
}

// ---- record 100 ----

TEST(WfdbRecord100, HeaderGivesFsSignalsSamplesGainBaselineFormat) {
  REQUIRE_MITDB();
  auto h = read_header(mitdb_record("100"));
  ASSERT_TRUE(h) << h.error().message;
  EXPECT_EQ(h->name, "100");
  EXPECT_EQ(h->signal_count, 2);
  EXPECT_DOUBLE_EQ(h->fs, 360.0);
  EXPECT_EQ(h->samples_per_signal, 650000);
  ASSERT_EQ(h->signals.size(), 2u);
  for (const auto& s : h->signals) {
    EXPECT_EQ(s.file, "100.dat");
    EXPECT_EQ(s.format, 212);
    EXPECT_DOUBLE_EQ(s.gain, 200.0);
    EXPECT_EQ(s.baseline, 1024);
    EXPECT_EQ(s.adc_zero, 1024);
    EXPECT_EQ(s.adc_resolution, 11);
    EXPECT_EQ(s.units, "mV");
  }
  EXPECT_EQ(h->signals[0].description, "MLII");
  EXPECT_EQ(h->signals[1].description, "V5");
  EXPECT_EQ(h->signals[0].initial_value, 995);
  EXPECT_EQ(h->signals[1].initial_value, 1011);
  EXPECT_EQ(h->signals[0].checksum, -22131);
  EXPECT_EQ(h->signals[1].checksum, 20052);
  ASSERT_FALSE(h->comments.empty());
  EXPECT_EQ(h->comments[0], "69 M 1085 1629 x1");
}

TEST(WfdbRecord100, FirstSamplesMatchBytesDecodedByHand) {
  REQUIRE_MITDB();
  // Independent decoding of the first two 3-byte groups of 100.dat (format 212): sample 0 is
  // byte0 + low nibble of byte1 << 8, sample 1 is byte2 + high nibble of byte1 << 4.
  std::ifstream in(mitdb_dir() / "100.dat", std::ios::binary);
  unsigned char b[6];
  in.read(reinterpret_cast<char*>(b), 6);
  ASSERT_EQ(in.gcount(), 6);
  int mlii0 = b[0] | ((b[1] & 0x0F) << 8), v5_0 = b[2] | ((b[1] & 0xF0) << 4);
  int mlii1 = b[3] | ((b[4] & 0x0F) << 8), v5_1 = b[5] | ((b[4] & 0xF0) << 4);
  EXPECT_EQ(mlii0, 995);  // published: the first MLII sample of record 100 is 995 adu
  EXPECT_EQ(v5_0, 1011);

  auto sig = read_signals(mitdb_record("100"));
  ASSERT_TRUE(sig) << sig.error().message;
  ASSERT_EQ(sig->samples.size(), 2u);
  ASSERT_EQ(sig->samples[0].size(), 650000u);
  ASSERT_EQ(sig->samples[1].size(), 650000u);
  EXPECT_EQ(sig->samples[0][0], mlii0);
  EXPECT_EQ(sig->samples[1][0], v5_0);
  EXPECT_EQ(sig->samples[0][1], mlii1);
  EXPECT_EQ(sig->samples[1][1], v5_1);
  EXPECT_EQ(sig->samples[0][0], sig->header.signals[0].initial_value);
  EXPECT_EQ(sig->samples[1][0], sig->header.signals[1].initial_value);
}

TEST(WfdbRecord100, SampleSumsMatchHeaderChecksums) {
  REQUIRE_MITDB();
  auto sig = read_signals(mitdb_record("100"));
  ASSERT_TRUE(sig) << sig.error().message;
  for (std::size_t i = 0; i < 2; ++i) {
    std::int64_t sum = 0;
    for (auto v : sig->samples[i]) sum += v;
    EXPECT_EQ(static_cast<std::int16_t>(static_cast<std::uint16_t>(sum & 0xFFFF)),
              sig->header.signals[i].checksum)
        << "signal " << i;
  }
}

TEST(WfdbRecord100, StreamingInOneSecondChunksEqualsWholeRead) {
  REQUIRE_MITDB();
  auto whole = read_signals(mitdb_record("100"));
  ASSERT_TRUE(whole) << whole.error().message;
  auto r = SignalReader::open(mitdb_record("100"));
  ASSERT_TRUE(r) << r.error().message;
  std::vector<std::vector<std::int32_t>> out;
  std::size_t chunks = 0;
  for (;;) {
    auto n = r->read(360, out);
    ASSERT_TRUE(n) << n.error().message;
    if (*n == 0) break;
    ++chunks;
  }
  EXPECT_EQ(chunks, (650000u + 359) / 360);
  EXPECT_EQ(r->position(), 650000);
  EXPECT_EQ(out, whole->samples);
}

// A minute of record 100 written in each format wide enough for its 11-bit samples reads back
// sample for sample (the HRV chain then sees the same record whatever its format).
class WfdbRecord100InAnotherFormat : public WfdbTemp {};
TEST_F(WfdbRecord100InAnotherFormat, AMinuteWrittenInEachWideFormatReadsBackTheSameSamples) {
  REQUIRE_MITDB();
  auto original = read_signals(mitdb_record("100"));
  ASSERT_TRUE(original) << original.error().message;
  const std::size_t frames = 21600;
  for (const int format : {16, 61, 160, 24, 32}) {
    SCOPED_TRACE("format " + std::to_string(format));
    std::string dat;
    for (std::size_t f = 0; f < frames; ++f)
      for (const auto& signal : original->samples) {
        const std::int32_t v = signal[f];
        const auto u = static_cast<std::uint32_t>(format == 160 ? v + 32768 : v);
        if (format == 61) {
          dat += static_cast<char>(u >> 8 & 0xFF);
          dat += static_cast<char>(u & 0xFF);
        } else {
          for (int k = 0; k < (format == 24 ? 3 : format == 32 ? 4 : 2); ++k) dat += static_cast<char>(u >> (8 * k) & 0xFF);
        }
      }
    const std::string name = "m" + std::to_string(format);
    write(name + ".hea", name + " 2 360 " + std::to_string(frames) + "\n" + name + ".dat " + std::to_string(format) +
                             " 200(1024) 11 1024 995 0 0 MLII\n" + name + ".dat " + std::to_string(format) +
                             " 200(1024) 11 1024 1011 0 0 V5\n");
    write(name + ".dat", dat);
    auto copy = read_signals(record(name));
    ASSERT_TRUE(copy) << copy.error().message;
    for (std::size_t i = 0; i < 2; ++i)
      EXPECT_TRUE(std::equal(copy->samples[i].begin(), copy->samples[i].end(), original->samples[i].begin()) &&
                  copy->samples[i].size() == frames)
          << "signal " << i;
  }
}

// A null signal (format 0, file "~": WFDB's place for a signal not recorded) beside the ECG, and
// an ECG lead recorded upside down (a negative gain): both stopped the record from being read
// (an exploratory run of session 85). The null signal reads as WFDB's no-value and is never the
// ECG; the upside-down lead gives the beats of the lead as recorded.
TEST_F(WfdbRecord100InAnotherFormat, ANullSignalBesideTheEcgAndANegativeGainAreRead) {
  REQUIRE_MITDB();
  auto original = read_signals(mitdb_record("100"));
  ASSERT_TRUE(original) << original.error().message;
  const std::size_t frames = 360 * 120;
  std::string plain, upside_down;
  for (std::size_t f = 0; f < frames; ++f) {
    const std::int32_t v = original->samples[0][f] - 1024;
    for (int k = 0; k < 2; ++k) {
      plain += static_cast<char>(static_cast<std::uint32_t>(v) >> (8 * k) & 0xFF);
      upside_down += static_cast<char>(static_cast<std::uint32_t>(-v) >> (8 * k) & 0xFF);
    }
  }
  const std::string count = std::to_string(frames);
  write("p.hea", "p 1 360 " + count + "\np.dat 16 200 11 0 0 0 0 MLII\n");
  write("p.dat", plain);
  write("n.hea", "n 2 360 " + count + "\n~ 0 200 16 1024 0 0 0 Resp\nn.dat 16 -200 11 0 0 0 0 MLII\n");
  write("n.dat", upside_down);
  auto h = read_header(record("n"));
  ASSERT_TRUE(h) << h.error().message;
  EXPECT_EQ(h->signals[1].gain, -200);
  EXPECT_EQ(ecg_signal(*h), 1u);
  auto why = not_an_ecg_signal(*h, 0);
  ASSERT_TRUE(why);
  EXPECT_EQ(*why, record("n") + ".hea: signal 0 (Resp) is a null signal (format 0: WFDB's place for a signal that was not "
                                "recorded), which has no samples");
  EXPECT_FALSE(not_an_ecg_signal(*h, 1));
  auto read = read_signals(record("n"));
  ASSERT_TRUE(read) << read.error().message;
  ASSERT_EQ(read->samples[0].size(), frames);
  EXPECT_TRUE(std::all_of(read->samples[0].begin(), read->samples[0].end(), [](std::int32_t v) { return v == -32768; }));
  EXPECT_DOUBLE_EQ(to_physical(read->samples[1][100], h->signals[1]), to_physical(original->samples[0][100], original->header.signals[0]));
  auto as_recorded = hrv_from_record(record("p"));
  auto beside_null = hrv_from_record(record("n"));
  ASSERT_TRUE(as_recorded) << as_recorded.error().message;
  ASSERT_TRUE(beside_null) << beside_null.error().message;
  EXPECT_GT(as_recorded->beats.size(), 100u);
  EXPECT_EQ(beside_null->beats, as_recorded->beats);
  auto null_named = hrv_from_record(record("n"), {}, 0);
  ASSERT_FALSE(null_named);
  EXPECT_EQ(null_named.error().message, *why);
  // Null signals apart from each other share no file ("signals of file ~ are not consecutive",
  // a review of session 85); null signals alone, with no sample count, read as none.
  write("z.hea", "z 3 360 " + count + "\n~ 0 200 16 1024 0 0 0 Resp\nn.dat 16 -200 11 0 0 0 0 MLII\n~ 0 200 16 1024 0 0 0 ABP\n");
  auto apart = hrv_from_record(record("z"));
  ASSERT_TRUE(apart) << apart.error().message;
  EXPECT_EQ(apart->beats, as_recorded->beats);
  write("e.hea", "e 2 360\n~ 0 200 16 1024 0 0 0 Resp\n~ 0 200 16 1024 0 0 0 ABP\n");
  auto none = read_signals(record("e"));
  ASSERT_TRUE(none) << none.error().message;
  EXPECT_TRUE(none->samples[0].empty());
}

TEST(WfdbRecord100, PhysicalValueIsAduMinusBaselineOverGain) {
  REQUIRE_MITDB();
  auto h = read_header(mitdb_record("100"));
  ASSERT_TRUE(h);
  EXPECT_DOUBLE_EQ(to_physical(995, h->signals[0]), (995 - 1024) / 200.0);
  EXPECT_DOUBLE_EQ(to_physical(1024, h->signals[0]), 0.0);
}

// ---- synthetic records ----

TEST_F(WfdbTemp, Format16IsLittleEndianSignedAndInterleaved) {
  write("r.hea", "r 2 100 3\r\nr.dat 16 100(5)/uV 16 0 0 0 0 a b c\r\nr.dat 16 100 16 0 0 0 0\r\n");
  // frames: (1, -1), (256, -32768), (300, 7)
  write("r.dat", bytes_of({0x01, 0x00, 0xFF, 0xFF, 0x00, 0x01, 0x00, 0x80, 0x2C, 0x01, 0x07, 0x00}));
  auto s = read_signals(record("r"));
  ASSERT_TRUE(s) << s.error().message;
  EXPECT_EQ(s->samples[0], (std::vector<std::int32_t>{1, 256, 300}));
  EXPECT_EQ(s->samples[1], (std::vector<std::int32_t>{-1, -32768, 7}));
  EXPECT_EQ(s->header.signals[0].baseline, 5);
  EXPECT_EQ(s->header.signals[0].units, "uV");
  EXPECT_EQ(s->header.signals[0].description, "a b c");
  EXPECT_EQ(s->header.signals[1].units, "mV");
  EXPECT_DOUBLE_EQ(to_physical(105, s->header.signals[0]), 1.0);
}

TEST_F(WfdbTemp, Format212DecodesNegativeTwelveBitValuesAndOddSignalCounts) {
  // One signal in 212: values 0x801 (-2047), 0x7FF (2047), 0xFFF (-1) pack as
  // [01 78 FF] [FF 0F]: the last pair holds a single value in two bytes.
  write("r.hea", "r 1 250 3\nr.dat 212 200 12 0 0 0 0\n");
  write("r.dat", bytes_of({0x01, 0x78, 0xFF, 0xFF, 0x0F}));
  auto s = read_signals(record("r"));
  ASSERT_TRUE(s) << s.error().message;
  EXPECT_EQ(s->samples[0], (std::vector<std::int32_t>{-2047, 2047, -1}));
  // Streaming one frame at a time crosses the middle of a 3-byte pair.
  auto r = SignalReader::open(record("r"));
  ASSERT_TRUE(r) << r.error().message;
  std::vector<std::vector<std::int32_t>> out;
  for (int k = 0; k < 3; ++k) {
    auto n = r->read(1, out);
    ASSERT_TRUE(n) << n.error().message;
    EXPECT_EQ(*n, 1u);
  }
  auto end = r->read(1, out);
  ASSERT_TRUE(end);
  EXPECT_EQ(*end, 0u);
  EXPECT_EQ(out[0], (std::vector<std::int32_t>{-2047, 2047, -1}));
}

// The formats of WFDB's signal(5) besides 212 and 16, each from bytes packed by hand from the
// specification (PhysioNet records come in them: 310 in older ones, 80 and 8 in 8-bit ones,
// 24 and 32 from newer recorders); a partial last block holds what WFDB's writers flush.
TEST_F(WfdbTemp, EachFormatOfSignal5DecodesBytesPackedByHand) {
  struct Case {
    const char* format;
    std::string bytes;
    std::vector<std::int32_t> values;
  };
  const std::vector<Case> cases = {
      {"80", bytes_of({0x80, 0x81, 0x7F, 0x00, 0xFF}), {0, 1, -1, -128, 127}},
      {"160", bytes_of({0x00, 0x80, 0x01, 0x80, 0xFF, 0x7F, 0x00, 0x00}), {0, 1, -1, -32768}},
      {"61", bytes_of({0x01, 0x2C, 0xFF, 0xFE, 0x80, 0x00}), {300, -2, -32768}},
      {"24", bytes_of({0x01, 0x00, 0x80, 0xFF, 0xFF, 0x7F, 0x00, 0x00, 0x01, 0xFE, 0xFF, 0xFF}), {-8388607, 8388607, 65536, -2}},
      {"32", bytes_of({0x00, 0x00, 0x01, 0x00, 0xFF, 0xFF, 0xFF, 0xFF, 0x00, 0x00, 0x00, 0x80}), {65536, -1, INT32_MIN}},
      // 5, -2, 300 in two words (bits 1-10 of each; 300's low five bits in bits 11-15 of the
      // first, its high five in bits 11-15 of the second), then -512 alone in one word.
      {"310", bytes_of({0x0A, 0x60, 0xFC, 0x4F, 0x00, 0x04}), {5, -2, 300, -512}},
      // 5, -2, 300 in bits 0-9, 10-19, 20-29 of one 32-bit word, then 1 and -1 in three bytes.
      {"311", bytes_of({0x05, 0xF8, 0xCF, 0x12, 0x01, 0xFC, 0x0F}), {5, -2, 300, 1, -1}},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(std::string("format ") + c.format);
    const std::string name = std::string("f") + c.format;
    write(name + ".hea", name + " 1 250 " + std::to_string(c.values.size()) + "\n" + name + ".dat " + c.format + " 200 0 0 0\n");
    write(name + ".dat", c.bytes);
    auto s = read_signals(record(name));
    ASSERT_TRUE(s) << s.error().message;
    EXPECT_EQ(s->samples[0], c.values);
    EXPECT_TRUE(unread_samples(s->header).empty());
    // One frame at a time: a packed block is decoded once, its values handed out in turn.
    auto r = SignalReader::open(record(name));
    ASSERT_TRUE(r) << r.error().message;
    std::vector<std::vector<std::int32_t>> out;
    for (std::size_t k = 0; k < c.values.size(); ++k) ASSERT_EQ(*r->read(1, out), 1u);
    EXPECT_EQ(*r->read(1, out), 0u);
    EXPECT_EQ(out[0], c.values);
  }
}

// Format 8 holds first differences: each signal of the file adds its own, from the header's
// initial value, the signals interleaved byte by byte.
TEST_F(WfdbTemp, Format8AddsEachSignalsDifferencesToItsInitialValue) {
  write("d.hea", "d 2 250 3\nd.dat 8 200 12 0 100 0 0 ECG\nd.dat 8 200 12 0 -5 0 0 V5\n");
  write("d.dat", bytes_of({0x01, 0x02, 0xFD, 0x80, 0x7F, 0x00}));
  auto s = read_signals(record("d"));
  ASSERT_TRUE(s) << s.error().message;
  EXPECT_EQ(s->samples[0], (std::vector<std::int32_t>{101, 98, 225}));
  EXPECT_EQ(s->samples[1], (std::vector<std::int32_t>{-3, -131, -131}));
  auto r = SignalReader::open(record("d"));
  ASSERT_TRUE(r) << r.error().message;
  std::vector<std::vector<std::int32_t>> out;
  ASSERT_EQ(*r->read(2, out), 2u);
  ASSERT_EQ(*r->read(5, out), 1u);
  EXPECT_EQ(out[0], s->samples[0]);
  EXPECT_EQ(out[1], s->samples[1]);
}

// A signal without a value is written as its format's least value; a record cut inside a
// packed block is truncated, not read short.
TEST_F(WfdbTemp, EachFormatsNoValueIsItsLeastValueAndACutBlockIsTruncation) {
  const std::vector<std::pair<int, std::int32_t>> least = {
      {16, -32768}, {61, -32768}, {160, -32768}, {212, -2048}, {310, -512}, {311, -512}, {80, -128}, {24, -8388608}, {32, INT32_MIN}};
  for (const auto& [format, value] : least) {
    SignalInfo info;
    info.format = format;
    EXPECT_EQ(invalid_sample(info), value) << "format " << format;
  }
  write("c.hea", "c 1 250 4\nc.dat 310 200 10 0 0 0 0\n");
  write("c.dat", bytes_of({0x0A, 0x60, 0xFC, 0x4F, 0x00}));  // three values, then half a word
  auto s = read_signals(record("c"));
  ASSERT_FALSE(s);
  EXPECT_NE(s.error().message.find("expected 4 samples per signal, found 3"), std::string::npos) << s.error().message;
}

// A record may start with respiration or blood pressure (the HRV chain read it as the ECG and
// gave 0 beats, or the pulse as beats), and a header may give its gain per microvolt or volt
// (read as per millivolt, the thresholds were off by a thousand).
TEST_F(WfdbTemp, TheEcgLeadIsTheFirstNamedOneElseTheFirstInVoltsAndGainIsPerMillivolt) {
  write("a.hea", "a 3 250 0\na.dat 16 1000/l 16 0 0 0 0 RESP\na.dat 16 100/mmHg 16 0 0 0 0 ABP\na.dat 16 200/mV 16 0 0 0 0 ECG II\n");
  write("b.hea", "b 2 250 0\nb.dat 16 1000/l 16 0 0 0 0 resp\nb.dat 16 1/uV 16 0 0 0 0\n");
  write("c.hea", "c 2 250 0\nc.dat 16 10/l 16 0 0 0 0 flow\nc.dat 16 10/mmHg 16 0 0 0 0 pressure\n");
  write("d.hea", "d 2 360 0\nd.dat 212 200 11 1024 995 -22131 0 V5\nd.dat 212 200 11 1024 1011 20052 0 MLII\n");
  // Named in the ways Holter and monitor records name them, after a signal in volts that is none.
  write("e.hea", "e 2 250 0\ne.dat 16 200/V 16 0 0 0 0 Pleth\ne.dat 16 200/mmHg 16 0 0 0 0 Lead II\n");
  write("f.hea", "f 2 250 0\nf.dat 16 200/V 16 0 0 0 0 Pleth\nf.dat 16 200 16 0 0 0 0 MCL1\n");
  write("g.hea", "g 2 250 0\ng.dat 16 200/V 16 0 0 0 0 Pleth\ng.dat 16 200 16 0 0 0 0 CM2\n");
  write("h.hea", "h 2 250 0\nh.dat 16 200/V 16 0 0 0 0 Pleth\nh.dat 16 200 16 0 0 0 0 ML2\n");
  write("i.hea", "i 2 250 0\ni.dat 16 200/V 16 0 0 0 0 Pleth\ni.dat 16 200 16 0 0 0 0 V4R\n");
  // An accelerometer's axes are not taken for Frank leads: the first signal in volts is.
  write("j.hea", "j 3 250 0\nj.dat 16 200/g 16 0 0 0 0 X\nj.dat 16 200/g 16 0 0 0 0 Y\nj.dat 16 200/mV 16 0 0 0 0 chest\n");
  // A bedside monitor's chest lead, named "V" (MIMIC), after a respiration signal in volts.
  write("k.hea", "k 2 125 0\nk.dat 16 200/V 16 0 0 0 0 Resp\nk.dat 16 200/mV 16 0 0 0 0 V\n");
  const std::pair<const char*, std::size_t> cases[] = {{"a", 2}, {"b", 1}, {"c", 0}, {"d", 0}, {"e", 1}, {"f", 1},
                                                       {"g", 1}, {"h", 1}, {"i", 1}, {"j", 2}, {"k", 1}};
  for (const auto& [name, lead] : cases) {
    auto h = read_header(record(name));
    ASSERT_TRUE(h) << h.error().message;
    EXPECT_EQ(ecg_signal(*h), lead) << name;
  }
  SignalInfo info;
  for (const auto& [units, gain, per_mv] : {std::tuple{"mV", 200.0, 200.0}, std::tuple{"uV", 1.0, 1000.0},
                                            std::tuple{"\xC2\xB5V", 0.2, 200.0}, std::tuple{"V", 1e6, 1000.0},
                                            std::tuple{"mmHg", 100.0, 100.0}, std::tuple{"mV", 0.0, 200.0}}) {
    info.units = units;
    info.gain = gain;
    EXPECT_DOUBLE_EQ(gain_per_mv(info), per_mv) << units << " " << gain;
  }
}

// A signal file in another format than its header says reads as numbers all the same; its
// checksum is how WFDB's tools notice (they warn and read on).
TEST_F(WfdbTemp, ASignalWhoseSamplesDoNotAddUpToTheChecksumIsNamed) {
  write("r.dat", bytes_of({0x01, 0x00, 0xFF, 0xFF, 0x00, 0x01}));  // 1, -1, 256 in format 16
  write("r.hea", "r 1 100 3\nr.dat 16 200 16 0 1 256 0 II\n");
  auto s = read_signals(record("r"));
  ASSERT_TRUE(s) << s.error().message;
  EXPECT_TRUE(checksum_mismatches(*s).empty());
  write("r.hea", "r 1 100 3\nr.dat 16 200 16 0 1 257 0 II\n");
  s = read_signals(record("r"));
  ASSERT_TRUE(s) << s.error().message;
  const auto said = checksum_mismatches(*s);
  ASSERT_EQ(said.size(), 1u);
  EXPECT_NE(said[0].find("r.hea: signal 0 (II): its samples add up to 256, the header's checksum is 257"), std::string::npos) << said[0];
  // The file read is named, not the record line's name for it.
  write("small.hea", "100 1 100 3\nr.dat 16 200 16 0 1 257 0 II\n");
  s = read_signals(record("small"));
  ASSERT_TRUE(s) << s.error().message;
  ASSERT_EQ(checksum_mismatches(*s).size(), 1u);
  EXPECT_EQ(checksum_mismatches(*s)[0].rfind(record("small") + ".hea: signal 0 (II)", 0), 0u) << checksum_mismatches(*s)[0];
  // A header without a sample count was written before the samples were known, its checksum
  // field too (0 here): not compared, so not said to be a file in another format.
  write("r.hea", "r 1 100 0\nr.dat 16 200 16 0 1 0 0 II\n");
  s = read_signals(record("r"));
  ASSERT_TRUE(s) << s.error().message;
  EXPECT_EQ(s->samples[0].size(), 3u);
  EXPECT_TRUE(checksum_mismatches(*s).empty());
}

// A record line without a sampling frequency is read at WFDB's 250 Hz, and said so: a record
// of another rate gives heart rates off by the ratio.
TEST_F(WfdbTemp, AHeaderWithoutASamplingFrequencyIsWarnedOf) {
  write("r.dat", bytes_of({0x01, 0x00, 0xFF, 0xFF, 0x00, 0x01}));
  write("r.hea", "r 1\nr.dat 16 200 16 0 1 256 0 II\n");
  auto h = read_header(record("r"));
  ASSERT_TRUE(h) << h.error().message;
  EXPECT_DOUBLE_EQ(h->fs, 250);
  const auto said = default_rate_warning(*h);
  ASSERT_TRUE(said);
  EXPECT_EQ(said->rfind(record("r") + ".hea: the record line gives no sampling frequency: WFDB's default of 250 Hz", 0), 0u) << *said;
  write("r.hea", "r 1 360\nr.dat 16 200 16 0 1 256 0 II\n");
  h = read_header(record("r"));
  ASSERT_TRUE(h) << h.error().message;
  EXPECT_FALSE(default_rate_warning(*h));
}

// A lead off for the whole record (a channel of zeros) gives no beat and every metric null; the
// report says why, rather than leaving a record "without HRV" unexplained.
TEST_F(WfdbTemp, AFlatRecordGivesNoBeatsAndSaysSo) {
  write("r.dat", std::string(360 * 60 * 2, '\0'));
  write("r.hea", "r 1 360 21600\nr.dat 16 200 11 1024 0 0 0 MLII\n");
  auto report = hrv_from_record(record("r"));
  ASSERT_TRUE(report) << report.error().message;
  EXPECT_TRUE(report->beats.empty());
  ASSERT_FALSE(report->warnings.empty());
  EXPECT_EQ(report->warnings.back(), "0 beat(s) found in 60 s of signal 0 (MLII): a flat or lead-off signal, a gain in its header off by far, or not an ECG; no HRV");
}

// A record with nothing to read is said so, not reported as HRV that happens to be null: no
// signals (it read "no signal 0 (the record has 0)", as if --signal were wrong), no samples (exit
// 0 without a word), a lead that is not the ECG among others (which --signal can name).
TEST_F(WfdbTemp, ARecordWithNoSignalNoSamplesOrTheWrongLeadIsSaidSo) {
  write("none.hea", "none 0 360 0\n");
  auto none = hrv_from_record(record("none"));
  ASSERT_FALSE(none);
  EXPECT_EQ(none.error().message, record("none") + ".hea: the record has no signals, so no ECG");

  write("empty.hea", "empty 1 360 0\nempty.dat 16 200 16 0 0 0 0 MLII\n");
  write("empty.dat", "");
  auto empty = hrv_from_record(record("empty"));
  ASSERT_TRUE(empty) << empty.error().message;
  ASSERT_FALSE(empty->warnings.empty());
  EXPECT_EQ(empty->warnings.back(), "the record holds no samples; no HRV");

  write("two.hea", "two 2 360 21600\ntwo.dat 16 200 16 0 0 0 0 resp\ntwo.dat 16 200 16 0 0 0 0\n");
  write("two.dat", std::string(360 * 60 * 4, '\0'));
  auto two = hrv_from_record(record("two"));
  ASSERT_TRUE(two) << two.error().message;
  ASSERT_FALSE(two->warnings.empty());
  EXPECT_EQ(two->warnings.back(), "0 beat(s) found in 60 s of signal 0 (resp): a flat or lead-off signal, a gain in its header off by far, or not an ECG; "
                                  "no HRV (the record has 2 signals: another may be the ECG: --signal N reads it)");
}

// An ECG lead whose units are no voltage is read as millivolts all the same: said, as a wrong
// header otherwise went on without a word ("200/furlongs" on an MLII lead).
TEST_F(WfdbTemp, AnEcgLeadInUnitsThatAreNoVoltageIsWarnedOf) {
  write("r.hea", "r 2 360 1\nr.dat 16 200/furlongs 16 0 0 0 0 MLII\nr.dat 16 100/mmHg 16 0 0 0 0 ABP\n");
  auto h = read_header(record("r"));
  ASSERT_TRUE(h) << h.error().message;
  EXPECT_EQ(non_voltage_warning(*h, 0), record("r") + ".hea: signal 0 (MLII), read as the ECG, is in 'furlongs', not a "
                                                      "voltage: its samples are read as millivolts at the header's gain (is the header right?)");
  write("v.hea", "v 4 360 1\nv.dat 16 200 16 0 0 0 0 MLII\nv.dat 16 1/uV 16 0 0 0 0 V1\nv.dat 16 1/V 16 0 0 0 0 V2\n"
                 "v.dat 16 1000/nV 16 0 0 0 0 V3\n");
  auto v = read_header(record("v"));
  ASSERT_TRUE(v) << v.error().message;
  for (std::size_t i = 0; i < 4; ++i) EXPECT_FALSE(non_voltage_warning(*v, i)) << i;  // mV by default, uV, V, nV
  EXPECT_DOUBLE_EQ(gain_per_mv(v->signals[3]), 1e9);
}

// WFDB writes its no-value (-32768 in format 16, -2048 in 212) where a signal has none. Read
// as a voltage, each run was a step of -160 mV into the QRS band: 0.5 s of it every minute of a
// synthetic ECG moved beats to the run's edges and raised SDNN by 18 %, without a word. It is
// read as no signal now, and said.
TEST_F(WfdbTemp, WfdbsNoValueIsReadAsNoSignalAndSaid) {
  auto ecg = synthetic_ecg(300, SyntheticEcgOptions{});
  ASSERT_TRUE(ecg) << ecg.error().message;
  std::vector<std::int32_t> gaps = *ecg;
  for (std::size_t start = 30 * 360; start + 180 <= gaps.size(); start += 60 * 360)
    std::fill(gaps.begin() + static_cast<std::ptrdiff_t>(start), gaps.begin() + static_cast<std::ptrdiff_t>(start + 180), -32768);
  tahvel::test_support::write_format16_record(dir_, "clean", *ecg);
  tahvel::test_support::write_format16_record(dir_, "gaps", gaps);
  auto clean = hrv_from_record(record("clean"));
  auto with_gaps = hrv_from_record(record("gaps"));
  ASSERT_TRUE(clean && with_gaps);
  ASSERT_TRUE(clean->metrics.sdnn_ms && with_gaps->metrics.sdnn_ms);
  EXPECT_NEAR(*with_gaps->metrics.sdnn_ms, *clean->metrics.sdnn_ms, 0.02 * *clean->metrics.sdnn_ms);
  EXPECT_TRUE(clean->warnings.empty());
  ASSERT_FALSE(with_gaps->warnings.empty());
  EXPECT_EQ(with_gaps->warnings[0].rfind("900 sample(s) of signal 0 (ECG) hold WFDB's no-value -32768, the first at 30.000 s", 0), 0u)
      << with_gaps->warnings[0];
}

// A lead off that the recorder wrote as its last value held, or as zeros, is no signal to the
// detector as WFDB's no-value is, and leaves the windows over it with fewer intervals; it went
// unsaid where the no-value was said. Flat stretches shorter than a beat at 40 bpm (a noise-free
// synthetic signal between its beats) are not.
TEST_F(WfdbTemp, ALeadOffWrittenAsAFlatLineIsSaidAsNoSignal) {
  auto ecg = synthetic_ecg(300, SyntheticEcgOptions{});
  ASSERT_TRUE(ecg) << ecg.error().message;
  std::vector<std::int32_t> held = *ecg, zeros = *ecg;
  const auto at = [](double s) { return static_cast<std::ptrdiff_t>(s * 360); };
  std::fill(held.begin() + at(100), held.begin() + at(120), held[static_cast<std::size_t>(at(100)) - 1]);
  std::fill(zeros.begin() + at(100), zeros.begin() + at(110), 0);
  std::fill(zeros.begin() + at(200), zeros.begin() + at(205), 0);
  tahvel::test_support::write_format16_record(dir_, "clean", *ecg);
  tahvel::test_support::write_format16_record(dir_, "held", held);
  tahvel::test_support::write_format16_record(dir_, "zeros", zeros);
  auto clean = hrv_from_record(record("clean"));
  auto with_held = hrv_from_record(record("held"));
  auto with_zeros = hrv_from_record(record("zeros"));
  ASSERT_TRUE(clean && with_held && with_zeros);
  EXPECT_TRUE(clean->warnings.empty()) << clean->warnings[0];
  ASSERT_EQ(with_held->warnings.size(), 1u);
  // The run starts at the sample whose value is held (99.997 s).
  EXPECT_EQ(with_held->warnings[0].rfind("20.0 s of signal 0 (ECG) hold one value for 1.5 s or more at a time (1 run(s), "
                                         "the first at 99.997 s): a lead off",
                                         0),
            0u)
      << with_held->warnings[0];
  ASSERT_FALSE(with_zeros->warnings.empty());
  EXPECT_EQ(with_zeros->warnings[0].rfind("15.0 s of signal 0 (ECG) hold one value for 1.5 s or more at a time (2 run(s), "
                                          "the first at 100.000 s)",
                                          0),
            0u)
      << with_zeros->warnings[0];
}

TEST_F(WfdbTemp, DefaultsApplyWhenOptionalFieldsAreAbsent) {
  write("r.hea", "# leading comment\n\nr 1\nr.dat 16\n");
  write("r.dat", bytes_of({0x05, 0x00}));
  auto h = read_header(record("r"));
  ASSERT_TRUE(h) << h.error().message;
  EXPECT_DOUBLE_EQ(h->fs, 250.0);
  EXPECT_EQ(h->samples_per_signal, 0);
  EXPECT_DOUBLE_EQ(h->signals[0].gain, 200.0);
  EXPECT_EQ(h->signals[0].baseline, 0);
  EXPECT_EQ(h->signals[0].adc_resolution, 16);
  EXPECT_EQ(h->signals[0].units, "mV");
  auto s = read_signals(record("r"));  // no sample count: read to the end of the file
  ASSERT_TRUE(s) << s.error().message;
  EXPECT_EQ(s->samples[0], (std::vector<std::int32_t>{5}));
}

TEST_F(WfdbTemp, ByteOffsetIsSkipped) {
  write("r.hea", "r 1 360 2\nr.dat 16+4 200 16 0 0 0 0\n");
  write("r.dat", bytes_of({0xAA, 0xAA, 0xAA, 0xAA, 0x02, 0x00, 0x03, 0x00}));
  auto s = read_signals(record("r"));
  ASSERT_TRUE(s) << s.error().message;
  EXPECT_EQ(s->samples[0], (std::vector<std::int32_t>{2, 3}));
}

TEST_F(WfdbTemp, BadGainFieldIsAnErrorNamingFileLineAndField) {
  write("r.hea", "r 1 360 2\r\n# comment\r\nr.dat 212 2x0 11 1024 0 0 0 MLII\r\n");
  auto h = read_header(record("r"));
  ASSERT_FALSE(h);
  const std::string& m = h.error().message;
  EXPECT_NE(m.find("r.hea:3"), std::string::npos) << m;
  EXPECT_NE(m.find("'gain'"), std::string::npos) << m;
  EXPECT_NE(m.find("2x0"), std::string::npos) << m;
}

TEST_F(WfdbTemp, BadSamplingFrequencyIsAnErrorNamingTheField) {
  write("r.hea", "r 1 fast 2\nr.dat 16\n");
  auto h = read_header(record("r"));
  ASSERT_FALSE(h);
  EXPECT_NE(h.error().message.find("r.hea:1: field 'sampling frequency'"), std::string::npos)
      << h.error().message;
  // Readers and the detector hold seconds of signal: a rate of 1e9 took all the memory there is.
  write("r.hea", "r 1 1e9 2\nr.dat 16\n");
  h = read_header(record("r"));
  ASSERT_FALSE(h);
  EXPECT_NE(h.error().message.find("r.hea:1: field 'sampling frequency' ('1e9'): more than 100000 Hz"), std::string::npos)
      << h.error().message;
}

// The counter frequency, base counter, base time and date are not used, but a record line that
// does not parse there is refused, as any other field is (docs/wfdb.md): "hello" as a time and
// "45/13/2003" as a date were read without a word.
TEST_F(WfdbTemp, RecordLineFieldsThatDoNotParseAreRefusedNamingTheField) {
  write("r.dat", bytes_of({0x05, 0x00}));
  // A counter frequency that is not positive is the sampling frequency (WFDB's header(5)).
  for (const char* line : {"r 1 360/10(0) 1 13:5:0 24/12/2003", "r 1 360/10 1 0:00:00.250", "r 1 360(-3) 1 59.5",
                           "r 1 360 1 10:30:15", "r 1 360/0 1", "r 1 360/ 1", "r 1 360 1 10:00:00 1/1/2000 more text"}) {
    write("r.hea", std::string(line) + "\nr.dat 16\n");
    auto h = read_header(record("r"));
    EXPECT_TRUE(h) << line << ": " << h.error().message;
  }
  const std::pair<const char*, const char*> refused[] = {
      {"r 1 360 1 hello", "r.hea:1: field 'base time' ('hello')"},
      {"r 1 360 1 99:99:99 1/1/2000", "r.hea:1: field 'base time' ('99:99:99')"},
      {"r 1 360 1 10:00:00 45/13/2003", "r.hea:1: field 'base date' ('45/13/2003')"},
      {"r 1 360/x 1", "r.hea:1: field 'sampling frequency' ('360/x'): the counter frequency"},
      {"r 1 360() 1", "r.hea:1: field 'sampling frequency' ('360()'): the base counter"},
      // A count too large for the reader is said to be so, not "not a non-negative integer".
      {"r 1 360 100000000000000000000", "r.hea:1: field 'number of samples per signal' ('100000000000000000000'): out of range: "
                                        "at most 9223372036854775807"},
      {"r 1 360 -5", "r.hea:1: field 'number of samples per signal' ('-5'): not a non-negative integer"},
      // A lone carriage return inside the line is shown, not printed raw beside a valid number.
      {"r 1 360 650000\r 10:00:00", "r.hea:1: field 'number of samples per signal' ('650000\\x0D'): not a non-negative integer"},
      {"r 99999999999 360 1", "r.hea:1: field 'number of signals' ('99999999999'): out of range: at most 2147483647"},
  };
  for (const auto& [line, expected] : refused) {
    write("r.hea", std::string(line) + "\nr.dat 16\n");
    auto h = read_header(record("r"));
    ASSERT_FALSE(h) << line;
    EXPECT_NE(h.error().message.find(expected), std::string::npos) << h.error().message;
  }
}

TEST_F(WfdbTemp, UnsupportedFormatIsAnErrorNamingFileLineFieldAndFormat) {
  write("r.hea", "r 1 360 2\nr.dat 99 200 10 0 0 0 0\n");
  auto h = read_header(record("r"));
  ASSERT_FALSE(h);
  const std::string& m = h.error().message;
  EXPECT_NE(m.find("r.hea:2: field 'format'"), std::string::npos) << m;
  EXPECT_NE(m.find("99 is not supported (supported: 8, 16, 24, 32, 61, 80, 160, 212, 310, 311)"), std::string::npos) << m;
  EXPECT_FALSE(read_signals(record("r")));
  // FLAC-compressed files (WFDB 10.7) are named as such, with what to do.
  write("z.hea", "z 1 360 2\nz.dat 516 200 16 0 0 0 0\n");
  auto z = read_header(record("z"));
  ASSERT_FALSE(z);
  EXPECT_NE(z.error().message.find("516 is not supported"), std::string::npos) << z.error().message;
  EXPECT_NE(z.error().message.find("FLAC-compressed: write the record out uncompressed"), std::string::npos) << z.error().message;
}

TEST_F(WfdbTemp, MissingSignalLinesAreAnError) {
  write("r.hea", "r 2 360 2\nr.dat 16\n");
  auto h = read_header(record("r"));
  ASSERT_FALSE(h);
  EXPECT_NE(h.error().message.find("announces 2 signals, found 1"), std::string::npos)
      << h.error().message;
}

// A record line that undercounts the signals of an interleaved file: read as one signal, every
// frame of two would be read at half its width (a heart rate of half the truth, no error). One
// more signal line of a file the header's signals are in is refused; an info string without
// '#' after the signal lines is still ignored, as WFDB does.
TEST_F(WfdbTemp, ARecordLineThatUndercountsAFilesSignalsIsAnError) {
  write("r.hea", "r 1 360 2\nr.dat 16 200 16 0 0 0 0 MLII\nr.dat 16 200 16 0 0 0 0 V1\n");
  auto h = read_header(record("r"));
  ASSERT_FALSE(h);
  EXPECT_NE(h.error().message.find("r.hea:3: record line announces 1 signal, but this line is one more signal of r.dat"),
            std::string::npos)
      << h.error().message;
  write("r.hea", "r 1 360 2\nr.dat 16 200 16 0 0 0 0 MLII\nrecorded at the bedside\nother.dat 16\n");
  EXPECT_TRUE(read_header(record("r"))) << "an info string, and a line of another file, are not signals of r.dat";
}

// A header whose sample count was cut short: the samples after it are not read, as WFDB's
// tools do not read them, and that is said; before, only a checksum mismatch showed, which
// reads as a file in the wrong format. Format 212's one value of padding is not "more".
TEST_F(WfdbTemp, SamplesAfterTheHeadersCountAreNamedAsNotRead) {
  write("r.hea", "r 1 100 100\nr.dat 16 200 16 0 0 0 0 MLII\n");
  write("r.dat", std::string(2 * 200, '\0'));
  auto h = read_header(record("r"));
  ASSERT_TRUE(h) << h.error().message;
  const std::vector<std::string> unread = unread_samples(*h);
  ASSERT_EQ(unread.size(), 1u);
  EXPECT_NE(unread[0].find("r.dat holds 200 samples per signal, the header " + record("r") +
                           ".hea says 100: the last 100 are not read"),
            std::string::npos)
      << unread[0];
  // A checksum (of the 200) then differs: the count is named as the cause, not the format.
  write("r.hea", "r 1 100 100\nr.dat 16 200 16 0 0 7 0 MLII\n");
  write("r.dat", std::string(2 * 100, '\0') + std::string(2 * 100, '\x01'));
  h = read_header(record("r"));
  ASSERT_TRUE(h) << h.error().message;
  auto mismatches = checksum_mismatches(*h, {0});
  ASSERT_EQ(mismatches.size(), 1u);
  EXPECT_NE(mismatches[0].find("(the header's sample count leaves samples of r.dat unread: is it right?)"), std::string::npos)
      << mismatches[0];
  write("r.dat", std::string(2 * 100, '\0'));
  mismatches = checksum_mismatches(*h, {0});
  ASSERT_EQ(mismatches.size(), 1u);
  EXPECT_NE(mismatches[0].find("(is r.dat in format 16?)"), std::string::npos) << mismatches[0];
  EXPECT_TRUE(unread_samples(*h).empty());
  write("r.hea", "r 1 100 101\nr.dat 212 200 12 0 0 0 0 MLII\n");
  write("r.dat", std::string(153, '\0'));  // 51 pairs of values: 101 and one of padding
  h = read_header(record("r"));
  ASSERT_TRUE(h) << h.error().message;
  EXPECT_TRUE(unread_samples(*h).empty());
}

TEST_F(WfdbTemp, MissingHeaderIsAnErrorNamingTheFile) {
  auto h = read_header(record("nothere"));
  ASSERT_FALSE(h);
  EXPECT_NE(h.error().message.find("nothere.hea"), std::string::npos);
}

TEST_F(WfdbTemp, TruncatedDatIsAnErrorWithExpectedAndFoundCounts) {
  write("r.hea", "r 2 360 4\nr.dat 212 200 11 1024 0 0 0\nr.dat 212 200 11 1024 0 0 0\n");
  write("r.dat", std::string(3 * 3, '\0'));  // 3 of 4 frames
  auto s = read_signals(record("r"));
  ASSERT_FALSE(s);
  const std::string& m = s.error().message;
  EXPECT_NE(m.find("r.dat"), std::string::npos) << m;
  EXPECT_NE(m.find("expected 4 samples per signal, found 3"), std::string::npos) << m;
  EXPECT_FALSE(SignalReader::open(record("r")));
}

TEST_F(WfdbTemp, FileShrinkingAfterOpenIsAnErrorNotAShortRead) {
  write("r.hea", "r 1 360 4\nr.dat 16\n");
  write("r.dat", std::string(8, '\0'));
  auto r = SignalReader::open(record("r"));
  ASSERT_TRUE(r) << r.error().message;
  fs::resize_file(dir_ / "r.dat", 4);  // 2 of the 4 samples remain
  std::vector<std::vector<std::int32_t>> out;
  auto n = r->read(4, out);
  ASSERT_FALSE(n);
  EXPECT_NE(n.error().message.find("expected 4 samples per signal, found 2"), std::string::npos)
      << n.error().message;
  EXPECT_TRUE(out.empty() || out[0].empty()) << "no partial chunk appended after an error";
  EXPECT_FALSE(r->read(1, out)) << "the error is sticky";
}

TEST_F(WfdbTemp, MissingDatIsAnErrorNamingTheFile) {
  write("r.hea", "r 1 360 4\nmissing.dat 16\n");
  auto s = read_signals(record("r"));
  ASSERT_FALSE(s);
  EXPECT_NE(s.error().message.find("missing.dat"), std::string::npos);
}

TEST_F(WfdbTemp, RandomlyCorruptedHeaderGivesAResultOrAnErrorNeverACrash) {
  const std::string good =
      "r 2 360 4\r\nr.dat 212 200 11 1024 995 -22131 0 MLII\r\nr.dat 212 200 11 1024 1011 20052 0 V5\r\n";
  write("r.dat", std::string(12, '\x11'));
  std::mt19937 rng(11);
  const std::string alphabet = "0123456789 +-/()x:.#\r\nabc\xff";
  for (int round = 0; round < 500; ++round) {
    std::string text = good;
    for (int k = 0; k < 3; ++k) text[rng() % text.size()] = alphabet[rng() % alphabet.size()];
    write("r.hea", text);
    auto s = read_signals(record("r"));
    if (s) {
      for (const auto& v : s->samples) EXPECT_EQ(v.size(), s->samples.front().size());
    } else {
      // Every error names a file of the record (the header, or the signal file it names).
      EXPECT_EQ(s.error().message.rfind(dir_.string(), 0), 0u) << s.error().message;
    }
  }
}

TEST_F(WfdbTemp, HugeSampleCountIsATruncationErrorNotAnAllocation) {
  write("r.hea", "r 1 360 9000000000000000000\nr.dat 212\n");
  write("r.dat", std::string(3, '\0'));
  auto s = read_signals(record("r"));
  ASSERT_FALSE(s);
  EXPECT_NE(s.error().message.find("truncated"), std::string::npos) << s.error().message;
}

// A header saying format 16 over data written in 212 (3 bytes a pair of samples, not 4) was
// called truncated and nothing more: the file is whole, its header wrong. The size says which.
TEST_F(WfdbTemp, AHeaderWhoseFormatDoesNotFitTheFileSaysTheFormatTheSizeFits) {
  write("r.hea", "r 2 360 1000\nr.dat 16 200 12 0 0 0 0 I\nr.dat 16 200 12 0 0 0 0 II\n");
  write("r.dat", std::string(3000, '\0'));  // 2 x 1000 samples in format 212
  auto s = read_signals(record("r"));
  ASSERT_FALSE(s);
  EXPECT_NE(s.error().message.find(": truncated: expected 1000 samples per signal, found 750 (3000 bytes); its size is what "
                                   "format 212 takes for that many: is the header's format (16) that of the file?"),
            std::string::npos) << s.error().message;
  write("r.dat", std::string(2000, '\0'));  // cut short in either format: no hint
  s = read_signals(record("r"));
  ASSERT_FALSE(s);
  EXPECT_EQ(s.error().message.find("format 212 takes"), std::string::npos) << s.error().message;
  // Behind a byte offset the bytes said are those after it (the whole file's size was given,
  // and a misplaced offset read as a file cut short).
  write("r.hea", "r 2 360 1000\nr.dat 16+1 200 12 0 0 0 0 I\nr.dat 16+1 200 12 0 0 0 0 II\n");
  write("r.dat", std::string(4000, '\0'));
  s = read_signals(record("r"));
  ASSERT_FALSE(s);
  EXPECT_NE(s.error().message.find(": truncated: expected 1000 samples per signal, found 999 (3999 bytes after the header's byte "
                                   "offset 1, of 4000)"),
            std::string::npos) << s.error().message;
}

// A byte offset past the end of the file was "truncated: … found 0", naming neither the offset
// nor the header; a device as the signal file "cannot stat signal file: Operation not supported".
TEST_F(WfdbTemp, AnOffsetPastTheFileAndASignalFileThatIsNoFileAreNamedSo) {
  write("r.hea", "r 1 360 100\nr.dat 16+5000 200 12 0 0 0 0 I\n");
  write("r.dat", std::string(200, '\0'));
  auto s = read_signals(record("r"));
  ASSERT_FALSE(s);
  EXPECT_NE(s.error().message.find("r.hea: signal 0: its byte offset (+5000 in 16+5000) is past the end of r.dat (200 bytes)"),
            std::string::npos) << s.error().message;
  write("r.hea", "r 1 360 100\n/dev/zero 16 200 12 0 0 0 0 I\n");
  s = read_signals(record("r"));
  ASSERT_FALSE(s);
  EXPECT_NE(s.error().message.find("/dev/zero: the signal file is not a regular file"), std::string::npos) << s.error().message;
  // A pipe with no writer: refused at once, not waited on for ever.
  write("r.hea", "r 1 360 100\nr.fifo 16 200 12 0 0 0 0 I\n");
  ASSERT_EQ(::mkfifo((dir_ / "r.fifo").c_str(), 0600), 0);
  s = read_signals(record("r"));
  ASSERT_FALSE(s);
  EXPECT_NE(s.error().message.find("r.fifo: the signal file is not a regular file"), std::string::npos) << s.error().message;
}

TEST_F(WfdbTemp, MultiSegmentRecordIsRefused) {
  write("r.hea", "r/3 1 360 4\n");
  auto h = read_header(record("r"));
  ASSERT_FALSE(h);
  EXPECT_NE(h.error().message.find("multi-segment"), std::string::npos);
}

}  // namespace
}  // namespace tahvel::aggregation
