// Environment sensing as Paper 3 §5 describes it, as pure functions (no store, no geometry):
// sensing subscriptions that say what to sense, where, how fresh and for how long, with a
// threshold rule that changes the sensing period; and the per-room aggregate a gateway keeps —
// latest value of each quantity with its time, "unknown" when nothing is fresher than the valid
// time, and a movement level from how often the PIR sensors of the room fire.
// The agents tahvel-env-motes and tahvel-environment (docs/spatial.md, "Environment") use it.
#pragma once

#include <array>
#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace tahvel::spatial {

enum class Quantity { temperature, humidity, light, movement };
inline constexpr std::array<Quantity, 4> kQuantities{Quantity::temperature, Quantity::humidity,
                                                     Quantity::light, Quantity::movement};

// The local name of the quantity in tv: ("temperature", "humidity", "light", "movement").
const char* quantity_name(Quantity q);
std::optional<Quantity> quantity_from_name(std::string_view local_name);

// "When the last reading is above `above`, sense every `period_s` instead."
struct ThresholdRule {
  double above = 0;
  double period_s = 0;  // > 0
};

struct SensingSubscription {
  std::string iri;
  Quantity quantity = Quantity::temperature;
  double max_age_s = 900;        // the last reading may be at most this old: the sensing period
  std::string area;              // the room's IRI
  std::int64_t until_ns = 0;     // end of the subscription (ns since the epoch); 0: no end
  std::optional<ThresholdRule> rule;

  bool active_at(std::int64_t now_ns) const { return until_ns == 0 || now_ns < until_ns; }
};

// The period at which a mote answering `s` senses, given its last reading of the quantity:
// the rule's period when the rule holds (last > above), else max_age_s. Never above max_age_s:
// a rule can only make sensing more frequent, so the freshness promise always holds.
double sensing_period_s(const SensingSubscription& s, std::optional<double> last_value);

// `seconds` (>= 0) in nanoseconds, saturating at INT64_MAX: a period of centuries is "rarely",
// not an overflow into a negative period that makes every step due.
std::int64_t saturating_ns(double seconds);

struct Reading {
  Quantity quantity = Quantity::temperature;
  double value = 0;          // movement: 1 movement detected, 0 none
  std::int64_t at_ns = 0;    // when it was sensed
};

struct QuantityState {
  std::optional<double> value;  // nullopt: unknown (no reading within the valid time)
  std::int64_t at_ns = 0;       // the reading's time when known
};

struct RoomEnvironment {
  std::map<Quantity, QuantityState> latest;  // temperature, humidity, light
  // PIR detections per hour over the valid time (readings with value >= 0.5 count as one
  // detection each); nullopt (unknown) when no PIR reading lies within the valid time.
  std::optional<double> movement_level;
};

// Per-room aggregation. Readings may arrive in any order; later `at_ns` wins per quantity.
class EnvironmentAggregator {
 public:
  void add(const std::string& room, const Reading& reading);

  // The environment of `room` at `now_ns`: per quantity the latest reading not after now and
  // at most valid_s old, else unknown; the movement level over [now - valid_s, now].
  RoomEnvironment environment(const std::string& room, std::int64_t now_ns, double valid_s) const;

 private:
  std::map<std::string, std::vector<Reading>> readings_;  // by room
};

}  // namespace tahvel::spatial
