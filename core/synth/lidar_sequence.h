// A simulated drive: a vehicle with a roof-mounted LiDAR follows the right lane of a generated
// street scene, scanning at 10 Hz, with a smoothly varying speed. Frames are simulated in
// parallel and handed to a sink; core/data/simulated_kitti.h writes them in the KITTI odometry
// layout (the layout's writer lives with its reader in core/data, which may link core/synth but
// not the other way round).
#ifndef RPSR_CORE_SYNTH_LIDAR_SEQUENCE_H_
#define RPSR_CORE_SYNTH_LIDAR_SEQUENCE_H_

#include <cstdint>
#include <functional>
#include <memory>
#include <vector>

#include "Eigen/Core"
#include "Eigen/Geometry"
#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "core/synth/lidar_simulator.h"
#include "core/synth/street_scene.h"

namespace rpsr::core {

struct LidarSequenceOptions {
  StreetStyle style = StreetStyle::kUrbanCanyon;
  int frame_count = 300;
  // Scans a second (KITTI: 10).
  double frame_rate_hz = 10.0;
  // The speed varies smoothly (a sinusoid of random period 20-40 s) between these.
  double min_speed_mps = 5.0;
  double max_speed_mps = 15.0;
  // Height of the sensor above the ground (KITTI's Velodyne: 1.73 m).
  double sensor_height_m = 1.73;
  // Seeds the scene, the speed profile and every frame's noise.
  uint64_t seed = 1;
  LidarSensorOptions sensor;
  // Worker threads for SimulateAllFrames (frames are independent; results do not depend on it).
  int thread_count = 2;
};

class LidarSequenceSimulator {
 public:
  // Generates the scene (a road long enough for the drive plus the sensor's range ahead and
  // behind), plans the drive and indexes the scene. InvalidArgument for a frame count outside
  // [1, 100000], a non-positive rate, speeds not 0 < min <= max <= 50, a sensor height outside
  // (0, 10], a thread count outside [1, 256], or bad sensor options.
  static absl::StatusOr<LidarSequenceSimulator> Create(const LidarSequenceOptions& options);

  int frame_count() const { return static_cast<int>(T_world_lidar_.size()); }
  // Pose of the sensor at each frame in the scene's world frame (z up; the first frame is not
  // the origin).
  const std::vector<Eigen::Isometry3d>& T_world_lidar() const { return T_world_lidar_; }
  // Capture time of each frame (s), starting at 0.
  const std::vector<double>& timestamps_s() const { return timestamps_s_; }
  const StreetScene& scene() const { return *scene_; }
  const LidarSimulator& simulator() const { return simulator_; }

  // Simulates frame `frame` (0 <= frame < frame_count()); deterministic, thread-safe.
  LidarScan SimulateFrame(int frame) const;

  // Simulates every frame on options.thread_count threads and hands each to `sink` (called from
  // the worker threads, possibly concurrently and in any order). Stops at the first error a sink
  // returns and returns it.
  using FrameSink = std::function<absl::Status(int frame, LidarScan scan)>;
  absl::Status SimulateAllFrames(const FrameSink& sink) const;

 private:
  LidarSequenceSimulator(const LidarSequenceOptions& options,
                         std::shared_ptr<const StreetScene> scene, LidarSimulator simulator)
      : options_(options), scene_(std::move(scene)), simulator_(std::move(simulator)) {}

  LidarSequenceOptions options_;
  std::shared_ptr<const StreetScene> scene_;
  LidarSimulator simulator_;
  std::vector<Eigen::Isometry3d> T_world_lidar_;
  std::vector<double> timestamps_s_;
};

// Poses of a sensor `sensor_height_m` above the ground, driving along the scene's road
// `lane_offset_m` to the right of its centre line, starting `start_arc_m` along it, one pose a
// timestamp; `speed_at` gives the speed (m/s) at a time. Heading follows the lane's tangent; pitch
// and roll follow the ground's slope. InvalidArgument when the scene has no road.
absl::StatusOr<std::vector<Eigen::Isometry3d>> PlanDrive(
    const StreetScene& scene, const std::vector<double>& timestamps_s, double start_arc_m,
    double lane_offset_m, double sensor_height_m, const std::function<double(double)>& speed_at);

}  // namespace rpsr::core

#endif  // RPSR_CORE_SYNTH_LIDAR_SEQUENCE_H_
