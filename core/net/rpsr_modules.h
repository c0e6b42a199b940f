// RPSRNet's LibTorch modules (private to core/net: include only from .cc files).
//
// Shapes: B pairs per batch, T = kNetTokens (64) tokens per cloud, E = embedding width. Node
// arrays of all clouds of a batch are packed (concatenated) per depth; index tensors already
// point into the packed arrays, with the value `rows` (one past the end) for "empty", which
// gathers an appended zero row ("zero filling" and "child filling" of the paper).
#ifndef RPSR_CORE_NET_RPSR_MODULES_H_
#define RPSR_CORE_NET_RPSR_MODULES_H_

#include <torch/torch.h>

#include <array>
#include <vector>

#include "core/net/dense_at_inference.h"
#include "core/net/inference_kernels.h"
#include "core/net/net_input.h"
#include "core/net/rpsr_net.h"

namespace rpsr::core::net {

// A batch of clouds as tensors (see PackClouds).
struct PackedClouds {
  int64_t batch = 0;
  std::array<torch::Tensor, kNetDepths> position;     // [N_d, 6] float
  std::array<torch::Tensor, kNetDepths> density;      // [N_d, 1] float
  std::array<torch::Tensor, kNetDepths> neighbors;    // [N_d, 27] int64 (depths 3..5)
  std::array<torch::Tensor, kNetDepths> child_slots;  // [N_d, 8] int64 into depth + 1 (2..4)
  // Per depth, each cloud's first row and N_d at the end (B + 1 values).
  std::array<std::vector<int64_t>, kNetDepths> row_offsets;
  torch::Tensor token_node;    // [B, T] int64 into depth 2
  torch::Tensor token_com;     // [B, T, 3] float
  torch::Tensor token_weight;  // [B, T] float
  torch::Tensor token_empty;   // [B, T] bool

  PackedClouds To(const torch::Device& device) const;
};

PackedClouds PackClouds(const std::vector<const NetCloudInput*>& clouds);

// Tree convolution: gather the 27 neighbours (zero for empty ones), one linear map over the
// gathered 27 x C_in values (= Conv1d with kernel 27, stride 27, but one GEMM: ~9x faster on CPU,
// see DEPS.md), BatchNorm, ReLU. At CPU inference, inputs of 16 channels or more skip the empty
// neighbours instead (SparseTreeConvLinear: the products per offset over the present ones), and
// every input does where the CPU has the AVX2 rulebook kernel (rulebook_kernel.h).
class TreeConvImpl : public torch::nn::Module {
 public:
  TreeConvImpl(int64_t in_channels, int64_t out_channels);
  // `row_offsets`: each cloud's first row and the row count (PackedClouds::row_offsets), so that
  // at inference each cloud is convolved on its own rows; empty: one cloud.
  torch::Tensor forward(const torch::Tensor& features, const torch::Tensor& neighbors,
                        const std::vector<int64_t>& row_offsets = {});

 private:
  int64_t in_channels_;
  torch::nn::Linear linear_{nullptr};
  torch::nn::BatchNorm1d norm_{nullptr};
  TransposedWeightCache weight_by_offset_;  // the rulebook's weight layout (inference only)
};
TORCH_MODULE(TreeConv);

// Max-pooling from children to parents through the label arrays.
torch::Tensor PoolToParents(const torch::Tensor& child_features, const torch::Tensor& child_slots);

// One branch of the hierarchical feature encoder (HPFE or HDFE): tree convolutions at depths 5,
// 4, 3 with max-pooling to the parent depth after each; returns features of the depth-2 nodes.
class FeatureBranchImpl : public torch::nn::Module {
 public:
  FeatureBranchImpl(int64_t in_channels, const std::array<int, 3>& widths);
  torch::Tensor forward(const PackedClouds& clouds, bool positions);

 private:
  std::array<TreeConv, 3> convs_{nullptr, nullptr, nullptr};  // depth 5, 4, 3
};
TORCH_MODULE(FeatureBranch);

// HFE: HPFE and HDFE fused by a Hadamard product at depth 2, Tree-to-Voxel into T tokens (empty
// ones zero), and a linear layer up to the embedding width. Output [B, T, E].
class HierarchicalEncoderImpl : public torch::nn::Module {
 public:
  explicit HierarchicalEncoderImpl(const RpsrNetConfig& config);
  torch::Tensor forward(const PackedClouds& clouds);

