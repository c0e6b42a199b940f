// The start along a refined answer's weakest direction (core/refine/weak_direction_start.h): the
// step moves the pose along the direction the information constrains least, by the length asked
// for; an answer stepped off along it on a helix spring is brought back toward the truth by the
// nodes left without a partner; an answer with none left is not stepped.
#include "core/refine/weak_direction_start.h"

#include <cmath>
#include <cstdio>
#include <optional>

#include "Eigen/Eigenvalues"
#include "core/data/object_pairs.h"
#include "core/data/registration_metrics.h"
#include "core/data/transform_convention.h"
#include "core/refine/cell_index.h"
#include "core/refine/node_closeness.h"
#include "core/refine/symmetry_starts.h"
#include "core/synth/seeded_random.h"
#include "gtest/gtest.h"
#include "tests/core/refine/refinement_test_geometry.h"
#include "tests/core/refine/refinement_test_util.h"

namespace rpsr::core {
namespace {

using testing_util::RefinementTree;
using Vector6d = Eigen::Matrix<double, 6, 1>;

constexpr int kDepth = 6;

// The motion from `from` to `to` in the information's units: rotation about information_center
// times the lever arms, then the translation (TreeRefinementResult::information).
Vector6d MotionInMetres(const TreeRefinementResult& r, const Eigen::Isometry3d& from,
                        const Eigen::Isometry3d& to) {
  const Eigen::Isometry3d D = to * from.inverse();
  const Eigen::AngleAxisd turn(D.linear());
  const Eigen::Vector3d& c = r.information_center;
  Vector6d u;
  u << (turn.angle() * turn.axis()).cwiseProduct(r.rotation_lever_arms),
      D.translation() - c + D.linear() * c;
  return u;
}

Eigen::Matrix<double, 6, 6> ScaledInformation(const TreeRefinementResult& r) {
  Vector6d s = Vector6d::Ones();
  for (int a = 0; a < 3; ++a) s[a] = 1.0 / r.rotation_lever_arms[a];
  return s.asDiagonal() * r.information * s.asDiagonal();
}

// The unseen study's clean pair 48 (`rpsr eval --protocol objects --split unseen --count 100
// --seed 1`), a helix spring whose net+refine answer ended 7.2 degrees off along its screw.
using Spring = testing_util::StudyPairAtTruth;

Spring MakeSpring() { return testing_util::CleanStudyPairAtTruth(1, 48, kDepth); }

TEST(WeakDirectionStartTest, TheStepMovesAlongTheLeastConstrainedDirectionByItsLength) {
  const Spring spring = MakeSpring();
  ASSERT_TRUE(spring.at_truth.valid) << spring.at_truth.failure_reason;
  const Eigen::Matrix<double, 6, 6> H = ScaledInformation(spring.at_truth);
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 6, 6>> solver(H);
  for (double step : {0.01, -0.02, 0.05}) {
    const Eigen::Isometry3d moved = StepAlongWeakestDirection(spring.at_truth, step);
    const Vector6d u = MotionInMetres(spring.at_truth, spring.at_truth.T_target_source, moved);
    EXPECT_NEAR(u.norm(), std::abs(step), 1e-6 * std::abs(step) + 1e-9) << step;
    // Its cost per squared metre is the smallest eigenvalue's: no direction is weaker.
    EXPECT_NEAR(u.dot(H * u) / u.squaredNorm(), solver.eigenvalues()[0],
                1e-6 * solver.eigenvalues()[5])
        << step;
  }
  EXPECT_TRUE(StepAlongWeakestDirection(spring.at_truth, 0.0)
                  .isApprox(spring.at_truth.T_target_source, 1e-12));
  // Nothing to step along without information.
  TreeRefinementResult empty = spring.at_truth;
  empty.information.setZero();
  EXPECT_TRUE(StepAlongWeakestDirection(empty, 0.05).isApprox(empty.T_target_source, 1e-12));
  // Several steps at once are each step alone, and none without information.
  const std::vector<double> steps = {0.01, -0.02, 0.0, 0.05};
  const std::vector<Eigen::Isometry3d> stepped = StepsAlongWeakestDirection(spring.at_truth, steps);
  ASSERT_EQ(stepped.size(), steps.size());
  for (size_t k = 0; k < steps.size(); ++k) {
    EXPECT_EQ(stepped[k].matrix(), StepAlongWeakestDirection(spring.at_truth, steps[k]).matrix())
        << steps[k];
  }
  EXPECT_TRUE(StepsAlongWeakestDirection(empty, steps).empty());
}

TEST(WeakDirectionStartTest, ASpringSteppedOffAlongItsScrewIsSteppedBack) {
  const Spring spring = MakeSpring();
  const int depth = SymmetryDepth(spring.source, spring.target);
  const double edge = CellEdge(spring.target, depth);
  int stepped_back = 0;
  for (double cells : {-3.0, -2.0, 2.0, 3.0}) {
    TreeRefinementResult answer = spring.at_truth;
    answer.T_target_source = StepAlongWeakestDirection(spring.at_truth, cells * edge);
    const double answer_error =
        ErrorOf(answer.T_target_source, spring.pair.T_target_source).rotation_deg;
    const std::optional<WeakDirectionStart> start =
        BestWeakDirectionStart(spring.source, spring.target, answer, depth);
    if (!start.has_value()) continue;
    ++stepped_back;
    const double start_error =
        ErrorOf(start->T_target_source, spring.pair.T_target_source).rotation_deg;
    std::printf(
        "answer %+.0f cells off (%.2f deg): start %+.1f cells, %.2f deg, far %.4f -> %.4f\n", cells,
        answer_error, start->step_cells, start_error, start->answer_far_fraction,
        start->far_fraction);
    EXPECT_LT(start_error, answer_error) << cells;
    EXPECT_LT(start->step_cells * cells, 0.0) << "stepped the wrong way from " << cells;
    EXPECT_LE(start->far_fraction,
              start->answer_far_fraction - WeakDirectionOptions{}.min_far_fraction_drop);
  }
  EXPECT_GE(stepped_back, 3);
}

// A lattice on itself at the identity leaves no node without a partner: no step can leave fewer.
TEST(WeakDirectionStartTest, AnAnswerLeavingNoNodeFarIsNotStepped) {
  PointCloud lattice;
  for (int i = 0; i < 5; ++i) {
    for (int j = 0; j < 5; ++j) {
      for (int k = 0; k < 5; ++k) {
        lattice.points.emplace_back(-1.0f + 0.5f * i, -1.0f + 0.4f * j, -1.0f + 0.3f * k);
      }
    }
  }
  const Octree tree = RefinementTree(lattice, kDepth);
  auto refined = RefineOnTrees(tree, tree, Eigen::Isometry3d::Identity());
  ASSERT_TRUE(refined.ok()) << refined.status();
  EXPECT_FALSE(BestWeakDirectionStart(tree, tree, *refined, kDepth - 1).has_value());
  // Depths the trees do not hold measure nothing.
  EXPECT_FALSE(BestWeakDirectionStart(tree, tree, *refined, 0).has_value());
  EXPECT_FALSE(BestWeakDirectionStart(tree, tree, *refined, kDepth + 1).has_value());
}

}  // namespace
}  // namespace rpsr::core
