#include "pipeline/export.h"

#include "core/character.h"
#include "proto/aligned_bytes.h"
#include "proto/level_format.h"

namespace motionlod::pipeline {

StatusOr<io::GltfExport> ExportLevelGltf(const io::Asset& character, std::string_view level_set,
                                         int joints, const std::string& clip_name) {
  const proto::AlignedBytes aligned = proto::AlignedBytes::CopyOf(level_set);
  auto view = proto::DecodeLevelSet(aligned.bytes());
  if (!view.ok()) return view.status();
  const proto::LevelView* chosen = nullptr;
  std::string available;
  for (const proto::LevelView& level : view->levels()) {
    if (static_cast<int>(level.kept_count()) == joints) chosen = &level;
    available += (available.empty() ? "" : ", ") + std::to_string(level.kept_count());
  }
  if (chosen == nullptr) {
    return InvalidArgument("no level keeps " + std::to_string(joints) +
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
  const size_t frame_floats = size_t{chosen->kept_count()} * proto::kMatrixFloats;
  const io::GltfLevel level{
      .joint_names = view->joint_names(),
      .kept_joints = chosen->kept_joints(),
      .joint_map = chosen->joint_map(),
      .matrices = chosen->matrices().subspan(chosen_clip.first_frame * frame_floats,
                                             chosen_clip.frame_count * frame_floats),
      .frame_count = chosen_clip.frame_count,
      .fps = chosen_clip.fps,
      .rigid = view->rigid(),
      .animation_name = chosen_clip.name.empty() ? clip_name : std::string(chosen_clip.name),
  };
  return io::ExportLevelGlb(**built, level);
}

}  // namespace motionlod::pipeline
