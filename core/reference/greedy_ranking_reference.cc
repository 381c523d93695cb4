#include "core/reference/greedy_ranking_reference.h"

#include <algorithm>
#include <limits>
#include <memory>
#include <vector>

#include "core/internal/prepared_data.h"
#include "core/reduce_skeleton.h"

namespace motionlod::core {

StatusOr<JointRanking> GreedyRankingReference(const GreedyRankingJob& job) {
  const Character& c = job.prepared->character();
  const int n = c.joint_count();
  auto probe = internal::SelectFrames(
      job.prepared->data(), ProbeFrames(job.prepared->clips(), job.probe_frames_per_clip));
  if (!probe.ok()) return probe.status();
  JointRanking ranking;
  ranking.priority.assign(n, std::numeric_limits<double>::infinity());
  std::vector<bool> locked(n, false), keep(n, true);
  locked[0] = true;
  for (const std::string& name : job.locked_joints) locked[c.FindJoint(name)] = true;
  for (int j = 0; j < n; ++j) ranking.locked_count += locked[j];
  for (int step = 0; step < n - ranking.locked_count; ++step) {
    std::vector<int> joints;
    std::vector<double> max_pct, mean_e;
    for (int j = 0; j < n; ++j) {
      if (!keep[j] || locked[j]) continue;
      const auto flags = std::make_unique<bool[]>(n);
      for (int k = 0; k < n; ++k) flags[k] = keep[k] && k != j;
      auto level = ReduceSkeleton(c, std::span<const bool>(flags.get(), n));
      if (!level.ok()) return level.status();
      auto errors =
          job.reparented ? (*probe)->BaselineErrors(*level) : [&]() -> StatusOr<LevelErrors> {
        auto solved = (*probe)->SolveLevel(*level);
        if (!solved.ok()) return solved.status();
        return solved->optimized;
      }();
      if (!errors.ok()) return errors.status();
      joints.push_back(j);
      max_pct.push_back(errors->max_vertex_error_pct);
      mean_e.push_back(errors->mean_e);
    }
    const int best = GreedyPick(joints, max_pct, mean_e);
    const double best_max = max_pct[std::find(joints.begin(), joints.end(), best) - joints.begin()];
    keep[best] = false;
    ranking.priority[best] = best_max;
    ranking.removal_order.push_back(best);
  }
  for (int j = n - 1; j >= 0; --j) {
    if (locked[j]) ranking.removal_order.push_back(j);
  }
  return ranking;
}

}  // namespace motionlod::core
