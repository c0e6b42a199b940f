#include "core/refine/noise_polish.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
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

// The nearest target CoM with a plane among the 27 cells around q's cell (ties to the lower
// index, so the answer does not depend on the visiting order).
Partner NearestWithPlane(const PlaneLevel& target, const Eigen::Vector3d& q) {
  const Octree& tree = *target.tree;
  const Octree::Level& level = tree.level(target.depth);
  const int64_t cells = int64_t{1} << target.depth;
  const std::array<uint32_t, 3> home = tree.CellOfPoint(q.cast<float>(), target.depth);
  Partner best;
  double best_d2 = 0.0;
  for (int dz = -1; dz <= 1; ++dz) {
    for (int dy = -1; dy <= 1; ++dy) {
      for (int dx = -1; dx <= 1; ++dx) {
        const int64_t x = int64_t{home[0]} + dx;
        const int64_t y = int64_t{home[1]} + dy;
        const int64_t z = int64_t{home[2]} + dz;
        if (x < 0 || y < 0 || z < 0 || x >= cells || y >= cells || z >= cells) continue;
        const int32_t j = target.index->Find(EncodeMorton<3>(
            {static_cast<uint32_t>(x), static_cast<uint32_t>(y), static_cast<uint32_t>(z)}));
        if (j < 0) continue;
        const double d2 = (level.center_of_mass[j].cast<double>() - q).squaredNorm();
        if (best.node >= 0 && (d2 > best_d2 || (d2 == best_d2 && j > best.node))) continue;
        const Eigen::Vector3d* n = target.normal(j);
        if (n == nullptr) continue;
        best = {j, n};
        best_d2 = d2;
      }
    }
  }
  return best;
}

double CellEdge(const PlaneLevel& target) {
  return 2.0 * target.tree->half_length() / static_cast<double>(uint64_t{1} << target.depth);
}

}  // namespace

BlockNormals::BlockNormals(const Octree& tree, int depth, const CellIndex& index)
    : tree_(tree),
      depth_(depth),
      index_(index),
      normals_(tree.level(depth).size()),
      state_(tree.level(depth).size(), 0) {}

const Eigen::Vector3d* BlockNormals::Of(int node) {
  const size_t k = static_cast<size_t>(node);
  if (state_[k] == 0) {
    const Octree::Level& level = tree_.level(depth_);
    const std::array<uint32_t, 3> home = tree_.Cell(depth_, node);
    const int64_t cells = int64_t{1} << depth_;
    double count = 0.0;
    Eigen::Vector3d first = Eigen::Vector3d::Zero();
    Eigen::Matrix3d second = Eigen::Matrix3d::Zero();
    for (int dz = -1; dz <= 1; ++dz) {
      for (int dy = -1; dy <= 1; ++dy) {
        for (int dx = -1; dx <= 1; ++dx) {
          const int64_t x = int64_t{home[0]} + dx;
          const int64_t y = int64_t{home[1]} + dy;
          const int64_t z = int64_t{home[2]} + dz;
          if (x < 0 || y < 0 || z < 0 || x >= cells || y >= cells || z >= cells) continue;
          const int32_t j = index_.Find(EncodeMorton<3>(
              {static_cast<uint32_t>(x), static_cast<uint32_t>(y), static_cast<uint32_t>(z)}));
          if (j < 0) continue;
          const double w = level.count[j];
          const Eigen::Vector3d mean = level.center_of_mass[j].cast<double>();
          count += w;
          first += w * mean;
          second += w * (tree_.Covariance(depth_, j).cast<double>() + mean * mean.transpose());
        }
      }
    }
    state_[k] = -1;
    if (count >= 3.0) {
      const Eigen::Vector3d mean = first / count;
      const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver(second / count -
                                                                  mean * mean.transpose());
      normals_[k] = solver.eigenvectors().col(0);
      state_[k] = 1;
    }
  }
  return state_[k] == 1 ? &normals_[k] : nullptr;
}

double MedianSurfaceScatterCells(const Octree& source, int source_depth, const PlaneLevel& target,
                                 const Eigen::Isometry3d& T_target_source, size_t max_nodes) {
  const Octree::Level& level = source.level(source_depth);
  const Octree::Level& target_level = target.tree->level(target.depth);
  if (level.size() == 0 || max_nodes == 0) return -1.0;
  const size_t stride = (level.size() + max_nodes - 1) / max_nodes;
  const double edge = CellEdge(target);
  std::vector<double> distances;
  distances.reserve(level.size() / stride + 1);
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

PlanePolishResult PolishPointToPlane(const Octree& source, int source_depth,
                                     const PlaneLevel& target,
                                     const Eigen::Isometry3d& T_target_source,
                                     const PlanePolishOptions& options) {
  PlanePolishResult result;
  result.T_target_source = T_target_source;
  const Octree::Level& level = source.level(source_depth);
  const Octree::Level& target_level = target.tree->level(target.depth);
  const double edge = CellEdge(target);
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
  terms.reserve(level.size());
  for (int iteration = 0; iteration < options.max_iterations; ++iteration) {
    terms.clear();
    Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
    double weight_sum = 0.0;
    for (size_t i = 0; i < level.size(); ++i) {
      const Eigen::Vector3d q = R * level.center_of_mass[i].cast<double>() + t;
      const Partner p = NearestWithPlane(target, q);
      if (p.node < 0) continue;
      const double r = p.normal->dot(q - target_level.center_of_mass[p.node].cast<double>());
      const double g = k2 / (k2 + r * r);
      const double w = static_cast<double>(level.count[i]) * g * g;
      terms.push_back({q, *p.normal, r, w});
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
    const Eigen::LDLT<Eigen::Matrix<double, 6, 6>> solver(H);
    if (solver.info() != Eigen::Success) break;
    const Eigen::Matrix<double, 6, 1> x = solver.solve(-b);
    if (!x.allFinite()) break;
    const double angle = x.head<3>().norm();
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
