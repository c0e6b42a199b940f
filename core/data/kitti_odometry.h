// The KITTI odometry layout (with SemanticKITTI's labels), read and written:
//
//   <root>/sequences/NN/velodyne/000000.bin ...   scans (core/io/kitti_bin.h)
//   <root>/sequences/NN/labels/000000.label ...   SemanticKITTI labels (optional)
//   <root>/sequences/NN/calib.txt                 P0..P3 and Tr (camera 0 <- LiDAR)
//   <root>/sequences/NN/poses.txt                 one pose a frame (SemanticKITTI's copy); KITTI
//                                                 itself ships it as <root>/poses/NN.txt, which
//                                                 the reader falls back to
//   <root>/sequences/NN/times.txt                 one timestamp (s) a frame (optional)
//
// Poses: line i of poses.txt is the 3x4 row-major [R | t] of camera 0 at frame i in the world
// frame, which is camera 0 at frame 0: P_i = T_world_camera_i. With Tr = T_camera_lidar from
// calib.txt, the LiDAR's pose in the world frame of the first LiDAR scan is
//   T_world_lidar_i = Tr^-1 * P_i * Tr.
// The ground truth of a pair whose source is frame i and target frame j is
//   T_target_source = T_world_lidar_j^-1 * T_world_lidar_i,
// which maps points of scan i (its LiDAR frame) into scan j's LiDAR frame (see DESIGN.md).
#ifndef RPSR_CORE_DATA_KITTI_ODOMETRY_H_
#define RPSR_CORE_DATA_KITTI_ODOMETRY_H_

#include <cstdint>
#include <string>
#include <vector>

#include "Eigen/Geometry"
#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"
#include "core/cloud/point_cloud.h"

namespace rpsr::core {

// <root>/sequences/NN (two digits, more when the number needs them).
std::string KittiSequenceDirectory(const std::string& dataset_root, int sequence);
// <sequence_dir>/velodyne/NNNNNN.bin and <sequence_dir>/labels/NNNNNN.label.
std::string KittiScanPath(const std::string& sequence_dir, int frame);
std::string KittiLabelPath(const std::string& sequence_dir, int frame);

// Parses poses.txt: one line of 12 numbers (3x4 row-major) a frame; trailing blank lines are
// ignored. InvalidArgument naming `name` and the 1-based line for a line with another count of
// numbers, a token that is not a number, a non-finite value or a blank line between poses.
absl::StatusOr<std::vector<Eigen::Isometry3d>> ParseKittiPoses(absl::string_view text,
                                                               absl::string_view name);
// Formats poses as poses.txt lines, each number in the shortest form that reads back exactly.
std::string FormatKittiPoses(const std::vector<Eigen::Isometry3d>& poses);

// T_camera_lidar from calib.txt's "Tr:" line (the raw KITTI name "Tr_velo_to_cam:" is accepted
// too). InvalidArgument naming `name` (and the line) when it is missing, malformed or not finite.
absl::StatusOr<Eigen::Isometry3d> ParseKittiCalibTr(absl::string_view text, absl::string_view name);
// Formats calib.txt: KITTI-like P0..P3 (grey and colour cameras of sequence 00) and `Tr`.
std::string FormatKittiCalib(const Eigen::Isometry3d& T_camera_lidar);

// Parses times.txt: one non-negative finite number a line, line numbers in errors.
absl::StatusOr<std::vector<double>> ParseKittiTimes(absl::string_view text, absl::string_view name);

// T_world_lidar_i = Tr^-1 * P_i * Tr and its inverse mapping P_i = Tr * T_world_lidar_i * Tr^-1.
std::vector<Eigen::Isometry3d> LidarPosesFromCameraPoses(
    const std::vector<Eigen::Isometry3d>& T_world_camera, const Eigen::Isometry3d& T_camera_lidar);
std::vector<Eigen::Isometry3d> CameraPosesFromLidarPoses(
    const std::vector<Eigen::Isometry3d>& T_world_lidar, const Eigen::Isometry3d& T_camera_lidar);

// A KITTI-like Tr (close to sequence 00's: x_cam = -y_lidar, y_cam = -z_lidar, z_cam = x_lidar,
// turned by a few milliradians and offset by centimetres), exactly orthonormal. The simulator
// writes it.
Eigen::Isometry3d KittiLikeCameraFromLidar();

struct LabeledScan {
  PointCloud cloud;
  // One SemanticKITTI label per point.
  std::vector<uint32_t> labels;
};

// One sequence of a KITTI odometry data set. Opening reads calib, poses and times; scans and
// labels are read on demand. Safe to read frames from several threads at once.
class KittiOdometrySequence {
 public:
  // Opens <root>/sequences/NN. Errors name the file and, for text files, the line:
  // NotFound when calib.txt, the poses (sequences/NN/poses.txt or poses/NN.txt) or velodyne/ are
  // missing; InvalidArgument for malformed calib, poses or times; FailedPrecondition when the
  // number of scans in velodyne/ or of lines in times.txt differs from the number of poses.
  static absl::StatusOr<KittiOdometrySequence> Open(const std::string& dataset_root, int sequence);

