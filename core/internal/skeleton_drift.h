// Step 5's skeleton figures (LevelErrors::bone_length_drift_pct and
// joint_rotation_drift_deg, core/solve_levels.h): how far a level's kept joints stray from
// the original skeleton, read from the matrices alone.
//   p_j(t)  = K_j(t) [p0_j; 1],   p'_j(t) = K'_s(t) [p0_j; 1]   (s the slot of kept joint j,
//             p0_j its bind position, M0_j's translation)
//   bone length drift: max over kept j with a kept parent q and frames t of
//             | |p'_j - p'_q| - |p_j - p_q| |, percent of the character's height
//   rotation drift: max over kept j and t of the angle between polar(K'_s(t)) and
//             polar(K_j(t)) (3x3 parts), degrees
// The naive reference, from the motion's world matrices, is
// core/reference/skeleton_drift_reference.h.
#pragma once

#include <vector>

#include <Eigen/Core>

#include "core/internal/prepared_data.h"
#include "core/reduce_skeleton.h"
#include "core/solve_levels.h"

namespace motionlod::core::internal {

// The positions K(t) [p0_j; 1] of joints[s] (original indices) from the matrices in k
// (block (first_rows[s], 3t) = K^T, 4x3): m x 3T, row s, column 3t + c.
Eigen::MatrixXd JointPositions(const PreparedData& d, const Eigen::MatrixXd& k,
                               const std::vector<int>& first_rows, const std::vector<int>& joints);

// The positions K'_s(t) [p0_j; 1] of a level's kept joints from its matrices x
// (4m x 3T, block (4s, 3t) = K'_s(t)^T): m x 3T, row s, column 3t + c.
Eigen::MatrixXd KeptJointPositions(const PreparedData& d, const Eigen::MatrixXd& x,
                                   const ReducedSkeleton& level);

// |p_j(t) - p_q(t)| of the original motion for each kept joint j (slot s) and its kept
// parent q: m x T (length), row 0, the root's, zero.
Eigen::MatrixXd OriginalBoneLengths(const PreparedData& d, const ReducedSkeleton& level);

// Sets out.bone_length_drift_pct and out.joint_rotation_drift_deg of a level's matrices x
// (4m x 3T, block (4s, 3t) = K'_s(t)^T).
void EvaluateSkeletonDrift(const PreparedData& d, const ReducedSkeleton& level,
                           const Eigen::MatrixXd& x, LevelErrors& out);

}  // namespace motionlod::core::internal
