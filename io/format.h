// Input formats the importer accepts, told apart by file extension and then checked by
// content (magic bytes or header keyword) before any parser sees the bytes. Internal to io.
#pragma once

#include <string>
#include <string_view>
#include <vector>

#include "base/status.h"

namespace motionlod::io {

enum class Format {
  kGlb,      // binary glTF (.glb)
  kGltf,     // JSON glTF (.gltf)
  kFbx,      // Autodesk FBX, binary or ASCII (.fbx)
  kCollada,  // COLLADA XML (.dae)
  kBvh,      // Biovision hierarchy (.bvh)
  kDirectX,  // DirectX .x, text or binary
  kSmd,      // Valve StudioModel data (.smd)
};

// The lower-case extensions (no dot) of every format above.
const std::vector<std::string>& AllFormatExtensions();

// "glTF binary", "FBX", ...: for messages.
const char* FormatName(Format format);

// The extension that Assimp's importer for `format` registers ("gltf" serves glb too).
const char* AssimpExtension(Format format);

// The lower-cased extension of `name` without the dot; "" when there is none.
std::string LowerExtension(std::string_view name);

// Checks that `name` is a plain file name (no directory part), that its extension is
// one of `allowed` (lower-case, no dot) and that `bytes` look like that format.
// Errors: InvalidArgument for a bad name, empty bytes or content of another format;
// Unsupported for an extension outside `allowed`; DataLoss for a header that is cut off
// or declares more bytes than there are.
StatusOr<Format> DetectFormat(std::string_view name, std::string_view bytes,
                              const std::vector<std::string>& allowed);

}  // namespace motionlod::io
