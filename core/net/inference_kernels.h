// CPU inference versions of the network's gather, convolution, pooling and SVD steps (private to
// core/net).
//
// Why: at inference on CPU the tree convolutions' GEMMs are about half of a pass (LibTorch's
// profiler, one 2,048-point object pair); much of the rest was generic operators on small rows
// (index_select copies 1-128 floats per index through its iterator; max over the 8 child slots
// reduces along a strided dimension; linalg_svd and linalg_det loop over 3x3 matrices with
// per-matrix tensor views). These plain loops compute the same values (the gather and the max
// are exact copies and comparisons, NaN propagating like torch::max; the 3x3 SVD runs in double
// with Eigen instead of LAPACK, the same rotation wherever it is unique, i.e. H of rank >= 2)
// and are used only where no gradient is wanted and the tensors are on the CPU; training and
// CUDA keep the differentiable operators.
#ifndef RPSR_CORE_NET_INFERENCE_KERNELS_H_
#define RPSR_CORE_NET_INFERENCE_KERNELS_H_

#include <torch/torch.h>

#include <mutex>
#include <utility>
#include <vector>

namespace rpsr::core::net {

// True when `t` can take the kernels below: CPU float32, and no autograd graph is being built.
bool UseInferenceKernels(const torch::Tensor& t);

// rows[i] = features[indices[i]], or zeros where indices[i] == features.size(0).
// features [N, C] float, indices int64 of any shape with R elements; returns [R, C].
torch::Tensor GatherRowsOrZero(const torch::Tensor& features, const torch::Tensor& indices);

// The tree convolution's linear map, skipping empty neighbours instead of multiplying their
// zero rows: out[i] = bias + sum over k with neighbors[i, k] present of
// weight[:, kC:(k+1)C] features[neighbors[i, k]], the products offset by offset (a "rulebook",
// as sparse convolution libraries do): with `weight_by_offset` on a CPU with AVX2 and FMA by
// rulebook_kernel.h's kernel straight into the output rows, elsewhere one BLAS GEMM per offset.
// features [N, C] float, neighbors [M, 27] int64 with N for an empty neighbour, weight
// [C', 27 C] and bias [C'] (or undefined) as torch::nn::Linear holds them; returns [M, C']. The
// same sums as Linear over the gathered rows, in another order (equal within float rounding).
// Why: about half of a tree's neighbour slots are empty (an object's nodes have 14 of 27 present
// at depth 4, 8.5-13 at depth 3), so half of the gathered GEMM multiplies zeros.
// `segments`: the first row of each cloud of a batch and the row count at the end (same-depth
// rows, neighbours within their cloud), so that each cloud is convolved on its own rows and its
// result is the same whatever else is in the batch (BLAS chooses kernels by size); empty: one.
// `weight_by_offset`: weight.t().contiguous() ([27 C, C']), which a caller keeps between calls
// (TransposedWeightCache): each offset's block is then a plain matrix, which OpenBLAS packs
// faster than the transposed block it reads otherwise (a per-offset GEMM in 0.58-0.72x the time
// at 50-300 rows, about the same at 560; the same products); undefined:
// `weight` is read as it is.
torch::Tensor SparseTreeConvLinear(const torch::Tensor& features, const torch::Tensor& neighbors,
                                   const torch::Tensor& weight, const torch::Tensor& bias,
                                   const std::vector<int64_t>& segments = {},
                                   const torch::Tensor& weight_by_offset = {});

// weight.t().contiguous() for SparseTreeConvLinear, kept while the weight is unchanged: the same
// storage and version counter (every in-place write, a loaded state or an optimiser's step, bumps
// it). Safe for concurrent callers (the registrar's workers share one model); a copy (a cloned
// module) starts empty. A weight made under InferenceMode (no version counter) is transposed at
// every call.
class TransposedWeightCache {
 public:
  TransposedWeightCache() = default;
  TransposedWeightCache(const TransposedWeightCache&) {}
  TransposedWeightCache& operator=(const TransposedWeightCache&) { return *this; }
  torch::Tensor Of(const torch::Tensor& weight);

 private:
  std::mutex mutex_;
  torch::Tensor transposed_;
  const void* storage_ = nullptr;
  int64_t version_ = -1;
};

// False when the loaded BLAS exports no Fortran sgemm_ (SparseTreeConvLinear then throws).
bool SparseTreeConvAvailable();

// c (m x n, row-major, leading dimension ldc) = alpha op(a) op(b) + beta c, with op(a) m x k and
// op(b) k x n, each row-major as stored (transposed when trans_*): the loaded BLAS's Fortran
// sgemm_ on the transposed, column-major problem, the call torch::addmm makes for a Linear
// (a [rows, in] times weight [out, in] transposed). Only where SparseTreeConvAvailable().
void SgemmRowMajor(bool trans_a, bool trans_b, int64_t m, int64_t n, int64_t k, float alpha,
                   const float* a, int64_t lda, const float* b, int64_t ldb, float beta, float* c,
                   int64_t ldc);

// out[p] = max over the 8 slots of features[slots[p, k]], a slot equal to features.size(0)
// counting as a zero row. features [N, C] float, slots [P, 8] int64; returns [P, C].
torch::Tensor MaxOverSlots(const torch::Tensor& features, const torch::Tensor& slots);

// Rotation with the reflection fix from H = sum_i w_i src_i tgt_i^T (the Kabsch cross-covariance):
// R = V diag(1, 1, sign det(V U^T)) U^T. H [B, 3, 3] (any float type); returns R [B, 3, 3] double,
// all NaN for an H that is not finite (as the differentiable path's NaN would propagate).
torch::Tensor KabschRotation(const torch::Tensor& H);

}  // namespace rpsr::core::net

#endif  // RPSR_CORE_NET_INFERENCE_KERNELS_H_
