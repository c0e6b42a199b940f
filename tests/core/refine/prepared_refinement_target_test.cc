// PreparedRefinementTarget: a target's side of the refinement prepared once changes no result
// (bit for bit, whatever the options, the start or the source), is ignored for other trees, is
// shared by threads, and refuses what it cannot prepare.
#include <atomic>
#include <random>
#include <thread>
#include <tuple>
#include <vector>

#include "core/data/object_pairs.h"
#include "core/refine/tree_refinement.h"
#include "core/synth/lidar_sequence.h"
#include "gtest/gtest.h"
#include "tests/core/refine/refinement_test_geometry.h"
#include "tests/core/refine/refinement_test_util.h"

namespace rpsr::core {
namespace {

using testing_util::ExpectSameRefinement;
using testing_util::Perturbed;
using testing_util::RefinementTree;
using testing_util::SimulatedScanPair;
using testing_util::Sphere;

constexpr double kDeg = M_PI / 180.0;

struct Call {
  const char* name;
  const Octree* source;
  const Octree* target;
  Eigen::Isometry3d initial;
  TreeRefinementOptions options;
  bool uses_prepared = true;  // whether the prepared target applies
};

bool EveryStageReadThePreparedSide(const TreeRefinementResult& result) {
  for (const DepthStage& stage : result.stages) {
    if (!stage.target_side_prepared) return false;
  }
  return !result.stages.empty();
}

// Calls of every kind against one prepared target: other starts and depths, the source's own
// cells with another epsilon, a min_count or a line rule it was not prepared for (its own side is
// built then),
// a source shallower than the target (the finest depth is the source's), another target (the
// prepared one does not apply) -- one cache through all of them, as the registrar's starts share
// one, and a fresh one per call.
TEST(PreparedRefinementTargetTest, SameResultsBitForBitAsWithoutIt) {
  PairOptions pair_options;
  pair_options.num_points = 2048;
  auto pair = MakeObjectPair(pair_options, 5);
  auto other = MakeObjectPair(pair_options, 6);
  ASSERT_TRUE(pair.ok() && other.ok());
  const Octree source = RefinementTree(pair->source, 6);
  const Octree shallow_source = RefinementTree(pair->source, 5);
  const Octree target = RefinementTree(pair->target, 6);
  const Octree other_source = RefinementTree(other->source, 6);
  const Octree other_target = RefinementTree(other->target, 6);
  auto prepared = PreparedRefinementTarget::Prepare(target);
  ASSERT_TRUE(prepared.ok()) << prepared.status();
  EXPECT_EQ(&(*prepared)->tree(), &target);

  std::mt19937_64 rng(4);
  TreeRefinementOptions finer;
  finer.coarsest_depth = 4;
  TreeRefinementOptions own_cells;
  own_cells.rebin_coarse_depths = false;
  own_cells.covariance_epsilon = 3e-3;
  TreeRefinementOptions other_min_count;
  other_min_count.min_count_for_covariance = 5;
  TreeRefinementOptions lines_from_planes;
  lines_from_planes.line_normals_from_planes = true;
  TreeRefinementOptions measure;
  measure.evaluate_only = true;
  const std::vector<Call> calls = {
      {"network-sized error",
       &source,
       &target,
       Perturbed(pair->T_target_source, 10 * kDeg, 0.05, rng),
       {}},
      {"identity", &source, &target, Eigen::Isometry3d::Identity(), {}},
      {"coarsest 4", &source, &target, Perturbed(pair->T_target_source, 5 * kDeg, 0.02, rng),
       finer},
      {"own cells", &source, &target, Perturbed(pair->T_target_source, 5 * kDeg, 0.02, rng),
       own_cells},
      {"min_count 5", &source, &target, Perturbed(pair->T_target_source, 5 * kDeg, 0.02, rng),
       other_min_count, false},
      {"line normals from planes", &source, &target,
       Perturbed(pair->T_target_source, 5 * kDeg, 0.02, rng), lines_from_planes, false},
      {"evaluate only", &source, &target, pair->T_target_source, measure},
      {"shallower source",
       &shallow_source,
       &target,
       Perturbed(pair->T_target_source, 8 * kDeg, 0.04, rng),
       {}},
      {"another target",
       &other_source,
       &other_target,
       Perturbed(other->T_target_source, 8 * kDeg, 0.04, rng),
       {},
       false},
      {"back to the prepared target",
       &source,
       &target,
       Perturbed(pair->T_target_source, 8 * kDeg, 0.04, rng),
       {}},
  };
  TreeRefinementCache shared(*prepared);
  for (const Call& c : calls) {
    auto plain = RefineOnTrees(*c.source, *c.target, c.initial, c.options);
    TreeRefinementCache fresh(*prepared);
    auto with_fresh = RefineOnTrees(*c.source, *c.target, c.initial, c.options, fresh);
    auto with_shared = RefineOnTrees(*c.source, *c.target, c.initial, c.options, shared);
    ASSERT_TRUE(plain.ok() && with_fresh.ok() && with_shared.ok()) << c.name;
    ExpectSameRefinement(*plain, *with_fresh, c.name);
    EXPECT_EQ(EveryStageReadThePreparedSide(*with_fresh), c.uses_prepared) << c.name;
    EXPECT_FALSE(EveryStageReadThePreparedSide(*plain)) << c.name;
    ExpectSameRefinement(*plain, *with_shared, std::string(c.name) + " (shared cache)");
  }
}

// Scene scale: a simulated scan pair to depth 9 from the identity, the registrar's finer start.
TEST(PreparedRefinementTargetTest, SameResultOnALidarPair) {
  LidarSequenceOptions options;
  options.frame_count = 3;
  options.seed = 5;
  auto scans = SimulatedScanPair(options, 0, 2);
  ASSERT_TRUE(scans.ok()) << scans.status();
  const Octree& source = scans->source;
  const Octree& target = scans->target;
  auto prepared = PreparedRefinementTarget::Prepare(target);
  ASSERT_TRUE(prepared.ok()) << prepared.status();
  for (int coarsest : {-1, 5}) {
    TreeRefinementOptions refine;
    refine.coarsest_depth = coarsest;
    auto plain = RefineOnTrees(source, target, Eigen::Isometry3d::Identity(), refine);
    TreeRefinementCache cache(*prepared);
    auto with = RefineOnTrees(source, target, Eigen::Isometry3d::Identity(), refine, cache);
    ASSERT_TRUE(plain.ok() && with.ok());
    ExpectSameRefinement(*plain, *with, "coarsest " + std::to_string(coarsest));
    EXPECT_TRUE(EveryStageReadThePreparedSide(*with));
    EXPECT_TRUE(with->valid) << with->failure_reason;
  }
  // Indexes and shapes of ~20k nodes: more than a shape a node, far less than the points.
  EXPECT_GT((*prepared)->bytes(), target.level(9).size() * 3 * sizeof(double));
  EXPECT_LT((*prepared)->bytes(), size_t{16} << 20);
}

// The line rule left unset: a VLP-16 scan's prepared target chooses it on from its own line
// fraction, and a pair of such scans, choosing it too, reads the prepared side; a rule given
// otherwise builds its own. Same results as without the prepared target either way.
TEST(PreparedRefinementTargetTest, ChosenLineRuleOnASparseScanReadsThePreparedSide) {
  LidarSequenceOptions options;
  options.frame_count = 3;
  options.seed = 5;
  options.sensor = *LidarSensorPreset("vlp16");
  auto scans = SimulatedScanPair(options, 1, 2);
  ASSERT_TRUE(scans.ok()) << scans.status();
  const Octree& source = scans->source;
  const Octree& target = scans->target;
  auto prepared = PreparedRefinementTarget::Prepare(target);
  ASSERT_TRUE(prepared.ok()) << prepared.status();
  ASSERT_TRUE((*prepared)->line_shaped_fraction().has_value());
  EXPECT_GE(*(*prepared)->line_shaped_fraction(), 0.67);
  TreeRefinementOptions own_normals;
  own_normals.line_normals_from_planes = false;
  for (const auto& [name, refine, reads_prepared] :
       {std::tuple{"chosen", TreeRefinementOptions{}, true},
        std::tuple{"given off", own_normals, false}}) {
    auto plain = RefineOnTrees(source, target, Eigen::Isometry3d::Identity(), refine);
    TreeRefinementCache cache(*prepared);
    auto with = RefineOnTrees(source, target, Eigen::Isometry3d::Identity(), refine, cache);
    ASSERT_TRUE(plain.ok() && with.ok());
    ExpectSameRefinement(*plain, *with, name);
    EXPECT_EQ(with->line_normals_from_planes, reads_prepared) << name;
    EXPECT_EQ(EveryStageReadThePreparedSide(*with), reads_prepared) << name;
  }
}

// One prepared target read by several threads at once (it is never written after Prepare): each
// thread's results equal the single-threaded ones.
TEST(PreparedRefinementTargetTest, SharedByThreads) {
  PairOptions pair_options;
  pair_options.num_points = 2048;
  auto pair = MakeObjectPair(pair_options, 9);
  ASSERT_TRUE(pair.ok());
  const Octree target = RefinementTree(pair->target, 6);
  // The pair's source and copies of it with a little noise of their own.
  std::vector<Octree> sources;
  std::mt19937_64 noise_rng(1);
  std::normal_distribution<float> noise(0.0f, 0.005f);
  for (int copy = 0; copy < 5; ++copy) {
    PointCloud cloud = pair->source;
    if (copy > 0) {
      for (Eigen::Vector3f& p : cloud.points) {
        p += Eigen::Vector3f(noise(noise_rng), noise(noise_rng), noise(noise_rng));
      }
    }
    sources.push_back(RefinementTree(cloud, 6));
  }
  std::mt19937_64 rng(7);
  std::vector<Eigen::Isometry3d> starts;
  for (size_t i = 0; i < sources.size(); ++i) {
    starts.push_back(Perturbed(pair->T_target_source, 6 * kDeg, 0.03, rng));
  }
  std::vector<TreeRefinementResult> expected;
  for (size_t i = 0; i < sources.size(); ++i) {
    auto r = RefineOnTrees(sources[i], target, starts[i]);
    ASSERT_TRUE(r.ok());
    expected.push_back(*r);
  }
  // Rounds of a fresh prepared target (no shape computed yet) that the threads start on together,
  // so that they reach the same nodes at about the same time (the ThreadSanitizer build of this
  // test, prepared_refinement_target_tsan_test, checks the claims and publications).
  constexpr int kThreads = 4;
  constexpr int kRounds = 3;
  std::vector<std::vector<TreeRefinementResult>> got(kThreads);
  for (int round = 0; round < kRounds; ++round) {
    auto prepared = PreparedRefinementTarget::Prepare(target);
    ASSERT_TRUE(prepared.ok());
    std::atomic<int> waiting{kThreads};
    std::vector<std::thread> threads;
    for (int k = 0; k < kThreads; ++k) {
      threads.emplace_back([&, k] {
        waiting.fetch_sub(1);
        while (waiting.load() > 0) {
        }
        for (size_t i = 0; i < sources.size(); ++i) {
          TreeRefinementCache cache(*prepared);
          auto r = RefineOnTrees(sources[i], target, starts[i], {}, cache);
          if (r.ok()) got[k].push_back(*r);
        }
      });
    }
    for (std::thread& t : threads) t.join();
  }
  for (int k = 0; k < kThreads; ++k) {
    ASSERT_EQ(got[k].size(), kRounds * sources.size()) << "thread " << k;
    for (size_t n = 0; n < got[k].size(); ++n) {
      ExpectSameRefinement(expected[n % sources.size()], got[k][n],
                           "thread " + std::to_string(k) + " call " + std::to_string(n));
    }
  }
}

TEST(PreparedRefinementTargetTest, RefusesWhatItCannotPrepare) {
  EXPECT_EQ(PreparedRefinementTarget::Prepare(Octree()).status().code(),
            absl::StatusCode::kInvalidArgument);
  const Octree tree = RefinementTree(Sphere(500, 1), 5);
  TreeRefinementOptions too_deep;
  too_deep.coarsest_depth = 6;
  EXPECT_EQ(PreparedRefinementTarget::Prepare(tree, too_deep).status().code(),
            absl::StatusCode::kInvalidArgument);
  TreeRefinementOptions negative;
  negative.min_count_for_covariance = -1;
  EXPECT_EQ(PreparedRefinementTarget::Prepare(tree, negative).status().code(),
            absl::StatusCode::kInvalidArgument);
  EXPECT_TRUE(PreparedRefinementTarget::Prepare(tree).ok());
}

}  // namespace
}  // namespace rpsr::core
