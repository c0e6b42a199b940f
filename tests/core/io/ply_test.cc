#include "core/io/ply.h"

#include <bit>
#include <chrono>
#include <cmath>
#include <limits>
#include <random>
#include <string>
#include <tuple>

#include "absl/strings/str_cat.h"
#include "core/io/binary_scalars.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/core/io/status_expectations.h"

namespace rpsr::core {
namespace {

using io_internal::AppendFloat32;
using io_internal::AppendFloat64;
using io_internal::AppendInt32;

PointCloud RandomCloud(size_t n, bool with_intensity, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> coordinate(-1000.0f, 1000.0f);
  PointCloud cloud;
  for (size_t i = 0; i < n; ++i) {
    cloud.points.emplace_back(coordinate(rng), coordinate(rng) * 1e-6f, coordinate(rng) * 1e3f);
    if (with_intensity) cloud.intensities.push_back(coordinate(rng));
  }
  return cloud;
}

const char* FormatName(PlyFormat format) {
  switch (format) {
    case PlyFormat::kAscii:
      return "ascii";
    case PlyFormat::kBinaryLittleEndian:
      return "binary_little_endian";
    case PlyFormat::kBinaryBigEndian:
      return "binary_big_endian";
  }
  return "";
}

class PlyRoundTripTest : public ::testing::TestWithParam<std::tuple<PlyFormat, PlyCoordinateType>> {
};

TEST_P(PlyRoundTripTest, CloudWithIntensitiesReadsBackExactly) {
  const auto [format, coordinate_type] = GetParam();
  const PointCloud cloud = RandomCloud(257, /*with_intensity=*/true, 7);
  absl::StatusOr<std::string> bytes = SerializePly(cloud, format, coordinate_type);
  ASSERT_TRUE(bytes.ok()) << bytes.status();
  EXPECT_THAT(*bytes, ::testing::HasSubstr(absl::StrCat("format ", FormatName(format))));
  absl::StatusOr<PlyContents> parsed = ParsePly(*bytes, "cloud.ply");
  ASSERT_TRUE(parsed.ok()) << parsed.status();
  EXPECT_EQ(parsed->cloud.points, cloud.points);
  EXPECT_EQ(parsed->cloud.intensities, cloud.intensities);
  EXPECT_FALSE(parsed->has_faces);
}

TEST_P(PlyRoundTripTest, MeshThroughAFile) {
  const auto [format, coordinate_type] = GetParam();
  TriangleMesh mesh;
  mesh.vertices = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0.5f}};
  mesh.triangles = {{0, 1, 2}, {0, 2, 3}};
  // One file per parameter: ctest runs the instances as parallel processes.
  const std::string path =
      absl::StrCat(testing::TempDir(), "/mesh_round_trip_", static_cast<int>(format), "_",
                   static_cast<int>(coordinate_type), ".ply");
  ASSERT_TRUE(WritePly(path, mesh, format, coordinate_type).ok());
  absl::StatusOr<PlyContents> read = ReadPly(path);
  ASSERT_TRUE(read.ok()) << read.status();
  EXPECT_TRUE(read->has_faces);
  EXPECT_EQ(read->mesh.vertices, mesh.vertices);
  EXPECT_EQ(read->mesh.triangles, mesh.triangles);
  EXPECT_EQ(read->cloud.points, mesh.vertices);
  EXPECT_TRUE(read->cloud.intensities.empty());
}

INSTANTIATE_TEST_SUITE_P(AllFormats, PlyRoundTripTest,
                         ::testing::Combine(::testing::Values(PlyFormat::kAscii,
                                                              PlyFormat::kBinaryLittleEndian,
                                                              PlyFormat::kBinaryBigEndian),
                                            ::testing::Values(PlyCoordinateType::kFloat32,
                                                              PlyCoordinateType::kFloat64)));

TEST(PlyTest, EmptyCloudRoundTrips) {
  absl::StatusOr<std::string> bytes =
      SerializePly(PointCloud{}, PlyFormat::kAscii, PlyCoordinateType::kFloat32);
  ASSERT_TRUE(bytes.ok());
  absl::StatusOr<PlyContents> parsed = ParsePly(*bytes, "empty.ply");
  ASSERT_TRUE(parsed.ok()) << parsed.status();
  EXPECT_TRUE(parsed->cloud.empty());
}

