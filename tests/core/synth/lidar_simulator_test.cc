#include "core/synth/lidar_simulator.h"

#include <cmath>

#include "gmock/gmock.h"
#include "gtest/gtest.h"

namespace rpsr::core {
namespace {

using ::testing::HasSubstr;

constexpr double kSensorHeight = 1.73;

Eigen::Isometry3d SensorAt(double x, double y, double z) {
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.translation() = Eigen::Vector3d(x, y, z);
  return pose;
}

// Only a flat ground at z = 0.
StreetScene FlatGroundScene() {
  StreetScene scene;
  scene.ground.default_label = semantic_kitti::kRoad;
  return scene;
}

LidarSimulator MakeSimulator(const StreetScene& scene, const LidarSensorOptions& options = {}) {
  absl::StatusOr<LidarSimulator> simulator = LidarSimulator::Create(scene, options);
  EXPECT_TRUE(simulator.ok()) << simulator.status();
  return *std::move(simulator);
}

TEST(LidarSimulatorTest, FlatGroundLiesAtMinusSensorHeight) {
  const LidarSimulator simulator = MakeSimulator(FlatGroundScene());
  const LidarScan scan = simulator.SimulateScan(SensorAt(3, -2, kSensorHeight), 11);
  ASSERT_GT(scan.cloud.size(), 100000u);
  ASSERT_EQ(scan.labels.size(), scan.cloud.size());
  ASSERT_EQ(scan.beam_indices.size(), scan.cloud.size());
  ASSERT_EQ(scan.cloud.intensities.size(), scan.cloud.size());
  // Range noise 0.02 m moves z by at most 0.02 * sin(24.8 deg) per sigma.
  for (size_t i = 0; i < scan.cloud.size(); ++i) {
    ASSERT_NEAR(scan.cloud.points[i].z(), -kSensorHeight, 0.05) << "point " << i;
    ASSERT_EQ(scan.labels[i], semantic_kitti::kRoad);
    ASSERT_GE(scan.cloud.intensities[i], 0.0f);
    ASSERT_LE(scan.cloud.intensities[i], 1.0f);
  }
  // Every beam that reaches the ground within 120 m returns, less ~3% dropouts: beams from
  // -atan(1.73 / 120) = -0.83 degrees down, i.e. beams 7..63 of 64 (0.425 degrees apart).
  const double expected = 57 * 2000 * 0.97;
  EXPECT_NEAR(static_cast<double>(scan.cloud.size()), expected, 0.01 * expected);
}

TEST(LidarSimulatorTest, LowestBeamRingHasAnalyticRadius) {
  const LidarSimulator simulator = MakeSimulator(FlatGroundScene());
  const LidarScan scan = simulator.SimulateScan(SensorAt(0, 0, kSensorHeight), 5);
  const double expected_radius = kSensorHeight / std::tan(24.8 * M_PI / 180.0);  // 3.744 m
  double sum = 0.0;
  int count = 0;
  for (size_t i = 0; i < scan.cloud.size(); ++i) {
    if (scan.beam_indices[i] != 63) continue;
    const double radius = scan.cloud.points[i].head<2>().norm();
    ASSERT_NEAR(radius, expected_radius, 0.1) << "point " << i;
    sum += radius;
    ++count;
  }
  ASSERT_GT(count, 1800);
  EXPECT_NEAR(sum / count, expected_radius, 0.005);
  EXPECT_NEAR(simulator.BeamElevationRad(63), -24.8 * M_PI / 180.0, 1e-12);
  EXPECT_NEAR(simulator.BeamElevationRad(0), 2.0 * M_PI / 180.0, 1e-12);
}

TEST(LidarSimulatorTest, WallPointsLieAtTheWallsDistance) {
  constexpr float kWallDistance = 12.0f;
  StreetScene scene = FlatGroundScene();
  SceneBox wall;
  wall.center = Eigen::Vector3f(kWallDistance + 0.25f, 0.0f, 5.0f);
  wall.half_extents = Eigen::Vector3f(0.25f, 30.0f, 6.0f);
  wall.label = semantic_kitti::kBuilding;
  scene.boxes.push_back(wall);
  const LidarSimulator simulator = MakeSimulator(scene);
  const LidarScan scan = simulator.SimulateScan(SensorAt(0, 0, kSensorHeight), 3);
  int wall_points = 0;
  for (size_t i = 0; i < scan.cloud.size(); ++i) {
    const Eigen::Vector3f& p = scan.cloud.points[i];
    if (scan.labels[i] == semantic_kitti::kBuilding) {
      ++wall_points;
      ASSERT_NEAR(p.x(), kWallDistance, 0.1) << "point " << i;
      ASSERT_LE(std::abs(p.y()), 30.0f + 0.1f);
    } else {
      // Nothing is seen through the wall: rays beyond it pass its ends (|y| = 30 at x = 12).
      if (p.x() > kWallDistance + 0.1f) {
        ASSERT_GT(std::abs(p.y()) * kWallDistance / p.x(), 30.0f - 0.1f) << "point " << i;
      }
      ASSERT_NEAR(p.z(), -kSensorHeight, 0.05);
    }
  }
  // The wall spans about 2 * atan(30 / 12) = 136 degrees of azimuth (~750 columns) and the ~25
  // beams above -atan(1.73 / 12) = -8.2 degrees (fewer towards its ends).
  EXPECT_GT(wall_points, 12000);
}

TEST(LidarSimulatorTest, CastRayMeetsEachPrimitiveAnalytically) {
  StreetScene scene = FlatGroundScene();
  SceneCylinder pole;
  pole.center = Eigen::Vector2f(10, 0);
  pole.radius_m = 0.5f;
  pole.z_max_m = 8.0f;
  scene.cylinders.push_back(pole);
  SceneEllipsoid crown;
  crown.center = Eigen::Vector3f(0, 20, 2);
  crown.radii = Eigen::Vector3f(1, 3, 2);
  scene.ellipsoids.push_back(crown);
  SceneBox box;
  box.center = Eigen::Vector3f(-15, 0, 1);
  box.half_extents = Eigen::Vector3f(2, 1, 1);
  box.yaw_rad = static_cast<float>(M_PI / 2);  // turned: the long side runs along y
  scene.boxes.push_back(box);
  const LidarSimulator simulator = MakeSimulator(scene);
  const Eigen::Vector3f origin(0, 0, 2);

  auto pole_hit = simulator.CastRay(origin, Eigen::Vector3f::UnitX(), 100.0f);
  ASSERT_TRUE(pole_hit.has_value());
  EXPECT_NEAR(pole_hit->distance_m, 9.5f, 1e-4f);
  EXPECT_EQ(pole_hit->label, semantic_kitti::kPole);
  EXPECT_TRUE(pole_hit->normal.isApprox(-Eigen::Vector3f::UnitX(), 1e-4f));

  auto crown_hit = simulator.CastRay(origin, Eigen::Vector3f::UnitY(), 100.0f);
  ASSERT_TRUE(crown_hit.has_value());
  EXPECT_NEAR(crown_hit->distance_m, 17.0f, 1e-4f);
  EXPECT_EQ(crown_hit->label, semantic_kitti::kVegetation);

  // The turned box spans x in [-16, -14].
  auto box_hit = simulator.CastRay(Eigen::Vector3f(0, 0, 1), -Eigen::Vector3f::UnitX(), 100.0f);
  ASSERT_TRUE(box_hit.has_value());
  EXPECT_NEAR(box_hit->distance_m, 14.0f, 1e-4f);

  auto ground_hit = simulator.CastRay(origin, -Eigen::Vector3f::UnitZ(), 100.0f);
  ASSERT_TRUE(ground_hit.has_value());
  EXPECT_NEAR(ground_hit->distance_m, 2.0f, 1e-5f);
  EXPECT_TRUE(ground_hit->normal.isApprox(Eigen::Vector3f::UnitZ(), 1e-6f));

  EXPECT_FALSE(simulator.CastRay(origin, Eigen::Vector3f(0, -1, 0), 100.0f).has_value());
  EXPECT_FALSE(simulator.CastRay(origin, Eigen::Vector3f::UnitX(), 9.0f).has_value());
}

TEST(LidarSimulatorTest, BumpyGroundHitsLieOnTheSurface) {
  StreetScene scene = FlatGroundScene();
  scene.ground.bump_amplitude_m = 0.15f;
  scene.ground.bump_wavelength_m = 30.0f;
  scene.ground.bump_phase_x = 0.4f;
  const LidarSimulator simulator = MakeSimulator(scene);
  const Eigen::Vector3f origin(1, 2, 1.8f);
  for (int k = 0; k < 64; ++k) {
    const double azimuth = 2 * M_PI * k / 64, elevation = -0.03 - 0.4 * k / 64;
    const Eigen::Vector3f direction(std::cos(elevation) * std::cos(azimuth),
                                    std::cos(elevation) * std::sin(azimuth), std::sin(elevation));
    auto hit = simulator.CastRay(origin, direction, 200.0f);
    ASSERT_TRUE(hit.has_value());
    const Eigen::Vector3f p = origin + hit->distance_m * direction;
    EXPECT_NEAR(p.z(), scene.ground.HeightAt(p.x(), p.y()), 2e-3f) << "ray " << k;
  }
}

TEST(LidarSimulatorTest, ScansAreDeterministicPerSeed) {
  StreetSceneOptions options;
  options.road_length_m = 300;
  absl::StatusOr<StreetScene> scene = GenerateStreetScene(options);
  ASSERT_TRUE(scene.ok()) << scene.status();
  const LidarSimulator simulator = MakeSimulator(*scene);
  const Eigen::Isometry3d pose = SensorAt(100, -1.75, kSensorHeight);
  const LidarScan a = simulator.SimulateScan(pose, 42);
  const LidarScan b = simulator.SimulateScan(pose, 42);
  const LidarScan c = simulator.SimulateScan(pose, 43);
  EXPECT_EQ(a.cloud.points, b.cloud.points);
  EXPECT_EQ(a.cloud.intensities, b.cloud.intensities);
  EXPECT_EQ(a.labels, b.labels);
  EXPECT_NE(a.cloud.points, c.cloud.points);
}

TEST(LidarSimulatorTest, NoNoiseNoDropoutGivesExactRanges) {
  LidarSensorOptions options;
  options.range_noise_sigma_m = 0.0;
  options.dropout_probability = 0.0;
  const LidarSimulator simulator = MakeSimulator(FlatGroundScene(), options);
  const LidarScan scan = simulator.SimulateScan(SensorAt(0, 0, kSensorHeight), 1);
  EXPECT_EQ(scan.cloud.size(), 57u * 2000u);
  for (const Eigen::Vector3f& p : scan.cloud.points) ASSERT_NEAR(p.z(), -kSensorHeight, 1e-4f);
}

TEST(LidarSimulatorTest, RejectsBadOptionsAndPrimitives) {
  LidarSensorOptions options;
  options.beam_count = 0;
  EXPECT_THAT(LidarSimulator::Create(FlatGroundScene(), options).status().message(),
              HasSubstr("beam_count"));
  options = {};
  options.min_range_m = 200;
  EXPECT_EQ(LidarSimulator::Create(FlatGroundScene(), options).status().code(),
            absl::StatusCode::kInvalidArgument);
  options = {};
  options.dropout_probability = 1.0;
  EXPECT_EQ(LidarSimulator::Create(FlatGroundScene(), options).status().code(),
            absl::StatusCode::kInvalidArgument);
  StreetScene scene = FlatGroundScene();
  scene.cylinders.push_back(SceneCylinder{});
  scene.cylinders.back().radius_m = -1;
  EXPECT_THAT(LidarSimulator::Create(scene).status().message(), HasSubstr("cylinder 0"));
}

}  // namespace
}  // namespace rpsr::core
