#include "core/refine/far_valley.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <vector>

#include "core/refine/cell_index.h"
#include "core/refine/node_closeness.h"
#include "core/refine/weak_direction_start.h"

namespace rpsr::core {

std::optional<FarValleyMove> FarValleyAlongWeakestDirection(const Octree& source,
                                                            const Octree& target,
                                                            const TreeRefinementResult& answer,
                                                            int depth,
                                                            const FarValleyOptions& options) {
  if (depth < 1 || depth > source.max_depth() || depth > target.max_depth()) return std::nullopt;
  if (!(answer.normalized_eigenvalues[0] >= options.min_weakest_eigenvalue)) return std::nullopt;
  // At most kMaxSteps steps either way (a tiny step would otherwise ask for millions of poses).
  constexpr double kMaxSteps = 1000.0;
  if (!(options.step_cells > 0.0) || !(options.reach_cells >= options.step_cells) ||
      !(options.reach_cells / options.step_cells <= kMaxSteps)) {
    return std::nullopt;
  }
  const double edge = CellEdge(target, depth);
  const int half = static_cast<int>(std::lround(options.reach_cells / options.step_cells));
  std::vector<double> steps_m;
  for (int k = -half; k <= half; ++k) steps_m.push_back(k * options.step_cells * edge);
  const std::vector<Eigen::Isometry3d> poses = StepsAlongWeakestDirection(answer, steps_m);
  if (poses.empty()) return std::nullopt;  // no weakest direction
  // A source cut short (a crop) lacks one of the walls: the target's nodes it no longer covers
  // are far at every step, and the wall on that side rises elsewhere.
  const double uncovered =
      FarNodeFractions(target, source, {answer.T_target_source.inverse()}, depth, options.far_cells)
          .front();
  if (!(uncovered >= 0.0 && uncovered <= options.max_uncovered_fraction)) return std::nullopt;
  const std::vector<double> far =
      TwoWayFarNodeFractions(source, target, poses, depth, options.far_cells);
  const int n = static_cast<int>(far.size());
  if (!(far[half] >= 0.0)) return std::nullopt;
  // The least measured count; among equal ones the nearest the answer (the answer itself first).
  int least = half;
  for (int k = 0; k < n; ++k) {
    if (far[k] < 0.0) continue;
    if (far[k] < far[least] ||
        (far[k] == far[least] && std::abs(k - half) < std::abs(least - half))) {
      least = k;
    }
  }
  // The valley: the measured steps on either side of the least, contiguous, below the level the
  // walls reach a share of the way up (at least the tolerance above the least). Its ends are where
  // the legs move off the other cloud, steep and well placed; its floor is a node or two of
  // sampling noise, flat, so the least's own position says little.
  double highest = far[least];
  for (int k = 0; k < n; ++k) highest = std::max(highest, far[k]);
  const double ceiling =
      far[least] + std::max(options.floor_tolerance, options.wall_share * (highest - far[least]));
  int low = least;
  int high = least;
  while (low > 0 && far[low - 1] >= 0.0 && far[low - 1] <= ceiling) --low;
  while (high + 1 < n && far[high + 1] >= 0.0 && far[high + 1] <= ceiling) ++high;
  // Both walls must rise within the reach, measured: a valley running off the search, or into a
  // step that could not be measured, has no middle.
  if (low == 0 || high == n - 1 || !(far[low - 1] > ceiling) || !(far[high + 1] > ceiling)) {
    return std::nullopt;
  }
  const double valley_cells = (high - low) * options.step_cells;
  // The middle, half a step between two steps where the valley spans an odd number of them (so
  // that the minimum move reads alike on both sides).
  const double move_cells = (0.5 * (low + high) - half) * options.step_cells;
  if (!(valley_cells >= options.min_valley_cells) ||
      !(std::abs(move_cells) >= options.min_move_cells)) {
    return std::nullopt;
  }
  FarValleyMove out;
  out.T_target_source = StepAlongWeakestDirection(answer, move_cells * edge);
  out.move_cells = move_cells;
  out.valley_cells = valley_cells;
  out.least_fraction = far[least];
  out.answer_fraction = far[half];
  return out;
}

}  // namespace rpsr::core
