// MeanNodeDistanceCells: the mean capped distance from a moved source's nodes to the target's
// nearest nodes of one depth, in the target's cells (what the registrar reads to choose between
// two starts' answers that fit equally well).
#include "core/refine/node_closeness.h"

#include <cmath>
#include <limits>
#include <vector>

#include "core/data/object_pairs.h"
#include "core/data/transform_convention.h"
#include "gtest/gtest.h"
#include "tests/core/refine/refinement_test_geometry.h"
#include "tests/core/refine/refinement_test_util.h"

namespace rpsr::core {
namespace {

using testing_util::RefinementTree;

constexpr int kDepth = 6;

// A 5 x 5 x 5 lattice 0.5 apart in [-1, 1]^3: one point a depth-6 cell, every neighbour ~16
// cells away, so a small shift's nearest target node is the node's own.
PointCloud Lattice() {
  PointCloud cloud;
  for (int i = 0; i < 5; ++i) {
    for (int j = 0; j < 5; ++j) {
      for (int k = 0; k < 5; ++k)
        cloud.points.emplace_back(-1.0f + 0.5f * i, -1.0f + 0.5f * j, -1.0f + 0.5f * k);
    }
  }
  return cloud;
}

double EdgeOf(const Octree& tree, int depth) {
  return 2.0 * tree.half_length() / static_cast<double>(1 << depth);
}

Eigen::Isometry3d Shift(const Eigen::Vector3d& v) {
  return MakeTransform(Eigen::Matrix3d::Identity(), v);
}

TEST(NodeClosenessTest, ATreeOnItselfIsAtZero) {
  const Octree tree = RefinementTree(testing_util::Plane(2000, 1), kDepth);
  EXPECT_EQ(MeanNodeDistanceCells(tree, tree, Eigen::Isometry3d::Identity(), kDepth), 0.0);
}

TEST(NodeClosenessTest, AShiftWithinTheCapReadsAsItsLengthInCells) {
  const Octree tree = RefinementTree(Lattice(), kDepth);
  const double edge = EdgeOf(tree, kDepth);
  for (double cells : {0.25, 0.5, 1.0, 1.9}) {
    const Eigen::Vector3d v = cells * edge * Eigen::Vector3d(1, 2, -2).normalized();
    EXPECT_NEAR(MeanNodeDistanceCells(tree, tree, Shift(v), kDepth), cells, 1e-5) << cells;
  }
}

TEST(NodeClosenessTest, NodesWithoutAPartnerWithinTwoCellsCountTheCap) {
  const Octree tree = RefinementTree(Lattice(), kDepth);
  const double edge = EdgeOf(tree, kDepth);
  // 3 cells from their own node and ~13 from the next: all capped.
  EXPECT_NEAR(MeanNodeDistanceCells(tree, tree, Shift(Eigen::Vector3d(3.0 * edge, 0, 0)), kDepth),
              NodeClosenessOptions::kCapCells, 1e-9);
  // A non-finite pose reads the cap too.
  EXPECT_NEAR(MeanNodeDistanceCells(tree, tree, Shift(Eigen::Vector3d(std::nan(""), 0, 0)), kDepth),
              NodeClosenessOptions::kCapCells, 1e-9);
  // Far outside the target's cube.
  EXPECT_NEAR(MeanNodeDistanceCells(tree, tree, Shift(Eigen::Vector3d(0, 1e6, 0)), kDepth),
              NodeClosenessOptions::kCapCells, 1e-9);
}

TEST(NodeClosenessTest, FarNodeFractionsCountTheNodesBeyondTheThresholdPerPose) {
  const Octree tree = RefinementTree(Lattice(), kDepth);
  const double edge = EdgeOf(tree, kDepth);
  const Eigen::Isometry3d one_cell = Shift(Eigen::Vector3d(edge, 0, 0));
  const std::vector<double> far =
      FarNodeFractions(tree, tree,
                       {Eigen::Isometry3d::Identity(), one_cell, Shift(Eigen::Vector3d(0.25, 0, 0)),
                        Shift(Eigen::Vector3d(0.5, 0, 0))},
                       kDepth, 1.5);
  ASSERT_EQ(far.size(), 4u);
  EXPECT_EQ(far[0], 0.0);
  // Every node 1 cell off: within 1.5 cells, beyond 0.5.
  EXPECT_EQ(far[1], 0.0);
  EXPECT_EQ(FarNodeFractions(tree, tree, {one_cell}, kDepth, 0.5).front(), 1.0);
  // The 25 nodes of the lattice's last x layer moved out of the cube, the rest onto their
  // neighbours 0.5 away (~16 cells: beyond the cap, so far as well): all far.
  EXPECT_EQ(far[2], 1.0);
  // Moved by a whole lattice step, 100 of the 125 land on a node again.
  EXPECT_NEAR(far[3], 25.0 / 125.0, 1e-9);
  EXPECT_LT(FarNodeFractions(tree, tree, {Eigen::Isometry3d::Identity()}, 0, 1.5).front(), 0.0);
  EXPECT_LT(FarNodeFractions(tree, tree, {Eigen::Isometry3d::Identity()}, kDepth + 1, 1.5).front(),
            0.0);
}

// FarNodeFractions against a search of every target node: its search of the 27 coarser cells
// around a node, ended at the first partner near enough, gives the same fractions, for an object
// pair under turns of 0-60 degrees and shifts (the turn contrast's and the twin margin's poses),
// at the depth they read and one finer.
TEST(NodeClosenessTest, FarNodeFractionsEqualASearchOfEveryNode) {
  auto pair = MakeObjectPair(testing_util::UnseenPairs(DisturbanceKind::kGaussianNoise, 1), 5);
  ASSERT_TRUE(pair.ok()) << pair.status();
  const Octree source = RefinementTree(pair->source, kDepth);
  const Octree target = RefinementTree(pair->target, kDepth);
  std::vector<Eigen::Isometry3d> poses;
  for (double deg : {0.0, 5.0, 15.0, 30.0, 45.0, 60.0}) {
    for (int axis = 0; axis < 3; ++axis) {
      Eigen::Isometry3d turn = Eigen::Isometry3d::Identity();
      turn.linear() = Eigen::AngleAxisd(deg * M_PI / 180.0, Eigen::Vector3d::Unit(axis)).matrix();
      turn.translation() = Eigen::Vector3d(0.01 * axis, -0.02, 0.03 * deg / 60.0);
      poses.push_back(turn * pair->T_target_source);
    }
  }
  for (int depth : {kDepth - 1, kDepth}) {
    for (double far_cells : {0.5, 1.0, 1.9}) {
      const std::vector<double> got = FarNodeFractions(source, target, poses, depth, far_cells);
      const Octree::Level& s = source.level(depth);
      const Octree::Level& t = target.level(depth);
      const double far = far_cells * EdgeOf(target, depth);
      ASSERT_LE(s.size(), NodeClosenessOptions{}.max_source_nodes);  // every node is sampled
      for (size_t p = 0; p < poses.size(); ++p) {
        size_t beyond = 0;
        for (size_t i = 0; i < s.size(); ++i) {
          const Eigen::Vector3d q = poses[p] * s.center_of_mass[i].cast<double>();
          double nearest2 = std::numeric_limits<double>::infinity();
          for (size_t j = 0; j < t.size(); ++j) {
            nearest2 = std::min(nearest2, (t.center_of_mass[j].cast<double>() - q).squaredNorm());
          }
          beyond += std::sqrt(nearest2) > far;
        }
        EXPECT_EQ(got[p], static_cast<double>(beyond) / static_cast<double>(s.size()))
            << "depth " << depth << ", far " << far_cells << " cells, pose " << p;
      }
    }
  }
}

// With stop_above, a pose whose far fraction stays at or below it reads its own fraction bit for
// bit, and one past it reads a value above stop_above and at most its own (the weak-direction
// start's way there, which only asks which steps can still win), with and without a mask.
TEST(NodeClosenessTest, FarNodeFractionsStopAboveKeepsThePosesWithinIt) {
  auto pair = MakeObjectPair(testing_util::UnseenPairs(DisturbanceKind::kGaussianNoise, 1), 5);
  ASSERT_TRUE(pair.ok()) << pair.status();
  const Octree source = RefinementTree(pair->source, kDepth);
  const Octree target = RefinementTree(pair->target, kDepth);
  std::vector<Eigen::Isometry3d> poses;
  for (double deg : {0.0, 2.0, 5.0, 10.0, 20.0, 40.0}) {
    Eigen::Isometry3d turn = Eigen::Isometry3d::Identity();
    turn.linear() = Eigen::AngleAxisd(deg * M_PI / 180.0, Eigen::Vector3d::UnitZ()).matrix();
    poses.push_back(turn * pair->T_target_source);
  }
  std::vector<uint8_t> every_other(source.level(kDepth).size(), 0);
  for (size_t i = 0; i < every_other.size(); i += 2) every_other[i] = 1;
  NodeClosenessOptions masked;
  masked.source_nodes = &every_other;
  for (const NodeClosenessOptions& options : {NodeClosenessOptions{}, masked}) {
    const std::vector<double> full = FarNodeFractions(source, target, poses, kDepth, 1.5, options);
    ASSERT_EQ(full.size(), poses.size());
    ASSERT_GT(full.back(), full.front());  // the turns spread the fractions across the bounds
    for (double stop_above : {0.0, 0.05, 0.2, 0.5}) {
      const std::vector<double> got =
          FarNodeFractions(source, target, poses, kDepth, 1.5, options, stop_above);
      ASSERT_EQ(got.size(), poses.size());
      int past = 0, stopped_early = 0;
      for (size_t p = 0; p < poses.size(); ++p) {
        if (full[p] <= stop_above) {
          EXPECT_EQ(got[p], full[p]) << "pose " << p << ", stop above " << stop_above;
        } else {
          ++past;
          stopped_early += got[p] < full[p];
          EXPECT_GT(got[p], stop_above) << "pose " << p << ", stop above " << stop_above;
          EXPECT_LE(got[p], full[p]) << "pose " << p << ", stop above " << stop_above;
        }
      }
      // The count does stop: the turned poses' many far nodes are not all counted.
      if (stop_above == 0.05) {
        EXPECT_GT(past, 0);
        EXPECT_GT(stopped_early, 0);
      }
    }
  }
}

// TwoWayFarNodeFractionsWithinDrop against TwoWayFarNodeFractions of every pose: the answer's
// fraction the same, each candidate that may leave at least the drop less than the answer its own
// fraction bit for bit, the others unmeasured, so that the least qualifying candidate is the same;
// and nothing measured when the drop exceeds what the answer leaves.
TEST(NodeClosenessTest, TwoWayFarWithinDropKeepsTheCandidatesThatMayQualify) {
  auto pair = MakeObjectPair(testing_util::UnseenPairs(DisturbanceKind::kGaussianNoise, 1), 5);
  ASSERT_TRUE(pair.ok()) << pair.status();
  const Octree source = RefinementTree(pair->source, kDepth);
  const Octree target = RefinementTree(pair->target, kDepth);
  // The answer 3 degrees off the truth; candidates turned back to it and far beyond.
  auto turned = [&](double deg) {
    Eigen::Isometry3d turn = Eigen::Isometry3d::Identity();
    turn.linear() = Eigen::AngleAxisd(deg * M_PI / 180.0, Eigen::Vector3d::UnitY()).matrix();
    return turn * pair->T_target_source;
  };
  const Eigen::Isometry3d answer = turned(3.0);
  std::vector<Eigen::Isometry3d> candidates;
  for (double deg : {40.0, 15.0, 6.0, 0.0, -1.5, -25.0}) candidates.push_back(turned(deg));
  std::vector<Eigen::Isometry3d> every = {answer};
  every.insert(every.end(), candidates.begin(), candidates.end());
  const std::vector<double> full = TwoWayFarNodeFractions(source, target, every, kDepth, 1.5);
  for (double drop : {0.0, 0.01, 0.05}) {
    const TwoWayFarWithinDrop got =
        TwoWayFarNodeFractionsWithinDrop(source, target, answer, candidates, kDepth, 1.5, drop);
    EXPECT_EQ(got.answer, full[0]);
    ASSERT_EQ(got.candidates.size(), candidates.size());
    const double most = full[0] - drop;
    int least_full = -1, least_got = -1, measured = 0;
    for (size_t k = 0; k < candidates.size(); ++k) {
      const double f = full[k + 1];
      if (f >= 0.0 && f <= most && (least_full < 0 || f < full[least_full + 1])) {
        least_full = static_cast<int>(k);
      }
      const double g = got.candidates[k];
      if (g >= 0.0) {
        ++measured;
        EXPECT_EQ(g, f) << "candidate " << k << ", drop " << drop;
        if (least_got < 0 || g < got.candidates[least_got]) least_got = static_cast<int>(k);
      } else {
        EXPECT_GT(f, most) << "candidate " << k << " left out, drop " << drop;
      }
    }
    if (least_got >= 0 && got.candidates[least_got] > most) least_got = -1;
    EXPECT_EQ(least_got, least_full) << "drop " << drop;
    EXPECT_GE(least_full, 0) << "the candidates at the truth leave fewer nodes far, drop " << drop;
    // Candidates 40 and -25 degrees off cannot qualify and are left unmeasured.
    EXPECT_LT(measured, static_cast<int>(candidates.size())) << "drop " << drop;
  }
  const TwoWayFarWithinDrop none = TwoWayFarNodeFractionsWithinDrop(
      source, target, answer, candidates, kDepth, 1.5, full[0] + 0.01);
  EXPECT_EQ(none.answer, full[0]);
  for (double g : none.candidates) EXPECT_LT(g, 0.0);
}

// The exact capped nearest distance, whatever search finds it (the cells' bounding boxes pass
// over cells that cannot hold a nearer partner): against every target node, with and without a
// mask of partners, under turns that leave many nodes without one.
TEST(NodeClosenessTest, MeanNodeDistanceEqualsASearchOfEveryNode) {
  auto pair = MakeObjectPair(testing_util::UnseenPairs(DisturbanceKind::kGaussianNoise, 1), 7);
  ASSERT_TRUE(pair.ok()) << pair.status();
  const Octree source = RefinementTree(pair->source, kDepth);
  const Octree target = RefinementTree(pair->target, kDepth);
  for (int depth : {kDepth - 1, kDepth}) {
    const Octree::Level& s = source.level(depth);
    const Octree::Level& t = target.level(depth);
    std::vector<uint8_t> every_third(t.size(), 0);
    for (size_t j = 0; j < t.size(); j += 3) every_third[j] = 1;
    for (const std::vector<uint8_t>* partners :
         {static_cast<std::vector<uint8_t>*>(nullptr), &every_third}) {
      NodeClosenessOptions options;
      options.target_nodes = partners;
      for (double deg : {0.0, 10.0, 45.0}) {
        Eigen::Isometry3d turn = Eigen::Isometry3d::Identity();
        turn.linear() =
            Eigen::AngleAxisd(deg * M_PI / 180.0, Eigen::Vector3d(1, 2, 3).normalized()).matrix();
        const Eigen::Isometry3d pose = turn * pair->T_target_source;
        const double cap = NodeClosenessOptions::kCapCells * EdgeOf(target, depth);
        ASSERT_LE(s.size(), options.max_source_nodes);  // every node is sampled
        double sum = 0.0;
        for (size_t i = 0; i < s.size(); ++i) {
          const Eigen::Vector3d q = pose * s.center_of_mass[i].cast<double>();
          double nearest2 = cap * cap;
          for (size_t j = 0; j < t.size(); ++j) {
            if (partners != nullptr && !(*partners)[j]) continue;
            nearest2 = std::min(nearest2, (t.center_of_mass[j].cast<double>() - q).squaredNorm());
          }
          sum += std::sqrt(nearest2);
        }
        const double expected = sum / static_cast<double>(s.size()) / EdgeOf(target, depth);
        EXPECT_NEAR(MeanNodeDistanceCells(source, target, pose, depth, options), expected, 1e-12)
            << "depth " << depth << ", " << deg << " degrees, mask " << (partners != nullptr);
      }
    }
  }
}

TEST(NodeClosenessTest, TheSampleIsAnEvenStrideOverTheSourceNodes) {
  const Octree tree = RefinementTree(Lattice(), kDepth);
  const double edge = EdgeOf(tree, kDepth);
  // Moving only the first node (in Morton order) away: read by a one-node sample, diluted 125
  // times by the full one.
  PointCloud moved = Lattice();
  const Eigen::Vector3f first = tree.level(kDepth).center_of_mass[0];
  for (Eigen::Vector3f& p : moved.points) {
    if ((p - first).norm() < 1e-6f) p.x() += static_cast<float>(0.5 * edge);
  }
  const Octree source = RefinementTree(moved, kDepth);
  ASSERT_EQ(source.half_length(), tree.half_length());
  NodeClosenessOptions one;
  one.max_source_nodes = 1;
  EXPECT_NEAR(MeanNodeDistanceCells(source, tree, Eigen::Isometry3d::Identity(), kDepth, one), 0.5,
              1e-5);
  EXPECT_NEAR(MeanNodeDistanceCells(source, tree, Eigen::Isometry3d::Identity(), kDepth),
              0.5 / 125.0, 1e-6);
}

TEST(NodeClosenessTest, APlateSlidAlongItselfIsFartherThanInPlace) {
  // Two independent samples of one square plate: slid by four cells along the plate, every node
  // still lies ON the target's plane (what fitness reads), yet the nodes past the edge lose their
  // partners and the interior's nearest partners are no closer on average.
  const Octree target = RefinementTree(testing_util::Plane(1000, 1), kDepth);
  const Octree source = RefinementTree(testing_util::Plane(1000, 2), kDepth);
  const double edge = EdgeOf(target, kDepth);
  const double in_place =
      MeanNodeDistanceCells(source, target, Eigen::Isometry3d::Identity(), kDepth);
  const double slid =
      MeanNodeDistanceCells(source, target, Shift(Eigen::Vector3d(4.0 * edge, 0, 0)), kDepth);
  EXPECT_GT(in_place, 0.0);
  EXPECT_GT(slid, 1.02 * in_place);  // 1.031 against 1.061 cells
}

TEST(NodeClosenessTest, UnmeasurableDepthsAreNegative) {
  const Octree tree = RefinementTree(Lattice(), kDepth);
  EXPECT_LT(MeanNodeDistanceCells(tree, tree, Eigen::Isometry3d::Identity(), 0), 0.0);
  EXPECT_LT(MeanNodeDistanceCells(tree, tree, Eigen::Isometry3d::Identity(), kDepth + 1), 0.0);
  const Octree shallow = RefinementTree(Lattice(), 3);
  EXPECT_LT(MeanNodeDistanceCells(tree, shallow, Eigen::Isometry3d::Identity(), kDepth), 0.0);
  NodeClosenessOptions none;
  none.max_source_nodes = 0;
  EXPECT_LT(MeanNodeDistanceCells(tree, tree, Eigen::Isometry3d::Identity(), kDepth, none), 0.0);
}

}  // namespace
}  // namespace rpsr::core
