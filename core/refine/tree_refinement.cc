#include "core/refine/tree_refinement.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <cassert>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "Eigen/Cholesky"
#include "Eigen/Eigenvalues"
#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "core/refine/cell_index.h"
#include "core/refine/noise_polish.h"
#include "core/tree/morton.h"

namespace rpsr::core {
namespace {

using Matrix6d = Eigen::Matrix<double, 6, 6>;
using Vector6d = Eigen::Matrix<double, 6, 1>;

double SecondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

Eigen::Isometry3d MakeIsometry(const Eigen::Matrix3d& R, const Eigen::Vector3d& t) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = R;
  T.translation() = t;
  return T;
}

// A node's covariance regularised as in GICP, in metres^2: eigenvalues (eps, 1, 1) * edge^2
// along the eigenvectors of the node's shape (the smallest is the surface normal). A node with
// too few points to have a shape borrows it from its nearest ancestor that has enough (the
// parent's patch of the same surface): deep levels of sparse clouds are mostly such nodes, and
// making them isotropic would hand every plane information along itself (a plane would look
// constrained in-plane). Only when even the root lacks points is it isotropic, edge^2 * I.
// Kept as iso * I - flat * n n^T (flat = edge^2 (1 - eps) when planar, 0 when isotropic): turning
// it by R then costs one rotated normal instead of two 3x3 products, in the correspondence loop.
struct RegularizedNode {
  double iso = 0.0;
  double flat = 0.0;
  Eigen::Vector3d normal = Eigen::Vector3d::Zero();
  bool planar = false;
};

// A node's shape as Regularize reads it: the normal of the nearest node on its path to the root
// (itself first) holding at least min_count points, or none (isotropic).
struct NodeShape {
  Eigen::Vector3d normal = Eigen::Vector3d::Zero();
  bool planar = false;
};

// How nodes get their shapes (what a side's shapes depend on besides the tree and the depth):
// TreeRefinementOptions::min_count_for_covariance and line_normals_from_planes.
struct ShapeRule {
  int min_count = 0;
  bool line_normals_from_planes = false;
  bool operator==(const ShapeRule&) const = default;
};

// RefineOnTrees resolves an unset line_normals_from_planes before any side is built, and
// PreparedRefinementTarget::Prepare its own; unresolved here would be a bug (read as off).
ShapeRule ShapeRuleOf(const TreeRefinementOptions& options) {
  assert(options.line_normals_from_planes.has_value());
  return {options.min_count_for_covariance, options.line_normals_from_planes.value_or(false)};
}

// TreeRefinementOptions::line_normals_from_planes: a shape is a line by kLineEigenvalueRatio
// (tree_refinement.h); an ancestor lends it its normal when the line lies within 60 degrees of
// the ancestor's plane (|normal . line| < 0.5), looking at most this many depths up.
constexpr double kLineInPlaneCosine = 0.5;
constexpr int kLineAncestorsSearched = 3;

bool IsLine(const Eigen::Vector3d& ascending_eigenvalues) {
  return ascending_eigenvalues[1] < kLineEigenvalueRatio * ascending_eigenvalues[2];
}

}  // namespace

std::pair<int, int> ShapeNodeOf(const Octree& tree, int depth, int node, int min_count) {
  while (static_cast<int>(tree.level(depth).count[node]) < min_count && depth > 0) {
    node = tree.level(depth).parent[node];
    --depth;
  }
  if (static_cast<int>(tree.level(depth).count[node]) < min_count) return {-1, -1};
  return {depth, node};
}

std::optional<double> LineShapedFraction(const Octree& tree, int min_count_for_covariance) {
  // 2,048 samples: the fraction within ~0.01 (binomial standard error; 0.12 ms a depth-9 scan
  // tree, against ~12 ms for its refinement); 100: within 0.05.
  constexpr size_t kSampled = 2048;
  constexpr size_t kFewestShaped = 100;
  const int depth = tree.max_depth();
  if (depth < 0) return std::nullopt;
  const Octree::Level& level = tree.level(depth);
  const size_t n = level.size();
  const size_t used = std::min(n, kSampled);
  size_t shaped = 0;
  size_t lines = 0;
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver;
  for (size_t k = 0; k < used; ++k) {
    const size_t node = k * n / used;  // even stride over the Morton order
    if (static_cast<int>(level.count[node]) < std::max(min_count_for_covariance, 1)) continue;
    ++shaped;
    solver.computeDirect(tree.Covariance(depth, static_cast<int>(node)).cast<double>(),
                         Eigen::EigenvaluesOnly);
    if (IsLine(solver.eigenvalues())) ++lines;
  }
  if (shaped < kFewestShaped) return std::nullopt;
  return static_cast<double>(lines) / static_cast<double>(shaped);
}

bool ChooseLineNormalsFromPlanes(std::optional<double> source_fraction,
                                 std::optional<double> target_fraction) {
  constexpr double kLineShapedMean = 0.67;
  if (!source_fraction.has_value() || !target_fraction.has_value()) return false;
  return 0.5 * (*source_fraction + *target_fraction) >= kLineShapedMean;
}

namespace {

// The ancestors' planes ShapeAt reads for line nodes, the last one asked at each depth. A line
// node searches up to kLineAncestorsSearched ancestors, and consecutive nodes in the Morton order
// (siblings, cousins) mostly ask for the same ones: on a VLP-16 drive, where most of the finest
// nodes are lines, these eigen-decompositions outnumbered the nodes' own (3.7M against 3.3M in
// `rpsr odometry` over 200 urban frames). The value is the one recomputing would give. One memo
// serves one tree and one caller (it is not shared between threads).
struct AncestorPlanes {
  struct Plane {
    int node = -1;
    bool line = false;
    Eigen::Vector3d normal = Eigen::Vector3d::Zero();
  };
  const Octree* tree = nullptr;
  std::array<Plane, kMaxMortonDepth<3> + 1> by_depth;

  const Plane& Of(const Octree& of, int depth, int node) {
    if (tree != &of) {
      tree = &of;
      by_depth.fill(Plane{});
    }
    Plane& plane = by_depth[static_cast<size_t>(depth)];
    if (plane.node != node) {
      Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver;
      solver.computeDirect(of.Covariance(depth, node).cast<double>());
      plane.node = node;
      plane.line = IsLine(solver.eigenvalues());
      plane.normal = solver.eigenvectors().col(0);
    }
    return plane;
  }
};

NodeShape ShapeAt(const Octree& tree, std::pair<int, int> shape_node, bool line_normals_from_planes,
                  AncestorPlanes& ancestors) {
  NodeShape out;
  if (shape_node.first < 0) return out;
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver;
  solver.computeDirect(tree.Covariance(shape_node.first, shape_node.second).cast<double>());
  out.normal = solver.eigenvectors().col(0);  // eigenvalues ascending
  out.planar = true;
  if (!line_normals_from_planes || !IsLine(solver.eigenvalues())) return out;
  // A line: its smallest eigenvector is whichever perpendicular noise made smaller. The plane it
  // lies on, seen by an ancestor, says which.
  const Eigen::Vector3d line = solver.eigenvectors().col(2);
  auto [depth, node] = shape_node;
  for (int up = 0; up < kLineAncestorsSearched && depth > 0; ++up) {
    node = tree.level(depth).parent[node];
    --depth;
    const AncestorPlanes::Plane& ancestor = ancestors.Of(tree, depth, node);
    if (ancestor.line) continue;
    if (std::abs(ancestor.normal.dot(line)) < kLineInPlaneCosine) out.normal = ancestor.normal;
    break;
  }
  return out;
}

NodeShape ShapeOf(const Octree& tree, int depth, int node, const ShapeRule& rule,
                  AncestorPlanes& ancestors) {
  return ShapeAt(tree, ShapeNodeOf(tree, depth, node, rule.min_count),
                 rule.line_normals_from_planes, ancestors);
}

// A node's regularised covariance from its shape (the shape's node may be an ancestor).
RegularizedNode Regularize(const NodeShape& shape, double edge, double covariance_epsilon) {
  RegularizedNode out;
  const double edge2 = edge * edge;
  out.iso = edge2;
  if (!shape.planar) return out;
  out.normal = shape.normal;
  out.flat = edge2 * (1.0 - covariance_epsilon);
  out.planar = true;
  return out;
}

// The target's side of one depth: its cell index (Morton code -> node, cell_index.h) and its nodes'
// shapes (the regularisation's epsilon is applied where they are read, so one side serves the
// coarse and the fine epsilon). It depends on the target tree, the depth and the shape rule alone,
// so the rounds of a re-binned depth and the registrar's several starts on one pair share it
// (TreeRefinementCache), and a PreparedRefinementTarget shares it among pairs and threads.
// Shapes are computed on first use (only nodes ever matched pay the eigen-decomposition), also
// when shared: a node's state goes 0 -> 1 (claimed by the one thread that computes it) -> 2 (its
// shape is written and published); a thread that finds it claimed computes a copy of its own.
struct TargetDepth {
  int depth = 0;
  ShapeRule rule;
  double edge = 0.0;
  CellIndex index;
  size_t nodes = 0;
  // The level's centres of mass (the same floats) and one more, out of every search's reach, at
  // index `nodes`: FindPartner reads an empty cell's slot there instead of branching on it.
  std::vector<Eigen::Vector3f> com;
  mutable std::unique_ptr<NodeShape[]> shapes;
  mutable std::unique_ptr<std::atomic<uint8_t>[]> state;
  // The side of depth - 1 (same tree and shape rule) when its owner holds one: a node too sparse
  // for a shape reads its parent's there (ShapeOf walks up the same way, so the value is the
  // same), and siblings share one eigen-decomposition instead of one each (at an object's finest
  // depth most nodes hold one or two points).
  const TargetDepth* coarser = nullptr;

