// The naive reference for a level's skeleton figures (LevelErrors::bone_length_drift_pct
// and joint_rotation_drift_deg, core/internal/skeleton_drift.h): the original joints'
// positions and skinning matrices from the motion's world matrices, p_j(t) = M_j(t)'s
// translation and K_j(t) = M_j(t) M0_j^-1, the level's from its stored matrices, every
// rotation by the SVD (core/reference/polar_reference.h) and every angle from the trace.
#pragma once

#include "core/character.h"
#include "core/motion.h"
#include "core/solve_levels.h"

namespace motionlod::core {

struct SkeletonDriftFigures {
  double bone_length_drift_pct = 0;     // percent of the character's height
  double joint_rotation_drift_deg = 0;  // degrees
};

// The figures of `level` (its skeleton and T x m matrices) for `motion` of `character`.
SkeletonDriftFigures SkeletonDriftReference(const Character& character, const Motion& motion,
                                            const LevelResult& level);

}  // namespace motionlod::core
