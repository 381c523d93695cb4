// A memory cache of level files with a byte budget, least recently used first out.
// Values are immutable and shared: a response keeps its bytes alive after eviction.
// Thread-safe (one mutex; the critical sections are a hash lookup and a list splice).
#pragma once

#include <cstdint>
#include <list>
#include <memory>
#include <mutex>
#include <string>
#include <string_view>
#include <unordered_map>

namespace motionlod::server {

class LevelCache {
 public:
  using Bytes = std::shared_ptr<const std::string>;

  explicit LevelCache(int64_t capacity_bytes) : capacity_(capacity_bytes) {}

  // The bytes under `key`, or null (counted as a hit or a miss).
  Bytes Get(const std::string& key);
  // Inserts or refreshes; a value larger than the whole budget is not kept.
  void Put(const std::string& key, Bytes bytes);
  void Erase(const std::string& key);

  struct Stats {
    uint64_t hits = 0, misses = 0, evictions = 0;
    int64_t bytes = 0, entries = 0, capacity = 0;
  };
  Stats stats() const;

 private:
  struct Entry {
    std::string key;
    Bytes bytes;
  };
  void EvictLocked();

  const int64_t capacity_;
  mutable std::mutex mutex_;
  std::list<Entry> lru_;  // front: most recently used
  std::unordered_map<std::string, std::list<Entry>::iterator> index_;
  int64_t bytes_ = 0;
  uint64_t hits_ = 0, misses_ = 0, evictions_ = 0;
};

}  // namespace motionlod::server