TEST(PlyTest, WriterRejectsInvalidInputNamingThePath) {
  PointCloud cloud;
  cloud.points = {{0, std::numeric_limits<float>::quiet_NaN(), 0}};
  ExpectInvalid(WritePly(testing::TempDir() + "/nan.ply", cloud), testing::TempDir() + "/nan.ply",
                {"point 0"});
  TriangleMesh mesh;
  mesh.vertices = {{0, 0, 0}};
  mesh.triangles = {{0, 0, 1}};
  ExpectError(SerializePly(mesh, PlyFormat::kAscii, PlyCoordinateType::kFloat32),
              absl::StatusCode::kInvalidArgument, {"triangle 0"});
}

// A big-endian double file written by hand: an extra vertex property before and after x y z, a
// face element with a property before the list and a quad, and an edge element after it.
TEST(PlyTest, HandWrittenBigEndianDoubleWithExtrasAndFaces) {
  std::string bytes =
      "ply\n"
      "format binary_big_endian 1.0\n"
      "comment made by hand\n"
      "obj_info nothing\n"
      "element vertex 4\n"
      "property uchar red\n"
      "property double x\n"
      "property double y\n"
      "property double z\n"
      "property float64 confidence\n"
      "element face 2\n"
      "property int8 flags\n"
      "property list uint8 int32 vertex_indices\n"
      "element edge 1\n"
      "property int vertex1\n"
      "property list ushort float extra\n"
      "end_header\n";
  const double xyz[4][3] = {{0, 0, 0}, {1.5, 0, 0}, {1.5, -2.25, 0}, {0, -2.25, 1e-3}};
  for (int v = 0; v < 4; ++v) {
    bytes.push_back(static_cast<char>(200 + v));
    for (double c : xyz[v]) AppendFloat64(c, std::endian::big, &bytes);
    AppendFloat64(0.5 * v, std::endian::big, &bytes);
  }
  bytes.push_back(1);  // flags
  bytes.push_back(4);  // a quad
  for (int32_t i : {0, 1, 2, 3}) AppendInt32(i, std::endian::big, &bytes);
  bytes.push_back(-1);
  bytes.push_back(3);
  for (int32_t i : {3, 2, 1}) AppendInt32(i, std::endian::big, &bytes);
  AppendInt32(7, std::endian::big, &bytes);  // edge vertex1
  bytes.append({0, 2});                      // a list of 2 floats
  AppendFloat32(1.0f, std::endian::big, &bytes);
  AppendFloat32(2.0f, std::endian::big, &bytes);

  absl::StatusOr<PlyContents> parsed = ParsePly(bytes, "hand.ply");
  ASSERT_TRUE(parsed.ok()) << parsed.status();
  ASSERT_EQ(parsed->cloud.size(), 4u);
  for (int v = 0; v < 4; ++v) {
    EXPECT_EQ(parsed->cloud.points[v],
              Eigen::Vector3d(xyz[v][0], xyz[v][1], xyz[v][2]).cast<float>());
  }
  EXPECT_TRUE(parsed->cloud.intensities.empty());
  ASSERT_TRUE(parsed->has_faces);
  EXPECT_EQ(parsed->mesh.vertices, parsed->cloud.points);
  EXPECT_EQ(parsed->mesh.triangles,
            (std::vector<Eigen::Vector3i>{{0, 1, 2}, {0, 2, 3}, {3, 2, 1}}));
}

TEST(PlyTest, HandWrittenAsciiWithOtherElementsCommentsAndCrLf) {
  const std::string text =
      "ply\r\n"
      "format ascii 1.0\r\n"
      "comment a material element first, and vertex_index with int counts\r\n"
      "element material 2\r\n"
      "property list uchar float name\r\n"
      "element vertex 3\r\n"
      "property short id\r\n"
      "property float x\r\n"
      "property float y\r\n"
      "property float z\r\n"
      "property uchar reflectance\r\n"
      "element face 1\r\n"
      "property list int uint vertex_index\r\n"
      "end_header\r\n"
      "2 0.5 0.25\r\n"
      "0\r\n"
      "1 1 2 3 10\r\n"
      "2 -4.5 5e2 +6 20\r\n"
      "3 7 8 9\r\n"  // records need not be one a line
      "30 3 0 1 2\r\n";
  absl::StatusOr<PlyContents> parsed = ParsePly(text, "hand.ply");
  ASSERT_TRUE(parsed.ok()) << parsed.status();
  EXPECT_EQ(parsed->cloud.points,
            (std::vector<Eigen::Vector3f>{{1, 2, 3}, {-4.5f, 500, 6}, {7, 8, 9}}));
  EXPECT_EQ(parsed->cloud.intensities, (std::vector<float>{10, 20, 30}));
  EXPECT_EQ(parsed->mesh.triangles, (std::vector<Eigen::Vector3i>{{0, 1, 2}}));
}

