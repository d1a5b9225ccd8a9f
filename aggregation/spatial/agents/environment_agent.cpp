// tahvel-environment: the room environment aggregator of Paper 3 §5. For every room of the
// board's floor plan it keeps one item <room>/environment with the latest value of temperature,
// humidity and light and each value's time, "unknown" for a quantity with no reading within
// the valid time, and a movement level (PIR detections per hour over the valid time, "unknown"
// without PIR readings); <room> tv:environment points at it (vocabulary: docs/vocabulary.md).
// A reading counts for every room whose closed shape holds its mote on the mote's floor (a mote
// on a shared wall counts for both rooms: the boundary rule of docs/spatial.md).
//
//   tahvel-environment DIR [--agent ID] [--valid-s S] [--once] [--now-ns T] [--interval-s S]
//                          [--idle S]
//
// --once: one update at --now-ns (default: now), then exit (tests, replays). Otherwise it is
// woken by every reading (it subscribes to sosa:madeBySensor) and at least every --interval-s
// (default 60: values turn "unknown" by the clock, with no reading to wake it), until
// SIGINT/SIGTERM or --idle S seconds without a reading. Each update replaces the rooms'
// environment items (all rooms in one transaction: a reader never sees a room without one).
#include <chrono>
#include <map>
#include <set>

#include "agent_runtime.h"
#include "tahvel/spatial/board.h"
#include "tahvel/spatial/environment_board.h"

namespace {

namespace rt = tahvel::agents::hrv;
namespace sp = tahvel::spatial;
namespace tn = tahvel::node;

constexpr const char* kProgram = "tahvel-environment";
const std::string kTvEnvironment = "https://w3id.org/tahvel#environment";
const std::string kTvRoom = "https://w3id.org/tahvel#room";

std::int64_t wall_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::system_clock::now().time_since_epoch()).count();
}

// One update at `now_ns`. Returns an error message, or nullopt.
std::optional<std::string> update(rt::Session& session, std::int64_t now_ns, double valid_s) {
  std::optional<sp::BoardPlan> board;
  std::vector<sp::MoteReading> readings;
  std::set<std::string> with_state;  // rooms this agent wrote a state of
  {  // the snapshot is released before writing (node.h: a held snapshot blocks map growth)
    auto snapshot = session.node.snapshot();
    if (!snapshot) return snapshot.error().message;
    auto plan = sp::load_plan(*snapshot);
    if (!plan) return plan.error().message;
    auto recent = sp::readings_since(*snapshot, now_ns - static_cast<std::int64_t>(valid_s * 1e9));
    if (!recent) return recent.error().message;
    // By the states' own tv:room: a room's tv:environment link goes with the room's records.
    auto written = snapshot->list({.p = tn::Term::iri(kTvRoom), .source = session.agent.iri()});
    if (!written) return written.error().message;
    for (const tn::Record& r : *written) with_state.insert(r.triple.o.value);
    board = std::move(*plan);
    readings = std::move(*recent);
  }
  const std::vector<std::string> rooms = board->plan.room_ids();
  static std::set<std::string> told;  // each skipped feature once per run, not every update
  for (const std::string& problem : board->problems)
    if (told.insert(problem).second) rt::log_line(kProgram, "feature skipped: " + problem);

  sp::EnvironmentAggregator aggregator;
  for (const sp::MoteReading& r : readings) {
    const sp::Sensor* mote = board->plan.sensor(r.mote);
    if (!mote) continue;  // a reading of a mote that is not on the plan
    // Stored before the mote was put where it stands now: it was sensed elsewhere, in a room
    // this plan no longer says. Counted for none rather than for the room it stands in now.
    if (auto placed = board->placed_by.find(r.mote); placed != board->placed_by.end() && r.record < placed->second)
      continue;
    for (const std::string& room : board->plan.rooms_at(mote->at, mote->floor)) aggregator.add(room, r.reading);
  }
  // Every room's state replaced in one transaction: a reader sees the previous states or the
  // new ones, never a room without its state.
  std::vector<tn::Pattern> old_states;
  std::vector<tn::Item> new_states;
  // A room's state as the board has it: its item, and the room's link to it.
  auto drop_state = [&](const std::string& room) {
    old_states.push_back({.s = tn::Term::iri(sp::environment_iri(room))});
    old_states.push_back({.s = tn::Term::iri(room), .p = tn::Term::iri(kTvEnvironment)});
  };
  for (const std::string& room : rooms) {
    drop_state(room);
    new_states.push_back(sp::environment_item(room, aggregator.environment(room, now_ns, valid_s), now_ns, valid_s));
  }
  // A room that left the plan (taken out, or its geometry now refused) has no state any more:
  // its last one, kept, read as current for ever (and rules fired on it).
  const std::set<std::string> in_plan(rooms.begin(), rooms.end());
  for (const std::string& room : with_state) {
    if (in_plan.count(room)) continue;
    rt::log_line(kProgram, "room <" + room + "> is no longer on the floor plan: its environment is removed");
    drop_state(room);
  }
  if (auto stored = session.agent.replace(old_states, new_states); !stored) {
    return "room environments: " + stored.error().message;
  }
  return std::nullopt;
}

