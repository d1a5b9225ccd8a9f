// WKT reading and writing (tahvel/spatial/wkt.h): the accepted forms, the refused ones with the
// column each error names, and the round trip through to_wkt.
#include "tahvel/spatial/wkt.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

namespace tahvel::spatial {
namespace {

// The error of parsing `text`, which must fail.
Error error_of(std::string_view text) {
  auto g = parse_wkt(text);
  EXPECT_FALSE(g.has_value()) << text;
  return g ? Error{} : g.error();
}

TEST(Wkt, ReadsAPoint) {
  auto p = parse_point("POINT(1.5 -2e1)");
  ASSERT_TRUE(p.has_value()) << p.error().message;
  EXPECT_EQ(*p, (Point{1.5, -20}));
}

TEST(Wkt, KeywordsInAnyCaseAndSpacesAnywhere) {
  auto p = parse_point("  point ( +3\t4 )\n");
  ASSERT_TRUE(p.has_value()) << p.error().message;
  EXPECT_EQ(*p, (Point{3, 4}));
}

TEST(Wkt, SkipsAGeoSparqlCrsIri) {
  auto p = parse_point("<http://www.opengis.net/def/crs/OGC/1.3/CRS84> POINT(24.7 59.4)");
  ASSERT_TRUE(p.has_value()) << p.error().message;
  EXPECT_EQ(*p, (Point{24.7, 59.4}));
  EXPECT_EQ(wkt_crs("  <http://www.opengis.net/def/crs/EPSG/0/4326> POINT(1 2)"), "http://www.opengis.net/def/crs/EPSG/0/4326");
  EXPECT_EQ(wkt_crs("POINT(1 2)"), "");
}

TEST(Wkt, ReadsAPolygonWithAHoleAndDropsTheClosingPoint) {
  auto s = parse_shape("POLYGON((0 0, 6 0, 6 4, 0 4, 0 0), (2 1, 3 1, 3 2, 2 2, 2 1))");
  ASSERT_TRUE(s.has_value()) << s.error().message;
  ASSERT_EQ(s->polygons.size(), 1u);
  EXPECT_EQ(s->polygons[0].outer, (Ring{{0, 0}, {6, 0}, {6, 4}, {0, 4}}));
  ASSERT_EQ(s->polygons[0].holes.size(), 1u);
  EXPECT_EQ(s->polygons[0].holes[0], (Ring{{2, 1}, {3, 1}, {3, 2}, {2, 2}}));
}

// A hall with 400 pillars, and a room whose holes leave a strip 0.02 wide: rooms, each (the
// holes' areas fall short of the room's, or, within 1 %, the exact test finds what is left). In
// a 4 x 4 room, holes that leave nothing are refused (the refusals below). Subtracted one by
// one, 2,000 pillars took 9 s to check at every read of a floor plan.
TEST(Wkt, ARoomWithManyHolesOrHolesLeavingAStripIsARoom) {
  std::string hall = "POLYGON((0 0, 100 0, 100 100, 0 100, 0 0)";
  for (int i = 0; i < 20; ++i)
    for (int j = 0; j < 20; ++j) {
      const std::string x = std::to_string(i * 5 + 2), y = std::to_string(j * 5 + 2), x1 = std::to_string(i * 5 + 3),
                        y1 = std::to_string(j * 5 + 3);
      hall += ", (" + x + " " + y + ", " + x1 + " " + y + ", " + x1 + " " + y1 + ", " + x + " " + y1 + ", " + x + " " + y + ")";
    }
  hall += ")";
  auto pillars = parse_shape(hall);
  ASSERT_TRUE(pillars.has_value()) << pillars.error().message;
  EXPECT_EQ(pillars->polygons.at(0).holes.size(), 400u);
  auto strip = parse_shape("POLYGON((0 0, 4 0, 4 4, 0 4, 0 0), (0 0, 4 0, 4 2, 0 2, 0 0), (0 2.02, 4 2.02, 4 4, 0 4, 0 2.02))");
  EXPECT_TRUE(strip.has_value()) << strip.error().message;
  auto none_left = parse_shape("POLYGON((0 0, 4 0, 4 4, 0 4, 0 0), (0 0, 4 0, 4 2, 0 2, 0 0), (0 2, 4 2, 4 4, 0 4, 0 2))");
  ASSERT_FALSE(none_left.has_value());
  EXPECT_NE(none_left.error().message.find("no area"), std::string::npos) << none_left.error().message;
  // Three triangles that tile a triangle near 1e-161, whose areas in doubles are subnormal and
  // added up to less than 99 % of it (a review's case): refused all the same.
  auto tiny = parse_shape(
      "POLYGON((0 0, 6.6682762484552325e-162 0, 0 2.0004828745365697e-161, 0 0), "
      "(0 0, 6.6682762484552325e-162 0, 4.445517498970155e-162 6.6682762484552325e-162, 0 0), "
      "(0 0, 4.445517498970155e-162 6.6682762484552325e-162, 2.2227587494850775e-162 1.3336552496910465e-161, 0 0), "
      "(0 0, 2.2227587494850775e-162 1.3336552496910465e-161, 0 2.0004828745365697e-161, 0 0))");
  EXPECT_FALSE(tiny.has_value()) << "holes that tile the polygon near 1e-161 were taken for leaving area";
}

TEST(Wkt, ReadsAMultipolygon) {
  auto s = parse_shape("MULTIPOLYGON(((0 0,1 0,1 1,0 0)),((5 5,6 5,6 6,5 6,5 5),(5.2 5.2,5.8 5.2,5.5 5.8,5.2 5.2)))");
  ASSERT_TRUE(s.has_value()) << s.error().message;
  ASSERT_EQ(s->polygons.size(), 2u);
  EXPECT_EQ(s->polygons[0].outer.size(), 3u);
  EXPECT_EQ(s->polygons[1].holes.size(), 1u);
}

TEST(Wkt, RoundTripsThroughToWkt) {
  for (const char* text : {"POINT(0.1 -3)", "POLYGON((0 0, 4 0, 4 3, 2 1, 0 3, 0 0))",
                           "POLYGON((0 0, 6 0, 6 4, 0 4, 0 0), (2 1, 3 1, 3 2, 2 2, 2 1))",
                           "MULTIPOLYGON(((0 0, 1 0, 1 1, 0 0)), ((5 5, 6 5, 6 6, 5 5)))"}) {
    auto g = parse_wkt(text);
    ASSERT_TRUE(g.has_value()) << text << ": " << g.error().message;
    std::string written = std::visit([](const auto& v) { return to_wkt(v); }, *g);
    EXPECT_EQ(written, text);
    auto again = parse_wkt(written);
    ASSERT_TRUE(again.has_value());
    EXPECT_EQ(std::visit([](const auto& v) { return to_wkt(v); }, *again), written);
  }
}

struct Refusal {
  const char* text;
  std::size_t column;
  const char* says;  // a part of the message
};

TEST(Wkt, RefusesMalformedTextNamingTheColumn) {
  const Refusal cases[] = {
      {"", 1, "expected a geometry type, found end of text"},
      {"LINESTRING(0 0, 1 1)", 1, "unsupported geometry type 'LINESTRING'"},
      {"POINT(1 2 3)", 11, "third coordinate"},
      {"POINT Z (1 2 3)", 7, "Z and M coordinates are not supported"},
      {"POINT EMPTY", 7, "EMPTY"},
      {"POINT(1 ,2)", 9, "expected a number, found ','"},
      {"POINT(1e 2)", 8, "exponent without digits"},
      {"POINT(1e999 2)", 7, "out of range"},
      {"POINT(nan 2)", 7, "expected a number, found 'nan'"},
      {"POINT(1 2) x", 12, "unexpected 'x' after the geometry"},
      {"42", 1, "expected a geometry type, found '42'"},  // the number whole, not its first digit
      {"POINT(1 2", 10, "expected ')', found end of text"},
      {"POLYGON((0 0, 1 0, 0 0))", 9, "at least 4 points"},
      {"POLYGON((0 0, 4 0, 4 4, 0 4))", 9, "not closed"},
      // Not simple: the column of the later of the two edges that meet.
      {"POLYGON((0 0, 4 4, 4 0, 0 4, 0 0))", 20, "the edge from (4 0) to (0 4) meets the edge from (0 0) to (4 4)"},
      {"POLYGON((0 0, 1 0, 2 0, 0 0))", 20, "the edge from (2 0) to (0 0) meets the edge from (0 0) to (1 0)"},
      {"POLYGON((0 0, 4 0, 4 4, 2 4, 2 0, 0 4, 0 0))", 25, "the edge from (2 4) to (2 0) meets the edge from (0 0) to (4 0)"},
      {"POLYGON((0 0, 4 0, 2 0, 2 4, 0 0))", 15, "the edge from (4 0) to (2 0) meets the edge from (0 0) to (4 0)"},
      {"POLYGON((0 0, 4 0, 4 4, 0 4, 0 0), (0 0, 4 0, 4 4, 0 4, 0 0))", 8, "holes cover all of it"},
      {"POLYGON((0 0, 4 0, 4 4, 0 4, 0 0), (0 0, 4 0, 4 4, 0 0), (0 0, 4 4, 0 4, 0 0))", 8, "no area"},
      {"POINT(\u22121 2)", 7, "expected a number, found '\u2212'"},  // a Unicode minus, whole
      {"POLYGON((0 0, 4 0, 4 4, 0 4, 0 0), (5 5, 6 5, 6 6, 5 5))", 36, "outside the outer ring"},
      // At the vertex that lies outside, not where its hole starts.
      {"POLYGON((0 0, 4 0, 4 4, 0 4, 0 0), (1 1, 5 1, 2 2, 1 1))", 42, "hole vertex (5 1) lies outside the outer ring"},
      {"MULTIPOLYGON(((0 0, 1 0, 1 1, 0 0)), ((0 0, 1 0, 1 1, 0 1)))", 39, "not closed"},
      {"<http://x/crs POINT(1 2)", 1, "without '>'"},
      {"<junk junk> POINT(1 2)", 1, "'<junk junk>' is not a CRS IRI"},
      {"<> POINT(1 2)", 1, "'<>' is not a CRS IRI"},
      // A typo is not two numbers: "1.5.5" is not (1.5 .5), "4-0" not (4 -0).
      {"POINT(1.5.5)", 7, "malformed number '1.5.5'"},
      {"POINT(2e1.5)", 7, "malformed number '2e1.5'"},
      {"POLYGON((0 0,4-0,4 4,0 4,0 0))", 14, "malformed number '4-0'"},
      {"POINT(1)", 8, "expected white space and a second coordinate, found ')'"},
      // Beyond this the exact geometry overflows (1e154 crashed CGAL; 1e308 the grid).
      {"POLYGON((-1e308 10, 1e308 10, 1e308 11, -1e308 11, -1e308 10))", 10, "beyond +/-1e15"},
      {"POLYGONZ((0 0 0, 4 0 0, 4 4 0, 0 0 0))", 8, "Z and M coordinates are not supported"},
      {"POINTZM(1 1 1 1)", 6, "Z and M coordinates are not supported"},
      {"SRID=4326;POINT(1 1)", 1, "EWKT's 'SRID=...;' is not WKT"},
      // A hole in an L-shaped ring's notch: its vertices lie on the ring, its edges only touch it.
      {"POLYGON((0 0, 4 0, 4 2, 2 2, 2 4, 0 4, 0 0), (2 2, 4 2, 2 4, 2 2))", 46, "the hole reaches outside the outer ring"},
      {"POLYGON((0 0, 4 0, 4 2, 2 2, 2 4, 0 4, 0 0), (3 1, 4 2, 2 4, 1 3, 3 1))", 46, "the hole reaches outside the outer ring"},
  };
  for (const Refusal& c : cases) {
    Error e = error_of(c.text);
    EXPECT_EQ(e.column, c.column) << c.text << ": " << e.message;
    EXPECT_NE(e.message.find("WKT column " + std::to_string(c.column) + ": "), std::string::npos)
        << c.text << ": " << e.message;
    EXPECT_NE(e.message.find(c.says), std::string::npos) << c.text << ": " << e.message;
  }
}

// Holes are checked exactly: one courtyard drawn twice (overlapping holes, which S2 leaves
// unchecked) still leaves floor, and a courtyard room at 1e-200 m is still a room.
TEST(Wkt, OverlappingHolesAndTinyCoordinatesAreNotTakenForAPolygonWithoutArea) {
  for (const char* text : {"POLYGON((0 0, 10 0, 10 10, 0 10, 0 0), (1 1, 9 1, 9 9, 1 9, 1 1), (1 1, 9 1, 9 9, 1 9, 1 1))",
                           "POLYGON((0 0, 10 0, 10 10, 0 10, 0 0), (1 1, 8 1, 8 8, 1 8, 1 1), (2 2, 9 2, 9 9, 2 9, 2 2))",
                           "POLYGON((0 0, 4e-200 0, 4e-200 4e-200, 0 4e-200, 0 0), (1e-200 1e-200, 3e-200 1e-200, "
                           "3e-200 3e-200, 1e-200 3e-200, 1e-200 1e-200))"})
    EXPECT_TRUE(parse_wkt(text).has_value()) << text << ": " << parse_wkt(text).error().message;
}

// S1: a number is read to the nearest double. Below the least subnormal that is zero, of the
// number's sign; 1e-330 was refused as "out of range" while 1e-310 was read.
TEST(Wkt, ANumberBelowTheLeastSubnormalIsReadAsZero) {
  auto tiny = parse_point("POINT(1e-330 -2.5e-400)");
  ASSERT_TRUE(tiny.has_value()) << tiny.error().message;
  EXPECT_EQ(tiny->x, 0.0);
  EXPECT_EQ(tiny->y, 0.0);
  EXPECT_TRUE(std::signbit(tiny->y));
  auto subnormal = parse_point("POINT(1e-310 5e-324)");
  ASSERT_TRUE(subnormal.has_value()) << subnormal.error().message;
  EXPECT_GT(subnormal->x, 0.0);
  EXPECT_EQ(subnormal->y, std::numeric_limits<double>::denorm_min());
  EXPECT_NE(error_of("POINT(1e-330 1e999)").message.find("'1e999' is out of range"), std::string::npos);
}

// Exporters (QGIS, some CAD tools) repeat a vertex; OGC allows it. It is kept once.
TEST(Wkt, AVertexRepeatedAtOnceIsKeptOnce) {
  auto s = parse_shape("POLYGON((0 0, 4 0, 4 0, 4 4, 0 4, 0 4, 0 0, 0 0))");
  ASSERT_TRUE(s.has_value()) << s.error().message;
  EXPECT_EQ(s->polygons[0].outer, (Ring{{0, 0}, {4, 0}, {4, 4}, {0, 4}}));
  Error e = error_of("POLYGON((0 0, 0 0, 1 1, 1 1, 0 0))");  // still too few distinct vertices
  EXPECT_NE(e.message.find("at least 3 distinct vertices, found 2"), std::string::npos) << e.message;
}

TEST(Wkt, ParsePointAndParseShapeRefuseTheOtherKind) {
  auto p = parse_point("  POLYGON((0 0, 1 0, 1 1, 0 0))");
  ASSERT_FALSE(p.has_value());
  EXPECT_EQ(p.error().column, 3u);
  auto s = parse_shape("POINT(1 2)");
  ASSERT_FALSE(s.has_value());
  EXPECT_NE(s.error().message.find("expected a POLYGON or MULTIPOLYGON"), std::string::npos);
}

TEST(Geometry, ValidateNamesThePolygonAndRing) {
  Shape bad{{Polygon{{{0, 0}, {4, 0}, {4, 4}, {0, 4}}, {{{1, 1}, {2, 2}, {2, 1}, {1, 2}}}}}};
  auto v = validate(bad);
  ASSERT_FALSE(v.has_value());
  EXPECT_NE(v.error().message.find("polygon 1, hole 1: ring is not simple"), std::string::npos)
      << v.error().message;
  EXPECT_FALSE(validate(Shape{}).has_value());
}

}  // namespace
}  // namespace tahvel::spatial
