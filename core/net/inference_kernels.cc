#include "core/net/inference_kernels.h"

#include <ATen/Parallel.h>
#include <dlfcn.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <limits>
#include <memory>
#include <vector>

#include "Eigen/Core"
#include "Eigen/LU"
#include "Eigen/SVD"
#include "core/net/rulebook_kernel.h"

namespace rpsr::core::net {

bool UseInferenceKernels(const torch::Tensor& t) {
  return t.device().is_cpu() && t.scalar_type() == torch::kFloat32 &&
         !(torch::GradMode::is_enabled() && t.requires_grad());
}

namespace {

// Row i of `dst` = row idx[i] of `in`, or zeros for the index `rows`, for the rows [begin, end);
// rows of kChannels floats, or of `channels` when kChannels is 0. A row size known at compile
// time makes each copy a few moves: over a run-time count GCC turns even a hand-written loop
// into a memset or memcpy call per row (loop-idiom recognition), which cost the depth-5 gather's
// rows of 1-6 floats more than the copies (the empty neighbours' memsets alone were 1.5% of an
// object pair's network time).
template <int kChannels>
void GatherRowsOrZeroRange(const float* in, const int64_t* idx, int64_t rows, int64_t channels,
                           int64_t begin, int64_t end, float* dst) {
  const int64_t width = kChannels > 0 ? kChannels : channels;
  const size_t row_bytes = static_cast<size_t>(width) * sizeof(float);
  for (int64_t i = begin; i < end; ++i) {
    const int64_t k = idx[i];
    float* row = dst + i * width;
    if (k == rows) {
      std::memset(row, 0, row_bytes);
    } else {
      TORCH_CHECK(k >= 0 && k < rows, "gather index ", k, " outside [0, ", rows, "]");
      std::memcpy(row, in + k * width, row_bytes);
    }
  }
}

using GatherFunction = void (*)(const float*, const int64_t*, int64_t, int64_t, int64_t, int64_t,
                                float*);

// The gather for rows of `channels` floats: a fixed row size for 1 to 8 (the depth-5 inputs),
// the run-time one otherwise (wider rows are worth their memcpy call).
GatherFunction RowsOrZeroGatherFor(int64_t channels) {
  static constexpr std::array<GatherFunction, 9> kByWidth = {
      &GatherRowsOrZeroRange<0>, &GatherRowsOrZeroRange<1>, &GatherRowsOrZeroRange<2>,
      &GatherRowsOrZeroRange<3>, &GatherRowsOrZeroRange<4>, &GatherRowsOrZeroRange<5>,
      &GatherRowsOrZeroRange<6>, &GatherRowsOrZeroRange<7>, &GatherRowsOrZeroRange<8>};
  return channels >= 1 && channels <= 8 ? kByWidth[channels] : kByWidth[0];
}

}  // namespace

torch::Tensor GatherRowsOrZero(const torch::Tensor& features, const torch::Tensor& indices) {
  const torch::Tensor source = features.contiguous();
  const torch::Tensor index = indices.contiguous().to(torch::kInt64);
  const int64_t rows = source.size(0);
  const int64_t channels = source.size(1);
  const int64_t count = index.numel();
  torch::Tensor out = torch::empty({count, channels}, source.options());
  const float* in = source.data_ptr<float>();
  const int64_t* idx = index.data_ptr<int64_t>();
  float* dst = out.data_ptr<float>();
  const GatherFunction gather = RowsOrZeroGatherFor(channels);
  at::parallel_for(0, count, 2048, [&](int64_t begin, int64_t end) {
    gather(in, idx, rows, channels, begin, end, dst);
  });
  return out;
}

namespace {

// Fortran BLAS's sgemm, looked up at run time among the process's global symbols (rpsr links no
// BLAS itself; see BlasDescription): the BLAS LibTorch links, unless the application loaded
// another sgemm_ before it. Column-major, arguments by pointer.
using SgemmFunction = void (*)(const char* transa, const char* transb, const int* m, const int* n,
                               const int* k, const float* alpha, const float* a, const int* lda,
                               const float* b, const int* ldb, const float* beta, float* c,
                               const int* ldc);

SgemmFunction Sgemm() {
  static const SgemmFunction sgemm = reinterpret_cast<SgemmFunction>(dlsym(RTLD_DEFAULT, "sgemm_"));
  return sgemm;
}

// The weight of a tree convolution as the GEMMs read it: Linear's [width, 27 C] (each offset's
// block read transposed), or by offset, [27 C, width] (weight.t(): each offset's block is a plain
// column-major width x C matrix, which OpenBLAS packs faster: a per-offset GEMM in 0.58-0.72x the
// time at 50-300 rows, about the same at 560; the same products).
struct OffsetWeights {
  const float* data = nullptr;
  bool by_offset = false;
};

// rows x width (row-major, leading dimension ldc) += / = a (rows x C, row-major) times the
// block W_k = weight[:, kC:(k+1)C] transposed. In column-major terms: c^T (width x rows) =
// W_k (width x C) a^T.
void MultiplyByOffsetBlock(const float* a, int64_t rows, int64_t channels, OffsetWeights weight,
                           int offset, int64_t width, float beta, float* c) {
  const int m = static_cast<int>(width), n = static_cast<int>(rows);
  const int k = static_cast<int>(channels);
  const float one = 1.0f;
  if (weight.by_offset) {
    Sgemm()("N", "N", &m, &n, &k, &one, weight.data + offset * channels * width, &m, a, &k, &beta,
            c, &m);
    return;
  }
  const int lda = static_cast<int>(27 * channels);
  Sgemm()("T", "N", &m, &n, &k, &one, weight.data + offset * channels, &lda, a, &k, &beta, c, &m);
}

}  // namespace

bool SparseTreeConvAvailable() { return Sgemm() != nullptr; }

void SgemmRowMajor(bool trans_a, bool trans_b, int64_t m, int64_t n, int64_t k, float alpha,
                   const float* a, int64_t lda, const float* b, int64_t ldb, float beta, float* c,
                   int64_t ldc) {
  TORCH_CHECK(SparseTreeConvAvailable(), "no sgemm_ in the loaded BLAS");
  if (m <= 0 || n <= 0) return;
  // Row-major c = op(a) op(b) is column-major c^T = op(b)^T op(a)^T: b's storage read as
  // column-major is b^T, so op(b)^T is b^T as stored ('N') unless b is transposed ('T').
  const int cm = static_cast<int>(n), cn = static_cast<int>(m), ck = static_cast<int>(k);
  // BLAS refuses a leading dimension below 1 even where nothing is read (k = 0: c = beta c).
  const int la = static_cast<int>(std::max<int64_t>(1, lda));
  const int lb = static_cast<int>(std::max<int64_t>(1, ldb));
  const int lc = static_cast<int>(std::max<int64_t>(1, ldc));
  Sgemm()(trans_b ? "T" : "N", trans_a ? "T" : "N", &cm, &cn, &ck, &alpha, b, &lb, a, &la, &beta, c,
          &lc);
}

namespace {

// out's rows = in's rows `rows[0 .. n)`, of kChannels floats, or of `channels` when kChannels is
// 0. The rulebook's input widths in the shipped models (16, 32 and 64 channels) get a fixed row
// size, so that each copy is a few vector moves rather than a memcpy call (2% of an object pair's
// network time).
template <int kChannels>
void GatherRows(const float* in, const int32_t* rows, int64_t n, int64_t channels, float* out) {
  const int64_t width = kChannels > 0 ? kChannels : channels;
  for (int64_t r = 0; r < n; ++r) {
    std::memcpy(out + r * width, in + static_cast<int64_t>(rows[r]) * width,
                static_cast<size_t>(width) * sizeof(float));
  }
}

using RowGather = void (*)(const float*, const int32_t*, int64_t, int64_t, float*);

RowGather RowGatherFor(int64_t channels) {
  switch (channels) {
    case 16:
      return &GatherRows<16>;
    case 32:
      return &GatherRows<32>;
    case 64:
      return &GatherRows<64>;
    default:
      return &GatherRows<0>;
  }
}

// The rulebook convolution of the output rows [begin, end) of one cloud, whose neighbours lie in
// the input rows [in_begin, in_end) (`empty` marks an empty neighbour), added into `dst`, which
// holds the bias. The GEMMs see this cloud's rows only, so that a cloud's result does not depend
// on the others in its batch (BLAS picks its kernels by the matrices' sizes).
void ConvolveSegment(const float* in, const int64_t* idx, int64_t begin, int64_t end,
                     int64_t in_begin, int64_t in_end, int64_t empty, int64_t channels,
                     OffsetWeights wp, int64_t width, float* dst) {
  const int64_t rows = end - begin;
  // The rulebook: for each of the 27 offsets, the (output row, input row) pairs whose neighbour
  // is present, laid out offset after offset (a counting sort), in rows of this segment. Each
  // offset's run has one spare slot: the fill writes every slot it visits and moves on only where
  // the neighbour is present, so that it does not branch on presence (a coin flip: about half of
  // the slots are empty), and the spare takes a run's last absent write.
  std::array<int64_t, 27> count{};
  for (int64_t i = begin; i < end; ++i) {
    const int64_t* row = idx + i * 27;
    for (int k = 0; k < 27; ++k) count[k] += row[k] != empty;
  }
  std::array<int64_t, 28> start{};
  for (int k = 0; k < 27; ++k) start[k + 1] = start[k] + count[k] + 1;
  // Every slot read is written below: no zero-fill.
  const std::unique_ptr<int32_t[]> pair_out(new int32_t[start[27]]);
  const std::unique_ptr<int32_t[]> pair_in(new int32_t[start[27]]);
  std::array<int64_t, 27> next;
  std::copy(start.begin(), start.begin() + 27, next.begin());
  bool outside = false;
  for (int64_t i = begin; i < end; ++i) {
    const int64_t* row = idx + i * 27;
    for (int k = 0; k < 27; ++k) {
      const int64_t j = row[k];
      const bool present = j != empty;
      outside |= present & ((j < in_begin) | (j >= in_end));
      pair_out[next[k]] = static_cast<int32_t>(i - begin);
      pair_in[next[k]] = static_cast<int32_t>(j - in_begin);
      next[k] += present;
    }
  }
  if (outside) {
    for (int64_t i = begin * 27; i < end * 27; ++i) {
      TORCH_CHECK(idx[i] == empty || (idx[i] >= in_begin && idx[i] < in_end), "neighbour index ",
                  idx[i], " outside its cloud's rows [", in_begin, ", ", in_end, ")");
    }
  }
  const float* seg_in = in + in_begin * channels;
  float* seg_out = dst + begin * width;
  // With AVX2 (rulebook_kernel.h) every offset, the centre too, adds its products straight into
  // the output rows: no gather, no BLAS, no scatter.
  if (wp.by_offset && RulebookKernelAvailable(width)) {
    for (int k = 0; k < 27; ++k) {
      RulebookAddProducts(seg_in, channels, pair_in.get() + start[k], pair_out.get() + start[k],
                          count[k], wp.data + k * channels * width, width, seg_out);
    }
    return;
  }
  // The centre offset of a same-depth convolution is each node itself: one GEMM straight into
  // the output, with no gather and no scatter.
  bool centre_is_self = rows == in_end - in_begin;
  for (int64_t i = begin; i < end && centre_is_self; ++i) {
    centre_is_self = idx[i * 27 + 13] == in_begin + (i - begin);
  }
  if (centre_is_self && rows > 0) {
    MultiplyByOffsetBlock(seg_in, rows, channels, wp, 13, width, 1.0f, seg_out);
  }
  // Buffers for the largest offset, uninitialised (every row used is written first).
  int64_t most = 0;
  for (int k = 0; k < 27; ++k) most = std::max(most, count[k]);
  const std::unique_ptr<float[]> gathered(new float[most * channels]);
  const std::unique_ptr<float[]> product(new float[most * width]);
  const RowGather gather = RowGatherFor(channels);
  for (int k = 0; k < 27; ++k) {
    const int64_t n = count[k];
    if (n == 0 || (k == 13 && centre_is_self)) continue;
    const int32_t* out_rows = pair_out.get() + start[k];
    const int32_t* in_rows = pair_in.get() + start[k];
    gather(seg_in, in_rows, n, channels, gathered.get());
    // Zeroed here and added to (beta = 1) rather than overwritten (beta = 0): for beta != 1
    // OpenBLAS first scales C by a routine of its own, which took 5% of an object pair's network
    // time with its AVX2 (Zen) kernels; 0 + the products is what beta = 0 gives, bit for bit.
    std::fill_n(product.get(), n * width, 0.0f);
    MultiplyByOffsetBlock(gathered.get(), n, channels, wp, k, width, 1.0f, product.get());
    for (int64_t r = 0; r < n; ++r) {
      float* o = seg_out + static_cast<int64_t>(out_rows[r]) * width;
      const float* v = product.get() + r * width;
      for (int64_t c = 0; c < width; ++c) o[c] += v[c];
    }
  }
}

}  // namespace

torch::Tensor SparseTreeConvLinear(const torch::Tensor& features, const torch::Tensor& neighbors,
                                   const torch::Tensor& weight, const torch::Tensor& bias,
                                   const std::vector<int64_t>& segments,
                                   const torch::Tensor& weight_by_offset) {
  TORCH_CHECK(SparseTreeConvAvailable(), "no sgemm_ in the loaded BLAS");
  const torch::Tensor x = features.contiguous();
  const torch::Tensor nbr = neighbors.contiguous().to(torch::kInt64);
  const torch::Tensor w = weight.contiguous();
  TORCH_CHECK(x.dim() == 2 && nbr.dim() == 2 && nbr.size(1) == 27 && w.dim() == 2,
              "features must be [N, C], neighbors [M, 27], weight [C', 27 C]");
  TORCH_CHECK(x.scalar_type() == torch::kFloat32 && w.scalar_type() == torch::kFloat32,
              "features and weight must be float32");
  const int64_t rows_in = x.size(0);
  const int64_t channels = x.size(1);
  const int64_t rows_out = nbr.size(0);
  const int64_t width = w.size(0);
  TORCH_CHECK(w.size(1) == 27 * channels, "weight must be [C', 27 C] for C = ", channels);
  TORCH_CHECK(!bias.defined() || bias.numel() == width, "bias must have C' = ", width, " values");
  constexpr int64_t kIntMax = std::numeric_limits<int>::max();
  TORCH_CHECK(
      rows_in <= kIntMax && rows_out <= kIntMax && 27 * channels <= kIntMax && width <= kIntMax,
      "tree convolution too large for BLAS's int sizes");
  // Segments: one cloud's rows each (same rows in and out); none given: one segment, which may
  // have fewer output rows than input rows.
  std::vector<int64_t> bounds = segments;
  if (bounds.empty()) bounds = {0, rows_out};
  TORCH_CHECK(bounds.front() == 0 && bounds.back() == rows_out &&
                  std::is_sorted(bounds.begin(), bounds.end()) &&
                  (bounds.size() == 2 || rows_in == rows_out),
              "segments must run from 0 to the output rows, ascending, over same-depth rows");
  // A fresh tensor, never a view: with one row, expand(...).contiguous() would hand back the
  // bias's own storage, and the sums below would write into the model.
  torch::Tensor out = torch::zeros({rows_out, width}, x.options());
  if (bias.defined()) {
    const torch::Tensor b = bias.detach().to(torch::kFloat32).contiguous();
    const float* bp = b.data_ptr<float>();
    float* op = out.data_ptr<float>();
    for (int64_t i = 0; i < rows_out; ++i) std::copy(bp, bp + width, op + i * width);
  }
  OffsetWeights wp{w.data_ptr<float>(), false};
  torch::Tensor by_offset;
  if (weight_by_offset.defined()) {
    by_offset = weight_by_offset.contiguous();
    TORCH_CHECK(by_offset.scalar_type() == torch::kFloat32 && by_offset.dim() == 2 &&
                    by_offset.size(0) == 27 * channels && by_offset.size(1) == width,
                "weight_by_offset must be float32 [27 C, C'] (weight.t()) for C = ", channels,
                ", C' = ", width);
    wp = {by_offset.data_ptr<float>(), true};
  }
  // No products to add (and BLAS rejects zero leading dimensions).
  if (rows_out == 0 || channels == 0 || width == 0) return out;
  const int64_t* idx = nbr.data_ptr<int64_t>();
  const float* in = x.data_ptr<float>();
  float* dst = out.data_ptr<float>();
  // One segment reads every input row (which may be more than its output rows); a batch's
  // segments read their own rows.
  const bool whole = bounds.size() == 2;
  for (size_t s = 0; s + 1 < bounds.size(); ++s) {
    ConvolveSegment(in, idx, bounds[s], bounds[s + 1], whole ? 0 : bounds[s],
                    whole ? rows_in : bounds[s + 1], rows_in, channels, wp, width, dst);
  }
  return out;
}

torch::Tensor TransposedWeightCache::Of(const torch::Tensor& weight) {
  // A weight made under InferenceMode has no version counter to tell its changes by.
  if (weight.is_inference()) return weight.detach().t().contiguous();
  std::lock_guard<std::mutex> lock(mutex_);
  const void* storage = weight.data_ptr();
  const int64_t version = weight._version();
  if (!transposed_.defined() || storage != storage_ || version != version_) {
    transposed_ = weight.detach().t().contiguous();
    storage_ = storage;
    version_ = version;
  }
  return transposed_;
}

torch::Tensor MaxOverSlots(const torch::Tensor& features, const torch::Tensor& slots) {
  const torch::Tensor source = features.contiguous();
  const torch::Tensor index = slots.contiguous().to(torch::kInt64);
  TORCH_CHECK(index.dim() == 2 && index.size(1) == 8, "slots must be [P, 8]");
  const int64_t rows = source.size(0);
  const int64_t channels = source.size(1);
  const int64_t parents = index.size(0);
  torch::Tensor out = torch::empty({parents, channels}, source.options());
  const float* in = source.data_ptr<float>();
  const int64_t* idx = index.data_ptr<int64_t>();
  float* dst = out.data_ptr<float>();
  at::parallel_for(0, parents, 256, [&](int64_t begin, int64_t end) {
    for (int64_t p = begin; p < end; ++p) {
      float* o = dst + p * channels;
      for (int s = 0; s < 8; ++s) {
        const int64_t k = idx[p * 8 + s];
        TORCH_CHECK(k >= 0 && k <= rows, "slot index ", k, " outside [0, ", rows, "]");
        if (s == 0) {
          if (k == rows) {
            std::fill(o, o + channels, 0.0f);
          } else {
            std::copy(in + k * channels, in + (k + 1) * channels, o);
          }
          continue;
        }
        // Selects rather than branches, so that the compiler vectorises the channel loops (as
        // branches they were a tenth of an object pair's network time).
        if (k == rows) {
          for (int64_t c = 0; c < channels; ++c) {
            const float current = o[c];
            o[c] = current < 0.0f ? 0.0f : current;  // an empty child is a zero row; NaN stays
          }
        } else {
          const float* r = in + k * channels;
          // NaN wins, as in torch::max (v != v: NaN).
          for (int64_t c = 0; c < channels; ++c) {
            const float v = r[c];
            const float current = o[c];
            o[c] = (v > current || v != v) ? v : current;
          }
        }
      }
    }
  });
  return out;
}

torch::Tensor KabschRotation(const torch::Tensor& H) {
  const torch::Tensor h = H.to(torch::kFloat64).contiguous();
  const int64_t batch = h.size(0);
  torch::Tensor out = torch::empty({batch, 3, 3}, h.options());
  using RowMajor3d = Eigen::Matrix<double, 3, 3, Eigen::RowMajor>;
  for (int64_t b = 0; b < batch; ++b) {
    const Eigen::Map<const RowMajor3d> m(h.data_ptr<double>() + 9 * b);
    Eigen::Map<RowMajor3d> R(out.data_ptr<double>() + 9 * b);
    if (!m.allFinite()) {
      R.setConstant(std::numeric_limits<double>::quiet_NaN());
      continue;
    }
    const Eigen::JacobiSVD<Eigen::Matrix3d> svd(Eigen::Matrix3d(m),
                                                Eigen::ComputeFullU | Eigen::ComputeFullV);
    const Eigen::Matrix3d& U = svd.matrixU();
    Eigen::Matrix3d V = svd.matrixV();
    const double det = (V * U.transpose()).determinant();
    // Same rule as the differentiable path: flip the last column of V where det < 0.
    if (det < 0) V.col(2) = -V.col(2);
    R = V * U.transpose();
  }
  return out;
}

}  // namespace rpsr::core::net
