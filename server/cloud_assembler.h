// Points on the wire (proto/rpsr/v1: packed little-endian float32 x y z, 12 bytes a point) into a
// cloud, and a cloud into the tree the session store caches.
//
// CloudAssembler checks an upload's chunks as they arrive, so that a lost, repeated or reordered
// chunk is an error and never a wrong cloud, and so that bad input is refused before it costs
// memory: the declared count is checked against the limit before anything is reserved.
#ifndef RPSR_SERVER_CLOUD_ASSEMBLER_H_
#define RPSR_SERVER_CLOUD_ASSEMBLER_H_

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "Eigen/Core"
#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"
#include "core/tree/bh_tree.h"

namespace rpsr::server {

inline constexpr size_t kBytesPerPoint = 12;

// Appends the points of `xyz` to `points`. InvalidArgument when the size is not a multiple of 12
// or a coordinate is not finite (naming the point by `first_index` + its position in `xyz`).
absl::Status AppendXyz(absl::string_view xyz, uint64_t first_index,
                       std::vector<Eigen::Vector3f>* points);

// Encodes points as the wire format (for tests and clients).
std::string EncodeXyz(const std::vector<Eigen::Vector3f>& points);

class CloudAssembler {
 public:
  // `what` names the cloud in messages ("upload", "frame 4").
  CloudAssembler(std::string what, uint64_t max_points);

  // The declared total. InvalidArgument for 0 (an empty cloud cannot be registered);
  // ResourceExhausted beyond max_points.
  absl::Status Begin(uint64_t point_count);

  // The next chunk: `sequence` must be the number of chunks received so far (0 first). A repeat,
  // a gap, more points than declared, a partial point or a non-finite coordinate is
  // InvalidArgument naming the chunk and the point.
  absl::Status AddChunk(uint32_t sequence, absl::string_view xyz);

  bool begun() const { return begun_; }
  bool complete() const { return begun_ && points_.size() == expected_; }
  // OK when complete; otherwise InvalidArgument saying how much arrived ("the upload ended after 2
  // chunks with 1000 of 5000 points: chunks are missing").
  absl::Status CheckComplete() const;

  uint64_t expected() const { return expected_; }
  uint64_t received() const { return points_.size(); }
  uint32_t chunks() const { return next_sequence_; }

  std::vector<Eigen::Vector3f> TakePoints() { return std::move(points_); }

 private:
  std::string what_;
  uint64_t max_points_;
  bool begun_ = false;
  uint64_t expected_ = 0;
  uint32_t next_sequence_ = 0;
  std::vector<Eigen::Vector3f> points_;
};

// The tree the service caches for a cloud: depth `max_depth`, neighbour tables to depth 5 (what
// the network reads). InvalidArgument from BuildBarnesHutTree (empty, non-finite, bad depth).
absl::StatusOr<std::shared_ptr<const core::Octree>> BuildCloudTree(
    const std::vector<Eigen::Vector3f>& points, int max_depth, uint64_t max_points);

}  // namespace rpsr::server

#endif  // RPSR_SERVER_CLOUD_ASSEMBLER_H_
