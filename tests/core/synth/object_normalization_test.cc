#include "core/synth/object_normalization.h"

#include <limits>

#include "core/synth/primitive_meshes.h"
#include "core/synth/shape_families.h"
#include "gtest/gtest.h"

namespace rpsr::core {
namespace {

TEST(NormalizedIntoUnitCubeTest, CentresAndScalesByLargestHalfExtent) {
  const TriangleMesh box =
      TransformedMesh(BoxMesh({2.0f, 1.0f, 0.5f}), PlacedAt({10.0f, -3.0f, 7.0f}));
  absl::StatusOr<TriangleMesh> normalized = NormalizedIntoUnitCube(box);
  ASSERT_TRUE(normalized.ok()) << normalized.status();
  const Eigen::AlignedBox3f bounds = BoundsOf(normalized->vertices);
  EXPECT_TRUE(bounds.min().isApprox(Eigen::Vector3f(-1.0f, -0.5f, -0.25f), 1e-6f));
  EXPECT_TRUE(bounds.max().isApprox(Eigen::Vector3f(1.0f, 0.5f, 0.25f), 1e-6f));
  EXPECT_EQ(normalized->triangles, box.triangles);
}

TEST(NormalizedIntoUnitCubeTest, EveryFamilyFitsTheCubeTightly) {
  for (size_t f = 0; f < ShapeFamilies().size(); ++f) {
    for (uint64_t seed = 0; seed < 10; ++seed) {
      absl::StatusOr<TriangleMesh> mesh = GenerateNormalizedObject(f, seed);
      ASSERT_TRUE(mesh.ok()) << mesh.status();
      const Eigen::AlignedBox3f bounds = BoundsOf(mesh->vertices);
      EXPECT_GE(bounds.min().minCoeff(), -1.0f);
      EXPECT_LE(bounds.max().maxCoeff(), 1.0f);
      // Centred, and the largest side spans the whole cube.
      EXPECT_LT(bounds.center().cwiseAbs().maxCoeff(), 1e-5f) << ShapeFamilies()[f].name;
      EXPECT_NEAR(bounds.sizes().maxCoeff(), 2.0f, 1e-5f) << ShapeFamilies()[f].name;
    }
  }
}

TEST(SampleNormalizedObjectTest, PointsInsideCubeAndDeterministic) {
  for (size_t f = 0; f < ShapeFamilies().size(); ++f) {
    absl::StatusOr<PointCloud> a = SampleNormalizedObject(f, 3, 1024, 4);
    absl::StatusOr<PointCloud> b = SampleNormalizedObject(f, 3, 1024, 4);
    absl::StatusOr<PointCloud> c = SampleNormalizedObject(f, 3, 1024, 5);
    ASSERT_TRUE(a.ok() && b.ok() && c.ok());
    ASSERT_EQ(a->size(), 1024u);
    EXPECT_EQ(a->points, b->points);
    EXPECT_NE(a->points, c->points);
    for (const Eigen::Vector3f& p : a->points) {
      EXPECT_LE(p.cwiseAbs().maxCoeff(), 1.0f);
    }
  }
}

TEST(NormalizedIntoUnitCubeTest, RejectsDegenerateMeshes) {
  EXPECT_EQ(NormalizedIntoUnitCube(TriangleMesh{}).status().code(),
            absl::StatusCode::kInvalidArgument);
  TriangleMesh point;
  point.vertices = {{1, 1, 1}, {1, 1, 1}, {1, 1, 1}};
  point.triangles = {{0, 1, 2}};
  EXPECT_EQ(NormalizedIntoUnitCube(point).status().code(), absl::StatusCode::kInvalidArgument);
  TriangleMesh nan = BoxMesh(Eigen::Vector3f::Ones());
  nan.vertices[3].x() = std::numeric_limits<float>::quiet_NaN();
  EXPECT_EQ(NormalizedIntoUnitCube(nan).status().code(), absl::StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace rpsr::core
