#include "core/io/off.h"

#include <chrono>
#include <limits>
#include <string>

#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/core/io/status_expectations.h"

namespace rpsr::core {
namespace {

TriangleMesh Tetrahedron() {
  TriangleMesh mesh;
  mesh.vertices = {{0, 0, 0}, {1.5f, 0, 0}, {0, 0.1f, 0}, {0, 0, -7e-5f}};
  mesh.triangles = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
  return mesh;
}

TEST(OffTest, RoundTripsThroughAFile) {
  const std::string path = testing::TempDir() + "/tetra.off";
  ASSERT_TRUE(WriteOff(path, Tetrahedron()).ok());
  absl::StatusOr<TriangleMesh> read = ReadOff(path);
  ASSERT_TRUE(read.ok()) << read.status();
  EXPECT_EQ(read->vertices, Tetrahedron().vertices);
  EXPECT_EQ(read->triangles, Tetrahedron().triangles);
}

TEST(OffTest, CommentsColoursQuadsAndCrLf) {
  const std::string text =
      "# a coloured square\r\n"
      "COFF\r\n"
      "\r\n"
      "4 2 0 # counts\r\n"
      "0 0 0 255 0 0 255\r\n"
      "1 0 0 0 255 0 255\r\n"
      "1 1 0\r\n"
      "# a comment between vertices\r\n"
      "0 1 0 1 1 1 1\r\n"
      "4 0 1 2 3 0.5 0.5 0.5\r\n"
      "3 3 2 1\r\n";
  absl::StatusOr<TriangleMesh> parsed = ParseOff(text, "square.off");
  ASSERT_TRUE(parsed.ok()) << parsed.status();
  EXPECT_EQ(parsed->vertices.size(), 4u);
  EXPECT_EQ(parsed->vertices[3], Eigen::Vector3f(0, 1, 0));
  EXPECT_EQ(parsed->triangles, (std::vector<Eigen::Vector3i>{{0, 1, 2}, {0, 2, 3}, {3, 2, 1}}));
}

TEST(OffTest, CountsOnTheKeywordLineIncludingModelNetQuirk) {
  for (const char* header : {"OFF 3 1 0\n", "OFF3 1 0\n", "NOFF\n3 1\n"}) {
    absl::StatusOr<TriangleMesh> parsed =
        ParseOff(std::string(header) + "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n", "m.off");
    ASSERT_TRUE(parsed.ok()) << header << parsed.status();
    EXPECT_EQ(parsed->triangles.size(), 1u) << header;
  }
}

TEST(OffMalformedTest, EmptyWrongMagicAndMissingCounts) {
  ExpectInvalid(ParseOff("", "e.off"), "e.off", {"empty"});
  ExpectInvalid(ParseOff("# nothing\n\n", "c.off"), "c.off", {"empty"});
  ExpectInvalid(ParseOff("ply\nformat ascii 1.0\n", "p.off"), "p.off", {"line 1", "'ply'"});
  ExpectInvalid(ParseOff("OFF\n", "n.off"), "n.off", {"before the vertex and face counts"});
  ExpectInvalid(ParseOff("OFF\n3\n", "n.off"), "n.off", {"line 2", "counts"});
  ExpectInvalid(ParseOff("OFF\n-3 1 0\n", "n.off"), "n.off", {"line 2", "counts"});
}

TEST(OffMalformedTest, UnsupportedVariants) {
  ExpectError(ParseOff("OFF BINARY\n", "b.off"), absl::StatusCode::kUnimplemented,
              {"b.off", "line 1", "BINARY"});
  ExpectError(ParseOff("4OFF\n1 0 0\n0 0 0 0\n", "4.off"), absl::StatusCode::kUnimplemented,
              {"4.off", "line 1"});
}

TEST(OffMalformedTest, HugeDeclaredCountsFailFastWithoutAllocating) {
  const auto start = std::chrono::steady_clock::now();
  ExpectInvalid(ParseOff("OFF\n4000000000 1 0\n0 0 0\n", "huge.off"), "huge.off",
                {"line 2", "4000000000", "limit"});
  ExpectInvalid(ParseOff("OFF\n1000000000 1000000000 0\n0 0 0\n", "big.off"), "big.off",
                {"line 4", "ends after 1 of the 1000000000 vertices"});
  EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(1));
}

TEST(OffMalformedTest, CountsThatLie) {
  ExpectInvalid(ParseOff("OFF\n3 1 0\n0 0 0\n1 0 0\n", "v.off"), "v.off",
                {"line 5", "ends after 2 of the 3 vertices"});
  ExpectInvalid(ParseOff("OFF\n3 2 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n", "f.off"), "f.off",
                {"line 7", "ends after 1 of the 2 faces"});
  ExpectInvalid(ParseOff("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n3 2 1 0\n", "d.off"), "d.off",
                {"line 7", "after the last face"});
}

TEST(OffMalformedTest, BadVerticesAndFaces) {
  const std::string head = "OFF\n3 1 0\n0 0 0\n1 0 0\n";
  ExpectInvalid(ParseOff(head + "0 1\n3 0 1 2\n", "v.off"), "v.off", {"line 5", "(vertex 2)"});
  ExpectInvalid(ParseOff(head + "0 nan 0\n3 0 1 2\n", "nan.off"), "nan.off",
                {"line 5", "(vertex 2)", "not a finite"});
  ExpectInvalid(ParseOff(head + "0 one 0\n3 0 1 2\n", "g.off"), "g.off",
                {"line 5", "'one' is not a number"});
  const std::string vertices = head + "0 1 0\n";
  ExpectInvalid(ParseOff(vertices + "2 0 1\n", "two.off"), "two.off",
                {"line 6", "(face 0)", "has 2 vertices"});
  ExpectInvalid(ParseOff(vertices + "4 0 1 2\n", "short.off"), "short.off",
                {"line 6", "declares 4 vertices but lists 3"});
  ExpectInvalid(ParseOff(vertices + "3 0 1 3\n", "idx.off"), "idx.off",
                {"line 6", "(face 0)", "'3'", "below the vertex count 3"});
  ExpectInvalid(ParseOff(vertices + "3 0 -1 2\n", "neg.off"), "neg.off", {"'-1'"});
  ExpectInvalid(ParseOff(vertices + "x 0 1 2\n", "cnt.off"), "cnt.off", {"line 6", "'x'"});
}

TEST(OffMalformedTest, WriterRejectsBadTriangles) {
  TriangleMesh mesh = Tetrahedron();
  mesh.triangles.push_back({0, 1, 4});
  ExpectInvalid(WriteOff(testing::TempDir() + "/bad.off", mesh), testing::TempDir() + "/bad.off",
                {"triangle 4"});
}

}  // namespace
}  // namespace rpsr::core
