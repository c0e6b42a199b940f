// OpenBLAS's kernels matched to the CPU where OpenBLAS does not recognise it.
//
// Why: OpenBLAS picks its kernels once, when it is loaded, from the CPU's family and model.
// Debian 12's OpenBLAS 0.3.21 predates Intel's newer Xeons (an Emerald Rapids, family 6 model
// 207, is taken for a Prescott: SSE3 kernels), so on them the network's matrix products run on
// its slowest x86-64 kernels although the CPU has AVX-512. Newer OpenBLAS releases choose by the
// CPU's features where the model is unknown; this does the same for the one loaded here: on a
// CPU with AVX2 and FMA whose OpenBLAS core has no AVX2 kernels, it switches to Cooperlake
// (AVX-512 with BF16), SkylakeX (AVX-512) or Haswell (AVX2), as OPENBLAS_CORETYPE would at load.
// On session 30's Emerald Rapids host: objects net+refine 0.88x and LiDAR 0.94x the time (medians
// of CPU time, alternated runs), the network alone 0.80-0.98x (tests/bench/notes/speed-notes.md,
// *OpenBLAS on CPUs it does not know*).
//
// A core forced by OPENBLAS_CORETYPE is always respected, and a core OpenBLAS chose with AVX2
// kernels or better (Haswell, Zen, SkylakeX, Cooperlake, ...) is kept: only a failed detection
// is corrected.
#ifndef RPSR_CORE_NET_OPENBLAS_CORE_CHOICE_H_
#define RPSR_CORE_NET_OPENBLAS_CORE_CHOICE_H_

#include <optional>
#include <string>

#include "absl/strings/string_view.h"

namespace rpsr::core::net {

// The instruction sets that decide which OpenBLAS kernels a CPU can run.
struct CpuVectorFeatures {
  bool avx2_fma = false;
  bool avx512 = false;  // F, CD, BW, DQ and VL: what OpenBLAS's SkylakeX kernels need
  bool avx512_bf16 = false;
};

// This CPU's features (cpuid, through the compiler's __builtin_cpu_supports).
CpuVectorFeatures DetectCpuVectorFeatures();

// The rule: the core OpenBLAS should run instead of `openblas_core` (its own choice, as
// openblas_get_corename names it) on a CPU with `cpu`'s features, or nullopt where its choice
// stands (it has AVX2 kernels or better, or the CPU has no AVX2 and FMA).
std::optional<std::string> BetterOpenBlasCore(absl::string_view openblas_core,
                                              const CpuVectorFeatures& cpu);

// What MatchOpenBlasCoreToCpu did.
struct OpenBlasCoreChoice {
  std::string detected;  // the core OpenBLAS chose when loaded ("" when no OpenBLAS is loaded)
  std::string running;   // the core it runs now
  bool switched = false;
  std::string reason;  // one line for logs: why it switched or why not
};

// Applies BetterOpenBlasCore to the loaded OpenBLAS, unless OPENBLAS_CORETYPE is set. Call it at
// the start of main, before any thread can be in a BLAS call (rpsrd, the rpsr command line and
// the benchmarks do): the switch re-runs OpenBLAS's own start-up selection, which is not safe
// against concurrent calls. A no-op without OpenBLAS, or when called again.
OpenBlasCoreChoice MatchOpenBlasCoreToCpu();

// Switches the loaded OpenBLAS to `core` (a name OPENBLAS_CORETYPE takes) as if the variable had
// been set at load; false when no OpenBLAS is loaded or it does not run `core` afterwards. The
// same caveat as above; for MatchOpenBlasCoreToCpu and tests.
bool SwitchOpenBlasCore(const std::string& core);

// The core rpsr switched OpenBLAS away from (for BlasDescription), nullopt when it did not.
std::optional<std::string> OpenBlasCoreSwitchedFrom();

}  // namespace rpsr::core::net

#endif  // RPSR_CORE_NET_OPENBLAS_CORE_CHOICE_H_
