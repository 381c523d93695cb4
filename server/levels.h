// Levels of baked level sets: a bake's level table (error figures and the on-screen
// heights each level serves), the level proto::SelectLevel picks for a height, the
// one-level files by hash, and a level exported as glTF.
#pragma once

#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "proto/api.h"
#include "server/jobs.h"
#include "server/level_cache.h"
#include "server/service_context.h"
#include "server/store.h"

namespace motionlod::server {

class Levels {
 public:
  Levels(ServiceContext& context, Jobs& jobs) : context_(context), jobs_(jobs) {}

  // proto::SelectLevel on the bake's level table (the figures over every clip) for a
  // character `px` pixels tall; `clip` (an animation name of the bake, or "" for every
  // clip) goes into the choice's url. 404 naming the bake's clips for an unknown clip.
  Result<proto::api::LevelChoice> Choose(const std::string& bake_id, double px, double budget_px,
                                         const std::string& clip);

  // A one-level file and its entity tag's value: the level's hash for the file of every
  // clip, the SHA-256 of the hash and the clip's name for one clip's.
  struct LevelFile {
    LevelCache::Bytes bytes;
    std::string key;
  };
  // The one-level file of that hash (served from the cache when hot); with `clip` not
  // empty, only the frames of the clip of that name (proto::ExtractLevelClip), made from
  // it once and then cached under `key`. 404 naming the level's clips for an unknown clip.
  Result<LevelFile> Get(const std::string& hash, const std::string& clip);

  // A level of a bake as glTF 2.0 binary (docs/EXPORT.md): the level whose one-level file
  // is `hash`, or else the finest that keeps `joints` joints; playing the clip of that name
  // ("" = the first), exported from the stored character on the first request and then
  // served from the level cache under `key`, the SHA-256 of what it is made of (an ETag).
  struct GltfPick {
    int joints = 0;
    std::string hash;
  };
  struct GltfFile {
    LevelCache::Bytes glb;
    std::string key;
  };
  Result<GltfFile> GetGltf(const std::string& bake_id, const GltfPick& pick,
                           const std::string& clip);

  struct Table {
    std::vector<double> max_error_fraction;  // finest first
    std::vector<proto::api::LevelEntry> entries;
    std::vector<proto::api::BakeClip> clips;  // in frame order
  };
  // The level table of a bake that has levels, made from its report once and then cached.
  StatusOr<std::shared_ptr<const Table>> GetTable(const BakeRecord& bake);
  // Drops the cached table of a deleted bake.
  void ForgetTable(const std::string& bake_id);

 private:
  // The bake record of a bake that has levels (an id checked first; 404, or 409 while its
  // job has not succeeded).
  Result<BakeRecord> BakeWithLevels(const std::string& bake_id);
  // The table of a bake that has levels, from the cache or the store.
  Result<std::shared_ptr<const Table>> TableOf(const std::string& bake_id);

  ServiceContext& context_;
  Jobs& jobs_;
  std::mutex tables_mutex_;
  std::map<std::string, std::shared_ptr<const Table>> tables_;
};

}  // namespace motionlod::server
