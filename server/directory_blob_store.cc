#include "server/directory_blob_store.h"

#include <fcntl.h>
#include <sys/statvfs.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstring>
#include <vector>

#include "io/sha256.h"
#include "proto/api.h"

namespace motionlod::server {
namespace {

namespace fs = std::filesystem;

constexpr const char* kTempPrefix = ".tmp-";

// The file system failed (full, read-only, unwritable): the same call may work later.
Status Errno(const std::string& what) {
  return Status(StatusCode::kUnavailable, what + ": " + std::strerror(errno));
}

Status FsyncPath(const fs::path& path, int flags) {
  const int fd = ::open(path.c_str(), flags | O_CLOEXEC);
  if (fd < 0) return Errno("open " + path.string());
  const int result = ::fsync(fd);
  ::close(fd);
  return result == 0 ? Status::Ok() : Errno("fsync " + path.string());
}

Status WriteAll(int fd, std::string_view bytes) {
  size_t written = 0;
  while (written < bytes.size()) {
    const ssize_t n = ::write(fd, bytes.data() + written, bytes.size() - written);
    if (n < 0) {
      if (errno == EINTR) continue;
      return Errno("write");
    }
    written += static_cast<size_t>(n);
  }
  return Status::Ok();
}

// mkdir that fsyncs the parent when it created the directory, so that a blob renamed
// into it survives a power cut.
Status EnsureDirectory(const fs::path& dir) {
  if (::mkdir(dir.c_str(), 0755) == 0) return FsyncPath(dir.parent_path(), O_RDONLY | O_DIRECTORY);
  if (errno == EEXIST) return Status::Ok();
  return Errno("mkdir " + dir.string());
}

}  // namespace

Status DirectoryBlobStore::CheckWritable(int64_t min_free_bytes) const {
  struct statvfs space {};
  if (::statvfs(root_.c_str(), &space) == 0) {
    const auto free_bytes = static_cast<int64_t>(space.f_bavail) * static_cast<int64_t>(space.f_frsize);
    if (free_bytes < min_free_bytes) {
      return Status(StatusCode::kUnavailable,
                    "the data directory has " + std::to_string(free_bytes >> 20) +
                        " MiB free, less than min_free_bytes (" +
                        std::to_string(min_free_bytes >> 20) + " MiB)");
    }
  }
  std::string probe = (root_ / "sha256" / (std::string(kTempPrefix) + "XXXXXX")).string();
  const int fd = ::mkostemp(probe.data(), O_CLOEXEC);
  if (fd < 0) {
    return Status(StatusCode::kUnavailable,
                  std::string("the data directory is not writable: ") + std::strerror(errno));
  }
  ::close(fd);
  ::unlink(probe.c_str());
  return Status::Ok();
}

StatusOr<std::unique_ptr<DirectoryBlobStore>> DirectoryBlobStore::Open(const fs::path& root, bool shared) {
  std::error_code error;
  fs::create_directories(root / "sha256", error);
  if (error)
    return Status(StatusCode::kInternal, "cannot create " + root.string() + ": " + error.message());
  auto store = std::unique_ptr<DirectoryBlobStore>(new DirectoryBlobStore(root));
  // Temporary files are the remains of a crash; in a shared directory, only those an hour
  // old (younger ones may be another daemon's writes in progress).
  const auto stale = shared ? fs::file_time_type::clock::now() - std::chrono::hours(1)
                            : fs::file_time_type::max();
  for (const auto& entry : fs::recursive_directory_iterator(root / "sha256", error)) {
    if (entry.is_regular_file() && entry.path().filename().string().rfind(kTempPrefix, 0) == 0 &&
        entry.last_write_time(error) < stale) {
      fs::remove(entry.path(), error);
    }
  }
  return store;
}

fs::path DirectoryBlobStore::PathOf(std::string_view hash) const {
  return root_ / "sha256" / std::string(hash.substr(0, 2)) / std::string(hash.substr(2));
}

Status DirectoryBlobStore::PutWithHash(std::string_view hash, std::string_view bytes) {
  if (!proto::api::IsContentId(hash)) return InvalidArgument("malformed blob id");
  const fs::path path = PathOf(hash);
  if (::access(path.c_str(), F_OK) == 0) return Status::Ok();
  const fs::path dir = path.parent_path();
  if (Status status = EnsureDirectory(dir); !status.ok()) return status;
  std::string temp = (dir / (std::string(kTempPrefix) + "XXXXXX")).string();
  const int fd = ::mkostemp(temp.data(), O_CLOEXEC);
  if (fd < 0) return Errno("mkstemp in " + dir.string());
  Status status = WriteAll(fd, bytes);
  if (status.ok() && ::fsync(fd) != 0) status = Errno("fsync " + temp);
  if (status.ok() && ::fchmod(fd, 0644) != 0) status = Errno("fchmod " + temp);
  ::close(fd);
  if (status.ok() && ::rename(temp.c_str(), path.c_str()) != 0) status = Errno("rename " + temp);
  if (!status.ok()) {
    ::unlink(temp.c_str());
    return status;
  }
  return FsyncPath(dir, O_RDONLY | O_DIRECTORY);
}

StatusOr<std::string> DirectoryBlobStore::Get(std::string_view hash) const {
  if (!proto::api::IsContentId(hash)) return InvalidArgument("malformed blob id");
  const fs::path path = PathOf(hash);
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) {
    if (errno == ENOENT) return NotFound("blob " + std::string(hash) + " is not stored");
    return Errno("open blob");
  }
  struct stat info {};
  if (::fstat(fd, &info) != 0) {
    ::close(fd);
    return Errno("fstat blob");
  }
  std::string bytes(static_cast<size_t>(info.st_size), '\0');
  size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n = ::read(fd, bytes.data() + done, bytes.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) break;
    done += static_cast<size_t>(n);
  }
  ::close(fd);
  if (done != bytes.size()) return DataLoss("blob " + std::string(hash) + " is truncated");
  if (io::Sha256Hex(bytes) != hash)
    return DataLoss("blob " + std::string(hash) + " does not match its hash");
  return bytes;
}

bool DirectoryBlobStore::Contains(std::string_view hash) const {
  return proto::api::IsContentId(hash) && ::access(PathOf(hash).c_str(), F_OK) == 0;
}

Status DirectoryBlobStore::Remove(std::string_view hash) {
  if (!proto::api::IsContentId(hash)) return InvalidArgument("malformed blob id");
  if (::unlink(PathOf(hash).c_str()) != 0 && errno != ENOENT) return Errno("unlink blob");
  return Status::Ok();
}

std::vector<std::string> DirectoryBlobStore::List() const {
  std::vector<std::string> hashes;
  std::error_code error;
  for (const auto& prefix : fs::directory_iterator(root_ / "sha256", error)) {
    const std::string head = prefix.path().filename().string();
    if (!prefix.is_directory() || head.size() != 2) continue;
    for (const auto& entry : fs::directory_iterator(prefix.path(), error)) {
      const std::string hash = head + entry.path().filename().string();
      if (entry.is_regular_file() && proto::api::IsContentId(hash)) hashes.push_back(hash);
    }
  }
  return hashes;
}

}  // namespace motionlod::server
