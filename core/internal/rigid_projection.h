// The rigid variants' step (eq. 8): each least-squares K'_s(t) is projected on its
// nearest rotation (polar decomposition, core/polar.h), then, by default, each translation
// is re-solved with every rotation fixed, the exact minimiser of E over the translations.
#pragma once

#include <Eigen/Core>

#include "core/internal/normal_equations.h"
#include "core/internal/prepared_data.h"

namespace motionlod::core::internal {

// Whether every 3x3 block of x (4m x 3T, one 4x3 block K^T per joint and frame) is a
// rotation to within the precision of float source data, |R^T R - I|_F <= 1e-5 and
// det R > 0. Composed through a skeleton's hierarchy, the float matrices of glTF, FBX and
// Collada files are orthonormal to 3e-6 to 8e-6 (2e-16 for BVH).
bool AllRotations(const Eigen::MatrixXd& x, SimdChoice simd);

// Projects system.x on rotations and, with SolveSettings::resolve_rigid_translation,
// re-solves its translations from G and system.translation_bt.
Status ProjectOnRotations(const PreparedData& d, LevelSystem& system);

}  // namespace motionlod::core::internal
