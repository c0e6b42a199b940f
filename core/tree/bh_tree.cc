#include "core/tree/bh_tree.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "absl/strings/str_cat.h"
#include "core/tree/morton.h"

namespace rpsr::core {
namespace {

// LSD radix sort of (code, index) pairs on the low `bits` bits of the codes, 11 bits a pass: a
// depth-6 octree needs 2 passes, depth 9 three. Stable, O(n) per pass; std::sort of 120k pairs
// took about 4x longer.
void RadixSortByCode(std::vector<uint64_t>& codes, std::vector<uint32_t>& order, int bits) {
  constexpr int kDigitBits = 11;
  constexpr size_t kBuckets = size_t{1} << kDigitBits;
  const size_t n = codes.size();
  std::vector<uint64_t> codes_tmp(n);
  std::vector<uint32_t> order_tmp(n);
  std::vector<uint32_t> offsets(kBuckets);
  for (int shift = 0; shift < bits; shift += kDigitBits) {
    std::fill(offsets.begin(), offsets.end(), 0u);
    for (size_t i = 0; i < n; ++i) ++offsets[(codes[i] >> shift) & (kBuckets - 1)];
    uint32_t running = 0;
    for (size_t b = 0; b < kBuckets; ++b) {
      const uint32_t c = offsets[b];
      offsets[b] = running;
      running += c;
    }
    for (size_t i = 0; i < n; ++i) {
      const uint32_t slot = offsets[(codes[i] >> shift) & (kBuckets - 1)]++;
      codes_tmp[slot] = codes[i];
      order_tmp[slot] = order[i];
    }
    codes.swap(codes_tmp);
    order.swap(order_tmp);
  }
}

constexpr int IntPow3(int d) { return d == 0 ? 1 : 3 * IntPow3(d - 1); }

}  // namespace

// Builds the levels bottom-up from sorted Morton codes. Sums are accumulated in double relative
// to the cube centre, so that covariances of small cells far from the origin keep their digits.
template <int D>
class BarnesHutTreeBuilder {
 public:
  using Tree = BarnesHutTree<D>;
  using Vector = typename Tree::Vector;
  using VectorD = Eigen::Matrix<double, D, 1>;
  using PackedD = Eigen::Matrix<double, D*(D + 1) / 2, 1>;

  // Raw moments of a node: count, sum of (p - c), sum of the packed outer products.
  struct Moments {
    std::vector<uint32_t> count;
    std::vector<VectorD> sum;
    std::vector<PackedD> sum_sq;
  };

  static absl::StatusOr<Tree> Build(absl::Span<const Vector> points,
                                    const BarnesHutTreeOptions& options) {
    if (options.max_depth < 0 || options.max_depth > kMaxMortonDepth<D>) {
      return absl::InvalidArgumentError(absl::StrCat("tree max_depth ", options.max_depth,
                                                     " is outside the supported range 0..",
                                                     kMaxMortonDepth<D>));
    }
    if (points.empty()) {
      return absl::InvalidArgumentError("cannot build a tree of an empty cloud: send points");
    }
    const size_t max_points =
        std::min<size_t>(options.max_points, std::numeric_limits<uint32_t>::max());
    if (points.size() > max_points) {
      return absl::InvalidArgumentError(absl::StrCat("cloud has ", points.size(),
                                                     " points, more than the limit of ", max_points,
                                                     "; downsample it first"));
    }
    Eigen::AlignedBox<double, D> box;
    for (size_t i = 0; i < points.size(); ++i) {
      if (!points[i].allFinite()) {
        return absl::InvalidArgumentError(
            absl::StrCat("point ", i, " has a non-finite coordinate; remove NaN/Inf points"));
      }
      box.extend(points[i].template cast<double>());
    }

    Tree tree;
    tree.num_points_ = points.size();
    const VectorD center = box.center();
    const double largest_half_extent = 0.5 * (box.max() - box.min()).maxCoeff();
    // The relative margin keeps the farthest points strictly inside the top cell; the floor gives
    // a single point (or a cloud of duplicates) a cube instead of a division by zero.
    const double half_length = std::max(largest_half_extent * (1.0 + 1e-6),
                                        1e-6 * std::max(1.0, center.cwiseAbs().maxCoeff()));
    tree.center_ = center;
    tree.half_length_ = half_length;

    const int max_depth = options.max_depth;
    tree.neighbor_max_depth_ = std::min(options.neighbor_max_depth, max_depth);
    tree.levels_.resize(max_depth + 1);

    // Morton codes of every point at max_depth, then sorted with the point order.
    std::vector<uint64_t> codes(points.size());
    std::vector<uint32_t> order(points.size());
    for (size_t i = 0; i < points.size(); ++i) {
      codes[i] = EncodeMorton<D>(tree.CellOfPoint(points[i], max_depth));
      order[i] = static_cast<uint32_t>(i);
    }
    RadixSortByCode(codes, order, D * max_depth);

    // Finest level: one node per run of equal codes.
    Moments finest;
    typename Tree::Level& bottom = tree.levels_[max_depth];
    for (size_t i = 0; i < codes.size(); ++i) {
      if (i == 0 || codes[i] != codes[i - 1]) {
        bottom.morton.push_back(codes[i]);
        finest.count.push_back(0);
        finest.sum.push_back(VectorD::Zero());
        finest.sum_sq.push_back(PackedD::Zero());
      }
      const VectorD p = points[order[i]].template cast<double>() - center;
      finest.count.back() += 1;
      finest.sum.back() += p;
      finest.sum_sq.back() += PackedOuter(p);
    }
    FinishLevel(finest, center, bottom);

    // Coarser levels: merge runs of children with equal parent codes.
    Moments child = std::move(finest);
    for (int depth = max_depth - 1; depth >= 0; --depth) {
      typename Tree::Level& level = tree.levels_[depth];
      typename Tree::Level& below = tree.levels_[depth + 1];
      Moments merged;
      below.parent.resize(below.size());
      for (size_t j = 0; j < below.size(); ++j) {
        const uint64_t parent_code = below.morton[j] >> D;
        if (j == 0 || parent_code != level.morton.back()) {
          level.morton.push_back(parent_code);
          merged.count.push_back(0);
          merged.sum.push_back(VectorD::Zero());
          merged.sum_sq.push_back(PackedD::Zero());
        }
        const int32_t parent = static_cast<int32_t>(level.morton.size() - 1);
        below.parent[j] = parent;
        merged.count.back() += child.count[j];
        merged.sum.back() += child.sum[j];
        merged.sum_sq.back() += child.sum_sq[j];
      }
      below.labels.assign(level.morton.size() * Tree::kChildren, Tree::kEmpty);
      for (size_t j = 0; j < below.size(); ++j) {
        const size_t octant = below.morton[j] & (Tree::kChildren - 1);
        below.labels[below.parent[j] * Tree::kChildren + octant] = static_cast<int32_t>(j);
      }
      FinishLevel(merged, center, level);
      child = std::move(merged);
    }
    tree.levels_[0].parent.assign(1, Tree::kEmpty);

    BuildNeighbors(tree);
    for (typename Tree::Level& level : tree.levels_) ShrinkToFit(level);
    return tree;
  }

