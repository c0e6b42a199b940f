// The noise polish (issue 5): when a cloud's points scatter about the surface by a sizeable part
// of the finest cell, a last point-to-plane stage one depth coarser, on kernel-smoothed surfaces.
//
// Why: a jittered source's finest cells hold single samples displaced by about a cell, and the
// re-binned coarse depths cut its thick shell with the target's grid; both bias the plane-to-plane
// minimum (refined from the TRUE pose under jitter 0.08, 33 of 40 unseen pairs ended beyond (1
// deg, 0.01)). The polish instead fits the source's nodes one depth coarser, each smoothed by a
// biweight kernel of 2.5 cells (smoothed_surface.h), to the target's kernel-smoothed surface about
// them: both sides are local averages across the thick shell, continuous in the pose, and sag
// alike inside curved surfaces. On clean clouds it costs precision (coarser, smoothed surfaces),
// so it runs only when the measured scatter says the finest depth is finer than the data.
//
// Measured (`rpsr eval --protocol objects --split unseen --count 100 --seed S --disturbance jitter
// --level 3|4`, recall at (1 deg, 0.01), seeds 1 / 2 / 3): jitter 0.05 0.54 / 0.49 / 0.54 before
// any polish, 0.66 / 0.67 / 0.63 with session 16's (each node to the nearest target CoM, normals
// from the 3x3x3 block), 0.74 / 0.71 / 0.73 with this one; jitter 0.08 0.19 / 0.16 / 0.11, 0.46 /
// 0.44 / 0.45, 0.66 / 0.61 / 0.62. Clean, noise, outliers and crop within a pair (their scatter
// stays below the threshold on almost every pair;
// tests/bench/results/noise_polish_smoothed.txt). The variants in
// tests/bench/notes/refinement-notes.md, *The noise polish*.
#ifndef RPSR_CORE_REFINE_NOISE_POLISH_H_
#define RPSR_CORE_REFINE_NOISE_POLISH_H_

#include <cstddef>
#include <cstdint>
#include <functional>
#include <vector>

#include "Eigen/Geometry"
#include "core/refine/cell_index.h"
#include "core/refine/smoothed_surface.h"
#include "core/tree/bh_tree.h"

namespace rpsr::core {

// A target level the polish reads: its CoMs (from `tree`), its cell index, and a plane normal per
// node (nullptr: no plane there; unit length otherwise). The normal is the caller's so that the
// refinement's shape rules and cached eigen-decompositions serve here too.
struct PlaneLevel {
  const Octree* tree = nullptr;
  int depth = 0;
  const CellIndex* index = nullptr;
  std::function<const Eigen::Vector3d*(int node)> normal;
};

// The median over the source's nodes of `source_depth` (an even stride, at most max_nodes) of
// |n . (T * CoM - q)|, q the nearest target CoM among the 27 target cells around the moved node
// and n its plane's normal, in cell edges of the target level: about 0.67 sigma / edge for
// points with Gaussian scatter sigma about the surface. Measured at the unseen objects' finest
// depth (6) at the refinement's answer, over 100 pairs (`rpsr eval --protocol objects --split
// unseen --count 100`, every start): clean median 0.17 (95th percentile 0.37), jitter 0.02 / 0.03 /
// 0.05 / 0.08 0.32 / 0.39 / 0.51 / 0.60 (5th percentiles 0.23 / 0.32 / 0.43 / 0.52), noise 40%
// 0.29, outliers 40% 0.20, crop 40% 0.18; KITTI-style scans at depth 9 0.02-0.04. Negative when no
// node has a partner.
double MedianSurfaceScatterCells(const Octree& source, int source_depth, const PlaneLevel& target,
                                 const Eigen::Isometry3d& T_target_source, size_t max_nodes);

struct PlanePolishOptions {
  // The smoothing kernel's support, in cell edges of the target level (the caller builds both
  // kernels with it). Unseen objects under jitter 0.08, seeds 1 / 2: 1.5 cells 0.40 / 0.35, 2
  // 0.58 / 0.56, 2.5 0.64 / 0.61, 3 0.56 / 0.58, 4 0.46 / 0.48.
  double kernel_radius_cells = 2.5;
  // The source's nodes read, at most (an even stride over the level; SmoothNodes).
  size_t max_nodes = 2048;
  // Geman-McClure scale on the plane distance, in cell edges of the target level: wide (jittered
  // nodes scatter by up to a cell), but a node far off its plane (an outlier) still counts little.
  double robust_scale_cells = 2.0;
  // Stops when an update rotates less than this (radians) and translates the matched centroid
  // less than translation_epsilon_cells cell edges (the refinement's finest-depth epsilons), or
  // after max_iterations (its per-depth cap): under heavy jitter the updates shrink slowly (most
  // pairs end with steps of 1e-3 rad, 0.06 degree; 30 iterations instead: 0.66 / 0.63 for 1.5
  // times the polish's time).
  int max_iterations = 12;
  double rotation_epsilon_rad = 1e-4;
  double translation_epsilon_cells = 1e-3;
  // Fewer correspondences than this: no update (a handful of nodes cannot hold six degrees of
  // freedom).
  int min_correspondences = 12;
  // A target support of fewer points than this has no plane (a node's partner needs a spread).
  double min_support_points = 3.0;
  // A polish corrects an answer by a fraction of a degree and of a cell: a step that would turn it
  // by more than max_step_rad or move its matched points by more than max_step_cells cell edges
  // (directions the planes leave free, as along a plane or a corridor) stops it where it stands.
  double max_step_rad = 0.05;
  double max_step_cells = 1.0;
};

struct PlanePolishResult {
  Eigen::Isometry3d T_target_source = Eigen::Isometry3d::Identity();
  int iterations = 0;
  int correspondences = 0;  // at the last iteration
  bool converged = false;
  // The last update's rotation (radians) and translation of the matched centroid (metres).
  double last_update_rotation_rad = 0.0;
  double last_update_translation = 0.0;
};

// What the polishes of one pair share, whatever their start: the source's nodes of `depth`
// smoothed (SmoothNodes), the target's kernel at that depth and the supports gathered so far.
// Both kernels have the options' kernel_radius_cells in cells of the target's level; supports are
// gathered again after a move of half a cell.
struct PolishSides {
  PolishSides(const Octree& source_tree, const Octree& target_tree, int depth,
              const PlanePolishOptions& options = {});
  SmoothedNodes source;
  SurfaceKernel target;
  SupportCache supports;
};

// Gauss-Newton on sum_i w_i rho(n(q_i) . (q_i - m(q_i))), q_i = T * s_i for the source's smoothed
// nodes s_i (w_i: the node's point count), m and n the target kernel's mean and normal about q_i
// (supports of at least min_support_points). Starts at `T_target_source`; returns it unchanged
// (iterations 0) when too few nodes find a supported plane. `options` as `sides` were built with.
PlanePolishResult PolishPointToPlane(PolishSides& sides, const Eigen::Isometry3d& T_target_source,
                                     const PlanePolishOptions& options = {});

}  // namespace rpsr::core

#endif  // RPSR_CORE_REFINE_NOISE_POLISH_H_
