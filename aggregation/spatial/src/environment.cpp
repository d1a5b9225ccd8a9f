// Sensing periods and the per-room environment (environment.h). Rooms keep their readings in
// a vector; a gateway prunes by asking only for a recent window (the agent reads readings
// since now - valid time), so the vectors stay short.
#include "tahvel/spatial/environment.h"

#include <limits>

#include <algorithm>

namespace tahvel::spatial {

const char* quantity_name(Quantity q) {
  switch (q) {
    case Quantity::temperature: return "temperature";
    case Quantity::humidity: return "humidity";
    case Quantity::light: return "light";
    case Quantity::movement: return "movement";
  }
  return "?";
}

std::optional<Quantity> quantity_from_name(std::string_view name) {
  for (Quantity q : kQuantities) {
    if (name == quantity_name(q)) return q;
  }
  return std::nullopt;
}

double sensing_period_s(const SensingSubscription& s, std::optional<double> last_value) {
  if (s.rule && last_value && *last_value > s.rule->above && s.rule->period_s > 0) {
    return std::min(s.rule->period_s, s.max_age_s);
  }
  return s.max_age_s;
}

std::int64_t saturating_ns(double seconds) {
  constexpr double kMax = 9.2e18;  // below INT64_MAX (9.22e18), exactly representable
  const double ns = seconds * 1e9;
  if (!(ns < kMax)) return std::numeric_limits<std::int64_t>::max();
  return ns <= 0 ? 0 : static_cast<std::int64_t>(ns);
}

void EnvironmentAggregator::add(const std::string& room, const Reading& reading) {
  readings_[room].push_back(reading);
}

RoomEnvironment EnvironmentAggregator::environment(const std::string& room, std::int64_t now_ns,
                                                   double valid_s) const {
  RoomEnvironment out;
  for (Quantity q : kQuantities) {
    if (q != Quantity::movement) out.latest[q] = {};
  }
  auto it = readings_.find(room);
  if (it == readings_.end()) return out;
  const auto valid_ns = static_cast<std::int64_t>(valid_s * 1e9);
  const std::int64_t from = now_ns - valid_ns;
  std::size_t pir_readings = 0, detections = 0;
  for (const Reading& r : it->second) {
    if (r.at_ns > now_ns || r.at_ns < from) continue;  // in the future or stale
    if (r.quantity == Quantity::movement) {
      ++pir_readings;
      detections += r.value >= 0.5;
      continue;
    }
    QuantityState& state = out.latest[r.quantity];
    if (!state.value || r.at_ns > state.at_ns) state = {r.value, r.at_ns};
  }
  if (pir_readings != 0 && valid_s > 0) {
    out.movement_level = static_cast<double>(detections) * 3600.0 / valid_s;
  }
  return out;
}

}  // namespace tahvel::spatial
