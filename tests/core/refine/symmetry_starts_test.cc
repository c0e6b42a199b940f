// FindSelfSymmetries, BestSymmetricTwin, the breaking nodes and FindContinuousSymmetry
// (core/refine/symmetry_starts.h): a gear's teeth are found as turns about its axis, a body of
// revolution's axis is found (a squat one's too, whose principal axis is off) and a mug's is
// not, an object without a symmetry has none, the feature that breaks a gear's symmetry (its pin)
// leaves more nodes without a partner a tooth off than at the truth, and its nodes meet the
// other cloud's at the truth only.
#include "core/refine/symmetry_starts.h"

#include <cmath>
#include <cstdio>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "Eigen/Eigenvalues"
#include "core/data/object_pairs.h"
#include "core/refine/node_closeness.h"
#include "core/synth/seeded_random.h"
#include "core/synth/shape_families.h"
#include "gtest/gtest.h"
#include "tests/core/refine/refinement_test_util.h"

namespace rpsr::core {
namespace {

using testing_util::RefinementTree;

// The first `count` unseen pairs of `family` among the seeds 1, 2, ... (clean, 1,024 points).
std::vector<ObjectPair> PairsOf(const std::string& family, int count) {
  PairOptions options;
  options.split = ObjectSplit::kM2Unseen;
  std::vector<ObjectPair> pairs;
  for (uint64_t i = 0; i < 400 && static_cast<int>(pairs.size()) < count; ++i) {
    absl::StatusOr<ObjectPair> pair = MakeObjectPair(options, DeriveSeed(2, i));
    EXPECT_TRUE(pair.ok()) << pair.status();
    if (pair.ok() && ShapeFamilies()[pair->family_index].name == family) {
      pairs.push_back(*std::move(pair));
    }
  }
  EXPECT_EQ(static_cast<int>(pairs.size()), count) << family;
  return pairs;
}

TEST(SymmetryStartsTest, AGearsTeethAreTurnsAboutItsAxis) {
  for (const ObjectPair& pair : PairsOf("gear", 3)) {
    const Octree target = RefinementTree(pair.target, 6);
    const std::vector<SelfSymmetry> found = FindSelfSymmetries(target);
    // 8 to 16 teeth: the turns by k/n of a circle, k = 1 .. n - 1, about the disc's normal (the
    // principal axis of least variance).
    ASSERT_GE(found.size(), 7u);
    ASSERT_LE(found.size(), 15u);
    const double step = found.front().angle_deg;
    EXPECT_NEAR(step, 360.0 / static_cast<double>(found.size() + 1), 1e-9);
    for (size_t k = 0; k < found.size(); ++k) {
      EXPECT_EQ(found[k].axis, 0);
      EXPECT_NEAR(found[k].angle_deg, step * static_cast<double>(k + 1), 1e-6);
      EXPECT_LE(found[k].self_distance_cells, SelfSymmetryOptions{}.max_self_distance_cells);
      // About the target's centre of mass: it stays in place.
      const Eigen::Vector3d centre = target.level(0).center_of_mass[0].cast<double>();
      EXPECT_LT((found[k].S * centre - centre).norm(), 1e-9);
    }
  }
}

// A gear whose turn by a tooth leaves its nodes 0.906 cells from its own (pair 1061 of `rpsr eval
// --protocol objects --split unseen --count 2000 --seed 1`): found since session 41 raised
// max_self_distance_cells to 1.0, missed at the 0.9 before it (the answer then ended a tooth off).
TEST(SymmetryStartsTest, AGearWhoseToothReadsJustAboveNineTenthsIsFound) {
  PairOptions options;
  options.split = ObjectSplit::kM2Unseen;
  absl::StatusOr<ObjectPair> pair = MakeObjectPair(options, DeriveSeed(1, 1061));
  ASSERT_TRUE(pair.ok()) << pair.status();
  ASSERT_EQ(ShapeFamilies()[pair->family_index].name, "gear");
  const Octree target = RefinementTree(pair->target, 6);
  const std::vector<SelfSymmetry> found = FindSelfSymmetries(target);
  ASSERT_EQ(found.size(), 13u);  // 14 teeth
  EXPECT_GT(found.front().self_distance_cells, 0.9);
  EXPECT_LE(found.front().self_distance_cells, 1.0);
  SelfSymmetryOptions before;
  before.max_self_distance_cells = 0.9;
  EXPECT_TRUE(FindSelfSymmetries(target, before).empty());
}

TEST(SymmetryStartsTest, AnObjectWithoutSymmetryHasNone) {
  for (const ObjectPair& pair : PairsOf("sofa", 3)) {
    EXPECT_TRUE(FindSelfSymmetries(RefinementTree(pair.target, 6)).empty());
  }
}

// testing_util::BodyOfRevolution's and RoundTable's axes pass through this point.
const Eigen::Vector3d kBodyCentre(0.1, -0.05, 0.2);

double DistanceFromLine(const Eigen::Vector3d& p, const Eigen::Vector3d& point,
                        const Eigen::Vector3d& axis) {
  return (p - point).cross(axis).norm();
}

// The angle between an axis and the target's principal axis nearest it, in degrees.
double PrincipalAxisErrorDeg(const Octree& target, const Eigen::Vector3d& axis) {
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver(
      target.Covariance(0, 0).cast<double>());
  double best = 0.0;
  for (int k = 0; k < 3; ++k)
    best = std::max(best, std::abs(solver.eigenvectors().col(k).dot(axis)));
  return std::acos(std::min(best, 1.0)) * 180.0 / M_PI;
}

TEST(SymmetryStartsTest, ABodyOfRevolutionIsFoundAboutItsAxisAndAMugIsNot) {
  const Eigen::Vector3d axis = Eigen::Vector3d(1.0, -2.0, 0.5).normalized();
  for (uint64_t seed : {1, 2, 3}) {
    const Octree vase = RefinementTree(testing_util::BodyOfRevolution(1024, seed, axis), 6);
    const std::optional<ContinuousSymmetry> found = FindContinuousSymmetry(vase);
    ASSERT_TRUE(found.has_value()) << "seed " << seed;
    EXPECT_GT(std::abs(found->axis.dot(axis)), 0.999) << found->axis.transpose();
    EXPECT_LE(found->max_far_fraction, SelfSymmetryOptions{}.max_continuous_far_fraction);
    const Eigen::Vector3d centre = vase.level(0).center_of_mass[0].cast<double>();
    EXPECT_LT((found->centre - centre).norm(), 1e-9);
    // A step that leaves fewer than two turns measures nothing, so nothing is found.
    SelfSymmetryOptions coarse_step;
    coarse_step.continuous_step_deg = 200.0;
    EXPECT_FALSE(FindContinuousSymmetry(vase, coarse_step).has_value()) << "seed " << seed;
    // Every 32nd point on a small handle: no turn maps it onto itself, and its nodes stay far
    // under nearly every turn.
    const Octree mug = RefinementTree(testing_util::BodyOfRevolution(1024, seed, axis, true), 6);
    EXPECT_FALSE(FindContinuousSymmetry(mug).has_value()) << "seed " << seed;
  }
  // A gear's teeth are a discrete symmetry; a sofa has none.
  for (const char* family : {"gear", "sofa"}) {
    for (const ObjectPair& pair : PairsOf(family, 3)) {
      EXPECT_FALSE(FindContinuousSymmetry(RefinementTree(pair.target, 6)).has_value()) << family;
    }
  }
}

// A squat body's principal axis is off by degrees, and turns about it leave many nodes far: the
// target registered onto itself finds the true axis (session 31; session 30's detector, which
// turned about the principal axis, missed such round tables).
TEST(SymmetryStartsTest, ASquatBodyOfRevolutionIsFoundAboutItsTrueAxisNotItsPrincipalOne) {
  const Eigen::Vector3d axis = Eigen::Vector3d(0.3, 0.2, 1.0).normalized();
  SelfSymmetryOptions principal_only;
  principal_only.refine_continuous_axis = false;
  int principal_off = 0;
  for (uint64_t seed : {1, 2, 3, 4}) {
    const Octree table = RefinementTree(testing_util::RoundTable(1024, seed, axis), 6);
    const double principal_error = PrincipalAxisErrorDeg(table, axis);
    std::printf("seed %d: principal axis %.2f degrees off\n", static_cast<int>(seed),
                principal_error);
    const std::optional<ContinuousSymmetry> found = FindContinuousSymmetry(table);
    ASSERT_TRUE(found.has_value()) << "seed " << seed;
    EXPECT_GT(std::abs(found->axis.dot(axis)), std::cos(M_PI / 180.0)) << found->axis.transpose();
    EXPECT_LE(found->max_far_fraction, SelfSymmetryOptions{}.max_continuous_far_fraction);
    // Through the centre of mass, which sampling moves off the true axis (0.012-0.041 on these
    // seeds; its spread across the axis is ~0.0125, the top's radial spread 0.4 over 32).
    EXPECT_LT(DistanceFromLine(found->centre, kBodyCentre, axis), 0.05);
    if (principal_error > 2.0) {
      ++principal_off;
      EXPECT_FALSE(FindContinuousSymmetry(table, principal_only).has_value()) << "seed " << seed;
    }
  }
  // The case the refinement exists for occurs among these seeds.
  EXPECT_GE(principal_off, 1);
}

// A guitar's half turns: one about each principal axis, through the centre of mass; the flip front
// to back (about its long axis, the axis of greatest variance) leaves its nodes near its own, the
// other two do not.
TEST(SymmetryStartsTest, AGuitarFlippedFrontToBackNearlyMapsOntoItself) {
  for (const ObjectPair& pair : PairsOf("guitar", 2)) {
    const Octree target = RefinementTree(pair.target, 6);
    const std::vector<SelfSymmetry> turns = HalfTurnsAboutPrincipalAxes(target);
    ASSERT_EQ(turns.size(), 3u);
    const Eigen::Vector3d centre = target.level(0).center_of_mass[0].cast<double>();
    std::vector<Eigen::Isometry3d> poses;
    for (size_t k = 0; k < turns.size(); ++k) {
      EXPECT_EQ(turns[k].axis, static_cast<int>(k));
      EXPECT_EQ(turns[k].angle_deg, 180.0);
      EXPECT_NEAR(turns[k].S.linear().trace(), -1.0, 1e-9);  // a half turn
      EXPECT_LT((turns[k].S * centre - centre).norm(), 1e-9);
      poses.push_back(turns[k].S);
    }
    const std::vector<double> far = TwoWayFarNodeFractions(
        target, target, poses, SymmetryDepth(target, target), SelfSymmetryOptions{}.far_cells);
    std::printf("guitar half turns leave %.3f %.3f %.3f far\n", far[0], far[1], far[2]);
    EXPECT_LT(far[2], 0.02);
    EXPECT_GT(far[0], 0.1);
    EXPECT_GT(far[1], 0.1);
    // The same target as its own source: only the flip fits about as well as the identity.
    const std::vector<Eigen::Isometry3d> alike =
        TwinsFittingAlike(target, target, Eigen::Isometry3d::Identity(), turns, 0.02);
    ASSERT_EQ(alike.size(), 1u);
    EXPECT_TRUE(alike.front().isApprox(turns[2].S));
  }
  EXPECT_TRUE(HalfTurnsAboutPrincipalAxes(Octree{}).empty());
}

TEST(SymmetryStartsTest, ATinyOrEmptyTreeHasNone) {
  PointCloud one;
  one.points.emplace_back(0.1f, 0.2f, 0.3f);
  EXPECT_TRUE(FindSelfSymmetries(RefinementTree(one, 1)).empty());
  EXPECT_FALSE(FindContinuousSymmetry(RefinementTree(one, 1)).has_value());
  EXPECT_FALSE(BestSymmetricTwin(RefinementTree(one, 1), RefinementTree(one, 1),
                                 Eigen::Isometry3d::Identity(), {})
                   .has_value());
}

TEST(SymmetryStartsTest, TheTruthLeavesFewerNodesFarThanATurnByATooth) {
  for (const ObjectPair& pair : PairsOf("gear", 3)) {
    const Octree source = RefinementTree(pair.source, 6);
    const Octree target = RefinementTree(pair.target, 6);
    const std::vector<SelfSymmetry> found = FindSelfSymmetries(target);
    ASSERT_FALSE(found.empty());
    const double at_truth = TwoWayFarFraction(source, target, pair.T_target_source);
    for (const SelfSymmetry& tooth : {found.front(), found.back()}) {
      // An answer a tooth off (either way), and the twin search from it.
      const Eigen::Isometry3d off = tooth.S * pair.T_target_source;
      EXPECT_LT(at_truth, TwoWayFarFraction(source, target, off)) << tooth.angle_deg;
      // Any drop (the default asks for 0.8% of the nodes, which a pin of few nodes may not reach).
      SelfSymmetryOptions any_drop;
      any_drop.min_far_fraction_drop = 0.0;
      const std::optional<SymmetricTwin> twin =
          BestSymmetricTwin(source, target, off, found, any_drop);
      ASSERT_TRUE(twin.has_value()) << tooth.angle_deg;
      EXPECT_LT(twin->far_fraction, twin->answer_far_fraction);
    }
  }
}

TEST(SymmetryStartsTest, TheTwinMarginIsHigherAtTheTruthThanATurnOff) {
  for (const ObjectPair& pair : PairsOf("gear", 3)) {
    const Octree source = RefinementTree(pair.source, 6);
    const Octree target = RefinementTree(pair.target, 6);
    const std::vector<SelfSymmetry> found = FindSelfSymmetries(target);
    ASSERT_FALSE(found.empty());
    const std::optional<double> at_truth =
        SymmetricTwinMargin(source, target, pair.T_target_source, found, 1.9);
    const std::optional<double> off =
        SymmetricTwinMargin(source, target, found.front().S * pair.T_target_source, found, 1.9);
    ASSERT_TRUE(at_truth.has_value() && off.has_value());
    EXPECT_GT(*at_truth, *off);
    EXPECT_LT(*off, 0.0);  // a twin (the truth) leaves fewer nodes without a partner
  }
  const ObjectPair sofa = PairsOf("sofa", 1).front();
  EXPECT_FALSE(SymmetricTwinMargin(RefinementTree(sofa.source, 6), RefinementTree(sofa.target, 6),
                                   sofa.T_target_source, {}, 1.9)
                   .has_value());
}

// The nodes that break a gear's symmetry are its pin's: a few, together, off the disc; an object
// without near-symmetries has none to find.
TEST(SymmetryStartsTest, TheNodesThatBreakAGearsSymmetryAreItsPin) {
  for (const ObjectPair& pair : PairsOf("gear", 3)) {
    const Octree source = RefinementTree(pair.source, 6);
    const Octree target = RefinementTree(pair.target, 6);
    const std::vector<SelfSymmetry> found = FindSelfSymmetries(target);
    ASSERT_FALSE(found.empty());
    const BreakingNodes breaking = FindBreakingNodes(source, target, pair.T_target_source, found);
    ASSERT_EQ(breaking.depth, 5);
    for (const auto& [tree, marks] :
         {std::pair{&source, &breaking.source}, std::pair{&target, &breaking.target}}) {
      const Octree::Level& level = tree->level(breaking.depth);
      ASSERT_EQ(marks->size(), level.size());
      std::vector<Eigen::Vector3d> marked;
      for (size_t i = 0; i < level.size(); ++i) {
        if ((*marks)[i]) marked.push_back(level.center_of_mass[i].cast<double>());
      }
      // 2-16 of ~800 nodes on the unseen gears; a pin is 0.2-0.4 long on a unit-radius gear.
      EXPECT_GE(marked.size(), 1u);
      EXPECT_LE(marked.size(), 20u);
      Eigen::Vector3d mean = Eigen::Vector3d::Zero();
      for (const Eigen::Vector3d& p : marked) mean += p / static_cast<double>(marked.size());
      for (const Eigen::Vector3d& p : marked) {
        EXPECT_LT((p - mean).norm(), 0.35 * tree->half_length());
      }
    }
  }
  const ObjectPair sofa = PairsOf("sofa", 1).front();
  const Octree sofa_target = RefinementTree(sofa.target, 6);
  const BreakingNodes none =
      FindBreakingNodes(RefinementTree(sofa.source, 6), sofa_target, sofa.T_target_source,
                        FindSelfSymmetries(sofa_target));
  EXPECT_TRUE(none.source.empty() && none.target.empty());
}

// At the truth the pins meet; a tooth off (either way) they do not, and the twin search from there
// returns the truth. From the truth it returns nothing. A disturbed source (20% outliers, which
// hide its own symmetry) keeps its pin through the target's turns carried over by the answer.
TEST(SymmetryStartsTest, TheTwinWhosePinsMeetIsTheTruth) {
  for (const DisturbanceKind disturbance :
       {DisturbanceKind::kNone, DisturbanceKind::kUniformOutliers}) {
    PairOptions options;
    options.split = ObjectSplit::kM2Unseen;
    options.disturbance = disturbance;
    options.disturbance_level = 3;
    int gears = 0;
    for (uint64_t i = 0; i < 400 && gears < 3; ++i) {
      absl::StatusOr<ObjectPair> pair = MakeObjectPair(options, DeriveSeed(2, i));
      ASSERT_TRUE(pair.ok()) << pair.status();
      if (ShapeFamilies()[pair->family_index].name != "gear") continue;
      ++gears;
      const Octree source = RefinementTree(pair->source, 6);
      const Octree target = RefinementTree(pair->target, 6);
      const std::vector<SelfSymmetry> found = FindSelfSymmetries(target);
      ASSERT_FALSE(found.empty());
      const BreakingNodes at_truth =
          FindBreakingNodes(source, target, pair->T_target_source, found);
      EXPECT_FALSE(TwinMatchingBreakingNodes(source, target, pair->T_target_source, found, at_truth)
                       .has_value())
          << "pair " << i;
      const double truth_match =
          BreakingNodeMatches(source, target, at_truth, {pair->T_target_source}).front();
      EXPECT_GE(truth_match, 0.6) << "pair " << i;
      for (const SelfSymmetry& tooth : {found.front(), found.back()}) {
        const Eigen::Isometry3d off = tooth.S * pair->T_target_source;
        const BreakingNodes breaking = FindBreakingNodes(source, target, off, found);
        EXPECT_LE(BreakingNodeMatches(source, target, breaking, {off}).front(), 0.2)
            << "pair " << i << " turned " << tooth.angle_deg;
        const std::optional<BreakingNodeTwin> twin =
            TwinMatchingBreakingNodes(source, target, off, found, breaking);
        ASSERT_TRUE(twin.has_value()) << "pair " << i << " turned " << tooth.angle_deg;
        const Eigen::AngleAxisd rest(twin->T_target_source.linear() *
                                     pair->T_target_source.linear().transpose());
        EXPECT_LT(std::abs(rest.angle()) * 180.0 / M_PI, 1e-6) << "pair " << i;
        EXPECT_GE(twin->match, twin->answer_match + SelfSymmetryOptions{}.min_breaking_match_gain);
        // Too few target breaking nodes to choose on: no twin.
        SelfSymmetryOptions too_few;
        too_few.min_breaking_nodes = static_cast<int>(breaking.target.size()) + 1;
        EXPECT_FALSE(
            TwinMatchingBreakingNodes(source, target, off, found, breaking, too_few).has_value());
      }
    }
    EXPECT_EQ(gears, 3);
  }
}

// A gear on a long round axle (a pulley on its shaft, a drill chuck): the axle's nodes lie near
// themselves under any turn about it, so the gear's half-tooth turn reads barely farther than
// its tooth turn (a small dip), as a real screwdriver's six-lobed handle did (session 26).
PointCloud OnAnAxle(const PointCloud& gear, uint64_t seed) {
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();
  for (const auto& p : gear.points) centre += p.cast<double>();
  centre /= static_cast<double>(gear.points.size());
  Eigen::Matrix3d spread = Eigen::Matrix3d::Zero();
  for (const auto& p : gear.points) {
    const Eigen::Vector3d d = p.cast<double>() - centre;
    spread += d * d.transpose();
  }
  const Eigen::Vector3d axis =
      Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(spread).eigenvectors().col(0);
  const Eigen::Vector3d e1 = axis.unitOrthogonal();
  const Eigen::Vector3d e2 = axis.cross(e1);
  PointCloud out = gear;
  SeededRandom random(seed);
  for (size_t k = 0; k < gear.points.size(); ++k) {  // as many points again, radius 0.3
    const double theta = random.Uniform(0.0, 2.0 * M_PI);
    const Eigen::Vector3d p = centre + random.Uniform(-0.8, 0.8) * axis +
                              0.3 * (std::cos(theta) * e1 + std::sin(theta) * e2);
    out.points.push_back(p.cast<float>());
  }
  return out;
}

TEST(SymmetryStartsTest, AGearOnAnAxleKeepsItsTeethThoughHalfATurnIsNearlyAsNear) {
  // Over 25 gears so mounted, a dip of 0.15 cells (the default before session 26) found the
  // teeth of 1, the default's 0.05 of 16 (a scratch count); here the first eight unseen gears.
  SelfSymmetryOptions strict;
  strict.min_dip_cells = 0.15;
  int found_by_default = 0;
  int found_by_strict = 0;
  for (const ObjectPair& pair : PairsOf("gear", 8)) {
    const Octree target = RefinementTree(OnAnAxle(pair.target, pair.object_seed), 6);
    const std::vector<SelfSymmetry> found = FindSelfSymmetries(target);
    found_by_strict += FindSelfSymmetries(target, strict).empty() ? 0 : 1;
    if (found.empty()) continue;
    ++found_by_default;
    // Turns by k/n about the gear's axis, n its tooth count.
    const double step = 360.0 / static_cast<double>(found.size() + 1);
    for (size_t k = 0; k < found.size(); ++k) {
      EXPECT_EQ(found[k].axis, 0);
      EXPECT_NEAR(found[k].angle_deg, step * static_cast<double>(k + 1), 1e-6);
    }
  }
  std::printf("gears on an axle with their teeth found: %d of 8 (a dip of 0.15: %d)\n",
              found_by_default, found_by_strict);
  EXPECT_GE(found_by_default, 4);
  EXPECT_GE(found_by_default, found_by_strict + 2);
}

}  // namespace
}  // namespace rpsr::core
