// The glTF export of one level of a level set (io/gltf_export.h): shared by `motionlod
// export` and the daemon's GET /v1/bakes/{id}/levels/{joints}.glb. docs/EXPORT.md.
#pragma once

#include <string>
#include <string_view>

#include "base/status.h"
#include "io/asset.h"
#include "io/gltf_export.h"

namespace motionlod::pipeline {

// Which level of a level set: by index (finest first), or the finest that keeps `joints`
// joints.
struct LevelPick {
  int index = -1;  // >= 0: this level
  int joints = 0;  // else: the finest level keeping this many
};

// The level of `level_set` (a level-set file, or a one-level file) that `pick` names,
// skinning `character` (the asset the level set was baked for) with the level's own mesh
// and influences where it has them, as a .glb with one animation: the clip named
// `clip_name` ("" = the first), called after it, every frame (poses between stored ones
// interpolated as a player does). A level set of one unnamed clip (format 1.0) plays that
// clip under the given name. Errors: kInvalidArgument (no such level: the message lists
// those that exist; the level set belongs to another character), kNotFound (no such clip:
// the message lists them), kDataLoss (the level set does not decode), and the importer's
// and the exporter's errors.
StatusOr<io::GltfExport> ExportLevelGltf(const io::Asset& character, std::string_view level_set,
                                         const LevelPick& pick, const std::string& clip_name);

}  // namespace motionlod::pipeline
