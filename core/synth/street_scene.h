// Procedural street scenes for the LiDAR simulator: a world made of analytic primitives (a ground
// surface with labelled zones, oriented boxes, vertical cylinders, axis-aligned ellipsoids), each
// carrying a SemanticKITTI class id, laid out along a generated road. The world frame is metric
// with z up; the road starts at the origin heading +x.
//
// Scenes can be generated (GenerateStreetScene, several styles) or built by hand (tests build a
// scene with only a flat ground, or one wall, to check the simulator against analytic geometry).
#ifndef RPSR_CORE_SYNTH_STREET_SCENE_H_
#define RPSR_CORE_SYNTH_STREET_SCENE_H_

#include <cstdint>
#include <vector>

#include "Eigen/Core"
#include "absl/status/statusor.h"

namespace rpsr::core {

// SemanticKITTI class ids (the lower 16 bits of a .label entry) that the simulator writes. Kept
// here rather than in core/data so that core/synth does not depend on core/data; core/data's
// semantic_labels.h decides which of them count as ground.
namespace semantic_kitti {
inline constexpr uint16_t kUnlabeled = 0;
inline constexpr uint16_t kCar = 10;
inline constexpr uint16_t kRoad = 40;
inline constexpr uint16_t kParking = 44;
inline constexpr uint16_t kSidewalk = 48;
inline constexpr uint16_t kOtherGround = 49;
inline constexpr uint16_t kBuilding = 50;
inline constexpr uint16_t kFence = 51;
inline constexpr uint16_t kOtherStructure = 52;
inline constexpr uint16_t kLaneMarking = 60;
inline constexpr uint16_t kVegetation = 70;
inline constexpr uint16_t kTrunk = 71;
inline constexpr uint16_t kTerrain = 72;
inline constexpr uint16_t kPole = 80;
inline constexpr uint16_t kTrafficSign = 81;
inline constexpr uint16_t kOtherObject = 99;
}  // namespace semantic_kitti

// The ground: z = base_height_m + bump_amplitude_m * sin(2 pi x / L + phase_x) *
// sin(2 pi y / L + phase_y), L = bump_wavelength_m. Rays only hit it from above; keep the bumps
// well below the sensor height.
struct GroundSurface {
  bool present = true;
  float base_height_m = 0.0f;
  float bump_amplitude_m = 0.0f;
  float bump_wavelength_m = 40.0f;
  float bump_phase_x = 0.0f;
  float bump_phase_y = 0.0f;
  // Class of ground that no zone covers.
  uint16_t default_label = semantic_kitti::kTerrain;

  float HeightAt(float x, float y) const;
  // (dz/dx, dz/dy) at (x, y).
  Eigen::Vector2f GradientAt(float x, float y) const;
};

// A labelled rectangle of ground (road, lane marking, sidewalk, parking): centre, half length
// along `yaw_rad`, half width across. Where zones overlap, the highest `priority` wins.
struct GroundZone {
  Eigen::Vector2f center = Eigen::Vector2f::Zero();
  float yaw_rad = 0.0f;
  float half_length_m = 1.0f;
  float half_width_m = 1.0f;
  uint16_t label = semantic_kitti::kRoad;
  int priority = 0;
};

// A box rotated by `yaw_rad` about the vertical axis through its centre.
struct SceneBox {
  Eigen::Vector3f center = Eigen::Vector3f::Zero();
  Eigen::Vector3f half_extents = Eigen::Vector3f::Ones();
  float yaw_rad = 0.0f;
  uint16_t label = semantic_kitti::kBuilding;
  float reflectance = 0.4f;
};

// A vertical cylinder (side and top cap) from z_min_m to z_max_m around (center_x, center_y).
struct SceneCylinder {
  Eigen::Vector2f center = Eigen::Vector2f::Zero();
  float radius_m = 0.1f;
  float z_min_m = 0.0f;
  float z_max_m = 1.0f;
  uint16_t label = semantic_kitti::kPole;
  float reflectance = 0.5f;
};

// An axis-aligned ellipsoid (tree crowns, bushes).
struct SceneEllipsoid {
  Eigen::Vector3f center = Eigen::Vector3f::Zero();
  Eigen::Vector3f radii = Eigen::Vector3f::Ones();
  uint16_t label = semantic_kitti::kVegetation;
  float reflectance = 0.45f;
};

struct StreetScene {
  GroundSurface ground;
  std::vector<GroundZone> ground_zones;
  std::vector<SceneBox> boxes;
  std::vector<SceneCylinder> cylinders;
  std::vector<SceneEllipsoid> ellipsoids;
  // Centre line of the road, about 1 m between points, starting at the origin; empty for scenes
  // built by hand. Vehicles drive along it (see lidar_sequence.h).
  std::vector<Eigen::Vector2f> road_centerline;
  // Half width of the road surface (lanes and parking strips).
  float road_half_width_m = 0.0f;
  // Distance from the centre line to the centre of the lane vehicles drive in (to the right).
  float drive_lane_offset_m = 0.0f;
};

enum class StreetStyle {
  // Continuous facades 8-25 m tall close to the road, parked cars, street lights, a few trees,
  // clutter on the sidewalks; 90-degree turns.
  kUrbanCanyon,
  // Houses behind lawns, fences and hedges, many trees, some parked cars; gentle curves.
  kSuburban,
  // A wide road through open terrain: guard rails, noise barriers, sparse trees and signs, gentle
  // bumps; wide curves. Many rays see only sky.
  kOpenRoad,
  // A lane through parking lots: rows of cars, light poles, low buildings at the edges.
  kParkingLot,
};

const char* StreetStyleName(StreetStyle style);

struct StreetSceneOptions {
  StreetStyle style = StreetStyle::kUrbanCanyon;
  // Length of road to build (m); the generator adds nothing beyond it, so ask for the drive's
  // length plus the sensor's range.
  float road_length_m = 600.0f;
  uint64_t seed = 1;
};

// Builds a scene of `options.style` around a road of `options.road_length_m`. Deterministic for a
// given seed. InvalidArgument for a non-positive length or one above 20 km.
absl::StatusOr<StreetScene> GenerateStreetScene(const StreetSceneOptions& options);

}  // namespace rpsr::core

#endif  // RPSR_CORE_SYNTH_STREET_SCENE_H_
