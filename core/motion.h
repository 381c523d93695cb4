// A motion: per-frame world matrices of every joint of one skeleton, sampled at a
// fixed rate. Skinning matrices follow as K_j(t) = M_j(t) * inverse(M0_j).
#pragma once

#include <cstddef>
#include <span>
#include <string>
#include <vector>

#include "base/status.h"
#include "core/simd.h"
#include "core/types.h"

namespace motionlod::core {

using ::motionlod::Status;
using ::motionlod::StatusOr;

class Character;

// Frames [first_frame, first_frame + frame_count) of a motion, played as one clip (an
// animation of the source).
struct MotionClip {
  std::string name;
  double fps = 30.0;  // frames per second, > 0
  int first_frame = 0;
  int frame_count = 0;  // >= 1
};

struct Motion {
  std::string name;
  double fps = 30.0;  // frames per second, > 0
  int frame_count = 0;  // T >= 1
  int joint_count = 0;  // n, equal to the character's
  // T x n, row-major by frame: joint_world[t * n + j] = M_j(t), model space.
  std::vector<Affine34d> joint_world;
  // The clips whose frames follow one another in joint_world, in order, covering every
  // frame: a character's clips are baked as one motion with one reduced skeleton per level,
  // while each clip keeps its own figures. Empty: one clip, the whole motion (name, fps).
  std::vector<MotionClip> clips;

  const Affine34d& world(int t, int j) const { return joint_world[t * joint_count + j]; }
  // `clips`, or the one clip of the whole motion.
  std::vector<MotionClip> Clips() const;
};

// The clips one after another as one motion (Motion::clips names them); every clip animates
// the same joints. Fails on no clips or clips with other joint counts.
StatusOr<Motion> ConcatenateClips(std::span<const Motion> clips);

// Whether an affine matrix can be a joint's transform: every entry finite and its 3x3 part
// A invertible by a margin that no scale changes, |det A| > 1e-12 |A|_F^3.
bool IsInvertibleAffine(const Affine34d& matrix);

// The index of the first matrix that IsInvertibleAffine rejects, or matrices.size() when it
// rejects none. Four matrices at a time, each coefficient one vector of their four values:
// a long clip holds 10^5 joint matrices, and a bake checks its motion at each entry point.
// In the given machine version (core/simd.h): a long clip's validation in the baseline
// version of its vector code costs four times the instructions.
size_t FirstNonInvertibleAffine(std::span<const Affine34d> matrices,
                                SimdChoice simd = SimdChoice::kWidest);

// Checks shapes against the character, finiteness and invertibility of every matrix.
Status ValidateMotion(const Motion& motion, const Character& character,
                      SimdChoice simd = SimdChoice::kWidest);

}  // namespace motionlod::core
