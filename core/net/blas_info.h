// Which BLAS the network's matrix products run on, for logs and benchmark headers.
//
// Why: the tree convolutions' GEMMs are about half of an object pair's network time, and
// OpenBLAS picks its kernels once, when it is loaded, from the CPU or from OPENBLAS_CORETYPE.
// On this project's machine (AMD EPYC with AVX-512) OpenBLAS 0.3.21's own choice is its
// Cooperlake (AVX-512) kernels, but the environment forced OPENBLAS_CORETYPE=Haswell (AVX2),
// and the network ran 1.3x slower. A figure means little without saying which kernels made it.
#ifndef RPSR_CORE_NET_BLAS_INFO_H_
#define RPSR_CORE_NET_BLAS_INFO_H_

#include <string>

namespace rpsr::core::net {

// OpenBLAS's configuration string, which names the kernels chosen in this process (e.g.
// "OpenBLAS 0.3.21 NO_LAPACKE DYNAMIC_ARCH NO_AFFINITY USE_OPENMP Cooperlake MAX_THREADS=64"), with
// " (OPENBLAS_CORETYPE=<value>)" appended when the environment forces a core, " (chosen by rpsr
// for this CPU; OpenBLAS took it for <core>)" when MatchOpenBlasCoreToCpu switched it; or
// "not OpenBLAS" when no OpenBLAS is loaded (e.g. reference BLAS, see ../shared/DEPS.md).
std::string BlasDescription();

// OpenBLAS's chosen core (openblas_get_corename: "Zen", "Haswell", "SkylakeX", ...), or null when
// the loaded BLAS is not OpenBLAS. For choices that depend on its kernels (rulebook_kernel.h).
const char* OpenBlasCoreName();

}  // namespace rpsr::core::net

#endif  // RPSR_CORE_NET_BLAS_INFO_H_
