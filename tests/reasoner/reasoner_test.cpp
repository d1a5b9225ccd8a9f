// The reasoner agent on a real node (reasoner.h): the thesis' robot session written to the
// board once, no conclusion written twice across sessions and restarts, removal of a premise
// retracting exactly what lost all support, rule reload (and a broken file reported while the
// previous rules run), the board against a from-scratch evaluation (differential), and a
// concurrent writer whose items a session never sees half of.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <sys/file.h>
#include <unistd.h>
#include <stdlib.h>

#include <atomic>
#include <condition_variable>
#include <functional>
#include <mutex>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <random>
#include <set>
#include <thread>

#include "tahvel/agents/reasoner.h"
#include "tahvel/node/node.h"
#include "temp_dir.h"

namespace {

namespace fs = std::filesystem;
namespace tr = tahvel::reasoner;
namespace tn = tahvel::node;

const std::string kIri = "http://example.org/robot3";
const std::string kNs = kIri + "#";

tn::Term n(const std::string& local) { return local == "me" ? tn::Term::iri(kIri) : tn::Term::iri(kNs + local); }

class ReasonerTest : public ::testing::Test {
 protected:
  void SetUp() override {
    auto node = tn::Node::init(root_ / "node", {.iri = kIri});
    ASSERT_TRUE(node.has_value()) << node.error().message;
    node_ = std::make_unique<tn::Node>(std::move(*node));
    auto agent = node_->agent("init");
    ASSERT_TRUE(agent.has_value());
    init_ = std::make_unique<tn::Agent>(std::move(*agent));
  }
  void TearDown() override {
    init_.reset();
    node_.reset();
  }
  fs::path rules(const std::string& name, const std::string& text) {
    fs::path p = root_ / name;
    std::ofstream(p) << text;
    // A later mtime than any earlier version, whatever the clock's resolution.
    static auto stamp = fs::file_time_type::clock::now();
    stamp += std::chrono::seconds(1);
    fs::last_write_time(p, stamp);
    return p;
  }
  fs::path source_rules(const std::string& name) {
    return fs::path(TAHVEL_SOURCE_DIR) / "agents/reasoner/rules" / name;
  }
  tr::Reasoner open(const fs::path& rule_file, const std::string& id = "reasoner") {
    tr::ReasonerOptions o;
    o.rules = rule_file;
    o.agent_id = id;
    auto r = tr::Reasoner::open(root_ / "node", o);
    EXPECT_TRUE(r.has_value()) << (r ? "" : r.error().message);
    return std::move(*r);
  }
  std::uint64_t put(std::vector<tn::Triple> triples, const std::string& context = "") {
    tn::Item item;
    item.triples = std::move(triples);
    item.context = context;
    auto id = init_->store(item);
    EXPECT_TRUE(id.has_value()) << (id ? "" : id.error().message);
    return id ? *id : 0;
  }
  // The reasoner's records: triple (N-Triples) -> how many records.
  std::map<std::string, int> board(const std::string& source = kIri + "/reasoner") {
    std::map<std::string, int> out;
    auto snap = node_->snapshot();
    tn::Pattern p;
    p.source = source;
    auto walked = snap->for_each(p, [&](const tn::Record& r) {
      ++out[r.triple.s.to_ntriples() + " " + r.triple.p.to_ntriples() + " " + r.triple.o.to_ntriples()];
      return true;
    });
    EXPECT_TRUE(walked.has_value());
    return out;
  }
  // One session of `rules_text` on s1's heart rate of 120: two conclusions, found by `first`
  // and `second`, each a record of an item of its own, asserted at the session's time. Returns
  // the reasoner, for what the test does next.
  tr::Reasoner two_items_of_one_session(const std::string& rules_text, const tn::Pattern& first, const tn::Pattern& second) {
    auto r = open(rules("two.rules", rules_text));
    put({{n("s1"), n("hr"), tn::Term::integer(120)}});
    auto s = r.session();
    EXPECT_TRUE(s.has_value()) << (s ? "" : s.error().message);
    if (s) {
      EXPECT_EQ(s->added.size(), 2u);
    }
    auto snap = node_->snapshot();
    auto a = snap->list(first), b = snap->list(second);
    EXPECT_TRUE(a && a->size() == 1u && b && b->size() == 1u);
    if (a && a->size() == 1u && b && b->size() == 1u) {
      EXPECT_NE(a->front().meta.item, b->front().meta.item);
      EXPECT_EQ(a->front().meta.asserted_at, b->front().meta.asserted_at);  // one session
    }
    return r;
  }
  static std::string nt(const std::string& s, const std::string& p, const std::string& o) {
    return n(s).to_ntriples() + " " + n(p).to_ntriples() + " " + n(o).to_ntriples();
  }
  static tn::Triple t(const std::string& s, const std::string& p, const std::string& o) { return {n(s), n(p), n(o)}; }

