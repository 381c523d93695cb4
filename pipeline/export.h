// The glTF export of one level of a level set (io/gltf_export.h): shared by `motionlod
// export` and the daemon's GET /v1/bakes/{id}/levels/{joints}.glb. docs/EXPORT.md.
#pragma once

#include <string>
#include <string_view>

#include "base/status.h"
#include "io/asset.h"
#include "io/gltf_export.h"

namespace motionlod::pipeline {

// The level of `level_set` (a level-set file, or a one-level file) that keeps `joints`
// joints, skinning `character` (the asset the level set was baked for), as a .glb with
// one animation: the clip named `clip_name` ("" = the first), called after it. A level
// set of one unnamed clip (format 1.0) plays that clip under the given name. Errors:
// kInvalidArgument (no level keeps that many joints: the message lists those that exist;
// the level set belongs to another character), kNotFound (no such clip: the message lists
// them), kDataLoss (the level set does not decode), and the importer's and the exporter's
// errors.
StatusOr<io::GltfExport> ExportLevelGltf(const io::Asset& character, std::string_view level_set,
                                         int joints, const std::string& clip_name);

}  // namespace motionlod::pipeline
