#include "core/data/kitti_odometry_metrics.h"

#include <algorithm>
#include <cmath>
#include <numbers>

#include "absl/strings/str_cat.h"

namespace rpsr::core {
namespace {

bool IsFinite(const Eigen::Isometry3d& T) { return T.matrix().allFinite(); }

// The devkit's rotationError: acos((trace - 1) / 2) with the cosine clamped into [-1, 1].
double RotationAngle(const Eigen::Isometry3d& T) {
  const double cosine = 0.5 * (T.linear().trace() - 1.0);
  return std::acos(std::clamp(cosine, -1.0, 1.0));
}

// The devkit's lastFrameFromSegmentLength: the first frame whose distance exceeds the first
// frame's by more than `length`; -1 when none.
int LastFrameOfSegment(const std::vector<double>& distances, int first_frame, double length) {
  for (size_t i = static_cast<size_t>(first_frame); i < distances.size(); ++i) {
    if (distances[i] > distances[first_frame] + length) return static_cast<int>(i);
  }
  return -1;
}

}  // namespace

std::vector<double> TrajectoryDistances(const std::vector<Eigen::Isometry3d>& T_world_frame) {
  std::vector<double> distances;
  distances.reserve(T_world_frame.size());
  for (size_t i = 0; i < T_world_frame.size(); ++i) {
    distances.push_back(
        i == 0 ? 0.0
               : distances.back() +
                     (T_world_frame[i].translation() - T_world_frame[i - 1].translation()).norm());
  }
  return distances;
}

absl::StatusOr<KittiOdometryMetrics> ComputeKittiOdometryMetrics(
    const std::vector<Eigen::Isometry3d>& T_world_frame_estimate,
    const std::vector<Eigen::Isometry3d>& T_world_frame_truth,
    const KittiOdometryMetricsOptions& options) {
  if (T_world_frame_truth.empty()) {
    return absl::InvalidArgumentError("the ground-truth trajectory is empty");
  }
  if (T_world_frame_estimate.size() != T_world_frame_truth.size()) {
    return absl::InvalidArgumentError(absl::StrCat(
        "the estimated trajectory has ", T_world_frame_estimate.size(),
        " poses and the ground truth ", T_world_frame_truth.size(), ": they must match"));
  }
  if (options.step_frames <= 0) {
    return absl::InvalidArgumentError(
        absl::StrCat("step_frames must be positive, got ", options.step_frames));
  }
  for (double length : options.segment_lengths_m) {
    if (!(length > 0.0) || !std::isfinite(length)) {
      return absl::InvalidArgumentError(
          absl::StrCat("segment lengths must be positive and finite, got ", length));
    }
  }
  for (size_t i = 0; i < T_world_frame_truth.size(); ++i) {
    if (!IsFinite(T_world_frame_truth[i]) || !IsFinite(T_world_frame_estimate[i])) {
      return absl::InvalidArgumentError(
          absl::StrCat("pose of frame ", i, " is not finite in the ",
                       IsFinite(T_world_frame_truth[i]) ? "estimate" : "ground truth"));
    }
  }

  KittiOdometryMetrics metrics;
  const std::vector<double> distances = TrajectoryDistances(T_world_frame_truth);
  metrics.path_length_m = distances.back();
  metrics.per_length.resize(options.segment_lengths_m.size());
  for (size_t l = 0; l < options.segment_lengths_m.size(); ++l) {
    metrics.per_length[l].length_m = options.segment_lengths_m[l];
  }
  const int frame_count = static_cast<int>(T_world_frame_truth.size());
  for (int first = 0; first < frame_count; first += options.step_frames) {
    for (size_t l = 0; l < options.segment_lengths_m.size(); ++l) {
      const double length = options.segment_lengths_m[l];
      const int last = LastFrameOfSegment(distances, first, length);
      if (last < 0) continue;
      const Eigen::Isometry3d delta_truth =
          T_world_frame_truth[first].inverse() * T_world_frame_truth[last];
      const Eigen::Isometry3d delta_estimate =
          T_world_frame_estimate[first].inverse() * T_world_frame_estimate[last];
      const Eigen::Isometry3d error = delta_estimate.inverse() * delta_truth;
      KittiSegmentError segment;
      segment.first_frame = first;
      segment.last_frame = last;
      segment.length_m = length;
      segment.translation_error_per_m = error.translation().norm() / length;
      segment.rotation_error_rad_per_m = RotationAngle(error) / length;
      metrics.segments.push_back(segment);
      KittiOdometryMetrics::PerLength& per_length = metrics.per_length[l];
      ++per_length.segment_count;
      per_length.translation_error_percent += segment.translation_error_per_m;
      per_length.rotation_error_deg_per_m += segment.rotation_error_rad_per_m;
    }
  }
  constexpr double kDegrees = 180.0 / std::numbers::pi;
  for (KittiOdometryMetrics::PerLength& per_length : metrics.per_length) {
    if (per_length.segment_count == 0) continue;
    per_length.translation_error_percent *= 100.0 / per_length.segment_count;
    per_length.rotation_error_deg_per_m *= kDegrees / per_length.segment_count;
  }
  metrics.segment_count = static_cast<int>(metrics.segments.size());
  if (metrics.segment_count > 0) {
    for (const KittiSegmentError& segment : metrics.segments) {
      metrics.translation_error_percent += segment.translation_error_per_m;
      metrics.rotation_error_deg_per_m += segment.rotation_error_rad_per_m;
    }
    metrics.translation_error_percent *= 100.0 / metrics.segment_count;
    metrics.rotation_error_deg_per_m *= kDegrees / metrics.segment_count;
  }
  return metrics;
}

}  // namespace rpsr::core
