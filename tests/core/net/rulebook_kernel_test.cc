// The AVX2 rulebook kernel adds the products a plain loop in double adds (every tail of its
// six-row groups), the tree convolution through it equals the BLAS path within float rounding,
// and a cloud's rows come out the same to the bit whatever shares its batch. Skipped on CPUs
// without AVX2 and FMA, where the BLAS path is the only one.
#include "core/net/rulebook_kernel.h"

#include <torch/torch.h>

#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include "core/net/inference_kernels.h"
#include "gtest/gtest.h"
#include "tests/core/net/rulebook_kernel_use.h"

namespace rpsr::core::net {
namespace {

using KernelUse = testing::ScopedRulebookKernelUse;

// Neighbour indices into `rows` rows, about a third empty (== rows), the centre (slot 13) each
// node itself, as a same-depth tree convolution has it.
torch::Tensor SameDepthNeighbours(int64_t rows, uint64_t seed) {
  torch::manual_seed(seed);
  torch::Tensor idx = torch::randint(rows, {rows, 27}, torch::kInt64);
  idx = torch::where(torch::rand({rows, 27}) < 0.33, torch::full_like(idx, rows), idx);
  idx.select(1, 13).copy_(torch::arange(rows, torch::kInt64));
  return idx;
}

TEST(RulebookKernelTest, StepsAsideForOpenBlasSmallMatrixKernelsByDefault) {
  EXPECT_TRUE(AutoChoosesRulebookKernel(true, "Zen"));
  EXPECT_TRUE(AutoChoosesRulebookKernel(true, "Haswell"));  // also OPENBLAS_CORETYPE=Haswell
  EXPECT_TRUE(AutoChoosesRulebookKernel(true, nullptr));    // another BLAS
  EXPECT_FALSE(AutoChoosesRulebookKernel(true, "SkylakeX"));
  EXPECT_FALSE(AutoChoosesRulebookKernel(true, "Cooperlake"));
  EXPECT_FALSE(AutoChoosesRulebookKernel(true, "SapphireRapids"));
  EXPECT_FALSE(AutoChoosesRulebookKernel(false, "Zen"));
  EXPECT_FALSE(AutoChoosesRulebookKernel(false, nullptr));
  // The default says what it chose; kOff and kOn override it.
  EXPECT_EQ(RulebookKernelAvailable(32),
            std::string(RulebookKernelDescription()) == "rpsr AVX2 kernel");
  {
    const KernelUse off(RulebookKernelUse::kOff);
    EXPECT_FALSE(RulebookKernelAvailable(32));
  }
  const KernelUse on(RulebookKernelUse::kOn);
  EXPECT_EQ(RulebookKernelAvailable(32), RulebookKernelSupported());
}

TEST(RulebookKernelTest, AddsWhatADoubleLoopAddsForEveryTailOfItsRowGroups) {
  if (!RulebookKernelSupported()) GTEST_SKIP() << "no AVX2 and FMA on this CPU";
  const KernelUse on(RulebookKernelUse::kOn);  // on AVX-512 hosts too, where kAuto leaves it out
  EXPECT_TRUE(RulebookKernelAvailable(32));
  EXPECT_FALSE(RulebookKernelAvailable(40)) << "widths that are not multiples of 16 use BLAS";
  EXPECT_FALSE(RulebookKernelAvailable(0));
  constexpr int64_t kChannels = 7, kWidth = 32, kInRows = 20, kOutRows = 16;
  torch::manual_seed(3);
  const torch::Tensor in = torch::randn({kInRows, kChannels});
  const torch::Tensor block = torch::randn({kChannels, kWidth});
  const torch::Tensor start = torch::randn({kOutRows, kWidth});
  for (int64_t n = 0; n <= 13; ++n) {
    std::vector<int32_t> in_rows, out_rows;
    for (int64_t p = 0; p < n; ++p) {
      in_rows.push_back(static_cast<int32_t>((p * 7 + 3) % kInRows));
      out_rows.push_back(static_cast<int32_t>((p * 5 + 1) % kOutRows));  // distinct for p < 16
    }
    torch::Tensor out = start.clone();
    RulebookAddProducts(in.data_ptr<float>(), kChannels, in_rows.data(), out_rows.data(), n,
                        block.data_ptr<float>(), kWidth, out.data_ptr<float>());
    const auto a = in.accessor<float, 2>();
    const auto w = block.accessor<float, 2>();
    const auto s = start.accessor<float, 2>();
    const auto got = out.accessor<float, 2>();
    std::vector<bool> touched(kOutRows, false);
    for (int64_t p = 0; p < n; ++p) {
      touched[out_rows[p]] = true;
      for (int64_t col = 0; col < kWidth; ++col) {
        double expected = s[out_rows[p]][col];
        for (int64_t c = 0; c < kChannels; ++c) {
          expected += static_cast<double>(a[in_rows[p]][c]) * w[c][col];
        }
        EXPECT_NEAR(got[out_rows[p]][col], expected, 1e-5) << "n " << n << " pair " << p;
      }
    }
    for (int64_t r = 0; r < kOutRows; ++r) {
      if (!touched[r]) {
        EXPECT_TRUE(torch::equal(out[r], start[r])) << "n " << n << " row " << r;
      }
    }
  }
}

// The few-channel convolution in one pass equals the gathered rows times the Linear's weight (the
// path it replaces on the BLAS hosts) within float rounding, for the depth-5 inputs' 1 and 6
// channels and each width it takes, with and without a bias, and it steps aside where it cannot.
TEST(RulebookKernelTest, SmallChannelConvolutionEqualsTheGatheredLinear) {
  if (!RulebookKernelSupported()) GTEST_SKIP() << "no AVX2 and FMA on this CPU";
  torch::NoGradGuard no_grad;
  for (const int64_t channels : {1, 6}) {
    for (const int64_t width : {16, 32, 64}) {
      for (const bool with_bias : {true, false}) {
        const int64_t rows = 157;
        torch::manual_seed(31 + channels + width);
        const torch::Tensor x = torch::randn({rows, channels});
        const torch::Tensor nbr = SameDepthNeighbours(rows, 37 + width);
        torch::nn::Linear linear(torch::nn::LinearOptions(27 * channels, width).bias(with_bias));
        const torch::Tensor expected =
            linear->forward(GatherRowsOrZero(x, nbr).reshape({rows, -1}));
        ASSERT_TRUE(SmallChannelConvAvailable(channels, width));
        const torch::Tensor weight_t = linear->weight.t().contiguous();
        torch::Tensor got = torch::empty({rows, width});
        SmallChannelConvRows(x.data_ptr<float>(), channels, nbr.data_ptr<int64_t>(), rows, rows,
                             weight_t.data_ptr<float>(), width,
                             with_bias ? linear->bias.data_ptr<float>() : nullptr,
                             got.data_ptr<float>());
        EXPECT_TRUE(torch::allclose(got, expected, 1e-5, 1e-5))
            << channels << " channels, width " << width << (with_bias ? ", bias" : "")
            << ": largest difference " << (got - expected).abs().max().item<float>();
      }
    }
  }
  EXPECT_FALSE(SmallChannelConvAvailable(16, 32));
  EXPECT_FALSE(SmallChannelConvAvailable(6, 48));
  const KernelUse off(RulebookKernelUse::kOff);
  EXPECT_FALSE(SmallChannelConvAvailable(6, 32));
}

TEST(RulebookKernelTest, TreeConvolutionEqualsTheBlasPath) {
  if (!RulebookKernelSupported()) GTEST_SKIP() << "no AVX2 and FMA on this CPU";
  if (!SparseTreeConvAvailable()) GTEST_SKIP() << "the loaded BLAS exports no sgemm_";
  torch::NoGradGuard no_grad;
  // The shipped models' convolutions: 6 and 1 channels to 32 (depth 5), 32 to 64, 64 to 128.
  for (const auto& [channels, width] :
       std::vector<std::pair<int64_t, int64_t>>{{1, 32}, {6, 32}, {32, 64}, {64, 128}}) {
    torch::manual_seed(11 + channels);
    torch::nn::Linear linear(27 * channels, width);
    const torch::Tensor features = torch::randn({301, channels});
    const torch::Tensor neighbors = SameDepthNeighbours(301, 13 + channels);
    const torch::Tensor by_offset = linear->weight.t().contiguous();
    torch::Tensor kernel, blas;
    {
      const KernelUse on(RulebookKernelUse::kOn);
      kernel = SparseTreeConvLinear(features, neighbors, linear->weight, linear->bias, {0, 301},
                                    by_offset);
    }
    {
      const KernelUse off(RulebookKernelUse::kOff);
      blas = SparseTreeConvLinear(features, neighbors, linear->weight, linear->bias, {0, 301},
                                  by_offset);
    }
    ASSERT_EQ(kernel.sizes(), blas.sizes());
    EXPECT_TRUE(torch::allclose(kernel, blas, 1e-5, 1e-5)) << channels << " -> " << width;
    EXPECT_FALSE(torch::equal(kernel, torch::zeros_like(kernel)));
  }
}

TEST(RulebookKernelTest, ACloudInABatchComesOutAsAlone) {
  if (!RulebookKernelSupported()) GTEST_SKIP() << "no AVX2 and FMA on this CPU";
  if (!SparseTreeConvAvailable()) GTEST_SKIP() << "the loaded BLAS exports no sgemm_";
  const KernelUse on(RulebookKernelUse::kOn);
  torch::NoGradGuard no_grad;
  torch::manual_seed(17);
  torch::nn::Linear linear(27 * 32, 64);
  const torch::Tensor by_offset = linear->weight.t().contiguous();
  const std::vector<int64_t> sizes = {7, 250, 41};
  std::vector<torch::Tensor> features, neighbors, shifted;
  std::vector<int64_t> offsets = {0};
  for (size_t b = 0; b < sizes.size(); ++b) {
    features.push_back(torch::randn({sizes[b], 32}));
    neighbors.push_back(SameDepthNeighbours(sizes[b], 19 + b));
    offsets.push_back(offsets.back() + sizes[b]);
  }
  for (size_t b = 0; b < sizes.size(); ++b) {
    const torch::Tensor& n = neighbors[b];
    shifted.push_back(
        torch::where(n == sizes[b], torch::full_like(n, offsets.back()), n + offsets[b]));
  }
  const torch::Tensor batched = SparseTreeConvLinear(
      torch::cat(features), torch::cat(shifted), linear->weight, linear->bias, offsets, by_offset);
  for (size_t b = 0; b < sizes.size(); ++b) {
    const torch::Tensor alone = SparseTreeConvLinear(features[b], neighbors[b], linear->weight,
                                                     linear->bias, {0, sizes[b]}, by_offset);
    EXPECT_TRUE(torch::equal(batched.narrow(0, offsets[b], sizes[b]), alone)) << "cloud " << b;
  }
}

}  // namespace
}  // namespace rpsr::core::net
