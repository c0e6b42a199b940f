// The KITTI odometry benchmark's errors of an estimated trajectory against the ground truth, as
// its development kit (evaluate_odometry.cpp) defines them:
//
//  - the distance travelled along the ground truth, frame by frame (sum of the steps between
//    consecutive ground-truth positions);
//  - segments: from every 10th frame (step_size 10) and for each length L in {100, 200, ..., 800}
//    metres, the segment ends at the first frame whose travelled distance exceeds the start's by
//    more than L (no segment when the sequence ends before);
//  - per segment, with the relative motions D_gt = P_gt[first]^-1 P_gt[last] and
//    D_est = P_est[first]^-1 P_est[last], the error E = D_est^-1 D_gt; its translation error is
//    ||t(E)|| / L and its rotation error is angle(E) / L (angle = acos of (trace - 1) / 2,
//    clamped);
//  - the sequence's figures are the plain means over all its segments: translation in percent
//    (x 100) and rotation in degrees per metre (the benchmark's table; x 100 for deg/100 m).
//
// Poses are T_world_frame as in poses.txt (12 numbers a line), both trajectories in the same
// convention (the devkit uses camera 0 poses; the errors are nearly the same in the LiDAR frame).
#ifndef RPSR_CORE_DATA_KITTI_ODOMETRY_METRICS_H_
#define RPSR_CORE_DATA_KITTI_ODOMETRY_METRICS_H_

#include <vector>

#include "Eigen/Geometry"
#include "absl/status/statusor.h"

namespace rpsr::core {

struct KittiOdometryMetricsOptions {
  // Segment lengths in metres (the benchmark's: 100, 200, ..., 800).
  std::vector<double> segment_lengths_m = {100, 200, 300, 400, 500, 600, 700, 800};
  // A segment starts every step_frames frames (the benchmark's: 10).
  int step_frames = 10;
};

// One evaluated segment.
struct KittiSegmentError {
  int first_frame = 0;
  int last_frame = 0;
  double length_m = 0.0;
  double translation_error_per_m = 0.0;   // ||t(E)|| / L (x 100 = percent)
  double rotation_error_rad_per_m = 0.0;  // angle(E) / L
};

struct KittiOdometryMetrics {
  // Means over every segment of every length; zero when segment_count is 0 (a trajectory shorter
  // than the shortest length: say so instead of printing the zeros).
  double translation_error_percent = 0.0;
  double rotation_error_deg_per_m = 0.0;
  int segment_count = 0;
  // The means per length, in the order of options.segment_lengths_m (a length without segments
  // gets count 0 and zeros).
  struct PerLength {
    double length_m = 0.0;
    int segment_count = 0;
    double translation_error_percent = 0.0;
    double rotation_error_deg_per_m = 0.0;
  };
  std::vector<PerLength> per_length;
  std::vector<KittiSegmentError> segments;
  // Distance travelled along the ground truth, metres.
  double path_length_m = 0.0;
};

// Cumulative distance travelled along `T_world_frame` (0 at frame 0).
std::vector<double> TrajectoryDistances(const std::vector<Eigen::Isometry3d>& T_world_frame);

// InvalidArgument when the trajectories differ in length, are empty, hold a non-finite pose, or
// when the options hold a non-positive length or step.
absl::StatusOr<KittiOdometryMetrics> ComputeKittiOdometryMetrics(
    const std::vector<Eigen::Isometry3d>& T_world_frame_estimate,
    const std::vector<Eigen::Isometry3d>& T_world_frame_truth,
    const KittiOdometryMetricsOptions& options = {});

}  // namespace rpsr::core

#endif  // RPSR_CORE_DATA_KITTI_ODOMETRY_METRICS_H_
