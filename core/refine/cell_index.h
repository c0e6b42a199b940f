// Which node of a tree level occupies a cell: Morton code -> node index, or -1. The refinement's
// correspondence search asks it for the 8 cells around a moved CoM whenever the CoM changes block
// (about a fifth of the node visits on 2,048-point objects), so it sits in the refinement's
// innermost loop.
//
// Why three representations: a hash lookup costs ~25 ns (hashing, probing, a random access), and
// those lookups were over half of the search's time. A level's nodes are listed by strictly
// ascending Morton code (Octree::Level::morton), so a node's index is simply its code's rank among
// the occupied cells: one bit per cell plus a running count per 64 cells (1.5 bits a cell)
// answers with a bit test and a popcount. Memory decides the form: with at most 64 cells a node
// that is at most 12 bytes a node (a hash map holds ~17 per slot, 15-23 a node), and a level of
// at most 2^18 cells (an octree's depths 0-6) costs at most 48 KB whatever its nodes. So an
// object's depths 3-6 are dense by the size clause (~55 KB in all, more than the hash map on a
// sparse object's depth 6), and so are a scan's coarse depths. A scan's deep, sparse levels (its
// depth 9 has ~134M cells for ~7,600 nodes) are blocked: the same ranks, kept only for the blocks
// of 8^3 cells that hold a node, found through a dense index of the blocks three depths up. Its
// memory is the hash map's or less, and a search's 8 neighbouring cells mostly lie in one block
// (one cache line of bits), where a hash map's 8 lookups were 8 random accesses (its probes were
// a seventh of a scan's linearisations). Sparser levels, or deeper ones than 9, are hashed.
// Same answers in every form (tests/core/refine/cell_index_test.cc).
#ifndef RPSR_CORE_REFINE_CELL_INDEX_H_
#define RPSR_CORE_REFINE_CELL_INDEX_H_

#include <algorithm>
#include <array>
#include <cassert>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "Eigen/Core"
#include "absl/container/flat_hash_map.h"
#include "core/tree/bh_tree.h"
#include "core/tree/morton.h"

namespace rpsr::core {

class CellIndex {
 public:
  // How a level is indexed (see the file comment).
  enum class Form { kDense, kBlocked, kHashed };
  // The dense form is taken when the level has at most this many cells per node (or at most
  // kSmallLevelCells cells in all, where the other forms' fixed costs dominate).
  static constexpr uint64_t kMaxDenseCellsPerNode = 64;
  static constexpr uint64_t kSmallLevelCells = uint64_t{1} << 18;  // depth 6 of an octree
  // The blocked form: blocks of 8^3 cells (a cell of the level three depths up), taken when that
  // coarser level fits kSmallLevelCells (depths 7-9) and the blocks cost at most this many bytes
  // a node (a hash map's ~15-23; a simulated scan's depths 7-9 hold 13-19 nodes a block, 5-7 bytes
  // a node, as CellIndexTest.AScansDeepLevelsAreBlocked prints).
  static constexpr int kBlockDepths = 3;
  static constexpr uint64_t kMaxBlockedBytesPerNode = 24;

  CellIndex() = default;
  // `codes`: a level's Morton codes, strictly ascending; `depth`: the level's depth (an octree's
  // 8^depth cells).
  CellIndex(const std::vector<uint64_t>& codes, int depth) {
    assert(depth >= 0 && depth <= 21);  // Morton codes of an octree fit 21 depths (morton.h)
    const uint64_t cells = uint64_t{1} << (3 * depth);
    // The dense form writes bit `code`: codes must be below 8^depth (and ascending for the ranks).
    assert(std::is_sorted(codes.begin(), codes.end()) &&
           std::adjacent_find(codes.begin(), codes.end()) == codes.end() &&
           (codes.empty() || codes.back() < cells));
    const uint64_t nodes = codes.size();
    if (cells <= kSmallLevelCells || cells <= kMaxDenseCellsPerNode * nodes) {
      form_ = Form::kDense;
      dense_.Build(codes, cells);
      return;
    }
    if (depth - kBlockDepths >= 0 && (cells >> (3 * kBlockDepths)) <= kSmallLevelCells &&
        TryBlocks(codes, cells)) {
      form_ = Form::kBlocked;
      return;
    }
    form_ = Form::kHashed;
    hash_.reserve(codes.size());
    for (size_t j = 0; j < codes.size(); ++j) hash_.emplace(codes[j], static_cast<int32_t>(j));
  }

  // The node at `code`, or -1 when the cell is empty (or outside the level).
  int32_t Find(uint64_t code) const {
    switch (form_) {
      case Form::kDense:
        return dense_.Find(code);
      case Form::kBlocked: {
        const int32_t b = top_.Find(code >> kBlockShift);
        return b < 0 ? -1 : FindInBlock(blocks_[static_cast<size_t>(b)], code);
      }
      case Form::kHashed:
        break;
    }
    const auto it = hash_.find(code);
    return it == hash_.end() ? -1 : it->second;
  }

