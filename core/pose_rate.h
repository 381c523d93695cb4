// Beyond the paper (#44): a far level stores fewer poses. At frame stride r a clip of F
// frames keeps frames 0, r, 2r, ... and its last (F - 1), and a player interpolates the
// frames between two stored ones: rigid matrices by slerp of the rotation and lerp of the
// translation (a rigid level stays rigid), affine ones by lerp of every entry. The level's
// pose rate is the clip's fps / r.
#pragma once

#include <span>
#include <vector>

#include "base/status.h"
#include "core/motion.h"
#include "core/types.h"

namespace motionlod::core {

inline constexpr int kMaxFrameStride = 16;

// How many frames a clip of `frame_count` frames stores at stride `stride`.
int StoredFrameCount(int frame_count, int stride);

// Frame t of a clip (in [0, frame_count)) between stored frames `index` and index + 1:
// `fraction` in [0, 1) of the way (0 on a stored frame, where index + 1 may not exist).
struct StoredFrameBlend {
  int index = 0;
  float fraction = 0;
};
StoredFrameBlend BlendOfFrame(int t, int frame_count, int stride);

// a at fraction 0, b at 1: rigid, slerp and lerp (a and b rotations plus translations);
// otherwise lerp.
RowMajorAffine34f InterpolateMatrix(const RowMajorAffine34f& a, const RowMajorAffine34f& b,
                                    float fraction, bool rigid);

// The stored frames of every clip at `stride`, clip after clip: from T x m matrices
// (frame-major, every frame of `clips`) to sum_c StoredFrameCount(F_c, stride) x m.
StatusOr<std::vector<RowMajorAffine34f>> StoreAtStride(std::span<const RowMajorAffine34f> matrices,
                                                       int kept_count,
                                                       std::span<const MotionClip> clips,
                                                       int stride);

// The m matrices of frame t of the motion (every clip's frames one after another) from
// stored frames at `stride`, into `out` (m).
void PlayFrame(std::span<const RowMajorAffine34f> stored, int kept_count,
               std::span<const MotionClip> clips, int stride, int t, bool rigid,
               std::span<RowMajorAffine34f> out);

}  // namespace motionlod::core
