#include "core/motion.h"

#include <cmath>
#include <string>

#include "core/internal/lanes.h"
#include "core/internal/simd_dispatch.h"
#include "core/character.h"

namespace motionlod::core {
namespace {

// FirstNonInvertibleAffine's test of four matrices (12 doubles each, column-major, the
// first at m): the index of the first one it rejects, or 4. Each group of four consecutive
// coefficients of the four matrices is transposed in registers (Transpose4), so that
// e[r + 3c] holds coefficient (r, c) of all four.
inline int FirstNonInvertibleOfFour(const double* m) {
  Lanes4 e[12];
  for (int group = 0; group < 3; ++group) {
    Lanes4 in[4];
    for (int i = 0; i < 4; ++i) in[i] = *AsLanes4(m + 12 * i + 4 * group);
    Transpose4(in, e + 4 * group);
  }
  Lanes4 poison = e[0] - e[0];  // 0 where every entry is finite, NaN otherwise
  for (int q = 1; q < 12; ++q) poison += e[q] - e[q];
  Lanes4 norm_squared = e[0] * e[0];
  for (int q = 1; q < 9; ++q) norm_squared += e[q] * e[q];
  const Lanes4 det = e[0] * (e[4] * e[8] - e[7] * e[5]) - e[3] * (e[1] * e[8] - e[7] * e[2]) +
                     e[6] * (e[1] * e[5] - e[4] * e[2]);
  Lanes4 bound, magnitude;
  for (int l = 0; l < 4; ++l) {
    const double scale = std::sqrt(norm_squared[l]);
    bound[l] = 1e-12 * scale * scale * scale;
    magnitude[l] = std::abs(det[l]);
  }
  const auto ok = (poison == 0) & (magnitude > bound);
  for (int i = 0; i < 4; ++i) {
    if (ok[i] == 0) return i;
  }
  return 4;
}

}  // namespace

size_t FirstNonInvertibleAffine(std::span<const Affine34d> matrices, SimdChoice simd) {
  static_assert(sizeof(Affine34d) == 12 * sizeof(double));
  return RunWithSimd(simd, [&]() -> size_t {
    const size_t count = matrices.size();
    const size_t whole = count - count % 4;
    for (size_t first = 0; first < whole; first += 4) {
      const int bad = FirstNonInvertibleOfFour(matrices[first].data());
      if (bad < 4) return first + bad;
    }
    if (whole == count) return count;
    // The last one to three, with identities after them.
    Affine34d last[4];
    for (size_t i = 0; i < 4; ++i) {
      last[i] = whole + i < count ? matrices[whole + i] : IdentityAffine();
    }
    const int bad = FirstNonInvertibleOfFour(last[0].data());
    return bad < 4 ? whole + bad : count;
  });
}

bool IsInvertibleAffine(const Affine34d& matrix) {
  return FirstNonInvertibleAffine(std::span<const Affine34d>(&matrix, 1)) == 1;
}

std::vector<MotionClip> Motion::Clips() const {
  if (!clips.empty()) return clips;
  return {MotionClip{name, fps, 0, frame_count}};
}

StatusOr<Motion> ConcatenateClips(std::span<const Motion> clips) {
  if (clips.empty()) return InvalidArgument("no clips to concatenate");
  Motion out;
  out.name = clips.front().name;
  out.fps = clips.front().fps;
  out.joint_count = clips.front().joint_count;
  for (const Motion& clip : clips) {
    if (!clip.clips.empty()) return InvalidArgument("clip '" + clip.name + "' is made of clips itself");
    if (clip.joint_count != out.joint_count) {
      return InvalidArgument("clip '" + clip.name + "' animates " + std::to_string(clip.joint_count) +
                             " joints, the first " + std::to_string(out.joint_count));
    }
    out.clips.push_back(MotionClip{clip.name, clip.fps, out.frame_count, clip.frame_count});
    out.frame_count += clip.frame_count;
    out.joint_world.insert(out.joint_world.end(), clip.joint_world.begin(), clip.joint_world.end());
  }
  return out;
}

Status ValidateMotion(const Motion& motion, const Character& character, SimdChoice simd) {
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
  int next_frame = 0;
  for (const MotionClip& clip : motion.clips) {
    if (clip.first_frame != next_frame || clip.frame_count < 1 || !(clip.fps > 0) ||
        !std::isfinite(clip.fps)) {
      return InvalidArgument("the motion's clip '" + clip.name +
                             "' does not follow the one before it with frames and a positive rate");
    }
    next_frame += clip.frame_count;
  }
  if (!motion.clips.empty() && next_frame != motion.frame_count) {
    return InvalidArgument("the motion's clips cover " + std::to_string(next_frame) + " of its " +
                           std::to_string(motion.frame_count) + " frames");
  }
  const size_t bad = FirstNonInvertibleAffine(motion.joint_world, simd);
  if (bad == motion.joint_world.size()) return Status::Ok();
  const int t = static_cast<int>(bad / motion.joint_count),
            j = static_cast<int>(bad % motion.joint_count);
  const std::string where =
      "frame " + std::to_string(t) + ", joint '" + character.skeleton().joint_names[j] + "'";
  return InvalidArgument((motion.joint_world[bad].allFinite() ? "singular joint matrix at "
                                                              : "non-finite joint matrix at ") +
                         where);
}

}  // namespace motionlod::core
