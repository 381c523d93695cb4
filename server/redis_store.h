// The Store and BlobStore of daemons that share one Redis (backend = "redis"). Every key
// starts with the configured prefix P:
//   P character:<id>  P motion:<id>  P bake:<id>  P job:<id>   hashes, one field a column
//   P characters, P bakes                sorted sets of ids by creation time
//   P character:<id>:motions  :bakes     sorted sets (motions by insertion order)
//   P blob-refs    hash: blob -> how many records name it (collected at 0)
//   P level-bytes  hash: level hash -> its size, while a bake names it
//   P job-counts   hash: state -> jobs in it
//   P blob:<sha256>                      a blob's bytes (RedisBlobStore)
// Each write is one Lua script, so it is atomic and another daemon sees all of it or
// none. One Redis (or one primary), not Redis Cluster: the scripts touch keys they
// compute.
#pragma once

#include <memory>
#include <string>

#include "server/blob_store.h"
#include "server/redis_client.h"
#include "server/store.h"

namespace motionlod::server {

class RedisStore final : public Store {
 public:
  RedisStore(std::shared_ptr<RedisPool> redis, std::string prefix)
      : redis_(std::move(redis)), prefix_(std::move(prefix)) {}

  StatusOr<bool> InsertCharacter(const CharacterRecord& character,
                                 const std::vector<MotionRecord>& motions) override;
  StatusOr<std::optional<CharacterRecord>> GetCharacter(const std::string& id) override;
  StatusOr<std::vector<CharacterRecord>> ListCharacters() override;
  StatusOr<std::vector<std::string>> DeleteCharacter(const std::string& id) override;
  Status InsertMotions(const std::vector<MotionRecord>& motions) override;
  StatusOr<std::optional<MotionRecord>> GetMotion(const std::string& id) override;
  StatusOr<std::vector<MotionRecord>> ListMotions(const std::string& character_id) override;
  StatusOr<bool> InsertBakeAndJob(const BakeRecord& bake, const JobRecord& job) override;
  StatusOr<std::optional<BakeRecord>> GetBake(const std::string& id) override;
  StatusOr<std::vector<BakeRecord>> ListBakes(const std::string& character_id) override;
  StatusOr<std::vector<LevelRecord>> GetLevels(const std::string& bake_id) override;
  StatusOr<std::vector<std::string>> DeleteBake(const std::string& id) override;
  Status CompleteBake(const BakeRecord& bake, const std::vector<LevelRecord>& levels,
                      JobRecord& job) override;
  StatusOr<std::optional<JobRecord>> GetJob(const std::string& id) override;
  StatusOr<bool> UpdateJob(JobRecord& job) override;
  StatusOr<UnfinishedJobs> TakeUnfinishedJobs(int max_runs, int64_t now_ms) override;
  StatusOr<std::map<std::string, int64_t>> CountJobsByState() override;
  StatusOr<std::optional<int64_t>> LevelBytes(const std::string& hash) override;
  StatusOr<bool> IsBlobReferenced(const std::string& hash) override;
  StatusOr<std::vector<std::string>> ReferencedBlobs() override;
  bool Healthy() override;
  bool shared() const override { return true; }

 private:
  // The hash at `key` as field -> value, empty when the key does not exist.
  StatusOr<std::map<std::string, std::string>> ReadHash(const std::string& key);
  // The members of the sorted set at `key`, lowest score first.
  StatusOr<std::vector<std::string>> ReadSortedSet(const std::string& key);
  StatusOr<std::vector<BakeRecord>> ReadBakes(const std::vector<std::string>& ids, bool reports);

  std::shared_ptr<RedisPool> redis_;
  const std::string prefix_;
};

// Blobs in Redis as P blob:<sha256> strings, each at most `max_blob_bytes` (a larger one
// is refused: such deployments use a shared directory, blob_store = "directory").
class RedisBlobStore final : public BlobStore {
 public:
  RedisBlobStore(std::shared_ptr<RedisPool> redis, std::string prefix, int64_t max_blob_bytes)
      : redis_(std::move(redis)), prefix_(std::move(prefix)), max_blob_bytes_(max_blob_bytes) {}

  Status PutWithHash(std::string_view hash, std::string_view bytes) override;
  StatusOr<std::string> Get(std::string_view hash) const override;
  bool Contains(std::string_view hash) const override;
  Status Remove(std::string_view hash) override;
  // Redis answers; its memory is Redis's to bound (maxmemory), not this daemon's.
  Status CheckWritable(int64_t min_free_bytes) const override;
  std::vector<std::string> List() const override;

 private:
  std::string KeyOf(std::string_view hash) const { return prefix_ + "blob:" + std::string(hash); }

  std::shared_ptr<RedisPool> redis_;
  const std::string prefix_;
  const int64_t max_blob_bytes_;
};

}  // namespace motionlod::server
