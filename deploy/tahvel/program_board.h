// A node's programs on its board (agents/supervisor.h, "on the board"), written by a thread of
// its own. The write waits for the store's writer lock, which a bulk `tahvel load` holds for
// seconds and a writer stopped inside its transaction holds for ever: the supervisor's loop
// (restarts, its state file, `down`) and the other nodes' boards must not wait with it.
#pragma once

#include <chrono>
#include <filesystem>
#include <functional>
#include <memory>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include "tahvel/agents/supervisor.h"

namespace tahvel::cli {

class ProgramBoard {
 public:
  using Log = std::function<void(std::string_view)>;
  // Writes to the store in `store` (opened at the first write) as its agent `supervisor`; a
  // failure is logged once, until the next write succeeds.
  ProgramBoard(std::filesystem::path store, std::string node_id, Log log);
  // Drops what waits to be posted (a node taken out of the deployment: its programs were
  // stopped, and another supervisor may run it next) and finishes without waiting; a write
  // under way is left to its thread, which ends with the process.
  ~ProgramBoard();
  ProgramBoard(const ProgramBoard&) = delete;
  ProgramBoard& operator=(const ProgramBoard&) = delete;

  // Replaces what waits to be written: only the newest list of programs matters.
  void post(std::vector<agents::ProgramState> programs);
  // How long the write under way has waited so far; zero when none is under way.
  std::chrono::steady_clock::duration waiting() const;
  // Whether a write has ended since the last post or the thread began, and succeeded.
  bool last_write_succeeded() const;
  // Waits up to `limit` for what was posted to be written, then ends the thread; false when a
  // write still waits (its thread is left to finish on its own).
  bool finish(std::chrono::milliseconds limit);

 private:
  struct Shared;
  std::shared_ptr<Shared> shared_;
  std::thread thread_;
};

}  // namespace tahvel::cli
