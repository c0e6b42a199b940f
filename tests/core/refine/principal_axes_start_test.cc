// The starts from the clouds' principal frames (core/refine/principal_axes_start.h): four proper
// rotations that put the centres of mass together, one of them the truth when the two clouds are
// the same points, the likeliest first; none for a target that a half turn about a principal axis
// maps onto itself (a box) or that has no frame (a line).
#include "core/refine/principal_axes_start.h"

#include <cstdint>
#include <random>

#include "core/cloud/point_cloud.h"
#include "core/data/registration_metrics.h"
#include "core/data/transform_convention.h"
#include "core/refine/symmetry_starts.h"
#include "gtest/gtest.h"
#include "tests/core/refine/refinement_test_util.h"

namespace rpsr::core {
namespace {

using testing_util::RefinementTree;

constexpr int kDepth = 6;
constexpr double kFarCells = 1.5;

// Points uniform in axis-aligned boxes (min corner, size), `n` in all, in proportion to volume.
PointCloud Boxes(const std::vector<std::pair<Eigen::Vector3f, Eigen::Vector3f>>& boxes, int n,
                 uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  float total = 0.0f;
  for (const auto& box : boxes) total += box.second.prod();
  PointCloud cloud;
  for (const auto& [corner, size] : boxes) {
    const int count = static_cast<int>(n * size.prod() / total);
    for (int i = 0; i < count; ++i) {
      cloud.points.push_back(corner + Eigen::Vector3f(u(rng), u(rng), u(rng)).cwiseProduct(size));
    }
  }
  return cloud;
}

// An L of two bars of unequal length with a bump at one end: no half turn maps it onto itself.
PointCloud Bracket(uint64_t seed) {
  return Boxes({{{-0.8f, -0.5f, -0.1f}, {1.6f, 0.3f, 0.2f}},
                {{-0.8f, -0.2f, -0.1f}, {0.3f, 0.9f, 0.2f}},
                {{0.5f, -0.5f, 0.1f}, {0.3f, 0.3f, 0.3f}}},
               2048, seed);
}

const Eigen::Isometry3d kTruth =
    MakeTransform(Eigen::AngleAxisd(2.2, Eigen::Vector3d(0.3, -0.8, 0.5).normalized()).matrix(),
                  Eigen::Vector3d(0.2, -0.1, 0.3));

TEST(PrincipalAxesStartTest, FourRotationsPutTheCentresTogetherAndTheTruthComesFirst) {
  const PointCloud source = Bracket(1);
  const Octree source_tree = RefinementTree(source, kDepth);
  const Octree target_tree = RefinementTree(TransformedCloud(source, kTruth.cast<float>()), kDepth);
  const std::vector<PrincipalAxesStart> starts = PrincipalAxesStarts(
      source_tree, target_tree, SymmetryDepth(source_tree, target_tree), kFarCells);
  ASSERT_EQ(starts.size(), 4u);
  const Eigen::Vector3d source_centre = source_tree.level(0).center_of_mass[0].cast<double>();
  const Eigen::Vector3d target_centre = target_tree.level(0).center_of_mass[0].cast<double>();
  for (const PrincipalAxesStart& start : starts) {
    const Eigen::Matrix3d R = start.T_target_source.linear();
    EXPECT_NEAR(R.determinant(), 1.0, 1e-9);
    EXPECT_TRUE((R.transpose() * R).isIdentity(1e-9));
    EXPECT_LT((start.T_target_source * source_centre - target_centre).norm(), 1e-9);
    EXPECT_GE(start.far_fraction, starts.front().far_fraction);
  }
  // The same points turned: the frames match up to the signs, and the right signs leave no node
  // without a partner.
  EXPECT_LT(ErrorOf(starts.front().T_target_source, kTruth).rotation_deg, 0.1);
  EXPECT_LT(starts.front().far_fraction, 0.01);
  // The other three are the truth turned by half a circle about a principal axis.
  for (size_t i = 1; i < starts.size(); ++i) {
    EXPECT_NEAR(ErrorOf(starts[i].T_target_source, kTruth).rotation_deg, 180.0, 0.1) << i;
    EXPECT_GT(starts[i].far_fraction, 0.1) << i;
  }
}

TEST(PrincipalAxesStartTest, IndependentSamplesStartNearTheTruth) {
  const Octree source_tree = RefinementTree(Bracket(1), kDepth);
  const Octree target_tree =
      RefinementTree(TransformedCloud(Bracket(2), kTruth.cast<float>()), kDepth);
  const std::vector<PrincipalAxesStart> starts = PrincipalAxesStarts(
      source_tree, target_tree, SymmetryDepth(source_tree, target_tree), kFarCells);
  ASSERT_EQ(starts.size(), 4u);
  EXPECT_LT(ErrorOf(starts.front().T_target_source, kTruth).rotation_deg, 5.0);
}

TEST(PrincipalAxesStartTest, ATargetAHalfTurnMapsOntoItselfGetsNone) {
  // A box of three unequal sides: every half turn about its axes maps it onto itself, so its
  // frame's signs are not its shape's.
  const PointCloud box = Boxes({{{-0.8f, -0.4f, -0.2f}, {1.6f, 0.8f, 0.4f}}}, 2048, 3);
  const Octree source_tree = RefinementTree(box, kDepth);
  const Octree target_tree = RefinementTree(TransformedCloud(box, kTruth.cast<float>()), kDepth);
  EXPECT_TRUE(PrincipalAxesStarts(source_tree, target_tree, SymmetryDepth(source_tree, target_tree),
                                  kFarCells)
                  .empty());
  // The bracket against the box's frame is still measured: only the target's symmetry matters.
  const Octree bracket_tree = RefinementTree(Bracket(1), kDepth);
  EXPECT_EQ(PrincipalAxesStarts(source_tree, bracket_tree, SymmetryDepth(source_tree, bracket_tree),
                                kFarCells)
                .size(),
            4u);
}

TEST(PrincipalAxesStartTest, ALineHasNoFrame) {
  PointCloud line;
  for (int i = 0; i < 500; ++i) line.points.emplace_back(-1.0f + 0.004f * i, 0.0f, 0.0f);
  const Octree line_tree = RefinementTree(line, kDepth);
  const Octree bracket_tree = RefinementTree(Bracket(1), kDepth);
  EXPECT_TRUE(PrincipalAxesStarts(line_tree, bracket_tree, SymmetryDepth(line_tree, bracket_tree),
                                  kFarCells)
                  .empty());
  EXPECT_TRUE(PrincipalAxesStarts(bracket_tree, line_tree, SymmetryDepth(bracket_tree, line_tree),
                                  kFarCells)
                  .empty());
}

}  // namespace
}  // namespace rpsr::core
