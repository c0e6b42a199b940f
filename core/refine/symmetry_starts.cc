#include "core/refine/symmetry_starts.h"

#include <algorithm>
#include <cmath>
#include <complex>

#include "Eigen/Eigenvalues"
#include "core/refine/node_closeness.h"

namespace rpsr::core {
namespace {

Eigen::Isometry3d TurnAbout(const Eigen::Vector3d& centre, const Eigen::Vector3d& axis,
                            double angle_rad) {
  Eigen::Isometry3d S = Eigen::Isometry3d::Identity();
  S.linear() = Eigen::AngleAxisd(angle_rad, axis).toRotationMatrix();
  S.translation() = centre - S.linear() * centre;
  return S;
}

// The fold n in 3..max_folds whose circular harmonic of the finest nodes' angles about `axis`
// (through `centre`, each node weighted by its distance from the axis: a rim's teeth outweigh a
// hub) is strongest; 0 when there is none.
int StrongestFold(const Octree& tree, const Eigen::Vector3d& centre, const Eigen::Vector3d& axis,
                  int max_folds) {
  const Octree::Level& level = tree.level(tree.max_depth());
  const Eigen::Vector3d e1 = axis.unitOrthogonal();
  const Eigen::Vector3d e2 = axis.cross(e1);
  std::vector<double> angle(level.size());
  std::vector<double> weight(level.size());
  double total = 0.0;
  for (size_t i = 0; i < level.size(); ++i) {
    const Eigen::Vector3d p = level.center_of_mass[i].cast<double>() - centre;
    const double x = p.dot(e1);
    const double y = p.dot(e2);
    angle[i] = std::atan2(y, x);
    weight[i] = std::hypot(x, y);
    total += weight[i];
  }
  if (!(total > 0.0)) return 0;
  int best = 0;
  double best_amplitude = 0.0;
  for (int n = 3; n <= max_folds; ++n) {
    std::complex<double> sum = 0.0;
    for (size_t i = 0; i < level.size(); ++i) sum += weight[i] * std::polar(1.0, n * angle[i]);
    const double amplitude = std::abs(sum) / total;
    if (amplitude > best_amplitude) {
      best_amplitude = amplitude;
      best = n;
    }
  }
  return best;
}

}  // namespace

int SymmetryDepth(const Octree& source, const Octree& target) {
  return std::max(std::min(source.max_depth(), target.max_depth()) - 1, 1);
}

std::vector<SelfSymmetry> FindSelfSymmetries(const Octree& target,
                                             const SelfSymmetryOptions& options) {
  std::vector<SelfSymmetry> found;
  if (target.max_depth() < 2 || target.num_points() == 0) return found;
  const int depth = SymmetryDepth(target, target);
  const Eigen::Vector3d centre = target.level(0).center_of_mass[0].cast<double>();
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver(
      target.Covariance(0, 0).cast<double>());
  const Eigen::Vector3d variances = solver.eigenvalues();  // ascending
  auto try_turn = [&](int axis, double angle_rad) {
    const Eigen::Isometry3d S = TurnAbout(centre, solver.eigenvectors().col(axis), angle_rad);
    const double distance = MeanNodeDistanceCells(target, target, S, depth);
    if (distance < 0.0 || distance > options.max_self_distance_cells) return false;
    found.push_back({S, axis, angle_rad * 180.0 / M_PI, distance});
    return true;
  };
  for (int axis = 0; axis < 3; ++axis) {
    const double a = variances[(axis + 1) % 3];
    const double b = variances[(axis + 2) % 3];
    const bool round =
        std::max(a, b) > 0.0 && std::min(a, b) >= options.min_round_ratio * std::max(a, b);
    const int folds =
        round ? StrongestFold(target, centre, solver.eigenvectors().col(axis), options.max_folds)
              : 0;
    // One turn checked stands for its multiples (the fold's group); the half turn is checked on
    // its own where the fold has none.
    if (folds > 0 && try_turn(axis, 2.0 * M_PI / folds)) {
      for (int k = 2; k < folds; ++k) {
        const double angle = 2.0 * M_PI * k / folds;
        found.push_back({TurnAbout(centre, solver.eigenvectors().col(axis), angle), axis,
                         angle * 180.0 / M_PI, found.back().self_distance_cells});
      }
    }
  }
  return found;
}

double TwoWayFarFraction(const Octree& source, const Octree& target, const Eigen::Isometry3d& T,
                         const SelfSymmetryOptions& options) {
  const int depth = SymmetryDepth(source, target);
  const double there = FarNodeFraction(source, target, T, depth, options.far_cells);
  const double back = FarNodeFraction(target, source, T.inverse(), depth, options.far_cells);
  if (there < 0.0 || back < 0.0) return -1.0;
  return 0.5 * (there + back);
}

std::optional<SymmetricTwin> BestSymmetricTwin(const Octree& source, const Octree& target,
                                               const Eigen::Isometry3d& answer,
                                               const std::vector<SelfSymmetry>& symmetries,
                                               const SelfSymmetryOptions& options) {
  if (symmetries.empty()) return std::nullopt;
  SymmetricTwin best;
  best.answer_far_fraction = TwoWayFarFraction(source, target, answer, options);
  if (best.answer_far_fraction < 0.0) return std::nullopt;
  best.far_fraction = 2.0;
  for (const SelfSymmetry& symmetry : symmetries) {
    const Eigen::Isometry3d T = symmetry.S * answer;
    const double far = TwoWayFarFraction(source, target, T, options);
    if (far >= 0.0 && far < best.far_fraction) {
      best.far_fraction = far;
      best.T_target_source = T;
    }
  }
  if (best.far_fraction > best.answer_far_fraction - options.min_far_fraction_drop) {
    return std::nullopt;
  }
  return best;
}

}  // namespace rpsr::core
