// RPSRNet: shapes, masking of empty tokens, batched = one by one.
#include "core/net/rpsr_net.h"

#include <torch/torch.h>

#include <cmath>

#include "core/net/rpsr_modules.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/core/net/test_clouds.h"

namespace rpsr::core {
namespace {

RpsrNetConfig SmallConfig() {
  RpsrNetConfig config;
  config.embedding_width = 32;
  config.feedforward_width = 64;
  config.conv_widths = {8, 16, 32};
  config.passes = 2;
  return config;
}

TEST(RpsrNetTest, EncoderShapesAndEmptyTokensAreZero) {
  auto tree = BuildOctree(testing::AsymmetricObject(1500, 1));
  ASSERT_TRUE(tree.ok());
  auto input = MakeNetInput(*tree);
  ASSERT_TRUE(input.ok());
  net::PackedClouds packed = net::PackClouds({&*input, &*input});
  EXPECT_EQ(packed.token_empty.sizes(), (std::vector<int64_t>{2, kNetTokens}));
  net::HierarchicalEncoder encoder(SmallConfig());
  encoder->eval();
  torch::NoGradGuard no_grad;
  torch::Tensor tokens = encoder->forward(packed);
  EXPECT_EQ(tokens.sizes(), (std::vector<int64_t>{2, kNetTokens, 32}));
  const int64_t empty = packed.token_empty.sum().item<int64_t>();
  ASSERT_GT(empty, 0) << "an object leaves some depth-2 cells empty";
  EXPECT_EQ(tokens.index({packed.token_empty}).abs().sum().item<float>(), 0.0f);
  EXPECT_GT(tokens.index({~packed.token_empty}).abs().sum().item<float>(), 0.0f);
  EXPECT_TRUE(torch::allclose(tokens[0], tokens[1]));
}

TEST(RpsrNetTest, ScoresIgnoreEmptyTargetTokens) {
  auto source = BuildOctree(testing::AsymmetricObject(1500, 2));
  auto target = BuildOctree(testing::AsymmetricObject(1500, 3));
  ASSERT_TRUE(source.ok() && target.ok());
  net::RpsrNetwork network(SmallConfig());
  network->eval();
  torch::NoGradGuard no_grad;
  auto source_input = MakeMovedNetInput(*source, Eigen::Isometry3d::Identity(), *target);
  auto target_input = MakeNetInput(*target);
  ASSERT_TRUE(source_input.ok() && target_input.ok());
  net::PackedClouds s = net::PackClouds({&*source_input});
  net::PackedClouds t = net::PackClouds({&*target_input});
  net::PassOutput out = network->Pass(s, t, network->EncodeTarget(t));
  EXPECT_EQ(out.scores.sizes(), (std::vector<int64_t>{1, kNetTokens, kNetTokens}));
  torch::Tensor to_empty = out.scores.index({0, torch::indexing::Slice(), t.token_empty[0]});
  EXPECT_LT(to_empty.max().item<float>(), 1e-12f);
  EXPECT_TRUE(torch::allclose(out.scores.sum(-1), torch::ones({1, kNetTokens})));
  EXPECT_NEAR(torch::linalg_det(out.rotation[0]).item<float>(), 1.0f, 1e-4f);
}

// Pairs of different sizes through Estimate, batched and one by one. An untrained network scores
// tokens nearly alike, so its correspondences collapse and the SVD's rotation is ill-conditioned
// (1e-6 differences in the scores from different GEMM blockings move R by 1e-2): this test
// compares what is well-defined for any weights, the scores' peaks; the rotation itself is
// compared with trained weights in model_test.cc.
TEST(RpsrNetTest, BatchedEstimatesEqualOneByOne) {
  auto net = RpsrNet::Create(SmallConfig(), 11);
  ASSERT_TRUE(net.ok());
  std::vector<Octree> trees;
  for (int i = 0; i < 6; ++i) {
    PointCloud cloud = testing::AsymmetricObject(600 + 400 * i, 20 + i, 0.2 + 0.05 * i);
    if (i % 2 == 1) {
      cloud =
          TransformedCloud(cloud, testing::SmallMotion(0.1 * i, {0.05 * i, 0, 0}).cast<float>());
    }
    auto tree = BuildOctree(cloud);
    ASSERT_TRUE(tree.ok());
    trees.push_back(*std::move(tree));
  }
  std::vector<NetPair> pairs;
  for (int i = 0; i < 3; ++i) {
    pairs.push_back(
        {&trees[2 * i], &trees[2 * i + 1], testing::SmallMotion(0.05 * i, {0, 0.1, 0})});
  }
  auto batched = (*net)->Estimate(pairs, 1);
  ASSERT_TRUE(batched.ok()) << batched.status();
  ASSERT_EQ(batched->size(), 3u);
  for (int i = 0; i < 3; ++i) {
    auto single = (*net)->Estimate({&pairs[i], 1}, 1);
    ASSERT_TRUE(single.ok());
    EXPECT_EQ((*batched)[i].per_pass.size(), 1u);
    EXPECT_NEAR((*batched)[i].score_peak, (*single)[0].score_peak, 1e-5);
    EXPECT_NEAR((*batched)[i].T_target_source.linear().determinant(), 1.0, 1e-4);
  }
  // To every bit: each cloud is convolved on its own rows (SmallConfig's depth-3 convolution
  // takes the rulebook), so a request's answer does not depend on what shares its batch.
  for (int i = 0; i < 3; ++i) {
    auto single = (*net)->Estimate({&pairs[i], 1}, 2);
    auto batched_two = (*net)->Estimate(pairs, 2);
    ASSERT_TRUE(single.ok() && batched_two.ok());
    EXPECT_EQ((*batched_two)[i].T_target_source.matrix(), (*single)[0].T_target_source.matrix());
    EXPECT_EQ((*batched_two)[i].score_peak, (*single)[0].score_peak);
  }
  auto three_passes = (*net)->Estimate({&pairs[0], 1}, 3);
  ASSERT_TRUE(three_passes.ok());
  EXPECT_EQ((*three_passes)[0].per_pass.size(), 3u);
}

// A target encoded once (EncodeTarget) gives the estimates of a fresh encoding (the same
// operators on the same rows: equal to every bit); an encoding of another tree or network is
// refused.
TEST(RpsrNetTest, EncodedTargetGivesTheSameEstimates) {
  auto net = RpsrNet::Create(SmallConfig(), 5);
  auto other_net = RpsrNet::Create(SmallConfig(), 6);
  ASSERT_TRUE(net.ok() && other_net.ok());
  std::vector<Octree> trees;
  for (int i = 0; i < 4; ++i) {
    auto tree = BuildOctree(testing::AsymmetricObject(700 + 300 * i, 40 + i, 0.25));
    ASSERT_TRUE(tree.ok());
    trees.push_back(*std::move(tree));
  }
  auto encoding = (*net)->EncodeTarget(trees[1]);
  ASSERT_TRUE(encoding.ok()) << encoding.status();
  const NetPair fresh{&trees[0], &trees[1], testing::SmallMotion(0.1, {0.05, 0, 0})};
  NetPair reused = fresh;
  reused.target_encoding = encoding->get();
  auto a = (*net)->Estimate({&fresh, 1}, 2);
  auto b = (*net)->Estimate({&reused, 1}, 2);
  ASSERT_TRUE(a.ok() && b.ok()) << a.status() << b.status();
  EXPECT_EQ((*a)[0].T_target_source.matrix(), (*b)[0].T_target_source.matrix());
  EXPECT_EQ((*a)[0].score_peak, (*b)[0].score_peak);

  // A batch mixing encoded and fresh targets: ShippedObjectModelTest (model_test.cc), where the
  // estimates are well conditioned (this untrained network's soft correspondences are nearly
  // uniform, so its rotations amplify float rounding across batch sizes).
  const NetPair other{&trees[2], &trees[3]};
  NetPair wrong_tree = other;
  wrong_tree.target_encoding = encoding->get();
  EXPECT_EQ((*net)->Estimate({&wrong_tree, 1}).status().code(), absl::StatusCode::kInvalidArgument);
  auto foreign = (*other_net)->EncodeTarget(trees[1]);
  ASSERT_TRUE(foreign.ok());
  NetPair wrong_net = fresh;
  wrong_net.target_encoding = foreign->get();
  EXPECT_EQ((*net)->Estimate({&wrong_net, 1}).status().code(), absl::StatusCode::kInvalidArgument);
}

// A cloud of one point (one node a depth) goes through every layer with a single row; no layer
// may write into the network's parameters then (the rulebook convolution once summed into a
// view of its bias with one output row): the next pair's estimate is the same to every bit.
TEST(RpsrNetTest, OneNodeCloudsLeaveTheNetworkUnchanged) {
  RpsrNetConfig config = SmallConfig();  // depth 3 convolves 16 channels: the rulebook's path
  auto net = RpsrNet::Create(config, 8);
  ASSERT_TRUE(net.ok());
  auto source = BuildOctree(testing::AsymmetricObject(900, 50));
  auto target = BuildOctree(testing::AsymmetricObject(900, 51));
  PointCloud one;
  one.points.push_back(Eigen::Vector3f(0.1f, -0.2f, 0.3f));
  auto lone = BuildOctree(one);
  ASSERT_TRUE(source.ok() && target.ok() && lone.ok());
  const NetPair pair{&*source, &*target, testing::SmallMotion(0.1, {0.05, 0, 0})};
  auto before = (*net)->Estimate({&pair, 1}, 2);
  ASSERT_TRUE(before.ok()) << before.status();
  const NetPair lone_pair{&*lone, &*lone};
  for (int i = 0; i < 3; ++i) {
    auto lone_estimate = (*net)->Estimate({&lone_pair, 1}, 2);
    auto encoding = (*net)->EncodeTarget(*lone);
    ASSERT_TRUE(lone_estimate.ok()) << lone_estimate.status();
    ASSERT_TRUE(encoding.ok()) << encoding.status();
  }
  auto after = (*net)->Estimate({&pair, 1}, 2);
  ASSERT_TRUE(after.ok()) << after.status();
  EXPECT_EQ((*before)[0].T_target_source.matrix(), (*after)[0].T_target_source.matrix());
  EXPECT_EQ((*before)[0].score_peak, (*after)[0].score_peak);
}

TEST(RpsrNetTest, BatchedPassEqualsOneByOneBeforeTheSvd) {
  net::RpsrNetwork network(SmallConfig());
  network->eval();
  torch::NoGradGuard no_grad;
  std::vector<NetCloudInput> inputs;
  for (int i = 0; i < 3; ++i) {
    auto tree = BuildOctree(testing::AsymmetricObject(600 + 500 * i, 30 + i));
    ASSERT_TRUE(tree.ok());
    inputs.push_back(*MakeNetInput(*tree));
  }
  net::PackedClouds all = net::PackClouds({&inputs[0], &inputs[1], &inputs[2]});
  const net::EncodedTarget all_target = network->EncodeTarget(all);
  const torch::Tensor& all_embedding = all_target.embedding;
  net::PassOutput all_out = network->Pass(all, all, all_target);
  for (int i = 0; i < 3; ++i) {
    net::PackedClouds one = net::PackClouds({&inputs[i]});
    const net::EncodedTarget target = network->EncodeTarget(one);
    EXPECT_TRUE(torch::allclose(target.embedding[0], all_embedding[i], 1e-5, 1e-6));
    net::PassOutput out = network->Pass(one, one, target);
    EXPECT_TRUE(torch::allclose(out.scores[0], all_out.scores[i], 1e-5, 1e-7));
  }
}

TEST(RpsrNetTest, MissingTreeIsAnError) {
  auto net = RpsrNet::Create(SmallConfig(), 1);
  ASSERT_TRUE(net.ok());
  NetPair pair;
  EXPECT_EQ((*net)->Estimate({&pair, 1}).status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_TRUE((*net)->Estimate({}).ok());
}

TEST(RpsrNetTest, BadConfigIsRejected) {
  RpsrNetConfig config = SmallConfig();
  config.attention_heads = 5;
  EXPECT_EQ(RpsrNet::Create(config, 1).status().code(), absl::StatusCode::kInvalidArgument);
  for (double cube : {-1.0, std::nan("")}) {
    config = SmallConfig();
    config.cube_half_length = cube;
    EXPECT_EQ(RpsrNet::Create(config, 1).status().code(), absl::StatusCode::kInvalidArgument);
  }
}

}  // namespace
}  // namespace rpsr::core
