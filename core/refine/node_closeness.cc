#include "core/refine/node_closeness.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
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
// partner's (enough to tell near from far; 0: the exact nearest distance). `pose_done(pose,
// sampled)`, asked after each visit with the number of nodes every pose samples: true ends that
// pose's nodes there.
struct NeverDone {
  bool operator()(size_t, size_t) const { return false; }
};
template <typename Visit, typename PoseDone = NeverDone>
double VisitNodeDistances(const Octree& source, const Octree& target,
                          const std::vector<Eigen::Isometry3d>& poses, int depth,
                          const NodeClosenessOptions& options, Visit visit, double stop_below = 0.0,
                          PoseDone pose_done = {}) {
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
  // The occupied cells of depth - 1: a dense table indexed by x + cells * (y + cells * z) where it
  // is small (an object's depth 5: 32^3 slots), else the refinement's CellIndex by Morton code (a
  // scan's depth 7, blocked). The table made an object pair's call 0.9 -> 0.2 ms
  // (tree_refinement_bench, BM_MeanNodeDistance); the CellIndex a scan's FarNodeFractions over 7
  // poses and 2,048 nodes 6.1 -> 4.0 ms against a binary search of the level's codes
  // (registrar_bench's confidence_ms, the confidence's turn contrast, single runs).
  constexpr int64_t kDenseSlots = int64_t{1} << 18;
  std::vector<int32_t> dense;
  CellIndex index;
  if (cells * cells * cells <= kDenseSlots) {
    dense.assign(static_cast<size_t>(cells * cells * cells), Octree::kEmpty);
    for (size_t p = 0; p < coarse.size(); ++p) {
      const std::array<uint32_t, 3> xyz = DecodeMorton<3>(coarse.morton[p]);
      dense[static_cast<size_t>(xyz[0] + cells * (xyz[1] + cells * int64_t{xyz[2]}))] =
          static_cast<int32_t>(p);
    }
  } else {
    index = CellIndex(coarse.morton, depth - 1);
  }
  // The cell at (x, y, z), all within [0, cells).
  auto find_coarse = [&](int64_t x, int64_t y, int64_t z) -> int32_t {
    if (!dense.empty()) return dense[static_cast<size_t>(x + cells * (y + cells * z))];
    return index.Find(EncodeMorton<3>(  // -1 is Octree::kEmpty
        {static_cast<uint32_t>(x), static_cast<uint32_t>(y), static_cast<uint32_t>(z)}));
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
  // With the dense table (an object's levels), each occupied cell of depth - 1 as its partner
  // children's centres of mass, contiguous, and their bounding box: a cell whose box lies farther
  // than the nearest partner found so far is passed over without reading its children. None of
  // them can be nearer, so every distance and every early stop is as without it (bit for bit: a
  // scratch comparison of both searches, node by node on 400 random trees, by a review). The turn
  // contrast on an object pair (BM_FarNodeFractions/lidar:0, three alternated runs) took
  // 0.94-1.04 -> 0.52-0.58 ms, MeanNodeDistanceCells 0.34-0.42 -> 0.25-0.29 ms. A scan's sparse
  // deep levels are left to the children's labels: listing all of a depth-8 level's children each
  // call cost what the boxes saved (1.15-1.28 -> 1.25-1.38 ms).
  struct Children {
    Eigen::Vector3d lo;
    Eigen::Vector3d hi;
    uint32_t first = 0;
    uint32_t count = 0;
  };
  const bool listed = !dense.empty();
  std::vector<Children> children(listed ? coarse.size() : 0);
  std::vector<Eigen::Vector3f> child_com;
  child_com.reserve(listed ? t.size() : 0);
  for (size_t p = 0; p < children.size(); ++p) {
    Children& c = children[p];
    c.first = static_cast<uint32_t>(child_com.size());
    c.lo.setConstant(std::numeric_limits<double>::infinity());
    c.hi.setConstant(-std::numeric_limits<double>::infinity());
    for (int octant = 0; octant < Octree::kChildren; ++octant) {
      const int32_t j = t.labels[p * Octree::kChildren + static_cast<size_t>(octant)];
      if (j == Octree::kEmpty) continue;
      if (partners != nullptr && !(*partners)[static_cast<size_t>(j)]) continue;
      const Eigen::Vector3f& com = t.center_of_mass[static_cast<size_t>(j)];
      child_com.push_back(com);
      c.lo = c.lo.cwiseMin(com.cast<double>());
      c.hi = c.hi.cwiseMax(com.cast<double>());
    }
    c.count = static_cast<uint32_t>(child_com.size()) - c.first;
  }
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
        if (pose_done(pose, used)) break;
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
        const int32_t found = find_coarse(x, y, z);
        if (found == Octree::kEmpty) continue;
        if (!listed) {
          const size_t parent = static_cast<size_t>(found);
          for (int octant = 0; octant < Octree::kChildren; ++octant) {
            const int32_t j = t.labels[parent * Octree::kChildren + static_cast<size_t>(octant)];
            if (j == Octree::kEmpty) continue;
            if (partners != nullptr && !(*partners)[static_cast<size_t>(j)]) continue;
            best2 = std::min(best2, (t.center_of_mass[j].cast<double>() - q).squaredNorm());
          }
          if (best2 <= stop2) break;
          continue;
        }
        const Children& c = children[static_cast<size_t>(found)];
        // The box's distance bounds its children's from below; the margin keeps rounding from
        // passing over a child as near as the best. A passed-over cell still ends the search
        // where the old loop would have, after any occupied cell (with stop_below at the cap or
        // beyond, at the first).
        const Eigen::Vector3d outside =
            (c.lo - q).cwiseMax(q - c.hi).cwiseMax(Eigen::Vector3d::Zero());
        if (c.count > 0 && !(outside.squaredNorm() > best2 * (1.0 + 1e-9))) {
          // The same expression as the labels' loop, so that each distance is the same double.
          for (uint32_t k = c.first; k < c.first + c.count; ++k) {
            best2 = std::min(best2, (child_com[k].cast<double>() - q).squaredNorm());
          }
        }
        if (best2 <= stop2) break;
      }
      visit(pose, node, std::sqrt(best2));
      if (pose_done(pose, used)) break;
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

std::vector<double> WeightedMeanNodeDistanceCells(const Octree& source, const Octree& target,
                                                  const std::vector<Eigen::Isometry3d>& poses,
                                                  int depth, const std::vector<double>& weights) {
  std::vector<double> means(poses.size(), -1.0);
  if (depth < 1 || depth > source.max_depth() || weights.size() != source.level(depth).size()) {
    return means;
  }
  std::vector<double> sum(poses.size(), 0.0);
  std::vector<double> weight(poses.size(), 0.0);
  const double edge = VisitNodeDistances(source, target, poses, depth, NodeClosenessOptions{},
                                         [&](size_t pose, size_t node, double distance) {
                                           sum[pose] += weights[node] * distance;
                                           weight[pose] += weights[node];
                                         });
  if (!(edge > 0.0)) return means;
  for (size_t pose = 0; pose < poses.size(); ++pose) {
    if (weight[pose] > 0.0) means[pose] = sum[pose] / weight[pose] / edge;
  }
  return means;
}

std::vector<double> FarNodeFractions(const Octree& source, const Octree& target,
                                     const std::vector<Eigen::Isometry3d>& poses, int depth,
                                     double far_cells, const NodeClosenessOptions& options,
                                     double stop_above) {
  std::vector<double> fractions(poses.size(), -1.0);
  if (depth < 1 || depth > target.max_depth()) return fractions;
  const double far_distance = far_cells * CellEdge(target, depth);
  std::vector<size_t> far(poses.size(), 0);
  std::vector<size_t> nodes(poses.size(), 0);
  // The fraction only grows with the nodes still to come, so a pose past `stop_above` stays past
  // it (the same expression as the fraction returned below, over the nodes every pose samples).
  std::vector<uint8_t> stopped(poses.size(), 0);
  size_t sampled = 0;
  const bool may_stop = std::isfinite(stop_above);  // no division per node otherwise
  auto past_bound = [&](size_t pose, size_t used) {
    if (!may_stop || !(static_cast<double>(far[pose]) / static_cast<double>(used) > stop_above)) {
      return false;
    }
    stopped[pose] = 1;
    sampled = used;
    return true;
  };
  const double edge = VisitNodeDistances(
      source, target, poses, depth, options,
      [&](size_t pose, size_t, double distance) {
        far[pose] += distance > far_distance;
        ++nodes[pose];
      },
      far_distance, past_bound);
  if (!(edge > 0.0)) return fractions;
  for (size_t pose = 0; pose < poses.size(); ++pose) {
    // A pose stopped early reads its count over every sampled node: above stop_above, at most
    // its own fraction.
    const size_t over = stopped[pose] ? sampled : nodes[pose];
    fractions[pose] = static_cast<double>(far[pose]) / static_cast<double>(over);
  }
  return fractions;
}

std::vector<double> TwoWayFarNodeFractions(const Octree& source, const Octree& target,
                                           const std::vector<Eigen::Isometry3d>& poses, int depth,
                                           double far_cells) {
  std::vector<Eigen::Isometry3d> inverses;
  inverses.reserve(poses.size());
  for (const Eigen::Isometry3d& T : poses) inverses.push_back(T.inverse());
  const std::vector<double> there = FarNodeFractions(source, target, poses, depth, far_cells);
  const std::vector<double> back = FarNodeFractions(target, source, inverses, depth, far_cells);
  std::vector<double> two_way(poses.size(), -1.0);
  for (size_t k = 0; k < poses.size(); ++k) {
    if (there[k] >= 0.0 && back[k] >= 0.0) two_way[k] = 0.5 * (there[k] + back[k]);
  }
  return two_way;
}

TwoWayFarWithinDrop TwoWayFarNodeFractionsWithinDrop(
    const Octree& source, const Octree& target, const Eigen::Isometry3d& answer,
    const std::vector<Eigen::Isometry3d>& candidates, int depth, double far_cells,
    double min_drop) {
  TwoWayFarWithinDrop out;
  out.candidates.assign(candidates.size(), -1.0);
  const double answer_far = TwoWayFarNodeFractions(source, target, {answer}, depth, far_cells)[0];
  if (answer_far < 0.0) return out;
  out.answer = answer_far;
  const double most = answer_far - min_drop;
  if (most < 0.0 || candidates.empty()) return out;
  // 0.5 * there <= most exactly when there <= 2 * most (scaling by two is exact), so the poses
  // stopped past 2 * most are exactly those left out here.
  const std::vector<double> there = FarNodeFractions(source, target, candidates, depth, far_cells,
                                                     NodeClosenessOptions{}, 2.0 * most);
  std::vector<size_t> contenders;
  std::vector<Eigen::Isometry3d> inverses;
  for (size_t k = 0; k < candidates.size(); ++k) {
    if (there[k] >= 0.0 && 0.5 * there[k] <= most) {
      contenders.push_back(k);
      inverses.push_back(candidates[k].inverse());
    }
  }
  if (contenders.empty()) return out;
  const std::vector<double> back = FarNodeFractions(target, source, inverses, depth, far_cells);
  for (size_t c = 0; c < contenders.size(); ++c) {
    if (back[c] >= 0.0) out.candidates[contenders[c]] = 0.5 * (there[contenders[c]] + back[c]);
  }
  return out;
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
