// `tahvel bench spatial`: the area query of Tahvel::spatial ("which sensors lie in this room")
// with its index, against the brute-force test of every sensor and against a scan that tests
// the area's bounding box first, all in the same run on the same queries, whose answers must
// agree. Layout (seeded): a building of two floors of rooms 5 m x 4 m in a grid, a third of
// them L-shaped (concave) and a tenth with a pillar (a hole); sensors at uniform random
// positions, many exactly on walls (coordinates on a 0.25 m grid).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <random>
#include <string>
#include <vector>

#include "args.h"
#include "bench.h"
#include "bench_measure.h"
#include "tahvel/spatial/plan.h"

namespace tahvel::cli {
namespace {

using bench::Clock;
namespace sp = tahvel::spatial;

const char* kUsage =
    "usage: tahvel bench spatial [--json] [--quick] [--sensors N] [--rooms N]\n"
    "  --json       print one JSON object instead of the table\n"
    "  --quick      fewer timed queries, for smoke tests (same sizes)\n"
    "  --sensors N  sensors in the building (default 10000)\n"
    "  --rooms N    rooms in the building, on two floors (default 1000)\n";

constexpr double kTarget = 50;  // index at least 50x faster than brute force (issue 6)

struct Options {
  bool json = false;
  std::size_t sensors = 10'000, rooms = 1'000;
  std::size_t queries = 5'000, brute_queries = 500;
};

Options parse_options(const std::vector<std::string>& args) {
  Options options;
  for (std::size_t i = 0; i < args.size(); ++i) {
    auto count = [&](const char* flag) {
      if (i + 1 >= args.size()) usage_error(std::string("bench spatial: ") + flag + " needs a value");
      auto n = parse_u64(args[++i]);
      if (!n || *n == 0) usage_error(std::string("bench spatial: ") + flag + ": expected a positive integer");
      return static_cast<std::size_t>(*n);
    };
    if (args[i] == "--help" || args[i] == "-h") {
      std::fputs(kUsage, stdout);
      std::exit(kExitOk);
    } else if (args[i] == "--json") {
      options.json = true;
    } else if (args[i] == "--quick") {
      options.queries = 500;
      options.brute_queries = 50;
    } else if (args[i] == "--sensors") {
      options.sensors = count("--sensors");
    } else if (args[i] == "--rooms") {
      options.rooms = count("--rooms");
    } else {
      usage_error("bench spatial: unknown argument '" + args[i] + "'\n" + kUsage);
    }
  }
  return options;
}

// One room of the grid: a rectangle, an L (the top-right quarter cut away) or a rectangle
// with a square pillar in the middle.
sp::Shape room_shape(double x, double y, int kind) {
  const double w = 5, h = 4;
  sp::Polygon p;
  if (kind == 1) {
    p.outer = {{x, y}, {x + w, y}, {x + w, y + h / 2}, {x + w / 2, y + h / 2}, {x + w / 2, y + h}, {x, y + h}};
  } else {
    p.outer = {{x, y}, {x + w, y}, {x + w, y + h}, {x, y + h}};
    if (kind == 2) p.holes.push_back({{x + 2, y + 1.5}, {x + 3, y + 1.5}, {x + 3, y + 2.5}, {x + 2, y + 2.5}});
  }
  return sp::Shape{{std::move(p)}};
}

struct Building {
  sp::Plan plan;
  std::vector<sp::Area> rooms;  // the rooms as areas, in order
  double width = 0, depth = 0;
};

Building make_building(const Options& options, std::mt19937& rng) {
  Building b;
  const std::size_t per_floor = (options.rooms + 1) / 2;
  const std::size_t columns = std::max<std::size_t>(1, static_cast<std::size_t>(std::sqrt(per_floor * 1.25)));
  const std::size_t rows = (per_floor + columns - 1) / columns;
  b.width = 5.0 * static_cast<double>(columns);
  b.depth = 4.0 * static_cast<double>(rows);
  std::uniform_int_distribution<int> kind(0, 29);
  for (std::size_t i = 0; i < options.rooms; ++i) {
    int floor = static_cast<int>(i / per_floor);
    std::size_t k = i % per_floor;
    int pick = kind(rng);
    sp::Shape shape = room_shape(5.0 * static_cast<double>(k % columns), 4.0 * static_cast<double>(k / columns),
                                 pick < 10 ? 1 : pick < 13 ? 2 : 0);
    auto put = b.plan.put_room({"room" + std::to_string(i), floor, shape});
    if (!put) fail("bench spatial: " + put.error().message);
    b.rooms.push_back({std::move(shape), floor});
  }
  std::uniform_int_distribution<int> gx(0, static_cast<int>(b.width * 4)), gy(0, static_cast<int>(b.depth * 4));
  std::uniform_int_distribution<int> floor(0, 1);
  for (std::size_t i = 0; i < options.sensors; ++i) {
    auto put = b.plan.put_sensor({"sensor" + std::to_string(i), floor(rng), {gx(rng) / 4.0, gy(rng) / 4.0}});
    if (!put) fail("bench spatial: " + put.error().message);
  }
  return b;
}

using Query = std::vector<std::string> (sp::Plan::*)(const sp::Area&) const;

// Times `query` on `count` areas (cycling through `order`); every answer is checked against
// `expected` (the brute force's) when given.
bench::Percentiles time_queries(const Building& b, Query query, const std::vector<std::size_t>& order,
                                std::size_t count, std::vector<std::vector<std::string>>* answers,
                                const std::vector<std::vector<std::string>>* expected, const char* name) {
  std::vector<double> us;
  us.reserve(count);
  for (std::size_t i = 0; i < count; ++i) {
    const sp::Area& area = b.rooms[order[i % order.size()]];
    auto start = Clock::now();
    std::vector<std::string> found = (b.plan.*query)(area);
    us.push_back(bench::micros(Clock::now() - start));
    if (expected && i < expected->size() && found != (*expected)[i]) {
      fail(std::string("bench spatial: ") + name + " disagrees with the brute force on room" +
           std::to_string(order[i % order.size()]));
    }
    if (answers) answers->push_back(std::move(found));
  }
  return bench::percentiles(std::move(us));
}

}  // namespace

int bench_spatial_main(const std::vector<std::string>& args) {
  const Options options = parse_options(args);
  std::mt19937 rng(20261121);
  Building b = make_building(options, rng);
  std::vector<std::size_t> order(b.rooms.size());
  for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
  std::shuffle(order.begin(), order.end(), rng);

  // Warm-up: builds the lazily built index, so that no timed query pays for it.
  (void)b.plan.sensors_in(b.rooms[0]);
  (void)b.plan.sensors_in(b.rooms.back());

  std::vector<std::vector<std::string>> brute_answers;
  const auto brute = time_queries(b, &sp::Plan::sensors_in_brute_force, order, options.brute_queries,
                                  &brute_answers, nullptr, "brute force");
  const auto scan = time_queries(b, &sp::Plan::sensors_in_scan, order, options.brute_queries, nullptr,
                                 &brute_answers, "scan");
  const auto indexed = time_queries(b, &sp::Plan::sensors_in, order, options.queries, nullptr, &brute_answers,
                                    "the index");
  std::size_t found = 0;
  for (const auto& a : brute_answers) found += a.size();
  const double mean_found = brute_answers.empty() ? 0 : static_cast<double>(found) / brute_answers.size();
  const double ratio = brute.p50_us / indexed.p50_us;
  const double ratio_scan = scan.p50_us / indexed.p50_us;
  const bool met = ratio >= kTarget;

  if (options.json) {
    std::printf(
        "{\"sensors\":%zu,\"rooms\":%zu,\"floors\":2,\"area_queries\":%zu,\"brute_force_queries\":%zu,"
        "\"mean_sensors_per_area\":%.2f,\"area_query_p50_us\":%.3f,\"area_query_p99_us\":%.3f,"
        "\"brute_force_p50_us\":%.3f,\"brute_force_p99_us\":%.3f,\"bbox_scan_p50_us\":%.3f,"
        "\"ratio_vs_brute_force\":%.1f,\"ratio_vs_bbox_scan\":%.1f,\"target_ratio\":%.0f,\"target_met\":%s}\n",
        options.sensors, options.rooms, indexed.samples, brute.samples, mean_found, indexed.p50_us, indexed.p99_us,
        brute.p50_us, brute.p99_us, scan.p50_us, ratio, ratio_scan, kTarget, met ? "true" : "false");
  } else {
    std::printf("tahvel bench spatial: %zu sensors, %zu rooms on 2 floors (%.0f m x %.0f m), %.1f sensors per room\n\n",
                options.sensors, options.rooms, b.width, b.depth, mean_found);
    std::printf("                              p50 us     p99 us   queries\n");
    std::printf("area query (kd-tree index) %9.2f  %9.2f  %8zu\n", indexed.p50_us, indexed.p99_us, indexed.samples);
    std::printf("brute force (every sensor) %9.2f  %9.2f  %8zu\n", brute.p50_us, brute.p99_us, brute.samples);
    std::printf("scan with box filter       %9.2f  %9.2f  %8zu\n\n", scan.p50_us, scan.p99_us, scan.samples);
    std::printf("index vs brute force  %8.1f x   target >= %.0f x  %s\n", ratio, kTarget, met ? "met" : "NOT met");
    std::printf("index vs box scan     %8.1f x\n", ratio_scan);
  }
  return kExitOk;
}

}  // namespace tahvel::cli
