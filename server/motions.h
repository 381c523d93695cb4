// Motions: the animations a character can be baked with, its own (registered when it is
// uploaded) and those of motion files retargeted onto it by joint name.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "io/asset.h"
#include "proto/api.h"
#include "server/service_context.h"
#include "server/store.h"

namespace motionlod::server {

class Motions {
 public:
  explicit Motions(ServiceContext& context) : context_(context) {}

  // A motion file: each of its animations retargeted onto the character (validation)
  // and registered as a motion of it.
  Result<Created<std::vector<proto::api::MotionInfo>>> Upload(const std::string& character_id,
                                                              std::vector<io::SourceFile> files);
  Result<proto::api::MotionInfo> Get(const std::string& id);
  // The motions of a character.
  Result<std::vector<proto::api::MotionInfo>> List(const std::string& character_id);

 private:
  ServiceContext& context_;
};

// The record of animation `animation` of the upload `source_id` as a motion of
// `character_id`; `source` is "character" (the character's own upload) or "file".
MotionRecord MakeMotionRecord(const std::string& character_id, const std::string& source,
                              const std::string& source_id, const io::AnimationInfo& animation,
                              int64_t created_ms);

proto::api::MotionInfo ToMotionInfo(const MotionRecord& m);

}  // namespace motionlod::server
