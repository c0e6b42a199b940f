#include "core/net/rulebook_kernel.h"

#include <immintrin.h>
#include <strings.h>

#include <atomic>

#include "core/net/blas_info.h"

namespace rpsr::core::net {

namespace {

std::atomic<RulebookKernelUse> kernel_use{RulebookKernelUse::kAuto};

bool CpuHasAvx2Fma() {
  static const bool has = __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
  return has;
}

bool KernelChosen() {
  switch (kernel_use.load(std::memory_order_relaxed)) {
    case RulebookKernelUse::kOn:
      return CpuHasAvx2Fma();
    case RulebookKernelUse::kOff:
      return false;
    case RulebookKernelUse::kAuto:
      break;
  }
  static const bool chosen = AutoChoosesRulebookKernel(CpuHasAvx2Fma(), OpenBlasCoreName());
  return chosen;
}

}  // namespace

// Only the functions below, up to pop_options, are compiled for AVX2 and FMA; the project's
// baseline stays x86-64, and they run only where CpuHasAvx2Fma() said so.
#pragma GCC push_options
#pragma GCC target("avx2,fma")

namespace {

// kRows output rows (distinct) += their input rows times `block` (rows `ldb` floats apart), 16
// columns at a time: 2 x kRows accumulators, the block's two column vectors and one broadcast
// input value in registers (15 of AVX2's 16 for six rows).
template <int kRows>
void AddRowsTimesBlock(const float* const* a, float* const* o, int64_t channels, const float* block,
                       int64_t ldb, int64_t width) {
  for (int64_t col = 0; col < width; col += 16) {
    __m256 lo[kRows], hi[kRows];
    for (int r = 0; r < kRows; ++r) {
      lo[r] = _mm256_loadu_ps(o[r] + col);
      hi[r] = _mm256_loadu_ps(o[r] + col + 8);
    }
    const float* w = block + col;
    for (int64_t c = 0; c < channels; ++c, w += ldb) {
      const __m256 w_lo = _mm256_loadu_ps(w);
      const __m256 w_hi = _mm256_loadu_ps(w + 8);
      for (int r = 0; r < kRows; ++r) {
        const __m256 x = _mm256_broadcast_ss(a[r] + c);
        lo[r] = _mm256_fmadd_ps(x, w_lo, lo[r]);
        hi[r] = _mm256_fmadd_ps(x, w_hi, hi[r]);
      }
    }
    for (int r = 0; r < kRows; ++r) {
      _mm256_storeu_ps(o[r] + col, lo[r]);
      _mm256_storeu_ps(o[r] + col + 8, hi[r]);
    }
  }
}

// Pairs p < n, six at a time and the rest by a kernel of their count; `rows(p, a, o)` sets pair
// p's input and output row pointers.
template <typename Rows>
void AddProducts(int64_t n, int64_t channels, const float* block, int64_t ldb, int64_t width,
                 Rows rows) {
  constexpr int kGroup = 6;
  const float* a[kGroup];
  float* o[kGroup];
  int64_t p = 0;
  for (; p + kGroup <= n; p += kGroup) {
    for (int r = 0; r < kGroup; ++r) rows(p + r, a[r], o[r]);
    AddRowsTimesBlock<kGroup>(a, o, channels, block, ldb, width);
  }
  // The last 1-5 pairs by the kernel of their count.
  using Tail =
      void (*)(const float* const*, float* const*, int64_t, const float*, int64_t, int64_t);
  static constexpr Tail kTail[kGroup] = {nullptr,
                                         &AddRowsTimesBlock<1>,
                                         &AddRowsTimesBlock<2>,
                                         &AddRowsTimesBlock<3>,
                                         &AddRowsTimesBlock<4>,
                                         &AddRowsTimesBlock<5>};
  const int left = static_cast<int>(n - p);
  if (left == 0) return;
  for (int r = 0; r < left; ++r) rows(p + r, a[r], o[r]);
  kTail[left](a, o, channels, block, ldb, width);
}

}  // namespace

void RulebookAddProducts(const float* in, int64_t channels, const int32_t* in_rows,
                         const int32_t* out_rows, int64_t n, const float* block, int64_t width,
                         float* out) {
  AddProducts(n, channels, block, width, width, [&](int64_t p, const float*& a, float*& o) {
    a = in + static_cast<int64_t>(in_rows[p]) * channels;
    o = out + static_cast<int64_t>(out_rows[p]) * width;
  });
}

void DenseAddProducts(const float* in, int64_t channels, int64_t n, const float* block, int64_t ldb,
                      int64_t width, float* out) {
  AddProducts(n, channels, block, ldb, width, [&](int64_t p, const float*& a, float*& o) {
    a = in + p * channels;
    o = out + p * width;
  });
}

namespace {

// SmallChannelConvRows for kVectors x 8 output channels: each output row's sums in kVectors
// registers, the neighbours' few input values broadcast.
template <int kVectors>
void SmallChannelConvRowsOf(const float* in, int64_t channels, const int64_t* neighbors,
                            int64_t rows, int64_t empty, const float* weight_t, const float* bias,
                            float* out) {
  constexpr int64_t kWidth = 8 * kVectors;
  for (int64_t i = 0; i < rows; ++i) {
    __m256 acc[kVectors];
    for (int v = 0; v < kVectors; ++v) acc[v] = _mm256_setzero_ps();
    const int64_t* nbr = neighbors + i * 27;
    for (int k = 0; k < 27; ++k) {
      const int64_t j = nbr[k];
      if (j == empty) continue;  // a zero row adds nothing to the sums
      const float* x = in + j * channels;
      const float* w = weight_t + k * channels * kWidth;
      for (int64_t c = 0; c < channels; ++c, w += kWidth) {
        const __m256 xv = _mm256_broadcast_ss(x + c);
        for (int v = 0; v < kVectors; ++v) {
          acc[v] = _mm256_fmadd_ps(xv, _mm256_loadu_ps(w + 8 * v), acc[v]);
        }
      }
    }
    float* o = out + i * kWidth;
    for (int v = 0; v < kVectors; ++v) {
      const __m256 b = bias != nullptr ? _mm256_loadu_ps(bias + 8 * v) : _mm256_setzero_ps();
      _mm256_storeu_ps(o + 8 * v, _mm256_add_ps(acc[v], b));
    }
  }
}

}  // namespace

bool SmallChannelConvRows(const float* in, int64_t channels, const int64_t* neighbors, int64_t rows,
                          int64_t empty, const float* weight_t, int64_t width, const float* bias,
                          float* out) {
  switch (width) {
    case 16:
      SmallChannelConvRowsOf<2>(in, channels, neighbors, rows, empty, weight_t, bias, out);
      return true;
    case 32:
      SmallChannelConvRowsOf<4>(in, channels, neighbors, rows, empty, weight_t, bias, out);
      return true;
    case 64:
      SmallChannelConvRowsOf<8>(in, channels, neighbors, rows, empty, weight_t, bias, out);
      return true;
    default:
      return false;
  }
}

#pragma GCC pop_options

bool RulebookKernelSupported() { return CpuHasAvx2Fma(); }

bool SmallChannelConvAvailable(int64_t channels, int64_t width) {
  return CpuHasAvx2Fma() && kernel_use.load(std::memory_order_relaxed) != RulebookKernelUse::kOff &&
         channels >= 1 && channels <= 8 && (width == 16 || width == 32 || width == 64);
}

bool AutoChoosesRulebookKernel(bool cpu_has_avx2_fma, const char* openblas_core) {
  if (!cpu_has_avx2_fma) return false;
  if (openblas_core == nullptr) return true;
  for (const char* avx512 : {"skylakex", "cooperlake", "sapphirerapids"}) {
    if (strcasecmp(openblas_core, avx512) == 0) return false;  // its small-matrix kernels
  }
  return true;
}

void SetRulebookKernelUse(RulebookKernelUse use) {
  kernel_use.store(use, std::memory_order_relaxed);
}

bool RulebookKernelAvailable(int64_t width) {
  return width > 0 && width % 16 == 0 && KernelChosen();
}

const char* RulebookKernelDescription() {
  if (KernelChosen()) return "rpsr AVX2 kernel";
  if (!CpuHasAvx2Fma()) return "BLAS (no AVX2 and FMA for rpsr's kernel)";
  if (kernel_use.load(std::memory_order_relaxed) == RulebookKernelUse::kOff) {
    return "BLAS (rpsr's kernel turned off)";
  }
  return "BLAS (OpenBLAS's AVX-512 small-matrix kernels)";
}

}  // namespace rpsr::core::net
