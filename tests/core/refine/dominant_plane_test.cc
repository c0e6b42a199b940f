// FindDominantPlane and OffPlaneFarFractions (issue 5): a scan's ground is found as the dominant
// family and told from the structure on it; an object has none; the structure, not the ground,
// says whether a shift is right. Bad sizes for the correlative search's node masks are errors.
#include "core/refine/dominant_plane.h"

#include <cmath>
#include <vector>

#include "core/data/training_pairs.h"
#include "core/refine/correlative_start.h"
#include "core/refine/node_closeness.h"
#include "core/synth/seeded_random.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"

namespace rpsr::core {
namespace {

using ::testing::HasSubstr;

Octree TreeOf(const PointCloud& cloud, int depth) {
  BarnesHutTreeOptions options;
  options.max_depth = depth;
  options.neighbor_max_depth = 2;
  auto tree = BuildOctree(cloud, options);
  EXPECT_TRUE(tree.ok()) << tree.status();
  return *std::move(tree);
}

// A sensor's view of an open lot, in its frame (z up, the ground 1.7 m below): rings on the ground
// every degree of elevation from 2 degrees (out to 49 m; most of the points, as in a parking lot),
// boxes the size of cars and a pole. `sensor_x` moves the sensor along x: the rings move with it,
// the structure does not (it is placed in the world and seen from the sensor).
PointCloud OpenLot(double sensor_x, uint64_t seed) {
  SeededRandom random(seed);
  PointCloud cloud;
  for (double elevation = 2.0; elevation < 30.0; elevation += 1.0) {
    const double range = 1.7 / std::tan(elevation * M_PI / 180.0);
    for (double azimuth = 0.0; azimuth < 2.0 * M_PI; azimuth += 0.004) {
      cloud.points.emplace_back(range * std::cos(azimuth), range * std::sin(azimuth),
                                -1.7 + random.Uniform(-0.01, 0.01));
    }
  }
  auto add_box = [&](double cx, double cy, double w, double l, double h) {
    for (int i = 0; i < 1500; ++i) {  // its sides and top
      const double u = random.UniformUnit(), v = random.UniformUnit();
      const int face = static_cast<int>(random.UniformUnit() * 5.0);
      double x = cx + (u - 0.5) * w, y = cy + (v - 0.5) * l, z = -1.7 + random.UniformUnit() * h;
      if (face == 0) x = cx - 0.5 * w;
      if (face == 1) x = cx + 0.5 * w;
      if (face == 2) y = cy - 0.5 * l;
      if (face == 3) y = cy + 0.5 * l;
      if (face == 4) z = -1.7 + h;
      cloud.points.emplace_back(x - sensor_x, y, z);
    }
  };
  for (int k = 0; k < 6; ++k) add_box(-12.0 + 5.0 * k, 8.0, 4.5, 1.9, 1.5);  // parked cars
  for (int k = 0; k < 4; ++k) add_box(-6.0 + 7.0 * k, -9.0, 1.9, 4.5, 1.6);  // and across
  for (int i = 0; i < 600; ++i) {                                            // a lamp pole
    const double a = random.Uniform(0.0, 2.0 * M_PI);
    cloud.points.emplace_back(15.0 - sensor_x + 0.15 * std::cos(a), -2.0 + 0.15 * std::sin(a),
                              -1.7 + random.Uniform(0.0, 6.0));
  }
  return cloud;
}

TEST(DominantPlaneTest, FindsAScansGroundAndKeepsTheStructureOnIt) {
  const Octree tree = TreeOf(OpenLot(0.0, 1), 9);
  const DominantPlane plane = FindDominantPlane(tree, 9);
  ASSERT_TRUE(plane.found);
  EXPECT_GT(std::abs(plane.normal.z()), 0.99);
  EXPECT_GT(plane.point_fraction, 0.6);
  const std::vector<uint8_t> off = plane.OffPlaneNodes(tree, 9);
  ASSERT_EQ(off.size(), tree.level(9).size());
  // Nodes of the cars' sides well above the ground and below their roofs (a roof is flat and
  // level: it may read as on the family) and of the pole are structure; nodes of the ground far
  // from any structure are not.
  int high = 0, high_off = 0, open_ground = 0, open_ground_off = 0;
  for (size_t i = 0; i < off.size(); ++i) {
    const Eigen::Vector3f p = tree.level(9).center_of_mass[i];
    if ((p.z() > -1.1f && p.z() < -0.5f) || p.z() > 0.0f) {
      ++high;
      high_off += off[i];
    } else if (p.x() < -20.0f) {  // beyond the cars: rings only
      ++open_ground;
      open_ground_off += off[i];
    }
  }
  ASSERT_GT(high, 100);
  ASSERT_GT(open_ground, 100);
  EXPECT_GT(high_off, 0.9 * high);
  EXPECT_LT(open_ground_off, 0.05 * open_ground);
  // A coarser depth: a node is structure when any of its nodes at the classifying depth is.
  const std::vector<uint8_t> coarse = plane.OffPlaneNodes(tree, 6);
  ASSERT_EQ(coarse.size(), tree.level(6).size());
  int coarse_off = 0;
  for (uint8_t v : coarse) coarse_off += v;
  EXPECT_GT(coarse_off, 0);
  EXPECT_LT(coarse_off, static_cast<int>(coarse.size()));
}

TEST(DominantPlaneTest, AnObjectHasNone) {
  SeededRandom random(3);
  PointCloud sphere;
  for (int i = 0; i < 2048; ++i) {
    Eigen::Vector3f p(static_cast<float>(random.Normal(0.0, 1.0)),
                      static_cast<float>(random.Normal(0.0, 1.0)),
                      static_cast<float>(random.Normal(0.0, 1.0)));
    sphere.points.push_back(p.normalized());
  }
  const Octree tree = TreeOf(sphere, 6);
  const DominantPlane plane = FindDominantPlane(tree, 6);
  EXPECT_FALSE(plane.found);
  const std::vector<uint8_t> off = plane.OffPlaneNodes(tree, 6);
  ASSERT_EQ(off.size(), tree.level(6).size());
  for (uint8_t v : off) ASSERT_EQ(v, 1);  // all structure
  EXPECT_FALSE(FindDominantPlane(tree, 0).found);
  EXPECT_FALSE(FindDominantPlane(tree, 7).found);
}

// The sensor moved 8 m along x between the scans: the true motion puts the structure on itself;
// the identity puts the rings on themselves. Over all nodes the identity leaves fewer without a
// partner (most nodes are rings); over the structure the truth does.
TEST(DominantPlaneTest, TheStructureNotTheGroundTellsTheTrueShift) {
  const Octree source = TreeOf(OpenLot(8.0, 5), 9);
  const Octree target = TreeOf(OpenLot(0.0, 6), 9);
  Eigen::Isometry3d truth = Eigen::Isometry3d::Identity();
  truth.translation().x() = 8.0;  // source points into the target's frame
  const std::vector<Eigen::Isometry3d> poses = {Eigen::Isometry3d::Identity(), truth};
  const std::vector<double> all = FarNodeFractions(source, target, poses, 9, 1.0);
  const std::vector<double> structure = OffPlaneFarFractions(
      source, FindDominantPlane(source, 9), target, FindDominantPlane(target, 9), poses, 9, 1.0);
  ASSERT_EQ(structure.size(), 2u);
  EXPECT_LT(all[0], all[1]) << "the rings favour the identity";
  EXPECT_LT(structure[1] + 0.3, structure[0]) << "the structure favours the truth";
}

TEST(DominantPlaneTest, TheSearchsNodeMasksMustFitTheTrees) {
  const Octree source = TreeOf(OpenLot(8.0, 5), 9);
  const Octree target = TreeOf(OpenLot(0.0, 6), 9);
  CorrelativeSearchOptions search;
  const int depth = CorrelativeSearchDepth(source, target, search);
  EXPECT_EQ(depth, 6);
  const std::vector<uint8_t> wrong(3, 1);
  search.source_nodes = &wrong;
  auto bad = FindCorrelativeStart(source, target, Eigen::Isometry3d::Identity(), search);
  ASSERT_FALSE(bad.ok());
  EXPECT_THAT(bad.status().message(), HasSubstr("sized as the trees' depth 6"));
  const std::vector<uint8_t> none(source.level(depth).size(), 0);
  search.source_nodes = &none;
  bad = FindCorrelativeStart(source, target, Eigen::Isometry3d::Identity(), search);
  ASSERT_FALSE(bad.ok());
  EXPECT_THAT(bad.status().message(), HasSubstr("no source node is marked"));
  // The structure alone: the search lands within 3.75 m of the 8 m shift (the identity is 8 m
  // off; this cube's depth-6 cells are ~1.5 m).
  const std::vector<uint8_t> source_off = FindDominantPlane(source, 9).OffPlaneNodes(source, depth);
  const std::vector<uint8_t> target_off = FindDominantPlane(target, 9).OffPlaneNodes(target, depth);
  search.source_nodes = &source_off;
  search.target_nodes = &target_off;
  auto start = FindCorrelativeStart(source, target, Eigen::Isometry3d::Identity(), search);
  ASSERT_TRUE(start.ok()) << start.status();
  EXPECT_NEAR(start->T_target_source.translation().x(), 8.0, 3.75);
}

}  // namespace
}  // namespace rpsr::core
