// tahvel-env-motes: a simulator of the environment motes of a home (temperature, humidity,
// light, PIR movement) placed on the floor plan of the board, honouring sensing subscriptions
// as Paper 3 §5 describes them: a quantity is sensed in a room only while a subscription for it
// covers the room, at the subscription's period (its maximum age), or at the rule's shorter
// period while the last reading is above the rule's threshold, until the subscription's
// duration ends. Where several subscriptions cover one room and quantity, the shortest period
// applies. The network decides which motes answer: every PIR mote of the room for movement,
// and for the other quantities one capable mote per reading, in turn. The motes are the point features with tv:senses (vocabulary:
// docs/vocabulary.md, "Spatial"); the board is re-read each step, so moved motes and new
// subscriptions apply from the next step.
//
//   tahvel-env-motes DIR [--seed N] [--start-ns T] [--steps N] [--step-s S]
//
// With --steps N: N steps of S seconds (default 10) of virtual time from --start-ns (default:
// now), written as fast as possible, readings asserted at their virtual time (for tests and
// replays). Without: real time, one step every S seconds, until SIGINT/SIGTERM.
// A mote whose IRI is the node's IRI + "/" + ID writes as agent ID (its readings' source is the
// mote); others are written by agent "env-motes". Values are deterministic for a seed: a daily
// temperature and light cycle per room, noise, and PIR detections at a per-mote rate.
#include <chrono>
#include <cmath>
#include <functional>
#include <limits>
#include <algorithm>
#include <map>
#include <optional>
#include <random>
#include <set>
#include <thread>

#include "agent_runtime.h"
#include "tahvel/spatial/board.h"
#include "tahvel/spatial/environment_board.h"

namespace {

namespace rt = tahvel::agents::hrv;
namespace sp = tahvel::spatial;
namespace tn = tahvel::node;

constexpr const char* kProgram = "tahvel-env-motes";
constexpr double kDay = 86400;

std::int64_t wall_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::system_clock::now().time_since_epoch()).count();
}

class Simulator {
 public:
  Simulator(tn::Node& node, std::uint32_t seed) : node_(node), rng_(seed) {}

  // After a (re)start: when each mote and room was last sensed, and by whom, from the readings
  // on the board of the last day before `now_ns`. Without it a restart (the supervisor's, after
  // a crash) sensed everything at once and always asked the same mote first.
  bool resume(std::int64_t now_ns) {
    constexpr std::int64_t kDay = 86'400'000'000'000;
    auto snapshot = node_.snapshot();
    if (!snapshot) return error(snapshot.error().message);
    auto board = sp::load_plan(*snapshot);
    if (!board) return error(board.error().message);
    auto readings = sp::readings_since(*snapshot, now_ns - kDay);
    if (!readings) return error(readings.error().message);
    std::size_t used = 0;
    for (const sp::MoteReading& r : *readings) {  // record order: the latest last
      if (r.reading.at_ns > now_ns) continue;
      const sp::Quantity q = r.reading.quantity;
      auto note = [&](const std::pair<std::string, sp::Quantity>& key) {
        if (auto it = last_time_.find(key); it != last_time_.end() && it->second > r.reading.at_ns) return;
        last_time_[key] = r.reading.at_ns;
        last_value_[key] = r.reading.value;
      };
      if (q == sp::Quantity::movement) {
        note({r.mote, q});
      } else {
        const sp::Sensor* mote = board->plan.sensor(r.mote);
        if (!mote) continue;
        // Sensed before the mote was last moved: not for the room it stands in now (S12).
        const auto placed = board->placed_by.find(r.mote);
        if (placed == board->placed_by.end() || r.record >= placed->second)
          for (const std::string& room : board->plan.rooms_at(mote->at, mote->floor)) note({room, q});
        std::int64_t& answered = last_answered_.try_emplace({r.mote, q}, r.reading.at_ns).first->second;
        answered = std::max(answered, r.reading.at_ns);
      }
      ++used;
    }
    if (used > 0) rt::log_line(kProgram, "resumed the schedule from " + std::to_string(used) + " reading(s) on the board");
    return true;
  }