 private:
  static PackedD PackedOuter(const VectorD& p) {
    PackedD packed;
    int k = 0;
    for (int r = 0; r < D; ++r) {
      for (int c = r; c < D; ++c) packed[k++] = p[r] * p[c];
    }
    return packed;
  }

  // Turns raw moments into the stored attributes (centre of mass, covariance, inverse density).
  static void FinishLevel(const Moments& moments, const VectorD& center,
                          typename Tree::Level& level) {
    const size_t n = moments.count.size();
    level.count = moments.count;
    level.center_of_mass.resize(n);
    level.covariance.resize(n);
    level.inverse_density.resize(n);
    double inverse_count_sum = 0.0;
    for (size_t i = 0; i < n; ++i) inverse_count_sum += 1.0 / moments.count[i];
    for (size_t i = 0; i < n; ++i) {
      const double count = moments.count[i];
      const VectorD mean = moments.sum[i] / count;
      const PackedD covariance = moments.sum_sq[i] / count - PackedOuter(mean);
      level.center_of_mass[i] = (mean + center).template cast<float>();
      level.covariance[i] = covariance.template cast<float>();
      level.inverse_density[i] = static_cast<float>((1.0 / count) / inverse_count_sum);
    }
  }

  // Top-down: a neighbour of a node is a child of a neighbour of its parent, so each depth's
  // table comes from the one above with 3^D lookups a node and no search.
  static void BuildNeighbors(Tree& tree) {
    constexpr int kN = Tree::kNeighbors;
    if (tree.neighbor_max_depth_ < 0) return;
    tree.levels_[0].neighbors.assign(kN, Tree::kEmpty);
    tree.levels_[0].neighbors[Tree::kSelfNeighbor] = 0;
    for (int depth = 1; depth <= tree.neighbor_max_depth_; ++depth) {
      typename Tree::Level& level = tree.levels_[depth];
      const typename Tree::Level& above = tree.levels_[depth - 1];
      const int64_t cells = int64_t{1} << depth;
      level.neighbors.assign(level.size() * kN, Tree::kEmpty);
      for (size_t i = 0; i < level.size(); ++i) {
        const std::array<uint32_t, D> cell = DecodeMorton<D>(level.morton[i]);
        const int32_t* parent_neighbors = &above.neighbors[level.parent[i] * kN];
        for (int k = 0; k < kN; ++k) {
          int parent_k = 0;
          int octant = 0;
          bool inside = true;
          for (int a = 0, stride = 1; a < D; ++a, stride *= 3) {
            const int delta = (k / IntPow3(a)) % 3 - 1;
            const int64_t g = static_cast<int64_t>(cell[a]) + delta;
            if (g < 0 || g >= cells) {
              inside = false;
              break;
            }
            parent_k += static_cast<int>((g >> 1) - (cell[a] >> 1) + 1) * stride;
            octant |= static_cast<int>(g & 1) << a;
          }
          if (!inside) continue;
          const int32_t parent_neighbor = parent_neighbors[parent_k];
          if (parent_neighbor == Tree::kEmpty) continue;
          level.neighbors[i * kN + k] = level.labels[parent_neighbor * Tree::kChildren + octant];
        }
      }
    }
  }

