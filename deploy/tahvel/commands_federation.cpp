// Federation on the command line: `tahvel link` (a node's communication agent), `tahvel query`
// (a remote query from this node down the tree), `tahvel up` / `tahvel down` (a deployment from
// a topology file under a supervisor) and `tahvel status` (the tree of nodes and agents).
#include <fcntl.h>
#include <sys/statvfs.h>
#include <sys/sysmacros.h>
#include <signal.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <pwd.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cctype>
#include <cerrno>
#include <cstdio>
#include <charconv>
#include <chrono>
#include <cstring>
#include <fstream>
#include <iostream>
#include <limits>
#include <map>
#include <memory>
#include <optional>
#include <sstream>
#include <set>
#include <thread>

#include "commands.h"
#include "tahvel/aggregation/hrv.h"
#include "tahvel/agents/dispatcher.h"
#include "tahvel/spatial/area_subscriptions.h"
#include "tahvel/agents/supervisor.h"
#include "tahvel/federation/link.h"
#include "tahvel/federation/transport.h"
#include "tahvel/node/format.h"
#include "tahvel/node/process.h"
#include "tahvel/node/stop_signal.h"
#include "tahvel/spatial/board.h"
#include "tahvel/spatial/wkt.h"
#include "tahvel/uri/iri.h"
#include "tahvel/uri/spelling.h"
#include "dataflow.h"
#include "opening.h"
#include "program_board.h"
#include "topology.h"
#include "vocabulary.h"

namespace tahvel::cli {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;

inline constexpr int kExitUnknownNode = 4;
inline constexpr int kExitUnreachable = 5;
inline constexpr int kExitInterrupted = 130;  // as a shell reports a command ended by SIGINT
// `up` refused to start as things stand (the file or a file it names, a store it would run, its
// owner or permissions, a supervisor already there): nothing was started or changed, and starting
// it again before someone acts fails the same way. A service manager told so
// (RestartPreventExitStatus=6 in deploy/systemd) stops restarting it.
inline constexpr int kExitFileRefused = 6;

// --- transports ---------------------------------------------------------------------------

// The settings of one transport from the flags, `prefix` "" for the parent side and "--listen-"
// for the children's side (which falls back to the parent side's flag when not given).
struct TransportFlags {
  std::string kind;
  federation::LcmSettings lcm;
  federation::DdsSettings dds;
  std::string dds_config_file;

  // An LCM link's two ends listen on different ports (LcmEnd), so a node's end toward its
  // parent never serves its children too.
  bool same_endpoint(const TransportFlags& o) const {
    if (kind != o.kind) return false;
    if (kind == "lcm") return lcm.url == o.lcm.url && lcm.end == o.lcm.end;
    return dds.domain == o.dds.domain && dds_config_file == o.dds_config_file;
  }
};

TransportFlags transport_flags(const std::string& kind, const Args& args, const std::string& prefix) {
  auto flag = [&](const std::string& name) -> std::optional<std::string> {
    if (!prefix.empty()) {
      if (auto v = args.get(prefix + name)) return v;
    }
    return args.get("--" + name);
  };
  TransportFlags t;
  t.kind = kind;
  if (kind == "lcm") {
    if (auto url = flag("lcm-url")) t.lcm.url = *url;
    t.lcm.end = prefix.empty() ? federation::LcmEnd::child : federation::LcmEnd::parent;
  } else if (kind == "dds") {
    if (auto domain = flag("dds-domain")) {
      auto n = parse_u64(*domain);
      if (!n || *n > 232) usage_error("DDS domain '" + *domain + "': give a number from 0 to 232");
      t.dds.domain = static_cast<std::uint32_t>(*n);
    }
    if (auto file = flag("dds-config")) {
      t.dds_config_file = *file;
      t.dds.config = read_input(*file);
    }
  } else {
    usage_error("transport kind '" + kind + "': use lcm or dds");
  }
  return t;
}

std::shared_ptr<federation::Transport> open_transport(const TransportFlags& t, const std::string& self,
                                                      federation::DropLog log) {
  node::Result<std::unique_ptr<federation::Transport>> transport =
      t.kind == "lcm" ? federation::open_lcm(t.lcm, self, std::move(log)) : federation::open_dds(t.dds, self, std::move(log));
  return std::shared_ptr<federation::Transport>(check(std::move(transport)));
}

// The terms of a pattern, split at blanks outside a quoted literal ('"x y"@en' is one term).
std::vector<std::string> pattern_terms(const std::string& text) {
  std::vector<std::string> terms;
  std::size_t i = 0;
  while (i < text.size()) {
    if (std::isspace(static_cast<unsigned char>(text[i]))) {
      ++i;
      continue;
    }
    const std::size_t start = i;
    if (text[i] == '"') {
      for (++i; i < text.size() && text[i] != '"'; ++i)
        if (text[i] == '\\') ++i;
      if (i < text.size()) ++i;  // the closing quote; an unclosed one is parse_term's to say
    }
    while (i < text.size() && !std::isspace(static_cast<unsigned char>(text[i]))) ++i;
    terms.push_back(text.substr(start, i - start));
  }
  return terms;
}

// "S P O" with '_' for any position, in the node's prefixes. Errors name `origin` (the flag, or
// the pattern as a topology file writes it).
node::Pattern forward_pattern(const std::string& text, const uri::PrefixMap& prefixes, std::string_view origin = "--forward") {
  const std::vector<std::string> terms = pattern_terms(text);
  if (terms.size() != 3)
    usage_error(std::string(origin) + " '" + text + "': write three terms 'S P O', '_' for any (found " +
                std::to_string(terms.size()) + ")");
  node::Pattern pattern;
  const std::string named = origin == "--forward" ? std::string(origin) : std::string(origin) + " '" + text + "'";
  const Position positions[] = {Position::subject, Position::predicate, Position::object};
  std::optional<node::Term>* fields[] = {&pattern.s, &pattern.p, &pattern.o};
  const char* names[] = {"subject", "predicate", "object"};
  for (int k = 0; k < 3; ++k) {
    if (terms[k] == "_") continue;
    *fields[k] = parse_term(terms[k], prefixes, named, positions[k]);
    // A blank node's label is the writer's own: it names no node of the store, so such a
    // pattern would forward nothing (the node refuses it, after the stores were made).
    if ((*fields[k])->is_blank())
      usage_error(named + ": the " + names[k] + " " + terms[k] + " is a blank node, which matches nothing here; write '_' for any");
  }
  return pattern;
}

volatile sig_atomic_t g_stop = 0;
void on_stop_signal(int) { g_stop = 1; }
// A running supervisor is asked to apply a changed topology file (`tahvel up` again).
volatile sig_atomic_t g_apply = 0;
void on_apply_signal(int) { g_apply = 1; }

}  // namespace

bool stop_requested() { return g_stop != 0; }

namespace {

// Without SA_RESTART: a write blocked on a full pipe returns at the signal (EINTR), and
// PieceOutput ends the output there, at the end of a piece.
void install_stop_handlers() {
  struct sigaction action {};
  action.sa_handler = on_stop_signal;
  sigemptyset(&action.sa_mask);
  sigaction(SIGTERM, &action, nullptr);
  sigaction(SIGINT, &action, nullptr);
}

// --- times ----------------------------------------------------------------------------------


const Flag kFlagLcmUrl{"--lcm-url", "", "URL", "LCM URL of the link to the parent: frames up on its PORT, down on PORT + 1 (default udpm://239.255.76.67:7667?ttl=0)"};
const Flag kFlagDdsDomain{"--dds-domain", "", "N", "Cyclone DDS domain id (default 0)"};
const Flag kFlagDdsConfig{"--dds-config", "", "FILE", "Cyclone DDS XML configuration"};
const Flag kFlagListenLcmUrl{"--listen-lcm-url", "", "URL", "LCM URL children reach this node on (default: --lcm-url)"};
const Flag kFlagListenDdsDomain{"--listen-dds-domain", "", "N", "DDS domain children reach this node on (default: --dds-domain)"};
const Flag kFlagListenDdsConfig{"--listen-dds-config", "", "FILE", "Cyclone DDS configuration for the children's side (default: --dds-config)"};
const Flag kFlagState{"--state", "", "DIR", "the deployment's state directory (default ./state)"};

// `path` as one word of a shell command the operator may paste: as it is when it has only
// characters no shell treats specially, else in double quotes ("/srv/my state").
std::string shell_word(const fs::path& path) {
  const std::string text = path.string();
  const bool plain = !text.empty() && std::all_of(text.begin(), text.end(), [](char c) {
    return std::isalnum(static_cast<unsigned char>(c)) || std::string_view("/._-+,:@%=").find(c) != std::string_view::npos;
  });
  if (plain) return text;
  std::string quoted = "\"";
  for (char c : text) {
    if (c == '"' || c == '\\' || c == '$' || c == '`') quoted += '\\';
    quoted += c;
  }
  return quoted + "\"";
}

// --state DIR: the directory holding the node stores. A node's own store given instead (every
// other command takes one as DIR) made `up` build a second deployment inside it.
fs::path state_dir(const Args& args) {
  const fs::path state = args.get("--state").value_or("state");
  if (state.empty()) usage_error("--state: give the deployment's state directory (default ./state)");
  std::error_code ec;
  if (fs::exists(state / "data.mdb", ec)) {
    std::string iri;
    if (auto node = node::Node::open(state)) iri = " <" + node->iri() + ">";
    fs::path store = fs::absolute(state, ec).lexically_normal();
    if (!store.has_filename()) store = store.parent_path();  // "st/home/"
    const fs::path parent = store.parent_path();
    fail(state.string() + " is the store of a node" + iri + ", not a state directory: --state takes the directory "
         "that holds the node stores (here " + parent.string() + ")");
  }
  if (fs::exists(state, ec) && !fs::is_directory(state, ec))
    fail(state.string() + " is a file, not a directory: --state takes the directory that holds the node stores");
  return state;
}

// The spatial library's answer to a query by area (federation::AreaQuery): the area is a room's
// absolute IRI or WKT, as the asking node sent it.
node::Result<std::vector<node::Record>> area_answer(const node::Snapshot& snapshot, const node::Pattern& pattern,
                                                    const std::string& area, std::optional<std::int64_t> floor,
                                                    const node::ListOptions& options) {
  spatial::AreaSpec spec;
  if (spatial::looks_like_wkt(area)) {
    auto shape = spatial::parse_shape(area);
    if (!shape) return node::fail(node::Errc::syntax, "area: " + shape.error().message);
    spec.shape = std::move(*shape);
    if (floor) spec.floor = static_cast<int>(*floor);
  } else {
    spec.room_iri = area;
  }
  auto records = spatial::list_in_area(snapshot, pattern, spec, options);
  // Not not_found: that is an unknown node to query (exit 4); a room the plan lacks is the
  // query's own mistake, as `list --area` and a target below say it (exit 1).
  if (!records) return node::fail(node::Errc::invalid_argument, records.error().message);
  return std::move(*records);
}

}  // namespace

// --- tahvel link ------------------------------------------------------------------------------

const Command kLinkCommand{
    "link",
    "DIR [--parent IRI --up lcm|dds] [--listen lcm|dds]... [--child ID]... [--forward 'S P O']... [--no-default-forward]\n"
    "            [--lcm-url URL] [--dds-domain N] [--dds-config FILE] [--listen-lcm-url URL] [--listen-dds-domain N]\n"
    "            [--listen-dds-config FILE]",
    "Run a node's communication agent (normally started by 'tahvel up').",
    "Links the node at DIR to its parent (--parent, over --up) and serves its children (--listen).\n"
    "Items its agent 'uplink' subscribes to go up exactly once (the policy: --forward patterns,\n"
    "default HRV windows); items addressed to a node below go down; queries are answered or\n"
    "routed on. Runs until SIGTERM or SIGINT. The protocol is docs/protocol.md.",
    {{"--parent", "", "IRI", "the parent node's IRI"},
     {"--up", "", "lcm|dds", "transport to the parent"},
     {"--listen", "", "lcm|dds", "transport children reach this node on (repeatable: lcm and dds)", true},
     {"--child", "", "ID", "accept this child id (repeatable; default: any direct child)", true},
     {"--forward", "", "'S P O'", "forward items with a triple matching (repeatable; '_' = any)", true},
     {"--no-default-forward", "", "", "never subscribe the default policy (the policy on the board is the whole of it)"},
     kFlagLcmUrl, kFlagDdsDomain, kFlagDdsConfig, kFlagListenLcmUrl, kFlagListenDdsDomain, kFlagListenDdsConfig},
    1, 1};

int run_link(const Args& args) {
  node::Node node = open_node(args.positional(0));
  uri::PrefixMap prefixes = prefixes_with_flags(node.prefixes(), args);
  federation::LinkOptions options;
  options.dir = args.positional(0);
  auto log = [iri = node.iri()](std::string_view line) {
    node::write_log_line("tahvel link <" + iri + ">: " + std::string(line));
  };
  options.log = log;
  auto parent = args.get("--parent");
  auto up = args.get("--up");
  if (parent.has_value() != up.has_value()) usage_error("--parent and --up go together");
  const std::vector<std::string> listens = args.all("--listen");
  if (!parent && listens.empty()) usage_error("give --parent IRI --up KIND, --listen KIND, or both");
  for (std::size_t i = 0; i < listens.size(); ++i)
    for (std::size_t j = 0; j < i; ++j)
      if (listens[i] == listens[j]) usage_error("--listen " + listens[i] + " is given twice: a node listens once on each kind");
  std::optional<TransportFlags> up_flags;
  std::vector<TransportFlags> listen_flags;
  if (up) up_flags = transport_flags(*up, args, "");
  for (const auto& kind : listens) listen_flags.push_back(transport_flags(kind, args, "--listen-"));
  if (up) {
    options.parent_iri = parse_iri(*parent, prefixes, "--parent");
    options.up = open_transport(*up_flags, node.iri(), log);
  }
  // One endpoint serves both sides only when they are the same DDS domain and configuration; a
  // gateway may reach its parent on one domain and its children on another.
  for (const auto& flags : listen_flags) {
    auto transport = up_flags && up_flags->same_endpoint(flags) ? options.up : open_transport(flags, node.iri(), log);
    if (!options.down) {
      options.down = std::move(transport);
    } else if (transport == options.up) {  // the endpoint to the parent serves children too: first
      options.also_down.push_back(std::exchange(options.down, std::move(transport)));
    } else {
      options.also_down.push_back(std::move(transport));
    }
  }
  options.children = args.all("--child");
  options.area_query = area_answer;
  for (const auto& text : args.all("--forward")) options.forward.push_back(forward_pattern(text, prefixes));
  options.default_forward = !args.has("--no-default-forward");
  // Stopped by its supervisor it ends with 0; by an operator's `kill`, with 143, and its
  // supervisor starts it again (node/stop_signal.h).
  node::install_stop_signal_handlers();
  auto started = federation::Link::start(std::move(options));
  if (!started) {
    // Restarted by its supervisor, a link says this at every start: which store, and for a
    // damaged one what can be done (an LMDB code alone named neither).
    const node::Error& e = started.error();
    fail("link <" + node.iri() + ">, store " + args.positional(0) + ": " + e.message +
         (e.code == node::Errc::corrupt
              ? "; the store is damaged and cannot be read: stop the node, move its directory aside, and 'tahvel up' "
                "makes a new one (its parent takes it as a new stream; what was only in the damaged store is lost)"
              : std::string()));
  }
  auto link = std::move(*started);
  log(std::string("running") + (parent ? " (parent <" + *parent + "> over " + *up + ")" : "") +
      (listens.empty() ? "" : " (children over " + (listens.size() == 1 ? listens[0] : listens[0] + " and " + listens[1]) + ")"));
  while (!node::stop_signal_received()) std::this_thread::sleep_for(100ms);
  link->stop();
  auto c = link->counters();
  log("stopped; sent up " + std::to_string(c.up_sent) + ", relayed in " + std::to_string(c.relayed_in) + ", duplicates dropped " +
      std::to_string(c.duplicates_in) + ", applied from above " + std::to_string(c.down_applied) + ", items refused " +
      std::to_string(c.items_refused) + ", refused by the other end " + std::to_string(c.items_refused_by_peer) +
      ", frames taken on the transport's thread " + std::to_string(c.taken_pushed));
  return node::stop_exit_status();
}

// --- tahvel query -----------------------------------------------------------------------------

const Command kQueryCommand{
    "query",
    "DIR --at NODE-IRI [-s S] [-p P] [-o O] [--source IRI] [--under IRI] [--area IRI|WKT [--floor N]] [--since T] [--until T] [--cascade N] [--limit N] [--format nt|ttl|json] [--timeout S]",
    "Ask a node below this one for its records; the answer streams back.",
    "Run against the node at DIR (e.g. the hospital): the query travels down the tree to the node\n"
    "at --at, is answered from its store and comes back in chunks, printed as they arrive. Times\n"
    "(--since, --until; by asserted-at) are ns since the epoch or RFC 3339 times: 2026-11-21T10:00:00Z, …T12:00:00.5+02:00;\n"
    "a record that holds for a span of time (an ECG chunk, its second) is in a range it overlaps.\n"
    "With --area the node that answers keeps the records located in a room or WKT area of its own\n"
    "floor plan (as 'tahvel list --area' does there; docs/spatial.md). --under names one\n"
    "recording's chunks where a node holds several patients' ('tahvel patients' prints it).\n"
    "Exit status: 0 answered, 3 timeout, 4 unknown node, 5 unreachable node, 2 usage error,\n"
    "130 interrupted (the query is cancelled below), 1 other failure.",
    {{"--at", "", "NODE-IRI", "the node that answers (this node or any node below it)"},
     kFlagS, kFlagP, kFlagO, kFlagSource, kFlagUnder,
     {"--area", "", "IRI|WKT", "only records located in this room or (MULTI)POLYGON, resolved at the target"},
     {"--floor", "", "N", "with a WKT --area: only that floor"},
     kFlagSince, kFlagUntil, kFlagCascade,
     {"--limit", "", "N", "at most N records (0: no limit)"},
     {"--timeout", "", "S", "give up after S seconds (default 30; a fraction allowed: 2.5)"},
     kFlagFormat},
    1, 1};

std::chrono::milliseconds seconds_flag(const Args& args, std::string_view command, std::chrono::milliseconds fallback,
                                       std::chrono::seconds at_most) {
  auto text = args.get("--timeout");
  if (!text) return fallback;
  double seconds = 0;
  auto [end, ec] = std::from_chars(text->data(), text->data() + text->size(), seconds);
  if (ec != std::errc() || end != text->data() + text->size() || !(seconds >= 0.001) ||
      seconds > static_cast<double>(at_most.count()))
    usage_error(std::string(command) + ": --timeout: '" + *text + "' is not a number of seconds from 0.001 to " +
                std::to_string(at_most.count()));
  return std::chrono::milliseconds(static_cast<std::int64_t>(seconds * 1000 + 0.5));
}

// A remote query's error as `command`'s failure, with the exit status that says which it was
// (docs/cli.md): 3 no answer in time, 4 unknown node, 5 unreachable, 1 anything else.
namespace {
std::int64_t remote_predicates(node::Node& node, const std::string& target, std::chrono::milliseconds timeout,
                               std::vector<node::PredicateSummary>& out);
[[noreturn]] void fail_remote(std::string_view command, const node::Error& e) {
  const int status = e.code == node::Errc::timeout ? kExitTimeout
                     : e.code == node::Errc::not_found ? kExitUnknownNode
                     : e.message.rfind("unreachable", 0) == 0 ? kExitUnreachable
                     : kExitFailure;
  throw Failure{status, std::string(command) + ": " + e.message};
}
}  // namespace

int run_query(const Args& args) {
  node::Node node = open_node(args.positional(0));
  uri::PrefixMap prefixes = prefixes_with_flags(node.prefixes(), args);
  federation::RemoteQuery query;
  query.target = parse_node_iri(args.required("--at"), prefixes, "--at", node.iri());
  query.pattern = pattern_from_args(args, prefixes);
  query.cascade = cascade_flag(args);
  // One record more than --limit is asked for, and not printed: it tells a cut answer from a
  // whole one (an operator asking for the latest 100 records must know that there are more).
  const std::uint64_t limit = args.get_u64("--limit", 0);
  query.limit = limit == 0 || limit == std::numeric_limits<std::uint64_t>::max() ? limit : limit + 1;
  if (auto area = args.get("--area")) {
    if (spatial::looks_like_wkt(*area)) {
      if (auto shape = spatial::parse_shape(*area); !shape) usage_error("--area: " + shape.error().message);
      query.area = *area;
    } else {
      query.area = parse_iri(*area, prefixes, "--area");  // absolute: the target's prefixes may differ
      if (args.has("--floor")) usage_error("--floor: only with a WKT --area (a room has its own floor)");
    }
    if (auto floor = args.get("--floor")) query.floor = floor_flag(*floor);
  } else if (args.has("--floor")) {
    usage_error("--floor: only with --area");
  }
  const std::chrono::milliseconds timeout = seconds_flag(args, "query", std::chrono::seconds(30), std::chrono::hours(24));
  node::Format format = format_flag(args, node::Format::ntriples);
  // Printed as the records come, Turtle too (with all of DIR's prefixes, as `dump` does: the
  // prefixes a long answer uses are known only at its end, and it must not wait in memory).
  // Each record is one piece of the output: a Ctrl-C ends it after a whole record.
  PieceOutput out;
  std::optional<node::RecordWriter> writer;
  std::uint64_t printed = 0;
  bool more = false;
  ask_below("query", node, query, timeout, out, [&](const node::Record& r) {
    if (limit != 0 && printed == limit) {
      more = true;
      return;
    }
    ++printed;
    if (!writer) writer.emplace(out.stream(), format, prefixes);
    writer->write(r);
    out.end_piece();
  }, [&] {
    // An empty answer in Turtle is the prefixes alone (docs/cli.md: they come first).
    if (!writer && format == node::Format::turtle) writer.emplace(out.stream(), format, prefixes);
    if (writer) writer->finish();
    out.finish();
  }, "record");
  out.check();
  // The target's holdings as its supervisor last wrote them (a second query, after an empty
  // answer only); none read, nothing said: a node not run by 'tahvel up' has none.
  if (printed == 0 && query.pattern.p) {
    std::vector<node::PredicateSummary> held;
    if (query.target == node.iri()) {
      if (auto snapshot = node.snapshot(); snapshot)
        if (auto here = snapshot->predicates(); here)
          warn_of_a_predicate_held_by_none("query", query.pattern, *here, prefixes, "this store");
    } else {
      try {
        if (const std::int64_t written = remote_predicates(node, query.target, std::min(timeout, std::chrono::milliseconds(5000)), held))
          warn_of_a_predicate_held_by_none("query", query.pattern, held, prefixes,
                                           "<" + query.target + "> (as its supervisor wrote it " + age_of(written) + ")");
      } catch (const Failure&) {
      }
    }
  }
  // A count for the operator at a terminal; a script's standard error stays empty on success.
  if (isatty(STDERR_FILENO)) {
    auto target = uri::normalize(query.target);
    std::cerr << "tahvel: query: " << printed << (printed == 1 ? " record" : " records") << " from <"
              << (target ? *target : query.target) << ">" << (more ? "; --limit reached, more records match" : "") << "\n";
  }
  return kExitOk;
}

