#include "core/synth/street_scene.h"

#include <algorithm>
#include <cmath>
#include <unordered_map>

#include "absl/strings/str_cat.h"
#include "core/synth/seeded_random.h"

namespace rpsr::core {

float GroundSurface::HeightAt(float x, float y) const {
  if (bump_amplitude_m == 0.0f) return base_height_m;
  const float k = 2.0f * static_cast<float>(M_PI) / bump_wavelength_m;
  return base_height_m +
         bump_amplitude_m * std::sin(k * x + bump_phase_x) * std::sin(k * y + bump_phase_y);
}

Eigen::Vector2f GroundSurface::GradientAt(float x, float y) const {
  if (bump_amplitude_m == 0.0f) return Eigen::Vector2f::Zero();
  const float k = 2.0f * static_cast<float>(M_PI) / bump_wavelength_m;
  const float sx = std::sin(k * x + bump_phase_x), cx = std::cos(k * x + bump_phase_x);
  const float sy = std::sin(k * y + bump_phase_y), cy = std::cos(k * y + bump_phase_y);
  return Eigen::Vector2f(bump_amplitude_m * k * cx * sy, bump_amplitude_m * k * sx * cy);
}

const char* StreetStyleName(StreetStyle style) {
  switch (style) {
    case StreetStyle::kUrbanCanyon:
      return "urban_canyon";
    case StreetStyle::kSuburban:
      return "suburban";
    case StreetStyle::kOpenRoad:
      return "open_road";
    case StreetStyle::kParkingLot:
      return "parking_lot";
  }
  return "unknown";
}

namespace {

namespace sk = semantic_kitti;

// Typical KITTI-like reflectance per class, in [0, 1].
float ReflectanceOf(uint16_t label) {
  switch (label) {
    case sk::kCar:
      return 0.25f;
    case sk::kBuilding:
      return 0.4f;
    case sk::kFence:
      return 0.5f;
    case sk::kOtherStructure:
      return 0.35f;
    case sk::kVegetation:
      return 0.45f;
    case sk::kTrunk:
      return 0.3f;
    case sk::kPole:
      return 0.5f;
    case sk::kTrafficSign:
      return 0.9f;
    default:
      return 0.4f;
  }
}

// Per-style layout figures (metres, radians).
struct StyleLayout {
  float road_half_width = 6.0f;
  float sidewalk_outer = 10.0f;  // sidewalk zone from road_half_width to here
  float straight_min = 80.0f, straight_max = 180.0f;
  float turn_angle_min = M_PI / 2, turn_angle_max = M_PI / 2;
  float turn_radius_min = 12.0f, turn_radius_max = 18.0f;
  bool dashed_center_line = true;
  float bump_amplitude = 0.0f;
};

StyleLayout LayoutFor(StreetStyle style) {
  StyleLayout layout;
  switch (style) {
    case StreetStyle::kUrbanCanyon:
      break;
    case StreetStyle::kSuburban:
      layout.road_half_width = 5.5f;
      layout.sidewalk_outer = 7.5f;
      layout.straight_min = 60.0f, layout.straight_max = 150.0f;
      layout.turn_angle_min = 0.35f, layout.turn_angle_max = 1.0f;
      layout.turn_radius_min = 40.0f, layout.turn_radius_max = 80.0f;
      layout.bump_amplitude = 0.05f;
      break;
    case StreetStyle::kOpenRoad:
      layout.road_half_width = 8.0f;
      layout.sidewalk_outer = 10.0f;  // shoulders
      layout.straight_min = 100.0f, layout.straight_max = 300.0f;
      layout.turn_angle_min = 0.2f, layout.turn_angle_max = 0.6f;
      layout.turn_radius_min = 150.0f, layout.turn_radius_max = 300.0f;
      layout.dashed_center_line = false;
      layout.bump_amplitude = 0.12f;
      break;
    case StreetStyle::kParkingLot:
      layout.road_half_width = 4.0f;
      layout.sidewalk_outer = 4.0f;  // the lot starts at the road's edge
      layout.straight_min = 150.0f, layout.straight_max = 300.0f;
      layout.turn_radius_min = 10.0f, layout.turn_radius_max = 14.0f;
      break;
  }
  return layout;
}

// The road's centre line with arc length and a coarse hash grid for distance queries.
class RoadGeometry {
 public:
  explicit RoadGeometry(std::vector<Eigen::Vector2f> points) : points_(std::move(points)) {
    arc_.resize(points_.size(), 0.0f);
    for (size_t i = 1; i < points_.size(); ++i) {
      arc_[i] = arc_[i - 1] + (points_[i] - points_[i - 1]).norm();
    }
    for (size_t i = 0; i + 1 < points_.size(); ++i) {
      const Eigen::Vector2f mid = 0.5f * (points_[i] + points_[i + 1]);
      cells_[Key(CellOf(mid.x()), CellOf(mid.y()))].push_back(static_cast<int>(i));
    }
  }

