// Endless, seeded streams of registration pairs for training and validation: pair i is a pure
// function of (options, i), so a run is reproducible and independent of thread counts.
#ifndef RPSR_CORE_DATA_TRAINING_PAIRS_H_
#define RPSR_CORE_DATA_TRAINING_PAIRS_H_

#include <cstdint>
#include <functional>

#include "Eigen/Geometry"
#include "absl/status/statusor.h"
#include "core/cloud/point_cloud.h"
#include "core/data/object_pairs.h"

namespace rpsr::core {

struct RegistrationPair {
  PointCloud source;
  PointCloud target;
  Eigen::Isometry3d T_target_source = Eigen::Isometry3d::Identity();  // transform_convention.h
};

// Thread-safe; pair i depends on i only.
using RegistrationPairGenerator = std::function<absl::StatusOr<RegistrationPair>(uint64_t index)>;

struct ObjectStreamOptions {
  PairOptions pair;  // split, points, angles, translation (the disturbance fields are set below)
  // Fraction of pairs given one of the paper's four disturbances at its training magnitude (the
  // paper disturbs ~10% of its training set; more makes the model robust to them).
  double disturbed_fraction = 0.3;
  // Seeds are derived from (stream_seed, index): use different stream seeds for training and
  // validation so their objects differ.
  uint64_t stream_seed = 1;
};
RegistrationPairGenerator MakeObjectPairStream(const ObjectStreamOptions& options);

struct LidarStreamOptions {
  // Pairs come from simulated sequences of `frames_per_sequence` frames (all four street styles
  // in turn), `pairs_per_sequence` consecutive indices per sequence; target = frame + offset.
  int frames_per_sequence = 120;
  int pairs_per_sequence = 32;
  int frame_offset = 5;
  // Fraction of pairs with ground points removed (the paper's K1-w/o); the rest keep them (K2-w).
  double ground_removed_fraction = 0.5;
  uint64_t stream_seed = 1;
};
RegistrationPairGenerator MakeLidarPairStream(const LidarStreamOptions& options);

}  // namespace rpsr::core

#endif  // RPSR_CORE_DATA_TRAINING_PAIRS_H_
