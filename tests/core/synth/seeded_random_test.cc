#include "core/synth/seeded_random.h"

#include <algorithm>
#include <cmath>
#include <set>

#include "gtest/gtest.h"

namespace rpsr::core {
namespace {

TEST(SeededRandomTest, SameSeedSameStream) {
  SeededRandom a(42);
  SeededRandom b(42);
  for (int i = 0; i < 100; ++i) {
    EXPECT_EQ(a.NextBits(), b.NextBits());
    EXPECT_EQ(a.Normal(0, 1), b.Normal(0, 1));
  }
}

TEST(SeededRandomTest, PinnedValuesDoNotDrift) {
  // std::mt19937_64's 10000th output for the default seed is fixed by the C++ standard; our
  // mappings on top of it must not change either, or every stored benchmark pair changes.
  std::mt19937_64 reference;
  reference.discard(9999);
  EXPECT_EQ(reference(), 9981545732273789042ULL);
  SeededRandom random(5489);
  EXPECT_EQ(random.UniformUnit(),
            static_cast<double>(14514284786278117030ULL >> 11) / 9007199254740992.0);
  EXPECT_EQ(DeriveSeed(0, 0), DeriveSeed(0, 0));
  EXPECT_NE(DeriveSeed(0, 0), DeriveSeed(0, 1));
  EXPECT_NE(DeriveSeed(1, 0), DeriveSeed(0, 1));
}

TEST(SeededRandomTest, UniformStaysInRange) {
  SeededRandom random(7);
  for (int i = 0; i < 10000; ++i) {
    const double u = random.Uniform(-0.5, 0.5);
    EXPECT_GE(u, -0.5);
    EXPECT_LT(u, 0.5);
    const int k = random.UniformInt(3, 7);
    EXPECT_GE(k, 3);
    EXPECT_LE(k, 7);
    EXPECT_LT(random.UniformIndex(5), 5u);
  }
}

TEST(SeededRandomTest, NormalHasRequestedMoments) {
  SeededRandom random(11);
  constexpr int kCount = 200000;
  double sum = 0, sum_squares = 0;
  for (int i = 0; i < kCount; ++i) {
    const double x = random.Normal(1.0, 0.02);
    sum += x;
    sum_squares += (x - 1.0) * (x - 1.0);
  }
  EXPECT_NEAR(sum / kCount, 1.0, 1e-3);
  EXPECT_NEAR(std::sqrt(sum_squares / kCount), 0.02, 2e-4);
}

TEST(SeededRandomTest, UnitVectorIsUnit) {
  SeededRandom random(3);
  for (int i = 0; i < 1000; ++i) EXPECT_NEAR(random.UnitVector().norm(), 1.0, 1e-12);
}

TEST(SeededRandomTest, DistinctIndicesAreDistinctAndInRange) {
  SeededRandom random(9);
  for (size_t count : {size_t{0}, size_t{1}, size_t{10}, size_t{100}}) {
    const std::vector<size_t> indices = random.DistinctIndices(100, count);
    ASSERT_EQ(indices.size(), count);
    EXPECT_EQ(std::set<size_t>(indices.begin(), indices.end()).size(), count);
    for (size_t i : indices) EXPECT_LT(i, 100u);
  }
}

}  // namespace
}  // namespace rpsr::core