  float length() const { return arc_.empty() ? 0.0f : arc_.back(); }

  // Position and unit tangent at arc length s (clamped to the line).
  void At(float s, Eigen::Vector2f* position, Eigen::Vector2f* tangent) const {
    s = std::clamp(s, 0.0f, length());
    size_t i = std::upper_bound(arc_.begin(), arc_.end(), s) - arc_.begin();
    i = std::clamp<size_t>(i, 1, points_.size() - 1);
    const Eigen::Vector2f delta = points_[i] - points_[i - 1];
    const float segment = std::max(delta.norm(), 1e-6f);
    const float f = (s - arc_[i - 1]) / segment;
    *position = points_[i - 1] + f * delta;
    *tangent = delta / segment;
  }

  // Point at arc length s, `lateral` metres to the left (negative: right).
  Eigen::Vector2f PointAt(float s, float lateral, float* yaw = nullptr) const {
    Eigen::Vector2f p, t;
    At(s, &p, &t);
    if (yaw != nullptr) *yaw = std::atan2(t.y(), t.x());
    return p + lateral * Eigen::Vector2f(-t.y(), t.x());
  }

  // Distance from q to the centre line, exact below kCell, otherwise at least kCell.
  float DistanceTo(const Eigen::Vector2f& q) const {
    float best = kCell;
    const int cx = CellOf(q.x()), cy = CellOf(q.y());
    for (int dx = -1; dx <= 1; ++dx) {
      for (int dy = -1; dy <= 1; ++dy) {
        auto it = cells_.find(Key(cx + dx, cy + dy));
        if (it == cells_.end()) continue;
        for (int i : it->second) {
          const Eigen::Vector2f a = points_[i], b = points_[i + 1];
          const Eigen::Vector2f ab = b - a;
          const float f =
              std::clamp((q - a).dot(ab) / std::max(ab.squaredNorm(), 1e-12f), 0.f, 1.f);
          best = std::min(best, (a + f * ab - q).norm());
        }
      }
    }
    return best;
  }

  // True when every sample of the rectangle (centre, yaw, half extents) is at least `clearance`
  // from the centre line.
  bool RectangleIsClear(const Eigen::Vector2f& center, float yaw, float half_length,
                        float half_width, float clearance) const {
    const Eigen::Vector2f u(std::cos(yaw), std::sin(yaw)), v(-u.y(), u.x());
    const int nu = std::max(1, static_cast<int>(std::ceil(half_length)));
    const int nv = std::max(1, static_cast<int>(std::ceil(half_width)));
    for (int i = -nu; i <= nu; ++i) {
      for (int j = -nv; j <= nv; ++j) {
        const Eigen::Vector2f q = center + u * (half_length * i / nu) + v * (half_width * j / nv);
        if (DistanceTo(q) < clearance) return false;
      }
    }
    return true;
  }

  const std::vector<Eigen::Vector2f>& points() const { return points_; }

 private:
  static constexpr float kCell = 16.0f;
  static int CellOf(float v) { return static_cast<int>(std::floor(v / kCell)); }
  static int64_t Key(int x, int y) { return (static_cast<int64_t>(x) << 32) ^ (y & 0xffffffffLL); }

