// The paper's object pair protocol (Sec. 4, ModelNet40 setups M1 and M2), on procedural objects
// (core/synth/shape_families.h) or on meshes the caller supplies:
//   1. an object is drawn (family uniformly from the split, then the object) and its MESH is
//      scaled into [-1, 1]^3;
//   2. the ground truth T_target_source (transform_convention.h) gets Euler angles each uniform in
//      (0, max_angle_deg] and a translation with each component uniform in
//      [-max_translation, max_translation];
//   3. source and target are sampled independently from the surface (or, with same_points, the
//      target is the clean source mapped by T), and the target is mapped into its frame:
//      target = T_target_source * points;
//   4. the disturbance is applied to the source only (kPartialViews also crops the target, from
//      its own stream).
// Every stage draws from its own stream derived from the pair's seed, so the same seed with
// kNone gives exactly the undisturbed version of a disturbed pair, and pairs are identical across
// runs and platforms.
#ifndef RPSR_CORE_DATA_OBJECT_PAIRS_H_
#define RPSR_CORE_DATA_OBJECT_PAIRS_H_

#include <cstddef>
#include <cstdint>
#include <optional>

#include "Eigen/Geometry"
#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "core/cloud/point_cloud.h"
#include "core/data/disturbances.h"

namespace rpsr::core {

// The paper's class splits: M1 uses every family; M2 trains on the seen half and tests on the
// unseen half. (Train and test objects within a split differ by seed: use disjoint seed ranges.)
enum class ObjectSplit { kM1All, kM2Seen, kM2Unseen };

struct PairOptions {
  // Points sampled for the source and for the target (before a crop shrinks the source, or
  // partial views both clouds). 1024 follows DCP's ModelNet40 protocol, which the paper compares
  // against.
  size_t num_points = 1024;
  // false (the paper's harder, honest default): source and target are independent samples of the
  // surface, so no point has an exact partner. true: target = T * clean source, point for point.
  bool same_points = false;
  // Each Euler angle uniform in (0, max_angle_deg] degrees (the paper: (0, 45]).
  double max_angle_deg = 45.0;
  // Each translation component uniform in [-max_translation, max_translation] (the paper: 0.5).
  double max_translation = 0.5;
  // Which families MakeObjectPair draws from.
  ObjectSplit split = ObjectSplit::kM1All;
  // The disturbance applied to the source (kPartialViews: to the target too, along another
  // direction), at evaluation level `disturbance_level` (0..4, see DisturbanceMagnitudeAtLevel)
  // unless `disturbance_magnitude` overrides it.
  DisturbanceKind disturbance = DisturbanceKind::kNone;
  int disturbance_level = 0;
  std::optional<double> disturbance_magnitude;
  // The paper's training mix: one of the four disturbances drawn uniformly per pair (then
  // `disturbance` is ignored), each at its training magnitude (noise and outliers 20%, crop 20%,
  // jitter 0.03) unless `disturbance_magnitude` is set.
  bool random_disturbance = false;
};

struct ObjectPair {
  PointCloud source;  // disturbed, in the object's normalised frame
  PointCloud target;  // clean (cropped for kPartialViews), in the target frame
  // Maps source points into the target frame (transform_convention.h).
  Eigen::Isometry3d T_target_source = Eigen::Isometry3d::Identity();
  // The drawn Euler angles (x, y, z) in radians; T's rotation is RotationFromEulerXyz of them.
  Eigen::Vector3d euler_angles_rad = Eigen::Vector3d::Zero();
  // The shape family (index into ShapeFamilies()), or -1 for a caller-supplied mesh.
  int family_index = -1;
  // The seed GenerateObject used (0 for a caller-supplied mesh).
  uint64_t object_seed = 0;
  AppliedDisturbance disturbance;
  // What was done to the target: kPartialViews' crop (indices into the full target sample; its
  // crop_direction in the target frame, the source's in the source frame), or kNone.
  AppliedDisturbance target_disturbance;
};

// OK when the options describe a protocol: num_points > 0, max_angle_deg in (0, 180],
// max_translation >= 0 and finite, a level in 0..4, a magnitude that ApplyDisturbance accepts.
absl::Status ValidatePairOptions(const PairOptions& options);

// A pair from a procedural object of `options.split`, a pure function of (options, seed).
absl::StatusOr<ObjectPair> MakeObjectPair(const PairOptions& options, uint64_t seed);

// A pair from `mesh` (e.g. one read from a mesh folder), normalised into [-1, 1]^3 first;
// `options.split` is ignored. InvalidArgument for a mesh without surface or with non-finite
// vertices.
absl::StatusOr<ObjectPair> MakeObjectPairFromMesh(const TriangleMesh& mesh,
                                                  const PairOptions& options, uint64_t seed);

}  // namespace rpsr::core

#endif  // RPSR_CORE_DATA_OBJECT_PAIRS_H_