TEST(PlyTest, LittleEndianIntegerCoordinatesUintCountsAndASkippedElement) {
  std::string bytes =
      "ply\nformat binary_little_endian 1.0\nelement material 2\nproperty uchar r\n"
      "property double s\nelement vertex 3\nproperty int16 x\n"
      "property uint y\nproperty int8 z\nproperty float intensity\nelement face 1\n"
      "property list uint int vertex_indices\nend_header\n";
  bytes.append(2 * 9, '\xff');  // two 9-byte material records, NaN doubles: skipped unread
  const int16_t xs[3] = {-3, 0, 300};
  for (int v = 0; v < 3; ++v) {
    bytes.append(reinterpret_cast<const char*>(&xs[v]), 2);
    AppendInt32(v * 1000, std::endian::little, &bytes);
    bytes.push_back(static_cast<char>(-v));
    AppendFloat32(0.25f * v, std::endian::little, &bytes);
  }
  AppendInt32(3, std::endian::little, &bytes);
  for (int32_t i : {2, 1, 0}) AppendInt32(i, std::endian::little, &bytes);
  absl::StatusOr<PlyContents> parsed = ParsePly(bytes, "ints.ply");
  ASSERT_TRUE(parsed.ok()) << parsed.status();
  EXPECT_EQ(parsed->cloud.points,
            (std::vector<Eigen::Vector3f>{{-3, 0, 0}, {0, 1000, -1}, {300, 2000, -2}}));
  EXPECT_EQ(parsed->cloud.intensities, (std::vector<float>{0, 0.25f, 0.5f}));
  EXPECT_EQ(parsed->mesh.triangles, (std::vector<Eigen::Vector3i>{{2, 1, 0}}));
}

// --- Malformed input -----------------------------------------------------------------------

std::string AsciiHeader(const std::string& vertex_count, const std::string& extra = "") {
  return absl::StrCat("ply\nformat ascii 1.0\nelement vertex ", vertex_count,
                      "\nproperty float x\nproperty float y\nproperty float z\n", extra,
                      "end_header\n");
}

std::string BinaryHeader(uint64_t vertex_count) {
  return absl::StrCat("ply\nformat binary_little_endian 1.0\nelement vertex ", vertex_count,
                      "\nproperty float x\nproperty float y\nproperty float z\nend_header\n");
}

std::string BinaryVertices(int n) {
  std::string bytes;
  for (int i = 0; i < n * 3; ++i) AppendFloat32(static_cast<float>(i), std::endian::little, &bytes);
  return bytes;
}

TEST(PlyMalformedTest, EmptyFile) { ExpectInvalid(ParsePly("", "e.ply"), "e.ply", {"empty"}); }

TEST(PlyMalformedTest, WrongMagic) {
  ExpectInvalid(ParsePly("plx\nformat ascii 1.0\n", "m.ply"), "m.ply", {"line 1", "not a PLY"});
  ExpectInvalid(ParsePly("OFF\n3 1 0\n", "m.ply"), "m.ply", {"line 1"});
}

TEST(PlyMalformedTest, HeaderWithoutEnd) {
  ExpectInvalid(ParsePly("ply\nformat ascii 1.0\nelement vertex 1\n", "h.ply"), "h.ply",
                {"end_header"});
}

TEST(PlyMalformedTest, HeaderErrorsNameTheLine) {
  ExpectInvalid(ParsePly("ply\nformat binary_middle_endian 1.0\nend_header\n", "f.ply"), "f.ply",
                {"line 2", "binary_middle_endian"});
  ExpectInvalid(ParsePly("ply\nformat ascii 1.0\nelement vertex 1\nproperty float128 x\n", "t.ply"),
                "t.ply", {"line 4", "float128"});
  ExpectInvalid(ParsePly("ply\nformat ascii 1.0\nproperty float x\n", "p.ply"), "p.ply",
                {"line 3", "before any 'element'"});
  ExpectInvalid(ParsePly("ply\nformat ascii 1.0\nfoo bar\n", "k.ply"), "k.ply",
                {"line 3", "'foo'"});
  ExpectInvalid(ParsePly("ply\nelement vertex 0\nend_header\n", "nf.ply"), "nf.ply",
                {"line 3", "format"});
  ExpectInvalid(ParsePly("ply\nformat ascii 1.0\nelement vertex -1\n", "n.ply"), "n.ply",
                {"line 3"});
  ExpectInvalid(
      ParsePly(AsciiHeader("1", "property list uchar float x\n").replace(0, 0, ""), "d.ply"),
      "d.ply", {"line 7", "a second property 'x'"});
}

