#include "core/net/dense_at_inference.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include "core/net/rulebook_kernel.h"

namespace rpsr::core::net {

namespace {

// A fresh [rows, out] tensor whose rows each hold bias[first, first + out); zeros without a bias.
torch::Tensor RowsOfBias(const torch::Tensor& bias, int64_t first, int64_t rows, int64_t out,
                         const torch::TensorOptions& options) {
  torch::Tensor y = torch::empty({rows, out}, options);
  float* yp = y.data_ptr<float>();
  if (!bias.defined()) {
    std::fill_n(yp, rows * out, 0.0f);
    return y;
  }
  const torch::Tensor b = bias.detach().contiguous();
  const float* bp = b.data_ptr<float>() + first;
  for (int64_t r = 0; r < rows; ++r) std::copy(bp, bp + out, yp + r * out);
  return y;
}

// rows x [rows, in] (contiguous) times columns [col, col + out) of weight_t [in, ldb] plus
// bias[col, col + out): a fresh [rows, out] tensor.
torch::Tensor DenseByKernel(const torch::Tensor& x, const torch::Tensor& weight_t, int64_t col,
                            int64_t out, const torch::Tensor& bias) {
  const int64_t in = x.size(-1);
  const int64_t rows = x.numel() / std::max<int64_t>(in, 1);
  torch::Tensor y = RowsOfBias(bias, col, rows, out, x.options());
  float* yp = y.data_ptr<float>();
  if (rows > 0 && in > 0) {
    DenseAddProducts(x.data_ptr<float>(), in, rows, weight_t.data_ptr<float>() + col,
                     weight_t.size(1), out, yp);
  }
  return y;
}

// The same through the BLAS (SgemmRowMajor) where rpsr's AVX2 kernel is not chosen (OpenBLAS's
// AVX-512 kernels): rows x [rows, in] (row stride in) times rows [row, row + out) of weight
// [*, in] (contiguous) transposed, plus bias[row, row + out): the bias copied into the output and
// added by the GEMM (beta 1), as torch::addmm computes a Linear.
torch::Tensor DenseByBlas(const float* x, int64_t rows, int64_t in, const torch::Tensor& weight,
                          int64_t row, int64_t out, const torch::Tensor& bias,
                          const torch::TensorOptions& options) {
  torch::Tensor y = RowsOfBias(bias, row, rows, out, options);
  // Without a bias the zeros are not read (beta 0), as torch::mm computes it.
  SgemmRowMajor(/*trans_a=*/false, /*trans_b=*/true, rows, out, in, 1.0f, x, in,
                weight.data_ptr<float>() + row * in, in, bias.defined() ? 1.0f : 0.0f,
                y.data_ptr<float>(), out);
  return y;
}

// Whether DenseByBlas serves `x` and an [out, in] weight: CPU float32 inference, a BLAS sgemm_.
bool DenseByBlasAvailable(const torch::Tensor& x, const torch::Tensor& weight) {
  return UseInferenceKernels(x) && UseInferenceKernels(weight) && weight.dim() == 2 &&
         x.dim() >= 1 && x.size(-1) == weight.size(1) && SparseTreeConvAvailable();
}

// MultiheadAttentionAtInference through the BLAS: each projection one GEMM (the three of a
// self-attention one), each head's scores and weighted values one GEMM on the projections' rows
// in place, the padding mask written into the scores, and one softmax over all heads' rows.
// LibTorch's multi_head_attention_forward (C++ API) took ~0.33 ms an object pair's call on
// 2-core AMD EPYC with AVX-512, of which its GEMMs ~0.1: the rest was some 25 operators' views,
// copies, equality tests of query and key, dispatch and allocations on 64 tokens. The same values
// bit for bit there for the network's shapes (64 tokens); LibTorch's bmm takes a plain loop below
// 400 products (tq tk head_dim), where the two agree within rounding only.
torch::Tensor AttentionByBlas(torch::nn::MultiheadAttentionImpl& attention,
                              const torch::Tensor& query, const torch::Tensor& key_value,
                              const torch::Tensor& key_padding_mask) {
  const int64_t e = attention.options.embed_dim();
  const int64_t heads = attention.options.num_heads();
  const int64_t head_dim = e / heads;
  const int64_t tq = query.size(0), tk = key_value.size(0), batch = query.size(1);
  const torch::Tensor weight = attention.in_proj_weight.detach().contiguous();  // [3E, E]
  const torch::Tensor& in_bias = attention.in_proj_bias;
  const torch::Tensor qc = query.contiguous();
  // A self-attention is the same tensor passed twice (as the Transformer passes it); LibTorch
  // tests equal values instead, so two equal but distinct tensors take two GEMMs here where it
  // takes one (the same values within rounding, not bit for bit).
  const bool self = query.is_same(key_value);
  const torch::Tensor kvc = self ? qc : key_value.contiguous();
  // Rows t * batch + b of each projection; a self-attention's three in one [T B, 3E].
  torch::Tensor q_rows, kv_rows;
  int64_t ldq, ldkv;
  const float* q;
  const float* k;
  const float* v;
  if (self) {
    q_rows =
        DenseByBlas(qc.data_ptr<float>(), tq * batch, e, weight, 0, 3 * e, in_bias, qc.options());
    ldq = ldkv = 3 * e;
    q = q_rows.data_ptr<float>();
    k = q + e;
    v = q + 2 * e;
  } else {
    q_rows = DenseByBlas(qc.data_ptr<float>(), tq * batch, e, weight, 0, e, in_bias, qc.options());
    kv_rows =
        DenseByBlas(kvc.data_ptr<float>(), tk * batch, e, weight, e, 2 * e, in_bias, kvc.options());
    ldq = e;
    ldkv = 2 * e;
    q = q_rows.data_ptr<float>();
    k = kv_rows.data_ptr<float>();
    v = k + e;
  }
  // The queries scaled by head_dim^-1/2 as LibTorch scales them: each projected value times the
  // factor in float (a float tensor times a double scalar), not the scores, so the same values
  // bit for bit.
  const float scaling = static_cast<float>(1.0 / std::sqrt(static_cast<double>(head_dim)));
  float* qw = q_rows.data_ptr<float>();
  for (int64_t r = 0; r < tq * batch; ++r) {
    for (int64_t c = 0; c < e; ++c) qw[r * ldq + c] *= scaling;
  }
  // Scores [batch, heads, tq, tk].
  torch::Tensor scores = torch::empty({batch * heads * tq, tk}, qc.options());
  float* sp = scores.data_ptr<float>();
  for (int64_t b = 0; b < batch; ++b) {
    for (int64_t h = 0; h < heads; ++h) {
      SgemmRowMajor(false, true, tq, tk, head_dim, 1.0f, q + b * ldq + h * head_dim, batch * ldq,
                    k + b * ldkv + h * head_dim, batch * ldkv, 0.0f, sp + (b * heads + h) * tq * tk,
                    tk);
    }
  }
  if (key_padding_mask.defined()) {
    TORCH_CHECK(key_padding_mask.dim() == 2 && key_padding_mask.size(0) == batch &&
                    key_padding_mask.size(1) == tk,
                "key_padding_mask must be [batch, keys] = [", batch, ", ", tk, "]");
    TORCH_CHECK(key_padding_mask.scalar_type() == torch::kBool ||
                    key_padding_mask.scalar_type() == torch::kUInt8,
                "key_padding_mask must be bool (or uint8), as the module's masked_fill wants");
    const torch::Tensor mask = key_padding_mask.to(torch::kBool).contiguous();
    const bool* mp = mask.data_ptr<bool>();
    constexpr float kMinusInf = -std::numeric_limits<float>::infinity();
    for (int64_t b = 0; b < batch; ++b) {
      for (int64_t j = 0; j < tk; ++j) {
        if (!mp[b * tk + j]) continue;
        for (int64_t row = b * heads * tq; row < (b + 1) * heads * tq; ++row)
          sp[row * tk + j] = kMinusInf;
      }
    }
  }
  const torch::Tensor weights = torch::softmax(scores, -1).contiguous();
  const float* wp = weights.data_ptr<float>();
  // The heads' weighted values side by side: rows t * batch + b, columns h * head_dim.
  torch::Tensor attended = torch::empty({tq * batch, e}, qc.options());
  float* ap = attended.data_ptr<float>();
  for (int64_t b = 0; b < batch; ++b) {
    for (int64_t h = 0; h < heads; ++h) {
      SgemmRowMajor(false, false, tq, head_dim, tk, 1.0f, wp + (b * heads + h) * tq * tk, tk,
                    v + b * ldkv + h * head_dim, batch * ldkv, 0.0f, ap + b * e + h * head_dim,
                    batch * e);
    }
  }
  const torch::Tensor out_weight = attention.out_proj->weight.detach().contiguous();
  return DenseByBlas(ap, tq * batch, e, out_weight, 0, e, attention.out_proj->bias, qc.options())
      .view({tq, batch, e});
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
  if (!DenseAtInferenceAvailable(x, linear.weight)) {
    if (!DenseByBlasAvailable(x, linear.weight)) return linear.forward(x);
    const int64_t out = linear.weight.size(0);
    const int64_t in = linear.weight.size(1);
    const torch::Tensor xc = x.contiguous();
    const torch::Tensor weight = linear.weight.detach().contiguous();
    return DenseByBlas(xc.data_ptr<float>(), xc.numel() / std::max<int64_t>(in, 1), in, weight, 0,
                       out, linear.bias, xc.options())
        .view(WithLast(x.sizes(), out));
  }
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
  const bool plain = !attention.is_training() && attention._qkv_same_embed_dim &&
                     !attention.bias_k.defined() && !attention.bias_v.defined() &&
                     !o.add_zero_attn() && query.dim() == 3 && key_value.dim() == 3 &&
                     key_value.size(2) == e && query.size(1) == key_value.size(1) &&
                     UseInferenceKernels(key_value);
  const bool by_kernel = plain && DenseAtInferenceAvailable(query, attention.in_proj_weight) &&
                         DenseAtInferenceAvailable(query, attention.out_proj->weight);
  if (!by_kernel) {
    if (plain && DenseByBlasAvailable(query, attention.in_proj_weight) &&
        DenseByBlasAvailable(query, attention.out_proj->weight)) {
      return AttentionByBlas(attention, query, key_value, key_padding_mask);
    }
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
