// Tells when a rule file changed since the reasoner last read it (docs/reasoner.md, RS15).
//
// Its stat fields (device, inode, size, modification and change times) tell most changes, but not
// one written within the file system's timestamp resolution of a read: that keeps both times (a
// save that truncates and then writes, read in between, left a reasoner on the empty file for
// good). So while the last read was less than kRacyNs after the file's modification time, the
// bytes are compared too, as git does for "racily clean" index entries.
//
//   RuleFile file("alerts.rules");
//   auto text = file.read();          // the bytes now; remembers what they were
//   ...
//   if (file.changed()) text = file.read();
#pragma once

#include <sys/types.h>

#include <cstdint>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>

#include "tahvel/agents/rules.h"

namespace tahvel::reasoner {

class RuleFile {
 public:
  struct Stamp {
    dev_t device = 0;
    ino_t inode = 0;
    off_t size = 0;
    std::int64_t mtime_ns = 0, ctime_ns = 0;
    bool operator==(const Stamp&) const = default;
  };
  // The file's stamp, nullopt when it cannot be stat'ed (removed); and the wall clock, ns since
  // the epoch. Replaceable for tests.
  using StatFn = std::function<std::optional<Stamp>(const std::filesystem::path&)>;
  using ClockFn = std::function<std::int64_t()>;

  // How long after a file's modification a read may still miss a write of the same tick: FAT's
  // resolution is 2 s, ext4's with small inodes 1 s, most others' a clock tick.
  static constexpr std::int64_t kRacyNs = 2'000'000'000;

  explicit RuleFile(std::filesystem::path path, StatFn stat = stat_of, ClockFn now = wall_clock_ns);

  const std::filesystem::path& path() const { return path_; }

  // The file's bytes now (read_rule_file's errors). The stamp is taken before them: a write
  // during the read shows as a change.
  Result<std::string> read();

  // Whether the file differs from what read() last returned. A file that could not be read, and
  // still cannot, has not changed.
  bool changed();

  static std::optional<Stamp> stat_of(const std::filesystem::path& path);
  static std::int64_t wall_clock_ns();

 private:
  bool racy(std::int64_t at, const Stamp& stamp) const;

  std::filesystem::path path_;
  StatFn stat_;
  ClockFn now_;
  std::optional<Stamp> stamp_;
  std::optional<std::string> bytes_;  // nullopt: the last read failed
  bool racy_ = false;
};

}  // namespace tahvel::reasoner