TEST(PlyMalformedTest, MissingCoordinateOrVertexElement) {
  ExpectInvalid(ParsePly("ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty "
                         "float z\nend_header\n1 2\n",
                         "y.ply"),
                "y.ply", {"line 3", "no property 'y'"});
  ExpectInvalid(
      ParsePly("ply\nformat ascii 1.0\nelement point 1\nproperty float x\nend_header\n1\n",
               "v.ply"),
      "v.ply", {"no element 'vertex'"});
  ExpectInvalid(ParsePly("ply\nformat ascii 1.0\nelement vertex 1\nproperty list uchar float x\n"
                         "property float y\nproperty float z\nend_header\n",
                         "l.ply"),
                "l.ply", {"'x' is a list"});
}

TEST(PlyMalformedTest, FaceElementWithoutUsableIndices) {
  ExpectInvalid(
      ParsePly(AsciiHeader("3", "element face 1\nproperty list uchar int vertices\n"), "f.ply"),
      "f.ply", {"line 7", "vertex_indices"});
  ExpectInvalid(
      ParsePly(AsciiHeader("3", "element face 1\nproperty list uchar float vertex_indices\n"),
               "f.ply"),
      "f.ply", {"line 7", "list of integers"});
  ExpectInvalid(ParsePly(AsciiHeader("3",
                                     "element face 1\nproperty list float int "
                                     "vertex_indices\n"),
                         "f.ply"),
                "f.ply", {"line 8", "count type"});
}

TEST(PlyMalformedTest, ElementWithRecordsButNoProperties) {
  ExpectInvalid(ParsePly(AsciiHeader("0", "element nothing 1000000000\n"), "n.ply"), "n.ply",
                {"line 7", "no properties"});
}

