// Plain point-cloud and mesh types shared by every part of rpsr (I/O, trees, synthesis, the
// service and the client). They hold Eigen and standard types only, so any file may include them
// without pulling in LibTorch or gRPC.
#ifndef RPSR_CORE_CLOUD_POINT_CLOUD_H_
#define RPSR_CORE_CLOUD_POINT_CLOUD_H_

#include <cstddef>
#include <vector>

#include "Eigen/Core"
#include "Eigen/Geometry"
#include "absl/status/status.h"

namespace rpsr::core {

// A set of 3D points in metres, in the frame of whoever produced them (sensor, object, world).
// `intensities` is either empty or holds one value per point (e.g. KITTI reflectance); every
// algorithm in rpsr uses positions only.
struct PointCloud {
  std::vector<Eigen::Vector3f> points;
  std::vector<float> intensities;

  size_t size() const { return points.size(); }
  bool empty() const { return points.empty(); }
};

// A triangle mesh: vertices and counter-clockwise triangles (indices into `vertices`). Polygons
// read from files are fan-triangulated on input.
struct TriangleMesh {
  std::vector<Eigen::Vector3f> vertices;
  std::vector<Eigen::Vector3i> triangles;
};

// OK when every coordinate is finite and `intensities` is empty or matches `points`; otherwise
// InvalidArgument naming the first offending point index and value.
absl::Status ValidatePointCloud(const PointCloud& cloud);

// OK when every vertex is finite and every triangle indexes existing vertices; otherwise
// InvalidArgument naming the first offending vertex or triangle.
absl::Status ValidateTriangleMesh(const TriangleMesh& mesh);

// Axis-aligned bounds of `points`; for an empty set an empty box (`isEmpty()` is true).
Eigen::AlignedBox3f BoundsOf(const std::vector<Eigen::Vector3f>& points);

// Returns `cloud` with every point mapped by T (p -> T * p); intensities are kept.
PointCloud TransformedCloud(const PointCloud& cloud, const Eigen::Isometry3f& T);

}  // namespace rpsr::core

#endif  // RPSR_CORE_CLOUD_POINT_CLOUD_H_