  // Find for each of codes[0 .. n) into out: the blocked form reads the index of blocks once for
  // a run of codes in one block (FindBlock's cells mostly are). A code of ~0 finds -1.
  void FindAll(const uint64_t* codes, int n, int32_t* out) const {
    if (form_ != Form::kBlocked) {
      for (int i = 0; i < n; ++i) out[i] = Find(codes[i]);
      return;
    }
    uint64_t last_top = ~uint64_t{0};
    int32_t b = -1;
    for (int i = 0; i < n; ++i) {
      const uint64_t top = codes[i] >> kBlockShift;
      if (top != last_top) {
        last_top = top;
        b = top_.Find(top);
      }
      out[i] = b < 0 ? -1 : FindInBlock(blocks_[static_cast<size_t>(b)], codes[i]);
    }
  }

  Form form() const { return form_; }
  bool dense() const { return form_ == Form::kDense; }

  size_t bytes() const {
    return sizeof(*this) + dense_.bytes() + top_.bytes() + blocks_.capacity() * sizeof(Block) +
           hash_.capacity() * (sizeof(std::pair<uint64_t, int32_t>) + 1);
  }

 private:
  static constexpr int kBlockShift = 3 * kBlockDepths;
  static constexpr uint64_t kBlockCells = uint64_t{1} << kBlockShift;  // 512: 8 words of bits

  // Bits set in x. Inline: the build targets baseline x86-64 (no POPCNT instruction), where
  // __builtin_popcountll is a call per lookup (into libgcc, through the PLT) to this same sequence.
  static int32_t PopCount(uint64_t x) {
    x = x - ((x >> 1) & 0x5555555555555555ull);
    x = (x & 0x3333333333333333ull) + ((x >> 2) & 0x3333333333333333ull);
    x = (x + (x >> 4)) & 0x0f0f0f0f0f0f0f0full;
    return static_cast<int32_t>((x * 0x0101010101010101ull) >> 56);
  }

  // One bit per cell and a running count per 64 cells: a code's rank among the occupied cells.
  struct RankedBits {
    std::vector<uint64_t> occupied;  // bit (code & 63) of word (code >> 6): the cell is occupied
    std::vector<int32_t> rank;       // occupied cells in the words before

    void Build(const std::vector<uint64_t>& codes, uint64_t cells) {
      const size_t words = static_cast<size_t>((cells + 63) / 64);
      occupied.assign(words, 0);
      for (uint64_t code : codes) occupied[code >> 6] |= uint64_t{1} << (code & 63);
      rank.resize(words);
      int32_t before = 0;
      for (size_t w = 0; w < words; ++w) {
        rank[w] = before;
        before += PopCount(occupied[w]);
      }
    }
    int32_t Find(uint64_t code) const {
      const uint64_t word = code >> 6;
      if (word >= occupied.size()) return -1;
      const uint64_t bits = occupied[word];
      const uint64_t bit = uint64_t{1} << (code & 63);
      if ((bits & bit) == 0) return -1;
      return rank[word] + PopCount(bits & (bit - 1));
    }
    size_t bytes() const {
      return occupied.capacity() * sizeof(uint64_t) + rank.capacity() * sizeof(int32_t);
    }
  };

  // The occupied cells of one block of kBlockCells: a lookup reads one block, and the 8 cells a
  // correspondence search asks for mostly share it (a hash map's 8 lookups are 8 random accesses).
  struct Block {
    std::array<uint64_t, kBlockCells / 64> bits{};
    std::array<uint16_t, kBlockCells / 64> before{};  // occupied cells in the block's words before
    int32_t first = 0;                                // the node of the block's first occupied cell
  };

  // The node at `code`, which lies in `block`, or -1.
  static int32_t FindInBlock(const Block& block, uint64_t code) {
    const uint64_t low = code & (kBlockCells - 1);
    const uint64_t bits = block.bits[low >> 6];
    const uint64_t bit = uint64_t{1} << (low & 63);
    if ((bits & bit) == 0) return -1;
    return block.first + block.before[low >> 6] + PopCount(bits & (bit - 1));
  }

  // The blocked form when it is small enough (kMaxBlockedBytesPerNode); false leaves it empty.
  bool TryBlocks(const std::vector<uint64_t>& codes, uint64_t cells) {
    std::vector<uint64_t> tops;
    for (uint64_t code : codes) {
      if (tops.empty() || tops.back() != code >> kBlockShift) tops.push_back(code >> kBlockShift);
    }
    if (tops.size() * sizeof(Block) > kMaxBlockedBytesPerNode * codes.size()) return false;
    top_.Build(tops, cells >> kBlockShift);
    blocks_.resize(tops.size());
    size_t b = 0;
    for (uint64_t code : codes) {
      if (tops[b] != code >> kBlockShift) ++b;
      const uint64_t low = code & (kBlockCells - 1);
      blocks_[b].bits[low >> 6] |= uint64_t{1} << (low & 63);
    }
    // The ranks: nodes before each block (its first node) and before each of its words.
    int32_t nodes_before = 0;
    for (Block& block : blocks_) {
      block.first = nodes_before;
      uint16_t before = 0;
      for (size_t w = 0; w < block.bits.size(); ++w) {
        block.before[w] = before;
        before = static_cast<uint16_t>(before + PopCount(block.bits[w]));
      }
      nodes_before += before;
    }
    return true;
  }