  // Node j's shape: the published one, or computed now (into `scratch` when another thread is
  // computing the published one).
  const NodeShape& Shape(const Octree& target, int j, NodeShape& scratch,
                         AncestorPlanes& ancestors) const {
    if (coarser != nullptr && static_cast<int>(target.level(depth).count[j]) < rule.min_count) {
      return coarser->Shape(target, target.level(depth).parent[j], scratch, ancestors);
    }
    uint8_t seen = state[j].load(std::memory_order_acquire);
    if (seen == 2) return shapes[j];
    if (seen == 0 && state[j].compare_exchange_strong(seen, 1, std::memory_order_acq_rel)) {
      shapes[j] = ShapeOf(target, depth, j, rule, ancestors);
      state[j].store(2, std::memory_order_release);
      return shapes[j];
    }
    scratch = ShapeOf(target, depth, j, rule, ancestors);
    return scratch;
  }

  size_t bytes() const {
    return sizeof(*this) + index.bytes() - sizeof(CellIndex) +
           nodes * (sizeof(NodeShape) + sizeof(std::atomic<uint8_t>)) +
           com.capacity() * sizeof(Eigen::Vector3f);
  }
};

// The source's side of one depth: the chosen nodes with their prior weights, and their
// regularised covariances on first use. On the source's own cells it is shared like the target's;
// re-binned cells are new at every round. Only matched nodes read a shape, and a scan's depths hold
// 15-25% without a partner, so computing them eagerly spent eigen-decompositions nobody read (the
// decompositions were a fifth of a scan's refinement). One thread at a time, like its cache.
struct SourceDepth {
  int depth = 0;
  double covariance_epsilon = 0.0;
  ShapeRule rule;
  WeightScheme weights = WeightScheme::kInverseDensity;
  int max_nodes = 0;
  std::vector<int32_t> nodes;
  std::vector<Eigen::Vector3d> mean;
  std::vector<double> prior;  // inverse density, count or 1 (see WeightScheme)

  // Entry k's regularised covariance, computed now if it has not been (the same value either way).
  const RegularizedNode& Regularized(size_t k) const {
    if (!shaped[k]) {
      // Nodes too sparse for a shape read their ancestor's, and siblings are adjacent in the
      // Morton order: the last shape computed is reused for them (at an object's finest depth most
      // nodes hold one or two points).
      const std::pair<int, int> shape_node = ShapeNodeOf(*tree, depth, nodes[k], rule.min_count);
      if (shape_node != last_shape_node) {
        last_shape = ShapeAt(*tree, shape_node, rule.line_normals_from_planes, ancestors);
        last_shape_node = shape_node;
      }
      regularized[k] = Regularize(last_shape, edge, covariance_epsilon);
      shaped[k] = 1;
    }
    return regularized[k];
  }

  const Octree* tree = nullptr;  // must outlive the side
  double edge = 0.0;             // the source tree's cell edge at `depth`
  mutable std::vector<RegularizedNode> regularized;
  mutable std::vector<uint8_t> shaped;
  mutable std::pair<int, int> last_shape_node = {-2, -2};
  mutable NodeShape last_shape;
  mutable AncestorPlanes ancestors;
};

// One stage's view: both sides, and per source entry the target nodes of the cell block last
// searched (block_size slots, -1 = empty cell), keyed by the block's home cell code and, for
// 8-cell blocks, its side bits.
struct DepthData {
  int depth = 0;
  double edge_target = 0.0;
  const SourceDepth* source = nullptr;
  const TargetDepth* target = nullptr;
  int block_size = 8;
  std::vector<uint64_t> block_home;
  std::vector<uint8_t> block_sides;
  std::vector<int32_t> block_nodes;
};

// Fills a new (empty) side; its shapes come on first use (SourceDepth::Regularized).
void PrepareSourceDepth(const Octree& source, int depth, const TreeRefinementOptions& options,
                        SourceDepth& side) {
  side.depth = depth;
  side.covariance_epsilon = options.covariance_epsilon;
  side.rule = ShapeRuleOf(options);
  side.weights = options.weights;
  side.max_nodes = options.max_source_nodes_per_depth;
  side.tree = &source;
  side.edge = CellEdge(source, depth);
  const Octree::Level& s = source.level(depth);
  const size_t n = s.size();
  const size_t used = std::min(n, static_cast<size_t>(options.max_source_nodes_per_depth));
  side.nodes.reserve(used);
  for (size_t k = 0; k < used; ++k) {
    // Even stride over the Morton order: spatially spread, deterministic.
    side.nodes.push_back(static_cast<int32_t>(k * n / used));
  }
  side.mean.reserve(used);
  side.prior.reserve(used);
  side.regularized.resize(used);
  side.shaped.assign(used, 0);
  for (int32_t node : side.nodes) {
    side.mean.push_back(s.center_of_mass[node].cast<double>());
    switch (options.weights) {
      case WeightScheme::kInverseDensity:
        side.prior.push_back(s.inverse_density[node]);
        break;
      case WeightScheme::kSourceCount:
        side.prior.push_back(s.count[node]);
        break;
      case WeightScheme::kUniform:
        side.prior.push_back(1.0);
        break;
    }
  }
}

// Fills a new (empty) side: the index now, the shapes on first use.
void PrepareTargetDepth(const Octree& target, int depth, const ShapeRule& rule, TargetDepth& side) {
  side.depth = depth;
  side.rule = rule;
  side.edge = CellEdge(target, depth);
  const Octree::Level& t = target.level(depth);
  side.index = CellIndex(t.morton, depth);
  side.nodes = t.size();
  side.com.reserve(t.size() + 1);
  side.com.assign(t.center_of_mass.begin(), t.center_of_mass.end());
  side.com.emplace_back(Eigen::Vector3f::Constant(std::numeric_limits<float>::max()));
  side.shapes = std::make_unique<NodeShape[]>(t.size());
  side.state = std::make_unique<std::atomic<uint8_t>[]>(t.size());  // value-initialised: all 0
}

// A target side found for a stage, and whether it came from a PreparedRefinementTarget.
struct TargetSideRef {
  const TargetDepth* side = nullptr;
  bool prepared = false;
};

DepthData MakeDepthData(const SourceDepth& source, TargetSideRef target,
                        const TreeRefinementOptions& options) {
  DepthData data;
  data.depth = target.side->depth;
  data.edge_target = target.side->edge;
  data.source = &source;
  data.target = target.side;
  const size_t used = source.nodes.size();
  data.block_size = options.search_27_neighbors ? 27 : 8;
  data.block_home.assign(used, ~uint64_t{0});  // no code: depth <= 21 uses 63 bits
  data.block_sides.assign(used, 0);
  data.block_nodes.assign(used * data.block_size, -1);
  return data;
}

}  // namespace

// A prepared target's sides: one per depth from the coarsest, for one shape rule.
struct PreparedRefinementTarget::Sides {
  std::vector<TargetDepth> depths;  // coarse to fine
  ShapeRule rule;

  const TargetDepth* Find(int depth, const ShapeRule& wanted) const {
    if (wanted != rule) return nullptr;
    for (const TargetDepth& side : depths) {
      if (side.depth == depth) return &side;
    }
    return nullptr;
  }
};

// The sides already prepared for one (source, target) pair, found by what they depend on.
struct TreeRefinementCache::Impl {
  const Octree* source = nullptr;
  const Octree* target = nullptr;
  std::vector<std::unique_ptr<SourceDepth>> sources;
  std::vector<std::unique_ptr<TargetDepth>> targets;
  // Read first when the bound target is its tree.
  std::shared_ptr<const PreparedRefinementTarget> prepared;
  // The trees' LineShapedFraction for fractions_min_count (-1: not yet measured).
  int fractions_min_count = -1;
  std::optional<double> source_fraction;
  std::optional<double> target_fraction;
  // The noise polish's two sides (one depth; every start on the pair polishes with them).
  std::unique_ptr<PolishSides> polish_sides;

  void BindTo(const Octree& s, const Octree& t) {
    if (source == &s && target == &t) return;
    source = &s;
    target = &t;
    sources.clear();
    targets.clear();
    polish_sides.reset();
    fractions_min_count = -1;
  }

  // The noise polish's sides at `depth` of the bound pair.
  PolishSides& PolishSidesAt(int depth) {
    if (polish_sides == nullptr || polish_sides->source.depth != depth) {
      polish_sides = std::make_unique<PolishSides>(*source, *target, depth);
    }
    return *polish_sides;
  }

