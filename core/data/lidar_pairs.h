// LiDAR registration pairs in the paper's KITTI protocol: the source is frame i of a sequence, the
// target frame i + 5; ground truth T_target_source = T_world_lidar_{i+5}^-1 * T_world_lidar_i
// (kitti_odometry.h), which maps source points into the target's frame. Two setups:
//   K1-w/o: ground points (semantic_labels.h's ground classes) removed from both clouds using
//           the SemanticKITTI labels;
//   K2-w:   clouds as scanned.
// Works on any sequence the KITTI reader opens, real or simulated.
//
// Splits: each sequence is cut into three contiguous blocks of frames, in the paper's order:
// training (first 70%), testing (next 20%), validation (last 10%); the splits of several sequences
// are then merged by the caller. A pair lies wholly inside one block, and the first
// `split_gap_frames` frames of the test and validation blocks are not used, so no frame of a test
// pair is within split_gap_frames of a training frame (neighbouring scans nearly repeat each
// other, and a random per-frame split would leak test geometry into training).
#ifndef RPSR_CORE_DATA_LIDAR_PAIRS_H_
#define RPSR_CORE_DATA_LIDAR_PAIRS_H_

#include <cstddef>
#include <cstdint>
#include <vector>

#include "Eigen/Geometry"
#include "absl/status/statusor.h"
#include "core/cloud/point_cloud.h"
#include "core/data/kitti_odometry.h"

namespace rpsr::core {

enum class GroundHandling {
  kKeep,    // K2-w
  kRemove,  // K1-w/o
};

enum class LidarSplit { kTrain, kTest, kValidation };

const char* LidarSplitName(LidarSplit split);

struct LidarPairOptions {
  // Target frame = source frame + frame_offset.
  int frame_offset = 5;
  // Block fractions; validation gets the rest (0.1).
  double train_fraction = 0.7;
  double test_fraction = 0.2;
  // Frames left out at the start of the test and validation blocks.
  int split_gap_frames = 10;
  // 0: every eligible source frame; otherwise at most this many, drawn without replacement with
  // `seed` (per sequence and split) and returned in frame order.
  size_t max_pairs = 0;
  uint64_t seed = 1;
};

// Frames [begin, end) of a split's block in a sequence of `frame_count` frames:
// train [0, floor(0.7 N)), test [floor(0.7 N), floor(0.9 N)), validation [floor(0.9 N), N).
struct FrameRange {
  int begin = 0;
  int end = 0;
};
FrameRange SplitFrameRange(int frame_count, LidarSplit split, const LidarPairOptions& options);

struct LidarPairIndex {
  int sequence = 0;
  int source_frame = 0;
  int target_frame = 0;
};

// The pairs of one split of one sequence, sorted by source frame. InvalidArgument for a
// non-positive offset, a negative gap or fractions outside [0, 1] that sum above 1. An empty list
// when the block is too short.
absl::StatusOr<std::vector<LidarPairIndex>> SelectLidarPairs(int sequence, int frame_count,
                                                             LidarSplit split,
                                                             const LidarPairOptions& options);

struct LidarPair {
  LidarPairIndex index;
  PointCloud source;
  PointCloud target;
  // Maps source points into the target's frame.
  Eigen::Isometry3d T_target_source = Eigen::Isometry3d::Identity();
};

// Reads a pair's scans (with ground removed for kRemove, which needs the sequence's labels).
// InvalidArgument when `index` names another sequence; the reader's errors otherwise.
absl::StatusOr<LidarPair> LoadLidarPair(const KittiOdometrySequence& sequence,
                                        const LidarPairIndex& index, GroundHandling ground);

}  // namespace rpsr::core

#endif  // RPSR_CORE_DATA_LIDAR_PAIRS_H_