// Of a node below that is no child (anymore): a store of it, or of the node it lies below,
// kept beside this node's in its state directory (`tahvel up` keeps the store of a node taken
// out of the file). An integrator's probe of session 89: "has no child <…/home2>" did not say
// that the home's data was at state/home2. Empty when none is.
std::string kept_store_hint(const node::Node& node, const std::string& target) {
  std::error_code ec;
  fs::path here = fs::absolute(node.dir(), ec).lexically_normal();
  if (ec) return {};
  if (!here.has_filename()) here = here.parent_path();  // given as "state/hospital/"
  const fs::path state = here.parent_path();
  if (state.empty()) return {};
  std::vector<fs::path> dirs;
  for (fs::directory_iterator it(state, ec), end; !ec && it != end; it.increment(ec))
    if (it->path() != here && fs::exists(it->path() / "data.mdb", ec)) dirs.push_back(it->path());
  std::sort(dirs.begin(), dirs.end());
  // The target's own store, else the one of the nearest node it lies below.
  fs::path best;
  std::string best_iri;
  for (const fs::path& dir : dirs) {
    // A store that cannot be opened here is simply not named.
    auto other = node::Node::open(dir);
    if (!other) continue;
    const std::string iri = other->iri();
    if (iri != target && !uri::is_under(target, iri)) continue;
    if (best_iri.empty() || iri.size() > best_iri.size()) {
      best = dir;
      best_iri = iri;
    }
  }
  if (best_iri.empty()) return {};
  return "; a store of <" + best_iri + "> is kept at " + best.string() + " on this machine (a node taken out of the deployment?): " +
         "ask it there, as in 'tahvel query " + shell_word(best) + (best_iri == target ? "" : " --at " + shell_word(target)) + " ...'";
}

std::uint64_t ask_below(std::string_view command, node::Node& node, const federation::RemoteQuery& query,
                        std::chrono::milliseconds timeout, PieceOutput& out, const std::function<void(const node::Record&)>& each,
                        const std::function<void()>& answered, std::string_view piece) {
  // Ctrl-C, SIGTERM or a reader that went away (`| head`) cancels the query below (P18) instead
  // of leaving its answer to run on into this node's store.
  install_stop_handlers();
  out.set_deadline(std::chrono::steady_clock::now() + timeout);
  auto cancelled = [&out] { return g_stop != 0 || !out.good(); };
  auto got = federation::remote_query(node, query, timeout, each, area_answer, cancelled);
  if (answered) answered();
  const std::string name(command);
  if (out.timed_out() && !g_stop) {
    const auto target = uri::normalize(query.target);
    const std::uint64_t n = out.written();
    throw Failure{kExitTimeout, name + ": timeout: the answer from <" + (target ? *target : query.target) + "> was not written out within " +
                                    seconds_text(timeout.count() / 1000.0) + ": standard output took no more (a reader that stopped reading, "
                                    "a pager left open: give it a longer --timeout); " + std::to_string(n) + " " + std::string(piece) +
                                    (n == 1 ? "" : "s") + " written out" +
                                    (out.cut() ? ", the next cut short" : "")};
  }
  // Interrupted while the answer came, or while the last of it was written out: what was
  // written out is counted (not what came: the rest never reached the reader).
  if (g_stop && (!got || !out.good())) {
    const auto target = uri::normalize(query.target);
    const std::uint64_t n = out.written();
    throw Failure{kExitInterrupted, name + ": interrupted; " + (got ? "stopped writing the answer out" : "cancelled") +
                                        " after " + std::to_string(n) + " " + std::string(piece) + (n == 1 ? "" : "s") +
                                        " from <" + (target ? *target : query.target) + ">" +
                                        (out.cut() ? "; the next is cut short (standard output took nothing for 2 s)" : "")};
  }
  if (!got && !out.good()) {
    // A reader that went away (`tahvel query … | head`) is not worth a message, as for every
    // command; a write that failed otherwise (a full disk) is.
    if (out.error() == EPIPE || stdout_reader_gone()) throw Failure{kExitFailure, ""};
    throw Failure{kExitFailure, name + ": cannot write the answer to standard output (" + std::strerror(out.error()) + "); " +
                                    got.error().message};
  }
  if (!got) {
    // What was written out is a correct beginning of the answer; the operator is told how much
    // of it came before the failure, as a timeout or an interrupt tells it.
    node::Error e = got.error();
    if (e.code == node::Errc::not_found) e.message += kept_store_hint(node, query.target);
    if (const std::uint64_t n = out.written(); n > 0)
      e.message += "; " + std::to_string(n) + " " + std::string(piece) + (n == 1 ? "" : "s") + " written out before it";
    fail_remote(command, e);
  }
  return *got;
}

// --- tahvel stats --predicates [--at IRI] -------------------------------------------------------

namespace {

// The holdings item a node's supervisor wrote on its board (agents/supervisor.h), asked for
// through the link. The time it was written, 0 when the node's board has none.
std::int64_t remote_predicates(node::Node& node, const std::string& target, std::chrono::milliseconds timeout,
                               std::vector<node::PredicateSummary>& out) {
  auto writer = uri::agent_iri(target, "supervisor");
  if (!writer) throw Failure{kExitUsage, "stats: --at <" + target + ">: " + writer.error().message};
  std::int64_t written = 0;
  std::map<std::string, node::PredicateSummary> by_holding;  // by the blank node's label there
  auto number = [](const node::Term& t) {
    std::int64_t n = 0;
    std::from_chars(t.value.data(), t.value.data() + t.value.size(), n);
    return n;
  };
  // One query (what the supervisor wrote about the node and, one level down, its holdings), so
  // that the time and the figures are of one write: it replaces them every 5 s.
  auto held = federation::remote_query(node, {.target = target, .pattern = {.s = node::Term::iri(target)}, .cascade = 1},
                                       timeout, [&](const node::Record& r) {
                                         if (r.meta.source != *writer) return;
                                         if (r.triple.s.value == target && r.triple.p.value == agents::vocab::kHoldingsAt) {
                                           written = std::max(written, number(r.triple.o));
                                           return;
                                         }
                                         if (!r.triple.s.is_blank()) return;
                                         node::PredicateSummary& h = by_holding[r.triple.s.value];
                                         if (r.triple.p.value == agents::vocab::kHeldPredicate) h.predicate = r.triple.o.value;
                                         else if (r.triple.p.value == agents::vocab::kHeldRecords) h.records = static_cast<std::uint64_t>(number(r.triple.o));
                                         else if (r.triple.p.value == agents::vocab::kFirstAssertedAt) h.first_asserted_at = number(r.triple.o);
                                         else if (r.triple.p.value == agents::vocab::kLastAssertedAt) h.last_asserted_at = number(r.triple.o);
                                       });
  if (!held) fail_remote("stats", held.error());
  for (auto& [label, h] : by_holding)
    if (!h.predicate.empty()) out.push_back(std::move(h));
  std::sort(out.begin(), out.end(), [](const auto& a, const auto& b) { return a.predicate < b.predicate; });
  return written;
}

}  // namespace

int print_predicates(node::Node& node, const Args& args) {
  const uri::PrefixMap prefixes = prefixes_with_flags(node.prefixes(), args);
  std::vector<node::PredicateSummary> held;
  std::optional<std::string> target;
  if (auto at = args.get("--at")) target = parse_node_iri(*at, prefixes, "--at", node.iri());
  std::int64_t written = 0;  // 0: read here and now
  if (target && *target != node.iri()) {
    written = remote_predicates(node, *target, seconds_flag(args, "stats", std::chrono::seconds(10), std::chrono::seconds(600)), held);
    if (written == 0)
      throw Failure{kExitFailure, "stats: <" + *target + ">'s board has no holdings item: its supervisor ('tahvel up') writes "
                                  "one every 5 s; a node not run by 'tahvel up', or by an older version, has none"};
  } else {
    held = check(check(node.snapshot()).predicates());
  }
  // The data first: the predicates of most records (a node's own bookkeeping has a few each).
  std::stable_sort(held.begin(), held.end(), [](const auto& a, const auto& b) { return a.records > b.records; });
  const std::string iri = target.value_or(node.iri());
  if (args.has("--json")) {
    std::cout << "{\"iri\":\"" << node::json_escape(iri) << "\",\"written_ns\":";
    if (written) std::cout << written; else std::cout << "null";
    std::cout << ",\"predicates\":[";
    for (std::size_t k = 0; k < held.size(); ++k)
      std::cout << (k ? "," : "") << "{\"predicate\":\"" << node::json_escape(held[k].predicate) << "\",\"records\":" << held[k].records
                << ",\"first_asserted_at_ns\":" << held[k].first_asserted_at << ",\"last_asserted_at_ns\":" << held[k].last_asserted_at << "}";
    std::cout << "]}\n";
  } else {
    std::cout << "<" << iri << "> holds" << (written ? " (as its supervisor wrote it " + age_of(written) + ")" : std::string()) << ":\n";
    std::size_t width = 9;
    std::vector<std::string> names;
    for (const auto& h : held) {
      std::string curie = prefixes.compact(h.predicate);
      names.push_back(curie == h.predicate ? "<" + curie + ">" : curie);
      width = std::max(width, names.back().size());
    }
    auto row = [&](const std::string& name, const std::string& records, const std::string& first, const std::string& last) {
      std::cout << name << std::string(width + 1 - name.size(), ' ') << std::string(10 - std::min<std::size_t>(10, records.size()), ' ')
                << records << "  " << first << std::string(28 - std::min<std::size_t>(27, first.size()), ' ') << last << "\n";
    };
    row("predicate", "records", "first stored, asserted at", "last stored, asserted at");
    for (std::size_t k = 0; k < held.size(); ++k)
      row(names[k], std::to_string(held[k].records), node::utc_text(held[k].first_asserted_at), node::utc_text(held[k].last_asserted_at));
  }
  finish_output(std::cout);
  return kExitOk;
}

// --- tahvel up / down / status ----------------------------------------------------------------

namespace {

// The argv of a node's link process.
std::vector<std::string> link_argv(const Topology& topo, const NodeSpec& spec, const fs::path& store, const fs::path& bin) {
  std::vector<std::string> argv{(bin / "tahvel").string(), "link", store.string()};
  // The parent's side with the plain flags, the children's side with the --listen- ones.
  auto transport_flags = [&](const LinkSpec& l, const std::string& prefix) {
    if (l.kind == "lcm") argv.insert(argv.end(), {prefix + "lcm-url", l.lcm_url});
    if (l.kind == "dds") {
      argv.insert(argv.end(), {prefix + "dds-domain", std::to_string(l.dds_domain)});
      if (!l.dds_config.empty()) argv.insert(argv.end(), {prefix + "dds-config", fs::absolute(l.dds_config).lexically_normal().string()});
    }
  };
  if (const LinkSpec* uplink = topo.uplink(spec)) {
    argv.insert(argv.end(), {"--parent", topo.node(spec.parent)->iri, "--up", uplink->kind});
    transport_flags(*uplink, "--");
  }
  const auto children = topo.children(spec.id);
  if (!children.empty()) {
    // Every kind the file declares, used by a child of this file or not: a child whose machine's
    // file links it over the other kind (added there first) heard nothing, not the refusal and
    // its reason; and a child moving to the other kind restarted the link under every child.
    for (const LinkSpec& l : spec.listen) {
      argv.insert(argv.end(), {"--listen", l.kind});
      transport_flags(l, "--listen-");
    }
    for (const NodeSpec* child : children) argv.insert(argv.end(), {"--child", child->id});
  }
  for (const auto& f : spec.forward) argv.insert(argv.end(), {"--forward", f});
  // `up` writes the whole policy on the board before the link starts; `forward = []` is none.
  if (!spec.parent.empty()) argv.push_back("--no-default-forward");
  return argv;
}

std::string pid_file_name(const std::optional<std::string>& only) {
  return "supervisor-" + only.value_or("all") + ".pid";
}

// Where the supervisor of `pid_file` lists the nodes it stopped because their store went.
fs::path gone_list_file(const fs::path& pid_file) { return fs::path(pid_file).replace_extension(".gone"); }

// Writes the programs' states to `file` through a temporary file renamed over it, so that a
// reader sees one whole write. Empty when written; else why not (a full disk), and the file
// keeps what it held: an emptied one made `status` show the node without its programs.
std::string write_state_file(const fs::path& file, const agents::Supervisor& sup) {
  fs::path tmp = file;
  tmp += ".tmp";
  std::string failed;
  {
    std::ofstream out(tmp);
    const auto now = std::chrono::steady_clock::now();
    for (const auto& s : sup.states()) {
      std::string state = s.running ? "running" : "stopped";
      // Alive but doing nothing, and what to do about it (a SIGSTOPped link looks like a link
      // that is down, from its parent's and children's side).
      if (s.running && s.suspended == agents::Suspension::signal)
        state = "suspended (stopped by a signal: 'kill -CONT " + std::to_string(s.pid) + "' resumes it)";
      if (s.running && s.suspended == agents::Suspension::debugger) state = "suspended (stopped by a debugger)";
      if (!s.running && s.restart_at) {
        state = "restarting in " + seconds_text(std::max(0.0, std::chrono::duration<double>(*s.restart_at - now).count()));
      }
      out << s.name << '\t' << s.pid << '\t' << state << '\t' << s.restarts << '\t' << s.last_exit << '\n';
    }
    out.flush();
    if (!out) failed = std::strerror(errno);
    out.close();
    if (failed.empty() && !out) failed = std::strerror(errno);
  }
  std::error_code ec;
  if (failed.empty()) {
    fs::rename(tmp, file, ec);
    if (!ec) return {};
    failed = ec.message();
  }
  fs::remove(tmp, ec);
  return "cannot write " + file.string() + " (" + failed + "); it keeps the programs' states as last written";
}


// A supervisor holds an exclusive lock (flock) on its pid file for as long as it runs; the lock
// goes with the process, however it ends (SIGKILL, power loss). A pid file that nobody holds is
// stale, and the pid in it says nothing: a SIGKILLed supervisor not yet reaped (a zombie, which
// kill(pid, 0) still finds) or, after a reboot, another program that got the same pid. So `up`
// and `down` believe the lock, not the pid. Returns the pid of the supervisor that holds
// `pid_file`, -1 if one holds it and has not written its pid yet, 0 if none does.
pid_t supervisor_holding(const fs::path& pid_file) {
  const int fd = ::open(pid_file.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return 0;
  pid_t pid = 0;
  if (flock(fd, LOCK_SH | LOCK_NB) != 0) {
    pid = -1;
    char text[32] = {};
    if (pread(fd, text, sizeof text - 1, 0) > 0 && std::atoi(text) > 0) pid = std::atoi(text);
  }
  ::close(fd);
  return pid;
}

// Takes `pid_file` for this process (the running supervisor) and writes its pid there; the
// descriptor (returned) stays open, and so the lock held, until the process ends. -1 if another
// supervisor holds it.
int hold_pid_file(const fs::path& pid_file) {
  const int fd = ::open(pid_file.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
  if (fd < 0) return -1;
  if (flock(fd, LOCK_EX | LOCK_NB) != 0) {
    ::close(fd);
    return -1;
  }
  const std::string text = std::to_string(getpid()) + "\n";
  if (ftruncate(fd, 0) != 0 || pwrite(fd, text.data(), text.size(), 0) != static_cast<ssize_t>(text.size())) {
    ::close(fd);
    return -1;
  }
  return fd;  // deliberately left open (close-on-exec: the programs do not inherit it)
}

// Whether `path` is still the file or directory `held` is open on: not when it was removed (the
// state directory by `rm -rf`), or made again by another `up` since.
bool still_holds(int held, const fs::path& path) {
  struct stat mine {}, there {};
  return held >= 0 && fstat(held, &mine) == 0 && mine.st_nlink > 0 && ::stat(path.c_str(), &there) == 0 &&
         there.st_ino == mine.st_ino && there.st_dev == mine.st_dev;
}

// The process holding a flock on `path` (from /proc/locks, by device and inode), or 0.
pid_t flock_holder(const fs::path& path) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) return 0;
  std::ifstream locks("/proc/locks");
  for (std::string line; std::getline(locks, line);) {
    // "1: FLOCK  ADVISORY  WRITE 4711 fd:00:1234567 0 EOF"
    std::istringstream fields(line);
    std::string number, kind, mode, access, pid, where;
    if (!(fields >> number >> kind >> mode >> access >> pid >> where) || kind != "FLOCK") continue;
    unsigned major = 0, minor = 0;
    unsigned long long inode = 0;
    if (std::sscanf(where.c_str(), "%x:%x:%llu", &major, &minor, &inode) != 3) continue;
    if (inode == st.st_ino && major == ::major(st.st_dev) && minor == ::minor(st.st_dev)) return std::atoi(pid.c_str());
  }
  return 0;
}

// The supervisor that holds node store `store` (Deployment::lock_node): its pid, -1 when it is
// held by a process /proc/locks does not name, 0 when none holds it.
pid_t supervisor_of_store(const fs::path& store) {
  const int fd = ::open(store.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd < 0) return 0;
  pid_t holder = 0;
  if (flock(fd, LOCK_SH | LOCK_NB) != 0 && (holder = flock_holder(store)) == 0) holder = -1;  // held, by whom not known
  ::close(fd);
  return holder;
}

struct ProgramRow {
  std::string name, pid, state, restarts, last_exit;
  std::string problem;  // what the program says on its board it cannot do (node::kProblem)
  std::string problem_pid;  // the process that said it (node::kProblemPid), when it said
};

bool alive(const ProgramRow& p);
// Said by a run of the program that is over: it stopped without taking the line back (killed,
// crashed), or a run since has not yet got as far as saying anything.
bool problem_of_a_run_before(const ProgramRow& p) {
  return !p.problem.empty() && (!alive(p) || (!p.problem_pid.empty() && p.problem_pid != p.pid));
}

// A running supervisor rewrites its state file every 100 ms; one that has not for this long is
// stopped (SIGSTOP), hung, or held up (a write to a store it waits for), and what the file says
// of its programs is not known to be true now.
constexpr double kSupervisorSilentS = 5;

// Seconds since the state file beside `pid_file` was written; 0 when there is none.
double state_file_silent_for(const fs::path& pid_file) {
  std::error_code ec;
  const auto written = fs::last_write_time(fs::path(pid_file).replace_extension(".state"), ec);
  if (ec) return 0;
  return std::chrono::duration<double>(fs::file_time_type::clock::now() - written).count();
}

// How long the process `pid` (a decimal number) has run, from /proc; nullopt when not known.
std::optional<double> seconds_running(const std::string& pid) {
  if (pid.empty() || pid.find_first_not_of("0123456789") != std::string::npos) return std::nullopt;
  std::ifstream stat_file("/proc/" + pid + "/stat");
  std::string text;
  std::getline(stat_file, text);
  const std::size_t name_end = text.rfind(')');  // the command name may hold spaces and ')'
  if (name_end == std::string::npos || name_end + 2 > text.size()) return std::nullopt;
  std::istringstream fields(text.substr(name_end + 2));  // from field 3, the state
  std::string skipped;
  for (int field = 3; field < 22; ++field) fields >> skipped;
  double start_ticks = 0, uptime_s = 0;
  std::ifstream uptime_file("/proc/uptime");
  const long ticks_per_s = sysconf(_SC_CLK_TCK);
  if (!(fields >> start_ticks) || !(uptime_file >> uptime_s) || ticks_per_s <= 0) return std::nullopt;
  return std::max(0.0, uptime_s - start_ticks / static_cast<double>(ticks_per_s));
}

// Whether the process `pid` (a decimal number) has exited: /proc has no such process, or it is
// a zombie its parent has not waited for. False when `pid` is not a number.
bool process_has_exited(const std::string& pid) {
  if (pid.empty() || pid.find_first_not_of("0123456789") != std::string::npos) return false;
  std::ifstream stat_file("/proc/" + pid + "/stat");
  if (!stat_file) return true;
  std::string text;
  std::getline(stat_file, text);
  const std::size_t name_end = text.rfind(')');
  return name_end != std::string::npos && name_end + 2 < text.size() &&
         (text[name_end + 2] == 'Z' || text[name_end + 2] == 'X');
}

// A link that runs and has not yet written its uplink's state is starting for this long.
constexpr double kLinkStartingS = 10;

// Why a supervisor may not have written its state file in `dir` for a while: a full disk under
// it, which is then the likely cause, and otherwise "stopped, hung or held up".
// A program's name on node `node` from its IRI (agents::programs_item): the path below the node,
// of one id or several ("behavior/17", a dispatcher's run); nullopt for an IRI not below it so.
std::optional<std::string> program_name(const std::string& iri, const std::string& node) {
  if (auto id = uri::child_id(iri, node)) return *id;
  if (iri.size() <= node.size() + 1 || iri.compare(0, node.size(), node) != 0 || iri[node.size()] != '/') return std::nullopt;
  const std::string path = iri.substr(node.size() + 1);
  for (std::size_t from = 0;;) {
    const std::size_t slash = std::min(path.find('/', from), path.size());
    if (!uri::check_id(std::string_view(path).substr(from, slash - from))) return std::nullopt;
    if (slash == path.size()) return path;
    from = slash + 1;
  }
}

std::string why_state_not_written(const fs::path& dir) {
  struct statvfs disk {};
  // The state file is written anew and renamed into place: it needs a block and an inode.
  if (statvfs(dir.c_str(), &disk) == 0 &&
      (static_cast<double>(disk.f_bavail) * static_cast<double>(disk.f_frsize) < 64 * 1024 || disk.f_favail == 0))
    return "the disk holding " + dir.string() + " is full: it cannot write its state file";
  return "stopped, hung or held up";
}

// The programs' rows of every supervisor's state file in `dir`. A supervisor rewrites its file
// every 100 ms while it runs; one that was killed leaves its last rows behind, and its programs
// died with it (PR_SET_PDEATHSIG), so those rows say so instead of "running". A node brought up
// one way (`up --node X`) and later another (`up` of the whole file) has rows in two files: the
// running supervisor's row wins, then the newest file's, so each program is shown once.
std::vector<ProgramRow> read_state_files(const fs::path& dir) {
  struct StateFile {
    fs::path path;
    bool supervised;
    fs::file_time_type written;
    double silent_s;  // since it was written
  };
  std::vector<StateFile> files;
  std::error_code ec;
  for (const auto& entry : fs::directory_iterator(dir, ec)) {
    if (entry.path().extension() != ".state") continue;
    fs::path pid_file = entry.path();
    pid_file.replace_extension(".pid");
    std::error_code time_ec;
    files.push_back({entry.path(), supervisor_holding(pid_file) != 0, fs::last_write_time(entry.path(), time_ec),
                     state_file_silent_for(pid_file)});
  }
  std::sort(files.begin(), files.end(), [](const StateFile& a, const StateFile& b) {
    return a.supervised != b.supervised ? a.supervised : a.written > b.written;
  });
  std::vector<ProgramRow> rows;
  std::set<std::string> shown;
  for (const StateFile& file : files) {
    std::ifstream in(file.path);
    std::string line;
    while (std::getline(in, line)) {
      std::vector<std::string> f;
      std::stringstream ss(line);
      std::string field;
      while (std::getline(ss, field, '\t')) f.push_back(field);
      f.resize(5);
      if (!shown.insert(f[0]).second) continue;
      if (!file.supervised && f[2].rfind("stopped", 0) != 0) f[2] = "stopped (its supervisor is not running)";
      // The file says what the supervisor saw last; a program that died since is dead now,
      // whether the supervisor has seen it yet or is itself stopped (SIGSTOP) and cannot.
      if (file.supervised && f[2] == "running" && process_has_exited(f[1])) {
        // A supervisor that cannot write its file for a full disk still runs, and restarts the
        // program (the file is all that is stale); one stopped or hung restarts nothing.
        const std::string why = why_state_not_written(dir);
        const bool disk_full = why.rfind("the disk holding", 0) == 0;
        f[2] = "exited (pid " + f[1] + "), and its supervisor has not seen it yet" +
               (file.silent_s > kSupervisorSilentS / 10
                    ? ": it has not written its state for " + seconds_text(file.silent_s) + " (" + why +
                          (disk_full ? "), so it may have restarted it since without saying so here"
                                     : "), so nothing restarts it now")
                    : "");
      }
      else if (file.supervised && file.silent_s > kSupervisorSilentS)
        // Whether its process is still there is known here (it has not exited: checked above);
        // whether it does its work is not.
        f[2] = "unknown: its supervisor has not written its state for " + seconds_text(file.silent_s) + " (" +
               why_state_not_written(dir) + "); it last said " + f[2] +
               (f[2] == "running" ? ", and its process (pid " + f[1] + ") is still there" : "");
      rows.push_back({f[0], f[1], f[2], f[3], f[4]});
    }
  }
  return rows;
}

}  // namespace

