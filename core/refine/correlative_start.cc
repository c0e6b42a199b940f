#include "core/refine/correlative_start.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "core/refine/cell_index.h"
#include "core/tree/morton.h"

namespace rpsr::core {
namespace {

// The target's occupied cells at one depth as a dense bitset over the cube (2^(3d) bits: 256 KB
// at depth 7), so that a lookup is an index and a bit test, not a hash probe: the search makes
// millions of them.
class Occupancy {
 public:
  Occupancy(const Octree& target, int depth, const std::vector<uint8_t>* marked)
      : side_(int64_t{1} << depth) {
    bits_.assign(static_cast<size_t>((side_ * side_ * side_ + 63) / 64), 0);
    const std::vector<uint64_t>& codes = target.level(depth).morton;
    for (size_t node = 0; node < codes.size(); ++node) {
      if (marked != nullptr && !(*marked)[node]) continue;
      const std::array<uint32_t, 3> cell = DecodeMorton<3>(codes[node]);
      const int64_t i = Index(cell[0], cell[1], cell[2]);
      bits_[static_cast<size_t>(i >> 6)] |= uint64_t{1} << (i & 63);
    }
  }
  bool Occupied(int64_t x, int64_t y, int64_t z) const {
    if (x < 0 || y < 0 || z < 0 || x >= side_ || y >= side_ || z >= side_) return false;
    const int64_t i = Index(x, y, z);
    return (bits_[static_cast<size_t>(i >> 6)] >> (i & 63)) & 1;
  }

 private:
  int64_t Index(int64_t x, int64_t y, int64_t z) const { return (z * side_ + y) * side_ + x; }
  int64_t side_;
  std::vector<uint64_t> bits_;
};

}  // namespace

int CorrelativeSearchDepth(const Octree& source, const Octree& target,
                           const CorrelativeSearchOptions& options) {
  const int deepest = std::min(source.max_depth(), target.max_depth());
  return options.depth < 0 ? std::clamp(deepest - 3, 1, kMaxCorrelativeDepth) : options.depth;
}

absl::StatusOr<CorrelativeStart> FindCorrelativeStart(const Octree& source, const Octree& target,
                                                      const Eigen::Isometry3d& initial,
                                                      const CorrelativeSearchOptions& options) {
  if (source.max_depth() < 0 || target.max_depth() < 0 || source.num_points() == 0 ||
      target.num_points() == 0) {
    return absl::InvalidArgumentError("FindCorrelativeStart: a tree is empty");
  }
  if (!initial.matrix().allFinite()) {
    return absl::InvalidArgumentError("FindCorrelativeStart: the initial guess is not finite");
  }
  const int deepest = std::min(source.max_depth(), target.max_depth());
  const int depth = CorrelativeSearchDepth(source, target, options);
  if (depth < 1 || depth > deepest || depth > kMaxCorrelativeDepth || options.max_shift_cells < 0 ||
      !(options.max_yaw_deg >= 0) || options.max_source_nodes <= 0) {
    return absl::InvalidArgumentError(
        absl::StrCat("FindCorrelativeStart: depth ", depth, " must be within the trees (1..",
                     deepest, ") and at most ", kMaxCorrelativeDepth,
                     "; max_shift_cells and max_yaw_deg non-negative, max_source_nodes positive"));
  }
  if ((options.source_nodes != nullptr &&
       options.source_nodes->size() != source.level(depth).size()) ||
      (options.target_nodes != nullptr &&
       options.target_nodes->size() != target.level(depth).size())) {
    return absl::InvalidArgumentError(absl::StrCat(
        "FindCorrelativeStart: the node masks must be sized as the trees' depth ", depth));
  }
  const Occupancy occupied(target, depth, options.target_nodes);
  const double edge = CellEdge(target, depth);
  const Eigen::Vector3d corner = target.center() - Eigen::Vector3d::Constant(target.half_length());

  // The scored source nodes, moved by the initial guess, about the pivot (their weighted CoM).
  const Octree::Level& level = source.level(depth);
  std::vector<uint32_t> scored;  // the marked source nodes (all when unmarked)
  for (size_t node = 0; node < level.size(); ++node) {
    if (options.source_nodes == nullptr || (*options.source_nodes)[node]) {
      scored.push_back(static_cast<uint32_t>(node));
    }
  }
  if (scored.empty()) {
    return absl::InvalidArgumentError("FindCorrelativeStart: no source node is marked");
  }
  const size_t n = scored.size();
  const size_t used = std::min(n, static_cast<size_t>(options.max_source_nodes));
  std::vector<Eigen::Vector3d> moved;
  moved.reserve(used);
  Eigen::Vector3d pivot = Eigen::Vector3d::Zero();
  for (size_t k = 0; k < used; ++k) {
    moved.push_back(initial * level.center_of_mass[scored[k * n / used]].cast<double>());
    pivot += moved.back();
  }
  pivot /= static_cast<double>(used);
  double mean_r2 = 0.0;
  for (const Eigen::Vector3d& p : moved) mean_r2 += (p - pivot).head<2>().squaredNorm();
  const double rms_r = std::sqrt(mean_r2 / static_cast<double>(used));
  const double max_yaw = options.max_yaw_deg * M_PI / 180.0;
  // At most 20 steps each way (a cloud wide against its cells would otherwise ask for hundreds:
  // the search's time is bounded whatever the input).
  const double yaw_step = rms_r > 0 ? std::max(0.5 * edge / rms_r, max_yaw / 20.0) : max_yaw + 1.0;
  const int yaw_half_steps = yaw_step > 0 ? static_cast<int>(std::floor(max_yaw / yaw_step)) : 0;
  // A search over every turn would try +-180 degrees twice (the same rotation).
  const int yaw_last = yaw_half_steps > 0 && yaw_half_steps * yaw_step >= M_PI - 1e-9
                           ? yaw_half_steps - 1
                           : yaw_half_steps;
  const int shift = options.max_shift_cells;

  CorrelativeStart best;
  best.depth = depth;
  int best_hits = -1;
  int64_t best_distance = 0;  // ties go to the candidate nearest the initial guess
  std::vector<std::array<int64_t, 3>> cell(used);
  for (int yi = -yaw_half_steps; yi <= yaw_last; ++yi) {
    const double yaw = yi * yaw_step;
    const Eigen::Matrix3d Rz = Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix();
    for (size_t k = 0; k < used; ++k) {
      const Eigen::Vector3d q = (Rz * (moved[k] - pivot) + pivot - corner) / edge;
      for (int a = 0; a < 3; ++a) cell[k][a] = static_cast<int64_t>(std::floor(q[a]));
    }
    for (int dy = -shift; dy <= shift; ++dy) {
      for (int dx = -shift; dx <= shift; ++dx) {
        int hits = 0;
        for (const auto& c : cell) hits += occupied.Occupied(c[0] + dx, c[1] + dy, c[2]);
        ++best.candidates;
        const int64_t distance = int64_t{dx} * dx + int64_t{dy} * dy + int64_t{yi} * yi;
        if (yi == 0 && dx == 0 && dy == 0) {
          best.initial_score = static_cast<double>(hits) / static_cast<double>(used);
        }
        if (hits > best_hits || (hits == best_hits && distance < best_distance)) {
          best_hits = hits;
          best_distance = distance;
          Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
          T.linear() = Rz;
          T.translation() = pivot - Rz * pivot + Eigen::Vector3d(dx * edge, dy * edge, 0.0);
          best.T_target_source = T * initial;
        }
      }
    }
  }
  best.score = static_cast<double>(best_hits) / static_cast<double>(used);
  return best;
}

}  // namespace rpsr::core
