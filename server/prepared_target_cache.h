// The targets the service prepared (core::Registrar::PrepareTarget), kept for the next pairs
// against the same cached cloud: a client registering many scans against one reference pays the
// target's share once (registrar_bench, interleaved: objects net+refine 14.7 -> 11.6 ms a pair;
// LiDAR refine 12.4 -> 11.1). Bounded by a count and by bytes (BatchingOptions::prepared_targets,
// prepared_target_bytes; rpsrd --prepared_targets, --prepared_target_bytes), least recently used
// out; keyed by the tree, holding it only weakly: a cloud evicted or released from the session
// store is not kept alive here, and a new tree at a freed one's address is never served the old
// preparation (the weak pointer has expired). Mode refine needs only the refinement's side
// (~200 KB for an object, ~750 KB for a 120k-point scan to depth 9), the network's modes the
// network's encoding too (~100 KB more): an entry made for refine is prepared again, fully, when
// a network mode asks for it (and kept if that fails: a tree the network cannot read).
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
  // `capacity`: prepared targets kept at most; `max_bytes`: their memory at most
  // (PreparedTarget::bytes). Either 0: none kept.
  PreparedTargetCache(std::shared_ptr<const core::Registrar> registrar, size_t capacity,
                      size_t max_bytes);

  // The prepared target of `tree` (with the network's encoding when `for_network`), prepared now
  // on a miss; null when it cannot be prepared (the registrar then reports the tree's problem
  // itself) or is larger than the whole budget. Thread-safe; two threads missing at once may both
  // prepare, and the first kept wins. `hit` (optional) says whether it was kept from before.
  std::shared_ptr<const core::PreparedTarget> Get(const std::shared_ptr<const core::Octree>& tree,
                                                  bool for_network, bool* hit = nullptr);

  size_t size() const;
  size_t bytes() const;
  uint64_t hits() const;
  uint64_t misses() const;

 private:
  struct Entry {
    std::weak_ptr<const core::Octree> tree;
    std::shared_ptr<const core::PreparedTarget> prepared;
    std::list<const core::Octree*>::iterator recency;
  };

  // Drops the least recently used entries until `incoming` more bytes and one more entry fit.
  void MakeRoomLocked(size_t incoming);
  void EraseLocked(const core::Octree* key);

  const std::shared_ptr<const core::Registrar> registrar_;
  const size_t capacity_;
  const size_t max_bytes_;
  mutable std::mutex mu_;
  std::unordered_map<const core::Octree*, Entry> entries_;  // guarded by mu_
  std::list<const core::Octree*> recency_;                  // most recent first; guarded by mu_
  size_t bytes_ = 0;                                        // guarded by mu_
  uint64_t hits_ = 0;                                       // guarded by mu_
  uint64_t misses_ = 0;                                     // guarded by mu_
};

}  // namespace rpsr::server

#endif  // RPSR_SERVER_PREPARED_TARGET_CACHE_H_