const Command kUpCommand{
    "up",
    "FILE [--state DIR] [--node ID] [--foreground] [--check]",
    "Bring up a deployment (or one node of it) from a topology file.",
    "Creates each node's store at DIR/<node id> when missing (IRI, durability and ring from the\n"
    "file), then starts every node's link and agents under a supervisor that restarts dead ones\n"
    "with back-off and logs why they died (DIR/logs/). With --node only that node (one machine of\n"
    "a real deployment). The supervisor runs in the background until 'tahvel down'; with\n"
    "--foreground it stays attached until SIGINT/SIGTERM. With --check it checks all it would\n"
    "check before making anything (the file, the files it names, the stores there) and stops,\n"
    "status 0, having made and started nothing. The file format is docs/deploy.md.\n"
    "\n"
    "Exit status 6: refused as things stand (the file or a file it names, a store of another\n"
    "node or that this user may not write, a supervisor already running: the message says which\n"
    "and where); no node was started or changed. 2: a bad command line. 1: any other failure (a\n"
    "file refused by a running supervisor asked to apply it, too).",
    {kFlagState, {"--node", "", "ID", "bring up only this node"},
     {"--foreground", "", "", "run the supervisor in this process"},
     {"--check", "", "", "check the file and what it names, make and start nothing"}},
    1, 1, false};

namespace {

// The subject, predicate and object of subscription `item` in the form of the file's patterns
// ("S P O", '_' for any, IRIs in the store's prefixes; the file's `a` comes back as rdf:type),
// from its records (docs/record-model.md R9). A forward pattern of the file binds only those.
std::string pattern_text(const node::Snapshot& snap, std::uint64_t item, const uri::PrefixMap& prefixes) {
  std::string parts[3] = {"_", "_", "_"};
  const std::string tv(federation::vocab::kTv);
  const std::string names[3] = {tv + "subject", tv + "predicate", tv + "object"};
  auto records = snap.item(item);
  if (!records) return "?";
  for (const node::Record& r : *records) {
    for (int k = 0; k < 3; ++k) {
      if (r.triple.p.value != names[k]) continue;
      if (r.triple.o.kind != node::TermKind::iri) {
        parts[k] = r.triple.o.to_ntriples();
      } else if (std::string curie = prefixes.compact(r.triple.o.value); curie != r.triple.o.value) {
        parts[k] = curie;
      } else {
        parts[k] = "<" + curie + ">";
      }
    }
  }
  return parts[0] + " " + parts[1] + " " + parts[2];
}

// Pattern `i` of the node's `forward`, errors naming where the file writes it and the node.
node::Pattern forward_pattern_of(const NodeSpec& spec, std::size_t i, const uri::PrefixMap& prefixes) {
  try {
    return forward_pattern(spec.forward[i], prefixes, "pattern");
  } catch (const Failure& f) {
    fail(spec.forward_place(i) + ": node '" + spec.id + "': forward: " + f.message);
  }
}

// The node's forwarding policy as the file gives it: its `forward` patterns, or the default
// (HRV windows) when it has no `forward`.
std::vector<node::Pattern> forwarding_policy(const NodeSpec& spec, const uri::PrefixMap& prefixes) {
  if (!spec.forward_given) return federation::default_forward_policy();
  std::vector<node::Pattern> policy;
  for (std::size_t i = 0; i < spec.forward.size(); ++i) policy.push_back(forward_pattern_of(spec, i, prefixes));
  return policy;
}

// Warns about a `forward` pattern that names a tv: term the vocabulary does not have, or a near
// miss of a SOSA term: no item of Tahvel's has it, so the pattern forwards nothing (a misspelt class, say), and nothing else
// would say so. A warning, not a refusal: an agent of the deployment's own may write such terms.
void warn_of_unknown_terms(const NodeSpec& spec, std::size_t i, const node::Pattern& pattern) {
  const std::string& text = spec.forward[i];
  constexpr std::string_view kTv = federation::vocab::kTv;
  constexpr std::string_view kSosa = "http://www.w3.org/ns/sosa/";
  for (const auto* term : {&pattern.s, &pattern.p, &pattern.o}) {
    if (!*term || !(*term)->is_iri()) continue;
    if ((*term)->value.starts_with(kSosa)) {
      const std::string_view local = std::string_view((*term)->value).substr(kSosa.size());
      if (auto near = sosa_term_misspelt(local))
        std::cerr << "up: warning: " << spec.forward_place(i) << ": node '" << spec.id << "': forward: pattern '" << text << "': sosa:" << local
                  << " is not a term of SOSA (http://www.w3.org/ns/sosa/); did you mean sosa:" << *near
                  << "? Only items that an agent of the deployment's own writes with it will go up\n";
      continue;
    }
    if (!(*term)->value.starts_with(kTv)) continue;
    const std::string_view local = std::string_view((*term)->value).substr(kTv.size());
    if (is_tahvel_term(local)) continue;
    std::cerr << "up: warning: " << spec.forward_place(i) << ": node '" << spec.id << "': forward: pattern '" << text << "': tv:" << local
              << " is not a term of the tv: vocabulary (docs/vocabulary.md)";
    if (auto near = nearest_tahvel_term(local)) std::cerr << "; did you mean tv:" << *near << "?";
    else std::cerr << ".";
    std::cerr << " Only items that an agent of the deployment's own writes with it will go up\n";
  }
}

// Refuses a `forward` pattern of a node another machine brings up that is wrong whatever its
// store's prefixes (not three terms, a blank node, a literal not closed): it passed `up --node`
// on every machine but its node's, which then would not start. A CURIE of a prefix the standard
// ones lack is left to that machine, whose store may define it.
void refuse_malformed_patterns_of_others(const Topology& topo, const std::vector<const NodeSpec*>& mine) {
  for (const NodeSpec& spec : topo.nodes) {
    if (std::find(mine.begin(), mine.end(), &spec) != mine.end()) continue;
    for (std::size_t i = 0; i < spec.forward.size(); ++i) {
      // The pattern read with every prefix it names that the standard ones lack standing for a
      // namespace of its own: all else about it (three terms, no blank node, literals closed)
      // is checked as on its node's machine.
      uri::PrefixMap prefixes = uri::PrefixMap::standard();
      for (const std::string& term : pattern_terms(spec.forward[i])) {
        const std::size_t colon = term.find(':');
        // An IRI written bare (http://…) is the parser's to read, not a CURIE of an unknown prefix.
        if (colon == std::string::npos || term[0] == '<' || term[0] == '"' || term.starts_with("_:") ||
            term.compare(colon + 1, 2, "//") == 0)
          continue;
        if (const std::string prefix = term.substr(0, colon); prefixes.entries().count(prefix) == 0)
          (void)prefixes.add(prefix, "http://prefix.invalid/" + std::to_string(prefixes.entries().size()) + "/");
      }
      (void)forward_pattern_of(spec, i, prefixes);
    }
  }
}

// A tahvel-hrv whose window or step is set on its node's board runs with that setting, whatever
// its command line says (docs/agents.md): a --window edited in the file was "restarted … '30'
// became '45'" and ran on at the board's 60 s (an integrator's probe of session 88). Said, with
// what lets the flag stand.
void warn_of_settings_on_the_board(const AgentSpec& agent, const NodeSpec& spec, const std::vector<std::string>& argv,
                                   const fs::path& store) {
  if (argv.empty() || fs::path(argv[0]).filename() != "tahvel-hrv" || !fs::exists(store / "data.mdb")) return;
  // The flags as tahvel-hrv reads them: "--window 45" or "--window=45"; the last one given stands.
  std::map<std::string, std::string> flags;
  for (std::size_t i = 1; i < argv.size(); ++i) {
    const std::string& a = argv[i];
    if (!a.starts_with("--")) continue;
    if (const auto eq = a.find('='); eq != std::string::npos) flags[a.substr(0, eq)] = a.substr(eq + 1);
    else if (i + 1 < argv.size()) flags[a] = argv[++i];
  }
  const auto agent_iri = uri::agent_iri(spec.iri, flags.count("--agent") ? flags["--agent"] : "hrv");  // its default --agent
  const auto parse_double = [](const std::string& text) -> std::optional<double> {
    double v = 0;
    const char* begin = text.data() + (text.starts_with('+') ? 1 : 0);
    const auto [end, ec] = std::from_chars(begin, text.data() + text.size(), v);
    if (ec != std::errc() || end != text.data() + text.size()) return std::nullopt;
    return v;
  };
  if (!agent_iri) return;
  std::optional<node::Node> board;
  for (const auto& [flag, setting] : {std::pair{"--window", "windowSeconds"}, std::pair{"--step", "stepSeconds"}}) {
    const auto given = flags.find(flag);
    if (given == flags.end()) continue;
    if (!board) {
      auto opened = node::Node::open(store);
      if (!opened) return;
      board.emplace(std::move(*opened));
    }
    auto snap = board->snapshot();
    if (!snap) return;
    const std::string predicate = std::string(uri::kTahvelNs) + setting;
    auto settings = snap->list({.s = node::Term::iri(*agent_iri), .p = node::Term::iri(predicate)});
    if (!settings) return;
    // The latest written that tahvel-hrv can use stands (by asserted-at, then by arrival), as it
    // reads them; one of the flag's value changes nothing.
    std::erase_if(*settings, [&](const node::Record& r) {
      const auto seconds = parse_double(r.triple.o.value);
      return !seconds || tahvel::aggregation::window_setting_problem(*seconds, std::string_view(flag) == "--step");
    });
    if (settings->empty()) continue;
    const node::Record& latest = *std::max_element(settings->begin(), settings->end(), [](const node::Record& a, const node::Record& b) {
      return std::pair(a.meta.asserted_at, a.meta.id) < std::pair(b.meta.asserted_at, b.meta.id);
    });
    if (parse_double(latest.triple.o.value) == parse_double(given->second)) continue;
    std::cerr << "up: warning: " << agent.at << ": node '" << spec.id << "': agent '" << agent.id << "': " << flag << " " << given->second
              << " is not in force: its board sets tv:" << setting << " " << latest.triple.o.value << " (the latest setting, put by <"
              << latest.meta.source << "> at " << node::utc_text(latest.meta.asserted_at)
              << "), which stands over the flag (docs/agents.md); to let the flag stand: tahvel remove " << shell_word(store) << " -s "
              << shell_word(fs::path(*agent_iri)) << " -p tv:" << setting << "\n";
  }
}

// Warns about an agent of the shipped chain whose input nothing in the file writes or passes up,
// or whose results a child sends up as well (dataflow.h).
void warn_of_dataflow(const Topology& topo, const std::vector<const NodeSpec*>& mine) {
  ForwardPolicies policies;
  for (const NodeSpec& spec : topo.nodes) {
    if (!spec.forward_given) {
      policies[spec.id] = federation::default_forward_policy();
      continue;
    }
    std::vector<node::Pattern> patterns;
    try {
      for (const auto& f : spec.forward) patterns.push_back(forward_pattern(f, uri::PrefixMap::standard(), "pattern"));
      policies[spec.id] = std::move(patterns);
    } catch (const Failure&) {
      policies[spec.id] = std::nullopt;  // said where that node is brought up
    }
  }
  for (const std::string& line : dataflow_warnings(topo, policies, mine)) std::cerr << "up: warning: " << line << "\n";
}

// The triples of a `load` file as the node's new board reads them: relative IRIs against the
// node's IRI + "/", as `tahvel put` reads.
std::vector<node::Triple> load_file_triples(const NodeSpec& spec, const fs::path& file, const uri::PrefixMap& prefixes,
                                            const Topology& topo) {
  node::ParseOptions parse;
  parse.base_iri = spec.iri + "/";
  parse.source_name = file.string();
  parse.prefixes = prefixes;
  std::string text;
  try {
    text = read_input(file.string());
  } catch (const Failure& f) {
    fail((spec.load_at.empty() ? topo.file.string() : spec.load_at) + ": node '" + spec.id + "': load: " + f.message);
  }
  auto triples = node::parse_rdf(text, parse);
  if (!triples) fail((spec.load_at.empty() ? topo.file.string() : spec.load_at) + ": node '" + spec.id + "': load: " + triples.error().message);
  return std::move(*triples);
}

// What a load item says of the file it came from (docs/deploy.md): its name as the topology
// file's folder sees it, and a digest of its bytes. `up` loads a file once per node, so that a
// file added to the topology of an existing node is loaded then, and one changed since is named.
const std::string kLoadFile = std::string(federation::vocab::kTv) + "loadFile";
const std::string kLoadDigest = std::string(federation::vocab::kTv) + "loadDigest";

std::string load_name(const fs::path& file, const Topology& topo) {
  return fs::absolute(file).lexically_normal().lexically_relative(fs::absolute(topo.file).parent_path().lexically_normal()).generic_string();
}

// FNV-1a, 64 bits: a change of the file, not a defence against anyone.
std::string load_digest(const fs::path& file) {
  std::uint64_t h = 0xcbf29ce484222325ull;
  for (unsigned char c : read_input(file.string())) h = (h ^ c) * 0x100000001b3ull;
  char hex[17];
  std::snprintf(hex, sizeof hex, "%016llx", static_cast<unsigned long long>(h));
  return std::string("fnv1a64:") + hex;
}

// Puts `file` on the node's board as one persistent item, with its name and digest. Returns
// the line that says so.
std::string load_onto(node::Agent& loader, const NodeSpec& spec, const fs::path& file, const uri::PrefixMap& prefixes,
                      const Topology& topo) {
  node::Item item;
  item.persistent = true;
  item.triples = load_file_triples(spec, file, prefixes, topo);
  const std::size_t triples = item.triples.size();
  const node::Term source = node::Term::blank("loaded");
  item.add(source, node::Term::iri(kLoadFile), node::Term::literal(load_name(file, topo)))
      .add(source, node::Term::iri(kLoadDigest), node::Term::literal(load_digest(file)));
  check(loader.store(item));
  return "up: put " + std::to_string(triples) + (triples == 1 ? " triple of " : " triples of ") + file.string() + " on " + spec.id + "\n";
}

// On an existing store: loads the topology's files it has not had yet, and names those changed
// since they were loaded (a loaded file is not replaced: its item may have been edited or
// removed on purpose, and removing it and loading the new one would not be one transaction).
void load_new_files(const NodeSpec& spec, node::Node& node, const Topology& topo) {
  if (spec.load.empty()) return;
  node::Agent loader = check(node.agent("deploy"));
  std::map<std::string, std::pair<std::string, std::uint64_t>> loaded;  // name -> (digest, item)
  bool loader_wrote = false;
  {  // released before loading: a store that must grow cannot while this process holds one
    auto snap = check(node.snapshot());
    std::map<std::uint64_t, std::string> digests;  // item -> digest
    for (const auto& r : check(snap.list({.p = node::Term::iri(kLoadDigest), .source = loader.iri()})))
      digests[r.meta.item] = r.triple.o.value;
    for (const auto& r : check(snap.list({.p = node::Term::iri(kLoadFile), .source = loader.iri()})))
      loaded[r.triple.o.value] = {digests[r.meta.item], r.meta.item};
    loader_wrote = loaded.empty() && check(snap.count({.source = loader.iri()})) > 0;
  }
  if (loader_wrote) {
    std::cerr << "up: warning: " << spec.load_at << ": node '" << spec.id << "': its store was made before up recorded "
              << "the files it loads; its load files are not loaded again nor checked\n";
    return;
  }
  for (const fs::path& file : spec.load) {
    auto it = loaded.find(load_name(file, topo));
    if (it == loaded.end()) {
      std::cout << load_onto(loader, spec, file, node.prefixes(), topo);
    } else if (it->second.first != load_digest(file)) {
      std::cerr << "up: warning: " << spec.load_at << ": node '" << spec.id << "': " << file.string()
                << " changed since up loaded it (item " << it->second.second << "); to load it anew: tahvel remove "
                << node.dir().string() << " --item " << it->second.second << ", then up again\n";
    }
  }
}

// Where create_store makes a node's store before renaming it into place: STATE/<id>.making.
// A first `up` interrupted there (Ctrl-C, SIGKILL) leaves one, holding the node's IRI, which is
// not a node (`status` and `down` pass it over; node ids cannot end so) and which the next `up`
// makes anew.
constexpr std::string_view kMakingSuffix = ".making";

bool store_being_made(const fs::path& dir) { return dir.filename().string().ends_with(kMakingSuffix); }

// A new store for `spec` beside one that already has its IRI: the file renamed a node (its
// id), and the node would start afresh, its history left in the other store, which `status`
// then showed beside it as a second node of that IRI.
void refuse_a_second_store_of(const NodeSpec& spec, const fs::path& state) {
  std::error_code ec;
  for (const auto& entry : fs::directory_iterator(state, ec)) {
    const fs::path dir = entry.path();
    if (dir.filename() == spec.id || store_being_made(dir) || !fs::exists(dir / "data.mdb")) continue;
    auto other = node::Node::open(dir);
    if (!other || other->iri() != spec.iri) continue;
    const std::string old_id = dir.filename().string();
    // Either the file renamed the node or its store was moved aside (a copy kept as home1.bak):
    // the way on is the same move, so both are said.
    fail("node '" + spec.id + "' would get a new store, but " + dir.string() + " already holds <" + spec.iri +
         ">: its store was moved there, or the node was renamed in the file (from '" + old_id + "'). To go on with its data, " +
         "move " + dir.string() + " to " + (state / spec.id).string() + " and 'up' again; to start it afresh, move " +
         dir.string() + " out of " + state.string() + " first");
  }
}

// What may be where a node's new store is to be made (`store`, no data.mdb there): nothing, an
// empty folder, or what is left of a store whose data file is gone. Anything else is not `up`'s
// to delete, and a mount point cannot take the rename (remove_all had emptied the volume before
// the rename failed). Checked before anything is made, so that a refusal leaves nothing behind.
void refuse_what_a_new_stores_place_holds(const NodeSpec& spec, const fs::path& store) {
  std::error_code ec;
  if (!fs::exists(store, ec)) return;
  const std::string where = spec.store_at + ": node '" + spec.id + "': " + store.string();
  if (!fs::is_directory(store, ec)) fail(where + " is not a directory");
  struct stat here {}, above {};
  if (stat(store.c_str(), &here) == 0 && stat(store.parent_path().c_str(), &above) == 0 && here.st_dev != above.st_dev)
    fail(where + " is a mount point: a node's store is made beside its directory and renamed into place, which a mount "
                 "point refuses; mount the volume on the state directory (--state) instead, or on a directory above it");
  for (const auto& entry : fs::directory_iterator(store, ec)) {
    const std::string name = entry.path().filename().string();
    if (name != "lock.mdb" && name != "wake")
      fail(where + " holds " + name + " but no store (no data.mdb); move it aside, and 'tahvel up' makes the node's store there");
  }
  if (ec) fail(where + ": " + ec.message());
}

// A node's new store with the files the topology puts on its board (a floor plan, sensing
// subscriptions: one persistent item each). Made beside `store` and renamed into place once
// whole, so a failure leaves no store that `up` would then take as made and never load.
void create_store(const NodeSpec& spec, const fs::path& store, const Topology& topo) {
  const fs::path making = store.string() + std::string(kMakingSuffix);
  refuse_what_a_new_stores_place_holds(spec, store);  // again: checked before, changed since?
  std::error_code ec;
  fs::remove_all(making, ec);
  std::string loaded;  // said after the store is in place, as it is made aside
  {
    node::InitOptions init;
    init.iri = spec.iri;
    init.durability = spec.durability == "durable" ? node::Durability::durable : node::Durability::fast;
    init.ring = spec.ring;
    node::Node created = check(node::Node::init(making, init));
    if (!spec.parent.empty()) {
      // The policy before the files: what they load and it matches goes up (P5, an item stored
      // before a pattern stays home), as the rest of the node's first items do. As the link
      // does, removal notices first (P6c, P6d send again only what the uplink was given).
      node::Agent uplink = check(created.agent("uplink"));
      check(uplink.receive_removals());
      for (const node::Pattern& pattern : forwarding_policy(spec, created.prefixes())) check(uplink.subscribe(pattern));
    }
    node::Agent loader = check(created.agent("deploy"));
    for (const fs::path& file : spec.load) loaded += load_onto(loader, spec, file, created.prefixes(), topo);
  }
  fs::remove_all(store, ec);  // an empty folder, or the rest of a store without its data file
  fs::rename(making, store, ec);
  if (ec) {
    const std::string why = ec.message();
    fs::remove_all(making, ec);
    fail("cannot make the store of node '" + spec.id + "' at " + store.string() + " (" + why + ")");
  }
  std::cout << "up: created the store of " << spec.id << " <" << spec.iri << "> at " << store.string() << "\n" << loaded;
}

// Writes `file` whole or not at all (beside it, then renamed).
void write_whole(const fs::path& file, const std::string& text) {
  fs::path tmp = file;
  tmp += ".tmp";
  {
    std::ofstream out(tmp);
    out << text;
    if (!out.flush()) fail(tmp.string() + ": cannot write");
  }
  std::error_code ec;
  fs::rename(tmp, file, ec);
  if (ec) fail(file.string() + ": " + ec.message());
}

// The programs `up` runs for the nodes `mine`: each node's link (when it has a parent or
// children) and its agents, as the supervisor starts them.
// The Cyclone DDS files a link's argv names, as a digest of their paths and bytes: the link reads
// them when it starts, so a file edited in place changes the link as much as a changed flag, and
// `up` restarts it (its argv alone is the same). Empty when it names none.
std::string dds_config_digest(const std::vector<std::string>& argv) {
  std::string named;
  for (std::size_t i = 0; i + 1 < argv.size(); ++i) {
    if (argv[i] != "--dds-config" && argv[i] != "--listen-dds-config") continue;
    std::ifstream in(argv[i + 1], std::ios::binary);
    named += argv[i + 1] + '\0' + std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()) + '\0';
  }
  if (named.empty()) return {};
  std::ostringstream hex;
  hex << std::hex << std::hash<std::string>{}(named);
  return hex.str();
}

// The longest a node's link waits before it is started again: the node's items, its
// configuration and queries to it wait for it (other programs back off up to 30 s).
constexpr std::chrono::milliseconds kLinkMaxBackOff{2000};

// Each program's log and the supervisor's own are kept within this, with the one before as
// `<log>.1` (agents::rotate_log): a deployment that runs for months, or a program that
// crash-loops, does not fill the disk with logs.
constexpr std::uint64_t kLogLimit = 16ull << 20;

std::vector<agents::ProgramSpec> programs_of(const Topology& topo, const std::vector<const NodeSpec*>& mine,
                                             const fs::path& state, const CommandContext& caller) {
  CommandContext context = caller;
  context.dir = fs::absolute(topo.file).lexically_normal().parent_path();
  std::vector<agents::ProgramSpec> programs;
  for (const NodeSpec* spec : mine) {
    const fs::path store = state / spec->id;
    // What a program starts inherits the mark: found and killed when a supervisor killed with
    // SIGKILL left it running (agents::kill_leftovers).
    const std::pair<std::string, std::string> mark{std::string(agents::kLeftoverMark), fs::absolute(store).string()};
    if (!spec->parent.empty() || !topo.children(spec->id).empty()) {
      auto argv = link_argv(topo, *spec, store, context.bin);
      std::vector<std::pair<std::string, std::string>> env{mark};
      if (auto digest = dds_config_digest(argv); !digest.empty()) env.emplace_back("TAHVEL_DDS_CONFIG_DIGEST", digest);
      programs.push_back({spec->id + "/link", std::move(argv), state / "logs" / spec->id / "link.log", std::move(env),
                          agents::Restart::always, kLinkMaxBackOff, kLogLimit});
    }
    for (const AgentSpec& agent : spec->agents)
      programs.push_back({spec->id + "/" + agent.id, check(expand_agent_command(agent, *spec, store, context)),
                          state / "logs" / spec->id / (agent.id + ".log"), {mark}, agent.restart, {}, kLogLimit});
  }
  return programs;
}