  // The options' line rule for the bound pair: as given, or chosen from the trees' fractions
  // (measured once per pair; the target's read from the prepared target when it has them).
  bool LineNormalsFromPlanes(const TreeRefinementOptions& o) {
    if (o.line_normals_from_planes.has_value()) return *o.line_normals_from_planes;
    if (fractions_min_count != o.min_count_for_covariance) {
      fractions_min_count = o.min_count_for_covariance;
      source_fraction = LineShapedFraction(*source, o.min_count_for_covariance);
      target_fraction = prepared != nullptr && &prepared->tree() == target &&
                                prepared->sides().rule.min_count == o.min_count_for_covariance
                            ? prepared->line_shaped_fraction()
                            : LineShapedFraction(*target, o.min_count_for_covariance);
    }
    return ChooseLineNormalsFromPlanes(source_fraction, target_fraction);
  }

  const SourceDepth& Source(int depth, const TreeRefinementOptions& o) {
    for (const auto& side : sources) {
      if (side->depth == depth && side->covariance_epsilon == o.covariance_epsilon &&
          side->rule == ShapeRuleOf(o) && side->weights == o.weights &&
          side->max_nodes == o.max_source_nodes_per_depth) {
        return *side;
      }
    }
    sources.push_back(std::make_unique<SourceDepth>());
    PrepareSourceDepth(*source, depth, o, *sources.back());
    return *sources.back();
  }

  TargetSideRef Target(int depth, const TreeRefinementOptions& o) {
    if (prepared != nullptr && &prepared->tree() == target) {
      if (const TargetDepth* side = prepared->sides().Find(depth, ShapeRuleOf(o))) {
        return {side, true};
      }
    }
    for (const auto& side : targets) {
      if (side->depth == depth && side->rule == ShapeRuleOf(o)) {
        return {side.get(), false};
      }
    }
    targets.push_back(std::make_unique<TargetDepth>());
    TargetDepth& made = *targets.back();
    PrepareTargetDepth(*target, depth, ShapeRuleOf(o), made);
    for (const auto& side : targets) {  // link neighbouring depths, in whichever order they came
      if (side->rule != made.rule) continue;
      if (side->depth == depth - 1) made.coarser = side.get();
      if (side->depth == depth + 1) side->coarser = &made;
    }
    return {&made, false};
  }
};

TreeRefinementCache::TreeRefinementCache() : impl_(std::make_unique<Impl>()) {}
TreeRefinementCache::TreeRefinementCache(std::shared_ptr<const PreparedRefinementTarget> prepared)
    : impl_(std::make_unique<Impl>()) {
  impl_->prepared = std::move(prepared);
}

PreparedRefinementTarget::PreparedRefinementTarget() = default;
PreparedRefinementTarget::~PreparedRefinementTarget() = default;

absl::StatusOr<std::shared_ptr<const PreparedRefinementTarget>> PreparedRefinementTarget::Prepare(
    const Octree& target, const TreeRefinementOptions& options) {
  if (target.max_depth() < 0 || target.num_points() == 0) {
    return absl::InvalidArgumentError("PreparedRefinementTarget: the target tree is empty");
  }
  if (options.min_count_for_covariance < 0 || options.coarsest_depth > target.max_depth()) {
    return absl::InvalidArgumentError(absl::StrCat(
        "PreparedRefinementTarget: min_count_for_covariance (", options.min_count_for_covariance,
        ") must be non-negative and coarsest_depth (", options.coarsest_depth,
        ") within the tree's depth ", target.max_depth()));
  }
  // Every depth a refinement against this target can visit with these options: from the
  // coarsest (StageDepths' rule) to the tree's deepest (a shallower source stops earlier).
  const int coarsest =
      options.coarsest_depth < 0 ? std::min(target.max_depth(), 3) : options.coarsest_depth;
  std::shared_ptr<PreparedRefinementTarget> prepared(new PreparedRefinementTarget());
  prepared->tree_ = &target;
  prepared->line_shaped_fraction_ = LineShapedFraction(target, options.min_count_for_covariance);
  auto sides = std::make_unique<Sides>();
  sides->rule = {options.min_count_for_covariance,
                 options.line_normals_from_planes.value_or(ChooseLineNormalsFromPlanes(
                     prepared->line_shaped_fraction_, prepared->line_shaped_fraction_))};
  sides->depths.resize(static_cast<size_t>(target.max_depth() - coarsest + 1));
  size_t bytes = sizeof(PreparedRefinementTarget) + sizeof(Sides);
  for (int depth = coarsest; depth <= target.max_depth(); ++depth) {
    TargetDepth& side = sides->depths[static_cast<size_t>(depth - coarsest)];
    PrepareTargetDepth(target, depth, sides->rule, side);
    if (depth > coarsest) side.coarser = &sides->depths[static_cast<size_t>(depth - coarsest - 1)];
    bytes += side.bytes();
  }
  prepared->sides_ = std::move(sides);
  prepared->bytes_ = bytes;
  return std::shared_ptr<const PreparedRefinementTarget>(std::move(prepared));
}
TreeRefinementCache::~TreeRefinementCache() = default;
TreeRefinementCache::TreeRefinementCache(TreeRefinementCache&&) noexcept = default;
TreeRefinementCache& TreeRefinementCache::operator=(TreeRefinementCache&&) noexcept = default;

namespace {

struct Correspondence {
  // User-provided, not defaulted: emplace_back() value-initialises, and a class whose default
  // constructor is implicit is zero-filled first, the 72-byte information matrix included (3.5%
  // of a scan's Linearize in a profile while the comment below already said it was not).
  Correspondence() {}                               // NOLINT(modernize-use-equals-default)
  int32_t k = 0;                                    // index into DepthData::source_*
  int32_t j = 0;                                    // target node
  Eigen::Vector3d moved = Eigen::Vector3d::Zero();  // T * mu_s
  Eigen::Vector3d target_mean = Eigen::Vector3d::Zero();
  // (C_t + R C_s R^T)^-1, set by Linearize's second pass before anything reads it. Left
  // uninitialised: the emplace_back that zeroed the whole struct was 1.7% of a scan's profile.
  Eigen::Matrix3d information;
  double weight = 0.0;  // normalised prior * robust weight
  double robust = 0.0;  // robust weight alone
};

// The nearest target CoM to `q` (the moved CoM of source entry k) among the target cells of the
// block around q's cell, within max_distance; -1 when none. The block's node indices are cached
// per source entry and looked up again only when q moves to another block: after the first
// iterations of a depth the updates are small, so the cell-index lookups (CellIndex: random
// memory accesses, most of the cost when they were all hash lookups) are mostly skipped. The answer
// is the same as without the cache.
int32_t FindPartner(const Octree& target, DepthData& data, size_t k, const Eigen::Vector3d& q,
                    double max_distance2) {
  const int depth = data.depth;
  const double cells = static_cast<double>(uint64_t{1} << depth);
  const BlockHome at = LocateBlockHome(target, depth, q);
  // Farther than a cell outside the cube: skipped (beyond the reach of a one-cell search; a
  // two-cell search, coarse_max_correspondence_distance_cells, could still find a border cell
  // for it, but its block is built around the clamped home cell anyway).
  for (int a = 0; a < 3; ++a) {
    if (!(at.position[a] > -1.0 && at.position[a] < cells + 1.0)) return -1;
  }
  const uint64_t home_code = EncodeMorton<3>(at.home);
  const int block = data.block_size;
  int32_t* candidates = &data.block_nodes[k * block];
  if (data.block_home[k] != home_code || (block == 8 && data.block_sides[k] != at.side_bits)) {
    data.block_home[k] = home_code;
    data.block_sides[k] = at.side_bits;
    FindBlock(data.target->index, at.home, at.side, block, static_cast<int64_t>(cells), candidates);
  }
  const Eigen::Vector3f* com = data.target->com.data();
  const int32_t none = static_cast<int32_t>(data.target->nodes);
  int32_t best = -1;
  double best_d2 = max_distance2;
  // An empty cell (-1) reads the padding CoM, ~1e77 away squared, instead of being branched
  // over: which of a block's cells are empty is data the branch predictor cannot learn
  // (registrar_bench objects refine ~0.96x, alternated; answers bit for bit the same). Forcing
  // the comparison below into masks as well was slower (~1.07x).
  for (int slot = 0; slot < block; ++slot) {
    const int32_t j = candidates[slot];
    const int32_t read = j < 0 ? none : j;
    const double d2 = (com[read].cast<double>() - q).squaredNorm();
    // Ties go to the lower index: the answer never depends on the visiting order.
    const bool nearer = d2 < best_d2 || (d2 == best_d2 && (best < 0 || j < best));
    best = nearer ? j : best;
    best_d2 = nearer ? d2 : best_d2;
  }
  return best;
}

// One linearisation at (R, t): correspondences, H, b about the weighted centroid, and the
// statistics the result reports.
struct Linearization {
  int correspondences = 0;
  Matrix6d H = Matrix6d::Zero();
  Vector6d b = Vector6d::Zero();
  Eigen::Vector3d center = Eigen::Vector3d::Zero();
  // Weighted second moment of the matched target CoMs about `center` (m^2).
  Eigen::Matrix3d spread = Eigen::Matrix3d::Zero();
  double inlier_count = 0.0;  // points (node counts)
  double used_count = 0.0;
  double inlier_sq_sum = 0.0;  // count-weighted squared plane distances
  int inlier_nodes = 0;
  double robust_sum = 0.0;  // sum of the correspondences' robust weights
  // The robust cost the iterations decrease: sum over the used source nodes of their prior weight
  // times the Geman-McClure rho(e^2) = c^2 e^2 / (c^2 + e^2) of the Mahalanobis distance, an
  // unmatched node counting the kernel's ceiling c^2 (and the target's mean inverse density), so
  // that costs under different correspondence sets compare.
  double cost = 0.0;
  // A joint stage's coarser depth (TreeRefinementOptions::joint_finest_stage): its H, b and cost
  // about the same `center`, added to the above for the step and for the information the result
  // reports; zero otherwise. The other statistics above stay the finest depth's own.
  Matrix6d coarser_H = Matrix6d::Zero();
  Vector6d coarser_b = Vector6d::Zero();
  double coarser_cost = 0.0;
  int coarser_correspondences = 0;
  // Sum of the correspondences' final weights (the spread's normaliser), the coarser depth's too.
  double weight_sum = 0.0;
  double coarser_weight_sum = 0.0;

