// A tree level read as a smooth surface, for the noise polish (noise_polish.h): about a point x,
// the count-weighted moments (mean and spread) of the level's cells under a biweight kernel of
// support `radius`, w_j = count_j (1 - |CoM_j - x|^2 / radius^2)^2, each cell contributing its CoM
// and its own covariance. The mean is a local average of many noisy samples (a jittered cloud's
// thick shell averaged across), the spread's least eigenvector the surface's normal there.
//
// Why this and not the nearest cell's CoM: a cell cuts a jittered shell thicker than itself, so
// its CoM lies off the surface by where the grid happened to cut, and which cell is nearest
// trades as the pose moves -- the point-to-plane minimum then wanders by up to a cell. The
// kernel's average is continuous in x and spans the shell. Its curvature bias (a mean sags inside
// a curved surface) is shared: the source's own nodes are smoothed by the same kernel
// (SmoothNodes), so at the true pose both sag alike and the residual is zero. The biweight has
// compact support, so the cells gathered are exactly those within `radius` (a Gaussian cut at a
// block's edge jumped as x crossed cells, and the polish did not settle: 0.58 of unseen pairs
// within (1 deg, 0.01) under jitter 0.08 on seed 1, against 0.64 with the biweight).
#ifndef RPSR_CORE_REFINE_SMOOTHED_SURFACE_H_
#define RPSR_CORE_REFINE_SMOOTHED_SURFACE_H_

#include <cstddef>
#include <cstdint>
#include <vector>

#include "Eigen/Core"
#include "core/refine/cell_index.h"
#include "core/tree/bh_tree.h"

namespace rpsr::core {

struct SurfaceMoments {
  double weight = 0.0;  // sum of the kernel weights (points, weighted)
  double points = 0.0;  // points of the cells inside the support (unweighted)
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  Eigen::Matrix3d spread = Eigen::Matrix3d::Zero();  // weighted covariance about the mean
};

class SurfaceKernel {
 public:
  // `radius` in the tree's units (> 0). Builds the parent level's cell index (Gather).
  SurfaceKernel(const Octree& tree, int depth, double radius);

  // The occupied cells whose CoM lies within `reach` (>= 0) of x, appended to `out` in ascending
  // node order. Found through the parent level (a reach of 3 cells spans up to 7^3 cells of this
  // level but 4^3 of the parent's, whose children the tree lists): the lookups were most of the
  // polish's time.
  void Gather(const Eigen::Vector3d& x, double reach, std::vector<int32_t>& out) const;
  // The moments about x over `cells` (which must hold every cell within `radius` of x; cells
  // farther out weigh nothing). Zero weight when none is inside the support.
  SurfaceMoments Moments(const Eigen::Vector3d& x, const int32_t* cells, size_t count) const;
  // The same, gathering the cells itself.
  SurfaceMoments Moments(const Eigen::Vector3d& x) const;

  double radius() const { return radius_; }
  const Octree& tree() const { return tree_; }
  int depth() const { return depth_; }

 private:
  const Octree& tree_;
  int depth_;
  double radius_;
  CellIndex parent_index_;  // depth_ - 1's (depth_ >= 1; the root level has one cell at most)
  // Per cell, in double: its CoM, point count and second moment about the origin
  // (covariance + CoM CoM^T), read by every kernel sum that reaches it.
  std::vector<Eigen::Vector3d> com_;
  std::vector<double> count_;
  std::vector<Eigen::Matrix3d> second_;
};

// A kernel's cells near each of a set of query points (a polish's source nodes), gathered within
// the support plus `margin` and gathered again only when the point has moved more than the margin
// from where they were: the same moments as gathering every time, without most of the lookups.
// Kept by the caller across calls with the same kernel (a pair's starts often end near each other).
class SupportCache {
 public:
  SupportCache(size_t points, double margin);
  // The kernel's moments about q, query point k's (k < points).
  SurfaceMoments At(const SurfaceKernel& kernel, size_t k, const Eigen::Vector3d& q);

 private:
  double margin_;
  std::vector<Eigen::Vector3d> anchors_;  // where each point's cells were gathered (NaN: never)
  std::vector<std::vector<int32_t>> cells_;
};

// A source level's nodes smoothed by the kernel in their own frame: pose-free, so a pair's starts
// share them. At most `max_nodes` nodes, an even stride over the level (a pose's six degrees of
// freedom need a few hundred; a scan's deep level has tens of thousands).
struct SmoothedNodes {
  int depth = -1;
  std::vector<Eigen::Vector3d> points;  // the kernel's mean about each node's CoM
  std::vector<double> weights;          // the node's point count
};
SmoothedNodes SmoothNodes(const Octree& tree, int depth, double radius, size_t max_nodes);

}  // namespace rpsr::core

#endif  // RPSR_CORE_REFINE_SMOOTHED_SURFACE_H_
