#include "server/prepared_target_cache.h"

#include <utility>

namespace rpsr::server {

PreparedTargetCache::PreparedTargetCache(std::shared_ptr<const core::Registrar> registrar,
                                         size_t capacity, size_t max_bytes)
    : registrar_(std::move(registrar)), capacity_(capacity), max_bytes_(max_bytes) {}

void PreparedTargetCache::EraseLocked(const core::Octree* key) {
  auto it = entries_.find(key);
  if (it == entries_.end()) return;
  bytes_ -= it->second.prepared->bytes();
  recency_.erase(it->second.recency);
  entries_.erase(it);
}

void PreparedTargetCache::MakeRoomLocked(size_t incoming) {
  while (!recency_.empty() && (entries_.size() + 1 > capacity_ || bytes_ + incoming > max_bytes_)) {
    EraseLocked(recency_.back());
  }
}

std::shared_ptr<const core::PreparedTarget> PreparedTargetCache::Get(
    const std::shared_ptr<const core::Octree>& tree, bool for_network, bool* hit) {
  if (hit != nullptr) *hit = false;
  if (tree == nullptr || capacity_ == 0 || max_bytes_ == 0) return nullptr;
  const core::Octree* key = tree.get();
  // Whether a kept entry serves this request: the same tree (same address is the same tree only
  // while the weak pointer still owns it) prepared for as much as is needed.
  auto serves = [&](const Entry& entry) {
    return entry.tree.lock() == tree && (!for_network || entry.prepared->has_net_encoding());
  };
  {
    std::lock_guard<std::mutex> lock(mu_);
    auto it = entries_.find(key);
    if (it != entries_.end()) {
      if (serves(it->second)) {
        ++hits_;
        if (hit != nullptr) *hit = true;
        recency_.splice(recency_.begin(), recency_, it->second.recency);
        return it->second.prepared;
      }
      // Another tree at a freed address goes now; an entry prepared for refine only stays until
      // its full replacement is made (a tree the network cannot read keeps it).
      if (it->second.tree.lock() != tree) EraseLocked(key);
    }
    ++misses_;
  }
  // Prepared outside the lock: it takes milliseconds and other workers go on.
  absl::StatusOr<std::shared_ptr<const core::PreparedTarget>> prepared =
      registrar_->PrepareTarget(*tree, for_network);
  if (!prepared.ok()) return nullptr;
  const size_t size = (*prepared)->bytes();
  std::lock_guard<std::mutex> lock(mu_);
  auto it = entries_.find(key);
  if (it != entries_.end() && serves(it->second)) return it->second.prepared;
  EraseLocked(key);
  if (size > max_bytes_) return *std::move(prepared);  // used once, never kept
  MakeRoomLocked(size);
  recency_.push_front(key);
  entries_[key] = Entry{tree, *prepared, recency_.begin()};
  bytes_ += size;
  return *std::move(prepared);
}

size_t PreparedTargetCache::size() const {
  std::lock_guard<std::mutex> lock(mu_);
  return entries_.size();
}

size_t PreparedTargetCache::bytes() const {
  std::lock_guard<std::mutex> lock(mu_);
  return bytes_;
}

uint64_t PreparedTargetCache::hits() const {
  std::lock_guard<std::mutex> lock(mu_);
  return hits_;
}

uint64_t PreparedTargetCache::misses() const {
  std::lock_guard<std::mutex> lock(mu_);
  return misses_;
}

}  // namespace rpsr::server
