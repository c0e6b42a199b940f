#include "core/data/object_pairs.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <set>

#include "core/data/transform_convention.h"
#include "core/synth/primitive_meshes.h"
#include "core/synth/shape_families.h"
#include "gtest/gtest.h"

namespace rpsr::core {
namespace {

constexpr double kDegree = M_PI / 180.0;

// Largest distance between T * source[i] (in double) and target[i].
double LargestPointwiseGap(const ObjectPair& pair, const PointCloud& source) {
  double largest = 0.0;
  for (size_t i = 0; i < source.size(); ++i) {
    const Eigen::Vector3d mapped = pair.T_target_source * source.points[i].cast<double>();
    largest = std::max(largest, (mapped - pair.target.points[i].cast<double>()).norm());
  }
  return largest;
}

TEST(ObjectPairsTest, AnglesAndTranslationsStayInThePapersRanges) {
  const PairOptions options;
  Eigen::Vector3d smallest = Eigen::Vector3d::Constant(INFINITY);
  Eigen::Vector3d largest = Eigen::Vector3d::Constant(-INFINITY);
  Eigen::Vector3d smallest_t = Eigen::Vector3d::Constant(INFINITY);
  Eigen::Vector3d largest_t = Eigen::Vector3d::Constant(-INFINITY);
  PairOptions small = options;
  small.num_points = 8;  // the pose does not depend on the point count
  for (uint64_t seed = 0; seed < 2000; ++seed) {
    absl::StatusOr<ObjectPair> pair = MakeObjectPair(small, seed);
    ASSERT_TRUE(pair.ok()) << pair.status();
    // Decompose the ground-truth rotation itself, not just the recorded angles.
    const Eigen::Vector3d angles = EulerXyzFromRotation(pair->T_target_source.linear());
    EXPECT_TRUE(angles.isApprox(pair->euler_angles_rad, 1e-9));
    for (int axis = 0; axis < 3; ++axis) {
      ASSERT_GT(angles[axis], 0.0) << "seed " << seed;
      ASSERT_LE(angles[axis], 45.0 * kDegree + 1e-12) << "seed " << seed;
    }
    const Eigen::Vector3d t = pair->T_target_source.translation();
    ASSERT_LE(t.cwiseAbs().maxCoeff(), 0.5) << "seed " << seed;
    smallest = smallest.cwiseMin(angles);
    largest = largest.cwiseMax(angles);
    smallest_t = smallest_t.cwiseMin(t);
    largest_t = largest_t.cwiseMax(t);
    EXPECT_TRUE(pair->T_target_source.linear().isUnitary(1e-12));
    EXPECT_NEAR(pair->T_target_source.linear().determinant(), 1.0, 1e-12);
  }
  // The whole range is used.
  EXPECT_LT(smallest.maxCoeff(), 1.0 * kDegree);
  EXPECT_GT(largest.minCoeff(), 44.0 * kDegree);
  EXPECT_LT(smallest_t.maxCoeff(), -0.49);
  EXPECT_GT(largest_t.minCoeff(), 0.49);
}

TEST(ObjectPairsTest, CustomRangesAreHonoured) {
  PairOptions options;
  options.num_points = 8;
  options.max_angle_deg = 10.0;
  options.max_translation = 0.1;
  for (uint64_t seed = 0; seed < 300; ++seed) {
    const ObjectPair pair = *MakeObjectPair(options, seed);
    EXPECT_LE(pair.euler_angles_rad.maxCoeff(), 10.0 * kDegree);
    EXPECT_GT(pair.euler_angles_rad.minCoeff(), 0.0);
    EXPECT_LE(pair.T_target_source.translation().cwiseAbs().maxCoeff(), 0.1);
  }
}

TEST(ObjectPairsTest, GroundTruthMapsTheCleanSourceOntoTheTarget) {
  PairOptions options;
  options.same_points = true;
  for (uint64_t seed = 0; seed < 50; ++seed) {
    absl::StatusOr<ObjectPair> pair = MakeObjectPair(options, seed);
    ASSERT_TRUE(pair.ok()) << pair.status();
    ASSERT_EQ(pair->source.size(), pair->target.size());
    // Float points, double transform: agreement to float rounding of coordinates <= ~2.
    EXPECT_LT(LargestPointwiseGap(*pair, pair->source), 1e-6) << "seed " << seed;
    // And not by the inverse: T^-1 would be far off.
    double inverse_gap = 0;
    for (size_t i = 0; i < pair->source.size(); ++i) {
      inverse_gap = std::max(
          inverse_gap, (pair->T_target_source.inverse() * pair->source.points[i].cast<double>() -
                        pair->target.points[i].cast<double>())
                           .norm());
    }
    EXPECT_GT(inverse_gap, 0.05);
  }
}

TEST(ObjectPairsTest, IndependentSamplesLieOnTheSameSurface) {
  const PairOptions options;  // same_points = false by default
  for (uint64_t seed = 0; seed < 10; ++seed) {
    const ObjectPair pair = *MakeObjectPair(options, seed);
    ASSERT_EQ(pair.source.size(), 1024u);
    ASSERT_EQ(pair.target.size(), 1024u);
    EXPECT_GT(LargestPointwiseGap(pair, pair.source), 0.05);  // no point-to-point partners
    // ...but each mapped source point is near some target point.
    double mean_nearest = 0;
    for (const Eigen::Vector3f& p : pair.source.points) {
      const Eigen::Vector3f mapped = (pair.T_target_source.cast<float>() * p);
      float nearest = INFINITY;
      for (const Eigen::Vector3f& q : pair.target.points) {
        nearest = std::min(nearest, (mapped - q).norm());
      }
      mean_nearest += nearest / pair.source.size();
    }
    EXPECT_LT(mean_nearest, 0.08) << "seed " << seed;
  }
}

TEST(ObjectPairsTest, SourceIsInsideTheUnitCube) {
  const PairOptions options;
  for (uint64_t seed = 0; seed < 50; ++seed) {
    const ObjectPair pair = *MakeObjectPair(options, seed);
    for (const Eigen::Vector3f& p : pair.source.points) {
      ASSERT_LE(p.cwiseAbs().maxCoeff(), 1.0f);
    }
  }
}

TEST(ObjectPairsTest, SameSeedSamePairOtherSeedOtherPair) {
  PairOptions options;
  options.disturbance = DisturbanceKind::kGaussianNoise;
  options.disturbance_level = 3;
  const ObjectPair a = *MakeObjectPair(options, 123);
  const ObjectPair b = *MakeObjectPair(options, 123);
  const ObjectPair c = *MakeObjectPair(options, 124);
  EXPECT_EQ(a.source.points, b.source.points);
  EXPECT_EQ(a.target.points, b.target.points);
  EXPECT_TRUE(a.T_target_source.matrix() == b.T_target_source.matrix());
  EXPECT_EQ(a.family_index, b.family_index);
  EXPECT_EQ(a.disturbance.affected_indices, b.disturbance.affected_indices);
  EXPECT_NE(a.source.points, c.source.points);
  EXPECT_FALSE(a.T_target_source.matrix() == c.T_target_source.matrix());
}

// The disturbance draws from its own stream: the kNone pair of the same seed is the clean
// version, so the disturbed fraction can be counted exactly against it.
TEST(ObjectPairsTest, DisturbanceFractionsAreExactAtEveryLevel) {
  PairOptions clean_options;
  for (DisturbanceKind kind : {DisturbanceKind::kGaussianNoise, DisturbanceKind::kUniformOutliers,
                               DisturbanceKind::kCrop, DisturbanceKind::kJitter}) {
    for (int level = 0; level < kNumDisturbanceLevels; ++level) {
      const uint64_t seed = 1000 + level;
      const ObjectPair clean = *MakeObjectPair(clean_options, seed);
      PairOptions options;
      options.disturbance = kind;
      options.disturbance_level = level;
      const ObjectPair pair = *MakeObjectPair(options, seed);
      const double magnitude = *DisturbanceMagnitudeAtLevel(kind, level);
      EXPECT_EQ(pair.disturbance.kind, kind);
      EXPECT_EQ(pair.disturbance.magnitude, magnitude);
      // The target and the ground truth are untouched.
      EXPECT_EQ(pair.target.points, clean.target.points);
      EXPECT_TRUE(pair.T_target_source.matrix() == clean.T_target_source.matrix());
      const size_t n = clean.source.size();
      if (kind == DisturbanceKind::kCrop) {
        EXPECT_EQ(pair.source.size(), n - AffectedPointCount(n, magnitude));
        continue;
      }
      ASSERT_EQ(pair.source.size(), n);
      std::vector<size_t> changed;
      for (size_t i = 0; i < n; ++i) {
        if (pair.source.points[i] != clean.source.points[i]) changed.push_back(i);
      }
      if (kind == DisturbanceKind::kJitter) {
        EXPECT_EQ(changed.size(), n);
      } else {
        EXPECT_EQ(changed.size(), AffectedPointCount(n, magnitude))
            << DisturbanceName(kind) << " level " << level;
        EXPECT_EQ(changed, pair.disturbance.affected_indices);
      }
    }
  }
}

TEST(ObjectPairsTest, SamePointsGroundTruthHoldsForUndisturbedPointsOfADisturbedSource) {
  PairOptions options;
  options.same_points = true;
  options.disturbance = DisturbanceKind::kUniformOutliers;
  options.disturbance_level = 4;
  const ObjectPair pair = *MakeObjectPair(options, 9);
  const std::set<size_t> outliers(pair.disturbance.affected_indices.begin(),
                                  pair.disturbance.affected_indices.end());
  for (size_t i = 0; i < pair.source.size(); ++i) {
    if (outliers.count(i)) continue;
    const Eigen::Vector3d mapped = pair.T_target_source * pair.source.points[i].cast<double>();
    EXPECT_LT((mapped - pair.target.points[i].cast<double>()).norm(), 1e-6);
  }
}

TEST(ObjectPairsTest, M2SplitsAreDisjointAndM1CoversEveryFamily) {
  PairOptions options;
  options.num_points = 8;
  std::set<int> seen, unseen, all;
  for (uint64_t seed = 0; seed < 400; ++seed) {
    options.split = ObjectSplit::kM2Seen;
    seen.insert(MakeObjectPair(options, seed)->family_index);
    options.split = ObjectSplit::kM2Unseen;
    unseen.insert(MakeObjectPair(options, seed)->family_index);
    options.split = ObjectSplit::kM1All;
    all.insert(MakeObjectPair(options, seed)->family_index);
  }
  const int num_families = static_cast<int>(ShapeFamilies().size());
  EXPECT_EQ(static_cast<int>(all.size()), num_families);
  EXPECT_EQ(static_cast<int>(seen.size()), num_families / 2);
  EXPECT_EQ(static_cast<int>(unseen.size()), num_families / 2);
  for (int f : seen) {
    EXPECT_LT(f, num_families / 2);
    EXPECT_EQ(ShapeFamilies()[f].split, FamilySplit::kSeen);
    EXPECT_EQ(unseen.count(f), 0u);
  }
  for (int f : unseen) EXPECT_EQ(ShapeFamilies()[f].split, FamilySplit::kUnseen);
}

TEST(ObjectPairsTest, RandomDisturbanceUsesAllFourAtTrainingMagnitudes) {
  PairOptions options;
  options.num_points = 200;
  options.random_disturbance = true;
  std::set<DisturbanceKind> kinds;
  for (uint64_t seed = 0; seed < 60; ++seed) {
    const ObjectPair pair = *MakeObjectPair(options, seed);
    kinds.insert(pair.disturbance.kind);
    EXPECT_EQ(pair.disturbance.magnitude,
              pair.disturbance.kind == DisturbanceKind::kJitter ? 0.03 : 0.20);
  }
  EXPECT_EQ(kinds.size(), 4u);
  EXPECT_EQ(kinds.count(DisturbanceKind::kNone), 0u);
}

// Partial views: the source is cut exactly as kCrop cuts it at the same seed, and the target loses
// the same fraction along another direction, a contiguous chunk of the clean target; the truth
// still maps every kept source point onto the surface where the clean pair has it.
TEST(ObjectPairsTest, PartialViewsCropBothCloudsAlongTheirOwnDirections) {
  PairOptions clean_options;
  PairOptions crop_options;
  crop_options.disturbance = DisturbanceKind::kCrop;
  crop_options.disturbance_level = 3;
  PairOptions partial_options = crop_options;
  partial_options.disturbance = DisturbanceKind::kPartialViews;
  for (uint64_t seed : {5u, 6u, 7u}) {
    const ObjectPair clean = *MakeObjectPair(clean_options, seed);
    const ObjectPair cropped = *MakeObjectPair(crop_options, seed);
    const ObjectPair partial = *MakeObjectPair(partial_options, seed);
    EXPECT_EQ(partial.source.points, cropped.source.points);
    EXPECT_TRUE(partial.T_target_source.matrix() == clean.T_target_source.matrix());
    EXPECT_EQ(partial.disturbance.kind, DisturbanceKind::kPartialViews);
    EXPECT_EQ(cropped.target_disturbance.kind, DisturbanceKind::kNone);
    ASSERT_EQ(partial.target_disturbance.kind, DisturbanceKind::kPartialViews);
    const size_t n = clean.target.size();
    const size_t removed = AffectedPointCount(n, 0.30);
    ASSERT_EQ(partial.target.size(), n - removed);
    ASSERT_EQ(partial.target_disturbance.affected_indices.size(), removed);
    // The kept target points are the clean target's others, in order; the removed ones lie
    // beyond a plane along the target's own direction, drawn apart from the source's (which,
    // mapped into the target frame, points elsewhere).
    std::vector<bool> gone(n, false);
    for (size_t i : partial.target_disturbance.affected_indices) gone[i] = true;
    std::vector<Eigen::Vector3f> kept;
    for (size_t i = 0; i < n; ++i) {
      if (!gone[i]) kept.push_back(clean.target.points[i]);
    }
    EXPECT_EQ(partial.target.points, kept);
    const Eigen::Vector3d d = partial.target_disturbance.crop_direction;
    double lowest_removed = std::numeric_limits<double>::infinity();
    double highest_kept = -std::numeric_limits<double>::infinity();
    for (size_t i = 0; i < n; ++i) {
      const double along = d.dot(clean.target.points[i].cast<double>());
      if (gone[i]) {
        lowest_removed = std::min(lowest_removed, along);
      } else {
        highest_kept = std::max(highest_kept, along);
      }
    }
    EXPECT_GE(lowest_removed, highest_kept);
    EXPECT_LT(d.dot(partial.T_target_source.linear() * partial.disturbance.crop_direction), 0.999);
  }
}

TEST(ObjectPairsTest, MagnitudeOverridesLevel) {
  PairOptions options;
  options.disturbance = DisturbanceKind::kCrop;
  options.disturbance_magnitude = 0.5;
  const ObjectPair pair = *MakeObjectPair(options, 1);
  EXPECT_EQ(pair.source.size(), 512u);
}

TEST(ObjectPairsTest, PairsFromACallersMesh) {
  const TriangleMesh box =
      TransformedMesh(BoxMesh({3.0f, 1.0f, 2.0f}), PlacedAt({5.0f, 5.0f, 5.0f}));
  PairOptions options;
  options.same_points = true;
  absl::StatusOr<ObjectPair> pair = MakeObjectPairFromMesh(box, options, 4);
  ASSERT_TRUE(pair.ok()) << pair.status();
  EXPECT_EQ(pair->family_index, -1);
  for (const Eigen::Vector3f& p : pair->source.points) {
    EXPECT_LE(p.cwiseAbs().maxCoeff(), 1.0f);
  }
  EXPECT_LT(LargestPointwiseGap(*pair, pair->source), 1e-6);
  EXPECT_FALSE(MakeObjectPairFromMesh(TriangleMesh{}, options, 4).ok());
}

TEST(ObjectPairsTest, RejectsInvalidOptions) {
  PairOptions options;
  options.num_points = 0;
  EXPECT_EQ(MakeObjectPair(options, 0).status().code(), absl::StatusCode::kInvalidArgument);
  options = PairOptions{};
  options.max_angle_deg = 0.0;
  EXPECT_FALSE(MakeObjectPair(options, 0).ok());
  options = PairOptions{};
  options.max_translation = -1.0;
  EXPECT_FALSE(MakeObjectPair(options, 0).ok());
  options = PairOptions{};
  options.disturbance = DisturbanceKind::kCrop;
  options.disturbance_level = 5;
  EXPECT_FALSE(MakeObjectPair(options, 0).ok());
  options.disturbance_level = 0;
  options.disturbance_magnitude = 1.5;
  EXPECT_FALSE(MakeObjectPair(options, 0).ok());
  options.disturbance = DisturbanceKind::kPartialViews;
  EXPECT_FALSE(ValidatePairOptions(options).ok());
  EXPECT_TRUE(ValidatePairOptions(PairOptions{}).ok());
}

}  // namespace
}  // namespace rpsr::core
