#include "core/refine/smoothed_surface.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

#include "core/tree/morton.h"

namespace rpsr::core {

SurfaceKernel::SurfaceKernel(const Octree& tree, int depth, double radius)
    : tree_(tree), depth_(depth), radius_(radius) {
  if (depth_ >= 1) parent_index_ = CellIndex(tree_.level(depth_ - 1).morton, depth_ - 1);
  const Octree::Level& level = tree_.level(depth_);
  com_.resize(level.size());
  count_.resize(level.size());
  second_.resize(level.size());
  for (size_t j = 0; j < level.size(); ++j) {
    const Eigen::Vector3d c = level.center_of_mass[j].cast<double>();
    com_[j] = c;
    count_[j] = static_cast<double>(level.count[j]);
    second_[j] = tree_.Covariance(depth_, static_cast<int>(j)).cast<double>() + c * c.transpose();
  }
}

void SurfaceKernel::Gather(const Eigen::Vector3d& x, double reach,
                           std::vector<int32_t>& out) const {
  const size_t first = out.size();
  const double reach2 = reach * reach;
  auto consider = [&](int32_t j) {
    if ((com_[static_cast<size_t>(j)] - x).squaredNorm() <= reach2) out.push_back(j);
  };
  if (depth_ == 0) {  // the root: one cell at most, no parent
    for (size_t j = 0; j < com_.size(); ++j) consider(static_cast<int32_t>(j));
    return;
  }
  // The parent level's cells, whose children the tree lists.
  const int depth = depth_ - 1;
  const int64_t cells = int64_t{1} << depth;
  const double scale = static_cast<double>(cells) / (2.0 * tree_.half_length());
  const Eigen::Vector3d p =
      (x - tree_.center()) * scale + Eigen::Vector3d::Constant(0.5 * static_cast<double>(cells));
  if (!p.allFinite()) return;
  // Every cell whose box meets the cube of half-edge `reach` about x: a CoM lies in its cell, and
  // a child's cell in its parent's.
  const double r = reach * scale;
  std::array<int64_t, 3> lo;
  std::array<int64_t, 3> hi;
  for (int a = 0; a < 3; ++a) {
    lo[a] = std::max<int64_t>(0, static_cast<int64_t>(std::floor(std::max(p[a] - r, -1.0))));
    hi[a] = std::min<int64_t>(cells - 1,
                              static_cast<int64_t>(std::floor(std::min(p[a] + r, 1.0 * cells))));
  }
  const std::vector<int32_t>& labels = tree_.level(depth_).labels;
  for (int64_t z = lo[2]; z <= hi[2]; ++z) {
    for (int64_t y = lo[1]; y <= hi[1]; ++y) {
      for (int64_t c = lo[0]; c <= hi[0]; ++c) {
        const int32_t j = parent_index_.Find(EncodeMorton<3>(
            {static_cast<uint32_t>(c), static_cast<uint32_t>(y), static_cast<uint32_t>(z)}));
        if (j < 0) continue;
        for (int octant = 0; octant < 8; ++octant) {
          const int32_t child = labels[static_cast<size_t>(j) * 8 + static_cast<size_t>(octant)];
          if (child >= 0) consider(child);
        }
      }
    }
  }
  std::sort(out.begin() + static_cast<std::ptrdiff_t>(first), out.end());
}

SurfaceMoments SurfaceKernel::Moments(const Eigen::Vector3d& x, const int32_t* cells,
                                      size_t count) const {
  const double radius2 = radius_ * radius_;
  SurfaceMoments m;
  Eigen::Vector3d first = Eigen::Vector3d::Zero();
  Eigen::Matrix3d second = Eigen::Matrix3d::Zero();
  for (size_t k = 0; k < count; ++k) {
    const size_t j = static_cast<size_t>(cells[k]);
    const double d2 = (com_[j] - x).squaredNorm();
    if (d2 >= radius2) continue;
    const double u = 1.0 - d2 / radius2;
    const double w = count_[j] * u * u;
    m.weight += w;
    m.points += count_[j];
    first += w * com_[j];
    second += w * second_[j];
  }
  if (m.weight > 0.0) {
    m.mean = first / m.weight;
    m.spread = second / m.weight - m.mean * m.mean.transpose();
  }
  return m;
}

SurfaceMoments SurfaceKernel::Moments(const Eigen::Vector3d& x) const {
  std::vector<int32_t> cells;
  Gather(x, radius_, cells);
  return Moments(x, cells.data(), cells.size());
}

SupportCache::SupportCache(size_t points, double margin)
    : margin_(margin),
      anchors_(points, Eigen::Vector3d::Constant(std::numeric_limits<double>::quiet_NaN())),
      cells_(points) {}

SurfaceMoments SupportCache::At(const SurfaceKernel& kernel, size_t k, const Eigen::Vector3d& q) {
  std::vector<int32_t>& cells = cells_[k];
  // A NaN anchor (never gathered) fails the comparison.
  if (!((q - anchors_[k]).squaredNorm() <= margin_ * margin_)) {
    anchors_[k] = q;
    cells.clear();
    kernel.Gather(q, kernel.radius() + margin_, cells);
  }
  return kernel.Moments(q, cells.data(), cells.size());
}

SmoothedNodes SmoothNodes(const Octree& tree, int depth, double radius, size_t max_nodes) {
  SmoothedNodes smoothed;
  smoothed.depth = depth;
  const Octree::Level& level = tree.level(depth);
  if (level.size() == 0 || max_nodes == 0) return smoothed;
  const SurfaceKernel kernel(tree, depth, radius);
  const size_t stride = (level.size() + max_nodes - 1) / max_nodes;
  std::vector<int32_t> cells;
  for (size_t i = 0; i < level.size(); i += stride) {
    cells.clear();
    const Eigen::Vector3d x = level.center_of_mass[i].cast<double>();
    kernel.Gather(x, radius, cells);
    smoothed.points.push_back(kernel.Moments(x, cells.data(), cells.size()).mean);
    smoothed.weights.push_back(static_cast<double>(level.count[i]));
  }
  return smoothed;
}

}  // namespace rpsr::core
