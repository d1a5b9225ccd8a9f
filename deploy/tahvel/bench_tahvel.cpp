// Store-to-wake latency across processes for `tahvel bench store` (see bench_tahvel.h).
// The writer waits for the subscriber's "taken" count on a futex of its own, outside every
// timed span, so that back-to-back probes alternate like the socket ping-pong they are
// compared with.
#include "bench_tahvel.h"

#include <linux/futex.h>
#include <signal.h>
#include <sys/mman.h>
#include <sys/syscall.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <functional>
#include <thread>

#include "bench_mix.h"

namespace tahvel::cli::bench {
namespace {

using namespace std::chrono_literals;
using node::Term;

const char* kProbe = "http://example.org/vocab#wakeProbe";

// The memory shared with the subscriber: a header, then the send and wake times.
struct WakeBoard {
  std::atomic<int> state{0};  // 0 starting, 1 subscribed, 2 failed
  std::atomic<std::uint32_t> received{0};  // probes taken; a futex word the writer sleeps on
  std::size_t samples = 0;  // probes sent, the first `warmup` of them not counted
  std::size_t warmup = 0;
  char error[512] = {};

  std::int64_t* sent() { return reinterpret_cast<std::int64_t*>(this + 1); }
  std::int64_t* returned() { return sent() + samples; }  // when store() returned
  std::int64_t* woke() { return sent() + 2 * samples; }
};

class SharedBoard {
 public:
  explicit SharedBoard(std::size_t samples)
      : bytes_(sizeof(WakeBoard) + 3 * samples * sizeof(std::int64_t)) {
    void* p = mmap(nullptr, bytes_, PROT_READ | PROT_WRITE, MAP_SHARED | MAP_ANONYMOUS, -1, 0);
    if (p != MAP_FAILED) {
      board_ = new (p) WakeBoard;
      board_->samples = samples;
    }
  }
  ~SharedBoard() {
    if (board_) munmap(board_, bytes_);
  }
  WakeBoard* get() const { return board_; }

 private:
  std::size_t bytes_;
  WakeBoard* board_ = nullptr;
};

// Kills and reaps the forked subscriber if the parent returns early.
class Child {
 public:
  explicit Child(pid_t pid) : pid_(pid) {}
  ~Child() {
    if (pid_ > 0) {
      kill(pid_, SIGKILL);
      waitpid(pid_, nullptr, 0);
    }
  }
  bool alive() {
    if (pid_ <= 0) return false;
    if (waitpid(pid_, nullptr, WNOHANG) == pid_) pid_ = -1;
    return pid_ > 0;
  }
  void reap() {
    if (pid_ > 0) waitpid(pid_, nullptr, 0);
    pid_ = -1;
  }

