#include "core/greedy_ranking.h"

#include <algorithm>
#include <atomic>
#include <limits>
#include <memory>
#include <mutex>
#include <numeric>
#include <vector>

#include "core/internal/level_errors.h"
#include "core/internal/level_solve.h"
#include "core/internal/prepared_data.h"
#include "core/reduce_skeleton.h"

namespace motionlod::core {
namespace {

constexpr double kInfinity = std::numeric_limits<double>::infinity();

// A candidate's score: the level's maximum vertex error (percent of the height) and mean E,
// or, where `decided_above`, only a maximum past the bound it was decided against.
struct Score {
  double max_pct = kInfinity;
  double mean_e = kInfinity;
  bool decided_above = false;
};

// Whether candidate a (score sa) is removed before b.
bool Before(const Score& sa, int a, const Score& sb, int b) {
  if (sa.max_pct != sb.max_pct) return sa.max_pct < sb.max_pct;
  if (sa.mean_e != sb.mean_e) return sa.mean_e < sb.mean_e;
  return a > b;
}

// A level solved on the probe: decided against `bound_pct` first
// where it is finite, exactly where it is within it.
StatusOr<Score> ScoreLevel(const internal::PreparedData& probe, const ReducedSkeleton& level,
                           double bound_pct) {
  auto solution = internal::SolveVariant(probe, level);
  if (!solution.ok()) return solution.status();
  const internal::DeltaView delta = solution->Delta(probe, level);
  const double height = probe.character->height();
  LevelErrors errors;
  if (std::isfinite(bound_pct)) {
    internal::EvaluateErrors(probe, delta, level.kept_joints, internal::Figures::kMaxVertexError,
                             errors, bound_pct / 100.0 * height);
    if (errors.max_vertex_error_pct > bound_pct) {
      return Score{errors.max_vertex_error_pct, kInfinity, true};
    }
  }
  internal::EvaluateErrors(probe, delta, level.kept_joints, internal::Figures::kMaxVertexError, errors);
  internal::EvaluateErrors(probe, delta, level.kept_joints, internal::Figures::kQuadratic, errors);
  return Score{errors.max_vertex_error_pct, errors.mean_e, false};
}

}  // namespace

std::vector<int> ProbeFrames(std::span<const MotionClip> clips, int per_clip) {
  std::vector<int> frames;
  for (const MotionClip& clip : clips) {
    if (per_clip <= 0 || clip.frame_count <= per_clip) {
      for (int t = 0; t < clip.frame_count; ++t) frames.push_back(clip.first_frame + t);
      continue;
    }
    // Evenly spaced from the first frame to the last.
    for (int i = 0; i < per_clip; ++i) {
      frames.push_back(clip.first_frame +
                       static_cast<int>(static_cast<int64_t>(i) * (clip.frame_count - 1) / (per_clip - 1)));
    }
  }
  return frames;
}

Status GreedyRankingJob::Validate() const {
  if (prepared == nullptr) return InvalidArgument("GreedyRankingJob: no prepared motion");
  if (probe_frames_per_clip < 0) {
    return InvalidArgument("GreedyRankingJob: probe_frames_per_clip must be >= 0 (0 = every frame)");
  }
  std::string unknown;
  for (const std::string& name : locked_joints) {
    if (prepared->character().FindJoint(name) < 0) unknown += (unknown.empty() ? "'" : ", '") + name + "'";
  }
  if (!unknown.empty()) return NotFound("locked joints not in the skeleton: " + unknown);
  return Status::Ok();
}

StatusOr<JointRanking> GreedyRankingJob::Run(const PieceRunner& run) const {
  if (Status status = Validate(); !status.ok()) return status;
  const Character& c = prepared->character();
  const int n = c.joint_count();
  auto probe = internal::SelectFrames(
      prepared->data(), ProbeFrames(prepared->clips(), probe_frames_per_clip));
  if (!probe.ok()) return probe.status();
  const internal::PreparedData& d = (*probe)->data();

  JointRanking ranking;
  ranking.priority.assign(n, kInfinity);
  std::vector<uint8_t> locked(n, 0), keep(n, 1);
  locked[0] = 1;
  for (const std::string& name : locked_joints) locked[c.FindJoint(name)] = 1;
  ranking.locked_count = static_cast<int>(std::count(locked.begin(), locked.end(), 1));

  // The last score of every joint, the order the next step tries them in.
  std::vector<Score> last(n, Score{0.0, 0.0, false});
  for (int step = 0; step < n - ranking.locked_count; ++step) {
    std::vector<int> candidates;
    for (int j = 0; j < n; ++j) {
      if (keep[j] && !locked[j]) candidates.push_back(j);
    }
    std::sort(candidates.begin(), candidates.end(),
              [&](int a, int b) { return Before(last[a], a, last[b], b); });
    std::mutex mutex;
    Score best;  // guarded by mutex
    int best_joint = -1;
    Status error;
    std::atomic<size_t> next{0};
    // Each piece takes the next candidate in order: with pieces run in order (one thread),
    // the first candidates set the bound the others are decided against.
    RunPieces(run, static_cast<int>(candidates.size()), [&](int) {
      const int j = candidates[next++];
      const auto flags = std::make_unique<bool[]>(n);
      for (int k = 0; k < n; ++k) flags[k] = keep[k] && k != j;
      auto level = ReduceSkeleton(c, std::span<const bool>(flags.get(), n));
      double bound;
      {
        std::lock_guard lock(mutex);
        bound = best.max_pct;
      }
      StatusOr<Score> score = level.ok() ? ScoreLevel(d, *level, bound) : StatusOr<Score>(level.status());
      std::lock_guard lock(mutex);
      if (!score.ok()) {
        error = score.status();
        return;
      }
      last[j] = *score;
      if (!score->decided_above && (best_joint < 0 || Before(*score, j, best, best_joint))) {
        best = *score;
        best_joint = j;
      }
    });
    if (!error.ok()) return error;
    keep[best_joint] = 0;
    ranking.priority[best_joint] = best.max_pct;
    ranking.removal_order.push_back(best_joint);
  }
  // The locked joints last, the root at the very end.
  for (int j = n - 1; j >= 0; --j) {
    if (locked[j]) ranking.removal_order.push_back(j);
  }
  return ranking;
}

}  // namespace motionlod::core
