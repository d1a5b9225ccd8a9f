// `tahvel` subcommands that read a whiteboard: list, dump, take, tail, stats.
// `tail` is the only long-running one: it blocks in Node::watch (woken by commits, no polling)
// and writes each batch as soon as it arrives.
#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <charconv>
#include <chrono>
#include <iostream>
#include <sstream>
#include <thread>

#include "commands.h"
#include "tahvel/spatial/board.h"
#include "tahvel/spatial/wkt.h"

namespace tahvel::cli {
namespace {

using std::chrono::milliseconds;

const Flag kFlagListContext{"--context", "", "IRI", "only records with this context ('' for none)"};
// One year: longer waits are refused rather than overflowing a deadline in the library.
milliseconds timeout_flag(const Args& args) {
  constexpr std::uint64_t kMax = 365ull * 24 * 3600 * 1000;
  // Past 64 bits too (12 significant digits or more are all above it), the bound said is this one.
  if (const auto text = args.get("--timeout");
      text && std::all_of(text->begin(), text->end(), [](char c) { return c >= '0' && c <= '9'; }) &&
      text->size() - std::min(text->size(), text->find_first_not_of('0')) > 11)
    usage_error("--timeout: at most " + std::to_string(kMax) + " ms");
  std::uint64_t ms = args.get_u64("--timeout", 0);
  if (ms > kMax) usage_error("--timeout: at most " + std::to_string(kMax) + " ms");
  return milliseconds(static_cast<milliseconds::rep>(ms));
}

// Writes the changes of one watch() batch that match `pattern`; counts inserted records in
// `printed` and stops at `count` (0: no limit). Turtle declares the prefixes of each batch.
void print_changes(std::ostream& out, const std::vector<node::Change>& changes,
                   const node::Pattern& pattern, node::Format format,
                   const uri::PrefixMap& all_prefixes, std::uint64_t count,
                   std::uint64_t& printed) {
  uri::PrefixMap prefixes;
  if (format == node::Format::turtle) {
    std::vector<node::Record> inserted;
    for (const node::Change& change : changes) {
      if (!change.removed) inserted.push_back(change.record);
    }
    prefixes = used_prefixes(all_prefixes, inserted);
  }
  std::optional<node::RecordWriter> writer;
  for (const node::Change& change : changes) {
    if (count != 0 && printed >= count) break;
    // One that cannot be read may or may not have matched: said, not counted.
    if (change.unreadable.empty() && !matches(pattern, change.record)) continue;
    if (!writer) writer.emplace(out, format, prefixes);
    writer->write(change);
    if (!change.removed && change.unreadable.empty()) ++printed;
  }
  writer.reset();
  finish_output(out);
}

// The figures of `tahvel stats`, in print order; text and JSON show the same list.
std::vector<std::pair<const char*, std::uint64_t>> stats_figures(const node::Stats& s) {
  return {{"ring", s.ring},
          {"max_literal_bytes", s.max_literal_bytes},
          {"records", s.records},
          {"persistent_records", s.persistent_records},
          {"items", s.items},
          {"terms", s.terms},
          {"subscriptions", s.subscriptions},
          {"pending_deliveries", s.pending_deliveries},
          {"last_seq", s.last_seq},
          {"reclaimed_records", s.reclaimed_records},
          {"used_bytes", s.used_bytes},
          {"high_water_bytes", s.high_water_bytes},
          {"map_bytes", s.map_bytes},
          {"max_map_bytes", s.max_map_bytes}};
}

const char* durability_name(node::Durability d) { return d == node::Durability::durable ? "durable" : "fast"; }

void print_stats_text(const node::Stats& s) {
  std::cout << "iri: " << s.iri << "\ndurability: " << durability_name(s.durability) << "\n";
  for (const auto& [key, value] : stats_figures(s)) std::cout << key << ": " << value << "\n";
}

void print_stats_json(const node::Stats& s) {
  std::cout << "{\"iri\":\"" << node::json_escape(s.iri) << "\",\"durability\":\""
            << durability_name(s.durability) << "\"";
  for (const auto& [key, value] : stats_figures(s)) std::cout << ",\"" << key << "\":" << value;
  std::cout << "}\n";
}

}  // namespace

const Command kListCommand{
    "list",
    "DIR [-s S] [-p P] [-o O] [--context IRI] [--source IRI] [--under IRI] [--since T] [--until T] [--area IRI|WKT [--floor N]] [--cascade N] [--limit N] [--format nt|ttl|json]",
    "Print the records matching a pattern (all when none is given).",
    "Times (--since, --until; by asserted-at) are ns since the epoch or RFC 3339 times:\n"
    "2026-11-21T10:00:00Z, …T12:00:00.5+02:00; a record that holds for a span of time (an ECG\n"
    "chunk, its second) is in a range it overlaps. A range is read through the store's time\n"
    "index: ten seconds of a month of ECG reads ten seconds' worth.\n"
    "Matches come in id order; with --cascade N each is followed by its sub-tree: the records\n"
    "whose subject is the match's object (an IRI or blank node), N levels deep. JSON output has\n"
    "one object per line with the record's metadata (id, item, stored_at, asserted_at, span when\n"
    "the record holds for a time, source, context, persistent). With --area only matches whose\n"
    "subject is a feature located in the area (a sensor inside it, a room or other polygon\n"
    "feature lying in it, or the room itself) or whose source is a sensor inside it are kept;\n"
    "sensors are placed by geo:hasGeometry/geo:asWKT as the board says when the command\n"
    "runs (docs/spatial.md).",
    {kFlagS, kFlagP, kFlagO, kFlagListContext, kFlagSource, kFlagUnder, kFlagSince, kFlagUntil, kFlagArea, kFlagFloor, kFlagCascade,
     {"--limit", "", "N", "print at most N records in all (0: no limit)"}, kFlagFormat},
    1, 1};

int run_list(const Args& args) {
  node::Node node = open_node(args.positional(0));
  uri::PrefixMap prefixes = prefixes_with_flags(node.prefixes(), args);
  node::Pattern pattern = pattern_from_args(args, prefixes);
  node::ListOptions options;
  options.cascade = cascade_flag(args);
  // One record more than --limit is read, and not printed: it tells a cut answer from a whole one.
  const std::uint64_t limit = args.get_u64("--limit", 0);
  options.limit = limit == 0 || limit == std::numeric_limits<std::uint64_t>::max() ? limit : limit + 1;
  node::Format format = format_flag(args, node::Format::ntriples);
  std::optional<spatial::AreaSpec> area;
  if (args.has("--area")) {
    area = area_flag(args, prefixes);
  } else if (args.has("--floor")) {
    usage_error("--floor: only with a WKT --area");
  }
  node::Snapshot snapshot = check(node.snapshot());
  std::vector<node::Record> records_read;
  if (area) {
    std::vector<std::string> skipped;
    auto records = spatial::list_in_area(snapshot, pattern, *area, options, &skipped);
    if (!records) fail("--area: " + records.error().message);
    // A feature whose place cannot be read is in no area: say so, or it is silently missing.
    for (const std::string& problem : skipped) std::cerr << "tahvel: list: warning: --area: feature skipped: " << problem << '\n';
    records_read = std::move(*records);
  } else {
    records_read = check(snapshot.list(pattern, options));
  }
  const bool more = limit != 0 && records_read.size() > limit;
  if (more) records_read.resize(limit);
  if (records_read.empty() && pattern.p)
    warn_of_a_predicate_held_by_none("list", pattern, check(snapshot.predicates()), prefixes, "this store");
  write_records(std::cout, format, prefixes, records_read);
  finish_output(std::cout);
  // Said to an operator at a terminal only: a script's standard error stays empty on success.
  if (more && isatty(STDERR_FILENO)) std::cerr << "tahvel: list: --limit reached, more records match\n";
  return kExitOk;
}

const Command kDumpCommand{
    "dump",
    "DIR [--format nt|ttl|json]",
    "Print every record, in id order, from one consistent snapshot.",
    "N-Triples output can be loaded into another node with 'tahvel load'.",
    {kFlagFormat},
    1, 1};

int run_dump(const Args& args) {
  node::Node node = open_node(args.positional(0));
  uri::PrefixMap prefixes = prefixes_with_flags(node.prefixes(), args);
  node::Format format = format_flag(args, node::Format::ntriples);
  node::Snapshot snapshot = check(node.snapshot());
  node::RecordWriter writer(std::cout, format, prefixes);
  check(snapshot.for_each({}, [&](const node::Record& r) {
    writer.write(r);
    return static_cast<bool>(std::cout);  // stop early when the reader went away
  }));
  writer.finish();
  finish_output(std::cout);
  return kExitOk;
}

const Command kBackupCommand{
    "backup",
    "DIR DEST",
    "Copy a store, as of one snapshot, to the new directory DEST, while its agents run.",
    "A copy of DIR's files made with cp while agents write may be damaged (a page copied half\n"
    "written); this one is taken from one snapshot, without the store's free pages. DEST must not\n"
    "exist; the copy is made beside it (DEST.partial-PID), synced and renamed to it once whole.\n"
    "To restore, stop the node ('tahvel down', or 'tahvel down --node ID' for a node brought up\n"
    "with 'up --node ID'), put DEST in DIR's place and start it again. The copy has a store id\n"
    "of its own, so its peers take the restored node for another store of it: its children send\n"
    "again what it lacks, its parent gets again what its outbox held and keeps one of each\n"
    "(docs/protocol.md P6a, P6d, P10c). Prints the copy's size in bytes.",
    {},
    2, 2, false};

int run_backup(const Args& args) {
  refuse_when_output_was_closed();
  node::Node node = open_node(args.positional(0));
  // Inside its own store, each backup would carry the ones before it.
  refuse_inside_a_store("backup", args.positional(1), "make the copy in a directory outside it");
  auto bytes = node.back_up(args.positional(1));
  if (!bytes) fail("backup: " + bytes.error().message);
  std::cout << *bytes << "\n";
  finish_output_after(std::cout, "the copy in " + args.positional(1) + " is made",
                      "running it again refuses, as " + args.positional(1) + " exists");
  return kExitOk;
}

const Command kTakeCommand{
    "take",
    "DIR --agent ID [--timeout MS] [--format nt|ttl|json]",
    "Take the oldest item from an agent's input buffer and print it.",
    "Waits up to MS milliseconds (default 0: do not wait) for an item to arrive. Each item is\n"
    "delivered once: it is acknowledged only after it was written to standard output, so a\n"
    "failed write leaves it in the buffer for the next take. Exit status 3, with nothing\n"
    "printed, when the timeout passes without an item. A removal notice (which only agents that\n"
    "asked for them get: a link's) prints as tail prints removals.",
    {{"--agent", "", "ID", "the agent whose input buffer to read (required)"},
     {"--timeout", "", "MS", "wait up to MS milliseconds for an item (default 0)"}, kFlagFormat},
    1, 1};

int run_take(const Args& args) {
  args.required("--agent");
  std::string id = agent_id(args, "");
  milliseconds timeout = timeout_flag(args);
  node::Format format = format_flag(args, node::Format::ntriples);
  node::Node node = open_node(args.positional(0));
  uri::PrefixMap prefixes = prefixes_with_flags(node.prefixes(), args);
  node::Agent agent = check(node.agent(id));
  // Takes of one agent by several processes (a pool of workers) each read the buffer's head and
  // acknowledge it once printed: between the two, another read the same item and printed it too.
  // A take holds the agent's take lock from reading the head again to acknowledging it; the wait
  // for an item happens outside it, so that a waiting take does not hold the others up.
  // The lock is waited for within --timeout too: a take whose output goes to a slow reader (or
  // one stopped by Ctrl-Z) holds it, and the others time out rather than hang.
  // Named after the id as the store knows it: "%41" and "A" are one agent with one buffer, and
  // a lock per spelling let two takes deliver its head twice.
  const auto known_id = uri::child_id(agent.iri(), node.iri());
  const std::string lock_path =
      (std::filesystem::path(args.positional(0)) / (".take-" + (known_id ? *known_id : id) + ".lock")).string();
  struct Lock {
    int fd = -1;
    ~Lock() {
      if (fd >= 0) ::close(fd);
    }
  } lock{::open(lock_path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644)};
  if (lock.fd < 0 && errno == EROFS)  // as a write to such a store says (cli.md "read-only filesystem")
    fail("the store in " + args.positional(0) + " is on a read-only filesystem: it can be read, not written");
  // A store this user may read but whose directory it may not write (another user's node).
  const auto cannot_make = [&](const std::string& path) {
    const int err = errno;
    std::error_code ec;
    const std::filesystem::path where = std::filesystem::absolute(path, ec);
    fail("take: cannot make its lock file " + (ec ? path : where.string()) + ": " + std::strerror(err) +
         (err == EACCES || err == EPERM ? " (a take writes in the store's directory: run it as the store's owner)" : ""));
  };
  if (lock.fd < 0) cannot_make(lock_path);
  // A program running as this agent (the shipped agents, `tahvel reason`) holds its agent lock
  // for as long as it runs: a take would take its input from under it. Takes share the lock
  // among themselves, a pool of them being one way to run an agent.
  const std::string running_path =
      (std::filesystem::path(args.positional(0)) / (".agent-" + (known_id ? *known_id : id) + ".lock")).string();
  Lock running{::open(running_path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644)};
  if (running.fd < 0) cannot_make(running_path);
  if (flock(running.fd, LOCK_SH | LOCK_NB) != 0)
    fail(errno == EWOULDBLOCK ? "another process runs as agent <" + agent.iri() + "> (" + running_path +
                                    " is locked): a take would take its input from it; stop it first, or take "
                                    "as an agent of your own"
                              : "lock " + running_path + ": " + std::strerror(errno));
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  const auto left = [&] {
    return std::max(milliseconds(0), std::chrono::duration_cast<milliseconds>(deadline - std::chrono::steady_clock::now()));
  };
  std::optional<node::Delivery> delivery;
  for (;;) {
    if (!check(agent.take(left(), node::Ack::manual))) return kExitTimeout;
    while (flock(lock.fd, LOCK_EX | LOCK_NB) != 0) {
      if (errno != EWOULDBLOCK && errno != EINTR) fail(lock_path + ": " + std::strerror(errno));
      if (left() == milliseconds(0)) return kExitTimeout;
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    delivery = check(agent.take(milliseconds(0), node::Ack::manual));
    if (delivery) break;
    flock(lock.fd, LOCK_UN);  // another take had it: wait for the next one
  }
  if (delivery->removal) {
    // A removal notice (a link's agents receive them): printed as tail prints removals.
    node::RecordWriter writer(std::cout, format, {});
    for (const node::Record& record : delivery->records) writer.write(node::Change{delivery->item, true, record});
  } else {
    write_records(std::cout, format, prefixes, delivery->records);
  }
  finish_output(std::cout);
  check(agent.ack(delivery->item));
  return kExitOk;
}

const Command kTailCommand{
    "tail",
    "DIR [-s S] [-p P] [-o O] [--context IRI] [--source IRI] [--under IRI] [--format nt|ttl|json] [--count N]",
    "Print records as they are stored from now on, until interrupted.",
    "Starts after the last record present when it starts and follows the node's change stream.\n"
    "Removals are printed as '# removed ID' (N-Triples, Turtle) or as the record's JSON object\n"
    "with \"removed\":true and the change's \"seq\". With --count N it exits 0 after N records\n"
    "(removals are not counted).",
    {kFlagS, kFlagP, kFlagO, kFlagListContext, kFlagSource, kFlagUnder, kFlagFormat,
     {"--count", "", "N", "exit after printing N records (default 0: run until interrupted)"}},
    1, 1};

int run_tail(const Args& args) {
  node::Node node = open_node(args.positional(0));
  uri::PrefixMap prefixes = prefixes_with_flags(node.prefixes(), args);
  node::Pattern pattern = pattern_from_args(args, prefixes);
  node::Format format = format_flag(args, node::Format::ntriples);
  std::uint64_t count = args.get_u64("--count", 0);
  std::uint64_t bookmark = check(node.snapshot()).last_seq();
  std::uint64_t printed = 0;
  while (count == 0 || printed < count) {
    std::vector<node::Change> changes = check(node.watch(bookmark, milliseconds(60'000)));
    if (changes.empty()) continue;
    bookmark = changes.back().seq;
    print_changes(std::cout, changes, pattern, format, prefixes, count, printed);
  }
  return kExitOk;
}

const Command kStatsCommand{
    "stats",
    "DIR [--json] [--predicates [--at NODE-IRI [--timeout S]]]",
    "Print the node's settings and counters, or what it holds per predicate.",
    "Text output has one 'key: value' line per counter; --json prints one JSON object with the\n"
    "same keys. --predicates prints, per predicate, the records and the asserted-at of the first\n"
    "and last stored: what there is to ask for. With --at, of a node below DIR's, as its\n"
    "supervisor last wrote it on its board (every 5 s), read through the running link.",
    {{"--json", "", "", "print one JSON object instead of key: value lines"},
     {"--predicates", "", "", "what the store holds per predicate"},
     {"--at", "", "NODE-IRI", "with --predicates: of the node at NODE-IRI below DIR's (exit 4 unknown, 5 unreachable)"},
     {"--timeout", "", "S", "with --at: seconds to wait for the answer (default 10; exit 3)"}},
    1, 1};

int run_stats(const Args& args) {
  node::Node node = open_node(args.positional(0));
  if ((args.has("--at") || args.has("--timeout")) && !args.has("--predicates"))
    usage_error("stats: --at and --timeout go with --predicates");
  if (args.has("--timeout") && !args.has("--at"))  // the local table needs no waiting: a --timeout there is a mistake
    usage_error("stats: --timeout goes with --at (the time to wait for a node below)");
  if (args.has("--predicates")) return print_predicates(node, args);
  node::Stats stats = check(node.stats());
  if (args.has("--json")) {
    print_stats_json(stats);
  } else {
    print_stats_text(stats);
  }
  finish_output(std::cout);
  return kExitOk;
}

}  // namespace tahvel::cli
