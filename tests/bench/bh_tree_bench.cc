// Speed and memory of building Barnes-Hut trees: a simulated 120k-point LiDAR scan (the service's
// main load) and a 2,048-point object. Counters: nodes in the tree,
// bytes it holds, and bytes_vs_xyz = tree bytes / raw float32 xyz bytes (what the session cache
// pays per cloud).
//
//   build/tests/bench/bh_tree_bench --benchmark_counters_tabular=true
#include <cmath>
#include <cstdlib>
#include <random>
#include <vector>

#include "benchmark/benchmark.h"
#include "core/synth/lidar_sequence.h"
#include "core/tree/bh_tree.h"

namespace rpsr::core {
namespace {

// A simulated HDL-64E scan of an urban street (core/synth's simulator: facades, cars, poles,
// trees, ground), the service's main load: frame 10 of a seeded sequence, simulated with 2,400
// azimuth steps (~140k points) and thinned by an even stride to exactly `num_points`.
PointCloud SimulatedUrbanScan(size_t num_points) {
  LidarSequenceOptions options;
  options.frame_count = 20;
  options.seed = 1;
  options.sensor.azimuth_steps = 2400;
  auto simulator = LidarSequenceSimulator::Create(options);
  if (!simulator.ok()) std::abort();
  const PointCloud full = simulator->SimulateFrame(10).cloud;
  if (full.size() < num_points) std::abort();
  PointCloud cloud;
  for (size_t i = 0; i < num_points; ++i) {
    cloud.points.push_back(full.points[i * full.size() / num_points]);
  }
  return cloud;
}

// A 2,048-point object: a noisy torus-knot-like closed curve thickened into a tube, in [-1, 1].
PointCloud MakeObject(int num_points, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<float> unit(0.0f, 1.0f);
  PointCloud cloud;
  for (int i = 0; i < num_points; ++i) {
    const float u = 2.0f * M_PI * unit(rng);
    const float v = 2.0f * M_PI * unit(rng);
    const float r = 0.6f + 0.25f * std::cos(3 * u);
    cloud.points.emplace_back((r + 0.1f * std::cos(v)) * std::cos(2 * u),
                              (r + 0.1f * std::cos(v)) * std::sin(2 * u),
                              0.3f * std::sin(3 * u) + 0.1f * std::sin(v));
  }
  return cloud;
}

void ReportTree(benchmark::State& state, const PointCloud& cloud, const Octree& tree) {
  size_t nodes = 0;
  for (const auto& level : tree.levels()) nodes += level.size();
  state.counters["nodes"] = static_cast<double>(nodes);
  state.counters["bytes"] = static_cast<double>(tree.MemoryBytes());
  state.counters["bytes_vs_xyz"] =
      static_cast<double>(tree.MemoryBytes()) / (12.0 * static_cast<double>(cloud.size()));
  state.counters["points_per_s"] = benchmark::Counter(
      static_cast<double>(cloud.size()) * state.iterations(), benchmark::Counter::kIsRate);
}

void BuildAndReport(benchmark::State& state, const PointCloud& cloud,
                    const BarnesHutTreeOptions& options) {
  for (auto _ : state) {
    auto tree = BuildOctree(cloud, options);
    benchmark::DoNotOptimize(tree);
  }
  ReportTree(state, cloud, *BuildOctree(cloud, options));
}

// neighbor_depth 99 (capped at depth): neighbour tables at every depth. neighbor_depth = 5 is what
// the service caches for a LiDAR scan: deep levels for refinement, neighbour tables only where the
// network's tree convolutions gather.
void BM_BuildTreeLidar(benchmark::State& state) {
  const PointCloud cloud = SimulatedUrbanScan(static_cast<size_t>(state.range(0)));
  BarnesHutTreeOptions options;
  options.max_depth = static_cast<int>(state.range(1));
  options.neighbor_max_depth = static_cast<int>(state.range(2));
  BuildAndReport(state, cloud, options);
}
BENCHMARK(BM_BuildTreeLidar)
    ->ArgNames({"points", "depth", "neighbor_depth"})
    ->ArgsProduct({{120000}, {6, 8, 9, 10}, {5}})
    ->ArgsProduct({{120000}, {6, 8, 9, 10}, {99}})
    ->Unit(benchmark::kMillisecond);

void BM_BuildTreeObject(benchmark::State& state) {
  const PointCloud cloud = MakeObject(static_cast<int>(state.range(0)), 2);
  BarnesHutTreeOptions options;
  options.max_depth = static_cast<int>(state.range(1));
  options.neighbor_max_depth = static_cast<int>(state.range(2));
  BuildAndReport(state, cloud, options);
}
BENCHMARK(BM_BuildTreeObject)
    ->ArgNames({"points", "depth", "neighbor_depth"})
    ->Args({2048, 6, 5})
    ->Unit(benchmark::kMicrosecond);

}  // namespace
}  // namespace rpsr::core

BENCHMARK_MAIN();
