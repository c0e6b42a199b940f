// The tree convolution's rulebook products without BLAS, on CPUs with AVX2 and FMA (private to
// core/net; SparseTreeConvLinear's fast path).
//
// Why: a rulebook offset is a small GEMM (50-560 rows, 16-64 channels in, 32-128 out). On AVX2
// hosts OpenBLAS has no small-matrix kernel (its SkylakeX/Cooperlake ones need AVX-512), so each
// of a convolution's 27 GEMMs packs its operands, and the rows are gathered into a buffer before
// and the products scattered back after. This kernel reads each pair's input row where it lies
// and adds its products straight into the output row, six rows at a time with the weights'
// 16-column slices in registers: no packing, no gather, no scatter. Each output value is summed
// in a fixed order (offset by offset, channel by channel, one rounding per fused multiply-add),
// whatever the rows' count or the batch, so a cloud's result does not depend on what shares
// its batch.
#ifndef RPSR_CORE_NET_RULEBOOK_KERNEL_H_
#define RPSR_CORE_NET_RULEBOOK_KERNEL_H_

#include <cstdint>

namespace rpsr::core::net {

// Whether RulebookAddProducts runs here: the CPU has AVX2 and FMA, `width` (output channels) is
// a positive multiple of 16, and the kernel is enabled. Otherwise callers keep the BLAS path.
bool RulebookKernelAvailable(int64_t width);

// The same kernel over dense rows: for each r < n, out[r] (`width` floats, rows `width` apart)
// += in[r] (`channels` floats, rows `channels` apart) * block, whose rows lie `ldb` floats apart
// (ldb >= width: a column slice of a wider matrix). A Linear layer's x W^T with block = W^T.
// Requires RulebookKernelAvailable(width).
void DenseAddProducts(const float* in, int64_t channels, int64_t n, const float* block, int64_t ldb,
                      int64_t width, float* out);

// On by default. Off, SparseTreeConvLinear takes its BLAS path everywhere: for tests and
// benchmarks that compare the two on one host (tree_conv_bench). Process-wide.
void SetRulebookKernelEnabled(bool enabled);

// For each pair p < n: out[out_rows[p]] += in[in_rows[p]] * block, where rows of `in` hold
// `channels` floats, rows of `out` `width` floats, and `block` is a row-major [channels, width]
// matrix (an offset's block of the convolution's weight.t()). The out_rows of one call must be
// distinct (one offset gives each output node at most one neighbour). Requires
// RulebookKernelAvailable(width).
void RulebookAddProducts(const float* in, int64_t channels, const int32_t* in_rows,
                         const int32_t* out_rows, int64_t n, const float* block, int64_t width,
                         float* out);

}  // namespace rpsr::core::net

#endif  // RPSR_CORE_NET_RULEBOOK_KERNEL_H_
