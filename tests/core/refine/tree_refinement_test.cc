// RefineOnTrees (issue 5): convergence on objects and simulated LiDAR pairs, honest reports on
// degenerate geometry and on clouds that do not overlap, determinism, and that only trees are
// needed.
#include "core/refine/tree_refinement.h"

#include <cmath>
#include <cstdio>
#include <functional>
#include <optional>
#include <random>
#include <string>
#include <tuple>
#include <vector>

#include "core/data/object_pairs.h"
#include "core/data/registration_metrics.h"
#include "core/data/transform_convention.h"
#include "core/synth/lidar_sequence.h"
#include "core/synth/shape_families.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/core/refine/refinement_test_geometry.h"
#include "tests/core/refine/refinement_test_util.h"

namespace rpsr::core {
namespace {

using ::testing::HasSubstr;
using ::testing::Not;
using testing_util::Corridor;
using testing_util::ExpectSameRefinement;
using testing_util::FailuresFromPerturbedStarts;
using testing_util::Perturbed;
using testing_util::Plane;
using testing_util::RefinementTree;
using testing_util::SimulatedScanPair;
using testing_util::Sphere;
using testing_util::UnseenPairs;

constexpr double kDeg = M_PI / 180.0;

TEST(TreeRefinementTest, ObjectsConvergeFromNetworkSizedErrors) {
  PairOptions pair_options;
  pair_options.num_points = 2048;
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> angle(5.0, 15.0);
  std::uniform_real_distribution<double> shift(0.05, 0.1);
  int tested = 0;
  for (uint64_t seed = 1; tested < 12; ++seed) {
    auto pair = MakeObjectPair(pair_options, seed);
    ASSERT_TRUE(pair.ok()) << pair.status();
    if (ShapeFamilies()[pair->family_index].symmetry != RotationalSymmetry::kNone) continue;
    ++tested;
    const Octree source = RefinementTree(pair->source, 6);
    const Octree target = RefinementTree(pair->target, 6);
    const Eigen::Isometry3d initial =
        Perturbed(pair->T_target_source, angle(rng) * kDeg, shift(rng), rng);
    auto result = RefineOnTrees(source, target, initial);
    ASSERT_TRUE(result.ok()) << result.status();
    const PairError error = ErrorOf(result->T_target_source, pair->T_target_source);
    const std::string family = ShapeFamilies()[pair->family_index].name;
    EXPECT_LT(error.rotation_deg, 0.5) << family << " seed " << seed;
    EXPECT_LT(error.translation, 0.005) << family << " seed " << seed;
    EXPECT_TRUE(result->valid) << family << ": " << result->failure_reason;
    // Full overlap: nearly every point has a partner surface at the fitness depth (where cells
    // hold a few points each: 5 for 2,048-point objects at default options).
    EXPECT_GT(result->fitness, 0.9) << family;
    const double edge = 2.0 * source.half_length() / (1 << result->fitness_depth);
    EXPECT_GT(result->inlier_rmse, 0.0) << family;
    EXPECT_LT(result->inlier_rmse, 0.5 * edge) << family;
    EXPECT_GT(result->iterations, 0);
    EXPECT_EQ(result->stages.size(), 4u);  // depths 3..6
  }
}

// A refused finest step shorter than settled_step_cells ends the stage: fewer iterations, and the
// answer no farther from the one the damped retries would have crept to than a small part of a
// cell (TreeRefinementOptions::settled_step_cells). Unseen objects from network-sized errors, and
// a simulated scan pair from the identity, where the retries were most of the finest stage.
TEST(TreeRefinementTest, SettledRefusedStepsEndTheFinestStage) {
  TreeRefinementOptions retrying;
  retrying.settled_step_cells = 0.0;
  const TreeRefinementOptions settling;
  ASSERT_GT(settling.settled_step_cells, 0.0);
  int iterations_retrying = 0;
  int iterations_settling = 0;
  const auto compare = [&](const Octree& source, const Octree& target,
                           const Eigen::Isometry3d& initial, const std::string& what) {
    auto a = RefineOnTrees(source, target, initial, retrying);
    auto b = RefineOnTrees(source, target, initial, settling);
    ASSERT_TRUE(a.ok()) << a.status();
    ASSERT_TRUE(b.ok()) << b.status();
    ASSERT_FALSE(a->stages.empty());
    ASSERT_FALSE(b->stages.empty());
    EXPECT_LE(b->stages.back().iterations, a->stages.back().iterations) << what;
    iterations_retrying += a->stages.back().iterations;
    iterations_settling += b->stages.back().iterations;
    // Displacement at the target cube's half-length, in finest cells.
    const double edge = a->stages.back().cell_edge;
    const Eigen::AngleAxisd turn(a->T_target_source.linear().transpose() *
                                 b->T_target_source.linear());
    const double shift =
        (a->T_target_source.translation() - b->T_target_source.translation()).norm();
    EXPECT_LT((shift + turn.angle() * target.half_length()) / edge, 0.1) << what;
    EXPECT_EQ(a->valid, b->valid) << what;
  };
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> angle(5.0, 15.0);
  std::uniform_real_distribution<double> offset(0.05, 0.1);
  for (uint64_t seed = 1; seed <= 8; ++seed) {
    auto pair = MakeObjectPair(UnseenPairs(DisturbanceKind::kNone, 0), seed);
    ASSERT_TRUE(pair.ok()) << pair.status();
    const Octree source = RefinementTree(pair->source, 6);
    const Octree target = RefinementTree(pair->target, 6);
    compare(source, target, Perturbed(pair->T_target_source, angle(rng) * kDeg, offset(rng), rng),
            "object seed " + std::to_string(seed));
  }
  LidarSequenceOptions lidar;
  lidar.frame_count = 6;
  lidar.seed = 3;
  auto scans = SimulatedScanPair(lidar, 0, 5);
  ASSERT_TRUE(scans.ok()) << scans.status();
  compare(scans->source, scans->target, Eigen::Isometry3d::Identity(), "scan pair");
  EXPECT_LT(iterations_settling, iterations_retrying);
}

// From network-sized errors (5-15 degrees, 0.05-0.1), unseen objects with their source jittered
// by up to 0.03. With the source's own
// coarse cells the coarse stages drift along weakly constrained directions (a laptop's hinge, a
// spring's axis) by up to a cell, even from the true pose, which the finer stages cannot undo;
// re-binned on the target's cells they compare the same parts of the surface
// (TreeRefinementOptions::rebin_coarse_depths).
TEST(TreeRefinementTest, RebinnedCoarseStagesReachTheTruthMoreOften) {
  const PairOptions pair_options =
      UnseenPairs(DisturbanceKind::kJitter, 2);  // 0.03: where the drift costs most
  auto failures = [&](bool rebin) {
    TreeRefinementOptions options;
    options.rebin_coarse_depths = rebin;
    options.noise_polish = false;  // the stages alone (the polish has noise_polish_test.cc)
    return FailuresFromPerturbedStarts(
        pair_options, options, 5.0, [&](const TreeRefinementResult& result) {
          EXPECT_EQ(result.stages.size(), 4u);  // one entry per depth 3..6, rounds folded in
          if (rebin) {
            EXPECT_GE(result.stages[0].rounds, 1);
            EXPECT_LE(result.stages[0].rounds, options.max_rebin_rounds);
          }
        });
  };
  const int own_cells = failures(false);
  const int rebinned = failures(true);
  // 24 and 11 of 60 here (13 before the coarse stages searched two cells and the joint stage's
  // coarser depth weighed by inverse density; 15 before the finest stage also fitted the coarser
  // depth; 14 when the
  // re-binned depths weighed cells by inverse density; clean: 8 and 8; 120 clean pairs: 23 and
  // 17, both measured then).
  EXPECT_LE(rebinned, own_cells - 5);
}

// The re-binned depths count cells (TreeRefinementOptions::coarse_weights = kUniform) instead of
// weighting them by inverse density, which amplified the sparse cells a disturbance makes: with
// 40% uniform outliers (each alone in its cell, each weighing as much as a patch of surface) the
// coarse stages were pulled off the pose. Same starts as above, unseen objects. (Jitter 0.03
// fails on 14 and 15 of these 60 either way from these starts; its gain shows in net+refine.)
TEST(TreeRefinementTest, RebinnedDepthsCountingCellsResistOutliers) {
  const PairOptions pair_options =
      UnseenPairs(DisturbanceKind::kUniformOutliers, 4);  // 40% of the points
  auto failures = [&](WeightScheme coarse_weights) {
    TreeRefinementOptions options;
    options.coarse_weights = coarse_weights;
    return FailuresFromPerturbedStarts(pair_options, options);
  };
  EXPECT_EQ(TreeRefinementOptions{}.coarse_weights, WeightScheme::kUniform);
  const int inverse_density = failures(WeightScheme::kInverseDensity);
  const int cells = failures(WeightScheme::kUniform);
  // 30 and 10 of 60 here (16 and 8 before the coarse stages searched two cells, which reaches the
  // outliers' sparse cells too; 15 and 8 before the finest stage also fitted the coarser depth).
  EXPECT_LE(cells, inverse_density - 4);
}

// The finest stage also fits the next coarser depth (TreeRefinementOptions::joint_finest_stage):
// jittered sources' finest cells hold single noisy samples whose shapes are noise, and the finest
// depth alone stopped where the coarser stages had left the pose. Unseen objects, jitter 0.05,
// from 2-6 degree starts (the pose a converged coarse stage hands over) and from 5-15 degree ones,
// 200 pairs each: the gain is a few pairs in a hundred, which 60 pairs could not tell from noise.
TEST(TreeRefinementTest, JointFinestStageHoldsJitteredPairsCloser) {
  const PairOptions pair_options = UnseenPairs(DisturbanceKind::kJitter, 3);  // 0.05
  auto failures = [&](bool joint) {
    TreeRefinementOptions options;
    options.joint_finest_stage = joint;
    options.noise_polish = false;  // the stages alone (the polish has noise_polish_test.cc)
    int failed = 0;
    for (double min_angle_deg : {2.0, 5.0}) {
      failed += FailuresFromPerturbedStarts(
          pair_options, options, min_angle_deg,
          [&](const TreeRefinementResult& result) { EXPECT_EQ(result.stages.back().joint, joint); },
          200);
    }
    return failed;
  };
  EXPECT_TRUE(TreeRefinementOptions{}.joint_finest_stage);
  const int finest_alone = failures(false);
  const int joint = failures(true);
  // 104 + 108 and 89 + 96 of 2 x 200 here. (On the first 60 pairs alone: 24 + 28 and 23 + 24,
  // where this test used to count; 21 + 23 before the joint stage's coarser depth weighed by
  // inverse density; from 2-6 degrees alone: 31 and 26 before the coarse stages searched two
  // cells, 31 and 24 before the step control's first refused damping became 1e-2.)
  EXPECT_LE(joint, finest_alone - 15);
}

// The re-binned coarse stages search two cells around each moved cell in the 3x3x3 block
// (TreeRefinementOptions::coarse_max_correspondence_distance_cells, coarse_search_27_neighbors):
// under heavy jitter a coarse cell's partner often lies beyond the one cell the finest stage
// searches, and the coarse stages settled short of the truth. Unseen objects, jitter 0.08, from
// 2-6 and 5-15 degree starts.
TEST(TreeRefinementTest, CoarseStagesSearchingTwoCellsHoldHeavyJitterCloser) {
  const PairOptions pair_options = UnseenPairs(DisturbanceKind::kJitter, 4);  // 0.08
  auto failures = [&](const TreeRefinementOptions& options) {
    return FailuresFromPerturbedStarts(pair_options, options, 2.0) +
           FailuresFromPerturbedStarts(pair_options, options, 5.0);
  };
  TreeRefinementOptions defaults;
  EXPECT_TRUE(defaults.coarse_search_27_neighbors);
  EXPECT_EQ(defaults.coarse_max_correspondence_distance_cells, 2.0);
  defaults.noise_polish = false;  // the stages alone (the polish has noise_polish_test.cc)
  TreeRefinementOptions one_cell = defaults;  // the finest stage's search at every depth
  SearchCoarseStagesAsTheFinest(one_cell);
  EXPECT_EQ(one_cell.coarse_search_27_neighbors, defaults.search_27_neighbors);
  EXPECT_EQ(one_cell.coarse_max_correspondence_distance_cells,
            defaults.max_correspondence_distance_cells);
  const int narrow = failures(one_cell);
  const int wide = failures(defaults);
  // 54 + 56 and 48 + 47 of 2 x 60 here. (Not every setting gains from these starts: 40% uniform
  // outliers fail on 15 of 2 x 60 searching one cell and 20 searching two; in net+refine they
  // gain, see the option.)
  EXPECT_LE(wide, narrow - 8);
}

TEST(TreeRefinementTest, JointFinestStageNeedsRebinnedCoarserDepth) {
  PairOptions pair_options;
  auto pair = MakeObjectPair(pair_options, 3);
  ASSERT_TRUE(pair.ok());
  const Octree source = RefinementTree(pair->source, 6);
  const Octree target = RefinementTree(pair->target, 6);
  auto last_stage = [&](const TreeRefinementOptions& options) {
    auto result = RefineOnTrees(source, target, pair->T_target_source, options);
    EXPECT_TRUE(result.ok()) << result.status();
    return result->stages.back();
  };
  const DepthStage joint = last_stage({});
  EXPECT_TRUE(joint.joint);
  EXPECT_GT(joint.coarser_correspondences, 50);  // depth 5's cells around the surface
  TreeRefinementOptions alone;
  alone.joint_finest_stage = false;
  EXPECT_FALSE(last_stage(alone).joint);
  EXPECT_EQ(last_stage(alone).coarser_correspondences, 0);
  TreeRefinementOptions own_cells;  // the coarser depth it would add is a re-binned one
  own_cells.rebin_coarse_depths = false;
  EXPECT_FALSE(last_stage(own_cells).joint);
  TreeRefinementOptions one_depth;  // no coarser stage ran
  one_depth.coarsest_depth = 6;
  EXPECT_FALSE(last_stage(one_depth).joint);
}

TEST(TreeRefinementTest, SimulatedLidarPairFiveFramesApartFromIdentity) {
  LidarSequenceOptions options;
  options.frame_count = 8;
  options.seed = 3;
  auto scans = SimulatedScanPair(options, 0, 5);
  ASSERT_TRUE(scans.ok()) << scans.status();
  const Eigen::Isometry3d truth = scans->T_target_source;
  ASSERT_GT(truth.translation().norm(), 2.0);  // a real motion, not a near-identity
  auto result = RefineOnTrees(scans->source, scans->target, Eigen::Isometry3d::Identity());
  ASSERT_TRUE(result.ok()) << result.status();
  const PairError error = ErrorOf(result->T_target_source, truth);
  EXPECT_LT(error.rotation_deg, 0.2);
  EXPECT_LT(error.translation, 0.1);
  EXPECT_TRUE(result->valid) << result->failure_reason;
  EXPECT_GT(result->fitness, 0.3);
}

// Consecutive frames of a simulated 10 Hz sequence as trees of depth 9, each frame refined onto
// the previous one from the previous frame's true motion (what `rpsr odometry` does with its
// estimate).
class ConsecutiveScans {
 public:
  explicit ConsecutiveScans(const LidarSequenceOptions& options) {
    auto sequence = LidarSequenceSimulator::Create(options);
    EXPECT_TRUE(sequence.ok()) << sequence.status();
    if (!sequence.ok()) return;
    for (int f = 0; f < options.frame_count; ++f) {
      trees_.push_back(RefinementTree(sequence->SimulateFrame(f).cloud, 9));
    }
    poses_ = sequence->T_world_lidar();
  }

