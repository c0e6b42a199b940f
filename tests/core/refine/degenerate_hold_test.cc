// HoldDegenerateDirections: the motion from the prior loses exactly its components along the
// degenerate directions, read in the refinement's own perturbation (rotation about
// information_center, rotation rows in metres through the lever arms).
#include "core/refine/degenerate_hold.h"

#include <cmath>

#include "core/data/transform_convention.h"
#include "gtest/gtest.h"

namespace rpsr::core {
namespace {

constexpr double kPi = 3.14159265358979323846;

// [R | c - R c + v]: rotation R about `center`, then translation v (the information's
// perturbation, TreeRefinementResult::information).
Eigen::Isometry3d MotionAbout(const Eigen::Vector3d& center, const Eigen::Matrix3d& R,
                              const Eigen::Vector3d& v) {
  return MakeTransform(R, center - R * center + v);
}

Eigen::Matrix3d TurnZ(double rad) {
  return Eigen::AngleAxisd(rad, Eigen::Vector3d::UnitZ()).toRotationMatrix();
}

TreeRefinementResult Degenerate(const Eigen::Isometry3d& refined, const Eigen::VectorXd& direction,
                                const Eigen::Vector3d& center, const Eigen::Vector3d& levers) {
  TreeRefinementResult r;
  r.T_target_source = refined;
  r.information_center = center;
  r.rotation_lever_arms = levers;
  r.num_degenerate = 1;
  r.degenerate_directions = direction.normalized();
  return r;
}

void ExpectNear(const Eigen::Isometry3d& got, const Eigen::Isometry3d& want) {
  EXPECT_TRUE(got.matrix().isApprox(want.matrix(), 1e-12)) << "got\n"
                                                           << got.matrix() << "\nwant\n"
                                                           << want.matrix();
}

const Eigen::Isometry3d kPrior =
    MakeTransform(Eigen::AngleAxisd(0.4, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix(),
                  Eigen::Vector3d(1.0, -2.0, 0.5));
const Eigen::Vector3d kCenter(3.0, 1.0, -1.0);

TEST(DegenerateHoldTest, WithoutDegenerateDirectionsTheRefinedPoseIsReturned) {
  TreeRefinementResult r;
  r.T_target_source = MotionAbout(kCenter, TurnZ(0.1), Eigen::Vector3d(0.3, 0.2, 0.1)) * kPrior;
  ExpectNear(HoldDegenerateDirections(r, kPrior), r.T_target_source);
}

TEST(DegenerateHoldTest, TranslationAlongTheDegenerateAxisIsThePriors) {
  Eigen::VectorXd along_x = Eigen::VectorXd::Zero(6);
  along_x[3] = 1.0;  // translation along x: a corridor along its length
  const Eigen::Matrix3d turn = TurnZ(2.0 * kPi / 180.0);
  const TreeRefinementResult r =
      Degenerate(MotionAbout(kCenter, turn, Eigen::Vector3d(0.5, 0.1, -0.05)) * kPrior, along_x,
                 kCenter, Eigen::Vector3d::Ones());
  ExpectNear(HoldDegenerateDirections(r, kPrior),
             MotionAbout(kCenter, turn, Eigen::Vector3d(0.0, 0.1, -0.05)) * kPrior);
}

TEST(DegenerateHoldTest, RotationAboutTheDegenerateAxisIsThePriorsAboutTheCenter) {
  Eigen::VectorXd about_z = Eigen::VectorXd::Zero(6);
  about_z[2] = 1.0;  // a sphere turning about its centre, a cylinder about its axis
  const Eigen::Vector3d shift(0.2, -0.1, 0.3);
  const TreeRefinementResult r = Degenerate(MotionAbout(kCenter, TurnZ(0.2), shift) * kPrior,
                                            about_z, kCenter, Eigen::Vector3d(2, 2, 2));
  ExpectNear(HoldDegenerateDirections(r, kPrior),
             MotionAbout(kCenter, Eigen::Matrix3d::Identity(), shift) * kPrior);
}

// A screw-like direction mixing a turn about z and a shift along x: in metres, 0.1 rad at a lever
// arm of 2 m is 0.2 m. Read with the lever arms, a motion along it is removed entirely and one
// across it kept entirely; read without them, neither would be.
TEST(DegenerateHoldTest, MixedDirectionsAreReadInMetresThroughTheLeverArms) {
  Eigen::VectorXd screw = Eigen::VectorXd::Zero(6);
  screw[2] = 1.0;
  screw[3] = 1.0;
  const Eigen::Vector3d levers(5.0, 5.0, 2.0);
  const TreeRefinementResult along =
      Degenerate(MotionAbout(kCenter, TurnZ(0.1), Eigen::Vector3d(0.2, 0, 0)) * kPrior, screw,
                 kCenter, levers);
  ExpectNear(HoldDegenerateDirections(along, kPrior), kPrior);
  const TreeRefinementResult across =
      Degenerate(MotionAbout(kCenter, TurnZ(0.1), Eigen::Vector3d(-0.2, 0, 0)) * kPrior, screw,
                 kCenter, levers);
  ExpectNear(HoldDegenerateDirections(across, kPrior), across.T_target_source);
}

}  // namespace
}  // namespace rpsr::core
