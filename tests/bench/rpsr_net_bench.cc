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
  static const TreePairs* pairs = [] {
    auto* out = new TreePairs;
    PairOptions options;
    options.num_points = 2048;
    options.split = ObjectSplit::kM2Unseen;
    for (int i = 0; i < 16; ++i) {
      auto pair = MakeObjectPair(options, 100 + i);
      if (!pair.ok()) std::abort();
      out->trees.push_back(*BuildOctree(pair->source));
      out->trees.push_back(*BuildOctree(pair->target));
    }
    return out;
  }();
  return *pairs;
}

const TreePairs& LidarTrees() {
  static const TreePairs* pairs = [] {
    auto* out = new TreePairs;
    LidarSequenceOptions options;
    options.frame_count = 40;
    auto simulator = LidarSequenceSimulator::Create(options);
    if (!simulator.ok()) std::abort();
    BarnesHutTreeOptions tree_options;
    tree_options.max_depth = 8;
    for (int i = 0; i < 4; ++i) {
      out->trees.push_back(*BuildOctree(simulator->SimulateFrame(5 * i).cloud, tree_options));
      out->trees.push_back(*BuildOctree(simulator->SimulateFrame(5 * i + 5).cloud, tree_options));
    }
    return out;
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

BENCHMARK_MAIN();
