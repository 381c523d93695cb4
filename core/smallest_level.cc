#include "core/smallest_level.h"

#include <algorithm>
#include <string>

#include "core/internal/level_errors.h"
#include "core/internal/level_search.h"
#include "core/internal/level_solve.h"
#include "core/internal/prepared_data.h"
#include "core/reduce_skeleton.h"

namespace motionlod::core {
namespace internal {

StatusOr<std::shared_ptr<const PreparedMotion>> EveryNthFrame(const PreparedMotion& prepared,
                                                              int stride) {
  if (stride < 1) return InvalidArgument("EveryNthFrame: the stride must be at least 1");
  std::vector<int> frames;
  for (int t = 0; t < prepared.frame_count(); t += stride) {
    frames.push_back(t);
    if (t > prepared.frame_count() - stride) break;  // t + stride would pass the end or overflow
  }
  return SelectFrames(prepared.data(), frames);
}

StatusOr<bool> MaxVertexErrorWithin(const PreparedMotion& prepared, const ReducedSkeleton& level,
                                    double bound_pct) {
  if (!(bound_pct > 0)) return InvalidArgument("MaxVertexErrorWithin: the bound must be positive");
  const PreparedData& d = prepared.data();
  auto solution = SolveVariant(d, level);
  if (!solution.ok()) return solution.status();
  LevelErrors errors;
  const double bound = bound_pct / 100.0 * d.character->height();
  EvaluateErrors(d, solution->Delta(d, level), level.kept_joints, Figures::kMaxVertexError, errors,
                 bound);
  return errors.max_vertex_error_pct <= bound_pct;
}

}  // namespace internal

Status SmallestLevelJob::Validate() const {
  if (prepared == nullptr || ranking == nullptr) {
    return InvalidArgument("SmallestLevelJob: no prepared motion or ranking");
  }
  const int n = prepared->character().joint_count();
  if (static_cast<int>(ranking->removal_order.size()) != n) {
    return InvalidArgument("SmallestLevelJob: the ranking is of another skeleton");
  }
  if (fewest < std::max(1, ranking->locked_count) || most < fewest || most > n) {
    return InvalidArgument("SmallestLevelJob: the counts must satisfy locked joints <= fewest (" +
                           std::to_string(fewest) + ") <= most (" + std::to_string(most) +
                           ") <= " + std::to_string(n));
  }
  if (!(bound_pct > 0)) return InvalidArgument("SmallestLevelJob: the bound must be positive");
  return Status::Ok();
}

StatusOr<int> SmallestLevelJob::Run() const {
  if (Status status = Validate(); !status.ok()) return status;
  int lo = fewest, hi = most;
  if (lo == hi) return hi;
  const int stride = (prepared->frame_count() + kProbeFrames - 1) / kProbeFrames;
  std::shared_ptr<const PreparedMotion> strided;
  if (stride > 1) {
    auto made = internal::EveryNthFrame(*prepared, stride);
    if (!made.ok()) return made.status();
    strided = *std::move(made);
  }
  const PreparedMotion& probe = strided ? *strided : *prepared;
  while (lo < hi) {
    const int mid = lo + (hi - lo) / 2;
    auto level = ReduceSkeletonToCount(probe.character(), *ranking, mid);
    if (!level.ok()) return level.status();
    auto within = internal::MaxVertexErrorWithin(probe, *level, bound_pct);
    if (!within.ok()) return within.status();
    if (*within) {
      hi = mid;
    } else {
      lo = mid + 1;
    }
  }
  return hi;
}

}  // namespace motionlod::core
