// Shared plumbing of the HRV pipeline agents; see agent_runtime.h.
#include "agent_runtime.h"

#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <cerrno>
#include <charconv>
#include <cstring>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <set>
#include <string_view>
#include <thread>
#include <algorithm>

#include "tahvel/node/format.h"
#include "tahvel/node/stop_signal.h"

namespace tahvel::agents::hrv {
namespace {

// "0", "30", "0.5": as a person writes the bound (std::to_string gave "0.000000").
std::string format_number(double v) {
  char text[32];
  std::snprintf(text, sizeof text, "%g", v);
  return text;
}

bool declared(const std::vector<std::string>& list, const std::string& flag) {
  for (const auto& f : list)
    if (f == flag) return true;
  return false;
}

std::string node_error(const node::Error& e) {
  return std::string(node::errc_name(e.code)) + " (" + e.message + ")";
}

}  // namespace

Args::Args(int argc, char** argv, const std::vector<std::string>& valued,
           const std::vector<std::string>& boolean, const std::vector<std::string>& repeatable) {
  for (int i = 1; i < argc; ++i) {
    std::string arg = argv[i];
    if (arg == "-h" || arg == "--help") throw HelpRequested{};
    // `--flag=VALUE` as `--flag VALUE`, as `tahvel` reads it (docs/cli.md, Conventions).
    std::optional<std::string> attached;
    if (const std::size_t eq = arg.find('='); arg.starts_with("--") && eq != std::string::npos &&
                                              (declared(valued, arg.substr(0, eq)) || declared(repeatable, arg.substr(0, eq)) ||
                                               declared(boolean, arg.substr(0, eq)))) {
      attached = arg.substr(eq + 1);
      arg.resize(eq);
    }
    const auto value = [&]() -> std::string {
      if (attached) return *attached;
      if (i + 1 >= argc) throw UsageError(arg + ": needs a value");
      return argv[++i];
    };
    if (declared(repeatable, arg)) {
      repeated_.emplace_back(arg, value());
      continue;
    }
    // A flag given twice is an error, as in `tahvel` (docs/cli.md, Conventions): the last one
    // was taken without a word, and a topology file that gives `--window` twice got one of them.
    if ((declared(valued, arg) || declared(boolean, arg)) && values_.count(arg))
      throw UsageError("flag '" + arg + "' given twice");
    if (declared(valued, arg)) {
      values_[arg] = value();
    } else if (declared(boolean, arg)) {
      if (attached) throw UsageError("flag '" + arg + "' takes no value");
      values_[arg] = "";
    } else if (arg.starts_with("-")) {
      throw UsageError("unknown flag '" + arg + "'");
    } else if (dir_.empty()) {
      dir_ = arg;
    } else {
      throw UsageError("unexpected argument '" + arg + "'");
    }
  }
  if (dir_.empty()) throw UsageError("the node directory is missing");
}

std::vector<std::string> Args::values(const std::string& flag) const {
  std::vector<std::string> out;
  for (const auto& [name, value] : repeated_)
    if (name == flag) out.push_back(value);
  return out;
}

std::string Args::text(const std::string& flag, const std::string& fallback) const {
  auto it = values_.find(flag);
  return it == values_.end() ? fallback : it->second;
}

double Args::number(const std::string& flag, double fallback, double minimum) const {
  auto it = values_.find(flag);
  if (it == values_.end()) return fallback;
  // Decimal only, as `tahvel hrv` reads its numbers: strtod took "0x3C" as 60 and " 60" too.
  const std::string& text = it->second;
  double v = 0;
  const char* begin = text.data() + (text.starts_with('+') && text.size() > 1 && text[1] != '-' ? 1 : 0);  // as strtod took "+300"
  const auto [end, ec] = std::from_chars(begin, text.data() + text.size(), v);
  if (text.empty() || ec != std::errc() || end != text.data() + text.size() || !std::isfinite(v) || v < minimum)
    throw UsageError(flag + ": '" + it->second + "' is not a number >= " + format_number(minimum));
  return v;
}

void install_stop_handlers() { node::install_stop_signal_handlers(); }

bool stop_requested() { return node::stop_signal_received(); }

namespace {
constexpr std::chrono::milliseconds kStopCheck{100};
}  // namespace

bool pause_unless_stopped(std::chrono::nanoseconds duration) {
  const auto until = std::chrono::steady_clock::now() + duration;
  for (auto now = std::chrono::steady_clock::now(); now < until && !stop_requested(); now = std::chrono::steady_clock::now())
    std::this_thread::sleep_for(std::min<std::chrono::nanoseconds>(until - now, kStopCheck));
  return !stop_requested();
}

node::Result<std::optional<node::Delivery>> take_unless_stopped(node::Agent& agent, std::chrono::milliseconds timeout) {
  const auto until = std::chrono::steady_clock::now() + timeout;
  for (;;) {
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(until - std::chrono::steady_clock::now());
    auto taken = agent.take(std::clamp(left, std::chrono::milliseconds(0), kStopCheck));
    if (!taken || *taken || stop_requested() || left <= kStopCheck) return taken;
  }
}

void log_line(const std::string& program, const std::string& message) {
  node::write_log_line(program + ": " + message);
}

HeldLock& HeldLock::operator=(HeldLock&& other) noexcept {
  if (this != &other) {
    if (fd_ >= 0) ::close(fd_);
    fd_ = std::exchange(other.fd_, -1);
  }
  return *this;
}

HeldLock::~HeldLock() {
  if (fd_ >= 0) ::close(fd_);
}

namespace {
struct OnlyChecking {};  // thrown by stop_here_when_only_checking, caught by guarded_main
}  // namespace

void stop_here_when_only_checking() {
  if (const char* only = std::getenv(kCheckArgsEnv); only && std::string_view(only) == "1") throw OnlyChecking{};
}

std::optional<Session> open_session(const std::string& program, const std::string& dir,
                                    const std::string& agent_id) {
  stop_here_when_only_checking();
  auto node = node::Node::open(dir);
  if (!node) {
    log_line(program, "open " + dir + ": " + node_error(node.error()));
    return std::nullopt;
  }
  auto agent = node->agent(agent_id);
  if (!agent) {
    log_line(program, "agent '" + agent_id + "': " + node_error(agent.error()));
    return std::nullopt;
  }
  // Named by the id as the agent's IRI has it (`r%70eak` is agent `rpeak`).
  const std::string lock_path = (node->dir() / (".agent-" + agent->iri().substr(node->iri().size() + 1) + ".lock")).string();
  const int fd = ::open(lock_path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
  if (fd < 0) {
    log_line(program, "open " + lock_path + ": " + std::strerror(errno));
    return std::nullopt;
  }
  HeldLock running(fd);
  // A predecessor killed a moment ago (a SIGKILLed supervisor's leftovers, killed by the next
  // `up` without waiting) may not have let go yet: tried for up to 3 s.
  int rc = 0;
  for (int attempt = 0; (rc = ::flock(fd, LOCK_EX | LOCK_NB)) != 0 && (errno == EINTR || errno == EWOULDBLOCK) && attempt < 60; ++attempt)
    if (errno == EWOULDBLOCK) std::this_thread::sleep_for(std::chrono::milliseconds(50));
  if (rc != 0) {
    log_line(program, errno == EWOULDBLOCK
                          ? "another process runs as agent <" + agent->iri() + "> (" + lock_path +
                                " is locked): one process per agent id, as each keeps its recordings' state; this one stops"
                          : "lock " + lock_path + ": " + std::strerror(errno));
    return std::nullopt;
  }
  return Session{program, std::move(*node), std::move(*agent), std::move(running)};
}

bool subscribe_predicates(Session& session, const std::vector<std::string>& predicate_iris) {
  for (const std::string& p : predicate_iris) {
    node::Pattern pattern;
    pattern.p = node::Term::iri(p);
    // earlier: a stage started after its input was written (a replay run first) gets it all.
    if (auto s = session.agent.subscribe(pattern, {.earlier = true}); !s) {
      log_line(session.program, "subscribe <" + p + ">: " + node_error(s.error()));
      return false;
    }
  }
  return true;
}

int run_take_loop(Session& session, double idle_s, const Handler& handle) {
  using Clock = std::chrono::steady_clock;
  auto last_input = Clock::now();
  std::uint64_t done = 0;
  while (!stop_requested()) {
    auto taken = session.agent.take(std::chrono::milliseconds(250), node::Ack::manual);
    if (!taken) {
      log_line(session.program, "take: " + node_error(taken.error()));
      return kExitError;
    }
    if (!*taken) {
      if (idle_s > 0 && Clock::now() - last_input >= std::chrono::duration<double>(idle_s)) {
        log_line(session.program, "no input for " + std::to_string(static_cast<long>(idle_s)) + " s, stopping");
        break;
      }
      continue;
    }
    last_input = Clock::now();
    const node::Delivery& delivery = **taken;
    const Outcome outcome = handle(delivery);
    if (outcome.fatal) {  // not acknowledged: delivered again after a restart
      log_line(session.program, *outcome.fatal);
      return kExitError;
    }
    if (auto acked = session.agent.ack(delivery.item); !acked) {
      log_line(session.program, "ack item " + std::to_string(delivery.item) + ": " + node_error(acked.error()));
      return kExitError;
    }
    ++done;
  }
  log_line(session.program, "processed " + std::to_string(done) + " item(s)" +
                                (stop_requested() ? ", stopped by signal" : ""));
  return kExitOk;
}

aggregation::Result<aggregation::RecordingInfo> load_recording(const node::Node& node,
                                                              const std::string& recording_iri) {
  auto snapshot = node.snapshot();
  if (!snapshot) return aggregation::fail("snapshot: " + node_error(snapshot.error()));
  node::Pattern pattern;
  pattern.s = node::Term::iri(recording_iri);
  auto records = snapshot->list(pattern);
  if (!records) return aggregation::fail("read <" + recording_iri + ">: " + node_error(records.error()));
  if (records->empty()) return aggregation::fail("no recording item <" + recording_iri + "> on the board");
  return aggregation::read_recording(*records, recording_iri);
}

aggregation::Result<std::vector<std::vector<node::Record>>> items_matching(
    const node::Node& node, const node::Pattern& pattern) {
  auto snapshot = node.snapshot();
  if (!snapshot) return aggregation::fail("snapshot: " + node_error(snapshot.error()));
  auto records = snapshot->list(pattern);
  if (!records) return aggregation::fail("list: " + node_error(records.error()));
  std::set<std::uint64_t> seen;
  std::vector<std::vector<node::Record>> items;
  for (const node::Record& r : *records) {
    if (!seen.insert(r.meta.item).second) continue;
    auto item = snapshot->item(r.meta.item);
    if (!item) continue;  // removed meanwhile
    items.push_back(std::move(*item));
  }
  return items;
}

aggregation::Result<std::vector<std::vector<node::Record>>> recording_items(
    const node::Node& node, const std::string& recording_iri) {
  node::Pattern pattern;
  pattern.p = aggregation::tv_term("recording");
  pattern.o = node::Term::iri(recording_iri);
  return items_matching(node, pattern);
}

aggregation::Result<void> for_each_recording_item(const node::Node& node, const std::string& recording_iri,
                                                  std::int64_t since_ns, std::int64_t until_ns,
                                                  const std::function<bool(const std::vector<node::Record>&)>& each) {
  constexpr std::int64_t kPageNs = std::int64_t{600} * 1'000'000'000;
  for (std::int64_t from = since_ns; from < until_ns;) {
    const std::int64_t to = until_ns - from > kPageNs ? from + kPageNs : until_ns;
    std::vector<std::pair<std::pair<std::int64_t, std::uint64_t>, std::vector<node::Record>>> page;
    {
      auto snapshot = node.snapshot();
      if (!snapshot) return aggregation::fail("snapshot: " + node_error(snapshot.error()));
      node::Pattern pattern{.p = aggregation::tv_term("recording"), .o = node::Term::iri(recording_iri), .since = from, .until = to};
      auto records = snapshot->list(pattern);
      if (!records) return aggregation::fail("list: " + node_error(records.error()));
      std::set<std::uint64_t> seen;
      for (const node::Record& r : *records) {
        // An item that began before the page (a span reaching into it) was in an earlier one.
        if (r.meta.asserted_at < from || r.meta.asserted_at >= to || !seen.insert(r.meta.item).second) continue;
        auto item = snapshot->item(r.meta.item);
        if (!item) continue;  // removed meanwhile
        page.push_back({{r.meta.asserted_at, r.meta.item}, std::move(*item)});
      }
    }
    std::sort(page.begin(), page.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
    for (const auto& entry : page)
      if (!each(entry.second)) return {};
    from = to;
  }
  return {};
}

std::optional<std::vector<node::Record>> item_about(const node::Node& node, const std::string& iri) {
  auto snapshot = node.snapshot();
  if (!snapshot) return std::nullopt;
  auto records = snapshot->list({.s = node::Term::iri(iri)}, {.limit = 1});
  if (!records || records->empty()) return std::nullopt;
  auto item = snapshot->item(records->front().meta.item);
  if (!item) return std::nullopt;
  return std::move(*item);
}

double warm_up_seconds(const Args& args) {
  const double seconds = args.number("--warm-up", 0);
  if (seconds > 0 && seconds < 60)
    throw UsageError("--warm-up " + args.text("--warm-up", "") + ": give 0 (replay from the start) or at least 60 seconds");
  return seconds;
}

aggregation::Result<bool> resume_by_warm_up(const std::string& program, const aggregation::RecordingInfo& info,
                                            std::int64_t upto, double warm_up_s, const std::string& inputs,
                                            const std::function<aggregation::Result<WarmUp>(std::int64_t start)>& warm_up) {
  for (double w = warm_up_s; w > 0 && info.started_at; w *= 4) {
    const std::int64_t start = upto - std::llround(std::min(w * info.fs, static_cast<double>(upto)));
    if (start <= 0) return false;
    auto tried = warm_up(start);
    if (!tried) return aggregation::fail("catch up <" + info.iri + ">: " + tried.error().message);
    switch (tried->verdict) {
      case WarmUp::Verdict::agreed:
        log_line(program, "<" + info.iri + ">: resumed at sample " + std::to_string(upto) + " after reading " +
                              std::to_string(tried->read) + " " + inputs + " again from sample " + std::to_string(start) +
                              "; the last " + std::to_string(tried->compared) + " output(s) agree with the board");
        return true;
      case WarmUp::Verdict::missing:
        return false;
      case WarmUp::Verdict::differs:
        log_line(program, "<" + info.iri + ">: a warm-up from sample " + std::to_string(start) + " " + tried->why +
                              "; reading further back");
        break;
    }
  }
  return false;
}

bool on_board(const node::Node& node, const std::string& iri) {
  auto snapshot = node.snapshot();
  if (!snapshot) return false;
  node::Pattern pattern;
  pattern.s = node::Term::iri(iri);
  auto n = snapshot->count(pattern);
  return n && *n > 0;
}

Outcome store_output(Session& session, const node::Item& item, bool catching_up) {
  const std::string& subject = item.triples.front().s.value;
  if (on_board(session.node, subject)) return Outcome::ok();
  if (auto s = session.agent.store(item); !s) return Outcome::error("store <" + subject + ">: " + node_error(s.error()));
  if (catching_up) log_line(session.program, "caught up: wrote <" + subject + ">");
  return Outcome::ok();
}

std::optional<std::int64_t> parse_int(const std::string& text) {
  std::int64_t v = 0;
  auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), v);
  if (ec != std::errc() || end != text.data() + text.size()) return std::nullopt;
  return v;
}

bool has_predicate(const std::vector<node::Record>& records, const char* local) {
  const std::string p = std::string(aggregation::kTv) + local;
  for (const node::Record& r : records)
    if (r.triple.p.value == p) return true;
  return false;
}

SkippedInputs::SkippedInputs(Session& session, std::string others) : session_(session), others_(std::move(others)) {
  report();
}

void SkippedInputs::skip(const std::string& key, const std::string& why, const std::string& what) {
  if (auto it = causes_.find(key); it != causes_.end() && it->second.text == why + "; " + what + " are skipped") {
    ++it->second.skipped_since;  // said already: one line and one write per change
    return;
  }
  log_line(session_.program, why + "; skipped");
  causes_[key] = Cause{why + "; " + what + " are skipped", 0};
  latest_ = key;
  report();
}

void SkippedInputs::hold(const std::string& key, const std::string& text) {
  if (auto it = causes_.find(key); it != causes_.end() && it->second.text == text) return;
  log_line(session_.program, text);
  causes_[key] = Cause{text, 0};
  latest_ = key;
  report();
}

void SkippedInputs::resume(const std::string& key) {
  auto it = causes_.find(key);
  if (it == causes_.end()) return;
  if (it->second.skipped_since > 0)
    log_line(session_.program, key + ": " + std::to_string(it->second.skipped_since) + " more skipped for the same cause");
  causes_.erase(it);
  if (latest_ == key) latest_ = causes_.empty() ? std::string() : causes_.begin()->first;
  report();
}

void SkippedInputs::report() {
  std::string text;
  if (!causes_.empty()) {
    text = causes_[latest_].text;
    if (causes_.size() > 1) text += " (and those of " + std::to_string(causes_.size() - 1) + " other " + others_ + ")";
  }
  if (auto said = session_.agent.report_problem(text); !said)
    log_line(session_.program, "report the problem on the board: " + said.error().message);
}

int guarded_main(const char* program, const char* usage, const std::function<int()>& body) {
  try {
    // A clean end after a SIGTERM from anyone but its supervisor (an operator's `kill`) is no
    // finish: 143, so that the supervisor starts it again (node/stop_signal.h).
    const int status = body();
    return status == 0 ? node::stop_exit_status() : status;
  } catch (const HelpRequested&) {
    std::cout << usage << '\n';
    return 0;
  } catch (const OnlyChecking&) {
    return 0;
  } catch (const UsageError& e) {
    // The usage first and the error last: the supervisor shows the last line of a failed
    // program's log with its exit (`tahvel status`, on the machines above too), and that line
    // must be the cause, not the usage.
    std::cerr << usage << '\n';
    log_line(program, e.what());
    return kExitUsage;
  }
}

}  // namespace tahvel::agents::hrv
