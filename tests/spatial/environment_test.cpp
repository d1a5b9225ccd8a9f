// Sensing periods and the per-room environment (tahvel/spatial/environment.h): latest values
// with their time, "unknown" once nothing is fresher than the valid time, movement level from
// PIR detections, and the threshold rule of a sensing subscription.
#include "tahvel/spatial/environment.h"

#include <gtest/gtest.h>

namespace tahvel::spatial {
namespace {

constexpr std::int64_t kS = 1'000'000'000;
constexpr std::int64_t kT0 = 1'800'000'000 * kS;

TEST(Environment, LatestValueWithItsTime) {
  EnvironmentAggregator agg;
  agg.add("bedroom", {Quantity::temperature, 20.0, kT0});
  agg.add("bedroom", {Quantity::temperature, 21.0, kT0 + 300 * kS});
  agg.add("bedroom", {Quantity::temperature, 19.0, kT0 + 100 * kS});  // late, older
  RoomEnvironment env = agg.environment("bedroom", kT0 + 400 * kS, 900);
  ASSERT_TRUE(env.latest[Quantity::temperature].value.has_value());
  EXPECT_EQ(*env.latest[Quantity::temperature].value, 21.0);
  EXPECT_EQ(env.latest[Quantity::temperature].at_ns, kT0 + 300 * kS);
  EXPECT_FALSE(env.latest[Quantity::humidity].value.has_value());  // never sensed: unknown
  EXPECT_FALSE(env.movement_level.has_value());
}

TEST(Environment, NoFreshReadingWithinTheValidTimeIsUnknown) {
  EnvironmentAggregator agg;
  agg.add("bedroom", {Quantity::temperature, 20.0, kT0});
  agg.add("bedroom", {Quantity::light, 300, kT0 + 600 * kS});
  RoomEnvironment fresh = agg.environment("bedroom", kT0 + 900 * kS, 900);  // exactly 900 s old
  EXPECT_TRUE(fresh.latest[Quantity::temperature].value.has_value());
  RoomEnvironment stale = agg.environment("bedroom", kT0 + 901 * kS, 900);
  EXPECT_FALSE(stale.latest[Quantity::temperature].value.has_value());
  EXPECT_TRUE(stale.latest[Quantity::light].value.has_value());
  // A room nobody reported on at all.
  RoomEnvironment hall = agg.environment("hall", kT0, 900);
  for (Quantity q : {Quantity::temperature, Quantity::humidity, Quantity::light}) {
    EXPECT_FALSE(hall.latest[q].value.has_value()) << quantity_name(q);
  }
}

TEST(Environment, ReadingsAfterNowAreIgnored) {
  EnvironmentAggregator agg;
  agg.add("bedroom", {Quantity::temperature, 20.0, kT0 + 10 * kS});
  EXPECT_FALSE(agg.environment("bedroom", kT0, 900).latest[Quantity::temperature].value);
}

TEST(Environment, MovementLevelIsDetectionsPerHourOverTheValidTime) {
  EnvironmentAggregator agg;
  for (int i = 0; i < 10; ++i) {
    agg.add("hall", {Quantity::movement, i % 2 == 0 ? 1.0 : 0.0, kT0 + i * 60 * kS});
  }
  // 5 detections in the last 15 minutes: 20 per hour.
  RoomEnvironment env = agg.environment("hall", kT0 + 9 * 60 * kS, 900);
  ASSERT_TRUE(env.movement_level.has_value());
  EXPECT_DOUBLE_EQ(*env.movement_level, 20.0);
  // PIR readings but no detection: level 0, not unknown.
  EnvironmentAggregator quiet;
  quiet.add("hall", {Quantity::movement, 0.0, kT0});
  EXPECT_EQ(quiet.environment("hall", kT0, 900).movement_level, 0.0);
  // No PIR reading within the valid time: unknown.
  EXPECT_FALSE(quiet.environment("hall", kT0 + 1000 * kS, 900).movement_level.has_value());
}

TEST(Environment, ThresholdRuleShortensTheSensingPeriod) {
  SensingSubscription s;
  s.quantity = Quantity::temperature;
  s.max_age_s = 600;
  EXPECT_EQ(sensing_period_s(s, 30.0), 600);
  s.rule = ThresholdRule{25.0, 60};
  EXPECT_EQ(sensing_period_s(s, std::nullopt), 600);  // no reading yet
  EXPECT_EQ(sensing_period_s(s, 25.0), 600);          // not above
  EXPECT_EQ(sensing_period_s(s, 25.5), 60);
  s.rule = ThresholdRule{25.0, 6000};                 // never longer than the max age
  EXPECT_EQ(sensing_period_s(s, 30.0), 600);
}

TEST(Environment, SubscriptionDuration) {
  SensingSubscription s;
  EXPECT_TRUE(s.active_at(kT0));
  s.until_ns = kT0;
  EXPECT_TRUE(s.active_at(kT0 - 1));
  EXPECT_FALSE(s.active_at(kT0));
}

TEST(Environment, QuantityNamesRoundTrip) {
  for (Quantity q : kQuantities) EXPECT_EQ(quantity_from_name(quantity_name(q)), q);
  EXPECT_FALSE(quantity_from_name("pressure").has_value());
}

}  // namespace
}  // namespace tahvel::spatial
