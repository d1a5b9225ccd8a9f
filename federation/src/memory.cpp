// The in-memory binding: endpoints of one MemoryBus exchange encoded frames through queues, with
// a seeded fault schedule (drop, duplicate, reorder) and cuts, for deterministic link tests.
#include <condition_variable>
#include <deque>
#include <iostream>
#include <map>
#include <mutex>
#include <random>
#include <set>

#include "tahvel/federation/transport.h"

namespace tahvel::federation {

struct MemoryBus::Impl {
  struct Mailbox {
    std::deque<std::string> queue;  // encoded frames, decoded on receive like wire bytes
    std::condition_variable ready;
  };

  std::mutex mutex;
  // Every endpoint bound to an IRI gets each frame to it, as on LCM or DDS, where two nodes with
  // one IRI (a misconfiguration, P6b) both receive.
  std::map<std::string, std::vector<std::shared_ptr<Mailbox>>, std::less<>> mailboxes;
  std::set<std::string, std::less<>> cut;
  Faults faults;
  std::mt19937_64 random{1};
  std::optional<std::pair<std::string, std::string>> held;  // a frame held back for reordering

  // Caller holds `mutex`.
  void deliver_locked(const std::string& to, std::string bytes) {
    auto it = mailboxes.find(to);
    if (it == mailboxes.end() || cut.count(to)) return;  // nobody listening: lost, as on a wire
    for (const auto& mailbox : it->second) {
      mailbox->queue.push_back(bytes);
      mailbox->ready.notify_one();
    }
  }

  void send(const std::string& to, std::string bytes) {
    std::lock_guard lock(mutex);
    std::uniform_real_distribution<double> chance(0.0, 1.0);
    if (faults.drop > 0 && chance(random) < faults.drop) return;
    bool twice = faults.duplicate > 0 && chance(random) < faults.duplicate;
    if (faults.reorder > 0 && !held && chance(random) < faults.reorder) {
      held.emplace(to, std::move(bytes));
      return;
    }
    if (twice) deliver_locked(to, bytes);
    deliver_locked(to, std::move(bytes));
    if (held) {
      auto [held_to, held_bytes] = std::move(*held);
      held.reset();
      deliver_locked(held_to, std::move(held_bytes));
    }
  }
};

namespace {

class MemoryTransport final : public Transport {
 public:
  MemoryTransport(std::shared_ptr<MemoryBus::Impl> bus, std::string self, DropLog log)
      : bus_(std::move(bus)), self_(std::move(self)), log_(std::move(log)) {
    std::lock_guard lock(bus_->mutex);
    mailbox_ = std::make_shared<MemoryBus::Impl::Mailbox>();
    bus_->mailboxes[self_].push_back(mailbox_);
  }

  ~MemoryTransport() override {
    std::lock_guard lock(bus_->mutex);
    auto it = bus_->mailboxes.find(self_);
    if (it == bus_->mailboxes.end()) return;
    std::erase(it->second, mailbox_);
    if (it->second.empty()) bus_->mailboxes.erase(it);
  }

  const std::string& self() const override { return self_; }

  Result<void> send(const Frame& frame) override {
    bus_->send(frame.to, encode_frame(frame));
    return {};
  }

  Result<std::optional<Frame>> receive(std::chrono::milliseconds timeout) override {
    auto deadline = std::chrono::steady_clock::now() + timeout;
    std::unique_lock lock(bus_->mutex);
    for (;;) {
      while (mailbox_->queue.empty()) {
        if (mailbox_->ready.wait_until(lock, deadline) == std::cv_status::timeout &&
            mailbox_->queue.empty())
          return std::optional<Frame>{};
      }
      std::string bytes = std::move(mailbox_->queue.front());
      mailbox_->queue.pop_front();
      auto frame = decode_frame(bytes);
      if (!frame) {
        drop("undecodable frame for <" + self_ + ">: " + frame.error().message);
        continue;
      }
      if (auto reason = frame_refusal(*frame, self_)) {
        drop(*reason);
        continue;
      }
      return std::optional<Frame>{std::move(*frame)};
    }
  }

 private:
  void drop(const std::string& reason) {
    if (log_) log_(reason);
    else std::cerr << "tahvel: memory transport dropped " << reason << "\n";
  }

  std::shared_ptr<MemoryBus::Impl> bus_;
  std::string self_;
  DropLog log_;
  std::shared_ptr<MemoryBus::Impl::Mailbox> mailbox_;
};

}  // namespace

MemoryBus::MemoryBus() : impl_(std::make_shared<Impl>()) {}
MemoryBus::~MemoryBus() = default;

void MemoryBus::set_faults(const Faults& faults) {
  std::lock_guard lock(impl_->mutex);
  impl_->faults = faults;
  impl_->random.seed(faults.seed);
}

void MemoryBus::set_cut(std::string_view iri, bool cut) {
  std::lock_guard lock(impl_->mutex);
  if (cut) impl_->cut.emplace(iri);
  else impl_->cut.erase(std::string(iri));
}

std::unique_ptr<Transport> MemoryBus::open(std::string_view self_iri, DropLog log) {
  return std::make_unique<MemoryTransport>(impl_, std::string(self_iri), std::move(log));
}

void MemoryBus::inject_raw(std::string_view to, std::string bytes) {
  std::lock_guard lock(impl_->mutex);
  impl_->deliver_locked(std::string(to), std::move(bytes));
}

}  // namespace tahvel::federation
