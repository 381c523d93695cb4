// Step 4 (sec. 4.3, eq. 6) for one level: the normal equations G X = B of E(t) summed over
// frames (core/solve_levels.h: G 4m x 4m, frame independent; B 4m x 3T), G factored once
// and every frame's coordinates solved as right-hand sides. The naive reference, a dense
// least-squares system per frame, is core/reference/solve_frame_reference.h.
#pragma once

#include <Eigen/Core>

#include "core/internal/block_cholesky.h"
#include "core/internal/prepared_data.h"
#include "core/reduce_skeleton.h"

namespace motionlod::core::internal {

// The normal equations of one level: G (4m x 4m, lambda included, in 4x4 blocks), B
// (4m x 3T) and their solution X (4m x 3T, block (4s, 3t) = K'_s(t)^T). B is kept
// transposed (3T x 4m: 4 contiguous columns of all frames per kept joint), the layout
// BlockCholesky::SolveTransposed works in.
struct LevelSystem {
  BlockSymmetric<4> g;
  Eigen::MatrixXd bt, x;  // bt: moved into the solve (empty after it) unless nothing is removed
  // The rigid re-solve's right-hand sides (3T x m): B^T's translation columns, 4s + 3.
  Eigen::MatrixXd translation_bt;
};

// G and B of a validated level, and X. With every joint kept, X is the original matrices
// (no residual, and what the regulariser pulls towards: the exact minimiser).
StatusOr<LevelSystem> SolveNormalEquations(const PreparedData& d, const ReducedSkeleton& level);

}  // namespace motionlod::core::internal
