// The naive reference for a level's figures (LevelErrors, core/solve_levels.h): every
// vertex of every frame skinned with the original matrices and with the level's, and the
// sums of eqs. (2)-(4) taken as written. What core/level_errors.cc (the quadratic forms),
// core/max_vertex_error.cc (the bounded search) and core/baseline_sequence.cc compute
// without skinning; the tests hold them to this.
#pragma once

#include <Eigen/Core>

#include "core/reduce_skeleton.h"
#include "core/solve_levels.h"

namespace motionlod::core {

// The figures of the level's matrices x (4m x 3T, block (4s, 3t) = K'_s(t)^T, as
// PreparedMotion::SolveLeastSquares returns them). mean_vertex_error_pct and
// mean_normal_error_deg are the exact means over every vertex and frame, which
// LevelErrors estimates from its sample.
LevelErrors LevelErrorsReference(const PreparedMotion& prepared, const ReducedSkeleton& level,
                                 const Eigen::MatrixXd& x);

// The baseline's figures: each kept joint keeps its original matrices.
LevelErrors BaselineErrorsReference(const PreparedMotion& prepared, const ReducedSkeleton& level);

}  // namespace motionlod::core
