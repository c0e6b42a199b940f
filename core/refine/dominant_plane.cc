#include "core/refine/dominant_plane.h"

#include <algorithm>
#include <cmath>
#include <numeric>

#include "Eigen/Eigenvalues"
#include "core/refine/cell_index.h"
#include "core/refine/node_closeness.h"

namespace rpsr::core {

DominantPlane FindDominantPlane(const Octree& tree, int finest_depth,
                                const DominantPlaneOptions& options) {
  DominantPlane plane;
  if (finest_depth < 1 || finest_depth > tree.max_depth()) return plane;
  const int coarse = std::max(1, finest_depth - options.classify_depths_up);
  plane.classify_depth = coarse;
  const Octree::Level& level = tree.level(coarse);
  const double thin = options.thin_fraction * CellEdge(tree, coarse);
  const double thin2 = thin * thin;
  // The nodes with enough points to have a shape; of the heaviest, the flat ones' normals are the
  // candidates (a ground's normal is among them; eigen-decomposing every node would cost ~1 ms a
  // scan).
  std::vector<Eigen::Matrix3d> shapes;
  std::vector<int32_t> shaped_node;
  for (size_t i = 0; i < level.size(); ++i) {
    if (level.count[i] < static_cast<uint32_t>(options.min_points)) continue;
    shapes.push_back(tree.Covariance(coarse, static_cast<int>(i)).cast<double>());
    shaped_node.push_back(static_cast<int32_t>(i));
  }
  std::vector<size_t> heaviest(shapes.size());
  std::iota(heaviest.begin(), heaviest.end(), size_t{0});
  const size_t examined = std::min<size_t>(heaviest.size(), 256);
  std::partial_sort(heaviest.begin(), heaviest.begin() + static_cast<std::ptrdiff_t>(examined),
                    heaviest.end(), [&](size_t a, size_t b) {
                      return level.count[static_cast<size_t>(shaped_node[a])] >
                             level.count[static_cast<size_t>(shaped_node[b])];
                    });
  std::vector<Eigen::Vector3d> flat;  // normals, heaviest first
  for (size_t k = 0; k < examined; ++k) {
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> shape(shapes[heaviest[k]]);
    const Eigen::Vector3d values = shape.eigenvalues();
    if (values[0] < options.flat_ratio * values[1]) flat.push_back(shape.eigenvectors().col(0));
  }
  if (flat.empty()) return plane;
  // The family: of the flat normals (one per direction within the tolerance, the first 64), the
  // one along which the most points lie thin (a ground cell crossed by one ring's arc is a line,
  // not flat, but thin along the ground's normal).
  const size_t candidates = std::min<size_t>(flat.size(), 64);
  const double cos_tolerance = std::cos(options.normal_tolerance_deg * M_PI / 180.0);
  std::vector<Eigen::Vector3d> tried;
  double best_points = -1.0;
  Eigen::Vector3d best_normal = flat[0];
  for (size_t c = 0; c < candidates; ++c) {
    const Eigen::Vector3d& n = flat[c];
    bool seen = false;
    for (const Eigen::Vector3d& t : tried) seen = seen || std::abs(t.dot(n)) >= cos_tolerance;
    if (seen) continue;
    tried.push_back(n);
    double points = 0.0;
    for (size_t j = 0; j < shapes.size(); ++j) {
      if (n.dot(shapes[j] * n) < thin2) points += level.count[static_cast<size_t>(shaped_node[j])];
    }
    if (points > best_points) {
      best_points = points;
      best_normal = n;
    }
  }
  plane.point_fraction =
      best_points / std::max<double>(1.0, static_cast<double>(tree.num_points()));
  if (plane.point_fraction < options.min_point_fraction) return plane;
  plane.found = true;
  plane.normal = best_normal;
  plane.on_plane.assign(level.size(), 0);
  for (size_t j = 0; j < shapes.size(); ++j) {
    if (best_normal.dot(shapes[j] * best_normal) < thin2) plane.on_plane[shaped_node[j]] = 1;
  }
  // A node with too few points for a shape (far ground, where rings lie apart) is judged by its
  // nearest ancestor with enough, at most two depths up, against that ancestor's cell.
  for (size_t i = 0; i < level.size(); ++i) {
    if (level.count[i] >= static_cast<uint32_t>(options.min_points)) continue;
    int32_t a = static_cast<int32_t>(i);
    for (int d = coarse; d > std::max(0, coarse - 2); --d) {
      a = tree.level(d).parent[static_cast<size_t>(a)];
      if (tree.level(d - 1).count[static_cast<size_t>(a)] <
          static_cast<uint32_t>(options.min_points)) {
        continue;
      }
      const double ancestor_thin = options.thin_fraction * CellEdge(tree, d - 1);
      const Eigen::Matrix3d c = tree.Covariance(d - 1, a).cast<double>();
      plane.on_plane[i] = best_normal.dot(c * best_normal) < ancestor_thin * ancestor_thin;
      break;
    }
  }
  return plane;
}

std::vector<uint8_t> DominantPlane::OffPlaneNodes(const Octree& tree, int depth) const {
  const size_t n = depth >= 0 && depth <= tree.max_depth() ? tree.level(depth).size() : 0;
  std::vector<uint8_t> off(n, 1);
  if (!found || n == 0 || on_plane.size() != tree.level(classify_depth).size()) return off;
  if (depth >= classify_depth) {
    // Each node's ancestor at the classifying depth.
    std::vector<int32_t> ancestor(n);
    std::iota(ancestor.begin(), ancestor.end(), 0);
    for (int d = depth; d > classify_depth; --d) {
      const std::vector<int32_t>& parent = tree.level(d).parent;
      for (int32_t& a : ancestor) a = parent[static_cast<size_t>(a)];
    }
    for (size_t i = 0; i < n; ++i) off[i] = !on_plane[static_cast<size_t>(ancestor[i])];
    return off;
  }
  // Coarser: on the family only when every descendant at the classifying depth is.
  std::fill(off.begin(), off.end(), 0);
  for (size_t i = 0; i < on_plane.size(); ++i) {
    if (on_plane[i]) continue;
    int32_t a = static_cast<int32_t>(i);
    for (int d = classify_depth; d > depth; --d) a = tree.level(d).parent[static_cast<size_t>(a)];
    off[static_cast<size_t>(a)] = 1;
  }
  return off;
}

std::vector<double> OffPlaneFarFractions(const Octree& source, const DominantPlane& source_plane,
                                         const Octree& target, const DominantPlane& target_plane,
                                         const std::vector<Eigen::Isometry3d>& poses, int depth,
                                         double far_cells) {
  if (depth < 1 || depth > source.max_depth() || depth > target.max_depth()) {
    return std::vector<double>(poses.size(), -1.0);
  }
  const std::vector<uint8_t> source_off = source_plane.OffPlaneNodes(source, depth);
  const std::vector<uint8_t> target_off = target_plane.OffPlaneNodes(target, depth);
  NodeClosenessOptions closeness;
  closeness.source_nodes = &source_off;
  closeness.target_nodes = &target_off;
  return FarNodeFractions(source, target, poses, depth, far_cells, closeness);
}

}  // namespace rpsr::core
