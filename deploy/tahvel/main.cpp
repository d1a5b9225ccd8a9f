// `tahvel`: the command-line tool over a node's whiteboard (docs/cli.md). A thin layer: each
// subcommand parses its flags (args.h), calls the node library once or twice and prints the
// result. This file dispatches and turns failures into "tahvel: <cause>" and an exit status.
#include <fcntl.h>
#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <csignal>
#include <exception>
#include <iostream>
#include <string>
#include <system_error>
#include <vector>

#include "args.h"
#include "bench.h"
#include "commands.h"
#include "tahvel/uri/spelling.h"

namespace tahvel::cli {

namespace {

const Command kBenchCommand{
    "bench",
    "store|hrv|spatial|reason|federation [--json] [--quick] [...]",
    "Run a benchmark: store, hrv, spatial, reason or federation (each against its peers).",
    "'store' measures Tahvel's store against SQLite and sord on the same records in the same run\n"
    "and prints ratios. 'hrv' measures the R-peak detector and the whole HRV chain as multiples\n"
    "of real time on one core over MIT-BIH records, raw bytes kept at home against HRV bytes\n"
    "sent up per patient-hour, and the operator's view (tahvel patients) of a hospital board\n"
    "against listing what it reads. 'spatial' measures which-sensors-in-a-room queries with 10,000\n"
    "sensors and 1,000 rooms against testing every sensor. 'reason' measures reasoner sessions and\n"
    "a closure with SWI-Prolog on the same rules and facts. 'federation' measures store-to-hospital\n"
    "latency over DDS and LCM against the raw transports, items/s per link and hospital ingest\n"
    "from K simulated homes; it sends packets, so run it under tests/tools/netns-run. Everything\n"
    "after the benchmark's name goes to it; 'tahvel bench store --help' (hrv, spatial, reason,\n"
    "federation) lists its flags.",
    {{"--json", "", "", "(after the benchmark's name) print one JSON object instead of the table"},
     {"--quick", "", "", "(after the benchmark's name) a small run of seconds, for smoke tests"}},
    1, 64, false};

void print_global_help(std::ostream& out) {
  out << "usage: tahvel SUBCOMMAND DIR [options]   (up FILE, down and status --state DIR, hrv RECORD)\n\n"
         "Tahvel's command line: create a node's whiteboard and put, list, take and follow its\n"
         "records; bring deployments up and down. DIR is the node's store directory.\n\nsubcommands:\n";
  auto row = [&](const Command& c) {
    std::string name(c.name);
    out << "  " << name << std::string(name.size() < 12 ? 12 - name.size() : 1, ' ') << c.summary
        << "\n";
  };
  for (const Subcommand& s : subcommands()) row(*s.spec);
  row(kBenchCommand);
  out << "  help        'tahvel help SUBCOMMAND' shows a subcommand's flags\n"
         "  --version   the software version (as links and status give it)\n\n"
         "terms (-s, -p, -o, --context): <http://x/a>, http://x/a, a CURIE such as\n"
         "sosa:Observation (the node's prefixes and --prefix P=IRI), _:label, \"text\",\n"
         "\"text\"@en, \"72\"^^xsd:integer, 72 (xsd:integer), 72.5 (xsd:decimal), 7e2 (xsd:double),\n"
         "true/false (xsd:boolean), and 'a' for rdf:type.\n\n"
         "exit status: 0 success, 1 failure, 2 bad command line, 3 timed out (take, query, ecg,\n"
         "stats --at), 4 unknown node, 5 unreachable node, 6 refused as things stand (up),\n"
         "130 interrupted (query, ecg, stats --at).\n";
}

const Command* find_command(std::string_view name) {
  for (const Subcommand& s : subcommands()) {
    if (s.spec->name == name) return s.spec;
  }
  return name == "bench" ? &kBenchCommand : nullptr;
}

int run_help(const std::vector<std::string>& rest) {
  if (rest.empty() || rest[0] == "--help" || rest[0] == "-h" || rest[0] == "help") {
    print_global_help(std::cout);
  } else if (const Command* c = find_command(rest[0])) {
    print_help(std::cout, *c);
  } else {
    usage_error("help: unknown subcommand '" + rest[0] + "'");
  }
  return kExitOk;
}

int run_bench(const std::vector<std::string>& rest) {
  if (rest.empty()) usage_error("bench: which benchmark? (usage: tahvel bench store|hrv|spatial|reason|federation [--json])");
  std::vector<std::string> args(rest.begin() + 1, rest.end());
  if (rest[0] == "store") return bench_store_main(args);
  if (rest[0] == "hrv") return bench_hrv_main(args);
  if (rest[0] == "spatial") return bench_spatial_main(args);
  if (rest[0] == "reason") return bench_reason_main(args);
  if (rest[0] == "federation") return bench_federation_main(args);
  usage_error("bench: unknown benchmark '" + rest[0] + "' (try 'store', 'hrv', 'spatial', 'reason' or 'federation')");
}

int dispatch(const std::vector<std::string>& argv) {
  if (argv.empty()) {
    print_global_help(std::cerr);
    return kExitUsage;
  }
  const std::string& name = argv[0];
  std::vector<std::string> rest(argv.begin() + 1, argv.end());
  if (name == "help" || name == "--help" || name == "-h") return run_help(rest);
  if (name == "--version" || name == "version") {
    std::cout << federation::LinkOptions{}.software_version << "\n";  // what links and status say
    return kExitOk;
  }
  const Command* command = find_command(name);
  if (!command) {
    // `tahvel lst`: the nearest subcommand within two edits.
    std::string nearest;
    std::size_t best = 3;
    for (const Subcommand& s : subcommands())
      if (const std::size_t d = uri::edit_distance(name, s.spec->name); d < best) best = d, nearest = s.spec->name;
    usage_error("unknown subcommand '" + name + "'" + (nearest.empty() ? "" : "; did you mean '" + nearest + "'?") +
                " (see 'tahvel --help')");
  }
  // `tahvel bench store --help` is answered by the store benchmark itself (and so on).
  bool named_bench = command == &kBenchCommand && !rest.empty() &&
                     (rest[0] == "store" || rest[0] == "hrv" || rest[0] == "spatial" || rest[0] == "reason" ||
                      rest[0] == "federation");
  if (wants_help(*command, rest) && !named_bench) {
    print_help(std::cout, *command);
    return kExitOk;
  }
  if (command == &kBenchCommand) return run_bench(rest);
  set_running_command(command->name);
  for (const Subcommand& s : subcommands()) {
    if (s.spec != command) continue;
    try {
      return s.run(parse_args(*command, rest));
    } catch (Failure& f) {
      // A usage error names its command, as the parser's own do ("reason: unknown flag"), also
      // where a command checks a value itself: in a script's log, "--max-conclusions: must be at
      // least 1" said not which of its commands was wrong.
      const std::string own = std::string(command->name) + ": ";
      if (f.status == kExitUsage && !f.message.starts_with(own)) f.message = own + f.message;
      throw;
    }
  }
  return kExitUsage;
}

}  // namespace

std::span<const Subcommand> subcommands() {
  static const Subcommand table[] = {
      {&kInitCommand, run_init},   {&kPutCommand, run_put},
      {&kListCommand, run_list},   {&kRemoveCommand, run_remove},
      {&kSubscribeCommand, run_subscribe}, {&kAreasCommand, run_areas},
      {&kTakeCommand, run_take},
      {&kTailCommand, run_tail},   {&kDumpCommand, run_dump},
      {&kBackupCommand, run_backup},
      {&kLoadCommand, run_load},   {&kStatsCommand, run_stats},
      {&kCheckCommand, run_check},
      {&kHrvCommand, run_hrv},     {&kPatientsCommand, run_patients},
      {&kEcgCommand, run_ecg},
      {&kReasonCommand, run_reason},
      {&kUpCommand, run_up},       {&kDownCommand, run_down},
      {&kStatusCommand, run_status}, {&kQueryCommand, run_query},
      {&kLinkCommand, run_link},
  };
  return table;
}

}  // namespace tahvel::cli