  double step_cost() const { return cost + coarser_cost; }
};

double FitnessOf(const Linearization& lin) {
  return lin.used_count > 0 ? lin.inlier_count / lin.used_count : 0.0;
}

double InlierRmseOf(const Linearization& lin) {
  return lin.inlier_count > 0 ? std::sqrt(lin.inlier_sq_sum / lin.inlier_count) : 0.0;
}

// H += J^T W J and b += J^T W r over `corr` (as Linearize left them: weighted, about lin.center),
// and the matched spread. Separate from Linearize because the finest stage's step control refuses
// most candidate steps (three in four on objects) by their cost alone, and this loop is a large
// share of a linearisation.
void AddSystem(const std::vector<Correspondence>& corr, Linearization& lin) {
  if (!(lin.weight_sum > 0.0)) return;
  // With J = [[a]x, -I] (a = moved CoM about the centre) and W = weight * information, written
  // out in 3x3 blocks: with Q = [a]x W, J^T W J is [[-Q [a]x, Q], [Q^T, W]] and J^T W r is
  // [(W r) x a, -W r] (about a third of the products of the 6x3 form).
  Eigen::Matrix3d H_rr = Eigen::Matrix3d::Zero();
  Eigen::Matrix3d H_rt = Eigen::Matrix3d::Zero();
  Eigen::Matrix3d H_tt = Eigen::Matrix3d::Zero();
  Eigen::Vector3d b_r = Eigen::Vector3d::Zero();
  Eigen::Vector3d b_t = Eigen::Vector3d::Zero();
  for (const Correspondence& c : corr) {
    const Eigen::Vector3d a = c.moved - lin.center;
    const Eigen::Vector3d arm = c.target_mean - lin.center;
    lin.spread.noalias() += c.weight * arm * arm.transpose();
    const Eigen::Matrix3d W = c.weight * c.information;
    Eigen::Matrix3d Q;
    for (int j = 0; j < 3; ++j) Q.col(j) = a.cross(W.col(j));
    for (int i = 0; i < 3; ++i) H_rr.row(i) += a.cross(Q.row(i).transpose()).transpose();
    H_rt += Q;
    H_tt += W;
    const Eigen::Vector3d Wr = W * (c.target_mean - c.moved);
    b_r += Wr.cross(a);
    b_t -= Wr;
  }
  lin.H.topLeftCorner<3, 3>() = H_rr;
  lin.H.topRightCorner<3, 3>() = H_rt;
  lin.H.bottomLeftCorner<3, 3>() = H_rt.transpose();
  lin.H.bottomRightCorner<3, 3>() = H_tt;
  lin.b.head<3>() = b_r;
  lin.b.tail<3>() = b_t;
  lin.spread /= lin.weight_sum;
}

// `fixed_center`: express H and b about this point instead of the matched centroid (a joint
// stage's coarser depth uses the finest depth's, so that the two systems add).
// `with_system` false: correspondences, weights, cost and statistics only; AddSystem completes it.
Linearization Linearize(const Octree& source, const Octree& target, DepthData& data,
                        const Eigen::Matrix3d& R, const Eigen::Vector3d& t,
                        const TreeRefinementOptions& options, std::vector<Correspondence>& corr,
                        const Eigen::Vector3d* fixed_center = nullptr, bool with_system = true) {
  Linearization lin;
  corr.clear();
  const double max_d = options.max_correspondence_distance_cells * data.edge_target;
  const double max_d2 = max_d * max_d;
  const Octree::Level& t_level = target.level(data.depth);
  const Octree::Level& s_level = source.level(data.depth);
  double prior_sum = 0.0;
  const SourceDepth& sd = *data.source;
  const TargetDepth& td = *data.target;
  // The target's regularised covariance, iso * I - flat * n n^T, from its shape (as Regularize).
  const double target_iso = data.edge_target * data.edge_target;
  const double target_flat = target_iso * (1.0 - options.covariance_epsilon);
  NodeShape scratch_shape;
  AncestorPlanes ancestors;
  for (size_t k = 0; k < sd.nodes.size(); ++k) {
    lin.used_count += s_level.count[sd.nodes[k]];
    const Eigen::Vector3d q = R * sd.mean[k] + t;
    const int32_t j = FindPartner(target, data, k, q, max_d2);
    if (j < 0) continue;
    Correspondence& c = corr.emplace_back();
    c.k = static_cast<int32_t>(k);
    c.j = j;
    c.moved = q;
    c.target_mean = t_level.center_of_mass[j].cast<double>();
    c.weight = sd.prior[k];
    if (options.weights == WeightScheme::kInverseDensity) c.weight *= t_level.inverse_density[j];
    prior_sum += c.weight;
  }
  lin.correspondences = static_cast<int>(corr.size());
  const double c2 =
      options.robust_scale_cells * options.robust_scale_cells / (2.0 * options.covariance_epsilon);
  const double mean_target_density = 1.0 / static_cast<double>(std::max<size_t>(t_level.size(), 1));
  // A source node's cost weight when unmatched: its prior times the target's mean density factor.
  auto unmatched_weight = [&](double prior) {
    return options.weights == WeightScheme::kInverseDensity ? prior * mean_target_density : prior;
  };
  for (double prior : sd.prior) {
    lin.cost += unmatched_weight(prior) * c2;  // matched nodes replace their share below
  }
  if (corr.empty() || !(prior_sum > 0.0)) return lin;

  // Prior weights rescaled to average 1, so H reads as "one measurement per correspondence".
  const double prior_scale = static_cast<double>(corr.size()) / prior_sum;
  const double inlier_distance = options.inlier_distance_cells * data.edge_target;
  double weight_sum = 0.0;
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  for (Correspondence& c : corr) {
    const NodeShape& tn = td.Shape(target, c.j, scratch_shape, ancestors);
    const RegularizedNode& sn = sd.Regularized(static_cast<size_t>(c.k));
    const Eigen::Vector3d m = R * sn.normal;  // the source's normal in the target frame
    Eigen::Matrix3d combined = (target_iso + sn.iso) * Eigen::Matrix3d::Identity();
    if (tn.planar) combined.noalias() -= target_flat * tn.normal * tn.normal.transpose();
    combined.noalias() -= sn.flat * m * m.transpose();
    c.information = combined.inverse();
    const Eigen::Vector3d r = c.target_mean - c.moved;
    const double e2 = r.dot(c.information * r);
    const double g = c2 / (c2 + e2);
    lin.cost += c.weight * c2 * e2 / (c2 + e2) - unmatched_weight(sd.prior[c.k]) * c2;
    c.robust = g * g;
    lin.robust_sum += c.robust;
    c.weight *= prior_scale * c.robust;
    weight_sum += c.weight;
    centroid += c.weight * c.target_mean;
    const double dist = tn.planar ? std::abs(tn.normal.dot(r)) : r.norm();
    if (dist <= inlier_distance) {
      const double count = s_level.count[sd.nodes[c.k]];
      lin.inlier_count += count;
      lin.inlier_sq_sum += count * dist * dist;
      ++lin.inlier_nodes;
    }
  }
  lin.weight_sum = weight_sum;
  if (!(weight_sum > 0.0)) return lin;
  lin.center = fixed_center != nullptr ? *fixed_center : centroid / weight_sum;
  if (with_system) AddSystem(corr, lin);
  return lin;
}

constexpr std::array<const char*, 6> kAxisNames = {"rotation about x",    "rotation about y",
                                                   "rotation about z",    "translation along x",
                                                   "translation along y", "translation along z"};

}  // namespace

