// Futex-based waking across processes; see wake.h.
#include "wake.h"

#include <fcntl.h>
#include <linux/futex.h>
#include <sys/mman.h>
#include <sched.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>

#include "codec.h"

namespace tahvel::node::detail {

static_assert(std::atomic<std::uint32_t>::is_always_lock_free);

WakeBoard::~WakeBoard() {
  if (shared_) munmap(shared_, sizeof(Shared));
}

Result<void> WakeBoard::open(const std::filesystem::path& file) {
  int fd = ::open(file.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
  if (fd < 0) return fail(Errc::io, "cannot open " + file.string() + ": " + std::strerror(errno));
  // A new file reads as zeros once extended: exactly the initial state of every slot.
  if (ftruncate(fd, sizeof(Shared)) != 0) {
    int err = errno;
    ::close(fd);
    return fail(Errc::io, "cannot size " + file.string() + ": " + std::strerror(err));
  }
  // Its blocks allocated now: ftruncate allocates none, and on a full disk the first write
  // into the map was SIGBUS. Where the filesystem cannot (EOPNOTSUPP), as before.
  int rc = 0;
  do rc = fallocate(fd, 0, 0, sizeof(Shared)) == 0 ? 0 : errno;
  while (rc == EINTR);
  if (rc == ENOSPC) {
    ::close(fd);
    return fail(Errc::store_full, "the disk holding " + file.string() + " has no room for it (" +
                                      std::to_string(sizeof(Shared) >> 10) + " KB): free some space on it and try again");
  }
  void* p = mmap(nullptr, sizeof(Shared), PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
  int err = errno;
  ::close(fd);
  if (p == MAP_FAILED) return fail(Errc::io, "cannot map " + file.string() + ": " + std::strerror(err));
  shared_ = static_cast<Shared*>(p);
  return {};
}

Result<void> WakeBoard::open_private() {
  void* p = mmap(nullptr, sizeof(Shared), PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
  if (p == MAP_FAILED) return fail(Errc::io, std::string("cannot map a wake board: ") + std::strerror(errno));
  shared_ = static_cast<Shared*>(p);
  return {};
}

std::uint32_t WakeBoard::slot_for(std::string_view agent_iri) {
  return 1 + static_cast<std::uint32_t>(codec::hash64(agent_iri) % (kSlots - 1));
}

namespace {

// How this thread's recent sleeps ended: a thread whose last kQuietAfter spins all ran out
// waits on a quiet word and goes straight to the futex, spinning only every kProbeEvery-th time
// to notice that its stream got busy.
struct SpinRecord {
  unsigned misses = 0;
  unsigned sleeps = 0;
};
thread_local SpinRecord t_spin;
constexpr unsigned kQuietAfter = 4;
constexpr unsigned kProbeEvery = 64;

std::chrono::nanoseconds read_spin_budget() {
  const char* text = std::getenv("TAHVEL_SPIN_US");
  if (!text || !*text) return WakeBoard::kDefaultSpin;
  char* end = nullptr;
  errno = 0;
  const long long us = std::strtoll(text, &end, 10);
  if (errno != 0 || *end != '\0' || us < 0) {
    std::fprintf(stderr, "tahvel: TAHVEL_SPIN_US='%s' is not a whole number of microseconds; spinning up to %lld us\n",
                 text, static_cast<long long>(WakeBoard::kDefaultSpin.count()));
    return WakeBoard::kDefaultSpin;
  }
  return std::chrono::microseconds(std::min<long long>(us, 100'000));
}

inline void cpu_relax() {
#if defined(__x86_64__) || defined(__i386__)
  __builtin_ia32_pause();
#elif defined(__aarch64__)
  asm volatile("yield");
#endif
}

// True when `word` moved past `token` within `budget`. Every few looks it yields: on a machine
// of two cores a spinning reader must not keep the thread it waits for off the CPU.
bool spin_until_moved(const std::atomic<std::uint32_t>& word, std::uint32_t token, std::chrono::nanoseconds budget) {
  const auto end = std::chrono::steady_clock::now() + budget;
  for (unsigned i = 1;; ++i) {
    if (word.load(std::memory_order_acquire) != token) return true;
    cpu_relax();
    if (i % 16 == 0) {
      if (std::chrono::steady_clock::now() >= end) return false;
      sched_yield();
    }
  }
}

std::atomic<std::int64_t> g_spin_ns{-1};  // -1: not read from the environment yet

}  // namespace

std::chrono::nanoseconds WakeBoard::spin_budget() {
  std::int64_t ns = g_spin_ns.load(std::memory_order_relaxed);
  if (ns < 0) {
    ns = read_spin_budget().count();
    g_spin_ns.store(ns, std::memory_order_relaxed);
  }
  return std::chrono::nanoseconds(ns);
}

void WakeBoard::set_spin_budget(std::chrono::nanoseconds budget) {
  g_spin_ns.store(std::max<std::int64_t>(budget.count(), 0), std::memory_order_relaxed);
}

bool WakeBoard::sleep(std::uint32_t slot, std::uint32_t token, std::chrono::nanoseconds timeout) {
  if (timeout.count() <= 0) return false;
  std::atomic<std::uint32_t>& word = shared_->seq[slot];
  const std::chrono::nanoseconds budget = std::min(spin_budget(), timeout);
  SpinRecord& record = t_spin;
  ++record.sleeps;
  if (budget.count() > 0 && (record.misses < kQuietAfter || record.sleeps % kProbeEvery == 0)) {
    if (spin_until_moved(word, token, budget)) {
      record.misses = 0;
      return false;
    }
    ++record.misses;
    timeout -= budget;
    if (timeout.count() <= 0) return false;
  }
  // Counted a waiter before the word is read again (both sequentially consistent): either the
  // writer sees the count and wakes this thread, or this thread sees the word moved.
  shared_->waiters[slot].fetch_add(1, std::memory_order_seq_cst);
  bool interrupted = false;
  if (word.load(std::memory_order_seq_cst) == token) {
    timespec ts{static_cast<time_t>(timeout.count() / 1'000'000'000),
                static_cast<long>(timeout.count() % 1'000'000'000)};
    // Not FUTEX_PRIVATE: the word lives in a file mapping shared between processes.
    interrupted = syscall(SYS_futex, reinterpret_cast<std::uint32_t*>(&word), FUTEX_WAIT, token, &ts, nullptr, 0) != 0 &&
                  errno == EINTR;
  }
  shared_->waiters[slot].fetch_sub(1, std::memory_order_seq_cst);
  return interrupted;
}

namespace {
// FUTEX_WAIT_BITSET masks on the commit word: plain FUTEX_WAIT waiters (watchers) match every
// mask; a buffer waiter sleeps on kBuffersBit only.
constexpr std::uint32_t kWatchersBit = 1;
constexpr std::uint32_t kBuffersBit = 2;
// A buffer waiter's unit in the commit slot's waiter count (wake.h, Shared).
constexpr std::uint32_t kBufferWaiter = 1u << 16;
constexpr std::uint32_t kWatcherCount = kBufferWaiter - 1;  // the mask of the watchers' part
}  // namespace

void WakeBoard::bump_commit(bool buffers_changed) {
  shared_->seq[kAnyCommit].fetch_add(1, std::memory_order_seq_cst);
  const std::uint32_t waiting = shared_->waiters[kAnyCommit].load(std::memory_order_seq_cst);
  if ((waiting & kWatcherCount) != 0 || (buffers_changed && waiting != 0)) {
    syscall(SYS_futex, reinterpret_cast<std::uint32_t*>(&shared_->seq[kAnyCommit]), FUTEX_WAKE_BITSET, INT32_MAX,
            nullptr, nullptr, buffers_changed ? FUTEX_BITSET_MATCH_ANY : kWatchersBit);
  }
}

bool WakeBoard::sleep_buffers(std::uint32_t token, std::chrono::nanoseconds timeout) {
  if (timeout.count() <= 0) return false;
  shared_->waiters[kAnyCommit].fetch_add(kBufferWaiter, std::memory_order_seq_cst);
  if (shared_->seq[kAnyCommit].load(std::memory_order_seq_cst) != token) {
    shared_->waiters[kAnyCommit].fetch_sub(kBufferWaiter, std::memory_order_seq_cst);
    return false;
  }
  // FUTEX_WAIT_BITSET takes an absolute CLOCK_MONOTONIC deadline.
  timespec now{};
  clock_gettime(CLOCK_MONOTONIC, &now);
  const std::int64_t end = static_cast<std::int64_t>(now.tv_sec) * 1'000'000'000 + now.tv_nsec + timeout.count();
  timespec deadline{static_cast<time_t>(end / 1'000'000'000), static_cast<long>(end % 1'000'000'000)};
  const bool interrupted = syscall(SYS_futex, reinterpret_cast<std::uint32_t*>(&shared_->seq[kAnyCommit]), FUTEX_WAIT_BITSET,
                                  token, &deadline, nullptr, kBuffersBit) != 0 &&
                          errno == EINTR;
  shared_->waiters[kAnyCommit].fetch_sub(kBufferWaiter, std::memory_order_seq_cst);
  return interrupted;
}

std::uint32_t WakeBoard::version(std::uint32_t slot) const {
  return shared_->seq[slot].load(std::memory_order_seq_cst);
}

void WakeBoard::bump(std::uint32_t slot) {
  shared_->seq[slot].fetch_add(1, std::memory_order_seq_cst);
  // A waiter killed while asleep leaves its count behind: that costs spurious FUTEX_WAKE calls,
  // never a missed wake-up.
  if (shared_->waiters[slot].load(std::memory_order_seq_cst) != 0) {
    syscall(SYS_futex, reinterpret_cast<std::uint32_t*>(&shared_->seq[slot]), FUTEX_WAKE, INT32_MAX,
            nullptr, nullptr, 0);
  }
}

}  // namespace tahvel::node::detail
