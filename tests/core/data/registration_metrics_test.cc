#include "core/data/registration_metrics.h"

#include <cmath>

#include "gtest/gtest.h"

namespace rpsr::core {
namespace {

TEST(RegistrationMetricsTest, ErrorOfKnownMotion) {
  Eigen::Isometry3d truth = Eigen::Isometry3d::Identity();
  truth.translation() = Eigen::Vector3d(1, 2, 3);
  Eigen::Isometry3d estimate = truth;
  estimate.linear() = Eigen::AngleAxisd(M_PI / 18, Eigen::Vector3d::UnitY()).toRotationMatrix();
  estimate.translation() += Eigen::Vector3d(0, 0.3, 0.4);
  const PairError e = ErrorOf(estimate, truth);
  EXPECT_NEAR(e.rotation_deg, 10.0, 1e-9);
  EXPECT_NEAR(e.translation, 0.5, 1e-12);
}

TEST(RegistrationMetricsTest, SummaryStatisticsAndRecall) {
  const std::vector<PairError> errors = {{0.5, 0.005}, {2.0, 0.02}, {0.8, 0.2}, {10.0, 0.001}};
  const ErrorSummary s = Summarize(errors, ObjectRecallThresholds());
  EXPECT_EQ(s.count, 4);
  EXPECT_NEAR(s.rotation_rmse_deg, std::sqrt((0.25 + 4.0 + 0.64 + 100.0) / 4), 1e-12);
  EXPECT_NEAR(s.rotation_mae_deg, (0.5 + 2.0 + 0.8 + 10.0) / 4, 1e-12);
  EXPECT_NEAR(s.rotation_median_deg, (0.8 + 2.0) / 2, 1e-12);
  EXPECT_NEAR(s.translation_median, (0.005 + 0.02) / 2, 1e-12);
  ASSERT_EQ(s.recall.size(), 2u);
  EXPECT_DOUBLE_EQ(s.recall[0], 0.25);  // only (0.5, 0.005) is within (1 deg, 0.01)
  EXPECT_DOUBLE_EQ(s.recall[1], 0.5);   // and (2.0, 0.02) within (5 deg, 0.05)
  EXPECT_EQ(ObjectRecallThresholds()[0].Name(), "recall@1deg/0.01");
}

TEST(RegistrationMetricsTest, EmptyIsZero) {
  const ErrorSummary s = Summarize({}, LidarRecallThresholds());
  EXPECT_EQ(s.count, 0);
  EXPECT_EQ(s.recall, std::vector<double>{0.0});
}

}  // namespace
}  // namespace rpsr::core
