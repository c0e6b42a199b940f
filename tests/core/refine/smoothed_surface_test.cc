// The noise polish's kernel-smoothed surfaces (core/refine/smoothed_surface.h): the mean lies on a
// jittered surface where cell CoMs do not, the support is exactly the radius, the moments move
// continuously with the point, and both sides of a pair sag alike on a curved surface.
#include "core/refine/smoothed_surface.h"

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include "Eigen/Eigenvalues"
#include "gtest/gtest.h"
#include "tests/core/refine/refinement_test_geometry.h"
#include "tests/core/refine/refinement_test_util.h"

namespace rpsr::core {
namespace {

using testing_util::RefinementTree;

constexpr int kDepth = 5;

PointCloud JitteredPlane(int n, float sigma, uint64_t seed) {
  PointCloud cloud = testing_util::Plane(n, seed);
  std::mt19937_64 rng(seed + 100);
  std::normal_distribution<float> noise(0.0f, sigma);
  for (auto& p : cloud.points) p.z() += noise(rng);
  return cloud;
}

double Median(std::vector<double> v) {
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2), v.end());
  return v[v.size() / 2];
}

// A plane jittered by half a cell (depth 5 of a 2-wide cube: 0.0625): the cells cut the thick
// shell, so their CoMs lie off the plane by up to a cell; the kernel's means, averaged across the
// shell, lie on it, and their normals are the plane's.
TEST(SmoothedSurfaceTest, MeanLiesOnAJitteredPlane) {
  const Octree tree = RefinementTree(JitteredPlane(20000, 0.03f, 1), kDepth);
  const Octree::Level& level = tree.level(kDepth);
  const SurfaceKernel kernel(tree, kDepth, 2.5 * CellEdge(tree, kDepth));
  std::vector<double> com_heights;
  std::vector<double> mean_heights;
  std::vector<double> normal_z;
  for (size_t j = 0; j < level.size(); j += 7) {
    const Eigen::Vector3d com = level.center_of_mass[j].cast<double>();
    if (std::abs(com.x()) > 0.7 || std::abs(com.y()) > 0.7) continue;  // away from the edges
    const SurfaceMoments m = kernel.Moments(com);
    ASSERT_GT(m.points, 3.0);
    com_heights.push_back(std::abs(com.z()));
    mean_heights.push_back(std::abs(m.mean.z()));
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver(m.spread);
    normal_z.push_back(std::abs(solver.eigenvectors().col(0).z()));
  }
  ASSERT_GT(com_heights.size(), 50u);
  const double com_median = Median(com_heights);
  const double mean_median = Median(mean_heights);
  std::printf(
      "median height off the plane: cell CoMs %.4f, kernel means %.4f; normals' median |z| %.4f, "
      "least %.4f\n",
      com_median, mean_median, Median(normal_z),
      *std::min_element(normal_z.begin(), normal_z.end()));
  EXPECT_GT(Median(normal_z), 0.995);
  EXPECT_GT(*std::min_element(normal_z.begin(), normal_z.end()), 0.95);
  EXPECT_GT(com_median, 0.01);
  EXPECT_LT(mean_median, com_median / 4.0);
}

// Cells beyond the radius weigh nothing: gathering farther changes the moments only by the order
// of the sums, and a point far from every cell has no support.
TEST(SmoothedSurfaceTest, SupportIsExactlyTheRadius) {
  const Octree tree = RefinementTree(testing_util::Sphere(3000, 2), kDepth);
  const double radius = 2.5 * CellEdge(tree, kDepth);
  const SurfaceKernel kernel(tree, kDepth, radius);
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> u(-1.2, 1.2);
  int supported = 0;
  for (int k = 0; k < 200; ++k) {
    const Eigen::Vector3d x(u(rng), u(rng), u(rng));
    std::vector<int32_t> wide;
    kernel.Gather(x, 2.0 * radius, wide);
    std::vector<int32_t> exact;
    kernel.Gather(x, radius, exact);
    EXPECT_LE(exact.size(), wide.size());
    const SurfaceMoments a = kernel.Moments(x);
    const SurfaceMoments b = kernel.Moments(x, wide.data(), wide.size());
    EXPECT_NEAR(a.weight, b.weight, 1e-9 * (1.0 + b.weight));
    EXPECT_EQ(a.points, b.points);
    EXPECT_LT((a.mean - b.mean).norm(), 1e-12);
    if (a.points > 0.0) ++supported;
  }
  EXPECT_GT(supported, 20);
  EXPECT_EQ(kernel.Moments(Eigen::Vector3d(30.0, 30.0, 30.0)).weight, 0.0);
}

