#include "core/io/mesh_sampling.h"

#include <cmath>
#include <limits>

#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/core/io/status_expectations.h"

namespace rpsr::core {
namespace {

// A unit cube [0,1]^3 as 12 triangles.
TriangleMesh UnitCube() {
  TriangleMesh mesh;
  for (int i = 0; i < 8; ++i) mesh.vertices.emplace_back(i & 1, (i >> 1) & 1, (i >> 2) & 1);
  mesh.triangles = {{0, 2, 1}, {1, 2, 3}, {4, 5, 6}, {5, 7, 6}, {0, 1, 4}, {1, 5, 4},
                    {2, 6, 3}, {3, 6, 7}, {0, 4, 2}, {2, 4, 6}, {1, 3, 5}, {3, 7, 5}};
  return mesh;
}

TEST(MeshSamplingTest, SameSeedSamePointsOtherSeedOtherPoints) {
  absl::StatusOr<PointCloud> a = SampleSurface(UnitCube(), 500, 42);
  absl::StatusOr<PointCloud> b = SampleSurface(UnitCube(), 500, 42);
  absl::StatusOr<PointCloud> c = SampleSurface(UnitCube(), 500, 43);
  ASSERT_TRUE(a.ok() && b.ok() && c.ok());
  EXPECT_EQ(a->points, b->points);
  EXPECT_NE(a->points, c->points);
  EXPECT_EQ(a->size(), 500u);
}

TEST(MeshSamplingTest, PointsLieOnTheSurface) {
  absl::StatusOr<PointCloud> cloud = SampleSurface(UnitCube(), 5000, 1);
  ASSERT_TRUE(cloud.ok());
  for (const Eigen::Vector3f& p : cloud->points) {
    EXPECT_TRUE((p.array() >= -1e-6f).all() && (p.array() <= 1 + 1e-6f).all()) << p.transpose();
    // On a face of the cube: one coordinate is 0 or 1.
    const float distance_to_face = (p.array().min(1.0f - p.array())).minCoeff();
    EXPECT_LT(distance_to_face, 1e-6f) << p.transpose();
  }
}

TEST(MeshSamplingTest, TrianglesGetPointsInProportionToArea) {
  // Triangle A (z = 0) has area 1/2; triangle B (z = 5) has area 3/2: a 1:3 split.
  TriangleMesh mesh;
  mesh.vertices = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 5}, {3, 0, 5}, {0, 1, 5}};
  mesh.triangles = {{0, 1, 2}, {3, 4, 5}};
  const size_t n = 40000;
  absl::StatusOr<PointCloud> cloud = SampleSurface(mesh, n, 7);
  ASSERT_TRUE(cloud.ok());
  size_t on_a = 0;
  for (const Eigen::Vector3f& p : cloud->points) {
    if (p.z() == 0.0f) {
      ++on_a;
      EXPECT_LE(p.x() + p.y(), 1.0f + 1e-6f);
    } else {
      EXPECT_FLOAT_EQ(p.z(), 5.0f);
      EXPECT_LE(p.x() / 3 + p.y(), 1.0f + 1e-6f);
    }
  }
  // Binomial(40000, 0.25): standard deviation ~87 points, 0.0022 of n; allow ~5 sigma.
  EXPECT_NEAR(static_cast<double>(on_a) / n, 0.25, 0.011);
}

TEST(MeshSamplingTest, ZeroPointsGivesAnEmptyCloud) {
  absl::StatusOr<PointCloud> cloud = SampleSurface(UnitCube(), 0, 1);
  ASSERT_TRUE(cloud.ok());
  EXPECT_TRUE(cloud->empty());
}

TEST(MeshSamplingTest, RejectsInvalidMeshes) {
  TriangleMesh out_of_range = UnitCube();
  out_of_range.triangles.push_back({0, 1, 8});
  ExpectError(SampleSurface(out_of_range, 10, 1), absl::StatusCode::kInvalidArgument,
              {"triangle 12", "8 vertices"});
  TriangleMesh negative = UnitCube();
  negative.triangles[3] = {-1, 0, 1};
  ExpectError(SampleSurface(negative, 10, 1), absl::StatusCode::kInvalidArgument, {"triangle 3"});
  TriangleMesh non_finite = UnitCube();
  non_finite.vertices[5].y() = std::numeric_limits<float>::quiet_NaN();
  ExpectError(SampleSurface(non_finite, 10, 1), absl::StatusCode::kInvalidArgument, {"vertex 5"});
  TriangleMesh flat;
  flat.vertices = {{0, 0, 0}, {1, 1, 1}, {2, 2, 2}};
  flat.triangles = {{0, 1, 2}};
  ExpectError(SampleSurface(flat, 10, 1), absl::StatusCode::kInvalidArgument, {"no surface"});
  ExpectError(SampleSurface(TriangleMesh{}, 10, 1), absl::StatusCode::kInvalidArgument,
              {"no surface"});
}

}  // namespace
}  // namespace rpsr::core
