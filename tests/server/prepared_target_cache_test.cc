// PreparedTargetCache: a tree's prepared target is made once and served again, the least recently
// used goes beyond the capacity, a tree is held only weakly (a cloud evicted from the session
// store is not kept alive, and a new tree is never served another's encoding), and trees the
// network cannot read give no entry.
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

std::shared_ptr<const core::Registrar> SharedRegistrar() {
  static const auto* registrar = [] {
    auto created = core::Registrar::Create();
    EXPECT_TRUE(created.ok()) << created.status();
    return new std::shared_ptr<const core::Registrar>(*std::move(created));
  }();
  return *registrar;
}

TEST(PreparedTargetCacheTest, PreparesOnceAndServesAgain) {
  PreparedTargetCache cache(SharedRegistrar(), 4);
  const auto tree = ObjectTree(1);
  bool hit = true;
  const auto first = cache.Get(tree, &hit);
  ASSERT_NE(first, nullptr);
  EXPECT_FALSE(hit);
  EXPECT_EQ(&first->tree(), tree.get());
  EXPECT_EQ(cache.Get(tree, &hit), first);
  EXPECT_TRUE(hit);
  EXPECT_EQ(cache.hits(), 1u);
  EXPECT_EQ(cache.misses(), 1u);
  EXPECT_EQ(cache.size(), 1u);
}

TEST(PreparedTargetCacheTest, LeastRecentlyUsedGoesBeyondTheCapacity) {
  PreparedTargetCache cache(SharedRegistrar(), 2);
  const auto a = ObjectTree(1), b = ObjectTree(2), c = ObjectTree(3);
  const auto prepared_a = cache.Get(a);
  cache.Get(b);
  EXPECT_EQ(cache.Get(a), prepared_a);  // a is now the most recent: b goes next
  cache.Get(c);
  EXPECT_EQ(cache.size(), 2u);
  EXPECT_EQ(cache.Get(a), prepared_a);
  const uint64_t misses = cache.misses();
  cache.Get(b);
  EXPECT_EQ(cache.misses(), misses + 1);  // b had gone
}

TEST(PreparedTargetCacheTest, HoldsTreesOnlyWeakly) {
  PreparedTargetCache cache(SharedRegistrar(), 4);
  auto tree = ObjectTree(1);
  const std::weak_ptr<const core::Octree> watch = tree;
  ASSERT_NE(cache.Get(tree), nullptr);
  tree.reset();
  EXPECT_TRUE(watch.expired()) << "the cache kept an evicted cloud's tree alive";
  // Whatever address the next tree gets, it is prepared for itself.
  const auto next = ObjectTree(2);
  const auto prepared = cache.Get(next);
  ASSERT_NE(prepared, nullptr);
  EXPECT_EQ(&prepared->tree(), next.get());
}

TEST(PreparedTargetCacheTest, TreesTheNetworkCannotReadGiveNothing) {
  PreparedTargetCache cache(SharedRegistrar(), 4);
  EXPECT_EQ(cache.Get(nullptr), nullptr);
  EXPECT_EQ(cache.Get(ObjectTree(1, /*max_depth=*/4)), nullptr);
  EXPECT_EQ(cache.size(), 0u);
}

}  // namespace
}  // namespace rpsr::server
