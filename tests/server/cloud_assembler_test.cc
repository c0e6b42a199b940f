#include "server/cloud_assembler.h"

#include <cmath>

#include "gmock/gmock.h"
#include "gtest/gtest.h"

namespace rpsr::server {
namespace {

using ::testing::HasSubstr;

std::vector<Eigen::Vector3f> Points(int n) {
  std::vector<Eigen::Vector3f> points;
  for (int i = 0; i < n; ++i) points.emplace_back(i, -0.5f * i, 1e-3f * i);
  return points;
}

std::string Slice(const std::vector<Eigen::Vector3f>& points, int begin, int end) {
  return EncodeXyz(std::vector<Eigen::Vector3f>(points.begin() + begin, points.begin() + end));
}

TEST(CloudAssemblerTest, AssemblesChunksInOrderBitExactly) {
  const auto points = Points(10);
  CloudAssembler assembler("upload", 100);
  ASSERT_TRUE(assembler.Begin(10).ok());
  ASSERT_TRUE(assembler.AddChunk(0, "").ok());  // an empty first chunk is allowed
  ASSERT_TRUE(assembler.AddChunk(1, Slice(points, 0, 4)).ok());
  EXPECT_FALSE(assembler.complete());
  EXPECT_THAT(assembler.CheckComplete().message(),
              HasSubstr("ended after 2 chunks with 4 of 10 declared points"));
  ASSERT_TRUE(assembler.AddChunk(2, Slice(points, 4, 10)).ok());
  ASSERT_TRUE(assembler.complete());
  EXPECT_TRUE(assembler.CheckComplete().ok());
  EXPECT_EQ(assembler.TakePoints(), points);
}

TEST(CloudAssemblerTest, WireFormatIsLittleEndianFloat32) {
  const std::string bytes = EncodeXyz({Eigen::Vector3f(1.0f, -2.0f, 0.5f)});
  ASSERT_EQ(bytes.size(), 12u);
  EXPECT_EQ(bytes.substr(0, 4), std::string("\x00\x00\x80\x3f", 4));  // 1.0f
  EXPECT_EQ(bytes.substr(4, 4), std::string("\x00\x00\x00\xc0", 4));  // -2.0f
}

TEST(CloudAssemblerTest, RefusesBadSequencesCountsAndValues) {
  const auto points = Points(10);
  {
    CloudAssembler a("upload", 100);
    ASSERT_TRUE(a.Begin(10).ok());
    EXPECT_THAT(a.AddChunk(1, "").message(), HasSubstr("chunk 1 arrived where chunk 0"));
  }
  {
    CloudAssembler a("frame 3", 100);
    ASSERT_TRUE(a.Begin(10).ok());
    ASSERT_TRUE(a.AddChunk(0, Slice(points, 0, 2)).ok());
    EXPECT_THAT(a.AddChunk(0, Slice(points, 0, 2)).message(),
                HasSubstr("frame 3: chunk 0 arrived twice"));
    EXPECT_THAT(a.AddChunk(1, Slice(points, 0, 9)).message(),
                HasSubstr("brings the cloud to 11 points, more than the 10 declared"));
    EXPECT_THAT(a.AddChunk(1, "12345").message(), HasSubstr("not a whole number of points"));
    auto bad = points;
    bad[3].z() = std::nanf("");
    EXPECT_THAT(a.AddChunk(1, Slice(bad, 0, 5)).message(), HasSubstr("point 5 has a non-finite"));
  }
  CloudAssembler a("upload", 100);
  EXPECT_EQ(a.Begin(0).code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(a.Begin(101).code(), absl::StatusCode::kResourceExhausted);
}

TEST(CloudAssemblerTest, BuildsTheTreeTheCacheKeeps) {
  auto tree = BuildCloudTree(Points(300), 7, 1000);
  ASSERT_TRUE(tree.ok());
  EXPECT_EQ((*tree)->max_depth(), 7);
  EXPECT_EQ((*tree)->neighbor_max_depth(), 5);
  EXPECT_EQ((*tree)->num_points(), 300u);
  EXPECT_EQ(BuildCloudTree(Points(300), 7, 100).status().code(),
            absl::StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace rpsr::server
