// Clouds and poses the refinement's and the registrar's tests share: degenerate geometry (a
// square of z = 0, a corridor along x with floor and two walls, a sphere, a body of revolution)
// and a truth perturbed by a known rotation and shift.
#ifndef RPSR_TESTS_CORE_REFINE_REFINEMENT_TEST_GEOMETRY_H_
#define RPSR_TESTS_CORE_REFINE_REFINEMENT_TEST_GEOMETRY_H_

#include <cmath>
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

// A vase-like body of revolution (radius 0.3 + 0.1 sin(2 z + 0.5) over z in [-1, 1]: elongated, so
// that its principal axis, from which FindContinuousSymmetry's self-registration starts, is
// estimated to within about a degree) about `axis` through (0.1, -0.05, 0.2); with `handle`, a
// cup's small one: a half ring of a tube on its side takes every 32nd point, which no turn about
// the axis maps onto itself.
inline PointCloud BodyOfRevolution(int n, uint64_t seed, const Eigen::Vector3d& axis,
                                   bool handle = false) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  const Eigen::Quaterniond tilt =
      Eigen::Quaterniond::FromTwoVectors(Eigen::Vector3d::UnitZ(), axis);
  const Eigen::Vector3d centre(0.1, -0.05, 0.2);
  PointCloud cloud;
  for (int i = 0; i < n; ++i) {
    Eigen::Vector3d p;
    const double phi = 2.0 * M_PI * u(rng);
    if (handle && i % 32 == 0) {
      // The handle: a tube of radius 0.03 about a half circle of radius 0.12 in the xz plane,
      // centred on the wall at the widest radius.
      const double along = M_PI * (u(rng) - 0.5);
      const Eigen::Vector3d spine(0.4 + 0.12 * std::cos(along), 0.0, 0.12 * std::sin(along));
      const Eigen::Vector3d out(std::cos(along), 0.0, std::sin(along));
      p = spine + 0.03 * (std::cos(phi) * out + std::sin(phi) * Eigen::Vector3d::UnitY());
    } else {
      const double z = -1.0 + 2.0 * u(rng);
      const double r = 0.3 + 0.1 * std::sin(2.0 * z + 0.5);
      p = Eigen::Vector3d(r * std::cos(phi), r * std::sin(phi), z);
    }
    cloud.points.push_back((centre + tilt * p).cast<float>());
  }
  return cloud;
}

// A round table about `axis` through (0.1, -0.05, 0.2): a top of radius 0.8 and thickness 0.04
// at height 0.46, a column of radius 0.07 down to a base disc of radius 0.5 at -0.46, points
// spread over the surfaces by area. Squat: its radial variances are 1.2 times its axial one, so
// its principal axis from 1,024 samples is degrees off (4.6-19.8 on seeds 1-4, as on the seen
// split's round tables), and only a refined axis finds it a body of revolution.
inline PointCloud RoundTable(int n, uint64_t seed, const Eigen::Vector3d& axis) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  const Eigen::Quaterniond tilt =
      Eigen::Quaterniond::FromTwoVectors(Eigen::Vector3d::UnitZ(), axis);
  const Eigen::Vector3d centre(0.1, -0.05, 0.2);
  constexpr double kTop = 0.8, kThickness = 0.04, kColumn = 0.07, kBase = 0.5;
  constexpr double kTopZ = 0.46, kBaseZ = -0.46;
  // Areas: the top's two faces and rim, the column's side, the base's upper face.
  const double top = 2.0 * M_PI * kTop * kTop;
  const double rim = 2.0 * M_PI * kTop * kThickness;
  const double column = 2.0 * M_PI * kColumn * (kTopZ - kBaseZ);
  const double base = M_PI * kBase * kBase;
  const double total = top + rim + column + base;
  PointCloud cloud;
  for (int i = 0; i < n; ++i) {
    const double pick = total * u(rng);
    const double phi = 2.0 * M_PI * u(rng);
    Eigen::Vector3d p;
    if (pick < top) {  // a disc face: radius by sqrt for an even spread
      const double r = kTop * std::sqrt(u(rng));
      const double z = kTopZ + (u(rng) < 0.5 ? 0.5 : -0.5) * kThickness;
      p = Eigen::Vector3d(r * std::cos(phi), r * std::sin(phi), z);
    } else if (pick < top + rim) {
      p = Eigen::Vector3d(kTop * std::cos(phi), kTop * std::sin(phi),
                          kTopZ + kThickness * (u(rng) - 0.5));
    } else if (pick < top + rim + column) {
      p = Eigen::Vector3d(kColumn * std::cos(phi), kColumn * std::sin(phi),
                          kBaseZ + (kTopZ - kBaseZ) * u(rng));
    } else {
      const double r = kBase * std::sqrt(u(rng));
      p = Eigen::Vector3d(r * std::cos(phi), r * std::sin(phi), kBaseZ);
    }
    cloud.points.push_back((centre + tilt * p).cast<float>());
  }
  return cloud;
}

}  // namespace rpsr::core::testing_util

#endif  // RPSR_TESTS_CORE_REFINE_REFINEMENT_TEST_GEOMETRY_H_