int main(int argc, char** argv) {
  using namespace tahvel::cli;
  // A closed pipe becomes a write error that each command checks (take must not ack then).
  std::signal(SIGPIPE, SIG_IGN);
  // Run with standard output closed, output is a write error too, as on a full disk: /dev/full
  // takes its number (else a store's file would, and the output would go into it), and take
  // keeps its item. A closed standard input or error is /dev/null.
  for (int fd = 0; fd <= 2; ++fd) {
    if (fcntl(fd, F_GETFD) != -1 || errno != EBADF) continue;
    const int opened = ::open(fd == 1 ? "/dev/full" : "/dev/null", fd == 0 ? O_RDONLY : O_WRONLY);
    if (opened >= 0 && opened != fd) ::close(opened);
    if (fd == 1) g_stdout_was_closed = true;
  }
  // A soft limit on open files below 1,024 (`ulimit -n 12`) made a link's Cyclone DDS domain fail
  // to start and crash in its own clean-up, restarted for ever: raised to what the hard limit
  // allows, up to 1,024 (no higher: liblcm waits with select(), which takes descriptors below
  // FD_SETSIZE only).
  if (rlimit files{}; getrlimit(RLIMIT_NOFILE, &files) == 0 && files.rlim_cur < 1024 && files.rlim_max > files.rlim_cur) {
    files.rlim_cur = std::min<rlim_t>(files.rlim_max, 1024);
    setrlimit(RLIMIT_NOFILE, &files);
  }
  std::vector<std::string> args(argv + 1, argv + argc);
  try {
    int status = dispatch(args);
    std::cout.flush();
    return status;
  } catch (const Failure& failure) {
    if (!failure.message.empty()) std::cerr << "tahvel: " << failure.message << "\n";
    return failure.status;
  } catch (const std::system_error& e) {
    // std::thread's way of saying the user's task limit (`ulimit -u`) is reached.
    if (e.code() == std::errc::resource_unavailable_try_again)
      std::cerr << "tahvel: cannot start a thread: " << e.what() << " (the limit on the user's processes and threads, "
                << "'ulimit -u', may be reached)\n";
    else
      std::cerr << "tahvel: internal error: " << e.what() << "\n";
    return kExitFailure;
  } catch (const std::exception& e) {
    std::cerr << "tahvel: internal error: " << e.what() << "\n";
    return kExitFailure;
  }
}