Matrix6d InformationInMetres(const TreeRefinementResult& result) {
  Vector6d s = Vector6d::Ones();
  for (int a = 0; a < 3; ++a) s[a] = 1.0 / result.rotation_lever_arms[a];
  return s.asDiagonal() * result.information * s.asDiagonal();
}

Vector6d MotionInMetres(const TreeRefinementResult& result, const Eigen::Isometry3d& motion) {
  const Eigen::Vector3d& c = result.information_center;
  const Eigen::AngleAxisd turn(motion.linear());
  const Eigen::Vector3d w = turn.angle() * turn.axis();
  const Eigen::Vector3d v = motion.translation() - c + motion.linear() * c;
  Vector6d u;
  u << w.cwiseProduct(result.rotation_lever_arms), v;
  return u;
}

Eigen::Isometry3d MotionFromMetres(const TreeRefinementResult& result, const Vector6d& u) {
  const Eigen::Vector3d w = u.head<3>().cwiseQuotient(result.rotation_lever_arms);
  const Eigen::Vector3d& c = result.information_center;
  Eigen::Isometry3d motion = Eigen::Isometry3d::Identity();
  const double angle = w.norm();
  if (angle > 0.0) motion.linear() = Eigen::AngleAxisd(angle, w / angle).toRotationMatrix();
  motion.translation() = c - motion.linear() * c + u.tail<3>();
  return motion;
}

