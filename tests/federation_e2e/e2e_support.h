// Shell commands and bounded waits shared by the end-to-end tests of this folder.
#pragma once
#include <sys/wait.h>

#include <chrono>
#include <cstdio>
#include <string>
#include <thread>

namespace tahvel::e2e {

struct Output {
  int status = -1;  // exit status; -1 when the command could not run or was killed
  std::string out;
};

// Runs a shell command line; its standard output is captured, standard error passed through.
inline Output run(const std::string& command) {
  Output result;
  FILE* pipe = popen(command.c_str(), "r");
  if (!pipe) return result;
  char buffer[65536];
  std::size_t n;
  while ((n = fread(buffer, 1, sizeof buffer, pipe)) > 0) result.out.append(buffer, n);
  int status = pclose(pipe);
  result.status = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return result;
}

// Asks `condition` every 200 ms until it holds or `limit` has passed; its last answer.
template <class F>
bool eventually(F condition, std::chrono::milliseconds limit = std::chrono::seconds(120)) {
  const auto deadline = std::chrono::steady_clock::now() + limit;
  while (std::chrono::steady_clock::now() < deadline) {
    if (condition()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
  }
  return condition();
}

}  // namespace tahvel::e2e