std::vector<const NodeSpec*> nodes_brought_up(const Topology& topo, const std::optional<std::string>& only) {
  std::vector<const NodeSpec*> mine;
  for (const NodeSpec& spec : topo.nodes)
    if (!only || spec.id == *only) mine.push_back(&spec);
  return mine;
}

// What one supervisor runs from a topology file: the programs, and per node its dispatcher (of
// behaviours, started through the same supervisor: docs/reasoner.md) and area keeper (docs/
// spatial.md, S9). apply() makes it run the file as written now: what is new starts, what left
// the file stops, a program whose command changed (a parent's link with a new child) restarts;
// the rest runs on untouched.
class Deployment {
 public:
  Deployment(agents::Supervisor& supervisor, fs::path state, std::optional<std::string> only)
      : supervisor_(supervisor), state_(std::move(state)), only_(std::move(only)) {
    std::error_code ec;  // an earlier supervisor's list is not this one's
    fs::remove(gone_list_file(state_ / pid_file_name(only_)), ec);
  }
  ~Deployment() {
    for (const auto& [id, fd] : locks_) ::close(fd);
  }
  Deployment(const Deployment&) = delete;
  Deployment& operator=(const Deployment&) = delete;

  const std::optional<std::string>& only() const { return only_; }

  // One line per change made, for the log and for the `up` that asked. `context`: the
  // environment of the `up` that asked (CommandContext).
  std::vector<std::string> apply(const Topology& topo, const CommandContext& context) {
    // A store removed (or moved) since this supervisor locked it, and most likely made again by
    // the `up` that asks: what ran of the node stops here first, then the node starts anew on
    // the store that is there now (lock_node below).
    std::vector<std::string> changes = drop_nodes(stores_gone());
    // Another file taking over a running deployment is most often the wrong file: said first.
    const fs::path file = fs::absolute(topo.file).lexically_normal();
    if (!file_.empty() && file != file_)
      changes.push_back("the deployment ran " + file_.string() + " until now and runs " + file.string() + " from now on");
    file_ = file;
    std::vector<const NodeSpec*> mine;
    const std::vector<const NodeSpec*> brought_up = nodes_brought_up(topo, only_);
    for (const NodeSpec* spec : brought_up)
      if (lock_node(*spec, changes)) mine.push_back(spec);
    // A node stopped as its store went that the file no longer has (renamed, its store moved to
    // the new id) is no node of the deployment: `status` showed it for ever as a store moved away.
    if (std::erase_if(gone_, [&](const auto& g) {
          return std::none_of(brought_up.begin(), brought_up.end(), [&](const NodeSpec* spec) { return spec->id == g.first; });
        }) > 0)
      if (auto listed = write_gone_list()) changes.push_back(*listed);
    const std::vector<agents::ProgramSpec> in_order = programs_of(topo, mine, state_, context);  // parents first
    std::map<std::string, const agents::ProgramSpec*> wanted;
    for (const auto& program : in_order) wanted[program.name] = &program;
    // What left the file and what changed stop together: each may take its 5 s of grace.
    std::vector<std::string> leaving;
    for (const auto& [name, spec] : applied_) {
      auto w = wanted.find(name);
      if (w == wanted.end() || !(same_program(spec, *w->second) || only_restart_differs(spec, *w->second))) leaving.push_back(name);
    }
    supervisor_.remove(leaving);
    for (auto it = applied_.begin(); it != applied_.end();) {
      if (wanted.count(it->first)) {
        ++it;
        continue;
      }
      changes.push_back("stopped " + it->first + " (no longer in the file)");
      it = applied_.erase(it);
    }
    for (const agents::ProgramSpec& program : in_order) {
      const std::string& name = program.name;
      auto it = applied_.find(name);
      if (it != applied_.end() && same_program(it->second, program)) continue;
      // A new restart policy alone is no reason to stop a program that runs.
      if (it != applied_.end() && only_restart_differs(it->second, program)) {
        auto starts = supervisor_.set_restart(name, program.restart);
        if (!starts) {
          changes.push_back("cannot change " + name + ": " + starts.error().message);
          continue;
        }
        changes.push_back("changed " + name + " (" + what_changed(it->second, program) +
                          (*starts ? "; it was not running, and starts again under the new policy)" : "; it was not restarted)"));
        it->second = program;
        continue;
      }
      const bool changed = it != applied_.end();
      if (auto started = supervisor_.start(program); !started) {
        changes.push_back("cannot start " + name + ": " + started.error().message);
        if (changed) applied_.erase(it);
        continue;
      }
      changes.push_back(changed ? "restarted " + name + " (" + what_changed(it->second, program) + ")" : "started " + name);
      applied_[name] = program;
    }
    std::set<std::string> ids;
    for (const NodeSpec* spec : mine) ids.insert(spec->id);
    if (auto listed = write_node_list(ids)) changes.push_back(*listed);
    if (only_) {  // what the file has beside this node, for `status` (nodes_supervised)
      std::set<std::string> in_file;
      for (const NodeSpec& spec : topo.nodes) in_file.insert(spec.id);
      if (auto listed = write_node_list(in_file, ".file-nodes")) changes.push_back(*listed);
    }
    for (auto it = dispatchers_.begin(); it != dispatchers_.end();) {
      const NodeSpec* spec = topo.node(it->first);
      if (ids.count(it->first) && spec->behaviours == it->second.folder) {
        ++it;
        continue;
      }
      (void)it->second.dispatcher.stop_all(std::chrono::seconds(2));
      changes.push_back("stopped the dispatcher of " + it->first);
      it = dispatchers_.erase(it);
    }
    // Left to their threads, and still counted at stop() while they wait.
    for (auto it = opening_dispatchers_.begin(); it != opening_dispatchers_.end();) {
      const NodeSpec* spec = topo.node(it->first);
      if (ids.count(it->first) && spec->behaviours == it->second.folder) {
        ++it;
        continue;
      }
      abandoned_dispatchers_.push_back(std::move(it->second.opening));
      it = opening_dispatchers_.erase(it);
    }
    std::erase_if(keepers_, [&](const auto& entry) { return !ids.count(entry.first); });
    for (auto it = opening_keepers_.begin(); it != opening_keepers_.end();) {
      if (ids.count(it->first)) {
        ++it;
        continue;
      }
      abandoned_keepers_.push_back(std::move(it->second));
      it = opening_keepers_.erase(it);
    }
    std::erase_if(published_, [&](const auto& entry) { return !ids.count(entry.first); });
    std::erase_if(locks_, [&](const auto& entry) {  // its programs stopped above
      if (ids.count(entry.first)) return false;
      ::close(entry.second);
      return true;
    });
    std::erase_if(data_files_, [&](const auto& entry) { return !ids.count(entry.first); });
    node_ids_ = ids;
    // Opened on threads of their own (opening.h); what opens within a moment is said by this
    // apply, what waits for its store is said when it opens (poll()).
    for (const NodeSpec* spec : mine) {
      const fs::path store = state_ / spec->id;
      if (!spec->behaviours.empty() && !dispatchers_.count(spec->id) && !opening_dispatchers_.count(spec->id)) {
        agents::DispatcherOptions options;
        options.folder = spec->behaviours;
        options.log_dir = state_ / "logs" / spec->id / "behaviours";
        options.program_prefix = spec->id + "/";
        options.env = {{std::string(agents::kLeftoverMark), fs::absolute(store).string()}};
        opening_dispatchers_.emplace(
            spec->id, OpeningDispatcher{spec->behaviours, std::make_unique<Opening<node::Result<agents::Dispatcher>>>(
                                                              [store, options, &supervisor = supervisor_] {
                                                                return agents::Dispatcher::open(store, options, supervisor);
                                                              })});
      }
      if (!keepers_.count(spec->id) && !opening_keepers_.count(spec->id))
        opening_keepers_.emplace(spec->id, std::make_unique<Opening<spatial::Result<OpenedKeeper>>>([store]() -> spatial::Result<OpenedKeeper> {
                                   spatial::AreaSyncReport first;
                                   auto keeper = spatial::AreaKeeper::open(store, &first);
                                   if (!keeper) return Unexpected<spatial::Error>{keeper.error()};
                                   return OpenedKeeper{std::move(*keeper), std::move(first)};
                                 }));
    }
    const auto deadline = std::chrono::steady_clock::now() + kOpeningSaidByApply;
    auto left = [&] {
      return std::max(std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now()),
                      std::chrono::milliseconds(0));
    };
    for (auto& [id, d] : opening_dispatchers_) d.opening->wait(left());
    for (auto& [id, k] : opening_keepers_) k->wait(left());
    take_opened(changes);
    for (const auto& [id, d] : opening_dispatchers_)
      changes.push_back("the dispatcher of " + id + " waits to open, most likely for the writer lock of " +
                        (state_ / id).string() + ", which another process holds; it runs once the lock is free");
    for (const auto& [id, k] : opening_keepers_)
      changes.push_back("the area keeper of " + id + " waits to open, most likely for the writer lock of " +
                        (state_ / id).string() + ", which another process holds; it runs once the lock is free");
    return changes;
  }

  // Keepers and dispatchers: their work of the moment, logged. Not on a node whose board write
  // waits for the store's writer lock: their writes would wait in this loop (and a snapshot
  // after another process grew the store would wait for that board write to begin).
  void poll(const agents::Supervisor::Log& log) {
    std::vector<std::string> opened;
    take_opened(opened);
    for (const auto& line : opened) log("up: " + line);
    for (auto& [id, keeper] : keepers_) {
      if (board_held_up(id)) continue;
      auto synced = keeper.poll(std::chrono::milliseconds(0));
      // A failure said once while it lasts (a store whose data file went failed every 100 ms).
      std::string& failed = poll_failures_["keeper " + keeper.iri()];
      if (!synced) {
        if (synced.error().message != failed) log("up: area keeper <" + keeper.iri() + ">: " + synced.error().message);
        failed = synced.error().message;
        continue;
      }
      failed.clear();
      if (*synced) {
        log("up: area keeper <" + keeper.iri() + ">: " + std::to_string((*synced)->added) + " subscriptions added, " +
            std::to_string((*synced)->removed) + " removed" + caught_up_text(**synced));
        for (const auto& problem : (*synced)->problems) log("up: area keeper <" + keeper.iri() + ">: " + problem);
      }
    }
    for (auto& [id, d] : dispatchers_) {
      if (board_held_up(id)) continue;
      auto events = d.dispatcher.poll(std::chrono::milliseconds(0));
      std::string& failed = poll_failures_["dispatcher " + d.dispatcher.iri()];
      if (!events) {
        if (events.error().message != failed) log("up: dispatcher <" + d.dispatcher.iri() + ">: " + events.error().message);
        failed = events.error().message;
        continue;
      }
      failed.clear();
      for (const auto& e : *events) log("up: " + e.run + " \"" + e.command + "\" " + e.detail);
    }
  }

  // `boards`: false when the state directory is no longer this supervisor's (removed, and
  // perhaps made again by another `up`): nothing is written there.
  void stop(const agents::Supervisor::Log& log, bool boards) {
    for (auto& [id, d] : dispatchers_) {  // its behaviours first, recorded as stopped
      auto events = d.dispatcher.stop_all(std::chrono::seconds(2));
      if (!events) log("up: dispatcher <" + d.dispatcher.iri() + ">: " + events.error().message);
    }
    supervisor_.stop_all();
    // The board then says they stopped, not how they last ran: for `status` on a machine above
    // once this node's link runs again (until then that machine cannot ask).
    if (boards) publish_programs(log, true);
    boards_finished_ = finish_boards(log, std::chrono::seconds(2));
    for (const auto& [id, d] : opening_dispatchers_)
      if (!d.opening->ended()) boards_finished_ = false;
    for (const auto& [id, k] : opening_keepers_)
      if (!k->ended()) boards_finished_ = false;
    for (const auto& d : abandoned_dispatchers_)
      if (!d->ended()) boards_finished_ = false;
    for (const auto& k : abandoned_keepers_)
      if (!k->ended()) boards_finished_ = false;
  }

  // After stop(): false when a thread (a board's write, a keeper or dispatcher opening) still
  // waits for its store.
  bool boards_finished() const { return boards_finished_; }

  // Each node's programs on its board (agents/supervisor.h, "on the board"), when they change
  // and every kProgramsRefresh: a machine above knows them only from there (`tahvel status`).
  // Written by each node's ProgramBoard thread: a store whose writer lock another process holds
  // is said once it has held the write up for kBoardHeldUpSaid, and holds up nothing else.
  void publish_programs(const agents::Supervisor::Log& log, bool now_all = false) {
    const auto now = std::chrono::steady_clock::now();
    const std::vector<agents::ProgramState> states = supervisor_.states();
    for (const std::string& id : node_ids_) {
      std::vector<agents::ProgramState> programs;
      std::string said;
      for (agents::ProgramState s : states) {
        if (s.name.rfind(id + "/", 0) != 0) continue;
        s.name.erase(0, id.size() + 1);
        said += s.name + ' ' + std::string(agents::program_state_name(s)) + ' ' + std::to_string(s.running ? s.pid : 0) +
                ' ' + std::to_string(s.restarts) + ' ' + s.last_exit + '\n';
        programs.push_back(std::move(s));
      }
      Published& board = published_[id];
      if (!board.writer) board.writer = std::make_unique<ProgramBoard>(state_ / id, id, log);
      const auto waited = board.writer->waiting();
      if (waited >= kBoardHeldUpSaid && !board.held_up_said) {
        board.held_up_said = true;
        log("up: the programs of " + id + " have waited " +
            std::to_string(std::chrono::duration_cast<std::chrono::seconds>(waited).count()) + " s to be written on its board, "
            "most likely for the writer lock of " + (state_ / id).string() +
            ", which another process holds (a long `tahvel load`, or a writer stopped inside its transaction); "
            "restarts and the other nodes go on, and the node's area keeper and dispatcher wait");
      } else if (board.held_up_said && board.writer->last_write_succeeded()) {
        board.held_up_said = false;
        log("up: the programs of " + id + " are written on its board again");
      }
      if (!now_all && said == board.said && now - board.at < agents::kProgramsRefresh) continue;
      board.said = said;
      board.at = now;
      board.writer->post(std::move(programs));
    }
  }

  // Waits up to `limit` in all for the boards' last writes (after stop()); false when one still
  // waits for its store (its thread is left to the process's end).
  bool finish_boards(const agents::Supervisor::Log& log, std::chrono::milliseconds limit) {
    const auto deadline = std::chrono::steady_clock::now() + limit;
    bool all = true;
    for (auto& [id, board] : published_) {
      if (!board.writer) continue;
      const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
      if (board.writer->finish(std::max(left, std::chrono::milliseconds(0)))) continue;
      all = false;
      log("up: the programs of " + id + " as they stopped are not on its board: its write still waits, most likely for "
          "the writer lock of " + (state_ / id).string() + ", which another process holds");
    }
    return all;
  }

  // Stops what this supervisor runs of the nodes `gone`, whose store directories were removed or
  // moved while they ran (stores_gone): their programs wrote into files nobody else opens, and an
  // `up` of the directory would start every program of the node a second time. Their
  // dispatchers, area keepers and board writers go too, and each directory's lock is let go. The
  // other nodes run on; the next `up` of the file makes the store again and starts the node anew.
  // One line per node stopped, for the log and for the `up` that asked.
  std::vector<std::string> drop_nodes(const std::vector<std::string>& gone) {
    std::vector<std::string> changes;
    for (const std::string& id : gone) {
      if (auto d = dispatchers_.find(id); d != dispatchers_.end()) {  // its behaviours first
        (void)d->second.dispatcher.stop_all(std::chrono::seconds(2));
        dispatchers_.erase(d);
      }
      if (auto d = opening_dispatchers_.find(id); d != opening_dispatchers_.end()) {
        abandoned_dispatchers_.push_back(std::move(d->second.opening));
        opening_dispatchers_.erase(d);
      }
      if (auto k = opening_keepers_.find(id); k != opening_keepers_.end()) {
        abandoned_keepers_.push_back(std::move(k->second));
        opening_keepers_.erase(k);
      }
      keepers_.erase(id);
      published_.erase(id);  // nothing is written on the board of a store that is gone
      const std::string prefix = id + "/";
      std::vector<std::string> programs;
      for (const auto& [name, spec] : applied_)
        if (name.starts_with(prefix)) programs.push_back(name);
      supervisor_.remove(programs);
      for (const auto& name : programs) applied_.erase(name);
      if (auto lock = locks_.find(id); lock != locks_.end()) {
        ::close(lock->second);
        locks_.erase(lock);
      }
      data_files_.erase(id);
      node_ids_.erase(id);
      gone_[id] = iris_[id];
      changes.push_back("stopped node '" + id + "' (" + std::to_string(programs.size()) + " program(s)): its store " +
                        (state_ / id).string() + " was removed or moved while it ran; the other nodes run on, and "
                        "'tahvel up' of the file makes the store again and starts the node anew");
    }
    if (!gone.empty()) {
      if (auto listed = write_node_list(node_ids_)) changes.push_back(*listed);
      if (auto listed = write_gone_list()) changes.push_back(*listed);
    }
    return changes;
  }

  // How many nodes this supervisor runs (whose store directory it holds).
  std::size_t node_count() const { return locks_.size(); }

  // The nodes whose store directory is no longer where this supervisor started them (`rm -rf`
  // of the state directory, or a move): their programs write into files nobody else opens, and
  // an `up` of that directory would start every program of the node a second time.
  // Also those whose data file alone was removed or replaced (`rm DIR/data.mdb`, a copy put in
  // its place): their programs' writes fail, and the keeper's and dispatcher's failed every poll.
  std::vector<std::string> stores_gone() const {
    std::vector<std::string> gone;
    for (const auto& [id, fd] : locks_) {
      struct stat held {}, there {}, data {};
      if (fstat(fd, &held) != 0) continue;
      const auto file = data_files_.find(id);
      const bool data_gone = file != data_files_.end() &&
                             (::stat((state_ / id / "data.mdb").c_str(), &data) != 0
                                  ? errno == ENOENT
                                  : std::pair(data.st_dev, data.st_ino) != file->second);
      if (held.st_nlink == 0 || ::stat((state_ / id).c_str(), &there) != 0 || there.st_ino != held.st_ino ||
          there.st_dev != held.st_dev || data_gone)
        gone.push_back(id);
    }
    return gone;
  }

  // Whether the write of `id`'s board has waited long enough to say its store is held.
  bool board_held_up(const std::string& id) const {
    auto it = published_.find(id);
    return it != published_.end() && it->second.writer && it->second.writer->waiting() >= kBoardWaitHoldsUpOthers;
  }

 private:
  // A board write that waits this long holds up the node's keeper and dispatcher (poll()).
  static constexpr std::chrono::milliseconds kBoardWaitHoldsUpOthers{200};
  // How long apply() waits for keepers and dispatchers to open, to say so itself.
  static constexpr std::chrono::milliseconds kOpeningSaidByApply{2000};

  struct OpenedKeeper {
    spatial::AreaKeeper keeper;
    spatial::AreaSyncReport first;
  };
  struct OpeningDispatcher {
    fs::path folder;
    std::unique_ptr<Opening<node::Result<agents::Dispatcher>>> opening;
  };

  // Keepers and dispatchers that have opened (or failed to) since the last call, as lines.
  void take_opened(std::vector<std::string>& changes) {
    for (auto it = opening_dispatchers_.begin(); it != opening_dispatchers_.end();) {
      auto dispatcher = it->second.opening->take();
      if (!dispatcher) {
        ++it;
        continue;
      }
      if (!*dispatcher) {
        changes.push_back("dispatcher of " + it->first + ": " + dispatcher->error().message);
      } else {
        changes.push_back("dispatcher <" + (*dispatcher)->iri() + "> runs behaviours from " + it->second.folder.string());
        dispatchers_.emplace(it->first, Dispatching{it->second.folder, std::move(**dispatcher)});
      }
      it = opening_dispatchers_.erase(it);
    }
    for (auto it = opening_keepers_.begin(); it != opening_keepers_.end();) {
      auto keeper = it->second->take();
      if (!keeper) {
        ++it;
        continue;
      }
      if (!*keeper) {
        changes.push_back("area keeper of " + it->first + ": " + keeper->error().message);
      } else {
        for (const auto& problem : (*keeper)->first.problems)
          changes.push_back("area keeper <" + (*keeper)->keeper.iri() + ">: " + problem);
        keepers_.emplace(it->first, std::move((*keeper)->keeper));
      }
      it = opening_keepers_.erase(it);
    }
  }
  // How long a board's write waits before the supervisor says which store holds it up.
  static constexpr std::chrono::seconds kBoardHeldUpSaid{5};

  struct Published {
    std::unique_ptr<ProgramBoard> writer;  // made at the first publish
    std::string said;                      // what was last posted
    std::chrono::steady_clock::time_point at{};
    bool held_up_said = false;
  };

  // One supervisor per node: it holds an exclusive lock (flock) on the node's store directory,
  // which outlives a deleted pid file (a second `up` after 'rm state/*.pid' found no supervisor
  // and ran every agent twice). Once held, what programs of a supervisor killed earlier left
  // running is killed. False (and why, in `changes`) when the node cannot run here.
  bool lock_node(const NodeSpec& spec, std::vector<std::string>& changes) {
    if (locks_.count(spec.id)) return true;
    const fs::path store = fs::absolute(state_ / spec.id);
    const int fd = ::open(store.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
    if (fd < 0) {
      changes.push_back("node '" + spec.id + "' not started: " + store.string() + ": " + std::strerror(errno) +
                        " ('tahvel up' of the file makes its store)");
      return false;
    }
    if (flock(fd, LOCK_EX | LOCK_NB) != 0) {
      ::close(fd);
      changes.push_back("node '" + spec.id + "' not started: another supervisor runs it (it holds " + store.string() +
                        "); 'tahvel status' shows which");
      return false;
    }
    locks_[spec.id] = fd;
    if (struct stat data {}; ::stat((store / "data.mdb").c_str(), &data) == 0) data_files_[spec.id] = {data.st_dev, data.st_ino};
    iris_[spec.id] = spec.iri;
    if (gone_.erase(spec.id) > 0)
      if (auto listed = write_gone_list()) changes.push_back(*listed);
    if (const auto killed = agents::kill_leftovers(store.string()); !killed.empty()) {
      std::string list;
      for (const auto& k : killed) list += (list.empty() ? "" : ", ") + k;
      changes.push_back("killed " + std::to_string(killed.size()) + " process(es) that programs of node '" + spec.id +
                        "' had started and left running when their supervisor was killed: " + list);
    }
    return true;
  }

  // The nodes this supervisor runs, for `status` to tell a store left from a node taken out of
  // the file from one that is part of the deployment. Why it could not be written, if so.
  // With `extension` ".file-nodes": the nodes of the file a supervisor of one node runs.
  std::optional<std::string> write_node_list(const std::set<std::string>& ids, const char* extension = ".nodes") {
    std::string listed;
    for (const auto& id : ids) listed += id + "\n";
    try {
      write_whole(fs::path(state_ / pid_file_name(only_)).replace_extension(extension), listed);
    } catch (const Failure& f) {
      return f.message;
    }
    return std::nullopt;
  }

  // The nodes this supervisor stopped because their store went (drop_nodes), "id TAB IRI" a
  // line, until an `up` starts them again: `status` shows each as this machine's node with its
  // store missing, not as a node on another machine known from its parent's state of it.
  std::optional<std::string> write_gone_list() {
    std::string listed;
    for (const auto& [id, iri] : gone_) listed += id + "\t" + iri + "\n";
    try {
      write_whole(gone_list_file(state_ / pid_file_name(only_)), listed);
    } catch (const Failure& f) {
      return f.message;
    }
    return std::nullopt;
  }

  static bool same_program(const agents::ProgramSpec& a, const agents::ProgramSpec& b) {
    return a.argv == b.argv && a.env == b.env && a.log_file == b.log_file && a.restart == b.restart;
  }
  static bool only_restart_differs(const agents::ProgramSpec& a, const agents::ProgramSpec& b) {
    return a.argv == b.argv && a.env == b.env && a.log_file == b.log_file && a.restart != b.restart;
  }
  static std::string what_changed(const agents::ProgramSpec& was, const agents::ProgramSpec& now) {
    std::vector<std::string> what;
    if (was.argv != now.argv) {
      // Where: a file unchanged but TAHVEL_MITDB unset (or set) changes a source's --record to
      // --synthetic, which "its command changed" alone did not tell.
      // The arguments the two share at the end are left out too: a child added to a link's
      // command read "nothing became '--child' 'homeD'", one flag taken out as if another had
      // replaced it (what followed it shifted into its place).
      std::size_t at = 0;
      while (at < was.argv.size() && at < now.argv.size() && was.argv[at] == now.argv[at]) ++at;
      std::size_t shared_tail = 0;
      while (shared_tail < was.argv.size() - at && shared_tail < now.argv.size() - at &&
             was.argv[was.argv.size() - 1 - shared_tail] == now.argv[now.argv.size() - 1 - shared_tail])
        ++shared_tail;
      auto words = [&](const std::vector<std::string>& argv) {
        const std::size_t end = argv.size() - shared_tail;
        std::string text;
        for (std::size_t i = at; i < end && i < at + 4; ++i) text += (text.empty() ? "'" : " '") + argv[i] + "'";
        return text + (end > at + 4 ? " ..." : "");
      };
      const std::string before = words(was.argv), after = words(now.argv);
      what.push_back("its command changed from argument " + std::to_string(at) + ": " +
                     (before.empty() ? after + " added" : after.empty() ? before + " taken out" : before + " became " + after));
    }
    else if (was.env != now.env) what.push_back("a file it reads at start changed");
    if (was.restart != now.restart)
      what.push_back("restart \"" + std::string(agents::restart_name(was.restart)) + "\" -> \"" +
                     std::string(agents::restart_name(now.restart)) + "\"");
    if (was.log_file != now.log_file) what.push_back("its log file changed");
    std::string text;
    for (const auto& w : what) text += (text.empty() ? "" : ", ") + w;
    return text;
  }
  struct Dispatching {
    fs::path folder;
    agents::Dispatcher dispatcher;
  };
  agents::Supervisor& supervisor_;
  fs::path state_;
  std::optional<std::string> only_;
  fs::path file_;  // the topology file applied last (absolute)
  std::map<std::string, agents::ProgramSpec> applied_;
  std::map<std::string, int> locks_;  // by node id: the store directory's descriptor, locked
  std::map<std::string, std::pair<dev_t, ino_t>> data_files_;  // by node id: its data.mdb when locked
  std::map<std::string, std::string> poll_failures_;  // by keeper or dispatcher IRI: what its poll last said
  std::map<std::string, Dispatching> dispatchers_;
  std::map<std::string, spatial::AreaKeeper> keepers_;
  std::map<std::string, OpeningDispatcher> opening_dispatchers_;
  std::map<std::string, std::unique_ptr<Opening<spatial::Result<OpenedKeeper>>>> opening_keepers_;
  // Of nodes that left the file (or changed their behaviours) while they opened.
  std::vector<std::unique_ptr<Opening<node::Result<agents::Dispatcher>>>> abandoned_dispatchers_;
  std::vector<std::unique_ptr<Opening<spatial::Result<OpenedKeeper>>>> abandoned_keepers_;
  std::set<std::string> node_ids_;                // the nodes this supervisor runs
  std::map<std::string, std::string> iris_;       // their IRIs, by node id
  std::map<std::string, std::string> gone_;       // IRI, by node id: stopped as their store went
  std::map<std::string, Published> published_;    // by node id
  bool boards_finished_ = true;
};

