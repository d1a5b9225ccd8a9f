// Futex-based waking across processes; see wake.h.
#include "wake.h"

#include <fcntl.h>
#include <linux/futex.h>
#include <sys/mman.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <cerrno>
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
  void* p = mmap(nullptr, sizeof(Shared), PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
  int err = errno;
  ::close(fd);
  if (p == MAP_FAILED) return fail(Errc::io, "cannot map " + file.string() + ": " + std::strerror(err));
  shared_ = static_cast<Shared*>(p);
  return {};
}

std::uint32_t WakeBoard::slot_for(std::string_view agent_iri) {
  return 1 + static_cast<std::uint32_t>(codec::hash64(agent_iri) % (kSlots - 1));
}

std::uint32_t WakeBoard::prepare(std::uint32_t slot) {
  shared_->waiters[slot].fetch_add(1, std::memory_order_seq_cst);
  return shared_->seq[slot].load(std::memory_order_seq_cst);
}

void WakeBoard::wait(std::uint32_t slot, std::uint32_t token, std::chrono::nanoseconds timeout) {
  if (timeout.count() <= 0) return;
  timespec ts{static_cast<time_t>(timeout.count() / 1'000'000'000),
              static_cast<long>(timeout.count() % 1'000'000'000)};
  // Not FUTEX_PRIVATE: the word lives in a file mapping shared between processes.
  syscall(SYS_futex, reinterpret_cast<std::uint32_t*>(&shared_->seq[slot]), FUTEX_WAIT, token, &ts,
          nullptr, 0);
}

void WakeBoard::finish(std::uint32_t slot) {
  shared_->waiters[slot].fetch_sub(1, std::memory_order_seq_cst);
}

namespace {
// FUTEX_WAIT_BITSET masks on the commit word: plain FUTEX_WAIT waiters (watchers) match every
// mask; a buffer waiter sleeps on kBuffersBit only.
constexpr std::uint32_t kWatchersBit = 1;
constexpr std::uint32_t kBuffersBit = 2;
}  // namespace

void WakeBoard::bump_commit(bool buffers_changed) {
  shared_->seq[kAnyCommit].fetch_add(1, std::memory_order_seq_cst);
  if (shared_->waiters[kAnyCommit].load(std::memory_order_seq_cst) != 0) {
    syscall(SYS_futex, reinterpret_cast<std::uint32_t*>(&shared_->seq[kAnyCommit]), FUTEX_WAKE_BITSET, INT32_MAX,
            nullptr, nullptr, buffers_changed ? FUTEX_BITSET_MATCH_ANY : kWatchersBit);
  }
}

void WakeBoard::wait_buffers(std::uint32_t token, std::chrono::nanoseconds timeout) {
  if (timeout.count() <= 0) return;
  // FUTEX_WAIT_BITSET takes an absolute CLOCK_MONOTONIC deadline.
  timespec now{};
  clock_gettime(CLOCK_MONOTONIC, &now);
  const std::int64_t end = static_cast<std::int64_t>(now.tv_sec) * 1'000'000'000 + now.tv_nsec + timeout.count();
  timespec deadline{static_cast<time_t>(end / 1'000'000'000), static_cast<long>(end % 1'000'000'000)};
  syscall(SYS_futex, reinterpret_cast<std::uint32_t*>(&shared_->seq[kAnyCommit]), FUTEX_WAIT_BITSET, token,
          &deadline, nullptr, kBuffersBit);
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
