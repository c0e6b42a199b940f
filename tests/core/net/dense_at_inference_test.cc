// The dense layers at inference give what LibTorch's modules give: a Linear layer and
// multi-head attention (self and cross, with padded keys) within float rounding through the AVX2
// kernel and through the BLAS where the kernel does not run (no AVX2, a width it does not take,
// OpenBLAS's AVX-512 hosts), and exactly the module's output where a gradient is wanted.
#include "core/net/dense_at_inference.h"

#include <torch/torch.h>

#include "core/net/rulebook_kernel.h"
#include "gtest/gtest.h"
#include "tests/core/net/rulebook_kernel_use.h"

namespace rpsr::core::net {
namespace {

TEST(DenseAtInferenceTest, LinearEqualsTheModule) {
  torch::NoGradGuard no_grad;
  for (const bool bias : {true, false}) {
    torch::manual_seed(5);
    torch::nn::Linear linear(torch::nn::LinearOptions(40, 48).bias(bias));
    TransposedWeightCache weight_t;
    // A batch of token rows, as the embedding sees them, and a transposed (non-contiguous) view.
    const torch::Tensor x = torch::randn({3, 64, 40});
    for (const torch::Tensor& input : {x, x.transpose(0, 1)}) {
      const torch::Tensor got = LinearAtInference(input, *linear, weight_t);
      const torch::Tensor expected = linear->forward(input);
      ASSERT_EQ(got.sizes(), expected.sizes());
      EXPECT_TRUE(torch::allclose(got, expected, 1e-5, 1e-5)) << "bias " << bias;
    }
  }
  // A width the kernel does not take (not a multiple of 16): the module's own answer.
  torch::nn::Linear odd(40, 20);
  TransposedWeightCache odd_t;
  const torch::Tensor x = torch::randn({64, 40});
  EXPECT_TRUE(torch::equal(LinearAtInference(x, *odd, odd_t), odd->forward(x)));
}

// Sequence-first [T, B, E] inputs, the second cloud of the batch with its last keys padded.
struct AttentionCase {
  torch::Tensor query, key_value, mask;
};

AttentionCase MakeCase(int64_t tq, int64_t tk, int64_t e, uint64_t seed) {
  torch::manual_seed(seed);
  AttentionCase c;
  c.query = torch::randn({tq, 2, e});
  c.key_value = torch::randn({tk, 2, e});
  c.mask = torch::zeros({2, tk}, torch::kBool);
  c.mask.index_put_({1, torch::indexing::Slice(tk / 2, torch::indexing::None)}, true);
  return c;
}

// MultiheadAttentionAtInference against the module for the shipped models' widths (128 and 64,
// 4 heads) and the tests' (32): self-attention (query == key == value) and cross-attention, each
// with and without a mask, within float rounding (seeded from `seed`).
void ExpectAttentionLikeTheModule(uint64_t seed) {
  torch::NoGradGuard no_grad;
  for (const int64_t e : {128, 64, 32}) {
    torch::manual_seed(seed + e);
    torch::nn::MultiheadAttention attention(e, 4);
    attention->eval();
    AttentionWeightsT weights_t;
    const AttentionCase self = MakeCase(64, 64, e, seed + 2);
    const AttentionCase cross = MakeCase(64, 48, e, seed + 4);
    for (const bool masked : {true, false}) {
      for (const AttentionCase* c : {&self, &cross}) {
        const torch::Tensor& kv = c == &self ? c->query : c->key_value;
        const torch::Tensor mask = masked ? c->mask : torch::Tensor();
        const torch::Tensor got =
            MultiheadAttentionAtInference(*attention, c->query, kv, mask, weights_t);
        const torch::Tensor expected =
            std::get<0>(attention->forward(c->query, kv, kv, mask, false));
        ASSERT_EQ(got.sizes(), expected.sizes());
        EXPECT_TRUE(torch::allclose(got, expected, 1e-5, 1e-5))
            << "E " << e << (c == &self ? " self" : " cross") << (masked ? " masked" : "")
            << ": largest difference " << (got - expected).abs().max().item<float>();
        EXPECT_FALSE(torch::equal(got, torch::zeros_like(got)));
      }
    }
  }
}

TEST(DenseAtInferenceTest, AttentionEqualsTheModule) {
  if (!RulebookKernelSupported()) GTEST_SKIP() << "no AVX2 and FMA on this CPU";
  const testing::ScopedRulebookKernelUse on(RulebookKernelUse::kOn);  // AVX-512 hosts too
  ExpectAttentionLikeTheModule(7);
}

// Without rpsr's kernel (OpenBLAS's AVX-512 hosts, or turned off), the layers run on the BLAS
// directly: a Linear is torch::addmm's own call (the same values bit for bit), the attention the
// module's values, self and cross, masked or not, two clouds a batch: bit for bit on the 2-core
// AMD EPYC with AVX-512 that measured it (session 43), asserted within float rounding, as the
// BLAS may take other kernels for the module's batched products elsewhere.
TEST(DenseAtInferenceTest, WithoutTheKernelTheBlasGivesTheModulesValues) {
  const testing::ScopedRulebookKernelUse kernel_off(RulebookKernelUse::kOff);
  torch::NoGradGuard no_grad;
  for (const bool bias : {true, false}) {
    torch::manual_seed(3);
    torch::nn::Linear linear(torch::nn::LinearOptions(128, 256).bias(bias));
    TransposedWeightCache weight_t;
    const torch::Tensor x = torch::randn({64, 1, 128});
    EXPECT_TRUE(torch::equal(LinearAtInference(x, *linear, weight_t), linear->forward(x)))
        << "bias " << bias;
  }
  ExpectAttentionLikeTheModule(17);
  // The padded keys are left out: a query attending to a cloud whose second half is masked reads
  // the same as attending to its first half alone.
  torch::manual_seed(23);
  torch::nn::MultiheadAttention attention(32, 4);
  attention->eval();
  AttentionWeightsT weights_t;
  const AttentionCase c = MakeCase(16, 16, 32, 25);
  const torch::Tensor masked =
      MultiheadAttentionAtInference(*attention, c.query, c.key_value, c.mask, weights_t);
  const torch::Tensor first_half =
      MultiheadAttentionAtInference(*attention, c.query.narrow(1, 1, 1),
                                    c.key_value.narrow(0, 0, 8).narrow(1, 1, 1), {}, weights_t);
  EXPECT_TRUE(torch::allclose(masked.narrow(1, 1, 1), first_half, 1e-5, 1e-5));
  // A mask of the wrong shape or type is refused, as the module refuses it, not read past its end.
  EXPECT_THROW(MultiheadAttentionAtInference(*attention, c.query, c.key_value, c.mask.select(0, 1),
                                             weights_t),
               c10::Error);
  EXPECT_THROW(MultiheadAttentionAtInference(*attention, c.query, c.key_value,
                                             c.mask.to(torch::kFloat32), weights_t),
               c10::Error);
}

TEST(DenseAtInferenceTest, WithAGradientItIsTheModule) {
  torch::manual_seed(13);
  torch::nn::MultiheadAttention attention(32, 4);
  attention->eval();
  AttentionWeightsT weights_t;
  const AttentionCase c = MakeCase(16, 16, 32, 15);
  // A gradient wanted: the module's own (differentiable) computation.
  const torch::Tensor with_grad =
      MultiheadAttentionAtInference(*attention, c.query, c.key_value, c.mask, weights_t);
  EXPECT_TRUE(with_grad.requires_grad());
  torch::NoGradGuard no_grad;
  EXPECT_TRUE(torch::equal(with_grad, std::get<0>(attention->forward(c.query, c.key_value,
                                                                     c.key_value, c.mask, false))));
}

}  // namespace
}  // namespace rpsr::core::net
