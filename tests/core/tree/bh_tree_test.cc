// Randomised property tests of the Barnes-Hut tree against brute force, for D = 2 and D = 3.
#include "core/tree/bh_tree.h"

#include <cmath>
#include <limits>
#include <map>
#include <random>
#include <vector>

#include "core/tree/morton.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"

namespace rpsr::core {
namespace {

using ::testing::HasSubstr;

template <int D>
using Points = std::vector<Eigen::Matrix<float, D, 1>>;

// Clouds with different structure: uniform, clustered (many empty cells, dense nodes), a flat
// sheet (degenerate covariance), and heavy duplication (nodes that never split).
enum class CloudKind { kUniform, kClusters, kSheet, kDuplicates };

template <int D>
Points<D> MakeCloud(CloudKind kind, int n, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<float> uniform(-5.0f, 7.0f);
  std::normal_distribution<float> normal(0.0f, 0.3f);
  Points<D> points;
  Eigen::Matrix<float, D, 1> centers[4];
  for (auto& c : centers) {
    for (int a = 0; a < D; ++a) c[a] = uniform(rng);
  }
  for (int i = 0; i < n; ++i) {
    Eigen::Matrix<float, D, 1> p;
    for (int a = 0; a < D; ++a) p[a] = uniform(rng);
    switch (kind) {
      case CloudKind::kUniform:
        break;
      case CloudKind::kClusters:
        for (int a = 0; a < D; ++a) p[a] = centers[i % 4][a] + normal(rng);
        break;
      case CloudKind::kSheet:
        p[D - 1] = 2.5f;
        break;
      case CloudKind::kDuplicates:
        p = centers[i % 3];
        if (i % 5 == 0) p[0] += 0.01f * (i % 7);
        break;
    }
    points.push_back(p);
  }
  return points;
}

template <typename T>
class BarnesHutTreePropertyTest : public ::testing::Test {};

template <int N>
struct Dim {
  static constexpr int kD = N;
};
using Dimensions = ::testing::Types<Dim<2>, Dim<3>>;
TYPED_TEST_SUITE(BarnesHutTreePropertyTest, Dimensions);

// Brute force per depth: group points by CellOfPoint (the tree's documented quantization) and
// compute counts, means and covariances directly.
template <int D>
struct BruteNode {
  uint32_t count = 0;
  Eigen::Matrix<double, D, 1> sum = Eigen::Matrix<double, D, 1>::Zero();
  Eigen::Matrix<double, D, D> sum_sq = Eigen::Matrix<double, D, D>::Zero();
};

template <int D>
std::map<uint64_t, BruteNode<D>> BruteForceLevel(const BarnesHutTree<D>& tree,
                                                 const Points<D>& points, int depth) {
  std::map<uint64_t, BruteNode<D>> nodes;
  for (const auto& p : points) {
    BruteNode<D>& node = nodes[EncodeMorton<D>(tree.CellOfPoint(p, depth))];
    const Eigen::Matrix<double, D, 1> q = p.template cast<double>();
    node.count += 1;
    node.sum += q;
    node.sum_sq += q * q.transpose();
  }
  return nodes;
}

TYPED_TEST(BarnesHutTreePropertyTest, LevelsMatchBruteForce) {
  constexpr int D = TypeParam::kD;
  for (CloudKind kind :
       {CloudKind::kUniform, CloudKind::kClusters, CloudKind::kSheet, CloudKind::kDuplicates}) {
    for (uint64_t seed : {1u, 2u, 3u}) {
      const Points<D> points = MakeCloud<D>(kind, 3000, seed);
      BarnesHutTreeOptions options;
      options.max_depth = 6;
      auto tree = BuildBarnesHutTree<D>(absl::MakeConstSpan(points), options);
      ASSERT_TRUE(tree.ok()) << tree.status();
      ASSERT_EQ(tree->max_depth(), 6);
      EXPECT_EQ(tree->num_points(), points.size());
      for (int depth = 0; depth <= tree->max_depth(); ++depth) {
        SCOPED_TRACE(::testing::Message() << "kind " << static_cast<int>(kind) << " seed " << seed
                                          << " depth " << depth);
        const auto brute = BruteForceLevel<D>(*tree, points, depth);
        const auto& level = tree->level(depth);
        ASSERT_EQ(level.size(), brute.size());
        size_t i = 0;
        double inverse_density_sum = 0.0;
        for (const auto& [code, node] : brute) {
          // std::map iterates codes ascending: this also checks Morton order.
          ASSERT_EQ(level.morton[i], code);
          ASSERT_EQ(level.count[i], node.count);
          const Eigen::Matrix<double, D, 1> mean = node.sum / node.count;
          EXPECT_LT((level.center_of_mass[i].template cast<double>() - mean).norm(), 1e-4);
          const Eigen::Matrix<double, D, D> covariance =
              node.sum_sq / node.count - mean * mean.transpose();
          EXPECT_LT((tree->Covariance(depth, i).template cast<double>() - covariance).norm(),
                    1e-3 * (1.0 + covariance.norm()));
          EXPECT_EQ(tree->IsLeaf(depth, i), node.count == 1);
          // The centre of mass lies inside its cell.
          EXPECT_TRUE(tree->CellBounds(depth, i).exteriorDistance(level.center_of_mass[i]) < 1e-4f);
          inverse_density_sum += level.inverse_density[i];
          ++i;
        }
        EXPECT_NEAR(inverse_density_sum, 1.0, 1e-5);
      }
    }
  }
}

TYPED_TEST(BarnesHutTreePropertyTest, ParentsAggregateChildren) {
  constexpr int D = TypeParam::kD;
  const Points<D> points = MakeCloud<D>(CloudKind::kClusters, 5000, 9);
  auto tree = BuildBarnesHutTree<D>(absl::MakeConstSpan(points));
  ASSERT_TRUE(tree.ok()) << tree.status();
  for (int depth = 1; depth <= tree->max_depth(); ++depth) {
    const auto& level = tree->level(depth);
    const auto& above = tree->level(depth - 1);
    std::vector<uint64_t> counts(above.size(), 0);
    std::vector<Eigen::Matrix<double, D, 1>> weighted(above.size(),
                                                      Eigen::Matrix<double, D, 1>::Zero());
    uint64_t total = 0;
    for (size_t j = 0; j < level.size(); ++j) {
      const int32_t parent = level.parent[j];
      ASSERT_GE(parent, 0);
      ASSERT_LT(parent, static_cast<int32_t>(above.size()));
      ASSERT_EQ(level.morton[j] >> D, above.morton[parent]);
      counts[parent] += level.count[j];
      weighted[parent] += level.count[j] * level.center_of_mass[j].template cast<double>();
      total += level.count[j];
    }
    EXPECT_EQ(total, points.size()) << "counts add up at depth " << depth;
    for (size_t i = 0; i < above.size(); ++i) {
      ASSERT_EQ(counts[i], above.count[i]);
      EXPECT_LT((weighted[i] / counts[i] - above.center_of_mass[i].template cast<double>()).norm(),
                1e-4);
    }
  }
  EXPECT_EQ(tree->level(0).parent[0], BarnesHutTree<D>::kEmpty);
}

TYPED_TEST(BarnesHutTreePropertyTest, LabelsAgreeWithNodes) {
  constexpr int D = TypeParam::kD;
  using Tree = BarnesHutTree<D>;
  const Points<D> points = MakeCloud<D>(CloudKind::kUniform, 2000, 4);
  auto tree = BuildBarnesHutTree<D>(absl::MakeConstSpan(points));
  ASSERT_TRUE(tree.ok()) << tree.status();
  EXPECT_TRUE(tree->level(0).labels.empty());
  for (int depth = 1; depth <= tree->max_depth(); ++depth) {
    const auto& level = tree->level(depth);
    const auto& above = tree->level(depth - 1);
    ASSERT_EQ(level.labels.size(), above.size() * Tree::kChildren);
    std::vector<int> seen(level.size(), 0);
    for (size_t parent = 0; parent < above.size(); ++parent) {
      int children = 0;
      for (int octant = 0; octant < Tree::kChildren; ++octant) {
        const int32_t child = level.labels[parent * Tree::kChildren + octant];
        if (child == Tree::kEmpty) continue;
        ++children;
        ASSERT_GE(child, 0);
        ASSERT_LT(child, static_cast<int32_t>(level.size()));
        EXPECT_EQ(level.parent[child], static_cast<int32_t>(parent));
        EXPECT_EQ(level.morton[child], (above.morton[parent] << D) | octant);
        ++seen[child];
      }
      EXPECT_GE(children, 1) << "a non-empty parent has a non-empty child";
    }
    for (int s : seen) EXPECT_EQ(s, 1) << "each node is labelled exactly once";
  }
}

TYPED_TEST(BarnesHutTreePropertyTest, NeighborsMatchBruteForceAndAreSymmetric) {
  constexpr int D = TypeParam::kD;
  using Tree = BarnesHutTree<D>;
  for (CloudKind kind : {CloudKind::kUniform, CloudKind::kClusters}) {
    const Points<D> points = MakeCloud<D>(kind, 2500, 5);
    BarnesHutTreeOptions options;
    options.neighbor_max_depth = 6;
    auto tree = BuildBarnesHutTree<D>(absl::MakeConstSpan(points), options);
    ASSERT_TRUE(tree.ok()) << tree.status();
    ASSERT_EQ(tree->neighbor_max_depth(), 6);
    for (int depth = 0; depth <= tree->neighbor_max_depth(); ++depth) {
      const auto& level = tree->level(depth);
      ASSERT_EQ(level.neighbors.size(), level.size() * Tree::kNeighbors);
      std::map<std::array<uint32_t, D>, int32_t> by_cell;
      for (size_t i = 0; i < level.size(); ++i) by_cell[tree->Cell(depth, i)] = i;
      for (size_t i = 0; i < level.size(); ++i) {
        const std::array<uint32_t, D> cell = tree->Cell(depth, i);
        for (int k = 0; k < Tree::kNeighbors; ++k) {
          std::array<uint32_t, D> other;
          int divisor = 1;
          for (int a = 0; a < D; ++a, divisor *= 3) {
            other[a] = cell[a] + ((k / divisor) % 3) - 1;  // wraps below 0: not in the map
          }
          const auto found = by_cell.find(other);
          const int32_t expected = found == by_cell.end() ? Tree::kEmpty : found->second;
          ASSERT_EQ(tree->Neighbor(depth, i, k), expected) << "depth " << depth << " k " << k;
          if (expected != Tree::kEmpty) {
            EXPECT_EQ(tree->Neighbor(depth, expected, Tree::kNeighbors - 1 - k),
                      static_cast<int32_t>(i));
          }
        }
        EXPECT_EQ(tree->Neighbor(depth, i, Tree::kSelfNeighbor), static_cast<int32_t>(i));
      }
    }
  }
}

TYPED_TEST(BarnesHutTreePropertyTest, DenseViewIndexesNodesByMortonCode) {
  constexpr int D = TypeParam::kD;
  using Tree = BarnesHutTree<D>;
  const Points<D> points = MakeCloud<D>(CloudKind::kClusters, 1000, 6);
  auto tree = BuildBarnesHutTree<D>(absl::MakeConstSpan(points));
  ASSERT_TRUE(tree.ok()) << tree.status();
  const std::vector<int32_t> view = tree->DenseView(2);
  ASSERT_EQ(view.size(), size_t{1} << (2 * D));
  size_t non_empty = 0;
  for (size_t slot = 0; slot < view.size(); ++slot) {
    if (view[slot] == Tree::kEmpty) continue;
    ++non_empty;
    EXPECT_EQ(tree->level(2).morton[view[slot]], slot);
  }
  EXPECT_EQ(non_empty, tree->level(2).size());
}

TYPED_TEST(BarnesHutTreePropertyTest, NormalizationMapsIntoUnitCubeAndBack) {
  constexpr int D = TypeParam::kD;
  const Points<D> points = MakeCloud<D>(CloudKind::kUniform, 500, 8);
  auto tree = BuildBarnesHutTree<D>(absl::MakeConstSpan(points));
  ASSERT_TRUE(tree.ok()) << tree.status();
  float largest = 0.0f;
  for (const auto& p : points) {
    const auto q = tree->ToNormalized(p);
    EXPECT_LE(q.cwiseAbs().maxCoeff(), 1.0f);
    largest = std::max(largest, q.cwiseAbs().maxCoeff());
    EXPECT_LT((tree->FromNormalized(q) - p).norm(), 1e-5f);
  }
  EXPECT_GT(largest, 0.999f) << "the cube is tight around the cloud";
  // The root's centre of mass is the cloud's mean.
  Eigen::Matrix<double, D, 1> mean = Eigen::Matrix<double, D, 1>::Zero();
  for (const auto& p : points) mean += p.template cast<double>();
  mean /= points.size();
  EXPECT_LT((tree->level(0).center_of_mass[0].template cast<double>() - mean).norm(), 1e-5);
}

TEST(BarnesHutTreeTest, SinglePointAndDuplicatesMakeOneNodePerDepth) {
  PointCloud cloud;
  cloud.points.assign(17, Eigen::Vector3f(3.0f, -2.0f, 1e4f));
  auto tree = BuildOctree(cloud);
  ASSERT_TRUE(tree.ok()) << tree.status();
  for (int depth = 0; depth <= tree->max_depth(); ++depth) {
    ASSERT_EQ(tree->level(depth).size(), 1u);
    EXPECT_EQ(tree->level(depth).count[0], 17u);
    EXPECT_TRUE(tree->level(depth).center_of_mass[0].isApprox(cloud.points[0]));
    EXPECT_LT(tree->Covariance(depth, 0).norm(), 1e-3f);
    EXPECT_FLOAT_EQ(tree->level(depth).inverse_density[0], 1.0f);
  }
  cloud.points.resize(1);
  EXPECT_TRUE(BuildOctree(cloud).ok());
}

TEST(BarnesHutTreeTest, LeafIsCarriedDownUnchanged) {
  PointCloud cloud;
  for (int i = 0; i < 50; ++i) cloud.points.push_back(Eigen::Vector3f(0.01f * i, 0.0f, 0.0f));
  cloud.points.push_back(Eigen::Vector3f(9.0f, 9.0f, 9.0f));  // alone in its corner
  auto tree = BuildOctree(cloud);
  ASSERT_TRUE(tree.ok()) << tree.status();
  for (int depth = 1; depth <= tree->max_depth(); ++depth) {
    const auto& level = tree->level(depth);
    const size_t last = level.size() - 1;  // the far corner has the largest Morton code
    EXPECT_EQ(level.count[last], 1u);
    EXPECT_TRUE(tree->IsLeaf(depth, last));
    EXPECT_TRUE(level.center_of_mass[last].isApprox(cloud.points.back()));
  }
}

TEST(BarnesHutTreeTest, InverseDensityFavoursSparseNodes) {
  PointCloud cloud;
  for (int i = 0; i < 90; ++i) cloud.points.push_back(Eigen::Vector3f(0.001f * i, 0, 0));
  for (int i = 0; i < 10; ++i) cloud.points.push_back(Eigen::Vector3f(10.0f + 0.001f * i, 0, 0));
  BarnesHutTreeOptions options;
  options.max_depth = 1;
  auto tree = BuildOctree(cloud, options);
  ASSERT_TRUE(tree.ok()) << tree.status();
  const auto& level = tree->level(1);
  ASSERT_EQ(level.size(), 2u);
  // (1/90) / (1/90 + 1/10) = 0.1 and (1/10) / (1/90 + 1/10) = 0.9.
  EXPECT_NEAR(level.inverse_density[0], 0.1f, 1e-6f);
  EXPECT_NEAR(level.inverse_density[1], 0.9f, 1e-6f);
}

TEST(BarnesHutTreeTest, NeighborTablesStopAtTheirDepthAndSaveMemory) {
  const Points<3> points = MakeCloud<3>(CloudKind::kUniform, 4000, 12);
  BarnesHutTreeOptions options;
  options.max_depth = 7;
  auto full = BuildBarnesHutTree<3>(absl::MakeConstSpan(points), options);
  options.neighbor_max_depth = 3;
  auto partial = BuildBarnesHutTree<3>(absl::MakeConstSpan(points), options);
  ASSERT_TRUE(full.ok() && partial.ok());
  EXPECT_EQ(partial->neighbor_max_depth(), 3);
  EXPECT_FALSE(partial->level(3).neighbors.empty());
  EXPECT_TRUE(partial->level(4).neighbors.empty());
  EXPECT_LT(partial->MemoryBytes(), full->MemoryBytes());
  EXPECT_EQ(partial->level(7).morton, full->level(7).morton);
}

TEST(BarnesHutTreeTest, RejectsBadInputWithClearMessages) {
  PointCloud cloud;
  auto empty = BuildOctree(cloud);
  EXPECT_EQ(empty.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(empty.status().message(), HasSubstr("empty"));

  cloud.points = {{0, 0, 0}, {1, 1, 1}, {0, std::numeric_limits<float>::infinity(), 0}};
  auto inf = BuildOctree(cloud);
  EXPECT_EQ(inf.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(inf.status().message(), HasSubstr("point 2"));

  cloud.points.pop_back();
  BarnesHutTreeOptions options;
  options.max_depth = 22;
  EXPECT_THAT(BuildOctree(cloud, options).status().message(), HasSubstr("0..21"));
  options.max_depth = 21;
  EXPECT_TRUE(BuildOctree(cloud, options).ok());
  options.max_depth = 6;
  options.max_points = 1;
  EXPECT_THAT(BuildOctree(cloud, options).status().message(), HasSubstr("limit of 1"));
}

TEST(BarnesHutTreeTest, WeightedBuildEqualsDuplicatedPoints) {
  const Points<3> points = MakeCloud<3>(CloudKind::kClusters, 400, 14);
  std::vector<uint32_t> weights;
  Points<3> duplicated;
  for (size_t i = 0; i < points.size(); ++i) {
    weights.push_back(1 + i % 4);
    for (uint32_t k = 0; k < weights.back(); ++k) duplicated.push_back(points[i]);
  }
  auto weighted = BuildWeightedBarnesHutTree<3>(absl::MakeConstSpan(points), weights);
  auto plain = BuildBarnesHutTree<3>(absl::MakeConstSpan(duplicated));
  ASSERT_TRUE(weighted.ok() && plain.ok());
  EXPECT_EQ(weighted->num_points(), duplicated.size());
  for (int depth = 0; depth <= plain->max_depth(); ++depth) {
    ASSERT_EQ(weighted->level(depth).morton, plain->level(depth).morton);
    ASSERT_EQ(weighted->level(depth).count, plain->level(depth).count);
    for (size_t i = 0; i < plain->level(depth).size(); ++i) {
      EXPECT_LT(
          (weighted->level(depth).center_of_mass[i] - plain->level(depth).center_of_mass[i]).norm(),
          1e-4f);
      EXPECT_LT((weighted->Covariance(depth, i) - plain->Covariance(depth, i)).norm(), 1e-3f);
    }
  }
  weights.pop_back();
  EXPECT_FALSE(BuildWeightedBarnesHutTree<3>(absl::MakeConstSpan(points), weights).ok());
}

// Re-binning a tree's nodes with their covariances (what the refinement does to put a source on a
// target's cells) gives the coarser levels a build from the raw points gives: counts, CoMs and
// covariances; without the covariances the cells would lose their nodes' own spread.
TEST(BarnesHutTreeTest, WeightedBuildWithNodeCovariancesEqualsTheRawPointsBuild) {
  const Points<3> points = MakeCloud<3>(CloudKind::kClusters, 3000, 21);
  BarnesHutTreeOptions options;
  options.max_depth = 6;
  auto raw = BuildBarnesHutTree<3>(absl::MakeConstSpan(points), options);
  ASSERT_TRUE(raw.ok()) << raw.status();
  const Octree::Level& fine = raw->level(6);
  BarnesHutTreeOptions coarse = options;
  coarse.max_depth = 3;
  coarse.cube_center = {raw->center()[0], raw->center()[1], raw->center()[2]};
  coarse.cube_half_length = raw->half_length();
  auto with_spread =
      BuildWeightedBarnesHutTree<3>(absl::MakeConstSpan(fine.center_of_mass), fine.count,
                                    absl::MakeConstSpan(fine.covariance), coarse);
  auto without_spread =
      BuildWeightedBarnesHutTree<3>(absl::MakeConstSpan(fine.center_of_mass), fine.count, coarse);
  ASSERT_TRUE(with_spread.ok() && without_spread.ok());
  float missing_spread = 0.0f;
  for (int depth = 0; depth <= 3; ++depth) {
    ASSERT_EQ(with_spread->level(depth).morton, raw->level(depth).morton);
    ASSERT_EQ(with_spread->level(depth).count, raw->level(depth).count);
    for (size_t i = 0; i < raw->level(depth).size(); ++i) {
      EXPECT_LT((with_spread->level(depth).center_of_mass[i] - raw->level(depth).center_of_mass[i])
                    .norm(),
                1e-4f);
      EXPECT_LT((with_spread->Covariance(depth, i) - raw->Covariance(depth, i)).norm(), 1e-4f);
      missing_spread =
          std::max(missing_spread,
                   (without_spread->Covariance(depth, i) - raw->Covariance(depth, i)).norm());
    }
  }
  EXPECT_GT(missing_spread, 1e-3f);  // the test would notice the spread being dropped
  std::vector<Octree::PackedSymmetric> short_list(fine.covariance.begin(),
                                                  fine.covariance.end() - 1);
  EXPECT_THAT(BuildWeightedBarnesHutTree<3>(absl::MakeConstSpan(fine.center_of_mass), fine.count,
                                            absl::MakeConstSpan(short_list), coarse)
                  .status()
                  .message(),
              HasSubstr("covariances"));
}

TEST(BarnesHutTreeTest, GivenCubeIsUsedAndOutsidePointsClampToBorderCells) {
  PointCloud cloud;
  cloud.points = {{0.25f, 0.25f, 0.25f}, {-0.5f, -0.5f, -0.5f}, {3.0f, 0.0f, 0.0f}};
  BarnesHutTreeOptions options;
  options.max_depth = 2;
  options.cube_center = {0.0, 0.0, 0.0};
  options.cube_half_length = 1.0;
  auto tree = BuildOctree(cloud, options);
  ASSERT_TRUE(tree.ok()) << tree.status();
  EXPECT_EQ(tree->half_length(), 1.0);
  EXPECT_EQ(tree->CellOfPoint(cloud.points[0], 2), (std::array<uint32_t, 3>{2, 2, 2}));
  // (3, 0, 0) lies outside: clamped to x cell 3, its centre of mass stays true.
  EXPECT_EQ(tree->CellOfPoint(cloud.points[2], 2), (std::array<uint32_t, 3>{3, 2, 2}));
  const auto& level = tree->level(2);
  ASSERT_EQ(level.size(), 3u);
  EXPECT_TRUE(level.center_of_mass.back().isApprox(cloud.points[2]));
  options.cube_center = {0.0};
  EXPECT_FALSE(BuildOctree(cloud, options).ok());
}

TEST(BarnesHutTreeTest, QuadtreeSupportsDeepTrees) {
  const Points<2> points = MakeCloud<2>(CloudKind::kUniform, 100, 13);
  BarnesHutTreeOptions options;
  options.max_depth = 31;
  options.neighbor_max_depth = 31;
  auto tree = BuildBarnesHutTree<2>(absl::MakeConstSpan(points), options);
  ASSERT_TRUE(tree.ok()) << tree.status();
  EXPECT_EQ(tree->level(31).size(), points.size()) << "distinct floats separate at depth 31";
}

}  // namespace
}  // namespace rpsr::core
