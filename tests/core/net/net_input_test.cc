#include "core/net/net_input.h"

#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/core/net/test_clouds.h"

namespace rpsr::core {
namespace {

TEST(NetInputTest, HasTheDepthsAndTokensOfTheTree) {
  auto tree = BuildOctree(testing::AsymmetricObject(2048, 1));
  ASSERT_TRUE(tree.ok());
  auto input = MakeNetInput(*tree);
  ASSERT_TRUE(input.ok()) << input.status();
  for (int d = kNetTokenDepth; d <= kNetLeafDepth; ++d) {
    const NetDepthInput& depth = input->depths[d - kNetTokenDepth];
    EXPECT_EQ(depth.num_nodes, static_cast<int>(tree->level(d).size()));
    EXPECT_EQ(depth.position.size(), depth.num_nodes * size_t{kNetPositionFeatures});
    EXPECT_EQ(depth.neighbors.size(), d > kNetTokenDepth ? depth.num_nodes * size_t{27} : 0u);
    EXPECT_EQ(depth.child_slots.size(), d < kNetLeafDepth ? depth.num_nodes * size_t{8} : 0u);
    for (float v : depth.position) EXPECT_LE(std::abs(v), 2.0f);
  }
  float weight = 0.0f;
  int tokens = 0;
  for (int s = 0; s < kNetTokens; ++s) {
    weight += input->token_weight[s];
    tokens += input->token_node[s] >= 0;
  }
  EXPECT_NEAR(weight, 1.0f, 1e-5f);
  EXPECT_EQ(tokens, static_cast<int>(tree->level(kNetTokenDepth).size()));
}

TEST(NetInputTest, MovingByIdentityIntoOwnCubeReproducesTheTreeInput) {
  // Depth-7 nodes lie inside single depth-5 cells of the same cube, so re-binning them is exact.
  BarnesHutTreeOptions options;
  options.max_depth = 8;
  auto tree = BuildOctree(testing::AsymmetricObject(3000, 2), options);
  ASSERT_TRUE(tree.ok());
  auto direct = MakeNetInput(*tree);
  auto moved = MakeMovedNetInput(*tree, Eigen::Isometry3d::Identity(), *tree);
  ASSERT_TRUE(direct.ok() && moved.ok());
  for (int d = 0; d < kNetDepths; ++d) {
    ASSERT_EQ(direct->depths[d].num_nodes, moved->depths[d].num_nodes);
    EXPECT_EQ(direct->depths[d].neighbors, moved->depths[d].neighbors);
    EXPECT_EQ(direct->depths[d].child_slots, moved->depths[d].child_slots);
    for (size_t i = 0; i < direct->depths[d].position.size(); ++i) {
      ASSERT_NEAR(direct->depths[d].position[i], moved->depths[d].position[i], 1e-4f);
    }
  }
  EXPECT_EQ(direct->token_node, moved->token_node);
}

TEST(NetInputTest, MovedTokensAreInTheMovedFrame) {
  auto tree = BuildOctree(testing::AsymmetricObject(2048, 3));
  ASSERT_TRUE(tree.ok());
  const Eigen::Isometry3d T = testing::SmallMotion(0.2, {0.1, 0.0, -0.1});
  auto moved = MakeMovedNetInput(*tree, T, *tree);
  ASSERT_TRUE(moved.ok());
  // The weighted mean of the token centres of mass is the moved cloud's mean.
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (int s = 0; s < kNetTokens; ++s) {
    mean += moved->token_weight[s] * Eigen::Vector3f(moved->token_com[3 * s],
                                                     moved->token_com[3 * s + 1],
                                                     moved->token_com[3 * s + 2])
                                         .cast<double>();
  }
  const Eigen::Vector3d expected = T * tree->level(0).center_of_mass[0].cast<double>();
  EXPECT_LT((mean - expected).norm(), 1e-4);
}

TEST(NetInputTest, ShallowTreeIsRejected) {
  BarnesHutTreeOptions options;
  options.max_depth = 4;
  auto tree = BuildOctree(testing::AsymmetricObject(100, 4), options);
  ASSERT_TRUE(tree.ok());
  EXPECT_EQ(MakeNetInput(*tree).status().code(), absl::StatusCode::kFailedPrecondition);
}

}  // namespace
}  // namespace rpsr::core