  int sequence() const { return sequence_; }
  const std::string& directory() const { return directory_; }
  int frame_count() const { return static_cast<int>(T_world_lidar_.size()); }
  // Tr from calib.txt.
  const Eigen::Isometry3d& T_camera_lidar() const { return T_camera_lidar_; }
  // poses.txt as read (camera 0 poses).
  const std::vector<Eigen::Isometry3d>& T_world_camera() const { return T_world_camera_; }
  // LiDAR poses (Tr^-1 * P_i * Tr).
  const std::vector<Eigen::Isometry3d>& T_world_lidar() const { return T_world_lidar_; }
  // times.txt, or empty when the sequence has none.
  const std::vector<double>& timestamps_s() const { return timestamps_s_; }
  // True when the sequence has a labels/ folder.
  bool has_labels() const { return has_labels_; }

  // Maps points of scan `source_frame` into scan `target_frame`'s LiDAR frame.
  Eigen::Isometry3d T_target_source(int source_frame, int target_frame) const;

  // OutOfRange for a frame outside [0, frame_count()); otherwise ReadKittiBin's errors.
  absl::StatusOr<PointCloud> ReadScan(int frame) const;
  // The scan with its labels. FailedPrecondition when the sequence has no labels/ folder;
  // InvalidArgument naming the label file when its label count differs from the scan's points.
  absl::StatusOr<LabeledScan> ReadLabeledScan(int frame) const;

 private:
  int sequence_ = 0;
  std::string directory_;
  Eigen::Isometry3d T_camera_lidar_ = Eigen::Isometry3d::Identity();
  std::vector<Eigen::Isometry3d> T_world_camera_;
  std::vector<Eigen::Isometry3d> T_world_lidar_;
  std::vector<double> timestamps_s_;
  bool has_labels_ = false;
};

// Writes one sequence in the layout above. Frames may be written from several threads at once.
class KittiSequenceWriter {
 public:
  // Creates <root>/sequences/NN/{velodyne,labels} and writes calib.txt with `T_camera_lidar`.
  static absl::StatusOr<KittiSequenceWriter> Create(const std::string& dataset_root, int sequence,
                                                    const Eigen::Isometry3d& T_camera_lidar);

  const std::string& directory() const { return directory_; }

  // Writes velodyne/NNNNNN.bin and, when `labels` is non-null, labels/NNNNNN.label (its size must
  // match the cloud's).
  absl::Status WriteFrame(int frame, const PointCloud& cloud,
                          const std::vector<uint32_t>* labels) const;

  // Writes poses.txt from LiDAR poses (converted to camera 0 poses relative to the first frame,
  // so that the reader's T_world_lidar() returns T_world_lidar[0]^-1 * T_world_lidar[i]) and, when
  // non-empty, times.txt (same count).
  absl::Status WritePoses(const std::vector<Eigen::Isometry3d>& T_world_lidar,
                          const std::vector<double>& timestamps_s) const;

 private:
  std::string directory_;
  Eigen::Isometry3d T_camera_lidar_ = Eigen::Isometry3d::Identity();
};

}  // namespace rpsr::core

#endif  // RPSR_CORE_DATA_KITTI_ODOMETRY_H_
