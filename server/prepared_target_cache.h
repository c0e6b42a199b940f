// The targets the service prepared (core::Registrar::PrepareTarget), kept for the next pairs
// against the same cached cloud: a client registering many scans against one reference pays the
// target's network encoding once (objects, net+refine: 14.2 -> 11.7 ms a pair in
// registrar_bench). Bounded (BatchingOptions::prepared_targets, rpsrd --prepared_targets) (least
// recently used out), keyed by the tree, holding it only weakly: a cloud evicted or released from
// the session store is not kept alive here, and a new tree at a freed one's address is never served
// the old encoding (the weak pointer has expired).
#ifndef RPSR_SERVER_PREPARED_TARGET_CACHE_H_
#define RPSR_SERVER_PREPARED_TARGET_CACHE_H_

#include <cstdint>
#include <list>
#include <memory>
#include <mutex>
#include <unordered_map>

#include "core/registrar/registrar.h"
#include "core/tree/bh_tree.h"

namespace rpsr::server {

class PreparedTargetCache {
 public:
  // `capacity`: prepared targets kept (~100 KB each: 64 tokens x the embedding, three times).
  PreparedTargetCache(std::shared_ptr<const core::Registrar> registrar, size_t capacity);

  // The prepared target of `tree`, prepared now on a miss; null when it cannot be prepared (the
  // registrar then reports the tree's problem itself). Thread-safe; two threads missing at once
  // may both prepare, and the first kept wins.
  // `hit` (optional) says whether it was kept from before.
  std::shared_ptr<const core::PreparedTarget> Get(const std::shared_ptr<const core::Octree>& tree,
                                                  bool* hit = nullptr);

  size_t size() const;
  uint64_t hits() const;
  uint64_t misses() const;

 private:
  struct Entry {
    std::weak_ptr<const core::Octree> tree;
    std::shared_ptr<const core::PreparedTarget> prepared;
    std::list<const core::Octree*>::iterator recency;
  };

  const std::shared_ptr<const core::Registrar> registrar_;
  const size_t capacity_;
  mutable std::mutex mu_;
  std::unordered_map<const core::Octree*, Entry> entries_;  // guarded by mu_
  std::list<const core::Octree*> recency_;                  // most recent first; guarded by mu_
  uint64_t hits_ = 0;                                       // guarded by mu_
  uint64_t misses_ = 0;                                     // guarded by mu_
};

}  // namespace rpsr::server

#endif  // RPSR_SERVER_PREPARED_TARGET_CACHE_H_
