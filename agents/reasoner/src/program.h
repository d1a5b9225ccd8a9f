// The compiled form of a rule file, shared by the parser (parse.cpp), the compiler
// (compile.cpp) and the evaluator (engine.cpp). Private to the reasoner.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "tahvel/agents/rules.h"

namespace tahvel::reasoner {

struct Pos {
  int line = 0, col = 0;
};

// A rule argument: a variable (index into the rule's variables) or a constant (index into
// Program::constants).
struct Arg {
  bool is_var = false;
  std::uint32_t index = 0;
  friend bool operator==(const Arg&, const Arg&) = default;
};

// An arithmetic expression over arguments and `now`.
struct Expr {
  enum Kind { arg, now, add, sub, mul, div, neg } kind = arg;
  Arg leaf;
  std::shared_ptr<Expr> a, b;
  std::uint32_t depth = 1;  // levels of the tree; the parser bounds it, as evaluation recurses
};

// Predicate index kAnyBinary: fact(S, P, O) with a variable P (args = S, P, O).
inline constexpr std::uint32_t kAnyBinary = 0xffffffffu;

struct Literal {
  enum Kind {
    atom,      // pred(args)
    negation,  // \+ pred(args)
    compare,   // lhs op rhs on values
    assign,    // lhs is rhs (lhs an argument)
    unify,     // lhs = rhs (terms)
    not_unify, // lhs \= rhs, lhs \== rhs
    identical, // lhs == rhs
    skolem,    // skolem(L, A1, ..., An): L = the IRI minted from A1..An (args)
    cut,       // ! (only before compilation)
  } kind = atom;
  std::uint32_t pred = 0;  // atom, negation: index into Program::preds or kAnyBinary
  std::vector<Arg> args;
  enum Op { lt, gt, le, ge, eq, ne } op = lt;
  Expr lhs, rhs;
  Pos pos;
};

// A bound on the values of one argument of an atom, taken from a comparison of the body:
// `V + o1 - o2 ... op other` (V alone on one side, plus or minus terms that do not contain it)
// bounds V by other - o1 + o2 ... (docs/reasoner.md, "Range scans"). The comparison stays in the
// body and is checked on every row; the bound only narrows which rows are tried.
struct RangeBound {
  bool lower = false, upper = false;  // V >= bound, V =< bound (strict comparisons widened)
  Expr other;
  std::vector<std::pair<bool, Expr>> offsets;  // (subtracted, term) of V's side
};

// The argument of an atom read through a sorted index, and its bounds (position -1: none).
struct RangeScan {
  int position = -1;
  std::vector<RangeBound> bounds;
};

// A run of plan steps, from an atom that shares no variable with the steps before it, whose
// atoms (two or more) are joined among themselves only: what they bind does not depend on the
// bindings before the run, only whether those pass its `cross` filters (comparisons and
// negations that also read earlier variables: a time window between the run's events and the
// outer sample). The evaluator re-enumerates it per outer binding while that is cheap, then
// keeps its bindings of `exported` once and replays them, through `range` when a comparison
// bounds one of them (docs/reasoner.md, "Independent parts").
struct Memo {
  std::uint32_t end = 0;                // the step after the run; 0: no run starts here
  std::vector<std::uint32_t> exported;  // its variables that later steps, cross filters or the head read
  std::vector<std::uint32_t> cross;     // steps of its cross filters
  RangeScan range;                      // position: index into exported
};

struct Pred {
  std::string iri;       // user predicates: the IRI; internal ones: a descriptive name
  std::uint32_t arity = 0;
  bool internal = false;  // demand and ranking helpers: never stored, never reported
  bool ranked = false;    // declared with :- ranked(p/N).
};

struct Rule {
  std::uint32_t head = 0;      // index into preds
  std::vector<Arg> head_args;
  std::vector<Literal> body;   // as written (after rewriting), evaluation order in plans
  std::uint32_t vars = 0;      // number of variables
  std::vector<std::string> var_names;
  std::vector<Pos> var_pos;    // where each variable is first written (errors name it there)
  bool uses_now = false;
  Pos pos;
  // Evaluation orders: plans[0] the full body (naive round: its first atom as written, then
  // the most bound atom at each step); plans[1 + k] starts with the k-th
  // positive atom of the body (the delta literal of a semi-naive round), kth_atom[k] its index.
  std::vector<std::vector<std::uint32_t>> plans;
  std::vector<std::uint32_t> kth_atom;
  // Per plan: the step from which every head variable is bound. There the evaluator stops when
  // the head is already derived (the rest could only derive it again: Prolog's once/1 for the
  // variables that do not reach the head).
  std::vector<std::uint32_t> ready;
  // Orders that start with a negated literal read as positive (over the rows its relation
  // gained), for finding the conclusions a growing negated relation may take away.
  std::vector<std::vector<std::uint32_t>> neg_plans;
  std::vector<std::uint32_t> neg_literal;
  // Per plan (and per negation plan), per step: the range scan of the atom at that step.
  std::vector<std::vector<RangeScan>> plan_ranges, neg_plan_ranges;
  // Per plan, per step: the independent run that starts there (Memo::end 0: none).
  std::vector<std::vector<Memo>> plan_memos, neg_plan_memos;
};

struct Stratum {
  std::vector<std::uint32_t> preds;  // defined here
  std::vector<std::uint32_t> rules;
  bool volatile_ = false;            // some rule uses now: recomputed every session
  bool recursive = false;            // some rule reads a predicate of this stratum
};

class Program {
 public:
  std::string file;
  std::string me;
  std::vector<node::Term> constants;
  std::vector<Pred> preds;
  std::vector<Rule> rules;
  std::vector<Stratum> strata;  // in evaluation order
  std::vector<std::uint32_t> read_binary;  // binary predicates some rule reads
  bool reads_any_binary = false;           // some rule reads fact(S, P, O) with a variable P
  std::vector<std::pair<std::uint32_t, Pos>> ranked_declarations;  // :- ranked(p/N): pred, position of p
  std::size_t written_rules = 0;
};

// parse.cpp: text to rules as written (cuts kept, no plans).
Result<std::shared_ptr<Program>> parse_program(std::string_view text, const ParseOptions& options);
// compile.cpp: ranking and demand rewriting, safety, strata, plans.
Result<void> compile_program(Program& program);

std::string where(const Program& program, Pos pos);

}  // namespace tahvel::reasoner
