// MIT-format annotation reading: record 100's reference annotations, read in place, against the
// published counts and first annotations; synthetic files for every pseudo-annotation word and
// for truncation; the beat and unreadable-interval helpers.
#include "tahvel/aggregation/annotations.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>
#include <vector>

#include "mitdb_support.h"

namespace tahvel::aggregation {
namespace {

namespace fs = std::filesystem;
using testing::mitdb_dir;
using testing::mitdb_record;

// Builds annotation file bytes word by word.
struct AtrWriter {
  std::string bytes;
  AtrWriter& word(unsigned w) {
    bytes.push_back(static_cast<char>(w & 0xFF));
    bytes.push_back(static_cast<char>((w >> 8) & 0xFF));
    return *this;
  }
  AtrWriter& ann(int type, unsigned delta) { return word((unsigned(type) << 10) | delta); }
  AtrWriter& skip(std::int32_t interval) {
    auto u = static_cast<std::uint32_t>(interval);
    return word(59u << 10).word(u >> 16).word(u & 0xFFFF);
  }
  AtrWriter& num(unsigned v) { return word((60u << 10) | v); }
  AtrWriter& sub(unsigned v) { return word((61u << 10) | v); }
  AtrWriter& chn(unsigned v) { return word((62u << 10) | v); }
  AtrWriter& aux(const std::string& s) {
    word((63u << 10) | static_cast<unsigned>(s.size()));
    bytes += s;
    if (s.size() % 2) bytes.push_back('\0');
    return *this;
  }
  AtrWriter& end() { return word(0); }
};

class AnnotTemp : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    dir_ = fs::temp_directory_path() /
           ("tahvel-annot-" + std::to_string(::getpid()) + "-" + info->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string write(const std::string& bytes, const std::string& ext = "atr") const {
    std::ofstream(dir_ / ("r." + ext), std::ios::binary) << bytes;
    return (dir_ / "r").string();
  }
  fs::path dir_;
};

// ---- record 100 ----

TEST(AnnotRecord100, Has2274AnnotationsOf2273Beats) {
  if (!fs::exists(mitdb_dir() / "100.atr")) GTEST_SKIP() << "MIT-BIH not found";
  auto a = read_annotations(mitdb_record("100"));
  ASSERT_TRUE(a) << a.error().message;
  EXPECT_EQ(a->size(), 2274u);
  EXPECT_EQ(std::count_if(a->begin(), a->end(), [](const Annotation& x) { return is_beat(x.code); }),
            2273);
  EXPECT_TRUE(std::is_sorted(a->begin(), a->end(),
                             [](const Annotation& x, const Annotation& y) { return x.sample < y.sample; }));
  EXPECT_LT(a->back().sample, 650000);
}

TEST(AnnotRecord100, FirstIsRhythmPlusAtSample18ThenNormalBeatAt77) {
  if (!fs::exists(mitdb_dir() / "100.atr")) GTEST_SKIP() << "MIT-BIH not found";
  // Independently: the file's first word is 0x7012 = type 28 ('+') << 10 | 18, followed by an
  // AUX word of 3 bytes "(N\0" and a pad byte; then 0x043B = type 1 ('N') << 10 | 59.
  std::ifstream in(mitdb_dir() / "100.atr", std::ios::binary);
  unsigned char b[10];
  in.read(reinterpret_cast<char*>(b), 10);
  ASSERT_EQ(in.gcount(), 10);
  EXPECT_EQ(b[0] | (b[1] << 8), (28 << 10) | 18);
  EXPECT_EQ(b[2] | (b[3] << 8), (63 << 10) | 3);
  EXPECT_EQ(b[8] | (b[9] << 8), (1 << 10) | 59);

  auto a = read_annotations(mitdb_record("100"));
  ASSERT_TRUE(a) << a.error().message;
  ASSERT_GE(a->size(), 3u);
  EXPECT_EQ((*a)[0].code, '+');
  EXPECT_EQ((*a)[0].type, 28);
  EXPECT_EQ((*a)[0].sample, 18);
  EXPECT_EQ((*a)[0].aux, "(N");
  EXPECT_EQ((*a)[1].code, 'N');
  EXPECT_EQ((*a)[1].sample, 77);
  EXPECT_TRUE((*a)[1].aux.empty());
  EXPECT_EQ((*a)[2].code, 'N');
}

TEST(AnnotRecord100, HasNoUnreadableIntervals) {
  if (!fs::exists(mitdb_dir() / "100.atr")) GTEST_SKIP() << "MIT-BIH not found";
  auto a = read_annotations(mitdb_record("100"));
  ASSERT_TRUE(a) << a.error().message;
  EXPECT_TRUE(unreadable_intervals(*a, 650000).empty());
}

// ---- synthetic files ----

TEST_F(AnnotTemp, PseudoWordsSetFieldsNumAndChanCarryOverSubtypeAndAuxDoNot) {
  AtrWriter w;
  w.ann(1, 10).num(3).chn(1).sub(2).aux("hi!")  // N at 10, num 3, chan 1, subtype 2, aux "hi!"
      .ann(5, 20)                               // V at 30 inherits num 3, chan 1
      .skip(100000)                             // SKIP forward
      .ann(14, 5).sub(0x30)                     // ~ at 100035
      .ann(14, 7)                               // ~ at 100042
      .ann(0, 3)                                // null annotation at 100045
      .end();
  auto a = read_annotations(write(w.bytes));
  ASSERT_TRUE(a) << a.error().message;
  ASSERT_EQ(a->size(), 5u);
  EXPECT_EQ((*a)[0].sample, 10);
  EXPECT_EQ((*a)[0].num, 3);
  EXPECT_EQ((*a)[0].chan, 1);
  EXPECT_EQ((*a)[0].subtype, 2);
  EXPECT_EQ((*a)[0].aux, "hi!");
  EXPECT_EQ((*a)[1].code, 'V');
  EXPECT_EQ((*a)[1].sample, 30);
  EXPECT_EQ((*a)[1].num, 3);
  EXPECT_EQ((*a)[1].chan, 1);
  EXPECT_EQ((*a)[1].subtype, 0);
  EXPECT_TRUE((*a)[1].aux.empty());
  EXPECT_EQ((*a)[2].sample, 100035);
  EXPECT_EQ((*a)[2].code, '~');
  EXPECT_EQ((*a)[2].subtype, 0x30);
  EXPECT_EQ((*a)[3].sample, 100042);
  EXPECT_EQ((*a)[4].type, 0);
  EXPECT_EQ((*a)[4].sample, 100045);
  auto u = unreadable_intervals(*a, 200000);
  ASSERT_EQ(u.size(), 1u);
  EXPECT_EQ(u[0], (std::pair<std::int64_t, std::int64_t>{100035, 100042}));
}

TEST_F(AnnotTemp, SkipIntervalIsHighWordFirst) {
  AtrWriter w;
  w.skip(0x00012345).ann(1, 0).end();  // high word 0x0001, low word 0x2345
  auto a = read_annotations(write(w.bytes));
  ASSERT_TRUE(a) << a.error().message;
  ASSERT_EQ(a->size(), 1u);
  EXPECT_EQ((*a)[0].sample, 0x12345);
}

// A negative SKIP that takes the time back before the last annotation: read, it scored the
// detector against a reference out of order (TP 1, FP 150) without a word.
TEST_F(AnnotTemp, AnnotationsOutOfTimeOrderAreRefusedNamingWhere) {
  AtrWriter w;
  w.ann(1, 500).skip(-100).ann(1, 0).end();
  auto a = read_annotations(write(w.bytes));
  ASSERT_FALSE(a);
  EXPECT_NE(a.error().message.find("r.atr: byte 8: annotation at sample 400 comes after one at sample 500"), std::string::npos)
      << a.error().message;
  AtrWriter ties;  // annotations at one sample (on several channels) are in order
  ties.ann(1, 500).ann(1, 0).end();
  EXPECT_TRUE(read_annotations(write(ties.bytes)));
}

// Annotations written in 1/1000 s (WFDB 10.5's setafreq, with its note at time 0) were read as
// samples: most reference beats fell past the record's end. They are converted to the record's
// samples; without a frequency to convert to they stay as written.
TEST_F(AnnotTemp, ATimeResolutionNoteConvertsTheTimesToTheRecordsSamples) {
  AtrWriter w;
  w.ann(22, 0).aux("## time resolution: 1000")  // NOTE at 0
      .ann(1, 1000)                              // N at 1.000 s
      .ann(1, 1001)                              // N at 2.001 s
      .end();
  const std::string record = write(w.bytes);
  auto at_360 = read_annotations(record, "atr", 360);
  ASSERT_TRUE(at_360) << at_360.error().message;
  ASSERT_EQ(at_360->size(), 3u);
  EXPECT_EQ((*at_360)[1].sample, 360);
  EXPECT_EQ((*at_360)[2].sample, 720);  // 2.001 s x 360 = 720.36
  auto as_written = read_annotations(record, "atr");
  ASSERT_TRUE(as_written) << as_written.error().message;
  EXPECT_EQ((*as_written)[2].sample, 2001);
  AtrWriter bad;
  bad.ann(22, 0).aux("## time resolution: none").ann(1, 10).end();
  auto refused = read_annotations(write(bad.bytes), "atr", 360);
  ASSERT_FALSE(refused);
  EXPECT_NE(refused.error().message.find("does not give a frequency above 0"), std::string::npos) << refused.error().message;
}

// WFDB's getann reads the unassigned types 50..58 as annotations; here they stopped the record.
TEST_F(AnnotTemp, AnUnassignedAnnotationTypeIsReadAsAnAnnotationThatIsNoBeat) {
  AtrWriter w;
  w.ann(1, 10).ann(50, 5).ann(58, 5).ann(1, 5).end();
  auto a = read_annotations(write(w.bytes));
  ASSERT_TRUE(a) << a.error().message;
  ASSERT_EQ(a->size(), 4u);
  EXPECT_EQ((*a)[1].type, 50);
  EXPECT_EQ((*a)[1].code, 0);
  EXPECT_FALSE(is_beat((*a)[2].code));
  EXPECT_EQ((*a)[3].sample, 25);
}

TEST_F(AnnotTemp, OtherAnnotatorNameSelectsTheExtension) {
  AtrWriter w;
  w.ann(1, 42).end();
  auto a = read_annotations(write(w.bytes, "qrs"), "qrs");
  ASSERT_TRUE(a) << a.error().message;
  ASSERT_EQ(a->size(), 1u);
  EXPECT_EQ((*a)[0].sample, 42);
}

TEST_F(AnnotTemp, MissingEndWordIsATruncationError) {
  AtrWriter w;
  w.ann(1, 10).ann(1, 10);
  auto a = read_annotations(write(w.bytes));
  ASSERT_FALSE(a);
  EXPECT_NE(a.error().message.find("r.atr: byte 4: truncated"), std::string::npos)
      << a.error().message;
}

TEST_F(AnnotTemp, TruncatedInsideWordSkipOrAuxIsAnErrorNamingTheFile) {
  AtrWriter half;
  half.ann(1, 10);
  half.bytes.push_back('\x01');
  AtrWriter skip;
  skip.ann(1, 10).word(59u << 10).word(0);  // 2 of the 4 interval bytes
  AtrWriter aux;
  aux.ann(1, 10).word((63u << 10) | 6);
  aux.bytes += "abc";  // 3 of 6 bytes
  for (const auto* w : {&half, &skip, &aux}) {
    auto a = read_annotations(write(w->bytes));
    ASSERT_FALSE(a);
    EXPECT_NE(a.error().message.find("r.atr"), std::string::npos) << a.error().message;
    EXPECT_NE(a.error().message.find("truncated"), std::string::npos) << a.error().message;
  }
}

TEST_F(AnnotTemp, TruncatedRecord100PrefixIsAnErrorNotACrash) {
  if (!fs::exists(mitdb_dir() / "100.atr")) GTEST_SKIP() << "MIT-BIH not found";
  std::ifstream in(mitdb_dir() / "100.atr", std::ios::binary);
  std::string all((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  for (std::size_t cut : {std::size_t{1}, std::size_t{3}, std::size_t{5}, all.size() / 2,
                          all.size() - 1}) {
    auto a = read_annotations(write(all.substr(0, cut)));
    EXPECT_FALSE(a) << "cut at " << cut;
  }
}

TEST_F(AnnotTemp, RandomlyCorruptedRecord100GivesAResultOrAnErrorNeverACrash) {
  if (!fs::exists(mitdb_dir() / "100.atr")) GTEST_SKIP() << "MIT-BIH not found";
  std::ifstream in(mitdb_dir() / "100.atr", std::ios::binary);
  const std::string all((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  std::mt19937 rng(7);
  for (int round = 0; round < 200; ++round) {
    std::string bytes = all;
    for (int k = 0; k < 8; ++k) bytes[rng() % bytes.size()] = static_cast<char>(rng() & 0xFF);
    auto a = read_annotations(write(bytes));
    if (a) {
      for (const auto& x : *a) ASSERT_GE(x.sample, 0);
    } else {
      EXPECT_NE(a.error().message.find("r.atr"), std::string::npos) << a.error().message;
    }
  }
}

TEST_F(AnnotTemp, MissingFileIsAnErrorNamingIt) {
  auto a = read_annotations((dir_ / "none").string());
  ASSERT_FALSE(a);
  EXPECT_NE(a.error().message.find("none.atr"), std::string::npos);
}

// ---- helpers ----

TEST(AnnotCodes, BeatCodesAreExactlyTheNineteenBeatMnemonics) {
  const std::string beats = "NLRBAaJSVrFejnE/fQ?";
  for (int c = 1; c < 128; ++c)
    EXPECT_EQ(is_beat(static_cast<char>(c)), beats.find(static_cast<char>(c)) != std::string::npos)
        << "code '" << static_cast<char>(c) << "'";
  EXPECT_FALSE(is_beat('!'));
}

TEST(AnnotCodes, MnemonicsRoundTripAndFollowEcgcodes) {
  EXPECT_EQ(annotation_code(1), 'N');
  EXPECT_EQ(annotation_code(14), '~');
  EXPECT_EQ(annotation_code(28), '+');
  EXPECT_EQ(annotation_code(31), '!');
  EXPECT_EQ(annotation_code(41), 'r');
  EXPECT_EQ(annotation_code(45), 0);
  for (int t = 1; t < 50; ++t) {
    if (char c = annotation_code(t)) {
      EXPECT_EQ(annotation_type(c), t) << c;
    }
  }
  EXPECT_EQ(annotation_type('`'), 39);
  EXPECT_EQ(annotation_type('\''), 40);
  EXPECT_EQ(annotation_type('Z'), -1);
}

Annotation make(std::int64_t sample, char code, int subtype = 0) {
  Annotation a;
  a.sample = sample;
  a.code = code;
  a.type = annotation_type(code);
  a.subtype = subtype;
  return a;
}

TEST(AnnotUnreadable, OnlyNoiseWithBits4And5OpensAndNextNoiseCloses) {
  std::vector<Annotation> a = {make(100, '~', 0x10),  // bit 4 only: not unreadable
                               make(200, '~', 0x20),  // bit 5 only: not unreadable
                               make(300, '~', 0x30), make(350, 'N'), make(400, '~', 0x01),
                               make(500, '~', 0x3F), make(600, '~', 0x30)};
  auto u = unreadable_intervals(a, 1000);
  ASSERT_EQ(u.size(), 2u);
  EXPECT_EQ(u[0], (std::pair<std::int64_t, std::int64_t>{300, 400}));
  EXPECT_EQ(u[1], (std::pair<std::int64_t, std::int64_t>{500, 600}));
}

TEST(AnnotUnreadable, IntervalLeftOpenRunsToRecordEnd) {
  std::vector<Annotation> a = {make(100, 'N'), make(300, '~', 0x30), make(350, 'N')};
  auto u = unreadable_intervals(a, 1000);
  ASSERT_EQ(u.size(), 1u);
  EXPECT_EQ(u[0], (std::pair<std::int64_t, std::int64_t>{300, 1000}));
}

// What `tahvel hrv --eval` warns of: the last interval never closed, with beats after its marker.
TEST(AnnotUnreadable, AnIntervalNeverClosedIsFoundWithTheBeatsAfterIt) {
  auto open = unclosed_unreadable({make(100, 'N'), make(300, '~', 0x30), make(350, 'N'), make(400, 'V')});
  ASSERT_TRUE(open);
  EXPECT_EQ(open->opened_at, 300);
  EXPECT_EQ(open->beats_after, 2u);
  EXPECT_FALSE(unclosed_unreadable({make(100, 'N'), make(300, '~', 0x30), make(350, 'N'), make(400, '~', 0)}));
  EXPECT_FALSE(unclosed_unreadable({make(100, 'N'), make(300, '~', 0x30)}));  // nothing after it
  EXPECT_FALSE(unclosed_unreadable({make(100, 'N'), make(300, '~', 0x10), make(350, 'N')}));  // no marker
}

TEST(AnnotFlutter, EpisodeRunsFromOpenBracketToCloseBracket) {
  std::vector<Annotation> a = {make(10, 'N'), make(20, '['), make(30, '!'), make(40, ']'),
                               make(90, '[')};
  auto f = flutter_intervals(a, 100);
  ASSERT_EQ(f.size(), 2u);
  EXPECT_EQ(f[0], (std::pair<std::int64_t, std::int64_t>{20, 40}));
  EXPECT_EQ(f[1], (std::pair<std::int64_t, std::int64_t>{90, 100}));
}

}  // namespace
}  // namespace tahvel::aggregation