  static void ShrinkToFit(typename Tree::Level& level) {
    level.morton.shrink_to_fit();
    level.count.shrink_to_fit();
    level.center_of_mass.shrink_to_fit();
    level.covariance.shrink_to_fit();
    level.inverse_density.shrink_to_fit();
    level.parent.shrink_to_fit();
    level.labels.shrink_to_fit();
    level.neighbors.shrink_to_fit();
  }
};

template <int D>
absl::StatusOr<BarnesHutTree<D>> BuildBarnesHutTree(
    absl::Span<const Eigen::Matrix<float, D, 1>> points, const BarnesHutTreeOptions& options) {
  return BarnesHutTreeBuilder<D>::Build(points, options);
}

absl::StatusOr<Octree> BuildOctree(const PointCloud& cloud, const BarnesHutTreeOptions& options) {
  return BuildBarnesHutTree<3>(absl::MakeConstSpan(cloud.points), options);
}

template <int D>
std::array<uint32_t, D> BarnesHutTree<D>::CellOfPoint(const Vector& p, int depth) const {
  // cells / (2 r) differs between depths by a power of two only, so the cell of a depth is
  // exactly the finer cell shifted right: the levels nest without rounding surprises.
  const double cells = static_cast<double>(uint64_t{1} << depth);
  const double scale = cells / (2.0 * half_length_);
  std::array<uint32_t, D> cell;
  for (int a = 0; a < D; ++a) {
    const double g = std::floor((static_cast<double>(p[a]) - (center_[a] - half_length_)) * scale);
    cell[a] = static_cast<uint32_t>(std::clamp(g, 0.0, cells - 1.0));
  }
  return cell;
}

template <int D>
std::array<uint32_t, D> BarnesHutTree<D>::Cell(int depth, int node) const {
  return DecodeMorton<D>(levels_[depth].morton[node]);
}

template <int D>
Eigen::AlignedBox<float, D> BarnesHutTree<D>::CellBounds(int depth, int node) const {
  const std::array<uint32_t, D> cell = Cell(depth, node);
  const double size = 2.0 * half_length_ / static_cast<double>(uint64_t{1} << depth);
  VectorD low;
  for (int a = 0; a < D; ++a) low[a] = center_[a] - half_length_ + size * cell[a];
  return Eigen::AlignedBox<float, D>(low.template cast<float>(),
                                     (low + VectorD::Constant(size)).template cast<float>());
}

template <int D>
typename BarnesHutTree<D>::Matrix BarnesHutTree<D>::Covariance(int depth, int node) const {
  const PackedSymmetric& packed = levels_[depth].covariance[node];
  Matrix m;
  int k = 0;
  for (int r = 0; r < D; ++r) {
    for (int c = r; c < D; ++c) {
      m(r, c) = packed[k];
      m(c, r) = packed[k];
      ++k;
    }
  }
  return m;
}

template <int D>
std::vector<int32_t> BarnesHutTree<D>::DenseView(int depth) const {
  if (depth < 0 || depth > std::min(7, max_depth())) return {};
  std::vector<int32_t> view(size_t{1} << (D * depth), kEmpty);
  const Level& level = levels_[depth];
  for (size_t i = 0; i < level.size(); ++i) view[level.morton[i]] = static_cast<int32_t>(i);
  return view;
}

template <int D>
size_t BarnesHutTree<D>::MemoryBytes() const {
  size_t bytes = sizeof(*this) + levels_.capacity() * sizeof(Level);
  for (const Level& level : levels_) {
    bytes += level.morton.capacity() * sizeof(uint64_t) +
             level.count.capacity() * sizeof(uint32_t) +
             level.center_of_mass.capacity() * sizeof(Vector) +
             level.covariance.capacity() * sizeof(PackedSymmetric) +
             level.inverse_density.capacity() * sizeof(float) +
             (level.parent.capacity() + level.labels.capacity() + level.neighbors.capacity()) *
                 sizeof(int32_t);
  }
  return bytes;
}

template class BarnesHutTree<2>;
template class BarnesHutTree<3>;
template absl::StatusOr<BarnesHutTree<2>> BuildBarnesHutTree<2>(
    absl::Span<const Eigen::Matrix<float, 2, 1>>, const BarnesHutTreeOptions&);
template absl::StatusOr<BarnesHutTree<3>> BuildBarnesHutTree<3>(
    absl::Span<const Eigen::Matrix<float, 3, 1>>, const BarnesHutTreeOptions&);

}  // namespace rpsr::core
