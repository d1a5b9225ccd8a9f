// The `tahvel` command line: a small hand-written option parser shared by every subcommand.
//
// Each subcommand describes itself with a Command (usage line, flags, positional range, help
// text); parse_args() checks an argument vector against it and print_help() renders its help.
// Grammar: flags and positionals in any order; "--flag VALUE" or "--flag=VALUE"; "-s VALUE";
// "--" ends flags; "-" alone is a positional (standard input). `--prefix` and `--help` are
// added to every command by parse_args()/print_help().
//
// Errors are reported by throwing Failure, caught once in main(): the CLI is the edge where
// exceptions are allowed (STYLE §5); nothing on a store or take path throws.
#pragma once

#include <cstdint>
#include <iosfwd>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace tahvel::cli {

// Exit statuses of the tool (docs/cli.md).
inline constexpr int kExitOk = 0;
inline constexpr int kExitFailure = 1;  // the operation failed (store, file, syntax, ...)
inline constexpr int kExitUsage = 2;    // bad command line: unknown flag, bad value, ...
inline constexpr int kExitTimeout = 3;  // `take` found nothing before its timeout

// Thrown to end the command; main() prints "tahvel: <message>" and exits with `status`.
struct Failure {
  int status;
  std::string message;
};

[[noreturn]] void usage_error(std::string message);  // status kExitUsage
[[noreturn]] void fail(std::string message);         // status kExitFailure

struct Flag {
  std::string_view name;         // "--agent" or "-s"
  std::string_view alias;        // second spelling ("--subject"), or empty
  std::string_view value;        // metavariable shown in help ("ID"); empty: a switch
  std::string_view help;         // one line
  bool repeatable = false;       // may be given more than once
};

struct Command {
  std::string_view name;         // "put"
  std::string_view usage;        // "DIR [--agent ID] ... [FILE|-]" (after "tahvel put ")
  std::string_view summary;      // one line, shown in `tahvel --help`
  std::string_view description;  // paragraphs shown in `tahvel put --help`
  std::vector<Flag> flags;
  std::size_t min_positional = 0;
  std::size_t max_positional = 0;
  // Whether the common --prefix applies: false for `bench` (its runs parse their own flags) and
  // for the commands that read no CURIEs from their command line, which refuse it.
  bool takes_prefix = true;
};

// The result of parsing: flag values by canonical name (Flag::name) and the positionals.
class Args {
 public:
  explicit Args(const Command& command) : command_(&command) {}

  const Command& command() const { return *command_; }
  const std::vector<std::string>& positional() const { return positional_; }
  const std::string& positional(std::size_t i) const { return positional_.at(i); }

  bool has(std::string_view flag) const;
  // The value of a flag given once (the last one if repeated), or nullopt.
  std::optional<std::string> get(std::string_view flag) const;
  // Every value of a repeatable flag, in order.
  std::vector<std::string> all(std::string_view flag) const;
  // The flag's value; usage error naming the flag when it is missing.
  std::string required(std::string_view flag) const;
  // The flag's value as an unsigned integer (or `fallback` when absent); usage error naming the
  // flag when it is not a non-negative decimal integer.
  std::uint64_t get_u64(std::string_view flag, std::uint64_t fallback) const;

  void add(std::string_view flag, std::string value);
  void add_positional(std::string value) { positional_.push_back(std::move(value)); }
  // A flag that took another of the command's flags for its value: said with an error it may
  // have caused ("'--limit' took '--format' as its value; give '--limit N'").
  void note_flag_as_value(std::string_view flag, std::string_view value);
  const std::string& flag_as_value() const { return flag_as_value_; }

 private:
  const Command* command_;
  std::string flag_as_value_;
  std::vector<std::pair<std::string, std::string>> values_;
  std::vector<std::string> positional_;
};

// True when `argv` asks for help: "-h" or "--help" in a flag's place before any "--". The value
// of a flag that takes one ("--child -h") is a value, not a request for help.
bool wants_help(const Command& command, std::span<const std::string> argv);

// Parses `argv` (the arguments after the subcommand name). Usage errors name the flag.
Args parse_args(const Command& command, std::span<const std::string> argv);

// Prints "usage: tahvel NAME USAGE", the description and every flag with its help.
void print_help(std::ostream& out, const Command& command);

// Parses a non-negative decimal integer; nullopt when `text` is not one or overflows.
std::optional<std::uint64_t> parse_u64(std::string_view text);

}  // namespace tahvel::cli
