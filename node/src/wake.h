// Waking without polling: a small file beside the store ("wake"), mapped shared by every
// process of the node. It holds slots of 32-bit sequence words: slot 0 changes on every commit
// (watchers), slot k for the agents whose IRI hashes to k (input buffers). A writer bumps the
// slots it affected after its commit and calls FUTEX_WAKE only when the slot's waiter count is
// non-zero, so a write with nobody asleep costs no system call. Collisions only cause a
// spurious wake-up; the woken side re-checks its buffer.
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <filesystem>
#include <string_view>

#include "tahvel/node/error.h"

namespace tahvel::node::detail {

class WakeBoard {
 public:
  static constexpr std::uint32_t kSlots = 1024;
  static constexpr std::uint32_t kAnyCommit = 0;

  WakeBoard() = default;
  WakeBoard(const WakeBoard&) = delete;
  WakeBoard& operator=(const WakeBoard&) = delete;
  ~WakeBoard();

  Result<void> open(const std::filesystem::path& file);

  static std::uint32_t slot_for(std::string_view agent_iri);

  // Waiter protocol: token = prepare(slot); re-check the condition; if still unmet,
  // wait(slot, token, timeout); always finish(slot). A bump between prepare and wait makes wait
  // return at once, so no wake-up is lost.
  std::uint32_t prepare(std::uint32_t slot);
  void wait(std::uint32_t slot, std::uint32_t token, std::chrono::nanoseconds timeout);
  void finish(std::uint32_t slot);

  // Writer side, after commit.
  void bump(std::uint32_t slot);

  // The commit slot (kAnyCommit), after a commit that grew the change stream. Watchers sleep on
  // it with plain FUTEX_WAIT and are woken by every such commit; a thread waiting for input
  // buffers (wait_buffers) only by commits that routed an item into one (`buffers_changed`) and
  // by wake_buffer_waiters. Its waiter count is shared, so the wake call is made either way.
  void bump_commit(bool buffers_changed);
  // kAnyCommit's word moves and every waiter on it wakes, the buffer waiters included.
  void wake_buffer_waiters() { bump_commit(true); }

  // As wait(kAnyCommit, ...), but woken only by commits that changed an input buffer (or a
  // change of the word before the sleep began).
  void wait_buffers(std::uint32_t token, std::chrono::nanoseconds timeout);

  // The slot's sequence word now (it changes at every bump).
  std::uint32_t version(std::uint32_t slot) const;

 private:
  struct Shared {
    std::atomic<std::uint32_t> seq[kSlots];
    std::atomic<std::uint32_t> waiters[kSlots];
  };
  Shared* shared_ = nullptr;
};

}  // namespace tahvel::node::detail
