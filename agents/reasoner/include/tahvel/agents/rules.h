// The reasoner's rule language and its incremental evaluator, independent of any store: parse a
// rule file into a Program, feed an Engine with the base facts that were added and removed, and
// get back the conclusions that appeared and disappeared (docs/reasoner.md).
//
//   auto program = tahvel::reasoner::parse_rules(text, {.file = "spo2.rules",
//                                                        .default_ns = "http://x/#",
//                                                        .me = "http://x/home1"});
//   tahvel::reasoner::Engine engine(*program);
//   auto update = engine.apply(inserted, removed, now_ns);   // update.added, update.removed
//
// Language (the Prolog-like syntax of the thesis, Papers 2 and 5): `pred(S, O)` is the triple
// S pred O; `fact(S, P, O)` is a triple with any predicate; predicates of other arity are
// relations of their own whose conclusions are stored reified. Variables start upper-case or
// with `_`; constants are <iri>, CURIEs (p:local with `@prefix p: <iri> .` or
// `:- prefix(p, <iri>).`), `#name` and bare lower-case atoms (IRIs in the default namespace),
// `me` (the node IRI), "strings" (optionally ^^datatype or @lang), 'quoted' strings and numbers.
// Body literals: atoms, `\+ atom` (negation as failure, stratified), comparisons
// `< > =< >= =:= =\=` on numbers and times, `X is Expr` (+ - * /), `=`, `\=`, `==`, `\==`,
// `now(T)`, `now` inside expressions, `lesstime(A, B)`, and `!`: the alternatives of a
// predicate are ranked when one of them contains a cut (or with `:- ranked(p/N).`): for each
// value of all arguments but the last, only the first alternative in file order whose literals
// before its cut hold gives conclusions (doctor > rule system > default).
//
// Workload: a few hundred rules, thousands to millions of facts, sessions every second or so
// with few new facts; tuned for the session after a few new facts (semi-naive, in memory).
#pragma once

#include <cstdint>
#include <filesystem>
#include <memory>
#include <span>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "tahvel/node/term.h"
#include "tahvel/uri/expected.h"
#include "tahvel/uri/iri.h"

