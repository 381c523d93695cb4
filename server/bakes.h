// Bakes: a character's motion baked into a level set. A bake is submitted as a job
// (server/jobs.h) and, once it has succeeded, has a level set, a report and a level table.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "pipeline/bake.h"
#include "proto/api.h"
#include "server/jobs.h"
#include "server/levels.h"
#include "server/service_context.h"
#include "server/store.h"

namespace motionlod::server {

class Bakes {
 public:
  Bakes(ServiceContext& context, Jobs& jobs, Levels& levels)
      : context_(context), jobs_(jobs), levels_(levels) {}

  // Resolves the request (the clips, levels and locked joints), stores the bake and queues
  // its job; the same request again is the same bake (created: false).
  Result<Created<proto::api::JobStatus>> Submit(const proto::api::BakeRequest& request);
  Result<proto::api::BakeInfo> Get(const std::string& id);
  Result<std::vector<proto::api::BakeInfo>> List(const std::string& character_id);
  Result<std::string> GetReport(const std::string& bake_id);  // report.json text
  Result<Done> Delete(const std::string& id);
  // Stops the job of a bake whose rows are deleted and drops what is cached of it.
  void Forget(const std::string& id);

 private:
  Result<proto::api::BakeInfo> ToBakeInfo(const BakeRecord& bake);

  ServiceContext& context_;
  Jobs& jobs_;
  Levels& levels_;
};

// What a bake's identity names of a clip: its source ("character" for the character's
// own file, else the motion file's upload id) and its animation.
struct ClipIdentity {
  std::string source;
  std::string animation;
};
ClipIdentity IdentityOf(const MotionRecord& motion);

// The canonical text a bake id hashes (the clips in order, the ranking, the levels, the
// solver settings), and the SHA-256 of the inputs stored in the level set
// (LevelSetData::source_hash). Exposed for the job runner and for tests that bake
// in-process.
struct BakeKey {
  std::string id;
  std::array<uint8_t, 32> source_hash{};
};
BakeKey MakeBakeKey(const proto::api::BakeRequest& resolved, const std::vector<ClipIdentity>& clips,
                    uint64_t settings_hash);

// The pipeline request the daemon bakes for a resolved API request and its clips (without
// the character's asset).
pipeline::BakeRequest MakePipelineRequest(const proto::api::BakeRequest& resolved,
                                          std::vector<pipeline::ClipSource> clips, int bake_threads,
                                          core::SimdChoice simd = core::SimdChoice::kWidest);

}  // namespace motionlod::server
