// A spinning multi-beam LiDAR (Velodyne HDL-64E-like by default) ray-cast into a StreetScene.
//
// Sensor model: `beam_count` beams at elevations spaced evenly from max_elevation_deg (beam 0)
// down to min_elevation_deg (the real HDL-64E spaces its two blocks of 32 lasers unevenly; even
// spacing over the same span is close enough for registration data), `azimuth_steps` azimuths a
// revolution. A ray returns the first surface it meets within max_range_m; returns nearer than
// min_range_m are dropped (they would be the ego vehicle, which the scene does not model), a
// fraction `dropout_probability` of the others are lost at random, and the range gets Gaussian
// noise. A scan is captured at one instant (no motion distortion), like KITTI's de-skewed scans.
//
// Points are in the sensor frame: x forward, y left, z up.
//
// Ray casting: the primitives are binned into a uniform grid over the xy plane (4 m cells); a ray
// walks the cells its xy projection crosses (2D DDA) from the sensor outwards and stops at the
// first cell beyond the nearest hit found so far, so it only tests nearby primitives. The ground
// is analytic (closed form when flat, a few Newton steps when bumpy) and bounds the walk.
#ifndef RPSR_CORE_SYNTH_LIDAR_SIMULATOR_H_
#define RPSR_CORE_SYNTH_LIDAR_SIMULATOR_H_

#include <cstdint>
#include <memory>
#include <optional>
#include <string_view>
#include <vector>

#include "Eigen/Core"
#include "Eigen/Geometry"
#include "absl/status/statusor.h"
#include "core/cloud/point_cloud.h"
#include "core/synth/street_scene.h"

namespace rpsr::core {

struct LidarSensorOptions {
  int beam_count = 64;
  double max_elevation_deg = 2.0;
  double min_elevation_deg = -24.8;
  // About 0.18 degrees: an HDL-64E at 10 Hz.
  int azimuth_steps = 2000;
  double max_range_m = 120.0;
  double min_range_m = 2.5;
  // Standard deviation of the Gaussian range error.
  double range_noise_sigma_m = 0.02;
  // Probability that a ray which hit something returns nothing.
  double dropout_probability = 0.03;
  // Standard deviation of the noise added to the simulated reflectance (in [0, 1]).
  double intensity_noise_sigma = 0.03;
};

// The scanners `rpsr data lidar --sensor` simulates, by name: "hdl64" (the defaults above:
// KITTI's), "hdl32" (32 beams, +10.67 to -30.67 degrees, 2,250 azimuths) or "vlp16" (16 beams,
// +-15 degrees, 1,800 azimuths): beams, elevations and azimuths from the datasheets at 10 Hz;
// range, noise and dropout as the defaults. nullopt for any other name.
std::optional<LidarSensorOptions> LidarSensorPreset(std::string_view name);

// One simulated revolution. `labels` and `beam_indices` run parallel to `cloud.points`;
// `cloud.intensities` holds a reflectance in [0, 1] (class reflectance, incidence angle, range).
struct LidarScan {
  PointCloud cloud;
  // SemanticKITTI class id of the surface each point lies on.
  std::vector<uint16_t> labels;
  // Beam (ring) of each point; 0 is the top beam.
  std::vector<uint8_t> beam_indices;
};

// The first surface a ray meets.
struct LidarRayHit {
  float distance_m = 0.0f;
  uint16_t label = 0;
  float reflectance = 0.0f;
  // Unit normal of the surface at the hit, facing the ray's origin side.
  Eigen::Vector3f normal = Eigen::Vector3f::UnitZ();
};

class LidarSimulator {
 public:
  // Indexes `scene` for ray casting. InvalidArgument for sensor options out of range (beam count
  // outside [1, 256], azimuth steps outside [1, 100000], ranges not 0 <= min < max <= 10 km,
  // elevations out of [-90, 90] or max < min, negative noise, dropout outside [0, 1)) or for a
  // primitive with non-finite or non-positive size.
  static absl::StatusOr<LidarSimulator> Create(const StreetScene& scene,
                                               const LidarSensorOptions& options = {});

  // Simulates one revolution from a sensor at T_world_sensor. Noise and dropouts are drawn from
  // `seed` alone, so a scan depends only on (scene, options, pose, seed). Safe to call from
  // several threads at once.
  LidarScan SimulateScan(const Eigen::Isometry3d& T_world_sensor, uint64_t seed) const;

  // Casts one ray (world frame, `direction` of unit length) without noise; for tests and tools.
  std::optional<LidarRayHit> CastRay(const Eigen::Vector3f& origin,
                                     const Eigen::Vector3f& direction, float max_distance_m) const;

  // Elevation of beam `beam` in radians (beam 0 is the highest).
  double BeamElevationRad(int beam) const;

  const LidarSensorOptions& options() const { return options_; }

  struct SceneIndex;  // defined in the .cc

 private:
  LidarSimulator(std::shared_ptr<const SceneIndex> index, const LidarSensorOptions& options)
      : index_(std::move(index)), options_(options) {}

  std::shared_ptr<const SceneIndex> index_;
  LidarSensorOptions options_;
};

}  // namespace rpsr::core

#endif  // RPSR_CORE_SYNTH_LIDAR_SIMULATOR_H_
