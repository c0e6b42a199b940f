// One tree convolution at CPU inference, the two ways rpsr computes it: the 27 neighbours
// gathered into one [N, 27 C] matrix (zero rows for empty ones) and one GEMM, and the rulebook
// (SparseTreeConvLinear: the products per offset over the neighbours present, each offset's
// weight block read from the transposed weight TreeConv keeps, as the network runs it), by the
// AVX2 kernel where the CPU has one (rulebook_kernel.h) or by one BLAS GEMM per offset. The
// network takes the rulebook for inputs of 16 channels or more, and for all with the AVX2
// kernel (rpsr_modules.cc); this bench gives the ratios on the machine at hand, on the
// neighbourhoods of a real 2,048-point object's tree (depth 4: 32 -> 64 channels, depth 3:
// 64 -> 128, the network's widths).
#include <torch/torch.h>

#include <cstdlib>
#include <vector>

#include "benchmark/benchmark.h"
#include "core/net/inference_kernels.h"
#include "core/net/net_input.h"
#include "core/net/rpsr_modules.h"
#include "core/net/rpsr_net.h"
#include "core/net/rulebook_kernel.h"
#include "tests/bench/bench_clouds.h"
#include "tests/bench/blas_benchmark_main.h"

namespace rpsr::core::net {
namespace {

struct ConvCase {
  torch::Tensor features;   // [N, C]
  torch::Tensor neighbors;  // [N, 27], N for an empty neighbour
  torch::nn::Linear linear{nullptr};
  TransposedWeightCache weight_by_offset;  // as TreeConv keeps it
};

// depth 4 or 3 of the first object of the set rpsr_net_bench uses.
ConvCase& CaseAt(int depth) {
  static std::vector<ConvCase>* cases = [] {
    SetNetThreads(1);
    const std::vector<Octree> trees =
        bench::TreesOf(bench::UnseenObjectClouds(1, 2048), BarnesHutTreeOptions{});
    absl::StatusOr<NetCloudInput> input = MakeNetInput(trees.front());
    if (!input.ok()) std::abort();
    const PackedClouds packed = PackClouds({&*input});
    auto* out = new std::vector<ConvCase>(2);
    torch::manual_seed(1);
    for (int d : {3, 4}) {
      ConvCase& c = (*out)[d - 3];
      const int64_t channels = d == 4 ? 32 : 64;
      c.neighbors = packed.neighbors[d - 2];  // index 0 = depth 2
      c.features = torch::randn({c.neighbors.size(0), channels});
      c.linear = torch::nn::Linear(27 * channels, 2 * channels);
    }
    return out;
  }();
  return (*cases)[depth - 3];
}

void Counters(benchmark::State& state, const ConvCase& c) {
  state.counters["nodes"] = static_cast<double>(c.neighbors.size(0));
  state.counters["present_of_27"] = (c.neighbors != c.features.size(0)).sum().item<double>() /
                                    static_cast<double>(std::max<int64_t>(c.neighbors.size(0), 1));
}

void BM_TreeConvGathered(benchmark::State& state) {
  ConvCase& c = CaseAt(static_cast<int>(state.range(0)));
  torch::NoGradGuard no_grad;
  const int64_t width = 27 * c.features.size(1);
  for (auto _ : state) {
    torch::Tensor out = c.linear->forward(
        GatherRowsOrZero(c.features, c.neighbors).reshape({c.neighbors.size(0), width}));
    benchmark::DoNotOptimize(out.data_ptr<float>());
  }
  Counters(state, c);
}
BENCHMARK(BM_TreeConvGathered)->ArgName("depth")->Arg(4)->Arg(3)->Unit(benchmark::kMicrosecond);

// kernel:1 the AVX2 kernel (rulebook_kernel.h; skipped on CPUs without it), kernel:0 the BLAS
// GEMM per offset, whichever the network takes here (the header's "network products" says).
void BM_TreeConvRulebook(benchmark::State& state) {
  if (!SparseTreeConvAvailable()) {
    state.SkipWithError("the loaded BLAS exports no sgemm_");
    return;
  }
  ConvCase& c = CaseAt(static_cast<int>(state.range(0)));
  const bool kernel = state.range(1) != 0;
  if (kernel && !RulebookKernelSupported()) {
    state.SkipWithError("no AVX2 and FMA on this CPU");
    return;
  }
  SetRulebookKernelUse(kernel ? RulebookKernelUse::kOn : RulebookKernelUse::kOff);
  torch::NoGradGuard no_grad;
  for (auto _ : state) {
    torch::Tensor out =
        SparseTreeConvLinear(c.features, c.neighbors, c.linear->weight, c.linear->bias, {},
                             c.weight_by_offset.Of(c.linear->weight));
    benchmark::DoNotOptimize(out.data_ptr<float>());
  }
  SetRulebookKernelUse(RulebookKernelUse::kAuto);
  Counters(state, c);
}
BENCHMARK(BM_TreeConvRulebook)
    ->ArgNames({"depth", "kernel"})
    ->ArgsProduct({{4, 3}, {1, 0}})
    ->Unit(benchmark::kMicrosecond);

}  // namespace
}  // namespace rpsr::core::net

RPSR_BENCHMARK_MAIN_WITH_BLAS();
