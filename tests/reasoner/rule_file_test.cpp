// RuleFile (tahvel/agents/rule_file.h): when a reasoner's rule file counts as changed. The stat
// fields and the clock are replaced here, so that a rewrite the stat fields cannot show (one in
// the same timestamp tick as the read) is made at will.
#include "tahvel/agents/rule_file.h"

#include <gtest/gtest.h>

#include <fstream>

#include "temp_dir.h"

namespace {

namespace fs = std::filesystem;
using tahvel::reasoner::RuleFile;

constexpr std::int64_t kSecond = 1'000'000'000;
constexpr std::int64_t kModified = 1'800'000'000 * kSecond;

class RuleFileTest : public ::testing::Test {
 protected:
  void write(const std::string& text) { std::ofstream(path_, std::ios::trunc) << text; }
  // A file whose stat fields never move: every change is one of the same tick.
  RuleFile frozen() {
    return RuleFile(
        path_, [](const fs::path& p) -> std::optional<RuleFile::Stamp> {
          if (!fs::exists(p)) return std::nullopt;
          return RuleFile::Stamp{1, 2, 20, kModified, kModified};
        },
        [this] { return now_; });
  }

  tahvel::test_support::TempDir tmp_{"tahvel-rule-file"};
  const fs::path path_ = tmp_.path() / "alerts.rules";
  std::int64_t now_ = kModified + kSecond / 2;
};

TEST_F(RuleFileTest, ARewriteInTheTickOfTheReadIsAChangeByItsBytes) {
  write("p(X, Y) :- a(X, Y).\n");
  RuleFile file = frozen();
  ASSERT_TRUE(file.read());
  EXPECT_FALSE(file.changed());
  write("q(X, Y) :- a(X, Y).\n");  // same size, same stamp
  EXPECT_TRUE(file.changed());
  ASSERT_EQ(*file.read(), "q(X, Y) :- a(X, Y).\n");
  EXPECT_FALSE(file.changed());
}

// Once a read is a resolution after the file's modification, a write moves the stamp: the bytes
// are no longer read (at every session, for ever). Here the stamp is frozen, so the rewrite
// goes unseen, which shows that they are not.
TEST_F(RuleFileTest, BytesAreComparedOnlyWhileAReadMayHaveMissedAWrite) {
  write("p(X, Y) :- a(X, Y).\n");
  RuleFile file = frozen();
  ASSERT_TRUE(file.read());
  now_ = kModified + 3 * kSecond;
  EXPECT_FALSE(file.changed());  // read once more, unchanged: settled
  write("q(X, Y) :- a(X, Y).\n");
  EXPECT_FALSE(file.changed());
}

// A modification time far in the future (a clock set back, a file unpacked with later times) is
// not a read in the same tick: any write now gets another mtime.
TEST_F(RuleFileTest, AModificationTimeFarInTheFutureIsNoReasonToReadTheBytes) {
  write("p(X, Y) :- a(X, Y).\n");
  now_ = kModified - 3600 * kSecond;
  RuleFile file = frozen();
  ASSERT_TRUE(file.read());
  write("q(X, Y) :- a(X, Y).\n");
  EXPECT_FALSE(file.changed());
}

// A file that could not be read and still cannot is no change (the reasoner would report the
// same error at every session); once it can be read, it is.
TEST_F(RuleFileTest, AFileThatStillCannotBeReadHasNotChanged) {
  RuleFile file(path_);
  EXPECT_FALSE(file.read());
  EXPECT_FALSE(file.changed());
  write("p(X, Y) :- a(X, Y).\n");
  EXPECT_TRUE(file.changed());
  EXPECT_TRUE(file.read());
  fs::remove(path_);
  EXPECT_TRUE(file.changed());
}

}  // namespace
