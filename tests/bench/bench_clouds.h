// The clouds the benchmarks share, so that their figures are about the same pairs: object pairs
// of the unseen classes (pair seeds 100, 101, ...) and simulated HDL-64E scans five frames apart.
// Header-only: each benchmark is one binary. A setup failure aborts with its status (a benchmark
// has no way to report one).
#ifndef RPSR_TESTS_BENCH_BENCH_CLOUDS_H_
#define RPSR_TESTS_BENCH_BENCH_CLOUDS_H_

#include <cstdio>
#include <cstdlib>
#include <utility>
#include <vector>

#include "absl/status/statusor.h"
#include "core/data/object_pairs.h"
#include "core/synth/lidar_sequence.h"
#include "core/tree/bh_tree.h"

namespace rpsr::bench {

template <typename T>
T OrDie(absl::StatusOr<T> value, const char* what) {
  if (!value.ok()) {
    std::fprintf(stderr, "%s: %s\n", what, value.status().ToString().c_str());
    std::abort();
  }
  return *std::move(value);
}

// Source, target, source, target, ... of `pairs` unseen-class object pairs of `num_points` each.
// `jitter_level` 1..4: the sources jittered at that evaluation level (0: clean).
inline std::vector<core::PointCloud> UnseenObjectClouds(int pairs, size_t num_points,
                                                        int jitter_level = 0) {
  core::PairOptions options;
  options.num_points = num_points;
  options.split = core::ObjectSplit::kM2Unseen;
  if (jitter_level > 0) {
    options.disturbance = core::DisturbanceKind::kJitter;
    options.disturbance_level = jitter_level;
  }
  std::vector<core::PointCloud> clouds;
  for (int i = 0; i < pairs; ++i) {
    core::ObjectPair pair = OrDie(core::MakeObjectPair(options, 100 + i), "object pair");
    clouds.push_back(std::move(pair.source));
    clouds.push_back(std::move(pair.target));
  }
  return clouds;
}

// Every (full.size() / num_points)-th point, when the cloud has more than num_points.
inline core::PointCloud Thinned(const core::PointCloud& full, size_t num_points) {
  if (full.size() < num_points) return full;
  core::PointCloud cloud;
  for (size_t i = 0; i < num_points; ++i) {
    cloud.points.push_back(full.points[i * full.size() / num_points]);
  }
  return cloud;
}

// Frames 5i (source) and 5i + 5 (target) of one simulated drive for i < pairs, alternating;
// thinned to max_points when it is positive.
inline std::vector<core::PointCloud> LidarCloudsFiveFramesApart(
    int pairs, const core::LidarSequenceOptions& options, size_t max_points = 0) {
  const core::LidarSequenceSimulator simulator =
      OrDie(core::LidarSequenceSimulator::Create(options), "LiDAR simulator");
  std::vector<core::PointCloud> clouds;
  for (int i = 0; i < pairs; ++i) {
    for (int frame : {5 * i, 5 * i + 5}) {
      core::PointCloud cloud = simulator.SimulateFrame(frame).cloud;
      clouds.push_back(max_points > 0 ? Thinned(cloud, max_points) : std::move(cloud));
    }
  }
  return clouds;
}

inline std::vector<core::Octree> TreesOf(const std::vector<core::PointCloud>& clouds,
                                         const core::BarnesHutTreeOptions& options) {
  std::vector<core::Octree> trees;
  trees.reserve(clouds.size());
  for (const core::PointCloud& cloud : clouds) {
    trees.push_back(OrDie(core::BuildOctree(cloud, options), "tree"));
  }
  return trees;
}

}  // namespace rpsr::bench

#endif  // RPSR_TESTS_BENCH_BENCH_CLOUDS_H_
