#include "core/data/kitti_odometry_metrics.h"

#include <cmath>
#include <numbers>
#include <vector>

#include "gtest/gtest.h"

namespace rpsr::core {
namespace {

// A straight drive along x at one metre a frame.
std::vector<Eigen::Isometry3d> StraightLine(int frames, double metres_per_frame = 1.0) {
  std::vector<Eigen::Isometry3d> poses;
  for (int i = 0; i < frames; ++i) {
    Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
    pose.translation() = Eigen::Vector3d(metres_per_frame * i, 0, 0);
    poses.push_back(pose);
  }
  return poses;
}

TEST(KittiOdometryMetricsTest, DistancesAccumulateSteps) {
  const std::vector<double> distances = TrajectoryDistances(StraightLine(4, 2.5));
  ASSERT_EQ(distances.size(), 4u);
  EXPECT_DOUBLE_EQ(distances[0], 0.0);
  EXPECT_DOUBLE_EQ(distances[3], 7.5);
}

TEST(KittiOdometryMetricsTest, PerfectEstimateHasNoErrorAndTheDevkitsSegments) {
  const std::vector<Eigen::Isometry3d> truth = StraightLine(250);
  absl::StatusOr<KittiOdometryMetrics> metrics = ComputeKittiOdometryMetrics(truth, truth);
  ASSERT_TRUE(metrics.ok()) << metrics.status();
  // 249 m: a 100 m segment from frame f ends at f + 101 (the first frame MORE than 100 m on), so
  // f = 0, 10, ..., 140 (15 segments); 200 m: f = 0..40 (5); nothing longer.
  EXPECT_EQ(metrics->segment_count, 20);
  ASSERT_EQ(metrics->per_length.size(), 8u);
  EXPECT_EQ(metrics->per_length[0].segment_count, 15);
  EXPECT_EQ(metrics->per_length[1].segment_count, 5);
  EXPECT_EQ(metrics->per_length[2].segment_count, 0);
  EXPECT_EQ(metrics->segments.front().last_frame, 101);
  EXPECT_NEAR(metrics->translation_error_percent, 0.0, 1e-12);
  EXPECT_NEAR(metrics->rotation_error_deg_per_m, 0.0, 1e-12);
  EXPECT_DOUBLE_EQ(metrics->path_length_m, 249.0);
}

TEST(KittiOdometryMetricsTest, ScaleDriftIsTranslationErrorOverTheNominalLength) {
  const std::vector<Eigen::Isometry3d> truth = StraightLine(250);
  const std::vector<Eigen::Isometry3d> estimate = StraightLine(250, 1.01);
  absl::StatusOr<KittiOdometryMetrics> metrics = ComputeKittiOdometryMetrics(estimate, truth);
  ASSERT_TRUE(metrics.ok()) << metrics.status();
  // A 100 m segment spans 101 m, 1% of which is missed: 1.01 m over the nominal 100 m. A 200 m
  // segment spans 201 m: 2.01 m over 200 m.
  EXPECT_NEAR(metrics->per_length[0].translation_error_percent, 1.01, 1e-9);
  EXPECT_NEAR(metrics->per_length[1].translation_error_percent, 1.005, 1e-9);
  EXPECT_NEAR(metrics->translation_error_percent, (15 * 1.01 + 5 * 1.005) / 20, 1e-9);
  EXPECT_NEAR(metrics->rotation_error_deg_per_m, 0.0, 1e-12);
}

TEST(KittiOdometryMetricsTest, HeadingDriftIsRotationErrorPerMetre) {
  const std::vector<Eigen::Isometry3d> truth = StraightLine(150);
  std::vector<Eigen::Isometry3d> estimate = truth;
  const double drift_rad_per_frame = 1e-4;
  for (size_t i = 0; i < estimate.size(); ++i) {
    estimate[i].linear() =
        Eigen::AngleAxisd(drift_rad_per_frame * i, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  }
  absl::StatusOr<KittiOdometryMetrics> metrics = ComputeKittiOdometryMetrics(estimate, truth);
  ASSERT_TRUE(metrics.ok()) << metrics.status();
  ASSERT_EQ(metrics->segment_count, 5);  // f = 0..40 for 100 m
  EXPECT_NEAR(metrics->rotation_error_deg_per_m,
              101 * drift_rad_per_frame / 100 * 180 / std::numbers::pi, 1e-9);
  // From frame 0 the positions agree exactly.
  EXPECT_NEAR(metrics->segments.front().translation_error_per_m, 0.0, 1e-12);
  EXPECT_GT(metrics->segments.back().translation_error_per_m, 0.0);
}

TEST(KittiOdometryMetricsTest, ShortTrajectoryHasNoSegments) {
  absl::StatusOr<KittiOdometryMetrics> metrics =
      ComputeKittiOdometryMetrics(StraightLine(50), StraightLine(50));
  ASSERT_TRUE(metrics.ok());
  EXPECT_EQ(metrics->segment_count, 0);
  EXPECT_EQ(metrics->translation_error_percent, 0.0);
  KittiOdometryMetricsOptions short_segments;
  short_segments.segment_lengths_m = {10, 20};
  short_segments.step_frames = 1;
  metrics = ComputeKittiOdometryMetrics(StraightLine(50), StraightLine(50), short_segments);
  ASSERT_TRUE(metrics.ok());
  EXPECT_EQ(metrics->segment_count, (49 - 11 + 1) + (49 - 21 + 1));
}

TEST(KittiOdometryMetricsTest, RejectsBadInput) {
  EXPECT_EQ(ComputeKittiOdometryMetrics(StraightLine(3), StraightLine(4)).status().code(),
            absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(ComputeKittiOdometryMetrics({}, {}).status().code(),
            absl::StatusCode::kInvalidArgument);
  std::vector<Eigen::Isometry3d> bad = StraightLine(3);
  bad[1].translation().x() = std::nan("");
  absl::StatusOr<KittiOdometryMetrics> metrics = ComputeKittiOdometryMetrics(bad, StraightLine(3));
  EXPECT_EQ(metrics.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(metrics.status().message().find("frame 1"), std::string::npos);
  KittiOdometryMetricsOptions zero_step;
  zero_step.step_frames = 0;
  EXPECT_FALSE(ComputeKittiOdometryMetrics(StraightLine(3), StraightLine(3), zero_step).ok());
}

}  // namespace
}  // namespace rpsr::core
