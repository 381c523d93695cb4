#include "core/motion.h"

#include <cmath>
#include <string>

#include "base/simd.h"
#include "core/character.h"

namespace motionlod::core {

Status ValidateMotion(const Motion& motion, const Character& character) {
  if (!(motion.fps > 0) || !std::isfinite(motion.fps)) {
    return InvalidArgument("the motion's frame rate must be positive, got " + std::to_string(motion.fps));
  }
  if (motion.frame_count < 1) return InvalidArgument("the motion has no frames");
  if (motion.joint_count != character.joint_count()) {
    return InvalidArgument("the motion animates " + std::to_string(motion.joint_count) +
                           " joints but the character has " +
                           std::to_string(character.joint_count()));
  }
  const size_t expected = static_cast<size_t>(motion.frame_count) * motion.joint_count;
  if (motion.joint_world.size() != expected) {
    return InvalidArgument("the motion holds " + std::to_string(motion.joint_world.size()) +
                           " matrices, expected frames x joints = " + std::to_string(expected));
  }
  // Every bake validates its motion at each core entry point, and a long clip holds 10^5
  // matrices: one branch-free pass decides, and only a failure is looked for again.
  const auto valid = [](const Affine34d& m) {
    double poison = 0;  // 0 where every entry is finite, NaN otherwise
    for (int i = 0; i < 12; ++i) poison += m.data()[i] - m.data()[i];
    const double scale = m.leftCols<3>().norm();
    return (poison == 0) &
           (std::abs(m.leftCols<3>().determinant()) > 1e-12 * scale * scale * scale);
  };
  const bool all_valid = RunWithWidestSimd([&] {
    bool all = true;
    for (const Affine34d& m : motion.joint_world) all &= valid(m);
    return all;
  });
  if (all_valid) return Status::Ok();
  for (int t = 0; t < motion.frame_count; ++t) {
    for (int j = 0; j < motion.joint_count; ++j) {
      const Affine34d& m = motion.world(t, j);
      if (valid(m)) continue;
      const std::string where = "frame " + std::to_string(t) + ", joint '" +
                                character.skeleton().joint_names[j] + "'";
      return InvalidArgument(
          (m.allFinite() ? "singular joint matrix at " : "non-finite joint matrix at ") + where);
    }
  }
  return Status::Ok();
}

}  // namespace motionlod::core
