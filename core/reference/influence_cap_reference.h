// The naive reference for the weight step of the influence cap (core/influence_cap.h):
// each vertex's quadratic form built by skinning it at every frame, the original from the
// motion's world matrices, K_j(t) = M_j(t) M0_j^-1, and the level's matrices one by one;
// the same candidates and capped simplex solve (core/internal/influence_cap.h).
#pragma once

#include <span>

#include "core/influence_cap.h"
#include "core/motion.h"

namespace motionlod::core {

// InfluenceCapJob's result for `character` and `motion` (T frames) with `matrices`
// (T x m, frame-major) of `level`.
LevelInfluences InfluenceCapReference(const Character& character, const Motion& motion,
                                      const ReducedSkeleton& level,
                                      std::span<const RowMajorAffine34f> matrices, int cap,
                                      double normal_weight);

}  // namespace motionlod::core
