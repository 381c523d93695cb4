// The daemon's metadata in an embedded SQLite database (<data>/motionlodd.db, WAL
// journal, foreign keys on, synchronous FULL, busy timeout): characters, motions, bakes,
// their levels and jobs. Bytes (uploads, level sets, single levels) live in the BlobStore;
// rows name them by SHA-256. One connection behind a mutex: every method is thread-safe
// and each write is one transaction.
#pragma once

#include <cstdint>
#include <filesystem>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "base/status.h"

struct sqlite3;

namespace motionlod::server {

struct FileRecord {
  std::string name;  // plain file name as uploaded
  std::string blob;  // sha256
  int64_t size = 0;
};

struct CharacterRecord {
  std::string id;
  std::string name;
  std::vector<FileRecord> files;  // files[0] is the main file
  int joints = 0, vertices = 0, triangles = 0;
  bool proxy_skin = false;
  std::vector<std::string> joint_names;  // n, in the file's topological order
  std::vector<std::string> warnings;
  int64_t created_ms = 0;
};

struct MotionRecord {
  std::string id;
  std::string character_id;
  std::string animation;
  std::string source;     // "character" or "file"
  std::string source_id;  // upload id of the motion file ("file"), the character id otherwise
  std::vector<FileRecord> files;  // the motion file's parts ("file" only)
  double duration_seconds = 0, source_fps = 0;
  int frames = 0;
  std::vector<std::string> warnings;
  int64_t created_ms = 0;
};

struct BakeRecord {
  std::string id;
  std::string character_id;
  std::string motion_id;                  // the first clip's
  std::vector<std::string> clip_motions;  // every clip's motion id, in the bake's order
  std::string request_json;  // the resolved api::BakeRequest
  int64_t created_ms = 0;
  // Filled when the bake succeeds.
  std::string level_set;  // sha256 of the whole level set
  int64_t level_set_bytes = 0;
  std::string report_json;
  int frames = 0;
  double fps = 0;
};

struct LevelRecord {
  int index = 0;  // finest first, as in the level set
  int joints = 0;
  std::string hash;  // sha256 of the one-level file
  int64_t bytes = 0;
};

struct JobRecord {
  std::string id;  // = the bake id
  std::string bake_id;
  std::string state;  // queued | running | succeeded | failed
  double progress = 0;
  std::string stage;
  std::string error_code, error_detail;
  int attempts = 0;
  int64_t created_ms = 0, started_ms = 0, finished_ms = 0;
};

class Store {
 public:
  static StatusOr<std::unique_ptr<Store>> Open(const std::filesystem::path& file);
  ~Store();
  Store(const Store&) = delete;
  Store& operator=(const Store&) = delete;

  // Characters and their embedded animations in one transaction; false when the id was
  // already present (nothing written).
  StatusOr<bool> InsertCharacter(const CharacterRecord& character,
                                 const std::vector<MotionRecord>& motions);
  StatusOr<std::optional<CharacterRecord>> GetCharacter(const std::string& id);
  StatusOr<std::vector<CharacterRecord>> ListCharacters();
  // Deletes the character with its motions, bakes, levels and jobs. Returns the blobs the
  // deleted rows named (to collect when nothing else names them); kNotFound when absent.
  StatusOr<std::vector<std::string>> DeleteCharacter(const std::string& id);

  // Motions already present are left as they are.
  Status InsertMotions(const std::vector<MotionRecord>& motions);
  StatusOr<std::optional<MotionRecord>> GetMotion(const std::string& id);
  StatusOr<std::vector<MotionRecord>> ListMotions(const std::string& character_id);

  // The bake (with its clips) and its job in one transaction; false when the bake
  // already existed.
  StatusOr<bool> InsertBakeAndJob(const BakeRecord& bake, const JobRecord& job);
  StatusOr<std::optional<BakeRecord>> GetBake(const std::string& id);
  StatusOr<std::vector<BakeRecord>> ListBakes(const std::string& character_id);  // "" = all
  StatusOr<std::vector<LevelRecord>> GetLevels(const std::string& bake_id);
  // Deletes the bake, its levels and its job; returns the blobs they named.
  StatusOr<std::vector<std::string>> DeleteBake(const std::string& id);

  // A finished bake: its level set, report and levels, and the job's final record.
  Status CompleteBake(const BakeRecord& bake, const std::vector<LevelRecord>& levels,
                      const JobRecord& job);

  StatusOr<std::optional<JobRecord>> GetJob(const std::string& id);
  // Updates state, progress, stage, error, attempts and times; false when the job is gone.
  StatusOr<bool> UpdateJob(const JobRecord& job);
  // The jobs left unfinished when the daemon stopped, to run again.
  struct UnfinishedJobs {
    std::vector<std::string> requeued;  // queued, oldest first; running ones set back to queued
    std::vector<std::string> failed;    // running on their max_runs-th run or later: failed
  };
  // A job found running was running when the daemon died (a shutdown leaves them queued).
  // One that has started max_runs runs is failed ('crashed', at `now_ms`), not run again:
  // a bake that takes the daemon down every time must not take it down forever.
  StatusOr<UnfinishedJobs> TakeUnfinishedJobs(int max_runs, int64_t now_ms);
  StatusOr<std::map<std::string, int64_t>> CountJobsByState();

  // The byte size of a stored single level, nullopt when no bake has that level.
  StatusOr<std::optional<int64_t>> LevelBytes(const std::string& hash);
  // Whether any row still names this blob.
  StatusOr<bool> IsBlobReferenced(const std::string& hash);
  // Every blob any row names.
  StatusOr<std::vector<std::string>> ReferencedBlobs();

  // A trivial query: the database answers.
  bool Healthy();

 private:
  explicit Store(sqlite3* db) : db_(db) {}
  Status Migrate();
  // Reads the clips of a bake read without them.
  Status ReadClipMotions(BakeRecord& bake);

  std::mutex mutex_;
  sqlite3* db_ = nullptr;
};

}  // namespace motionlod::server
