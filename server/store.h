// The daemon's metadata: characters, motions, bakes, their levels and jobs, as records.
// Bytes (uploads, level sets, single levels) live in a BlobStore; records name them by
// SHA-256. Two implementations: SqliteStore (server/sqlite_store.h, one daemon, the
// default) and RedisStore (server/redis_store.h, daemons sharing one Redis). Every
// method is thread-safe and each write is atomic: all of it or none.
#pragma once

#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "base/status.h"

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
  // Bumped by every UpdateJob of a shared store (RedisStore), so that every daemon answers
  // one version for one state; 0 in a store of one daemon, whose versions are its own.
  uint64_t version = 0;
};

// The JSON text both stores keep file lists and string lists in, and back (text that is
// not such a list reads as an empty one).
std::string FilesToJson(const std::vector<FileRecord>& files);
std::vector<FileRecord> FilesFromJson(const std::string& text);
std::string ListToJson(const std::vector<std::string>& items);
std::vector<std::string> ListFromJson(const std::string& text);

// The error detail of a job failed as 'crashed' after `max_runs` runs that the daemon
// running it did not survive.
std::string CrashedDetail(int max_runs);

class Store {
 public:
  virtual ~Store() = default;

  // Characters and their embedded animations in one transaction; false when the id was
  // already present (nothing written).
  virtual StatusOr<bool> InsertCharacter(const CharacterRecord& character,
                                 const std::vector<MotionRecord>& motions) = 0;
  virtual StatusOr<std::optional<CharacterRecord>> GetCharacter(const std::string& id) = 0;
  virtual StatusOr<std::vector<CharacterRecord>> ListCharacters() = 0;
  // Deletes the character with its motions, bakes, levels and jobs. Returns the blobs the
  // deleted rows named (to collect when nothing else names them); kNotFound when absent.
  virtual StatusOr<std::vector<std::string>> DeleteCharacter(const std::string& id) = 0;

  // Motions already present are left as they are.
  virtual Status InsertMotions(const std::vector<MotionRecord>& motions) = 0;
  virtual StatusOr<std::optional<MotionRecord>> GetMotion(const std::string& id) = 0;
  virtual StatusOr<std::vector<MotionRecord>> ListMotions(const std::string& character_id) = 0;

  // The bake (with its clips) and its job in one transaction; false when the bake
  // already existed.
  virtual StatusOr<bool> InsertBakeAndJob(const BakeRecord& bake, const JobRecord& job) = 0;
  virtual StatusOr<std::optional<BakeRecord>> GetBake(const std::string& id) = 0;
  // "" = all.
  virtual StatusOr<std::vector<BakeRecord>> ListBakes(const std::string& character_id) = 0;
  virtual StatusOr<std::vector<LevelRecord>> GetLevels(const std::string& bake_id) = 0;
  // Deletes the bake, its levels and its job; returns the blobs they named.
  virtual StatusOr<std::vector<std::string>> DeleteBake(const std::string& id) = 0;

  // A finished bake: its level set, report and levels, and the job's final record (whose
  // version a shared store bumps).
  virtual Status CompleteBake(const BakeRecord& bake, const std::vector<LevelRecord>& levels,
                              JobRecord& job) = 0;

  virtual StatusOr<std::optional<JobRecord>> GetJob(const std::string& id) = 0;
  // Updates state, progress, stage, error, attempts and times (and bumps `job.version` in
  // a shared store); false when the job is gone.
  virtual StatusOr<bool> UpdateJob(JobRecord& job) = 0;
  // The jobs left unfinished when the daemon stopped, to run again.
  struct UnfinishedJobs {
    std::vector<std::string> requeued;  // queued, oldest first; running ones set back to queued
    std::vector<std::string> failed;    // running on their max_runs-th run or later: failed
  };
  // A job found running was running when the daemon died (a shutdown leaves them queued).
  // One that has started max_runs runs is failed ('crashed', at `now_ms`), not run again:
  // a bake that takes the daemon down every time must not take it down forever. A shared
  // store returns none: its queue holds the unfinished jobs, and Jobs::Run applies the cap.
  virtual StatusOr<UnfinishedJobs> TakeUnfinishedJobs(int max_runs, int64_t now_ms) = 0;
  virtual StatusOr<std::map<std::string, int64_t>> CountJobsByState() = 0;

  // The byte size of a stored single level, nullopt when no bake has that level.
  virtual StatusOr<std::optional<int64_t>> LevelBytes(const std::string& hash) = 0;
  // Whether any row still names this blob.
  virtual StatusOr<bool> IsBlobReferenced(const std::string& hash) = 0;
  // Every blob any row names.
  virtual StatusOr<std::vector<std::string>> ReferencedBlobs() = 0;

  // A trivial query: the database answers.
  virtual bool Healthy() = 0;
  // Whether other daemons work on the same records (their jobs run elsewhere, their blobs
  // may be written now by another process).
  virtual bool shared() const = 0;
};

}  // namespace motionlod::server
