#include "core/data/kitti_odometry.h"

#include <charconv>
#include <cmath>
#include <filesystem>
#include <system_error>

#include "absl/strings/ascii.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_split.h"
#include "core/data/semantic_labels.h"
#include "core/io/file_bytes.h"
#include "core/io/kitti_bin.h"

namespace rpsr::core {

namespace {

namespace fs = std::filesystem;

std::vector<absl::string_view> SplitLines(absl::string_view text) {
  std::vector<absl::string_view> lines = absl::StrSplit(text, '\n');
  for (absl::string_view& line : lines) {
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
  }
  // Drop trailing blank lines (a final newline gives one empty piece).
  while (!lines.empty() && absl::StripAsciiWhitespace(lines.back()).empty()) lines.pop_back();
  return lines;
}

// Parses the whitespace-separated numbers of `fields`; `where` prefixes errors ("poses.txt line
// 3").
absl::Status ParseNumbers(absl::string_view fields, size_t expected, absl::string_view where,
                          std::vector<double>* values) {
  std::vector<absl::string_view> tokens =
      absl::StrSplit(fields, absl::ByAnyChar(" \t\r\v\f"), absl::SkipEmpty());
  if (tokens.size() != expected) {
    return absl::InvalidArgumentError(
        absl::StrCat(where, ": expected ", expected, " numbers, found ", tokens.size()));
  }
  values->clear();
  for (absl::string_view token : tokens) {
    double value = 0.0;
    if (!absl::SimpleAtod(token, &value)) {
      return absl::InvalidArgumentError(absl::StrCat(where, ": '", token, "' is not a number"));
    }
    if (!std::isfinite(value)) {
      return absl::InvalidArgumentError(absl::StrCat(where, ": '", token, "' is not finite"));
    }
    values->push_back(value);
  }
  return absl::OkStatus();
}

Eigen::Isometry3d IsometryFromRowMajor3x4(const std::vector<double>& v) {
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  for (int row = 0; row < 3; ++row) {
    for (int col = 0; col < 4; ++col) pose.matrix()(row, col) = v[row * 4 + col];
  }
  return pose;
}

void AppendExact(double value, std::string* out) {
  char buffer[64];
  const auto result = std::to_chars(buffer, buffer + sizeof(buffer), value);
  out->append(buffer, result.ptr);
}

void AppendRowMajor3x4(const Eigen::Matrix<double, 3, 4>& m, std::string* out) {
  for (int row = 0; row < 3; ++row) {
    for (int col = 0; col < 4; ++col) {
      if (row != 0 || col != 0) out->push_back(' ');
      AppendExact(m(row, col), out);
    }
  }
}

// General inverse: calib files carry rotations orthonormal only to about 1e-9.
Eigen::Isometry3d Inverse(const Eigen::Isometry3d& T) {
  Eigen::Isometry3d inverse;
  inverse.matrix() = T.matrix().inverse();
  return inverse;
}

}  // namespace

std::string KittiSequenceDirectory(const std::string& dataset_root, int sequence) {
  return absl::StrCat(dataset_root, "/sequences/", absl::StrFormat("%02d", sequence));
}

std::string KittiScanPath(const std::string& sequence_dir, int frame) {
  return absl::StrCat(sequence_dir, "/velodyne/", absl::StrFormat("%06d", frame), ".bin");
}

std::string KittiLabelPath(const std::string& sequence_dir, int frame) {
  return absl::StrCat(sequence_dir, "/labels/", absl::StrFormat("%06d", frame), ".label");
}

absl::StatusOr<std::vector<Eigen::Isometry3d>> ParseKittiPoses(absl::string_view text,
                                                               absl::string_view name) {
  std::vector<Eigen::Isometry3d> poses;
  std::vector<double> values;
  const std::vector<absl::string_view> lines = SplitLines(text);
  for (size_t i = 0; i < lines.size(); ++i) {
    const std::string where = absl::StrCat(name, " line ", i + 1);
    if (absl::StripAsciiWhitespace(lines[i]).empty()) {
      return absl::InvalidArgumentError(
          absl::StrCat(where, ": blank line between poses (one pose a frame, no gaps)"));
    }
    absl::Status status = ParseNumbers(lines[i], 12, where, &values);
    if (!status.ok()) return status;
    poses.push_back(IsometryFromRowMajor3x4(values));
  }
  return poses;
}

std::string FormatKittiPoses(const std::vector<Eigen::Isometry3d>& poses) {
  std::string text;
  for (const Eigen::Isometry3d& pose : poses) {
    AppendRowMajor3x4(pose.matrix().topRows<3>(), &text);
    text.push_back('\n');
  }
  return text;
}

absl::StatusOr<Eigen::Isometry3d> ParseKittiCalibTr(absl::string_view text,
                                                    absl::string_view name) {
  const std::vector<absl::string_view> lines = SplitLines(text);
  for (size_t i = 0; i < lines.size(); ++i) {
    const absl::string_view line = absl::StripLeadingAsciiWhitespace(lines[i]);
    for (absl::string_view key : {"Tr:", "Tr_velo_to_cam:"}) {
      if (!absl::StartsWith(line, key)) continue;
      std::vector<double> values;
      absl::Status status =
          ParseNumbers(line.substr(key.size()), 12, absl::StrCat(name, " line ", i + 1), &values);
      if (!status.ok()) return status;
      return IsometryFromRowMajor3x4(values);
    }
  }
  return absl::InvalidArgumentError(
      absl::StrCat(name, ": no 'Tr:' line (the LiDAR-to-camera transform) found"));
}

std::string FormatKittiCalib(const Eigen::Isometry3d& T_camera_lidar) {
  // Sequence 00's rectified projection matrices (focal length, principal point, baselines).
  const double f = 718.856, cx = 607.1928, cy = 185.2157;
  const double tx[4] = {0.0, -386.1448, 45.38225, -337.2877};
  std::string text;
  for (int camera = 0; camera < 4; ++camera) {
    Eigen::Matrix<double, 3, 4> P;
    P << f, 0, cx, tx[camera], 0, f, cy, 0, 0, 0, 1, 0;
    absl::StrAppend(&text, "P", camera, ": ");
    AppendRowMajor3x4(P, &text);
    text.push_back('\n');
  }
  text.append("Tr: ");
  AppendRowMajor3x4(T_camera_lidar.matrix().topRows<3>(), &text);
  text.push_back('\n');
  return text;
}

absl::StatusOr<std::vector<double>> ParseKittiTimes(absl::string_view text,
                                                    absl::string_view name) {
  std::vector<double> times;
  std::vector<double> values;
  const std::vector<absl::string_view> lines = SplitLines(text);
  for (size_t i = 0; i < lines.size(); ++i) {
    const std::string where = absl::StrCat(name, " line ", i + 1);
    absl::Status status = ParseNumbers(lines[i], 1, where, &values);
    if (!status.ok()) return status;
    if (values[0] < 0.0) {
      return absl::InvalidArgumentError(absl::StrCat(where, ": negative timestamp"));
    }
    times.push_back(values[0]);
  }
  return times;
}

std::vector<Eigen::Isometry3d> LidarPosesFromCameraPoses(
    const std::vector<Eigen::Isometry3d>& T_world_camera, const Eigen::Isometry3d& T_camera_lidar) {
  const Eigen::Isometry3d T_lidar_camera = Inverse(T_camera_lidar);
  std::vector<Eigen::Isometry3d> poses;
  poses.reserve(T_world_camera.size());
  for (const Eigen::Isometry3d& P : T_world_camera) {
    poses.push_back(T_lidar_camera * P * T_camera_lidar);
  }
  return poses;
}

std::vector<Eigen::Isometry3d> CameraPosesFromLidarPoses(
    const std::vector<Eigen::Isometry3d>& T_world_lidar, const Eigen::Isometry3d& T_camera_lidar) {
  const Eigen::Isometry3d T_lidar_camera = Inverse(T_camera_lidar);
  std::vector<Eigen::Isometry3d> poses;
  poses.reserve(T_world_lidar.size());
  for (const Eigen::Isometry3d& T : T_world_lidar) {
    poses.push_back(T_camera_lidar * T * T_lidar_camera);
  }
  return poses;
}

Eigen::Isometry3d KittiLikeCameraFromLidar() {
  Eigen::Matrix3d axes;
  axes << 0, -1, 0,  //
      0, 0, -1,      //
      1, 0, 0;
  const Eigen::Matrix3d tilt = (Eigen::AngleAxisd(0.0072, Eigen::Vector3d::UnitX()) *
                                Eigen::AngleAxisd(-0.0081, Eigen::Vector3d::UnitY()) *
                                Eigen::AngleAxisd(0.0004, Eigen::Vector3d::UnitZ()))
                                   .toRotationMatrix();
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = tilt * axes;
  T.translation() = Eigen::Vector3d(-0.0120, -0.0540, -0.2922);
  return T;
}

absl::StatusOr<KittiOdometrySequence> KittiOdometrySequence::Open(const std::string& dataset_root,
                                                                  int sequence) {
  KittiOdometrySequence result;
  result.sequence_ = sequence;
  result.directory_ = KittiSequenceDirectory(dataset_root, sequence);
  const std::string& dir = result.directory_;

  const std::string calib_path = dir + "/calib.txt";
  absl::StatusOr<std::string> calib = ReadFileBytes(calib_path, size_t{1} << 20);
  if (!calib.ok()) return calib.status();
  absl::StatusOr<Eigen::Isometry3d> tr = ParseKittiCalibTr(*calib, calib_path);
  if (!tr.ok()) return tr.status();
  result.T_camera_lidar_ = *tr;

  std::string poses_path = dir + "/poses.txt";
  absl::StatusOr<std::string> poses_text = ReadFileBytes(poses_path, size_t{256} << 20);
  if (absl::IsNotFound(poses_text.status())) {
    const std::string fallback =
        absl::StrCat(dataset_root, "/poses/", absl::StrFormat("%02d", sequence), ".txt");
    poses_text = ReadFileBytes(fallback, size_t{256} << 20);
    if (absl::IsNotFound(poses_text.status())) {
      return absl::NotFoundError(
          absl::StrCat("no poses for sequence ", sequence, ": neither ", poses_path, " nor ",
                       fallback, " exists (KITTI's test sequences 11-21 have no ground truth)"));
    }
    poses_path = fallback;
  }
  if (!poses_text.ok()) return poses_text.status();
  absl::StatusOr<std::vector<Eigen::Isometry3d>> poses = ParseKittiPoses(*poses_text, poses_path);
  if (!poses.ok()) return poses.status();
  result.T_world_camera_ = *std::move(poses);
  result.T_world_lidar_ = LidarPosesFromCameraPoses(result.T_world_camera_, result.T_camera_lidar_);

  const std::string velodyne_dir = dir + "/velodyne";
  std::error_code error;
  if (!fs::is_directory(velodyne_dir, error)) {
    return absl::NotFoundError(absl::StrCat(velodyne_dir, ": no such folder of scans"));
  }
  size_t scan_count = 0;
  for (const fs::directory_entry& entry : fs::directory_iterator(velodyne_dir, error)) {
    if (entry.path().extension() == ".bin") ++scan_count;
  }
  if (error) {
    return absl::PermissionDeniedError(
        absl::StrCat(velodyne_dir, ": cannot list: ", error.message()));
  }
  if (scan_count != result.T_world_camera_.size()) {
    return absl::FailedPreconditionError(absl::StrCat(
        poses_path, " has ", result.T_world_camera_.size(), " poses but ", velodyne_dir, " holds ",
        scan_count, " .bin scans; the sequence is incomplete"));
  }

  const std::string times_path = dir + "/times.txt";
  absl::StatusOr<std::string> times_text = ReadFileBytes(times_path, size_t{64} << 20);
  if (times_text.ok()) {
    absl::StatusOr<std::vector<double>> times = ParseKittiTimes(*times_text, times_path);
    if (!times.ok()) return times.status();
    if (times->size() != result.T_world_camera_.size()) {
      return absl::FailedPreconditionError(absl::StrCat(times_path, " has ", times->size(),
                                                        " timestamps but ", poses_path, " has ",
                                                        result.T_world_camera_.size(), " poses"));
    }
    result.timestamps_s_ = *std::move(times);
  } else if (!absl::IsNotFound(times_text.status())) {
    return times_text.status();
  }
  result.has_labels_ = fs::is_directory(dir + "/labels", error);
  return result;
}

Eigen::Isometry3d KittiOdometrySequence::T_target_source(int source_frame, int target_frame) const {
  return T_world_lidar_[target_frame].inverse(Eigen::Isometry) * T_world_lidar_[source_frame];
}

absl::StatusOr<PointCloud> KittiOdometrySequence::ReadScan(int frame) const {
  if (frame < 0 || frame >= frame_count()) {
    return absl::OutOfRangeError(
        absl::StrCat(directory_, ": frame ", frame, " is outside [0, ", frame_count(), ")"));
  }
  return ReadKittiBin(KittiScanPath(directory_, frame));
}

absl::StatusOr<LabeledScan> KittiOdometrySequence::ReadLabeledScan(int frame) const {
  if (!has_labels_) {
    return absl::FailedPreconditionError(
        absl::StrCat(directory_, "/labels: no such folder; SemanticKITTI labels are needed"));
  }
  absl::StatusOr<PointCloud> cloud = ReadScan(frame);
  if (!cloud.ok()) return cloud.status();
  const std::string label_path = KittiLabelPath(directory_, frame);
  absl::StatusOr<std::vector<uint32_t>> labels = ReadSemanticKittiLabels(label_path);
  if (!labels.ok()) return labels.status();
  if (labels->size() != cloud->size()) {
    return absl::InvalidArgumentError(absl::StrCat(label_path, ": ", labels->size(), " labels but ",
                                                   KittiScanPath(directory_, frame), " has ",
                                                   cloud->size(), " points"));
  }
  LabeledScan scan;
  scan.cloud = *std::move(cloud);
  scan.labels = *std::move(labels);
  return scan;
}

absl::StatusOr<KittiSequenceWriter> KittiSequenceWriter::Create(
    const std::string& dataset_root, int sequence, const Eigen::Isometry3d& T_camera_lidar) {
  KittiSequenceWriter writer;
  writer.directory_ = KittiSequenceDirectory(dataset_root, sequence);
  writer.T_camera_lidar_ = T_camera_lidar;
  for (const char* sub : {"/velodyne", "/labels"}) {
    std::error_code error;
    const std::string path = writer.directory_ + sub;
    fs::create_directories(path, error);
    if (error) {
      return absl::PermissionDeniedError(
          absl::StrCat(path, ": cannot create folder: ", error.message()));
    }
  }
  absl::Status status =
      WriteFileBytes(writer.directory_ + "/calib.txt", FormatKittiCalib(T_camera_lidar));
  if (!status.ok()) return status;
  return writer;
}

absl::Status KittiSequenceWriter::WriteFrame(int frame, const PointCloud& cloud,
                                             const std::vector<uint32_t>* labels) const {
  if (frame < 0 || frame > 999999) {
    return absl::InvalidArgumentError(
        absl::StrCat(directory_, ": frame ", frame, " is outside [0, 999999]"));
  }
  if (labels != nullptr && labels->size() != cloud.size()) {
    return absl::InvalidArgumentError(absl::StrCat(KittiLabelPath(directory_, frame), ": ",
                                                   labels->size(), " labels for ", cloud.size(),
                                                   " points"));
  }
  absl::Status status = WriteKittiBin(KittiScanPath(directory_, frame), cloud);
  if (!status.ok() || labels == nullptr) return status;
  return WriteSemanticKittiLabels(KittiLabelPath(directory_, frame), *labels);
}

absl::Status KittiSequenceWriter::WritePoses(const std::vector<Eigen::Isometry3d>& T_world_lidar,
                                             const std::vector<double>& timestamps_s) const {
  if (!timestamps_s.empty() && timestamps_s.size() != T_world_lidar.size()) {
    return absl::InvalidArgumentError(absl::StrCat(
        directory_, ": ", timestamps_s.size(), " timestamps for ", T_world_lidar.size(), " poses"));
  }
  std::vector<Eigen::Isometry3d> relative;
  relative.reserve(T_world_lidar.size());
  for (const Eigen::Isometry3d& pose : T_world_lidar) {
    relative.push_back(T_world_lidar.front().inverse(Eigen::Isometry) * pose);
  }
  absl::Status status =
      WriteFileBytes(directory_ + "/poses.txt",
                     FormatKittiPoses(CameraPosesFromLidarPoses(relative, T_camera_lidar_)));
  if (!status.ok() || timestamps_s.empty()) return status;
  std::string times;
  for (double t : timestamps_s) {
    absl::StrAppend(&times, absl::StrFormat("%e", t), "\n");
  }
  return WriteFileBytes(directory_ + "/times.txt", times);
}

}  // namespace rpsr::core
