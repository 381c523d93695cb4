// Immutable bytes named by their SHA-256 (uploads, level sets, single levels). Two
// implementations: DirectoryBlobStore (server/directory_blob_store.h: a local or shared
// directory, the default) and RedisBlobStore (server/redis_store.h: blobs up to a size
// cap in Redis). Reads check the hash: a corrupted blob reads as kDataLoss, never as
// wrong bytes. Every method is thread-safe.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "base/status.h"
#include "io/sha256.h"

namespace motionlod::server {

class BlobStore {
 public:
  virtual ~BlobStore() = default;

  // Stores `bytes` and returns their SHA-256 hex. Idempotent: storing present bytes again
  // is a no-op.
  StatusOr<std::string> Put(std::string_view bytes) {
    std::string hash = io::Sha256Hex(bytes);
    if (Status status = PutWithHash(hash, bytes); !status.ok()) return status;
    return hash;
  }
  // The same when the caller already knows the hash (which must be that of `bytes`).
  virtual Status PutWithHash(std::string_view hash, std::string_view bytes) = 0;

  // kNotFound when absent, kDataLoss when the bytes no longer match their hash,
  // kInvalidArgument for a malformed id.
  virtual StatusOr<std::string> Get(std::string_view hash) const = 0;
  virtual bool Contains(std::string_view hash) const = 0;
  // Removes the blob (absent is fine).
  virtual Status Remove(std::string_view hash) = 0;

  // Unavailable (naming no path) when a blob cannot be written now, or fewer than
  // `min_free_bytes` are free: what /readyz reports.
  virtual Status CheckWritable(int64_t min_free_bytes) const = 0;

  // Every stored hash (for garbage collection at start).
  virtual std::vector<std::string> List() const = 0;
};

}  // namespace motionlod::server