namespace {

void AnalyseDegeneracy(const Linearization& lin, const TreeRefinementOptions& options,
                       TreeRefinementResult& result) {
  // A joint finest stage's estimate minimises both depths' cost: its information is their sum.
  result.information = lin.H + lin.coarser_H;
  result.information_center = lin.center;
  // A rotation w about axis a moves the matched points by w times their RMS lever arm about a,
  // sqrt(trace(spread) - spread_aa): dividing the rotation rows and columns by it turns every
  // direction into a displacement in metres, so the six eigenvalues are comparable.
  for (int a = 0; a < 3; ++a) {
    result.rotation_lever_arms[a] =
        std::sqrt(std::max(lin.spread.trace() - lin.spread(a, a), 1e-24));
  }
  Eigen::SelfAdjointEigenSolver<Matrix6d> solver(InformationInMetres(result));
  const Vector6d values = solver.eigenvalues();
  const double largest = std::max(values.maxCoeff(), 1e-300);
  result.normalized_eigenvalues = values / largest;
  std::vector<int> degenerate;
  for (int i = 0; i < 6; ++i) {
    if (result.normalized_eigenvalues[i] < options.degeneracy_threshold) degenerate.push_back(i);
  }
  result.num_degenerate = static_cast<int>(degenerate.size());
  result.degenerate_directions.resize(6, result.num_degenerate);
  for (int c = 0; c < result.num_degenerate; ++c) {
    result.degenerate_directions.col(c) = solver.eigenvectors().col(degenerate[c]);
  }
  for (int axis = 0; axis < 6; ++axis) {
    double share = 0.0;
    for (int c = 0; c < result.num_degenerate; ++c) {
      share += result.degenerate_directions(axis, c) * result.degenerate_directions(axis, c);
    }
    result.degenerate_axes[axis] = share > 0.5;
  }
}

absl::Status ValidateInputs(const Octree& source, const Octree& target,
                            const Eigen::Isometry3d& initial, const TreeRefinementOptions& o) {
  if (source.max_depth() < 0 || target.max_depth() < 0 || source.num_points() == 0 ||
      target.num_points() == 0) {
    return absl::InvalidArgumentError("RefineOnTrees: a tree is empty (no levels or no points)");
  }
  if (!initial.matrix().allFinite()) {
    return absl::InvalidArgumentError("RefineOnTrees: the initial transform is not finite");
  }
  const Eigen::Matrix3d r = initial.linear();
  if (!(r.transpose() * r).isApprox(Eigen::Matrix3d::Identity(), 1e-6) ||
      std::abs(r.determinant() - 1.0) > 1e-6) {
    return absl::InvalidArgumentError(
        "RefineOnTrees: the initial transform's 3x3 block is not a rotation");
  }
  if (o.max_iterations_per_depth <= 0 || o.max_source_nodes_per_depth <= 0 ||
      o.max_rebin_rounds <= 0 || o.min_count_for_covariance < 0) {
    return absl::InvalidArgumentError(absl::StrCat(
        "RefineOnTrees: max_iterations_per_depth (", o.max_iterations_per_depth,
        "), max_source_nodes_per_depth (", o.max_source_nodes_per_depth, ") and max_rebin_rounds (",
        o.max_rebin_rounds, ") must be positive, min_count_for_covariance non-negative"));
  }
  if (!(o.rotation_epsilon_rad > 0) || !(o.translation_epsilon_cells > 0) ||
      !(o.max_correspondence_distance_cells > 0) ||
      !(o.coarse_max_correspondence_distance_cells > 0) || !(o.covariance_epsilon > 0) ||
      !(o.covariance_epsilon <= 1) || !(o.coarse_covariance_epsilon > 0) ||
      !(o.coarse_covariance_epsilon <= 1) || !(o.robust_scale_cells > 0) ||
      !(o.inlier_distance_cells > 0) || !(o.fitness_min_mean_count >= 0) || !(o.damping >= 0) ||
      !(o.coarse_epsilon_factor >= 1) || !(o.degeneracy_threshold >= 0) || !(o.min_fitness >= 0) ||
      !(o.settled_step_cells >= 0)) {
    return absl::InvalidArgumentError(
        "RefineOnTrees: epsilons, distances and scales must be positive (covariance_epsilon and "
        "coarse_covariance_epsilon in (0, 1]); damping, degeneracy_threshold, min_fitness and "
        "settled_step_cells non-negative");
  }
  return absl::OkStatus();
}

std::string DegeneracyReason(const TreeRefinementResult& result) {
  std::vector<std::string> axes;
  for (int a = 0; a < 6; ++a) {
    if (result.degenerate_axes[a]) axes.push_back(kAxisNames[a]);
  }
  return absl::StrCat("degenerate geometry: ", result.num_degenerate,
                      " unconstrained direction(s) (normalised information eigenvalue below the "
                      "threshold)",
                      axes.empty() ? std::string(", mixing several axes")
                                   : absl::StrCat("; mostly ", absl::StrJoin(axes, ", ")));
}

// A coarse stage's source cells re-binned on the target's grid: the source's `from_depth` nodes,
// moved by (R, t) into the target frame, weighted by their counts and binned to `to_depth` in the
// target's cube. The result lives in the TARGET frame. (Why: two independently placed grids cut
// a surface into different patches, so the source's own coarse CoMs are not the target's even at
// the true pose, and a coarse stage fitted to them drifts along weakly constrained directions
// (the hinge of a laptop, the axis of a spring) by up to a cell, which the finer stages, seeing
// only a cell around each node, cannot undo. Binned on the same grid, the true pose makes the two
// trees' cells hold the same part of the surface: Eq. 2's cost is then minimal at the truth,
// which is what the network's passes do too when they re-encode the moved source.)
absl::StatusOr<Octree> RebinOnTargetCells(const Octree& source, int from_depth, int to_depth,
                                          const Eigen::Matrix3d& R, const Eigen::Vector3d& t,
                                          const Octree& target) {
  const Octree::Level& fine = source.level(from_depth);
  const Octree::VectorD& c = target.center();
  const double r = target.half_length();
  std::vector<Eigen::Vector3f> moved;
  std::vector<uint32_t> counts;
  std::vector<Octree::PackedSymmetric> spreads;
  moved.reserve(fine.size());
  counts.reserve(fine.size());
  spreads.reserve(fine.size());
  for (size_t i = 0; i < fine.size(); ++i) {
    const Eigen::Vector3d q = R * fine.center_of_mass[i].cast<double>() + t;
    // Outside the target's cube nothing corresponds; clamped into its border cells, these nodes
    // would pull the border CoMs away from the target's.
    if ((q - c).cwiseAbs().maxCoeff() > r) continue;
    moved.push_back(q.cast<float>());
    counts.push_back(fine.count[i]);
    // The node's own spread, turned into the target frame (the cell's shape is what the
    // refinement's plane-to-plane residuals read; CoMs alone would leave a cell of a few
    // children without a reliable normal).
    const Eigen::Matrix3d C =
        R * source.Covariance(from_depth, static_cast<int>(i)).cast<double>() * R.transpose();
    spreads.push_back(
        Octree::PackedSymmetric(C(0, 0), C(0, 1), C(0, 2), C(1, 1), C(1, 2), C(2, 2)));
  }
  if (moved.empty()) {
    return absl::InvalidArgumentError("no source node inside the target's cube");
  }
  BarnesHutTreeOptions options;
  options.max_depth = to_depth;
  options.neighbor_max_depth = -1;
  options.cube_center = {c[0], c[1], c[2]};
  options.cube_half_length = r;
  return BuildWeightedBarnesHutTree<3>(moved, counts, spreads, options);
}

// A re-binned stage that moved the source by more than this many cells is re-binned at its new
// pose and run again (its cells no longer coincide with the target's).
constexpr double kRebinAgainCells = 0.25;
// A re-binned depth d is built from the source's nodes at depth min(finest, d + this).
constexpr int kRebinFromDepthsBelow = 3;

// The options of a coarse stage on re-binned cells: the coarse covariance epsilon, weights and
// correspondence search.
TreeRefinementOptions RebinnedStageOptions(const TreeRefinementOptions& options) {
  TreeRefinementOptions out = options;
  out.covariance_epsilon = options.coarse_covariance_epsilon;
  out.weights = options.coarse_weights;
  out.search_27_neighbors = options.coarse_search_27_neighbors;
  out.max_correspondence_distance_cells = options.coarse_max_correspondence_distance_cells;
  return out;
}

// The options of the joint finest stage's coarser depth: re-binned cells (the coarse covariance
// epsilon) weighed by joint_coarser_weights, searched as the finest depth is (it polishes within
// a cell).
TreeRefinementOptions JointCoarserDepthOptions(const TreeRefinementOptions& options) {
  TreeRefinementOptions out = options;
  out.covariance_epsilon = options.coarse_covariance_epsilon;
  out.weights = options.joint_coarser_weights;
  return out;
}

// The coarser depth of a joint finest stage: the source re-binned on the target's cells of
// depth finest - 1 at the stage's starting pose (R0, t0), so a pose (R, t) moves those cells by
// (R R0^T, t - R R0^T t0). Filled in place (`data` points at `side`).
struct CoarserDepth {
  Octree cells;  // the re-binned source
  SourceDepth side;
  DepthData data;
  TreeRefinementOptions options;  // JointCoarserDepthOptions
  Eigen::Matrix3d R0 = Eigen::Matrix3d::Identity();
  Eigen::Vector3d t0 = Eigen::Vector3d::Zero();
  std::vector<Correspondence> corr;
};

// The finest depth's linearisation at (R, t), with the coarser depth's share added when the stage
// is joint. `with_system` false: costs and correspondences only (CompleteStageSystem adds H and b
// while `corr` and the coarser depth's correspondences are still this linearisation's).
Linearization LinearizeStage(const Octree& source, const Octree& target, DepthData& data,
                             const Eigen::Matrix3d& R, const Eigen::Vector3d& t,
                             const TreeRefinementOptions& options,
                             std::vector<Correspondence>& corr, CoarserDepth* coarser,
                             bool with_system = true) {
  Linearization lin = Linearize(source, target, data, R, t, options, corr, nullptr, with_system);
  if (coarser == nullptr || lin.correspondences == 0) return lin;
  const Eigen::Matrix3d dR = R * coarser->R0.transpose();
  const Eigen::Vector3d dt = t - dR * coarser->t0;
  const Linearization c = Linearize(coarser->cells, target, coarser->data, dR, dt, coarser->options,
                                    coarser->corr, &lin.center, with_system);
  lin.coarser_H = c.H;
  lin.coarser_b = c.b;
  lin.coarser_cost = c.cost;
  lin.coarser_correspondences = c.correspondences;
  lin.coarser_weight_sum = c.weight_sum;
  return lin;
}

// Adds H and b to a linearisation made without them (LinearizeStage's with_system false), from
// the correspondences it left.
void CompleteStageSystem(const std::vector<Correspondence>& corr, CoarserDepth* coarser,
                         Linearization& lin) {
  AddSystem(corr, lin);
  if (coarser == nullptr || lin.correspondences == 0) return;
  Linearization c;
  c.center = lin.center;
  c.weight_sum = lin.coarser_weight_sum;
  AddSystem(coarser->corr, c);
  lin.coarser_H = c.H;
  lin.coarser_b = c.b;
}

// Step control's damping (relative to H's mean diagonal, rotations as displacements: RunStage)
// after a first refused step. Against the tenfold ladder from 1e-6 (unseen study, KITTI-style K2
// refine, registrar_bench), 1e-2 kept the mean recall (0.7595) and K2 RMSE at objects refine
// 5.1 -> 4.6 ms, scans 14.0 -> 12.1 ms. Since the rotation is damped as a displacement (before, a
// scan's translation was damped ~200 times harder than its rotation, an object's about as hard),
// scans refused more steps at 1e-2 (registrar_bench's 120k-point refine 12.2 -> 15.6 ms); from 1:
// 14.4 ms there (tests/bench/results/registrar_bench_damping_scale.txt), KITTI-style K1 refine
// 9.1 ms against the old binary's 9.2 (`rpsr eval --manifest ... --mode refine`, alternated),
// objects' mean recall over ten settings 0.733 -> 0.734 (four settings moved by one or two pairs),
// K1 / K2 refine RMSE 0.167 deg / 0.030 m and 0.097 / 0.0082.
constexpr double kFirstRefusedDamping = 1.0;

struct StageOutcome {
  Linearization lin;      // at the last iterate (the final transform at the finest depth)
  bool singular = false;  // the normal equations had no solution
};

// Gauss-Newton iterations of one depth from (R, t), updated in place. At the finest depth with
// step_control, Levenberg-Marquardt: a step that raises the robust cost (Linearization::cost) is
// taken back and the damping raised tenfold, an accepted one lowers it again (there the plain
// iteration oscillated between two correspondence sets and stopped wherever the budget ran out).
// The returned linearisation is at the final transform: it feeds the information matrix, fitness
// and RMSE.
// `coarser` (joint finest stage, else null): its share enters every step and cost comparison.
StageOutcome RunStage(const Octree& source, const Octree& target, DepthData& data, bool is_finest,
                      const TreeRefinementOptions& options, std::vector<Correspondence>& corr,
                      Eigen::Matrix3d& R, Eigen::Vector3d& t, DepthStage& stage,
                      TreeRefinementResult& result, CoarserDepth* coarser = nullptr) {
  StageOutcome outcome;
  // A coarser depth only has to hand the next one an error well inside a cell: looser test.
  const double loosen = is_finest ? 1.0 : options.coarse_epsilon_factor;
  const double rotation_epsilon = loosen * options.rotation_epsilon_rad;
  const double translation_epsilon = loosen * options.translation_epsilon_cells * data.edge_target;
  Linearization& lin = outcome.lin;
  lin = LinearizeStage(source, target, data, R, t, options, corr, coarser);
  stage.correspondences = lin.correspondences;
  stage.coarser_correspondences = lin.coarser_correspondences;
  if (options.evaluate_only) return outcome;
  double damping = options.damping;
  for (int iteration = 0; iteration < options.max_iterations_per_depth; ++iteration) {
    if (lin.correspondences < options.min_correspondences) break;
    Matrix6d H = lin.H + lin.coarser_H;
    // The damping is relative to H's mean diagonal with the rotation rows and columns taken as
    // the displacement they cause, rotation * L, L^2 the mean over axes of the matched points'
    // squared lever arm (AnalyseDegeneracy's scaling): H's rotation block grows with the clouds'
    // size squared while its translation block does not, so a mean over the raw diagonal damped
    // the rotation of small clouds to a standstill and the translation of large ones (the same
    // object pairs scaled by 1/1024, refined from the identity: median error 0.11 -> 0.86 degree;
    // RegistrarUnitsTest). Measured against the raw mean (old and new binaries, same pairs):
    // unseen objects, ten settings, mean recall 0.733 -> 0.734; KITTI-style K1 / K2
    // refine within 0.002 degree and 0.0005 m; `rpsr odometry` translation error on the twelve
    // simulated drives (with kFirstRefusedDamping below) lower in seven (HDL-64E parking 1.29 ->
    // 1.19%, open road 3.71 -> 3.63%), within 0.015 point in four, and VLP-16 parking 1.88 ->
    // 1.99%.
    const double arm2 = 2.0 / 3.0 * lin.spread.trace();
    const double l2 = arm2 > 0.0 ? arm2 : target.half_length() * target.half_length();
    const double mean_diag =
        (H.diagonal().head<3>().sum() / l2 + H.diagonal().tail<3>().sum()) / 6.0;
    H.diagonal().head<3>().array() += damping * mean_diag * l2;
    H.diagonal().tail<3>().array() += damping * mean_diag;
    const Vector6d delta = H.ldlt().solve(-(lin.b + lin.coarser_b));
    if (!delta.allFinite() || !(mean_diag > 0)) {
      outcome.singular = true;
      return outcome;
    }
    const Eigen::Vector3d w = delta.head<3>();
    const Eigen::Vector3d v = delta.tail<3>();
    const double angle = w.norm();
    const Eigen::Matrix3d dR = angle > 0 ? Eigen::AngleAxisd(angle, w / angle).toRotationMatrix()
                                         : Eigen::Matrix3d::Identity();
    // Re-orthonormalise so that many small updates never drift off SO(3).
    const Eigen::Matrix3d next_R = Eigen::Quaterniond(dR * R).normalized().toRotationMatrix();
    const Eigen::Vector3d next_t = lin.center + dR * (t - lin.center) + v;
    ++stage.iterations;
    ++result.iterations;
    const bool small = angle < rotation_epsilon && v.norm() < translation_epsilon;
    const auto take_step = [&] {
      R = next_R;
      t = next_t;
      stage.last_update_rotation_rad = angle;
      stage.last_update_translation = v.norm();
    };
    if (small && !is_finest) {
      // A coarse stage takes every step, and this one ends it: linearising at its pose only to
      // stop would be wasted (a coarse stage's system and statistics are not read beyond the
      // overlap check, which the last linearisation, a small step away, answers as well). On
      // scans that was about one linearisation in two of depths 6-8 (session 24).
      take_step();
      stage.converged = true;
      break;
    }
    // A step the step control may refuse is judged by its cost alone; its system is assembled
    // only once it is accepted.
    const bool controlled = options.step_control && is_finest;
    Linearization next = LinearizeStage(source, target, data, next_R, next_t, options, corr,
                                        coarser, /*with_system=*/!controlled);
    if (controlled && (next.step_cost() > lin.step_cost() ||
                       next.correspondences < options.min_correspondences)) {
      // Uphill (or losing the overlap): stay, damp harder. A step this small that still climbs
      // means the minimum is here. The first refused step jumps to kFirstRefusedDamping: below
      // it the damped step was the refused one again (82% of an object's finest iterations were
      // refusals climbing 1e-5, 1e-4, ... each a linearisation of both depths).
      damping = std::max(damping * 10.0, kFirstRefusedDamping);
      const double shift = std::sqrt(v.squaredNorm() + angle * angle * l2);
      const bool settled = shift < options.settled_step_cells * data.edge_target;
      if (small || settled || damping > 1e4) {
        stage.converged = true;
        break;
      }
      continue;
    }
    take_step();
    if (controlled) CompleteStageSystem(corr, coarser, next);
    lin = std::move(next);
    stage.correspondences = lin.correspondences;
    stage.coarser_correspondences = lin.coarser_correspondences;
    damping = std::max(damping * 0.1, options.damping);
    if (small) {
      stage.converged = true;
      break;
    }
  }
  return outcome;
}

}  // namespace

