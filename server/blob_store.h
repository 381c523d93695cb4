// A content-addressed directory of immutable files: <root>/sha256/ab/cdef... holds the
// bytes whose SHA-256 is abcdef.... Writes are atomic (a temporary file in the same
// directory, fsync, rename, fsync of the directory), so a reader never sees a partial
// file and a crash leaves either nothing or the whole blob. Reads check the hash: a
// corrupted blob reads as kDataLoss, never as wrong bytes. Paths are only ever built
// from validated ids (^[0-9a-f]{64}$), never from user text. Thread-safe.
#pragma once

#include <filesystem>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "base/status.h"

namespace motionlod::server {

class BlobStore {
 public:
  // Creates <root>/sha256 when missing and removes temporary files a crash left behind.
  static StatusOr<std::unique_ptr<BlobStore>> Open(const std::filesystem::path& root);

  // Stores `bytes` and returns their SHA-256 hex. Idempotent: storing present bytes again
  // is a no-op.
  StatusOr<std::string> Put(std::string_view bytes);
  // The same when the caller already knows the hash (checked in debug builds).
  Status PutWithHash(std::string_view hash, std::string_view bytes);

  // kNotFound when absent, kDataLoss when the bytes no longer match their hash,
  // kInvalidArgument for a malformed id.
  StatusOr<std::string> Get(std::string_view hash) const;
  bool Contains(std::string_view hash) const;
  // Removes the blob (absent is fine).
  Status Remove(std::string_view hash);

  // Unavailable (naming no path) when a file cannot be created under the root now, or
  // the file system has less than `min_free_bytes` free: what /readyz reports.
  Status CheckWritable(int64_t min_free_bytes) const;

  // Every stored hash (for garbage collection at start).
  std::vector<std::string> List() const;

  const std::filesystem::path& root() const { return root_; }

 private:
  explicit BlobStore(std::filesystem::path root) : root_(std::move(root)) {}
  std::filesystem::path PathOf(std::string_view hash) const;

  std::filesystem::path root_;  // <data>/blobs
};

}  // namespace motionlod::server