  // One step at time `now_ns`: the readings due, written. False after printing an error.
  bool step(std::int64_t now_ns) {
    auto snapshot = node_.snapshot();
    if (!snapshot) return error(snapshot.error().message);
    auto board = sp::load_plan(*snapshot);
    if (!board) return error(board.error().message);
    auto subscriptions = sp::read_sensing_subscriptions(*snapshot);
    if (!subscriptions) return error(subscriptions.error().message);
    auto capabilities = sp::read_capabilities(*snapshot);
    if (!capabilities) return error(capabilities.error().message);
    for (const std::string& problem : subscriptions->problems) warn_once(problem);
    for (const std::string& problem : board->problems) warn_once("feature skipped: " + problem);
    // Which motes answer is the network's decision (Paper 3 §5: "the actual nodes that are going
    // to provide the requested data are determined in the WSN"). Movement: every PIR mote of the
    // room, each watching its own part of it (the movement level counts their detections). The
    // other quantities: one reading per room and period, from the capable motes of the room in
    // turn, the one that answered least recently first — the room gets its reading at the period
    // asked, and the motes share the battery cost.
    std::map<std::pair<std::string, sp::Quantity>, double> each_due;   // (mote, movement)
    std::map<std::pair<std::string, sp::Quantity>, RoomDue> room_due;  // (room, quantity)
    for (const sp::SensingSubscription& s : subscriptions->subscriptions) {
      if (!s.active_at(now_ns)) continue;
      if (!board->plan.room(s.area)) {
        // A room on the board whose place cannot be read is skipped (said above), not absent.
        const bool skipped = std::any_of(board->problems.begin(), board->problems.end(),
                                         [&](const std::string& p) { return p.starts_with(s.area + ":"); });
        warn_once(s.iri + (skipped ? ": room " + s.area + " cannot be used as an area (its place cannot be read; see the feature skipped)"
                                   : ": no room " + s.area + " on the board"));
        continue;
      }
      std::vector<std::string> capable;
      for (const std::string& mote : board->plan.sensors_in_room(s.area)) {
        auto caps = capabilities->find(mote);
        if (caps == capabilities->end()) continue;
        if (std::find(caps->second.begin(), caps->second.end(), s.quantity) != caps->second.end())
          capable.push_back(mote);
      }
      if (capable.empty()) {
        warn_once(s.iri + ": no mote in " + s.area + " senses " + sp::quantity_name(s.quantity));
        continue;
      }
      auto last_of = [&](const std::pair<std::string, sp::Quantity>& key) -> std::optional<double> {
        if (auto it = last_value_.find(key); it != last_value_.end()) return it->second;
        return std::nullopt;
      };
      auto ask = [&](auto& due, const std::pair<std::string, sp::Quantity>& key, std::optional<double> last) -> double& {
        double period = sp::sensing_period_s(s, last);
        auto [it, inserted] = due.try_emplace(key);
        auto& slot = period_of(it->second);
        slot = inserted ? period : std::min(slot, period);
        return slot;
      };
      if (s.quantity == sp::Quantity::movement) {
        // The threshold rule asks about the room: movement that one PIR mote saw speeds up every
        // mote of the room (the highest of their last readings is the room's).
        std::optional<double> room_last;
        for (const std::string& mote : capable)
          if (auto v = last_of({mote, s.quantity})) room_last = std::max(room_last.value_or(*v), *v);
        for (const std::string& mote : capable) ask(each_due, {mote, s.quantity}, room_last);
      } else {
        std::pair<std::string, sp::Quantity> key{s.area, s.quantity};
        ask(room_due, key, last_of(key));
        room_due[key].motes = std::move(capable);
      }
    }
    for (const auto& [key, period_s] : each_due) {
      if (!is_due(key, period_s, now_ns)) continue;
      sp::Reading r{key.second, sense(key.first, key.second, now_ns), now_ns};
      if (!write(key.first, r)) return false;
      last_time_[key] = now_ns;
      last_value_[key] = r.value;
    }
    // A mote on the wall between two rooms is in both (S3): one reading at an instant counts
    // for each room it stands in (S12). So the rooms due now are served fewest capable motes
    // first, a room that a reading of this instant already counts for takes that one, and a
    // room picks, of its motes, one that stands in no room served already, then the one that
    // answered least recently: a mote on the corner of rooms B and C, C's only one, read for
    // C after B's own mote had been read for B gave B two readings of one instant (and a room
    // next to a shared mote read for it, as many).
    std::vector<std::pair<std::pair<std::string, sp::Quantity>, const RoomDue*>> due_now;
    for (const auto& [key, due] : room_due)
      if (is_due(key, due.period_s, now_ns)) due_now.push_back({key, &due});
    std::stable_sort(due_now.begin(), due_now.end(),
                     [](const auto& a, const auto& b) { return a.second->motes.size() < b.second->motes.size(); });
    std::map<std::pair<std::string, sp::Quantity>, std::set<std::string>> rooms_of;  // (mote, quantity) -> rooms due
    for (const auto& [key, due] : due_now)
      for (const std::string& m : due->motes) rooms_of[{m, key.second}].insert(key.first);
    // Every room asked for the quantity that a mote stands in, due now or not: its reading is
    // each one's latest (S12), as resume() counts it after a restart.
    std::map<std::pair<std::string, sp::Quantity>, std::vector<std::string>> asked_rooms_of;
    for (const auto& [key, due] : room_due)
      for (const std::string& m : due.motes) asked_rooms_of[{m, key.second}].push_back(key.first);
    std::map<std::pair<std::string, sp::Quantity>, double> read_now;  // (mote, quantity) -> value
    std::set<std::pair<std::string, sp::Quantity>> served;           // (room, quantity)
    for (const auto& [key, due] : due_now) {
      const auto shared = std::find_if(due->motes.begin(), due->motes.end(),
                                       [&](const std::string& m) { return read_now.count({m, key.second}) > 0; });
      if (shared != due->motes.end()) {
        last_time_[key] = now_ns;
        last_value_[key] = read_now.at({*shared, key.second});
        served.insert(key);
        continue;
      }
      auto answered = [&](const std::string& x) {
        auto it = last_answered_.find({x, key.second});
        return it == last_answered_.end() ? std::numeric_limits<std::int64_t>::min() : it->second;
      };
      auto in_a_served_room = [&](const std::string& x) {
        const auto& rooms = rooms_of[{x, key.second}];
        return std::any_of(rooms.begin(), rooms.end(), [&](const std::string& room) { return served.count({room, key.second}) > 0; });
      };
      const std::string* mote = &due->motes.front();
      for (const std::string& m : due->motes)
        if (std::pair(in_a_served_room(m), answered(m)) < std::pair(in_a_served_room(*mote), answered(*mote))) mote = &m;
      sp::Reading r{key.second, sense(*mote, key.second, now_ns), now_ns};
      if (!write(*mote, r)) return false;
      for (const std::string& room : asked_rooms_of[{*mote, key.second}]) {
        last_time_[{room, key.second}] = now_ns;
        last_value_[{room, key.second}] = r.value;
      }
      last_answered_[{*mote, key.second}] = now_ns;
      read_now[{*mote, key.second}] = r.value;
      served.insert(key);
    }
    return true;
  }

