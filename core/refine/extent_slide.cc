#include "core/refine/extent_slide.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <utility>
#include <vector>

#include "core/refine/cell_index.h"
#include "core/refine/weak_direction_start.h"

namespace rpsr::core {

double ExtentAlong(const Octree& tree, int depth, const Eigen::Isometry3d& T,
                   const Eigen::Vector3d& axis, int rank) {
  const Octree::Level& level = tree.level(depth);
  if (rank < 1 || level.size() < static_cast<size_t>(rank)) {
    return -std::numeric_limits<double>::infinity();
  }
  // In the tree's own frame: a . (R mu + t) = (R^T a) . mu + a . t.
  const Eigen::Vector3d a = T.linear().transpose() * axis;
  // The `rank` greatest reaches so far, greatest first.
  std::vector<double> top(static_cast<size_t>(rank), -std::numeric_limits<double>::infinity());
  for (size_t j = 0; j < level.size(); ++j) {
    const double along = a.dot(level.center_of_mass[j].cast<double>());
    const double spread = a.dot(tree.Covariance(depth, static_cast<int>(j)).cast<double>() * a);
    const double reach = along + std::sqrt(std::max(spread, 0.0));
    if (reach > top.back()) {
      top.back() = reach;
      for (size_t i = top.size() - 1; i > 0 && top[i] > top[i - 1]; --i) {
        std::swap(top[i], top[i - 1]);
      }
    }
  }
  return top.back() + axis.dot(T.translation());
}

std::optional<ExtentSlide> SlideToMatchExtents(const Octree& source, const Octree& target,
                                               const TreeRefinementResult& answer, int depth,
                                               const ExtentSlideOptions& options) {
  if (depth < 0 || depth > source.max_depth() || depth > target.max_depth()) return std::nullopt;
  const double edge = CellEdge(target, depth);
  const double probe = options.probe_cells * edge;
  const Eigen::Isometry3d& at = answer.T_target_source;
  const Eigen::Isometry3d probed = StepAlongWeakestDirection(answer, probe);
  // The line the extents are read along: where the weakest direction moves the source's centre.
  // (The answer itself comes back when the information has no weakest direction.)
  const Eigen::Vector3d centre = source.level(0).center_of_mass[0].cast<double>();
  const Eigen::Vector3d moved = probed * centre - at * centre;
  if (!(moved.norm() >= options.min_centre_share * probe)) return std::nullopt;
  const Eigen::Vector3d axis = moved.normalized();
  // Each end: the target's reach, the source's at the answer and at the probe, and so how far
  // along the weakest direction that end asks the source to move.
  std::array<double, 2> slides{};
  for (int end = 0; end < 2; ++end) {
    const Eigen::Vector3d a = end == 0 ? axis : Eigen::Vector3d(-axis);
    const double wanted =
        ExtentAlong(target, depth, Eigen::Isometry3d::Identity(), a, options.rank);
    const double now = ExtentAlong(source, depth, at, a, options.rank);
    const double then = ExtentAlong(source, depth, probed, a, options.rank);
    const double rate = (then - now) / probe;  // ~ +1 at the end ahead, ~ -1 at the one behind
    if (!std::isfinite(wanted) || !std::isfinite(now) ||
        !(std::abs(rate) >= options.min_end_rate)) {
      return std::nullopt;
    }
    slides[end] = (wanted - now) / rate;
  }
  const double slide = 0.5 * (slides[0] + slides[1]);
  if (!(std::abs(slide) >= options.min_slide_cells * edge) ||
      !(std::abs(slide) <= options.max_slide_cells * edge) ||
      !(std::abs(slides[0] - slides[1]) <= options.max_end_disagreement * std::abs(slide))) {
    return std::nullopt;
  }
  ExtentSlide out;
  out.T_target_source = StepAlongWeakestDirection(answer, slide);
  out.slide_cells = slide / edge;
  out.ahead_end_cells = slides[0] / edge;
  out.behind_end_cells = slides[1] / edge;
  return out;
}

}  // namespace rpsr::core
