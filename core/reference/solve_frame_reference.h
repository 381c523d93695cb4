// The naive reference for the least-squares solve of a level (core/normal_equations.cc): per frame, the stacked weighted system of eq. (6)
// built row by row from the skinned mesh and solved by dense QR. Orders of magnitude
// slower than PreparedMotion::SolveLevel; kept for tests (equal to 1e-9) and the
// benchmark that shows the gap.
#pragma once

#include <vector>

#include "core/reduce_skeleton.h"
#include "core/solve_levels.h"

namespace motionlod::core {

// The unconstrained least-squares K'_s(t) (before any polar projection) of frame t,
// m matrices, with the weights (alpha, beta, omega, lambda) of `prepared`.
std::vector<Affine34d> SolveFrameReference(const PreparedMotion& prepared,
                                       const ReducedSkeleton& level, int frame);

}  // namespace motionlod::core
