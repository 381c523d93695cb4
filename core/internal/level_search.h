// The probes of SmallestLevelJob (core/smallest_level.h), exposed for their tests.
#pragma once

#include <memory>

#include "core/reduce_skeleton.h"
#include "core/solve_levels.h"

namespace motionlod::core::internal {

// The same prepared motion on frames 0, stride, 2 stride, ... (stride >= 1): alpha and beta
// stay the motion's, and the normal matrix does not depend on the frames, so a level
// solved on it has the full motion's solution on those frames, to rounding. Costs a copy
// of those frames' columns and a new sample, not a Create.
StatusOr<std::shared_ptr<const PreparedMotion>> EveryNthFrame(const PreparedMotion& prepared,
                                                              int stride);

// Whether the level's optimised maximum vertex error is at most bound_pct > 0, decided
// without finding the maximum: the search stops at the first vertex past the bound.
StatusOr<bool> MaxVertexErrorWithin(const PreparedMotion& prepared, const ReducedSkeleton& level,
                                    double bound_pct);

}  // namespace motionlod::core::internal
