// KITTI velodyne scans: a flat little-endian array of float32 (x, y, z, reflectance) records,
// with no header. The point count is the file size / 16.
#ifndef RPSR_CORE_IO_KITTI_BIN_H_
#define RPSR_CORE_IO_KITTI_BIN_H_

#include <string>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"
#include "core/cloud/point_cloud.h"

namespace rpsr::core {

// Parses the bytes of a .bin scan; `name` labels errors (usually the path). Reflectance goes
// to `intensities`. Errors (InvalidArgument): a size that is not a multiple of 16 bytes, or a
// non-finite coordinate (named by record index).
absl::StatusOr<PointCloud> ParseKittiBin(absl::string_view bytes, absl::string_view name);

// Reads a .bin scan from disk (NotFound / PermissionDenied when it cannot be opened).
absl::StatusOr<PointCloud> ReadKittiBin(const std::string& path);

// Writes `cloud` as a .bin scan; reflectance is 0 where the cloud has no intensities.
absl::Status WriteKittiBin(const std::string& path, const PointCloud& cloud);

}  // namespace rpsr::core

#endif  // RPSR_CORE_IO_KITTI_BIN_H_
