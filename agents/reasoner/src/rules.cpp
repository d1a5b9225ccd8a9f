// Public entry points of the rule language (rules.h): parsing, atoms and their stored form.
#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <set>

#include "program.h"

namespace tahvel::reasoner {

Result<std::shared_ptr<const Program>> parse_rules(std::string_view text, const ParseOptions& options) {
  auto program = parse_program(text, options);
  if (!program) return unexpected(program.error());
  if (auto c = compile_program(**program); !c) return unexpected(c.error());
  return std::shared_ptr<const Program>(std::move(*program));
}

Result<std::string> read_rule_file(const std::filesystem::path& path) {
  // A directory opens as an empty stream: read as no rules, it would retract every conclusion.
  if (std::error_code ec; std::filesystem::is_directory(path, ec))
    return unexpected(Error{path.string() + ": cannot read the rule file: it is a directory"});
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return unexpected(Error{path.string() + ": cannot read the rule file: " + std::strerror(errno)});
  // read(2), not a stream: `out << in.rdbuf()` stops at a read error as at the end of the file,
  // and a rule file cut short that way still parses (fewer rules: the rest retracted).
  std::string text;
  char buffer[65536];
  for (;;) {
    const ssize_t got = ::read(fd, buffer, sizeof buffer);
    if (got == 0) break;
    if (got < 0) {
      if (errno == EINTR) continue;
      const int error = errno;
      ::close(fd);
      return unexpected(Error{path.string() + ": error while reading the rule file: " + std::strerror(error)});
    }
    text.append(buffer, static_cast<std::size_t>(got));
  }
  ::close(fd);
  return text;
}

Result<std::shared_ptr<const Program>> load_rules(const std::filesystem::path& path, ParseOptions options) {
  auto text = read_rule_file(path);
  if (!text) return unexpected(text.error());
  options.file = path.string();
  return parse_rules(*text, options);
}

std::size_t rule_count(const Program& program) { return program.written_rules; }

std::vector<BasePredicate> base_predicates(const Program& program) {
  std::vector<bool> concluded(program.preds.size(), false), named(program.preds.size(), false);
  for (const Rule& rule : program.rules) concluded[rule.head] = true;
  std::vector<BasePredicate> out;
  for (const Rule& rule : program.rules)
    for (const Literal& lit : rule.body) {
      if ((lit.kind != Literal::atom && lit.kind != Literal::negation) || lit.pred == kAnyBinary) continue;
      const Pred& pred = program.preds[lit.pred];
      if (pred.arity != 2 || pred.internal || concluded[lit.pred] || named[lit.pred]) continue;
      named[lit.pred] = true;
      std::set<std::uint32_t> arities;
      for (const Rule& other : program.rules)
        if (program.preds[other.head].iri == pred.iri) arities.insert(program.preds[other.head].arity);
      out.push_back({pred.iri, where(program, lit.pos), {arities.begin(), arities.end()}});
    }
  return out;
}

std::string Atom::to_string() const {
  std::string out = "<" + predicate + ">(";
  for (std::size_t i = 0; i < args.size(); ++i) out += (i ? ", " : "") + args[i].to_ntriples();
  return out + ")";
}

bool operator<(const Atom& a, const Atom& b) {
  if (a.predicate != b.predicate) return a.predicate < b.predicate;
  std::size_t n = std::min(a.args.size(), b.args.size());
  for (std::size_t i = 0; i < n; ++i) {
    const node::Term& x = a.args[i];
    const node::Term& y = b.args[i];
    if (x == y) continue;
    return std::tie(x.kind, x.value, x.datatype, x.language) < std::tie(y.kind, y.value, y.datatype, y.language);
  }
  return a.args.size() < b.args.size();
}

std::vector<node::Triple> store_form(const Atom& atom, std::string_view node_prefix) {
  if (atom.args.size() == 2 && !atom.args[0].is_literal())
    return {{atom.args[0], node::Term::iri(atom.predicate), atom.args[1]}};
  std::uint64_t h = 1469598103934665603ull;  // FNV-1a 64 of the atom's text
  for (unsigned char c : atom.to_string()) h = (h ^ c) * 1099511628211ull;
  char hex[17];
  std::snprintf(hex, sizeof hex, "%016llx", static_cast<unsigned long long>(h));
  node::Term n = node::Term::iri(std::string(node_prefix) + hex);
  std::vector<node::Triple> out{{n, node::Term::iri(std::string(node::kRdfType)), node::Term::iri(atom.predicate)}};
  const std::string rdf = "http://www.w3.org/1999/02/22-rdf-syntax-ns#_";
  for (std::size_t i = 0; i < atom.args.size(); ++i)
    out.push_back({n, node::Term::iri(rdf + std::to_string(i + 1)), atom.args[i]});
  return out;
}

}  // namespace tahvel::reasoner
