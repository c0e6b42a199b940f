#include "core/synth/primitive_meshes.h"

#include <cmath>
#include <map>
#include <tuple>
#include <utility>

#include "gtest/gtest.h"

namespace rpsr::core {
namespace {

// Signed volume by the divergence theorem: positive when triangles face outward.
double SignedVolume(const TriangleMesh& mesh) {
  double volume = 0.0;
  for (const Eigen::Vector3i& t : mesh.triangles) {
    const Eigen::Vector3d a = mesh.vertices[t.x()].cast<double>();
    const Eigen::Vector3d b = mesh.vertices[t.y()].cast<double>();
    const Eigen::Vector3d c = mesh.vertices[t.z()].cast<double>();
    volume += a.dot(b.cross(c)) / 6.0;
  }
  return volume;
}

// True when, after welding vertices at identical positions, every directed edge of a
// non-degenerate triangle is matched by exactly one opposite directed edge: a closed,
// consistently oriented surface.
bool IsClosedAndOriented(const TriangleMesh& mesh) {
  std::map<std::tuple<float, float, float>, int> welded;
  std::vector<int> id(mesh.vertices.size());
  for (size_t v = 0; v < mesh.vertices.size(); ++v) {
    const Eigen::Vector3f& p = mesh.vertices[v];
    id[v] = welded.emplace(std::make_tuple(p.x(), p.y(), p.z()), static_cast<int>(welded.size()))
                .first->second;
  }
  std::map<std::pair<int, int>, int> directed;
  for (const Eigen::Vector3i& t : mesh.triangles) {
    const int a = id[t.x()], b = id[t.y()], c = id[t.z()];
    if (a == b || b == c || c == a) continue;  // pole triangles collapse to an edge
    ++directed[{a, b}];
    ++directed[{b, c}];
    ++directed[{c, a}];
  }
  for (const auto& [edge, count] : directed) {
    if (count != 1) return false;
    const auto opposite = directed.find({edge.second, edge.first});
    if (opposite == directed.end() || opposite->second != 1) return false;
  }
  return !directed.empty();
}

TEST(PrimitiveMeshesTest, BoxIsClosedWithExactVolumeAndArea) {
  const TriangleMesh box = BoxMesh({1.0f, 2.0f, 3.0f});
  EXPECT_TRUE(IsClosedAndOriented(box));
  EXPECT_NEAR(SignedVolume(box), 48.0, 1e-9);
  EXPECT_NEAR(SurfaceArea(box), 2 * (8 + 24 + 12), 1e-9);
}

TEST(PrimitiveMeshesTest, RoundSolidsApproachTheirAnalyticVolume) {
  const TriangleMesh cylinder = FrustumMesh(0.5f, 0.5f, 2.0f, 64);
  EXPECT_TRUE(IsClosedAndOriented(cylinder));
  EXPECT_NEAR(SignedVolume(cylinder), M_PI * 0.25 * 2.0, 0.01);

  const TriangleMesh sphere = EllipsoidMesh(Eigen::Vector3f::Ones(), 32, 64);
  EXPECT_TRUE(IsClosedAndOriented(sphere));
  EXPECT_NEAR(SignedVolume(sphere), 4.0 / 3.0 * M_PI, 0.05);

  const TriangleMesh torus = TorusMesh(1.0f, std::vector<float>(64, 0.25f), 32);
  EXPECT_TRUE(IsClosedAndOriented(torus));
  EXPECT_NEAR(SignedVolume(torus), 2 * M_PI * M_PI * 1.0 * 0.0625, 0.02);
}

TEST(PrimitiveMeshesTest, BoxLikeSuperquadricFillsItsBox) {
  const TriangleMesh squarish = SuperquadricMesh(Eigen::Vector3f::Ones(), 0.1f, 0.1f, 32, 64);
  EXPECT_TRUE(IsClosedAndOriented(squarish));
  EXPECT_GT(SignedVolume(squarish), 6.0);
  EXPECT_LT(SignedVolume(squarish), 8.0);
}

TEST(PrimitiveMeshesTest, LoftAndTubeAreClosed) {
  const std::vector<Eigen::Vector2f> square = {{-1, -1}, {1, -1}, {1, 1}, {-1, 1}};
  const TriangleMesh prism = LoftMesh({square, square}, {0.0f, 2.0f});
  EXPECT_TRUE(IsClosedAndOriented(prism));
  EXPECT_NEAR(SignedVolume(prism), 8.0, 1e-6);

  std::vector<Eigen::Vector3f> arc;
  for (int k = 0; k <= 20; ++k) {
    const float angle = 1.5f * k / 20;
    arc.emplace_back(std::cos(angle), std::sin(angle), 0.1f * k);
  }
  const TriangleMesh tube = TubeMesh(arc, 0.1f, 12);
  EXPECT_TRUE(IsClosedAndOriented(tube));
  EXPECT_GT(SignedVolume(tube), 0.0);
}

TEST(PrimitiveMeshesTest, CylinderBetweenSpansItsEndpoints) {
  const TriangleMesh cylinder = CylinderBetween({1, 1, 1}, {1, 1, 3}, 0.5f, 16);
  Eigen::AlignedBox3f bounds = BoundsOf(cylinder.vertices);
  EXPECT_NEAR(bounds.min().z(), 1.0f, 1e-5);
  EXPECT_NEAR(bounds.max().z(), 3.0f, 1e-5);
  EXPECT_GT(SignedVolume(cylinder), 0.0);
}

TEST(PrimitiveMeshesTest, MirroringKeepsTrianglesOutward) {
  const TriangleMesh mirrored = TransformedMesh(BoxMesh({1.0f, 2.0f, 3.0f}),
                                                Eigen::Affine3f(Eigen::Scaling(1.0f, -1.0f, 1.0f)));
  EXPECT_NEAR(SignedVolume(mirrored), 48.0, 1e-9);
  EXPECT_TRUE(IsClosedAndOriented(mirrored));
}

TEST(PrimitiveMeshesTest, AppendMeshReindexes) {
  TriangleMesh merged = BoxMesh(Eigen::Vector3f::Ones());
  AppendMesh(TransformedMesh(BoxMesh(Eigen::Vector3f::Ones()), PlacedAt({5, 0, 0})), merged);
  EXPECT_EQ(merged.vertices.size(), 16u);
  EXPECT_EQ(merged.triangles.size(), 24u);
  EXPECT_NEAR(SignedVolume(merged), 16.0, 1e-9);
  EXPECT_TRUE(IsClosedAndOriented(merged));
}

}  // namespace
}  // namespace rpsr::core
