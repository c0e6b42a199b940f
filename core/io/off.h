// OFF (Object File Format) polygon meshes, as in ModelNet and Princeton Shape Benchmark.
//
// Supported subset, reading: the ascii form. The first line is `OFF`, or a variant with a prefix
// of C (vertex colours), N (normals), ST (texture coordinates) such as `COFF` / `NOFF`; the counts
// "<vertices> <faces> [<edges>]" follow on the next line or on the same one, including the
// ModelNet quirk "OFF490 518 0" with no space. Then one vertex a line (x y z first; colours,
// normals and the like after them are ignored) and one face a line ("n i0 ... i(n-1)", optional
// colour values after the indices ignored). Polygons are fan-triangulated. '#' starts a comment
// anywhere on a line; blank lines are skipped. Binary OFF (`OFF BINARY`) and 4OFF / nOFF give
// Unimplemented.
//
// Errors: InvalidArgument "<name>: line N (vertex K | face K): <what is wrong>" for a wrong magic,
// counts above 1e9, too few lines for the counts or lines after the last face, a vertex line
// with fewer than 3 numbers or a non-finite coordinate, a face with fewer than 3 indices, fewer
// indices than it declares, or an index out of range.
#ifndef RPSR_CORE_IO_OFF_H_
#define RPSR_CORE_IO_OFF_H_

#include <string>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"
#include "core/cloud/point_cloud.h"

namespace rpsr::core {

// Parses the text of an OFF file; `name` labels errors (usually the path).
absl::StatusOr<TriangleMesh> ParseOff(absl::string_view text, absl::string_view name);

// Reads and parses an OFF file (NotFound / PermissionDenied / ResourceExhausted from the read).
absl::StatusOr<TriangleMesh> ReadOff(const std::string& path);

// The text of an OFF file holding `mesh` (one "3 a b c" line per triangle; shortest exact
// decimals for the vertices). InvalidArgument for a non-finite vertex or a triangle that indexes
// a missing vertex.
absl::StatusOr<std::string> SerializeOff(const TriangleMesh& mesh);

// Serializes and writes atomically (see WriteFileBytes); errors name `path`.
absl::Status WriteOff(const std::string& path, const TriangleMesh& mesh);

}  // namespace rpsr::core

#endif  // RPSR_CORE_IO_OFF_H_
