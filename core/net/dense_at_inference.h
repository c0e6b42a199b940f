// The Transformer's and the token embedding's dense layers at CPU inference through the AVX2
// kernel of rulebook_kernel.h (private to core/net).
//
// Why: after the tree convolutions moved to that kernel, OpenBLAS's GEMMs were 23% of an object
// pair's network time on an AVX2 host (`perf`, rpsr_net_bench), all of them these layers: each
// pass's token embedding (64 tokens, 128 -> 128), the attention's projections (128 -> 384 and
// 128 -> 128) and the feed-forward (128 -> 256 -> 128), small GEMMs whose operands OpenBLAS packs
// at every call. The attention's own products (64 x 64 scores per head) stay LibTorch's bmm and
// softmax, as torch::nn::MultiheadAttention computes them.
#ifndef RPSR_CORE_NET_DENSE_AT_INFERENCE_H_
#define RPSR_CORE_NET_DENSE_AT_INFERENCE_H_

#include <torch/torch.h>

#include "core/net/inference_kernels.h"

namespace rpsr::core::net {

// x [..., in] times weight^T plus bias (weight [out, in] as torch::nn::Linear holds it; bias
// [out] or undefined): [..., out], as torch::nn::functional::linear, within float rounding.
// Through the kernel where DenseAtInferenceAvailable; otherwise torch's linear.
torch::Tensor LinearAtInference(const torch::Tensor& x, torch::nn::LinearImpl& linear,
                                TransposedWeightCache& weight_t);

// Whether LinearAtInference takes the kernel for `x` and an [out, in] weight: CPU float32, no
// gradient wanted (UseInferenceKernels of both) and RulebookKernelAvailable(out).
bool DenseAtInferenceAvailable(const torch::Tensor& x, const torch::Tensor& weight);

// A MultiheadAttention's weights transposed for the kernel, kept per module.
struct AttentionWeightsT {
  TransposedWeightCache in_proj;   // in_proj_weight.t(): [E, 3E]
  TransposedWeightCache out_proj;  // out_proj->weight.t(): [E, E]
};

// torch::nn::MultiheadAttention's output (need_weights false, no attention mask) for sequence-
// first query [Tq, B, E] and key = value [Tk, B, E] with key_padding_mask [B, Tk] (true: ignore;
// or undefined), its projections through the kernel: the same operations as LibTorch's
// multi_head_attention_forward otherwise (scaling by head_dim^-1/2, bmm, -inf masking, softmax,
// bmm), so the same values within float rounding. Falls back to the module's forward where the
// kernel is not available or the module uses what this path does not (separate key/value
// widths, bias_k/bias_v, add_zero_attn, training).
torch::Tensor MultiheadAttentionAtInference(torch::nn::MultiheadAttentionImpl& attention,
                                            const torch::Tensor& query,
                                            const torch::Tensor& key_value,
                                            const torch::Tensor& key_padding_mask,
                                            AttentionWeightsT& weights_t);

}  // namespace rpsr::core::net

#endif  // RPSR_CORE_NET_DENSE_AT_INFERENCE_H_
