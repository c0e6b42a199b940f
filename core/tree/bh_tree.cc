#include "core/tree/bh_tree.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "absl/strings/str_cat.h"
#include "core/tree/morton.h"

namespace rpsr::core {
namespace {

// Per-thread scratch for the point codes and their sort. A worker builds many trees; reusing the
// buffers saves the page faults and zero-filling of ~3 MB per 120k-point build, which were half
// of the build time when allocated afresh.
struct SortScratch {
  std::vector<uint64_t> codes, codes_tmp;
  std::vector<uint32_t> order, order_tmp;
  std::vector<uint32_t> offsets;

  void Reserve(size_t n) {
    if (codes.size() < n) {
      codes.resize(n);
      codes_tmp.resize(n);
      order.resize(n);
      order_tmp.resize(n);
    }
  }
};

SortScratch& ThreadSortScratch() {
  thread_local SortScratch scratch;
  return scratch;
}

// floor((v - origin) * scale) clamped to [0, max_cell]: the one quantization used by the build
// and by CellOfPoint, so the two agree bit for bit. Clamping first and then truncating equals
// flooring then clamping, and avoids std::floor, which baseline x86-64 emulates slowly.
inline uint32_t QuantizeAxis(double v, double origin, double scale, double max_cell) {
  return static_cast<uint32_t>(std::clamp((v - origin) * scale, 0.0, max_cell));
}

// LSD radix sort of the first n (code, index) pairs on the low `bits` bits of the codes, 11 bits
// a pass: a depth-6 octree needs 2 passes, depth 9 three. Stable, O(n) per pass.
void RadixSortByCode(SortScratch& s, size_t n, int bits) {
  constexpr int kDigitBits = 11;
  constexpr size_t kBuckets = size_t{1} << kDigitBits;
  std::vector<uint64_t>& codes = s.codes;
  std::vector<uint32_t>& order = s.order;
  std::vector<uint64_t>& codes_tmp = s.codes_tmp;
  std::vector<uint32_t>& order_tmp = s.order_tmp;
  std::vector<uint32_t>& offsets = s.offsets;
  offsets.resize(kBuckets);
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

// Offsets in {-1, 0, 1} per axis of neighbour k (k = sum_a (delta_a + 1) 3^a).
template <int D>
constexpr std::array<std::array<int, D>, BarnesHutTree<D>::kNeighbors> NeighborOffsets() {
  std::array<std::array<int, D>, BarnesHutTree<D>::kNeighbors> offsets{};
  for (int k = 0; k < BarnesHutTree<D>::kNeighbors; ++k) {
    for (int a = 0, divisor = 1; a < D; ++a, divisor *= 3) offsets[k][a] = (k / divisor) % 3 - 1;
  }
  return offsets;
}

}  // namespace

// Builds the levels bottom-up from sorted Morton codes. Sums are accumulated in double relative
// to the cube centre, so that covariances of small cells far from the origin keep their digits.
template <int D>
class BarnesHutTreeBuilder {
 public:
  using Tree = BarnesHutTree<D>;
  using Vector = typename Tree::Vector;
  using PackedSymmetric = typename Tree::PackedSymmetric;
  using VectorD = Eigen::Matrix<double, D, 1>;
  using PackedD = Eigen::Matrix<double, D*(D + 1) / 2, 1>;

  // Raw moments of the nodes of one depth: count, sum of (p - c), sum of packed outer products.
  struct Moments {
    std::vector<uint32_t> count;
    std::vector<VectorD> sum;
    std::vector<PackedD> sum_sq;

    void ResizeZeroed(size_t m) {
      count.assign(m, 0);
      sum.assign(m, VectorD::Zero());
      sum_sq.assign(m, PackedD::Zero());
    }
  };

  // Two per thread, alternating between a depth and its parent depth; reused across builds for
  // the same reason as SortScratch (allocation and page faults dominated deep trees).
  static std::array<Moments, 2>& ThreadMoments() {
    thread_local std::array<Moments, 2> moments;
    return moments;
  }

