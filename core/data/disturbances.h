// The paper's four disturbances of a source cloud (Sec. 4) and their five evaluation levels, and
// one beyond the paper: partial views, where the target is cropped too.
// Counts are exact: a fraction f of an N-point cloud affects exactly AffectedPointCount(N, f) =
// round(f * N) distinct points (half away from zero), so the benchmark's levels mean the same
// thing for every cloud. Every random draw comes from SeededRandom, so a seed fixes the result.
#ifndef RPSR_CORE_DATA_DISTURBANCES_H_
#define RPSR_CORE_DATA_DISTURBANCES_H_

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "Eigen/Core"
#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "core/cloud/point_cloud.h"

namespace rpsr::core {

enum class DisturbanceKind {
  kNone,
  // N(0, sigma^2) added to each coordinate of round(p N) distinct points (sigma 0.02: the paper's
  // N(0, 0.02), read as a standard deviation).
  kGaussianNoise,
  // round(p N) distinct points replaced by points uniform in [-1, 1]^3 (the paper's U(-1, 1)).
  kUniformOutliers,
  // The round(c N) points farthest along a random direction removed: everything beyond a plane,
  // a contiguous chunk. The cloud shrinks to N - round(c N) points.
  kCrop,
  // Every point moved by a Gaussian displacement (sigma = tolerance / 2 per axis) whose length is
  // clipped to the displacement tolerance.
  kJitter,
  // Not the paper's: partial views on BOTH sides, as two scans of an object from different
  // viewpoints (RPM-Net's partial-to-partial protocol). Applied to one cloud it is kCrop; a pair
  // generator (object_pairs.h) crops the source and, along another random direction, the target,
  // each by the same fraction, so the overlap is usually smaller than either cloud.
  kPartialViews,
};

// "none", "gaussian_noise", "uniform_outliers", "crop", "jitter", "partial_views".
std::string DisturbanceName(DisturbanceKind kind);

// Whether `kind`'s magnitude is a fraction of the points (noise, outliers, crop, partial views),
// which must lie in [0, 1]; jitter's is a distance.
bool IsFractionDisturbance(DisturbanceKind kind);

inline constexpr int kNumDisturbanceLevels = 5;
inline constexpr double kGaussianNoiseSigma = 0.02;
inline constexpr double kOutlierHalfExtent = 1.0;

// The magnitude of `kind` at evaluation level 0..4 (the paper's five validation sets):
//   noise and outliers: fraction of points 0.01, 0.05, 0.10, 0.20, 0.40;
//   crop and partial views: fraction of points (of each cloud) 0.01, 0.10, 0.20, 0.30, 0.40;
//   jitter: displacement tolerance 0.01, 0.02, 0.03, 0.05, 0.08 (in the [-1, 1] object frame;
//           the paper names no values beyond "increasing", and trains with 0.03 = level 2).
// The paper's training mix uses level 3 for noise/outliers (20%), level 2 for crop (20%) and
// jitter (0.03). 0 for kNone. InvalidArgument for a level outside 0..4.
absl::StatusOr<double> DisturbanceMagnitudeAtLevel(DisturbanceKind kind, int level);

// round(fraction * num_points), half away from zero; fraction must be in [0, 1].
size_t AffectedPointCount(size_t num_points, double fraction);

// What was done to a cloud. `affected_indices` are indices into the cloud BEFORE the
// disturbance (noised, replaced or removed points), ascending; empty for kNone and kJitter
// (jitter moves every point).
struct AppliedDisturbance {
  DisturbanceKind kind = DisturbanceKind::kNone;
  double magnitude = 0.0;  // fraction of points, or the jitter tolerance
  std::vector<size_t> affected_indices;
  // kCrop and kPartialViews only: the unit direction along which the removed chunk lies; every
  // removed point's projection on it is >= every kept point's (the chunk is cut off by a plane).
  Eigen::Vector3d crop_direction = Eigen::Vector3d::Zero();
};

// Applies `kind` with `magnitude` to `cloud` in place, drawing from a SeededRandom seeded with
// `seed`. Intensities, if present, follow their points (removed with them; kept for moved or
// replaced points). InvalidArgument for a fraction outside [0, 1] or a negative tolerance.
absl::StatusOr<AppliedDisturbance> ApplyDisturbance(DisturbanceKind kind, double magnitude,
                                                    uint64_t seed, PointCloud& cloud);

}  // namespace rpsr::core

#endif  // RPSR_CORE_DATA_DISTURBANCES_H_
