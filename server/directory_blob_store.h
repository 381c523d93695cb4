// The BlobStore in a directory: <root>/sha256/ab/cdef... holds the bytes whose SHA-256 is
// abcdef.... Writes are atomic (a temporary file in the same directory, fsync, rename,
// fsync of the directory), so a reader never sees a partial file and a crash leaves
// either nothing or the whole blob; several daemons may share the directory (NFS, a
// volume), since equal names mean equal bytes. Paths are only ever built from validated
// ids (^[0-9a-f]{64}$), never from user text.
#pragma once

#include <filesystem>
#include <memory>

#include "server/blob_store.h"

namespace motionlod::server {

class DirectoryBlobStore final : public BlobStore {
 public:
  // Creates <root>/sha256 when missing and removes temporary files a crash left behind.
  // `shared`: other daemons write to the directory too.
  static StatusOr<std::unique_ptr<DirectoryBlobStore>> Open(const std::filesystem::path& root,
                                                            bool shared);

  Status PutWithHash(std::string_view hash, std::string_view bytes) override;
  StatusOr<std::string> Get(std::string_view hash) const override;
  bool Contains(std::string_view hash) const override;
  Status Remove(std::string_view hash) override;
  Status CheckWritable(int64_t min_free_bytes) const override;
  std::vector<std::string> List() const override;

  const std::filesystem::path& root() const { return root_; }

 private:
  explicit DirectoryBlobStore(std::filesystem::path root) : root_(std::move(root)) {}
  std::filesystem::path PathOf(std::string_view hash) const;

  std::filesystem::path root_;
};

}  // namespace motionlod::server
