// Scaling objects into the paper's [-1, 1] cube, and sampling normalised objects as point clouds.
// The normalisation is applied to the MESH, before any sampling, so that every cloud drawn from
// one object (a pair's source and target, sampled independently) shares one frame and one scale.
#ifndef RPSR_CORE_SYNTH_OBJECT_NORMALIZATION_H_
#define RPSR_CORE_SYNTH_OBJECT_NORMALIZATION_H_

#include <cstddef>
#include <cstdint>

#include "absl/status/statusor.h"
#include "core/cloud/point_cloud.h"

namespace rpsr::core {

// `mesh` moved so that its vertices' bounding box is centred at the origin and scaled uniformly
// by 1 / (largest half extent), so the largest side spans exactly [-1, 1] and the others fit
// inside. Unreferenced vertices count too (generators leave none). InvalidArgument when the mesh
// has no vertex, a non-finite vertex, or zero extent.
absl::StatusOr<TriangleMesh> NormalizedIntoUnitCube(const TriangleMesh& mesh);

// GenerateObject (shape_families.h) followed by NormalizedIntoUnitCube.
absl::StatusOr<TriangleMesh> GenerateNormalizedObject(size_t family_index, uint64_t object_seed);

// `num_points` points sampled from the surface of the normalised object (family_index,
// object_seed) with SampleSurface(..., sampling_seed). Every point lies in [-1, 1]^3.
absl::StatusOr<PointCloud> SampleNormalizedObject(size_t family_index, uint64_t object_seed,
                                                  size_t num_points, uint64_t sampling_seed);

}  // namespace rpsr::core

#endif  // RPSR_CORE_SYNTH_OBJECT_NORMALIZATION_H_
