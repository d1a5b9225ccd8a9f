// Something of a node opened on a thread of its own: a node's area keeper and dispatcher
// subscribe their agents when they open, a write that waits for the store's writer lock, which
// another process may hold for seconds (a bulk `tahvel load`) or for ever (a writer stopped
// inside its transaction). The supervisor's loop (restarts, `up`, `down`, the other nodes)
// must not wait with it; program_board.h is the same for the node's programs.
#pragma once

#include <chrono>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <system_error>
#include <thread>
#include <utility>

namespace tahvel::cli {

// R: what opening gives (a Result).
template <class R>
class Opening {
 public:
  // Runs `open` at once on a new thread; it must own what it uses (the thread may outlive this
  // object). Where no thread can be had (a task limit), it runs here.
  explicit Opening(std::function<R()> open) : shared_(std::make_shared<Shared>()) {
    auto run = [shared = shared_, open]() mutable {
      auto result = open();
      open = nullptr;  // its captures go with this thread, not with the last owner of `shared`
      std::lock_guard lock(shared->mutex);
      shared->result.emplace(std::move(result));
    };
    try {
      thread_ = std::thread(run);
    } catch (const std::system_error&) {
      run();
    }
  }
  // One still opening is left to its thread, which ends with the process or drops what it
  // opened.
  ~Opening() {
    if (!thread_.joinable()) return;
    if (ended()) thread_.join();
    else thread_.detach();
  }
  Opening(const Opening&) = delete;
  Opening& operator=(const Opening&) = delete;

  bool ended() const {
    std::lock_guard lock(shared_->mutex);
    return shared_->result.has_value();
  }
  // Waits up to `limit` for opening to end; true when it has.
  bool wait(std::chrono::milliseconds limit) const {
    const auto deadline = std::chrono::steady_clock::now() + limit;
    while (!ended()) {
      if (std::chrono::steady_clock::now() >= deadline) return false;
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    return true;
  }
  // What opening gave, once it has ended (then the thread is joined); nullopt before.
  std::optional<R> take() {
    std::optional<R> out;
    {
      std::lock_guard lock(shared_->mutex);
      if (!shared_->result) return out;
      out = std::move(shared_->result);
      shared_->result.reset();
    }
    if (thread_.joinable()) thread_.join();
    return out;
  }
  std::chrono::steady_clock::duration waited() const { return std::chrono::steady_clock::now() - began_; }

 private:
  struct Shared {
    mutable std::mutex mutex;
    std::optional<R> result;
  };
  std::shared_ptr<Shared> shared_;
  std::thread thread_;
  std::chrono::steady_clock::time_point began_ = std::chrono::steady_clock::now();
};

}  // namespace tahvel::cli
