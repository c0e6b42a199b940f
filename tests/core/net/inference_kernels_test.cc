// The CPU inference kernels give what the differentiable operators they replace give: the
// gather and the pooling exactly, the rulebook convolution within float rounding, the SVD head
// within double rounding; and they are chosen only where no gradient is wanted.
#include "core/net/inference_kernels.h"

#include <torch/torch.h>

#include <cmath>
#include <limits>

#include "core/net/rpsr_modules.h"
#include "gtest/gtest.h"

namespace rpsr::core::net {
namespace {

// Index tensor into `rows` rows with about a third "empty" (== rows).
torch::Tensor IndicesWithEmpty(int64_t count, int64_t rows, int64_t width, uint64_t seed) {
  torch::manual_seed(seed);
  torch::Tensor idx = torch::randint(rows, {count, width}, torch::kInt64);
  torch::Tensor empty = torch::rand({count, width}) < 0.33;
  return torch::where(empty, torch::full_like(idx, rows), idx);
}

torch::Tensor WithZeroRow(const torch::Tensor& f) {
  return torch::cat({f, torch::zeros({1, f.size(1)}, f.options())}, 0);
}

TEST(InferenceKernelsTest, GatherEqualsIndexSelectWithAZeroRow) {
  // Every row width with its own fixed-size copy (1-8 floats), the first one without, and wide.
  for (int64_t channels : {1, 2, 3, 4, 5, 6, 7, 8, 9, 32, 128}) {
    torch::Tensor features = torch::randn({300, channels});
    torch::Tensor idx = IndicesWithEmpty(200, 300, 27, 7 + channels);
    torch::Tensor expected = WithZeroRow(features).index_select(0, idx.reshape({-1}));
    torch::Tensor got = GatherRowsOrZero(features, idx);
    ASSERT_EQ(got.sizes(), expected.sizes());
    EXPECT_TRUE(torch::equal(got, expected)) << "channels " << channels;
  }
}

TEST(InferenceKernelsTest, GatherRejectsIndicesOutsideTheRows) {
  torch::Tensor features = torch::randn({10, 4});
  EXPECT_THROW(GatherRowsOrZero(features, torch::tensor({0, 11}, torch::kInt64)), c10::Error);
  EXPECT_THROW(GatherRowsOrZero(features, torch::tensor({-1}, torch::kInt64)), c10::Error);
  // The fixed-size copies of short rows check their indices too.
  torch::Tensor narrow = torch::randn({10, 6});
  EXPECT_THROW(GatherRowsOrZero(narrow, torch::tensor({0, 11}, torch::kInt64)), c10::Error);
  EXPECT_THROW(GatherRowsOrZero(narrow, torch::tensor({-1}, torch::kInt64)), c10::Error);
}

TEST(InferenceKernelsTest, MaxOverSlotsEqualsTheGenericPoolingOfReluOutputs) {
  for (int64_t channels : {1, 32, 64}) {
    torch::Tensor children = torch::relu(torch::randn({400, channels}));
    torch::Tensor slots = IndicesWithEmpty(120, 400, 8, 11 + channels);
    torch::Tensor gathered =
        WithZeroRow(children).index_select(0, slots.reshape({-1})).reshape({120, 8, channels});
    torch::Tensor expected = std::get<0>(gathered.max(1));
    EXPECT_TRUE(torch::equal(MaxOverSlots(children, slots), expected)) << "channels " << channels;
  }
}

TEST(InferenceKernelsTest, KabschRotationEqualsTheDifferentiableHead) {
  torch::manual_seed(5);
  torch::Tensor src = torch::randn({8, 64, 3});
  torch::Tensor tgt = torch::randn({8, 64, 3});
  // Make half of them mirror images so that the reflection fix is exercised.
  tgt.index_put_({torch::indexing::Slice(0, 4)},
                 src.index({torch::indexing::Slice(0, 4)}) * torch::tensor({1.0f, 1.0f, -1.0f}));
  torch::Tensor weights = torch::rand({8, 64}) + 0.05;
  torch::Tensor R_fast, t_fast;
  {
    torch::NoGradGuard no_grad;
    std::tie(R_fast, t_fast) = WeightedProcrustes(src, tgt, weights);
  }
  // The differentiable path runs when the correspondences carry a gradient.
  torch::Tensor tgt_grad = tgt.clone().requires_grad_(true);
  auto [R_slow, t_slow] = WeightedProcrustes(src, tgt_grad, weights);
  EXPECT_LT((R_fast - R_slow.detach()).abs().max().item<float>(), 1e-5);
  EXPECT_LT((t_fast - t_slow.detach()).abs().max().item<float>(), 1e-5);
  torch::Tensor det = torch::linalg_det(R_fast.to(torch::kFloat64));
  EXPECT_LT((det - 1.0).abs().max().item<double>(), 1e-5);
}

TEST(InferenceKernelsTest, NonFiniteValuesPropagateLikeTheGenericOperators) {
  torch::Tensor children = torch::relu(torch::randn({16, 4}));
  children[3][1] = std::numeric_limits<float>::quiet_NaN();
  torch::Tensor slots = torch::arange(16, torch::kInt64).reshape({2, 8});
  torch::Tensor pooled = MaxOverSlots(children, slots);
  EXPECT_TRUE(std::isnan(pooled[0][1].item<float>()));  // slot 3 of parent 0
  EXPECT_FALSE(std::isnan(pooled[1][1].item<float>()));
  torch::Tensor H = torch::randn({2, 3, 3}, torch::kFloat64);
  H[1][0][0] = std::numeric_limits<double>::infinity();
  torch::Tensor R = KabschRotation(H);
  EXPECT_TRUE(torch::isfinite(R[0]).all().item<bool>());
  EXPECT_TRUE(torch::isnan(R[1]).all().item<bool>());
}

TEST(InferenceKernelsTest, ChosenOnlyWithoutGradientOnCpuFloat) {
  torch::Tensor leaf = torch::randn({4, 4}).requires_grad_(true);
  EXPECT_FALSE(UseInferenceKernels(leaf));
  EXPECT_FALSE(UseInferenceKernels(torch::randn({4, 4}, torch::kFloat64)));
  EXPECT_TRUE(UseInferenceKernels(torch::randn({4, 4})));
  {
    torch::NoGradGuard no_grad;
    EXPECT_TRUE(UseInferenceKernels(leaf));
  }
  {
    torch::InferenceMode inference;
    EXPECT_TRUE(UseInferenceKernels(torch::randn({4, 4})));
  }
}

// Neighbour lists as a tree has them: the centre (offset 13) is each node itself.
torch::Tensor WithSelfAtCentre(torch::Tensor neighbors) {
  neighbors.index_put_({torch::indexing::Slice(), 13}, torch::arange(neighbors.size(0)));
  return neighbors;
}

TEST(InferenceKernelsTest, SparseTreeConvEqualsTheLinearMapOverGatheredRows) {
  if (!SparseTreeConvAvailable()) GTEST_SKIP() << "the loaded BLAS exports no sgemm_";
  // 16, 32 and 64 channels gather their rows with fixed-size copies, 1 and 20 without.
  for (int64_t channels : {1, 16, 20, 32, 64}) {
    torch::manual_seed(21 + channels);
    torch::nn::Linear linear(27 * channels, 48);
    torch::Tensor features = torch::randn({400, channels});
    torch::Tensor random = IndicesWithEmpty(400, 400, 27, 23 + channels);
    // Centre = self takes the direct GEMM; random centres and a coarser output depth (fewer
    // rows than inputs) take the gathered one.
    for (const torch::Tensor& neighbors :
         {WithSelfAtCentre(random.clone()), random, IndicesWithEmpty(90, 400, 27, 29)}) {
      torch::NoGradGuard no_grad;
      torch::Tensor expected = linear->forward(WithZeroRow(features)
                                                   .index_select(0, neighbors.reshape({-1}))
                                                   .reshape({neighbors.size(0), 27 * channels}));
      torch::Tensor got = SparseTreeConvLinear(features, neighbors, linear->weight, linear->bias);
      ASSERT_EQ(got.sizes(), expected.sizes());
      EXPECT_TRUE(torch::allclose(got, expected, 1e-5, 1e-5)) << "channels " << channels;
      // The weight by offset (weight.t()), as TreeConv passes it: the same map.
      const std::vector<int64_t> one_cloud =
          neighbors.size(0) == 400 ? std::vector<int64_t>{0, 400} : std::vector<int64_t>{};
      torch::Tensor by_offset =
          SparseTreeConvLinear(features, neighbors, linear->weight, linear->bias, one_cloud,
                               linear->weight.t().contiguous());
      EXPECT_TRUE(torch::allclose(by_offset, expected, 1e-5, 1e-5)) << "channels " << channels;
    }
  }
}

TEST(InferenceKernelsTest, TransposedWeightCacheFollowsEveryChangeOfTheWeight) {
  torch::nn::Linear linear(6, 4);
  TransposedWeightCache cache;
  torch::Tensor first = cache.Of(linear->weight);
  EXPECT_TRUE(torch::equal(first, linear->weight.t()));
  EXPECT_TRUE(first.is_contiguous());
  // Unchanged: the same tensor, not a new transpose.
  EXPECT_EQ(cache.Of(linear->weight).data_ptr(), first.data_ptr());
  // An in-place write (a loaded state, an optimiser's step) is seen.
  {
    torch::NoGradGuard no_grad;
    linear->weight.mul_(2.0);
  }
  EXPECT_TRUE(torch::equal(cache.Of(linear->weight), linear->weight.t()));
  // Another weight of the same shape (another module) is seen too.
  torch::nn::Linear other(6, 4);
  EXPECT_TRUE(torch::equal(cache.Of(other->weight), other->weight.t()));
  // A copy starts empty and answers for its own weight.
  TransposedWeightCache copy = cache;
  EXPECT_TRUE(torch::equal(copy.Of(linear->weight), linear->weight.t()));
  // A weight made under InferenceMode has no version counter: transposed afresh.
  torch::Tensor made_in_inference;
  {
    c10::InferenceMode inference;
    made_in_inference = torch::randn({4, 6});
  }
  EXPECT_TRUE(torch::equal(cache.Of(made_in_inference), made_in_inference.t()));
}

TEST(InferenceKernelsTest, SparseTreeConvHandlesEmptyAndAllEmptyNeighbourhoods) {
  if (!SparseTreeConvAvailable()) GTEST_SKIP() << "the loaded BLAS exports no sgemm_";
  torch::NoGradGuard no_grad;
  torch::nn::Linear linear(27 * 16, 8);
  torch::Tensor features = torch::randn({5, 16});
  // No rows at all, and a row whose 27 neighbours are all empty: only the bias.
  EXPECT_EQ(SparseTreeConvLinear(features, torch::empty({0, 27}, torch::kInt64), linear->weight,
                                 linear->bias)
                .sizes(),
            (std::vector<int64_t>{0, 8}));
  torch::Tensor lonely = torch::full({1, 27}, 5, torch::kInt64);
  EXPECT_TRUE(torch::equal(SparseTreeConvLinear(features, lonely, linear->weight, linear->bias),
                           linear->bias.reshape({1, 8})));
}

// The rulebook's result against Linear over the gathered rows (zero rows for empty neighbours).
void ExpectSparseEqualsGathered(const torch::Tensor& features, const torch::Tensor& neighbors,
                                const torch::Tensor& weight, const torch::Tensor& bias) {
  torch::NoGradGuard no_grad;
  torch::Tensor gathered = WithZeroRow(features)
                               .index_select(0, neighbors.reshape({-1}))
                               .reshape({neighbors.size(0), weight.size(1)});
  torch::Tensor expected = torch::matmul(gathered, weight.t());
  if (bias.defined()) expected += bias;
  torch::Tensor got = SparseTreeConvLinear(features, neighbors, weight, bias);
  ASSERT_EQ(got.sizes(), expected.sizes());
  EXPECT_TRUE(torch::allclose(got, expected, 1e-5, 1e-5));
}

// One output row: the output must be a tensor of its own, not a view of the bias (expanding a
// [1, C'] bias to one row and asking for a contiguous tensor returns the bias itself), or the
// sums would be written into the model.
TEST(InferenceKernelsTest, SparseTreeConvOfOneRowLeavesTheWeightsUntouched) {
  if (!SparseTreeConvAvailable()) GTEST_SKIP() << "the loaded BLAS exports no sgemm_";
  torch::manual_seed(31);
  torch::nn::Linear linear(27 * 16, 8);
  const torch::Tensor weight_before = linear->weight.detach().clone();
  const torch::Tensor bias_before = linear->bias.detach().clone();
  // A lone node (its centre itself, the direct GEMM) and one coarser row over five inputs.
  torch::Tensor lone = torch::full({1, 27}, 1, torch::kInt64);
  lone[0][13] = 0;
  torch::Tensor coarse = torch::full({1, 27}, 5, torch::kInt64);
  coarse[0][2] = 0;
  coarse[0][13] = 3;
  coarse[0][26] = 4;
  for (int call = 0; call < 2; ++call) {
    ExpectSparseEqualsGathered(torch::randn({1, 16}), lone, linear->weight, linear->bias);
    ExpectSparseEqualsGathered(torch::randn({5, 16}), coarse, linear->weight, linear->bias);
  }
  EXPECT_TRUE(torch::equal(linear->weight, weight_before));
  EXPECT_TRUE(torch::equal(linear->bias, bias_before));
}

TEST(InferenceKernelsTest, SparseTreeConvTakesACentreThatIsNotSelfAndNoBias) {
  if (!SparseTreeConvAvailable()) GTEST_SKIP() << "the loaded BLAS exports no sgemm_";
  torch::manual_seed(37);
  torch::nn::Linear linear(27 * 32, 24);
  torch::Tensor features = torch::randn({60, 32});
  // Every centre present but pointing at another row: the gathered path, not the direct GEMM.
  torch::Tensor neighbors = IndicesWithEmpty(60, 60, 27, 41);
  neighbors.index_put_({torch::indexing::Slice(), 13}, torch::randperm(60).roll(1));
  ExpectSparseEqualsGathered(features, neighbors, linear->weight, linear->bias);
  ExpectSparseEqualsGathered(features, neighbors, linear->weight, torch::Tensor());
}

// A batch of clouds convolved segment by segment gives each cloud what it gets alone, to every
// bit, and a neighbour in another cloud's rows is refused.
TEST(InferenceKernelsTest, SparseTreeConvBySegmentsEqualsEachCloudAlone) {
  if (!SparseTreeConvAvailable()) GTEST_SKIP() << "the loaded BLAS exports no sgemm_";
  torch::NoGradGuard no_grad;
  torch::manual_seed(53);
  torch::nn::Linear linear(27 * 32, 64);
  const std::vector<int64_t> sizes = {5, 300, 40};
  std::vector<torch::Tensor> features, neighbors;
  std::vector<int64_t> offsets = {0};
  for (size_t b = 0; b < sizes.size(); ++b) {
    features.push_back(torch::randn({sizes[b], 32}));
    neighbors.push_back(WithSelfAtCentre(IndicesWithEmpty(sizes[b], sizes[b], 27, 59 + b)));
    offsets.push_back(offsets.back() + sizes[b]);
  }
  const int64_t total = offsets.back();
  std::vector<torch::Tensor> shifted;
  for (size_t b = 0; b < sizes.size(); ++b) {
    torch::Tensor n = neighbors[b];
    shifted.push_back(torch::where(n == sizes[b], torch::full_like(n, total), n + offsets[b]));
  }
  const torch::Tensor all = torch::cat(shifted);
  const torch::Tensor batched =
      SparseTreeConvLinear(torch::cat(features), all, linear->weight, linear->bias, offsets);
  for (size_t b = 0; b < sizes.size(); ++b) {
    const torch::Tensor alone =
        SparseTreeConvLinear(features[b], neighbors[b], linear->weight, linear->bias);
    EXPECT_TRUE(torch::equal(batched.narrow(0, offsets[b], sizes[b]), alone)) << "cloud " << b;
  }
  torch::Tensor crossing = all.clone();
  crossing[0][0] = offsets[1];  // the first cloud's node pointing into the second cloud
  EXPECT_THROW(
      SparseTreeConvLinear(torch::cat(features), crossing, linear->weight, linear->bias, offsets),
      c10::Error);
}

TEST(InferenceKernelsTest, SparseTreeConvRejectsIndicesAndShapesItCannotUse) {
  if (!SparseTreeConvAvailable()) GTEST_SKIP() << "the loaded BLAS exports no sgemm_";
  torch::NoGradGuard no_grad;
  torch::nn::Linear linear(27 * 16, 8);
  torch::Tensor features = torch::randn({10, 16});
  torch::Tensor neighbors = torch::full({2, 27}, 10, torch::kInt64);
  neighbors[1][4] = 11;
  EXPECT_THROW(SparseTreeConvLinear(features, neighbors, linear->weight, linear->bias), c10::Error);
  neighbors[1][4] = -1;
  EXPECT_THROW(SparseTreeConvLinear(features, neighbors, linear->weight, linear->bias), c10::Error);
  EXPECT_THROW(
      SparseTreeConvLinear(features.to(torch::kFloat64), torch::full({2, 27}, 10, torch::kInt64),
                           linear->weight, linear->bias),
      c10::Error);
  torch::Tensor narrower = torch::randn({10, 8});
  EXPECT_THROW(SparseTreeConvLinear(narrower, torch::full({2, 27}, 10, torch::kInt64),
                                    linear->weight, linear->bias),
               c10::Error);
  // A weight by offset must be weight.t(): Linear's own layout, or doubles, are refused.
  const torch::Tensor all_empty = torch::full({2, 27}, 10, torch::kInt64);
  EXPECT_THROW(SparseTreeConvLinear(features, all_empty, linear->weight, linear->bias, {},
                                    linear->weight.contiguous()),
               c10::Error);
  EXPECT_THROW(SparseTreeConvLinear(features, all_empty, linear->weight, linear->bias, {},
                                    linear->weight.t().to(torch::kFloat64).contiguous()),
               c10::Error);
}

// A tree convolution and the pooling after it: the inference path gives the training path's
// features (inputs that carry a gradient take the generic gather and pooling).
TEST(InferenceKernelsTest, TreeConvolutionAndPoolingMatchTheTrainingPath) {
  // 6 input channels take the gathered GEMM at inference, 32 the rulebook (the network's depth-5
  // and depth-4 convolutions).
  for (int64_t channels : {6, 32}) {
    torch::manual_seed(9);
    TreeConv conv(channels, 32);
    conv->eval();
    torch::Tensor features = torch::randn({500, channels});
    torch::Tensor neighbors = WithSelfAtCentre(IndicesWithEmpty(500, 500, 27, 13));
    torch::Tensor slots = IndicesWithEmpty(300, 500, 8, 17);  // above the pooling's grain of 256
    torch::Tensor slow =
        PoolToParents(conv->forward(features.clone().requires_grad_(true), neighbors), slots);
    torch::Tensor fast;
    {
      torch::InferenceMode inference;
      fast = PoolToParents(conv->forward(features, neighbors), slots);
    }
    // The gathered GEMM is the training path's own operator; the rulebook sums in another order.
    const double tolerance = channels < 16 ? 1e-6 : 1e-5;
    EXPECT_TRUE(torch::allclose(fast, slow.detach(), tolerance, tolerance))
        << "channels " << channels;
  }
}

// Features without a gradient (an input, or a frozen earlier layer) still train a convolution
// whose weights want one: the rulebook, which computes no gradient, is not taken then.
TEST(InferenceKernelsTest, WeightsThatWantAGradientKeepTheDifferentiablePath) {
  torch::manual_seed(43);
  TreeConv conv(32, 16);
  torch::Tensor features = torch::randn({200, 32});  // no gradient of its own
  torch::Tensor neighbors = WithSelfAtCentre(IndicesWithEmpty(200, 200, 27, 47));
  conv->forward(features, neighbors).sum().backward();
  const torch::Tensor grad = conv->named_parameters()["linear.weight"].grad();
  ASSERT_TRUE(grad.defined());
  EXPECT_GT(grad.abs().sum().item<float>(), 0.0f);
}

// The rulebook's transposed weights (TransposedWeightCache) follow an optimiser's step: an
// inference after it gives what the differentiable path gives with the new weights.
TEST(InferenceKernelsTest, TreeConvAtInferenceFollowsAnOptimisersStep) {
  if (!SparseTreeConvAvailable()) GTEST_SKIP() << "the loaded BLAS exports no sgemm_";
  torch::manual_seed(44);
  TreeConv conv(32, 16);
  conv->eval();
  torch::Tensor features = torch::randn({120, 32});
  torch::Tensor neighbors = WithSelfAtCentre(IndicesWithEmpty(120, 120, 27, 53));
  auto inferred = [&] {
    torch::NoGradGuard no_grad;
    return conv->forward(features, neighbors);
  };
  const torch::Tensor before = inferred();
  torch::optim::Adam adam(conv->parameters(), torch::optim::AdamOptions(0.05));
  adam.zero_grad();
  conv->forward(features, neighbors).pow(2).sum().backward();
  adam.step();
  const torch::Tensor after = inferred();
  const torch::Tensor expected = conv->forward(features, neighbors).detach();  // differentiable
  EXPECT_FALSE(torch::allclose(before, after, 1e-3, 1e-3));
  EXPECT_TRUE(torch::allclose(after, expected, 1e-5, 1e-5));
}

}  // namespace
}  // namespace rpsr::core::net
