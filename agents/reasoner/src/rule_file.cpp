// RuleFile (rule_file.h): a rule file's changes, told by its stat fields and, while a read may
// have missed a write of the same timestamp tick, by its bytes.
#include "tahvel/agents/rule_file.h"

#include <sys/stat.h>

#include <chrono>
#include <cstdlib>

namespace tahvel::reasoner {

RuleFile::RuleFile(std::filesystem::path path, StatFn stat, ClockFn now)
    : path_(std::move(path)), stat_(std::move(stat)), now_(std::move(now)) {}

std::optional<RuleFile::Stamp> RuleFile::stat_of(const std::filesystem::path& path) {
  struct stat st;
  if (::stat(path.c_str(), &st) != 0) return std::nullopt;
  auto ns = [](const timespec& t) { return std::int64_t{t.tv_sec} * 1'000'000'000 + t.tv_nsec; };
  return Stamp{st.st_dev, st.st_ino, st.st_size, ns(st.st_mtim), ns(st.st_ctim)};
}

std::int64_t RuleFile::wall_clock_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch())
      .count();
}

// A read at `at` may have missed a write of the same tick as `stamp`'s mtime. One far in the
// future (a clock set back, files unpacked with later times) is not: any write now gets an
// mtime of now, which differs from it.
bool RuleFile::racy(std::int64_t at, const Stamp& stamp) const {
  return std::llabs(at - stamp.mtime_ns) < kRacyNs;
}

Result<std::string> RuleFile::read() {
  const std::int64_t at = now_();
  stamp_ = stat_(path_);
  auto text = read_rule_file(path_);
  bytes_ = text ? std::optional<std::string>(*text) : std::nullopt;
  racy_ = stamp_ && racy(at, *stamp_);
  return text;
}

bool RuleFile::changed() {
  const std::int64_t at = now_();
  const std::optional<Stamp> now = stat_(path_);
  if (now != stamp_) return true;
  if (!racy_) return false;
  auto text = read_rule_file(path_);
  if (!text || !bytes_) return text.has_value() != bytes_.has_value();
  if (*text != *bytes_) return true;
  // Read again, unchanged, once the tick is over: a later write moves the stamp.
  if (!racy(at, *now)) racy_ = false;
  return false;
}

}  // namespace tahvel::reasoner