  tahvel::test_support::TempDir tmp_{"tahvel-reasoner"};
  const fs::path root_ = tmp_.path();
  std::unique_ptr<tn::Node> node_;
  std::unique_ptr<tn::Agent> init_;
};

// XSD 1.1 reads a double beyond its range as an infinity and one below it as zero: `V < 1e400`
// never held, and data of "1e400"^^xsd:double compared with nothing. A local name with %HH
// (`ex:a%20b`, as `tahvel put` stores it) is the IRI as written: its '%' started a comment.
TEST_F(ReasonerTest, DoublesBeyondTheirRangeCompareAsInfinityOrZeroAndPercentNamesMatch) {
  auto r = open(rules("range.rules",
                      "small(X, true) :- v(X, V), V < 1e400.\n"
                      "positive(X, true) :- v(X, V), V > 1e-400.\n"
                      "huge(X, true) :- v(X, V), V > 1e300.\n"
                      "spaced(X, true) :- v(X, _), X == #a%20b.\n"));
  put({{n("five"), n("v"), tn::Term::integer(5)},
       {n("big"), n("v"), tn::Term::literal("1e400", std::string(tn::xsd::kDouble))},
       {n("a%20b"), n("v"), tn::Term::integer(1)}});
  auto s = r.session();
  ASSERT_TRUE(s.has_value()) << s.error().message;
  const auto held = board();
  for (const char* want : {"five small", "five positive", "big huge", "big positive", "a%20b spaced", "a%20b small"}) {
    std::istringstream in(want);
    std::string x, p;
    in >> x >> p;
    EXPECT_EQ(held.count(n(x).to_ntriples() + " " + n(p).to_ntriples() + " \"true\"^^<http://www.w3.org/2001/XMLSchema#boolean>"), 1u)
        << want;
  }
  EXPECT_EQ(held.count(n("big").to_ntriples() + " " + n("small").to_ntriples() + " \"true\"^^<http://www.w3.org/2001/XMLSchema#boolean>"), 0u);
}

// "Reachable from a start node" written left-recursively, the usual Datalog form: the recursive
// call passes the demanded start on unchanged, and was refused as leaving it unbound. Only what
// the demand asks for is derived (nothing from m1), and a link added later extends it.
TEST_F(ReasonerTest, LeftRecursionFromADemandedStartDerivesWhatIsReachableFromIt) {
  auto r = open(rules("reach.rules",
                      "path(S, Y) :- Y = S.\n"
                      "path(S, Z) :- path(S, Y), link(Y, Z).\n"
                      "reach(X, Z) :- start(X, yes), path(X, Z).\n"));
  put({t("n1", "link", "n2"), t("n2", "link", "n3"), t("m1", "link", "m2"), t("n1", "start", "yes")});
  auto s = r.session();
  ASSERT_TRUE(s.has_value()) << s.error().message;
  auto reached = [&] {
    std::set<std::string> out;
    for (const auto& [triple, count] : board())
      for (const char* to : {"n1", "n2", "n3", "n4", "m1", "m2"})
        if (triple == nt("n1", "reach", to)) out.insert(to);
    return out;
  };
  EXPECT_EQ(reached(), (std::set<std::string>{"n1", "n2", "n3"}));
  for (const auto& [triple, count] : board()) EXPECT_NE(triple.rfind(n("m1").to_ntriples(), 0), 0u) << "not demanded: " << triple;
  put({t("n3", "link", "n4")});
  ASSERT_TRUE(r.session().has_value());
  EXPECT_EQ(reached(), (std::set<std::string>{"n1", "n2", "n3", "n4"}));
}

TEST_F(ReasonerTest, RobotSessionIsWrittenOnceWithTheReasonersSourceAndSessionTime) {
  put({t("me", "state", "stateIdle"), t("me", "myNameIs", "robot3"), t("robot3", "receivedTask", "clean")},
      kIri + "/wGandalf");
  auto r = open(source_rules("robot.rules"));
  auto s1 = r.session();
  ASSERT_TRUE(s1.has_value()) << s1.error().message;
  std::map<std::string, int> want = {{nt("me", "handleTask", "clean"), 1},
                                     {nt("me", "startMode", "cleaningMode"), 1},
                                     {nt("me", "state", "stateWorking"), 1}};
  EXPECT_EQ(board(), want);
  auto snap = node_->snapshot();
  tn::Pattern p;
  p.source = r.iri();
  auto records = snap->list(p);
  ASSERT_EQ(records->size(), 3u);
  for (const auto& rec : *records) EXPECT_EQ(rec.meta.asserted_at, s1->time_ns);
  // Sessions without new records write nothing.
  for (int i = 0; i < 3; ++i) {
    auto s = r.session();
    ASSERT_TRUE(s.has_value());
    EXPECT_TRUE(s->added.empty());
  }
  put({t("currentTask", "status", "finished")}, kIri + "/wGandalf");
  auto s2 = r.session();
  ASSERT_TRUE(s2.has_value());
  ASSERT_EQ(s2->added.size(), 1u);
  want[nt("me", "state", "stateIdle")] = 1;
  EXPECT_EQ(board(), want);
}

// A reasoner owns its agent's conclusions and removes, at its first session, those it did not
// derive: a second reasoner as the same agent deleted the first one's live conclusions.
TEST_F(ReasonerTest, ASecondReasonerAsTheSameAgentIsRefusedAndAnotherAgentIsNot) {
  auto first = open(rules("a.rules", "hot(X, true) :- temp(X, T), T > 30.\n"));
  tr::ReasonerOptions o;
  o.rules = rules("b.rules", "cold(X, true) :- temp(X, T), T < 10.\n");
  auto second = tr::Reasoner::open(root_ / "node", o);
  ASSERT_FALSE(second.has_value());
  EXPECT_NE(second.error().message.find("another process runs as agent <" + kIri + "/reasoner> on this node (pid " +
                                        std::to_string(getpid()) + "), " + (root_ / "node" / ".agent-reasoner.lock").string() +
                                        " is locked: give each reasoner its own --agent"),
            std::string::npos) << second.error().message;
  o.agent_id = "cold-reasoner";
  EXPECT_TRUE(tr::Reasoner::open(root_ / "node", o).has_value());
}

// A reasoner run as another program's agent (`--agent ecg` beside tahvel-ecg-source) would take
// that program's records for conclusions of an earlier run and remove them at its first session:
// it holds the lock the shipped agents hold, and is refused while one of them runs.
TEST_F(ReasonerTest, AReasonerAsTheAgentOfARunningProgramIsRefusedAndRemovesNothing) {
  tn::Item written;
  written.add(n("chunk1"), n("samples"), n("x"));
  const std::uint64_t chunk = node_->agent("ecg").value().store(written).value();
  const int held = ::open((root_ / "node" / ".agent-ecg.lock").c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
  ASSERT_GE(held, 0);
  ASSERT_EQ(flock(held, LOCK_EX | LOCK_NB), 0);  // as tahvel-ecg-source holds it while it runs
  tr::ReasonerOptions o;
  o.rules = rules("a.rules", "hot(X, true) :- temp(X, T), T > 30.\n");
  o.agent_id = "ecg";
  auto reasoner = tr::Reasoner::open(root_ / "node", o);
  ::close(held);
  ASSERT_FALSE(reasoner.has_value());
  EXPECT_NE(reasoner.error().message.find("another process runs as agent <" + kIri + "/ecg> on this node"), std::string::npos)
      << reasoner.error().message;
  EXPECT_TRUE(node_->snapshot()->item(chunk).has_value()) << "the program's record is gone";
}

// A session reports the removed facts that some rule reads, as it does the new ones: removals of
// anything else were counted ("24 removed facts" after a ring reclaimed readings no rule reads).
TEST_F(ReasonerTest, RemovedFactsThatNoRuleReadsAreNotCountedAsRemovedFacts) {
  auto r = open(rules("hot.rules", "hot(X, true) :- temp(X, T), T > 30.\n"));
  const std::uint64_t unrelated = put({{n("s1"), n("humidity"), tn::Term::integer(40)}});
  const std::uint64_t premise = put({{n("s1"), n("temp"), tn::Term::integer(35)}});
  ASSERT_TRUE(r.session().has_value());
  ASSERT_TRUE(node_->remove_item(unrelated).has_value());
  auto s = r.session();
  ASSERT_TRUE(s.has_value());
  EXPECT_EQ(s->facts_out, 0u);
  ASSERT_TRUE(node_->remove_item(premise).has_value());
  s = r.session();
  ASSERT_TRUE(s.has_value());
  EXPECT_EQ(s->facts_out, 1u);
  EXPECT_EQ(s->removed.size(), 1u);
}

// A forwarding policy routes whole items (P5): the conclusions of one session go in one item per
// predicate, so that a policy for the alert does not send up what else the session concluded.
TEST_F(ReasonerTest, EachPredicatesConclusionsOfASessionAreAnItemOfTheirOwn) {
  auto r = two_items_of_one_session("alert(X, high) :- hr(X, V), V > 100.\nnote(X, seen) :- hr(X, _).\n",
                                    {.p = n("alert")}, {.p = n("note")});
  // And the next session reads what is new only: nothing is derived twice.
  put({{n("s2"), n("hr"), tn::Term::integer(50)}});
  auto next = r.session();
  ASSERT_TRUE(next.has_value());
  EXPECT_EQ(next->added.size(), 1u);
  EXPECT_EQ(board().size(), 3u);
}

// Every class shares rdf:type: one item per predicate put a home-only class (a marker on each
// low window) in the item of the alert class the policy forwards, and both went up.
TEST_F(ReasonerTest, EachClassesConclusionsOfASessionAreAnItemOfTheirOwn) {
  const tn::Term type = tn::Term::iri(std::string(tn::kRdfType));
  two_items_of_one_session("rdf:type(X, alert) :- hr(X, V), V > 100.\nrdf:type(X, seen) :- hr(X, _).\n",
                           {.p = type, .o = n("alert")}, {.p = type, .o = n("seen")});
}

TEST_F(ReasonerTest, NoConclusionIsWrittenTwiceAcrossSessionsAndRestarts) {
  put({t("me", "state", "stateIdle"), t("me", "myNameIs", "robot3"), t("robot3", "receivedTask", "clean")});
  {
    auto r = open(source_rules("robot.rules"));
    for (int i = 0; i < 5; ++i) {
      ASSERT_TRUE(r.session().has_value());
      put({t("noise" + std::to_string(i), "unrelated", "x")});
      // The same premise written again: one more record, no new conclusion.
      put({t("robot3", "receivedTask", "clean")});
    }
  }
  auto restarted = open(source_rules("robot.rules"));
  auto s = restarted.session();
  ASSERT_TRUE(s.has_value());
  EXPECT_TRUE(s->added.empty());
  EXPECT_TRUE(s->removed.empty());
  for (const auto& [triple, count] : board()) EXPECT_EQ(count, 1) << triple;
  EXPECT_EQ(board().size(), 3u);
}

TEST_F(ReasonerTest, RemovingAPremiseRetractsExactlyWhatLostAllSupport) {
  auto file = rules("r.rules",
                    "r(X, Y) :- a(X, Y).\nr(X, Y) :- b(X, Y).\nr(X, Z) :- r(X, Y), r(Y, Z).\n"
                    "lonely(X, Y) :- r(X, Y), \\+ a(X, Y).\n");
  std::uint64_t a_xy = put({t("x", "a", "y")});
  std::uint64_t b_xy = put({t("x", "b", "y")});
  put({t("y", "a", "z")});
  auto r = open(file);
  ASSERT_TRUE(r.session().has_value());
  auto before = board();
  ASSERT_TRUE(node_->remove_item(a_xy).has_value());
  auto s = r.session();
  ASSERT_TRUE(s.has_value());
  EXPECT_TRUE(s->removed.empty());  // r(x, y) still holds through b
  ASSERT_EQ(s->added.size(), 1u);   // lonely(x, y): r(x, y) without a(x, y)
  ASSERT_TRUE(node_->remove_item(b_xy).has_value());
  s = r.session();
  ASSERT_TRUE(s.has_value());
  std::set<std::string> removed;
  for (const auto& a : s->removed) removed.insert(a.to_string());
  std::set<std::string> want = {tr::Atom{kNs + "r", {n("x"), n("y")}}.to_string(),
                                tr::Atom{kNs + "r", {n("x"), n("z")}}.to_string(),
                                tr::Atom{kNs + "lonely", {n("x"), n("y")}}.to_string(),
                                tr::Atom{kNs + "lonely", {n("x"), n("z")}}.to_string()};
  EXPECT_EQ(removed, want);
  EXPECT_EQ(before.size(), 4u);  // r(x, y), r(x, z), r(y, z), lonely(x, z)
  std::map<std::string, int> left = {{nt("y", "r", "z"), 1}};
  EXPECT_EQ(board(), left);
}

// A blank node of the board is written as its skolem IRI, <node>/.well-known/genid/bN (RS12),
// which is the only name other agents have for it. Read back as an IRI, a fact about that IRI did
// not join with the blank node's, a conclusion reached through each name was the same triple
// written twice, and removing one support removed the triple that the other still held.
TEST_F(ReasonerTest, TheSkolemIriOfABlankNodeIsReadAsThatBlankNode) {
  auto file = rules("g.rules",
                    "has(X, yes) :- name(X, _).\nhas(X, yes) :- hr(X, _).\nnamed(X, N) :- hr(X, _), name(X, N).\n");
  put({{tn::Term::blank("x"), n("hr"), tn::Term::integer(120)}});
  auto snap = node_->snapshot();
  auto hr = snap->list(tn::Pattern{.p = n("hr")});
  ASSERT_TRUE(hr && hr->size() == 1u);
  const tn::Term skolem = tn::Term::iri(kIri + "/.well-known/genid/" + hr->front().triple.s.value);
  const std::uint64_t name = put({{skolem, n("name"), tn::Term::literal("Bob")}});
  // skolem()'s own IRIs (…/genid/s…) and other nodes' are IRIs still.
  put({{tn::Term::iri(kIri + "/.well-known/genid/s00ff"), n("name"), tn::Term::literal("Eve")}});

  auto r = open(file);
  ASSERT_TRUE(r.session().has_value());
  const std::string subject = skolem.to_ntriples();
  auto b = board();
  EXPECT_EQ(b[subject + " " + n("has").to_ntriples() + " " + n("yes").to_ntriples()], 1) << "written once";
  EXPECT_EQ(b[subject + " " + n("named").to_ntriples() + " \"Bob\""], 1) << "the two names join";
  EXPECT_EQ(b["<" + kIri + "/.well-known/genid/s00ff> " + n("has").to_ntriples() + " " + n("yes").to_ntriples()], 1);

  ASSERT_TRUE(node_->remove_item(name).has_value());
  ASSERT_TRUE(r.session().has_value());
  b = board();
  EXPECT_EQ(b[subject + " " + n("has").to_ntriples() + " " + n("yes").to_ntriples()], 1) << "still held by hr";
  EXPECT_EQ(b.count(subject + " " + n("named").to_ntriples() + " \"Bob\""), 0u);
}

// A snapshot held by a process keeps the store from growing (Env::grow). The reasoner wrote a
// session's conclusions with the session's snapshot still open, so a write that needed the store
// to grow failed with store_full, and so did every session after it.
TEST_F(ReasonerTest, ASessionWhoseConclusionsMakeTheStoreGrowIsWritten) {
  const std::uint64_t first_map = node_->stats()->map_bytes;
  for (int i = 0; node_->stats()->used_bytes + (3u << 20) < first_map; ++i) {  // nearly full
    tn::Item filler;
    filler.add(n("filler" + std::to_string(i)), n("blob"),
               tn::Term::literal(std::to_string(i) + std::string(1'000'000, static_cast<char>('a' + i % 26))));
    ASSERT_TRUE(init_->store(filler).has_value());
  }
  constexpr int kLinks = 400;
  std::vector<tn::Triple> chain;
  for (int i = 0; i < kLinks; ++i) chain.push_back(t("c" + std::to_string(i), "next", "c" + std::to_string(i + 1)));
  put(chain);
  auto r = open(rules("reach.rules", "reach(X, Y) :- next(X, Y).\nreach(X, Z) :- reach(X, Y), next(Y, Z).\n"));
  auto s = r.session();
  ASSERT_TRUE(s.has_value()) << s.error().message;
  EXPECT_EQ(s->added.size(), static_cast<std::size_t>(kLinks * (kLinks + 1) / 2));
  EXPECT_GT(node_->stats()->map_bytes, first_map) << "the store did not have to grow: the test proves nothing";
}

// A conclusion with a literal over the node's limit (init --max-literal) failed the whole
// session's write: the reasoner ended with "item 1: triple 1, object: literal of 2000 bytes
// exceeds …", and every other conclusion of the session went with it. It is left out and said,
// once per predicate, and the rest is written.
TEST_F(ReasonerTest, AConclusionTheNodeCannotHoldIsLeftOutAndSaidAndTheRestIsWritten) {
  init_.reset();
  node_.reset();
  fs::remove_all(root_ / "node");
  auto small = tn::Node::init(root_ / "node", {.iri = kIri, .max_literal_bytes = 1000});
  ASSERT_TRUE(small) << small.error().message;
  node_ = std::make_unique<tn::Node>(std::move(*small));
  init_ = std::make_unique<tn::Agent>(node_->agent("init").value());
  put({t("a", "v", "b")});
  auto r = open(rules("big.rules", "big(X, S) :- v(X, _), S = \"" + std::string(2000, 'x') + "\".\nok(X) :- v(X, _).\n"));
  auto s = r.session();
  ASSERT_TRUE(s) << s.error().message;
  ASSERT_EQ(s->not_written.size(), 1u);
  EXPECT_NE(s->not_written[0].find("its literal of 2000 bytes is over this node's limit of 1000 (tahvel init "
                                   "--max-literal); the rest of the session is written"),
            std::string::npos)
      << s->not_written[0];
  ASSERT_EQ(s->added.size(), 1u);
  EXPECT_EQ(s->added[0].predicate, kNs + "ok");
  EXPECT_EQ(board().size(), 2u);  // ok(a): its node's rdf:type and rdf:_1 (NonBinaryConclusionsHaveTheDocumentedStoredForm)
  put({t("c", "v", "d")});
  auto next = r.session();
  ASSERT_TRUE(next) << next.error().message;
  EXPECT_TRUE(next->not_written.empty());  // said once
  EXPECT_EQ(next->added.size(), 1u);       // ok(c)
}

// Conclusions an earlier run wrote that no longer hold go at the first session (RS13), and the
// session says how many (it said "retracted 0").
TEST_F(ReasonerTest, TheFirstSessionReportsTheEarlierRunsConclusionsItRemoves) {
  auto file = rules("anc.rules", "anc(X, Y) :- parent(X, Y).\nanc(X, Z) :- parent(X, Y), anc(Y, Z).\n");
  put({t("a", "parent", "b")});
  const std::uint64_t b_c = put({t("b", "parent", "c")});
  {
    auto r = open(file);
    ASSERT_EQ(r.session().value().added.size(), 3u);
  }
  ASSERT_TRUE(node_->remove_item(b_c).has_value());
  auto restarted = open(file);
  auto s = restarted.session();
  ASSERT_TRUE(s.has_value());
  EXPECT_EQ(s->stale_records_removed, 2u);  // anc(b, c), anc(a, c)
  EXPECT_EQ(board(), (std::map<std::string, int>{{nt("a", "anc", "b"), 1}}));
}

// On a ring store the ring may reclaim the reasoner's own conclusions. One that still holds is
// written again at the next session (the board had lost it until the reasoner restarted).
TEST_F(ReasonerTest, AConclusionTheRingReclaimedIsWrittenAgainWhileItHolds) {
  auto ring = tn::Node::init(root_ / "ring", {.iri = kIri, .ring = 40});
  ASSERT_TRUE(ring.has_value()) << ring.error().message;
  auto writer = ring->agent("init");
  tn::Item premises;
  premises.persistent = true;  // the ring takes only non-persistent records
  premises.triples = {t("a", "parent", "b"), t("b", "parent", "c")};
  ASSERT_TRUE(writer->store(premises).has_value());
  tr::ReasonerOptions o;
  o.rules = rules("anc.rules", "anc(X, Y) :- parent(X, Y).\nanc(X, Z) :- parent(X, Y), anc(Y, Z).\n");
  auto r = tr::Reasoner::open(root_ / "ring", o);
  ASSERT_TRUE(r.has_value()) << r.error().message;
  ASSERT_EQ(r->session().value().added.size(), 3u);
  auto anc = [&] {
    auto snap = ring->snapshot();
    return *snap->count({.p = n("anc"), .source = kIri + "/reasoner"});
  };
  ASSERT_EQ(anc(), 3u);
  for (int i = 0; i < 60; ++i) {  // readings push the oldest non-persistent records out
    tn::Item reading;
    reading.add(n("sensor"), n("value"), tn::Term::integer(i));
    ASSERT_TRUE(writer->store(reading).has_value());
  }
  ASSERT_EQ(anc(), 0u) << "the ring did not reclaim the conclusions: the test proves nothing";
  auto s = r->session();
  ASSERT_TRUE(s.has_value()) << s.error().message;
  EXPECT_EQ(anc(), 3u);
  EXPECT_TRUE(s->removed.empty());
}

// The ring reclaims without a change in the stream (R17): a running reasoner waiting for a
// relevant change never saw that readings had pushed its conclusions out, and the board stayed
// without them until some premise changed.
TEST_F(ReasonerTest, RunWritesAgainTheConclusionsOtherWritersPushedOutOfTheRing) {
  auto ring = tn::Node::init(root_ / "ring", {.iri = kIri, .ring = 40});
  ASSERT_TRUE(ring.has_value()) << ring.error().message;
  auto writer = ring->agent("init");
  tn::Item premises;
  premises.persistent = true;
  premises.triples = {t("a", "parent", "b"), t("b", "parent", "c")};
  ASSERT_TRUE(writer->store(premises).has_value());
  tr::ReasonerOptions o;
  o.rules = rules("anc.rules", "anc(X, Y) :- parent(X, Y).\nanc(X, Z) :- parent(X, Y), anc(Y, Z).\n");
  o.interval = std::chrono::milliseconds(0);
  auto r = tr::Reasoner::open(root_ / "ring", o);
  ASSERT_TRUE(r.has_value()) << r.error().message;
  auto anc = [&] { return *ring->snapshot()->count({.p = n("anc"), .source = kIri + "/reasoner"}); };
  std::vector<tr::SessionReport> reports;
  std::uint64_t after_readings = 99;
  int turns = 0;
  auto ran = r->run(
      [&](const tr::SessionReport& report) {
        reports.push_back(report);
        if (reports.size() == 1) {
          for (int i = 0; i < 60; ++i) {  // irrelevant to the rules: no session of their own
            tn::Item reading;
            reading.add(n("sensor"), n("value"), tn::Term::integer(i));
            EXPECT_TRUE(writer->store(reading).has_value());
          }
          after_readings = anc();
        }
        return reports.size() < 2;
      },
      [&] { return ++turns > 30; });
  ASSERT_TRUE(ran.has_value()) << ran.error().message;
  ASSERT_EQ(after_readings, 0u) << "the ring did not reclaim the conclusions: the test proves nothing";
  ASSERT_EQ(reports.size(), 2u);
  EXPECT_TRUE(reports[1].resynced);
  EXPECT_EQ(anc(), 3u);
}

// A ring too small for the conclusions reclaims some of them as the reasoner writes them. That
// starts no session: the watch's notice of records reclaimed before they were read (R17) made
// one every turn, for ever, each writing the conclusions again.
TEST_F(ReasonerTest, RunStartsNoSessionForConclusionsItsOwnWritePushedOutOfTheRing) {
  auto ring = tn::Node::init(root_ / "ring", {.iri = kIri, .ring = 8});
  ASSERT_TRUE(ring.has_value()) << ring.error().message;
  tn::Item premises;
  premises.persistent = true;
  premises.triples = {t("a", "parent", "b"), t("b", "parent", "c"), t("c", "parent", "d"), t("d", "parent", "e")};
  ASSERT_TRUE(ring->agent("init")->store(premises).has_value());
  tr::ReasonerOptions o;
  o.rules = rules("anc.rules", "anc(X, Y) :- parent(X, Y).\nanc(X, Z) :- parent(X, Y), anc(Y, Z).\n");
  o.interval = std::chrono::milliseconds(0);
  auto r = tr::Reasoner::open(root_ / "ring", o);
  ASSERT_TRUE(r.has_value()) << r.error().message;
  int sessions = 0, turns = 0;
  auto ran = r->run([&](const tr::SessionReport&) { return ++sessions < 10; }, [&] { return ++turns > 20; });
  ASSERT_TRUE(ran.has_value()) << ran.error().message;
  ASSERT_GT(ring->stats()->reclaimed_records, 0u) << "the ring reclaimed nothing: the test proves nothing";
  EXPECT_EQ(sessions, 1);
}

// A directory opens as an empty stream; read as a rule file without rules it retracted every
// conclusion of the agent.
TEST_F(ReasonerTest, ADirectoryIsNotARuleFile) {
  tr::ReasonerOptions o;
  o.rules = root_;
  auto r = tr::Reasoner::open(root_ / "node", o);
  ASSERT_FALSE(r.has_value());
  EXPECT_EQ(r.error().message, root_.string() + ": cannot read the rule file: it is a directory");
}

// A rule file that would not open was "cannot read the rule file", without why.
TEST_F(ReasonerTest, ARuleFileThatWillNotOpenIsRefusedSayingWhy) {
  tr::ReasonerOptions o;
  o.rules = root_ / "no-such.rules";
  auto r = tr::Reasoner::open(root_ / "node", o);
  ASSERT_FALSE(r.has_value());
  EXPECT_EQ(r.error().message, (root_ / "no-such.rules").string() + ": cannot read the rule file: No such file or directory");
}

// A read that failed part way stopped the reading as the file's end did: the rules before it
// ran, those after it were retracted, and nothing said so. (/proc/self/mem fails its first read
// with EIO: its offset 0 is mapped in no process.)
TEST_F(ReasonerTest, ARuleFileWhoseReadFailsIsRefusedSayingWhy) {
  auto text = tr::read_rule_file("/proc/self/mem");
  ASSERT_FALSE(text.has_value()) << text->size() << " bytes read";
  EXPECT_EQ(text.error().message, "/proc/self/mem: error while reading the rule file: Input/output error");
}

// A rule on a misspelt predicate (rmsd for the rmssd on the board) holds for nothing, and an
// alert of it never fires, without a word: the first session, and the first after the rules
// are reloaded, say so. A predicate that nothing on the board is near may not have come yet,
// unless it is a built-in of another language (count).
TEST_F(ReasonerTest, ASessionOfNewRulesWarnsOfAPredicateTheyReadThatIsASlipOfOneOnTheBoard) {
  put({{n("w1"), n("rmssd"), tn::Term::integer(12)}, t("w1", "patient", "p1")});
  auto file = rules("alert.rules",
                    "low(P, yes) :- rmsd(W, R), patient(W, P), R < 20.\n"
                    "flag(P, yes) :- notyet(P, _).\n"
                    "mark(W, yes) :- rmssd(W, _), \\+ patiant(W, _).\n"
                    "many(P, N) :- patient(_, P), count(P, N).\n");
  auto r = open(file);
  auto s = r.session();
  ASSERT_TRUE(s.has_value()) << s.error().message;
  ASSERT_EQ(s->warnings.size(), 3u) << ::testing::PrintToString(s->warnings);
  EXPECT_EQ(s->warnings[0], file.string() + ":1:16: <" + kNs + "rmsd>: no fact on the board has this predicate; did you mean <" +
                                kNs + "rmssd> (1 record)? Until one has it, what the rules read of it holds for nothing");
  const std::string patiant = file.string() + ":3:33: <" + kNs + "patiant>: no fact on the board has this predicate; did you mean <" +
                              kNs + "patient> (1 record)?";
  // Near nothing, but a built-in of another language (a researcher's aggregation, session 87).
  const std::string count = file.string() + ":4:30: <" + kNs + "count>: no rule concludes it and no fact on the board has it, so "
                            "what the rules read of it holds for nothing; count is no built-in here (there is no aggregation; "
                            "the built-ins are in docs/reasoner.md RS5)";
  EXPECT_EQ(std::count_if(s->warnings.begin(), s->warnings.end(), [&](const std::string& w) { return w.starts_with(patiant); }), 1)
      << ::testing::PrintToString(s->warnings);
  EXPECT_EQ(std::count(s->warnings.begin(), s->warnings.end(), count), 1) << ::testing::PrintToString(s->warnings);
  put({t("w2", "patient", "p2")});
  EXPECT_TRUE(r.session().value().warnings.empty());  // said once per rules
  rules("alert.rules", "low(P, yes) :- rmssd(W, R), patient(W, P), R < 20.\n");
  auto mended = r.session();
  ASSERT_TRUE(mended.has_value());
  EXPECT_TRUE(mended->rules_reloaded);
  EXPECT_TRUE(mended->warnings.empty()) << ::testing::PrintToString(mended->warnings);
  EXPECT_EQ(board().count(nt("p1", "low", "yes")), 1u);
}

// `\+ low(W, _)` beside rules of low/1 reads triples none of those rules writes: the negation
// held for every window and each alerted, without a word (a researcher's probe, session 89). A
// board that holds such triples is read as written.
TEST_F(ReasonerTest, ASessionWarnsOfACallWithTwoArgumentsOfAPredicateTheRulesConcludeWithAnother) {
  put({{n("w1"), n("sdnn"), tn::Term::integer(12)}, {n("w2"), n("sdnn"), tn::Term::integer(80)}});
  auto file = rules("arity.rules",
                    "low(W) :- sdnn(W, V), V < 30.\n"
                    "alert(W, yes) :- sdnn(W, _), \\+ low(W, _).\n");
  auto r = open(file);
  auto s = r.session();
  ASSERT_TRUE(s.has_value()) << s.error().message;
  ASSERT_EQ(s->warnings.size(), 1u) << ::testing::PrintToString(s->warnings);
  EXPECT_EQ(s->warnings[0], file.string() + ":2:33: <" + kNs + "low> with 2 arguments is concluded by no rule (its rules have arity 1) "
                            "and no fact on the board has it, so a call of it holds for nothing and its negation for everything: "
                            "give the call its rules' arguments");
  rules("arity.rules",
        "low(W) :- sdnn(W, V), V < 30.\n"
        "alert(W, yes) :- sdnn(W, _), \\+ low(W).\n");
  auto mended = r.session();
  ASSERT_TRUE(mended.has_value()) << mended.error().message;
  EXPECT_TRUE(mended->warnings.empty()) << ::testing::PrintToString(mended->warnings);
  EXPECT_EQ(board().count(nt("w2", "alert", "yes")), 1u);
  EXPECT_EQ(board().count(nt("w1", "alert", "yes")), 0u);
}

TEST_F(ReasonerTest, RulesReloadAndABrokenFileIsReportedWhileThePreviousRulesRun) {
  auto file = rules("live.rules", "p(X, Y) :- a(X, Y).\n");
  put({t("x", "a", "y")});
  auto r = open(file);
  ASSERT_TRUE(r.session().has_value());
  EXPECT_EQ(board().count(nt("x", "p", "y")), 1u);
  rules("live.rules", "q(X, Y) :- a(X, Y).\n");
  auto s = r.session();
  ASSERT_TRUE(s.has_value());
  EXPECT_TRUE(s->rules_reloaded);
  EXPECT_EQ(board().count(nt("x", "p", "y")), 0u);
  EXPECT_EQ(board().count(nt("x", "q", "y")), 1u);
  rules("live.rules", "q(X, Y) :- a(X, Y).\nbroken(X :- a(X, Y).\n");
  put({t("u", "a", "v")});
  s = r.session();
  ASSERT_TRUE(s.has_value());
  ASSERT_TRUE(s->rules_error.has_value());
  EXPECT_EQ(s->rules_error->rfind((root_ / "live.rules").string() + ":2:10:", 0), 0u) << *s->rules_error;
  EXPECT_EQ(board().count(nt("u", "q", "v")), 1u);  // the previous rules ran
}

// `tahvel status` shows what the board says: a rule file that does not parse is the reasoner's
// problem there until a rule file parses, or the reasoner starts again (with rules that parse).
TEST_F(ReasonerTest, ABrokenRuleFileIsTheReasonersProblemOnTheBoardUntilRulesParse) {
  auto file = rules("live.rules", "p(X, Y) :- a(X, Y).\n");
  put({t("x", "a", "y")});
  auto problems = [&] { return node_->snapshot().value().list({.p = tn::Term::iri(tn::kProblem)}).value(); };
  {
    auto r = open(file);
    ASSERT_TRUE(r.session().has_value());
    EXPECT_TRUE(problems().empty());
    rules("live.rules", "p(X, Y) :- a(X, Y).\nbroken(X :- a(X, Y).\n");
    ASSERT_TRUE(r.session().value().rules_error.has_value());
    auto said = problems();
    ASSERT_EQ(said.size(), 1u);
    EXPECT_EQ(said[0].triple.s, tn::Term::iri(r.iri()));
    EXPECT_EQ(said[0].meta.source, r.iri());
    EXPECT_EQ(said[0].triple.o.value.rfind("rules not reloaded (the previous rules run): " + file.string() + ":2:10:", 0), 0u)
        << said[0].triple.o.value;
    // Not a conclusion: a session leaves it, and the conclusions, as they are.
    put({t("u", "a", "v")});
    ASSERT_TRUE(r.session().has_value());
    EXPECT_EQ(problems().size(), 1u);
    EXPECT_EQ(board().count(nt("u", "p", "v")), 1u);
    rules("live.rules", "p(X, Y) :- a(X, Y).\n");
    ASSERT_TRUE(r.session().value().rules_reloaded);
    EXPECT_TRUE(problems().empty());
    EXPECT_EQ(board().count(nt("x", "p", "y")), 1u);
    // A file that is not UTF-8 (Latin-1 here): the error quotes its bytes; the problem says
    // them as replacement characters, and the session goes on.
    rules("live.rules", "caf\xE9(X :- a(X, Y).\n");
    auto latin1 = r.session();
    ASSERT_TRUE(latin1.has_value()) << latin1.error().message;
    EXPECT_FALSE(latin1->problem_not_written) << *latin1->problem_not_written;
    said = problems();
    ASSERT_EQ(said.size(), 1u);
    EXPECT_EQ(tn::ill_formed_utf8_at(said[0].triple.o.value), std::string_view::npos);
    // With the process that runs it, for `status` to find its program by.
    auto pid = node_->snapshot().value().list({.s = tn::Term::iri(r.iri()), .p = tn::Term::iri(tn::kProblemPid)}).value();
    ASSERT_EQ(pid.size(), 1u);
    EXPECT_EQ(pid[0].triple.o, tn::Term::integer(getpid()));
  }
  rules("live.rules", "p(X, Y) :- a(X, Y).\n");
  auto again = open(file);
  EXPECT_TRUE(problems().empty());
  EXPECT_EQ(node_->snapshot().value().count({.p = tn::Term::iri(tn::kProblemPid)}).value(), 0u);
  ASSERT_TRUE(again.session().has_value());
  EXPECT_EQ(board(), (std::map<std::string, int>{{nt("x", "p", "y"), 1}, {nt("u", "p", "v"), 1}}));
}

// The board after random sessions of insertions and removals holds exactly the conclusions of
// a from-scratch evaluation of the board's other records.
TEST_F(ReasonerTest, BoardEqualsFromScratchEvaluationOnRandomData) {
  const std::string text =
      "reach(X, Y) :- edge(X, Y).\nreach(X, Z) :- reach(X, Y), edge(Y, Z).\n"
      "cyclic(X) :- reach(X, X).\nacyclic_start(X) :- edge(X, Y), \\+ cyclic(X).\n";
  auto file = rules("d.rules", text);
  auto r = open(file);
  std::mt19937 rng(7);
  std::vector<std::uint64_t> items;
  for (int session = 0; session < 25; ++session) {
    for (int i = 0, k = 1 + static_cast<int>(rng() % 6); i < k; ++i)
      items.push_back(put({t("v" + std::to_string(rng() % 9), "edge", "v" + std::to_string(rng() % 9))}));
    for (int i = 0, k = static_cast<int>(rng() % 3); i < k && !items.empty(); ++i) {
      std::size_t j = rng() % items.size();
      ASSERT_TRUE(node_->remove_item(items[j]).has_value());
      items.erase(items.begin() + static_cast<long>(j));
    }
    ASSERT_TRUE(r.session().has_value());
  }
  tr::ParseOptions po;
  po.default_ns = kNs;
  po.me = kIri;
  auto program = tr::parse_rules(text, po);
  ASSERT_TRUE(program.has_value());
  tr::Engine scratch(*program);
  std::vector<tn::Triple> base;
  auto snap = node_->snapshot();
  tn::Pattern p;
  p.source = kIri + "/init";
  auto records = snap->list(p);
  ASSERT_TRUE(records.has_value());
  for (const auto& rec : *records) base.push_back(rec.triple);
  scratch.apply(base, {}, 0);
  std::map<std::string, int> want;
  for (const auto& atom : scratch.conclusions())
    for (const auto& tr3 : tr::store_form(atom, kIri + "/reasoner/c/"))
      ++want[tr3.s.to_ntriples() + " " + tr3.p.to_ntriples() + " " + tr3.o.to_ntriples()];
  EXPECT_EQ(board(), want);
}

// A writer thread stores items of two triples (x p1 v, x p2 v) and removes some; a session that
// saw half an item would derive half(x). Every session, and the final board, must show none.
TEST_F(ReasonerTest, ASessionNeverSeesAHalfWrittenItem) {
  auto file = rules("h.rules", "half(X) :- p1(X, V), \\+ p2(X, V).\nhalf(X) :- p2(X, V), \\+ p1(X, V).\n"
                               "whole(X, V) :- p1(X, V), p2(X, V).\n");
  auto r = open(file);
  std::atomic<bool> done{false};
  std::thread writer([&] {
    auto node = tn::Node::open(root_ / "node");
    auto agent = node->agent("writer");
    std::vector<std::uint64_t> mine;
    for (int i = 0; i < 400; ++i) {
      tn::Item item;
      std::string x = "x" + std::to_string(i);
      item.add(n(x), n("p1"), tn::Term::integer(i)).add(n(x), n("p2"), tn::Term::integer(i));
      auto id = agent->store(item);
      if (id) mine.push_back(*id);
      if (i % 7 == 3 && !mine.empty()) {
        (void)node->remove_item(mine.front());
        mine.erase(mine.begin());
      }
    }
    done = true;
  });
  int sessions = 0;
  while (!done || sessions < 3) {
    auto s = r.session();
    ASSERT_TRUE(s.has_value()) << s.error().message;
    for (const auto& a : s->added) EXPECT_NE(a.predicate, kNs + "half") << a.to_string();
    ++sessions;
  }
  writer.join();
  ASSERT_TRUE(r.session().has_value());
  auto snap = node_->snapshot();
  tn::Pattern p1;
  p1.p = n("p1");
  std::size_t items = *snap->count(p1);
  std::size_t whole = 0, half = 0;
  for (const auto& [triple, count] : board()) {
    EXPECT_EQ(count, 1);
    whole += triple.find("#whole>") != std::string::npos;
    half += triple.find("#half>") != std::string::npos;
  }
  EXPECT_EQ(whole, items);
  EXPECT_EQ(half, 0u);
}

// A reasoner's run() on a thread of its own, its session reports collected, until stopped (also
// when a test ends early).
class Running {
 public:
  explicit Running(tr::Reasoner& r)
      : thread_([this, &r] {
          auto ran = r.run(
              [this](const tr::SessionReport& report) {
                std::lock_guard lock(mu_);
                reports_.push_back(report);
                cv_.notify_all();
                return true;
              },
              [this] { return stop_.load(); });
          EXPECT_TRUE(ran.has_value()) << ran.error().message;
        }) {}
  ~Running() { stop(); }
  void stop() {
    stop_ = true;
    if (thread_.joinable()) thread_.join();
  }
  // Whether `holds` comes true of the reports within 20 s.
  bool wait(const std::function<bool(const std::vector<tr::SessionReport>&)>& holds) {
    std::unique_lock lock(mu_);
    return cv_.wait_for(lock, std::chrono::seconds(20), [&] { return holds(reports_); });
  }
  std::vector<tr::SessionReport> reports() {
    std::lock_guard lock(mu_);
    return reports_;
  }

 private:
  std::mutex mu_;
  std::condition_variable cv_;
  std::vector<tr::SessionReport> reports_;
  std::atomic<bool> stop_{false};
  std::thread thread_;  // last: started once the rest is made
};

// RS16: run() starts a session when a record that some rule reads arrives (not for records no
// rule reads), and stops when asked.
TEST_F(ReasonerTest, RunStartsASessionWhenARelevantRecordArrives) {
  auto file = rules("w.rules", "p(X, Y) :- a(X, Y).\n");
  auto r = open(file);
  Running running(r);
  auto sessions = [&](std::size_t n) { return running.wait([&](const auto& reports) { return reports.size() >= n; }); };
  ASSERT_TRUE(sessions(1));  // the first session, at start
  put({t("noise", "unread", "x")});
  put({t("x", "a", "y")});
  ASSERT_TRUE(sessions(2));
  running.stop();
  bool derived = false;
  for (const auto& report : running.reports())
    for (const auto& a : report.added) derived |= a.predicate == kNs + "p";
  EXPECT_TRUE(derived);
  EXPECT_EQ(board().count(nt("x", "p", "y")), 1u);
}

// `tahvel remove -s -p -o` removes every matching record, the reasoner's copy of a fact that is
// also derived among them. Such a conclusion stayed off the board until a restart (or, by
// chance, a gap in the change stream) although it still held.
TEST_F(ReasonerTest, AConclusionRemovedByHandIsWrittenAgainWhileItHolds) {
  auto file = rules("sym.rules", "f(Y, X) :- f(X, Y).\n");
  put({t("a", "f", "b")});
  put({t("b", "f", "a")});
  auto r = open(file);
  Running running(r);
  auto sessions = [&](std::size_t n) { return running.wait([&](const auto& reports) { return reports.size() >= n; }); };
  ASSERT_TRUE(sessions(1));
  ASSERT_EQ(board().count(nt("a", "f", "b")), 1u);
  ASSERT_EQ(board().count(nt("b", "f", "a")), 1u);
  const auto pattern = [](const std::string& s, const std::string& o) {
    tn::Pattern p;
    p.s = n(s);
    p.p = n("f");
    p.o = n(o);
    return p;
  };
  // Only the reasoner's record: nothing any rule reads changed, and yet a session must run.
  tn::Pattern mine = pattern("a", "b");
  mine.source = kIri + "/reasoner";
  auto removed = node_->remove(mine);
  ASSERT_TRUE(removed.has_value());
  ASSERT_EQ(*removed, 1u);
  ASSERT_TRUE(sessions(2));
  EXPECT_TRUE(running.wait([&](const auto&) { return board().count(nt("a", "f", "b")) == 1; }));
  // Every record of b f a, the fact and the conclusion, which a f b still gives.
  removed = node_->remove(pattern("b", "a"));
  ASSERT_TRUE(removed.has_value());
  ASSERT_EQ(*removed, 2u);
  ASSERT_TRUE(sessions(3));
  running.stop();
  std::map<std::string, int> both = {{nt("a", "f", "b"), 1}, {nt("b", "f", "a"), 1}};
  EXPECT_EQ(board(), both);
}

// Removing a fact routed to an agent that receives removal notices (an uplink's) gives the notice
// a sequence number that is neither a record nor a logged removal. The session after reads the
// removal as a change, not as a gap: under `tahvel up` a supervisor replacing a link's items
// made every reasoner on the node read its whole board again every few seconds.
TEST_F(ReasonerTest, ARemovalThatSendsANoticeIsReadAsAChangeNotAsAGap) {
  auto uplink = node_->agent("uplink");
  ASSERT_TRUE(uplink.has_value());
  ASSERT_TRUE(uplink->subscribe({.p = n("p")}).has_value());
  ASSERT_TRUE(uplink->receive_removals().has_value());
  put({t("a", "p", "b")});
  put({t("c", "p", "d")});
  auto r = open(rules("notice.rules", "r(X, Y) :- p(X, Y).\n"));
  ASSERT_TRUE(r.session().has_value());
  ASSERT_EQ(board(), (std::map<std::string, int>{{nt("a", "r", "b"), 1}, {nt("c", "r", "d"), 1}}));
  const std::uint64_t notices_before = node_->snapshot()->notice_seqs();
  ASSERT_EQ(*node_->remove({.s = n("a"), .p = n("p")}), 1u);
  ASSERT_EQ(node_->snapshot()->notice_seqs(), notices_before + 1) << "no notice was sent: the test proves nothing";
  auto s = r.session();
  ASSERT_TRUE(s.has_value()) << s.error().message;
  EXPECT_FALSE(s->resynced);
  ASSERT_EQ(s->removed.size(), 1u);
  EXPECT_EQ(board(), (std::map<std::string, int>{{nt("c", "r", "d"), 1}}));
  // Its notice is still in the uplink's input buffer: a second removal, a second number.
  ASSERT_EQ(*node_->remove({.s = n("c"), .p = n("p")}), 1u);
  s = r.session();
  ASSERT_TRUE(s.has_value()) << s.error().message;
  EXPECT_FALSE(s->resynced);
  EXPECT_TRUE(board().empty());
}

// A finite closure larger than the default limit on a session's conclusions (a restart derives
// all of it in one session) runs with a larger --max-conclusions; below it, the error says so.
TEST_F(ReasonerTest, TheLimitOnASessionsConclusionsIsTheReasonersSetting) {
  auto file = rules("anc.rules", "anc(X, Y) :- parent(X, Y).\nanc(X, Z) :- anc(X, Y), parent(Y, Z).\n");
  for (int i = 0; i < 10; ++i) put({t("p" + std::to_string(i), "parent", "p" + std::to_string(i + 1))});  // 55 conclusions
  tr::ReasonerOptions o;
  o.rules = file;
  o.max_conclusions = 50;
  {
    auto r = tr::Reasoner::open(root_ / "node", o);
    ASSERT_TRUE(r.has_value()) << r.error().message;
    auto s = r->session();
    ASSERT_FALSE(s.has_value());
    EXPECT_NE(s.error().message.find("more than 50 conclusions in one session"), std::string::npos) << s.error().message;
    EXPECT_NE(s.error().message.find("--max-conclusions"), std::string::npos) << s.error().message;
  }
  o.max_conclusions = 55;
  auto r = tr::Reasoner::open(root_ / "node", o);
  ASSERT_TRUE(r.has_value()) << r.error().message;
  auto s = r->session();
  ASSERT_TRUE(s.has_value()) << s.error().message;
  EXPECT_EQ(s->added.size(), 55u);
}

// RS16: rules on `now` change their conclusions as time passes, with nothing on the board
// changing: "no reading for 2 s" comes to hold 2 s after the last reading, on a quiet board.
TEST_F(ReasonerTest, ARuleOnNowComesToHoldAsTimePassesOnAQuietBoard) {
  auto file = rules("quiet.rules", "recent(P) :- last(P, T), now(N), T >= N - 2.\nstale(P) :- patient(P, yes), \\+ recent(P).\n");
  const auto seconds_now = std::chrono::duration_cast<std::chrono::seconds>(std::chrono::system_clock::now().time_since_epoch()).count();
  put({t("x", "patient", "yes"), {n("x"), n("last"), tn::Term::integer(seconds_now)}});
  auto r = open(file);
  Running running(r);
  ASSERT_TRUE(running.wait([](const auto& reports) { return !reports.empty(); }));
  const std::vector<tr::SessionReport> first = running.reports();  // kept: a range-for over a temporary's member dangles
  for (const auto& a : first.front().added) EXPECT_NE(a.predicate, kNs + "stale") << "stale at once";
  EXPECT_TRUE(running.wait([](const auto& reports) {
    for (const auto& report : reports)
      for (const auto& a : report.added)
        if (a.predicate == kNs + "stale") return report.clocked;
    return false;
  })) << "not stale after 20 s of quiet";
  running.stop();
  bool written = false;
  for (const auto& [triple, records] : board()) written |= triple.find(kNs + "stale") != std::string::npos;
  EXPECT_TRUE(written) << "stale(x) is not on the board";
}

// RS15: new rules are evaluated on the board. A new rule that reads a predicate the old rules did
// not read derives from the facts of it already there, as a restart would.
TEST_F(ReasonerTest, AReloadWithANewRuleDerivesFromFactsOnTheBoard) {
  put({t("a", "p", "b"), t("a", "q", "c")});
  auto file = rules("new.rules", "r1(X, Y) :- p(X, Y).\n");
  auto r = open(file);
  ASSERT_TRUE(r.session().has_value());
  rules("new.rules", "r1(X, Y) :- p(X, Y).\nr2(X, Y) :- q(X, Y).\n");
  auto s = r.session();
  ASSERT_TRUE(s.has_value()) << s.error().message;
  EXPECT_TRUE(s->rules_reloaded);
  EXPECT_FALSE(s->resynced);
  EXPECT_EQ(board(), (std::map<std::string, int>{{nt("a", "r1", "b"), 1}, {nt("a", "r2", "c"), 1}}));
  s = r.session();  // and nothing again
  ASSERT_TRUE(s.has_value());
  EXPECT_TRUE(s->added.empty());
  EXPECT_TRUE(s->removed.empty());
}

// A rule file briefly empty (an editor truncating it before writing) retracts the conclusions;
// the same rules back give them back.
TEST_F(ReasonerTest, ARuleFileEmptiedAndRestoredGetsItsConclusionsBack) {
  put({t("a", "e", "b"), t("b", "e", "c")});
  const std::string text = "tc(X, Y) :- e(X, Y).\ntc(X, Z) :- e(X, Y), tc(Y, Z).\n";
  auto file = rules("tc.rules", text);
  auto r = open(file);
  ASSERT_TRUE(r.session().has_value());
  const std::map<std::string, int> closure = {{nt("a", "tc", "b"), 1}, {nt("a", "tc", "c"), 1}, {nt("b", "tc", "c"), 1}};
  EXPECT_EQ(board(), closure);
  rules("tc.rules", "");
  auto s = r.session();
  ASSERT_TRUE(s.has_value());
  EXPECT_TRUE(s->rules_reloaded);
  EXPECT_TRUE(board().empty());
  rules("tc.rules", text);
  s = r.session();
  ASSERT_TRUE(s.has_value());
  EXPECT_TRUE(s->rules_reloaded);
  EXPECT_EQ(s->added.size(), 3u);
  EXPECT_EQ(board(), closure);
}

// The same, when the truncating save is read in between and its write lands within the file
// system's timestamp resolution (mtime and ctime unchanged): the rules as written are read,
// not the empty file for good. The file here is at least read back once written.
TEST_F(ReasonerTest, ARuleFileReadWhileHalfWrittenIsReadAgainOnceWritten) {
  put({t("a", "e", "b")});
  auto file = rules("half.rules", "p(X, Y) :- e(X, Y).\n");
  auto r = open(file);
  ASSERT_TRUE(r.session().has_value());
  std::ofstream save(file, std::ios::trunc);
  ASSERT_TRUE(r.session().value().rules_reloaded);
  EXPECT_TRUE(board().empty());
  save << "q(X, Y) :- e(X, Y).\n";
  save.close();
  auto s = r.session();
  ASSERT_TRUE(s.has_value());
  EXPECT_TRUE(s->rules_reloaded);
  EXPECT_EQ(board(), (std::map<std::string, int>{{nt("a", "q", "b"), 1}}));
}

// A rule file copied over with its old mtime kept (`cp -p`, `rsync -t`) is a new rule file.
TEST_F(ReasonerTest, ARuleFileChangedUnderItsOldMtimeIsReloaded) {
  put({t("a", "e", "b")});
  auto file = rules("kept.rules", "p(X, Y) :- e(X, Y).\n");
  const auto old_mtime = fs::last_write_time(file);
  auto r = open(file);
  ASSERT_TRUE(r.session().has_value());
  std::ofstream(file, std::ios::trunc) << "q(X, Y) :- e(X, Y).\n";
  fs::last_write_time(file, old_mtime);
  auto s = r.session();
  ASSERT_TRUE(s.has_value());
  EXPECT_TRUE(s->rules_reloaded);
  EXPECT_EQ(board(), (std::map<std::string, int>{{nt("a", "q", "b"), 1}}));
}

// A rule file replaced by one whose expression would overflow the parser's stack is reported
// (RS15) and the previous rules keep running: the process does not die.
TEST_F(ReasonerTest, ADeeplyNestedExpressionOnReloadIsReportedWhileThePreviousRulesRun) {
  auto file = rules("deep.rules", "r(X, W) :- v(X, V), W is V + 1.\n");
  auto r = open(file);
  ASSERT_TRUE(r.session().has_value());
  rules("deep.rules", "r(X, W) :- v(X, V), W is " + std::string(100000, '(') + "V" + std::string(100000, ')') + ".\n");
  put({{n("a"), n("v"), tn::Term::integer(1)}});
  auto s = r.session();
  ASSERT_TRUE(s.has_value());
  ASSERT_TRUE(s->rules_error.has_value());
  EXPECT_EQ(s->rules_error->rfind((root_ / "deep.rules").string() + ":1:", 0), 0u) << *s->rules_error;
  EXPECT_NE(s->rules_error->find("nested deeper than 1000"), std::string::npos) << *s->rules_error;
  ASSERT_EQ(s->added.size(), 1u);  // the previous rules ran
  EXPECT_EQ(s->added[0].args[1], tn::Term::integer(2));
}

// One bulk change (one item, more changes than one watch batch) gives one session: the loop
// does not go on reading the batches the session already covered, starting a session with
// nothing to do for each. stop() is asked once per loop turn, and each turn after the bulk
// session with a leftover batch would run one at once (interval 0); twelve turns with no session
// cover the eight batches of the reasoner's own conclusions, which do not count.
TEST_F(ReasonerTest, ABulkChangeGivesOneSessionNotOnePerWatchBatch) {
  tr::ReasonerOptions o;
  o.rules = rules("bulk.rules", "r(X, Y) :- e(X, Y).\n");
  o.interval = std::chrono::milliseconds(0);
  auto r = tr::Reasoner::open(root_ / "node", o);
  ASSERT_TRUE(r.has_value()) << r.error().message;
  tn::Item bulk;
  for (int i = 0; i < 30000; ++i) bulk.add(n("x" + std::to_string(i)), n("e"), n("y" + std::to_string(i)));
  std::vector<tr::SessionReport> reports;
  int turns_after_bulk = 0;
  auto ran = r->run(
      [&](const tr::SessionReport& report) {
        reports.push_back(report);
        if (reports.size() == 1) {
          EXPECT_TRUE(init_->store(bulk).has_value());  // while running
        }
        return reports.size() < 5;
      },
      [&] { return reports.size() >= 2 && ++turns_after_bulk > 12; });
  ASSERT_TRUE(ran.has_value()) << ran.error().message;
  ASSERT_EQ(reports.size(), 2u);
  EXPECT_EQ(reports[1].added.size(), 30000u);
}

// An interval beyond one day would overflow run()'s arithmetic in nanoseconds (and a negative
// one is what a wrapped-around unsigned flag gives): refused at open, naming the option.
TEST_F(ReasonerTest, AnIntervalAboveOneDayIsRefused) {
  tr::ReasonerOptions o;
  o.rules = rules("i.rules", "r(X, Y) :- e(X, Y).\n");
  for (auto bad : {std::chrono::milliseconds(10'000'000'000'000), std::chrono::milliseconds(-1),
                   tr::kMaxInterval + std::chrono::milliseconds(1)}) {
    o.interval = bad;
    auto r = tr::Reasoner::open(root_ / "node", o);
    ASSERT_FALSE(r.has_value()) << bad.count();
    EXPECT_EQ(r.error().message, "the interval between sessions (--interval) must be 0 to 86400000 ms (one day)");
  }
  o.interval = tr::kMaxInterval;
  EXPECT_TRUE(tr::Reasoner::open(root_ / "node", o).has_value());
}

}  // namespace
