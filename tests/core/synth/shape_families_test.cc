#include "core/synth/shape_families.h"

#include <algorithm>
#include <cmath>
#include <set>
#include <string>
#include <vector>

#include "Eigen/Eigenvalues"
#include "core/io/mesh_sampling.h"
#include "core/synth/object_normalization.h"
#include "core/synth/primitive_meshes.h"
#include "gtest/gtest.h"

namespace rpsr::core {
namespace {

TEST(ShapeFamiliesTest, AtLeastTwentyNamedFamiliesSplitInHalves) {
  const std::vector<ShapeFamily>& families = ShapeFamilies();
  ASSERT_GE(families.size(), 20u);
  ASSERT_EQ(families.size() % 2, 0u);
  std::set<std::string> names;
  for (size_t i = 0; i < families.size(); ++i) {
    EXPECT_FALSE(families[i].name.empty());
    EXPECT_TRUE(names.insert(families[i].name).second) << "duplicate " << families[i].name;
    EXPECT_EQ(families[i].split,
              i < families.size() / 2 ? FamilySplit::kSeen : FamilySplit::kUnseen)
        << families[i].name;
    EXPECT_NE(families[i].generate, nullptr);
  }
  const std::vector<size_t> seen = FamilyIndicesIn(FamilySplit::kSeen);
  const std::vector<size_t> unseen = FamilyIndicesIn(FamilySplit::kUnseen);
  EXPECT_EQ(seen.size(), families.size() / 2);
  EXPECT_EQ(unseen.size(), families.size() / 2);
  for (size_t i : seen) EXPECT_EQ(std::count(unseen.begin(), unseen.end(), i), 0);
}

TEST(ShapeFamiliesTest, MostFamiliesAreFreeOfRotationalSymmetry) {
  int asymmetric = 0;
  for (const ShapeFamily& family : ShapeFamilies()) {
    asymmetric += family.symmetry == RotationalSymmetry::kNone;
  }
  EXPECT_GE(asymmetric, static_cast<int>(ShapeFamilies().size()) - 4);
}

TEST(ShapeFamiliesTest, EveryFamilyMakesValidMeshesForManySeeds) {
  for (size_t f = 0; f < ShapeFamilies().size(); ++f) {
    const std::string& name = ShapeFamilies()[f].name;
    for (uint64_t seed = 0; seed < 60; ++seed) {
      absl::StatusOr<TriangleMesh> mesh = GenerateObject(f, seed);
      ASSERT_TRUE(mesh.ok()) << name << ": " << mesh.status();
      ASSERT_FALSE(mesh->triangles.empty()) << name;
      EXPECT_LT(mesh->triangles.size(), 20000u) << name << " seed " << seed;
      for (const Eigen::Vector3f& v : mesh->vertices) {
        ASSERT_TRUE(v.allFinite()) << name << " seed " << seed;
      }
      const int num_vertices = static_cast<int>(mesh->vertices.size());
      for (const Eigen::Vector3i& t : mesh->triangles) {
        ASSERT_TRUE((t.array() >= 0).all() && (t.array() < num_vertices).all()) << name;
      }
      EXPECT_GT(SurfaceArea(*mesh), 1e-3) << name << " seed " << seed;
      // Outward-facing parts: the divergence-theorem volume is positive.
      double volume = 0.0;
      for (const Eigen::Vector3i& t : mesh->triangles) {
        volume +=
            mesh->vertices[t.x()].cast<double>().dot(
                mesh->vertices[t.y()].cast<double>().cross(mesh->vertices[t.z()].cast<double>())) /
            6.0;
      }
      EXPECT_GT(volume, 0.0) << name << " seed " << seed;
    }
  }
}

TEST(ShapeFamiliesTest, SameSeedSameObjectOtherSeedOtherObject) {
  for (size_t f = 0; f < ShapeFamilies().size(); ++f) {
    const TriangleMesh a = *GenerateObject(f, 17);
    const TriangleMesh b = *GenerateObject(f, 17);
    const TriangleMesh c = *GenerateObject(f, 18);
    ASSERT_EQ(a.vertices.size(), b.vertices.size());
    EXPECT_EQ(a.vertices, b.vertices) << ShapeFamilies()[f].name;
    EXPECT_EQ(a.triangles, b.triangles);
    EXPECT_NE(a.vertices, c.vertices) << ShapeFamilies()[f].name;
  }
}

TEST(ShapeFamiliesTest, RejectsIndexOutOfRange) {
  EXPECT_EQ(GenerateObject(ShapeFamilies().size(), 0).status().code(),
            absl::StatusCode::kInvalidArgument);
}

// A rotation-invariant shape signature of a normalised cloud: the histogram of distances between
// point pairs (D2, Osada et al.), the histogram of distances from the centroid, and the sorted
// principal extents.
std::vector<double> ShapeSignature(const PointCloud& cloud) {
  constexpr int kPairBins = 24;
  constexpr int kRadialBins = 12;
  std::vector<double> signature(kPairBins + kRadialBins + 3, 0.0);
  const size_t n = cloud.size();
  int pairs = 0;
  for (size_t i = 0; i < n; i += 2) {
    for (size_t j = i + 1; j < n; j += 7) {
      const double d = (cloud.points[i] - cloud.points[j]).norm();
      signature[std::min(kPairBins - 1, static_cast<int>(d / 3.4642 * kPairBins))] += 1.0;
      ++pairs;
    }
  }
  for (int b = 0; b < kPairBins; ++b) signature[b] /= pairs;
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const Eigen::Vector3f& p : cloud.points) mean += p.cast<double>();
  mean /= n;
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();
  for (const Eigen::Vector3f& p : cloud.points) {
    const Eigen::Vector3d d = p.cast<double>() - mean;
    covariance += d * d.transpose() / n;
    const int bin = std::min(kRadialBins - 1, static_cast<int>(d.norm() / 1.8 * kRadialBins));
    signature[kPairBins + bin] += 1.0 / n;
  }
  Eigen::Vector3d extents = Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(covariance)
                                .eigenvalues()
                                .cwiseMax(0.0)
                                .cwiseSqrt();
  for (int k = 0; k < 3; ++k) signature[kPairBins + kRadialBins + k] = 0.3 * extents[k];
  return signature;
}

double SquaredDistance(const std::vector<double>& a, const std::vector<double>& b) {
  double sum = 0;
  for (size_t i = 0; i < a.size(); ++i) sum += (a[i] - b[i]) * (a[i] - b[i]);
  return sum;
}

// Families are genuinely distinct shapes: a nearest-centroid classifier on a crude rotation-
// invariant signature, fitted on some seeds, recognises other seeds' family far above chance
// (1 / number of families).
TEST(ShapeFamiliesTest, FamiliesAreDistinguishableShapes) {
  const size_t num_families = ShapeFamilies().size();
  constexpr int kFitSeeds = 16;
  constexpr int kTestSeeds = 8;
  std::vector<std::vector<double>> centroids(num_families);
  std::vector<std::vector<std::vector<double>>> tests(num_families);
  for (size_t f = 0; f < num_families; ++f) {
    for (int s = 0; s < kFitSeeds + kTestSeeds; ++s) {
      absl::StatusOr<PointCloud> cloud = SampleNormalizedObject(f, 1000 + s, 512, s);
      ASSERT_TRUE(cloud.ok()) << cloud.status();
      const std::vector<double> signature = ShapeSignature(*cloud);
      if (s < kFitSeeds) {
        if (centroids[f].empty()) centroids[f].assign(signature.size(), 0.0);
        for (size_t k = 0; k < signature.size(); ++k) centroids[f][k] += signature[k] / kFitSeeds;
      } else {
        tests[f].push_back(signature);
      }
    }
  }
  int correct = 0;
  for (size_t f = 0; f < num_families; ++f) {
    for (const std::vector<double>& signature : tests[f]) {
      size_t best = 0;
      for (size_t g = 1; g < num_families; ++g) {
        if (SquaredDistance(signature, centroids[g]) <
            SquaredDistance(signature, centroids[best])) {
          best = g;
        }
      }
      correct += best == f;
    }
  }
  const double accuracy = static_cast<double>(correct) / (num_families * kTestSeeds);
  RecordProperty("nearest_centroid_accuracy", std::to_string(accuracy));
  std::printf("nearest-centroid family accuracy: %.3f (chance %.3f)\n", accuracy,
              1.0 / num_families);
  EXPECT_GT(accuracy, 0.4);
}

}  // namespace
}  // namespace rpsr::core
