// `tahvel check DIR`: reads the whole store and says whether it holds together (Node::check).
// LMDB checksums no page, so reading a damaged one may end the reading process instead of
// returning an error: the walk runs in a child process, which tells the parent over a pipe which
// table it is reading and then what it found. A child that dies says where the damage is.
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <csignal>
#include <cstring>
#include <iostream>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include "commands.h"

namespace tahvel::cli {

const Command kCheckCommand{
    "check",
    "DIR [--json] [--max-problems N]",
    "Read the whole store and say whether it holds together.",
    "Every table is read in one snapshot (agents may go on writing): each row decoded, each\n"
    "reference followed (a record's item, terms and index entries; index and time-index\n"
    "entries to their records and items), the counters compared with the tables. Prints the\n"
    "counts and each problem found; exits 0 when there is none, 1 when there are (or the store\n"
    "cannot be read). LMDB checksums no page: a damaged page may end the reading process, so\n"
    "the reading runs in a process of its own, and its end is reported with the table it was\n"
    "reading.",
    {{"--json", "", "", "print one JSON object"},
     {"--max-problems", "", "N", "list at most N problems (default 100; all are counted)"}},
    1, 1, false};

namespace {

// What the child sends, one line each: "table NAME", then "count NAME N" per figure and
// "problem TEXT" per problem, then "end"; "error CODE TEXT" (CODE: node::errc_name) when the
// store cannot be opened or read.
void child_walk(const std::string& dir, std::size_t max_problems, int fd) {
  auto send = [fd](std::string line) {
    for (char& c : line)
      if (c == '\n') c = ' ';
    line += '\n';
    for (std::size_t off = 0; off < line.size();) {
      ssize_t n = ::write(fd, line.data() + off, line.size() - off);
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) _exit(kExitFailure);
      off += static_cast<std::size_t>(n);
    }
  };
  // Nothing leaves this function but by _exit: an exception (memory for a huge store) must not
  // reach the parent's code, copied into this process by fork.
  std::optional<node::CheckReport> checked;
  try {
    auto node = node::Node::open(dir);
    if (!node) {
      send("error " + std::string(node::errc_name(node.error().code)) + " " + node.error().message);
      _exit(kExitFailure);
    }
    // Each problem as it is found: a damaged page may end this process before the report.
    auto report = node->check(
        max_problems, [&](std::string_view table) { send("table " + std::string(table)); },
        [&](std::string_view problem) { send("problem " + std::string(problem)); });
    if (!report) {
      send("error " + std::string(node::errc_name(report.error().code)) + " " + report.error().message);
      _exit(kExitFailure);
    }
    checked = std::move(*report);
  } catch (const std::exception& e) {
    send(std::string("error io check: ") + e.what());
    _exit(kExitFailure);
  } catch (...) {
    send("error io check: the reading process failed");
    _exit(kExitFailure);
  }
  const node::CheckReport* report = &*checked;
  const std::pair<const char*, std::uint64_t> counts[] = {
      {"records", report->records},           {"items", report->items},
      {"terms", report->terms},               {"index_entries", report->index_entries},
      {"time_entries", report->time_entries}, {"buffer_entries", report->buffer_entries},
      {"problems_found", report->problems_found}};
  for (const auto& [name, value] : counts) send(std::string("count ") + name + " " + std::to_string(value));
  send("end");
  _exit(kExitOk);
}

std::string signal_name(int sig) {
  switch (sig) {
    case SIGSEGV: return "SIGSEGV";
    case SIGBUS: return "SIGBUS";
    case SIGABRT: return "SIGABRT";
    case SIGKILL: return "SIGKILL";
    default: return "signal " + std::to_string(sig);
  }
}

}  // namespace