std::pair<int, int> StageDepths(const Octree& source, const Octree& target,
                                const TreeRefinementOptions& options) {
  const int deepest = std::min(source.max_depth(), target.max_depth());
  const int finest = options.finest_depth < 0 ? deepest : options.finest_depth;
  const int coarsest = options.coarsest_depth < 0 ? std::min(finest, 3) : options.coarsest_depth;
  return {coarsest, finest};
}

absl::Status ValidateTreeRefinement(const Octree& source, const Octree& target,
                                    const Eigen::Isometry3d& initial_T_target_source,
                                    const TreeRefinementOptions& options) {
  if (absl::Status status = ValidateInputs(source, target, initial_T_target_source, options);
      !status.ok()) {
    return status;
  }
  const auto [coarsest, finest] = StageDepths(source, target, options);
  const int deepest = std::min(source.max_depth(), target.max_depth());
  if (finest > deepest || coarsest < 0 || coarsest > finest) {
    return absl::InvalidArgumentError(absl::StrCat(
        "RefineOnTrees: depths ", coarsest, "..", finest, " do not fit the trees (deepest shared ",
        "depth ", deepest, "; need 0 <= coarsest <= finest)"));
  }
  return absl::OkStatus();
}

absl::StatusOr<TreeRefinementResult> RefineOnTrees(const Octree& source, const Octree& target,
                                                   const Eigen::Isometry3d& initial_T_target_source,
                                                   const TreeRefinementOptions& options) {
  TreeRefinementCache cache;
  return RefineOnTrees(source, target, initial_T_target_source, options, cache);
}

