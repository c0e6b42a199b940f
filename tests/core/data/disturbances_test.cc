#include "core/data/disturbances.h"

#include <algorithm>
#include <cmath>
#include <set>

#include "core/synth/object_normalization.h"
#include "gtest/gtest.h"

namespace rpsr::core {
namespace {

PointCloud TestCloud(size_t num_points = 1024) {
  return *SampleNormalizedObject(/*family_index=*/4, /*object_seed=*/1, num_points, 2);
}

std::vector<size_t> ChangedIndices(const PointCloud& before, const PointCloud& after) {
  std::vector<size_t> changed;
  for (size_t i = 0; i < before.size(); ++i) {
    if (before.points[i] != after.points[i]) changed.push_back(i);
  }
  return changed;
}

TEST(DisturbanceLevelsTest, PaperLevels) {
  const double noise[] = {0.01, 0.05, 0.10, 0.20, 0.40};
  const double crop[] = {0.01, 0.10, 0.20, 0.30, 0.40};
  for (int level = 0; level < kNumDisturbanceLevels; ++level) {
    EXPECT_EQ(*DisturbanceMagnitudeAtLevel(DisturbanceKind::kGaussianNoise, level), noise[level]);
    EXPECT_EQ(*DisturbanceMagnitudeAtLevel(DisturbanceKind::kUniformOutliers, level), noise[level]);
    EXPECT_EQ(*DisturbanceMagnitudeAtLevel(DisturbanceKind::kCrop, level), crop[level]);
    EXPECT_EQ(*DisturbanceMagnitudeAtLevel(DisturbanceKind::kPartialViews, level), crop[level]);
    if (level > 0) {
      EXPECT_GT(*DisturbanceMagnitudeAtLevel(DisturbanceKind::kJitter, level),
                *DisturbanceMagnitudeAtLevel(DisturbanceKind::kJitter, level - 1));
    }
  }
  EXPECT_EQ(*DisturbanceMagnitudeAtLevel(DisturbanceKind::kJitter, 2), 0.03);
  EXPECT_FALSE(DisturbanceMagnitudeAtLevel(DisturbanceKind::kCrop, 5).ok());
  EXPECT_FALSE(DisturbanceMagnitudeAtLevel(DisturbanceKind::kCrop, -1).ok());
}

TEST(DisturbanceLevelsTest, AffectedCountRounds) {
  EXPECT_EQ(AffectedPointCount(1024, 0.01), 10u);
  EXPECT_EQ(AffectedPointCount(1024, 0.05), 51u);
  EXPECT_EQ(AffectedPointCount(1024, 0.20), 205u);
  EXPECT_EQ(AffectedPointCount(1024, 0.40), 410u);
  EXPECT_EQ(AffectedPointCount(1000, 0.30), 300u);
  EXPECT_EQ(AffectedPointCount(10, 0.25), 3u);  // 2.5 rounds away from zero
  EXPECT_EQ(AffectedPointCount(0, 0.4), 0u);
}

TEST(DisturbancesTest, GaussianNoiseMovesExactlyTheRoundedFraction) {
  const PointCloud clean = TestCloud();
  for (int level = 0; level < kNumDisturbanceLevels; ++level) {
    const double fraction = *DisturbanceMagnitudeAtLevel(DisturbanceKind::kGaussianNoise, level);
    PointCloud cloud = clean;
    absl::StatusOr<AppliedDisturbance> applied =
        ApplyDisturbance(DisturbanceKind::kGaussianNoise, fraction, 77, cloud);
    ASSERT_TRUE(applied.ok()) << applied.status();
    ASSERT_EQ(cloud.size(), clean.size());
    EXPECT_EQ(applied->affected_indices.size(), AffectedPointCount(clean.size(), fraction));
    EXPECT_EQ(ChangedIndices(clean, cloud), applied->affected_indices);
  }
  // The displacement has the paper's standard deviation 0.02 per axis.
  PointCloud cloud = clean;
  const AppliedDisturbance all = *ApplyDisturbance(DisturbanceKind::kGaussianNoise, 1.0, 5, cloud);
  double sum_squares = 0;
  for (size_t i = 0; i < cloud.size(); ++i) {
    sum_squares += (cloud.points[i] - clean.points[i]).cast<double>().squaredNorm();
  }
  EXPECT_NEAR(std::sqrt(sum_squares / (3.0 * cloud.size())), kGaussianNoiseSigma, 0.002);
}

TEST(DisturbancesTest, UniformOutliersReplaceExactlyTheRoundedFraction) {
  const PointCloud clean = TestCloud();
  for (int level = 0; level < kNumDisturbanceLevels; ++level) {
    const double fraction = *DisturbanceMagnitudeAtLevel(DisturbanceKind::kUniformOutliers, level);
    PointCloud cloud = clean;
    const AppliedDisturbance applied =
        *ApplyDisturbance(DisturbanceKind::kUniformOutliers, fraction, 78, cloud);
    ASSERT_EQ(cloud.size(), clean.size());
    EXPECT_EQ(applied.affected_indices.size(), AffectedPointCount(clean.size(), fraction));
    EXPECT_EQ(ChangedIndices(clean, cloud), applied.affected_indices);
    for (size_t i : applied.affected_indices) {
      EXPECT_LE(cloud.points[i].cwiseAbs().maxCoeff(), kOutlierHalfExtent);
    }
  }
}

TEST(DisturbancesTest, CropRemovesExactlyTheRoundedFractionBeyondAPlane) {
  const PointCloud clean = TestCloud();
  for (int level = 0; level < kNumDisturbanceLevels; ++level) {
    const double fraction = *DisturbanceMagnitudeAtLevel(DisturbanceKind::kCrop, level);
    PointCloud cloud = clean;
    const AppliedDisturbance applied =
        *ApplyDisturbance(DisturbanceKind::kCrop, fraction, 79 + level, cloud);
    const size_t removed = AffectedPointCount(clean.size(), fraction);
    ASSERT_EQ(applied.affected_indices.size(), removed);
    ASSERT_EQ(cloud.size(), clean.size() - removed);
    EXPECT_NEAR(applied.crop_direction.norm(), 1.0, 1e-12);
    // The kept points are the others, in their original order.
    const std::set<size_t> gone(applied.affected_indices.begin(), applied.affected_indices.end());
    size_t next = 0;
    double lowest_removed = INFINITY, highest_kept = -INFINITY;
    for (size_t i = 0; i < clean.size(); ++i) {
      const double height = applied.crop_direction.dot(clean.points[i].cast<double>());
      if (gone.count(i)) {
        lowest_removed = std::min(lowest_removed, height);
      } else {
        ASSERT_EQ(cloud.points[next++], clean.points[i]);
        highest_kept = std::max(highest_kept, height);
      }
    }
    EXPECT_GE(lowest_removed, highest_kept);
  }
}

TEST(DisturbancesTest, JitterStaysWithinTolerance) {
  const PointCloud clean = TestCloud();
  for (int level = 0; level < kNumDisturbanceLevels; ++level) {
    const double tolerance = *DisturbanceMagnitudeAtLevel(DisturbanceKind::kJitter, level);
    PointCloud cloud = clean;
    const AppliedDisturbance applied =
        *ApplyDisturbance(DisturbanceKind::kJitter, tolerance, 80, cloud);
    ASSERT_EQ(cloud.size(), clean.size());
    EXPECT_TRUE(applied.affected_indices.empty());
    EXPECT_EQ(ChangedIndices(clean, cloud).size(), clean.size());
    double largest = 0, total = 0;
    for (size_t i = 0; i < clean.size(); ++i) {
      const double moved = (cloud.points[i] - clean.points[i]).cast<double>().norm();
      largest = std::max(largest, moved);
      total += moved;
    }
    EXPECT_LE(largest, tolerance + 1e-6);
    // Sigma is tolerance / 2, so the mean displacement is a sizeable part of the tolerance.
    EXPECT_GT(total / clean.size(), 0.4 * tolerance);
  }
}

TEST(DisturbancesTest, SameSeedSameResultOtherSeedOther) {
  for (DisturbanceKind kind : {DisturbanceKind::kGaussianNoise, DisturbanceKind::kUniformOutliers,
                               DisturbanceKind::kCrop, DisturbanceKind::kJitter}) {
    PointCloud a = TestCloud(), b = TestCloud(), c = TestCloud();
    ASSERT_TRUE(ApplyDisturbance(kind, 0.2, 1, a).ok());
    ASSERT_TRUE(ApplyDisturbance(kind, 0.2, 1, b).ok());
    ASSERT_TRUE(ApplyDisturbance(kind, 0.2, 2, c).ok());
    EXPECT_EQ(a.points, b.points) << DisturbanceName(kind);
    EXPECT_NE(a.points, c.points) << DisturbanceName(kind);
  }
}

TEST(DisturbancesTest, CropKeepsIntensitiesWithTheirPoints) {
  PointCloud cloud = TestCloud(100);
  for (size_t i = 0; i < cloud.size(); ++i) cloud.intensities.push_back(static_cast<float>(i));
  const PointCloud clean = cloud;
  const AppliedDisturbance applied = *ApplyDisturbance(DisturbanceKind::kCrop, 0.3, 4, cloud);
  ASSERT_EQ(cloud.intensities.size(), cloud.size());
  for (size_t k = 0; k < cloud.size(); ++k) {
    const size_t original = static_cast<size_t>(cloud.intensities[k]);
    EXPECT_EQ(cloud.points[k], clean.points[original]);
  }
  EXPECT_EQ(applied.affected_indices.size(), 30u);
}

TEST(DisturbancesTest, RejectsBadMagnitudes) {
  PointCloud cloud = TestCloud(10);
  EXPECT_EQ(ApplyDisturbance(DisturbanceKind::kCrop, 1.5, 0, cloud).status().code(),
            absl::StatusCode::kInvalidArgument);
  EXPECT_FALSE(ApplyDisturbance(DisturbanceKind::kPartialViews, 1.5, 0, cloud).ok());
  EXPECT_FALSE(ApplyDisturbance(DisturbanceKind::kGaussianNoise, -0.1, 0, cloud).ok());
  EXPECT_FALSE(ApplyDisturbance(DisturbanceKind::kJitter, -0.1, 0, cloud).ok());
  EXPECT_FALSE(ApplyDisturbance(DisturbanceKind::kJitter, NAN, 0, cloud).ok());
  EXPECT_EQ(cloud.size(), 10u);
  // Jitter's magnitude is a distance, so more than 1 is allowed.
  EXPECT_FALSE(IsFractionDisturbance(DisturbanceKind::kJitter));
  EXPECT_TRUE(ApplyDisturbance(DisturbanceKind::kJitter, 1.5, 0, cloud).ok());
  EXPECT_TRUE(IsFractionDisturbance(DisturbanceKind::kUniformOutliers));
}

}  // namespace
}  // namespace rpsr::core
