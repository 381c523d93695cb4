#include "pipeline/export.h"

#include "core/character.h"
#include "proto/aligned_bytes.h"
#include "proto/level_format.h"

namespace motionlod::pipeline {

StatusOr<io::GltfExport> ExportLevelGltf(const io::Asset& character, std::string_view level_set,
                                         int joints, const std::string& animation_name) {
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
  auto built = core::BuildCharacter(character.character());
  if (!built.ok()) return built.status();
  const io::GltfLevel level{
      .joint_names = view->joint_names(),
      .kept_joints = chosen->kept_joints(),
      .joint_map = chosen->joint_map(),
      .matrices = chosen->matrices(),
      .frame_count = chosen->frame_count(),
      .fps = view->fps(),
      .rigid = view->rigid(),
      .animation_name = animation_name,
  };
  return io::ExportLevelGlb(**built, level);
}

}  // namespace motionlod::pipeline
