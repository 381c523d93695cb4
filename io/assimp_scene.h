// The one door to Assimp: parses one file (plus the files it references) into a Scene.
// Only assimp_scene.cc includes Assimp headers. Internal to io.
#pragma once

#include <functional>
#include <string>
#include <string_view>

#include "base/status.h"
#include "io/format.h"
#include "io/scene.h"

namespace motionlod::io {

// Returns the bytes of the file called `name` (a plain name, no directories) or nullptr
// when there is none. The pointer must stay valid until ImportScene returns.
using FileResolver = std::function<const std::string*(const std::string& name)>;

// Parses `bytes` (the file `name`, already checked by DetectFormat to be `format`) with
// only the Assimp importers of `format` enabled. Files the main file references are
// looked up through `resolver` by plain name only: a reference with a directory part,
// "..", a drive, an absolute path or a URI scheme is refused, and no host file is
// opened. Never throws. Errors: DataLoss when Assimp rejects the bytes (the message
// carries Assimp's), InvalidArgument when a refused reference made the import fail
// or the data holds NaN or infinity.
StatusOr<Scene> ImportScene(const std::string& name, const std::string& bytes, Format format,
                            const FileResolver& resolver);

}  // namespace motionlod::io