TEST(PlyMalformedTest, HugeDeclaredCountsFailFastWithoutAllocating) {
  const auto start = std::chrono::steady_clock::now();
  ExpectInvalid(ParsePly(BinaryHeader(4'000'000'000) + BinaryVertices(1), "huge.ply"), "huge.ply",
                {"line 3", "4000000000", "limit"});
  ExpectInvalid(ParsePly(BinaryHeader(1'000'000'000) + BinaryVertices(1), "big.ply"), "big.ply",
                {"element 'vertex'", "1000000000 records", "12 bytes remain"});
  ExpectInvalid(ParsePly(AsciiHeader("1000000000") + "1 2 3\n", "big.ply"), "big.ply",
                {"element 'vertex'", "1000000000 records"});
  ExpectInvalid(ParsePly(AsciiHeader("99999999999999999999999"), "overflow.ply"), "overflow.ply",
                {"line 3"});
  EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(1));
}

TEST(PlyMalformedTest, BinaryCountThatLiesUp) {
  ExpectInvalid(ParsePly(BinaryHeader(3) + BinaryVertices(2), "up.ply"), "up.ply",
                {"byte offset", "element 'vertex'", "declares 3 records", "24 bytes remain"});
}

TEST(PlyMalformedTest, BinaryCountThatLiesDown) {
  const std::string header = BinaryHeader(2);
  ExpectInvalid(ParsePly(header + BinaryVertices(3), "down.ply"), "down.ply",
                {absl::StrCat("byte offset ", header.size() + 24), "12 bytes after the last"});
}

TEST(PlyMalformedTest, AsciiCountThatLiesUp) {
  const std::string text = AsciiHeader("3") + "1.000000 2.000000 3.000000\n4.0000 5.0000 6.0000\n";
  ExpectInvalid(ParsePly(text, "up.ply"), "up.ply",
                {"line 10", "element 'vertex' record 2", "property 'x'", "file ends"});
}

TEST(PlyMalformedTest, AsciiCountThatLiesDown) {
  ExpectInvalid(ParsePly(AsciiHeader("1") + "1 2 3\n4 5 6\n", "down.ply"), "down.ply",
                {"line 9", "unexpected '4'", "fewer records"});
}

TEST(PlyMalformedTest, TruncatedInsideAFaceList) {
  std::string bytes =
      "ply\nformat binary_little_endian 1.0\nelement vertex 4\nproperty float x\nproperty float "
      "y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n";
  const size_t data_start = bytes.size();
  bytes += BinaryVertices(4);
  bytes.push_back(4);
  for (int32_t i : {0, 1, 2}) AppendInt32(i, std::endian::little, &bytes);
  ExpectInvalid(ParsePly(bytes, "cut.ply"), "cut.ply",
                {absl::StrCat("byte offset ", data_start + 48 + 1 + 12), "element 'face' record 0",
                 "property 'vertex_indices'", "the file ends"});
}

TEST(PlyMalformedTest, HugeListCountsRunIntoTheEnd) {
  std::string bytes =
      "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float "
      "y\nproperty float z\nelement face 1\nproperty list uint int vertex_indices\n"
      "element junk 1\nproperty list uint double values\nend_header\n";
  bytes += BinaryVertices(3);
  std::string faces = bytes;
  AppendInt32(-1, std::endian::little, &faces);  // 4294967295 indices
  for (int32_t i : {0, 1, 2}) AppendInt32(i, std::endian::little, &faces);
  ExpectInvalid(ParsePly(faces, "faces.ply"), "faces.ply", {"element 'face' record 0", "ends"});

  std::string junk = bytes;
  AppendInt32(3, std::endian::little, &junk);
  for (int32_t i : {0, 1, 2}) AppendInt32(i, std::endian::little, &junk);
  AppendInt32(-1, std::endian::little, &junk);
  ExpectInvalid(ParsePly(junk, "junk.ply"), "junk.ply",
                {"element 'junk' record 0", "property 'values'", "4294967295"});
}

TEST(PlyMalformedTest, NonFiniteCoordinates) {
  ExpectInvalid(ParsePly(AsciiHeader("2") + "1 2 3\n4 nan 6\n", "nan.ply"), "nan.ply",
                {"line 9", "element 'vertex' record 1", "property 'y'", "not a finite"});
  ExpectInvalid(ParsePly(AsciiHeader("1") + "inf 2 3\n", "inf.ply"), "inf.ply",
                {"record 0", "property 'x'"});
  std::string bytes = BinaryHeader(2) + BinaryVertices(1);
  const size_t offset = bytes.size() + 8;
  AppendFloat32(0, std::endian::little, &bytes);
  AppendFloat32(0, std::endian::little, &bytes);
  AppendFloat32(std::numeric_limits<float>::quiet_NaN(), std::endian::little, &bytes);
  ExpectInvalid(ParsePly(bytes, "nan.ply"), "nan.ply",
                {absl::StrCat("byte offset ", offset), "record 1", "property 'z'"});
  std::string doubles =
      "ply\nformat binary_big_endian 1.0\nelement vertex 1\nproperty double x\nproperty double "
      "y\nproperty double z\nend_header\n";
  for (double c : {0.0, 1e300, 0.0}) AppendFloat64(c, std::endian::big, &doubles);
  ExpectInvalid(ParsePly(doubles, "far.ply"), "far.ply", {"property 'y'", "1e+300"});
}

TEST(PlyMalformedTest, BadFaceIndices) {
  const std::string header = AsciiHeader("3",
                                         "element face 1\nproperty list uchar int "
                                         "vertex_indices\n");
  const std::string vertices = "0 0 0\n1 0 0\n0 1 0\n";
  ExpectInvalid(ParsePly(header + vertices + "3 0 1 7\n", "idx.ply"), "idx.ply",
                {"line 13", "element 'face' record 0", "vertex index 7", "3 vertices"});
  ExpectInvalid(ParsePly(header + vertices + "3 0 -1 2\n", "neg.ply"), "neg.ply",
                {"vertex index -1"});
  ExpectInvalid(ParsePly(header + vertices + "2 0 1\n", "two.ply"), "two.ply",
                {"at least 3", "has 2"});
  ExpectInvalid(ParsePly(header + vertices + "-3 0 1 2\n", "cnt.ply"), "cnt.ply",
                {"negative list length"});
  ExpectInvalid(ParsePly(header + vertices + "3 0 1.5 2\n", "f.ply"), "f.ply",
                {"'1.5' is not an integer"});
}

TEST(PlyMalformedTest, GarbageTokensAndBytes) {
  ExpectInvalid(ParsePly(AsciiHeader("1") + "1 two 3\n", "g.ply"), "g.ply",
                {"line 8", "'two' is not a number"});
  std::string garbage = "ply\n";
  std::mt19937 rng(3);
  for (int i = 0; i < 4096; ++i) garbage.push_back(static_cast<char>(rng()));
  absl::StatusOr<PlyContents> parsed = ParsePly(garbage, "garbage.ply");
  ExpectInvalid(parsed, "garbage.ply", {"line 2"});
}

TEST(PlyMalformedTest, MissingFileIsNotFound) {
  ExpectError(ReadPly(testing::TempDir() + "/no_such.ply"), absl::StatusCode::kNotFound,
              {"no_such.ply"});
}

}  // namespace
}  // namespace rpsr::core
