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

// A scene-like cloud: a dense patch near the origin and sparse far points.
PointCloud SceneLike() {
  PointCloud cloud = testing::AsymmetricObject(3000, 4);
  for (Eigen::Vector3f& p : cloud.points) p *= 10.0f;  // +-10 m around the "sensor"
  for (int i = 0; i < 50; ++i) {
    cloud.points.push_back(Eigen::Vector3f(100.0f + i, -90.0f, 2.0f));  // a far wall
  }
  return cloud;
}

TEST(NetInputTest, CroppedCubeKeepsOnlyPointsInsideAroundTheTargetsCentreOfMass) {
  BarnesHutTreeOptions options;
  options.max_depth = 8;
  auto tree = BuildOctree(SceneLike(), options);
  ASSERT_TRUE(tree.ok());
  const NetCube cube = CroppedNetCube(*tree, 40.0);
  EXPECT_TRUE(cube.center.isApprox(tree->level(0).center_of_mass[0].cast<double>()));
  EXPECT_EQ(cube.half_length, 40.0);
  auto input = MakeCroppedNetInput(*tree, Eigen::Isometry3d::Identity(), cube);
  ASSERT_TRUE(input.ok()) << input.status();
  EXPECT_EQ(input->cube_half_length, 40.0);
  EXPECT_TRUE(input->cube_center.isApprox(cube.center, 1e-9));
  float weight = 0.0f;
  for (int s = 0; s < kNetTokens; ++s) {
    weight += input->token_weight[s];
    if (input->token_node[s] < 0) continue;
    // Every kept token's centre of mass lies inside the cube: the far wall was dropped, not
    // clamped into border cells.
    for (int a = 0; a < 3; ++a) {
      EXPECT_LT(std::abs(input->token_com[s * 3 + a] - cube.center[a]), 40.0) << "token " << s;
    }
  }
  EXPECT_NEAR(weight, 1.0f, 1e-5f);  // fractions of the kept points
  for (float v : input->depths[0].position) EXPECT_LE(std::abs(v), 2.0f);

  // Moved so that nothing stays inside: a clear error, not an empty input.
  Eigen::Isometry3d far = Eigen::Isometry3d::Identity();
  far.translation() = Eigen::Vector3d(1000, 0, 0);
  auto outside = MakeCroppedNetInput(*tree, far, cube);
  EXPECT_EQ(outside.status().code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_THAT(outside.status().message(), ::testing::HasSubstr("within the network's cube"));
}

}  // namespace
}  // namespace rpsr::core
