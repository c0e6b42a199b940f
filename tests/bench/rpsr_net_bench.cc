// Inference speed of RPSRNet (all passes, trees given), one intra-op thread: 2,048-point object
// pairs and 120k-point simulated LiDAR pairs, at batch 1 and batch 16 (pairs of a batch share
// one forward pass per pass). Speed only: the LiDAR cases run the object model too (the
// architecture and so the cost are the same; there is no LiDAR model yet).
//
//   OMP_WAIT_POLICY=PASSIVE build/tests/bench/rpsr_net_bench --benchmark_counters_tabular=true
#include <cstdlib>
#include <memory>
#include <vector>

#include "benchmark/benchmark.h"
#include "core/data/object_pairs.h"
#include "core/net/rpsr_net.h"
#include "core/synth/lidar_sequence.h"
#include "tests/bench/bench_clouds.h"
#include "tests/bench/blas_benchmark_main.h"

namespace rpsr::core {
namespace {

const RpsrNet& ShippedModel() {
  static const RpsrNet* net = [] {
    SetNetThreads(1);
    auto loaded = RpsrNet::Load(std::string(RPSR_SOURCE_DIR) + "/core/models/objects/model.rpsrw");
    if (!loaded.ok()) std::abort();
    return loaded->release();
  }();
  return *net;
}

struct TreePairs {
  std::vector<Octree> trees;  // source, target, source, target, ...
  std::vector<NetPair> Pairs(size_t count) const {
    std::vector<NetPair> pairs;
    for (size_t i = 0; i < count; ++i) {
      const size_t k = i % (trees.size() / 2);
      pairs.push_back({&trees[2 * k], &trees[2 * k + 1]});
    }
    return pairs;
  }
};

const TreePairs& ObjectTrees() {
  static const TreePairs* pairs =
      new TreePairs{bench::TreesOf(bench::UnseenObjectClouds(16, 2048), BarnesHutTreeOptions{})};
  return *pairs;
}

const TreePairs& LidarTrees() {
  static const TreePairs* pairs = [] {
    LidarSequenceOptions options;
    options.frame_count = 40;
    BarnesHutTreeOptions tree_options;
    tree_options.max_depth = 8;
    return new TreePairs{
        bench::TreesOf(bench::LidarCloudsFiveFramesApart(4, options), tree_options)};
  }();
  return *pairs;
}

void RunEstimate(benchmark::State& state, const TreePairs& trees) {
  const RpsrNet& net = ShippedModel();
  const std::vector<NetPair> pairs = trees.Pairs(static_cast<size_t>(state.range(0)));
  for (auto _ : state) {
    auto estimates = net.Estimate(pairs);
    if (!estimates.ok()) state.SkipWithError("estimate failed");
    benchmark::DoNotOptimize(estimates);
  }
  state.counters["pairs_per_s"] = benchmark::Counter(
      static_cast<double>(pairs.size()) * state.iterations(), benchmark::Counter::kIsRate);
  state.counters["time_per_pair"] =
      benchmark::Counter(static_cast<double>(pairs.size()) * state.iterations(),
                         benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
}

void BM_NetObjects(benchmark::State& state) { RunEstimate(state, ObjectTrees()); }
BENCHMARK(BM_NetObjects)->ArgName("batch")->Arg(1)->Arg(16)->Unit(benchmark::kMillisecond);

void BM_NetLidar(benchmark::State& state) { RunEstimate(state, LidarTrees()); }
BENCHMARK(BM_NetLidar)->ArgName("batch")->Arg(1)->Arg(16)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace rpsr::core

RPSR_BENCHMARK_MAIN_WITH_BLAS();
