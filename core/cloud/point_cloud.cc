#include "core/cloud/point_cloud.h"

#include "absl/strings/str_cat.h"

namespace rpsr::core {

absl::Status ValidatePointCloud(const PointCloud& cloud) {
  if (!cloud.intensities.empty() && cloud.intensities.size() != cloud.points.size()) {
    return absl::InvalidArgumentError(absl::StrCat("point cloud has ", cloud.points.size(),
                                                   " points but ", cloud.intensities.size(),
                                                   " intensities; give one per point or none"));
  }
  for (size_t i = 0; i < cloud.points.size(); ++i) {
    const Eigen::Vector3f& p = cloud.points[i];
    if (!p.allFinite()) {
      return absl::InvalidArgumentError(absl::StrCat("point ", i, " is not finite (", p.x(), ", ",
                                                     p.y(), ", ", p.z(),
                                                     "); remove NaN/Inf points before sending"));
    }
  }
  return absl::OkStatus();
}

absl::Status ValidateTriangleMesh(const TriangleMesh& mesh) {
  for (size_t v = 0; v < mesh.vertices.size(); ++v) {
    if (!mesh.vertices[v].allFinite()) {
      return absl::InvalidArgumentError(absl::StrCat("mesh vertex ", v, " is not finite"));
    }
  }
  const int64_t num_vertices = static_cast<int64_t>(mesh.vertices.size());
  for (size_t t = 0; t < mesh.triangles.size(); ++t) {
    const Eigen::Vector3i& tri = mesh.triangles[t];
    if ((tri.array() < 0).any() || (tri.cast<int64_t>().array() >= num_vertices).any()) {
      return absl::InvalidArgumentError(
          absl::StrCat("mesh triangle ", t, " indexes vertex (", tri.x(), ", ", tri.y(), ", ",
                       tri.z(), ") but the mesh has ", num_vertices, " vertices"));
    }
  }
  return absl::OkStatus();
}

Eigen::AlignedBox3f BoundsOf(const std::vector<Eigen::Vector3f>& points) {
  Eigen::AlignedBox3f box;  // Default-constructed: empty (min = +max float, max = lowest).
  for (const Eigen::Vector3f& p : points) box.extend(p);
  return box;
}

PointCloud TransformedCloud(const PointCloud& cloud, const Eigen::Isometry3f& T) {
  PointCloud out;
  out.points.reserve(cloud.points.size());
  for (const Eigen::Vector3f& p : cloud.points) out.points.push_back(T * p);
  out.intensities = cloud.intensities;
  return out;
}

}  // namespace rpsr::core
