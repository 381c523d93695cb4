// The Store of one daemon: an embedded SQLite database (<data>/motionlodd.db, WAL
// journal, foreign keys on, synchronous FULL, busy timeout). One connection behind a
// mutex; each write is one transaction.
#pragma once

#include <filesystem>
#include <memory>
#include <mutex>

#include "server/store.h"

struct sqlite3;

namespace motionlod::server {

class SqliteStore final : public Store {
 public:
  static StatusOr<std::unique_ptr<SqliteStore>> Open(const std::filesystem::path& file);
  ~SqliteStore() override;
  SqliteStore(const SqliteStore&) = delete;
  SqliteStore& operator=(const SqliteStore&) = delete;

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
  bool shared() const override { return false; }

 private:
  explicit SqliteStore(sqlite3* db) : db_(db) {}
  Status Migrate();
  // Reads the clips of a bake read without them.
  Status ReadClipMotions(BakeRecord& bake);

  std::mutex mutex_;
  sqlite3* db_ = nullptr;
};

}  // namespace motionlod::server
