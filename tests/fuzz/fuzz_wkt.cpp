// Fuzz target: the WKT reader of Tahvel::spatial (GeoSPARQL literals come from any writer).
// Properties checked: no crash or sanitizer report; an error names a column within the text
// (1 .. size + 1) and says so in its message; what parses is valid, writes back to WKT that
// parses to the same text again, and can be used as a room and queried.
#include <cstdint>
#include <string>
#include <string_view>
#include <variant>
#include <vector>

#include "tahvel/spatial/plan.h"
#include "tahvel/spatial/wkt.h"
#include "require.h"

using namespace tahvel::spatial;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  std::string_view text(reinterpret_cast<const char*>(data), size);
  auto parsed = parse_wkt(text);
  if (!parsed) {
    REQUIRE(parsed.error().column >= 1 && parsed.error().column <= size + 1);
    REQUIRE(parsed.error().message.rfind("WKT column " + std::to_string(parsed.error().column) + ": ", 0) == 0);
    return 0;
  }
  std::string written = std::visit([](const auto& g) { return to_wkt(g); }, *parsed);
  auto again = parse_wkt(written);
  REQUIRE(again.has_value());
  REQUIRE(std::visit([](const auto& g) { return to_wkt(g); }, *again) == written);
  if (const Shape* shape = std::get_if<Shape>(&*parsed)) {
    REQUIRE(validate(*shape).has_value());
    Plan plan;
    REQUIRE(plan.put_room({"room", 0, *shape}).has_value());
    const Box box = bounding_box(*shape);
    for (Point p : {Point{box.xmin, box.ymin}, Point{box.xmax, box.ymax},
                    Point{(box.xmin + box.xmax) / 2, (box.ymin + box.ymax) / 2}}) {
      REQUIRE(plan.put_sensor({"s", 0, p}).has_value());
      bool in = contains(*shape, p);
      REQUIRE(plan.sensors_in({*shape, 0}).size() == (in ? 1u : 0u));
      REQUIRE(plan.sensors_in_brute_force({*shape, 0}) == plan.sensors_in({*shape, 0}));
      REQUIRE((plan.rooms_at(p, 0).size() == 1) == in);
    }
  }
  return 0;
}

std::vector<std::string> fuzz_seeds() {
  return {"POINT(1 2)",
          "point ( -1.5e3 +2 )",
          "<http://www.opengis.net/def/crs/OGC/1.3/CRS84> POINT(24.7 59.4)",
          "POLYGON((0 0, 4 0, 4 2, 2 2, 2 4, 0 4, 0 0))",
          "POLYGON((0 0, 6 0, 6 4, 0 4, 0 0), (2 1, 3 1, 3 2, 2 2, 2 1))",
          "MULTIPOLYGON(((0 0, 1 0, 1 1, 0 0)), ((5 5, 6 5, 6 6, 5 6, 5 5), (5.2 5.2, 5.8 5.2, 5.5 5.8, 5.2 5.2)))",
          "POLYGON((0 0, 4 4, 4 0, 0 4, 0 0))",
          "POINT Z (1 2 3)",
          "POLYGON EMPTY"};
}
