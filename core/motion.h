// A motion: per-frame world matrices of every joint of one skeleton, sampled at a
// fixed rate. Skinning matrices follow as K_j(t) = M_j(t) * inverse(M0_j).
#pragma once

#include <string>
#include <vector>

#include "base/status.h"
#include "core/types.h"

namespace motionlod::core {

using ::motionlod::Status;
using ::motionlod::StatusOr;

class Character;

struct Motion {
  std::string name;
  double fps = 30.0;  // frames per second, > 0
  int frame_count = 0;  // T >= 1
  int joint_count = 0;  // n, equal to the character's
  // T x n, row-major by frame: joint_world[t * n + j] = M_j(t), model space.
  std::vector<Affine34d> joint_world;

  const Affine34d& world(int t, int j) const { return joint_world[t * joint_count + j]; }
};

// Checks shapes against the character, finiteness and invertibility of every matrix.
Status ValidateMotion(const Motion& motion, const Character& character);

}  // namespace motionlod::core
