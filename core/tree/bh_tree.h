// The Barnes-Hut 2^D-tree of a point cloud (paper Sec. 2 and 3.2), for D = 3 (octree) and D = 2
// (quadtree) from one template.
//
// Frame and normalisation. A tree is built from ONE cloud, independently of any partner cloud, so
// the service can build it once per upload and cache it. The root cell is the cube centred on the
// cloud's axis-aligned bounding box with half-length r = (largest half-extent) * (1 + 1e-6) (plus a
// tiny floor so that a single point still gets a cube). With c the cube's centre,
//     p_normalized = (p - c) / r   lies in [-1, 1]^D,      p = c + r * p_normalized.
// `center()` and `half_length()` store that mapping. Every geometric attribute of a node (centre
// of mass, covariance, cell bounds) is stored in the CLOUD'S OWN FRAME (metres), so registration
// results need no conversion; a consumer that wants the unit cube applies the mapping above.
//
// Levels. Depth 0 is the root; depth d splits the cube into 2^d cells per axis (cell half-length
// r / 2^d). Level d lists the NON-EMPTY cells of depth d in Morton 'Z' order (see morton.h), so a
// parent's children are contiguous and ordered by octant. The paper stops subdividing a cell
// that holds a single point (a 'leaf'); here such a leaf is carried down unchanged (its one point
// occupies exactly one cell per finer depth). Each depth is then a complete partition of the
// cloud (counts sum to the number of points), which the fixed-depth tree convolutions need. Node
// kinds follow the paper: 'null' = an empty slot (kEmpty in the label arrays), 'leaf' = a node
// with count 1, 'internal' = count > 1.
//
// Inverse density (the paper's footnote: importance weights normalised to sum to one). For node
// l of depth d with n_{d,l} points,
//     inverse_density_{d,l} = (1 / n_{d,l}) / sum_{l'} (1 / n_{d,l'}),
// i.e. per depth the weights sum to 1 and sparse nodes weigh more than dense ones: used as w(x) =
// p(x)/q(x) with q the sampling density (proportional to n) and p uniform over occupied cells.
//
// Label arrays L_d (paper Sec. 3.2, "child filling"): level d (d >= 1) holds 2^D slots per node of
// depth d-1; slot 2^D * i + octant is the index (0-based) at depth d of the child of parent i in
// that octant, or kEmpty. (The authors' later loader used 1-based indices with 0 = empty and
// skipped the children of node 0 by a `> 0` guard; 0-based with -1 avoids that trap.)
//
// Neighbours ("zero filling"): for depths up to `neighbor_max_depth`, each node has 3^D entries:
// entry k = sum_a (delta_a + 1) * 3^a for the offset delta in {-1, 0, 1}^D (x varies fastest);
// entry (3^D - 1) / 2 is the node itself; kEmpty marks an empty or out-of-cube neighbour cell.
//
// No raw points are kept: what refinement and confidence need (count, centre of mass,
// covariance) lives in the nodes.
#ifndef RPSR_CORE_TREE_BH_TREE_H_
#define RPSR_CORE_TREE_BH_TREE_H_

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "Eigen/Core"
#include "Eigen/Geometry"
#include "absl/status/statusor.h"
#include "absl/types/span.h"
#include "core/cloud/point_cloud.h"

namespace rpsr::core {

struct BarnesHutTreeOptions {
  // Deepest level built (0 .. 21 for octrees, 0 .. 31 for quadtrees). The network reads depths
  // 2..5; refinement wants deeper cells (depth 9 gives ~0.5 m cells on a 240 m LiDAR cube).
  int max_depth = 6;
  // Neighbour tables are built for depths 0 .. min(neighbor_max_depth, max_depth) only: they cost
  // 4 * 3^D bytes a node and only the tree convolutions (depths <= 5) gather neighbours.
  int neighbor_max_depth = 5;
  // Clouds with more points are rejected (InvalidArgument) instead of building a huge tree.
  size_t max_points = 20'000'000;
  // A given root cube instead of the cloud's own (cube_half_length > 0; cube_center has D
  // entries). Used to bin a moved cloud into a partner's cells; points outside the cube are
  // counted in the border cells they are clamped to (their centre of mass stays true).
  std::vector<double> cube_center;
  double cube_half_length = 0.0;
};

template <int D>
class BarnesHutTreeBuilder;

template <int D>
class BarnesHutTree {
 public:
  static_assert(D == 2 || D == 3, "BarnesHutTree supports D = 2 (quadtree) and D = 3 (octree)");
  using Vector = Eigen::Matrix<float, D, 1>;
  using Matrix = Eigen::Matrix<float, D, D>;
  // Upper triangle of a symmetric D x D matrix, row by row: (xx, xy, yy) or (xx, xy, xz, yy, yz,
  // zz).
  using PackedSymmetric = Eigen::Matrix<float, D*(D + 1) / 2, 1>;

  static constexpr int kChildren = 1 << D;
  static constexpr int kNeighbors = D == 2 ? 9 : 27;
  static constexpr int kSelfNeighbor = (kNeighbors - 1) / 2;
  static constexpr int32_t kEmpty = -1;

