// Small deterministic clouds for network tests (no dependency on core/synth).
#ifndef RPSR_TESTS_CORE_NET_TEST_CLOUDS_H_
#define RPSR_TESTS_CORE_NET_TEST_CLOUDS_H_

#include <cmath>
#include <random>

#include "core/cloud/point_cloud.h"
#include "core/tree/bh_tree.h"

namespace rpsr::core::testing {

// An asymmetric object in [-1, 1]: a box surface with a sphere stuck to one corner.
inline PointCloud AsymmetricObject(int n, uint64_t seed, double sphere_radius = 0.35) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  PointCloud cloud;
  for (int i = 0; i < n; ++i) {
    Eigen::Vector3d p(u(rng), u(rng), u(rng));
    if (i % 3 == 0) {
      p = Eigen::Vector3d(0.5, 0.3, 0.2) + sphere_radius * p.normalized();
    } else {
      const int axis = i % 3 == 1 ? (i / 3) % 3 : 2 - (i / 3) % 3;
      p[axis] = p[axis] > 0 ? 0.6 : -0.6;
      p.y() *= 0.5;
    }
    cloud.points.push_back(p.cast<float>());
  }
  return cloud;
}

inline Eigen::Isometry3d SmallMotion(double angle_rad, const Eigen::Vector3d& t) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() =
      Eigen::AngleAxisd(angle_rad, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  T.translation() = t;
  return T;
}

}  // namespace rpsr::core::testing

#endif  // RPSR_TESTS_CORE_NET_TEST_CLOUDS_H_
