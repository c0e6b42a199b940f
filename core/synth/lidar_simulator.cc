#include "core/synth/lidar_simulator.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "absl/strings/str_cat.h"
#include "core/synth/seeded_random.h"

namespace rpsr::core {

namespace {

constexpr float kInfinity = std::numeric_limits<float>::infinity();
// Hits closer than this along a ray are ignored (self-intersection guard).
constexpr float kMinHitDistance = 1e-4f;

enum PrimitiveKind : uint32_t { kBox = 0, kCylinder = 1, kEllipsoid = 2 };
constexpr uint32_t kKindShift = 30;
constexpr uint32_t kIndexMask = (1u << kKindShift) - 1;

struct IndexedBox {
  Eigen::Vector3f center;
  Eigen::Vector3f half_extents;
  float cos_yaw, sin_yaw;
};

bool FinitePositive(float v) { return std::isfinite(v) && v > 0.0f; }

}  // namespace

std::optional<LidarSensorOptions> LidarSensorPreset(std::string_view name) {
  struct Preset {
    std::string_view name;
    int beam_count;
    double max_elevation_deg;
    double min_elevation_deg;
    int azimuth_steps;
  };
  static constexpr Preset kPresets[] = {{"hdl32", 32, 10.67, -30.67, 2250},
                                        {"vlp16", 16, 15.0, -15.0, 1800}};
  LidarSensorOptions sensor;  // the defaults: hdl64
  if (name == "hdl64") return sensor;
  for (const Preset& preset : kPresets) {
    if (preset.name != name) continue;
    sensor.beam_count = preset.beam_count;
    sensor.max_elevation_deg = preset.max_elevation_deg;
    sensor.min_elevation_deg = preset.min_elevation_deg;
    sensor.azimuth_steps = preset.azimuth_steps;
    return sensor;
  }
  return std::nullopt;
}

// The scene in ray-casting form: primitives with precomputed terms, and two uniform xy grids in
// compressed-row form (cell -> primitive references; cell -> ground zones).
struct LidarSimulator::SceneIndex {
  StreetScene scene;
  std::vector<IndexedBox> boxes;
  float min_x = 0, min_y = 0, cell = 4.0f;
  int nx = 0, ny = 0;
  std::vector<uint32_t> cell_start;  // nx * ny + 1
  std::vector<uint32_t> cell_refs;
  std::vector<uint32_t> zone_start;
  std::vector<uint32_t> zone_refs;
  std::vector<Eigen::Vector2f> zone_cos_sin;
  float z_top = -kInfinity;
  float z_bottom = kInfinity;
  uint32_t primitive_count = 0;

  int CellX(float x) const { return static_cast<int>(std::floor((x - min_x) / cell)); }
  int CellY(float y) const { return static_cast<int>(std::floor((y - min_y) / cell)); }

  uint32_t FlatIndex(uint32_t ref) const {
    const uint32_t kind = ref >> kKindShift, index = ref & kIndexMask;
    if (kind == kBox) return index;
    if (kind == kCylinder) return static_cast<uint32_t>(boxes.size()) + index;
    return static_cast<uint32_t>(boxes.size() + scene.cylinders.size()) + index;
  }

  float IntersectBox(uint32_t i, const Eigen::Vector3f& o, const Eigen::Vector3f& d) const;
  float IntersectCylinder(uint32_t i, const Eigen::Vector3f& o, const Eigen::Vector3f& d) const;
  float IntersectEllipsoid(uint32_t i, const Eigen::Vector3f& o, const Eigen::Vector3f& d) const;
  float IntersectGround(const Eigen::Vector3f& o, const Eigen::Vector3f& d) const;
  uint16_t GroundLabelAt(float x, float y) const;

