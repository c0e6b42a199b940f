// PreparedTargetCache: a tree's prepared target is made once and served again, the least recently
// used goes beyond the capacity or the byte budget, a tree is held only weakly (a cloud evicted
// from the session store is not kept alive, and a new tree is never served another's encoding),
// an entry prepared for refine is prepared again for the network, and trees the network cannot
// read give no entry for it.
#include "server/prepared_target_cache.h"

#include <memory>
#include <vector>

#include "core/data/object_pairs.h"
#include "core/registrar/registrar.h"
#include "gtest/gtest.h"

namespace rpsr::server {
namespace {

std::shared_ptr<const core::Octree> ObjectTree(uint64_t seed, int max_depth = 6) {
  auto pair = core::MakeObjectPair(core::PairOptions{}, seed);
  EXPECT_TRUE(pair.ok()) << pair.status();
  core::BarnesHutTreeOptions options;
  options.max_depth = max_depth;
  auto tree = core::BuildOctree(pair->target, options);
  EXPECT_TRUE(tree.ok()) << tree.status();
  return std::make_shared<const core::Octree>(*std::move(tree));
}

constexpr size_t kPlenty = size_t{1} << 30;

std::shared_ptr<const core::Registrar> SharedRegistrar() {
  static const auto* registrar = [] {
    auto created = core::Registrar::Create();
    EXPECT_TRUE(created.ok()) << created.status();
    return new std::shared_ptr<const core::Registrar>(*std::move(created));
  }();
  return *registrar;
}

TEST(PreparedTargetCacheTest, PreparesOnceAndServesAgain) {
  PreparedTargetCache cache(SharedRegistrar(), 4, kPlenty);
  const auto tree = ObjectTree(1);
  bool hit = true;
  const auto first = cache.Get(tree, /*for_network=*/true, &hit);
  ASSERT_NE(first, nullptr);
  EXPECT_FALSE(hit);
  EXPECT_EQ(&first->tree(), tree.get());
  EXPECT_EQ(cache.Get(tree, /*for_network=*/true, &hit), first);
  EXPECT_TRUE(hit);
  EXPECT_EQ(cache.hits(), 1u);
  EXPECT_EQ(cache.misses(), 1u);
  EXPECT_EQ(cache.size(), 1u);
}

TEST(PreparedTargetCacheTest, LeastRecentlyUsedGoesBeyondTheCapacity) {
  PreparedTargetCache cache(SharedRegistrar(), 2, kPlenty);
  const auto a = ObjectTree(1), b = ObjectTree(2), c = ObjectTree(3);
  const auto prepared_a = cache.Get(a, /*for_network=*/true);
  cache.Get(b, /*for_network=*/true);
  EXPECT_EQ(cache.Get(a, /*for_network=*/true),
            prepared_a);  // a is now the most recent: b goes next
  cache.Get(c, /*for_network=*/true);
  EXPECT_EQ(cache.size(), 2u);
  EXPECT_EQ(cache.Get(a, /*for_network=*/true), prepared_a);
  const uint64_t misses = cache.misses();
  cache.Get(b, /*for_network=*/true);
  EXPECT_EQ(cache.misses(), misses + 1);  // b had gone
}

TEST(PreparedTargetCacheTest, HoldsTreesOnlyWeakly) {
  PreparedTargetCache cache(SharedRegistrar(), 4, kPlenty);
  auto tree = ObjectTree(1);
  const std::weak_ptr<const core::Octree> watch = tree;
  ASSERT_NE(cache.Get(tree, /*for_network=*/true), nullptr);
  tree.reset();
  EXPECT_TRUE(watch.expired()) << "the cache kept an evicted cloud's tree alive";
  // Whatever address the next tree gets, it is prepared for itself.
  const auto next = ObjectTree(2);
  const auto prepared = cache.Get(next, /*for_network=*/true);
  ASSERT_NE(prepared, nullptr);
  EXPECT_EQ(&prepared->tree(), next.get());
}

TEST(PreparedTargetCacheTest, TreesTheNetworkCannotReadGiveNothingForIt) {
  PreparedTargetCache cache(SharedRegistrar(), 4, kPlenty);
  EXPECT_EQ(cache.Get(nullptr, /*for_network=*/true), nullptr);
  const auto shallow = ObjectTree(1, /*max_depth=*/4);
  EXPECT_EQ(cache.Get(shallow, /*for_network=*/true), nullptr);
  EXPECT_EQ(cache.size(), 0u);
  // The refinement reads it; a network mode asking again keeps that entry (no churn).
  const auto for_refine = cache.Get(shallow, /*for_network=*/false);
  EXPECT_NE(for_refine, nullptr);
  EXPECT_EQ(cache.size(), 1u);
  EXPECT_EQ(cache.Get(shallow, /*for_network=*/true), nullptr);
  bool hit = false;
  EXPECT_EQ(cache.Get(shallow, /*for_network=*/false, &hit), for_refine);
  EXPECT_TRUE(hit);
}

// Mode refine's entries hold the refinement's side only; a network mode on the same tree
// prepares it again, fully, and that entry then serves both.
TEST(PreparedTargetCacheTest, RefineOnlyEntryIsPreparedAgainForTheNetwork) {
  PreparedTargetCache cache(SharedRegistrar(), 4, kPlenty);
  const auto tree = ObjectTree(1);
  bool hit = true;
  const auto for_refine = cache.Get(tree, /*for_network=*/false, &hit);
  ASSERT_NE(for_refine, nullptr);
  EXPECT_FALSE(hit);
  EXPECT_FALSE(for_refine->has_net_encoding());
  EXPECT_EQ(cache.bytes(), for_refine->bytes());
  const auto full = cache.Get(tree, /*for_network=*/true, &hit);
  ASSERT_NE(full, nullptr);
  EXPECT_FALSE(hit);
  EXPECT_TRUE(full->has_net_encoding());
  EXPECT_EQ(cache.Get(tree, /*for_network=*/false, &hit), full);
  EXPECT_TRUE(hit);
  EXPECT_EQ(cache.size(), 1u);
  EXPECT_EQ(cache.bytes(), full->bytes());
}

// The byte budget bounds what is kept whatever the count allows; an entry larger than the whole
// budget is handed out once and not kept.
TEST(PreparedTargetCacheTest, ByteBudgetEvictsTheLeastRecentlyUsed) {
  const auto a = ObjectTree(1), b = ObjectTree(2), c = ObjectTree(3);
  PreparedTargetCache probe(SharedRegistrar(), 4, kPlenty);
  const size_t one = probe.Get(a, /*for_network=*/true)->bytes();
  ASSERT_GT(one, 10000u);
  PreparedTargetCache cache(SharedRegistrar(), 100, 2 * one + one / 2);  // room for two
  cache.Get(a, /*for_network=*/true);
  cache.Get(b, /*for_network=*/true);
  cache.Get(c, /*for_network=*/true);
  EXPECT_EQ(cache.size(), 2u);
  EXPECT_LE(cache.bytes(), 2 * one + one / 2);
  bool hit = true;
  cache.Get(a, /*for_network=*/true, &hit);
  EXPECT_FALSE(hit) << "a was the least recently used";

  PreparedTargetCache tiny(SharedRegistrar(), 100, one / 2);
  EXPECT_NE(tiny.Get(a, /*for_network=*/true), nullptr);
  EXPECT_EQ(tiny.size(), 0u);
  EXPECT_EQ(tiny.bytes(), 0u);
}

}  // namespace
}  // namespace rpsr::server