  static absl::StatusOr<Tree> Build(absl::Span<const Vector> points,
                                    absl::Span<const uint32_t> weights,
                                    absl::Span<const PackedSymmetric> covariances,
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
    if (!weights.empty() && weights.size() != points.size()) {
      return absl::InvalidArgumentError(absl::StrCat("tree build got ", weights.size(),
                                                     " weights for ", points.size(), " points"));
    }
    if (!covariances.empty() && covariances.size() != points.size()) {
      return absl::InvalidArgumentError(absl::StrCat(
          "tree build got ", covariances.size(), " covariances for ", points.size(), " points"));
    }
    for (size_t i = 0; i < covariances.size(); ++i) {
      if (!covariances[i].allFinite()) {
        return absl::InvalidArgumentError(
            absl::StrCat("covariance ", i, " has a non-finite entry"));
      }
    }
    uint64_t total_weight = weights.empty() ? points.size() : 0;
    for (uint32_t w : weights) total_weight += w;
    if (total_weight == 0 || total_weight > std::numeric_limits<uint32_t>::max()) {
      return absl::InvalidArgumentError(
          absl::StrCat("tree build: total point weight ", total_weight, " is outside 1..2^32-1"));
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
    tree.num_points_ = total_weight;
    VectorD center = box.center();
    // The relative margin keeps the farthest points strictly inside the top cell; the floor gives
    // a single point (or a cloud of duplicates) a cube instead of a division by zero.
    double half_length = std::max(0.5 * (box.max() - box.min()).maxCoeff() * (1.0 + 1e-6),
                                  1e-6 * std::max(1.0, center.cwiseAbs().maxCoeff()));
    if (options.cube_half_length > 0.0) {
      if (options.cube_center.size() != D || !std::isfinite(options.cube_half_length)) {
        return absl::InvalidArgumentError(
            absl::StrCat("tree build: a given cube needs ", D, " finite centre coordinates"));
      }
      for (int a = 0; a < D; ++a) center[a] = options.cube_center[a];
      half_length = options.cube_half_length;
    }
    tree.center_ = center;
    tree.half_length_ = half_length;

    const int max_depth = options.max_depth;
    tree.neighbor_max_depth_ = std::min(options.neighbor_max_depth, max_depth);
    tree.levels_.resize(max_depth + 1);

    // Morton codes of every point at max_depth, then sorted with the point order.
    const size_t n = points.size();
    SortScratch& scratch = ThreadSortScratch();
    scratch.Reserve(n);
    {
      const double cells = static_cast<double>(uint64_t{1} << max_depth);
      const double scale = cells / (2.0 * half_length);
      const VectorD origin = center - VectorD::Constant(half_length);
      for (size_t i = 0; i < n; ++i) {
        std::array<uint32_t, D> cell;
        for (int a = 0; a < D; ++a) {
          cell[a] = QuantizeAxis(points[i][a], origin[a], scale, cells - 1.0);
        }
        scratch.codes[i] = EncodeMorton<D>(cell);
        scratch.order[i] = static_cast<uint32_t>(i);
      }
    }
    RadixSortByCode(scratch, n, D * max_depth);
    const uint64_t* codes = scratch.codes.data();
    const uint32_t* order = scratch.order.data();

    // Finest level: one node per run of equal codes. Runs are counted first so every array is
    // allocated once at its exact size. A run is summed in plain local scalars and stored once:
    // accumulating through vector elements or Eigen temporaries stalled on store forwarding.
    std::array<Moments, 2>& moments = ThreadMoments();
    Moments* child = &moments[0];
    Moments* merged = &moments[1];
    typename Tree::Level& bottom = tree.levels_[max_depth];
    size_t runs = n > 0 ? 1 : 0;
    for (size_t i = 1; i < n; ++i) runs += codes[i] != codes[i - 1];
    bottom.morton.resize(runs);
    child->ResizeZeroed(runs);
    constexpr int kPacked = D * (D + 1) / 2;
    for (size_t i = 0, node = 0; i < n; ++node) {
      const uint64_t code = codes[i];
      uint32_t count = 0;
      double sum[D] = {};
      double sum_sq[kPacked] = {};
      do {
        double p[D];
        for (int a = 0; a < D; ++a) p[a] = static_cast<double>(points[order[i]][a]) - center[a];
        const uint32_t w = weights.empty() ? 1 : weights[order[i]];
        count += w;
        for (int a = 0; a < D; ++a) sum[a] += w * p[a];
        for (int r = 0, k = 0; r < D; ++r) {
          for (int c = r; c < D; ++c, ++k) sum_sq[k] += w * p[r] * p[c];
        }
        if (!covariances.empty()) {  // the patch's own spread about its centre
          const PackedSymmetric& spread = covariances[order[i]];
          for (int k = 0; k < kPacked; ++k) sum_sq[k] += w * static_cast<double>(spread[k]);
        }
        ++i;
      } while (i < n && codes[i] == code);
      bottom.morton[node] = code;
      child->count[node] = count;
      child->sum[node] = Eigen::Map<const VectorD>(sum);
      child->sum_sq[node] = Eigen::Map<const PackedD>(sum_sq);
    }
    FinishLevel(*child, center, bottom);

    // Coarser levels: merge runs of children with equal parent codes.
    for (int depth = max_depth - 1; depth >= 0; --depth) {
      typename Tree::Level& level = tree.levels_[depth];
      typename Tree::Level& below = tree.levels_[depth + 1];
      const size_t m = below.size();
      size_t parents = 1;
      for (size_t j = 1; j < m; ++j)
        parents += (below.morton[j] >> D) != (below.morton[j - 1] >> D);
      level.morton.resize(parents);
      merged->ResizeZeroed(parents);
      below.parent.resize(m);
      int32_t parent = -1;
      for (size_t j = 0; j < m; ++j) {
        if (j == 0 || (below.morton[j] >> D) != (below.morton[j - 1] >> D)) {
          level.morton[++parent] = below.morton[j] >> D;
        }
        below.parent[j] = parent;
        merged->count[parent] += child->count[j];
        merged->sum[parent] += child->sum[j];
        merged->sum_sq[parent] += child->sum_sq[j];
      }
      below.labels.assign(parents * Tree::kChildren, Tree::kEmpty);
      for (size_t j = 0; j < m; ++j) {
        const size_t octant = below.morton[j] & (Tree::kChildren - 1);
        below.labels[below.parent[j] * Tree::kChildren + octant] = static_cast<int32_t>(j);
      }
      FinishLevel(*merged, center, level);
      std::swap(child, merged);
    }
    tree.levels_[0].parent.assign(1, Tree::kEmpty);

    BuildNeighbors(tree);
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
    static constexpr auto kOffsets = NeighborOffsets<D>();
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
            const int64_t g = static_cast<int64_t>(cell[a]) + kOffsets[k][a];
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
};

template <int D>
absl::StatusOr<BarnesHutTree<D>> BuildBarnesHutTree(
    absl::Span<const Eigen::Matrix<float, D, 1>> points, const BarnesHutTreeOptions& options) {
  return BarnesHutTreeBuilder<D>::Build(points, {}, {}, options);
}

template <int D>
absl::StatusOr<BarnesHutTree<D>> BuildWeightedBarnesHutTree(
    absl::Span<const Eigen::Matrix<float, D, 1>> points, absl::Span<const uint32_t> weights,
    const BarnesHutTreeOptions& options) {
  return BarnesHutTreeBuilder<D>::Build(points, weights, {}, options);
}

template <int D>
absl::StatusOr<BarnesHutTree<D>> BuildWeightedBarnesHutTree(
    absl::Span<const Eigen::Matrix<float, D, 1>> points, absl::Span<const uint32_t> weights,
    absl::Span<const typename BarnesHutTree<D>::PackedSymmetric> covariances,
    const BarnesHutTreeOptions& options) {
  return BarnesHutTreeBuilder<D>::Build(points, weights, covariances, options);
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
    cell[a] = QuantizeAxis(p[a], center_[a] - half_length_, scale, cells - 1.0);
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
template absl::StatusOr<BarnesHutTree<2>> BuildWeightedBarnesHutTree<2>(
    absl::Span<const Eigen::Matrix<float, 2, 1>>, absl::Span<const uint32_t>,
    const BarnesHutTreeOptions&);
template absl::StatusOr<BarnesHutTree<3>> BuildWeightedBarnesHutTree<3>(
    absl::Span<const Eigen::Matrix<float, 3, 1>>, absl::Span<const uint32_t>,
    const BarnesHutTreeOptions&);
template absl::StatusOr<BarnesHutTree<2>> BuildWeightedBarnesHutTree<2>(
    absl::Span<const Eigen::Matrix<float, 2, 1>>, absl::Span<const uint32_t>,
    absl::Span<const BarnesHutTree<2>::PackedSymmetric>, const BarnesHutTreeOptions&);
template absl::StatusOr<BarnesHutTree<3>> BuildWeightedBarnesHutTree<3>(
    absl::Span<const Eigen::Matrix<float, 3, 1>>, absl::Span<const uint32_t>,
    absl::Span<const BarnesHutTree<3>::PackedSymmetric>, const BarnesHutTreeOptions&);

}  // namespace rpsr::core
