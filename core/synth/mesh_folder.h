// A folder of mesh files as an object source: the user's own CAD models (e.g. ModelNet40's OFF
// files) instead of, or besides, the procedural families. Listing is sorted, so a folder gives
// the same objects in the same order on every run; pair them with MakeObjectPairFromMesh
// (core/data/object_pairs.h).
#ifndef RPSR_CORE_SYNTH_MESH_FOLDER_H_
#define RPSR_CORE_SYNTH_MESH_FOLDER_H_

#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "core/cloud/point_cloud.h"

namespace rpsr::core {

// Paths of the regular files in `folder` whose extension is .off or .ply (case-insensitive),
// sorted by path (byte order). With `recursive`, subfolders are searched too (ModelNet's
// <class>/<train|test>/*.off layout). NotFound when `folder` is not a directory; an empty list
// when it holds no mesh.
absl::StatusOr<std::vector<std::string>> ListMeshFiles(const std::string& folder,
                                                       bool recursive = false);

// ReadTriangleMesh (core/io/point_cloud_io.h) followed by NormalizedIntoUnitCube: the mesh
// centred and scaled into [-1, 1]^3. Errors from either step, prefixed with the path.
absl::StatusOr<TriangleMesh> ReadNormalizedMesh(const std::string& path);

}  // namespace rpsr::core

#endif  // RPSR_CORE_SYNTH_MESH_FOLDER_H_
