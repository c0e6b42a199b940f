// Area-weighted, seeded sampling of points on the surface of a triangle mesh.
#ifndef RPSR_CORE_IO_MESH_SAMPLING_H_
#define RPSR_CORE_IO_MESH_SAMPLING_H_

#include <cstddef>
#include <cstdint>

#include "absl/status/statusor.h"
#include "core/cloud/point_cloud.h"

namespace rpsr::core {

// Draws `num_points` points uniformly over the mesh's surface: a triangle is chosen with
// probability proportional to its area, then a point uniformly inside it (square-root
// barycentric sampling). The same mesh, count and seed give the same points on every platform
// (std::mt19937_64 and our own uniform mapping; no std:: distributions, whose output is
// implementation-defined).
//
// Errors: InvalidArgument when the mesh has no triangle of positive area, a triangle indexes a
// vertex that does not exist, or a vertex is not finite.
absl::StatusOr<PointCloud> SampleSurface(const TriangleMesh& mesh, size_t num_points,
                                         uint64_t seed);

}  // namespace rpsr::core

#endif  // RPSR_CORE_IO_MESH_SAMPLING_H_
