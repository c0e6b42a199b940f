#include "core/refine/noise_polish.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

#include "Eigen/Cholesky"
#include "Eigen/Eigenvalues"
#include "core/tree/morton.h"

namespace rpsr::core {
namespace {

struct Partner {
  int node = -1;
  const Eigen::Vector3d* normal = nullptr;
};

// The nearest target CoM to q among the 3x3x3 cells around its cell, if it has a plane; else the
// nearest that has one. Ties go to the lower index (the answer does not depend on the visiting
// order). The scatter measure reads each node once, so nothing is remembered between calls.
Partner NearestWithPlane(const PlaneLevel& target, const Eigen::Vector3d& q) {
  const Octree::Level& level = target.tree->level(target.depth);
  const BlockHome at = LocateBlockHome(*target.tree, target.depth, q);
  std::array<int32_t, 27> block;
  FindBlock(*target.index, at.home, at.side, 27, int64_t{1} << target.depth, block.data());
  // The nearest; only when it has no plane, the nearest of those that have one.
  for (bool need_plane : {false, true}) {
    int32_t best = -1;
    double best_d2 = 0.0;
    for (const int32_t j : block) {
      if (j < 0) continue;
      const double d2 = (level.center_of_mass[j].cast<double>() - q).squaredNorm();
      if (best >= 0 && (d2 > best_d2 || (d2 == best_d2 && j > best))) continue;
      if (need_plane && target.normal(j) == nullptr) continue;
      best = j;
      best_d2 = d2;
    }
    if (best < 0) return {};
    if (const Eigen::Vector3d* normal = target.normal(best)) return {best, normal};
  }
  return {};
}

}  // namespace

double MedianSurfaceScatterCells(const Octree& source, int source_depth, const PlaneLevel& target,
                                 const Eigen::Isometry3d& T_target_source, size_t max_nodes) {
  const Octree::Level& level = source.level(source_depth);
  const Octree::Level& target_level = target.tree->level(target.depth);
  if (level.size() == 0 || max_nodes == 0) return -1.0;
  const size_t stride = (level.size() + max_nodes - 1) / max_nodes;
  const double edge = CellEdge(*target.tree, target.depth);
  std::vector<double> distances;
  distances.reserve(level.size() / stride + 1);
  // The 3x3x3 block, not the 2x2x2 nearest one: a node a cell off the surface often has no
  // partner within half a cell, and leaving such nodes out would read a jittered cloud as
  // thinner than it is (unseen objects under jitter 0.08: median 0.43 instead of 0.61).
  for (size_t i = 0; i < level.size(); i += stride) {
    const Eigen::Vector3d q = T_target_source * level.center_of_mass[i].cast<double>();
    const Partner p = NearestWithPlane(target, q);
    if (p.node < 0) continue;
    const Eigen::Vector3d offset = q - target_level.center_of_mass[p.node].cast<double>();
    distances.push_back(std::abs(p.normal->dot(offset)) / edge);
  }
  if (distances.empty()) return -1.0;
  const auto middle = distances.begin() + static_cast<std::ptrdiff_t>(distances.size() / 2);
  std::nth_element(distances.begin(), middle, distances.end());
  return *middle;
}

PolishSides::PolishSides(const Octree& source_tree, const Octree& target_tree, int depth,
                         const PlanePolishOptions& options)
    : source(SmoothNodes(source_tree, depth,
                         options.kernel_radius_cells * CellEdge(target_tree, depth),
                         options.max_nodes)),
      target(target_tree, depth, options.kernel_radius_cells * CellEdge(target_tree, depth)),
      supports(source.points.size(), 0.5 * CellEdge(target_tree, depth)) {}

PlanePolishResult PolishPointToPlane(PolishSides& sides, const Eigen::Isometry3d& T_target_source,
                                     const PlanePolishOptions& options) {
  const SmoothedNodes& source = sides.source;
  const SurfaceKernel& target = sides.target;
  PlanePolishResult result;
  result.T_target_source = T_target_source;
  const double edge = CellEdge(target.tree(), target.depth());
  const double k2 = options.robust_scale_cells * options.robust_scale_cells * edge * edge;
  Eigen::Matrix3d R = T_target_source.linear();
  Eigen::Vector3d t = T_target_source.translation();
  struct Term {
    Eigen::Vector3d moved;
    Eigen::Vector3d normal;
    double residual = 0.0;
    double weight = 0.0;
  };
  std::vector<Term> terms;
  terms.reserve(source.points.size());
  for (int iteration = 0; iteration < options.max_iterations; ++iteration) {
    terms.clear();
    Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
    double weight_sum = 0.0;
    for (size_t i = 0; i < source.points.size(); ++i) {
      const Eigen::Vector3d q = R * source.points[i] + t;
      const SurfaceMoments m = sides.supports.At(target, i, q);
      if (m.points < options.min_support_points) continue;
      // The closed form (a jittered object pair 0.92-0.94x, the same recalls): it loses accuracy
      // only where the least eigenvalue nears another, where no solver's normal means much.
      Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver;
      solver.computeDirect(m.spread);
      const Eigen::Vector3d normal = solver.eigenvectors().col(0);
      const double r = normal.dot(q - m.mean);
      const double g = k2 / (k2 + r * r);
      const double w = source.weights[i] * g * g;
      terms.push_back({q, normal, r, w});
      centroid += w * q;
      weight_sum += w;
    }
    result.correspondences = static_cast<int>(terms.size());
    if (result.correspondences < options.min_correspondences || !(weight_sum > 0.0)) break;
    // About the weighted centroid, so the rotation and translation columns are well separated:
    // a point moves by w x (q - c) + v.
    const Eigen::Vector3d center = centroid / weight_sum;
    Eigen::Matrix<double, 6, 6> H = Eigen::Matrix<double, 6, 6>::Zero();
    Eigen::Matrix<double, 6, 1> b = Eigen::Matrix<double, 6, 1>::Zero();
    for (const Term& term : terms) {
      Eigen::Matrix<double, 6, 1> J;
      J.head<3>() = (term.moved - center).cross(term.normal);
      J.tail<3>() = term.normal;
      H.noalias() += term.weight * J * J.transpose();
      b.noalias() += term.weight * term.residual * J;
    }
    // A trace-relative damping keeps directions the planes leave free (along a plane, about a
    // line's axis) from dividing rounding noise in b by rounding noise in H: that ratio is a step
    // of any size, which the step cap below would refuse, stopping the whole polish (tested:
    // DampingKeepsRoundingNoiseFromStoppingIt). Damped, those steps are ~0.
    const double mean_diagonal = H.trace() / 6.0;
    if (!(mean_diagonal > 0.0)) break;
    H.diagonal().array() += 1e-9 * mean_diagonal;
    const Eigen::LDLT<Eigen::Matrix<double, 6, 6>> solver(H);
    if (solver.info() != Eigen::Success) break;
    const Eigen::Matrix<double, 6, 1> x = solver.solve(-b);
    if (!x.allFinite()) break;
    const double angle = x.head<3>().norm();
    if (angle > options.max_step_rad || x.tail<3>().norm() > options.max_step_cells * edge) break;
    const Eigen::Matrix3d dR =
        angle > 0.0 ? Eigen::AngleAxisd(angle, x.head<3>() / angle).toRotationMatrix()
                    : Eigen::Matrix3d::Identity();
    R = dR * R;
    t = dR * (t - center) + center + x.tail<3>();
    R = Eigen::Quaterniond(R).normalized().toRotationMatrix();
    ++result.iterations;
    result.last_update_rotation_rad = angle;
    result.last_update_translation = x.tail<3>().norm();
    if (angle < options.rotation_epsilon_rad &&
        result.last_update_translation < options.translation_epsilon_cells * edge) {
      result.converged = true;
      break;
    }
  }
  result.T_target_source.linear() = R;
  result.T_target_source.translation() = t;
  return result;
}

}  // namespace rpsr::core