namespace {

// The coarse-to-fine stages and the measurements at their end (everything but the noise polish);
// the inputs are validated and `shared` bound to the trees.
TreeRefinementResult RefineStages(const Octree& source, const Octree& target,
                                  const Eigen::Isometry3d& initial_T_target_source,
                                  const TreeRefinementOptions& requested,
                                  TreeRefinementCache::Impl& shared) {
  const auto start = std::chrono::steady_clock::now();
  const auto [coarsest, finest] = StageDepths(source, target, requested);
  TreeRefinementOptions options = requested;
  options.line_normals_from_planes = shared.LineNormalsFromPlanes(requested);

  TreeRefinementResult result;
  result.line_normals_from_planes = *options.line_normals_from_planes;
  result.T_target_source = initial_T_target_source;
  Eigen::Matrix3d R = initial_T_target_source.linear();
  Eigen::Vector3d t = initial_T_target_source.translation();
  std::vector<Correspondence> corr;
  bool all_converged = true;
  Linearization final_lin;
  // Measuring only visits the finest depth (and the fitness depth below).
  for (int depth = options.evaluate_only ? finest : coarsest; depth <= finest; ++depth) {
    const bool is_finest = depth == finest;
    const bool rebin = !is_finest && options.rebin_coarse_depths;
    const int rounds = rebin ? options.max_rebin_rounds : 1;
    for (int round = 0; round < rounds; ++round) {
      const auto stage_start = std::chrono::steady_clock::now();
      DepthStage stage;
      stage.depth = depth;
      // A re-binned stage refines the motion of the source as already moved (from the identity)
      // and composes it onto (R, t) afterwards.
      std::optional<Octree> rebinned;
      if (rebin) {
        // From nodes 8^3 times finer than the cells (or the finest): plenty to place each cell's
        // CoM and shape, and a 120k-point scan's depth 3 re-bins ~700 depth-6 nodes, not ~12k
        // depth-9 ones (its depths 6-8 still read depth 9).
        const int from_depth = std::min(finest, depth + kRebinFromDepthsBelow);
        absl::StatusOr<Octree> cells = RebinOnTargetCells(source, from_depth, depth, R, t, target);
        if (!cells.ok()) {
          // Nothing of the source inside the target's cube: no overlap at this pose.
          result.T_target_source = MakeIsometry(R, t);
          result.failure_reason =
              absl::StrCat("no overlap: the source lies outside the target's cube at depth ", depth,
                           " under the current transform");
          result.total_seconds = SecondsSince(start);
          return result;
        }
        rebinned = *std::move(cells);
      }
      const Octree& stage_source = rebin ? *rebinned : source;
      Eigen::Matrix3d stage_R = rebin ? Eigen::Matrix3d::Identity() : R;
      Eigen::Vector3d stage_t = rebin ? Eigen::Vector3d::Zero() : t;
      const TreeRefinementOptions stage_options = rebin ? RebinnedStageOptions(options) : options;
      // Re-binned cells are new at every round; the source's own cells and the target's side
      // come from the cache (shared with the other rounds and starts).
      std::optional<SourceDepth> rebinned_side;
      if (rebin) PrepareSourceDepth(*rebinned, depth, stage_options, rebinned_side.emplace());
      const TargetSideRef target_side = shared.Target(depth, stage_options);
      stage.target_side_prepared = target_side.prepared;
      DepthData data = MakeDepthData(rebin ? *rebinned_side : shared.Source(depth, stage_options),
                                     target_side, stage_options);
      stage.cell_edge = data.edge_target;
      stage.source_nodes = static_cast<int>(data.source->nodes.size());
      stage.prepare_seconds = SecondsSince(stage_start);
      // The joint finest stage's coarser depth (TreeRefinementOptions::joint_finest_stage): the
      // source re-binned on the target's cells of depth finest - 1 at the pose this stage starts
      // from. (Reusing the cells of that depth's last round instead, re-binned where the round
      // started, saved 0.1 ms an object but lost: unseen study mean recall 0.760 -> 0.756, clean
      // rotation RMSE 1.65 -> 4.05 deg.)
      std::optional<CoarserDepth> coarser;
      // (Measuring only, evaluate_only, builds it too: the information is reported as a
      // refinement ending at that pose would report it.)
      if (is_finest && options.joint_finest_stage && options.rebin_coarse_depths &&
          depth > coarsest) {
        absl::StatusOr<Octree> cells = RebinOnTargetCells(source, depth, depth - 1, R, t, target);
        if (cells.ok()) {  // else nothing of the source is inside the target's cube: finest alone
          CoarserDepth& c = coarser.emplace();
          c.cells = *std::move(cells);
          c.options = JointCoarserDepthOptions(options);
          PrepareSourceDepth(c.cells, depth - 1, c.options, c.side);
          c.data = MakeDepthData(c.side, shared.Target(depth - 1, c.options), c.options);
          c.R0 = R;
          c.t0 = t;
          stage.joint = true;
        }
      }
      const StageOutcome outcome =
          RunStage(stage_source, target, data, is_finest, stage_options, corr, stage_R, stage_t,
                   stage, result, coarser ? &*coarser : nullptr);
      if (rebin) {
        R = stage_R * R;
        t = stage_R * t + stage_t;
        R = Eigen::Quaterniond(R).normalized().toRotationMatrix();
      } else {
        R = stage_R;
        t = stage_t;
      }
      stage.seconds = SecondsSince(stage_start);
      if (round == 0) {
        result.stages.push_back(stage);
      } else {  // one entry per depth: the rounds add up, the last one's state stands
        DepthStage& merged = result.stages.back();
        stage.rounds = merged.rounds + 1;
        stage.iterations += merged.iterations;
        stage.seconds += merged.seconds;
        stage.prepare_seconds += merged.prepare_seconds;
        merged = stage;
      }
      if (outcome.singular) {
        result.T_target_source = MakeIsometry(R, t);
        result.failure_reason =
            absl::StrCat("singular normal equations at depth ", depth, " (no constraint at all)");
        result.total_seconds = SecondsSince(start);
        return result;
      }
      const Linearization& lin = outcome.lin;
      if (lin.correspondences < options.min_correspondences) {
        result.T_target_source = MakeIsometry(R, t);
        // Too few correspondences because a cloud has too few cells to give them (a handful of
        // points, all points on one spot or one line) is not a question of overlap: say which.
        const size_t source_cells = source.level(depth).size();
        const size_t target_cells = target.level(depth).size();
        const size_t fewest = std::min(source_cells, target_cells);
        if (fewest < static_cast<size_t>(options.min_correspondences)) {
          result.failure_reason = absl::StrCat(
              "too little geometry: the ", source_cells <= target_cells ? "source" : "target",
              "'s points fill ", fewest, " cell(s) at depth ", depth, " (need ",
              options.min_correspondences,
              "): too few distinct points, or all on one spot or line; register clouds that "
              "sample a surface");
        } else {
          result.failure_reason =
              absl::StrCat("no overlap: ", lin.correspondences, " correspondence(s) at depth ",
                           depth, " (need ", options.min_correspondences,
                           "); the clouds do not overlap under the current transform");
        }
        result.total_seconds = SecondsSince(start);
        return result;
      }
      final_lin = lin;
      // Another round on cells re-binned at the new pose only when this one moved the source by
      // a sizeable part of a cell (its cells no longer coincide with the target's): its turn at
      // the cube's half-length, or its shift of the cube's centre (not stage_t itself, which
      // grows with the clouds' distance from their frame's origin).
      const Eigen::Vector3d centre = target.center();
      const double moved = std::max(Eigen::AngleAxisd(stage_R).angle() * target.half_length(),
                                    (stage_R * centre + stage_t - centre).norm());
      const bool last_round = round + 1 == rounds || moved < kRebinAgainCells * data.edge_target;
      if (last_round) {
        all_converged = all_converged && stage.converged && !options.evaluate_only;
        break;
      }
    }
  }

  result.T_target_source = MakeIsometry(R, t);
  result.converged = all_converged;
  AnalyseDegeneracy(final_lin, options, result);  // the finest depth's information
  result.finest_fitness = FitnessOf(final_lin);
  result.finest_inlier_rmse = InlierRmseOf(final_lin);
  // Fitness is measured where the source's cells hold surface patches rather than single
  // samples: at depths finer than the sampling, a node's partner is often more than a cell away
  // although the surfaces coincide, and the fraction would read as partial overlap.
  int fitness_depth = finest;
  while (fitness_depth > coarsest &&
         static_cast<double>(source.num_points()) <
             options.fitness_min_mean_count *
                 static_cast<double>(source.level(fitness_depth).size())) {
    --fitness_depth;
  }
  result.fitness_depth = fitness_depth;
  if (fitness_depth != finest) {
    DepthData data = MakeDepthData(shared.Source(fitness_depth, options),
                                   shared.Target(fitness_depth, options), options);
    final_lin = Linearize(source, target, data, R, t, options, corr);
  }
  result.inliers = final_lin.inlier_nodes;
  result.fitness = FitnessOf(final_lin);
  result.inlier_rmse = InlierRmseOf(final_lin);
  result.mean_robust_weight =
      final_lin.correspondences > 0 ? final_lin.robust_sum / final_lin.correspondences : 0.0;
  if (result.fitness < options.min_fitness) {
    result.failure_reason =
        absl::StrCat("fitness ", result.fitness, " below min_fitness ", options.min_fitness,
                     ": too little of the source overlaps");
  } else if (result.num_degenerate > 0) {
    result.failure_reason = DegeneracyReason(result);
  } else {
    result.valid = true;
  }
  result.total_seconds = SecondsSince(start);
  return result;
}

// A target level for the noise polish: its cell index from the cache, and per node the normal of
// its ancestor `normal_depth` (the refinement's shapes there: one eigen-decomposition per ancestor,
// shared with the stages and the registrar's other starts); no plane where that shape has none.
PlaneLevel PlaneLevelOf(const Octree& target, int depth, int normal_depth,
                        const TreeRefinementOptions& options, TreeRefinementCache::Impl& shared,
                        NodeShape& scratch, AncestorPlanes& ancestors) {
  PlaneLevel level;
  level.tree = &target;
  level.depth = depth;
  level.index = &shared.Target(depth, options).side->index;
  const TargetDepth* normals = shared.Target(normal_depth, options).side;
  level.normal = [&target, depth, normal_depth, normals, &scratch,
                  &ancestors](int node) -> const Eigen::Vector3d* {
    for (int d = depth; d > normal_depth; --d) node = target.level(d).parent[node];
    const NodeShape& shape = normals->Shape(target, node, scratch, ancestors);
    return shape.planar ? &shape.normal : nullptr;
  };
  return level;
}

// Scatter measurements read this many of the source's finest nodes at most (an even stride), and
// the target's normals this many depths above the finest (the refinement's shapes there).
constexpr size_t kScatterMaxNodes = 512;
constexpr int kScatterNormalDepthsUp = 2;

// The noise polish (TreeRefinementOptions::noise_polish) after the stages ended at
// result.T_target_source: measures the scatter and, at or above the threshold, polishes and
// measures the result again at the polished pose.
TreeRefinementResult NoisePolish(const Octree& source, const Octree& target,
                                 const TreeRefinementOptions& options,
                                 TreeRefinementCache::Impl& shared, TreeRefinementResult result) {
  const auto start = std::chrono::steady_clock::now();
  const auto [coarsest, finest] = StageDepths(source, target, options);
  const int depth = finest - 1;
  if (depth < coarsest || finest - kScatterNormalDepthsUp < 0) return result;
  TreeRefinementOptions shapes = options;  // the shape rule the stages ran with
  shapes.line_normals_from_planes = result.line_normals_from_planes;
  NodeShape scratch;
  AncestorPlanes ancestors;
  const PlaneLevel finest_planes = PlaneLevelOf(target, finest, finest - kScatterNormalDepthsUp,
                                                shapes, shared, scratch, ancestors);
  result.surface_scatter_cells = MedianSurfaceScatterCells(
      source, finest, finest_planes, result.T_target_source, kScatterMaxNodes);
  if (result.surface_scatter_cells < options.noise_polish_min_scatter_cells ||
      result.fitness < options.noise_polish_min_fitness) {
    return result;
  }
  // Both sides smoothed by the same kernel (PolishSides), shared by the pair's starts.
  PolishSides& sides = shared.PolishSidesAt(depth);
  const PlanePolishResult polished = PolishPointToPlane(sides, result.T_target_source);
  if (polished.iterations == 0) return result;
  DepthStage stage;
  stage.depth = depth;
  stage.cell_edge = CellEdge(target, depth);
  stage.source_nodes = static_cast<int>(sides.source.points.size());
  stage.correspondences = polished.correspondences;
  stage.iterations = polished.iterations;
  stage.converged = polished.converged;
  stage.last_update_rotation_rad = polished.last_update_rotation_rad;
  stage.last_update_translation = polished.last_update_translation;
  stage.noise_polish = true;
  // Everything the result reports about the pose, measured again where the polish left it (as a
  // refinement ending there would report it); what the run did stays the run's.
  TreeRefinementOptions measure = shapes;
  measure.evaluate_only = true;
  TreeRefinementResult measured =
      RefineStages(source, target, polished.T_target_source, measure, shared);
  measured.T_target_source = polished.T_target_source;
  measured.converged = result.converged && polished.converged;
  measured.iterations = result.iterations + polished.iterations;
  measured.stages = std::move(result.stages);
  stage.seconds = SecondsSince(start);
  measured.stages.push_back(stage);
  measured.total_seconds = result.total_seconds + stage.seconds;
  measured.surface_scatter_cells = result.surface_scatter_cells;
  measured.noise_polished = true;
  return measured;
}

}  // namespace

absl::StatusOr<TreeRefinementResult> RefineOnTrees(const Octree& source, const Octree& target,
                                                   const Eigen::Isometry3d& initial_T_target_source,
                                                   const TreeRefinementOptions& requested,
                                                   TreeRefinementCache& cache) {
  if (absl::Status status =
          ValidateTreeRefinement(source, target, initial_T_target_source, requested);
      !status.ok()) {
    return status;
  }
  TreeRefinementCache::Impl& shared = *cache.impl_;
  shared.BindTo(source, target);
  TreeRefinementResult result =
      RefineStages(source, target, initial_T_target_source, requested, shared);
  if (!requested.noise_polish || requested.evaluate_only || !result.valid) return result;
  return NoisePolish(source, target, requested, shared, std::move(result));
}

}  // namespace rpsr::core
