// Smoke test of `tahvel bench store --quick --json`: the bench runs end to end (Tahvel, SQLite,
// Sord, the socket floor), prints one JSON object with every figure the issue asks for as a
// number, and removes its scratch stores. It asserts nothing about speed: figures are printed
// for people to judge, never checked against the clock (STYLE 8).
#include <gtest/gtest.h>
#include <stdlib.h>
#include <sys/wait.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <regex>
#include <string>

namespace {

namespace fs = std::filesystem;

const char* const kRequiredKeys[] = {
    "item_writes_per_s",
    "item10_writes_per_s",
    "bulk_triples_per_s",
    "query_s_p50_us",
    "query_s_p99_us",
    "query_p_p50_us",
    "query_p_p99_us",
    "query_range_p50_us",
    "query_range_p99_us",
    "wake_p50_us",
    "wake_p99_us",
    "bytes_per_triple",
    "sqlite_item_writes_per_s",
    "sqlite_default_item_writes_per_s",
    "sqlite_query_s_p50_us",
    "sqlite_query_s_p99_us",
    "sqlite_query_p_p50_us",
    "sqlite_query_p_p99_us",
    "sqlite_query_range_p50_us",
    "sord_bulk_triples_per_s",
    "unix_socket_p50_us",
    "ratio_items_vs_sqlite",
    "ratio_bulk_vs_sord",
};

struct BenchRun {
  int status = -1;
  std::string out;
};

BenchRun run_command(const std::string& command) {
  BenchRun r;
  FILE* pipe = popen(command.c_str(), "r");
  if (!pipe) return r;
  char buf[4096];
  for (std::size_t n; (n = std::fread(buf, 1, sizeof buf, pipe)) > 0;) r.out.append(buf, n);
  r.status = pclose(pipe);
  return r;
}

// Reads the value of "key": <number> from a flat JSON object; false when absent.
bool number_of(const std::string& json, const std::string& key, double& value) {
  std::smatch m;
  const std::regex re("\"" + key + "\"\\s*:\\s*(-?[0-9][0-9.eE+-]*)");
  if (!std::regex_search(json, m, re)) return false;
  char* end = nullptr;
  value = std::strtod(m[1].str().c_str(), &end);
  return end && *end == '\0';
}

TEST(BenchSmoke, QuickJsonHasEveryFigure) {
  std::string dir = (fs::temp_directory_path() / "tahvel-bench-smoke-XXXXXX").string();
  ASSERT_NE(mkdtemp(dir.data()), nullptr);
  BenchRun r = run_command(std::string(TAHVEL_BIN_DIR) +
                           "/tahvel bench store --quick --json --dir '" + dir + "'");
  ASSERT_TRUE(WIFEXITED(r.status)) << r.out;
  ASSERT_EQ(WEXITSTATUS(r.status), 0) << r.out;
  ASSERT_FALSE(r.out.empty());
  EXPECT_EQ(r.out.front(), '{') << r.out;
  EXPECT_NE(r.out.find('}'), std::string::npos) << r.out;
  for (const char* key : kRequiredKeys) {
    double value = -1;
    EXPECT_TRUE(number_of(r.out, key, value)) << "missing or not a number: " << key << "\n"
                                              << r.out;
    EXPECT_GE(value, 0) << key;
  }
  double records = 0;
  ASSERT_TRUE(number_of(r.out, "store_records", records)) << r.out;
  EXPECT_GT(records, 0);
  EXPECT_TRUE(fs::is_empty(dir)) << "the bench left files in " << dir;
  fs::remove_all(dir);
}

TEST(BenchSmoke, RejectsUnknownArgument) {
  BenchRun r = run_command(std::string(TAHVEL_BIN_DIR) + "/tahvel bench store --no-such-flag 2>&1");
  ASSERT_TRUE(WIFEXITED(r.status));
  EXPECT_EQ(WEXITSTATUS(r.status), 2) << r.out;
  EXPECT_NE(r.out.find("--no-such-flag"), std::string::npos) << r.out;
}

}  // namespace