  Form form_ = Form::kDense;
  RankedBits dense_;                             // kDense
  RankedBits top_;                               // kBlocked: the blocks' cells, three depths up
  std::vector<Block> blocks_;                    // kBlocked: by the rank of their cell in top_
  absl::flat_hash_map<uint64_t, int32_t> hash_;  // kHashed
};

// The edge of a cell of `tree`'s level `depth` (2^depth cells across the cube), in metres.
inline double CellEdge(const Octree& tree, int depth) {
  return 2.0 * tree.half_length() / static_cast<double>(uint64_t{1} << depth);
}

// Where a point q falls on a tree's level of `depth`: its position in cell units (0 at the cube's
// low corner, 2^depth cells per axis), its home cell (clamped to the level and truncated as
// CellOfPoint does, up to rounding at cell faces; a NaN coordinate reads as cell 0, never as an
// undefined cast) and, per axis, the side of that cell's centre it lies on
// (+1 or -1; bit a of side_bits when +1), which picks FindBlock's 2x2x2 block. Shared by the
// refinement's and the polish's correspondence searches, whose cached blocks are keyed on it.
struct BlockHome {
  Eigen::Vector3d position;
  std::array<uint32_t, 3> home;
  std::array<int, 3> side;
  uint8_t side_bits = 0;
};

inline BlockHome LocateBlockHome(const Octree& tree, int depth, const Eigen::Vector3d& q) {
  const double cells = static_cast<double>(uint64_t{1} << depth);
  const double scale = cells / (2.0 * tree.half_length());
  BlockHome at;
  at.position = (q - tree.center()).array() * scale + 0.5 * cells;
  for (int a = 0; a < 3; ++a) {
    // std::clamp for finite values; a NaN fails `>= 0` and goes to 0.
    const double p = at.position[a];
    const double clamped = p >= 0.0 ? std::min(p, cells - 1.0) : 0.0;
    at.home[a] = static_cast<uint32_t>(clamped);
    at.side[a] = (at.position[a] - static_cast<double>(at.home[a]) >= 0.5) ? 1 : -1;
    if (at.side[a] > 0) at.side_bits |= static_cast<uint8_t>(1 << a);
  }
  return at;
}

// The nodes of a block of cells of a level with `cells` per axis, -1 for an empty cell or one
// outside the level, into out[0 .. block): block 27, the 3x3x3 cells around `home` (z, then y,
// then x from -1 to 1); block 8, the 2x2x2 cells nearest to a point in `home` whose offset from
// the cell's centre has the signs `side` (+1 or -1 per axis), which hold every cell within half a
// cell edge of it. The correspondence searches of the refinement and of the noise polish.
inline void FindBlock(const CellIndex& index, const std::array<uint32_t, 3>& home,
                      const std::array<int, 3>& side, int block, int64_t cells, int32_t* out) {
  // The cells' codes (~0, which finds nothing, for one outside the level), then one FindAll.
  auto code = [&](int64_t x, int64_t y, int64_t z) -> uint64_t {
    if (x < 0 || y < 0 || z < 0 || x >= cells || y >= cells || z >= cells) return ~uint64_t{0};
    return EncodeMorton<3>(
        {static_cast<uint32_t>(x), static_cast<uint32_t>(y), static_cast<uint32_t>(z)});
  };
  std::array<uint64_t, 27> codes;
  int slot = 0;
  if (block == 27) {
    for (int dz = -1; dz <= 1; ++dz) {
      for (int dy = -1; dy <= 1; ++dy) {
        for (int dx = -1; dx <= 1; ++dx) {
          codes[slot++] = code(int64_t{home[0]} + dx, int64_t{home[1]} + dy, int64_t{home[2]} + dz);
        }
      }
    }
  } else {
    for (int b = 0; b < 8; ++b) {
      codes[slot++] = code(int64_t{home[0]} + ((b & 1) ? side[0] : 0),
                           int64_t{home[1]} + ((b & 2) ? side[1] : 0),
                           int64_t{home[2]} + ((b & 4) ? side[2] : 0));
    }
  }
  index.FindAll(codes.data(), slot, out);
}

}  // namespace rpsr::core

#endif  // RPSR_CORE_REFINE_CELL_INDEX_H_
