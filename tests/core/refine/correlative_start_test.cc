// FindCorrelativeStart (issue 5): on simulated scans ten frames apart, where the refinement from
// the identity does not reach the truth, the searched start lands within a few metres and a few
// degrees of it; bad inputs are errors.
#include "core/refine/correlative_start.h"

#include <cmath>

#include "core/data/registration_metrics.h"
#include "core/data/training_pairs.h"
#include "core/refine/tree_refinement.h"
#include "core/synth/seeded_random.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"

namespace rpsr::core {
namespace {

using ::testing::HasSubstr;

Octree TreeOf(const PointCloud& cloud) {
  BarnesHutTreeOptions options;
  options.max_depth = 9;
  options.neighbor_max_depth = 2;
  auto tree = BuildOctree(cloud, options);
  EXPECT_TRUE(tree.ok()) << tree.status();
  return *std::move(tree);
}

// Pairs of the simulated LiDAR stream ten frames apart (the registrar test's and the scratch
// study's set) whose motion the refinement from the identity does not pull in.
RegistrationPair HardPair(int index) {
  LidarStreamOptions stream;
  stream.frame_offset = 10;
  stream.pairs_per_sequence = 8;
  stream.stream_seed = DeriveSeed(11, 1010);
  auto pair = MakeLidarPairStream(stream)(index);
  EXPECT_TRUE(pair.ok()) << pair.status();
  return *std::move(pair);
}

TEST(CorrelativeStartTest, LandsNearTheTruthWhereTheRefinementFromIdentityDoesNot) {
  for (int index : {24, 38}) {  // ~10 and ~11 m from the identity's answer here
    const RegistrationPair pair = HardPair(index);
    ASSERT_GT(pair.T_target_source.translation().norm(), 5.0) << "a motion of several metres";
    const Octree source = TreeOf(pair.source);
    const Octree target = TreeOf(pair.target);
    // The registrar's first start on deep trees: four depths above the finest (7.5 m cells).
    TreeRefinementOptions finer_start;
    finer_start.coarsest_depth = 5;
    auto refined = RefineOnTrees(source, target, Eigen::Isometry3d::Identity(), finer_start);
    ASSERT_TRUE(refined.ok()) << refined.status();
    const PairError from_identity = ErrorOf(refined->T_target_source, pair.T_target_source);
    EXPECT_FALSE(from_identity.rotation_deg < 1.0 && from_identity.translation < 0.3)
        << "pair " << index << ": the identity's basin holds it; this test no longer needs it";

    auto start = FindCorrelativeStart(source, target, Eigen::Isometry3d::Identity());
    ASSERT_TRUE(start.ok()) << start.status();
    const PairError error = ErrorOf(start->T_target_source, pair.T_target_source);
    EXPECT_LT(error.rotation_deg, 3.0) << "pair " << index;
    EXPECT_LT(error.translation, 3.0) << "pair " << index;  // within a cell of 3.75 m
    EXPECT_GT(start->score, start->initial_score) << "pair " << index;
    EXPECT_EQ(start->depth, 6);
    EXPECT_GT(start->candidates, 100);

    // And the refinement from it reaches the truth.
    auto from_start = RefineOnTrees(source, target, start->T_target_source, finer_start);
    ASSERT_TRUE(from_start.ok()) << from_start.status();
    const PairError final_error = ErrorOf(from_start->T_target_source, pair.T_target_source);
    EXPECT_LT(final_error.rotation_deg, 1.0) << "pair " << index;
    EXPECT_LT(final_error.translation, 0.3) << "pair " << index;
  }
}

TEST(CorrelativeStartTest, RejectsBadInputs) {
  const RegistrationPair pair = HardPair(27);
  const Octree source = TreeOf(pair.source);
  const Octree target = TreeOf(pair.target);
  Eigen::Isometry3d nan = Eigen::Isometry3d::Identity();
  nan.translation().x() = std::nan("");
  EXPECT_THAT(FindCorrelativeStart(source, target, nan).status().message(),
              HasSubstr("not finite"));
  CorrelativeSearchOptions too_deep;
  too_deep.depth = kMaxCorrelativeDepth + 1;  // within the trees (depth 9), beyond the bitset's cap
  EXPECT_EQ(
      FindCorrelativeStart(source, target, Eigen::Isometry3d::Identity(), too_deep).status().code(),
      absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(FindCorrelativeStart(Octree(), target, Eigen::Isometry3d::Identity()).status().code(),
            absl::StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace rpsr::core
