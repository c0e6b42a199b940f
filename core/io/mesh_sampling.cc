#include "core/io/mesh_sampling.h"

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include "absl/strings/str_cat.h"

namespace rpsr::core {
namespace {

// Uniform double in [0, 1) from 53 random bits: identical on every standard library.
double UniformUnit(std::mt19937_64& rng) { return (rng() >> 11) * (1.0 / 9007199254740992.0); }

}  // namespace

absl::StatusOr<PointCloud> SampleSurface(const TriangleMesh& mesh, size_t num_points,
                                         uint64_t seed) {
  if (absl::Status valid = ValidateTriangleMesh(mesh); !valid.ok()) return valid;
  // Cumulative areas, in double so that millions of small triangles do not lose the tail.
  std::vector<double> cumulative_area;
  cumulative_area.reserve(mesh.triangles.size());
  double total = 0.0;
  for (size_t t = 0; t < mesh.triangles.size(); ++t) {
    const Eigen::Vector3i& tri = mesh.triangles[t];
    const Eigen::Vector3d a = mesh.vertices[tri.x()].cast<double>();
    const Eigen::Vector3d b = mesh.vertices[tri.y()].cast<double>();
    const Eigen::Vector3d c = mesh.vertices[tri.z()].cast<double>();
    total += 0.5 * (b - a).cross(c - a).norm();
    cumulative_area.push_back(total);
  }
  if (!(total > 0.0)) {
    return absl::InvalidArgumentError(absl::StrCat(
        "mesh has no surface to sample (", mesh.triangles.size(), " triangles, total area 0)"));
  }

  std::mt19937_64 rng(seed);
  PointCloud cloud;
  cloud.points.reserve(num_points);
  for (size_t i = 0; i < num_points; ++i) {
    const double pick = UniformUnit(rng) * total;
    const size_t t =
        std::min<size_t>(std::upper_bound(cumulative_area.begin(), cumulative_area.end(), pick) -
                             cumulative_area.begin(),
                         cumulative_area.size() - 1);
    const Eigen::Vector3i& tri = mesh.triangles[t];
    const double s = std::sqrt(UniformUnit(rng));
    const double r = UniformUnit(rng);
    // Barycentric (1 - s, s (1 - r), s r) is uniform over the triangle.
    const Eigen::Vector3d p = (1.0 - s) * mesh.vertices[tri.x()].cast<double>() +
                              s * (1.0 - r) * mesh.vertices[tri.y()].cast<double>() +
                              s * r * mesh.vertices[tri.z()].cast<double>();
    cloud.points.push_back(p.cast<float>());
  }
  return cloud;
}

}  // namespace rpsr::core
