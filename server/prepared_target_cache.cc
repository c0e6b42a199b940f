#include "server/prepared_target_cache.h"

#include <utility>

namespace rpsr::server {

PreparedTargetCache::PreparedTargetCache(std::shared_ptr<const core::Registrar> registrar,
                                         size_t capacity)
    : registrar_(std::move(registrar)), capacity_(capacity) {}

std::shared_ptr<const core::PreparedTarget> PreparedTargetCache::Get(
    const std::shared_ptr<const core::Octree>& tree, bool* hit) {
  if (hit != nullptr) *hit = false;
  if (tree == nullptr || capacity_ == 0) return nullptr;
  const core::Octree* key = tree.get();
  {
    std::lock_guard<std::mutex> lock(mu_);
    auto it = entries_.find(key);
    if (it != entries_.end()) {
      // Same address, same tree only while the cached weak pointer still owns it.
      if (it->second.tree.lock() == tree) {
        ++hits_;
        if (hit != nullptr) *hit = true;
        recency_.splice(recency_.begin(), recency_, it->second.recency);
        return it->second.prepared;
      }
      recency_.erase(it->second.recency);
      entries_.erase(it);
    }
    ++misses_;
  }
  // Prepared outside the lock: the encoding takes milliseconds and other workers go on.
  absl::StatusOr<std::shared_ptr<const core::PreparedTarget>> prepared =
      registrar_->PrepareTarget(*tree);
  if (!prepared.ok()) return nullptr;
  std::lock_guard<std::mutex> lock(mu_);
  auto it = entries_.find(key);
  if (it != entries_.end() && it->second.tree.lock() == tree) return it->second.prepared;
  if (it != entries_.end()) {
    recency_.erase(it->second.recency);
    entries_.erase(it);
  }
  while (entries_.size() >= capacity_ && !recency_.empty()) {
    entries_.erase(recency_.back());
    recency_.pop_back();
  }
  recency_.push_front(key);
  entries_[key] = Entry{tree, *prepared, recency_.begin()};
  return *std::move(prepared);
}

size_t PreparedTargetCache::size() const {
  std::lock_guard<std::mutex> lock(mu_);
  return entries_.size();
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
