// From rules as written to rules the evaluator runs (docs/reasoner.md, "Compilation"):
//  1. demand: a head variable that no body literal binds (Prolog's `p(P, T) :- T = 97.`) is
//     bound by the callers: the rule gets a demand literal, and each call of p gets a rule
//     deriving that demand from the literals written before the call (a magic-set rewriting
//     restricted to the rules that need it);
//  2. ranking: alternative j of a ranked predicate gets `\+ applies_i(key)` for each earlier
//     alternative i with a cut, applies_i(key) holding when i's literals before its cut do;
//  3. safety and evaluation orders (plans) for the naive round and for each delta literal, with
//     per step the range scan a comparison allows and the independent run that starts there
//     (docs/reasoner.md, "Joins");
//  4. strata: strongly connected components of the graph of head patterns (the rules of a
//     predicate whose heads have the same constants) in dependency order; a negation inside a
//     component is an error.
#include <algorithm>
#include <limits>
#include <deque>
#include <functional>
#include <iterator>
#include <map>
#include <optional>
#include <set>

#include "program.h"

namespace tahvel::reasoner {

namespace {

using VarSet = std::vector<bool>;

void expr_vars(const Expr& e, std::vector<std::uint32_t>& out) {
  if (e.kind == Expr::arg) {
    if (e.leaf.is_var) out.push_back(e.leaf.index);
  } else {
    if (e.a) expr_vars(*e.a, out);
    if (e.b) expr_vars(*e.b, out);
  }
}

// Variables a literal needs bound before it runs, and those it binds.
void needs_and_binds(const Literal& l, const VarSet& bound, std::vector<std::uint32_t>& needs,
                     std::vector<std::uint32_t>& binds) {
  needs.clear();
  binds.clear();
  switch (l.kind) {
    case Literal::atom:
      for (const Arg& a : l.args) if (a.is_var) binds.push_back(a.index);
      break;
    case Literal::negation:
      for (const Arg& a : l.args) if (a.is_var) needs.push_back(a.index);
      break;
    case Literal::assign:
      expr_vars(l.rhs, needs);
      if (l.lhs.leaf.is_var) binds.push_back(l.lhs.leaf.index);
      break;
    case Literal::skolem:
      for (std::size_t i = 1; i < l.args.size(); ++i) if (l.args[i].is_var) needs.push_back(l.args[i].index);
      if (l.args[0].is_var) binds.push_back(l.args[0].index);
      break;
    case Literal::unify: {
      bool left_bound = !l.lhs.leaf.is_var || bound[l.lhs.leaf.index];
      bool right_bound = !l.rhs.leaf.is_var || bound[l.rhs.leaf.index];
      if (!left_bound && !right_bound) needs.push_back(l.rhs.leaf.index);
      if (l.lhs.leaf.is_var) binds.push_back(l.lhs.leaf.index);
      if (l.rhs.leaf.is_var) binds.push_back(l.rhs.leaf.index);
      break;
    }
    default:
      expr_vars(l.lhs, needs);
      expr_vars(l.rhs, needs);
      break;
  }
}

bool runnable(const Literal& l, const VarSet& bound) {
  std::vector<std::uint32_t> needs, binds;
  needs_and_binds(l, bound, needs, binds);
  return std::all_of(needs.begin(), needs.end(), [&](std::uint32_t v) { return bound[v]; });
}

void bind_vars(const Literal& l, VarSet& bound) {
  std::vector<std::uint32_t> needs, binds;
  needs_and_binds(l, bound, needs, binds);
  for (std::uint32_t v : binds) bound[v] = true;
}

// A comparison that bounds a variable V (program.h, RangeBound): V's side is V plus or minus
// terms without V; `needs` are the variables of the other side and of those terms, which must be
// bound before the atom that binds V for the bound to be known there.
struct RangeCandidate {
  std::uint32_t var = 0;
  RangeBound bound;
  std::vector<std::uint32_t> needs;
};

bool mentions(const Expr& e, std::uint32_t var) {
  std::vector<std::uint32_t> vars;
  expr_vars(e, vars);
  return std::find(vars.begin(), vars.end(), var) != vars.end();
}

// V when `e` is V + t1 - t2 ... with no t mentioning V (the terms go to `offsets`), else nothing.
std::optional<std::uint32_t> peel(const Expr& e, std::vector<std::pair<bool, Expr>>& offsets) {
  if (e.kind == Expr::arg) return e.leaf.is_var ? std::optional(e.leaf.index) : std::nullopt;
  if (e.kind != Expr::add && e.kind != Expr::sub) return std::nullopt;
  std::vector<std::pair<bool, Expr>> mine = offsets;
  if (auto v = peel(*e.a, mine); v && !mentions(*e.b, *v)) {
    mine.emplace_back(e.kind == Expr::sub, *e.b);
    offsets = std::move(mine);
    return v;
  }
  if (e.kind == Expr::sub) return std::nullopt;  // t - V: V with a negative sign
  mine = offsets;
  if (auto v = peel(*e.b, mine); v && !mentions(*e.a, *v)) {
    mine.emplace_back(false, *e.a);
    offsets = std::move(mine);
    return v;
  }
  return std::nullopt;
}

std::vector<RangeCandidate> range_candidates(const Rule& rule) {
  std::vector<RangeCandidate> out;
  for (const Literal& l : rule.body) {
    if (l.kind != Literal::compare || l.op == Literal::ne) continue;
    const bool below = l.op == Literal::lt || l.op == Literal::le || l.op == Literal::eq;  // lhs =< rhs
    const bool above = l.op == Literal::gt || l.op == Literal::ge || l.op == Literal::eq;  // lhs >= rhs
    for (int side = 0; side < 2; ++side) {
      const Expr& mine = side == 0 ? l.lhs : l.rhs;
      const Expr& other = side == 0 ? l.rhs : l.lhs;
      RangeCandidate c;
      auto v = peel(mine, c.bound.offsets);
      if (!v || mentions(other, *v)) continue;
      c.var = *v;
      c.bound.other = other;
      c.bound.upper = side == 0 ? below : above;
      c.bound.lower = side == 0 ? above : below;
      expr_vars(other, c.needs);
      for (const auto& [subtracted, term] : c.bound.offsets) expr_vars(term, c.needs);
      out.push_back(std::move(c));
    }
  }
  return out;
}

// The sides (0, 1 or 2) from which comparisons runnable under `bound` bound `var`.
int range_sides(std::uint32_t var, const std::vector<RangeCandidate>& ranges, const VarSet& bound) {
  bool lower = false, upper = false;
  for (const RangeCandidate& c : ranges) {
    if (c.var != var || !std::all_of(c.needs.begin(), c.needs.end(), [&](std::uint32_t v) { return bound[v]; }))
      continue;
    lower |= c.bound.lower;
    upper |= c.bound.upper;
  }
  return int{lower} + int{upper};
}

// How bound an atom is: a fully bound atom is a lookup; a bound variable or constant follows an
// index; a variable that comparisons bound is a scan of part of a sorted index — a window
// (both sides, such as a time window) counts for more than a lone constant, a half-open range
// (H > 90) for less than a window, neither for as much as an equality.
int boundness(const Literal& l, const VarSet& bound, const std::vector<RangeCandidate>& ranges) {
  int vars = 0, consts = 0, total = 0, ranged = 0;
  for (std::size_t i = 0; i < l.args.size(); ++i) {
    const Arg& a = l.args[i];
    if (l.pred == kAnyBinary && i == 1) continue;  // the predicate picks the relation
    ++total;
    if (!a.is_var) ++consts;
    else if (bound[a.index]) ++vars;
    else if (l.pred != kAnyBinary) ranged = std::max(ranged, range_sides(a.index, ranges, bound));
  }
  return (vars + consts == total ? 1000 : 0) + 10 * vars + 3 * ranged + consts;
}

// Named where the variable is first written (the literal's start named another variable's place:
// `Y > W` said W at Y's column), or at the literal when that is not known.
Unexpected<Error> unbound_before(const Program& program, const Rule& rule, const Literal& l, std::uint32_t var) {
  // First written before the literal (in the head, or a literal that binds nothing): the
  // literal is where the error is.
  Pos pos = var < rule.var_pos.size() ? rule.var_pos[var] : l.pos;
  if (pos.line < l.pos.line || (pos.line == l.pos.line && pos.col < l.pos.col)) pos = l.pos;
  const std::string variable = var < rule.var_names.size() ? rule.var_names[var] : "?";
  // Order counts for a negation only (RS6); "before it" sent the author of a comparison to
  // reorder literals, which does not help (RS9: bound by nothing).
  return unexpected(Error{where(program, pos) + ": variable " + variable +
                          (l.kind == Literal::negation ? " is not bound by any positive literal before it (unsafe; for 'any value' write _ there)"
                                                       : " is not bound by any positive literal of the rule (unsafe)")});
}

// An evaluation order of `body` following `preference`: filters (built-ins, negations) as soon
// as their variables are bound, atoms in preference order. Error names the literal that can
// never run and its unbound variable.
// With `greedy`, atoms after the first go by how bound they are (a fully bound atom is a
// lookup; an atom sharing a bound variable follows an index rather than starting a cross
// product; a variable that a comparison bounds is a range scan), ties in preference order.
Result<std::vector<std::uint32_t>> plan(const Program& program, const Rule& rule,
                                        std::vector<std::uint32_t> preference, VarSet bound,
                                        bool greedy = false) {
  const std::vector<RangeCandidate> ranges = range_candidates(rule);
  std::vector<std::uint32_t> order;
  while (!preference.empty()) {
    auto pick = std::find_if(preference.begin(), preference.end(), [&](std::uint32_t i) {
      return rule.body[i].kind != Literal::atom && runnable(rule.body[i], bound);
    });
    if (pick == preference.end()) {
      pick = std::find_if(preference.begin(), preference.end(),
                          [&](std::uint32_t i) { return rule.body[i].kind == Literal::atom; });
      if (greedy && (!order.empty() || std::find(bound.begin(), bound.end(), true) != bound.end())) {
        int best = -1;
        for (auto it = preference.begin(); it != preference.end(); ++it) {
          if (rule.body[*it].kind != Literal::atom) continue;
          int score = boundness(rule.body[*it], bound, ranges);
          if (score > best) { best = score; pick = it; }
        }
      }
    }
    if (pick == preference.end()) {
      const Literal& l = rule.body[preference.front()];
      std::vector<std::uint32_t> needs, binds;
      needs_and_binds(l, bound, needs, binds);
      std::uint32_t var = std::numeric_limits<std::uint32_t>::max();
      for (std::uint32_t v : needs) if (!bound[v]) { var = v; break; }
      return unbound_before(program, rule, l, var);
    }
    bind_vars(rule.body[*pick], bound);
    order.push_back(*pick);
    preference.erase(pick);
  }
  return order;
}

// Variables bound, starting from `bound`, by running every runnable literal among the body's
// first `count` to a fixpoint (order-free).
VarSet reachable_bindings(const Rule& rule, std::size_t count, VarSet bound) {
  for (bool changed = true; changed;) {
    changed = false;
    for (std::size_t i = 0; i < count; ++i) {
      const Literal& l = rule.body[i];
      if (l.kind == Literal::cut || !runnable(l, bound)) continue;
      VarSet before = bound;
      bind_vars(l, bound);
      changed |= before != bound;
    }
  }
  return bound;
}

VarSet reachable_bindings(const Rule& rule) {
  return reachable_bindings(rule, rule.body.size(), VarSet(rule.vars, false));
}

std::uint32_t add_pred(Program& program, std::string name, std::uint32_t arity) {
  program.preds.push_back(Pred{std::move(name), arity, true, false});
  return static_cast<std::uint32_t>(program.preds.size() - 1);
}

Literal atom_literal(std::uint32_t pred, std::vector<Arg> args, Pos pos, bool negated = false) {
  Literal l;
  l.kind = negated ? Literal::negation : Literal::atom;
  l.pred = pred;
  l.args = std::move(args);
  l.pos = pos;
  return l;
}

// Cut positions: index of the first literal after the cut (= number of literals before it),
// or -1. The cut literal is removed from the body.
Result<std::vector<int>> take_cuts(Program& program) {
  std::vector<int> cuts;
  for (Rule& rule : program.rules) {
    int cut = -1;
    for (std::size_t i = 0; i < rule.body.size(); ++i) {
      if (rule.body[i].kind != Literal::cut) continue;
      if (cut >= 0) return unexpected(Error{where(program, rule.body[i].pos) + ": a second cut in one rule"});
      cut = static_cast<int>(i);
    }
    if (cut >= 0) rule.body.erase(rule.body.begin() + cut);
    if (cut < 0 && program.preds[rule.head].ranked) cut = static_cast<int>(rule.body.size());
    cuts.push_back(cut);
  }
  return cuts;
}

// Every variable a literal mentions (with repeats).
void literal_vars(const Literal& l, std::vector<std::uint32_t>& out) {
  for (const Arg& a : l.args) if (a.is_var) out.push_back(a.index);
  expr_vars(l.lhs, out);
  expr_vars(l.rhs, out);
}

// Step 0: a negation's anonymous variables (`_`, `_Name`) that occur nowhere else in its rule
// are existential, as in Prolog: `\+ knows(X, _)` holds when X knows no one. (A named variable
// there stays an error: more often a typo than meant.) The negation becomes
// `\+ h(X)` with a helper rule `h(X) :- knows(X, _)`, so that the evaluator only ever negates
// fully bound atoms.
void add_existential_negations(Program& program, std::vector<int>& cuts) {
  const std::size_t written = program.rules.size();
  for (std::size_t r = 0; r < written; ++r) {
    for (std::size_t i = 0; i < program.rules[r].body.size(); ++i) {
      Rule& rule = program.rules[r];
      Literal& neg = rule.body[i];
      if (neg.kind != Literal::negation) continue;
      std::vector<std::uint32_t> elsewhere;
      for (const Arg& a : rule.head_args) if (a.is_var) elsewhere.push_back(a.index);
      for (std::size_t k = 0; k < rule.body.size(); ++k) if (k != i) literal_vars(rule.body[k], elsewhere);
      std::vector<Arg> kept;
      bool existential = false;
      for (const Arg& a : neg.args) {
        if (!a.is_var) continue;
        if (rule.var_names[a.index][0] == '_' &&
            std::find(elsewhere.begin(), elsewhere.end(), a.index) == elsewhere.end())
          existential = true;
        else if (std::find(kept.begin(), kept.end(), a) == kept.end()) kept.push_back(a);
      }
      if (!existential) continue;
      const std::string called = neg.pred == kAnyBinary ? std::string("fact/3") : program.preds[neg.pred].iri;
      Rule helper;
      helper.head = add_pred(program, "some " + called + " for " + where(program, neg.pos),
                             static_cast<std::uint32_t>(kept.size()));
      helper.head_args = kept;
      helper.body.push_back(neg);
      helper.body.back().kind = Literal::atom;
      helper.vars = rule.vars;
      helper.var_names = rule.var_names;
      helper.var_pos = rule.var_pos;
      helper.pos = neg.pos;
      neg.pred = helper.head;
      neg.args = kept;
      program.rules.push_back(std::move(helper));  // invalidates `rule` and `neg`
      cuts.push_back(-1);
    }
  }
}

struct Demand {
  std::vector<std::uint32_t> positions;  // head argument positions the callers bind
  std::uint32_t pred = 0;
  Pos pos;               // the first rule that needs it, and
  std::string variable;  // its first head variable from the callers, for the error when none calls
  // When a literal would bind `variable` but needs a variable that nothing binds (Z in
  // `a(X, Y) :- b(X), Y is Z + 1.`): that variable and the literal, which the error names instead.
  std::string unbound_need;
  Pos unbound_need_pos;
  // Per head argument position callers must bind: the first alternative that needs it and the
  // name of its head variable there, for the error at a call that leaves it unbound.
  std::map<std::uint32_t, std::pair<Pos, std::string>> needed_by;
};

// The variable that keeps `rule` from binding head variable `head_var`, and the literal that
// needs it: following what a literal that would bind a variable needs (Y in `Y is W + 1`, then W
// in `W is V * 2`), the first variable no literal binds at all (V). nullopt when there is none
// (the chain loops: `Y is W + 1, W is Y - 1`).
std::optional<std::pair<std::uint32_t, Pos>> unbound_need_of(const Rule& rule, std::uint32_t head_var) {
  const VarSet bound = reachable_bindings(rule);
  VarSet bindable(rule.vars, false), visited(rule.vars, false);
  for (const Literal& l : rule.body) {
    std::vector<std::uint32_t> needs, binds;
    needs_and_binds(l, bound, needs, binds);
    for (std::uint32_t v : binds) bindable[v] = true;
  }
  std::vector<std::uint32_t> todo{head_var};
  while (!todo.empty()) {
    const std::uint32_t var = todo.back();
    todo.pop_back();
    if (visited[var]) continue;
    visited[var] = true;
    for (const Literal& l : rule.body) {
      std::vector<std::uint32_t> needs, binds;
      needs_and_binds(l, bound, needs, binds);
      if (std::find(binds.begin(), binds.end(), var) == binds.end()) continue;
      for (std::uint32_t v : needs) {
        if (bound[v] || visited[v]) continue;
        if (!bindable[v]) return std::make_pair(v, l.pos);
        todo.push_back(v);
      }
    }
  }
  return std::nullopt;
}

// Head argument positions a rule needs from its callers (RS8): those of the head variables that
// no body literal binds; then, while the body with those known still leaves head variables
// unbound (both sides of X = Y), the leftmost of them. A variable that a literal binds once the
// callers' are known (L in `limit(A, L) :- L is 130 - A.`, Y in `id(X, Y) :- Y = X.`) is not one.
std::vector<std::uint32_t> demand_positions(const Rule& rule) {
  VarSet bindable(rule.vars, false);
  for (const Literal& l : rule.body) {
    std::vector<std::uint32_t> needs, binds;
    needs_and_binds(l, VarSet(rule.vars, false), needs, binds);
    for (std::uint32_t v : binds) bindable[v] = true;
  }
  std::vector<std::uint32_t> positions;
  VarSet from_callers(rule.vars, false);
  for (std::size_t i = 0; i < rule.head_args.size(); ++i) {
    const Arg& a = rule.head_args[i];
    if (!a.is_var || bindable[a.index]) continue;
    positions.push_back(static_cast<std::uint32_t>(i));
    from_callers[a.index] = true;
  }
  // One at a time, leftmost first: `id(X, Y) :- Y = X.` needs X from its callers, and then Y
  // follows. Taking every head variable still unbound at once demanded Y too, and refused the
  // call id(A, Y) that leaves Y to the rule, as Prolog's `fib(N, F) :- N < 2, F = N.` does.
  for (;;) {
    const VarSet bound = reachable_bindings(rule, rule.body.size(), from_callers);
    std::optional<std::uint32_t> next;
    for (std::size_t i = 0; i < rule.head_args.size() && !next; ++i) {
      const Arg& a = rule.head_args[i];
      if (a.is_var && !bound[a.index]) next = static_cast<std::uint32_t>(i);
    }
    if (!next) break;
    positions.push_back(*next);
    from_callers[rule.head_args[*next].index] = true;
  }
  std::sort(positions.begin(), positions.end());
  positions.erase(std::unique(positions.begin(), positions.end()), positions.end());
  return positions;
}

// Step 1: demand literals for rules with unbound head variables.
Result<std::map<std::uint32_t, Demand>> add_demand_literals(Program& program, std::vector<int>& cuts) {
  std::map<std::uint32_t, Demand> demands;  // by predicate
  // The positions callers must bind are those any alternative needs: the first alternative's
  // were taken for all, and an alternative needing others was refused, or not, by clause order
  // (`q(P, D, I) :- I = 1.` then `q(P, D, I) :- ex:interval(D, I).` was accepted, the other
  // way round refused).
  std::vector<std::vector<std::uint32_t>> own(program.rules.size());
  std::map<std::uint32_t, std::vector<std::uint32_t>> needed;  // by predicate
  for (std::size_t r = 0; r < program.rules.size(); ++r) {
    own[r] = demand_positions(program.rules[r]);
    if (own[r].empty()) continue;
    std::vector<std::uint32_t>& all = needed[program.rules[r].head];
    std::vector<std::uint32_t> merged;
    std::set_union(all.begin(), all.end(), own[r].begin(), own[r].end(), std::back_inserter(merged));
    all = std::move(merged);
  }
  for (std::size_t r = 0; r < program.rules.size(); ++r) {
    Rule& rule = program.rules[r];
    if (own[r].empty()) continue;
    const std::vector<std::uint32_t>& positions = needed.at(rule.head);
    auto [it, fresh] = demands.try_emplace(rule.head);
    if (fresh) {
      it->second.positions = positions;
      it->second.pos = rule.pos;
      const std::uint32_t head_var = rule.head_args[own[r].front()].index;
      it->second.variable = rule.var_names[head_var];
      if (auto need = unbound_need_of(rule, head_var)) {
        it->second.unbound_need = rule.var_names[need->first];
        it->second.unbound_need_pos = need->second;
      }
      const Pred& p = program.preds[rule.head];
      it->second.pred = add_pred(program, "demand for " + p.iri + "/" + std::to_string(p.arity),
                                 static_cast<std::uint32_t>(positions.size()));
    }
    for (std::uint32_t i : own[r]) it->second.needed_by.try_emplace(i, rule.pos, rule.var_names[rule.head_args[i].index]);
    std::vector<Arg> args;
    for (std::uint32_t i : positions) args.push_back(rule.head_args[i]);
    rule.body.insert(rule.body.begin(), atom_literal(it->second.pred, std::move(args), rule.pos));
    if (cuts[r] >= 0) ++cuts[r];
  }
  return demands;
}

// Step 2: the alternatives of ranked predicates, in file order.
void add_ranking(Program& program, const std::vector<int>& cuts) {
  std::map<std::uint32_t, std::vector<std::size_t>> by_pred;
  for (std::size_t r = 0; r < program.rules.size(); ++r) by_pred[program.rules[r].head].push_back(r);
  for (auto& [pred, alternatives] : by_pred) {
    bool ranked = std::any_of(alternatives.begin(), alternatives.end(), [&](std::size_t r) { return cuts[r] >= 0; });
    if (!ranked) continue;
    const std::uint32_t arity = program.preds[pred].arity;
    const std::uint32_t key = arity == 0 ? 0 : arity - 1;
    std::vector<std::uint32_t> applies;  // helper predicate per earlier alternative with a cut
    for (std::size_t n = 0; n < alternatives.size(); ++n) {
      std::size_t r = alternatives[n];
      Rule& rule = program.rules[r];
      std::vector<Arg> key_args(rule.head_args.begin(), rule.head_args.begin() + key);
      for (std::uint32_t a : applies) rule.body.push_back(atom_literal(a, key_args, rule.pos, true));
      if (cuts[r] < 0) continue;
      std::uint32_t a = add_pred(program, "alternative " + std::to_string(n + 1) + " of " +
                                              program.preds[pred].iri + " applies", key);
      Rule helper;
      helper.head = a;
      helper.head_args = key_args;
      helper.body.assign(rule.body.begin(), rule.body.begin() + cuts[r]);
      helper.vars = rule.vars;
      helper.var_names = rule.var_names;
      helper.var_pos = rule.var_pos;
      helper.uses_now = rule.uses_now;
      helper.pos = rule.pos;
      program.rules.push_back(std::move(helper));  // invalidates `rule`
      applies.push_back(a);
    }
  }
}

// Step 1b: for every call of a predicate with demand, a rule deriving the demand. A predicate
// with demand that no other rule calls could never hold (RS9: its head variable is bound by
// nothing; most likely a typo, as in `alarm(X, Levl) :- level(X, Level), ...`).
Result<void> add_demand_rules(Program& program, const std::map<std::uint32_t, Demand>& demands) {
  std::set<std::uint32_t> called;
  for (std::size_t r = 0; r < program.rules.size(); ++r) {
    for (std::size_t i = 0; i < program.rules[r].body.size(); ++i) {
      const Rule& rule = program.rules[r];
      const Literal& call = rule.body[i];
      if (call.kind != Literal::atom && call.kind != Literal::negation) continue;
      auto it = demands.find(call.pred);
      if (it == demands.end()) continue;
      Rule d;
      d.head = it->second.pred;
      for (std::uint32_t p : it->second.positions) d.head_args.push_back(call.args[p]);
      d.body.assign(rule.body.begin(), rule.body.begin() + static_cast<long>(i));
      d.vars = rule.vars;
      d.var_names = rule.var_names;
      d.var_pos = rule.var_pos;
      d.uses_now = rule.uses_now;
      d.pos = call.pos;
      VarSet bound = reachable_bindings(d);
      // Left recursion (`path(S, Z) :- path(S, Y), link(Y, Z).` beside `path(S, Y) :- Y = S.`):
      // the call passes the head's own demanded arguments on unchanged, so it asks for nothing
      // new; its facts are those the demand made. Its demand would be demand itself.
      const bool passes_its_own_on =
          rule.head == call.pred && std::all_of(it->second.positions.begin(), it->second.positions.end(), [&](std::uint32_t p) {
            const Arg& in_call = call.args[p];
            const Arg& in_head = rule.head_args[p];
            return in_call.is_var && in_head.is_var && in_call.index == in_head.index;
          });
      const bool leaves_one_unbound = std::any_of(d.head_args.begin(), d.head_args.end(),
                                                  [&](const Arg& a) { return a.is_var && !bound[a.index]; });
      if (passes_its_own_on && leaves_one_unbound) continue;
      for (std::size_t k = 0; k < d.head_args.size(); ++k) {
        const Arg& a = d.head_args[k];
        if (!a.is_var || bound[a.index]) continue;
        // Named with the alternative: the slip is most often there (`thr(P, T) :- Tt = 20.`).
        std::string which = "an alternative of it";
        if (auto by = it->second.needed_by.find(it->second.positions[k]); by != it->second.needed_by.end())
          which = "its alternative at " + where(program, by->second.first) + " (whose body binds no " + by->second.second + ")";
        return unexpected(Error{where(program, call.pos) + ": this call of " + program.preds[call.pred].iri + " leaves " +
                                rule.var_names[a.index] + " unbound, and " + which + " takes that argument from its caller only"});
      }
      if (rule.head != call.pred) called.insert(call.pred);
      program.rules.push_back(std::move(d));
    }
  }
  for (const auto& [pred, demand] : demands) {
    if (called.count(pred)) continue;
    const Pred& p = program.preds[pred];
    if (!demand.unbound_need.empty())
      return unexpected(Error{where(program, demand.unbound_need_pos) + ": variable " + demand.unbound_need +
                              " is bound by no literal, so head variable " + demand.variable +
                              " is not either, and no rule calls " + p.iri + "/" + std::to_string(p.arity) +
                              " to bind it (unsafe)"});
    return unexpected(Error{where(program, demand.pos) + ": head variable " + demand.variable +
                            " is bound by no literal, and no rule calls " + p.iri + "/" + std::to_string(p.arity) +
                            " to bind it (unsafe)"});
  }
  return {};
}

// Per step of `order`: the argument of the atom there that a comparison bounds, when the
// comparison's other variables are bound by the steps before (`bound`: those bound on entry).
std::vector<RangeScan> range_scans(const Rule& rule, const std::vector<std::uint32_t>& order, VarSet bound) {
  const std::vector<RangeCandidate> candidates = range_candidates(rule);
  std::vector<RangeScan> scans(order.size());
  for (std::size_t k = 0; k < order.size(); ++k) {
    const Literal& l = rule.body[order[k]];
    if (l.kind == Literal::atom && l.pred != kAnyBinary) {
      for (std::size_t i = 0; i < l.args.size() && scans[k].position < 0; ++i) {
        const Arg& a = l.args[i];
        if (!a.is_var || bound[a.index]) continue;
        for (const RangeCandidate& c : candidates) {
          if (c.var != a.index || !std::all_of(c.needs.begin(), c.needs.end(), [&](std::uint32_t v) { return bound[v]; }))
            continue;
          scans[k].position = static_cast<int>(i);
          scans[k].bounds.push_back(c.bound);
        }
      }
    }
    bind_vars(l, bound);
    if (l.kind == Literal::negation)  // the first step of a negation plan, read as positive
      for (const Arg& a : l.args) if (a.is_var) bound[a.index] = true;
  }
  return scans;
}

std::vector<std::uint32_t> literal_vars(const Literal& l) {
  std::vector<std::uint32_t> out;
  for (const Arg& a : l.args) if (a.is_var) out.push_back(a.index);
  expr_vars(l.lhs, out);
  expr_vars(l.rhs, out);
  return out;
}

// Per step of `order`: the independent run (program.h, Memo) that starts there. A run starts at
// an atom after the first step none of whose variables is bound yet, and goes on while the
// steps are atoms joined to it by its own variables only, or filters (comparisons, negations,
// ==, \==) on its variables and earlier ones; it needs two atoms.
std::vector<Memo> independent_runs(const Rule& rule, const std::vector<std::uint32_t>& order, VarSet bound) {
  std::vector<Memo> memos(order.size());
  const std::vector<RangeCandidate> candidates = range_candidates(rule);
  auto is_filter = [](const Literal& l) {
    return l.kind == Literal::compare || l.kind == Literal::negation || l.kind == Literal::identical ||
           l.kind == Literal::not_unify;
  };
  for (std::size_t k = 0; k < order.size();) {
    const Literal& first = rule.body[order[k]];
    const std::vector<std::uint32_t> first_vars = literal_vars(first);
    bool starts = k > 0 && first.kind == Literal::atom && !first_vars.empty() &&
                  std::none_of(first_vars.begin(), first_vars.end(), [&](std::uint32_t v) { return bound[v]; });
    std::size_t end = k + 1, atoms = 1;
    VarSet own(rule.vars, false);
    for (std::uint32_t v : first_vars) own[v] = true;
    std::vector<std::uint32_t> cross;
    while (starts && end < order.size()) {
      const Literal& l = rule.body[order[end]];
      const std::vector<std::uint32_t> vars = literal_vars(l);
      const bool outer = std::any_of(vars.begin(), vars.end(), [&](std::uint32_t v) { return bound[v]; });
      const bool mine = std::any_of(vars.begin(), vars.end(), [&](std::uint32_t v) { return own[v]; });
      if (l.kind == Literal::atom && mine && !outer) {
        for (std::uint32_t v : vars) own[v] = true;
        ++atoms;
      } else if (is_filter(l) && mine) {
        if (outer) cross.push_back(static_cast<std::uint32_t>(end));
      } else {
        break;
      }
      ++end;
    }
    if (!starts || atoms < 2) {
      bind_vars(first, bound);
      if (first.kind == Literal::negation)  // the first step of a negation plan, read as positive
        for (const Arg& a : first.args) if (a.is_var) bound[a.index] = true;
      ++k;
      continue;
    }
    Memo& m = memos[k];
    m.end = static_cast<std::uint32_t>(end);
    m.cross = cross;
    VarSet read(rule.vars, false);  // by the steps after the run, its cross filters and the head
    for (std::size_t q = end; q < order.size(); ++q) for (std::uint32_t v : literal_vars(rule.body[order[q]])) read[v] = true;
    for (std::uint32_t q : cross) for (std::uint32_t v : literal_vars(rule.body[order[q]])) read[v] = true;
    for (const Arg& a : rule.head_args) if (a.is_var) read[a.index] = true;
    for (std::uint32_t v = 0; v < rule.vars; ++v) if (own[v] && read[v]) m.exported.push_back(v);
    for (std::size_t slot = 0; slot < m.exported.size() && m.range.position < 0; ++slot) {
      for (const RangeCandidate& c : candidates) {
        if (c.var != m.exported[slot] ||
            !std::all_of(c.needs.begin(), c.needs.end(), [&](std::uint32_t v) { return bound[v]; }))
          continue;
        m.range.position = static_cast<int>(slot);
        m.range.bounds.push_back(c.bound);
      }
    }
    for (std::size_t q = k; q < end; ++q) bind_vars(rule.body[order[q]], bound);
    k = end;
  }
  return memos;
}

std::uint32_t ready_step(const Rule& rule, const std::vector<std::uint32_t>& order) {
  VarSet bound(rule.vars, false);
  auto head_bound = [&] {
    return std::all_of(rule.head_args.begin(), rule.head_args.end(),
                       [&](const Arg& a) { return !a.is_var || bound[a.index]; });
  };
  for (std::uint32_t k = 0; k < order.size(); ++k) {
    if (head_bound()) return k;
    bind_vars(rule.body[order[k]], bound);
  }
  return static_cast<std::uint32_t>(order.size());
}

// RS6: a negation's variables are bound by the literals written before it, as in Prolog, where
// `\+ c(X, Z)` before the literal that binds Z asks whether X has any c at all. (Plans may still
// move the negation. The rewritten rules keep the property: what comes before their negations is
// a prefix of a written body, after the demand literal, or the whole body.)
Result<void> check_negations_follow_their_bindings(const Program& program, const Rule& rule) {
  for (std::size_t k = 0; k < rule.body.size(); ++k) {
    const Literal& l = rule.body[k];
    if (l.kind != Literal::negation) continue;
    const VarSet bound = reachable_bindings(rule, k, VarSet(rule.vars, false));
    for (const Arg& a : l.args)
      if (a.is_var && !bound[a.index]) return unbound_before(program, rule, l, a.index);
  }
  return {};
}

Result<void> make_plans(Program& program) {
  for (Rule& rule : program.rules) {
    if (auto c = check_negations_follow_their_bindings(program, rule); !c) return c;
    std::vector<std::uint32_t> written(rule.body.size());
    for (std::uint32_t i = 0; i < written.size(); ++i) written[i] = i;
    auto full = plan(program, rule, written, VarSet(rule.vars, false), true);
    if (!full) return unexpected(full.error());
    VarSet bound(rule.vars, false);
    for (std::uint32_t i : *full) bind_vars(rule.body[i], bound);
    for (const Arg& a : rule.head_args) {
      if (a.is_var && !bound[a.index])
        return unexpected(Error{where(program, rule.pos) + ": head variable " + rule.var_names[a.index] +
                                " is bound by no literal (unsafe)"});
    }
    rule.plans = {std::move(*full)};
    for (std::uint32_t k = 0; k < rule.body.size(); ++k) {
      if (rule.body[k].kind != Literal::atom) continue;
      std::vector<std::uint32_t> pref{k};
      for (std::uint32_t i = 0; i < rule.body.size(); ++i) if (i != k) pref.push_back(i);
      auto delta = plan(program, rule, pref, VarSet(rule.vars, false), true);
      if (!delta) return unexpected(delta.error());
      rule.plans.push_back(std::move(*delta));
      rule.kth_atom.push_back(k);
    }
    rule.ready.clear();
    rule.plan_ranges.clear();
    rule.plan_memos.clear();
    for (const auto& order : rule.plans) {
      rule.ready.push_back(ready_step(rule, order));
      rule.plan_ranges.push_back(range_scans(rule, order, VarSet(rule.vars, false)));
      rule.plan_memos.push_back(independent_runs(rule, order, VarSet(rule.vars, false)));
    }
    rule.neg_plans.clear();
    rule.neg_literal.clear();
    rule.neg_plan_ranges.clear();
    rule.neg_plan_memos.clear();
    for (std::uint32_t k = 0; k < rule.body.size(); ++k) {
      if (rule.body[k].kind != Literal::negation) continue;
      VarSet bound(rule.vars, false);
      for (const Arg& a : rule.body[k].args) if (a.is_var) bound[a.index] = true;
      std::vector<std::uint32_t> rest;
      for (std::uint32_t i = 0; i < rule.body.size(); ++i) if (i != k) rest.push_back(i);
      auto order = plan(program, rule, rest, bound, true);
      if (!order) return unexpected(order.error());
      order->insert(order->begin(), k);
      rule.neg_plan_ranges.push_back(range_scans(rule, *order, VarSet(rule.vars, false)));
      rule.neg_plan_memos.push_back(independent_runs(rule, *order, VarSet(rule.vars, false)));
      rule.neg_plans.push_back(std::move(*order));
      rule.neg_literal.push_back(k);
    }
  }
  return {};
}

// Step 4 works on head patterns, not predicates (RS6): a pattern is the rules of one predicate
// whose heads have the same constants in the same places. A call depends on the patterns whose
// head could match it (a constant other than the call's own there cannot), so
// `rdf:type(X, alerted) :- q(X, _), \+ rdf:type(X, person).` beside
// `rdf:type(X, person) :- q(X, person).` is stratified: the person rule, a stratum of its own,
// runs first. (Until session 75 the graph was one of predicates, and a rule deriving rdf:type
// person made every rdf:type rule depend on it: that rule set was refused as not stratified.)
// A call that matches one rule of a pattern matches all of them, so grouping them changes no
// cycle. The evaluator keeps, per row, which strata derive it (engine.cpp, Relation::owners).
struct Dependency {
  std::uint32_t to = 0;    // pattern
  bool negated = false;
  std::uint32_t rule = 0;  // the rule whose body makes it
};

struct PatternGraph {
  std::vector<std::uint32_t> pattern_of_rule;
  std::vector<std::vector<std::uint32_t>> rules_of;        // per pattern, in written order
  std::vector<std::vector<std::uint32_t>> patterns_of;     // per predicate
  std::vector<std::uint32_t> binary_patterns;              // of binary user predicates (fact/3 reads them)
  std::vector<std::vector<Dependency>> edges;              // per pattern
};

// Whether a head (args of a rule of the pattern) could derive an atom the call `l` matches:
// `fact(S, P, O)` against a binary head (S, O), another call argument by argument. A variable
// matches anything; two constants only when they are the same.
bool head_may_match(const std::vector<Arg>& head, const Literal& l) {
  const bool any_binary = l.pred == kAnyBinary;
  if (any_binary ? head.size() != 2 || l.args.size() != 3 : head.size() != l.args.size()) return true;
  for (std::size_t i = 0; i < head.size(); ++i) {
    const Arg& call = l.args[any_binary && i == 1 ? 2 : i];
    if (!head[i].is_var && !call.is_var && head[i].index != call.index) return false;
  }
  return true;
}

// The patterns a call depends on.
template <class F>
void for_each_match(const Program& program, const PatternGraph& g, const Literal& l, F&& f) {
  const auto& candidates = l.pred == kAnyBinary ? g.binary_patterns : g.patterns_of[l.pred];
  for (std::uint32_t p : candidates)
    if (head_may_match(program.rules[g.rules_of[p].front()].head_args, l)) f(p);
}

PatternGraph pattern_graph(const Program& program) {
  PatternGraph g;
  g.patterns_of.resize(program.preds.size());
  std::map<std::pair<std::uint32_t, std::vector<std::int64_t>>, std::uint32_t> by_head;
  for (std::uint32_t ri = 0; ri < program.rules.size(); ++ri) {
    const Rule& rule = program.rules[ri];
    std::vector<std::int64_t> key;
    for (const Arg& a : rule.head_args) key.push_back(a.is_var ? -1 : static_cast<std::int64_t>(a.index));
    auto [it, fresh] = by_head.try_emplace({rule.head, std::move(key)}, static_cast<std::uint32_t>(g.rules_of.size()));
    if (fresh) {
      g.rules_of.emplace_back();
      g.patterns_of[rule.head].push_back(it->second);
      const Pred& pred = program.preds[rule.head];
      if (pred.arity == 2 && !pred.internal) g.binary_patterns.push_back(it->second);
    }
    g.rules_of[it->second].push_back(ri);
    g.pattern_of_rule.push_back(it->second);
  }
  g.edges.resize(g.rules_of.size());
  for (std::uint32_t ri = 0; ri < program.rules.size(); ++ri) {
    for (const Literal& l : program.rules[ri].body) {
      if (l.kind != Literal::atom && l.kind != Literal::negation) continue;
      for_each_match(program, g, l, [&](std::uint32_t p) {
        g.edges[g.pattern_of_rule[ri]].push_back({p, l.kind == Literal::negation, ri});
      });
    }
  }
  return g;
}

// Tarjan's strongly connected components, iteratively (a chain of 300,000 negations is as many
// levels); components are emitted dependencies first. Returns each pattern's component.
std::vector<int> components_of(const PatternGraph& g, std::vector<std::vector<std::uint32_t>>& components) {
  const std::size_t n = g.edges.size();
  std::vector<int> index(n, -1), low(n, 0), comp(n, -1);
  std::vector<bool> on_stack(n, false);
  std::vector<std::uint32_t> stack;
  std::vector<std::pair<std::uint32_t, std::size_t>> work;  // (pattern, next edge)
  int counter = 0;
  auto enter = [&](std::uint32_t v) {
    index[v] = low[v] = counter++;
    stack.push_back(v);
    on_stack[v] = true;
    work.emplace_back(v, 0);
  };
  for (std::uint32_t s = 0; s < n; ++s) {
    if (index[s] >= 0) continue;
    enter(s);
    while (!work.empty()) {
      const std::uint32_t v = work.back().first;
      if (work.back().second < g.edges[v].size()) {
        const std::uint32_t w = g.edges[v][work.back().second++].to;
        if (index[w] < 0) enter(w);
        else if (on_stack[w]) low[v] = std::min(low[v], index[w]);
        continue;
      }
      work.pop_back();
      if (!work.empty()) low[work.back().first] = std::min(low[work.back().first], low[v]);
      if (low[v] != index[v]) continue;
      std::vector<std::uint32_t> members;
      std::uint32_t w;
      do {
        w = stack.back();
        stack.pop_back();
        on_stack[w] = false;
        comp[w] = static_cast<int>(components.size());
        members.push_back(w);
      } while (w != v);
      components.push_back(std::move(members));
    }
  }
  return comp;
}

// The shortest chain by which pattern `from` depends on `to` (both in one component), as
// "a <- b <- c (each derived from the next), by the rules at f:2:1 <- f:1:1 <- f:3:1": the
// predicates and the rules that close the loop. `last_rule`: the rule of `to` on the loop (the
// one with the negation).
std::string dependency_path(const Program& program, const PatternGraph& g, const std::vector<int>& comp,
                            std::uint32_t from, std::uint32_t to, std::uint32_t last_rule) {
  struct Step {
    std::int64_t pattern = -1;
    std::uint32_t rule = 0;
  };
  std::vector<Step> came_from(g.edges.size());
  std::deque<std::uint32_t> queue{from};
  came_from[from].pattern = from;
  while (!queue.empty() && came_from[to].pattern < 0) {
    const std::uint32_t v = queue.front();
    queue.pop_front();
    for (const Dependency& d : g.edges[v]) {
      if (comp[d.to] != comp[from] || came_from[d.to].pattern >= 0) continue;
      came_from[d.to] = {v, d.rule};
      queue.push_back(d.to);
    }
  }
  auto pred_of = [&](std::uint32_t p) { return program.preds[program.rules[g.rules_of[p].front()].head].iri; };
  if (came_from[to].pattern < 0) return pred_of(from) + " <- " + pred_of(to);
  // chain[i] is derived from chain[i + 1] by rules[i]; the last by the negating rule.
  std::vector<std::uint32_t> chain{to}, rules{last_rule};
  while (chain.back() != from) {
    rules.push_back(came_from[chain.back()].rule);
    chain.push_back(static_cast<std::uint32_t>(came_from[chain.back()].pattern));
  }
  std::string preds, places;
  for (std::size_t i = chain.size(); i-- > 0;) {
    preds += (preds.empty() ? "" : " <- ") + pred_of(chain[i]);
    places += (places.empty() ? "" : " <- ") + where(program, program.rules[rules[i]].pos);
  }
  if (chain.size() == 1) return preds + ", by the rule at " + places;
  return preds + " (each derived from the next), by the rules at " + places;
}

Result<void> stratify(Program& program) {
  const PatternGraph g = pattern_graph(program);
  std::vector<std::vector<std::uint32_t>> components;
  const std::vector<int> comp = components_of(g, components);
  for (std::uint32_t ri = 0; ri < program.rules.size(); ++ri) {
    const Rule& rule = program.rules[ri];
    const std::uint32_t own = g.pattern_of_rule[ri];
    for (const Literal& l : rule.body) {
      if (l.kind != Literal::negation) continue;
      std::optional<std::uint32_t> loop;
      for_each_match(program, g, l, [&](std::uint32_t p) { if (!loop && comp[p] == comp[own]) loop = p; });
      if (!loop) continue;
      const std::string& negated = program.preds[program.rules[g.rules_of[*loop].front()].head].iri;
      return unexpected(Error{where(program, l.pos) + ": " + program.preds[rule.head].iri + " depends on the negation of " +
                              negated + ", which is derived from " + program.preds[rule.head].iri +
                              " in turn (not stratified; ranking and \\+ cannot go through recursion): " +
                              dependency_path(program, g, comp, *loop, own, ri)});
    }
  }
  program.strata.clear();
  for (const auto& members : components) {
    Stratum s;
    for (std::uint32_t p : members) {
      for (std::uint32_t ri : g.rules_of[p]) {
        s.rules.push_back(ri);
        s.preds.push_back(program.rules[ri].head);
        s.volatile_ |= program.rules[ri].uses_now;
      }
      for (const Dependency& d : g.edges[p]) s.recursive |= comp[d.to] == comp[p];
    }
    std::sort(s.rules.begin(), s.rules.end());
    std::sort(s.preds.begin(), s.preds.end());
    s.preds.erase(std::unique(s.preds.begin(), s.preds.end()), s.preds.end());
    program.strata.push_back(std::move(s));
  }
  return {};
}

void collect_reads(Program& program) {
  std::set<std::uint32_t> binary;
  for (const Rule& rule : program.rules) {
    for (const Literal& l : rule.body) {
      if (l.kind != Literal::atom && l.kind != Literal::negation) continue;
      if (l.pred == kAnyBinary) program.reads_any_binary = true;
      else if (program.preds[l.pred].arity == 2 && !program.preds[l.pred].internal) binary.insert(l.pred);
    }
  }
  program.read_binary.assign(binary.begin(), binary.end());
}

// `:- ranked(p/N).` names a predicate that rules define, with that arity (else a typo).
Result<void> check_ranked_declarations(const Program& program) {
  for (const auto& [pred, pos] : program.ranked_declarations) {
    const Pred& p = program.preds[pred];
    auto defines = [&](const Rule& rule) { return rule.head == pred; };
    if (std::any_of(program.rules.begin(), program.rules.end(), defines)) continue;
    std::set<std::uint32_t> arities;
    for (const Rule& rule : program.rules)
      if (program.preds[rule.head].iri == p.iri) arities.insert(program.preds[rule.head].arity);
    std::string others;
    for (std::uint32_t n : arities) others += (others.empty() ? "; its rules have arity " : " and ") + std::to_string(n);
    return unexpected(Error{where(program, pos) + ": ranked: no rule defines " + p.iri + "/" +
                            std::to_string(p.arity) + others});
  }
  return {};
}

// A call of p/N (N other than 2) that no rule defines: base facts are triples, so it never holds,
// and under \+ always holds (`\+ low(P)` beside rules of low/2 said every patient stable). As
// Prolog's "unknown procedure", an error.
std::optional<Error> undefined_call(const Program& program) {
  std::set<std::uint32_t> defined;
  for (const Rule& rule : program.rules) defined.insert(rule.head);
  for (const Rule& rule : program.rules) {
    for (const Literal& l : rule.body) {
      if ((l.kind != Literal::atom && l.kind != Literal::negation) || l.pred == kAnyBinary) continue;
      const Pred& p = program.preds[l.pred];
      if (p.internal || p.arity == 2 || defined.contains(l.pred)) continue;
      std::set<std::uint32_t> arities;
      for (std::uint32_t head : defined)
        if (program.preds[head].iri == p.iri) arities.insert(program.preds[head].arity);
      std::string others;
      for (std::uint32_t n : arities) others += (others.empty() ? " (its rules have arity " : " and ") + std::to_string(n);
      if (!others.empty()) others += ")";
      return Error{where(program, l.pos) + ": " + p.iri + "/" + std::to_string(p.arity) + " is defined by no rule" + others +
                   ", and base facts are triples (arity 2): this " +
                   (l.kind == Literal::negation ? "negation would always hold" : "call would never hold")};
    }
  }
  return std::nullopt;
}

}  // namespace

Result<void> compile_program(Program& program) {
  // Found in the rules as written, said after the other errors (an unbound variable, a
  // negation through recursion), which name the line to mend first.
  const std::optional<Error> undefined = undefined_call(program);
  if (auto r = check_ranked_declarations(program); !r) return r;
  auto cuts = take_cuts(program);
  if (!cuts) return unexpected(cuts.error());
  add_existential_negations(program, *cuts);
  auto demands = add_demand_literals(program, *cuts);
  if (!demands) return unexpected(demands.error());
  add_ranking(program, *cuts);
  if (auto d = add_demand_rules(program, *demands); !d) return d;
  if (auto p = make_plans(program); !p) return p;
  if (auto s = stratify(program); !s) return s;
  if (undefined) return unexpected(*undefined);
  collect_reads(program);
  return {};
}

}  // namespace tahvel::reasoner
