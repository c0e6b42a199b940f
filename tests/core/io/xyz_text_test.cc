#include "core/io/xyz_text.h"

#include <limits>
#include <string>

#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/core/io/status_expectations.h"

namespace rpsr::core {
namespace {

PointCloud SmallCloud() {
  PointCloud cloud;
  cloud.points = {{0.1f, -2.5f, 3e7f}, {-1e-20f, 0, 42}, {1, 2, 3}};
  return cloud;
}

TEST(XyzTextTest, RoundTripsBothDelimitersThroughFiles) {
  for (XyzTextDelimiter delimiter : {XyzTextDelimiter::kWhitespace, XyzTextDelimiter::kComma}) {
    const std::string path = testing::TempDir() + "/round_trip.xyz";
    ASSERT_TRUE(WriteXyzText(path, SmallCloud(), delimiter).ok());
    absl::StatusOr<PointCloud> read = ReadXyzText(path, delimiter);
    ASSERT_TRUE(read.ok()) << read.status();
    EXPECT_EQ(read->points, SmallCloud().points);
  }
}

TEST(XyzTextTest, WhitespaceWithTabsCommentsBlankLinesAndExtraColumns) {
  const std::string text =
      "# x y z r g b\r\n"
      "1\t2 3 255 0 0\r\n"
      "\r\n"
      "   -4.5   +5e2\t6\n"
      "7 8 9 0.5";
  absl::StatusOr<PointCloud> parsed = ParseXyzText(text, "a.xyz", XyzTextDelimiter::kWhitespace);
  ASSERT_TRUE(parsed.ok()) << parsed.status();
  EXPECT_EQ(parsed->points, (std::vector<Eigen::Vector3f>{{1, 2, 3}, {-4.5f, 500, 6}, {7, 8, 9}}));
  EXPECT_TRUE(parsed->intensities.empty());
}

TEST(XyzTextTest, CsvWithAndWithoutHeader) {
  absl::StatusOr<PointCloud> with_header =
      ParseXyzText("X, Y, Z, intensity\n1, 2, 3, 9\n 4 ,5,6,\n", "h.csv", XyzTextDelimiter::kComma);
  ASSERT_TRUE(with_header.ok()) << with_header.status();
  EXPECT_EQ(with_header->points, (std::vector<Eigen::Vector3f>{{1, 2, 3}, {4, 5, 6}}));
  absl::StatusOr<PointCloud> without =
      ParseXyzText("1,2,3\n4,5,6\n", "n.csv", XyzTextDelimiter::kComma);
  ASSERT_TRUE(without.ok()) << without.status();
  EXPECT_EQ(without->size(), 2u);
  absl::StatusOr<PointCloud> header_only =
      ParseXyzText("x,y,z\n", "o.csv", XyzTextDelimiter::kComma);
  ASSERT_TRUE(header_only.ok());
  EXPECT_TRUE(header_only->empty());
}

TEST(XyzTextTest, EmptyTextIsAnEmptyCloud) {
  absl::StatusOr<PointCloud> parsed = ParseXyzText("", "e.xyz", XyzTextDelimiter::kWhitespace);
  ASSERT_TRUE(parsed.ok());
  EXPECT_TRUE(parsed->empty());
}

TEST(XyzTextMalformedTest, ErrorsNameTheLineAndColumn) {
  ExpectInvalid(ParseXyzText("1 2 3\n4 5\n", "c.xyz", XyzTextDelimiter::kWhitespace), "c.xyz",
                {"line 2", "2 columns"});
  ExpectInvalid(ParseXyzText("1 2 3\n4 five 6\n", "n.xyz", XyzTextDelimiter::kWhitespace), "n.xyz",
                {"line 2, column 2", "'five' is not a number"});
  ExpectInvalid(ParseXyzText("1 2 3\n\n4 5 NaN\n", "nan.txt", XyzTextDelimiter::kWhitespace),
                "nan.txt", {"line 3, column 3", "not a finite"});
  ExpectInvalid(ParseXyzText("1e39 0 0\n", "big.txt", XyzTextDelimiter::kWhitespace), "big.txt",
                {"line 1, column 1", "not a finite float"});
  ExpectInvalid(ParseXyzText("x y z\n1 2 3\n", "h.xyz", XyzTextDelimiter::kWhitespace), "h.xyz",
                {"line 1, column 1", "'x'"});
  ExpectInvalid(ParseXyzText("x,y,z\n1,2,3\na,b,c\n", "h.csv", XyzTextDelimiter::kComma), "h.csv",
                {"line 3, column 1"});
  ExpectInvalid(ParseXyzText("1,,3\n", "e.csv", XyzTextDelimiter::kComma), "e.csv",
                {"line 1, column 2", "'' is not a number"});
  ExpectInvalid(
      ParseXyzText("1 2 3\n\x01\xff\xfe garbage\n", "g.xyz", XyzTextDelimiter::kWhitespace),
      "g.xyz", {"line 2"});
}

TEST(XyzTextMalformedTest, WriterRejectsNonFinitePoints) {
  PointCloud cloud = SmallCloud();
  cloud.points[2].z() = std::numeric_limits<float>::infinity();
  ExpectInvalid(WriteXyzText(testing::TempDir() + "/inf.xyz", cloud, XyzTextDelimiter::kWhitespace),
                testing::TempDir() + "/inf.xyz", {"point 2"});
}

}  // namespace
}  // namespace rpsr::core