  std::uint64_t written() const { return written_; }

 private:
  bool error(const std::string& message) {
    rt::log_line(kProgram, message);
    return false;
  }

  void warn_once(const std::string& message) {
    if (warned_.insert(message).second) rt::log_line(kProgram, message + "; skipped");
  }

  // A deterministic value: per-mote offsets from a hash of its IRI, a daily cycle, noise.
  double sense(const std::string& mote, sp::Quantity q, std::int64_t now_ns) {
    const double h = static_cast<double>(std::hash<std::string>{}(mote) % 1000) / 1000.0;
    const double day = std::fmod(static_cast<double>(now_ns) / 1e9, kDay) / kDay;  // 0..1
    std::normal_distribution<double> noise(0, 1);
    switch (q) {
      case sp::Quantity::temperature:
        return std::round((19.5 + 3 * h + 1.5 * std::sin(2 * M_PI * (day - 0.375)) + 0.1 * noise(rng_)) * 10) / 10;
      case sp::Quantity::humidity:
        return std::round(40 + 20 * h + noise(rng_));
      case sp::Quantity::light:
        return std::round(std::max(0.0, 400 * std::sin(M_PI * (day - 0.25) * 2) + 50 * h + 5 * noise(rng_)));
      case sp::Quantity::movement:
        return std::bernoulli_distribution(0.15 + 0.3 * h)(rng_) ? 1 : 0;
    }
    return 0;
  }