  // The length of the mean error vector of the translations a frame (mm): what adds up along a
  // trajectory (noise averages out of it).
  double BiasMm(const TreeRefinementOptions& refinement) const {
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    const int frames = static_cast<int>(trees_.size());
    for (int f = 2; f < frames; ++f) {
      const Eigen::Isometry3d truth = poses_[f - 1].inverse() * poses_[f];
      const Eigen::Isometry3d previous = poses_[f - 2].inverse() * poses_[f - 1];
      auto result = RefineOnTrees(trees_[f], trees_[f - 1], previous, refinement);
      EXPECT_TRUE(result.ok()) << result.status();
      if (result.ok()) sum += 1e3 * (result->T_target_source.translation() - truth.translation());
    }
    return frames > 2 ? (sum / (frames - 2)).norm() : 0.0;
  }

  const std::vector<Octree>& trees() const { return trees_; }

 private:
  std::vector<Octree> trees_;
  std::vector<Eigen::Isometry3d> poses_;
};

// The joint finest stage's coarser depth weighs its cells by inverse density (the default) or
// counts them: counted, the re-binned cells near the sensor, holding arcs of the rings that move
// with it, pulled every estimate the same way and odometry drifted
// (TreeRefinementOptions::joint_coarser_weights). A suburban street; here the mean error vector a
// frame is 1.61 mm counted and 0.45 mm by inverse density.
TEST(TreeRefinementTest, JointStageCoarserDepthDoesNotPullConsecutiveScans) {
  LidarSequenceOptions options;
  options.style = StreetStyle::kSuburban;
  options.frame_count = 25;
  options.seed = 11;
  const ConsecutiveScans scans(options);
  EXPECT_EQ(TreeRefinementOptions{}.joint_coarser_weights, WeightScheme::kInverseDensity);
  TreeRefinementOptions counted_cells;
  counted_cells.joint_coarser_weights = WeightScheme::kUniform;
  const double counted = scans.BiasMm(counted_cells);
  const double inverse_density = scans.BiasMm({});
  std::printf(
      "mean translation error vector a frame: cells counted %.2f mm, inverse density %.2f "
      "mm\n",
      counted, inverse_density);
  EXPECT_LT(inverse_density, 0.5 * counted);
}

// TreeRefinementOptions::line_normals_from_planes: a simulated VLP-16 (16 beams, +-15 degrees,
// 1,800 azimuths) on a suburban street. Most depth-9 cells of such a scan hold one ring's arc;
// given normals across the ring, they pulled every estimate short (the rings move with the
// sensor). Taking the ground's or the wall's normal from an ancestor, the bias a frame is a
// fraction of that (here the mean error vector a frame is 328 mm with their own normals and 8 mm
// with the planes').
// A VLP-16 (`rpsr data lidar --sensor vlp16`) driving a suburban street.
LidarSequenceOptions Vlp16SuburbanDrive(int frame_count) {
  LidarSequenceOptions options;
  options.style = StreetStyle::kSuburban;
  options.frame_count = frame_count;
  options.seed = 11;
  options.sensor = *LidarSensorPreset("vlp16");
  return options;
}

TEST(TreeRefinementTest, LineNodesTakingTheirPlanesNormalDoNotPullSparseScansTogether) {
  const ConsecutiveScans scans(Vlp16SuburbanDrive(16));
  TreeRefinementOptions own_normals;
  own_normals.line_normals_from_planes = false;
  TreeRefinementOptions from_planes;
  from_planes.line_normals_from_planes = true;
  const double own = scans.BiasMm(own_normals);
  const double borrowed = scans.BiasMm(from_planes);
  std::printf("mean translation error vector a frame: own normals %.1f mm, planes' %.1f mm\n", own,
              borrowed);
  EXPECT_LT(borrowed, 0.5 * own);
}

// Left unset, the line rule is chosen from the trees: on for a VLP-16's scans (most of their
// depth-9 cells hold one ring's arc), off for an HDL-64E's (several rings a cell) and for objects
// (too few fine nodes with a shape of their own to tell). The choice runs exactly as the rule
// given explicitly would.
TEST(TreeRefinementTest, UnsetLineRuleIsChosenFromTheScansRings) {
  const LidarSequenceOptions vlp16 = Vlp16SuburbanDrive(3);
  LidarSequenceOptions hdl64 = vlp16;
  hdl64.sensor = LidarSequenceOptions{}.sensor;
  ASSERT_EQ(hdl64.sensor.beam_count, 64);
  const int min_count = TreeRefinementOptions{}.min_count_for_covariance;
  for (const auto& [scanner, options, expected] :
       {std::tuple{"VLP-16", vlp16, true}, std::tuple{"HDL-64E", hdl64, false}}) {
    SCOPED_TRACE(scanner);
    const ConsecutiveScans scans(options);
    ASSERT_EQ(scans.trees().size(), 3u);
    for (const Octree& tree : scans.trees()) {
      const std::optional<double> fraction = LineShapedFraction(tree, min_count);
      ASSERT_TRUE(fraction.has_value());
      std::printf("%s: %.2f of the depth-9 shapes are lines\n", scanner, *fraction);
      EXPECT_EQ(*fraction >= 0.67, expected);
    }
    const Octree& source = scans.trees()[2];
    const Octree& target = scans.trees()[1];
    auto chosen = RefineOnTrees(source, target, Eigen::Isometry3d::Identity());
    TreeRefinementOptions given;
    given.line_normals_from_planes = expected;
    auto explicit_rule = RefineOnTrees(source, target, Eigen::Isometry3d::Identity(), given);
    ASSERT_TRUE(chosen.ok() && explicit_rule.ok());
    EXPECT_EQ(chosen->line_normals_from_planes, expected);
    EXPECT_EQ(explicit_rule->line_normals_from_planes, expected);
    EXPECT_TRUE(chosen->T_target_source.isApprox(explicit_rule->T_target_source, 0.0));
  }

  PairOptions pair_options;
  pair_options.num_points = 2048;
  auto pair = MakeObjectPair(pair_options, 1);
  ASSERT_TRUE(pair.ok()) << pair.status();
  const Octree object = RefinementTree(pair->source, 6);
  EXPECT_FALSE(LineShapedFraction(object, min_count).has_value());
  auto on_objects = RefineOnTrees(object, RefinementTree(pair->target, 6), pair->T_target_source);
  ASSERT_TRUE(on_objects.ok());
  EXPECT_FALSE(on_objects->line_normals_from_planes);

  // Both fractions are needed; their mean decides.
  EXPECT_FALSE(ChooseLineNormalsFromPlanes(std::nullopt, 0.95));
  EXPECT_TRUE(ChooseLineNormalsFromPlanes(0.6, 0.76));
  EXPECT_FALSE(ChooseLineNormalsFromPlanes(0.6, 0.7));
}

// Points on z = 0 (a square), on two walls and a floor of a corridor along x, on a sphere.
struct DegenerateCase {
  std::string name;
  PointCloud (*make)(int, uint64_t);
  std::array<bool, 6> axes;  // (rx, ry, rz, tx, ty, tz)
};

class DegenerateGeometryTest : public ::testing::TestWithParam<DegenerateCase> {};

TEST_P(DegenerateGeometryTest, ReportedInvalidWithTheUnconstrainedAxes) {
  const DegenerateCase& c = GetParam();
  const Octree source = RefinementTree(c.make(8000, 1), 6);
  const Octree target = RefinementTree(c.make(8000, 2), 6);
  const Eigen::Isometry3d initial =
      MakeTransform(RotationFromEulerXyz({0.01, -0.01, 0.01}), Eigen::Vector3d(0.01, 0.01, -0.01));
  auto result = RefineOnTrees(source, target, initial);
  ASSERT_TRUE(result.ok()) << result.status();
  EXPECT_FALSE(result->valid);
  EXPECT_THAT(result->failure_reason, HasSubstr("degenerate"));
  int expected = 0;
  for (bool a : c.axes) expected += a;
  EXPECT_EQ(result->num_degenerate, expected) << result->normalized_eigenvalues.transpose();
  EXPECT_EQ(result->degenerate_axes, c.axes) << result->failure_reason;
  EXPECT_EQ(result->degenerate_directions.cols(), expected);
}

INSTANTIATE_TEST_SUITE_P(
    Shapes, DegenerateGeometryTest,
    ::testing::Values(DegenerateCase{"plane", Plane, {false, false, true, true, true, false}},
                      DegenerateCase{
                          "corridor", Corridor, {false, false, false, true, false, false}},
                      DegenerateCase{"sphere", Sphere, {true, true, true, false, false, false}}),
    [](const auto& info) { return info.param.name; });

TEST(TreeRefinementTest, WellConstrainedObjectIsNotDegenerate) {
  PairOptions pair_options;
  pair_options.num_points = 2048;
  auto pair = MakeObjectPair(pair_options, 1);
  ASSERT_TRUE(pair.ok());
  auto result = RefineOnTrees(RefinementTree(pair->source, 6), RefinementTree(pair->target, 6),
                              pair->T_target_source);
  ASSERT_TRUE(result.ok());
  EXPECT_EQ(result->num_degenerate, 0) << result->normalized_eigenvalues.transpose();
  // The information matrix is symmetric positive definite.
  EXPECT_TRUE(result->information.isApprox(result->information.transpose()));
  EXPECT_GT(result->information.ldlt().vectorD().minCoeff(), 0.0);
}

// A cloud with too few cells to give the correspondences (a few points, one spot, one line) is
// told apart from clouds that do not overlap: the reason says what to fix.
TEST(TreeRefinementTest, TooLittleGeometryIsNamedAsSuch) {
  std::vector<Eigen::Vector3f> line;
  for (int i = 0; i < 500; ++i) line.emplace_back(0.002f * i, 0.004f * i, 0.0f);
  PointCloud line_cloud;
  line_cloud.points = line;
  const Octree source = RefinementTree(line_cloud, 6);
  const Octree target = RefinementTree(Sphere(2000, 2), 6);
  auto result = RefineOnTrees(source, target, Eigen::Isometry3d::Identity());
  ASSERT_TRUE(result.ok()) << result.status();
  EXPECT_FALSE(result->valid);
  EXPECT_THAT(result->failure_reason, HasSubstr("too little geometry: the source's points fill"));
  EXPECT_THAT(result->failure_reason, Not(HasSubstr("no overlap")));
}

TEST(TreeRefinementTest, NoOverlapIsInvalidNotAnError) {
  const Octree source = RefinementTree(Sphere(2000, 1), 6);
  const Octree target = RefinementTree(Sphere(2000, 2), 6);
  const Eigen::Isometry3d far =
      MakeTransform(Eigen::Matrix3d::Identity(), Eigen::Vector3d(100.0, 0.0, 0.0));
  auto result = RefineOnTrees(source, target, far);
  ASSERT_TRUE(result.ok()) << result.status();
  EXPECT_FALSE(result->valid);
  EXPECT_THAT(result->failure_reason, HasSubstr("no overlap"));
  EXPECT_EQ(result->fitness, 0.0);
  EXPECT_TRUE(result->T_target_source.isApprox(far));
}

TEST(TreeRefinementTest, DeterministicAndNeedsOnlyTrees) {
  PairOptions pair_options;
  pair_options.num_points = 2048;
  Octree source, target;
  Eigen::Isometry3d truth;
  {
    // The clouds go out of scope: refinement sees the trees alone.
    auto pair = MakeObjectPair(pair_options, 5);
    ASSERT_TRUE(pair.ok());
    source = RefinementTree(pair->source, 6);
    target = RefinementTree(pair->target, 6);
    truth = pair->T_target_source;
  }
  std::mt19937_64 rng(1);
  const Eigen::Isometry3d initial = Perturbed(truth, 10 * kDeg, 0.05, rng);
  auto a = RefineOnTrees(source, target, initial);
  auto b = RefineOnTrees(source, target, initial);
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_EQ(a->T_target_source.matrix(), b->T_target_source.matrix());
  EXPECT_EQ(a->iterations, b->iterations);
  EXPECT_EQ(a->fitness, b->fitness);
  EXPECT_EQ(a->information, b->information);
}

// A cache shared by several calls (the registrar's starts) only saves work: every call returns
// what a fresh call returns, bit for bit, whatever ran before it with the cache (other starts,
// other depths and regularisation, other trees: the cache re-binds to them).
TEST(TreeRefinementTest, SharedCacheChangesNothing) {
  PairOptions pair_options;
  pair_options.num_points = 2048;
  auto pair = MakeObjectPair(pair_options, 5);
  auto other = MakeObjectPair(pair_options, 6);
  ASSERT_TRUE(pair.ok() && other.ok());
  const Octree source = RefinementTree(pair->source, 6);
  const Octree target = RefinementTree(pair->target, 6);
  const Octree other_source = RefinementTree(other->source, 6);
  const Octree other_target = RefinementTree(other->target, 6);
  std::mt19937_64 rng(2);
  TreeRefinementOptions finer;
  finer.coarsest_depth = 4;
  TreeRefinementOptions own_cells;
  own_cells.rebin_coarse_depths = false;
  own_cells.covariance_epsilon = 3e-3;
  struct Call {
    const Octree* source;
    const Octree* target;
    Eigen::Isometry3d initial;
    TreeRefinementOptions options;
  };
  const std::vector<Call> calls = {
      {&source, &target, Perturbed(pair->T_target_source, 10 * kDeg, 0.05, rng), {}},
      {&source, &target, Eigen::Isometry3d::Identity(), {}},
      {&source, &target, Perturbed(pair->T_target_source, 5 * kDeg, 0.02, rng), finer},
      {&source, &target, Perturbed(pair->T_target_source, 5 * kDeg, 0.02, rng), own_cells},
      {&other_source, &other_target, Perturbed(other->T_target_source, 8 * kDeg, 0.04, rng), {}},
      {&source, &target, Eigen::Isometry3d::Identity(), {}},
  };
  TreeRefinementCache cache;
  for (size_t i = 0; i < calls.size(); ++i) {
    const Call& c = calls[i];
    auto fresh = RefineOnTrees(*c.source, *c.target, c.initial, c.options);
    auto shared = RefineOnTrees(*c.source, *c.target, c.initial, c.options, cache);
    ASSERT_TRUE(fresh.ok() && shared.ok()) << i;
    ExpectSameRefinement(*fresh, *shared, "call " + std::to_string(i));
  }
}

TEST(TreeRefinementTest, EvaluateOnlyMeasuresWithoutMoving) {
  PairOptions pair_options;
  pair_options.num_points = 2048;
  auto pair = MakeObjectPair(pair_options, 5);
  ASSERT_TRUE(pair.ok());
  const Octree source = RefinementTree(pair->source, 6);
  const Octree target = RefinementTree(pair->target, 6);
  std::mt19937_64 rng(3);
  const Eigen::Isometry3d initial = Perturbed(pair->T_target_source, 10 * kDeg, 0.05, rng);
  auto refined = RefineOnTrees(source, target, initial);
  ASSERT_TRUE(refined.ok());
  TreeRefinementOptions measure;
  measure.evaluate_only = true;
  // At the refined pose: the same statistics as the refinement reported there.
  auto at_refined = RefineOnTrees(source, target, refined->T_target_source, measure);
  ASSERT_TRUE(at_refined.ok());
  EXPECT_EQ(at_refined->T_target_source.matrix(), refined->T_target_source.matrix());
  EXPECT_EQ(at_refined->iterations, 0);
  EXPECT_FALSE(at_refined->converged);
  EXPECT_EQ(at_refined->stages.size(), 1u);  // the finest depth only
  EXPECT_EQ(at_refined->fitness_depth, refined->fitness_depth);
  EXPECT_NEAR(at_refined->fitness, refined->fitness, 1e-9);
  EXPECT_NEAR(at_refined->inlier_rmse, refined->inlier_rmse, 1e-9);
  // The information includes the coarser depth of the finest stage (joint_finest_stage), whose
  // cells the refinement re-binned where that stage started and the measurement at its end:
  // equal to within a fraction of a percent (3e-4 here), not bit for bit.
  EXPECT_TRUE(at_refined->information.isApprox(refined->information, 1e-2));
  EXPECT_TRUE(at_refined->valid);
  {  // Without it they are the same numbers.
    TreeRefinementOptions alone;
    alone.joint_finest_stage = false;
    auto refined_alone = RefineOnTrees(source, target, initial, alone);
    ASSERT_TRUE(refined_alone.ok());
    alone.evaluate_only = true;
    auto at_alone = RefineOnTrees(source, target, refined_alone->T_target_source, alone);
    ASSERT_TRUE(at_alone.ok());
    EXPECT_TRUE(at_alone->information.isApprox(refined_alone->information, 1e-9));
    EXPECT_NEAR(at_alone->fitness, refined_alone->fitness, 1e-9);
  }
  // At the perturbed start: worse on every count, and not moved.
  auto at_initial = RefineOnTrees(source, target, initial, measure);
  ASSERT_TRUE(at_initial.ok());
  EXPECT_EQ(at_initial->T_target_source.matrix(), initial.matrix());
  EXPECT_LT(at_initial->fitness, refined->fitness);
  // The refinement records its last update per stage; the finest one is small once converged.
  // (Its step control ends the stage when no damped step lowers the cost, so the last step taken
  // need not be below the epsilon test: with the coarser depth in the finest stage's cost, this
  // pair's was 5e-3 of a cell.)
  ASSERT_FALSE(refined->stages.empty());
  EXPECT_GT(refined->stages.front().last_update_rotation_rad, 0.0);
  EXPECT_TRUE(refined->stages.back().converged);
  EXPECT_LT(refined->stages.back().last_update_translation,
            1e-2 * refined->stages.back().cell_edge);
}

TEST(TreeRefinementTest, RejectsBadInputs) {
  const Octree tree = RefinementTree(Sphere(500, 1), 5);
  EXPECT_EQ(RefineOnTrees(Octree(), tree, Eigen::Isometry3d::Identity()).status().code(),
            absl::StatusCode::kInvalidArgument);
  Eigen::Isometry3d scaled = Eigen::Isometry3d::Identity();
  scaled.linear() *= 2.0;
  EXPECT_EQ(RefineOnTrees(tree, tree, scaled).status().code(), absl::StatusCode::kInvalidArgument);
  TreeRefinementOptions options;
  options.finest_depth = 6;  // deeper than the trees
  EXPECT_EQ(RefineOnTrees(tree, tree, Eigen::Isometry3d::Identity(), options).status().code(),
            absl::StatusCode::kInvalidArgument);
  options = {};
  options.coarsest_depth = 5;
  options.finest_depth = 4;
  EXPECT_EQ(RefineOnTrees(tree, tree, Eigen::Isometry3d::Identity(), options).status().code(),
            absl::StatusCode::kInvalidArgument);
  options = {};
  options.max_iterations_per_depth = 0;
  EXPECT_EQ(RefineOnTrees(tree, tree, Eigen::Isometry3d::Identity(), options).status().code(),
            absl::StatusCode::kInvalidArgument);
  options = {};
  options.settled_step_cells = std::nan("");
  EXPECT_THAT(RefineOnTrees(tree, tree, Eigen::Isometry3d::Identity(), options).status().message(),
              HasSubstr("settled_step_cells"));
  options.settled_step_cells = -0.01;
  EXPECT_EQ(RefineOnTrees(tree, tree, Eigen::Isometry3d::Identity(), options).status().code(),
            absl::StatusCode::kInvalidArgument);
  options = {};
  options.max_iterations_per_depth = 0;
  // ValidateTreeRefinement is the same check alone.
  EXPECT_EQ(ValidateTreeRefinement(tree, tree, Eigen::Isometry3d::Identity(), options).code(),
            absl::StatusCode::kInvalidArgument);
  EXPECT_TRUE(ValidateTreeRefinement(tree, tree, Eigen::Isometry3d::Identity()).ok());
}

}  // namespace
}  // namespace rpsr::core
