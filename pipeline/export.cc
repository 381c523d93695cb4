#include "pipeline/export.h"

#include <algorithm>
#include <vector>

#include "core/character.h"
#include "core/pose_rate.h"
#include "proto/aligned_bytes.h"
#include "proto/level_format.h"

namespace motionlod::pipeline {

StatusOr<io::GltfExport> ExportLevelGltf(const io::Asset& character, std::string_view level_set,
                                         const LevelPick& pick, const std::string& clip_name) {
  const proto::AlignedBytes aligned = proto::AlignedBytes::CopyOf(level_set);
  auto view = proto::DecodeLevelSet(aligned.bytes());
  if (!view.ok()) return view.status();
  const proto::LevelView* chosen = nullptr;
  std::string available;
  for (const proto::LevelView& level : view->levels()) {
    if (chosen == nullptr && pick.index < 0 && static_cast<int>(level.kept_count()) == pick.joints)
      chosen = &level;
    available += (available.empty() ? "" : ", ") + std::to_string(level.kept_count());
  }
  if (pick.index >= 0 && static_cast<uint32_t>(pick.index) < view->level_count())
    chosen = &view->level(static_cast<uint32_t>(pick.index));
  if (chosen == nullptr && pick.index >= 0) {
    return InvalidArgument("no level " + std::to_string(pick.index) + "; the level set has " +
                           std::to_string(view->level_count()) + " (0 is the finest)");
  }
  if (chosen == nullptr) {
    return InvalidArgument("no level keeps " + std::to_string(pick.joints) +
                           " joints; the levels keep " + available);
  }
  // The clip: by name, the first where none is named, or the one unnamed clip of a level
  // set that names none (format 1.0), whose animation then takes the given name.
  const std::span<const proto::ClipView> clips = view->clips();
  int clip = clip_name.empty() ? 0 : view->FindClip(clip_name);
  if (clip < 0 && clips.size() == 1 && clips.front().name.empty()) clip = 0;
  if (clip < 0) {
    std::string names;
    for (const proto::ClipView& c : clips) names += (names.empty() ? "'" : ", '") + std::string(c.name) + "'";
    return NotFound("the level set has no clip '" + clip_name + "'; its clips are " + names);
  }
  const proto::ClipView& chosen_clip = clips[clip];
  auto built = core::BuildCharacter(character.character());
  if (!built.ok()) return built.status();
  // Every frame of the clip: the stored poses, and between them the interpolation a player
  // makes at the level's pose rate (core/pose_rate.h).
  const uint32_t m = chosen->kept_count();
  std::vector<float> matrices(size_t{chosen_clip.frame_count} * m * proto::kMatrixFloats);
  for (uint32_t t = 0; t < chosen_clip.frame_count; ++t) {
    const proto::FrameBlend blend = chosen->Blend(static_cast<uint32_t>(clip), t, chosen_clip.frame_count);
    for (uint32_t s = 0; s < m; ++s) {
      const core::RowMajorAffine34f from = Eigen::Map<const core::RowMajorAffine34f>(chosen->matrix(blend.from, s));
      const core::RowMajorAffine34f to = Eigen::Map<const core::RowMajorAffine34f>(chosen->matrix(blend.to, s));
      const core::RowMajorAffine34f played = core::InterpolateMatrix(from, to, blend.fraction, view->rigid());
      std::copy(played.data(), played.data() + proto::kMatrixFloats,
                matrices.begin() + (size_t{t} * m + s) * proto::kMatrixFloats);
    }
  }
  const io::GltfLevel level{
      .joint_names = view->joint_names(),
      .kept_joints = chosen->kept_joints(),
      .joint_map = chosen->joint_map(),
      .matrices = matrices,
      .frame_count = chosen_clip.frame_count,
      .fps = chosen_clip.fps,
      .rigid = view->rigid(),
      .animation_name = chosen_clip.name.empty() ? clip_name : std::string(chosen_clip.name),
      .vertices = chosen->vertices(),
      .triangles = chosen->triangles(),
      .influences_per_vertex = chosen->influences_per_vertex(),
      .influence_slots = chosen->influence_slots(),
      .influence_weights = chosen->influence_weights(),
  };
  return io::ExportLevelGlb(**built, level);
}

}  // namespace motionlod::pipeline
