#include "core/refine/weak_direction_chamfer.h"

#include <algorithm>
#include <cmath>
#include <utility>
#include <vector>

#include "Eigen/Eigenvalues"
#include "core/refine/cell_index.h"
#include "core/refine/node_closeness.h"
#include "core/refine/weak_direction_start.h"

namespace rpsr::core {
namespace {

// Per node of `depth`: how much a motion that moves the tree's point x to `moved` * x crosses the
// node's shape one depth up (the nearest ancestor there or above holding 3 points): the squared
// share of the motion along a plane's normal, or across a line. The motion is read in the tree's
// own frame (`placed` places the tree where the motion acts).
std::vector<double> CrossingWeights(const Octree& tree, int depth, const Eigen::Isometry3d& placed,
                                    const Eigen::Isometry3d& moved, double line_ratio) {
  constexpr int kMinShapeCount = 3;
  const Octree::Level& level = tree.level(depth);
  std::vector<double> weights(level.size(), 0.0);
  // Siblings share their parent's shape, and are adjacent in the Morton order.
  std::pair<int, int> last = {-1, -1};
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver;
  for (size_t i = 0; i < level.size(); ++i) {
    std::pair<int, int> shape = ShapeNodeOf(tree, depth - 1, level.parent[i], kMinShapeCount);
    if (shape.first < 0) shape = {0, 0};  // a tree of fewer points: the root's spread, whatever
    if (shape != last) {
      solver.computeDirect(tree.Covariance(shape.first, shape.second).cast<double>());
      last = shape;
    }
    const Eigen::Vector3d x = level.center_of_mass[i].cast<double>();
    const Eigen::Vector3d motion = placed.linear().transpose() * (moved * x - placed * x);
    if (!(motion.norm() > 0.0)) continue;
    const Eigen::Vector3d v = motion.normalized();
    const Eigen::Vector3d values = solver.eigenvalues();  // ascending
    if (values[1] < line_ratio * values[2]) {
      const double along = solver.eigenvectors().col(2).dot(v);
      weights[i] = 1.0 - along * along;
    } else {
      const double across = solver.eigenvectors().col(0).dot(v);
      weights[i] = across * across;
    }
  }
  return weights;
}

}  // namespace

std::optional<WeakChamferMove> ChamferAlongWeakestDirection(const Octree& source,
                                                            const Octree& target,
                                                            const TreeRefinementResult& answer,
                                                            int depth,
                                                            const WeakChamferOptions& options) {
  if (depth < 1 || depth > source.max_depth() || depth > target.max_depth()) return std::nullopt;
  if (!(answer.normalized_eigenvalues[0] >= options.min_weakest_eigenvalue)) return std::nullopt;
  const double edge = CellEdge(target, depth);
  const Eigen::Isometry3d& at = answer.T_target_source;
  const int half = static_cast<int>(std::lround(options.reach_cells / options.step_cells));
  std::vector<double> steps;
  std::vector<double> steps_m;
  for (int k = -half; k <= half; ++k) {
    steps.push_back(k * options.step_cells);
    steps_m.push_back(steps.back() * edge);
  }
  const std::vector<Eigen::Isometry3d> poses = StepsAlongWeakestDirection(answer, steps_m);
  if (poses.empty()) return std::nullopt;  // no weakest direction
  // The direction's motion, one probe cell long: the source's nodes move from `at` to `probed`,
  // the target's (seen from the source) by the inverse motion.
  const Eigen::Isometry3d probed = StepAlongWeakestDirection(answer, edge);
  const std::vector<double> source_weights =
      CrossingWeights(source, depth, at, probed, options.line_eigenvalue_ratio);
  const std::vector<double> target_weights =
      CrossingWeights(target, depth, Eigen::Isometry3d::Identity(), at * probed.inverse(),
                      options.line_eigenvalue_ratio);
  std::vector<Eigen::Isometry3d> inverses;
  for (const Eigen::Isometry3d& pose : poses) inverses.push_back(pose.inverse());
  const std::vector<double> there =
      WeightedMeanNodeDistanceCells(source, target, poses, depth, source_weights);
  const std::vector<double> back =
      WeightedMeanNodeDistanceCells(target, source, inverses, depth, target_weights);
  std::vector<double> measure(poses.size());
  for (size_t k = 0; k < poses.size(); ++k) {
    if (there[k] < 0.0 || back[k] < 0.0) return std::nullopt;
    measure[k] = 0.5 * (there[k] + back[k]);
  }
  const size_t answer_index = static_cast<size_t>(half);
  const size_t best =
      static_cast<size_t>(std::min_element(measure.begin(), measure.end()) - measure.begin());
  double move = steps[best];
  if (best > 0 && best + 1 < measure.size()) {
    const double a = measure[best - 1];
    const double b = measure[best];
    const double c = measure[best + 1];
    const double curvature = a - 2.0 * b + c;
    if (curvature > 0.0) move += 0.5 * options.step_cells * (a - c) / curvature;
  }
  const double drop =
      measure[answer_index] > 0.0 ? 1.0 - measure[best] / measure[answer_index] : 0.0;
  if (!(std::abs(move) >= options.min_move_cells) || !(drop >= options.min_drop)) {
    return std::nullopt;
  }
  WeakChamferMove out;
  out.T_target_source = StepAlongWeakestDirection(answer, move * edge);
  out.move_cells = move;
  out.drop = drop;
  return out;
}

}  // namespace rpsr::core
