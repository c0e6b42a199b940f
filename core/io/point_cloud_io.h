// Reading and writing point clouds and meshes by file extension (case-insensitive):
//
//   extension    ReadPointCloud                  WritePointCloud             ReadTriangleMesh
//   .ply         vertices (+ intensity)          binary little-endian float  vertices + faces
//   .pcd         x y z (+ intensity)             binary                      -
//   .xyz .txt    first 3 whitespace columns      "x y z" lines               -
//   .csv         first 3 comma columns           "x,y,z" header and lines    -
//   .bin         KITTI velodyne float32 x y z r  KITTI (reflectance 0 if none)  -
//   .off         the mesh's vertices             vertices, no faces          vertices + faces
//
// See ply.h, pcd.h, xyz_text.h, kitti_bin.h and off.h for each format's subset and errors. An
// unknown extension gives InvalidArgument listing the supported ones.
#ifndef RPSR_CORE_IO_POINT_CLOUD_IO_H_
#define RPSR_CORE_IO_POINT_CLOUD_IO_H_

#include <string>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "core/cloud/point_cloud.h"

namespace rpsr::core {

// Reads the points of a .ply .pcd .xyz .txt .csv .bin or .off file (a mesh gives its vertices).
absl::StatusOr<PointCloud> ReadPointCloud(const std::string& path);

// Writes `cloud` in the format its extension names (.ply .pcd .xyz .txt .csv .bin .off).
absl::Status WritePointCloud(const std::string& path, const PointCloud& cloud);

// Reads a triangle mesh from a .ply file with a `face` element or an .off file. InvalidArgument
// for another extension or a PLY without faces.
absl::StatusOr<TriangleMesh> ReadTriangleMesh(const std::string& path);

}  // namespace rpsr::core

#endif  // RPSR_CORE_IO_POINT_CLOUD_IO_H_
