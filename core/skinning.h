// Linear blend skinning, eq. (1): v_i = sum_j w_ij K_j [v0_i; 1] and, with the 3x3
// parts, the *unnormalised* blended normal n_i = sum_j w_ij K_j [n0_i; 0] (the
// targets of eq. (3); callers normalise for display).
#pragma once

#include <span>

#include "base/status.h"
#include "core/character.h"
#include "core/types.h"

namespace motionlod::core {

// One frame: skinning matrices in, posed positions and normals out (caller-owned).
// Streamed data is float; nothing is allocated.
struct SkinningJob {
  const Character* character = nullptr;  // validated by BuildCharacter
  std::span<const Affine34f> skinning_matrices;  // n, K_j for this frame
  std::span<Vec3f> out_positions;                // p
  std::span<Vec3f> out_normals;                  // p, or empty to skip normals

  // Shapes only: the skin's joint indices were checked by BuildCharacter.
  Status Validate() const;
  // Validates first and touches nothing when invalid.
  Status Run() const;
};

}  // namespace motionlod::core
