#include "io/asset.h"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <map>
#include <sstream>
#include <system_error>
#include <utility>

#include "io/asset_impl.h"
#include "io/assimp_scene.h"
#include "io/clips.h"
#include "io/format.h"
#include "io/rig.h"
#include "io/text.h"

namespace motionlod::io {

namespace {

constexpr double kMaxFps = 1000.0;
constexpr int kMaxFrames = 1000000;
constexpr double kMaxMatrices = 1e7;  // about 1 GB of Affine34d

// A BVH declares its joints and frames in plain text: counted before Assimp parses a
// file that exceeds them (Assimp took minutes on 100,000 joints).
Status PrecheckBvh(const SourceFile& main, const LoadOptions& options) {
  const std::string_view text(main.bytes);
  const size_t motion = text.find("MOTION");
  const std::string_view hierarchy = text.substr(0, motion);
  int64_t joints = 0;
  for (const std::string_view keyword : {"ROOT", "JOINT"}) {
    for (size_t at = hierarchy.find(keyword); at != std::string_view::npos;
         at = hierarchy.find(keyword, at + keyword.size())) {
      ++joints;
    }
  }
  if (joints > options.max_joints) {
    return InvalidArgument(Quote(main.name) + " declares " + std::to_string(joints) +
                           " joints, more than the limit of " + std::to_string(options.max_joints) +
                           " (max_joints)");
  }
  if (motion == std::string_view::npos) return Status::Ok();
  const size_t frames_at = text.find("Frames:", motion);
  if (frames_at == std::string_view::npos) return Status::Ok();
  const double frames = std::strtod(main.bytes.c_str() + frames_at + 7, nullptr);
  if (frames > static_cast<double>(options.max_frames)) {
    return InvalidArgument(Quote(main.name) + " declares " + std::to_string(frames) +
                           " frames, more than the limit of " + std::to_string(options.max_frames) +
                           " (max_frames)");
  }
  return Status::Ok();
}

StatusOr<std::shared_ptr<const Asset>> Load(const SourceFile& main, const FileResolver& resolver,
                                            const LoadOptions& options) {
  if (Status s = options.Validate(); !s.ok()) return s;
  StatusOr<Format> format = DetectFormat(main.name, main.bytes, options.allowed_extensions);
  if (!format.ok()) return format.status();
  if (*format == Format::kBvh) {
    if (Status s = PrecheckBvh(main, options); !s.ok()) return s;
  }
  StatusOr<Scene> scene = ImportScene(main.name, main.bytes, *format, resolver);
  if (!scene.ok()) return scene.status();

  auto impl = std::make_unique<Asset::Impl>();
  impl->warnings = scene->warnings;
  StatusOr<Rig> rig = BuildRig(*scene, options.max_influences, main.name, options.max_joints);
  if (!rig.ok()) return rig.status();
  impl->rig = std::move(rig).value();
  const int64_t vertices = static_cast<int64_t>(impl->rig.character.skin.positions.size());
  if (vertices > options.max_vertices) {
    return InvalidArgument(Quote(main.name) + " has " + std::to_string(vertices) +
                           " vertices, more than the limit of " +
                           std::to_string(options.max_vertices) + " (max_vertices)");
  }
  impl->warnings.insert(impl->warnings.end(), impl->rig.warnings.begin(), impl->rig.warnings.end());
  if (Status s = core::ValidateRawCharacter(impl->rig.character); !s.ok()) {
    return InvalidArgument(Quote(main.name) + " imports to an invalid character: " + s.message());
  }

  std::vector<char> is_joint_node(scene->nodes.size(), 0);
  for (int k : impl->rig.joint_nodes) is_joint_node[k] = 1;
  StatusOr<std::vector<Clip>> clips = BuildClips(*scene, is_joint_node, impl->warnings);
  if (!clips.ok()) return clips.status();
  impl->clips = std::move(clips).value();
  int64_t frames = 0;
  for (const Clip& clip : impl->clips) {
    impl->infos.push_back(clip.info);
    frames += clip.info.source_frame_count;
  }
  const int64_t joint_frames = frames * static_cast<int64_t>(impl->rig.joint_nodes.size());
  if (frames > options.max_frames || joint_frames > options.max_joint_frames) {
    return InvalidArgument(Quote(main.name) + "'s clips hold " + std::to_string(frames) +
                           " frames of " + std::to_string(impl->rig.joint_nodes.size()) +
                           " joints, more than the limit of " + std::to_string(options.max_frames) +
                           " frames (max_frames) or " + std::to_string(options.max_joint_frames) +
                           " joint frames (max_joint_frames)");
  }
  impl->nodes = std::move(scene->nodes);
  return AssetFactory::Make(std::move(impl));
}

}  // namespace

Status LoadOptions::Validate() const {
  if (allowed_extensions.empty()) return InvalidArgument("no file extension is allowed");
  const std::vector<std::string>& all = AllFormatExtensions();
  for (const std::string& e : allowed_extensions) {
    if (std::find(all.begin(), all.end(), e) == all.end()) {
      return InvalidArgument(
          Quote(e) +
          " is not a supported extension (lower case, no dot: glb, gltf, fbx, dae, bvh, x, smd)");
    }
  }
  if (max_influences < 1 || max_influences > 16) {
    return InvalidArgument("max_influences must be in [1, 16], got " +
                           std::to_string(max_influences));
  }
  if (max_total_bytes == 0) return InvalidArgument("max_total_bytes must be positive");
  if (max_joints < 1 || max_vertices < 1 || max_frames < 1 || max_joint_frames < 1) {
    return InvalidArgument("max_joints, max_vertices, max_frames and max_joint_frames must be "
                           "positive");
  }
  return Status::Ok();
}

Asset::Asset(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
Asset::~Asset() = default;

const core::RawCharacter& Asset::character() const { return impl_->rig.character; }
bool Asset::has_proxy_skin() const { return impl_->rig.proxy_skin; }
const std::vector<AnimationInfo>& Asset::animations() const { return impl_->infos; }
const std::vector<std::string>& Asset::warnings() const { return impl_->warnings; }

StatusOr<core::Motion> Asset::SampleAnimation(std::string_view name, double fps,
                                              const PieceRunner& run) const {
  if (impl_->clips.empty()) {
    return NotFound(Quote(impl_->rig.character.name) + " has no animation");
  }
  const Clip* clip = nullptr;
  if (name.empty()) {
    clip = &impl_->clips.front();
  } else {
    for (const Clip& c : impl_->clips) {
      if (c.info.name == name) clip = &c;
    }
  }
  if (clip == nullptr) {
    std::vector<std::string> available;
    for (const Clip& c : impl_->clips) available.push_back(c.info.name);
    return NotFound(Quote(impl_->rig.character.name) + " has no animation named '" +
                    std::string(name) + "'; available: " + QuotedList(available));
  }
  if (fps == 0) fps = clip->info.source_fps;
  if (!(fps > 0) || !std::isfinite(fps) || fps > kMaxFps) {
    return InvalidArgument(
        "the frame rate must be in (0, 1000] frames per second (0 for the source's), got " +
        std::to_string(fps));
  }
  const double frames = clip->info.duration_seconds * fps + 1;
  const double matrices = frames * static_cast<double>(impl_->rig.joint_nodes.size());
  if (!(frames <= kMaxFrames) || !(matrices <= kMaxMatrices)) {
    return InvalidArgument("sampling " + Quote(clip->info.name) + " at " + std::to_string(fps) +
                           " fps would give " + std::to_string(frames) + " frames of " +
                           std::to_string(impl_->rig.joint_nodes.size()) + " joints, more than " +
                           std::to_string(kMaxFrames) + " frames or " +
                           std::to_string(kMaxMatrices) + " matrices");
  }
  SampledClip sampled = SampleClip(*clip, impl_->nodes, impl_->rig.joint_nodes, fps, run);
  // Corrupted transforms (a zero scale in a rest matrix, say) must not reach the caller
  // as a motion that core::ValidateMotion would reject.
  const size_t bad = sampled.first_non_invertible;
  if (bad < sampled.motion.joint_world.size()) {
    const size_t n = static_cast<size_t>(sampled.motion.joint_count);
    return InvalidArgument("animation " + Quote(clip->info.name) + " gives joint " +
                           Quote(impl_->rig.character.skeleton.joint_names[bad % n]) +
                           " a singular or non-finite matrix at frame " + std::to_string(bad / n) +
                           " (corrupted transforms?)");
  }
  return std::move(sampled.motion);
}

StatusOr<std::shared_ptr<const Asset>> LoadAsset(std::vector<SourceFile> files,
                                                 const LoadOptions& options) {
  if (Status s = options.Validate(); !s.ok()) return s;
  if (files.empty()) return InvalidArgument("no file was given");
  size_t total = 0;
  std::map<std::string, const std::string*> by_name;
  for (const SourceFile& f : files) {
    total += f.bytes.size();
    if (!by_name.emplace(f.name, &f.bytes).second) {
      return InvalidArgument("two files are named '" + f.name + "'");
    }
  }
  if (total > options.max_total_bytes) {
    return InvalidArgument("the files hold " + std::to_string(total) +
                           " bytes, more than the limit of " +
                           std::to_string(options.max_total_bytes));
  }
  const FileResolver resolver = [&](const std::string& name) -> const std::string* {
    const auto it = by_name.find(name);
    return it == by_name.end() ? nullptr : it->second;
  };
  return Load(files.front(), resolver, options);
}

StatusOr<std::shared_ptr<const Asset>> LoadAssetFile(const std::filesystem::path& path,
                                                     const LoadOptions& options) {
  if (Status s = options.Validate(); !s.ok()) return s;
  auto read = [&](const std::filesystem::path& p, std::string& out) -> Status {
    std::error_code error;
    if (!std::filesystem::is_regular_file(p, error))
      return NotFound(Quote(p.string()) + " is not a regular file");
    const auto size = std::filesystem::file_size(p, error);
    if (error) return NotFound("cannot read '" + p.string() + "': " + error.message());
    if (size > options.max_total_bytes) {
      return InvalidArgument(Quote(p.string()) + " has " + std::to_string(size) +
                             " bytes, more than the limit");
    }
    std::ifstream in(p, std::ios::binary);
    std::ostringstream buffer;
    buffer << in.rdbuf();
    if (!in && !in.eof()) return NotFound("cannot read '" + p.string() + "'");
    out = std::move(buffer).str();
    return Status::Ok();
  };
  SourceFile main;
  main.name = path.filename().string();
  if (Status s = read(path, main.bytes); !s.ok()) return s;
  const std::filesystem::path directory = path.parent_path();
  std::map<std::string, std::string> loaded;  // node-based: pointers stay valid
  const FileResolver resolver = [&](const std::string& name) -> const std::string* {
    // Plain names only (ImportScene refuses the rest before asking).
    const auto it = loaded.find(name);
    if (it != loaded.end()) return &it->second;
    // A symbolic link could lead out of the directory: only regular files count.
    std::error_code error;
    if (std::filesystem::is_symlink(directory / name, error)) return nullptr;
    std::string bytes;
    if (!read(directory / name, bytes).ok()) return nullptr;
    return &loaded.emplace(name, std::move(bytes)).first->second;
  };
  return Load(main, resolver, options);
}

}  // namespace motionlod::io
