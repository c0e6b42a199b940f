// Speed and memory of building Barnes-Hut trees: a LiDAR-like scan of 120k points (the service's
// main load) and a 2,048-point object. Counters: nodes in the tree, bytes it holds, and
// bytes_vs_xyz = tree bytes / raw float32 xyz bytes (what the session cache pays per cloud).
//
//   build/tests/bench/bh_tree_bench --benchmark_counters_tabular=true
#include <cmath>
#include <random>
#include <vector>

#include "benchmark/benchmark.h"
#include "core/tree/bh_tree.h"

namespace rpsr::core {
namespace {

// An analytic HDL-64E-like scan, self-contained so the benchmark does not depend on the
// simulator: 64 beams from +2 to -24.8 degrees, `azimuth_steps` rays each, hitting a ground
// plane 1.73 m below the sensor, facades 9-14 m to the sides, and poles; 2 cm range noise.
PointCloud MakeLidarLikeScan(int num_points, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<float> noise(0.0f, 0.02f);
  const int beams = 64;
  const int azimuth_steps = num_points / beams;
  PointCloud cloud;
  cloud.points.reserve(num_points);
  for (int b = 0; b < beams; ++b) {
    const double elevation = (2.0 - 26.8 * b / (beams - 1)) * M_PI / 180.0;
    for (int s = 0; s < azimuth_steps; ++s) {
      const double azimuth = 2.0 * M_PI * s / azimuth_steps;
      const Eigen::Vector3d dir(std::cos(elevation) * std::cos(azimuth),
                                std::cos(elevation) * std::sin(azimuth), std::sin(elevation));
      double range = 120.0;
      if (dir.z() < 0) range = std::min(range, -1.73 / dir.z());
      const double wall = dir.y() > 0 ? 9.0 + 0.5 * std::sin(0.1 * s) : -14.0;
      if (std::abs(dir.y()) > 1e-6) {
        const double t = wall / dir.y();
        if (t > 0) range = std::min(range, t);
      }
      // Poles every 15 m along x at y = 6.
      const double pole_x = 15.0 * std::round(range * dir.x() / 15.0);
      if (std::abs(dir.y()) > 1e-6 && dir.y() > 0) {
        const double t = 6.0 / dir.y();
        if (t < range && std::abs(t * dir.x() - pole_x) < 0.15) range = t;
      }
      cloud.points.push_back(((range + noise(rng)) * dir).cast<float>());
    }
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

// Full tree: neighbour tables at every depth.
void BM_BuildTreeLidar(benchmark::State& state) {
  const PointCloud cloud = MakeLidarLikeScan(static_cast<int>(state.range(0)), 1);
  BarnesHutTreeOptions options;
  options.max_depth = static_cast<int>(state.range(1));
  options.neighbor_max_depth = options.max_depth;
  BuildAndReport(state, cloud, options);
}
BENCHMARK(BM_BuildTreeLidar)
    ->ArgNames({"points", "depth"})
    ->Args({120000, 6})
    ->Args({120000, 8})
    ->Args({120000, 9})
    ->Args({120000, 10})
    ->Unit(benchmark::kMillisecond);

// What the service caches for a LiDAR scan: deep levels for refinement, neighbour tables only
// where the network's tree convolutions gather (depths <= 5).
void BM_BuildTreeLidarCached(benchmark::State& state) {
  const PointCloud cloud = MakeLidarLikeScan(static_cast<int>(state.range(0)), 1);
  BarnesHutTreeOptions options;
  options.max_depth = static_cast<int>(state.range(1));
  options.neighbor_max_depth = 5;
  BuildAndReport(state, cloud, options);
}
BENCHMARK(BM_BuildTreeLidarCached)
    ->ArgNames({"points", "depth"})
    ->Args({120000, 6})
    ->Args({120000, 8})
    ->Args({120000, 9})
    ->Args({120000, 10})
    ->Unit(benchmark::kMillisecond);

void BM_BuildTreeObject(benchmark::State& state) {
  const PointCloud cloud = MakeObject(static_cast<int>(state.range(0)), 2);
  BarnesHutTreeOptions options;
  options.max_depth = static_cast<int>(state.range(1));
  BuildAndReport(state, cloud, options);
}
BENCHMARK(BM_BuildTreeObject)
    ->ArgNames({"points", "depth"})
    ->Args({2048, 6})
    ->Unit(benchmark::kMicrosecond);

}  // namespace
}  // namespace rpsr::core

BENCHMARK_MAIN();
