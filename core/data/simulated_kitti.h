// Simulated LiDAR sequences written in the KITTI odometry layout (kitti_odometry.h), so that the
// reader and the pair protocol serve simulated and real data alike: velodyne scans, SemanticKITTI
// labels (class only, instance 0), calib.txt with a KITTI-like Tr, poses.txt (camera 0 poses
// relative to the first frame, converted from the simulated LiDAR poses) and times.txt.
#ifndef RPSR_CORE_DATA_SIMULATED_KITTI_H_
#define RPSR_CORE_DATA_SIMULATED_KITTI_H_

#include <cstddef>
#include <string>

#include "Eigen/Geometry"
#include "absl/status/statusor.h"
#include "core/data/kitti_odometry.h"
#include "core/synth/lidar_sequence.h"

namespace rpsr::core {

struct SimulatedKittiSummary {
  int frame_count = 0;
  size_t total_points = 0;
  size_t min_points_per_scan = 0;
  size_t max_points_per_scan = 0;
  // Wall time of simulating and writing.
  double seconds = 0.0;
};

// Simulates `options` and writes it as <dataset_root>/sequences/NN. Errors from the simulator's
// options or from writing (naming the file).
absl::StatusOr<SimulatedKittiSummary> WriteSimulatedKittiSequence(
    const std::string& dataset_root, int sequence, const LidarSequenceOptions& options,
    const Eigen::Isometry3d& T_camera_lidar = KittiLikeCameraFromLidar());

}  // namespace rpsr::core

#endif  // RPSR_CORE_DATA_SIMULATED_KITTI_H_
