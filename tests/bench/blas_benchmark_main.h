// BENCHMARK_MAIN for the benchmarks that run the network: the BLAS kernels decide much of its
// time (core/net/blas_info.h), so the benchmark's header names them (`blas: ...`), after
// matching them to the CPU as rpsrd and rpsr do (core/net/openblas_core_choice.h).
#ifndef RPSR_TESTS_BENCH_BLAS_BENCHMARK_MAIN_H_
#define RPSR_TESTS_BENCH_BLAS_BENCHMARK_MAIN_H_

#include "benchmark/benchmark.h"
#include "core/net/blas_info.h"
#include "core/net/openblas_core_choice.h"
#include "core/net/rulebook_kernel.h"

#define RPSR_BENCHMARK_MAIN_WITH_BLAS()                                                            \
  int main(int argc, char** argv) {                                                                \
    rpsr::core::net::MatchOpenBlasCoreToCpu();                                                     \
    benchmark::AddCustomContext("blas", rpsr::core::net::BlasDescription());                       \
    benchmark::AddCustomContext("network products", rpsr::core::net::RulebookKernelDescription()); \
    benchmark::Initialize(&argc, argv);                                                            \
    if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;                              \
    benchmark::RunSpecifiedBenchmarks();                                                           \
    benchmark::Shutdown();                                                                         \
    return 0;                                                                                      \
  }                                                                                                \
  static_assert(true, "a semicolon follows the macro")

#endif  // RPSR_TESTS_BENCH_BLAS_BENCHMARK_MAIN_H_
