#include "core/net/rpsr_modules.h"

#include <cmath>

#include "core/net/dense_at_inference.h"
#include "core/net/inference_kernels.h"
#include "core/net/rulebook_kernel.h"

namespace rpsr::core::net {
namespace {

// With BLAS, inputs narrower than this take the gathered GEMM at inference too: 27 GEMMs with an
// inner dimension of 1 (densities) or 6 (positions) cost more than one over the zero rows
// (measured, rpsr_net_bench: with every convolution on the rulebook objects took 14.2-14.3 ms a
// pair, with the depth-5 inputs gathered 13.7; all gathered 14.7; tests/bench/results/
// rulebook_conv_exploration.txt). The AVX2 kernel has no per-call cost to amortise and takes
// them all (tests/bench/notes/speed-notes.md, *An AVX2 rulebook kernel*).
constexpr int64_t kSparseConvMinChannels = 16;

// Copies `values` into a [rows, cols] int64 tensor, adding `offset` to valid indices and
// mapping -1 (no node) to `empty`, the row past the last node (a zero row in the gathers).
void AppendIndices(const std::vector<int32_t>& values, int64_t offset, int64_t empty,
                   int64_t* out) {
  for (size_t i = 0; i < values.size(); ++i) out[i] = values[i] < 0 ? empty : values[i] + offset;
}

torch::Tensor WithZeroRow(const torch::Tensor& features) {
  return torch::cat({features, torch::zeros({1, features.size(1)}, features.options())}, 0);
}

}  // namespace

PackedClouds PackClouds(const std::vector<const NetCloudInput*>& clouds) {
  PackedClouds packed;
  const int64_t batch = static_cast<int64_t>(clouds.size());
  packed.batch = batch;
  const auto f32 = torch::TensorOptions().dtype(torch::kFloat32);
  const auto i64 = torch::TensorOptions().dtype(torch::kInt64);
  std::array<std::vector<int64_t>, kNetDepths> offsets;
  std::array<int64_t, kNetDepths> totals{};
  for (int d = 0; d < kNetDepths; ++d) {
    for (const NetCloudInput* c : clouds) {
      offsets[d].push_back(totals[d]);
      totals[d] += c->depths[d].num_nodes;
    }
  }
  for (int d = 0; d < kNetDepths; ++d) {
    torch::Tensor position = torch::empty({totals[d], kNetPositionFeatures}, f32);
    torch::Tensor density = torch::empty({totals[d], kNetDensityFeatures}, f32);
    const bool has_neighbors = d >= 1;
    const bool has_children = d + 1 < kNetDepths;
    torch::Tensor neighbors = torch::empty({has_neighbors ? totals[d] : 0, 27}, i64);
    torch::Tensor children = torch::empty({has_children ? totals[d] : 0, 8}, i64);
    for (int64_t b = 0; b < batch; ++b) {
      const NetDepthInput& in = clouds[b]->depths[d];
      const int64_t start = offsets[d][b];
      std::copy(in.position.begin(), in.position.end(),
                position.data_ptr<float>() + start * kNetPositionFeatures);
      std::copy(in.density.begin(), in.density.end(),
                density.data_ptr<float>() + start * kNetDensityFeatures);
      if (has_neighbors)
        AppendIndices(in.neighbors, start, totals[d], neighbors.data_ptr<int64_t>() + start * 27);
      if (has_children) {
        AppendIndices(in.child_slots, offsets[d + 1][b], totals[d + 1],
                      children.data_ptr<int64_t>() + start * 8);
      }
    }
    packed.row_offsets[d] = offsets[d];
    packed.row_offsets[d].push_back(totals[d]);
    packed.position[d] = position;
    packed.density[d] = density;
    packed.neighbors[d] = neighbors;
    packed.child_slots[d] = children;
  }
  torch::Tensor token_node = torch::empty({batch, kNetTokens}, i64);
  torch::Tensor token_com = torch::empty({batch, kNetTokens, 3}, f32);
  torch::Tensor token_weight = torch::empty({batch, kNetTokens}, f32);
  for (int64_t b = 0; b < batch; ++b) {
    const NetCloudInput& c = *clouds[b];
    for (int s = 0; s < kNetTokens; ++s) {
      token_node.data_ptr<int64_t>()[b * kNetTokens + s] =
          c.token_node[s] < 0 ? totals[0] : c.token_node[s] + offsets[0][b];
    }
    std::copy(c.token_com.begin(), c.token_com.end(),
              token_com.data_ptr<float>() + b * kNetTokens * 3);
    std::copy(c.token_weight.begin(), c.token_weight.end(),
              token_weight.data_ptr<float>() + b * kNetTokens);
  }
  packed.token_node = token_node;
  packed.token_com = token_com;
  packed.token_weight = token_weight;
  packed.token_empty = token_node == totals[0];
  return packed;
}

PackedClouds PackedClouds::To(const torch::Device& device) const {
  PackedClouds out = *this;
  for (int d = 0; d < kNetDepths; ++d) {
    out.position[d] = position[d].to(device);
    out.density[d] = density[d].to(device);
    out.neighbors[d] = neighbors[d].to(device);
    out.child_slots[d] = child_slots[d].to(device);
  }
  out.token_node = token_node.to(device);
  out.token_com = token_com.to(device);
  out.token_weight = token_weight.to(device);
  out.token_empty = token_empty.to(device);
  return out;
}

TreeConvImpl::TreeConvImpl(int64_t in_channels, int64_t out_channels) : in_channels_(in_channels) {
  linear_ = register_module("linear", torch::nn::Linear(27 * in_channels, out_channels));
  norm_ = register_module("norm", torch::nn::BatchNorm1d(out_channels));
}

torch::Tensor TreeConvImpl::forward(const torch::Tensor& features, const torch::Tensor& neighbors,
                                    const std::vector<int64_t>& row_offsets) {
  // The rulebook computes no gradient: the weights must not want one either (features without
  // a gradient can meet weights that have one, e.g. when an earlier layer is frozen).
  if (UseInferenceKernels(features) && UseInferenceKernels(linear_->weight) &&
      (in_channels_ >= kSparseConvMinChannels ||
       RulebookKernelAvailable(linear_->weight.size(0))) &&
      SparseTreeConvAvailable()) {
    return torch::relu(
        norm_->forward(SparseTreeConvLinear(features, neighbors, linear_->weight, linear_->bias,
                                            row_offsets, weight_by_offset_.Of(linear_->weight))));
  }
  const int64_t rows = neighbors.size(0);
  if (UseInferenceKernels(features) && UseInferenceKernels(linear_->weight) &&
      SmallChannelConvAvailable(in_channels_, linear_->weight.size(0))) {
    // The gather and the GEMM in one pass over the present neighbours (rulebook_kernel.h).
    TORCH_CHECK(features.dim() == 2 && features.size(1) == in_channels_ && neighbors.dim() == 2 &&
                    neighbors.size(1) == 27,
                "features must be [N, ", in_channels_, "], neighbors [M, 27]");
    const torch::Tensor x = features.contiguous();
    const torch::Tensor nbr = neighbors.contiguous().to(torch::kInt64);
    const int64_t* idx = nbr.data_ptr<int64_t>();
    for (int64_t i = 0; i < nbr.numel(); ++i) {  // as GatherRowsOrZero checks them
      TORCH_CHECK(idx[i] >= 0 && idx[i] <= x.size(0), "neighbour index ", idx[i], " outside [0, ",
                  x.size(0), "]");
    }
    const torch::Tensor weight_t = weight_by_offset_.Of(linear_->weight);  // [27 C, width]
    const int64_t width = linear_->weight.size(0);
    torch::Tensor out = torch::empty({rows, width}, x.options());
    const torch::Tensor bias =
        linear_->bias.defined() ? linear_->bias.detach().contiguous() : torch::Tensor();
    TORCH_CHECK(SmallChannelConvRows(x.data_ptr<float>(), in_channels_, idx, rows, x.size(0),
                                     weight_t.data_ptr<float>(), width,
                                     bias.defined() ? bias.data_ptr<float>() : nullptr,
                                     out.data_ptr<float>()),
                "no few-channel convolution for ", width, " output channels");
    return torch::relu(norm_->forward(out));
  }
  torch::Tensor gathered = UseInferenceKernels(features)
                               ? GatherRowsOrZero(features, neighbors)
                               : WithZeroRow(features).index_select(0, neighbors.reshape({-1}));
  gathered = gathered.reshape({rows, 27 * in_channels_});
  return torch::relu(norm_->forward(linear_->forward(gathered)));
}

torch::Tensor PoolToParents(const torch::Tensor& child_features, const torch::Tensor& child_slots) {
  if (UseInferenceKernels(child_features)) return MaxOverSlots(child_features, child_slots);
  const int64_t parents = child_slots.size(0);
  const int64_t channels = child_features.size(1);
  // Children come out of a ReLU (>= 0), so the zero row of an empty slot never wins the max
  // unless all are 0.
  torch::Tensor gathered = WithZeroRow(child_features)
                               .index_select(0, child_slots.reshape({-1}))
                               .reshape({parents, 8, channels});
  return std::get<0>(gathered.max(1));
}

FeatureBranchImpl::FeatureBranchImpl(int64_t in_channels, const std::array<int, 3>& widths) {
  int64_t in = in_channels;
  for (int i = 0; i < 3; ++i) {
    convs_[i] = register_module("conv" + std::to_string(i), TreeConv(in, widths[i]));
    in = widths[i];
  }
}

torch::Tensor FeatureBranchImpl::forward(const PackedClouds& clouds, bool positions) {
  // Index 3 = depth 5, ..., 0 = depth 2.
  torch::Tensor x = positions ? clouds.position[3] : clouds.density[3];
  for (int i = 0; i < 3; ++i) {
    const int d = 3 - i;
    x = convs_[i]->forward(x, clouds.neighbors[d], clouds.row_offsets[d]);
    x = PoolToParents(x, clouds.child_slots[d - 1]);
  }
  return x;  // depth-2 nodes
}

HierarchicalEncoderImpl::HierarchicalEncoderImpl(const RpsrNetConfig& config) {
  position_branch_ =
      register_module("position_branch", FeatureBranch(kNetPositionFeatures, config.conv_widths));
  density_branch_ =
      register_module("density_branch", FeatureBranch(kNetDensityFeatures, config.conv_widths));
  to_embedding_ = register_module("to_embedding",
                                  torch::nn::Linear(config.conv_widths[2], config.embedding_width));
}

torch::Tensor HierarchicalEncoderImpl::forward(const PackedClouds& clouds) {
  torch::Tensor fused =
      position_branch_->forward(clouds, true) * density_branch_->forward(clouds, false);
  torch::Tensor tokens = (UseInferenceKernels(fused)
                              ? GatherRowsOrZero(fused, clouds.token_node)
                              : WithZeroRow(fused).index_select(0, clouds.token_node.reshape({-1})))
                             .reshape({clouds.batch, kNetTokens, fused.size(1)});
  torch::Tensor embedded = LinearAtInference(tokens, *to_embedding_, to_embedding_t_);
  // Empty tokens stay exactly zero (the bias would otherwise make them look alike and real).
  return embedded.masked_fill(clouds.token_empty.unsqueeze(-1), 0.0);
}

namespace {
torch::nn::Sequential FeedForward(int64_t width, int64_t hidden) {
  return torch::nn::Sequential(torch::nn::Linear(width, hidden), torch::nn::ReLU(),
                               torch::nn::Linear(hidden, width));
}
// The feed-forward block (Linear, ReLU, Linear) with each Linear through LinearAtInference: the
// kernel where it runs (dense_at_inference.h), the layer's own forward elsewhere.
torch::Tensor FeedForwardAt(torch::nn::Sequential& block, const torch::Tensor& x,
                            std::array<TransposedWeightCache, 2>& weights_t) {
  auto* first = block->ptr(0)->as<torch::nn::LinearImpl>();
  auto* second = block->ptr(2)->as<torch::nn::LinearImpl>();
  if (first == nullptr || second == nullptr) return block->forward(x);
  return LinearAtInference(torch::relu(LinearAtInference(x, *first, weights_t[0])), *second,
                           weights_t[1]);
}
torch::nn::LayerNorm Norm(int64_t width) {
  return torch::nn::LayerNorm(torch::nn::LayerNormOptions({width}));
}
}  // namespace

ContextTransformerImpl::ContextTransformerImpl(const RpsrNetConfig& config) {
  const int64_t e = config.embedding_width;
  const int64_t h = config.attention_heads;
  enc_norm1_ = register_module("enc_norm1", Norm(e));
  enc_norm2_ = register_module("enc_norm2", Norm(e));
  enc_attention_ = register_module("enc_attention", torch::nn::MultiheadAttention(e, h));
  enc_feedforward_ = register_module("enc_feedforward", FeedForward(e, config.feedforward_width));
  dec_norm1_ = register_module("dec_norm1", Norm(e));
  dec_norm2_ = register_module("dec_norm2", Norm(e));
  dec_norm3_ = register_module("dec_norm3", Norm(e));
  dec_self_attention_ = register_module("dec_self_attention", torch::nn::MultiheadAttention(e, h));
  dec_cross_attention_ =
      register_module("dec_cross_attention", torch::nn::MultiheadAttention(e, h));
  dec_feedforward_ = register_module("dec_feedforward", FeedForward(e, config.feedforward_width));
}

torch::Tensor ContextTransformerImpl::Memory(const torch::Tensor& y, const torch::Tensor& y_empty) {
  // Sequence-first [T, B, E].
  torch::Tensor memory = y.transpose(0, 1);
  torch::Tensor n = enc_norm1_->forward(memory);
  memory = memory + MultiheadAttentionAtInference(*enc_attention_, n, n, y_empty, enc_attention_t_);
  return memory + FeedForwardAt(enc_feedforward_, enc_norm2_->forward(memory), enc_feedforward_t_);
}

torch::Tensor ContextTransformerImpl::SelfAttended(const torch::Tensor& x,
                                                   const torch::Tensor& x_empty) {
  torch::Tensor z = x.transpose(0, 1);
  torch::Tensor n = dec_norm1_->forward(z);
  return z +
         MultiheadAttentionAtInference(*dec_self_attention_, n, n, x_empty, dec_self_attention_t_);
}

torch::Tensor ContextTransformerImpl::Attend(const torch::Tensor& self_attended,
                                             const torch::Tensor& memory,
                                             const torch::Tensor& memory_empty) {
  torch::Tensor n = dec_norm2_->forward(self_attended);
  torch::Tensor z =
      self_attended + MultiheadAttentionAtInference(*dec_cross_attention_, n, memory, memory_empty,
                                                    dec_cross_attention_t_);
  z = z + FeedForwardAt(dec_feedforward_, dec_norm3_->forward(z), dec_feedforward_t_);
  return z.transpose(0, 1);
}

std::pair<torch::Tensor, torch::Tensor> WeightedProcrustes(const torch::Tensor& src,
                                                           const torch::Tensor& tgt,
                                                           const torch::Tensor& weights) {
  torch::Tensor w = weights / weights.sum(1, true).clamp_min(1e-12);  // [B, T]
  torch::Tensor w3 = w.unsqueeze(-1);
  torch::Tensor src_mean = (w3 * src).sum(1, true);  // [B, 1, 3]
  torch::Tensor tgt_mean = (w3 * tgt).sum(1, true);
  torch::Tensor src_c = src - src_mean;
  torch::Tensor tgt_c = tgt - tgt_mean;
  // The SVD runs in double: its gradient has 1 / (s_i^2 - s_j^2) terms that overflow float32
  // for nearly symmetric correspondences and produced NaN steps in training.
  const auto dtype = src.scalar_type();
  torch::Tensor H = torch::matmul((w3 * src_c).transpose(1, 2), tgt_c).to(torch::kFloat64);
  torch::Tensor R;
  if (UseInferenceKernels(src) && !(torch::GradMode::is_enabled() && H.requires_grad())) {
    R = KabschRotation(H).to(dtype);
  } else {
    auto [U, S, Vh] = torch::linalg_svd(H, /*full_matrices=*/false, c10::nullopt);
    torch::Tensor V = Vh.transpose(1, 2);
    torch::Tensor Ut = U.transpose(1, 2);
    // Reflection fix: flip the last column of V where det(V U^T) < 0.
    torch::Tensor det = torch::linalg_det(torch::matmul(V, Ut));
    torch::Tensor ones = torch::ones_like(det);
    torch::Tensor diag =
        torch::stack({ones, ones, torch::sign(det) + (det == 0).to(det.dtype())}, 1);
    R = torch::matmul(V * diag.unsqueeze(1), Ut).to(dtype);
  }
  torch::Tensor t = tgt_mean.squeeze(1) - torch::matmul(R, src_mean.transpose(1, 2)).squeeze(-1);
  return {R, t};
}

RpsrNetworkImpl::RpsrNetworkImpl(const RpsrNetConfig& config) : config_(config) {
  encoder_ = register_module("encoder", HierarchicalEncoder(config));
  transformer_ = register_module("transformer", ContextTransformer(config));
}

EncodedTarget RpsrNetworkImpl::EncodeTarget(const PackedClouds& target) {
  EncodedTarget encoded;
  encoded.embedding = Encode(target);
  encoded.memory = transformer_->Memory(encoded.embedding, target.token_empty);
  encoded.self_attended = transformer_->SelfAttended(encoded.embedding, target.token_empty);
  return encoded;
}

PassOutput RpsrNetworkImpl::Pass(const PackedClouds& source, const PackedClouds& target,
                                 const EncodedTarget& encoded_target) {
  torch::Tensor fs = Encode(source);
  const torch::Tensor& ft = encoded_target.embedding;
  // = transformer_(fs, source, ft, target) and transformer_(ft, target, fs, source), with the
  // target-only steps taken from encoded_target.
  torch::Tensor src = fs + transformer_->Attend(transformer_->SelfAttended(fs, source.token_empty),
                                                encoded_target.memory, target.token_empty);
  torch::Tensor tgt =
      ft + transformer_->Attend(encoded_target.self_attended,
                                transformer_->Memory(fs, source.token_empty), source.token_empty);
  const double scale = 1.0 / std::sqrt(static_cast<double>(config_.embedding_width));
  torch::Tensor logits = torch::matmul(src, tgt.transpose(1, 2)) * scale;  // [B, T, T]
  logits = logits.masked_fill(target.token_empty.unsqueeze(1), -1e9);
  torch::Tensor scores = torch::softmax(logits, -1);
  torch::Tensor correspondences = torch::matmul(scores, target.token_com);  // [B, T, 3]
  auto [R, t] = WeightedProcrustes(source.token_com, correspondences, source.token_weight);
  return {R, t, scores};
}

}  // namespace rpsr::core::net
