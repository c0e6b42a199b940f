#include "core/synth/object_normalization.h"

#include "absl/strings/str_cat.h"
#include "core/io/mesh_sampling.h"
#include "core/synth/shape_families.h"

namespace rpsr::core {

absl::StatusOr<TriangleMesh> NormalizedIntoUnitCube(const TriangleMesh& mesh) {
  if (mesh.vertices.empty()) return absl::InvalidArgumentError("mesh has no vertices");
  for (size_t v = 0; v < mesh.vertices.size(); ++v) {
    if (!mesh.vertices[v].allFinite()) {
      return absl::InvalidArgumentError(absl::StrCat("mesh vertex ", v, " is not finite"));
    }
  }
  // Bounds in double so the centre and scale do not depend on float rounding of large inputs.
  Eigen::Vector3d low = mesh.vertices.front().cast<double>();
  Eigen::Vector3d high = low;
  for (const Eigen::Vector3f& v : mesh.vertices) {
    low = low.cwiseMin(v.cast<double>());
    high = high.cwiseMax(v.cast<double>());
  }
  const Eigen::Vector3d centre = 0.5 * (low + high);
  const double half_extent = 0.5 * (high - low).maxCoeff();
  if (!(half_extent > 0.0)) return absl::InvalidArgumentError("mesh has zero extent");
  TriangleMesh out;
  out.triangles = mesh.triangles;
  out.vertices.reserve(mesh.vertices.size());
  for (const Eigen::Vector3f& v : mesh.vertices) {
    // Clamp guards the last float rounding step; the true value is inside [-1, 1].
    const Eigen::Vector3d p = (v.cast<double>() - centre) / half_extent;
    out.vertices.push_back(p.cwiseMax(-1.0).cwiseMin(1.0).cast<float>());
  }
  return out;
}

absl::StatusOr<TriangleMesh> GenerateNormalizedObject(size_t family_index, uint64_t object_seed) {
  absl::StatusOr<TriangleMesh> mesh = GenerateObject(family_index, object_seed);
  if (!mesh.ok()) return mesh.status();
  return NormalizedIntoUnitCube(*mesh);
}

absl::StatusOr<PointCloud> SampleNormalizedObject(size_t family_index, uint64_t object_seed,
                                                  size_t num_points, uint64_t sampling_seed) {
  absl::StatusOr<TriangleMesh> mesh = GenerateNormalizedObject(family_index, object_seed);
  if (!mesh.ok()) return mesh.status();
  return SampleSurface(*mesh, num_points, sampling_seed);
}

}  // namespace rpsr::core
