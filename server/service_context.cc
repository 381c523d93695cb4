#include "server/service_context.h"

#include <spdlog/spdlog.h>

#include <chrono>
#include <cstdio>
#include <ctime>

namespace motionlod::server {
namespace {

constexpr size_t kAssetCacheEntries = 8;

}  // namespace

ServiceError Error(ErrorKind kind, std::string detail, int retry_after) {
  return ServiceError{kind, std::move(detail), retry_after};
}

ServiceError Internal(const Status& status) {
  if (status.code() == StatusCode::kUnavailable) {
    spdlog::error("storage error: {}", status.message());
    return Error(ErrorKind::kUnavailable, kStorageFaultDetail, 30);
  }
  spdlog::error("internal error: {}", status.message());
  return Error(ErrorKind::kInternal, "internal error; see the daemon's log");
}

ServiceError MalformedId(const std::string& what) {
  return Error(ErrorKind::kNotFound, "no " + what + " with that id (ids are 64 hex digits)");
}

int64_t NowMs() {
  return std::chrono::duration_cast<std::chrono::milliseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

std::string Rfc3339(int64_t ms) {
  if (ms <= 0) return "";
  const std::time_t seconds = static_cast<std::time_t>(ms / 1000);
  std::tm utc{};
  gmtime_r(&seconds, &utc);
  char buffer[40];
  const size_t n = std::strftime(buffer, sizeof buffer, "%Y-%m-%dT%H:%M:%S", &utc);
  std::snprintf(buffer + n, sizeof buffer - n, ".%03dZ", static_cast<int>(ms % 1000));
  return buffer;
}

std::shared_ptr<const io::Asset> AssetCache::Get(const std::string& source_id) {
  std::lock_guard lock(mutex_);
  for (auto it = entries_.begin(); it != entries_.end(); ++it) {
    if (it->first == source_id) {
      entries_.splice(entries_.begin(), entries_, it);
      return entries_.front().second;
    }
  }
  return nullptr;
}

void AssetCache::Put(const std::string& source_id, std::shared_ptr<const io::Asset> asset) {
  std::lock_guard lock(mutex_);
  entries_.remove_if([&](const auto& entry) { return entry.first == source_id; });
  entries_.emplace_front(source_id, std::move(asset));
  while (entries_.size() > kAssetCacheEntries) entries_.pop_back();
}

void AssetCache::Erase(const std::string& source_id) {
  std::lock_guard lock(mutex_);
  entries_.remove_if([&](const auto& entry) { return entry.first == source_id; });
}

StatusOr<std::shared_ptr<const io::Asset>> ServiceContext::Import(
    const std::vector<io::SourceFile>& files) {
  io::LoadOptions options;
  options.max_total_bytes = static_cast<size_t>(config.max_upload_bytes);
  options.max_joints = config.max_joints;
  options.max_vertices = config.max_vertices;
  options.max_frames = config.max_frames;
  options.max_joint_frames = config.max_joint_frames;
  return importer->Import(files, options);
}

StatusOr<std::shared_ptr<const io::Asset>> ServiceContext::LoadSource(
    const std::string& source_id, const std::vector<FileRecord>& files) {
  if (std::shared_ptr<const io::Asset> cached = assets.Get(source_id)) return cached;
  std::vector<io::SourceFile> sources;
  for (const FileRecord& f : files) {
    auto bytes = blobs->Get(f.blob);
    if (!bytes.ok()) return bytes.status();
    sources.push_back({f.name, std::move(*bytes)});
  }
  auto asset = Import(sources);
  if (!asset.ok()) return asset.status();
  assets.Put(source_id, *asset);
  return *asset;
}

Status ServiceContext::StoreFiles(const std::vector<io::SourceFile>& files,
                                  std::vector<FileRecord>& records) {
  for (const io::SourceFile& f : files) {
    auto hash = blobs->Put(f.bytes);
    if (!hash.ok()) return hash.status();
    records.push_back({f.name, *hash, static_cast<int64_t>(f.bytes.size())});
  }
  return Status::Ok();
}

void ServiceContext::CollectBlobs(const std::vector<std::string>& hashes) {
  std::unique_lock lock(blobs_mutex);
  for (const std::string& hash : hashes) {
    auto referenced = store->IsBlobReferenced(hash);
    if (!referenced.ok() || *referenced) continue;
    cache.Erase(hash);
    if (Status status = blobs->Remove(hash); !status.ok())
      spdlog::warn("blob {}: {}", hash, status.message());
  }
}

}  // namespace motionlod::server