 private:
  FeatureBranch position_branch_{nullptr};
  FeatureBranch density_branch_{nullptr};
  torch::nn::Linear to_embedding_{nullptr};
  TransposedWeightCache to_embedding_t_;  // its weight.t() for dense_at_inference.h
};
TORCH_MODULE(HierarchicalEncoder);

// DCP-v2's Transformer: one pre-norm encoder block and one pre-norm decoder block, shared by
// both directions. Sequence-first inside (LibTorch 1.13 attention has no batch_first).
class ContextTransformerImpl : public torch::nn::Module {
 public:
  explicit ContextTransformerImpl(const RpsrNetConfig& config);
  // phi(x, y), the residual that makes x's embedding aware of y (x, y: [B, T, E]), is
  // Attend(SelfAttended(x, x_empty), Memory(y, y_empty), y_empty); the parts are separate so
  // that what depends on the target alone is computed once per pair, not once per pass.
  // The encoder block over y: the memory x attends to. [T, B, E] (sequence-first).
  torch::Tensor Memory(const torch::Tensor& y, const torch::Tensor& y_empty);
  // The decoder's self-attention step over x [B, T, E]: x plus its residual, [T, B, E].
  torch::Tensor SelfAttended(const torch::Tensor& x, const torch::Tensor& x_empty);
  // The decoder's cross-attention to `memory` and feed-forward; returns [B, T, E].
  torch::Tensor Attend(const torch::Tensor& self_attended, const torch::Tensor& memory,
                       const torch::Tensor& memory_empty);

 private:
  torch::nn::LayerNorm enc_norm1_{nullptr}, enc_norm2_{nullptr};
  torch::nn::MultiheadAttention enc_attention_{nullptr};
  torch::nn::Sequential enc_feedforward_{nullptr};
  torch::nn::LayerNorm dec_norm1_{nullptr}, dec_norm2_{nullptr}, dec_norm3_{nullptr};
  torch::nn::MultiheadAttention dec_self_attention_{nullptr}, dec_cross_attention_{nullptr};
  torch::nn::Sequential dec_feedforward_{nullptr};
  // The weights' transposes for the CPU inference path (dense_at_inference.h).
  AttentionWeightsT enc_attention_t_, dec_self_attention_t_, dec_cross_attention_t_;
  std::array<TransposedWeightCache, 2> enc_feedforward_t_, dec_feedforward_t_;
};
TORCH_MODULE(ContextTransformer);

// Weighted Procrustes (Kabsch with the reflection fix) of source points onto target points.
// src, tgt: [B, T, 3]; weights [B, T] (>= 0, not all 0 per row). Returns R [B, 3, 3], t [B, 3]
// with tgt ~ R src + t. Differentiable through torch::linalg_svd.
std::pair<torch::Tensor, torch::Tensor> WeightedProcrustes(const torch::Tensor& src,
                                                           const torch::Tensor& tgt,
                                                           const torch::Tensor& weights);

// One pass: HFE of the source (the target's is given, EncodedTarget), Transformer residuals,
// scores (Eq. 3) with empty target tokens masked, soft correspondences and the SVD head.
struct PassOutput {
  torch::Tensor rotation;     // [B, 3, 3], moved source -> target
  torch::Tensor translation;  // [B, 3]
  torch::Tensor scores;       // [B, T, T]
};

// What a pass needs of the target, fixed over passes: its embedding and the two Transformer
// steps that read the target alone (its encoder memory, its decoder self-attention).
struct EncodedTarget {
  torch::Tensor embedding;      // [B, T, E]
  torch::Tensor memory;         // [T, B, E]
  torch::Tensor self_attended;  // [T, B, E]
};

class RpsrNetworkImpl : public torch::nn::Module {
 public:
  explicit RpsrNetworkImpl(const RpsrNetConfig& config);
  torch::Tensor Encode(const PackedClouds& clouds) { return encoder_->forward(clouds); }
  EncodedTarget EncodeTarget(const PackedClouds& target);
  PassOutput Pass(const PackedClouds& source, const PackedClouds& target,
                  const EncodedTarget& encoded_target);
  const RpsrNetConfig& config() const { return config_; }

 private:
  RpsrNetConfig config_;
  HierarchicalEncoder encoder_{nullptr};
  ContextTransformer transformer_{nullptr};
};
TORCH_MODULE(RpsrNetwork);

}  // namespace rpsr::core::net

#endif  // RPSR_CORE_NET_RPSR_MODULES_H_
