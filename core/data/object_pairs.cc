#include "core/data/object_pairs.h"

#include <cmath>
#include <vector>

#include "absl/strings/str_cat.h"
#include "core/data/transform_convention.h"
#include "core/io/mesh_sampling.h"
#include "core/synth/object_normalization.h"
#include "core/synth/seeded_random.h"
#include "core/synth/shape_families.h"

namespace rpsr::core {
namespace {

// Independent streams of one pair seed; never renumber (that would change every pair).
enum Stream : uint64_t {
  kFamilyStream = 1,
  kObjectStream = 2,
  kPoseStream = 3,
  kSourceSamplingStream = 4,
  kTargetSamplingStream = 5,
  kDisturbanceStream = 6,
  kDisturbanceKindStream = 7,
  kTargetDisturbanceStream = 8,
};

std::vector<size_t> FamiliesOf(ObjectSplit split) {
  switch (split) {
    case ObjectSplit::kM2Seen:
      return FamilyIndicesIn(FamilySplit::kSeen);
    case ObjectSplit::kM2Unseen:
      return FamilyIndicesIn(FamilySplit::kUnseen);
    case ObjectSplit::kM1All:
      break;
  }
  std::vector<size_t> all(ShapeFamilies().size());
  for (size_t i = 0; i < all.size(); ++i) all[i] = i;
  return all;
}

// The disturbance kind and magnitude for this pair.
absl::StatusOr<std::pair<DisturbanceKind, double>> ChooseDisturbance(const PairOptions& options,
                                                                     uint64_t seed) {
  if (options.random_disturbance) {
    static constexpr DisturbanceKind kKinds[4] = {DisturbanceKind::kGaussianNoise,
                                                  DisturbanceKind::kUniformOutliers,
                                                  DisturbanceKind::kCrop, DisturbanceKind::kJitter};
    // The paper's training magnitudes: 20% noise / outliers / crop, jitter tolerance 0.03.
    static constexpr double kTrainingMagnitudes[4] = {0.20, 0.20, 0.20, 0.03};
    SeededRandom random(DeriveSeed(seed, kDisturbanceKindStream));
    const size_t pick = random.UniformIndex(4);
    return std::make_pair(kKinds[pick],
                          options.disturbance_magnitude.value_or(kTrainingMagnitudes[pick]));
  }
  if (options.disturbance_magnitude.has_value()) {
    return std::make_pair(options.disturbance, *options.disturbance_magnitude);
  }
  absl::StatusOr<double> magnitude =
      DisturbanceMagnitudeAtLevel(options.disturbance, options.disturbance_level);
  if (!magnitude.ok()) return magnitude.status();
  return std::make_pair(options.disturbance, *magnitude);
}

// Steps 2-4 of the protocol on an already normalised mesh.
absl::StatusOr<ObjectPair> PairFromNormalizedMesh(const TriangleMesh& mesh,
                                                  const PairOptions& options, uint64_t seed) {
  ObjectPair pair;
  SeededRandom pose_random(DeriveSeed(seed, kPoseStream));
  const double max_angle_rad = options.max_angle_deg * M_PI / 180.0;
  for (int axis = 0; axis < 3; ++axis) {
    // 1 - U is in (0, 1], so each angle is in (0, max], as in the paper.
    pair.euler_angles_rad[axis] = max_angle_rad * (1.0 - pose_random.UniformUnit());
  }
  Eigen::Vector3d translation;
  for (int axis = 0; axis < 3; ++axis) {
    translation[axis] = pose_random.Uniform(-options.max_translation, options.max_translation);
  }
  pair.T_target_source = MakeTransform(RotationFromEulerXyz(pair.euler_angles_rad), translation);

  absl::StatusOr<PointCloud> source =
      SampleSurface(mesh, options.num_points, DeriveSeed(seed, kSourceSamplingStream));
  if (!source.ok()) return source.status();
  PointCloud target_points;
  if (options.same_points) {
    target_points = *source;
  } else {
    absl::StatusOr<PointCloud> target =
        SampleSurface(mesh, options.num_points, DeriveSeed(seed, kTargetSamplingStream));
    if (!target.ok()) return target.status();
    target_points = *std::move(target);
  }
  pair.target = TransformedCloud(target_points, pair.T_target_source.cast<float>());
  pair.source = *std::move(source);

  absl::StatusOr<std::pair<DisturbanceKind, double>> disturbance = ChooseDisturbance(options, seed);
  if (!disturbance.ok()) return disturbance.status();
  absl::StatusOr<AppliedDisturbance> applied = ApplyDisturbance(
      disturbance->first, disturbance->second, DeriveSeed(seed, kDisturbanceStream), pair.source);
  if (!applied.ok()) return applied.status();
  pair.disturbance = *std::move(applied);
  if (disturbance->first == DisturbanceKind::kPartialViews) {
    // Its own stream: the source's cut and every other draw stay as for kCrop at this seed.
    absl::StatusOr<AppliedDisturbance> target_cut =
        ApplyDisturbance(DisturbanceKind::kPartialViews, disturbance->second,
                         DeriveSeed(seed, kTargetDisturbanceStream), pair.target);
    if (!target_cut.ok()) return target_cut.status();
    pair.target_disturbance = *std::move(target_cut);
  }
  return pair;
}

}  // namespace

absl::Status ValidatePairOptions(const PairOptions& options) {
  if (options.num_points == 0) return absl::InvalidArgumentError("num_points must be positive");
  if (!(options.max_angle_deg > 0.0 && options.max_angle_deg <= 180.0)) {
    return absl::InvalidArgumentError(
        absl::StrCat("max_angle_deg ", options.max_angle_deg, " outside (0, 180]"));
  }
  if (!(options.max_translation >= 0.0 && std::isfinite(options.max_translation))) {
    return absl::InvalidArgumentError(
        absl::StrCat("max_translation ", options.max_translation, " is not finite and >= 0"));
  }
  if (!options.random_disturbance && !options.disturbance_magnitude.has_value()) {
    absl::StatusOr<double> magnitude =
        DisturbanceMagnitudeAtLevel(options.disturbance, options.disturbance_level);
    if (!magnitude.ok()) return magnitude.status();
  }
  if (options.disturbance_magnitude.has_value()) {
    const double magnitude = *options.disturbance_magnitude;
    if (!(magnitude >= 0.0 && std::isfinite(magnitude))) {
      return absl::InvalidArgumentError(
          absl::StrCat("disturbance_magnitude ", magnitude, " is not finite and >= 0"));
    }
    const bool is_fraction =
        options.random_disturbance || IsFractionDisturbance(options.disturbance);
    if (is_fraction && magnitude > 1.0) {
      return absl::InvalidArgumentError(
          absl::StrCat("disturbance fraction ", magnitude, " outside [0, 1]"));
    }
  }
  return absl::OkStatus();
}

absl::StatusOr<ObjectPair> MakeObjectPair(const PairOptions& options, uint64_t seed) {
  if (absl::Status valid = ValidatePairOptions(options); !valid.ok()) return valid;
  const std::vector<size_t> families = FamiliesOf(options.split);
  SeededRandom family_random(DeriveSeed(seed, kFamilyStream));
  const size_t family_index = families[family_random.UniformIndex(families.size())];
  const uint64_t object_seed = DeriveSeed(seed, kObjectStream);
  absl::StatusOr<TriangleMesh> mesh = GenerateNormalizedObject(family_index, object_seed);
  if (!mesh.ok()) return mesh.status();
  absl::StatusOr<ObjectPair> pair = PairFromNormalizedMesh(*mesh, options, seed);
  if (!pair.ok()) return pair.status();
  pair->family_index = static_cast<int>(family_index);
  pair->object_seed = object_seed;
  return pair;
}

absl::StatusOr<ObjectPair> MakeObjectPairFromMesh(const TriangleMesh& mesh,
                                                  const PairOptions& options, uint64_t seed) {
  if (absl::Status valid = ValidatePairOptions(options); !valid.ok()) return valid;
  absl::StatusOr<TriangleMesh> normalized = NormalizedIntoUnitCube(mesh);
  if (!normalized.ok()) return normalized.status();
  return PairFromNormalizedMesh(*normalized, options, seed);
}

}  // namespace rpsr::core