int run(int argc, char** argv) {
  // First: a SIGTERM while the store opens ends the program cleanly at its first check.
  rt::install_stop_handlers();
  rt::Args args(argc, argv, {"--agent", "--valid-s", "--now-ns", "--interval-s", "--idle"}, {"--once"});
  const double valid_s = args.number("--valid-s", 900, 0.001);
  const double interval_s = args.number("--interval-s", 60, 0.01);
  const double idle_s = args.number("--idle", 0);
  std::optional<std::int64_t> fixed_now;
  if (args.has("--now-ns")) {
    fixed_now = rt::parse_int(args.text("--now-ns", ""));
    if (!fixed_now) throw rt::UsageError("--now-ns: expected an integer (ns since the epoch)");
  }
  auto session = rt::open_session(kProgram, args.dir(), args.text("--agent", "environment"));
  if (!session) return rt::kExitError;
  if (args.has("--once")) {
    if (auto e = update(*session, fixed_now.value_or(wall_ns()), valid_s)) {
      rt::log_line(kProgram, *e);
      return rt::kExitError;
    }
    return rt::kExitOk;
  }
  if (!rt::subscribe_predicates(*session, {"http://www.w3.org/ns/sosa/madeBySensor"})) return rt::kExitError;
  auto last_input = std::chrono::steady_clock::now();
  const auto timeout = std::chrono::milliseconds(static_cast<std::int64_t>(interval_s * 1000));
  while (!rt::stop_requested()) {
    if (auto e = update(*session, fixed_now.value_or(wall_ns()), valid_s)) {
      rt::log_line(kProgram, *e);
      return rt::kExitError;
    }
    auto taken = rt::take_unless_stopped(session->agent, timeout);  // a reading, the interval, or a stop
    if (!taken) {
      rt::log_line(kProgram, taken.error().message);
      return rt::kExitError;
    }
    if (*taken) {
      last_input = std::chrono::steady_clock::now();
      // Drain what else arrived: one update covers them all.
      for (;;) {
        auto more = session->agent.take(std::chrono::milliseconds(0));
        if (!more || !*more) break;
      }
    } else if (idle_s > 0 && std::chrono::steady_clock::now() - last_input >= std::chrono::duration<double>(idle_s)) {
      break;
    }
  }
  return rt::kExitOk;
}

}  // namespace

int main(int argc, char** argv) {
  return rt::guarded_main(kProgram,
                          "usage: tahvel-environment DIR [--agent ID] [--valid-s S] [--once] [--now-ns T] "
                          "[--interval-s S] [--idle S]",
                          [&] { return run(argc, argv); });
}
