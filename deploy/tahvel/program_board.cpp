// ProgramBoard; see program_board.h.
#include "program_board.h"

#include <condition_variable>
#include <mutex>
#include <optional>
#include <utility>

#include "commands.h"
#include "tahvel/node/node.h"

namespace tahvel::cli {

struct ProgramBoard::Shared {
  std::mutex mutex;
  std::condition_variable changed;
  std::optional<std::vector<agents::ProgramState>> pending;
  bool finishing = false;
  bool writing = false;
  bool succeeded = false;  // the last write ended, and wrote
  std::chrono::steady_clock::time_point write_began{};
};

namespace {

// The programs and the predicates the store holds (agents::holdings_item), replacing what the
// supervisor wrote before.
node::Result<void> write_programs(std::optional<node::Node>& board, const std::filesystem::path& store,
                                  const std::vector<agents::ProgramState>& programs) {
  if (!board) {
    auto opened = node::Node::open(store);
    if (!opened) return Unexpected<node::Error>{opened.error()};
    board.emplace(std::move(*opened));
  }
  const std::int64_t now = unix_now_ns();
  auto item = agents::programs_item(board->iri(), programs, now);
  if (!item) return Unexpected<node::Error>{item.error()};
  node::Result<std::vector<node::PredicateSummary>> held = std::vector<node::PredicateSummary>{};
  {  // released before the write: a snapshot held here would keep the store from growing
    auto snap = board->snapshot();
    if (!snap) return Unexpected<node::Error>{snap.error()};
    held = snap->predicates();
    if (!held) return Unexpected<node::Error>{held.error()};
  }
  auto agent = board->agent("supervisor");
  if (!agent) return Unexpected<node::Error>{agent.error()};
  auto stored = agent->replace({{.source = agent->iri()}}, {*item, agents::holdings_item(board->iri(), *held, now)});
  if (!stored) return Unexpected<node::Error>{stored.error()};
  return {};
}

}  // namespace

ProgramBoard::ProgramBoard(std::filesystem::path store, std::string node_id, Log log)
    : shared_(std::make_shared<Shared>()) {
  // The thread owns what it uses (the store's handle, the log) and shares only `shared`: left
  // waiting at the end, it outlives this object.
  thread_ = std::thread([shared = shared_, store = std::move(store), id = std::move(node_id), log = std::move(log)] {
    std::optional<node::Node> board;
    std::string failure;  // the last write's, once logged
    std::unique_lock lock(shared->mutex);
    for (;;) {
      shared->changed.wait(lock, [&] { return shared->pending || shared->finishing; });
      if (!shared->pending) return;
      std::vector<agents::ProgramState> programs = std::move(*shared->pending);
      shared->pending.reset();
      shared->writing = true;
      shared->write_began = std::chrono::steady_clock::now();
      lock.unlock();
      auto written = write_programs(board, store, programs);
      if (!written && written.error().message != failure)
        log("up: cannot write the programs of " + id + " on its board: " + written.error().message);
      failure = written ? std::string() : written.error().message;
      lock.lock();
      shared->writing = false;
      shared->succeeded = written.has_value();
      shared->changed.notify_all();
    }
  });
}

ProgramBoard::~ProgramBoard() {
  if (!thread_.joinable()) return;
  {
    std::lock_guard lock(shared_->mutex);
    shared_->pending.reset();
  }
  finish(std::chrono::milliseconds(0));
}

void ProgramBoard::post(std::vector<agents::ProgramState> programs) {
  std::lock_guard lock(shared_->mutex);
  shared_->pending = std::move(programs);
  shared_->succeeded = false;
  shared_->changed.notify_all();
}

bool ProgramBoard::last_write_succeeded() const {
  std::lock_guard lock(shared_->mutex);
  return shared_->succeeded && !shared_->writing;
}

std::chrono::steady_clock::duration ProgramBoard::waiting() const {
  std::lock_guard lock(shared_->mutex);
  return shared_->writing ? std::chrono::steady_clock::now() - shared_->write_began : std::chrono::steady_clock::duration::zero();
}

bool ProgramBoard::finish(std::chrono::milliseconds limit) {
  bool done = false;
  {
    std::unique_lock lock(shared_->mutex);
    shared_->finishing = true;
    shared_->changed.notify_all();
    done = shared_->changed.wait_for(lock, limit, [&] { return !shared_->pending && !shared_->writing; });
  }
  if (!thread_.joinable()) return done;
  if (done) thread_.join();
  else thread_.detach();
  return done;
}

}  // namespace tahvel::cli
