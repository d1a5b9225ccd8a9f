// The dispatcher (dispatcher.h) with the reasoner: the thesis' behaviour rules (Paper 2 §7.1)
// derive command records, the dispatcher starts the named executables through the supervisor,
// writes their end back (state, exit status, result), and the result feeds the next rule;
// a stop command ends a running behaviour; a command naming no behaviour is refused.
#include <gtest/gtest.h>
#include <stdlib.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <functional>

#include "tahvel/agents/dispatcher.h"
#include "tahvel/agents/reasoner.h"
#include "tahvel/node/node.h"
#include "temp_dir.h"

namespace {

namespace fs = std::filesystem;
namespace ta = tahvel::agents;
namespace tn = tahvel::node;
namespace tr = tahvel::reasoner;
using namespace std::chrono_literals;

const std::string kIri = "http://example.org/robot3";
const std::string kNs = kIri + "#";
const std::string kTv = "https://w3id.org/tahvel#";

tn::Term n(const std::string& local) { return local == "me" ? tn::Term::iri(kIri) : tn::Term::iri(kNs + local); }

class DispatcherTest : public ::testing::Test {
 protected:
  void SetUp() override {
    ASSERT_TRUE(tn::Node::init(root_ / "node", {.iri = kIri}).has_value());
    fs::create_directories(root_ / "behaviours");
    script("goAhead", "echo moving at \"$1\" >&2\necho ok\n");
    script("solveObstacle", "echo fail\nexit 1\n");
    script("handleFailState", "echo stopped motors\n");
    script("monitorObstacles", "exec sleep 300\n");
    auto node = tn::Node::open(root_ / "node");
    node_ = std::make_unique<tn::Node>(std::move(*node));
  }
  void TearDown() override {
    node_.reset();
  }
  void script(const std::string& name, const std::string& body) {
    fs::path p = root_ / "behaviours" / name;
    std::ofstream(p) << "#!/bin/sh\n" << body;
    fs::permissions(p, fs::perms::owner_all);
  }
  void put(std::vector<tn::Triple> triples, const std::string& context = "") {
    auto agent = node_->agent("sensors");
    tn::Item item;
    item.triples = std::move(triples);
    item.context = context;
    ASSERT_TRUE(agent->store(item).has_value());
  }
  bool holds(const tn::Term& s, const std::string& p, const tn::Term& o) {
    auto snap = node_->snapshot();
    return *snap->count({.s = s, .p = tn::Term::iri(p), .o = o}) > 0;
  }
  // Polls until `done` or 30 s.
  std::vector<ta::DispatchEvent> poll_until(ta::Dispatcher& d, const std::function<bool()>& done) {
    std::vector<ta::DispatchEvent> all;
    auto deadline = std::chrono::steady_clock::now() + 30s;
    while (!done() && std::chrono::steady_clock::now() < deadline) {
      auto events = d.poll(20ms);
      EXPECT_TRUE(events.has_value());
      if (events) all.insert(all.end(), events->begin(), events->end());
    }
    return all;
  }
  tahvel::test_support::TempDir tmp_{"tahvel-dispatcher"};
  const fs::path root_ = tmp_.path();
  std::unique_ptr<tn::Node> node_;
};

TEST_F(DispatcherTest, ThesisBehaviourRulesRunThroughTheSupervisorAndResultsFeedBack) {
  fs::path rules = root_ / "behaviours.rules";
  std::ofstream(rules) << "behavior(me, \"goAhead 200\") :-\n  state(me, stateCanmove),\n  obstacle(me, nothing).\n"
                          "behavior(me, \"handleFailState\") :-\n  result(solveObstacle, fail),\n"
                          "  state(me, stateDriveAround).\n";
  ta::Supervisor supervisor([](std::string_view) {});
  auto d = ta::Dispatcher::open(root_ / "node", {.folder = root_ / "behaviours"}, supervisor);
  ASSERT_TRUE(d.has_value()) << d.error().message;
  tr::ReasonerOptions ro;
  ro.rules = rules;
  auto r = tr::Reasoner::open(root_ / "node", ro);
  ASSERT_TRUE(r.has_value()) << r.error().message;

  put({{n("me"), n("state"), n("stateCanmove")}, {n("me"), n("obstacle"), n("nothing")}});
  ASSERT_TRUE(r->session().has_value());
  poll_until(*d, [&] { return holds(n("goAhead"), kNs + "result", n("ok")); });
  EXPECT_TRUE(holds(n("goAhead"), kNs + "result", n("ok")));
  auto snap = node_->snapshot();
  auto states = snap->list({.p = tn::Term::iri(kTv + "exitStatus")});
  ASSERT_EQ(states->size(), 1u);
  EXPECT_EQ(states->at(0).triple.o, tn::Term::integer(0));
  EXPECT_EQ(states->at(0).meta.source, d->iri());

  // A command written by hand (context: the dispatcher), then the rule on its result.
  put({{n("me"), n("behavior"), tn::Term::literal("solveObstacle")}}, d->iri());
  poll_until(*d, [&] { return holds(n("solveObstacle"), kNs + "result", n("fail")); });
  put({{n("me"), n("state"), n("stateDriveAround")}});
  ASSERT_TRUE(r->session().has_value());
  poll_until(*d, [&] { return holds(n("handleFailState"), kNs + "result", tn::Term::literal("stopped motors")); });
  EXPECT_TRUE(holds(n("handleFailState"), kNs + "result", tn::Term::literal("stopped motors")));
  // Sessions without new premises write no command again: nothing more starts.
  ASSERT_TRUE(r->session().has_value());
  auto events = d->poll(50ms);
  ASSERT_TRUE(events.has_value());
  EXPECT_TRUE(events->empty());
  EXPECT_EQ(d->running(), 0u);
}

TEST_F(DispatcherTest, StopCommandEndsARunningBehaviourAndUnknownNamesAreRefused) {
  ta::Supervisor supervisor([](std::string_view) {});
  auto d = ta::Dispatcher::open(root_ / "node", {.folder = root_ / "behaviours"}, supervisor);
  ASSERT_TRUE(d.has_value());
  put({{n("me"), n("behavior"), tn::Term::literal("monitorObstacles")}}, d->iri());
  poll_until(*d, [&] { return d->running() == 1; });
  ASSERT_EQ(d->running(), 1u);
  put({{n("me"), n("behavior"), tn::Term::literal("stop monitorObstacles")}}, d->iri());
  auto events = poll_until(*d, [&] { return d->running() == 0; });
  EXPECT_EQ(d->running(), 0u);
  EXPECT_TRUE(holds(tn::Term::iri(events.empty() ? "" : events.back().run), kTv + "state", tn::Term::literal("stopped")));
  put({{n("me"), n("behavior"), tn::Term::literal("../../bin/sh -c true")}}, d->iri());
  put({{n("me"), n("behavior"), tn::Term::literal("noSuchBehaviour 1")}}, d->iri());
  // Addressed to another agent: not a command for the dispatcher.
  put({{n("me"), n("behavior"), tn::Term::literal("goAhead 1")}}, kIri + "/someone-else");
  auto snap_count = [&] {
    auto snap = node_->snapshot();
    return *snap->count({.p = tn::Term::iri(kTv + "state"), .o = tn::Term::literal("refused")});
  };
  poll_until(*d, [&] { return snap_count() == 2; });
  EXPECT_EQ(snap_count(), 2u);
  auto more = d->poll(50ms);
  ASSERT_TRUE(more.has_value());
  EXPECT_EQ(d->running(), 0u);
  EXPECT_FALSE(holds(n("goAhead"), kNs + "result", n("ok")));
}

// A stop that finds nothing to stop, a bare "stop", and a behaviour file without its execute
// bit were passed over without a word, or called "no such executable behaviour" (an
// exploratory run of session 81). Each is refused saying why.
TEST_F(DispatcherTest, AStopOfNothingRunningABareStopAndAFileThatIsNotExecutableAreRefusedSayingWhy) {
  std::ofstream(root_ / "behaviours" / "notExecutable") << "#!/bin/sh\necho ok\n";
  fs::permissions(root_ / "behaviours" / "notExecutable", fs::perms::owner_read | fs::perms::owner_write);
  ta::Supervisor supervisor([](std::string_view) {});
  auto d = ta::Dispatcher::open(root_ / "node", {.folder = root_ / "behaviours"}, supervisor);
  ASSERT_TRUE(d.has_value());
  std::vector<ta::DispatchEvent> events;
  for (const char* command : {"stop monitorObstacle", "stop", "notExecutable"}) {
    put({{n("me"), n("behavior"), tn::Term::literal(command)}}, d->iri());
    auto more = poll_until(*d, [&] {
      auto snap = node_->snapshot();
      return *snap->count({.p = tn::Term::iri(kTv + "command"), .o = tn::Term::literal(command)}) == 1;
    });
    events.insert(events.end(), more.begin(), more.end());
  }
  const auto refused_saying = [&](const std::string& command, const std::string& why) {
    return std::any_of(events.begin(), events.end(), [&](const ta::DispatchEvent& e) {
      return e.kind == ta::DispatchEvent::refused && e.command == command && e.detail.find(why) != std::string::npos;
    });
  };
  EXPECT_TRUE(refused_saying("stop monitorObstacle", "no run of 'monitorObstacle' is running, so none was stopped (none is running)"));
  EXPECT_TRUE(refused_saying("stop", "'stop' names no behaviour to stop: write \"stop NAME\""));
  EXPECT_TRUE(refused_saying("notExecutable", "notExecutable: not executable by this user (chmod +x it)"));
  EXPECT_EQ(d->running(), 0u);
}

// `behavior(me, goAhead)` for `behavior(me, "goAhead")`: a command written as an IRI was passed
// over without a run record or a word in the log.
TEST_F(DispatcherTest, ACommandWrittenAsAnIriIsRefusedSayingToQuoteIt) {
  ta::Supervisor supervisor([](std::string_view) {});
  auto d = ta::Dispatcher::open(root_ / "node", {.folder = root_ / "behaviours"}, supervisor);
  ASSERT_TRUE(d.has_value());
  put({{n("me"), n("behavior"), n("goAhead")}}, d->iri());
  std::vector<ta::DispatchEvent> events = poll_until(*d, [&] {
    auto snap = node_->snapshot();
    return *snap->count({.p = tn::Term::iri(kTv + "state"), .o = tn::Term::literal("refused")}) == 1;
  });
  ASSERT_EQ(events.size(), 1u);
  EXPECT_EQ(events[0].kind, ta::DispatchEvent::refused);
  EXPECT_NE(events[0].detail.find("<" + kNs + "goAhead> is not a string: write it quoted"), std::string::npos) << events[0].detail;
  EXPECT_EQ(d->running(), 0u);
  EXPECT_FALSE(holds(n("goAhead"), kNs + "result", n("ok")));
}

// A command sent down from a node above is addressed to the node (its context is the node's
// IRI, as configuration is): it was taken and acknowledged without running, and no trace left.
TEST_F(DispatcherTest, ACommandAddressedToTheNodeRunsAsOneAddressedToTheDispatcher) {
  ta::Supervisor supervisor([](std::string_view) {});
  auto d = ta::Dispatcher::open(root_ / "node", {.folder = root_ / "behaviours"}, supervisor);
  ASSERT_TRUE(d.has_value());
  put({{n("me"), n("behavior"), tn::Term::literal("goAhead 7")}}, kIri);
  poll_until(*d, [&] { return holds(n("goAhead"), kNs + "result", n("ok")); });
  EXPECT_TRUE(holds(n("goAhead"), kNs + "result", n("ok")));
  // Sent to a whole subtree from above, it reaches this node addressed to its own subtree.
  put({{n("me"), n("behavior"), tn::Term::literal("handleFailState")}}, kIri + "/*");
  poll_until(*d, [&] { return holds(n("handleFailState"), kNs + "result", tn::Term::literal("stopped motors")); });
  EXPECT_TRUE(holds(n("handleFailState"), kNs + "result", tn::Term::literal("stopped motors")));
}

// Each run has one state at a time, and each behaviour one result: its latest run's. (A rule
// reading result(solveObstacle, R) must not see an old failure beside the new success.)
TEST_F(DispatcherTest, ARunHasOneStateAndABehaviourOnlyItsLatestResult) {
  script("flip", "if [ -e \"$0.done\" ]; then echo success; else touch \"$0.done\"; echo fail; fi\n");
  ta::Supervisor supervisor([](std::string_view) {});
  auto d = ta::Dispatcher::open(root_ / "node", {.folder = root_ / "behaviours"}, supervisor);
  ASSERT_TRUE(d.has_value());
  put({{n("me"), n("behavior"), tn::Term::literal("flip")}}, d->iri());
  poll_until(*d, [&] { return holds(n("flip"), kNs + "result", n("fail")); });
  put({{n("me"), n("behavior"), tn::Term::literal("flip")}}, d->iri());
  poll_until(*d, [&] { return holds(n("flip"), kNs + "result", n("success")); });
  auto snap = node_->snapshot();
  auto results = snap->list({.s = n("flip"), .p = tn::Term::iri(kNs + "result")});
  ASSERT_EQ(results->size(), 1u);
  EXPECT_EQ(results->at(0).triple.o, n("success"));
  auto states = snap->list({.p = tn::Term::iri(kTv + "state")});
  ASSERT_EQ(states->size(), 2u);  // two runs, each "exited" only
  for (const auto& r : *states) EXPECT_EQ(r.triple.o, tn::Term::literal("exited")) << r.triple.s.value;
}

// The result is what the latest run printed on standard output: a warning on standard error
// after it was taken for the result, and a run that printed nothing left an older run's result
// standing for rules to fire on.
TEST_F(DispatcherTest, AResultIsTheLatestRunsStandardOutputOrNone) {
  script("say", "[ -n \"$1\" ] && echo \"$1\"\necho 'warning: something' >&2\nexit 0\n");
  ta::Supervisor supervisor([](std::string_view) {});
  auto d = ta::Dispatcher::open(root_ / "node", {.folder = root_ / "behaviours"}, supervisor);
  ASSERT_TRUE(d.has_value());
  auto has_result = [&] {
    auto snap = node_->snapshot();
    return *snap->count({.s = n("say"), .p = tn::Term::iri(kNs + "result")}) > 0;
  };
  auto runs_ended = [&](std::size_t count) {
    auto snap = node_->snapshot();
    return *snap->count({.p = tn::Term::iri(kTv + "state"), .o = tn::Term::literal("exited")}) >= count;
  };
  put({{n("me"), n("behavior"), tn::Term::literal("say ok")}}, d->iri());
  poll_until(*d, [&] { return runs_ended(1); });
  EXPECT_TRUE(holds(n("say"), kNs + "result", n("ok")));
  put({{n("me"), n("behavior"), tn::Term::literal("say")}}, d->iri());
  poll_until(*d, [&] { return runs_ended(2); });
  EXPECT_FALSE(has_result());
}

// A behaviour's last line longer than the node's literal limit is recorded cut, and the run's
// end is recorded (it used to fail on every poll and the run stayed "running").
TEST_F(DispatcherTest, AnOutputLineOverTheLiteralLimitIsRecordedCut) {
  ASSERT_TRUE(tn::Node::init(root_ / "small", {.iri = kIri, .max_literal_bytes = 1000}).has_value());
  script("chatty", "head -c 300000 /dev/zero | tr '\\0' x; echo\n");
  ta::Supervisor supervisor([](std::string_view) {});
  auto d = ta::Dispatcher::open(root_ / "small", {.folder = root_ / "behaviours"}, supervisor);
  ASSERT_TRUE(d.has_value());
  auto small = tn::Node::open(root_ / "small");
  auto writer = small->agent("sensors");
  tn::Item item;
  item.triples = {{n("me"), n("behavior"), tn::Term::literal("chatty")}};
  item.context = d->iri();
  ASSERT_TRUE(writer->store(item).has_value());
  auto ended = [&] {
    auto snap = small->snapshot();
    return *snap->count({.p = tn::Term::iri(kTv + "state"), .o = tn::Term::literal("exited")}) == 1;
  };
  poll_until(*d, ended);
  ASSERT_TRUE(ended());
  auto snap = small->snapshot();
  auto output = snap->list({.p = tn::Term::iri(kTv + "output")});
  ASSERT_EQ(output->size(), 1u);
  const std::string& line = output->at(0).triple.o.value;
  EXPECT_LE(line.size(), 1000u);
  EXPECT_EQ(line.substr(0, 10), "xxxxxxxxxx");
  EXPECT_EQ(line.substr(line.size() - 3), "\u2026");
}

// A behaviour file whose name cannot end an IRI ("a%zz") started, and its end could never be
// written: it and every run after it stayed "running". It is refused; a later run is recorded.
// A line of output in Latin-1 was stored as is, and a dump of the node could not be loaded.
TEST_F(DispatcherTest, ANameThatCannotEndAnIriIsRefusedAndOutputThatIsNotUtf8IsRecordedReplaced) {
  script("a%zz", "echo hi\n");
  script("latin1", "printf 'caf\\351 latin1\\n'\n");
  ta::Supervisor supervisor([](std::string_view) {});
  auto d = ta::Dispatcher::open(root_ / "node", {.folder = root_ / "behaviours"}, supervisor);
  ASSERT_TRUE(d.has_value());
  put({{n("me"), n("behavior"), tn::Term::literal("a%zz")}}, d->iri());
  put({{n("me"), n("behavior"), tn::Term::literal("latin1")}}, d->iri());
  auto ended = [&] { return holds(n("latin1"), kNs + "result", tn::Term::literal("caf\xEF\xBF\xBD latin1")); };
  poll_until(*d, ended);
  EXPECT_TRUE(ended());
  EXPECT_EQ(d->running(), 0u);
  auto snap = node_->snapshot();
  auto refused = snap->list({.p = tn::Term::iri(kTv + "state"), .o = tn::Term::literal("refused")});
  ASSERT_EQ(refused->size(), 1u);
  auto why = snap->list({.s = refused->at(0).triple.s, .p = tn::Term::iri(kTv + "output")});
  ASSERT_EQ(why->size(), 1u);
  EXPECT_NE(why->at(0).triple.o.value.find("'a%zz' cannot end the IRI"), std::string::npos) << why->at(0).triple.o.value;
}

// One supervisor runs the dispatchers of several nodes (`tahvel up` of a whole file). Runs were
// named by their command's item id, which is a store's own: a command on one node was refused as
// "already supervised" when another node's finished run had that id, and every run stayed in the
// supervisor for good. Each node's runs carry its prefix, a run leaves once its end is written,
// and a run's environment carries what `up` asks of every program it starts.
TEST_F(DispatcherTest, DispatchersOfTwoNodesUnderOneSupervisorKeepTheirRunsApart) {
  script("mark", "echo \"$TAHVEL_SUPERVISED_NODE\"\n");
  const std::string kOther = "http://example.org/robot4";
  ASSERT_TRUE(tn::Node::init(root_ / "other", {.iri = kOther}).has_value());
  ta::Supervisor supervisor([](std::string_view) {});
  auto here = ta::Dispatcher::open(root_ / "node", {.folder = root_ / "behaviours", .program_prefix = "robot3/",
                                                    .env = {{"TAHVEL_SUPERVISED_NODE", "/state/robot3"}}},
                                   supervisor);
  auto there = ta::Dispatcher::open(root_ / "other", {.folder = root_ / "behaviours", .program_prefix = "robot4/"}, supervisor);
  ASSERT_TRUE(here.has_value() && there.has_value());
  auto other = tn::Node::open(root_ / "other");
  ASSERT_TRUE(other.has_value());
  auto operator_there = other->agent("sensors");
  ASSERT_TRUE(operator_there.has_value());
  auto ended_on = [&](tn::Node& node) {
    auto snap = node.snapshot();
    return *snap->count({.p = tn::Term::iri(kTv + "state"), .o = tn::Term::literal("exited")});
  };
  for (std::uint64_t round = 1; round <= 3; ++round) {
    put({{n("me"), n("behavior"), tn::Term::literal("mark")}}, here->iri());
    tn::Item item;
    item.add(tn::Term::iri(kOther), tn::Term::iri(kOther + "#behavior"), tn::Term::literal("goAhead 1"));
    item.context = there->iri();
    ASSERT_TRUE(operator_there->store(item).has_value());
    auto deadline = std::chrono::steady_clock::now() + 30s;
    while ((ended_on(*node_) < round || ended_on(*other) < round) && std::chrono::steady_clock::now() < deadline) {
      ASSERT_TRUE(here->poll(10ms).has_value());
      ASSERT_TRUE(there->poll(10ms).has_value());
    }
    ASSERT_EQ(ended_on(*node_), round);
    ASSERT_EQ(ended_on(*other), round);
  }
  auto snap = other->snapshot();
  EXPECT_EQ(*snap->count({.p = tn::Term::iri(kTv + "state"), .o = tn::Term::literal("refused")}), 0u);
  EXPECT_TRUE(holds(n("mark"), kNs + "result", tn::Term::literal("/state/robot3")));
  EXPECT_TRUE(supervisor.states().empty()) << supervisor.states().size() << " finished runs kept";
}

// `tahvel up` stopping: its behaviours are stopped and recorded so. A dispatcher that died
// with runs in progress has them recorded "interrupted" when it next opens, not left running.
TEST_F(DispatcherTest, RunsInProgressAtStopAreRecordedStoppedOrInterrupted) {
  auto state_of = [&](const std::string& run) {
    auto snap = node_->snapshot();
    auto states = snap->list({.s = tn::Term::iri(run), .p = tn::Term::iri(kTv + "state")});
    std::vector<std::string> out;
    for (const auto& r : *states) out.push_back(r.triple.o.value);
    return out;
  };
  std::string first, second;
  {
    ta::Supervisor supervisor([](std::string_view) {});
    auto d = ta::Dispatcher::open(root_ / "node", {.folder = root_ / "behaviours"}, supervisor);
    ASSERT_TRUE(d.has_value());
    put({{n("me"), n("behavior"), tn::Term::literal("monitorObstacles")}}, d->iri());
    auto events = poll_until(*d, [&] { return d->running() == 1; });
    ASSERT_EQ(events.size(), 1u);
    first = events[0].run;
    auto stopped = d->stop_all(std::chrono::seconds(2));
    ASSERT_TRUE(stopped.has_value());
    EXPECT_EQ(d->running(), 0u);
    EXPECT_EQ(state_of(first), std::vector<std::string>{"stopped"});

    put({{n("me"), n("behavior"), tn::Term::literal("monitorObstacles")}}, d->iri());
    events = poll_until(*d, [&] { return d->running() == 1; });
    ASSERT_EQ(events.size(), 1u);
    second = events[0].run;
  }  // the dispatcher and its supervisor gone without stop_all: as when `up` is killed
  EXPECT_EQ(state_of(second), std::vector<std::string>{"running"});
  ta::Supervisor supervisor([](std::string_view) {});
  auto again = ta::Dispatcher::open(root_ / "node", {.folder = root_ / "behaviours"}, supervisor);
  ASSERT_TRUE(again.has_value());
  EXPECT_EQ(state_of(second), std::vector<std::string>{"interrupted"});
  EXPECT_EQ(state_of(first), std::vector<std::string>{"stopped"});
}

}  // namespace
