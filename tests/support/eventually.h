// Polls a condition until it holds or a deadline passes: a test waits on what it checks rather
// than sleeping and hoping. Links and stores deliver within milliseconds; the deadline only
// bounds a failing test. Shared by every test suite (tests/support is on their include path).
#pragma once

#include <chrono>
#include <thread>

namespace tahvel::test_support {

// Asks `condition` every `every` until it holds or `limit` has passed; its last answer.
template <class F>
bool eventually(F condition, std::chrono::milliseconds limit = std::chrono::seconds(20),
                std::chrono::milliseconds every = std::chrono::milliseconds(10)) {
  const auto deadline = std::chrono::steady_clock::now() + limit;
  while (std::chrono::steady_clock::now() < deadline) {
    if (condition()) return true;
    std::this_thread::sleep_for(every);
  }
  return condition();
}

}  // namespace tahvel::test_support
