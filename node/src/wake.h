// Waking without polling: a small file beside the store ("wake"), mapped shared by every
// process of the node. It holds slots of 32-bit sequence words: slot 0 changes on every commit
// (watchers), slot k for the agents whose IRI hashes to k (input buffers). A writer bumps the
// slots it affected after its commit and calls FUTEX_WAKE only when the slot's waiter count is
// non-zero, so a write with nobody asleep costs no system call. Collisions only cause a
// spurious wake-up; the woken side re-checks its buffer.
//
// A waiter first watches its word for a short while before it sleeps (see sleep()): on this
// kind of machine (virtual CPUs) a futex wake-up costs tens of µs on each side, the waker's
// FUTEX_WAKE included, while a word seen moving costs well under one.
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
  // A board of this process only, for a store that cannot be written (on a read-only
  // filesystem): nothing commits there, so a sleeper just sleeps out its timeout.
  Result<void> open_private();

  static std::uint32_t slot_for(std::string_view agent_iri);

  // Waiter protocol: token = version(slot); check the condition; if unmet,
  // sleep(slot, token, timeout), and check again. A bump after version() moves the word past
  // `token` and sleep returns at once, so no wake-up is lost.
  //
  // sleep() first spins on the word for up to spin_budget() while this thread's recent sleeps
  // were ended by a bump within that budget (a busy stream: the spin saves both wake-ups); a
  // thread whose waits run long (a quiet buffer) goes straight to the futex, bar an occasional
  // probe, and costs no CPU. Only then does it count itself a waiter, so a writer whose readers
  // are all spinning makes no system call.
  //
  // Returns true when a signal handler ran during the sleep (EINTR: one installed without
  // SA_RESTART): the caller returns as on a timeout, so that a program whose handler set a stop
  // flag sees it instead of waiting on.
  bool sleep(std::uint32_t slot, std::uint32_t token, std::chrono::nanoseconds timeout);

  // Writer side, after commit.
  void bump(std::uint32_t slot);

  // The commit slot (kAnyCommit), after a commit that grew the change stream. Watchers sleep on
  // it with plain FUTEX_WAIT and are woken by every such commit; a thread waiting for input
  // buffers (sleep_buffers) only by commits that routed an item into one (`buffers_changed`) and
  // by wake_buffer_waiters. The two kinds are counted apart, so that a commit routing nothing
  // makes no system call for a parent's down pump asleep on the slot (one per relayed run).
  void bump_commit(bool buffers_changed);
  // kAnyCommit's word moves and every waiter on it wakes, the buffer waiters included.
  void wake_buffer_waiters() { bump_commit(true); }

  // As sleep(kAnyCommit, ...), but woken only by commits that changed an input buffer (or a
  // change of the word before the sleep began). It never spins: the word moves at every commit,
  // and its one user (a parent's down pump) would spin through a hospital's whole ingest.
  bool sleep_buffers(std::uint32_t token, std::chrono::nanoseconds timeout);

  // The slot's sequence word now (it changes at every bump).
  std::uint32_t version(std::uint32_t slot) const;

  // How long sleep() may spin: TAHVEL_SPIN_US in the environment (0: never), read once;
  // default kDefaultSpin.
  static constexpr std::chrono::microseconds kDefaultSpin{200};
  static std::chrono::nanoseconds spin_budget();
  // Overrides it for this process (tests compare both ways).
  static void set_spin_budget(std::chrono::nanoseconds budget);

 private:
  struct Shared {
    std::atomic<std::uint32_t> seq[kSlots];
    // [kAnyCommit] counts both kinds of its waiters: watchers in the low 16 bits, threads in
    // sleep_buffers from bit 16 (kBufferWaiter). The file keeps its size, so a process of an
    // older version on the same store (which counts both as 1) still wakes and is woken.
    std::atomic<std::uint32_t> waiters[kSlots];
  };
  Shared* shared_ = nullptr;
};

}  // namespace tahvel::node::detail
