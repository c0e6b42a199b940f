#include "core/data/transform_convention.h"

#include <algorithm>
#include <cmath>

#include "absl/strings/str_cat.h"

namespace rpsr::core {

Eigen::Matrix3d RotationFromEulerXyz(const Eigen::Vector3d& angles_rad) {
  return (Eigen::AngleAxisd(angles_rad.z(), Eigen::Vector3d::UnitZ()) *
          Eigen::AngleAxisd(angles_rad.y(), Eigen::Vector3d::UnitY()) *
          Eigen::AngleAxisd(angles_rad.x(), Eigen::Vector3d::UnitX()))
      .toRotationMatrix();
}

Eigen::Vector3d EulerXyzFromRotation(const Eigen::Matrix3d& rotation) {
  // R(2,0) = -sin(theta_y); R(2,1) / R(2,2) = tan(theta_x); R(1,0) / R(0,0) = tan(theta_z).
  const double theta_y = std::asin(std::clamp(-rotation(2, 0), -1.0, 1.0));
  const double theta_x = std::atan2(rotation(2, 1), rotation(2, 2));
  const double theta_z = std::atan2(rotation(1, 0), rotation(0, 0));
  return {theta_x, theta_y, theta_z};
}

Eigen::Isometry3d MakeTransform(const Eigen::Matrix3d& rotation,
                                const Eigen::Vector3d& translation) {
  Eigen::Isometry3d transform = Eigen::Isometry3d::Identity();
  transform.linear() = rotation;
  transform.translation() = translation;
  return transform;
}

std::array<double, 16> RowMajorEntries(const Eigen::Isometry3d& transform) {
  std::array<double, 16> entries;
  const Eigen::Matrix4d& matrix = transform.matrix();
  for (int r = 0; r < 4; ++r) {
    for (int c = 0; c < 4; ++c) entries[4 * r + c] = matrix(r, c);
  }
  return entries;
}

absl::StatusOr<Eigen::Isometry3d> TransformFromRowMajor(const std::array<double, 16>& entries) {
  Eigen::Matrix4d matrix;
  for (int i = 0; i < 16; ++i) {
    if (!std::isfinite(entries[i])) {
      return absl::InvalidArgumentError(absl::StrCat("transform entry ", i, " is not finite"));
    }
    matrix(i / 4, i % 4) = entries[i];
  }
  if ((matrix.row(3) - Eigen::RowVector4d(0, 0, 0, 1)).cwiseAbs().maxCoeff() > 1e-9) {
    return absl::InvalidArgumentError("transform's last row is not (0 0 0 1)");
  }
  const Eigen::Matrix3d rotation = matrix.topLeftCorner<3, 3>();
  const double orthogonality =
      (rotation.transpose() * rotation - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
  if (orthogonality > 1e-6 || std::abs(rotation.determinant() - 1.0) > 1e-6) {
    return absl::InvalidArgumentError(
        absl::StrCat("transform's 3x3 block is not a rotation (|R^T R - I| = ", orthogonality,
                     ", det = ", rotation.determinant(), ")"));
  }
  return MakeTransform(rotation, matrix.topRightCorner<3, 1>());
}

double RotationErrorRad(const Eigen::Matrix3d& rotation_gt, const Eigen::Matrix3d& rotation) {
  const double cosine = 0.5 * ((rotation_gt.transpose() * rotation).trace() - 1.0);
  return std::acos(std::clamp(cosine, -1.0, 1.0));
}

double TranslationError(const Eigen::Vector3d& translation_gt, const Eigen::Vector3d& translation) {
  return (translation_gt - translation).norm();
}

}  // namespace rpsr::core
