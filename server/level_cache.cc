#include "server/level_cache.h"

namespace motionlod::server {

LevelCache::Bytes LevelCache::Get(const std::string& key) {
  std::lock_guard lock(mutex_);
  const auto found = index_.find(key);
  if (found == index_.end()) {
    ++misses_;
    return nullptr;
  }
  ++hits_;
  // A hot level is usually at the front already.
  if (found->second != lru_.begin()) lru_.splice(lru_.begin(), lru_, found->second);
  return found->second->bytes;
}

void LevelCache::Put(const std::string& key, Bytes bytes) {
  if (bytes == nullptr) return;
  const int64_t size = static_cast<int64_t>(bytes->size());
  std::lock_guard lock(mutex_);
  if (const auto found = index_.find(key); found != index_.end()) {
    bytes_ -= static_cast<int64_t>(found->second->bytes->size());
    lru_.erase(found->second);
    index_.erase(found);
  }
  if (size > capacity_) return;
  lru_.push_front({key, std::move(bytes)});
  index_.emplace(key, lru_.begin());
  bytes_ += size;
  EvictLocked();
}

void LevelCache::Erase(const std::string& key) {
  std::lock_guard lock(mutex_);
  const auto found = index_.find(key);
  if (found == index_.end()) return;
  bytes_ -= static_cast<int64_t>(found->second->bytes->size());
  lru_.erase(found->second);
  index_.erase(found);
}

void LevelCache::EvictLocked() {
  while (bytes_ > capacity_ && !lru_.empty()) {
    const Entry& last = lru_.back();
    bytes_ -= static_cast<int64_t>(last.bytes->size());
    index_.erase(last.key);
    lru_.pop_back();
    ++evictions_;
  }
}

LevelCache::Stats LevelCache::stats() const {
  std::lock_guard lock(mutex_);
  return {hits_, misses_, evictions_, bytes_, static_cast<int64_t>(index_.size()), capacity_};
}

}  // namespace motionlod::server