namespace tahvel::reasoner {

// The library's one error: a message naming the cause and its place ("spo2.rules:4:12: ...").
struct Error {
  std::string message;
};

template <class T>
using Result = Expected<T, Error>;

struct ParseOptions {
  std::string file = "<rules>";  // named in error messages
  std::string default_ns;        // namespace of #name and bare atoms (absolute IRI, required)
  std::string me;                // the node IRI that `me` stands for (absolute IRI, required)
  uri::PrefixMap prefixes = uri::PrefixMap::standard();  // CURIEs; the file may add more
};

// A parsed and checked rule set: ranked alternatives and demand-bound defaults rewritten into
// stratified rules (docs/reasoner.md, "Compilation"). Immutable; share it between engines.
class Program;

// Parses and checks `text`. Errors name file, line and column: syntax, unknown prefix, unsafe
// variables (a head or negated variable that no positive literal binds and no caller binds),
// negation or ranking through recursion (not stratified), a conclusion with a variable
// predicate, a cut inside a negation.
Result<std::shared_ptr<const Program>> parse_rules(std::string_view text, const ParseOptions& options);

// The bytes of the rule file at `path`. Error when it cannot be read, or is a directory.
Result<std::string> read_rule_file(const std::filesystem::path& path);

// Reads `path` and parses it with options.file = path. Error when the file cannot be read.
Result<std::shared_ptr<const Program>> load_rules(const std::filesystem::path& path, ParseOptions options);

// Number of rules of the program as written (clauses, without the rewriting).
std::size_t rule_count(const Program& program);

// A predicate the rules read as triples and no rule concludes: only the board's facts give it.
struct BasePredicate {
  std::string iri;
  std::string where;  // file:line:col of the first literal reading it
  // The arities the rules conclude the IRI with (never 2): `\+ low(W, _)` beside rules of
  // low/1 reads triples that none of those rules writes.
  std::vector<std::uint32_t> concluded_arities;
};

// The program's base predicates, in the order the rules first read them.
std::vector<BasePredicate> base_predicates(const Program& program);

// A conclusion: a predicate IRI and its arguments. Arity 2 is the triple args[0] predicate
// args[1]; other arities are stored reified (see store_form).
struct Atom {
  std::string predicate;
  std::vector<node::Term> args;
  friend bool operator==(const Atom&, const Atom&) = default;
  std::string to_string() const;  // N-Triples terms: <p>(<s>, "1"^^<...>)
};
bool operator<(const Atom& a, const Atom& b);

// The triples a conclusion is stored as. A binary atom whose subject is an IRI or blank node is
// the triple itself. Any other atom is a node N = `node_prefix` + 16 hex digits of a hash of the
// atom, with N rdf:type <predicate> and N rdf:_1 args[0], N rdf:_2 args[1], ... (arity 0: the
// type triple only).
std::vector<node::Triple> store_form(const Atom& atom, std::string_view node_prefix);

struct EngineStats {
  std::size_t base_facts = 0;       // distinct base triples held
  std::size_t conclusions = 0;      // distinct conclusions held
  std::size_t derivations = 0;      // rule firings of the last apply (incl. repeated ones)
  std::size_t strata_run = 0;       // strata evaluated by the last apply
  std::size_t strata_recomputed = 0;  // of which recomputed from scratch (removal, negation, now)
  std::size_t rows = 0;             // rows held, including those of facts that went (see compact)
  std::size_t terms = 0;            // terms interned
};

// Thrown by Engine::apply (and recompute, reload) when one call derives more than two million
// conclusions: rules whose conclusion gives itself new values never stop, and took all the
// memory there is. The message names the rule file, line and column of the rule that was
// deriving. The engine is then unusable: make a new one.
struct RunawayDerivation : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// Incremental evaluator. Holds the base facts it was given (only those whose predicate some
// rule reads, see relevant()) and all conclusions. Not thread-safe; one thread at a time.
class Engine {
 public:
  explicit Engine(std::shared_ptr<const Program> program);
  Engine(Engine&&) noexcept;
  Engine& operator=(Engine&&) noexcept;
  ~Engine();

  struct Update {
    std::vector<Atom> added;    // conclusions that hold now and did not before (any order)
    std::vector<Atom> removed;  // conclusions that held before and lost all support (any order)
  };

  // Applies base changes (each inserted triple counts once per call; the same triple inserted
  // twice needs two removals to go, as records do) and brings every conclusion up to date:
  // semi-naive from the inserted facts where the strata allow it, recomputation of the strata
  // that a removal, a change under negation or `now` (= now_ns, ns since the epoch) reaches.
  // Removals of facts not held are ignored.
  Update apply(std::span<const node::Triple> inserted, std::span<const node::Triple> removed,
               std::int64_t now_ns);

  // Replaces the rules, keeps the base facts, recomputes everything; the update is the
  // difference between the old program's conclusions and the new one's. The engine holds only
  // the facts the old rules read: facts of a predicate only the new rules read are not there
  // (the reasoner agent reads its board again on a reload instead).
  Update reload(std::shared_ptr<const Program> program, std::int64_t now_ns);

  // Derives everything again from the base facts held, as a first session does (all strata
  // recomputed). The update is empty unless `now` changed a conclusion. For measurements and
  // checks: the cost of a from-scratch evaluation without reading any store.
  Update recompute(std::int64_t now_ns);

  // Rebuilds the engine from the base facts it holds: rows of facts that went and terms no
  // longer used are dropped (rows never move while the engine runs, so they accumulate). The
  // update is empty unless `now` changed a conclusion.
  Update compact(std::int64_t now_ns);

  // All conclusions held, sorted.
  std::vector<Atom> conclusions() const;

  // True when some rule reads triples with this predicate (all are, when a rule reads
  // fact(S, P, O) with a variable P).
  bool relevant(std::string_view predicate_iri) const;

  EngineStats stats() const;

  // The conclusions one apply may derive before it throws RunawayDerivation (default two
  // million).
  void set_conclusion_limit(std::size_t limit);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace tahvel::reasoner
