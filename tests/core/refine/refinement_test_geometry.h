// Clouds and poses the refinement's and the registrar's tests share: degenerate geometry (a
// square of z = 0, a corridor along x with floor and two walls, a sphere) and a truth perturbed by
// a known rotation and shift.
#ifndef RPSR_TESTS_CORE_REFINE_REFINEMENT_TEST_GEOMETRY_H_
#define RPSR_TESTS_CORE_REFINE_REFINEMENT_TEST_GEOMETRY_H_

#include <cstdint>
#include <random>

#include "Eigen/Geometry"
#include "core/cloud/point_cloud.h"
#include "core/data/transform_convention.h"

namespace rpsr::core::testing_util {

// Truth composed with a rotation of `angle_rad` about a random axis and a translation of length
// `shift` in a random direction (applied in the target frame).
inline Eigen::Isometry3d Perturbed(const Eigen::Isometry3d& truth, double angle_rad, double shift,
                                   std::mt19937_64& rng) {
  std::normal_distribution<double> normal;
  const Eigen::Vector3d axis = Eigen::Vector3d(normal(rng), normal(rng), normal(rng)).normalized();
  const Eigen::Vector3d dir = Eigen::Vector3d(normal(rng), normal(rng), normal(rng)).normalized();
  return MakeTransform(Eigen::AngleAxisd(angle_rad, axis).toRotationMatrix(), shift * dir) * truth;
}

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

#endif  // RPSR_TESTS_CORE_REFINE_REFINEMENT_TEST_GEOMETRY_H_