// The request `up` leaves for a running supervisor before SIGHUP (its id, then the topology
// file), and the supervisor's answer (the id, then one line per change).
fs::path apply_request_file(const fs::path& pid_file) { return fs::path(pid_file).replace_extension(".apply"); }
fs::path apply_answer_file(const fs::path& pid_file) { return fs::path(pid_file).replace_extension(".applied"); }

// In the running supervisor, on SIGHUP: applies the file the request names, and answers.
// `before_answer` runs once the file is applied, before the answer is written: the supervisor
// writes its state there, since applying may take longer than kSupervisorSilentS and the `up`
// next in turn must not take it for stopped.
void apply_requested(Deployment& deployment, const fs::path& pid_file, const agents::Supervisor::Log& log,
                     const std::function<void()>& before_answer) {
  // The request is taken (moved aside) before it is read: a SIGHUP from anything else later
  // (a closed terminal, logrotate) finds none, instead of applying the file as it is on disk
  // then, which nobody asked for.
  const fs::path request = apply_request_file(pid_file);
  fs::path taken = request;
  taken += ".taken";
  std::error_code moved;
  fs::rename(request, taken, moved);
  if (moved) return log("up: SIGHUP without a request to apply a file: ignored ('tahvel up FILE' applies a file)");
  std::ifstream in(taken);
  std::string id, file, mitdb, path, bin;
  const bool complete = std::getline(in, id) && std::getline(in, file) && std::getline(in, mitdb) &&
                        std::getline(in, path) && std::getline(in, bin);
  in.close();
  fs::remove(taken, moved);
  if (!complete || !mitdb.starts_with("mitdb=") || !path.starts_with("path=") || !bin.starts_with("bin="))
    return log("up: an incomplete request to apply a file (from another version of tahvel?): ignored");
  const CommandContext context{bin.substr(4), mitdb.substr(6), path.substr(5)};
  std::string answer = id + "\n";
  auto topo = load_topology(file);
  // CYCLONEDDS_URI as the links will read it: this supervisor's.
  if (topo) {
    if (auto ok = check_cyclone_uri(*topo, nodes_brought_up(*topo, deployment.only())); !ok) {
      topo = Unexpected<node::Error>{ok.error()};
    } else if (auto fits = check_dds_participants(*topo, nodes_brought_up(*topo, deployment.only())); !fits) {
      topo = Unexpected<node::Error>{fits.error()};
    }
  }
  if (!topo) {
    answer += "error: " + topo.error().message + "\n";
    log("up: cannot apply " + file + ": " + topo.error().message);
  } else {
    try {
      auto changes = deployment.apply(*topo, context);
      log("up: applied " + file + ": " + (changes.empty() ? "nothing to change" : std::to_string(changes.size()) + " change(s)"));
      for (const auto& change : changes) {
        log("up: " + change);
        answer += change + "\n";
      }
    } catch (const Failure& f) {
      answer += "error: " + f.message + "\n";
      log("up: cannot apply " + file + ": " + f.message);
    }
  }
  before_answer();
  try {
    write_whole(apply_answer_file(pid_file), answer);
  } catch (const Failure& f) {
    log("up: " + f.message);
  }
}

// In `up`, when the supervisor of this selection runs: asks it to apply `file` and prints what
// it changed.
int ask_to_apply(pid_t supervisor, const fs::path& pid_file, const fs::path& file) {
  // One request at a time: two `up`s at once would overwrite each other's request, and one
  // would wait for an answer that never comes. The next waits here for the one before.
  struct Turn {
    int fd;
    ~Turn() {
      if (fd >= 0) ::close(fd);  // and the lock with it
    }
  } turn{::open(fs::path(pid_file).replace_extension(".apply.lock").c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644)};
  if (turn.fd < 0 || flock(turn.fd, LOCK_EX) != 0)
    fail(fs::path(pid_file).replace_extension(".apply.lock").string() + ": " + std::strerror(errno));
  const std::string id = std::to_string(getpid()) + "-" +
                         std::to_string(std::chrono::steady_clock::now().time_since_epoch().count());
  // With this process's environment: the supervisor expands the agents' commands with it, as
  // this `up` checked them (TAHVEL_MITDB switches to run_with_mitdb).
  const CommandContext here = CommandContext::of_this_process();
  const std::string request = id + "\n" + fs::absolute(file).lexically_normal().string() + "\nmitdb=" + here.mitdb + "\npath=" + here.path +
                              "\nbin=" + here.bin.string() + "\n";
  if (std::count(request.begin(), request.end(), '\n') != 5)
    fail("the topology file's path, TAHVEL_MITDB, PATH or this program's directory has a line break: the running supervisor "
         "cannot be asked to apply it");
  write_whole(apply_request_file(pid_file), request);
  if (kill(supervisor, SIGHUP) != 0) fail("cannot signal the supervisor " + std::to_string(supervisor) + ": " + std::strerror(errno));
  // Stopping a changed program may take its 5 s of grace, several in turn.
  const auto deadline = std::chrono::steady_clock::now() + 60s;
  while (std::chrono::steady_clock::now() < deadline) {
    std::ifstream in(apply_answer_file(pid_file));
    std::string answered;
    if (std::getline(in, answered) && answered == id) {
      std::vector<std::string> lines;
      for (std::string line; std::getline(in, line);) lines.push_back(line);
      for (const auto& line : lines)
        if (line.rfind("error: ", 0) == 0) fail("the running supervisor (pid " + std::to_string(supervisor) + ") did not apply " + file.string() + ": " + line.substr(7));
      if (lines.empty())
        std::cout << "up: the running supervisor (pid " << supervisor << ") already runs " << file.string() << " as written: nothing to change\n";
      else
        std::cout << "up: applied " << file.string() << " to the running supervisor (pid " << supervisor << "):\n";
      for (const auto& line : lines) std::cout << "up:   " << line << "\n";
      return kExitOk;
    }
    if (supervisor_holding(pid_file) == 0) fail("the supervisor " + std::to_string(supervisor) + " ended before it applied " + file.string());
    std::this_thread::sleep_for(50ms);
  }
  fail("the supervisor " + std::to_string(supervisor) + " did not answer within 60 s; its log is " +
       (pid_file.parent_path() / "logs" / "supervisor.log").string());
}

}  // namespace

// Why --node ID may name no node: a systemd unit's instance name as systemd passes it (`%i`,
// each byte outside [A-Za-z0-9:_.-] as \xHH: `kodu-\xc3\xb5ie` for kodu-õie), or a slip of one or
// two characters. Empty when neither.
std::string node_id_hint(const Topology& topo, const std::string& id) {
  std::string unescaped;
  for (std::size_t i = 0; i < id.size(); ++i) {
    unsigned byte = 0;
    if (id.compare(i, 2, "\\x") == 0 && i + 4 <= id.size() && std::sscanf(id.c_str() + i + 2, "%2x", &byte) == 1 &&
        std::isxdigit(static_cast<unsigned char>(id[i + 2])) && std::isxdigit(static_cast<unsigned char>(id[i + 3]))) {
      unescaped += static_cast<char>(byte);
      i += 3;
    } else {
      unescaped += id[i];
    }
  }
  if (unescaped != id && topo.node(unescaped))
    return " ('" + unescaped + "', systemd-escaped: a unit passes its instance name so when the id holds characters "
           "other than ASCII letters, digits, ':', '_', '.' and '-'; give the node an id of those, docs/deploy.md)";
  const NodeSpec* nearest = nullptr;
  std::size_t best = 3;
  for (const NodeSpec& spec : topo.nodes)
    if (const std::size_t d = uri::edit_distance(id, spec.id); d < best) {
      best = d;
      nearest = &spec;
    }
  return nearest ? "; did you mean '" + nearest->id + "'?" : std::string();
}

namespace {
// "tahvel (uid 998)", or "uid 998" for a user the system does not name.
std::string user_name(uid_t uid) {
  const std::string number = "uid " + std::to_string(uid);
  if (const passwd* user = ::getpwuid(uid); user && user->pw_name) return std::string(user->pw_name) + " (" + number + ")";
  return number;
}

// The user as sudo -u takes it: "tahvel", or "#998".
std::string sudo_user(uid_t uid) {
  if (const passwd* user = ::getpwuid(uid); user && user->pw_name) return user->pw_name;
  return "'#" + std::to_string(uid) + "'";
}

// The effective uid of process `pid` (the second field of the Uid line of /proc/PID/status: the
// owner of /proc/PID is root for a process that is not dumpable), nullopt when it cannot be read.
std::optional<uid_t> effective_uid_of(pid_t pid) {
  std::ifstream status("/proc/" + std::to_string(pid) + "/status");
  for (std::string line; std::getline(status, line);) {
    if (!line.starts_with("Uid:")) continue;
    std::istringstream fields(line.substr(4));
    unsigned long real = 0, effective = 0;
    if (fields >> real >> effective) return static_cast<uid_t>(effective);
  }
  return std::nullopt;
}
}  // namespace

