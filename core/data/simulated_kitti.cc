#include "core/data/simulated_kitti.h"

#include <algorithm>
#include <chrono>
#include <limits>
#include <mutex>

#include "core/data/semantic_labels.h"

namespace rpsr::core {

absl::StatusOr<SimulatedKittiSummary> WriteSimulatedKittiSequence(
    const std::string& dataset_root, int sequence, const LidarSequenceOptions& options,
    const Eigen::Isometry3d& T_camera_lidar) {
  const auto start = std::chrono::steady_clock::now();
  absl::StatusOr<LidarSequenceSimulator> simulator = LidarSequenceSimulator::Create(options);
  if (!simulator.ok()) return simulator.status();
  absl::StatusOr<KittiSequenceWriter> writer =
      KittiSequenceWriter::Create(dataset_root, sequence, T_camera_lidar);
  if (!writer.ok()) return writer.status();

  SimulatedKittiSummary summary;
  summary.frame_count = simulator->frame_count();
  summary.min_points_per_scan = std::numeric_limits<size_t>::max();
  std::mutex summary_mutex;
  absl::Status status = simulator->SimulateAllFrames([&](int frame, LidarScan scan) {
    std::vector<uint32_t> labels(scan.labels.size());
    for (size_t i = 0; i < labels.size(); ++i) labels[i] = MakeSemanticKittiLabel(scan.labels[i]);
    {
      std::lock_guard<std::mutex> lock(summary_mutex);
      summary.total_points += scan.cloud.size();
      summary.min_points_per_scan = std::min(summary.min_points_per_scan, scan.cloud.size());
      summary.max_points_per_scan = std::max(summary.max_points_per_scan, scan.cloud.size());
    }
    return writer->WriteFrame(frame, scan.cloud, &labels);
  });
  if (!status.ok()) return status;
  status = writer->WritePoses(simulator->T_world_lidar(), simulator->timestamps_s());
  if (!status.ok()) return status;
  summary.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return summary;
}

}  // namespace rpsr::core
