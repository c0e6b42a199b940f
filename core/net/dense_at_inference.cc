#include "core/net/dense_at_inference.h"

#include <cmath>
#include <limits>
#include <vector>

#include "core/net/rulebook_kernel.h"

namespace rpsr::core::net {

namespace {

// rows x [rows, in] (contiguous) times columns [col, col + out) of weight_t [in, ldb] plus
// bias[col, col + out): a fresh [rows, out] tensor.
torch::Tensor DenseByKernel(const torch::Tensor& x, const torch::Tensor& weight_t, int64_t col,
                            int64_t out, const torch::Tensor& bias) {
  const int64_t in = x.size(-1);
  const int64_t rows = x.numel() / std::max<int64_t>(in, 1);
  torch::Tensor y = torch::empty({rows, out}, x.options());
  float* yp = y.data_ptr<float>();
  if (bias.defined()) {
    const torch::Tensor b = bias.detach().contiguous();
    const float* bp = b.data_ptr<float>() + col;
    for (int64_t r = 0; r < rows; ++r) std::copy(bp, bp + out, yp + r * out);
  } else {
    std::fill_n(yp, rows * out, 0.0f);
  }
  if (rows > 0 && in > 0) {
    DenseAddProducts(x.data_ptr<float>(), in, rows, weight_t.data_ptr<float>() + col,
                     weight_t.size(1), out, yp);
  }
  return y;
}

std::vector<int64_t> WithLast(torch::IntArrayRef sizes, int64_t last) {
  std::vector<int64_t> out(sizes.begin(), sizes.end());
  out.back() = last;
  return out;
}

}  // namespace

bool DenseAtInferenceAvailable(const torch::Tensor& x, const torch::Tensor& weight) {
  return UseInferenceKernels(x) && UseInferenceKernels(weight) && weight.dim() == 2 &&
         x.dim() >= 1 && x.size(-1) == weight.size(1) && RulebookKernelAvailable(weight.size(0));
}

torch::Tensor LinearAtInference(const torch::Tensor& x, torch::nn::LinearImpl& linear,
                                TransposedWeightCache& weight_t) {
  if (!DenseAtInferenceAvailable(x, linear.weight)) return linear.forward(x);
  const int64_t out = linear.weight.size(0);
  const torch::Tensor xc = x.contiguous();
  return DenseByKernel(xc, weight_t.Of(linear.weight), 0, out, linear.bias)
      .view(WithLast(x.sizes(), out));
}

torch::Tensor MultiheadAttentionAtInference(torch::nn::MultiheadAttentionImpl& attention,
                                            const torch::Tensor& query,
                                            const torch::Tensor& key_value,
                                            const torch::Tensor& key_padding_mask,
                                            AttentionWeightsT& weights_t) {
  const auto& o = attention.options;
  const int64_t e = o.embed_dim();
  const bool usable = !attention.is_training() && attention._qkv_same_embed_dim &&
                      !attention.bias_k.defined() && !attention.bias_v.defined() &&
                      !o.add_zero_attn() && query.dim() == 3 && key_value.dim() == 3 &&
                      key_value.size(2) == e && query.size(1) == key_value.size(1) &&
                      DenseAtInferenceAvailable(query, attention.in_proj_weight) &&
                      DenseAtInferenceAvailable(query, attention.out_proj->weight);
  if (!usable) {
    return std::get<0>(
        attention.forward(query, key_value, key_value, key_padding_mask, /*need_weights=*/false));
  }
  const int64_t heads = o.num_heads();
  const int64_t head_dim = e / heads;
  const int64_t tq = query.size(0), tk = key_value.size(0), batch = query.size(1);
  const torch::Tensor in_t = weights_t.in_proj.Of(attention.in_proj_weight);  // [E, 3E]
  const torch::Tensor& in_bias = attention.in_proj_bias;
  const torch::Tensor qc = query.contiguous();
  const torch::Tensor kvc = key_value.contiguous();
  // Columns [0, E) of W^T project queries, [E, 2E) keys, [2E, 3E) values.
  torch::Tensor q = DenseByKernel(qc, in_t, 0, e, in_bias);
  torch::Tensor k = DenseByKernel(kvc, in_t, e, e, in_bias);
  torch::Tensor v = DenseByKernel(kvc, in_t, 2 * e, e, in_bias);
  // From here as multi_head_attention_forward (LibTorch 1.13) computes it.
  q = q * (1 / std::sqrt(head_dim));
  q = q.view({tq, batch * heads, head_dim}).transpose(0, 1);
  k = k.view({tk, batch * heads, head_dim}).transpose(0, 1);
  v = v.view({tk, batch * heads, head_dim}).transpose(0, 1);
  torch::Tensor weights = torch::bmm(q, k.transpose(1, 2));
  if (key_padding_mask.defined()) {
    weights = weights.view({batch, heads, tq, tk})
                  .masked_fill(key_padding_mask.unsqueeze(1).unsqueeze(2),
                               -std::numeric_limits<float>::infinity())
                  .view({batch * heads, tq, tk});
  }
  weights = torch::softmax(weights, -1);
  const torch::Tensor attended =
      torch::bmm(weights, v).transpose(0, 1).contiguous().view({tq * batch, e});
  return DenseByKernel(attended, weights_t.out_proj.Of(attention.out_proj->weight), 0, e,
                       attention.out_proj->bias)
      .view({tq, batch, e});
}

}  // namespace rpsr::core::net