  // The non-empty nodes of one depth, structure of arrays, all indexed by node (Morton order).
  struct Level {
    std::vector<uint64_t> morton;             // cell code at this depth, strictly ascending
    std::vector<uint32_t> count;              // points in the cell
    std::vector<Vector> center_of_mass;       // mean of the cell's points, cloud frame
    std::vector<PackedSymmetric> covariance;  // population covariance (divides by count)
    std::vector<float> inverse_density;       // see the header comment; sums to 1 per depth
    std::vector<int32_t> parent;              // index at depth - 1; kEmpty at the root
    std::vector<int32_t> labels;              // L_d: kChildren slots per node of depth - 1
    std::vector<int32_t> neighbors;           // kNeighbors per node, or empty (see options)

    size_t size() const { return count.size(); }
  };

  int max_depth() const { return static_cast<int>(levels_.size()) - 1; }
  int neighbor_max_depth() const { return neighbor_max_depth_; }
  // Points in the tree (the total weight for a weighted build).
  size_t num_points() const { return num_points_; }
  const Level& level(int depth) const { return levels_[depth]; }
  const std::vector<Level>& levels() const { return levels_; }

  // The cube: centre c and half-length r (cloud frame, kept in double so that CellOfPoint is
  // exactly the quantization the build used), see the header comment.
  using VectorD = Eigen::Matrix<double, D, 1>;
  const VectorD& center() const { return center_; }
  double half_length() const { return half_length_; }
  Vector ToNormalized(const Vector& p) const {
    return ((p.template cast<double>() - center_) / half_length_).template cast<float>();
  }
  Vector FromNormalized(const Vector& q) const {
    return (center_ + half_length_ * q.template cast<double>()).template cast<float>();
  }

  // The cell of depth `depth` that holds point p (clamped into the cube): the quantization used
  // to build the tree, floor((p - c + r) / (2 r) * 2^depth) per axis.
  std::array<uint32_t, D> CellOfPoint(const Vector& p, int depth) const;

  // Integer cell coordinates (0 .. 2^depth - 1 per axis) and bounds (cloud frame) of a node.
  std::array<uint32_t, D> Cell(int depth, int node) const;
  Eigen::AlignedBox<float, D> CellBounds(int depth, int node) const;
  Matrix Covariance(int depth, int node) const;
  bool IsLeaf(int depth, int node) const { return levels_[depth].count[node] == 1; }

  // Neighbour `k` (see the header comment) of `node`; requires depth <= neighbor_max_depth().
  int32_t Neighbor(int depth, int node, int k) const {
    return levels_[depth].neighbors[static_cast<size_t>(node) * kNeighbors + k];
  }

  // Dense view of one depth: 2^(D*depth) slots, slot = Morton code of the cell, value = node index
  // or kEmpty. DenseView(2) is the paper's Tree-to-Voxel input (64 tokens for an octree).
  // Depth is limited to 7 (2M slots for an octree).
  std::vector<int32_t> DenseView(int depth) const;

  // Bytes held by the tree (what a cache charges for it).
  size_t MemoryBytes() const;

 private:
  friend class BarnesHutTreeBuilder<D>;  // bh_tree.cc: fills the levels

  std::vector<Level> levels_;
  VectorD center_ = VectorD::Zero();
  double half_length_ = 1.0;
  size_t num_points_ = 0;
  int neighbor_max_depth_ = -1;
};

using Octree = BarnesHutTree<3>;
using Quadtree = BarnesHutTree<2>;

// Builds the tree of `points`. Errors (InvalidArgument): no points, more than
// options.max_points, a non-finite coordinate (named by index), a depth outside the supported
// range. Cost: O(n) plus a radix sort of the n Morton codes; one thread.
template <int D>
absl::StatusOr<BarnesHutTree<D>> BuildBarnesHutTree(
    absl::Span<const Eigen::Matrix<float, D, 1>> points, const BarnesHutTreeOptions& options = {});

// The same for weighted points (weight = how many points each stands for, e.g. the counts of
// another tree's nodes): counts and moments are weighted sums. `weights` empty means all 1.
template <int D>
absl::StatusOr<BarnesHutTree<D>> BuildWeightedBarnesHutTree(
    absl::Span<const Eigen::Matrix<float, D, 1>> points, absl::Span<const uint32_t> weights,
    const BarnesHutTreeOptions& options = {});

// The same for weighted points that each stand for a patch of points: `covariances` (one per
// point: the patch's population covariance, packed like the nodes') add each patch's own spread
// to the moments, so that re-binning another tree's nodes into new cells keeps the cells' shapes
// as a build from the raw points would give them (core/refine re-bins a source on a target's
// cells). InvalidArgument when the sizes differ or an entry is not finite.
template <int D>
absl::StatusOr<BarnesHutTree<D>> BuildWeightedBarnesHutTree(
    absl::Span<const Eigen::Matrix<float, D, 1>> points, absl::Span<const uint32_t> weights,
    absl::Span<const typename BarnesHutTree<D>::PackedSymmetric> covariances,
    const BarnesHutTreeOptions& options = {});

// Convenience for 3D clouds.
absl::StatusOr<Octree> BuildOctree(const PointCloud& cloud,
                                   const BarnesHutTreeOptions& options = {});

}  // namespace rpsr::core

#endif  // RPSR_CORE_TREE_BH_TREE_H_
