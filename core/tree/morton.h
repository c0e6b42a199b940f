// Morton (Z-order) codes for D = 2 and D = 3 integer grids.
//
// Bit layout: at every level the D bits of a cell's octant are (x, y[, z]) from least to most
// significant, so a child's octant index is `(x & 1) | (y & 1) << 1 [| (z & 1) << 2]` where 1
// means the upper half of its parent along that axis. A code at depth d holds d such groups, the
// coarsest in the most significant position, hence:
//   parent code = code >> D,   octant within the parent = code & (2^D - 1),
// and sorting codes ascending visits cells in Morton 'Z' order with every parent's children
// contiguous and ordered by octant.
#ifndef RPSR_CORE_TREE_MORTON_H_
#define RPSR_CORE_TREE_MORTON_H_

#include <array>
#include <cstdint>

namespace rpsr::core {

// Spreads the low 32 bits of x so that bit i moves to bit 2i (for D = 2).
constexpr uint64_t SpreadBits2(uint64_t x) {
  x &= 0xffffffffull;
  x = (x | (x << 16)) & 0x0000ffff0000ffffull;
  x = (x | (x << 8)) & 0x00ff00ff00ff00ffull;
  x = (x | (x << 4)) & 0x0f0f0f0f0f0f0f0full;
  x = (x | (x << 2)) & 0x3333333333333333ull;
  x = (x | (x << 1)) & 0x5555555555555555ull;
  return x;
}

constexpr uint64_t CompactBits2(uint64_t x) {
  x &= 0x5555555555555555ull;
  x = (x | (x >> 1)) & 0x3333333333333333ull;
  x = (x | (x >> 2)) & 0x0f0f0f0f0f0f0f0full;
  x = (x | (x >> 4)) & 0x00ff00ff00ff00ffull;
  x = (x | (x >> 8)) & 0x0000ffff0000ffffull;
  x = (x | (x >> 16)) & 0x00000000ffffffffull;
  return x;
}

// Spreads the low 21 bits of x so that bit i moves to bit 3i (for D = 3).
constexpr uint64_t SpreadBits3(uint64_t x) {
  x &= 0x1fffffull;
  x = (x | (x << 32)) & 0x001f00000000ffffull;
  x = (x | (x << 16)) & 0x001f0000ff0000ffull;
  x = (x | (x << 8)) & 0x100f00f00f00f00full;
  x = (x | (x << 4)) & 0x10c30c30c30c30c3ull;
  x = (x | (x << 2)) & 0x1249249249249249ull;
  return x;
}

constexpr uint64_t CompactBits3(uint64_t x) {
  x &= 0x1249249249249249ull;
  x = (x | (x >> 2)) & 0x10c30c30c30c30c3ull;
  x = (x | (x >> 4)) & 0x100f00f00f00f00full;
  x = (x | (x >> 8)) & 0x001f0000ff0000ffull;
  x = (x | (x >> 16)) & 0x001f00000000ffffull;
  x = (x | (x >> 32)) & 0x00000000001fffffull;
  return x;
}

// Largest depth whose codes fit in 64 bits: 31 for quadtrees, 21 for octrees.
template <int D>
inline constexpr int kMaxMortonDepth = 63 / D;

template <int D>
constexpr uint64_t EncodeMorton(const std::array<uint32_t, D>& cell) {
  static_assert(D == 2 || D == 3, "Morton codes are implemented for D = 2 and D = 3");
  if constexpr (D == 2) {
    return SpreadBits2(cell[0]) | (SpreadBits2(cell[1]) << 1);
  } else {
    return SpreadBits3(cell[0]) | (SpreadBits3(cell[1]) << 1) | (SpreadBits3(cell[2]) << 2);
  }
}

template <int D>
constexpr std::array<uint32_t, D> DecodeMorton(uint64_t code) {
  static_assert(D == 2 || D == 3, "Morton codes are implemented for D = 2 and D = 3");
  if constexpr (D == 2) {
    return {static_cast<uint32_t>(CompactBits2(code)),
            static_cast<uint32_t>(CompactBits2(code >> 1))};
  } else {
    return {static_cast<uint32_t>(CompactBits3(code)),
            static_cast<uint32_t>(CompactBits3(code >> 1)),
            static_cast<uint32_t>(CompactBits3(code >> 2))};
  }
}

}  // namespace rpsr::core

#endif  // RPSR_CORE_TREE_MORTON_H_
