#include "core/synth/lidar_sequence.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <mutex>
#include <thread>

#include "absl/strings/str_cat.h"
#include "core/synth/seeded_random.h"

namespace rpsr::core {

namespace {

// Seed stream numbers (DeriveSeed) of the parts of a sequence.
constexpr uint64_t kSceneStream = 1;
constexpr uint64_t kSpeedStream = 2;
constexpr uint64_t kFrameStreamBase = 1000;

// Point `lateral` metres left of the centre line at arc length s (linear between its points).
Eigen::Vector2d CenterlinePoint(const std::vector<Eigen::Vector2f>& line,
                                const std::vector<double>& arc, double s, double lateral) {
  s = std::clamp(s, 0.0, arc.back());
  size_t i = std::upper_bound(arc.begin(), arc.end(), s) - arc.begin();
  i = std::clamp<size_t>(i, 1, line.size() - 1);
  const Eigen::Vector2d a = line[i - 1].cast<double>(), b = line[i].cast<double>();
  const double segment = std::max(arc[i] - arc[i - 1], 1e-9);
  const Eigen::Vector2d tangent = (b - a) / segment;
  return a + (s - arc[i - 1]) * tangent + lateral * Eigen::Vector2d(-tangent.y(), tangent.x());
}

}  // namespace

absl::StatusOr<std::vector<Eigen::Isometry3d>> PlanDrive(
    const StreetScene& scene, const std::vector<double>& timestamps_s, double start_arc_m,
    double lane_offset_m, double sensor_height_m, const std::function<double(double)>& speed_at) {
  const std::vector<Eigen::Vector2f>& line = scene.road_centerline;
  if (line.size() < 2) {
    return absl::InvalidArgumentError("PlanDrive: the scene has no road centre line");
  }
  std::vector<double> arc(line.size(), 0.0);
  for (size_t i = 1; i < line.size(); ++i) {
    arc[i] = arc[i - 1] + (line[i] - line[i - 1]).cast<double>().norm();
  }
  std::vector<Eigen::Isometry3d> poses;
  poses.reserve(timestamps_s.size());
  double s = start_arc_m, time = timestamps_s.empty() ? 0.0 : timestamps_s.front();
  constexpr double kIntegrationStep = 0.005;  // s
  for (double stamp : timestamps_s) {
    while (time + 1e-12 < stamp) {
      const double dt = std::min(kIntegrationStep, stamp - time);
      s += dt * speed_at(time + 0.5 * dt);
      time += dt;
    }
    const Eigen::Vector2d xy = CenterlinePoint(line, arc, s, -lane_offset_m);
    // Heading from a central difference over 3 m, so it turns smoothly through curves.
    const Eigen::Vector2d ahead = CenterlinePoint(line, arc, s + 1.5, -lane_offset_m);
    const Eigen::Vector2d behind = CenterlinePoint(line, arc, s - 1.5, -lane_offset_m);
    Eigen::Vector2d heading = ahead - behind;
    if (heading.norm() < 1e-9) heading = Eigen::Vector2d::UnitX();
    heading.normalize();
    const float x = static_cast<float>(xy.x()), y = static_cast<float>(xy.y());
    const Eigen::Vector2d grad = scene.ground.GradientAt(x, y).cast<double>();
    const Eigen::Vector3d up = Eigen::Vector3d(-grad.x(), -grad.y(), 1.0).normalized();
    const Eigen::Vector3d forward_flat(heading.x(), heading.y(), 0.0);
    const Eigen::Vector3d forward = (forward_flat - forward_flat.dot(up) * up).normalized();
    const Eigen::Vector3d left = up.cross(forward);
    Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
    pose.linear().col(0) = forward;
    pose.linear().col(1) = left;
    pose.linear().col(2) = up;
    pose.translation() =
        Eigen::Vector3d(xy.x(), xy.y(), scene.ground.HeightAt(x, y)) + sensor_height_m * up;
    poses.push_back(pose);
  }
  return poses;
}

absl::StatusOr<LidarSequenceSimulator> LidarSequenceSimulator::Create(
    const LidarSequenceOptions& options) {
  auto invalid = [](auto&&... parts) {
    return absl::InvalidArgumentError(absl::StrCat("LidarSequenceSimulator: ", parts...));
  };
  if (options.frame_count < 1 || options.frame_count > 100000) {
    return invalid("frame_count must be in [1, 100000], got ", options.frame_count);
  }
  if (!(options.frame_rate_hz > 0.0 && options.frame_rate_hz <= 1000.0)) {
    return invalid("frame_rate_hz must be in (0, 1000], got ", options.frame_rate_hz);
  }
  if (!(options.min_speed_mps > 0.0 && options.min_speed_mps <= options.max_speed_mps &&
        options.max_speed_mps <= 50.0)) {
    return invalid("need 0 < min_speed_mps <= max_speed_mps <= 50, got ", options.min_speed_mps,
                   " and ", options.max_speed_mps);
  }
  if (!(options.sensor_height_m > 0.0 && options.sensor_height_m <= 10.0)) {
    return invalid("sensor_height_m must be in (0, 10], got ", options.sensor_height_m);
  }
  if (options.thread_count < 1 || options.thread_count > 256) {
    return invalid("thread_count must be in [1, 256], got ", options.thread_count);
  }

  const double duration_s = (options.frame_count - 1) / options.frame_rate_hz;
  // Scene behind the start and ahead of the end, so that every scan sees a full street.
  const double margin_m = std::min(options.sensor.max_range_m, 150.0) + 30.0;
  StreetSceneOptions scene_options;
  scene_options.style = options.style;
  scene_options.seed = DeriveSeed(options.seed, kSceneStream);
  scene_options.road_length_m =
      static_cast<float>(duration_s * options.max_speed_mps + 2.0 * margin_m);
  absl::StatusOr<StreetScene> scene = GenerateStreetScene(scene_options);
  if (!scene.ok()) return scene.status();
  auto shared_scene = std::make_shared<const StreetScene>(*std::move(scene));
  absl::StatusOr<LidarSimulator> simulator = LidarSimulator::Create(*shared_scene, options.sensor);
  if (!simulator.ok()) return simulator.status();

  LidarSequenceSimulator sequence(options, shared_scene, *std::move(simulator));
  SeededRandom speed_random(DeriveSeed(options.seed, kSpeedStream));
  const double period_s = speed_random.Uniform(20.0, 40.0);
  const double phase = speed_random.Uniform(0.0, 2.0 * M_PI);
  const double mid = 0.5 * (options.min_speed_mps + options.max_speed_mps);
  const double amplitude = 0.5 * (options.max_speed_mps - options.min_speed_mps);
  auto speed_at = [=](double t) {
    return mid + amplitude * std::sin(2.0 * M_PI * t / period_s + phase);
  };
  for (int i = 0; i < options.frame_count; ++i) {
    sequence.timestamps_s_.push_back(i / options.frame_rate_hz);
  }
  absl::StatusOr<std::vector<Eigen::Isometry3d>> poses =
      PlanDrive(*shared_scene, sequence.timestamps_s_, margin_m, shared_scene->drive_lane_offset_m,
                options.sensor_height_m, speed_at);
  if (!poses.ok()) return poses.status();
  sequence.T_world_lidar_ = *std::move(poses);
  return sequence;
}

LidarScan LidarSequenceSimulator::SimulateFrame(int frame) const {
  return simulator_.SimulateScan(T_world_lidar_[frame],
                                 DeriveSeed(options_.seed, kFrameStreamBase + frame));
}

absl::Status LidarSequenceSimulator::SimulateAllFrames(const FrameSink& sink) const {
  std::atomic<int> next_frame{0};
  std::atomic<bool> failed{false};
  std::mutex error_mutex;
  absl::Status first_error;
  auto work = [&] {
    while (!failed.load()) {
      const int frame = next_frame.fetch_add(1);
      if (frame >= frame_count()) return;
      absl::Status status = sink(frame, SimulateFrame(frame));
      if (!status.ok()) {
        std::lock_guard<std::mutex> lock(error_mutex);
        if (first_error.ok()) first_error = std::move(status);
        failed.store(true);
      }
    }
  };
  const int workers = std::min(options_.thread_count, frame_count());
  std::vector<std::thread> threads;
  for (int i = 1; i < workers; ++i) threads.emplace_back(work);
  work();
  for (std::thread& thread : threads) thread.join();
  return first_error;
}

}  // namespace rpsr::core
