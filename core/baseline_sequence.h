// The baseline figures (PreparedMotion::BaselineErrors: kept joints keep their original
// matrices, the removed joints' weights moved) of nested levels, each level from the one
// before. Going to a level that keeps a subset of the last one's joints changes Delta_k
// only for the joints whose nearest kept joint changes; only the joint pairs, sampled
// vertices and clusters of vertices that they weight are evaluated again, and the maximum
// search starts from the last maximum when the vertex that attained it is not among them.
// The baselines of every level (n, n-1, ..., 1 joints) then cost about two levels'
// instead of n. The figures are BaselineErrors' to rounding (of equal maxima, another
// vertex may be named). Its reference is BaselineErrors itself, level by level.
#pragma once

#include <memory>

#include "core/reduce_skeleton.h"
#include "core/solve_levels.h"

namespace motionlod::core {

// Not thread-safe.
class BaselineSequence {
 public:
  explicit BaselineSequence(std::shared_ptr<const PreparedMotion> prepared);
  ~BaselineSequence();
  // `level` keeps a subset of the joints of the level before it (any level, first).
  StatusOr<LevelErrors> Next(const ReducedSkeleton& level);

 private:
  struct State;
  std::unique_ptr<State> state_;
};

}  // namespace motionlod::core
