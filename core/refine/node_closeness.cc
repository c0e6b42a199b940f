#include "core/refine/node_closeness.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <vector>

#include "core/refine/cell_index.h"
#include "core/tree/morton.h"

namespace rpsr::core {

namespace {

// The 27 cells of the search, the home cell first.
constexpr std::array<std::array<int, 3>, 27> kHomeFirst = [] {
  std::array<std::array<int, 3>, 27> cells{};
  int k = 1;  // cells[0] is the home cell (0, 0, 0)
  for (int dz = -1; dz <= 1; ++dz) {
    for (int dy = -1; dy <= 1; ++dy) {
      for (int dx = -1; dx <= 1; ++dx) {
        if (dx != 0 || dy != 0 || dz != 0) cells[static_cast<size_t>(k++)] = {dx, dy, dz};
      }
    }
  }
  return cells;
}();

// Calls visit(pose index, source node index, distance capped at kCapCells cells) for each sampled
// source node under each pose (the target's lookup built once for all) and returns the cell edge; 0
// when nothing can be measured (MeanNodeDistanceCells' negative cases). `stop_below` (metres, > 0):
// a node's search ends at the first partner that near, and the distance visited is then that
// partner's (enough to tell near from far; 0: the exact nearest distance).
template <typename Visit>
double VisitNodeDistances(const Octree& source, const Octree& target,
                          const std::vector<Eigen::Isometry3d>& poses, int depth,
                          const NodeClosenessOptions& options, Visit visit,
                          double stop_below = 0.0) {
  if (depth < 1 || depth > source.max_depth() || depth > target.max_depth()) return 0.0;
  const Octree::Level& s = source.level(depth);
  const Octree::Level& t = target.level(depth);
  const Octree::Level& coarse = target.level(depth - 1);
  if (s.size() == 0 || t.size() == 0 || options.max_source_nodes == 0) return 0.0;
  const int64_t cells = int64_t{1} << (depth - 1);
  const double coarse_edge = CellEdge(target, depth - 1);
  const double edge = 0.5 * coarse_edge;
  // The cap is one cell of depth - 1: every target node within it lies in the 27 cells of depth
  // - 1 around the one holding the moved node.
  const double cap = NodeClosenessOptions::kCapCells * edge;
  const double cap2 = cap * cap;
  const double stop2 = stop_below * stop_below;
  const Eigen::Vector3d origin = target.center() - Eigen::Vector3d::Constant(target.half_length());
  // The occupied cells of depth - 1: a dense table indexed by Morton code where it is small (an
  // object's depth 5: 32^3 slots), else the refinement's CellIndex (a scan's depth 7, blocked).
  // The table made an object pair's call 0.9 -> 0.2 ms (tree_refinement_bench,
  // BM_MeanNodeDistance); the CellIndex a scan's FarNodeFractions over 7 poses and 2,048 nodes
  // 6.1 -> 4.0 ms against a binary search of the level's codes (registrar_bench's confidence_ms,
  // the confidence's turn contrast, single runs).
  constexpr int64_t kDenseSlots = int64_t{1} << 18;
  std::vector<int32_t> dense;
  CellIndex index;
  if (cells * cells * cells <= kDenseSlots) {
    dense.assign(static_cast<size_t>(cells * cells * cells), Octree::kEmpty);
    for (size_t p = 0; p < coarse.size(); ++p) {
      dense[static_cast<size_t>(coarse.morton[p])] = static_cast<int32_t>(p);
    }
  } else {
    index = CellIndex(coarse.morton, depth - 1);
  }
  auto find_coarse = [&](uint64_t code) -> int32_t {
    if (!dense.empty()) return dense[static_cast<size_t>(code)];
    return index.Find(code);  // -1 is Octree::kEmpty
  };
  // The source nodes that take part (all, or those marked), sampled by an even stride over the
  // Morton order.
  std::vector<uint32_t> kept;
  if (options.source_nodes != nullptr) {
    if (options.source_nodes->size() != s.size()) return 0.0;
    for (size_t i = 0; i < s.size(); ++i) {
      if ((*options.source_nodes)[i]) kept.push_back(static_cast<uint32_t>(i));
    }
    if (kept.empty()) return 0.0;
  }
  const std::vector<uint8_t>* partners = options.target_nodes;
  if (partners != nullptr && partners->size() != t.size()) return 0.0;
  const size_t n = options.source_nodes != nullptr ? kept.size() : s.size();
  const size_t used = std::min(n, options.max_source_nodes);
  for (size_t pose = 0; pose < poses.size(); ++pose) {
    const Eigen::Isometry3d& T_target_source = poses[pose];
    for (size_t k = 0; k < used; ++k) {
      const size_t stride = k * n / used;  // even stride over the Morton order
      const size_t node = kept.empty() ? stride : kept[stride];
      const Eigen::Vector3d q = T_target_source * s.center_of_mass[node].cast<double>();
      if (!q.allFinite()) {  // a non-finite pose: no partner (and no undefined integer cast)
        visit(pose, node, cap);
        continue;
      }
      std::array<int64_t, 3> home;
      for (int a = 0; a < 3; ++a) {
        // Clamped so that a node far outside the cube neither overflows nor finds a cell.
        const double f =
            std::clamp((q[a] - origin[a]) / coarse_edge, -2.0, static_cast<double>(cells) + 2.0);
        home[a] = static_cast<int64_t>(std::floor(f));
      }
      double best2 = cap2;
      // The home cell first: with stop_below set, most nodes find a partner that near there.
      for (const std::array<int, 3>& d : kHomeFirst) {
        const int64_t x = home[0] + d[0];
        const int64_t y = home[1] + d[1];
        const int64_t z = home[2] + d[2];
        if (x < 0 || y < 0 || z < 0 || x >= cells || y >= cells || z >= cells) continue;
        const uint64_t code = EncodeMorton<3>(
            {static_cast<uint32_t>(x), static_cast<uint32_t>(y), static_cast<uint32_t>(z)});
        const int32_t found = find_coarse(code);
        if (found == Octree::kEmpty) continue;
        const size_t parent = static_cast<size_t>(found);
        for (int octant = 0; octant < Octree::kChildren; ++octant) {
          const int32_t j = t.labels[parent * Octree::kChildren + static_cast<size_t>(octant)];
          if (j == Octree::kEmpty) continue;
          if (partners != nullptr && !(*partners)[static_cast<size_t>(j)]) continue;
          best2 = std::min(best2, (t.center_of_mass[j].cast<double>() - q).squaredNorm());
        }
        if (best2 <= stop2) break;
      }
      visit(pose, node, std::sqrt(best2));
    }
  }
  return edge;
}

}  // namespace

double MeanNodeDistanceCells(const Octree& source, const Octree& target,
                             const Eigen::Isometry3d& T_target_source, int depth,
                             const NodeClosenessOptions& options) {
  double sum = 0.0;
  size_t nodes = 0;
  const double edge = VisitNodeDistances(source, target, {T_target_source}, depth, options,
                                         [&](size_t, size_t, double distance) {
                                           sum += distance;
                                           ++nodes;
                                         });
  if (!(edge > 0.0)) return -1.0;
  return sum / static_cast<double>(nodes) / edge;
}

std::vector<double> FarNodeFractions(const Octree& source, const Octree& target,
                                     const std::vector<Eigen::Isometry3d>& poses, int depth,
                                     double far_cells, const NodeClosenessOptions& options) {
  std::vector<double> fractions(poses.size(), -1.0);
  if (depth < 1 || depth > target.max_depth()) return fractions;
  const double far_distance = far_cells * CellEdge(target, depth);
  std::vector<size_t> far(poses.size(), 0);
  std::vector<size_t> nodes(poses.size(), 0);
  const double edge = VisitNodeDistances(
      source, target, poses, depth, options,
      [&](size_t pose, size_t, double distance) {
        far[pose] += distance > far_distance;
        ++nodes[pose];
      },
      far_distance);
  if (!(edge > 0.0)) return fractions;
  for (size_t pose = 0; pose < poses.size(); ++pose) {
    fractions[pose] = static_cast<double>(far[pose]) / static_cast<double>(nodes[pose]);
  }
  return fractions;
}

std::vector<uint8_t> NodesFarUnderAllButFewPoses(const Octree& source, const Octree& target,
                                                 const std::vector<Eigen::Isometry3d>& poses,
                                                 int depth, double far_cells, int max_near) {
  if (depth < 1 || depth > source.max_depth() || depth > target.max_depth() || poses.empty()) {
    return {};
  }
  const size_t nodes = source.level(depth).size();
  const double far_distance = far_cells * CellEdge(target, depth);
  // Pose by pose over the nodes still in the running: a node near under more than max_near poses
  // is out, and under a near-symmetry most are near at once, so after the first few poses only
  // the feature's nodes and a few strays are still looked up (each pose still builds the depth's
  // small cell table and the list of nodes in the running).
  std::vector<uint8_t> marked(nodes, 1);
  std::vector<int> near_under(nodes, 0);
  NodeClosenessOptions running;
  running.source_nodes = &marked;
  running.max_source_nodes = nodes;
  std::vector<size_t> visited;
  for (const Eigen::Isometry3d& pose : poses) {
    visited.clear();
    const double edge = VisitNodeDistances(
        source, target, {pose}, depth, running,
        [&](size_t, size_t node, double distance) {
          near_under[node] += distance <= far_distance;
          visited.push_back(node);
        },
        far_distance);
    if (!(edge > 0.0)) {
      // Nothing in the running any more (or nothing measurable at all on the first pose).
      if (visited.empty() && &pose == &poses.front()) return {};
      break;
    }
    for (size_t node : visited) {
      if (near_under[node] > max_near) marked[node] = 0;
    }
  }
  return marked;
}

}  // namespace rpsr::core
