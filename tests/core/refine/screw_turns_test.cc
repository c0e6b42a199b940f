// Screw near-symmetries (core/refine/screw_turns.h): a motion read back as the screw it is; unseen
// helix springs found about their coil's axis with an advance, and not bodies of revolution (a
// plain turn) nor a laptop (whose self-registration ends at some other motion); the screw's turns
// each advanced by their share.
#include "core/refine/screw_turns.h"

#include <cmath>
#include <cstdio>
#include <optional>
#include <vector>

#include "core/refine/cell_index.h"
#include "core/refine/node_closeness.h"
#include "core/synth/shape_families.h"
#include "gtest/gtest.h"
#include "tests/core/refine/refinement_test_geometry.h"
#include "tests/core/refine/refinement_test_util.h"

namespace rpsr::core {
namespace {

using testing_util::RefinementTree;

Eigen::Isometry3d Screw(const Eigen::Vector3d& point, const Eigen::Vector3d& axis, double angle,
                        double advance_per_rad) {
  Eigen::Isometry3d T = TurnAbout(point, axis, angle);
  T.pretranslate(advance_per_rad * angle * axis);
  return T;
}

TEST(ScrewTurnsTest, AMotionIsReadBackAsItsScrew) {
  const Eigen::Vector3d axis = Eigen::Vector3d(0.3, -0.4, 0.8).normalized();
  const Eigen::Vector3d point(0.2, 0.1, -0.3);
  for (double angle_deg : {40.0, 90.0, 170.0, 179.5}) {
    for (double advance : {0.05, -0.02, 0.0}) {
      const Eigen::Isometry3d T = Screw(point, axis, angle_deg * M_PI / 180.0, advance);
      const Eigen::Vector3d near(1.0, 0.5, 0.2);
      const std::optional<ScrewSymmetry> screw = ScrewOf(T, near, 30.0 * M_PI / 180.0);
      ASSERT_TRUE(screw.has_value()) << angle_deg;
      EXPECT_GT(screw->axis.dot(axis), 1.0 - 1e-9) << angle_deg;
      EXPECT_NEAR(screw->advance_per_rad, advance, 1e-9) << angle_deg;
      // On the axis, at the foot of `near`'s perpendicular.
      const Eigen::Vector3d foot = point + axis.dot(near - point) * axis;
      EXPECT_LT((screw->point - foot).norm(), 1e-9) << angle_deg << " " << advance;
      // The screw's own turn by the same angle is T again.
      EXPECT_TRUE(Screw(screw->point, screw->axis, angle_deg * M_PI / 180.0, screw->advance_per_rad)
                      .isApprox(T, 1e-9));
    }
  }
  // A turn below the minimum has no axis to speak of.
  EXPECT_FALSE(ScrewOf(Screw(point, axis, 0.2, 0.05), point, 30.0 * M_PI / 180.0).has_value());
  EXPECT_FALSE(ScrewOf(Eigen::Isometry3d::Identity(), point, 0.0).has_value());
}

TEST(ScrewTurnsTest, TurnsAdvanceByTheirShareTheShorterWay) {
  const ScrewSymmetry screw{Eigen::Vector3d::UnitZ(), Eigen::Vector3d(1.0, 0.0, 0.0), 0.1};
  const std::vector<SelfSymmetry> turns = ScrewTurns(screw, 15.0);
  ASSERT_EQ(turns.size(), 23u);
  for (const SelfSymmetry& turn : turns) {
    EXPECT_GT(turn.angle_deg, -180.0);
    EXPECT_LE(turn.angle_deg, 180.0);
    const double angle = turn.angle_deg * M_PI / 180.0;
    // A point on the axis only advances along it.
    const Eigen::Vector3d moved = turn.S * screw.point;
    EXPECT_LT((moved - screw.point - 0.1 * angle * Eigen::Vector3d::UnitZ()).norm(), 1e-12);
    EXPECT_NEAR(Eigen::AngleAxisd(turn.S.linear()).angle(), std::abs(angle), 1e-9);
  }
  EXPECT_NEAR(turns.front().angle_deg, 15.0, 1e-9);
  EXPECT_NEAR(turns.back().angle_deg, -15.0, 1e-9);
  EXPECT_TRUE(ScrewTurns(screw, 0.0).empty());
}

// Unseen helix springs (clean pairs of the study's seeds; seed 4's pair 5 ended 44 degrees off
// along its screw before the screw turns): the screw is found about the coil's axis (the mesh's z,
// which the pair's truth takes into the target's frame), advancing, and its quarter maps the target
// nearly onto itself, where the plain quarter turn about the same line leaves more nodes far.
TEST(ScrewTurnsTest, SpringsAreFoundAboutTheirCoilsAxis) {
  struct Case {
    uint64_t seed;
    uint64_t pair;
  };
  for (const Case& c : {Case{4, 5}, Case{3, 71}, Case{5, 6}, Case{1, 45}}) {
    const testing_util::StudyPairAtTruth spring =
        testing_util::CleanStudyPairAtTruth(c.seed, c.pair, 6);
    ASSERT_EQ(ShapeFamilies()[static_cast<size_t>(spring.pair.family_index)].name, "helix_spring");
    const std::optional<ScrewSymmetry> screw = FindScrewSymmetry(spring.target);
    ASSERT_TRUE(screw.has_value()) << c.seed << "/" << c.pair;
    const Eigen::Vector3d coil = spring.pair.T_target_source.linear() * Eigen::Vector3d::UnitZ();
    const double off_deg = std::acos(std::min(1.0, std::abs(screw->axis.dot(coil)))) * 180.0 / M_PI;
    const int depth = SymmetryDepth(spring.target, spring.target);
    const double cell = CellEdge(spring.target, depth);
    const Eigen::Isometry3d quarter =
        Screw(screw->point, screw->axis, 0.5 * M_PI, screw->advance_per_rad);
    const std::vector<double> far = FarNodeFractions(
        spring.target, spring.target, {quarter, TurnAbout(screw->point, screw->axis, 0.5 * M_PI)},
        depth, SelfSymmetryOptions{}.far_cells);
    std::printf(
        "spring %d/%d: axis %.1f deg off the coil's, advance %.2f cells a radian, quarter "
        "screw leaves %.3f far, plain quarter turn %.3f\n",
        static_cast<int>(c.seed), static_cast<int>(c.pair), off_deg, screw->advance_per_rad / cell,
        far[0], far[1]);
    EXPECT_LT(off_deg, 5.0) << c.seed << "/" << c.pair;
    EXPECT_LT(far[0], far[1]) << c.seed << "/" << c.pair;
  }
}

// A body of revolution registered onto itself ends at a plain turn (no advance), so no screw; a
// laptop's self-registration from a quarter turn ends at a motion that advances but maps it onto
// itself nowhere near (seed 1's clean pair 30: over half its nodes far), which the gate refuses.
TEST(ScrewTurnsTest, BodiesOfRevolutionAndALaptopHaveNoScrew) {
  const Eigen::Vector3d axis = Eigen::Vector3d(1.0, -2.0, 0.5).normalized();
  for (uint64_t seed : {1, 2, 3}) {
    const Octree vase = RefinementTree(testing_util::BodyOfRevolution(1024, seed, axis), 6);
    EXPECT_FALSE(FindScrewSymmetry(vase).has_value()) << "seed " << seed;
    // Registered onto itself from a quarter turn it ends at a plain turn: under half a cell's
    // advance.
    TreeRefinementCache cache;
    const Eigen::Vector3d centre = vase.level(0).center_of_mass[0].cast<double>();
    const absl::StatusOr<TreeRefinementResult> self =
        SelfRegisteredFromQuarterTurn(vase, centre, axis, cache);
    ASSERT_TRUE(self.ok()) << self.status();
    const std::optional<ScrewSymmetry> turn = ScrewOf(self->T_target_source, centre, 0.0);
    ASSERT_TRUE(turn.has_value()) << "seed " << seed;
    const double advance =
        std::abs(turn->advance_per_rad) * Eigen::AngleAxisd(self->T_target_source.linear()).angle();
    EXPECT_LT(advance, ScrewOptions{}.min_advance_cells * CellEdge(vase, SymmetryDepth(vase, vase)))
        << "seed " << seed;
  }
  const testing_util::StudyPairAtTruth laptop = testing_util::CleanStudyPairAtTruth(1, 30, 6);
  ASSERT_EQ(ShapeFamilies()[static_cast<size_t>(laptop.pair.family_index)].name, "laptop");
  EXPECT_FALSE(FindScrewSymmetry(laptop.target).has_value());
  ScrewOptions ungated;
  ungated.max_far_fraction = 1.0;
  EXPECT_TRUE(FindScrewSymmetry(laptop.target, ungated).has_value());
}

}  // namespace
}  // namespace rpsr::core
