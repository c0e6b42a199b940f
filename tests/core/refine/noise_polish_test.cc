// The noise polish (core/refine/noise_polish.h, TreeRefinementOptions::noise_polish): the scatter
// it is gated on separates clean from jittered clouds, it holds heavily jittered pairs closer to
// the truth, leaves clean pairs exactly as they were, and the result describes the polished pose.
#include "core/refine/noise_polish.h"

#include <algorithm>
#include <random>
#include <string>
#include <vector>

#include "core/data/object_pairs.h"
#include "core/data/registration_metrics.h"
#include "core/refine/tree_refinement.h"
#include "gtest/gtest.h"
#include "tests/core/refine/refinement_test_geometry.h"
#include "tests/core/refine/refinement_test_util.h"

namespace rpsr::core {
namespace {

using testing_util::ExpectSameRefinement;
using testing_util::FailuresFromPerturbedStarts;
using testing_util::Perturbed;
using testing_util::RefinementTree;
using testing_util::UnseenPairs;

constexpr double kDeg = M_PI / 180.0;
constexpr int kDepth = 6;

// The polish alone at depth kDepth - 1, its two sides built as the refinement builds them.
PlanePolishResult Polish(const Octree& source, const Octree& target,
                         const Eigen::Isometry3d& initial, const PlanePolishOptions& options = {}) {
  const int depth = kDepth - 1;
  PolishSides sides(source, target, depth, options);
  return PolishPointToPlane(sides, initial, options);
}

// The refinement's measure at the truth, for `pairs` unseen pairs of a jitter level: its median.
double MedianScatterAtTruth(int jitter_level, int pairs) {
  std::vector<double> scatter;
  for (int seed = 0; seed < pairs; ++seed) {
    auto pair =
        MakeObjectPair(jitter_level == 0 ? UnseenPairs(DisturbanceKind::kNone, 0)
                                         : UnseenPairs(DisturbanceKind::kJitter, jitter_level),
                       2000 + seed);
    EXPECT_TRUE(pair.ok()) << pair.status();
    const Octree source = RefinementTree(pair->source, kDepth);
    const Octree target = RefinementTree(pair->target, kDepth);
    auto result = RefineOnTrees(source, target, pair->T_target_source, {});
    EXPECT_TRUE(result.ok()) << result.status();
    if (result->surface_scatter_cells >= 0.0) scatter.push_back(result->surface_scatter_cells);
  }
  EXPECT_FALSE(scatter.empty());
  std::nth_element(scatter.begin(), scatter.begin() + scatter.size() / 2, scatter.end());
  return scatter[scatter.size() / 2];
}

// The scatter grows with the jitter and the threshold lies between clean and heavy jitter.
TEST(NoisePolishTest, ScatterSeparatesCleanFromJitteredClouds) {
  const double threshold = TreeRefinementOptions{}.noise_polish_min_scatter_cells;
  const double clean = MedianScatterAtTruth(0, 12);
  const double jitter_003 = MedianScatterAtTruth(2, 12);
  const double jitter_008 = MedianScatterAtTruth(4, 12);
  EXPECT_LT(clean, threshold);
  EXPECT_LT(clean, jitter_003);
  EXPECT_LT(jitter_003, jitter_008);
  EXPECT_GT(jitter_008, threshold);
}

// Refined from 2-6 and 5-15 degree starts, heavily jittered unseen pairs (0.08) end within (1 deg,
// 0.01) more often with the polish; every one polished says so, its last stage one depth above
// the finest.
TEST(NoisePolishTest, HoldsHeavilyJitteredPairsCloser) {
  const PairOptions pair_options = UnseenPairs(DisturbanceKind::kJitter, 4);
  auto failures = [&](bool polish) {
    TreeRefinementOptions options;
    options.noise_polish = polish;
    auto check = [&](const TreeRefinementResult& result) {
      if (polish && result.noise_polished) {
        EXPECT_TRUE(result.stages.back().noise_polish);
        EXPECT_EQ(result.stages.back().depth, kDepth - 1);
        EXPECT_GE(result.surface_scatter_cells, options.noise_polish_min_scatter_cells);
      }
      if (!polish) {
        EXPECT_FALSE(result.noise_polished);
        EXPECT_LT(result.surface_scatter_cells, 0.0);  // not measured
      }
    };
    return FailuresFromPerturbedStarts(pair_options, options, 2.0, check, 40) +
           FailuresFromPerturbedStarts(pair_options, options, 5.0, check, 40);
  };
  const int without = failures(false);
  const int with = failures(true);
  std::printf("jitter 0.08, 2 x 40 starts beyond (1 deg, 0.01): without the polish %d, with %d\n",
              without, with);
  // 66 and 38 of 2 x 40 here (44 with session 16's polish: each node to the nearest target CoM).
  EXPECT_LE(with, without - 20);
}

// Clean pairs stay below the threshold: the result is the stages' own, digit for digit.
TEST(NoisePolishTest, LeavesCleanPairsAsTheyWere) {
  TreeRefinementOptions off;
  off.noise_polish = false;
  std::mt19937_64 rng(5);
  for (int seed = 0; seed < 12; ++seed) {
    auto pair = MakeObjectPair(UnseenPairs(DisturbanceKind::kNone, 0), 3000 + seed);
    ASSERT_TRUE(pair.ok()) << pair.status();
    const Octree source = RefinementTree(pair->source, kDepth);
    const Octree target = RefinementTree(pair->target, kDepth);
    const Eigen::Isometry3d initial = Perturbed(pair->T_target_source, 5.0 * kDeg, 0.05, rng);
    auto polished = RefineOnTrees(source, target, initial, {});
    auto plain = RefineOnTrees(source, target, initial, off);
    ASSERT_TRUE(polished.ok() && plain.ok());
    EXPECT_FALSE(polished->noise_polished) << "seed " << seed;
    if (polished->valid) {
      EXPECT_GE(polished->surface_scatter_cells, 0.0);
      EXPECT_LT(polished->surface_scatter_cells, off.noise_polish_min_scatter_cells);
    }
    ExpectSameRefinement(*polished, *plain, "seed " + std::to_string(seed));
  }
}

// What a polished result reports (fitness, information, validity) is measured at the pose it
// returns, as a refinement ending there reports it.
TEST(NoisePolishTest, ResultDescribesThePolishedPose) {
  int polished_pairs = 0;
  for (int seed = 0; seed < 6; ++seed) {
    auto pair = MakeObjectPair(UnseenPairs(DisturbanceKind::kJitter, 4), 4000 + seed);
    ASSERT_TRUE(pair.ok()) << pair.status();
    const Octree source = RefinementTree(pair->source, kDepth);
    const Octree target = RefinementTree(pair->target, kDepth);
    auto result = RefineOnTrees(source, target, pair->T_target_source, {});
    ASSERT_TRUE(result.ok()) << result.status();
    if (!result->noise_polished) continue;
    ++polished_pairs;
    TreeRefinementOptions measure;
    measure.evaluate_only = true;
    auto measured = RefineOnTrees(source, target, result->T_target_source, measure);
    ASSERT_TRUE(measured.ok()) << measured.status();
    EXPECT_EQ(result->fitness, measured->fitness);
    EXPECT_EQ(result->inlier_rmse, measured->inlier_rmse);
    EXPECT_EQ(result->information, measured->information);
    EXPECT_EQ(result->valid, measured->valid);
    EXPECT_GT(result->stages.back().iterations, 0);
    EXPECT_GT(result->stages.back().correspondences, 12);
  }
  EXPECT_GE(polished_pairs, 4);  // jitter 0.08 reads above the threshold on most pairs
}

// On a jittered plane the planes constrain only three directions: the polish keeps the pose
// finite and moves it neither along the plane nor about its normal.
TEST(NoisePolishTest, StaysPutAlongWhatThePlanesLeaveFree) {
  PointCloud plane = testing_util::Plane(4000, 1);
  PointCloud jittered = testing_util::Plane(4000, 2);
  std::mt19937_64 rng(9);
  std::normal_distribution<float> noise(0.0f, 0.02f);
  for (auto& p : jittered.points) p.z() += noise(rng);
  const Octree source = RefinementTree(jittered, kDepth);
  const Octree target = RefinementTree(plane, kDepth);
  Eigen::Isometry3d initial = Eigen::Isometry3d::Identity();
  initial.translation() = Eigen::Vector3d(0.01, -0.01, 0.005);
  const PlanePolishResult result = Polish(source, target, initial);
  ASSERT_TRUE(result.T_target_source.matrix().allFinite());
  EXPECT_GT(result.iterations, 0);
  const Eigen::Vector3d t = result.T_target_source.translation();
  EXPECT_NEAR(t.x(), 0.01, 1e-3);  // free along the plane
  EXPECT_NEAR(t.y(), -0.01, 1e-3);
  EXPECT_NEAR(t.z(), 0.0, 0.005);  // the normal's offset is removed
  const Eigen::AngleAxisd turn(result.T_target_source.linear());
  EXPECT_LT(turn.angle(), 0.01);
}

// A source that is a single straight line of points on a plane, started 0.01 above it, leaves the
// normal equations four free directions (along the line and across it, about the line and about
// the plane's normal): their pivots are rounding noise, and so is b there. Undamped, their ratio
// is a step of any size, which the step cap refuses, so the polish would not even remove the
// plane's offset (checked by removing the damping; a rounding-dependent guard, so the check may
// pass undamped under other compiler flags);
// damped relative to the trace, those steps are ~0 and the offset goes.
TEST(NoisePolishTest, DampingKeepsRoundingNoiseFromStoppingIt) {
  // Turned off the axes, so that no normal or lever arm is exact and no pivot exactly zero.
  const Eigen::Matrix3f turn =
      Eigen::AngleAxisf(0.7f, Eigen::Vector3f(1.0f, 2.0f, 3.0f).normalized()).toRotationMatrix();
  PointCloud plane = testing_util::Plane(4000, 1);
  for (auto& p : plane.points) p = turn * p;
  PointCloud line;
  for (int i = 0; i < 400; ++i) {
    line.points.push_back(
        turn * Eigen::Vector3f(-0.9f + 1.8f * static_cast<float>(i) / 399.0f, 0.1f, 0.0f));
  }
  const Octree source = RefinementTree(line, kDepth);
  const Octree target = RefinementTree(plane, kDepth);
  const Eigen::Matrix3d to_world = turn.cast<double>();
  Eigen::Isometry3d initial = Eigen::Isometry3d::Identity();
  initial.translation() = to_world * Eigen::Vector3d(0.02, -0.01, 0.01);
  const PlanePolishResult result = Polish(source, target, initial);
  ASSERT_TRUE(result.T_target_source.matrix().allFinite());
  EXPECT_GT(result.correspondences, 12);
  EXPECT_GT(result.iterations, 0);
  const Eigen::Vector3d t = to_world.transpose() * result.T_target_source.translation();
  EXPECT_NEAR(t.z(), 0.0, 1e-3);   // the plane's offset removed
  EXPECT_NEAR(t.x(), 0.02, 1e-3);  // nothing moved along the free directions
  EXPECT_NEAR(t.y(), -0.01, 1e-3);
  EXPECT_LT(Eigen::AngleAxisd(result.T_target_source.linear()).angle(), 1e-3);
}

// The polish alone, from a 3-degree error on a clean object whose source is the target's own
// points moved: it converges close to the truth, unless its steps are capped below what it needs.
TEST(NoisePolishTest, PointToPlaneConvergesFromSmallErrors) {
  auto pair = MakeObjectPair(UnseenPairs(DisturbanceKind::kNone, 0), 5000);
  ASSERT_TRUE(pair.ok()) << pair.status();
  PointCloud moved = pair->target;
  const Eigen::Isometry3d truth = pair->T_target_source;
  for (auto& p : moved.points) p = (truth.inverse() * p.cast<double>()).cast<float>();
  const Octree source = RefinementTree(moved, kDepth);
  const Octree target = RefinementTree(pair->target, kDepth);
  std::mt19937_64 rng(3);
  const Eigen::Isometry3d initial = Perturbed(truth, 3.0 * kDeg, 0.02, rng);
  const PlanePolishResult result = Polish(source, target, initial);
  const PairError before = ErrorOf(initial, truth);
  const PairError after = ErrorOf(result.T_target_source, truth);
  EXPECT_GT(result.iterations, 1);
  EXPECT_GT(result.correspondences, 100);
  EXPECT_LT(after.rotation_deg, 0.5);
  EXPECT_LT(after.translation, 0.005);
  EXPECT_LT(after.rotation_deg, before.rotation_deg / 5.0);
  // A step larger than the polish allows (here: any turn at all) stops it where it stands.
  PlanePolishOptions tiny_steps;
  tiny_steps.max_step_rad = 1e-9;
  const PlanePolishResult stopped = Polish(source, target, initial, tiny_steps);
  EXPECT_EQ(stopped.iterations, 0);
  EXPECT_EQ(stopped.T_target_source.matrix(), initial.matrix());
}

}  // namespace
}  // namespace rpsr::core
