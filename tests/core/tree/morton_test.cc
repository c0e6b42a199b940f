#include "core/tree/morton.h"

#include <random>

#include "gtest/gtest.h"

namespace rpsr::core {
namespace {

TEST(MortonTest, OctantBitsAreXThenYThenZ) {
  EXPECT_EQ(EncodeMorton<3>({1, 0, 0}), 1u);
  EXPECT_EQ(EncodeMorton<3>({0, 1, 0}), 2u);
  EXPECT_EQ(EncodeMorton<3>({0, 0, 1}), 4u);
  EXPECT_EQ(EncodeMorton<2>({1, 0}), 1u);
  EXPECT_EQ(EncodeMorton<2>({0, 1}), 2u);
  // Depth 2: the coarse octant sits above the fine one.
  EXPECT_EQ(EncodeMorton<3>({2, 0, 0}), 8u);
  EXPECT_EQ(EncodeMorton<3>({3, 3, 3}), 63u);
}

TEST(MortonTest, RoundTripsAtTheLargestDepth) {
  std::mt19937_64 rng(7);
  for (int i = 0; i < 10000; ++i) {
    const std::array<uint32_t, 3> cell3 = {static_cast<uint32_t>(rng() & 0x1fffff),
                                           static_cast<uint32_t>(rng() & 0x1fffff),
                                           static_cast<uint32_t>(rng() & 0x1fffff)};
    EXPECT_EQ(DecodeMorton<3>(EncodeMorton<3>(cell3)), cell3);
    const std::array<uint32_t, 2> cell2 = {static_cast<uint32_t>(rng() & 0x7fffffff),
                                           static_cast<uint32_t>(rng() & 0x7fffffff)};
    EXPECT_EQ(DecodeMorton<2>(EncodeMorton<2>(cell2)), cell2);
  }
}

TEST(MortonTest, ParentIsShiftedCode) {
  std::mt19937_64 rng(11);
  for (int i = 0; i < 1000; ++i) {
    const std::array<uint32_t, 3> cell = {static_cast<uint32_t>(rng() & 0x3ff),
                                          static_cast<uint32_t>(rng() & 0x3ff),
                                          static_cast<uint32_t>(rng() & 0x3ff)};
    const std::array<uint32_t, 3> parent = {cell[0] >> 1, cell[1] >> 1, cell[2] >> 1};
    EXPECT_EQ(EncodeMorton<3>(cell) >> 3, EncodeMorton<3>(parent));
  }
}

}  // namespace
}  // namespace rpsr::core
