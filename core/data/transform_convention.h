// THE one place that states rpsr's ground-truth convention; everything that makes, stores or
// scores pairs uses these helpers.
//
//   T_target_source maps source points into the target frame:
//       p_target = R * p_source + t,   T_target_source = [R t; 0 0 0 1].
//   A registration result is scored against it directly (R_gt = T_target_source.linear(),
//   t_gt = T_target_source.translation()).
//
//   Euler angles (theta_x, theta_y, theta_z), radians, compose as R = Rz(theta_z) Ry(theta_y)
//   Rx(theta_x): rotate about the fixed x axis first, then fixed y, then fixed z (equivalently
//   intrinsic z, y', x''). Vectors of angles are ordered (x, y, z).
//
//   Manifests store T_target_source as its 16 entries in row-major order (r00 r01 r02 t0 r10 ...
//   0 0 0 1).
#ifndef RPSR_CORE_DATA_TRANSFORM_CONVENTION_H_
#define RPSR_CORE_DATA_TRANSFORM_CONVENTION_H_

#include <array>

#include "Eigen/Core"
#include "Eigen/Geometry"
#include "absl/status/statusor.h"

namespace rpsr::core {

// R = Rz(angles.z()) * Ry(angles.y()) * Rx(angles.x()).
Eigen::Matrix3d RotationFromEulerXyz(const Eigen::Vector3d& angles_rad);

// Inverse of RotationFromEulerXyz for |theta_y| < 90 degrees (unique there): returns
// (theta_x, theta_y, theta_z) with theta_y in [-90, 90] and the others in (-180, 180] degrees.
Eigen::Vector3d EulerXyzFromRotation(const Eigen::Matrix3d& rotation);

// [R t; 0 1] as an isometry.
Eigen::Isometry3d MakeTransform(const Eigen::Matrix3d& rotation,
                                const Eigen::Vector3d& translation);

// The 16 entries of T, row-major (the manifest layout).
std::array<double, 16> RowMajorEntries(const Eigen::Isometry3d& transform);

// Parses the manifest layout back. InvalidArgument when an entry is not finite, the last row is
// not (0 0 0 1) within 1e-9, or the 3x3 block is not a rotation (orthonormal, det +1, within
// 1e-6).
absl::StatusOr<Eigen::Isometry3d> TransformFromRowMajor(const std::array<double, 16>& entries);

// The paper's rotation error: acos((trace(R_gt^T R) - 1) / 2) in radians, in [0, pi]; the cosine
// is clamped into [-1, 1] so rounding never produces NaN.
double RotationErrorRad(const Eigen::Matrix3d& rotation_gt, const Eigen::Matrix3d& rotation);

// The paper's translation error: ||t_gt - t||.
double TranslationError(const Eigen::Vector3d& translation_gt, const Eigen::Vector3d& translation);

}  // namespace rpsr::core

#endif  // RPSR_CORE_DATA_TRANSFORM_CONVENTION_H_