// The moments move continuously as the point moves (what lets the polish settle): along a line
// through a jittered plane, steps of 1e-4 move the mean by little more than that.
TEST(SmoothedSurfaceTest, MomentsMoveContinuously) {
  const Octree tree = RefinementTree(JitteredPlane(20000, 0.05f, 4), kDepth);
  const SurfaceKernel kernel(tree, kDepth, 2.5 * CellEdge(tree, kDepth));
  double largest = 0.0;
  Eigen::Vector3d previous = kernel.Moments(Eigen::Vector3d(-0.5, -0.3, 0.02)).mean;
  for (int k = 1; k <= 5000; ++k) {
    const Eigen::Vector3d x =
        Eigen::Vector3d(-0.5, -0.3, 0.02) + 1e-4 * k * Eigen::Vector3d(1, 0.5, 0);
    const Eigen::Vector3d mean = kernel.Moments(x).mean;
    largest = std::max(largest, (mean - previous).norm());
    previous = mean;
  }
  EXPECT_LT(largest, 5e-4);
}

// On a sphere, the source's smoothed nodes (its own kernel, in its frame) and the target's kernel
// about them sag alike: at the true pose their offsets along the target's normal average out,
// where the raw CoMs' offsets from the target's smoothed surface do not.
TEST(SmoothedSurfaceTest, BothSidesSagAlike) {
  const Octree source = RefinementTree(testing_util::Sphere(4000, 5), kDepth);
  const Octree target = RefinementTree(testing_util::Sphere(4000, 6), kDepth);
  const double radius = 2.5 * CellEdge(target, kDepth);
  const SurfaceKernel kernel(target, kDepth, radius);
  const SmoothedNodes nodes = SmoothNodes(source, kDepth, radius, 100000);
  ASSERT_EQ(nodes.points.size(), source.level(kDepth).size());
  double smoothed_offset = 0.0;
  double raw_offset = 0.0;
  int counted = 0;
  for (size_t i = 0; i < nodes.points.size(); ++i) {
    const SurfaceMoments at_smoothed = kernel.Moments(nodes.points[i]);
    const Eigen::Vector3d raw = source.level(kDepth).center_of_mass[i].cast<double>();
    const SurfaceMoments at_raw = kernel.Moments(raw);
    if (at_smoothed.points < 3.0 || at_raw.points < 3.0) continue;
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> a(at_smoothed.spread);
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> b(at_raw.spread);
    // Signed outward: the sphere's centre is (0.3, -0.2, 0.1).
    const Eigen::Vector3d centre(0.3, -0.2, 0.1);
    const Eigen::Vector3d na = a.eigenvectors().col(0) *
                               (a.eigenvectors().col(0).dot(nodes.points[i] - centre) < 0 ? -1 : 1);
    const Eigen::Vector3d nb =
        b.eigenvectors().col(0) * (b.eigenvectors().col(0).dot(raw - centre) < 0 ? -1 : 1);
    smoothed_offset += na.dot(nodes.points[i] - at_smoothed.mean);
    raw_offset += nb.dot(raw - at_raw.mean);
    ++counted;
  }
  ASSERT_GT(counted, 200);
  smoothed_offset /= counted;
  raw_offset /= counted;
  std::printf("mean signed offset along the normal: smoothed %.5f, raw CoMs %.5f (radius %.3f)\n",
              smoothed_offset, raw_offset, radius);
  EXPECT_LT(std::abs(smoothed_offset), 0.002);
  EXPECT_GT(std::abs(raw_offset), 3.0 * std::abs(smoothed_offset));
}

// At most max_nodes nodes, an even stride; each weighs its node's point count.
TEST(SmoothedSurfaceTest, SmoothNodesReadsAnEvenStride) {
  const Octree tree = RefinementTree(testing_util::Sphere(3000, 7), kDepth);
  const size_t nodes = tree.level(kDepth).size();
  const SmoothedNodes all = SmoothNodes(tree, kDepth, 0.1, nodes);
  ASSERT_EQ(all.points.size(), nodes);
  const SmoothedNodes some = SmoothNodes(tree, kDepth, 0.1, 100);
  EXPECT_LE(some.points.size(), 100u);
  EXPECT_GE(some.points.size(), 50u);
  const size_t stride = (nodes + 99) / 100;
  for (size_t k = 0; k < some.points.size(); ++k) {
    EXPECT_EQ(some.points[k], all.points[k * stride]);
    EXPECT_EQ(some.weights[k], tree.level(kDepth).count[k * stride]);
  }
  EXPECT_TRUE(SmoothNodes(tree, kDepth, 0.1, 0).points.empty());
}

}  // namespace
}  // namespace rpsr::core
