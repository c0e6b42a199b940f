#include "core/refine/weak_direction_start.h"

#include <cmath>

#include "Eigen/Eigenvalues"
#include "core/refine/cell_index.h"
#include "core/refine/node_closeness.h"

namespace rpsr::core {
namespace {

using Vector6d = Eigen::Matrix<double, 6, 1>;
using Matrix6d = Eigen::Matrix<double, 6, 6>;

struct WeakestDirection {
  Vector6d direction = Vector6d::Zero();  // unit, rotation rows in metres
  bool found = false;
};

// The weakest direction of the information in metres (InformationInMetres), unit.
WeakestDirection FindWeakestDirection(const TreeRefinementResult& answer) {
  WeakestDirection weakest;
  for (int a = 0; a < 3; ++a) {
    if (!(answer.rotation_lever_arms[a] > 0.0)) return weakest;
  }
  const Matrix6d scaled = InformationInMetres(answer);
  if (!scaled.allFinite()) return weakest;
  Eigen::SelfAdjointEigenSolver<Matrix6d> solver(scaled);
  const double largest = solver.eigenvalues().maxCoeff();
  if (!(largest > 0.0)) return weakest;
  weakest.direction = solver.eigenvectors().col(0);
  weakest.found = true;
  return weakest;
}

Eigen::Isometry3d Step(const TreeRefinementResult& answer, const Vector6d& direction,
                       double step_m) {
  return MotionFromMetres(answer, step_m * direction) * answer.T_target_source;
}

}  // namespace

Eigen::Isometry3d StepAlongWeakestDirection(const TreeRefinementResult& answer, double step_m) {
  const WeakestDirection weakest = FindWeakestDirection(answer);
  if (!weakest.found) return answer.T_target_source;
  return Step(answer, weakest.direction, step_m);
}

std::vector<Eigen::Isometry3d> StepsAlongWeakestDirection(const TreeRefinementResult& answer,
                                                          const std::vector<double>& steps_m) {
  std::vector<Eigen::Isometry3d> poses;
  const WeakestDirection weakest = FindWeakestDirection(answer);
  if (!weakest.found) return poses;
  poses.reserve(steps_m.size());
  for (double step_m : steps_m) poses.push_back(Step(answer, weakest.direction, step_m));
  return poses;
}

std::optional<WeakDirectionStart> BestWeakDirectionStart(const Octree& source, const Octree& target,
                                                         const TreeRefinementResult& answer,
                                                         int depth,
                                                         const WeakDirectionOptions& options) {
  if (depth < 1 || depth > source.max_depth() || depth > target.max_depth()) return std::nullopt;
  const WeakestDirection weakest = FindWeakestDirection(answer);
  if (!weakest.found) return std::nullopt;
  const double edge = CellEdge(target, depth);
  std::vector<Eigen::Isometry3d> poses = {answer.T_target_source};
  std::vector<double> steps = {0.0};
  for (double cells : options.steps_cells) {
    for (double sign : {1.0, -1.0}) {
      steps.push_back(sign * cells);
      poses.push_back(Step(answer, weakest.direction, sign * cells * edge));
    }
  }
  // The steps measured only as far as the best one that may be kept needs (the same best step as
  // measuring every pose both ways, bit for bit, for less than half the work).
  const std::vector<Eigen::Isometry3d> stepped(poses.begin() + 1, poses.end());
  const TwoWayFarWithinDrop measured =
      TwoWayFarNodeFractionsWithinDrop(source, target, answer.T_target_source, stepped, depth,
                                       options.far_cells, options.min_far_fraction_drop);
  if (measured.answer < 0.0) return std::nullopt;
  const double most = measured.answer - options.min_far_fraction_drop;
  std::vector<double> far = {measured.answer};
  far.insert(far.end(), measured.candidates.begin(), measured.candidates.end());
  int best = -1;
  for (size_t k = 1; k < far.size(); ++k) {
    if (far[k] >= 0.0 && (best < 0 || far[k] < far[best])) best = static_cast<int>(k);
  }
  if (best < 0 || far[best] > most) return std::nullopt;
  WeakDirectionStart start;
  start.T_target_source = poses[best];
  start.step_cells = steps[best];
  start.far_fraction = far[best];
  start.answer_far_fraction = far[0];
  return start;
}

}  // namespace rpsr::core
