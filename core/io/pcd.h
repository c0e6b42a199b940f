// PCD (Point Cloud Library) point clouds, version 0.7 (and the 0.6 headers without VERSION /
// POINTS / VIEWPOINT).
//
// Supported subset, reading:
//   - header lines VERSION, FIELDS, SIZE, TYPE, COUNT (optional, default 1 each), WIDTH, HEIGHT
//     (optional, default 1), VIEWPOINT (ignored), POINTS (optional, default WIDTH * HEIGHT; when
//     present it must equal WIDTH * HEIGHT), DATA; '#' comment lines; "\r\n" line endings;
//   - DATA ascii (one point a line) and DATA binary (packed little-endian records of the sum of
//     SIZE * COUNT bytes); DATA binary_compressed gives Unimplemented;
//   - TYPE F with SIZE 4 or 8, TYPE I / U with SIZE 1, 2, 4 or 8;
//   - fields x, y, z (COUNT 1) are required; a COUNT-1 field `intensity` goes to
//     PointCloud::intensities; every other field (rgb, normal_x, padding `_`, ...) is read past
//     using its SIZE and COUNT and ignored.
//
// Errors. Every malformed input gives InvalidArgument -- truncated data included -- with a
// message "<name>: <place>: <what is wrong>", the place being a header line, a data line (ascii)
// or a point index and byte offset (binary). Rejected: unknown keywords, SIZE / TYPE / COUNT
// lists that do not match FIELDS, POINTS != WIDTH * HEIGHT, counts above 1e9, binary data that is
// shorter or longer than POINTS records (checked before any allocation), ascii point lines with
// the wrong number of values or more / fewer lines than POINTS, and non-finite coordinates (NaN
// points of organized clouds included: remove them before writing).
#ifndef RPSR_CORE_IO_PCD_H_
#define RPSR_CORE_IO_PCD_H_

#include <string>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"
#include "core/cloud/point_cloud.h"

namespace rpsr::core {

enum class PcdFormat { kAscii, kBinary };

// Parses the bytes of a PCD file; `name` labels errors (usually the path).
absl::StatusOr<PointCloud> ParsePcd(absl::string_view bytes, absl::string_view name);

// Reads and parses a PCD file (NotFound / PermissionDenied / ResourceExhausted from the read).
absl::StatusOr<PointCloud> ReadPcd(const std::string& path);

// The bytes of a PCD v0.7 file holding `cloud` as float32 fields x y z (and `intensity` when the
// cloud has intensities), WIDTH = POINTS = size, HEIGHT 1. InvalidArgument when the cloud fails
// ValidatePointCloud.
absl::StatusOr<std::string> SerializePcd(const PointCloud& cloud, PcdFormat format);

// Serializes and writes atomically (see WriteFileBytes); errors name `path`.
absl::Status WritePcd(const std::string& path, const PointCloud& cloud,
                      PcdFormat format = PcdFormat::kBinary);

}  // namespace rpsr::core

#endif  // RPSR_CORE_IO_PCD_H_
