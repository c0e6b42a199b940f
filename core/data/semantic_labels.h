// SemanticKITTI point labels: a .label file next to each velodyne scan holds one little-endian
// uint32 per point of the scan, in the scan's order. The lower 16 bits are the semantic class
// (the ids in core/synth/street_scene.h's semantic_kitti namespace), the upper 16 an instance id.
//
// Ground, for the paper's K1-w/o setup, is the SemanticKITTI "ground" category: road (40),
// parking (44), sidewalk (48), other-ground (49), lane-marking (60), plus terrain (72), the grass
// and soil between them, which is as flat and as uninformative for registration as the rest.
// Vegetation, trunks, buildings and every object stay.
#ifndef RPSR_CORE_DATA_SEMANTIC_LABELS_H_
#define RPSR_CORE_DATA_SEMANTIC_LABELS_H_

#include <cstdint>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"
#include "core/cloud/point_cloud.h"

namespace rpsr::core {

inline uint16_t SemanticClassOf(uint32_t label) { return static_cast<uint16_t>(label & 0xffffu); }
inline uint16_t InstanceIdOf(uint32_t label) { return static_cast<uint16_t>(label >> 16); }
inline uint32_t MakeSemanticKittiLabel(uint16_t semantic_class, uint16_t instance_id = 0) {
  return (static_cast<uint32_t>(instance_id) << 16) | semantic_class;
}

// True for the ground classes listed above (40, 44, 48, 49, 60, 72).
bool IsGroundClass(uint16_t semantic_class);

// Parses the bytes of a .label file; `name` labels errors. InvalidArgument when the size is not a
// multiple of 4 bytes.
absl::StatusOr<std::vector<uint32_t>> ParseSemanticKittiLabels(absl::string_view bytes,
                                                               absl::string_view name);

// Reads a .label file (NotFound / PermissionDenied when it cannot be opened).
absl::StatusOr<std::vector<uint32_t>> ReadSemanticKittiLabels(const std::string& path);

// Writes `labels` as a .label file (atomically, see WriteFileBytes).
absl::Status WriteSemanticKittiLabels(const std::string& path, const std::vector<uint32_t>& labels);

// The points of `cloud` whose label is not ground (intensities follow their points).
// InvalidArgument naming `labels_name` when the label count differs from the point count.
absl::StatusOr<PointCloud> RemoveGroundPoints(const PointCloud& cloud,
                                              const std::vector<uint32_t>& labels,
                                              absl::string_view labels_name);

}  // namespace rpsr::core

#endif  // RPSR_CORE_DATA_SEMANTIC_LABELS_H_
