// The operator's side of a remote query (link.h: remote_query): a query item on this node's
// board addressed to the target (R18 hands it to the link agent of the child on the way), then
// answer chunks taken from the asking agent's input buffer (P13-P16).
#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <charconv>
#include <ctime>
#include <filesystem>
#include <map>
#include <thread>

#include "base64.h"
#include "children_hint.h"
#include "tahvel/federation/link.h"
#include "tahvel/node/process.h"
#include "tahvel/uri/iri.h"
#include "tahvel/federation/wire.h"

namespace tahvel::federation {
namespace {

using node::Term;

// Answer items read per round at most: the origin's link keeps no more than its window (32
// chunks beyond those read) waiting on the board.
constexpr std::size_t kChunksPerRound = 64;
// While the answer is awaited, whether this node's link still runs is looked at this often; one
// that stopped (`tahvel down`) for longer than kLinkGone ends the query as unreachable, rather
// than at its timeout. A link that restarts within it tells the asker itself (link_restarted).
constexpr std::chrono::milliseconds kLinkCheckEvery{500};
constexpr std::chrono::milliseconds kLinkGone{3000};

const Term* object_of(const std::vector<node::Record>& records, const std::string& predicate) {
  for (const auto& r : records)
    if (r.triple.p.value == predicate) return &r.triple.o;
  return nullptr;
}

// Whether a link serving this node's children runs: it holds a shared lock on the lock file,
// so an exclusive one cannot be had. (A stopped node leaves its children's state "up" on the
// board, and the query would wait out its whole timeout.) A link stopped by a signal or a
// debugger holds the lock and does nothing: `stopped_pid` is its process id then.
struct LinkSeen {
  bool serving = false;
  std::optional<pid_t> stopped_pid;
  // How long the serving run has run: it writes its pid into the lock file at its start.
  std::optional<std::chrono::nanoseconds> run_age;
};

LinkSeen link_serving(const std::filesystem::path& dir) {
  LinkSeen seen;
  const int fd = ::open((dir / kServingLockFile).c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return seen;
  seen.serving = flock(fd, LOCK_EX | LOCK_NB) != 0 && errno == EWOULDBLOCK;
  if (seen.serving) {
    char text[24] = {};
    const ssize_t got = pread(fd, text, sizeof text - 1, 0);
    pid_t pid = 0;
    const auto [end, ec] = std::from_chars(text, text + std::max<ssize_t>(got, 0), pid);
    if (ec == std::errc() && pid > 0 && node::is_stopped(node::process_state(pid))) seen.stopped_pid = pid;
    struct stat st {};
    timespec now {};
    if (fstat(fd, &st) == 0 && clock_gettime(CLOCK_REALTIME, &now) == 0)
      seen.run_age = std::chrono::seconds(now.tv_sec - st.st_mtim.tv_sec) + std::chrono::nanoseconds(now.tv_nsec - st.st_mtim.tv_nsec);
  }
  ::close(fd);
  return seen;
}

std::string stopped_link(const std::string& self, pid_t pid) {
  const std::string p = std::to_string(pid);
  return "the link of <" + self + "> (process " + p + ") is stopped by a signal or a debugger (state T or t in /proc/" + p +
         "/stat); 'kill -CONT " + p + "' resumes it";
}

Unexpected<Error> timed_out(const std::string& target, std::chrono::milliseconds timeout, std::uint64_t delivered) {
  // In seconds, as --timeout is given: "2 s", "0.05 s".
  std::string seconds = std::to_string(timeout.count() / 1000);
  if (const auto ms = timeout.count() % 1000; ms != 0) {
    std::string fraction = std::to_string(1000 + ms).substr(1);
    fraction.erase(fraction.find_last_not_of('0') + 1);
    seconds += "." + fraction;
  }
  return node::fail(Errc::timeout, "timeout: no complete answer from <" + target + "> within " + seconds + " s (" +
                                       std::to_string(delivered) + " records received)");
}

// "; did you mean <…>?" for a child of the node whose IRI is `child` written with characters
// where `child` percent-encodes them (or the other way round); "" when none is.
std::string percent_spelling_hint(const node::Snapshot& snap, const std::string& child) {
  const std::string decoded = uri::percent_decoded(child);
  auto children = snap.list({.p = node::Term::iri(vocab::kLinkState)});
  if (!children) return {};
  for (const node::Record& r : *children)
    if (r.triple.s.is_iri() && r.triple.s.value != child && uri::percent_decoded(r.triple.s.value) == decoded)
      return "; did you mean <" + r.triple.s.value + ">? (an IRI is compared as written: a character and its percent-encoding are two IRIs)";
  return {};
}

// The children this node knows (those whose link state it keeps). `served` says whether a link
// has ever served children here (its lock file is there): a store whose link never ran (`up`
// failed, only `init`) knows none for that reason, not because none exists.
std::string known_children_hint(const node::Snapshot& snap, bool served) {
  auto states = snap.list({.p = node::Term::iri(vocab::kLinkState)});
  if (!states) return {};
  std::vector<std::string> children;
  for (const node::Record& r : *states)
    if (r.triple.s.is_iri()) children.push_back(r.triple.s.value);
  return detail::children_hint(std::move(children),
                               served ? "; it knows no child (none has said hello to its link)"
                                      : "; it knows no child: no link has served children here (a node without 'listen', "
                                        "or one whose link has not run yet: 'tahvel status' shows it)");
}

}  // namespace

Result<std::uint64_t> remote_query(node::Node& node, const RemoteQuery& query,
                                   std::chrono::milliseconds timeout,
                                   const std::function<void(const node::Record&)>& each,
                                   const AreaQuery& area_query, const std::function<bool()>& cancelled) {
  auto target = uri::normalize(query.target);
  if (!target) return node::fail(Errc::invalid_iri, "--at: " + target.error().message);
  const std::string& self = node.iri();
  // A node's IRI never ends in '/' below the root (a child's is its parent's + "/" + id):
  // "<…/home1/>", as a browser writes it, means <…/home1>.
  while (target->size() > self.size() && target->back() == '/') target->pop_back();
  node::Pattern pattern = query.pattern;
  // What the query frame carries (P13); anything else would be left out below without a word.
  if (pattern.context || pattern.after_id)
    return node::fail(Errc::invalid_argument, "a remote query takes no context nor after_id in its pattern");
  for (std::optional<std::string>* iri : {&pattern.source, &pattern.under}) {
    if (!*iri) continue;
    auto normal = uri::normalize(**iri);
    if (!normal) return node::fail(Errc::invalid_iri, std::string(iri == &pattern.source ? "source" : "under") + ": " + normal.error().message);
    *iri = std::move(*normal);
  }
  if (*target == self) {  // asked here: the local store answers, within the same timeout
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    auto snap = node.snapshot();
    if (!snap) return Unexpected<Error>{snap.error()};
    node::ListOptions options{.cascade = query.cascade, .limit = query.limit};
    node::Result<std::vector<node::Record>> records = std::vector<node::Record>{};
    if (query.area.empty()) records = snap->list(pattern, options);
    else if (area_query) records = area_query(*snap, pattern, query.area, query.floor, options);
    else return node::fail(Errc::invalid_argument, "no area resolver for a query by area");
    if (!records) return Unexpected<Error>{records.error()};
    std::uint64_t delivered = 0;
    for (const auto& r : *records) {
      if (cancelled && cancelled())
        return node::fail(Errc::io, "cancelled after " + std::to_string(delivered) + " records from <" + *target + ">");
      // A reader slower than the answer (a pager left open) ends it, as it does a remote one.
      if (std::chrono::steady_clock::now() >= deadline)
        return timed_out(*target, timeout, delivered);
      each(r);
      ++delivered;
    }
    return delivered;
  }
  if (!uri::is_under(*target, self))
    return node::fail(Errc::not_found, "unknown node <" + *target + ">: not below <" + self + ">, where the query was asked");
  std::size_t end = target->find_first_of("/#?", self.size() + 1);
  // `…/hospital//home1`: no child has an empty id. It was said to have "no child
  // <…/hospital/>", an IRI --at itself refuses.
  if (end == self.size() + 1 && (*target)[end] == '/')
    return node::fail(Errc::not_found, "unknown node <" + *target + ">: an empty segment follows <" + self +
                                           "> (a node's IRI is its parent's, '/' and its id)");
  const std::string child = target->substr(0, end);
  // One deadline for the whole call: the wait for a restarting link comes out of the timeout.
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  const auto grace_end = std::chrono::steady_clock::now() + std::min(timeout, query.restart_grace);
  for (;;) {
    if (cancelled && cancelled()) return node::fail(Errc::io, "cancelled before anything was asked of <" + *target + ">");
    std::string child_state;
    bool child_left = false;  // down because its link said it was stopping (P12c)
    {  // the snapshot is not held while waiting
      auto snap = node.snapshot();
      if (!snap) return Unexpected<Error>{snap.error()};
      auto state = snap->list({.s = Term::iri(child), .p = Term::iri(vocab::kLinkState)});
      if (!state) return Unexpected<Error>{state.error()};
      if (state->empty()) {
        // A link served children here and none runs now (stopped, or restarting): a child that
        // had not said hello to it yet is not known to be absent, only not heard from. Said as
        // unreachable, as any child is with no link running, after the wait for a restart.
        std::error_code ec;
        const bool served = std::filesystem::exists(node.dir() / kServingLockFile, ec);
        const LinkSeen link = served ? link_serving(node.dir()) : LinkSeen{};
        // The children it knows, or a spelling it holds: a mistyped child is seen as such now,
        // not only once the link runs again.
        const std::string hint = [&] {
          std::string said = percent_spelling_hint(*snap, child);
          if (!said.empty()) return said;
          // The IRI of an agent here (a recording's prefix, <…/home1/hrv>) taken for a node.
          if (detail::made_data(*snap, child)) return ": <" + child + "> is an agent of <" + self + ">, not a node (ask --at <" + self + ">)";
          return known_children_hint(*snap, served);
        }();
        if (link.stopped_pid)
          return node::fail(Errc::io, "unreachable: nothing reaches <" + child + ">: " + stopped_link(self, *link.stopped_pid) +
                                          "; <" + child + "> has not said hello to it" + hint);
        if (served && !link.serving) {
          if (std::chrono::steady_clock::now() < grace_end) {
            std::this_thread::sleep_for(std::chrono::milliseconds(50));
            continue;
          }
          return node::fail(Errc::io, "unreachable: no link runs for <" + self + "> (nothing holds " +
                                          (node.dir() / kServingLockFile).string() + "), and <" + child +
                                          "> has not said hello to a link here, so only a running link can tell whether it "
                                          "is below <" + self + ">" + (hint.size() > 2 ? " (" + hint.substr(2) + ")" : std::string()) +
                                          "; if 'tahvel status' shows the link "
                                          "restarting, ask again once it runs, else start it ('tahvel up')");
        }
        return node::fail(Errc::not_found, "unknown node <" + *target + ">: <" + self + "> has no child <" + child + ">" + hint);
      }
      child_state = state->back().triple.o.value;
      auto left = snap->list({.s = Term::iri(child), .p = Term::iri(vocab::kLinkLeft), .source = state->back().meta.source});
      child_left = left && !left->empty() && left->back().triple.o.value == "true";
    }
    const LinkSeen link = link_serving(node.dir());
    if (link.stopped_pid)
      return node::fail(Errc::io, "unreachable: nothing reaches <" + child + ">: " + stopped_link(self, *link.stopped_pid));
    const bool serving = link.serving;
    if (child_state == "up" && serving) break;
    // A run younger than child_silence has not heard its children's hello yet: "down" is what
    // the run before left (it says its children down as it stops), not that the child is.
    const bool young = serving && link.run_age && *link.run_age >= std::chrono::nanoseconds::zero() &&
                       *link.run_age < LinkOptions{}.child_silence;  // negative: the clock was set back
    const bool restarting = !serving || child_state == "never connected" || (young && child_state == "down");
    if (restarting && std::chrono::steady_clock::now() < grace_end) {
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
      continue;
    }
    // With no link running here, that is the reason for every child: the states on the board
    // are what its last run left ("up" for one that was connected, "never connected" for one
    // it had not heard from yet), and none of them says why nothing reaches the child now.
    if (!serving)
      return node::fail(Errc::io, "unreachable: no link runs for <" + self + "> (nothing holds " +
                                      (node.dir() / kServingLockFile).string() + "), so nothing reaches <" + child +
                                      ">; if 'tahvel status' shows the link restarting, ask again once it runs, "
                                      "else start it ('tahvel up')");
    return node::fail(Errc::io, "unreachable: <" + child + ">" + (child == *target ? "" : " (on the way to <" + *target + ">)") +
                                    (child_state == "never connected" ? " has never connected to <" + self + ">"
                                                                      : " is " + child_state + " at <" + self + ">") +
                                    (child_state == "down" && child_left ? " (its link was stopped: it said so as it left)" : ""));
  }
  static std::atomic<int> counter{0};
  auto agent = node.agent("query-" + std::to_string(getpid()) + "-" + std::to_string(++counter));
  if (!agent) return Unexpected<Error>{agent.error()};
  node::Item ask;
  ask.context = *target;
  // A ring at the origin must not reclaim the query while it runs: the link would read that as a
  // cancel (P18). Every way out of this function removes it.
  ask.persistent = true;
  const Term q = Term::blank("query");
  ask.add(q, Term::iri(std::string(node::kRdfType)), Term::iri(vocab::kRemoteQuery));
  ask.add(q, Term::iri(vocab::kQueryTarget), Term::iri(*target));
  ask.add(q, Term::iri(vocab::kReplyTo), Term::iri(agent->iri()));
  auto as_written = [](const Term& t) { return t.is_blank() ? Term::literal(t.value, vocab::kBlankNodeLabel) : t; };
  if (pattern.s) ask.add(q, Term::iri(vocab::kQuerySubject), as_written(*pattern.s));
  if (pattern.p) ask.add(q, Term::iri(vocab::kQueryPredicate), *pattern.p);
  if (pattern.o) ask.add(q, Term::iri(vocab::kQueryObject), as_written(*pattern.o));
  if (pattern.source) ask.add(q, Term::iri(vocab::kQuerySource), Term::iri(*pattern.source));
  if (pattern.under) ask.add(q, Term::iri(vocab::kQueryUnder), Term::iri(*pattern.under));
  if (pattern.since) ask.add(q, Term::iri(vocab::kQuerySince), Term::integer(*pattern.since));
  if (pattern.until) ask.add(q, Term::iri(vocab::kQueryUntil), Term::integer(*pattern.until));
  if (query.cascade) ask.add(q, Term::iri(vocab::kQueryCascade), Term::integer(query.cascade));
  if (query.limit) ask.add(q, Term::iri(vocab::kQueryLimit), Term::integer(static_cast<std::int64_t>(query.limit)));
  if (!query.area.empty()) ask.add(q, Term::iri(vocab::kQueryArea), Term::literal(query.area));
  if (query.floor) ask.add(q, Term::iri(vocab::kQueryFloor), Term::integer(*query.floor));
  const auto time_left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
  ask.add(q, Term::iri(vocab::kQueryTimeout), Term::integer(std::max<std::int64_t>(1, time_left.count())));
  auto asked = agent->store(ask);
  if (!asked) return Unexpected<Error>{asked.error()};
  // The query item and any answer item taken but not yet removed leave the board on every way
  // out, a throwing `each` included.
  struct RemoveOnExit {
    node::Node& node;
    std::vector<std::uint64_t> ids;
    ~RemoveOnExit() { (void)node.remove_items(ids); }
  } board{node, {*asked}};
  std::vector<std::uint64_t>& to_remove = board.ids;

  std::uint64_t delivered = 0;
  std::int64_t next_chunk = 1, last_chunk = 0;
  std::uint64_t read_through = 0;  // the answer items read so far: those up to this id
  std::map<std::int64_t, std::vector<node::Record>> early;  // chunks ahead of the next one
  constexpr auto kServing = std::chrono::steady_clock::time_point::max();
  auto unserved_since = kServing;  // since when the link is seen gone
  bool done = false;
  while (!done) {
    auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
    if (left.count() <= 0) {
      return timed_out(*target, timeout, delivered);
    }
    if (cancelled && cancelled()) {
      // The query item leaves the board on return, and the link cancels the query below (P18).
      return node::fail(Errc::io, "cancelled after " + std::to_string(delivered) + " records from <" + *target + ">");
    }
    // Every answer item waiting is read, then all go off the board in one transaction: one commit
    // (one sync, on a durable store) per round rather than two per chunk (a take, a removal).
    auto got = agent->peek(read_through, kChunksPerRound,
                           std::min(left, cancelled ? std::chrono::milliseconds(100) : kLinkCheckEvery));
    if (!got) return Unexpected<Error>{got.error()};
    if (got->empty()) {
      const LinkSeen link = link_serving(node.dir());
      const auto now = std::chrono::steady_clock::now();
      if (link.serving && !link.stopped_pid) {
        unserved_since = kServing;
        continue;
      }
      if (unserved_since == kServing) unserved_since = now;
      if (now - unserved_since < kLinkGone) continue;
      if (link.stopped_pid)
        return node::fail(Errc::io, "unreachable: " + stopped_link(self, *link.stopped_pid) + "; it stopped while the query ran, after " +
                                        std::to_string(delivered) + " records from <" + *target + ">; ask again once it runs");
      return node::fail(Errc::io, "unreachable: the link of <" + self + "> stopped while the query ran (nothing holds " +
                                      (node.dir() / kServingLockFile).string() + "), after " + std::to_string(delivered) +
                                      " records from <" + *target + ">; what was not printed is lost: ask again once it runs");
    }
    const std::size_t first_unremoved = to_remove.size();
    for (const node::Delivery& delivery : *got) {
      read_through = delivery.item;
      to_remove.push_back(delivery.item);
    }
    for (const node::Delivery& delivery : *got) {
      const auto& records = delivery.records;
      const Term* answer_to = object_of(records, vocab::kAnswerTo);
      if (!answer_to || answer_to->value != std::to_string(*asked)) continue;
      if (const Term* code = object_of(records, vocab::kErrorCode)) {
        const Term* message = object_of(records, vocab::kErrorMessage);
        std::string text = message ? message->value : code->value;
        // A node of this version begins with the node asked for ("<T>: <…> has no child <…>");
        // one before session 87 with "no node <T> below <…>".
        if (code->value == "unknown_node") return node::fail(Errc::not_found, "unknown node" + std::string(text.starts_with('<') ? " " : ": ") + text);
        if (code->value == "unreachable") return node::fail(Errc::io, "unreachable: " + text);
        return node::fail(Errc::io, code->value + ": " + text);
      }
      const Term* chunk = object_of(records, vocab::kAnswerChunk);
      if (!chunk) continue;
      // The chunk's base64 in one literal or several, in the item's order (P14).
      std::string encoded;
      for (const auto& r : records)
        if (r.triple.p.value == vocab::kAnswerRecords) encoded += r.triple.o.value;
      auto raw = detail::base64_decode(encoded);
      if (!raw) return node::fail(Errc::corrupt, "answer chunk " + chunk->value + " from <" + *target + ">: not base64");
      auto body = wire::decode_answer(*raw);
      if (!body) {
        return node::fail(Errc::corrupt, "answer chunk " + chunk->value + " from <" + *target + ">: " + body.error().message);
      }
      std::int64_t n = 0;
      if (auto [end, ec] = std::from_chars(chunk->value.data(), chunk->value.data() + chunk->value.size(), n);
          ec != std::errc() || end != chunk->value.data() + chunk->value.size() || n < 1)
        return node::fail(Errc::corrupt, "answer chunk number '" + chunk->value + "' from <" + *target + ">: not a positive integer");
      if (body->last) last_chunk = n;
      early[n] = std::move(body->records);
      // Handed over as each chunk is read, so that what came before an error later in the round
      // is not lost to the caller.
      for (auto it = early.find(next_chunk); it != early.end(); it = early.find(next_chunk)) {
        for (const auto& r : it->second) {
          // Asked before each record, not only between chunks: one that comes after the caller
          // stopped taking them would be counted as delivered.
          if (cancelled && cancelled())
            return node::fail(Errc::io, "cancelled after " + std::to_string(delivered) + " records from <" + *target + ">");
          each(r);
          ++delivered;
        }
        early.erase(it);
        ++next_chunk;
      }
      if (cancelled && cancelled())
        return node::fail(Errc::io, "cancelled after " + std::to_string(delivered) + " records from <" + *target + ">");
    }
    // Off the board once handed over, not before: the link acknowledges chunks below only as
    // they leave the board (P14), so a caller that is slow to take records (a slow pipe) holds
    // the answer back at the target instead of in this process. And off it then: a long answer
    // must not pile up in this node's store.
    if (node.remove_items({to_remove.begin() + static_cast<std::ptrdiff_t>(first_unremoved), to_remove.end()}))
      to_remove.resize(first_unremoved);
    done = last_chunk > 0 && next_chunk > last_chunk;
  }
  return delivered;
}

}  // namespace tahvel::federation
