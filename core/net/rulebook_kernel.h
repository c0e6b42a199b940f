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

// Where the kernel runs (SetRulebookKernelUse). kAuto, the default: on CPUs with AVX2 and FMA,
// unless the loaded BLAS is OpenBLAS running its AVX-512 kernels (SkylakeX, Cooperlake,
// SapphireRapids), whose small-matrix GEMMs skip the packing: there the BLAS path ran an object's
// depth-4 / depth-3 convolution in 301-317 / 101-103 us (session 19's Intel host), this kernel
// 414 / 175 us on an AVX2 host of about the same AVX2 peak, i.e. likely slower there. kOn: wherever
// the CPU can run it (tests, and benchmarks comparing both on one host). kOff: never.
enum class RulebookKernelUse { kAuto, kOn, kOff };
void SetRulebookKernelUse(RulebookKernelUse use);  // process-wide

// Whether the CPU can run the kernel (AVX2 and FMA).
bool RulebookKernelSupported();

// kAuto's rule, given the CPU's AVX2-and-FMA and OpenBLAS's chosen core (openblas_get_corename;
// null when the BLAS is not OpenBLAS). Separate so that tests can state it for any host.
bool AutoChoosesRulebookKernel(bool cpu_has_avx2_fma, const char* openblas_core);

// Whether RulebookAddProducts and DenseAddProducts run here for `width` output channels: the
// kernel is chosen (above) and `width` is a positive multiple of 16. Otherwise callers keep the
// BLAS path.
bool RulebookKernelAvailable(int64_t width);

// In words, for benchmark headers and logs: "rpsr AVX2 kernel", or why the BLAS does the work.
const char* RulebookKernelDescription();

// The same kernel over dense rows: for each r < n, out[r] (`width` floats, rows `width` apart)
// += in[r] (`channels` floats, rows `channels` apart) * block, whose rows lie `ldb` floats apart
// (ldb >= width: a column slice of a wider matrix). A Linear layer's x W^T with block = W^T.
// Requires RulebookKernelAvailable(width).
void DenseAddProducts(const float* in, int64_t channels, int64_t n, const float* block, int64_t ldb,
                      int64_t width, float* out);

// For each pair p < n: out[out_rows[p]] += in[in_rows[p]] * block, where rows of `in` hold
// `channels` floats, rows of `out` `width` floats, and `block` is a row-major [channels, width]
// matrix (an offset's block of the convolution's weight.t()). The out_rows of one call must be
// distinct (one offset gives each output node at most one neighbour). Requires
// RulebookKernelAvailable(width).
void RulebookAddProducts(const float* in, int64_t channels, const int32_t* in_rows,
                         const int32_t* out_rows, int64_t n, const float* block, int64_t width,
                         float* out);

// A tree convolution of few input channels (the depth-5 inputs: 1 and 6) in one pass, for the
// BLAS path's hosts, where it is otherwise a gather of each node's 27 neighbour rows into a
// [rows, 27 C] matrix (a zero row for an empty neighbour) and a GEMM: out[i] (`width` floats) =
// the sum over k < 27 with neighbors[i, k] != `empty` and c < channels of in[neighbors[i, k], c]
// times weight_t[k C + c] (row-major [27 C, width], the Linear's weight transposed), in that
// order, one rounding per fused multiply-add from zero, then plus bias (or nothing when null):
// the order OpenBLAS's AVX-512 (Cooperlake) kernel sums that GEMM in on session 43's host, with
// the bias added as torch::addmm adds it, so the same values there; elsewhere within rounding.
// Neighbour indices must lie in [0, empty]. Requires SmallChannelConvAvailable(channels, width);
// false (nothing written) for another width.
bool SmallChannelConvRows(const float* in, int64_t channels, const int64_t* neighbors, int64_t rows,
                          int64_t empty, const float* weight_t, int64_t width, const float* bias,
                          float* out);

// Whether SmallChannelConvRows runs here: AVX2 and FMA, the kernel not turned off
// (SetRulebookKernelUse(kOff)), 1-8 channels in and 16, 32 or 64 out.
bool SmallChannelConvAvailable(int64_t channels, int64_t width);

}  // namespace rpsr::core::net

#endif  // RPSR_CORE_NET_RULEBOOK_KERNEL_H_
