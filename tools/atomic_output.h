// Writing a tool's output directory so that readers never see half of it: files go to a
// hidden sibling directory, are flushed to disk, and the directory then replaces the
// target in one rename (an atomic exchange when the target already exists).
#pragma once

#include <filesystem>
#include <string>
#include <utility>
#include <vector>

#include "base/status.h"

namespace motionlod::tools {

// (file name, contents) pairs written as DIR/name. Names must be plain file names.
Status WriteDirectoryAtomically(const std::filesystem::path& dir,
                                const std::vector<std::pair<std::string, std::string>>& files);

// One file, written to a sibling temporary file, flushed, then renamed over `path`; its
// directory is created when missing.
Status WriteFileAtomically(const std::filesystem::path& path, const std::string& contents);

}  // namespace motionlod::tools
