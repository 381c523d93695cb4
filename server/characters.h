// Characters: skinned meshes uploaded as one file or as a main file with the files it
// references, imported in the sandbox, stored with their own animations as motions.
#pragma once

#include <string>
#include <vector>

#include "io/asset.h"
#include "proto/api.h"
#include "server/bakes.h"
#include "server/service_context.h"

namespace motionlod::server {

class Characters {
 public:
  Characters(ServiceContext& context, Bakes& bakes) : context_(context), bakes_(bakes) {}

  // files[0] is the main file; the others are what it references.
  Result<Created<proto::api::CharacterInfo>> Upload(std::vector<io::SourceFile> files);
  Result<proto::api::CharacterInfo> Get(const std::string& id);
  Result<std::vector<proto::api::CharacterInfo>> List();
  // Deletes the character with its motions and bakes; its running bakes stop.
  Result<Done> Delete(const std::string& id);

 private:
  ServiceContext& context_;
  Bakes& bakes_;
};

}  // namespace motionlod::server
