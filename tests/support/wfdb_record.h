// Writes a one-lead WFDB record in format 16 (header and signal file, with the checksum), for
// tests that need a recording other than MIT-BIH's: synthetic ECG, WFDB's no-value samples.
// Shared by every test suite (tests/support is on their include path).
#pragma once

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

namespace tahvel::test_support {

// `dir`/`name`.hea and .dat: samples at 360 Hz, gain 200 adu/mV, 16-bit ADC, baseline 0, lead
// "ECG". Returns the record's path without extension (what WFDB readers take).
inline std::string write_format16_record(const std::filesystem::path& dir, const std::string& name,
                                         const std::vector<std::int32_t>& samples) {
  std::string bytes;
  std::uint16_t sum = 0;
  for (std::int32_t v : samples) {
    const auto u = static_cast<std::uint16_t>(static_cast<std::int16_t>(v));
    bytes.push_back(static_cast<char>(u & 0xFF));
    bytes.push_back(static_cast<char>(u >> 8));
    sum = static_cast<std::uint16_t>(sum + u);
  }
  std::ofstream(dir / (name + ".dat"), std::ios::binary) << bytes;
  std::ofstream(dir / (name + ".hea")) << name << " 1 360 " << samples.size() << "\n"
                                       << name << ".dat 16 200 16 1024 " << (samples.empty() ? 0 : samples.front()) << " "
                                       << static_cast<std::int16_t>(sum) << " 0 ECG\n";
  return (dir / name).string();
}

}  // namespace tahvel::test_support
