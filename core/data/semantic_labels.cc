#include "core/data/semantic_labels.h"

#include <bit>
#include <cstring>

#include "absl/strings/str_cat.h"
#include "core/io/file_bytes.h"
#include "core/synth/street_scene.h"

namespace rpsr::core {

static_assert(std::endian::native == std::endian::little,
              "SemanticKITTI .label is little-endian; a big-endian host needs byte swapping here");

bool IsGroundClass(uint16_t semantic_class) {
  namespace sk = semantic_kitti;
  switch (semantic_class) {
    case sk::kRoad:
    case sk::kParking:
    case sk::kSidewalk:
    case sk::kOtherGround:
    case sk::kLaneMarking:
    case sk::kTerrain:
      return true;
    default:
      return false;
  }
}

absl::StatusOr<std::vector<uint32_t>> ParseSemanticKittiLabels(absl::string_view bytes,
                                                               absl::string_view name) {
  if (bytes.size() % sizeof(uint32_t) != 0) {
    return absl::InvalidArgumentError(
        absl::StrCat(name, ": ", bytes.size(),
                     " bytes is not a whole number of 4-byte uint32 labels; the file is truncated "
                     "or not a SemanticKITTI .label file"));
  }
  std::vector<uint32_t> labels(bytes.size() / sizeof(uint32_t));
  if (!labels.empty()) std::memcpy(labels.data(), bytes.data(), bytes.size());
  return labels;
}

absl::StatusOr<std::vector<uint32_t>> ReadSemanticKittiLabels(const std::string& path) {
  absl::StatusOr<std::string> bytes = ReadFileBytes(path);
  if (!bytes.ok()) return bytes.status();
  return ParseSemanticKittiLabels(*bytes, path);
}

absl::Status WriteSemanticKittiLabels(const std::string& path,
                                      const std::vector<uint32_t>& labels) {
  std::string bytes(labels.size() * sizeof(uint32_t), '\0');
  if (!labels.empty()) std::memcpy(bytes.data(), labels.data(), bytes.size());
  return WriteFileBytes(path, bytes);
}

absl::StatusOr<PointCloud> RemoveGroundPoints(const PointCloud& cloud,
                                              const std::vector<uint32_t>& labels,
                                              absl::string_view labels_name) {
  if (labels.size() != cloud.size()) {
    return absl::InvalidArgumentError(absl::StrCat(labels_name, ": ", labels.size(),
                                                   " labels for a scan of ", cloud.size(),
                                                   " points; the label file does not belong to "
                                                   "this scan"));
  }
  const bool has_intensities = cloud.intensities.size() == cloud.size();
  PointCloud kept;
  kept.points.reserve(cloud.size());
  if (has_intensities) kept.intensities.reserve(cloud.size());
  for (size_t i = 0; i < cloud.size(); ++i) {
    if (IsGroundClass(SemanticClassOf(labels[i]))) continue;
    kept.points.push_back(cloud.points[i]);
    if (has_intensities) kept.intensities.push_back(cloud.intensities[i]);
  }
  return kept;
}

}  // namespace rpsr::core
