// Shell commands and bounded waits shared by the end-to-end tests of this folder.
#pragma once
#include <sys/wait.h>

#include <chrono>
#include <cstdio>
#include <string>
#include <thread>

#include "eventually.h"

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

// Asks `condition` every 200 ms (it runs commands) until it holds or `limit` has passed.
template <class F>
bool eventually(F condition, std::chrono::milliseconds limit = std::chrono::seconds(120)) {
  return test_support::eventually(condition, limit, std::chrono::milliseconds(200));
}

}  // namespace tahvel::e2e