int run_check(const Args& args) {
  const std::string dir = args.positional(0);
  const std::uint64_t max_problems = args.get_u64("--max-problems", 100);
  const bool json = args.has("--json");
  std::cout.flush();
  int fds[2];
  if (::pipe(fds) != 0) fail(std::string("check: cannot make a pipe: ") + std::strerror(errno));
  const pid_t pid = ::fork();
  if (pid < 0) fail(std::string("check: cannot start the reading process: ") + std::strerror(errno));
  if (pid == 0) {
    ::close(fds[0]);
    child_walk(dir, static_cast<std::size_t>(max_problems), fds[1]);
  }
  ::close(fds[1]);
  std::string text;
  char buf[4096];
  for (;;) {
    ssize_t n = ::read(fds[0], buf, sizeof buf);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) break;
    text.append(buf, static_cast<std::size_t>(n));
  }
  ::close(fds[0]);
  int status = 0;
  while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }

  std::string table, error, error_code;
  std::vector<std::pair<std::string, std::string>> counts;
  std::vector<std::string> problems;
  bool ended = false;
  std::istringstream lines(text);
  for (std::string line; std::getline(lines, line);) {
    const auto space = line.find(' ');
    const std::string kind = line.substr(0, space), rest = space == std::string::npos ? "" : line.substr(space + 1);
    if (kind == "table") table = rest;
    else if (kind == "error") {
      const auto sep = rest.find(' ');
      error_code = rest.substr(0, sep);
      error = sep == std::string::npos ? "" : rest.substr(sep + 1);
    }
    else if (kind == "problem") problems.push_back(rest);
    else if (kind == "end") ended = true;
    else if (kind == "count") {
      const auto sep = rest.find(' ');
      counts.emplace_back(rest.substr(0, sep), rest.substr(sep + 1));
    }
  }
  if (!error_code.empty()) {
    if (error.find(dir) == std::string::npos) error = dir + ": " + error;  // which store, among many checked
    // A monitoring script reads JSON whatever happened: a store that cannot be opened or read
    // for damage is not consistent; one that is missing or busy was not judged.
    if (json) {
      const bool damaged = error_code == "corrupt" || error_code == "version";
      std::cout << "{\"consistent\":" << (damaged ? "false" : "null") << ",\"error\":\"" << node::json_escape(error)
                << "\",\"error_code\":\"" << node::json_escape(error_code) << "\",\"problems\":[";
      for (std::size_t i = 0; i < problems.size(); ++i) std::cout << (i ? "," : "") << '"' << node::json_escape(problems[i]) << '"';
      std::cout << "]}\n";
      finish_output(std::cout);
    }
    fail(error);
  }
  if (!ended) {
    // A damaged page ends the reader by a fault or LMDB's assertion; other ends (the OOM
    // killer's SIGKILL, a SIGTERM) say nothing of the file.
    const int sig = WIFSIGNALED(status) ? WTERMSIG(status) : 0;
    const bool fault = sig == SIGSEGV || sig == SIGBUS || sig == SIGABRT;
    const std::string how = sig ? "ended by " + signal_name(sig) : "ended with status " + std::to_string(WEXITSTATUS(status));
    const std::string where = table.empty() ? "while opening the store" : "while reading table " + table;
    const std::string message =
        fault ? dir + ": the store's file is damaged: the reading process was " + how + " " + where +
                    " (LMDB checksums no page; a damaged one can end a reader or a writer)"
              : dir + ": the check did not finish: the reading process was " + how + " " + where;
    // What it had found before it ended (a first damaged page read without a fault).
    if (json) {
      std::cout << "{\"consistent\":" << (fault ? "false" : "null") << ",\"ended_in_table\":\"" << node::json_escape(table) << "\",\"how\":\""
                << node::json_escape(how) << "\",\"problems\":[";
      for (std::size_t i = 0; i < problems.size(); ++i) std::cout << (i ? "," : "") << '"' << node::json_escape(problems[i]) << '"';
      std::cout << "]}\n";
    } else {
      for (const std::string& p : problems) std::cout << "problem: " << p << "\n";
    }
    finish_output(std::cout);
    fail(message);
  }
  std::string found = "0";
  for (const auto& [name, value] : counts)
    if (name == "problems_found") found = value;
  if (json) {
    std::cout << "{\"consistent\":" << (found == "0" ? "true" : "false");
    for (const auto& [name, value] : counts) std::cout << ",\"" << name << "\":" << value;
    std::cout << ",\"problems\":[";
    for (std::size_t i = 0; i < problems.size(); ++i) std::cout << (i ? "," : "") << '"' << node::json_escape(problems[i]) << '"';
    std::cout << "]}\n";
  } else {
    for (const auto& [name, value] : counts) std::cout << name << ": " << value << "\n";
    for (const std::string& p : problems) std::cout << "problem: " << p << "\n";
  }
  finish_output(std::cout);
  if (found != "0") {
    fail(dir + ": " + found + " problem(s): the store does not hold together");
  }
  return kExitOk;
}

}  // namespace tahvel::cli
