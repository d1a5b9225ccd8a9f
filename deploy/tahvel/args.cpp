// The option parser behind every `tahvel` subcommand (see args.h for the grammar).
#include "args.h"

#include <algorithm>
#include <charconv>
#include <ostream>
#include <vector>

#include "tahvel/uri/spelling.h"

namespace tahvel::cli {
namespace {

// Flags every subcommand accepts, appended to its own.
const std::vector<Flag>& common_flags() {
  static const std::vector<Flag> flags = {
      {"--prefix", "", "P=IRI",
       "expand CURIEs P:x to IRI+x (repeatable; adds to the node's prefixes)",
       true},
      {"--help", "-h", "", "show this help and exit"},
  };
  return flags;
}

const Flag* find_in(const std::vector<Flag>& flags, std::string_view name) {
  for (const Flag& f : flags) {
    if (f.name == name || (!f.alias.empty() && f.alias == name)) return &f;
  }
  return nullptr;
}

const Flag* find_flag(const Command& command, std::string_view name) {
  if (const Flag* f = find_in(command.flags, name)) return f;
  if (name == "--prefix" && !command.takes_prefix) return nullptr;
  return find_in(common_flags(), name);
}

bool looks_like_flag(std::string_view arg) { return arg.size() > 1 && arg[0] == '-'; }

std::string prefix_of(const Command& command) { return std::string(command.name) + ": "; }

// Handles one flag at argv[i]; returns the index of the last argument it consumed.
std::size_t take_flag(const Command& command, std::span<const std::string> argv, std::size_t i,
                      Args& args) {
  std::string_view arg = argv[i];
  std::optional<std::string> inline_value;
  if (auto eq = arg.find('='); arg.starts_with("--") && eq != std::string_view::npos) {
    inline_value = std::string(arg.substr(eq + 1));
    arg = arg.substr(0, eq);
  }
  const Flag* flag = find_flag(command, arg);
  if (!flag && arg == "--prefix")
    usage_error(prefix_of(command) + "--prefix: not taken by " + std::string(command.name) +
                ", which reads no CURIEs from its command line" +
                (command.name == "up" ? " (a topology file's forward patterns and load files use the node's prefixes, "
                                        "a load file's own @prefix lines, or <full IRIs>)"
                                      : ""));
  if (!flag) {
    // Some commands print JSON with --json, those that have other formats with --format json.
    std::string instead;
    if (arg == "--json" && find_flag(command, "--format")) instead = "; give --format json";
    if (arg == "--format" && find_flag(command, "--json")) instead = "; give --json";
    // `-p=sosa:x`: only long flags take their value after '='.
    if (const auto eq = arg.find('='); !arg.starts_with("--") && eq != std::string_view::npos) {
      const Flag* short_flag = find_flag(command, arg.substr(0, eq));
      if (short_flag && !short_flag->value.empty()) {
        const std::string value(arg.substr(eq + 1));
        instead = "; write '" + std::string(arg.substr(0, eq)) + " " + value + "'";
        const std::string_view long_name = short_flag->name.starts_with("--") ? short_flag->name : short_flag->alias;
        if (long_name.starts_with("--")) instead += " or '" + std::string(long_name) + "=" + value + "'";
      }
    }
    // A slip of a letter or two (--fromat, --lmit): the nearest flag, when one alone is that near.
    if (instead.empty() && arg.starts_with("--") && arg.size() > 4) {
      std::vector<std::string_view> names{"--help"};
      if (command.takes_prefix) names.push_back("--prefix");
      for (const Flag& f : command.flags)
        for (std::string_view n : {f.name, f.alias})
          if (n.starts_with("--")) names.push_back(n);
      std::size_t best = arg.size() <= 6 ? 1 : 2;  // more edits than this is another word (a swap is one)
      std::vector<std::string_view> nearest;
      for (std::string_view n : names) {
        const std::size_t d = uri::edit_distance(arg, n);
        if (d < best) best = d, nearest.clear();
        if (d == best) nearest.push_back(n);
      }
      if (nearest.size() == 1) instead = "; did you mean '" + std::string(nearest.front()) + "'?";
    }
    usage_error(prefix_of(command) + "unknown flag '" + std::string(arg) + "'" + instead + " (see 'tahvel " +
                std::string(command.name) + " --help')");
  }
  if (!flag->repeatable && args.has(flag->name)) {
    usage_error(prefix_of(command) + "flag '" + std::string(flag->name) + "' given twice");
  }
  if (flag->value.empty()) {
    if (inline_value) {
      usage_error(prefix_of(command) + "flag '" + std::string(flag->name) + "' takes no value");
    }
    args.add(flag->name, "");
    return i;
  }
  if (inline_value) {
    args.add(flag->name, std::move(*inline_value));
    return i;
  }
  if (i + 1 >= argv.size()) {
    usage_error(prefix_of(command) + "flag '" + std::string(flag->name) + "' needs a value (" +
                std::string(flag->value) + ")");
  }
  // A value is a value, whatever it looks like (a child named "-h"); one that is also a flag of
  // the command is remembered, so that what it leaves over is explained (check_positional_count).
  if (const std::string_view next = argv[i + 1]; looks_like_flag(next) && find_flag(command, next.substr(0, next.find('='))))
    args.note_flag_as_value(flag->name, next);
  args.add(flag->name, argv[i + 1]);
  return i + 1;
}

void check_positional_count(const Command& command, const Args& args) {
  std::size_t n = args.positional().size();
  if (n < command.min_positional) {
    usage_error(prefix_of(command) + "missing argument (usage: tahvel " +
                std::string(command.name) + " " + std::string(command.usage) + ")");
  }
  if (n > command.max_positional) {
    // `--limit --format json`: --limit took "--format" for its value, and "json" is left over.
    std::string hint = args.flag_as_value().empty() ? "" : " (" + args.flag_as_value() + ")";
    // `tahvel status st`: the other commands take their directory as DIR, these as a flag.
    if (hint.empty() && command.max_positional == 0 && find_flag(command, "--state"))
      hint = " (the state directory is given as --state " + args.positional()[0] + ")";
    usage_error(prefix_of(command) + "unexpected argument '" + args.positional()[command.max_positional] + "'" + hint);
  }
}

void print_flags(std::ostream& out, const std::vector<Flag>& flags) {
  for (const Flag& f : flags) {
    std::string left = std::string(f.name);
    if (!f.alias.empty()) {  // the short spelling first: "-s, --subject"
      bool alias_short = !f.alias.starts_with("--");
      left = alias_short ? std::string(f.alias) + ", " + left : left + ", " + std::string(f.alias);
    }
    if (!f.value.empty()) left += " " + std::string(f.value);
    out << "  " << left;
    if (left.size() < 22) {
      out << std::string(22 - left.size(), ' ');
    } else {
      out << "\n" << std::string(24, ' ');
    }
    out << f.help << "\n";
  }
}

}  // namespace

void usage_error(std::string message) { throw Failure{kExitUsage, std::move(message)}; }
void fail(std::string message) { throw Failure{kExitFailure, std::move(message)}; }

bool Args::has(std::string_view flag) const {
  return std::any_of(values_.begin(), values_.end(),
                     [&](const auto& kv) { return kv.first == flag; });
}

std::optional<std::string> Args::get(std::string_view flag) const {
  for (auto it = values_.rbegin(); it != values_.rend(); ++it) {
    if (it->first == flag) return it->second;
  }
  return std::nullopt;
}

std::vector<std::string> Args::all(std::string_view flag) const {
  std::vector<std::string> out;
  for (const auto& [name, value] : values_) {
    if (name == flag) out.push_back(value);
  }
  return out;
}

std::string Args::required(std::string_view flag) const {
  if (auto v = get(flag)) return *v;
  usage_error(prefix_of(*command_) + "flag '" + std::string(flag) + "' is required");
}

std::uint64_t Args::get_u64(std::string_view flag, std::uint64_t fallback) const {
  auto text = get(flag);
  if (!text) return fallback;
  if (auto v = parse_u64(*text)) return *v;
  const bool digits = !text->empty() && std::all_of(text->begin(), text->end(), [](char c) { return c >= '0' && c <= '9'; });
  usage_error(prefix_of(*command_) + std::string(flag) + ": '" + *text + "' is " +
              (digits ? "too large (at most 18446744073709551615)" : "not a non-negative integer"));
}

void Args::add(std::string_view flag, std::string value) {
  values_.emplace_back(std::string(flag), std::move(value));
}

void Args::note_flag_as_value(std::string_view flag, std::string_view value) {
  if (flag_as_value_.empty())
    flag_as_value_ = "'" + std::string(flag) + "' took '" + std::string(value) + "' as its value; did you leave out " +
                     std::string(flag) + "'s value?";
}

std::optional<std::uint64_t> parse_u64(std::string_view text) {
  std::uint64_t v = 0;
  if (text.empty() || text[0] == '+' || text[0] == '-') return std::nullopt;
  auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), v);
  if (ec != std::errc() || end != text.data() + text.size()) return std::nullopt;
  return v;
}

