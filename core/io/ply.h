// PLY (Stanford polygon file format) point clouds and meshes.
//
// Supported subset, reading:
//   - formats `ascii 1.0`, `binary_little_endian 1.0`, `binary_big_endian 1.0`;
//   - scalar property types char/int8, uchar/uint8, short/int16, ushort/uint16, int/int32,
//     uint/uint32, float/float32, double/float64, and list properties of them;
//   - element `vertex` (required) with scalar properties `x`, `y`, `z` of any numeric type;
//     a scalar `intensity` or `reflectance` property goes to PointCloud::intensities; every other
//     vertex property is read past and ignored;
//   - element `face` with a list property `vertex_indices` (or `vertex_index`) of integer count
//     and integer index types; polygons are fan-triangulated (v0 v1 v2, v0 v2 v3, ...);
//   - any other element (edges, materials, ...) is read past, in every format;
//   - `comment` and `obj_info` header lines are ignored; "\r\n" header lines are accepted.
// ASCII data is read as a stream of whitespace-separated tokens (one record per line is not
// required).
//
// Errors. Every malformed input gives InvalidArgument -- truncated data included, since a short
// file and a header that over-declares are the same thing to a parser -- with a message
// "<name>: <place>: <what is wrong>", where the place is a header line, or the element, record
// and property together with the line (ascii) or byte offset (binary). Rejected: a missing `ply`
// magic or `end_header`, unknown keywords or types, declared counts above 1e9 or larger than the
// remaining bytes can hold (checked before any allocation), records that run past the end, bytes
// or tokens left after the last element, non-finite or float-overflowing coordinates, faces with
// fewer than 3 or out-of-range vertex indices. Intensities are stored as read (not checked).
#ifndef RPSR_CORE_IO_PLY_H_
#define RPSR_CORE_IO_PLY_H_

#include <string>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"
#include "core/cloud/point_cloud.h"

namespace rpsr::core {

// What a PLY file holds. `cloud` has one point per vertex (and intensities when the vertices have
// an `intensity` / `reflectance` property). `mesh` is filled only when the file has a `face`
// element (`has_faces`): the same vertices and the fan-triangulated faces.
struct PlyContents {
  PointCloud cloud;
  TriangleMesh mesh;
  bool has_faces = false;
};

enum class PlyFormat { kAscii, kBinaryLittleEndian, kBinaryBigEndian };

// Type the writers use for vertex coordinates (and intensities): `float` or `double`.
enum class PlyCoordinateType { kFloat32, kFloat64 };

// Parses the bytes of a PLY file; `name` labels errors (usually the path).
absl::StatusOr<PlyContents> ParsePly(absl::string_view bytes, absl::string_view name);

// Reads and parses a PLY file (NotFound / PermissionDenied / ResourceExhausted from the read).
absl::StatusOr<PlyContents> ReadPly(const std::string& path);

// The bytes of a PLY file holding `cloud`: element vertex with x y z (and `intensity` when the
// cloud has intensities). InvalidArgument when the cloud fails ValidatePointCloud.
absl::StatusOr<std::string> SerializePly(const PointCloud& cloud, PlyFormat format,
                                         PlyCoordinateType coordinate_type);

// The bytes of a PLY file holding `mesh`: element vertex (x y z) and element face
// (`property list uchar int vertex_indices`). InvalidArgument for a non-finite vertex or a
// triangle that indexes a missing vertex.
absl::StatusOr<std::string> SerializePly(const TriangleMesh& mesh, PlyFormat format,
                                         PlyCoordinateType coordinate_type);

// Serialize and write atomically (see WriteFileBytes); errors name `path`.
absl::Status WritePly(const std::string& path, const PointCloud& cloud,
                      PlyFormat format = PlyFormat::kBinaryLittleEndian,
                      PlyCoordinateType coordinate_type = PlyCoordinateType::kFloat32);
absl::Status WritePly(const std::string& path, const TriangleMesh& mesh,
                      PlyFormat format = PlyFormat::kBinaryLittleEndian,
                      PlyCoordinateType coordinate_type = PlyCoordinateType::kFloat32);

}  // namespace rpsr::core

#endif  // RPSR_CORE_IO_PLY_H_
