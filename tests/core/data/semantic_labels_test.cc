#include "core/data/semantic_labels.h"

#include "core/synth/street_scene.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"

namespace rpsr::core {
namespace {

using ::testing::HasSubstr;

TEST(SemanticLabelsTest, GroundClassesAreTheFlatOnes) {
  namespace sk = semantic_kitti;
  for (uint16_t c :
       {sk::kRoad, sk::kParking, sk::kSidewalk, sk::kOtherGround, sk::kLaneMarking, sk::kTerrain}) {
    EXPECT_TRUE(IsGroundClass(c)) << c;
  }
  for (uint16_t c : {sk::kUnlabeled, sk::kCar, sk::kBuilding, sk::kFence, sk::kVegetation,
                     sk::kTrunk, sk::kPole, sk::kTrafficSign, sk::kOtherObject, uint16_t{252}}) {
    EXPECT_FALSE(IsGroundClass(c)) << c;
  }
}

TEST(SemanticLabelsTest, ClassIsTheLowerSixteenBits) {
  const uint32_t label = MakeSemanticKittiLabel(semantic_kitti::kRoad, 77);
  EXPECT_EQ(label, (77u << 16) | 40u);
  EXPECT_EQ(SemanticClassOf(label), 40);
  EXPECT_EQ(InstanceIdOf(label), 77);
}

TEST(SemanticLabelsTest, ParsesLittleEndianWordsAndRejectsTruncation) {
  const std::string bytes("\x28\x00\x05\x00\x0a\x00\x00\x00", 8);
  absl::StatusOr<std::vector<uint32_t>> labels = ParseSemanticKittiLabels(bytes, "a.label");
  ASSERT_TRUE(labels.ok());
  EXPECT_EQ(*labels, (std::vector<uint32_t>{(5u << 16) | 40u, 10u}));
  absl::Status status = ParseSemanticKittiLabels(bytes.substr(0, 7), "a.label").status();
  EXPECT_EQ(status.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(status.message(), HasSubstr("a.label: 7 bytes"));
  EXPECT_EQ(ReadSemanticKittiLabels("/nonexistent/x.label").status().code(),
            absl::StatusCode::kNotFound);
}

TEST(SemanticLabelsTest, RemoveGroundPointsKeepsObjectsWithIntensities) {
  PointCloud cloud;
  cloud.points = {{0, 0, 0}, {1, 0, 0}, {2, 0, 0}, {3, 0, 0}};
  cloud.intensities = {0.1f, 0.2f, 0.3f, 0.4f};
  const std::vector<uint32_t> labels = {MakeSemanticKittiLabel(40, 3), 10, 72, 50};
  absl::StatusOr<PointCloud> kept = RemoveGroundPoints(cloud, labels, "x.label");
  ASSERT_TRUE(kept.ok());
  EXPECT_EQ(kept->points, (std::vector<Eigen::Vector3f>{{1, 0, 0}, {3, 0, 0}}));
  EXPECT_EQ(kept->intensities, (std::vector<float>{0.2f, 0.4f}));
  EXPECT_THAT(RemoveGroundPoints(cloud, {40}, "x.label").status().message(),
              HasSubstr("x.label: 1 labels for a scan of 4 points"));
}

}  // namespace
}  // namespace rpsr::core
