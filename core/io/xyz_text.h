// Plain-text point lists: .xyz / .txt (values separated by spaces or tabs) and .csv (values
// separated by commas).
//
// Supported subset, reading: one point a line with 3 or more numeric columns, of which the first
// three are x y z and the rest are ignored (colours, normals, intensities: their meaning varies
// between tools). Blank lines and lines starting with '#' are skipped; "\r\n" endings accepted.
// CSV only: a first line none of whose first three columns is a number ("x,y,z", "X, Y, Z, i")
// is taken as a header and skipped. An empty text is an empty cloud.
//
// Errors: InvalidArgument "<name>: line N: <what is wrong>" for a line with fewer than three
// columns, a column that is not a number, or a non-finite coordinate.
#ifndef RPSR_CORE_IO_XYZ_TEXT_H_
#define RPSR_CORE_IO_XYZ_TEXT_H_

#include <string>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"
#include "core/cloud/point_cloud.h"

namespace rpsr::core {

enum class XyzTextDelimiter {
  kWhitespace,  // .xyz, .txt
  kComma,       // .csv
};

// Parses the text of a point list; `name` labels errors (usually the path). Intensities are
// never filled.
absl::StatusOr<PointCloud> ParseXyzText(absl::string_view text, absl::string_view name,
                                        XyzTextDelimiter delimiter);

// Reads and parses a point list (NotFound / PermissionDenied / ResourceExhausted from the read).
absl::StatusOr<PointCloud> ReadXyzText(const std::string& path, XyzTextDelimiter delimiter);

// The text of a point list: "x y z" lines, or for kComma an "x,y,z" header and "x,y,z" lines,
// with the shortest decimals that read back exactly. Intensities are not written.
// InvalidArgument when the cloud fails ValidatePointCloud.
absl::StatusOr<std::string> SerializeXyzText(const PointCloud& cloud, XyzTextDelimiter delimiter);

// Serializes and writes atomically (see WriteFileBytes); errors name `path`.
absl::Status WriteXyzText(const std::string& path, const PointCloud& cloud,
                          XyzTextDelimiter delimiter);

}  // namespace rpsr::core

#endif  // RPSR_CORE_IO_XYZ_TEXT_H_