bool wants_help(const Command& command, std::span<const std::string> argv) {
  for (std::size_t i = 0; i < argv.size(); ++i) {
    const std::string& a = argv[i];
    if (a == "--") return false;
    if (a == "-h" || a == "--help") return true;
    // The next argument is this flag's value, whatever it looks like, as parse_args takes it: a
    // child node named "-h" (`tahvel link DIR --child -h`, as `up` runs it) is not a request for
    // help, which would print the usage and exit 0 in place of running the link.
    if (looks_like_flag(a) && !(a.starts_with("--") && a.find('=') != std::string::npos))
      if (const Flag* flag = find_flag(command, a); flag && !flag->value.empty()) ++i;
  }
  return false;
}

Args parse_args(const Command& command, std::span<const std::string> argv) {
  Args args(command);
  bool flags_done = false;
  for (std::size_t i = 0; i < argv.size(); ++i) {
    if (!flags_done && argv[i] == "--") {
      flags_done = true;
    } else if (!flags_done && looks_like_flag(argv[i])) {
      i = take_flag(command, argv, i, args);
    } else {
      args.add_positional(argv[i]);
    }
  }
  check_positional_count(command, args);
  return args;
}

void print_help(std::ostream& out, const Command& command) {
  out << "usage: tahvel " << command.name << " " << command.usage << "\n\n"
      << command.summary << "\n";
  if (!command.description.empty()) out << "\n" << command.description << "\n";
  out << "\noptions:\n";
  print_flags(out, command.flags);
  for (const Flag& f : common_flags())
    if (command.takes_prefix || f.name != "--prefix") print_flags(out, {f});
}

}  // namespace tahvel::cli
