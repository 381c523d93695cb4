// The rigid variants' step (eq. 8): each least-squares K'_s(t) is projected on its
// nearest rotation (polar decomposition, core/polar.h), then, by default, the level keeps
// its skeleton: rounds of (a) the translations re-solved with every rotation fixed (the
// exact minimiser of E over them) and the kept joints' positions moved, in E's metric,
// until each bone |p'_j - p'_q| (q its kept parent) is within 1.9% of the character's
// height of the original |p_j(t) - p_q(t)|, and (b) the rotations re-fitted with those
// positions fixed by majorise-minimise steps that never raise E. The drift figures are
// core/internal/skeleton_drift.h.
#pragma once

#include <Eigen/Core>

#include "core/internal/normal_equations.h"
#include "core/internal/prepared_data.h"
#include "core/reduce_skeleton.h"

namespace motionlod::core::internal {

// Whether every 3x3 block of x (4m x 3T, one 4x3 block K^T per joint and frame) is a
// rotation, |R^T R - I|_F <= tolerance and det R > 0. Composed through a skeleton's
// hierarchy, the float matrices of glTF, FBX and Collada files are orthonormal to 3e-6 to
// 8e-6 (2e-16 for BVH): kFloatRotation takes them as they are.
inline constexpr double kFloatRotation = 1e-5;
// What the rigid variants promise: each kept joint's distance to its kept parent within
// this percentage of the character's height of the original's on every frame.
inline constexpr double kRigidBoneLengthDriftPct = 2.0;

// What a rigid level set promises its clients (proto/level_format.h, kLevelSetFlagRigid).
inline constexpr double kRigidLevelRotation = 1e-3;
bool AllRotations(const Eigen::MatrixXd& x, SimdChoice simd, double tolerance = kFloatRotation);

// Projects system.x (the least-squares solution of `level`) on rotations and, with
// SolveSettings::resolve_rigid_translation, fits its translations and rotations under the
// bone lengths from G and system.translation_bt (which it consumes).
Status ProjectOnRotations(const PreparedData& d, const ReducedSkeleton& level, LevelSystem& system);

}  // namespace motionlod::core::internal
