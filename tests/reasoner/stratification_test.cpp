// Stratification by head pattern (docs/reasoner.md RS6): a call depends on the rules of its
// predicate whose head could match it, so a negation of one class is stratified beside a rule
// deriving that class, and the rule deriving it runs first, in the first session and in the
// sessions after. A negation its own loop can reach is still refused, naming the rules.
#include <gtest/gtest.h>

#include <random>
#include <set>

#include "differential.h"
#include "tahvel/agents/rules.h"

namespace {

namespace tr = tahvel::reasoner;
namespace tn = tahvel::node;

const std::string kNs = "http://example.org/n#";
const std::string kType = std::string(tn::kRdfType);

tr::ParseOptions options(const std::string& file) {
  tr::ParseOptions o;
  o.file = file;
  o.default_ns = kNs;
  o.me = "http://example.org/n";
  return o;
}

std::shared_ptr<const tr::Program> parse(const std::string& text) {
  auto p = tr::parse_rules(text, options("e.rules"));
  EXPECT_TRUE(p.has_value()) << (p ? "" : p.error().message);
  return p ? *p : nullptr;
}

tn::Term n(const std::string& local) { return tn::Term::iri(kNs + local); }
tn::Triple t(const std::string& s, const std::string& p, const std::string& o) { return {n(s), n(p), n(o)}; }
tn::Triple type(const std::string& s, const std::string& o) { return {n(s), tn::Term::iri(kType), n(o)}; }
std::string a2(const std::string& p, const std::string& s, const std::string& o) {
  return tr::Atom{p.rfind("http", 0) == 0 ? p : kNs + p, {n(s), n(o)}}.to_string();
}

std::set<std::string> strings(const std::vector<tr::Atom>& atoms) {
  std::set<std::string> out;
  for (const auto& a : atoms) out.insert(a.to_string());
  return out;
}

// q(a, person), q(b, robot): a is a person, b is alerted.
const std::vector<tn::Triple> kFacts = {t("a", "q", "person"), t("b", "q", "robot")};

std::set<std::string> from_scratch(const std::string& rules, const std::vector<tn::Triple>& facts) {
  auto program = parse(rules);
  if (!program) return {};
  tr::Engine engine(program);
  return strings(engine.apply(facts, {}, 0).added);
}

TEST(Stratification, ANegationOfAPatternNoOtherHeadMatchesIsStratifiedWhenAnotherRuleDerivesThePattern) {
  const std::string rules =
      "rdf:type(X, alerted) :- q(X, _), \\+ rdf:type(X, person).\n"
      "rdf:type(X, person) :- q(X, person).\n";
  EXPECT_EQ(from_scratch(rules, kFacts), (std::set<std::string>{a2(kType, "a", "person"), a2(kType, "b", "alerted")}));
}

TEST(Stratification, ANegationOfAPatternOfAnOrdinaryPredicateIsStratifiedWhenAnotherRuleDerivesThePattern) {
  const std::string rules =
      "isa(X, alerted) :- q(X, _), \\+ isa(X, person).\n"
      "isa(X, person) :- q(X, person).\n";
  EXPECT_EQ(from_scratch(rules, kFacts), (std::set<std::string>{a2("isa", "a", "person"), a2("isa", "b", "alerted")}));
}

TEST(Stratification, ANegationThroughAHelperOfAPatternAnotherRuleDerivesIsStratified) {
  const std::string rules =
      "rdf:type(X, alerted) :- q(X, _), \\+ person(X, yes).\n"
      "person(X, yes) :- rdf:type(X, person).\n"
      "rdf:type(X, person) :- q(X, person).\n";
  EXPECT_EQ(from_scratch(rules, kFacts), (std::set<std::string>{a2(kType, "a", "person"), a2("person", "a", "yes"),
                                                                 a2(kType, "b", "alerted")}));
}

// A loop through the negation is refused as before, and the error names the rules that close it.
TEST(Stratification, ANegationOnALoopOfHeadPatternsIsRefusedNamingTheRulesOfTheLoop) {
  auto loop = tr::parse_rules(
      "rdf:type(X, alerted) :- q(X, _), \\+ rdf:type(X, person).\n"
      "rdf:type(X, person) :- q(X, person), \\+ rdf:type(X, alerted).\n",
      options("e.rules"));
  ASSERT_FALSE(loop.has_value());
  const std::string& m = loop.error().message;
  EXPECT_EQ(m.rfind("e.rules:1:37: " + kType + " depends on the negation of " + kType + ", which is derived from " + kType +
                        " in turn (not stratified",
                    0),
            0u)
      << m;
  EXPECT_NE(m.find(kType + " <- " + kType + " (each derived from the next), by the rules at e.rules:2:1 <- e.rules:1:1"),
            std::string::npos)
      << m;

  auto self = tr::parse_rules("p(X) :- q(X), \\+ p(X).\n", options("e.rules"));
  ASSERT_FALSE(self.has_value());
  EXPECT_EQ(self.error().message.rfind("e.rules:1:18: " + kNs + "p depends on the negation of " + kNs + "p", 0), 0u)
      << self.error().message;
  EXPECT_NE(self.error().message.find("by the rule at e.rules:1:1"), std::string::npos) << self.error().message;

  // Through a helper: person(X, yes) reads rdf:type person, whose rule negates person.
  auto helper = tr::parse_rules(
      "person(X, yes) :- rdf:type(X, person).\n"
      "rdf:type(X, person) :- q(X, person), \\+ person(X, yes).\n",
      options("e.rules"));
  ASSERT_FALSE(helper.has_value());
  EXPECT_NE(helper.error().message.find("not stratified"), std::string::npos) << helper.error().message;
}

// The rule deriving the negated pattern runs before the negation in every session: a fact that
// makes b a person takes b's alert back in the session it arrives, and removing it gives the
// alert again.
TEST(Stratification, AFactThatMakesTheNegatedPatternHoldLaterRetractsTheConclusion) {
  auto program = parse(
      "rdf:type(X, alerted) :- q(X, _), \\+ rdf:type(X, person).\n"
      "rdf:type(X, person) :- q(X, person).\n");
  ASSERT_TRUE(program);
  tr::Engine engine(program);
  engine.apply(kFacts, {}, 0);
  auto u = engine.apply(std::vector<tn::Triple>{t("b", "q", "person")}, {}, 0);
  EXPECT_EQ(strings(u.added), std::set<std::string>{a2(kType, "b", "person")});
  EXPECT_EQ(strings(u.removed), std::set<std::string>{a2(kType, "b", "alerted")});
  u = engine.apply({}, std::vector<tn::Triple>{t("b", "q", "person")}, 0);
  EXPECT_EQ(strings(u.added), std::set<std::string>{a2(kType, "b", "alerted")});
  EXPECT_EQ(strings(u.removed), std::set<std::string>{a2(kType, "b", "person")});
  // A person by a record of the class itself, no rule: the same.
  u = engine.apply(std::vector<tn::Triple>{type("b", "person")}, {}, 0);
  EXPECT_EQ(strings(u.removed), std::set<std::string>{a2(kType, "b", "alerted")});
}

// Rules of one predicate in several strata may derive the same row (`rdf:type(X, Y) :- kind(X, Y)`
// gives rdf:type(b, alerted) too): recomputing one stratum takes back only its own derivations.
// Differential: random insertions and removals session by session against a from-scratch run.
TEST(Stratification, IncrementalEqualsFromScratchWhenAPredicatesRulesLieInSeveralStrata) {
  auto program = parse(
      "rdf:type(X, person) :- q(X, person).\n"
      "rdf:type(X, Y) :- kind(X, Y).\n"
      "rdf:type(X, alerted) :- q(X, _), \\+ rdf:type(X, person).\n"
      "rdf:type(X, flagged) :- rdf:type(X, alerted), \\+ rdf:type(X, robot).\n"
      "seen(X, yes) :- rdf:type(X, flagged).\n"
      "seen(X, yes) :- kind(X, flagged).\n");
  ASSERT_TRUE(program);
  std::mt19937 rng(20261206);
  const char* classes[] = {"person", "robot", "alerted", "flagged"};
  auto pick = [&] { return "v" + std::to_string(rng() % 6); };
  for (int round = 0; round < 40; ++round) {
    tr::Engine incremental(program);
    std::vector<tn::Triple> held;
    for (int session = 0; session < 12; ++session) {
      std::vector<tn::Triple> in;
      for (int i = 1 + static_cast<int>(rng() % 4); i > 0; --i) {
        switch (rng() % 3) {
          case 0: in.push_back(t(pick(), "q", classes[rng() % 2])); break;
          case 1: in.push_back(t(pick(), "kind", classes[rng() % 4])); break;
          default: in.push_back(type(pick(), classes[rng() % 4]));
        }
      }
      tr::differential::apply_session(incremental, held, in, static_cast<int>(rng() % 3), rng);
    }
    tr::differential::expect_as_from_scratch(program, incremental, held, round);
    if (HasFailure()) return;
  }
}

}  // namespace