  std::vector<Eigen::Vector2f> points_;
  std::vector<float> arc_;
  std::unordered_map<int64_t, std::vector<int>> cells_;
};

// Straights joined by circular turns; turn directions keep the heading within 90 degrees of +x,
// so the road never loops back over itself. Points about 1 m apart.
std::vector<Eigen::Vector2f> BuildCenterline(const StyleLayout& layout, float length,
                                             SeededRandom& random) {
  std::vector<Eigen::Vector2f> points = {Eigen::Vector2f::Zero()};
  Eigen::Vector2d position = Eigen::Vector2d::Zero();
  double heading = 0.0, travelled = 0.0;
  auto step = [&](double ds, double dheading) {
    heading += dheading;
    position += ds * Eigen::Vector2d(std::cos(heading), std::sin(heading));
    travelled += ds;
    points.push_back(position.cast<float>());
  };
  bool straight = true;
  while (travelled < length) {
    if (straight) {
      const double run = random.Uniform(layout.straight_min, layout.straight_max);
      for (int i = 0; i < static_cast<int>(run) && travelled < length; ++i) step(1.0, 0.0);
    } else {
      double angle = random.Uniform(layout.turn_angle_min, layout.turn_angle_max);
      double sign = random.Bernoulli(0.5) ? 1.0 : -1.0;
      if (heading + sign * angle > M_PI / 2 + 1e-6 || heading + sign * angle < -M_PI / 2 - 1e-6) {
        sign = -sign;
      }
      angle *= sign;
      const double radius = random.Uniform(layout.turn_radius_min, layout.turn_radius_max);
      const int steps = std::max(1, static_cast<int>(std::ceil(std::abs(angle) * radius)));
      const double ds = std::abs(angle) * radius / steps;
      for (int i = 0; i < steps && travelled < length; ++i) step(ds, angle / steps);
    }
    straight = !straight;
  }
  return points;
}

class SceneBuilder {
 public:
  SceneBuilder(StreetScene* scene, const RoadGeometry* road, SeededRandom* random)
      : scene_(*scene), road_(*road), random_(*random) {}

  float Uniform(float a, float b) { return static_cast<float>(random_.Uniform(a, b)); }
  bool Chance(double p) { return random_.Bernoulli(p); }

  float GroundAt(const Eigen::Vector2f& xy) const { return scene_.ground.HeightAt(xy.x(), xy.y()); }

  // Box whose footprint centre is `xy`, bottom slightly buried at the local ground height.
  void AddBox(const Eigen::Vector2f& xy, float yaw, float half_length, float half_width,
              float z_bottom, float z_top, uint16_t label) {
    const float ground = GroundAt(xy);
    const float bottom = ground + z_bottom - (z_bottom <= 0.0f ? 0.3f : 0.0f);
    const float top = ground + z_top;
    SceneBox box;
    box.center = Eigen::Vector3f(xy.x(), xy.y(), 0.5f * (bottom + top));
    box.half_extents = Eigen::Vector3f(half_length, half_width, 0.5f * (top - bottom));
    box.yaw_rad = yaw;
    box.label = label;
    box.reflectance = ReflectanceOf(label);
    scene_.boxes.push_back(box);
  }

  void AddCylinder(const Eigen::Vector2f& xy, float radius, float z_top, uint16_t label,
                   float z_bottom = 0.0f) {
    SceneCylinder cylinder;
    cylinder.center = xy;
    cylinder.radius_m = radius;
    const float ground = GroundAt(xy);
    cylinder.z_min_m = ground + z_bottom - (z_bottom <= 0.0f ? 0.3f : 0.0f);
    cylinder.z_max_m = ground + z_top;
    cylinder.label = label;
    cylinder.reflectance = ReflectanceOf(label);
    scene_.cylinders.push_back(cylinder);
  }

  void AddEllipsoid(const Eigen::Vector2f& xy, float z_center, const Eigen::Vector3f& radii,
                    uint16_t label) {
    SceneEllipsoid ellipsoid;
    ellipsoid.center = Eigen::Vector3f(xy.x(), xy.y(), GroundAt(xy) + z_center);
    ellipsoid.radii = radii;
    ellipsoid.label = label;
    ellipsoid.reflectance = ReflectanceOf(label);
    scene_.ellipsoids.push_back(ellipsoid);
  }

  // A parked car (body and cabin) centred at xy, facing yaw.
  void AddCar(const Eigen::Vector2f& xy, float yaw) {
    const float length = Uniform(3.9f, 4.8f), width = Uniform(1.7f, 1.9f);
    const float body_top = Uniform(0.9f, 1.1f), roof = Uniform(1.4f, 1.65f);
    AddBox(xy, yaw, 0.5f * length, 0.5f * width, 0.25f, body_top, sk::kCar);
    const Eigen::Vector2f back(-std::cos(yaw), -std::sin(yaw));
    AddBox(xy + back * (0.1f * length), yaw, 0.28f * length, 0.45f * width, body_top - 0.05f, roof,
           sk::kCar);
  }

