#include "core/synth/street_scene.h"

#include <cmath>

#include "gmock/gmock.h"
#include "gtest/gtest.h"

namespace rpsr::core {
namespace {

class StreetSceneStyleTest : public ::testing::TestWithParam<StreetStyle> {};

float CenterlineLength(const StreetScene& scene) {
  float length = 0.0f;
  for (size_t i = 1; i < scene.road_centerline.size(); ++i) {
    length += (scene.road_centerline[i] - scene.road_centerline[i - 1]).norm();
  }
  return length;
}

TEST_P(StreetSceneStyleTest, BuildsARoadWithObjectsAndKeepsTheLaneClear) {
  StreetSceneOptions options;
  options.style = GetParam();
  options.road_length_m = 500;
  options.seed = 3;
  absl::StatusOr<StreetScene> scene = GenerateStreetScene(options);
  ASSERT_TRUE(scene.ok()) << scene.status();
  EXPECT_GE(CenterlineLength(*scene), 500.0f);
  EXPECT_LT(CenterlineLength(*scene), 502.0f);
  EXPECT_GT(scene->boxes.size() + scene->cylinders.size() + scene->ellipsoids.size(), 50u);
  EXPECT_FALSE(scene->ground_zones.empty());
  EXPECT_GT(scene->drive_lane_offset_m, 0.0f);

  // A vehicle 2 m wide and 2 m tall driving the right lane hits nothing.
  const std::vector<Eigen::Vector2f>& line = scene->road_centerline;
  for (size_t i = 1; i < line.size(); ++i) {
    const Eigen::Vector2f tangent = (line[i] - line[i - 1]).normalized();
    const Eigen::Vector2f right(tangent.y(), -tangent.x());
    const Eigen::Vector2f car = line[i] + scene->drive_lane_offset_m * right;
    for (const SceneBox& box : scene->boxes) {
      if (box.center.z() - box.half_extents.z() > 2.0f) continue;
      const float c = std::cos(box.yaw_rad), s = std::sin(box.yaw_rad);
      const Eigen::Vector2f d = car - box.center.head<2>();
      const float u = std::abs(c * d.x() + s * d.y()), v = std::abs(-s * d.x() + c * d.y());
      ASSERT_FALSE(u < box.half_extents.x() + 1.0f && v < box.half_extents.y() + 1.0f)
          << StreetStyleName(GetParam()) << ": box at " << box.center.transpose()
          << " blocks the lane at centre-line point " << i;
    }
    for (const SceneCylinder& cylinder : scene->cylinders) {
      ASSERT_GT((car - cylinder.center).norm(), cylinder.radius_m + 1.0f)
          << StreetStyleName(GetParam()) << ": cylinder blocks the lane at point " << i;
    }
  }
}

TEST_P(StreetSceneStyleTest, IsDeterministicPerSeed) {
  StreetSceneOptions options;
  options.style = GetParam();
  options.road_length_m = 300;
  const StreetScene a = *GenerateStreetScene(options);
  const StreetScene b = *GenerateStreetScene(options);
  options.seed = 2;
  const StreetScene c = *GenerateStreetScene(options);
  ASSERT_EQ(a.boxes.size(), b.boxes.size());
  for (size_t i = 0; i < a.boxes.size(); ++i) {
    EXPECT_EQ(a.boxes[i].center, b.boxes[i].center);
    EXPECT_EQ(a.boxes[i].half_extents, b.boxes[i].half_extents);
  }
  EXPECT_EQ(a.road_centerline, b.road_centerline);
  EXPECT_NE(a.road_centerline, c.road_centerline);
}

INSTANTIATE_TEST_SUITE_P(AllStyles, StreetSceneStyleTest,
                         ::testing::Values(StreetStyle::kUrbanCanyon, StreetStyle::kSuburban,
                                           StreetStyle::kOpenRoad, StreetStyle::kParkingLot),
                         [](const ::testing::TestParamInfo<StreetStyle>& info) {
                           return std::string(StreetStyleName(info.param));
                         });

TEST(StreetSceneTest, GroundHeightAndGradientAgree) {
  GroundSurface ground;
  ground.bump_amplitude_m = 0.2f;
  ground.bump_wavelength_m = 25.0f;
  ground.bump_phase_y = 1.0f;
  const float x = 3.3f, y = -7.1f, h = 1e-2f;
  const Eigen::Vector2f gradient = ground.GradientAt(x, y);
  EXPECT_NEAR(gradient.x(), (ground.HeightAt(x + h, y) - ground.HeightAt(x - h, y)) / (2 * h),
              1e-3f);
  EXPECT_NEAR(gradient.y(), (ground.HeightAt(x, y + h) - ground.HeightAt(x, y - h)) / (2 * h),
              1e-3f);
}

TEST(StreetSceneTest, RejectsBadLength) {
  StreetSceneOptions options;
  options.road_length_m = 0;
  EXPECT_EQ(GenerateStreetScene(options).status().code(), absl::StatusCode::kInvalidArgument);
  options.road_length_m = 1e6f;
  EXPECT_EQ(GenerateStreetScene(options).status().code(), absl::StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace rpsr::core
