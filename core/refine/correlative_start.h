// A start for the refinement on scene-scale clouds found by exhaustive search (issue 5): the
// motions of a ground vehicle between two scans are mostly a turn about the vertical axis and a
// shift in the horizontal plane, and the refinement's basin (about a cell of its coarsest depth
// on a street that repeats along the road) does not always hold motions of 10 m or more. So the
// candidates are the initial guess turned about the target's z axis (through the moved source's
// centre of mass) by a grid of yaw angles and shifted by a grid of whole cells in x and y, each
// scored by how many of the source's nodes land in cells the target occupies, at a depth three
// above the finest (3.75 m on a 240 m LiDAR cube): correlative scan matching on the trees'
// occupancy, with no raw points. The best candidate is a START, to be refined and compared with
// the other starts' results; it is not a pose to trust.
//
// Conventions: T_target_source maps source points into the target frame; z is "up" in the
// target frame (a LiDAR's sensor frame, as in KITTI). On clouds where it is not, the search only
// costs its time: its start is refined and kept only if its fit is better.
#ifndef RPSR_CORE_REFINE_CORRELATIVE_START_H_
#define RPSR_CORE_REFINE_CORRELATIVE_START_H_

#include <cstdint>
#include <vector>

#include "Eigen/Geometry"
#include "absl/status/statusor.h"
#include "core/tree/bh_tree.h"

namespace rpsr::core {

// The occupancy bitset holds 2^(3 depth) bits: 2 MB at depth 8, 128 MB at depth 10, so deeper
// trees (a server may allow depth 21) are searched at depth 8 at most.
inline constexpr int kMaxCorrelativeDepth = 8;

struct CorrelativeSearchOptions {
  // Occupancy depth, 1..kMaxCorrelativeDepth; < 0: three above the deepest depth both trees
  // hold, within that range: 3.75 m cells on a 240 m LiDAR cube, fine enough for a start that
  // the refinement's first stage (7.5 m cells) pulls in.
  int depth = -1;
  // Yaw candidates within +-max_yaw_deg of the initial guess, spaced so that the source's nodes
  // at their RMS distance from the pivot move about half a cell per step (at most 41 angles).
  double max_yaw_deg = 20.0;
  // Shifts of -max_shift_cells..max_shift_cells whole cells in x and y (+-22.5 m at 3.75 m).
  int max_shift_cells = 6;
  // Source nodes scored at most (an even stride over the Morton order).
  int max_source_nodes = 1500;
  // When set (each sized as its tree's level at the search's depth, CorrelativeSearchDepth): only
  // the source nodes marked 1 are scored and only the target nodes marked 1 occupy their cells.
  // The registrar's sensor-aligned check passes the structure off a scan's ground
  // (dominant_plane.h), whose cells are occupied wherever the scan reached.
  const std::vector<uint8_t>* source_nodes = nullptr;
  const std::vector<uint8_t>* target_nodes = nullptr;
};

// The occupancy depth a search with these options uses (options.depth, or its default).
int CorrelativeSearchDepth(const Octree& source, const Octree& target,
                           const CorrelativeSearchOptions& options = {});

struct CorrelativeStart {
  Eigen::Isometry3d T_target_source = Eigen::Isometry3d::Identity();
  // Fraction of the scored source nodes that land in occupied target cells: at the best
  // candidate and at the initial guess. Ties go to the candidate nearest the initial guess, so
  // score == initial_score means the best candidate IS the initial guess.
  double score = 0.0;
  double initial_score = 0.0;
  int candidates = 0;
  int depth = 0;
};

// InvalidArgument for empty trees, a non-finite initial guess or options out of range (depth
// beyond the trees or kMaxCorrelativeDepth, negative counts or angles).
absl::StatusOr<CorrelativeStart> FindCorrelativeStart(
    const Octree& source, const Octree& target, const Eigen::Isometry3d& initial_T_target_source,
    const CorrelativeSearchOptions& options = {});

}  // namespace rpsr::core

#endif  // RPSR_CORE_REFINE_CORRELATIVE_START_H_
