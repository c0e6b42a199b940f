#include "core/io/kitti_bin.h"

#include <bit>
#include <cmath>
#include <cstring>

#include "absl/strings/str_cat.h"
#include "core/io/file_bytes.h"

namespace rpsr::core {

static_assert(std::endian::native == std::endian::little,
              "KITTI .bin is little-endian; a big-endian host needs byte swapping here");

namespace {
constexpr size_t kRecordBytes = 4 * sizeof(float);
}  // namespace

absl::StatusOr<PointCloud> ParseKittiBin(absl::string_view bytes, absl::string_view name) {
  if (bytes.size() % kRecordBytes != 0) {
    return absl::InvalidArgumentError(
        absl::StrCat(name, ": ", bytes.size(),
                     " bytes is not a whole number of 16-byte (x, y, z, "
                     "reflectance) float32 records; the file is truncated or not a KITTI scan"));
  }
  const size_t count = bytes.size() / kRecordBytes;
  PointCloud cloud;
  cloud.points.resize(count);
  cloud.intensities.resize(count);
  for (size_t i = 0; i < count; ++i) {
    float record[4];
    std::memcpy(record, bytes.data() + i * kRecordBytes, kRecordBytes);
    if (!std::isfinite(record[0]) || !std::isfinite(record[1]) || !std::isfinite(record[2])) {
      return absl::InvalidArgumentError(absl::StrCat(name, ": record ", i, " (byte offset ",
                                                     i * kRecordBytes,
                                                     ") has a non-finite coordinate"));
    }
    cloud.points[i] = Eigen::Vector3f(record[0], record[1], record[2]);
    cloud.intensities[i] = record[3];
  }
  return cloud;
}

absl::StatusOr<PointCloud> ReadKittiBin(const std::string& path) {
  absl::StatusOr<std::string> bytes = ReadFileBytes(path);
  if (!bytes.ok()) return bytes.status();
  return ParseKittiBin(*bytes, path);
}

absl::Status WriteKittiBin(const std::string& path, const PointCloud& cloud) {
  if (!cloud.intensities.empty() && cloud.intensities.size() != cloud.points.size()) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": cloud has ", cloud.points.size(),
                                                   " points but ", cloud.intensities.size(),
                                                   " intensities"));
  }
  std::string bytes(cloud.points.size() * kRecordBytes, '\0');
  for (size_t i = 0; i < cloud.points.size(); ++i) {
    const float record[4] = {cloud.points[i].x(), cloud.points[i].y(), cloud.points[i].z(),
                             cloud.intensities.empty() ? 0.0f : cloud.intensities[i]};
    std::memcpy(bytes.data() + i * kRecordBytes, record, kRecordBytes);
  }
  return WriteFileBytes(path, bytes);
}

}  // namespace rpsr::core
