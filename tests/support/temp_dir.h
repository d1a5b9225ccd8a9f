// A temporary directory for one test, removed with everything in it when the test ends. Shared
// by every test suite (tests/CMakeLists.txt puts tests/support on their include path). Declare
// it before the members that use it (stores, agents) so that it is removed after them.
#pragma once

#include <stdlib.h>

#include <filesystem>
#include <stdexcept>
#include <string>

namespace tahvel::test_support {

class TempDir {
 public:
  explicit TempDir(const std::string& prefix = "tahvel-test") {
    std::string pattern = (std::filesystem::temp_directory_path() / (prefix + "-XXXXXX")).string();
    if (!mkdtemp(pattern.data())) throw std::runtime_error("cannot create " + pattern);
    path_ = pattern;
  }
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
  ~TempDir() {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  const std::filesystem::path& path() const { return path_; }
  std::filesystem::path operator/(const std::string& name) const { return path_ / name; }

 private:
  std::filesystem::path path_;
};

}  // namespace tahvel::test_support