  bool write(const std::string& mote, const sp::Reading& r) {
    const std::string prefix = node_.iri() + "/";
    std::string id = "env-motes";
    if (mote.rfind(prefix, 0) == 0 && mote.find('/', prefix.size()) == std::string::npos &&
        mote.size() > prefix.size()) {
      id = mote.substr(prefix.size());
    }
    auto agent = agents_.find(id);
    if (agent == agents_.end()) {
      auto made = node_.agent(id);
      if (!made) {
        made = node_.agent("env-motes");
        if (!made) return error("agent " + id + ": " + made.error().message);
      }
      agent = agents_.emplace(id, std::move(*made)).first;
    }
    auto stored = agent->second.store(sp::reading_item(mote, r));
    if (!stored) return error("reading of " + mote + ": " + stored.error().message);
    ++written_;
    return true;
  }

  struct RoomDue {
    double period_s = 0;
    std::vector<std::string> motes;  // capable motes of the room, sorted
  };
  static double& period_of(double& period) { return period; }
  static double& period_of(RoomDue& due) { return due.period_s; }

  bool is_due(const std::pair<std::string, sp::Quantity>& key, double period_s, std::int64_t now_ns) const {
    auto last = last_time_.find(key);
    return last == last_time_.end() || now_ns - last->second >= sp::saturating_ns(period_s);
  }

  tn::Node& node_;
  std::mt19937 rng_;
  std::map<std::string, tn::Agent> agents_;
  std::map<std::pair<std::string, sp::Quantity>, std::int64_t> last_time_;
  // Keyed by (mote, movement) for PIR, by (room, quantity) for the others.
  std::map<std::pair<std::string, sp::Quantity>, double> last_value_;
  std::map<std::pair<std::string, sp::Quantity>, std::int64_t> last_answered_;  // (mote, quantity)
  std::set<std::string> warned_;
  std::uint64_t written_ = 0;
};

int run(int argc, char** argv) {
  // First: a SIGTERM while the store opens ends the program cleanly at its first check.
  rt::install_stop_handlers();
  rt::Args args(argc, argv, {"--seed", "--start-ns", "--steps", "--step-s"}, {});
  const double step_s = args.number("--step-s", 10, 0.001);
  const auto seed = static_cast<std::uint32_t>(args.number("--seed", 1));
  const bool virtual_time = args.has("--steps");
  const auto steps = static_cast<std::uint64_t>(args.number("--steps", 0));
  std::int64_t now = wall_ns();
  if (args.has("--start-ns")) {
    auto parsed = rt::parse_int(args.text("--start-ns", ""));
    if (!parsed) throw rt::UsageError("--start-ns: expected an integer (ns since the epoch)");
    now = *parsed;
  }
  rt::stop_here_when_only_checking();
  auto opened = tn::Node::open(args.dir());
  if (!opened) {
    rt::log_line(kProgram, opened.error().message);
    return rt::kExitError;
  }
  Simulator simulator(*opened, seed);
  if (!simulator.resume(now)) return rt::kExitError;
  const auto step_ns = static_cast<std::int64_t>(step_s * 1e9);
  for (std::uint64_t i = 0; !rt::stop_requested() && (!virtual_time || i < steps); ++i) {
    if (!simulator.step(now)) return rt::kExitError;
    if (virtual_time) {
      now += step_ns;
    } else {
      if (!rt::pause_unless_stopped(std::chrono::nanoseconds(step_ns))) break;
      now = wall_ns();
    }
  }
  rt::log_line(kProgram, "wrote " + std::to_string(simulator.written()) + " reading(s)");
  return rt::kExitOk;
}

}  // namespace

int main(int argc, char** argv) {
  return rt::guarded_main(kProgram, "usage: tahvel-env-motes DIR [--seed N] [--start-ns T] [--steps N] [--step-s S]", [&] { return run(argc, argv); });
}
