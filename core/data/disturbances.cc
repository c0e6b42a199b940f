#include "core/data/disturbances.h"

#include <algorithm>
#include <cmath>
#include <numeric>

#include "absl/strings/str_cat.h"
#include "core/synth/seeded_random.h"

namespace rpsr::core {
namespace {

std::vector<size_t> Sorted(std::vector<size_t> indices) {
  std::sort(indices.begin(), indices.end());
  return indices;
}

void AddGaussianNoise(double fraction, SeededRandom& random, PointCloud& cloud,
                      AppliedDisturbance& applied) {
  applied.affected_indices =
      Sorted(random.DistinctIndices(cloud.size(), AffectedPointCount(cloud.size(), fraction)));
  for (size_t i : applied.affected_indices) {
    const Eigen::Vector3d noise(random.Normal(0, kGaussianNoiseSigma),
                                random.Normal(0, kGaussianNoiseSigma),
                                random.Normal(0, kGaussianNoiseSigma));
    cloud.points[i] += noise.cast<float>();
  }
}

void ReplaceWithUniformOutliers(double fraction, SeededRandom& random, PointCloud& cloud,
                                AppliedDisturbance& applied) {
  applied.affected_indices =
      Sorted(random.DistinctIndices(cloud.size(), AffectedPointCount(cloud.size(), fraction)));
  for (size_t i : applied.affected_indices) {
    cloud.points[i] = Eigen::Vector3d(random.Uniform(-kOutlierHalfExtent, kOutlierHalfExtent),
                                      random.Uniform(-kOutlierHalfExtent, kOutlierHalfExtent),
                                      random.Uniform(-kOutlierHalfExtent, kOutlierHalfExtent))
                          .cast<float>();
  }
}

void CropChunk(double fraction, SeededRandom& random, PointCloud& cloud,
               AppliedDisturbance& applied) {
  const size_t count = AffectedPointCount(cloud.size(), fraction);
  const Eigen::Vector3d direction = random.UnitVector();
  applied.crop_direction = direction;
  std::vector<double> height(cloud.size());
  for (size_t i = 0; i < cloud.size(); ++i)
    height[i] = direction.dot(cloud.points[i].cast<double>());
  // The `count` highest points along `direction`; ties broken by index so the choice is unique.
  std::vector<size_t> order(cloud.size());
  std::iota(order.begin(), order.end(), size_t{0});
  std::nth_element(order.begin(), order.begin() + count, order.end(), [&](size_t a, size_t b) {
    return height[a] != height[b] ? height[a] > height[b] : a < b;
  });
  order.resize(count);
  applied.affected_indices = Sorted(std::move(order));
  std::vector<bool> removed(cloud.size(), false);
  for (size_t i : applied.affected_indices) removed[i] = true;
  PointCloud kept;
  kept.points.reserve(cloud.size() - count);
  const bool has_intensities = !cloud.intensities.empty();
  for (size_t i = 0; i < cloud.size(); ++i) {
    if (removed[i]) continue;
    kept.points.push_back(cloud.points[i]);
    if (has_intensities) kept.intensities.push_back(cloud.intensities[i]);
  }
  cloud = std::move(kept);
}

void Jitter(double tolerance, SeededRandom& random, PointCloud& cloud) {
  const double sigma = 0.5 * tolerance;
  for (Eigen::Vector3f& p : cloud.points) {
    Eigen::Vector3d displacement(random.Normal(0, sigma), random.Normal(0, sigma),
                                 random.Normal(0, sigma));
    const double length = displacement.norm();
    if (length > tolerance) displacement *= tolerance / length;
    p += displacement.cast<float>();
  }
}

}  // namespace

std::string DisturbanceName(DisturbanceKind kind) {
  switch (kind) {
    case DisturbanceKind::kNone:
      return "none";
    case DisturbanceKind::kGaussianNoise:
      return "gaussian_noise";
    case DisturbanceKind::kUniformOutliers:
      return "uniform_outliers";
    case DisturbanceKind::kCrop:
      return "crop";
    case DisturbanceKind::kJitter:
      return "jitter";
    case DisturbanceKind::kPartialViews:
      return "partial_views";
  }
  return "unknown";
}

bool IsFractionDisturbance(DisturbanceKind kind) {
  return kind == DisturbanceKind::kGaussianNoise || kind == DisturbanceKind::kUniformOutliers ||
         kind == DisturbanceKind::kCrop || kind == DisturbanceKind::kPartialViews;
}

absl::StatusOr<double> DisturbanceMagnitudeAtLevel(DisturbanceKind kind, int level) {
  if (level < 0 || level >= kNumDisturbanceLevels) {
    return absl::InvalidArgumentError(
        absl::StrCat("disturbance level ", level, " outside 0..", kNumDisturbanceLevels - 1));
  }
  static constexpr double kNoiseFractions[kNumDisturbanceLevels] = {0.01, 0.05, 0.10, 0.20, 0.40};
  static constexpr double kCropFractions[kNumDisturbanceLevels] = {0.01, 0.10, 0.20, 0.30, 0.40};
  static constexpr double kJitterTolerances[kNumDisturbanceLevels] = {0.01, 0.02, 0.03, 0.05, 0.08};
  switch (kind) {
    case DisturbanceKind::kNone:
      return 0.0;
    case DisturbanceKind::kGaussianNoise:
    case DisturbanceKind::kUniformOutliers:
      return kNoiseFractions[level];
    case DisturbanceKind::kCrop:
    case DisturbanceKind::kPartialViews:
      return kCropFractions[level];
    case DisturbanceKind::kJitter:
      return kJitterTolerances[level];
  }
  return absl::InvalidArgumentError("unknown disturbance kind");
}

size_t AffectedPointCount(size_t num_points, double fraction) {
  return static_cast<size_t>(std::llround(fraction * static_cast<double>(num_points)));
}

absl::StatusOr<AppliedDisturbance> ApplyDisturbance(DisturbanceKind kind, double magnitude,
                                                    uint64_t seed, PointCloud& cloud) {
  if (IsFractionDisturbance(kind) && !(magnitude >= 0.0 && magnitude <= 1.0)) {
    return absl::InvalidArgumentError(
        absl::StrCat(DisturbanceName(kind), " fraction ", magnitude, " outside [0, 1]"));
  }
  if (kind == DisturbanceKind::kJitter && !(magnitude >= 0.0 && std::isfinite(magnitude))) {
    return absl::InvalidArgumentError(
        absl::StrCat("jitter tolerance ", magnitude, " is not a finite value >= 0"));
  }
  AppliedDisturbance applied;
  applied.kind = kind;
  applied.magnitude = kind == DisturbanceKind::kNone ? 0.0 : magnitude;
  SeededRandom random(seed);
  switch (kind) {
    case DisturbanceKind::kNone:
      break;
    case DisturbanceKind::kGaussianNoise:
      AddGaussianNoise(magnitude, random, cloud, applied);
      break;
    case DisturbanceKind::kUniformOutliers:
      ReplaceWithUniformOutliers(magnitude, random, cloud, applied);
      break;
    case DisturbanceKind::kCrop:
    case DisturbanceKind::kPartialViews:
      CropChunk(magnitude, random, cloud, applied);
      break;
    case DisturbanceKind::kJitter:
      Jitter(magnitude, random, cloud);
      break;
  }
  return applied;
}

}  // namespace rpsr::core
