// Where the shared MIT-BIH records are: $TAHVEL_MITDB, else ../shared/data/mitdb beside the
// checkout. Tests read them in place; the project never copies them.
#pragma once

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

namespace tahvel::aggregation::testing {

inline std::filesystem::path mitdb_dir() {
  if (const char* env = std::getenv("TAHVEL_MITDB"); env && *env) return env;
  return std::filesystem::path(TAHVEL_SOURCE_DIR) / ".." / "shared" / "data" / "mitdb";
}

// The record names listed in RECORDS (empty when the directory is missing).
inline std::vector<std::string> mitdb_records() {
  std::vector<std::string> names;
  std::ifstream in(mitdb_dir() / "RECORDS");
  for (std::string line; std::getline(in, line);) {
    while (!line.empty() && (line.back() == '\r' || line.back() == ' ')) line.pop_back();
    if (!line.empty()) names.push_back(line);
  }
  return names;
}

// Path of a record without extension, as WFDB tools take it ("…/mitdb/100").
inline std::string mitdb_record(const std::string& name) { return (mitdb_dir() / name).string(); }

}  // namespace tahvel::aggregation::testing
