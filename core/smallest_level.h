// The fewest joints of the ranking's nested levels whose optimised maximum vertex error
// (LevelErrors::max_vertex_error_pct) stays within a bound: the skeleton of a level by cost
// (pipeline/cost_levels.h) within its share of the budget. Found by bisection between a count that fails (or
// the fewest a level may keep) and one that meets the bound. The error grows as joints go,
// though not strictly, so the count found meets the bound with the one below failing.
// Each probe solves a level on at most kProbeFrames evenly spaced frames of the motion and
// only decides whether its maximum is within the bound (core/internal/level_search.h):
// the probes steer the search, and the caller solves the level found on every frame.
#pragma once

#include "base/status.h"
#include "core/rank_joints.h"
#include "core/solve_levels.h"

namespace motionlod::core {

struct SmallestLevelJob {
  static constexpr int kProbeFrames = 64;

  const PreparedMotion* prepared = nullptr;
  const JointRanking* ranking = nullptr;
  int fewest = 1;          // the fewest joints a level may keep (or one known to fail), >= 1
  int most = 0;            // a count known to meet the bound (never probed), >= fewest
  double bound_pct = 10;   // percent of the character's height, > 0

  Status Validate() const;
  // The fewest joints found within the bound, in [fewest, most].
  StatusOr<int> Run() const;
};

}  // namespace motionlod::core
