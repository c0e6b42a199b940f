// What the refinement's tests share beyond geometry: unseen object pairs, trees built as the
// refinement reads them, simulated scan pairs, and the comparison of two results that must be the
// same bit for bit.
#ifndef RPSR_TESTS_CORE_REFINE_REFINEMENT_TEST_UTIL_H_
#define RPSR_TESTS_CORE_REFINE_REFINEMENT_TEST_UTIL_H_

#include <cmath>
#include <functional>
#include <random>
#include <string>
#include <utility>

#include "core/cloud/point_cloud.h"
#include "core/data/object_pairs.h"
#include "core/data/registration_metrics.h"
#include "core/refine/tree_refinement.h"
#include "core/synth/lidar_sequence.h"
#include "core/synth/seeded_random.h"
#include "core/tree/bh_tree.h"
#include "gtest/gtest.h"
#include "tests/core/refine/refinement_test_geometry.h"

namespace rpsr::core::testing_util {

// Unseen-class object pairs with their source disturbed at `level` (0..4).
inline PairOptions UnseenPairs(DisturbanceKind disturbance, int level) {
  PairOptions options;
  options.split = ObjectSplit::kM2Unseen;
  options.disturbance = disturbance;
  options.disturbance_level = level;
  return options;
}

// A tree to `max_depth` without the network's neighbour tables (the refinement reads none).
inline Octree RefinementTree(const PointCloud& cloud, int max_depth) {
  BarnesHutTreeOptions options;
  options.max_depth = max_depth;
  options.neighbor_max_depth = 2;
  auto tree = BuildOctree(cloud, options);
  EXPECT_TRUE(tree.ok()) << tree.status();
  return *std::move(tree);
}

// Pair i of the unseen study's clean pairs (`rpsr eval --protocol objects --split unseen --seed
// S`), its trees to `depth`, and the pair refined from its true pose.
struct StudyPairAtTruth {
  ObjectPair pair;
  Octree source;
  Octree target;
  TreeRefinementResult at_truth;
};
inline StudyPairAtTruth CleanStudyPairAtTruth(uint64_t seed, uint64_t i, int depth) {
  PairOptions options;
  options.split = ObjectSplit::kM2Unseen;
  auto pair = MakeObjectPair(options, DeriveSeed(seed, i));
  EXPECT_TRUE(pair.ok()) << pair.status();
  StudyPairAtTruth out{
      *pair, RefinementTree(pair->source, depth), RefinementTree(pair->target, depth), {}};
  auto refined = RefineOnTrees(out.source, out.target, pair->T_target_source);
  EXPECT_TRUE(refined.ok()) << refined.status();
  out.at_truth = *std::move(refined);
  return out;
}

// Two frames of a simulated sequence as refinement trees of depth 9 (the CLI's depth for scenes)
// and the true motion between them.
struct ScanPairTrees {
  Octree source;
  Octree target;
  Eigen::Isometry3d T_target_source;
};
inline absl::StatusOr<ScanPairTrees> SimulatedScanPair(const LidarSequenceOptions& options,
                                                       int target_frame, int source_frame) {
  absl::StatusOr<LidarSequenceSimulator> sequence = LidarSequenceSimulator::Create(options);
  if (!sequence.ok()) return sequence.status();
  return ScanPairTrees{
      RefinementTree(sequence->SimulateFrame(source_frame).cloud, 9),
      RefinementTree(sequence->SimulateFrame(target_frame).cloud, 9),
      sequence->T_world_lidar()[target_frame].inverse() * sequence->T_world_lidar()[source_frame]};
}

// Refines `pairs` object pairs of `pair_options` (seeds 1000..) from the truth perturbed by
// a..3a degrees and 0.01a..0.02a (a = min_angle_deg; 5: 5-15 degrees and 0.05-0.1, network-sized
// errors) and counts those ending beyond (1 deg, 0.01); `check` also sees each result.
inline int FailuresFromPerturbedStarts(
    const PairOptions& pair_options, const TreeRefinementOptions& options,
    double min_angle_deg = 5.0,
    const std::function<void(const TreeRefinementResult&)>& check = nullptr, int pairs = 60) {
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> angle(min_angle_deg, 3.0 * min_angle_deg);
  std::uniform_real_distribution<double> shift(0.01 * min_angle_deg, 0.02 * min_angle_deg);
  int failed = 0;
  for (uint64_t seed = 0; seed < static_cast<uint64_t>(pairs); ++seed) {
    auto pair = MakeObjectPair(pair_options, 1000 + seed);
    EXPECT_TRUE(pair.ok()) << pair.status();
    const Octree source = RefinementTree(pair->source, 6);
    const Octree target = RefinementTree(pair->target, 6);
    const Eigen::Isometry3d initial =
        Perturbed(pair->T_target_source, angle(rng) * M_PI / 180.0, shift(rng), rng);
    auto result = RefineOnTrees(source, target, initial, options);
    EXPECT_TRUE(result.ok()) << result.status();
    const PairError error = ErrorOf(result->T_target_source, pair->T_target_source);
    failed += error.rotation_deg > 1.0 || error.translation > 0.01;
    if (check) check(*result);
  }
  return failed;
}

// Two refinements that only shared or prepared work differently: every reported number equal.
inline void ExpectSameRefinement(const TreeRefinementResult& a, const TreeRefinementResult& b,
                                 const std::string& what) {
  EXPECT_EQ(a.T_target_source.matrix(), b.T_target_source.matrix()) << what;
  EXPECT_EQ(a.iterations, b.iterations) << what;
  EXPECT_EQ(a.fitness, b.fitness) << what;
  EXPECT_EQ(a.inlier_rmse, b.inlier_rmse) << what;
  EXPECT_EQ(a.information, b.information) << what;
  EXPECT_EQ(a.valid, b.valid) << what;
}

}  // namespace rpsr::core::testing_util

#endif  // RPSR_TESTS_CORE_REFINE_REFINEMENT_TEST_UTIL_H_
