// CellIndex: the refinement's Morton code -> node lookup gives the same answers in its dense
// (rank bitset), blocked (rank bitsets of the occupied 8^3-cell blocks) and hashed forms, on real
// tree levels and at the edges of the code range.
#include "core/refine/cell_index.h"

#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <random>
#include <vector>

#include "core/data/object_pairs.h"
#include "core/synth/lidar_sequence.h"
#include "core/tree/bh_tree.h"
#include "core/tree/morton.h"
#include "gtest/gtest.h"

namespace rpsr::core {
namespace {

// Every code of the level finds its node; every other code of a sample (and the codes around
// each occupied one) finds nothing.
void ExpectIndexes(const CellIndex& index, const std::vector<uint64_t>& codes, int depth) {
  const uint64_t cells = uint64_t{1} << (3 * depth);
  for (size_t j = 0; j < codes.size(); ++j) {
    ASSERT_EQ(index.Find(codes[j]), static_cast<int32_t>(j)) << "code " << codes[j];
  }
  std::mt19937_64 rng(depth);
  std::vector<uint64_t> probes = {0, cells - 1, cells, cells + 64, ~uint64_t{0}};
  for (uint64_t code : codes) {
    probes.push_back(code + 1);
    if (code > 0) probes.push_back(code - 1);
  }
  for (int i = 0; i < 2000; ++i) probes.push_back(rng() % cells);
  for (uint64_t probe : probes) {
    const auto it = std::lower_bound(codes.begin(), codes.end(), probe);
    const int32_t expected =
        (it != codes.end() && *it == probe) ? static_cast<int32_t>(it - codes.begin()) : -1;
    ASSERT_EQ(index.Find(probe), expected) << "probe " << probe;
  }
}

TEST(CellIndexTest, EveryDepthOfAnObjectTreeFindsItsNodesDenseOrHashed) {
  PairOptions pair_options;
  pair_options.num_points = 2048;
  auto pair = MakeObjectPair(pair_options, /*seed=*/3);
  ASSERT_TRUE(pair.ok()) << pair.status();
  BarnesHutTreeOptions options;
  options.max_depth = 8;
  auto tree = BuildOctree(pair->target, options);
  ASSERT_TRUE(tree.ok()) << tree.status();
  int dense = 0, hashed = 0;
  for (int depth = 0; depth <= tree->max_depth(); ++depth) {
    const std::vector<uint64_t>& codes = tree->level(depth).morton;
    const CellIndex index(codes, depth);
    // 2,048 points: dense through depth 6 (at most 2^18 cells); depths 7 and 8 (2.1M and 16.7M
    // cells for ~2,000 nodes, far more than 64 a node) are hashed.
    if (index.dense())
      ++dense;
    else
      ++hashed;
    SCOPED_TRACE(testing::Message() << "depth " << depth << (index.dense() ? " dense" : " hashed"));
    ExpectIndexes(index, codes, depth);
  }
  EXPECT_EQ(dense, 7);
  // Depths 7 and 8 of a 2,048-point object hold about one node per block: hashed.
  EXPECT_EQ(hashed, 2);
  EXPECT_FALSE(CellIndex(tree->level(8).morton, 8).dense());
  EXPECT_TRUE(CellIndex(tree->level(6).morton, 6).dense());
}

TEST(CellIndexTest, AScansDeepLevelsAreBlocked) {
  LidarSequenceOptions options;
  options.frame_count = 1;
  auto sequence = LidarSequenceSimulator::Create(options);
  ASSERT_TRUE(sequence.ok()) << sequence.status();
  BarnesHutTreeOptions tree_options;
  tree_options.max_depth = 9;  // the CLI's depth for scenes
  tree_options.neighbor_max_depth = -1;
  auto tree = BuildOctree(sequence->SimulateFrame(0).cloud, tree_options);
  ASSERT_TRUE(tree.ok()) << tree.status();
  for (int depth = 0; depth <= 9; ++depth) {
    const std::vector<uint64_t>& codes = tree->level(depth).morton;
    const CellIndex index(codes, depth);
    SCOPED_TRACE(testing::Message() << "depth " << depth << ", " << codes.size() << " nodes");
    // Depths 0-6 fit 2^18 cells; a street's surfaces fill its 8^3-cell blocks of depths 7-9 well
    // enough for blocks of 88 bytes to cost less than a hash map.
    EXPECT_EQ(index.form(), depth <= 6 ? CellIndex::Form::kDense : CellIndex::Form::kBlocked);
    ExpectIndexes(index, codes, depth);
    if (depth >= 7) {
      size_t blocks = 0;
      for (size_t j = 0; j < codes.size(); ++j)
        blocks += j == 0 || codes[j] >> 9 != codes[j - 1] >> 9;
      std::printf("depth %d: %zu nodes in %zu blocks of 8^3 cells, %.1f a block; index %zu bytes\n",
                  depth, codes.size(), blocks, static_cast<double>(codes.size()) / blocks,
                  index.bytes());
    }
  }
}

TEST(CellIndexTest, BlockedAndHashedFormsAnswerAlikeAtTheBlocksEdges) {
  // Depth 9, every node in one of a few blocks, filling each block's first and last cells and
  // its word boundaries (the ranks carried between words and between blocks).
  std::vector<uint64_t> codes;
  for (uint64_t block : {0ull, 1ull, 4095ull, 262143ull}) {
    for (uint64_t low : {0ull, 1ull, 62ull, 63ull, 64ull, 127ull, 128ull, 300ull, 448ull, 511ull}) {
      codes.push_back(block * 512 + low);
    }
  }
  const CellIndex blocked(codes, 9);
  EXPECT_EQ(blocked.form(), CellIndex::Form::kBlocked);
  ExpectIndexes(blocked, codes, 9);
  // One node a block costs 88 bytes a node there: hashed, the same answers.
  std::vector<uint64_t> scattered;
  for (uint64_t block = 0; block < 262144; block += 97) scattered.push_back(block * 512 + 17);
  const CellIndex hashed(scattered, 9);
  EXPECT_EQ(hashed.form(), CellIndex::Form::kHashed);
  ExpectIndexes(hashed, scattered, 9);
  EXPECT_LT(blocked.bytes(), hashed.bytes());
  // Deeper than 9, the blocks' own index would pass 2^18 cells: hashed.
  std::vector<uint64_t> deep;
  for (uint64_t c = 0; c < 4096; ++c) deep.push_back((uint64_t{1} << 30) + c);
  EXPECT_EQ(CellIndex(deep, 10).form(), CellIndex::Form::kHashed);
  ExpectIndexes(CellIndex(deep, 10), deep, 10);
}

TEST(CellIndexTest, ADeepLevelWithAtMost64CellsANodeIsDense) {
  // Depth 7 (2^21 cells) with every 64th cell occupied: 32,768 nodes, exactly 64 cells a node.
  std::vector<uint64_t> every_64th;
  for (uint64_t c = 5; c < (uint64_t{1} << 21); c += 64) every_64th.push_back(c);
  const CellIndex dense(every_64th, 7);
  EXPECT_TRUE(dense.dense());
  ExpectIndexes(dense, every_64th, 7);
  // One node fewer: more than 64 cells a node, hashed, the same answers.
  every_64th.pop_back();
  const CellIndex hashed(every_64th, 7);
  EXPECT_FALSE(hashed.dense());
  ExpectIndexes(hashed, every_64th, 7);
}

TEST(CellIndexTest, FullAndEmptyLevels) {
  // Every cell of depth 2 occupied: the last word's ranks reach 63.
  std::vector<uint64_t> all(64);
  for (uint64_t c = 0; c < 64; ++c) all[c] = c;
  const CellIndex full(all, 2);
  ASSERT_TRUE(full.dense());
  ExpectIndexes(full, all, 2);
  const CellIndex empty(std::vector<uint64_t>{}, 3);
  EXPECT_EQ(empty.Find(0), -1);
  EXPECT_EQ(empty.Find(511), -1);
  // A sparse deep level (three nodes in three blocks) is hashed and answers the same way.
  const std::vector<uint64_t> sparse = {EncodeMorton<3>({1, 2, 3}), EncodeMorton<3>({500, 7, 9}),
                                        EncodeMorton<3>({511, 511, 511})};
  std::vector<uint64_t> sorted = sparse;
  std::sort(sorted.begin(), sorted.end());
  const CellIndex deep(sorted, 9);
  EXPECT_FALSE(deep.dense());
  ExpectIndexes(deep, sorted, 9);
  EXPECT_GT(deep.bytes(), sizeof(CellIndex));
}

}  // namespace
}  // namespace rpsr::core