  // Nearest hit along o + t d, t in (0, max_t); `mailbox` (one stamp per primitive) and `ray_id`
  // skip primitives met again in later cells. Returns the hit reference (kGroundRef for the
  // ground, kNoHit for none) and sets *t.
  static constexpr uint32_t kGroundRef = 0xfffffffeu;
  static constexpr uint32_t kNoHit = 0xffffffffu;
  uint32_t Cast(const Eigen::Vector3f& o, const Eigen::Vector3f& d, float max_t,
                std::vector<uint32_t>* mailbox, uint32_t ray_id, float* t) const;
  LidarRayHit Describe(uint32_t ref, const Eigen::Vector3f& o, const Eigen::Vector3f& d,
                       float t) const;
};

float LidarSimulator::SceneIndex::IntersectBox(uint32_t i, const Eigen::Vector3f& o,
                                               const Eigen::Vector3f& d) const {
  const IndexedBox& box = boxes[i];
  const Eigen::Vector3f p = o - box.center;
  const float c = box.cos_yaw, s = box.sin_yaw;
  const float local_o[3] = {c * p.x() + s * p.y(), -s * p.x() + c * p.y(), p.z()};
  const float local_d[3] = {c * d.x() + s * d.y(), -s * d.x() + c * d.y(), d.z()};
  float t_near = -kInfinity, t_far = kInfinity;
  for (int axis = 0; axis < 3; ++axis) {
    const float h = box.half_extents[axis];
    if (std::abs(local_d[axis]) < 1e-12f) {
      if (local_o[axis] < -h || local_o[axis] > h) return kInfinity;
      continue;
    }
    const float inv = 1.0f / local_d[axis];
    float t0 = (-h - local_o[axis]) * inv, t1 = (h - local_o[axis]) * inv;
    if (t0 > t1) std::swap(t0, t1);
    t_near = std::max(t_near, t0);
    t_far = std::min(t_far, t1);
    if (t_near > t_far) return kInfinity;
  }
  return t_near > kMinHitDistance ? t_near : kInfinity;
}

float LidarSimulator::SceneIndex::IntersectCylinder(uint32_t i, const Eigen::Vector3f& o,
                                                    const Eigen::Vector3f& d) const {
  const SceneCylinder& cyl = scene.cylinders[i];
  const float dx = o.x() - cyl.center.x(), dy = o.y() - cyl.center.y();
  const float a = d.x() * d.x() + d.y() * d.y();
  float best = kInfinity;
  if (a > 1e-12f) {
    const float b = dx * d.x() + dy * d.y();
    const float c = dx * dx + dy * dy - cyl.radius_m * cyl.radius_m;
    const float disc = b * b - a * c;
    if (disc >= 0.0f) {
      const float t = (-b - std::sqrt(disc)) / a;
      const float z = o.z() + t * d.z();
      if (t > kMinHitDistance && z >= cyl.z_min_m && z <= cyl.z_max_m) best = t;
    }
  }
  if (d.z() < 0.0f && o.z() > cyl.z_max_m) {
    const float t = (cyl.z_max_m - o.z()) / d.z();
    const float x = dx + t * d.x(), y = dy + t * d.y();
    if (x * x + y * y <= cyl.radius_m * cyl.radius_m) best = std::min(best, t);
  }
  return best;
}

float LidarSimulator::SceneIndex::IntersectEllipsoid(uint32_t i, const Eigen::Vector3f& o,
                                                     const Eigen::Vector3f& d) const {
  const SceneEllipsoid& e = scene.ellipsoids[i];
  const Eigen::Vector3f p = (o - e.center).cwiseQuotient(e.radii);
  const Eigen::Vector3f q = d.cwiseQuotient(e.radii);
  const float a = q.squaredNorm(), b = p.dot(q), c = p.squaredNorm() - 1.0f;
  const float disc = b * b - a * c;
  if (disc < 0.0f) return kInfinity;
  const float t = (-b - std::sqrt(disc)) / a;
  return t > kMinHitDistance ? t : kInfinity;
}

float LidarSimulator::SceneIndex::IntersectGround(const Eigen::Vector3f& o,
                                                  const Eigen::Vector3f& d) const {
  const GroundSurface& g = scene.ground;
  if (!g.present || d.z() >= 0.0f) return kInfinity;
  float t = (g.base_height_m - o.z()) / d.z();
  if (t <= 0.0f) return kInfinity;
  if (g.bump_amplitude_m == 0.0f) return t;
  // Newton on f(t) = o.z + t d.z - h(o.xy + t d.xy), from the flat solution.
  for (int iteration = 0; iteration < 8; ++iteration) {
    const float x = o.x() + t * d.x(), y = o.y() + t * d.y();
    const float f = o.z() + t * d.z() - g.HeightAt(x, y);
    const Eigen::Vector2f grad = g.GradientAt(x, y);
    const float df = d.z() - grad.x() * d.x() - grad.y() * d.y();
    if (df >= -1e-6f) break;  // ray grazing a rising slope: keep the last estimate
    const float step = f / df;
    t -= step;
    if (std::abs(step) < 1e-4f) break;
  }
  return t > kMinHitDistance ? t : kInfinity;
}

uint16_t LidarSimulator::SceneIndex::GroundLabelAt(float x, float y) const {
  const int ix = CellX(x), iy = CellY(y);
  uint16_t label = scene.ground.default_label;
  if (ix < 0 || iy < 0 || ix >= nx || iy >= ny || zone_start.empty()) return label;
  int best_priority = std::numeric_limits<int>::min();
  const size_t cell_id = static_cast<size_t>(iy) * nx + ix;
  for (uint32_t k = zone_start[cell_id]; k < zone_start[cell_id + 1]; ++k) {
    const uint32_t z = zone_refs[k];
    const GroundZone& zone = scene.ground_zones[z];
    if (zone.priority <= best_priority) continue;
    const float px = x - zone.center.x(), py = y - zone.center.y();
    const float c = zone_cos_sin[z].x(), s = zone_cos_sin[z].y();
    if (std::abs(c * px + s * py) <= zone.half_length_m &&
        std::abs(-s * px + c * py) <= zone.half_width_m) {
      best_priority = zone.priority;
      label = zone.label;
    }
  }
  return label;
}

uint32_t LidarSimulator::SceneIndex::Cast(const Eigen::Vector3f& o, const Eigen::Vector3f& d,
                                          float max_t, std::vector<uint32_t>* mailbox,
                                          uint32_t ray_id, float* t_hit) const {
  float best_t = max_t;
  uint32_t best_ref = kNoHit;
  const float ground_t = IntersectGround(o, d);
  if (ground_t < best_t) {
    best_t = ground_t;
    best_ref = kGroundRef;
  }
  if (primitive_count > 0 && nx > 0) {
    // Limit the walk to the slab of heights that holds primitives.
    float walk_end = best_t;
    if (d.z() > 0.0f) walk_end = std::min(walk_end, (z_top - o.z()) / d.z());
    if (d.z() < 0.0f) walk_end = std::min(walk_end, (z_bottom - o.z()) / d.z());
    // Entry into the grid's xy rectangle.
    const float max_x = min_x + nx * cell, max_y = min_y + ny * cell;
    float t_enter = 0.0f, t_leave = walk_end;
    const float bounds_min[2] = {min_x, min_y}, bounds_max[2] = {max_x, max_y};
    for (int axis = 0; axis < 2; ++axis) {
      if (std::abs(d[axis]) < 1e-12f) {
        if (o[axis] < bounds_min[axis] || o[axis] > bounds_max[axis]) t_enter = kInfinity;
        continue;
      }
      float t0 = (bounds_min[axis] - o[axis]) / d[axis],
            t1 = (bounds_max[axis] - o[axis]) / d[axis];
      if (t0 > t1) std::swap(t0, t1);
      t_enter = std::max(t_enter, t0);
      t_leave = std::min(t_leave, t1);
    }
    if (t_enter < t_leave) {
      const float px = o.x() + t_enter * d.x(), py = o.y() + t_enter * d.y();
      int ix = std::clamp(CellX(px), 0, nx - 1), iy = std::clamp(CellY(py), 0, ny - 1);
      const int step_x = d.x() > 0.0f ? 1 : -1, step_y = d.y() > 0.0f ? 1 : -1;
      const float delta_x = std::abs(d.x()) > 1e-12f ? cell / std::abs(d.x()) : kInfinity;
      const float delta_y = std::abs(d.y()) > 1e-12f ? cell / std::abs(d.y()) : kInfinity;
      float next_x = std::abs(d.x()) > 1e-12f ? (min_x + (ix + (step_x > 0)) * cell - o.x()) / d.x()
                                              : kInfinity;
      float next_y = std::abs(d.y()) > 1e-12f ? (min_y + (iy + (step_y > 0)) * cell - o.y()) / d.y()
                                              : kInfinity;
      float cell_enter = t_enter;
      while (cell_enter < std::min(best_t, t_leave)) {
        const size_t cell_id = static_cast<size_t>(iy) * nx + ix;
        for (uint32_t k = cell_start[cell_id]; k < cell_start[cell_id + 1]; ++k) {
          const uint32_t ref = cell_refs[k];
          const uint32_t flat = FlatIndex(ref);
          if ((*mailbox)[flat] == ray_id) continue;
          (*mailbox)[flat] = ray_id;
          const uint32_t kind = ref >> kKindShift, index = ref & kIndexMask;
          const float t = kind == kBox        ? IntersectBox(index, o, d)
                          : kind == kCylinder ? IntersectCylinder(index, o, d)
                                              : IntersectEllipsoid(index, o, d);
          if (t < best_t) {
            best_t = t;
            best_ref = ref;
          }
        }
        if (next_x < next_y) {
          cell_enter = next_x;
          next_x += delta_x;
          ix += step_x;
          if (ix < 0 || ix >= nx) break;
        } else {
          cell_enter = next_y;
          next_y += delta_y;
          iy += step_y;
          if (iy < 0 || iy >= ny) break;
        }
      }
    }
  }
  *t_hit = best_t;
  return best_ref;
}

LidarRayHit LidarSimulator::SceneIndex::Describe(uint32_t ref, const Eigen::Vector3f& o,
                                                 const Eigen::Vector3f& d, float t) const {
  LidarRayHit hit;
  hit.distance_m = t;
  const Eigen::Vector3f p = o + t * d;
  Eigen::Vector3f normal;
  if (ref == kGroundRef) {
    const Eigen::Vector2f grad = scene.ground.GradientAt(p.x(), p.y());
    normal = Eigen::Vector3f(-grad.x(), -grad.y(), 1.0f);
    hit.label = GroundLabelAt(p.x(), p.y());
    hit.reflectance = hit.label == semantic_kitti::kLaneMarking ? 0.8f
                      : hit.label == semantic_kitti::kRoad      ? 0.2f
                                                                : 0.35f;
  } else {
    const uint32_t kind = ref >> kKindShift, index = ref & kIndexMask;
    if (kind == kBox) {
      const IndexedBox& box = boxes[index];
      const Eigen::Vector3f q = p - box.center;
      const float c = box.cos_yaw, s = box.sin_yaw;
      const Eigen::Vector3f local(c * q.x() + s * q.y(), -s * q.x() + c * q.y(), q.z());
      Eigen::Vector3f scaled = local.cwiseQuotient(box.half_extents).cwiseAbs();
      int axis = 0;
      scaled.maxCoeff(&axis);
      Eigen::Vector3f local_normal = Eigen::Vector3f::Zero();
      local_normal[axis] = local[axis] >= 0.0f ? 1.0f : -1.0f;
      normal = Eigen::Vector3f(c * local_normal.x() - s * local_normal.y(),
                               s * local_normal.x() + c * local_normal.y(), local_normal.z());
      hit.label = scene.boxes[index].label;
      hit.reflectance = scene.boxes[index].reflectance;
    } else if (kind == kCylinder) {
      const SceneCylinder& cyl = scene.cylinders[index];
      if (p.z() >= cyl.z_max_m - 1e-4f) {
        normal = Eigen::Vector3f::UnitZ();
      } else {
        normal = Eigen::Vector3f(p.x() - cyl.center.x(), p.y() - cyl.center.y(), 0.0f);
      }
      hit.label = cyl.label;
      hit.reflectance = cyl.reflectance;
    } else {
      const SceneEllipsoid& e = scene.ellipsoids[index];
      normal = (p - e.center).cwiseQuotient(e.radii.cwiseProduct(e.radii));
      hit.label = e.label;
      hit.reflectance = e.reflectance;
    }
  }
  normal.normalize();
  if (normal.dot(d) > 0.0f) normal = -normal;
  hit.normal = normal;
  return hit;
}

absl::StatusOr<LidarSimulator> LidarSimulator::Create(const StreetScene& scene,
                                                      const LidarSensorOptions& options) {
  auto invalid = [](auto&&... parts) {
    return absl::InvalidArgumentError(absl::StrCat("LidarSimulator: ", parts...));
  };
  if (options.beam_count < 1 || options.beam_count > 256) {
    return invalid("beam_count must be in [1, 256], got ", options.beam_count);
  }
  if (options.azimuth_steps < 1 || options.azimuth_steps > 100000) {
    return invalid("azimuth_steps must be in [1, 100000], got ", options.azimuth_steps);
  }
  if (!(options.min_range_m >= 0.0 && options.min_range_m < options.max_range_m &&
        options.max_range_m <= 10000.0)) {
    return invalid("need 0 <= min_range_m < max_range_m <= 10000, got ", options.min_range_m,
                   " and ", options.max_range_m);
  }
  if (!(options.max_elevation_deg <= 90.0 && options.min_elevation_deg >= -90.0 &&
        options.min_elevation_deg <= options.max_elevation_deg)) {
    return invalid("need -90 <= min_elevation_deg <= max_elevation_deg <= 90, got ",
                   options.min_elevation_deg, " and ", options.max_elevation_deg);
  }
  if (!(options.range_noise_sigma_m >= 0.0) || !(options.intensity_noise_sigma >= 0.0)) {
    return invalid("noise sigmas must be non-negative");
  }
  if (!(options.dropout_probability >= 0.0 && options.dropout_probability < 1.0)) {
    return invalid("dropout_probability must be in [0, 1), got ", options.dropout_probability);
  }

  auto index = std::make_shared<SceneIndex>();
  index->scene = scene;
  const StreetScene& s = index->scene;
  if (s.boxes.size() + s.cylinders.size() + s.ellipsoids.size() > kIndexMask) {
    return invalid("too many primitives");
  }
  // Footprints (xy bounds) of every primitive and zone.
  Eigen::AlignedBox2f bounds;
  std::vector<Eigen::AlignedBox2f> footprints;
  std::vector<uint32_t> refs;
  for (size_t i = 0; i < s.boxes.size(); ++i) {
    const SceneBox& box = s.boxes[i];
    if (!FinitePositive(box.half_extents.minCoeff()) || !box.center.allFinite() ||
        !std::isfinite(box.yaw_rad)) {
      return invalid("box ", i, " has a non-finite or non-positive size");
    }
    IndexedBox indexed{box.center, box.half_extents, std::cos(box.yaw_rad), std::sin(box.yaw_rad)};
    index->boxes.push_back(indexed);
    const float ex = std::abs(indexed.cos_yaw) * box.half_extents.x() +
                     std::abs(indexed.sin_yaw) * box.half_extents.y();
    const float ey = std::abs(indexed.sin_yaw) * box.half_extents.x() +
                     std::abs(indexed.cos_yaw) * box.half_extents.y();
    const Eigen::Vector2f c = box.center.head<2>(), e(ex, ey);
    footprints.emplace_back(c - e, c + e);
    refs.push_back((kBox << kKindShift) | static_cast<uint32_t>(i));
    index->z_top = std::max(index->z_top, box.center.z() + box.half_extents.z());
    index->z_bottom = std::min(index->z_bottom, box.center.z() - box.half_extents.z());
  }
  for (size_t i = 0; i < s.cylinders.size(); ++i) {
    const SceneCylinder& cyl = s.cylinders[i];
    if (!FinitePositive(cyl.radius_m) || !FinitePositive(cyl.z_max_m - cyl.z_min_m) ||
        !cyl.center.allFinite()) {
      return invalid("cylinder ", i, " has a non-finite or non-positive size");
    }
    const Eigen::Vector2f e(cyl.radius_m, cyl.radius_m);
    footprints.emplace_back(cyl.center - e, cyl.center + e);
    refs.push_back((kCylinder << kKindShift) | static_cast<uint32_t>(i));
    index->z_top = std::max(index->z_top, cyl.z_max_m);
    index->z_bottom = std::min(index->z_bottom, cyl.z_min_m);
  }
  for (size_t i = 0; i < s.ellipsoids.size(); ++i) {
    const SceneEllipsoid& e = s.ellipsoids[i];
    if (!FinitePositive(e.radii.minCoeff()) || !e.center.allFinite()) {
      return invalid("ellipsoid ", i, " has a non-finite or non-positive size");
    }
    const Eigen::Vector2f c = e.center.head<2>(), r = e.radii.head<2>();
    footprints.emplace_back(c - r, c + r);
    refs.push_back((kEllipsoid << kKindShift) | static_cast<uint32_t>(i));
    index->z_top = std::max(index->z_top, e.center.z() + e.radii.z());
    index->z_bottom = std::min(index->z_bottom, e.center.z() - e.radii.z());
  }
  index->primitive_count = static_cast<uint32_t>(refs.size());
  std::vector<Eigen::AlignedBox2f> zone_footprints;
  for (const GroundZone& zone : s.ground_zones) {
    const float c = std::cos(zone.yaw_rad), sn = std::sin(zone.yaw_rad);
    index->zone_cos_sin.emplace_back(c, sn);
    const Eigen::Vector2f e(std::abs(c) * zone.half_length_m + std::abs(sn) * zone.half_width_m,
                            std::abs(sn) * zone.half_length_m + std::abs(c) * zone.half_width_m);
    zone_footprints.emplace_back(zone.center - e, zone.center + e);
  }
  for (const auto& f : footprints) bounds.extend(f);
  for (const auto& f : zone_footprints) bounds.extend(f);
  if (!bounds.isEmpty()) {
    // 4 m cells, coarser if the scene is huge (at most ~4M cells).
    const Eigen::Vector2f size = bounds.sizes() + Eigen::Vector2f(1e-3f, 1e-3f);
    index->cell = std::max(4.0f, std::sqrt(size.x() * size.y() / 4.0e6f));
    index->min_x = bounds.min().x();
    index->min_y = bounds.min().y();
    index->nx = std::max(1, static_cast<int>(std::ceil(size.x() / index->cell)));
    index->ny = std::max(1, static_cast<int>(std::ceil(size.y() / index->cell)));
    const size_t cells = static_cast<size_t>(index->nx) * index->ny;
    auto fill = [&](const std::vector<Eigen::AlignedBox2f>& boxes, const std::vector<uint32_t>* ids,
                    std::vector<uint32_t>* start, std::vector<uint32_t>* out) {
      start->assign(cells + 1, 0);
      auto for_cells = [&](const Eigen::AlignedBox2f& f, auto&& visit) {
        const int x0 = std::clamp(index->CellX(f.min().x()), 0, index->nx - 1);
        const int x1 = std::clamp(index->CellX(f.max().x()), 0, index->nx - 1);
        const int y0 = std::clamp(index->CellY(f.min().y()), 0, index->ny - 1);
        const int y1 = std::clamp(index->CellY(f.max().y()), 0, index->ny - 1);
        for (int y = y0; y <= y1; ++y) {
          for (int x = x0; x <= x1; ++x) visit(static_cast<size_t>(y) * index->nx + x);
        }
      };
      for (const auto& f : boxes) for_cells(f, [&](size_t c) { ++(*start)[c + 1]; });
      for (size_t c = 0; c < cells; ++c) (*start)[c + 1] += (*start)[c];
      out->resize((*start)[cells]);
      std::vector<uint32_t> cursor(start->begin(), start->end() - 1);
      for (size_t i = 0; i < boxes.size(); ++i) {
        const uint32_t id = ids != nullptr ? (*ids)[i] : static_cast<uint32_t>(i);
        for_cells(boxes[i], [&](size_t c) { (*out)[cursor[c]++] = id; });
      }
    };
    fill(footprints, &refs, &index->cell_start, &index->cell_refs);
    fill(zone_footprints, nullptr, &index->zone_start, &index->zone_refs);
  }
  return LidarSimulator(std::move(index), options);
}

double LidarSimulator::BeamElevationRad(int beam) const {
  const double top = options_.max_elevation_deg, bottom = options_.min_elevation_deg;
  const double deg =
      options_.beam_count == 1
          ? top
          : top - (top - bottom) * beam / static_cast<double>(options_.beam_count - 1);
  return deg * M_PI / 180.0;
}

std::optional<LidarRayHit> LidarSimulator::CastRay(const Eigen::Vector3f& origin,
                                                   const Eigen::Vector3f& direction,
                                                   float max_distance_m) const {
  std::vector<uint32_t> mailbox(index_->primitive_count, 0);
  float t = 0.0f;
  const uint32_t ref = index_->Cast(origin, direction, max_distance_m, &mailbox, 1, &t);
  if (ref == SceneIndex::kNoHit) return std::nullopt;
  return index_->Describe(ref, origin, direction, t);
}

LidarScan LidarSimulator::SimulateScan(const Eigen::Isometry3d& T_world_sensor,
                                       uint64_t seed) const {
  const int beams = options_.beam_count, steps = options_.azimuth_steps;
  std::vector<float> cos_azimuth(steps), sin_azimuth(steps);
  for (int k = 0; k < steps; ++k) {
    const double azimuth = 2.0 * M_PI * k / steps;
    cos_azimuth[k] = static_cast<float>(std::cos(azimuth));
    sin_azimuth[k] = static_cast<float>(std::sin(azimuth));
  }
  const Eigen::Matrix3f rotation = T_world_sensor.linear().cast<float>();
  const Eigen::Vector3f origin = T_world_sensor.translation().cast<float>();
  const float max_range = static_cast<float>(options_.max_range_m);
  const float min_range = static_cast<float>(options_.min_range_m);

  SeededRandom random(seed);
  std::vector<uint32_t> mailbox(index_->primitive_count, 0);
  uint32_t ray_id = 0;
  LidarScan scan;
  const size_t rays = static_cast<size_t>(beams) * steps;
  scan.cloud.points.reserve(rays);
  scan.cloud.intensities.reserve(rays);
  scan.labels.reserve(rays);
  scan.beam_indices.reserve(rays);
  for (int beam = 0; beam < beams; ++beam) {
    const double elevation = BeamElevationRad(beam);
    const float cos_e = static_cast<float>(std::cos(elevation));
    const float sin_e = static_cast<float>(std::sin(elevation));
    for (int k = 0; k < steps; ++k) {
      const Eigen::Vector3f local(cos_e * cos_azimuth[k], cos_e * sin_azimuth[k], sin_e);
      const Eigen::Vector3f direction = rotation * local;
      if (++ray_id == 0) {  // wrapped: reset the stamps
        std::fill(mailbox.begin(), mailbox.end(), 0);
        ray_id = 1;
      }
      float t = 0.0f;
      const uint32_t ref = index_->Cast(origin, direction, max_range, &mailbox, ray_id, &t);
      if (ref == SceneIndex::kNoHit || t < min_range) continue;
      if (random.Bernoulli(options_.dropout_probability)) continue;
      const float range = t + static_cast<float>(random.Normal(0.0, options_.range_noise_sigma_m));
      const LidarRayHit hit = index_->Describe(ref, origin, direction, t);
      const float incidence = std::abs(hit.normal.dot(direction));
      float intensity = hit.reflectance * (0.35f + 0.65f * incidence) *
                        (1.0f - 0.3f * std::min(1.0f, t / max_range));
      intensity += static_cast<float>(random.Normal(0.0, options_.intensity_noise_sigma));
      scan.cloud.points.push_back(local * range);
      scan.cloud.intensities.push_back(std::clamp(intensity, 0.0f, 1.0f));
      scan.labels.push_back(hit.label);
      scan.beam_indices.push_back(static_cast<uint8_t>(beam));
    }
  }
  return scan;
}

}  // namespace rpsr::core