namespace {

// A refusal of `up` as things stand, wherever it is met (kExitFileRefused).
[[noreturn]] void refuse(std::string message) { throw Failure{kExitFileRefused, std::move(message)}; }

// `checking` stays true while up only reads and checks (the file, what it names, the stores and
// supervisors there), and is made false before anything is created or a supervisor asked;
// refusals met after that (another `up` won the race) are thrown as such (refuse).
int up_checked(const Args& args, bool& checking) {
  Topology topo = check(load_topology(args.positional(0)));
  fs::path state = fs::absolute(state_dir(args));
  std::optional<std::string> only = args.get("--node");
  if (only && !topo.node(*only)) {
    const bool runs = supervisor_holding(state / pid_file_name(only)) != 0;
    fail("--node '" + *only + "': no such node in " + topo.file.string() +
         (runs ? " (it still runs from an earlier file: 'tahvel down --state " + shell_word(state) + " --node " + *only + "' stops it)"
               : node_id_hint(topo, *only)));
  }
  fs::path pid_file = state / pid_file_name(only);
  // The supervisor of this selection already running is asked to apply the file as it is now,
  // once it is checked (below): `up` again after an edit adds a node, restarts what changed.
  pid_t running = supervisor_holding(pid_file);
  if (running < 0) {
    checking = false;  // passes in a moment: not a refusal of the file
    fail("a supervisor is starting (" + pid_file.string() + "); try again in a moment");
  }
  // A supervisor stopped with SIGSTOP (or hung) would never answer, and one stopped inside a
  // write to a store would hold up this `up` at its own writes: said before anything is touched.
  if (const double silent = running > 0 ? state_file_silent_for(pid_file) : 0; silent > kSupervisorSilentS) {
    const std::string why = why_state_not_written(pid_file.parent_path());
    fail("the supervisor " + std::to_string(running) + " has not written its state for " + seconds_text(silent) + " (" + why +
         "): nothing applied. " +
         (why.ends_with("state file") ? "Free some space there" : "If it was stopped, 'kill -CONT " + std::to_string(running) + "'") +
         "; its log is " + (pid_file.parent_path() / "logs" / "supervisor.log").string());
  }
  // Under a service manager `up --foreground` is the supervisor: applying the file to another
  // one and returning would end the service while the node runs outside it.
  if (running > 0 && args.has("--foreground"))
    fail("a supervisor already runs this selection (pid " + std::to_string(running) + ", " + pid_file.string() +
         "): --foreground would not be it. 'tahvel down --state " + shell_word(state) + (only ? " --node " + *only : "") +
         "' first, or 'tahvel up' without --foreground applies the file to it");
  // Root applying a file to a service user's supervisor left root's files in its state
  // directory (the next `up` of that user failed on them) after changing its stores: refused
  // before anything is touched.
  if (const std::optional<uid_t> runs_as = running > 0 ? effective_uid_of(running) : std::nullopt; runs_as && *runs_as != ::geteuid())
    fail("the running supervisor (pid " + std::to_string(running) + ") runs as " + user_name(*runs_as) + ", this 'up' as " +
         user_name(::geteuid()) + ": nothing applied. Run it as that user (sudo -u " + sudo_user(*runs_as) +
         " tahvel up …), so that what it writes in " + state.string() + " stays that user's");
  // One supervisor per node: `up --node X` beside `up` of the whole file would run X's link and
  // agents twice (two ECG sources writing every chunk twice). Checked again once this `up` has
  // its turn (below): an `up` of the other selection started at the same moment may have won it.
  auto refuse_a_supervisor_of_another_selection = [&] {
    if (only) {
      if (pid_t whole = supervisor_holding(state / pid_file_name(std::nullopt)); whole != 0)
        refuse("the supervisor of the whole file runs under " + state.string() + " (pid " + std::to_string(whole) + "), node '" +
             *only + "' with it: 'tahvel up " + shell_word(topo.file) + " --state " + shell_word(state) +
             "' applies the file to it (it starts what is new), 'tahvel down --state " + shell_word(state) + "' stops it");
    } else {
      for (const NodeSpec& spec : topo.nodes)
        if (supervisor_holding(state / pid_file_name(spec.id)) != 0)
          refuse("node '" + spec.id + "' already runs under its own supervisor (" + (state / pid_file_name(spec.id)).string() +
               "); 'tahvel down --state " + shell_word(state) + " --node " + spec.id + "' first");
    }
  };
  refuse_a_supervisor_of_another_selection();
  // Everything is checked before anything is created: a store that exists must be the node's,
  // and the files and patterns a new one gets must read.
  const std::vector<const NodeSpec*> mine = nodes_brought_up(topo, only);
  // The links take the supervisor's environment: one that runs checks the file it is asked to
  // apply in its own (apply_requested).
  if (running == 0)
    if (auto ok = check_cyclone_uri(topo, mine); !ok) fail(ok.error().message);
  if (auto fits = check_dds_participants(topo, mine); !fits) fail(fits.error().message);
  for (const NodeSpec* spec : mine) {
    const fs::path store = state / spec->id;
    if (fs::exists(store / "data.mdb")) {
      node::Node existing = check(node::Node::open(store));
      // Named where the file says it: the `iri`, or for a child that derives it, its `parent`.
      const std::string& changed_at = !spec->parent.empty() && spec->iri_at == spec->at ? spec->parent_at : spec->iri_at;
      if (existing.iri() != spec->iri) {
        // A home moved to another hospital: what its outbox holds was sent up as <old IRI>'s, and
        // goes up only under that IRI, to the old parent; a new store starts with an empty one.
        std::string outbox;
        auto uplink = existing.agent("uplink");
        if (const auto waiting = uplink ? uplink->pending() : node::Result<std::uint64_t>(std::uint64_t{0}); waiting && *waiting > 0)
          outbox = "; its outbox holds " + std::to_string(*waiting) + (*waiting == 1 ? " item" : " items") +
                   " its parent never acknowledged, which go up only under <" + existing.iri() +
                   ">: to keep them, run it as before until 'tahvel status' shows its outbox empty, then move it";
        // Its parent renamed (home3 to home4): said as such, at the renamed node, not only at
        // this child's `parent` line (an integrator's probe of session 89).
        std::string renamed;
        const std::string& was = existing.iri();
        const auto was_cut = was.rfind('/'), is_cut = spec->iri.rfind('/');
        if (was_cut != std::string::npos && is_cut != std::string::npos &&
            was.compare(was_cut, std::string::npos, spec->iri, is_cut, std::string::npos) == 0) {
          const std::string old_parent = was.substr(0, was_cut), new_parent = spec->iri.substr(0, is_cut);
          const auto in_file = [&](const std::string& iri) {
            return std::find_if(topo.nodes.begin(), topo.nodes.end(), [&](const NodeSpec& n) { return n.iri == iri; });
          };
          if (const auto parent = in_file(new_parent); parent != topo.nodes.end() && in_file(old_parent) == topo.nodes.end())
            renamed = "; its parent in that store, <" + old_parent + ">, is no node of the file, and its parent '" + parent->id +
                      "' (" + parent->at + ") is <" + new_parent + ">: renamed? A node's IRI is its identity, and a node renamed " +
                      "gives each node below it a new one: their stores cannot go on under it. Give it its old id back, or move " +
                      "away its store and those of the nodes below it" +
                      (running != 0 ? std::string(" (they stop within a second; the others run on)") : std::string()) +
                      " and 'tahvel up' again: each stays readable where it is moved (tahvel query DIR)";
        }
        fail((changed_at.empty() ? topo.file.string() : changed_at) + ": node '" + spec->id + "': the store at " + store.string() + " is the node <" + existing.iri() + ">, the file says <" +
             spec->iri + "> (a changed iri or parent)" +
             (!renamed.empty() ? renamed
                               : "; move that store away" +
                                     (running != 0 ? std::string(" (its node stops within a second; the others run on)") : std::string()) +
                                     " and 'tahvel up' again, or give the node another id") +
             outbox);
      }
      for (std::size_t i = 0; i < spec->forward.size(); ++i)
        warn_of_unknown_terms(*spec, i, forward_pattern_of(*spec, i, existing.prefixes()));
      for (const fs::path& file : spec->load) (void)load_file_triples(*spec, file, existing.prefixes(), topo);
      // Durability and ring are the store's, set when it was made: a changed ring would remove
      // records (or keep more) behind the operator's back, so the file's is only compared.
      const node::Stats made = check(existing.stats());
      const std::string made_durability = made.durability == node::Durability::durable ? "durable" : "fast";
      if (made_durability != spec->durability || made.ring != spec->ring)
        std::cerr << "up: warning: " << spec->store_at << ": node '" << spec->id << "': the store at " << store.string() << " was made with durability "
                  << made_durability << ", ring " << made.ring << "; the file's durability " << spec->durability << ", ring "
                  << spec->ring << " apply only to a new store (move this one away to make it so)\n";
    } else {
      if (fs::is_directory(state)) refuse_a_second_store_of(*spec, state);
      refuse_what_a_new_stores_place_holds(*spec, store);
      const uri::PrefixMap prefixes = uri::PrefixMap::standard();
      for (std::size_t i = 0; i < spec->forward.size(); ++i) warn_of_unknown_terms(*spec, i, forward_pattern_of(*spec, i, prefixes));
      for (const fs::path& file : spec->load) (void)load_file_triples(*spec, file, prefixes, topo);
    }
  }
  refuse_malformed_patterns_of_others(topo, mine);
  const CommandContext here = CommandContext::of_this_process();
  CommandContext here_for_file = here;
  here_for_file.dir = fs::absolute(topo.file).lexically_normal().parent_path();
  for (const NodeSpec* spec : mine)
    if (auto clash = agents_running_as_one(*spec, !here.mitdb.empty())) fail(*clash);
  for (const NodeSpec* spec : mine) {
    // A rule file's CURIEs read with the store's prefixes, as its reasoner will read them.
    std::optional<uri::PrefixMap> prefixes;
    for (const AgentSpec& agent : spec->agents) {
      auto argv = expand_agent_command(agent, *spec, state / spec->id, here_for_file);
      if (!argv) fail(argv.error().message);  // it starts with the file, line and column of the agent
      if (!prefixes) {
        auto existing = fs::exists(state / spec->id / "data.mdb") ? node::Node::open(state / spec->id) : node::Result<node::Node>(node::fail(node::Errc::not_found, ""));
        prefixes = existing ? existing->prefixes() : uri::PrefixMap::standard();
      }
      if (auto rules = check_rule_file(agent, *spec, *argv, *prefixes); !rules) fail(rules.error().message);
      if (auto flags = check_agent_flags(agent, *spec, *argv, here_for_file); !flags) fail(flags.error().message);
      warn_of_settings_on_the_board(agent, *spec, *argv, state / spec->id);
    }
  }
  warn_of_dataflow(topo, mine);
  if (args.has("--check")) {
    std::string ids;
    for (const NodeSpec* spec : mine) ids += (ids.empty() ? "" : ", ") + spec->id;
    std::cout << "up: " << topo.file.string() << ": checked " << mine.size() << (mine.size() == 1 ? " node" : " nodes") << " (" << ids
              << ") as this machine would bring " << (mine.size() == 1 ? "it" : "them") << " up; nothing made or started (--check)\n";
    return 0;
  }
  checking = false;
  // Only now, with everything checked: a refused file leaves no state directory behind.
  std::error_code ec;
  const bool new_state = !fs::exists(state, ec);
  fs::create_directories(state / "logs", ec);
  if (ec) fail(state.string() + ": " + ec.message());
  // A mistyped --state would start a second, empty deployment beside the first: said.
  if (new_state) std::cout << "up: created the state directory " << state.string() << "\n";
  // Two `up`s of one state directory at once (a service unit and an operator) each made the same
  // new store, and one removed what the other had just made. They take turns from here until the
  // supervisor holds its pid file; the second then finds it running and applies the file to it.
  const fs::path turn_file = state / ".up.lock";
  const int turn = ::open(turn_file.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
  if (turn < 0 || flock(turn, LOCK_EX) != 0) fail(turn_file.string() + ": " + std::strerror(errno));
  running = supervisor_holding(pid_file);
  if (running < 0) fail("a supervisor is starting (" + pid_file.string() + "); try again in a moment");
  if (running == 0) refuse_a_supervisor_of_another_selection();
  // A supervisor runs each node it holds (Deployment::lock_node); one that holds a node here
  // without a pid file saying so (the file was deleted) would be a second writer beside the one
  // this `up` would start.
  if (running == 0) {
    for (const NodeSpec* spec : mine)
      if (const pid_t holder = supervisor_of_store(state / spec->id); holder != 0)
        refuse("node '" + spec->id + "' is run by " + (holder > 0 ? "supervisor " + std::to_string(holder) : std::string("another supervisor")) +
             ", which holds its store " + (state / spec->id).string() + " though no pid file under " + state.string() +
             " says so (was it deleted?): 'tahvel down --state " + shell_word(state) + "' stops it");
  }
  for (const NodeSpec* node_spec : mine) {
    const NodeSpec& spec = *node_spec;
    fs::path store = state / spec.id;
    const bool new_store = !fs::exists(store / "data.mdb");
    if (new_store) create_store(spec, store, topo);  // with its policy, then its files
    {
      // Whose child the node is, on its own board (tv:parent, written as its uplink, persistent):
      // `status` tells a child from a root by it where no forwarding policy (`forward = []`) and
      // no state of a link that never ran say so. A node made a root loses it.
      node::Node node = check(node::Node::open(store));
      node::Agent uplink = check(node.agent("uplink"));
      const node::Pattern recorded{.s = node::Term::iri(node.iri()), .p = node::Term::iri(federation::vocab::kParent), .source = uplink.iri()};
      const NodeSpec* parent = topo.node(spec.parent);
      auto was = check(check(node.snapshot()).list(recorded));
      if (!parent && !was.empty()) check(uplink.replace({recorded}, {}));
      if (parent && (was.size() != 1 || was[0].triple.o.value != parent->iri)) {
        node::Item item;
        item.persistent = true;
        item.add(node::Term::iri(node.iri()), node::Term::iri(federation::vocab::kParent), node::Term::iri(parent->iri));
        check(uplink.replace({recorded}, {item}));
      }
    }
    if (!spec.parent.empty()) {
      // The forwarding policy is on the board before any agent starts: an item written before
      // the uplink subscribed would never be routed to it (P5).
      node::Node node = check(node::Node::open(store));
      node::Agent uplink = check(node.agent("uplink"));
      const std::vector<node::Pattern> policy = forwarding_policy(spec, node.prefixes());
      // Snapshots are released before the writes below: a store that must grow for them (a
      // copy made by `tahvel backup`, its map as large as its data) cannot while this process
      // holds one, and `up` on a restored backup failed so.
      std::set<std::uint64_t> had;
      for (const auto& r : check(check(node.snapshot()).list({.p = node::Term::iri(std::string(federation::vocab::kTv) + "subscriber"),
                                                              .o = node::Term::iri(uplink.iri())})))
        had.insert(r.meta.item);
      // Said once, when the node's first policy is written: a sensor node left without `forward`
      // sends its parent nothing of its raw signal, and nothing else says so.
      if (!spec.forward_given && (had.empty() || new_store))
        std::cout << "up: " << spec.id << ": no forward in the file, so only HRV windows go up to '" << spec.parent
                  << "' (the default); raw signals stay on the node\n";
      std::set<std::uint64_t> kept;
      // As the link does at its start (P7a), before the first pattern: every item routed to the
      // uplink is then remembered as given to it (P6c, P6d send only those again).
      check(uplink.receive_removals());
      for (std::size_t k = 0; k < policy.size(); ++k) {
        // Its own, beside a parent's identical one: the parent's removal must not take the file's.
        const std::uint64_t item = check(uplink.subscribe(policy[k], {.own_only = true}));
        kept.insert(item);
        // Not at a new store's first policy, which is the file's as it is. A store whose policy
        // was empty (`forward = []`) has no subscription to tell it from a new one by.
        if (!had.count(item) && k < spec.forward.size() && !new_store)
          std::cout << "up: " << spec.id << ": added the forwarding pattern '" << spec.forward[k] << "' (item " << item << ")\n";
      }
      // A pattern taken out of the file stops going up (a narrowed policy keeps raw data home):
      // the uplink's own subscriptions are the file's. Those the parent sent down stay.
      std::vector<std::pair<std::uint64_t, std::string>> dropped;  // item, pattern
      {
        auto snap = check(node.snapshot());
        const std::string subscriber = std::string(federation::vocab::kTv) + "subscriber";
        for (const auto& r : check(snap.list({.p = node::Term::iri(subscriber), .o = node::Term::iri(uplink.iri())})))
          if (r.meta.source == uplink.iri() && !kept.count(r.meta.item))
            dropped.emplace_back(r.meta.item, pattern_text(snap, r.meta.item, node.prefixes()));
      }
      bool narrowed = false;
      for (const auto& [item, pattern] : dropped) {
        check(uplink.unsubscribe(item));
        narrowed = true;
        std::cout << "up: " << spec.id << ": removed the forwarding pattern '" << pattern
                  << "', no longer in the file (item " << item << ")\n";
      }
      // What the removed patterns queued while the parent was away stays home too: a policy
      // narrowed to keep raw ECG at home must not still send the backlog.
      if (narrowed) {
        if (const std::uint64_t withdrawn = check(uplink.withdraw_unrouted()); withdrawn > 0)
          std::cout << "up: " << spec.id << ": " << withdrawn << (withdrawn == 1 ? " item" : " items")
                    << " queued for '" << spec.parent << "' under the removed patterns " << (withdrawn == 1 ? "stays" : "stay")
                    << " on the node (out of the outbox)\n";
      }
    }
    if (!new_store) {
      // After the policy: a file added to the node together with a pattern that matches it goes up.
      node::Node existing = check(node::Node::open(store));
      load_new_files(spec, existing, topo);
    }
  }
  // A node taken out of the file, or renamed (a child's IRI changes with its id), keeps its store
  // and what its outbox holds: items its parent never acknowledged, which go up only when a node
  // of that IRI runs again. Said, as nothing else would; with --node too (one machine of a real
  // deployment, whose state directory holds its one node).
  {
    for (const auto& entry : fs::directory_iterator(state, ec)) {
      const std::string id = entry.path().filename().string();
      if (topo.node(id) || !fs::exists(entry.path() / "data.mdb") || store_being_made(entry.path())) continue;
      auto left = node::Node::open(entry.path());
      // A copy of a node of the file (a backup kept here) is not one left behind.
      if (!left || std::any_of(topo.nodes.begin(), topo.nodes.end(), [&](const NodeSpec& n) { return n.iri == left->iri(); }))
        continue;
      auto uplink = left->agent("uplink");
      const auto waiting = uplink ? uplink->pending() : node::Result<std::uint64_t>(std::uint64_t{0});
      // Brought up with `up --node ID` and left running: its own supervisor runs it on, as the
      // node the file no longer has, beside the one that replaces it.
      const pid_t runs = only ? supervisor_holding(state / pid_file_name(id)) : 0;
      const std::string still_runs = runs > 0 ? " Its supervisor (pid " + std::to_string(runs) + ") still runs it: 'tahvel down --state " +
                                                    shell_word(state) + " --node " + id + "' stops it."
                                              : std::string();
      if (waiting && *waiting > 0)
        std::cout << "up: warning: the store " << entry.path().string() << " of <" << left->iri() << ">, a node not in "
                  << topo.file.string() << ", holds " << *waiting << (*waiting == 1 ? " item" : " items")
                  << " its parent never acknowledged: they go up only when a node of that IRI runs again (put it back "
                     "in the file until its outbox is empty, as 'tahvel status' shows)." << still_runs << "\n";
      else if (runs > 0)
        std::cout << "up: warning: node '" << id << "' <" << left->iri() << ">, not in " << topo.file.string()
                  << ", still runs, beside the node that replaces it." << still_runs << "\n";
    }
    ec.clear();
  }
  if (running > 0) return ask_to_apply(running, pid_file, topo.file);
  const std::size_t program_count = programs_of(topo, mine, state, here).size();
  const bool foreground = args.has("--foreground");
  // The foreground supervisor is a service's main process, its output a pipe to the journal: a
  // line is written when it is said, not held in a buffer until a clean stop (a SIGKILL, the
  // service manager's stop timeout, lost what was held).
  if (foreground) std::cout << std::unitbuf << std::flush;
  int ready_fd = -1;  // the daemon's end of the pipe `up` waits on
  int pid_fd = -1;    // the pid file, held
  if (!foreground) {
    // The supervisor lives on in a daemon; this process returns once it has started.
    std::cout.flush();  // or the daemon would write this process's buffered lines again, into its log
    // Close-on-exec: a program the supervisor starts must not hold the pipe open, or this
    // process would wait for that program's end.
    int ready[2];
    if (pipe2(ready, O_CLOEXEC) != 0) fail(std::string("pipe: ") + std::strerror(errno));
    pid_t pid = fork();
    if (pid < 0) fail(std::string("fork: ") + std::strerror(errno));
    if (pid > 0) {
      close(ready[1]);
      // "1" once the supervisor holds its pid file and has applied the file, the number of
      // programs it started, then a line for each change that is not a program's start;
      // otherwise "0" and why not (or nothing: it died).
      std::string answer;
      char buffer[512];
      for (ssize_t n; (n = read(ready[0], buffer, sizeof buffer)) != 0;) {
        if (n < 0 && errno == EINTR) continue;
        if (n < 0) break;
        answer.append(buffer, static_cast<std::size_t>(n));
      }
      close(ready[0]);
      if (answer.empty() || answer[0] != '1')
        fail("the supervisor did not start" + (answer.size() > 1 ? ": " + answer.substr(1) : std::string()) + "; see " +
             (state / "logs" / "supervisor.log").string());
      std::istringstream said(answer.substr(1));
      std::string count;
      std::getline(said, count);
      const std::size_t started = count.empty() ? program_count : std::strtoull(count.c_str(), nullptr, 10);
      for (std::string line; std::getline(said, line);) std::cout << "up: " << line << "\n";
      std::cout << "up: " << topo.name << ": " << started << (started == 1 ? " program" : " programs") << " under supervisor"
                << (started == program_count ? std::string()
                                             : " (of " + std::to_string(program_count) + " in the file for this machine; see above)")
                << " (pid file "
                << pid_file.string() << "); logs in " << (state / "logs").string() << "\n"
                << "up: 'tahvel status --state " << shell_word(state) << "' shows the tree, 'tahvel down --state "
                << shell_word(state) << "' stops it\n";
      return kExitOk;
    }
    close(ready[0]);
    setsid();
    if (fork() > 0) _exit(0);  // not a session leader: never gets a controlling terminal
    // Close-on-exec, and closed once duplicated: the programs get 0, 1 and 2 of their own and
    // must not hold the supervisor's log open.
    int log = ::open((state / "logs" / "supervisor.log").c_str(), O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0644);
    int null = ::open("/dev/null", O_RDONLY | O_CLOEXEC);
    if (null >= 0) {
      dup2(null, 0);
      if (null > 2) ::close(null);
    }
    if (log >= 0) {
      dup2(log, 1);
      dup2(log, 2);
      if (log > 2) ::close(log);
    }
    if ((pid_fd = hold_pid_file(pid_file)) < 0) {
      const std::string why = pid_file.string() + " is held by another supervisor (or cannot be written)";
      std::cerr << "up: " << why << std::endl;
      const std::string answer = "0" + why;
      (void)!write(ready[1], answer.data(), answer.size());
      _exit(1);  // `up` says why the supervisor did not start
    }
    ready_fd = ready[1];
  } else if ((pid_fd = hold_pid_file(pid_file)) < 0) {
    fail(pid_file.string() + " is held by another supervisor (or cannot be written)");
  }
  close(turn);  // the supervisor runs: the next `up` applies its file to it
  install_stop_handlers();
  struct sigaction on_hup {};
  on_hup.sa_handler = on_apply_signal;
  sigemptyset(&on_hup.sa_mask);
  sigaction(SIGHUP, &on_hup, nullptr);
  signal(SIGPIPE, SIG_IGN);
  const agents::Supervisor::Log log = [](std::string_view line) { node::write_log_line(line); };
  agents::Supervisor supervisor(log);
  fs::path state_file = state / pid_file_name(only);
  state_file.replace_extension(".state");
  // Stopping programs (a changed command, `down`) may take their grace: the state file stays
  // current meanwhile, or `status` and the next `up` would take this supervisor for hung.
  // Said once when it cannot be written, and once when it can again (it is written ten times a
  // second).
  std::string state_file_trouble;
  // The state directory as it was when this supervisor started: nothing is written into one
  // that another `up` made again after this one was removed.
  const int state_fd = ::open(state.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  auto keep_state_file = [&] {
    if (!still_holds(state_fd, state)) return;
    std::string why = write_state_file(state_file, supervisor);
    if (why == state_file_trouble) return;
    log(why.empty() ? "up: " + state_file.string() + " written again" : "up: " + why);
    state_file_trouble = std::move(why);
  };
  supervisor.while_waiting(keep_state_file);
  log("up: supervisor " + std::to_string(getpid()) + " runs " + fs::absolute(topo.file).lexically_normal().string() +
      (only ? " (node " + *only + ")" : std::string()));
  Deployment deployment(supervisor, state, only);
  // What `up` says: a node not started (another supervisor runs it), leftovers of a killed
  // supervisor killed, a program that cannot start. Logged only, they went unseen.
  std::string said;
  std::size_t started = 0;
  for (const auto& change : deployment.apply(topo, CommandContext::of_this_process())) {
    if (change.rfind("started ", 0) == 0) {  // the supervisor logs each start
      ++started;
      continue;
    }
    log("up: " + change);
    said += change + "\n";
  }
  said = "1" + std::to_string(started) + "\n" + said;
  if (ready_fd >= 0) {
    (void)!write(ready_fd, said.data(), said.size());
    ::close(ready_fd);
  }
  auto log_checked = std::chrono::steady_clock::now(), stores_checked = log_checked;
  // Left with no node to run (its stores removed to start afresh): it ends with a failure, so that
  // a service manager restarting on failure starts it again and its `up` makes the stores anew.
  bool stores_removed = false;
  while (!g_stop) {
    supervisor.poll();
    // Its own log too (in the foreground it writes to the terminal: nothing to keep).
    if (!foreground && std::chrono::steady_clock::now() - log_checked >= 5s) {
      log_checked = std::chrono::steady_clock::now();
      if (auto rotated = agents::rotate_log(state / "logs" / "supervisor.log", kLogLimit); !rotated)
        log("up: " + rotated.error().message);
      else if (*rotated)
        log("up: the supervisor's log passed " + std::to_string(kLogLimit) + " bytes; what it held is in supervisor.log.1");
    }
    if (g_apply) {
      g_apply = 0;
      apply_requested(deployment, pid_file, log, keep_state_file);
    }
    deployment.poll(log);
    deployment.publish_programs(log);
    keep_state_file();
    if (std::chrono::steady_clock::now() - stores_checked >= 1s) {
      stores_checked = std::chrono::steady_clock::now();
      if (const auto gone = deployment.stores_gone(); !gone.empty()) {
        // The whole state directory removed (or every node's store): nothing is left to run.
        if (!still_holds(state_fd, state) || gone.size() == deployment.node_count()) {
          std::string ids;
          for (const auto& id : gone) ids += (ids.empty() ? "'" : ", '") + id + "'";
          log("up: the store of node " + ids + " is no longer in " + state.string() +
              " (removed or moved while it ran); stopping, since its programs would write where no one reads and an "
              "'up' of that directory would run them twice");
          stores_removed = true;
          break;
        }
        for (const auto& line : deployment.drop_nodes(gone)) log("up: " + line);
      }
    }
    std::this_thread::sleep_for(100ms);
  }
  log("up: supervisor " + std::to_string(getpid()) + " stopping its programs");
  deployment.stop(log, still_holds(state_fd, state));
  keep_state_file();
  std::error_code removed;
  if (still_holds(pid_fd, pid_file)) fs::remove(pid_file, removed);  // not another supervisor's
  log("up: supervisor " + std::to_string(getpid()) + " stopped");
  // A board's thread still waiting in the store would run on while static destructors do
  // (the log's mutex among them) should the lock be freed meanwhile: end without them.
  const int status = stores_removed ? kExitFailure : kExitOk;
  if (!deployment.boards_finished()) _exit(status);
  return status;
}

}  // namespace

int run_up(const Args& args) {
  bool checking = true;
  try {
    return up_checked(args, checking);
  } catch (Failure& failure) {
    if (checking && failure.status == kExitFailure) failure.status = kExitFileRefused;
    throw;
  }
}

const Command kDownCommand{
    "down",
    "[--state DIR] [--node ID]",
    "Stop what 'tahvel up' started with this state directory.",
    "Sends SIGTERM and SIGCONT to each supervisor of DIR (its pid files; SIGCONT so that one\n"
    "stopped with SIGSTOP handles the SIGTERM), which stops its agents (the same, then SIGKILL\n"
    "after 5 s), and waits up to 20 s for them to end. The stores stay. With --node only the\n"
    "supervisor that 'tahvel up FILE --node ID' started.",
    {kFlagState, {"--node", "", "ID", "stop only the node brought up with 'up --node ID'"}},
    0, 0, false};

namespace {

// Why the supervisor `pid`, sent SIGTERM and SIGCONT, still runs, from its state in
// /proc/PID/stat, and what to do about it.
std::string not_stopped_because(pid_t pid, const fs::path& state) {
  const std::string p = std::to_string(pid), stat = "/proc/" + p + "/stat";
  const std::string head = "supervisor " + p + " did not stop within 20 s: ";
  const std::string kill_it = "'kill -KILL " + p + "' ends it and its programs at once";
  const std::optional<char> now = node::process_state(pid);
  if (now == 'T')
    return head + "it is stopped (state T in " + stat + ": stopped by a signal again since SIGCONT); 'kill -CONT " + p +
           "' lets it stop, or " + kill_it;
  if (now == 't')
    return head + "a debugger holds it (state t in " + stat + "); once the debugger lets it go it stops (SIGTERM is pending)";
  if (now == 'D')
    return head + "it waits in the kernel (state D in " + stat + ", most often for a disk or a network file system); " +
           kill_it + " once that wait ends";
  if (now)
    return head + "it runs (state " + std::string(1, *now) + " in " + stat + ") but has not finished stopping its programs; see " +
           (state / "logs" / "supervisor.log").string() + ", or " + kill_it;
  return head + "its state cannot be read (" + stat + "); see " + (state / "logs" / "supervisor.log").string();
}

}  // namespace

int run_down(const Args& args) {
  fs::path state = state_dir(args);
  std::optional<std::string> only = args.get("--node");
  if (std::error_code ec; !fs::is_directory(state, ec)) {
    std::cout << "down: nothing was running under " << state.string() << " (no such directory)\n";
    return kExitOk;
  }
  if (only && !fs::exists(state / *only / "data.mdb") && supervisor_holding(state / pid_file_name(only)) == 0) {
    std::set<std::string> stores;  // the nodes brought up under DIR
    std::error_code list_ec;
    for (const auto& entry : fs::directory_iterator(state, list_ec))
      if (fs::exists(entry.path() / "data.mdb") && !store_being_made(entry.path())) stores.insert(entry.path().filename().string());
    std::string nodes;
    for (const auto& id : stores) nodes += (nodes.empty() ? "" : ", ") + id;
    fail("--node '" + *only + "': no such node under " + state.string() +
         (nodes.empty() ? std::string(" (it holds no node's store)") : " (its nodes: " + nodes + ")"));
  }
  if (only && supervisor_holding(state / pid_file_name(only)) == 0 &&
      supervisor_holding(state / pid_file_name(std::nullopt)) != 0)
    fail("--node '" + *only + "': it runs under the supervisor of the whole file (" +
         (state / pid_file_name(std::nullopt)).string() + "), which 'tahvel down --state " + shell_word(state) + "' stops");
  // An `up` still making the stores holds .up.lock until its supervisor runs: waited for, or
  // this `down` would find nothing to stop and the deployment would start after it.
  if (const int turn = ::open((state / ".up.lock").c_str(), O_RDWR | O_CLOEXEC); turn >= 0) {
    bool said = false;
    const auto until = std::chrono::steady_clock::now() + 120s;
    while (flock(turn, LOCK_EX | LOCK_NB) != 0) {
      if (!said) std::cout << "down: an 'up' is starting the deployment under " << state.string() << "; waiting for it\n" << std::flush;
      said = true;
      if (std::chrono::steady_clock::now() >= until) {
        ::close(turn);
        fail("the 'up' starting the deployment under " + state.string() + " did not finish within 120 s (it holds " +
             (state / ".up.lock").string() + "); try again when it has");
      }
      std::this_thread::sleep_for(100ms);
    }
    ::close(turn);  // and the lock: the supervisor, if that `up` started one, holds its pid file now
  }
  std::error_code ec;
  int stopped = 0;
  std::set<std::string> stopped_ids;  // of the pid files whose supervisor this down stopped ("all": every node)
  for (const auto& entry : fs::directory_iterator(state, ec)) {
    const std::string name = entry.path().filename().string();
    if (name.rfind("supervisor-", 0) != 0 || entry.path().extension() != ".pid") continue;
    if (only && name != pid_file_name(only)) continue;
    pid_t pid = supervisor_holding(entry.path());
    const auto deadline = std::chrono::steady_clock::now() + 20s;
    while (pid < 0 && std::chrono::steady_clock::now() < deadline) {  // starting: its pid comes
      std::this_thread::sleep_for(50ms);
      pid = supervisor_holding(entry.path());
    }
    if (pid == 0) {  // stale (no supervisor holds it): never signal the pid written there
      fs::remove(entry.path(), ec);
      continue;
    }
    if (pid > 0) {
      // SIGCONT after SIGTERM, as systemd does: a supervisor stopped with SIGSTOP then handles
      // the SIGTERM now, instead of keeping it pending until someone resumes it (and finding
      // the deployment stopped then, long after this `down` failed).
      kill(pid, SIGTERM);
      kill(pid, SIGCONT);
    }
    while (supervisor_holding(entry.path()) != 0 && std::chrono::steady_clock::now() < deadline)
      std::this_thread::sleep_for(50ms);
    if (supervisor_holding(entry.path()) != 0) fail(not_stopped_because(pid, state));
    ++stopped;
    stopped_ids.insert(name.substr(std::string("supervisor-").size(), name.size() - std::string("supervisor-").size() - 4));
    std::cout << "down: stopped supervisor " << pid << " (" << name << ")\n";
  }
  if (ec) fail(state.string() + ": " + ec.message());
  // What programs of a supervisor killed with SIGKILL started lives on (agents::kill_leftovers);
  // a node no supervisor holds now has nothing that should run.
  int leftovers = 0;
  for (const auto& entry : fs::directory_iterator(state, ec)) {
    if (only && entry.path().filename() != *only) continue;
    if (!fs::exists(entry.path() / "data.mdb") || store_being_made(entry.path())) continue;
    const fs::path store = fs::absolute(entry.path());
    // A supervisor still holding the store had no pid file (deleted): stopped as the others.
    if (const pid_t holder = supervisor_of_store(store); holder > 0) {
      kill(holder, SIGTERM);
      kill(holder, SIGCONT);
      const auto deadline = std::chrono::steady_clock::now() + 20s;
      while (supervisor_of_store(store) != 0 && std::chrono::steady_clock::now() < deadline) std::this_thread::sleep_for(50ms);
      if (supervisor_of_store(store) != 0) fail(not_stopped_because(holder, state));
      ++stopped;
      stopped_ids.insert(entry.path().filename().string());
      std::cout << "down: stopped supervisor " << holder << " (it ran node '" << entry.path().filename().string()
                << "' without a pid file)\n";
    }
    const int fd = ::open(store.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
    if (fd < 0) continue;
    if (flock(fd, LOCK_EX | LOCK_NB) == 0) {
      const std::string id = entry.path().filename().string();
      // A supervisor this down stopped ended its programs' process groups: what is left was
      // started apart from them (setsid, a double fork), not left by a supervisor killed.
      const bool stopped_now = stopped_ids.count(id) > 0 || stopped_ids.count("all") > 0;
      for (const auto& killed : agents::kill_leftovers(store.string())) {
        std::cout << "down: killed " << killed << ", left running by a program of node '" << id << "' "
                  << (stopped_now ? "outside its process group (setsid or a double fork: its supervisor, stopped, did not reach it)"
                                  : "when its supervisor was killed")
                  << "\n";
        ++leftovers;
      }
    }
    ::close(fd);
  }
  if (stopped == 0 && leftovers == 0) {
    // With --node, the others under the state directory may run: "nothing" said they did not.
    if (only) std::cout << "down: node '" << *only << "' was not running under " << state.string() << "\n";
    else std::cout << "down: nothing was running under " << state.string() << "\n";
  }
  return kExitOk;
}

const Command kStatusCommand{
    "status",
    "[--state DIR] [--json] [--local] [--timeout S]",
    "Print the tree of nodes and agents of a deployment.",
    "For each node store under DIR: its IRI; the state its parent keeps of it (link up/down,\n"
    "last seen, outbox depth, software version); and the programs the supervisor runs for it\n"
    "(pid, restarts, last exit). A child on another machine is asked, through the running link,\n"
    "for its programs and its own children's states, and so on down the tree (unless --local).\n"
    "--json prints the same as one JSON object (docs/cli.md).",
    {kFlagState, {"--json", "", "", "print one JSON object instead of the tree"},
     {"--local", "", "", "only what this machine's stores hold: ask no node on another machine"},
     {"--timeout", "", "S", "how long to wait for each node on another machine (default 3; a fraction allowed)"}},
    0, 0, false};

namespace {

// A link rewrites the state it keeps of a connected child, and its own uplink's, at least every
// 2-3 s, with the time it last heard the other end (heartbeats every second): an "up" older than
// this was not rewritten (the link is stopped, frozen or cannot write).
constexpr double kStateStaleAfterS = 6.0;
// A supervisor rewrites a node's programs on its board every agents::kProgramsRefresh (5 s).
constexpr double kProgramsStaleAfterS = 15.0;

using Fields = std::map<std::string, std::string>;  // by the local name of each predicate
// The field of a link state that holds when it was read here (ns since the epoch), no
// predicate's local name: its age is judged as of then. `status` asks the nodes on other
// machines level by level, for seconds, and a state read before that and judged after it was
// called "not refreshed" of a child that is up.
constexpr const char* kReadAtField = "@read_ns";

// What a program says on its board it cannot do (node::kProblem), and its process.
struct Problem {
  std::string text, pid;
};

// One node of the tree `status` prints: a store under DIR, or a node on another machine known
// from the state its parent keeps of it (a store here, or a node on another machine asked).
struct StatusNode {
  std::string id, iri;
  bool remote = false;
  Fields link;    // its parent's view (P12), when known
  Fields uplink;  // its own view of its uplink (P12a), local nodes
  std::vector<ProgramRow> programs;  // named as on the node ("link", "hrv")
  // A node on another machine: why its programs or its children are not known (empty: they
  // are), and when its supervisor last wrote its programs on its board.
  std::string programs_unknown_because, children_unknown_because;
  std::int64_t programs_at = 0, programs_read_ns = 0;  // as for RemoteBoard
  bool programs_current = true;  // a remote node's: read now, and rewritten recently
  std::string store_warning;     // a local store near its maximum, or its disk near full
  std::string moved_from;        // a store under another id: the node whose store was moved here
  // A local store with a forwarding policy (`up` subscribes its uplink only on a node with a
  // parent): without an uplink state it is a child whose link has not run, not a root.
  bool has_parent = false;
  // Problems the node's programs report on its board (node::kProblem), by agent IRI.
  std::map<std::string, Problem> problems;
  // Input buffers of agents nothing on a local node knows (board_knows_agent, and no program of
  // its runs as them): items addressed to a home not deployed, or to a typo, wait there for ever.
  std::vector<node::InputBufferSummary> waiting_for_unknown;
  // A local store with a parent: the items its uplink's outbox holds (its input buffer), read
  // here. Its parent's state says the depth of its last heartbeat, and its own link, stopped or
  // killed, no longer rewrites its own.
  std::optional<std::uint64_t> outbox_here;
};

// The problems on a board: records of node::kProblem and node::kProblemPid that an agent of
// `node_iri` wrote about itself, into `problems` by agent IRI.
void read_problems(const std::vector<node::Record>& records, const std::string& node_iri,
                   std::map<std::string, Problem>& problems) {
  for (const node::Record& r : records) {
    if (r.triple.s.value != r.meta.source || !uri::is_under(r.meta.source, node_iri)) continue;
    if (r.triple.p.value == node::kProblem) problems[r.meta.source].text = r.triple.o.value;
    else if (r.triple.p.value == node::kProblemPid) problems[r.meta.source].pid = r.triple.o.value;
  }
}

// Each program's problem, from those of its node: the program whose agent IRI wrote it, or else
// the one whose process did (an agent whose IRI is not its program's: `reason --agent`).
void attach_problems(std::vector<ProgramRow>& programs, const std::string& node_iri,
                     const std::map<std::string, Problem>& problems) {
  for (const auto& [agent, problem] : problems) {
    if (problem.text.empty()) continue;
    ProgramRow* to = nullptr;
    for (ProgramRow& p : programs) {
      if (auto iri = uri::agent_iri(node_iri, p.name); iri && *iri == agent) to = &p;
      else if (!to && !problem.pid.empty() && p.pid == problem.pid) to = &p;
    }
    if (to) {
      to->problem = problem.text;
      to->problem_pid = problem.pid;
    }
  }
}

// store_room_warning of a store here.
std::string store_warning(const node::Node& node, const fs::path& dir) {
  std::optional<std::uint64_t> disk_free;
  if (struct statvfs disk {}; statvfs(dir.c_str(), &disk) == 0)
    disk_free = static_cast<std::uint64_t>(disk.f_bavail) * disk.f_frsize;
  auto st = node.stats();
  return st ? store_room_warning(st->high_water_bytes, st->used_bytes, st->max_map_bytes, disk_free)
            : store_room_warning(0, 0, 0, disk_free);
}

// The fields of each item with a triple of `predicate`, by the item's subject.
void read_state_items(const node::Snapshot& snap, const std::string& predicate, std::map<std::string, Fields>& by_subject) {
  auto records = snap.list({.p = node::Term::iri(predicate)});
  if (!records) return;
  for (const auto& r : *records) {
    auto item = snap.item(r.meta.item);
    if (!item) continue;
    Fields* fields = nullptr;
    for (const auto& f : *item) {
      fields = &by_subject[f.triple.s.value];
      (*fields)[f.triple.p.value.substr(f.triple.p.value.find('#') + 1)] = f.triple.o.value;
    }
    if (fields) (*fields)[kReadAtField] = std::to_string(unix_now_ns());
  }
}

// What the board of `target`, a node on another machine, says of its children (P12, written by
// its link) and of its programs (written by its supervisor), read with remote queries through
// `from`, the store here above it, and its running link, before `deadline`. Each part that
// could not be read says why; the children then stay unknown (and are not asked in turn).
struct RemoteBoard {
  std::map<std::string, Fields> children;  // by child IRI
  std::vector<ProgramRow> programs;
  std::int64_t programs_at = 0, programs_read_ns = 0;  // when written there, when read here
  std::string children_error, programs_error;
};

RemoteBoard ask_board(node::Node& from, const std::string& target, std::chrono::steady_clock::time_point deadline,
                      std::chrono::milliseconds budget) {
  RemoteBoard board;
  auto link = uri::agent_iri(target, "link"), supervisor = uri::agent_iri(target, "supervisor");
  if (!link || !supervisor) {
    board.children_error = board.programs_error = "<" + target + "> cannot have agents: " + (link ? supervisor : link).error().message;
    return board;
  }
  // Asks for every record of predicate `p` (about `subject` when given) that `writer` wrote
  // (empty: that its subject wrote about itself).
  // A query's pattern names no source, and a state item has no one triple that leads to the
  // rest, so each field is asked for by its predicate.
  // As --timeout gave it: "0.001" was said as "within 0.0 s".
  const std::string no_answer =
      "no answer within " + (budget < std::chrono::seconds(1) ? std::to_string(budget.count()) + " ms"
                                                             : seconds_text(static_cast<double>(budget.count()) / 1e3));
  auto ask = [&](const std::string& p, const std::string& subject, const std::string& writer,
                 const std::function<void(const node::Record&)>& each) -> std::string {
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
    if (left.count() <= 0) return no_answer;
    node::Pattern pattern{.p = node::Term::iri(p)};
    if (!subject.empty()) pattern.s = node::Term::iri(subject);
    // A node whose link restarts is shown as it is now, not waited for: status asks many nodes.
    auto answered = federation::remote_query(from, {.target = target, .pattern = std::move(pattern), .restart_grace = {}}, left, [&](const node::Record& r) {
      if (r.meta.source == (writer.empty() ? r.triple.s.value : writer)) each(r);
    });
    if (answered) return {};
    if (answered.error().code == node::Errc::timeout) return no_answer;
    return answered.error().message;
  };
  auto local_name = [](const std::string& iri) { return iri.substr(iri.find('#') + 1); };
  for (const std::string& p : {federation::vocab::kLinkState, federation::vocab::kParent, federation::vocab::kLastSeen,
                               federation::vocab::kOutboxDepth, federation::vocab::kSoftwareVersion, federation::vocab::kLinkConflict,
                               federation::vocab::kLinkLeft}) {
    board.children_error = ask(p, "", *link, [&](const node::Record& r) {
      if (r.triple.s.value == target) return;
      Fields& fields = board.children[r.triple.s.value];
      fields[local_name(p)] = r.triple.o.value;
      if (p == federation::vocab::kLastSeen) fields[kReadAtField] = std::to_string(unix_now_ns());
    });
    if (!board.children_error.empty()) break;
  }
  if (!board.children_error.empty()) board.children.clear();
  // The figures of the children's stores (P12, version 5) last, and without them the children
  // are still shown: they only add a STORE line.
  if (!board.children.empty())
    for (const std::string& p : {federation::vocab::kStoreUsedBytes, federation::vocab::kStoreDataBytes,
                                 federation::vocab::kStoreMaxBytes, federation::vocab::kDiskFreeBytes}) {
      const std::string failed = ask(p, "", *link, [&](const node::Record& r) {
        if (auto child = board.children.find(r.triple.s.value); child != board.children.end()) child->second[local_name(p)] = r.triple.o.value;
      });
      if (!failed.empty()) break;
    }
  std::erase_if(board.children, [](const auto& c) { return !c.second.count("linkState"); });

  std::vector<std::pair<std::string, Fields>> programs;  // by program IRI, in the supervisor's order
  board.programs_error = ask(agents::vocab::kProgram, target, *supervisor,
                             [&](const node::Record& r) { programs.emplace_back(r.triple.o.value, Fields{}); });
  for (const std::string& p : {agents::vocab::kProgramState, agents::vocab::kPid, agents::vocab::kRestarts, agents::vocab::kLastExit}) {
    if (!board.programs_error.empty()) break;
    board.programs_error = ask(p, "", *supervisor, [&](const node::Record& r) {
      for (auto& [iri, fields] : programs)
        if (iri == r.triple.s.value) fields[local_name(p)] = r.triple.o.value;
    });
  }
  if (board.programs_error.empty())
    board.programs_error = ask(agents::vocab::kProgramsAt, target, *supervisor, [&](const node::Record& r) {
      if (auto at = parse_u64(r.triple.o.value)) board.programs_at = static_cast<std::int64_t>(*at);
      board.programs_read_ns = unix_now_ns();
    });
  if (!board.programs_error.empty()) return board;
  std::vector<node::Record> problem_records;
  // A node whose programs were read but not their problems is shown without them.
  for (const std::string& p : {node::kProblem, node::kProblemPid})
    (void)ask(p, "", "", [&](const node::Record& r) { problem_records.push_back(r); });
  std::map<std::string, Problem> problems;
  read_problems(problem_records, target, problems);
  for (auto& [iri, f] : programs) {
    auto name = program_name(iri, target);
    if (!name) continue;
    board.programs.push_back({*name, f["pid"], f["programState"], f["restarts"].empty() ? "0" : f["restarts"], f["lastExit"]});
  }
  attach_problems(board.programs, target, problems);
  return board;
}

// Why a state a link wrote cannot be believed now, or empty: the link that writes it
// (`writer`, the program "link" of `keeper` when known) is not running (a stopped hospital left
// every home "up"), or an "up" has not been rewritten.
std::string unbelieved_because(const StatusNode* keeper, const std::string& writer, const std::string& state,
                               std::int64_t heard_ns, std::int64_t read_ns) {
  const auto seconds_since = [read_ns](std::int64_t unix_ns) { return cli::seconds_since(unix_ns, read_ns); };
  if (keeper && keeper->programs_current)
    for (const auto& p : keeper->programs) {
      if (p.name != "link" || p.state == "running") continue;
      // "unknown": only its supervisor is late (frozen, stopped). An "up" the link refreshed
      // within kStateStaleAfterS is its own word that it runs, as the machine above sees it.
      if (p.state.starts_with("unknown") && state == "up" && seconds_since(heard_ns) <= kStateStaleAfterS) continue;
      return writer + " is " + p.state;
    }
  if (state == "up" && seconds_since(heard_ns) > kStateStaleAfterS)
    return writer + " has not refreshed it for " + seconds_text(seconds_since(heard_ns));
  return {};
}

// The ids of the nodes the supervisor of the whole file runs, or ran until `down` (its .nodes
// file), or nothing when it does not say (one from before .nodes files) or a supervisor of one
// node (`up --node`) runs here now: the state is then a machine's share of a deployment, which
// an older whole-file list does not describe. A node of a store under `state` that is not in
// the list was taken out of the file (a node brought up alone cannot be: that `up` would not
// find it).
std::optional<std::set<std::string>> nodes_supervised(const fs::path& state) {
  const fs::path whole = state / pid_file_name(std::nullopt);
  if (supervisor_holding(whole) == 0) {
    // Supervisors of one node each (`up --node`): the nodes of the files they run. A store of a
    // node none of those files has is one taken out of the file.
    std::optional<std::set<std::string>> in_files;
    std::error_code ec;
    for (const auto& entry : fs::directory_iterator(state, ec)) {
      const std::string name = entry.path().filename().string();
      if (!name.starts_with("supervisor-") || !name.ends_with(".pid") || supervisor_holding(entry.path()) == 0) continue;
      std::ifstream in(fs::path(entry.path()).replace_extension(".file-nodes"));
      if (!in) return std::nullopt;  // a supervisor of an earlier build, which did not say
      if (!in_files) in_files.emplace();
      for (std::string id; std::getline(in, id);) in_files->insert(id);
    }
    if (in_files) return in_files;
  }
  std::ifstream in(fs::path(whole).replace_extension(".nodes"));
  if (!in) return std::nullopt;
  std::set<std::string> ids;
  for (std::string id; std::getline(in, id);) ids.insert(id);
  return ids;
}

// A program with a process: running, or suspended ("suspended" on a board; with why and what
// to do in a state file).
bool alive(const ProgramRow& p) { return p.state == "running" || p.state.starts_with("suspended"); }

void print_json_string_or_null(const std::string& text) {
  if (text.empty()) std::cout << "null";
  else std::cout << "\"" << node::json_escape(text) << "\"";
}

// One side's view of a link in `status --json`: the parent's of a child (P12) or the child's
// own (P12a), which differ in their time (`time_key`) and last field (`extra_key`).
void print_link_json(const std::string& parent, const std::string& state, const std::string& unknown_because,
                     std::string_view time_key, std::int64_t time_ns, const std::string& outbox, std::string_view extra_key,
                     const std::string& extra, const std::string& conflict, bool left = false, const Fields* room_of = nullptr) {
  std::cout << "{\"parent\":\"" << node::json_escape(parent) << "\",\"state\":\"" << node::json_escape(state)
            << "\",\"known\":" << (unknown_because.empty() ? "true" : "false") << ",\"unknown_because\":";
  print_json_string_or_null(unknown_because);
  std::cout << ",\"" << time_key << "\":" << (time_ns > 0 ? std::to_string(time_ns) : "null")
            << ",\"outbox_depth\":" << (parse_u64(outbox) ? outbox : "null") << ",\"" << extra_key << "\":";
  print_json_string_or_null(extra);
  std::cout << ",\"conflict\":";
  print_json_string_or_null(conflict);
  // Down because its link said it was stopping (P12c), not because it went silent.
  std::cout << ",\"left\":" << (left ? "true" : "false");
  // The child's store as its last hello or heartbeat said (P12; null from a link before
  // protocol version 5).
  if (room_of) {
    std::cout << ",\"store\":";
    const auto field = [&](const char* name) -> std::optional<std::uint64_t> {
      auto it = room_of->find(name);
      return it == room_of->end() ? std::nullopt : parse_u64(it->second);
    };
    const auto used = field("storeUsedBytes"), data = field("storeDataBytes"), max = field("storeMaxBytes"), disk = field("diskFreeBytes");
    if (used && data && max)
      std::cout << "{\"used_bytes\":" << *used << ",\"data_bytes\":" << *data << ",\"max_bytes\":" << *max
                << ",\"disk_free_bytes\":" << (disk ? std::to_string(*disk) : "null") << "}";
    else
      std::cout << "null";
  }
  std::cout << "}";
}

}  // namespace

int run_status(const Args& args) {
  fs::path state = state_dir(args);
  if (std::error_code ec; !fs::is_directory(state, ec))
    fail("no directory " + state.string() + " (did 'tahvel up' run with this --state?)");
  const std::chrono::milliseconds ask_budget = seconds_flag(args, "status", std::chrono::seconds(3), std::chrono::seconds(60));
  std::vector<StatusNode> nodes;
  std::map<std::string, Fields> child_state, own_state;  // by node IRI
  std::map<std::string, fs::path> store_of;               // the stores here, by node IRI
  std::string unfinished;                                 // stores an interrupted first `up` left
  std::map<std::string, std::string> unopened;            // why, by the store's directory name
  std::error_code ec;
  // Copies of a node's store kept beside it (`tahvel backup state/hospital
  // state/hospital-2026-12-06`): the same IRI as the node's, so shown as a node they took its
  // children, or hid them, with stale states. The node's is the one of the deployment, else
  // the one a supervisor holds, else the one named as its IRI ends; the others are copies.
  const std::optional<std::set<std::string>> supervised = nodes_supervised(state);
  std::map<std::string, std::vector<std::string>> dirs_of_iri;
  for (const auto& entry : fs::directory_iterator(state, ec)) {
    if (!entry.is_directory() || !fs::exists(entry.path() / "data.mdb") || store_being_made(entry.path())) continue;
    if (auto node = node::Node::open(entry.path())) dirs_of_iri[node->iri()].push_back(entry.path().filename().string());
  }
  ec.clear();
  std::map<std::string, std::string> copy_of;  // directory name -> the node's
  for (const auto& [iri, dirs] : dirs_of_iri) {
    if (dirs.size() < 2) continue;
    const std::string ends_as = iri.substr(iri.rfind('/') + 1);
    const auto rank = [&](const std::string& dir) {
      return (supervised && supervised->count(dir) ? 4 : 0) + (supervisor_of_store(state / dir) != 0 ? 2 : 0) + (dir == ends_as ? 1 : 0);
    };
    const std::string node_dir = *std::max_element(dirs.begin(), dirs.end(), [&](const auto& a, const auto& b) { return rank(a) < rank(b); });
    if (std::count_if(dirs.begin(), dirs.end(), [&](const std::string& d) { return rank(d) == rank(node_dir); }) > 1) continue;
    for (const std::string& dir : dirs)
      if (dir != node_dir) copy_of[dir] = node_dir;
  }
  for (const auto& entry : fs::directory_iterator(state, ec)) {
    if (!entry.is_directory() || !fs::exists(entry.path() / "data.mdb")) continue;
    // Not a node, though it holds one's IRI: shown as one, it doubled the node in the tree.
    if (store_being_made(entry.path())) {
      unfinished += (unfinished.empty() ? "" : ", ") + entry.path().filename().string();
      continue;
    }
    if (const auto copy = copy_of.find(entry.path().filename().string()); copy != copy_of.end()) {
      std::cerr << "status: " << entry.path().string() << " holds a copy of the store of node '" << copy->second
                << "' (its IRI), not shown: keep copies outside " << state.string() << "\n";
      continue;
    }
    auto node = node::Node::open(entry.path());
    if (!node) {  // shown in the tree as the node's, below, not as a node on another machine
      unopened[entry.path().filename().string()] = node.error().message;
      continue;
    }
    nodes.push_back({.id = entry.path().filename().string(), .iri = node->iri()});
    nodes.back().store_warning = store_warning(*node, entry.path());
    store_of[node->iri()] = entry.path();
    auto snap = node->snapshot();
    if (!snap) continue;
    read_state_items(*snap, federation::vocab::kLinkState, child_state);
    std::map<std::string, Fields> own;
    read_state_items(*snap, federation::vocab::kUplinkState, own);
    if (auto it = own.find(node->iri()); it != own.end()) own_state[node->iri()] = it->second;
    auto policy = snap->count({.p = node::Term::iri(std::string(federation::vocab::kTv) + "subscriber"),
                               .o = node::Term::iri(node->iri() + "/uplink")});
    auto parent = snap->count({.s = node::Term::iri(node->iri()), .p = node::Term::iri(federation::vocab::kParent),
                               .source = node->iri() + "/uplink"});
    nodes.back().has_parent = (policy && *policy > 0) || (parent && *parent > 0);
    for (const std::string& p : {node::kProblem, node::kProblemPid})
      if (auto records = snap->list({.p = node::Term::iri(p)})) read_problems(*records, node->iri(), nodes.back().problems);
    if (nodes.back().has_parent) nodes.back().outbox_here = 0;
    if (auto buffers = snap->input_buffers())
      for (node::InputBufferSummary& buffer : *buffers) {
        if (nodes.back().has_parent && buffer.agent == node->iri() + "/uplink") nodes.back().outbox_here = buffer.waiting;
        if (!board_knows_agent(*snap, buffer.agent)) nodes.back().waiting_for_unknown.push_back(std::move(buffer));
      }
  }
  if (ec) fail(state.string() + ": " + ec.message());
  if (nodes.empty() && unopened.empty())
    fail("no node stores under " + state.string() +
         (unfinished.empty() ? " (did 'tahvel up' run with this --state?)"
                             : " (only " + unfinished + ", left unfinished by an interrupted 'tahvel up': the next 'up' makes it anew)"));
  // A user who may open none of the stores (a monitoring account) got every node as "<>", none
  // under its parent, and status 0: refused, naming whose the stores are.
  if (nodes.empty() && std::all_of(unopened.begin(), unopened.end(), [](const auto& u) { return u.second.find("Permission denied") != std::string::npos; })) {
    struct stat owner {};
    const fs::path first = state / unopened.begin()->first;
    const bool known = ::stat(first.c_str(), &owner) == 0;
    fail(user_name(::geteuid()) + " may open none of the node stores under " + state.string() + " (" +
         unopened.begin()->second + ")" +
         (known && owner.st_uid != ::geteuid() ? "; they are " + user_name(owner.st_uid) + "'s: 'sudo -u " + sudo_user(owner.st_uid) +
                                                      " tahvel status --state " + shell_word(state) + "'"
                                                : std::string()));
  }
  auto find = [&](const std::string& iri) -> StatusNode* {
    for (StatusNode& n : nodes)
      if (n.iri == iri) return &n;
    return nullptr;
  };
  auto local_id = [&](const std::string& iri) -> std::string {
    const StatusNode* n = find(iri);
    return n && !n->remote ? n->id : std::string();
  };
  // A child whose store is elsewhere is still part of the tree this machine knows of.
  auto add_remote = [&](const std::string& iri, const Fields& fields) {
    auto parent = fields.find("parent");
    std::string id = iri;
    if (parent != fields.end())
      if (auto child = uri::child_id(iri, parent->second)) id = *child;
    nodes.push_back({.id = id, .iri = iri, .remote = true, .link = fields});
  };
  // A node this machine runs whose store is gone (deleted while its programs run): shown here,
  // with its programs failing and why, not as a node on another machine with nothing known.
  const std::vector<ProgramRow> program_rows = read_state_files(state);
  std::set<std::string> storeless;
  for (const ProgramRow& p : program_rows) {
    const auto slash = p.name.find('/');
    if (slash == std::string::npos || p.state == "stopped") continue;
    const std::string id = p.name.substr(0, slash);
    if (std::none_of(nodes.begin(), nodes.end(), [&](const StatusNode& n) { return n.id == id; })) storeless.insert(id);
  }
  // Nodes a running supervisor stopped as their store went (drop_nodes): this machine's, and
  // still the deployment's, though no program of theirs runs.
  std::map<std::string, std::string> gone;  // IRI, by node id
  for (const auto& entry : fs::directory_iterator(state, ec)) {
    const std::string name = entry.path().filename().string();
    if (!name.starts_with("supervisor-") || !name.ends_with(".pid") || supervisor_holding(entry.path()) == 0) continue;
    std::ifstream in(gone_list_file(entry.path()));
    for (std::string line; std::getline(in, line);)
      if (const auto tab = line.find('\t'); tab != std::string::npos && tab > 0) gone[line.substr(0, tab)] = line.substr(tab + 1);
  }
  ec.clear();
  for (const auto& [id, iri] : gone) storeless.erase(id);
  auto iri_from_parent = [&](const std::string& id) {  // from its parent's state of it, when that store is here
    std::string iri;
    for (const auto& [child_iri, fields] : child_state) {
      auto parent = fields.find("parent");
      if (parent == fields.end() || local_id(parent->second).empty()) continue;
      if (auto child = uri::child_id(child_iri, parent->second); child && *child == id) iri = child_iri;
    }
    return iri;
  };
  for (const std::string& id : storeless) {
    if (unopened.count(id)) continue;  // there, and cannot be opened: said below
    nodes.push_back({.id = id, .iri = iri_from_parent(id)});
    nodes.back().store_warning = "its store " + (state / id).string() +
                                 " is missing (deleted while the node runs?): its programs fail until 'tahvel down' and "
                                 "'tahvel up' make it again";
  }
  for (const auto& [id, iri] : gone) {
    if (unopened.count(id) || std::any_of(nodes.begin(), nodes.end(), [&](const StatusNode& n) { return n.id == id; })) continue;
    StatusNode node{.id = id, .iri = iri.empty() ? iri_from_parent(id) : iri};
    // Moved within the state directory (a copy kept as state/home1.bak): 'up' refuses to make a
    // new store beside another of the node's IRI, so "up makes it again" was no way out.
    auto moved = std::find_if(nodes.begin(), nodes.end(), [&](const StatusNode& n) {
      return !n.remote && !node.iri.empty() && n.iri == node.iri && n.id != id;
    });
    if (moved != nodes.end()) {
      node.store_warning = "its store " + (state / id).string() + " was moved to " + (state / moved->id).string() +
                           " while the node ran: its supervisor stopped its programs; move it back and 'tahvel up' "
                           "the file again to go on with its data, or move it out of " + state.string() +
                           " for 'tahvel up' to make the node a new store";
      moved->moved_from = id;
    } else {
      node.store_warning = "its store " + (state / id).string() +
                           " was removed or moved while the node ran: its supervisor stopped its programs, and "
                           "'tahvel up' of the file makes the store again and starts the node anew";
    }
    nodes.push_back(std::move(node));
  }
  // A store here that cannot be opened (damaged, cut short, on a read-only disk): the node is
  // this machine's, with its programs, not "on another machine" by its parent's state of it.
  for (const auto& [id, why] : unopened) {
    nodes.push_back({.id = id, .iri = iri_from_parent(id)});
    nodes.back().store_warning = "its store " + (state / id).string() + " cannot be opened: " + why;
  }
  for (const auto& [iri, fields] : child_state)
    if (!find(iri)) add_remote(iri, fields);
  for (StatusNode& n : nodes) {
    if (auto it = child_state.find(n.iri); it != child_state.end()) n.link = it->second;
    if (auto it = own_state.find(n.iri); it != own_state.end() && !n.remote) n.uplink = it->second;
  }
  for (ProgramRow p : program_rows) {
    const auto slash = p.name.find('/');
    if (slash == std::string::npos) continue;
    for (StatusNode& n : nodes)
      if (!n.remote && n.id == p.name.substr(0, slash)) {
        n.programs.push_back(p);
        n.programs.back().name.erase(0, slash + 1);
      }
  }
  for (StatusNode& n : nodes) {
    if (n.remote) continue;
    attach_problems(n.programs, n.iri, n.problems);
    // A program that runs as the agent takes what waits for it (it has not subscribed yet).
    std::erase_if(n.waiting_for_unknown, [&](const node::InputBufferSummary& buffer) {
      return std::any_of(n.programs.begin(), n.programs.end(),
                         [&](const ProgramRow& p) {
                           auto iri = uri::agent_iri(n.iri, p.name);
                           return iri && *iri == buffer.agent;
                         });
    });
  }
  const std::optional<std::set<std::string>>& deployed = supervised;
  auto in_deployment = [&](const std::string& id) { return !deployed || deployed->count(id) > 0 || gone.count(id) > 0; };
  // What a store left behind by a node taken out of the file kept of its children is not news.
  std::erase_if(nodes, [&](const StatusNode& n) {
    if (!n.remote) return false;
    auto parent = n.link.find("parent");
    const std::string keeper = parent == n.link.end() ? std::string() : local_id(parent->second);
    return !keeper.empty() && !in_deployment(keeper);
  });
  // The nodes on other machines, asked through the store here above them (and its link), from
  // the top down: each one's children are asked in turn.
  if (args.has("--local")) {
    for (StatusNode& n : nodes)
      if (n.remote) n.programs_unknown_because = n.children_unknown_because = "not asked (--local)";
  } else {
    // The deepest store here above `target`, whose link the questions go through.
    auto via_of = [&](const std::string& target) {
      std::string via;
      for (const auto& [iri, dir] : store_of)
        if (uri::is_under(target, iri) && iri.size() > via.size()) via = iri;
      return via;
    };
    // One level of the tree at a time, its nodes asked side by side (a hospital with hundreds
    // of homes); each thread opens its own handles on the stores (node.h: one thread per Node).
    std::vector<std::size_t> level;
    for (std::size_t i = 0; i < nodes.size(); ++i)
      if (nodes[i].remote) level.push_back(i);
    while (!level.empty()) {
      // Every node of a level answers within one --timeout: a level of many silent nodes costs
      // that once, not once per node.
      const auto deadline = std::chrono::steady_clock::now() + ask_budget;
      std::vector<RemoteBoard> boards(level.size());
      std::atomic<std::size_t> next{0};
      auto ask_some = [&] {
        std::map<std::string, node::Node> opened;
        for (std::size_t k; (k = next++) < level.size();) {
          RemoteBoard& board = boards[k];
          auto cannot = [&](const std::string& why) { board.children_error = board.programs_error = why; };
          const std::string& target = nodes[level[k]].iri;
          const std::string via = via_of(target);
          if (via.empty()) {
            cannot("no store here is above it");
            continue;
          }
          try {
            if (!opened.count(via)) {
              auto node = node::Node::open(store_of.at(via));
              if (!node) {
                cannot(node.error().message);
                continue;
              }
              opened.emplace(via, std::move(*node));
            }
            board = ask_board(opened.at(via), target, deadline, ask_budget);
          } catch (const std::exception& e) {  // a thread must not end the process
            cannot(e.what());
          }
        }
      };
      std::vector<std::thread> askers;
      for (std::size_t t = 0; t < std::min<std::size_t>(level.size(), 16); ++t) askers.emplace_back(ask_some);
      for (auto& t : askers) t.join();
      std::vector<std::size_t> below;
      for (std::size_t k = 0; k < level.size(); ++k) {
        StatusNode& n = nodes[level[k]];
        RemoteBoard& board = boards[k];
        n.programs_unknown_because = board.programs_error;
        n.children_unknown_because = board.children_error;
        n.programs = std::move(board.programs);
        n.programs_at = board.programs_at;
        n.programs_read_ns = board.programs_read_ns;
        const std::string target = n.iri;  // `nodes` grows below: no reference into it past here
        for (auto& [iri, fields] : board.children) {
          if (find(iri) || !uri::is_under(iri, target)) continue;
          add_remote(iri, fields);
          below.push_back(nodes.size() - 1);
        }
      }
      level = std::move(below);
    }
  }
  // A store on another machine is known here only by what it said of its room to its parent.
  for (StatusNode& n : nodes)
    if (n.remote && n.store_warning.empty()) {
      auto read = n.link.find(kReadAtField);
      n.store_warning = store_warning_from_state(n.link, read == n.link.end() ? 0 : static_cast<std::int64_t>(parse_u64(read->second).value_or(0)));
    }
  // A remote node's programs are what its supervisor last wrote on its board: believed when
  // rewritten within kProgramsStaleAfterS of when they were read here (by the clock of that
  // machine: the machines' clocks are taken to agree, as the link's times are, and a clock
  // found more than that ahead is said).
  for (StatusNode& n : nodes) {
    if (!n.remote) continue;
    if (n.programs_unknown_because.empty() && n.programs_at == 0)
      n.programs_unknown_because = "its board has none (no supervisor writes them there)";
    else if (n.programs_unknown_because.empty() && seconds_since(n.programs_at, n.programs_read_ns) > kProgramsStaleAfterS)
      n.programs_unknown_because =
          "its supervisor has not refreshed them for " + seconds_text(seconds_since(n.programs_at, n.programs_read_ns));
    // Written "later" than they were read: that machine's clock is ahead, and however long ago
    // its supervisor stopped, they would look fresh (a sensor without NTP showed a frozen
    // supervisor's programs as running for as long as its clock was ahead).
    else if (n.programs_unknown_because.empty() && -seconds_since(n.programs_at, n.programs_read_ns) > kProgramsStaleAfterS)
      n.programs_unknown_because = "its clock is " + seconds_text(-seconds_since(n.programs_at, n.programs_read_ns)) +
                                   " ahead of this machine's (its supervisor's last write is dated " + node::utc_text(n.programs_at) +
                                   "), so how old they are cannot be told; set its clock (NTP)";
    n.programs_current = n.programs_unknown_because.empty();
  }
  // Depth first: each node right after its parent and before the parent's next sibling. '/'
  // sorts before every other character here, as in plain order "home1-annex" and "home1.0"
  // came between "home1" and "home1/bed-a".
  std::sort(nodes.begin(), nodes.end(), [](const StatusNode& a, const StatusNode& b) {
    auto rank = [](char c) { return c == '/' ? -1 : static_cast<int>(static_cast<unsigned char>(c)); };
    return std::lexicographical_compare(a.iri.begin(), a.iri.end(), b.iri.begin(), b.iri.end(),
                                        [&](char x, char y) { return rank(x) < rank(y); });
  });
  const bool json = args.has("--json");
  if (json) std::cout << "{\"state\":\"" << node::json_escape(state.string()) << "\",\"nodes\":[";
  bool first_node = true;
  for (StatusNode& n : nodes) {
    const bool left = !n.remote && !in_deployment(n.id);
    if (left) {  // what its links last wrote is no longer news
      n.link.clear();
      n.uplink.clear();
    }
    int depth = 0;
    const StatusNode* parent = nullptr;  // the nearest node above it here
    for (const StatusNode& other : nodes)
      if (other.iri != n.iri && uri::is_under(n.iri, other.iri)) {
        ++depth;
        if (!parent || other.iri.size() > parent->iri.size()) parent = &other;
      }
    // What the parent keeps of this node's link (written by the parent's link: shown as that
    // program's name when the parent is here), and whether it can be believed.
    std::string said, unknown_because;
    std::int64_t seen = 0;
    if (!n.link.empty()) {
      auto& f = n.link;
      if (auto p = parse_u64(f["lastSeen"])) seen = static_cast<std::int64_t>(*p);
      const StatusNode* keeper = find(f["parent"]);
      const std::string writer = keeper && !keeper->remote ? keeper->id + "/link"
                                 : keeper                  ? "the link of <" + keeper->iri + ">"
                                                           : "the parent's link";
      const std::int64_t read_ns = static_cast<std::int64_t>(parse_u64(f[kReadAtField]).value_or(0));
      said = "link " + f["linkState"] + (f["linkState"] == "down" && f["linkLeft"] == "true" ? " (its link was stopped: it said so as it left)" : "") +
             ", last seen " + age_of(seen, read_ns) + ", outbox " + f["outboxDepth"];
      if (!f["softwareVersion"].empty()) said += ", " + f["softwareVersion"];
      if (!f["linkConflict"].empty()) said += "; CONFLICT: " + f["linkConflict"];
      unknown_because = unbelieved_because(keeper, writer, f["linkState"], seen, read_ns);
      // Asked after the state was read, the parent's link answered that the node is down: it
      // heard so before writing it (a link that said it was leaving, within 0.1 s), and "link
      // up" beside "unreachable: … is down" was two answers to one question.
      const std::string& asked = n.programs_unknown_because;
      if (unknown_because.empty() && f["linkState"] == "up" && n.remote &&
          (asked.find("<" + n.iri + "> is down at <") != std::string::npos || asked.find("<" + n.iri + "> went silent at <") != std::string::npos))
        unknown_because = writer + " has since answered that it is not up";
    }
    // This node's own view of its uplink, shown when its parent is not here to say more.
    std::string uplink_said, uplink_unknown_because;
    std::int64_t heard = 0;
    if (!n.uplink.empty()) {
      auto& f = n.uplink;
      if (auto p = parse_u64(f["parentLastHeard"])) heard = static_cast<std::int64_t>(*p);
      uplink_said = "uplink to <" + f["parent"] + "> " + f["uplinkState"];
      if (!f["uplinkRefusal"].empty()) uplink_said += " (" + f["uplinkRefusal"] + ")";
      const std::int64_t read_ns = static_cast<std::int64_t>(parse_u64(f[kReadAtField]).value_or(0));
      uplink_said += ", parent last heard " + age_of(heard, read_ns) + ", outbox " + f["outboxDepth"];
      if (!f["linkConflict"].empty()) uplink_said += "; CONFLICT: " + f["linkConflict"];
      uplink_unknown_because = unbelieved_because(&n, n.id + "/link", f["uplinkState"], heard, read_ns);
    }
    const std::string& programs_unknown_because = n.programs_unknown_because;
    if (json) {
      std::cout << (first_node ? "" : ",") << "{\"id\":\"" << node::json_escape(n.id) << "\",\"iri\":\""
                << node::json_escape(n.iri) << "\",\"depth\":" << depth << ",\"parent\":";
      print_json_string_or_null(parent ? parent->iri : std::string());
      std::cout << ",\"remote\":" << (n.remote ? "true" : "false")
                << ",\"in_deployment\":" << (left ? "false" : "true") << ",\"moved_from\":";
      print_json_string_or_null(n.moved_from);
      std::cout << ",\"link\":";
      first_node = false;
      if (n.link.empty()) std::cout << "null";
      else
        print_link_json(n.link["parent"], n.link["linkState"], unknown_because, "last_seen_ns", seen, n.link["outboxDepth"],
                        "software_version", n.link["softwareVersion"], n.link["linkConflict"],
                        n.link["linkState"] == "down" && n.link["linkLeft"] == "true", &n.link);
      std::cout << ",\"has_parent\":" << (n.has_parent || !n.uplink.empty() || n.remote ? "true" : "false") << ",\"outbox_here\":"
                << (!n.remote && n.outbox_here ? std::to_string(*n.outbox_here) : "null") << ",\"uplink\":";
      if (n.uplink.empty()) std::cout << "null";
      else
        print_link_json(n.uplink["parent"], n.uplink["uplinkState"], uplink_unknown_because, "parent_last_heard_ns", heard,
                        n.uplink["outboxDepth"], "refusal", n.uplink["uplinkRefusal"], n.uplink["linkConflict"]);
      std::cout << ",\"programs\":[";
      bool first_program = true;
      for (const auto& p : n.programs) {
        std::cout << (first_program ? "" : ",") << "{\"name\":\"" << node::json_escape(p.name)
                  << "\",\"state\":\"" << node::json_escape(p.state) << "\",\"pid\":"
                  << (alive(p) && parse_u64(p.pid) ? std::to_string(*parse_u64(p.pid)) : "null")
                  << ",\"restarts\":" << parse_u64(p.restarts).value_or(0) << ",\"last_exit\":";
        print_json_string_or_null(p.last_exit);
        std::cout << ",\"problem\":";
        print_json_string_or_null(p.problem);
        std::cout << ",\"problem_of_this_run\":" << (p.problem.empty() ? "null" : problem_of_a_run_before(p) ? "false" : "true") << "}";
        first_program = false;
      }
      std::cout << "],\"programs_known\":" << (programs_unknown_because.empty() ? "true" : "false")
                << ",\"programs_unknown_because\":";
      print_json_string_or_null(programs_unknown_because);
      std::cout << ",\"programs_written_ns\":" << (n.remote && n.programs_at > 0 ? std::to_string(n.programs_at) : "null")
                << ",\"children_unknown_because\":";
      print_json_string_or_null(n.children_unknown_because);
      std::cout << ",\"store_warning\":";
      print_json_string_or_null(n.store_warning);
      std::cout << ",\"waiting_for_unknown\":[";
      for (std::size_t i = 0; i < n.waiting_for_unknown.size(); ++i) {
        const node::InputBufferSummary& w = n.waiting_for_unknown[i];
        std::cout << (i ? "," : "") << "{\"agent\":\"" << node::json_escape(w.agent) << "\",\"items\":" << w.waiting
                  << ",\"oldest_asserted_at_ns\":" << w.oldest_asserted_at << "}";
      }
      std::cout << "]}";
      continue;
    }
    std::string indent(depth * 2, ' ');
    std::cout << indent << n.id << "  <" << n.iri << ">";
    if (n.remote) std::cout << "  (on another machine)";
    if (left && !n.moved_from.empty())
      std::cout << "  not in the deployment (the store of node '" << n.moved_from << "', moved here while it ran)";
    else if (left)
      std::cout << "  not in the deployment (taken out of its file; the store is kept)";
    // Its own link not running, the depths said above are of before: the outbox as it is here
    // (a home SIGKILLed while its parent was away showed "outbox 0" and held 60 windows).
    const auto own_link = std::find_if(n.programs.begin(), n.programs.end(), [](const ProgramRow& p) { return p.name == "link"; });
    const bool own_link_runs = own_link != n.programs.end() && alive(*own_link);
    const std::string outbox_here = !n.remote && n.outbox_here && *n.outbox_here > 0 && !own_link_runs
                                        ? "; its outbox here holds " + std::to_string(*n.outbox_here) + " item(s)"
                                        : std::string();
    if (!n.link.empty() && !unknown_because.empty()) {
      std::cout << "  link state unknown: " << unknown_because << " (it last said: " << said << ")" << outbox_here;
      // The parent's view is stale; the node's own, written here, is not (its outbox grows).
      if (!n.uplink.empty() && uplink_unknown_because.empty()) std::cout << "; its own link says: " << uplink_said;
    } else if (!n.link.empty()) {
      std::cout << "  " << said << outbox_here;
      // The parent's view says the link is up; only the node's own says the parent refuses what
      // it sends (P9b: a full store), and its outbox grows.
      if (!n.uplink.empty() && uplink_unknown_because.empty() && !n.uplink["uplinkRefusal"].empty())
        std::cout << "; REFUSED: " << n.uplink["uplinkRefusal"];
      // Its own link died a moment ago: the parent calls it down only after child_silence, and
      // the line said "link up" above "link  restarting … killed by signal 9".
      const auto own = std::find_if(n.programs.begin(), n.programs.end(), [](const ProgramRow& p) { return p.name == "link"; });
      if (!n.remote && n.link["linkState"] == "up" && own != n.programs.end() && !alive(*own))
        std::cout << " (as its parent last saw it; its own link is " << own->state << " now)";
    } else if (!n.uplink.empty() && !uplink_unknown_because.empty())
      std::cout << "  uplink state unknown: " << uplink_unknown_because << " (it last said: " << uplink_said << ")";
    else if (!n.uplink.empty())
      std::cout << "  " << uplink_said;
    else if (const auto link = std::find_if(n.programs.begin(), n.programs.end(),
                                            [](const auto& p) { return p.name == "link" && p.state == "running"; });
             n.has_parent && !left && link != n.programs.end() && link->restarts == "0" && link->last_exit.empty()) {
      // The link runs, has not failed, and has not yet written how its parent is: in its first
      // seconds, starting; later, something holds it up. One that failed and runs again is
      // "never started" below: its last exit says why.
      const std::optional<double> age = seconds_running(link->pid);
      if (age && *age < kLinkStartingS)
        std::cout << "  uplink starting (its link runs and has not yet said how its parent is)";
      else
        std::cout << "  uplink state not written (its link has run " << (age ? seconds_text(*age) : "a while")
                  << " without saying how its parent is: see its log)";
    } else if (n.has_parent && !left)
      std::cout << "  uplink never started (its link has not run: see the link's last exit)";
    else if (depth == 0 && !left)
      std::cout << "  (root)";
    std::cout << "\n";
    if (!n.store_warning.empty()) std::cout << indent << "  STORE " << n.store_warning << "\n";
    for (const node::InputBufferSummary& w : n.waiting_for_unknown)
      std::cout << indent << "  WAITING " << w.waiting << " item(s) addressed to <" << w.agent
                << ">, which nothing on this node knows (no child node of that IRI has registered, and no agent of it "
                   "runs, subscribes itself or has said anything: a subscription another wrote for it, as a parent's "
                   "forwarding policy, routes items there all the same)"
                << (w.oldest_asserted_at > 0 ? ", the oldest asserted " + age_of(w.oldest_asserted_at) : std::string())
                << ": they wait in its input buffer until one takes them\n";
    if (n.remote && !programs_unknown_because.empty() && programs_unknown_because == n.children_unknown_because) {
      std::cout << indent << "  programs and children unknown: " << programs_unknown_because << "\n";
    } else {
      if (n.remote && !programs_unknown_because.empty())
        std::cout << indent << "  programs " << (n.programs.empty() ? "unknown" : "as last written, now unknown") << ": "
                  << programs_unknown_because << "\n";
      if (n.remote && !n.children_unknown_because.empty())
        std::cout << indent << "  children unknown: " << n.children_unknown_because << "\n";
    }
    for (const auto& p : n.programs) {
      std::cout << indent << "  - " << p.name << "  " << p.state;
      // A local suspended program's state says its pid already; a remote one's is "suspended".
      if (p.state == "running" || p.state == "suspended") std::cout << " (pid " << p.pid << ")";
      if (p.restarts != "0") std::cout << ", " << p.restarts << " restarts";
      if (!p.last_exit.empty()) std::cout << ", last: " << p.last_exit;
      // What a run that is over said is what it last found: nothing takes the line back until
      // a run of the program says otherwise.
      if (!p.problem.empty())
        std::cout << "\n" << indent << "      PROBLEM "
                  << (!problem_of_a_run_before(p) ? ""
                      : alive(p)                  ? "(said by its run before this one) "
                                                  : "(said while it ran; it is not running now) ")
                  << p.problem;
      std::cout << "\n";
    }
  }
  if (json) std::cout << "]}\n";
  return kExitOk;
}

}  // namespace tahvel::cli