  // Tries to place a car, keeping `clearance` from the road's centre line.
  bool TryCar(const Eigen::Vector2f& xy, float yaw, float clearance) {
    if (!road_.RectangleIsClear(xy, yaw, 2.4f, 1.0f, clearance)) return false;
    AddCar(xy, yaw);
    return true;
  }

  void AddTree(const Eigen::Vector2f& xy, float scale) {
    const float trunk_height = Uniform(2.2f, 3.8f) * scale;
    AddCylinder(xy, Uniform(0.12f, 0.28f) * scale, trunk_height + 0.5f, sk::kTrunk);
    const Eigen::Vector3f radii(Uniform(1.5f, 3.0f) * scale, Uniform(1.5f, 3.0f) * scale,
                                Uniform(1.5f, 3.0f) * scale);
    AddEllipsoid(xy, trunk_height + 0.7f * radii.z(), radii, sk::kVegetation);
  }

  // A street light: pole plus an arm reaching over the road (towards `toward_road`).
  void AddStreetLight(const Eigen::Vector2f& xy, const Eigen::Vector2f& toward_road) {
    const float height = Uniform(7.0f, 9.0f);
    AddCylinder(xy, 0.12f, height, sk::kPole);
    const float yaw = std::atan2(toward_road.y(), toward_road.x());
    AddBox(xy + toward_road * 0.9f, yaw, 0.9f, 0.08f, height - 0.15f, height, sk::kPole);
  }

  void AddSign(const Eigen::Vector2f& xy, float yaw) {
    const float height = Uniform(2.3f, 3.0f);
    AddCylinder(xy, 0.05f, height, sk::kPole);
    AddBox(xy, yaw + static_cast<float>(M_PI / 2), 0.35f, 0.03f, height, height + 0.7f,
           sk::kTrafficSign);
  }

  // One random piece of street furniture (bin, bench, bollard, kiosk, bike rack).
  void AddClutter(const Eigen::Vector2f& xy, float yaw) {
    switch (random_.UniformInt(0, 4)) {
      case 0:
        AddCylinder(xy, 0.3f, 1.0f, sk::kOtherObject);
        break;
      case 1:
        AddBox(xy, yaw, 0.9f, 0.25f, 0.0f, 0.45f, sk::kOtherObject);
        break;
      case 2:
        AddCylinder(xy, 0.1f, 0.9f, sk::kOtherObject);
        break;
      case 3:
        AddBox(xy, yaw, 0.8f, 0.8f, 0.0f, 2.5f, sk::kOtherObject);
        break;
      default:
        AddBox(xy, yaw, 1.2f, 0.05f, 0.3f, 0.9f, sk::kOtherObject);
        break;
    }
  }

  // Ground zone from lateral `from` to `to` (left positive) for the road piece at [s0, s1].
  void AddZone(float s0, float s1, float from, float to, uint16_t label, int priority) {
    float yaw = 0.0f;
    const Eigen::Vector2f center = road_.PointAt(0.5f * (s0 + s1), 0.5f * (from + to), &yaw);
    GroundZone zone;
    zone.center = center;
    zone.yaw_rad = yaw;
    zone.half_length_m = 0.5f * (s1 - s0) + 0.3f;
    zone.half_width_m = 0.5f * std::abs(to - from);
    zone.label = label;
    zone.priority = priority;
    scene_.ground_zones.push_back(zone);
  }

  StreetScene& scene() { return scene_; }
  const RoadGeometry& road() const { return road_; }

