// Importing characters and motions: one file (plus the files it references) becomes an
// immutable Asset holding a core::RawCharacter (skeleton + skin) and its animations,
// which are sampled on demand into core::Motion world matrices.
//
// Index letters as in core/types.h: j joint (n of them), i vertex, t frame (T).
// Spaces: "model space" is the file's world space (the root node's parent space), in the
// file's length unit. M0_j (bind_world) and the vertices of the skin are expressed in it,
// and so are the sampled M_j(t), so that K_j(t) = M_j(t) M0_j^-1 poses the skin.
//
// Supported formats (by extension, then checked by content): glTF 2 (.glb, .gltf),
// FBX (.fbx), COLLADA (.dae), BVH (.bvh), DirectX (.x) and Valve SMD (.smd). Assimp is an
// implementation detail: no header of io includes it, and io never logs: what it fixed
// or ignored is listed in Asset::warnings().
//
// What the import decides (details in rig.h, clips.h, proxy_skin.h):
//  * joints: the bones of the skinned meshes plus the nodes joining them to one root;
//    for files without skin (BVH, skeleton-only FBX) the animated nodes, without FBX
//    Null nodes and pivot helpers; BVH End Sites and FBX "_end" leaves are no joints;
//  * skin: all skinned meshes merged; rigid meshes bound with weight 1 to their nearest
//    joint ancestor (the root when none); at most LoadOptions::max_influences weights
//    per vertex, renormalised; files without mesh get a capsule proxy skin;
//  * clips: unnamed single-channel animations of equal length merged (COLLADA2GLTF);
//    the source rate derived from the key spacing (glTF's millisecond ticks give 24 or
//    30 fps, BVH's 0.0083333 s frame time gives 120); scale keys of zero raised to 1e-4.
#pragma once

#include <filesystem>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "base/pieces.h"
#include "base/status.h"
#include "core/character.h"
#include "core/motion.h"

namespace motionlod::io {

struct SourceFile {
  std::string name;   // plain file name (no directories): picks the format, resolves references
  std::string bytes;  // the whole file
};

struct LoadOptions {
  // Lower-case extensions (no dot) that may be read; a subset of the default.
  std::vector<std::string> allowed_extensions = {"glb", "gltf", "fbx", "dae", "bvh", "x", "smd"};
  // Influences kept per vertex (the largest, renormalised to sum 1), in [1, 16].
  int max_influences = 8;
  // Upper bound on the summed size of the files handed to LoadAsset.
  size_t max_total_bytes = size_t{512} << 20;
  // What an asset may hold, so that memory follows configuration, not what a file
  // declares: joints (checked before a proxy skin is made for them, and for a BVH before
  // Assimp parses it), skin vertices, source frames over every clip, and joints times
  // those frames.
  int max_joints = 1024;
  int64_t max_vertices = 2000000;
  int64_t max_frames = 200000;
  int64_t max_joint_frames = 4000000;

  Status Validate() const;
};

struct AnimationInfo {
  std::string name;             // unique within the asset; unnamed clips get "animation[_k]"
  double duration_seconds = 0;  // time of the last frame; 0 for a single pose
  double source_fps = 0;        // the rate the clip was keyed at (derived from key spacing)
  int source_frame_count = 1;   // floor(duration_seconds * source_fps + 1e-6) + 1
};

// An imported file. Immutable once loaded; every const method is thread-safe.
class Asset {
 public:
  ~Asset();
  Asset(const Asset&) = delete;
  Asset& operator=(const Asset&) = delete;

  // Skeleton and skin, ready for core::BuildCharacter. Joint 0 is the root.
  const core::RawCharacter& character() const;
  // True when the file had no mesh (a BVH or skeleton-only FBX) and the skin is a proxy
  // made of capsules around the bones (see proxy_skin.h).
  bool has_proxy_skin() const;
  const std::vector<AnimationInfo>& animations() const;
  // Things the importer fixed or ignored, one sentence each.
  const std::vector<std::string>& warnings() const;

  // Samples animation `name` ("" = the first) at `fps` frames per second (0 = the clip's
  // source_fps): frame t is at time t / fps, T = floor(duration * fps + 1e-6) + 1, and the
  // result holds M_j(t) for every joint of character(). Positions interpolate linearly,
  // rotations spherically; times outside the keys hold the first or last key, and a node
  // without keys keeps its rest transform. Errors: NotFound (no animation, or no
  // animation of that name: the message lists the available ones), InvalidArgument
  // (fps negative, not finite or above 1000, a result of more than 1e6 frames or 1e7
  // joint matrices, or a joint matrix that is singular or not finite), so that a
  // returned motion always passes core::ValidateMotion. The frames are sampled in pieces
  // on `run` (base/pieces.h; empty: on the calling thread); the motion is the same.
  StatusOr<core::Motion> SampleAnimation(std::string_view name, double fps,
                                         const PieceRunner& run = {}) const;

  struct Impl;

 private:
  friend struct AssetFactory;  // the importer and the worker reply decoder (asset_impl.h)
  explicit Asset(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

// Imports files[0]; the other files are what it may reference (a glTF's .bin buffers,
// textures). References resolve only among `files`, by plain name: no host file is ever
// opened, and a reference with a directory, "..", an absolute path or a URI scheme
// fails cleanly. Errors: InvalidArgument (bad options or names, empty or foreign
// content, refused references, NaN or infinity in the data, no skeleton), Unsupported
// (extension not allowed), DataLoss (truncated or corrupted bytes).
StatusOr<std::shared_ptr<const Asset>> LoadAsset(std::vector<SourceFile> files,
                                                 const LoadOptions& options = {});

// Reads `path` and lets it reference regular files in the same directory only.
StatusOr<std::shared_ptr<const Asset>> LoadAssetFile(const std::filesystem::path& path,
                                                     const LoadOptions& options = {});

}  // namespace motionlod::io