 private:
  pid_t pid_;
};

long futex(std::atomic<std::uint32_t>* word, int op, std::uint32_t value) {
  timespec limit{0, 1'000'000};  // re-check the child and the deadline every millisecond
  return syscall(SYS_futex, reinterpret_cast<std::uint32_t*>(word), op, value,
                 op == FUTEX_WAIT ? &limit : nullptr, nullptr, 0);
}

bool report(WakeBoard* b, const std::string& message) {
  std::snprintf(b->error, sizeof b->error, "%s", message.c_str());
  b->state.store(2);
  return false;
}

std::uint64_t probe_index(const node::Delivery& d) {
  for (const node::Record& r : d.records) {
    if (r.triple.p.value == kProbe) return std::strtoull(r.triple.o.value.c_str(), nullptr, 10);
  }
  return ~0ull;
}

bool run_subscriber(const std::filesystem::path& dir, WakeBoard* b) {
  auto node = node::Node::open(dir);
  if (!node) return report(b, node.error().message);
  auto agent = node->agent("sink");
  if (!agent) return report(b, agent.error().message);
  node::Pattern pattern;
  pattern.p = Term::iri(kProbe);
  if (auto sub = agent->subscribe(pattern); !sub) return report(b, sub.error().message);
  b->state.store(1);
  while (b->received.load() < b->samples) {
    auto delivery = agent->take(5000ms, node::Ack::manual);
    const std::int64_t woke = now_ns();
    if (!delivery) return report(b, "take: " + delivery.error().message);
    if (!*delivery) return report(b, "take: no probe arrived within 5 s");
    std::uint64_t i = probe_index(**delivery);
    if (i < b->samples) b->woke()[i] = woke;
    if (auto acked = agent->ack((*delivery)->item); !acked) return report(b, acked.error().message);
    b->received.fetch_add(1);
    futex(&b->received, FUTEX_WAKE, 1);
  }
  return true;
}

// Polls `done` every 20 us until it holds, the child dies or `limit` passes.
bool wait_for(Child& child, Clock::duration limit, const std::function<bool()>& done) {
  const auto deadline = Clock::now() + limit;
  while (!done()) {
    if (Clock::now() > deadline || !child.alive()) return done();
    std::this_thread::sleep_for(20us);
  }
  return true;
}

// Sleeps on the subscriber's count until it reaches `count`, the child dies or `limit` passes.
bool wait_for_taken(Child& child, WakeBoard* b, std::uint32_t count, Clock::duration limit) {
  const auto deadline = Clock::now() + limit;
  for (std::uint32_t seen = b->received.load(); seen < count; seen = b->received.load()) {
    if (Clock::now() > deadline || !child.alive()) return b->received.load() >= count;
    futex(&b->received, FUTEX_WAIT, seen);
  }
  return true;
}

Unexpected<node::Error> child_failed(WakeBoard* b, const std::string& what) {
  std::string why = b->state.load() == 2 ? std::string(b->error) : "no answer";
  return node::fail(node::Errc::timeout, "wake bench: " + what + ": subscriber: " + why);
}

node::Item probe(std::uint64_t i) {
  node::Item item;
  item.add(Term::iri(std::string(kNodeIri) + "/wake/" + std::to_string(i)), Term::iri(kProbe),
           Term::integer(static_cast<std::int64_t>(i)));
  return item;
}

// Percentiles of to[i] - from[i] over the probes that were taken.
Percentiles span(WakeBoard* b, const std::int64_t* from, const std::int64_t* to) {
  std::vector<double> us;
  for (std::size_t i = b->warmup; i < b->samples; ++i) {
    if (b->woke()[i] > 0) us.push_back(static_cast<double>(to[i] - from[i]) / 1e3);
  }
  return percentiles(std::move(us));
}

}  // namespace

node::Result<node::Node> tahvel_init(const std::filesystem::path& dir,
                                     node::Durability durability) {
  node::InitOptions options;
  options.iri = kNodeIri;
  options.durability = durability;
  return node::Node::init(dir, options);
}

node::Result<WakeFigures> tahvel_wake(const std::filesystem::path& dir, std::size_t samples,
                                      std::chrono::microseconds pause, Placement where) {
  if (auto created = tahvel_init(dir, node::Durability::fast); !created) {
    return node::fail(created.error().code, created.error().message);
  }  // closed again here: only the child's own handle exists across the fork
  const std::size_t warmup = samples / 10 + 10;  // as the socket floor: page faults, caches
  samples += warmup;
  SharedBoard shared(samples);
  WakeBoard* b = shared.get();
  if (!b) return node::fail(node::Errc::io, "wake bench: mmap failed");
  b->warmup = warmup;
  std::fflush(nullptr);
  pid_t pid = fork();
  if (pid < 0) return node::fail(node::Errc::io, "wake bench: fork failed");
  if (pid == 0) _exit(pin_to_cpu(where.child_cpu) && run_subscriber(dir, b) ? 0 : 1);
  Child child(pid);
  ScopedPin pinned(where.parent_cpu);
  auto node = node::Node::open(dir);
  if (!node) return node::fail(node.error().code, node.error().message);
  auto agent = node->agent("sensor");
  if (!agent) return node::fail(agent.error().code, agent.error().message);
  if (!wait_for(child, 10s, [&] { return b->state.load() == 1; })) {
    return child_failed(b, "subscribing");
  }
  for (std::size_t i = 0; i < samples; ++i) {
    if (!wait_for_taken(child, b, static_cast<std::uint32_t>(i), 5s)) {
      return child_failed(b, "probe " + std::to_string(i) + " was not taken");
    }
    if (pause.count() > 0) std::this_thread::sleep_for(pause);
    node::Item item = probe(i);
    b->sent()[i] = now_ns();
    if (auto stored = agent->store(item); !stored) {
      return node::fail(stored.error().code, stored.error().message);
    }
    b->returned()[i] = now_ns();
  }
  if (!wait_for_taken(child, b, static_cast<std::uint32_t>(samples), 5s)) {
    return child_failed(b, "the last probe was not taken");
  }
  child.reap();
  return WakeFigures{span(b, b->sent(), b->woke()), span(b, b->sent(), b->returned()),
                     span(b, b->returned(), b->woke())};
}

}  // namespace tahvel::cli::bench