 private:
  StreetScene& scene_;
  const RoadGeometry& road_;
  SeededRandom& random_;
};

// Ground zones shared by every style: the road, its markings and a sidewalk/shoulder band.
void AddRoadZones(const StyleLayout& layout, StreetStyle style, SceneBuilder& builder) {
  const float length = builder.road().length();
  const float piece = 2.0f;
  const uint16_t band_label = style == StreetStyle::kOpenRoad ? sk::kOtherGround : sk::kSidewalk;
  for (float s = 0.0f; s < length; s += piece) {
    const float e = std::min(length, s + piece);
    builder.AddZone(s, e, -layout.road_half_width, layout.road_half_width, sk::kRoad, 2);
    if (layout.sidewalk_outer > layout.road_half_width) {
      builder.AddZone(s, e, layout.road_half_width, layout.sidewalk_outer, band_label, 1);
      builder.AddZone(s, e, -layout.sidewalk_outer, -layout.road_half_width, band_label, 1);
    }
    if (layout.dashed_center_line) {
      // 3 m dashes every 9 m.
      if (std::fmod(s, 9.0f) < 3.0f) builder.AddZone(s, e, -0.075f, 0.075f, sk::kLaneMarking, 3);
    } else {
      for (float lateral : {-3.75f, 0.0f, 3.75f}) {
        if (lateral != 0.0f && std::fmod(s, 12.0f) >= 4.0f) continue;
        builder.AddZone(s, e, lateral - 0.075f, lateral + 0.075f, sk::kLaneMarking, 3);
      }
      for (float lateral : {-7.6f, 7.6f}) {
        builder.AddZone(s, e, lateral - 0.1f, lateral + 0.1f, sk::kLaneMarking, 3);
      }
    }
  }
}

void BuildUrbanCanyon(const StyleLayout& layout, SceneBuilder& b) {
  const float length = b.road().length();
  for (float side : {-1.0f, 1.0f}) {
    // Facades: a continuous row broken by alleys; some with balconies or ledges.
    for (float s = 0.0f; s < length;) {
      const float width = b.Uniform(8.0f, 25.0f), depth = b.Uniform(10.0f, 16.0f);
      const float height = b.Uniform(8.0f, 25.0f);
      const float setback = layout.sidewalk_outer + b.Uniform(0.0f, 1.2f);
      float yaw = 0.0f;
      const Eigen::Vector2f center =
          b.road().PointAt(s + 0.5f * width, side * (setback + 0.5f * depth), &yaw);
      if (b.road().RectangleIsClear(center, yaw, 0.5f * width, 0.5f * depth,
                                    layout.sidewalk_outer - 0.3f)) {
        b.AddBox(center, yaw, 0.5f * width, 0.5f * depth, 0.0f, height, sk::kBuilding);
        if (b.Chance(0.4)) {
          const Eigen::Vector2f front = b.road().PointAt(s + 0.5f * width, side * (setback - 0.3f));
          for (float z = 4.0f; z + 1.0f < height; z += 3.0f) {
            b.AddBox(front, yaw, 0.5f * width - 0.5f, 0.3f, z, z + 0.2f, sk::kBuilding);
          }
        }
      }
      s += width + (b.Chance(0.15) ? b.Uniform(4.0f, 10.0f) : b.Uniform(0.0f, 1.0f));
    }
    // Parked cars in the parking strip.
    for (float s = b.Uniform(0.0f, 5.0f); s < length; s += b.Uniform(5.0f, 10.0f)) {
      if (!b.Chance(0.7)) continue;
      float yaw = 0.0f;
      const Eigen::Vector2f xy = b.road().PointAt(s, side * (layout.road_half_width - 1.25f), &yaw);
      b.TryCar(xy, yaw, layout.road_half_width - 2.4f);
    }
    // Street lights, signs, trees and clutter on the sidewalk.
    for (float s = b.Uniform(0.0f, 20.0f); s < length; s += b.Uniform(25.0f, 35.0f)) {
      float yaw = 0.0f;
      const Eigen::Vector2f xy = b.road().PointAt(s, side * (layout.road_half_width + 0.6f), &yaw);
      if (b.road().DistanceTo(xy) < layout.road_half_width + 0.4f) continue;
      b.AddStreetLight(xy, Eigen::Vector2f(std::sin(yaw), -std::cos(yaw)) * side);
    }
    for (float s = b.Uniform(0.0f, 30.0f); s < length; s += b.Uniform(30.0f, 60.0f)) {
      float yaw = 0.0f;
      const Eigen::Vector2f xy = b.road().PointAt(s, side * (layout.road_half_width + 0.4f), &yaw);
      if (b.road().DistanceTo(xy) < layout.road_half_width + 0.3f) continue;
      b.AddSign(xy, yaw);
    }
    for (float s = b.Uniform(0.0f, 12.0f); s < length; s += b.Uniform(9.0f, 15.0f)) {
      if (!b.Chance(0.35)) continue;
      const Eigen::Vector2f xy = b.road().PointAt(s, side * (layout.road_half_width + 2.2f));
      if (b.road().DistanceTo(xy) < layout.road_half_width + 2.0f) continue;
      b.AddTree(xy, 0.9f);
    }
    for (float s = b.Uniform(0.0f, 6.0f); s < length; s += b.Uniform(4.0f, 12.0f)) {
      float yaw = 0.0f;
      const Eigen::Vector2f xy = b.road().PointAt(
          s, side * b.Uniform(layout.road_half_width + 1.0f, layout.sidewalk_outer - 0.8f), &yaw);
      if (b.road().DistanceTo(xy) < layout.road_half_width + 0.8f) continue;
      b.AddClutter(xy, yaw);
    }
  }
}

void BuildSuburban(const StyleLayout& layout, SceneBuilder& b) {
  const float length = b.road().length();
  for (float side : {-1.0f, 1.0f}) {
    for (float s = 0.0f; s < length;) {
      const float lot = b.Uniform(18.0f, 30.0f);
      float yaw = 0.0f;
      const float mid = s + 0.5f * lot;
      // House (and a roof block) behind a front lawn.
      const float width = b.Uniform(9.0f, 14.0f), depth = b.Uniform(8.0f, 12.0f);
      const float height = b.Uniform(4.5f, 7.0f);
      const float setback = b.Uniform(12.0f, 18.0f);
      const Eigen::Vector2f house = b.road().PointAt(mid, side * (setback + 0.5f * depth), &yaw);
      if (b.road().RectangleIsClear(house, yaw, 0.5f * width, 0.5f * depth, 10.0f)) {
        b.AddBox(house, yaw, 0.5f * width, 0.5f * depth, 0.0f, height, sk::kBuilding);
        b.AddBox(house, yaw, 0.5f * width - 0.5f, 0.3f * depth, height,
                 height + b.Uniform(1.2f, 2.5f), sk::kBuilding);
      }
      // Driveway with a car, fence or hedge along the front, trees in the garden.
      const float driveway = side * b.Uniform(-0.35f, 0.35f) * lot;
      if (b.Chance(0.5)) {
        const Eigen::Vector2f car = b.road().PointAt(mid + driveway, side * b.Uniform(9.5f, 11.0f));
        b.TryCar(car, yaw + static_cast<float>(M_PI / 2), 7.0f);
      }
      if (b.Chance(0.6)) {
        const float fence_half = 0.5f * (lot - 5.0f);
        const Eigen::Vector2f fence = b.road().PointAt(mid - std::copysign(2.5f, driveway),
                                                       side * (layout.sidewalk_outer + 0.8f));
        if (b.road().RectangleIsClear(fence, yaw, fence_half, 0.5f, layout.sidewalk_outer)) {
          if (b.Chance(0.5)) {
            b.AddBox(fence, yaw, fence_half, 0.03f, 0.0f, b.Uniform(0.9f, 1.5f), sk::kFence);
          } else {
            b.AddBox(fence, yaw, fence_half, 0.4f, 0.0f, b.Uniform(1.0f, 1.8f), sk::kVegetation);
          }
        }
      }
      const int trees = b.Chance(0.8) ? 1 + static_cast<int>(b.Uniform(0.0f, 2.99f)) : 0;
      for (int i = 0; i < trees; ++i) {
        const Eigen::Vector2f xy =
            b.road().PointAt(s + b.Uniform(2.0f, lot - 2.0f), side * b.Uniform(9.0f, 35.0f));
        if (b.road().DistanceTo(xy) < layout.sidewalk_outer + 1.0f) continue;
        b.AddTree(xy, b.Uniform(0.8f, 1.4f));
      }
      s += lot;
    }
    for (float s = b.Uniform(0.0f, 10.0f); s < length; s += b.Uniform(8.0f, 30.0f)) {
      if (!b.Chance(0.3)) continue;
      float yaw = 0.0f;
      const Eigen::Vector2f xy = b.road().PointAt(s, side * (layout.road_half_width - 1.0f), &yaw);
      b.TryCar(xy, yaw, layout.road_half_width - 2.2f);
    }
    for (float s = b.Uniform(0.0f, 40.0f); s < length; s += b.Uniform(35.0f, 45.0f)) {
      const Eigen::Vector2f xy = b.road().PointAt(s, side * (layout.road_half_width + 0.8f));
      if (b.road().DistanceTo(xy) < layout.road_half_width + 0.6f) continue;
      b.AddCylinder(xy, 0.15f, 9.0f, sk::kPole);
    }
    for (float s = b.Uniform(0.0f, 50.0f); s < length; s += b.Uniform(40.0f, 90.0f)) {
      float yaw = 0.0f;
      const Eigen::Vector2f xy = b.road().PointAt(s, side * (layout.road_half_width + 0.5f), &yaw);
      if (b.road().DistanceTo(xy) < layout.road_half_width + 0.3f) continue;
      if (b.Chance(0.5)) {
        b.AddSign(xy, yaw);
      } else {
        b.AddClutter(xy, yaw);
      }
    }
  }
}

void BuildOpenRoad(const StyleLayout& layout, SceneBuilder& b) {
  const float length = b.road().length();
  for (float side : {-1.0f, 1.0f}) {
    // Guard rails (boxes on posts) in long stretches.
    bool rail = b.Chance(0.6);
    bool barrier = false;
    float next_switch = b.Uniform(50.0f, 150.0f);
    for (float s = 0.0f; s < length; s += 4.0f) {
      if (s > next_switch) {
        rail = b.Chance(0.6);
        barrier = b.Chance(0.35);
        next_switch = s + b.Uniform(50.0f, 150.0f);
      }
      float yaw = 0.0f;
      if (rail) {
        const Eigen::Vector2f xy =
            b.road().PointAt(s + 2.0f, side * (layout.sidewalk_outer + 0.3f), &yaw);
        if (b.road().RectangleIsClear(xy, yaw, 2.0f, 0.1f, 9.8f)) {
          b.AddBox(xy, yaw, 2.05f, 0.05f, 0.45f, 0.8f, sk::kFence);
          b.AddCylinder(b.road().PointAt(s, side * (layout.sidewalk_outer + 0.4f)), 0.06f, 0.75f,
                        sk::kFence);
        }
      }
      if (barrier) {
        const Eigen::Vector2f xy = b.road().PointAt(s + 2.0f, side * 14.0f, &yaw);
        if (b.road().RectangleIsClear(xy, yaw, 2.0f, 0.2f, 13.0f)) {
          b.AddBox(xy, yaw, 2.05f, 0.15f, 0.0f, 3.5f, sk::kOtherStructure);
        }
      }
    }
    // Trees and bushes, sparse and clustered, away from the road.
    for (float s = b.Uniform(0.0f, 20.0f); s < length; s += b.Uniform(5.0f, 25.0f)) {
      const Eigen::Vector2f xy = b.road().PointAt(s, side * b.Uniform(16.0f, 60.0f));
      if (b.road().DistanceTo(xy) < 15.0f) continue;
      if (b.Chance(0.6)) {
        b.AddTree(xy, b.Uniform(0.9f, 1.6f));
      } else {
        b.AddEllipsoid(
            xy, 0.3f,
            Eigen::Vector3f(b.Uniform(0.8f, 2.0f), b.Uniform(0.8f, 2.0f), b.Uniform(0.6f, 1.2f)),
            sk::kVegetation);
      }
    }
    for (float s = b.Uniform(0.0f, 60.0f); s < length; s += b.Uniform(60.0f, 150.0f)) {
      float yaw = 0.0f;
      const Eigen::Vector2f xy = b.road().PointAt(s, side * 11.5f, &yaw);
      if (b.road().DistanceTo(xy) < 11.0f) continue;
      if (b.Chance(0.5)) {
        b.AddSign(xy, yaw);
      } else {
        b.AddStreetLight(xy, Eigen::Vector2f(std::sin(yaw), -std::cos(yaw)) * side);
      }
    }
    // Now and then a farm building or a hall far off.
    for (float s = b.Uniform(0.0f, 100.0f); s < length; s += b.Uniform(80.0f, 200.0f)) {
      float yaw = 0.0f;
      const Eigen::Vector2f xy = b.road().PointAt(s, side * b.Uniform(30.0f, 70.0f), &yaw);
      const float half_length = b.Uniform(6.0f, 20.0f), half_width = b.Uniform(5.0f, 12.0f);
      if (!b.road().RectangleIsClear(xy, yaw, half_length, half_width, 20.0f)) continue;
      b.AddBox(xy, yaw, half_length, half_width, 0.0f, b.Uniform(5.0f, 12.0f), sk::kBuilding);
    }
  }
}

void BuildParkingLot(const StyleLayout& layout, SceneBuilder& b) {
  const float length = b.road().length();
  const float lot_outer = 42.0f;
  for (float s = 0.0f; s < length; s += 2.0f) {
    for (float side : {-1.0f, 1.0f}) {
      b.AddZone(s, std::min(length, s + 2.0f), side * layout.road_half_width, side * lot_outer,
                sk::kParking, 1);
    }
  }
  // Rows of cars perpendicular to the lane: stalls 2.6 m wide, rows at these lateral centres.
  const float row_centers[] = {6.75f, 17.5f, 22.25f, 33.0f};
  for (float side : {-1.0f, 1.0f}) {
    for (float row : row_centers) {
      for (float s = 1.3f; s < length; s += 2.6f) {
        if (!b.Chance(0.7)) continue;
        float yaw = 0.0f;
        const Eigen::Vector2f xy = b.road().PointAt(s, side * row, &yaw);
        if (!b.road().RectangleIsClear(xy, yaw, 1.3f, 2.5f, layout.road_half_width + 0.6f)) {
          continue;
        }
        b.AddCar(xy, yaw + static_cast<float>(M_PI / 2) + b.Uniform(-0.05f, 0.05f));
      }
    }
    // Light poles on the islands between double rows, kerbed islands at intervals.
    for (float s = b.Uniform(0.0f, 15.0f); s < length; s += b.Uniform(28.0f, 36.0f)) {
      float yaw = 0.0f;
      const Eigen::Vector2f xy = b.road().PointAt(s, side * 19.9f, &yaw);
      if (!b.road().RectangleIsClear(xy, yaw, 1.0f, 1.0f, layout.road_half_width + 1.0f)) continue;
      b.AddBox(xy, yaw, 1.2f, 0.35f, 0.0f, 0.15f, sk::kSidewalk);
      b.AddCylinder(xy, 0.15f, b.Uniform(8.0f, 11.0f), sk::kPole);
      if (b.Chance(0.5)) b.AddTree(b.road().PointAt(s + 4.0f, side * 19.9f), 0.8f);
    }
    // Low halls and stores around the lot.
    for (float s = 0.0f; s < length;) {
      const float width = b.Uniform(20.0f, 60.0f);
      float yaw = 0.0f;
      const float depth = b.Uniform(15.0f, 30.0f);
      const Eigen::Vector2f xy =
          b.road().PointAt(s + 0.5f * width, side * (lot_outer + 2.0f + 0.5f * depth), &yaw);
      if (b.Chance(0.75) &&
          b.road().RectangleIsClear(xy, yaw, 0.5f * width, 0.5f * depth, lot_outer)) {
        b.AddBox(xy, yaw, 0.5f * width, 0.5f * depth, 0.0f, b.Uniform(5.0f, 10.0f), sk::kBuilding);
      }
      s += width + b.Uniform(3.0f, 15.0f);
    }
  }
}

}  // namespace

absl::StatusOr<StreetScene> GenerateStreetScene(const StreetSceneOptions& options) {
  if (!(options.road_length_m > 0.0f) || options.road_length_m > 20000.0f) {
    return absl::InvalidArgumentError(absl::StrCat(
        "GenerateStreetScene: road_length_m must be in (0, 20000], got ", options.road_length_m));
  }
  const StyleLayout layout = LayoutFor(options.style);
  SeededRandom road_random(DeriveSeed(options.seed, 1));
  SeededRandom object_random(DeriveSeed(options.seed, 2));

  StreetScene scene;
  scene.road_half_width_m = layout.road_half_width;
  scene.drive_lane_offset_m = options.style == StreetStyle::kOpenRoad ? 1.875f : 1.75f;
  scene.ground.bump_amplitude_m = layout.bump_amplitude;
  scene.ground.bump_wavelength_m = 50.0f;
  scene.ground.bump_phase_x = static_cast<float>(road_random.Uniform(0.0, 2.0 * M_PI));
  scene.ground.bump_phase_y = static_cast<float>(road_random.Uniform(0.0, 2.0 * M_PI));
  scene.ground.default_label = sk::kTerrain;
  scene.road_centerline = BuildCenterline(layout, options.road_length_m, road_random);

  const RoadGeometry road(scene.road_centerline);
  SceneBuilder builder(&scene, &road, &object_random);
  AddRoadZones(layout, options.style, builder);
  switch (options.style) {
    case StreetStyle::kUrbanCanyon:
      BuildUrbanCanyon(layout, builder);
      break;
    case StreetStyle::kSuburban:
      BuildSuburban(layout, builder);
      break;
    case StreetStyle::kOpenRoad:
      BuildOpenRoad(layout, builder);
      break;
    case StreetStyle::kParkingLot:
      BuildParkingLot(layout, builder);
      break;
  }
  return scene;
}

}  // namespace rpsr::core
