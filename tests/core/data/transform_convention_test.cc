#include "core/data/transform_convention.h"

#include <cmath>
#include <limits>

#include "gtest/gtest.h"

namespace rpsr::core {
namespace {

constexpr double kDegree = M_PI / 180.0;

Eigen::Matrix3d Rx(double a) {
  Eigen::Matrix3d r;
  r << 1, 0, 0, 0, std::cos(a), -std::sin(a), 0, std::sin(a), std::cos(a);
  return r;
}
Eigen::Matrix3d Ry(double a) {
  Eigen::Matrix3d r;
  r << std::cos(a), 0, std::sin(a), 0, 1, 0, -std::sin(a), 0, std::cos(a);
  return r;
}
Eigen::Matrix3d Rz(double a) {
  Eigen::Matrix3d r;
  r << std::cos(a), -std::sin(a), 0, std::sin(a), std::cos(a), 0, 0, 0, 1;
  return r;
}

TEST(TransformConventionTest, EulerOrderIsRzRyRx) {
  const Eigen::Vector3d angles(10 * kDegree, 20 * kDegree, 30 * kDegree);
  const Eigen::Matrix3d expected = Rz(angles.z()) * Ry(angles.y()) * Rx(angles.x());
  EXPECT_TRUE(RotationFromEulerXyz(angles).isApprox(expected, 1e-12));
  // Not the other order: the convention is a real choice.
  EXPECT_FALSE(RotationFromEulerXyz(angles).isApprox(
      Rx(angles.x()) * Ry(angles.y()) * Rz(angles.z()), 1e-6));
}

TEST(TransformConventionTest, EulerRoundTrip) {
  for (double x : {-170.0, -45.0, 0.0, 0.5, 45.0, 179.0}) {
    for (double y : {-80.0, -10.0, 0.0, 33.0, 89.0}) {
      for (double z : {-120.0, 0.0, 45.0, 180.0}) {
        const Eigen::Vector3d angles = Eigen::Vector3d(x, y, z) * kDegree;
        const Eigen::Vector3d back = EulerXyzFromRotation(RotationFromEulerXyz(angles));
        EXPECT_TRUE(RotationFromEulerXyz(back).isApprox(RotationFromEulerXyz(angles), 1e-9));
        if (std::abs(z) < 180.0) {
          EXPECT_TRUE(back.isApprox(angles, 1e-9) || angles.isZero());
        }
      }
    }
  }
}

TEST(TransformConventionTest, TargetPointIsRotatedThenTranslatedSourcePoint) {
  const Eigen::Matrix3d rotation = Rz(M_PI / 2);
  const Eigen::Vector3d translation(1, 2, 3);
  const Eigen::Isometry3d T_target_source = MakeTransform(rotation, translation);
  const Eigen::Vector3d p_source(1, 0, 0);
  // Rz(90) sends x to y; then the translation is added.
  EXPECT_TRUE((T_target_source * p_source).isApprox(Eigen::Vector3d(1, 3, 3), 1e-12));
}

TEST(TransformConventionTest, RowMajorLayoutAndRoundTrip) {
  const Eigen::Isometry3d transform =
      MakeTransform(RotationFromEulerXyz({0.1, 0.2, 0.3}), Eigen::Vector3d(4, 5, 6));
  const std::array<double, 16> entries = RowMajorEntries(transform);
  EXPECT_EQ(entries[3], 4.0);
  EXPECT_EQ(entries[7], 5.0);
  EXPECT_EQ(entries[11], 6.0);
  EXPECT_EQ(entries[1], transform.linear()(0, 1));
  EXPECT_EQ(entries[4], transform.linear()(1, 0));
  EXPECT_EQ(entries[12], 0.0);
  EXPECT_EQ(entries[15], 1.0);
  absl::StatusOr<Eigen::Isometry3d> parsed = TransformFromRowMajor(entries);
  ASSERT_TRUE(parsed.ok()) << parsed.status();
  EXPECT_TRUE(parsed->matrix().isApprox(transform.matrix(), 0.0));
}

TEST(TransformConventionTest, ParsingRejectsNonRigidMatrices) {
  std::array<double, 16> entries = RowMajorEntries(Eigen::Isometry3d::Identity());
  entries[0] = 2.0;  // a scale, not a rotation
  EXPECT_EQ(TransformFromRowMajor(entries).status().code(), absl::StatusCode::kInvalidArgument);
  entries = RowMajorEntries(Eigen::Isometry3d::Identity());
  entries[0] = -1.0;  // a reflection
  EXPECT_FALSE(TransformFromRowMajor(entries).ok());
  entries = RowMajorEntries(Eigen::Isometry3d::Identity());
  entries[12] = 0.5;
  EXPECT_FALSE(TransformFromRowMajor(entries).ok());
  entries = RowMajorEntries(Eigen::Isometry3d::Identity());
  entries[3] = std::numeric_limits<double>::quiet_NaN();
  EXPECT_FALSE(TransformFromRowMajor(entries).ok());
}

TEST(TransformConventionTest, PaperErrors) {
  const Eigen::Matrix3d rotation = RotationFromEulerXyz({0.3, -0.2, 0.1});
  EXPECT_EQ(RotationErrorRad(rotation, rotation), 0.0);
  const Eigen::Matrix3d turned =
      rotation * Eigen::AngleAxisd(0.25, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  EXPECT_NEAR(RotationErrorRad(rotation, turned), 0.25, 1e-9);
  EXPECT_NEAR(RotationErrorRad(Eigen::Matrix3d::Identity(), Rz(M_PI)), M_PI, 1e-7);
  // Rounding beyond the cosine's range must not give NaN.
  EXPECT_FALSE(std::isnan(
      RotationErrorRad(Eigen::Matrix3d::Identity(), Eigen::Matrix3d::Identity() * (1 + 1e-12))));
  EXPECT_DOUBLE_EQ(TranslationError({1, 2, 3}, {1, 2, 5}), 2.0);
}

}  // namespace
}  // namespace rpsr::core
