#include "core/io/pcd.h"

#include <bit>
#include <chrono>
#include <cstring>
#include <limits>
#include <string>

#include "absl/strings/str_cat.h"
#include "core/io/binary_scalars.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/core/io/status_expectations.h"

namespace rpsr::core {
namespace {

using io_internal::AppendFloat32;
using io_internal::AppendFloat64;

PointCloud SmallCloud(bool with_intensity) {
  PointCloud cloud;
  cloud.points = {{0.1f, -2.5f, 3e7f}, {-1e-20f, 0, 42}, {1, 2, 3}};
  if (with_intensity) cloud.intensities = {0.5f, -1, 1e10f};
  return cloud;
}

TEST(PcdTest, RoundTripsAsciiAndBinaryWithAndWithoutIntensity) {
  for (PcdFormat format : {PcdFormat::kAscii, PcdFormat::kBinary}) {
    for (bool with_intensity : {false, true}) {
      const PointCloud cloud = SmallCloud(with_intensity);
      absl::StatusOr<std::string> bytes = SerializePcd(cloud, format);
      ASSERT_TRUE(bytes.ok()) << bytes.status();
      absl::StatusOr<PointCloud> parsed = ParsePcd(*bytes, "c.pcd");
      ASSERT_TRUE(parsed.ok()) << parsed.status();
      EXPECT_EQ(parsed->points, cloud.points);
      EXPECT_EQ(parsed->intensities, cloud.intensities);
    }
  }
}

TEST(PcdTest, RoundTripsThroughAFile) {
  const std::string path = testing::TempDir() + "/round_trip.pcd";
  const PointCloud cloud = SmallCloud(true);
  ASSERT_TRUE(WritePcd(path, cloud).ok());
  absl::StatusOr<PointCloud> read = ReadPcd(path);
  ASSERT_TRUE(read.ok()) << read.status();
  EXPECT_EQ(read->points, cloud.points);
  EXPECT_EQ(read->intensities, cloud.intensities);
}

TEST(PcdTest, EmptyCloudRoundTrips) {
  absl::StatusOr<std::string> bytes = SerializePcd(PointCloud{}, PcdFormat::kBinary);
  ASSERT_TRUE(bytes.ok());
  absl::StatusOr<PointCloud> parsed = ParsePcd(*bytes, "empty.pcd");
  ASSERT_TRUE(parsed.ok()) << parsed.status();
  EXPECT_TRUE(parsed->empty());
}

TEST(PcdTest, HandWrittenAsciiWithExtraFieldsAndCrLf) {
  const std::string text =
      "# .PCD v0.7 - Point Cloud Data file format\r\n"
      "VERSION 0.7\r\n"
      "FIELDS rgb x normal y _ z intensity\r\n"
      "SIZE 4 4 4 8 1 4 2\r\n"
      "TYPE U F F F U F U\r\n"
      "COUNT 1 1 3 1 2 1 1\r\n"
      "WIDTH 2\r\n"
      "HEIGHT 1\r\n"
      "VIEWPOINT 0 0 0 1 0 0 0\r\n"
      "POINTS 2\r\n"
      "DATA ascii\r\n"
      "4278190080 1 nan nan nan 2 0 0 3 100\r\n"
      "\r\n"
      "0 -1.5 0 0 1 +2.5e1 7 7 -3 200\r\n";
  absl::StatusOr<PointCloud> parsed = ParsePcd(text, "extras.pcd");
  ASSERT_TRUE(parsed.ok()) << parsed.status();
  EXPECT_EQ(parsed->points, (std::vector<Eigen::Vector3f>{{1, 2, 3}, {-1.5f, 25, -3}}));
  EXPECT_EQ(parsed->intensities, (std::vector<float>{100, 200}));
}

TEST(PcdTest, HandWrittenBinaryWithMixedTypesAndOrganizedShape) {
  std::string bytes =
      "VERSION .7\nFIELDS x y z label intensity desc\nSIZE 8 4 2 4 1 2\nTYPE F F I U U U\n"
      "COUNT 1 1 1 1 1 3\nWIDTH 2\nHEIGHT 2\nPOINTS 4\nDATA binary\n";
  for (int i = 0; i < 4; ++i) {
    AppendFloat64(0.5 * i, std::endian::little, &bytes);
    AppendFloat32(-1.0f * i, std::endian::little, &bytes);
    const int16_t z = static_cast<int16_t>(-300 * i);
    bytes.append(reinterpret_cast<const char*>(&z), 2);
    bytes.append(4, '\x7f');
    bytes.push_back(static_cast<char>(250 + i));
    bytes.append(6, '\xff');
  }
  absl::StatusOr<PointCloud> parsed = ParsePcd(bytes, "mixed.pcd");
  ASSERT_TRUE(parsed.ok()) << parsed.status();
  ASSERT_EQ(parsed->size(), 4u);
  EXPECT_EQ(parsed->points[3], Eigen::Vector3f(1.5f, -3, -900));
  EXPECT_EQ(parsed->intensities, (std::vector<float>{250, 251, 252, 253}));
}

TEST(PcdTest, OldHeaderWithoutPointsOrCount) {
  absl::StatusOr<PointCloud> parsed =
      ParsePcd("FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 1\nDATA ascii\n1 2 3", "old.pcd");
  ASSERT_TRUE(parsed.ok()) << parsed.status();
  EXPECT_EQ(parsed->points, (std::vector<Eigen::Vector3f>{{1, 2, 3}}));
}

// --- Malformed input -----------------------------------------------------------------------

std::string Header(
    const std::string& points, const std::string& data,
    const std::string& fields = "FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n",
    const std::string& width = "") {
  return absl::StrCat("VERSION 0.7\n", fields, "WIDTH ", width.empty() ? points : width,
                      "\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS ", points, "\nDATA ", data,
                      "\n");
}

std::string Floats(int n) {
  std::string bytes;
  for (int i = 0; i < n; ++i) AppendFloat32(static_cast<float>(i), std::endian::little, &bytes);
  return bytes;
}

TEST(PcdMalformedTest, EmptyAndGarbage) {
  ExpectInvalid(ParsePcd("", "e.pcd"), "e.pcd", {"empty"});
  ExpectInvalid(ParsePcd("ply\nformat ascii 1.0\n", "g.pcd"), "g.pcd",
                {"line 1", "'ply'", "not a PCD file"});
  ExpectInvalid(ParsePcd("# only a comment\n", "c.pcd"), "c.pcd", {"DATA"});
}

TEST(PcdMalformedTest, CompressedIsUnimplemented) {
  ExpectError(ParsePcd(Header("1", "binary_compressed") + "xxxx", "lzf.pcd"),
              absl::StatusCode::kUnimplemented, {"lzf.pcd", "line 10", "binary_compressed"});
}

TEST(PcdMalformedTest, InconsistentHeaders) {
  ExpectInvalid(
      ParsePcd(Header("3", "ascii", "FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\n", "2"), "p.pcd"),
      "p.pcd", {"line 8", "POINTS 3", "WIDTH 2"});
  ExpectInvalid(ParsePcd(Header("1", "ascii", "FIELDS x y z\nSIZE 4 4\nTYPE F F F\n"), "s.pcd"),
                "s.pcd", {"line 3", "SIZE has 2 values"});
  ExpectInvalid(ParsePcd(Header("1", "ascii", "FIELDS x y z\nSIZE 4 2 4\nTYPE F F F\n"), "t.pcd"),
                "t.pcd", {"line 4", "field 'y'", "SIZE '2'"});
  ExpectInvalid(ParsePcd(Header("1", "ascii",
                                "FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 0 "
                                "1\n"),
                         "c.pcd"),
                "c.pcd", {"line 5", "COUNT '0'"});
  ExpectInvalid(ParsePcd(Header("1", "ascii",
                                "FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 2 "
                                "1\n"),
                         "c2.pcd"),
                "c2.pcd", {"line 5", "field 'y' has COUNT 2"});
  ExpectInvalid(ParsePcd(Header("1", "ascii", "FIELDS x z w\nSIZE 4 4 4\nTYPE F F F\n"), "y.pcd"),
                "y.pcd", {"line 2", "no field 'y'"});
  ExpectInvalid(
      ParsePcd(Header("1", "ascii", "FIELDS x y x z\nSIZE 4 4 4 4\nTYPE F F F F\n"), "d.pcd"),
      "d.pcd", {"line 2", "'x' appears twice"});
  ExpectInvalid(ParsePcd("FIELDS x y z\nSIZE 4 4 4\nWIDTH 1\nDATA ascii\n1 2 3\n", "nt.pcd"),
                "nt.pcd", {"line 4", "no TYPE"});
  ExpectInvalid(ParsePcd(Header("1", "lzma"), "k.pcd"), "k.pcd", {"line 10", "'lzma'"});
  ExpectInvalid(ParsePcd("FIELDS x y z\nBOGUS 1\n", "b.pcd"), "b.pcd", {"line 2", "'BOGUS'"});
}

TEST(PcdMalformedTest, HugeDeclaredCountsFailFastWithoutAllocating) {
  const auto start = std::chrono::steady_clock::now();
  ExpectInvalid(ParsePcd(Header("4000000000", "binary") + Floats(3), "huge.pcd"), "huge.pcd",
                {"line 6", "4000000000", "limit"});
  ExpectInvalid(ParsePcd(Header("1000000000", "binary") + Floats(3), "big.pcd"), "big.pcd",
                {"byte offset", "1000000000 points", "12 bytes follow", "truncated"});
  ExpectInvalid(ParsePcd(Header("1000000000", "ascii") + "1 2 3\n", "big.pcd"), "big.pcd",
                {"ends after 1 of the 1000000000"});
  ExpectInvalid(
      ParsePcd("FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 1000000000\nHEIGHT 1000000000\n"
               "DATA binary\n",
               "wh.pcd"),
      "wh.pcd", {"line 5", "WIDTH 1000000000 * HEIGHT 1000000000"});
  ExpectInvalid(ParsePcd(Header("1", "binary",
                                "FIELDS x y z w\nSIZE 4 4 4 8\nTYPE F F F F\n"
                                "COUNT 1 1 1 99999999999\n"),
                         "cnt.pcd"),
                "cnt.pcd", {"line 5", "field 'w' has COUNT"});
  EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(1));
}

TEST(PcdMalformedTest, BinaryCountsThatLie) {
  const std::string up = Header("3", "binary");
  ExpectInvalid(
      ParsePcd(up + Floats(6), "up.pcd"), "up.pcd",
      {absl::StrCat("byte offset ", up.size()), "3 points of 12 bytes", "24 bytes", "truncated"});
  ExpectInvalid(ParsePcd(Header("1", "binary") + Floats(6), "down.pcd"), "down.pcd",
                {"24 bytes follow", "too long"});
}

TEST(PcdMalformedTest, AsciiCountsThatLie) {
  ExpectInvalid(ParsePcd(Header("3", "ascii") + "1 2 3\n4 5 6\n", "up.pcd"), "up.pcd",
                {"line 13", "ends after 2 of the 3 points"});
  ExpectInvalid(ParsePcd(Header("1", "ascii") + "1 2 3\n4 5 6\n", "down.pcd"), "down.pcd",
                {"line 12", "more point lines than POINTS 1"});
  ExpectInvalid(ParsePcd(Header("2", "ascii") + "1 2 3\n4 5\n", "short.pcd"), "short.pcd",
                {"line 12", "point 1", "2 values"});
}

TEST(PcdMalformedTest, NonFiniteAndGarbageValues) {
  ExpectInvalid(ParsePcd(Header("2", "ascii") + "1 2 3\n4 nan 6\n", "nan.pcd"), "nan.pcd",
                {"line 12", "point 1", "field 'y'", "not a finite"});
  ExpectInvalid(ParsePcd(Header("1", "ascii") + "1 2 zz\n", "z.pcd"), "z.pcd",
                {"line 11", "'zz' is not a number"});
  const std::string header = Header("2", "binary");
  std::string bytes = header + Floats(3);
  AppendFloat32(0, std::endian::little, &bytes);
  AppendFloat32(std::numeric_limits<float>::infinity(), std::endian::little, &bytes);
  AppendFloat32(0, std::endian::little, &bytes);
  ExpectInvalid(ParsePcd(bytes, "inf.pcd"), "inf.pcd",
                {absl::StrCat("byte offset ", header.size() + 16), "point 1", "field 'y'"});
}

TEST(PcdMalformedTest, WriterRejectsMismatchedIntensities) {
  PointCloud cloud = SmallCloud(false);
  cloud.intensities = {1};
  ExpectInvalid(WritePcd(testing::TempDir() + "/bad.pcd", cloud), testing::TempDir() + "/bad.pcd",
                {"intensities"});
}

}  // namespace
}  // namespace rpsr::core
