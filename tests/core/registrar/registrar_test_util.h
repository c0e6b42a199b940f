// Shared fixtures of the registrar's tests: trees, one registrar per process (loading the model
// costs ~30 ms), seeded object pairs of asymmetric families and degenerate clouds.
#ifndef RPSR_TESTS_CORE_REGISTRAR_REGISTRAR_TEST_UTIL_H_
#define RPSR_TESTS_CORE_REGISTRAR_REGISTRAR_TEST_UTIL_H_

#include <random>

#include "core/data/object_pairs.h"
#include "core/data/transform_convention.h"
#include "core/registrar/registrar.h"
#include "core/synth/shape_families.h"
#include "gtest/gtest.h"

namespace rpsr::core::testing_util {

inline Octree TreeOf(const PointCloud& cloud, int max_depth = 6) {
  BarnesHutTreeOptions options;
  options.max_depth = max_depth;
  options.neighbor_max_depth = std::min(5, max_depth);
  auto tree = BuildOctree(cloud, options);
  EXPECT_TRUE(tree.ok()) << tree.status();
  return *std::move(tree);
}

inline const Registrar& SharedRegistrar() {
  static const Registrar* registrar = [] {
    auto r = Registrar::Create();
    EXPECT_TRUE(r.ok()) << r.status();
    return r->release();
  }();
  return *registrar;
}

// The first object pair at or after `seed` whose family has no rotational symmetry (so the truth
// is the only right answer), 2,048 points, unseen classes.
inline ObjectPair AsymmetricObjectPair(uint64_t seed, double max_angle_deg) {
  PairOptions options;
  options.num_points = 2048;
  options.max_angle_deg = max_angle_deg;
  options.max_translation = 0.2;
  options.split = ObjectSplit::kM2Unseen;
  for (;; ++seed) {
    auto pair = MakeObjectPair(options, seed);
    EXPECT_TRUE(pair.ok()) << pair.status();
    if (ShapeFamilies()[pair->family_index].symmetry == RotationalSymmetry::kNone) return *pair;
  }
}

// Truth composed with a rotation of `angle_rad` about a random axis and a translation of length
// `shift` in a random direction (in the target frame).
inline Eigen::Isometry3d Perturbed(const Eigen::Isometry3d& truth, double angle_rad, double shift,
                                   std::mt19937_64& rng) {
  std::normal_distribution<double> normal;
  const Eigen::Vector3d axis = Eigen::Vector3d(normal(rng), normal(rng), normal(rng)).normalized();
  const Eigen::Vector3d dir = Eigen::Vector3d(normal(rng), normal(rng), normal(rng)).normalized();
  return MakeTransform(Eigen::AngleAxisd(angle_rad, axis).toRotationMatrix(), shift * dir) * truth;
}

// Degenerate geometry: a square of z = 0, a corridor along x (floor and two walls), a sphere.
inline PointCloud Plane(int n, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  PointCloud cloud;
  for (int i = 0; i < n; ++i) cloud.points.emplace_back(u(rng), u(rng), 0.0f);
  return cloud;
}

inline PointCloud Corridor(int n, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<float> along(-10.0f, 10.0f);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  PointCloud cloud;
  for (int i = 0; i < n; ++i) {
    const float x = along(rng);
    switch (i % 3) {
      case 0:
        cloud.points.emplace_back(x, -1.5f + 3.0f * u(rng), 0.0f);
        break;
      case 1:
        cloud.points.emplace_back(x, -1.5f, 2.5f * u(rng));
        break;
      default:
        cloud.points.emplace_back(x, 1.5f, 2.5f * u(rng));
        break;
    }
  }
  return cloud;
}

inline PointCloud Sphere(int n, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<float> normal;
  PointCloud cloud;
  const Eigen::Vector3f center(0.3f, -0.2f, 0.1f);
  for (int i = 0; i < n; ++i) {
    cloud.points.push_back(center +
                           Eigen::Vector3f(normal(rng), normal(rng), normal(rng)).normalized());
  }
  return cloud;
}

}  // namespace rpsr::core::testing_util

#endif  // RPSR_TESTS_CORE_REGISTRAR_REGISTRAR_TEST_UTIL_H_
