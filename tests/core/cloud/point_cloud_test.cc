#include "core/cloud/point_cloud.h"

#include <cmath>
#include <limits>

#include "gmock/gmock.h"
#include "gtest/gtest.h"

namespace rpsr::core {
namespace {

using ::testing::HasSubstr;

TEST(ValidatePointCloudTest, AcceptsFiniteCloud) {
  PointCloud cloud;
  cloud.points = {{0, 0, 0}, {1, 2, 3}};
  EXPECT_TRUE(ValidatePointCloud(cloud).ok());
}

TEST(ValidatePointCloudTest, NamesFirstNonFinitePoint) {
  PointCloud cloud;
  cloud.points = {{0, 0, 0},
                  {1, std::numeric_limits<float>::quiet_NaN(), 3},
                  {std::numeric_limits<float>::infinity(), 0, 0}};
  absl::Status status = ValidatePointCloud(cloud);
  EXPECT_EQ(status.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(status.message(), HasSubstr("point 1 "));
}

TEST(ValidatePointCloudTest, RejectsMismatchedIntensities) {
  PointCloud cloud;
  cloud.points = {{0, 0, 0}, {1, 2, 3}};
  cloud.intensities = {0.5f};
  EXPECT_THAT(ValidatePointCloud(cloud).message(), HasSubstr("1 intensities"));
}

TEST(BoundsOfTest, EmptyAndNonEmpty) {
  EXPECT_TRUE(BoundsOf({}).isEmpty());
  Eigen::AlignedBox3f box = BoundsOf({{1, -2, 3}, {-1, 4, 0}});
  EXPECT_EQ(box.min(), Eigen::Vector3f(-1, -2, 0));
  EXPECT_EQ(box.max(), Eigen::Vector3f(1, 4, 3));
}

TEST(TransformedCloudTest, AppliesRotationThenTranslation) {
  PointCloud cloud;
  cloud.points = {{1, 0, 0}};
  cloud.intensities = {7.0f};
  Eigen::Isometry3f T = Eigen::Isometry3f::Identity();
  T.linear() = Eigen::AngleAxisf(M_PI / 2, Eigen::Vector3f::UnitZ()).toRotationMatrix();
  T.translation() = Eigen::Vector3f(0, 0, 5);
  PointCloud moved = TransformedCloud(cloud, T);
  EXPECT_TRUE(moved.points[0].isApprox(Eigen::Vector3f(0, 1, 5), 1e-6f));
  EXPECT_EQ(moved.intensities, cloud.intensities);
}

}  // namespace
}  // namespace rpsr::core
