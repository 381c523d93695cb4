#include "core/greedy_ranking.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <numeric>
#include <optional>
#include <vector>

#include "core/internal/level_errors.h"
#include "core/internal/level_solve.h"
#include "core/internal/prepared_data.h"
#include "core/reduce_skeleton.h"

namespace motionlod::core {
namespace {

using internal::Figures;

constexpr double kInfinity = std::numeric_limits<double>::infinity();

// A candidate's score: the level's maximum vertex error (percent of the height) and mean E,
// or, where `decided_above`, only a maximum past the bound it was decided against.
struct Score {
  double max_pct = kInfinity;
  double mean_e = kInfinity;
  bool decided_above = false;
};

// Whether candidate a (score sa) is tried before b: the order of the last scores.
bool Before(const Score& sa, int a, const Score& sb, int b) {
  if (sa.max_pct != sb.max_pct) return sa.max_pct < sb.max_pct;
  if (sa.mean_e != sb.mean_e) return sa.mean_e < sb.mean_e;
  return a > b;
}

// The largest value that ties with `value` (GreedyPick).
double TieLimit(double value) { return value + kGreedyTieTolerance * std::abs(value); }

// The score of the level SolveLevel writes on the probe (the solution, or the reparented
// level where the solution is worse: KeepNoWorseThanReparenting), or of the reparented
// level alone. Decided against `bound_pct` first where it is finite, exact within it.
StatusOr<Score> ScoreLevel(const internal::PreparedData& probe, const ReducedSkeleton& level,
                           bool reparented_only, double bound_pct) {
  const double height = probe.character->height();
  const auto decide = [&](const internal::DeltaView& delta, double within_pct,
                          Figures figures) -> std::optional<LevelErrors> {
    LevelErrors errors;
    if (std::isfinite(within_pct)) {
      internal::EvaluateErrors(probe, delta, level.kept_joints, internal::Figures::kMaxVertexError,
                               errors, within_pct / 100.0 * height);
      if (errors.max_vertex_error_pct > within_pct) return std::nullopt;
    }
    internal::EvaluateErrors(probe, delta, level.kept_joints, figures, errors);
    if (figures == internal::Figures::kQuadratic) {
      internal::EvaluateErrors(probe, delta, level.kept_joints, internal::Figures::kMaxVertexError,
                               errors);
    }
    return errors;
  };
  const internal::DeltaView reparented = internal::BaselineDelta(probe, level);
  if (reparented_only) {
    const auto errors = decide(reparented, bound_pct, internal::Figures::kQuadratic);
    if (!errors) return Score{std::nextafter(bound_pct, kInfinity), kInfinity, true};
    return Score{errors->max_vertex_error_pct, errors->mean_e, false};
  }
  auto solution = internal::SolveVariant(probe, level);
  if (!solution.ok()) return solution.status();
  const internal::DeltaView solved = solution->Delta(probe, level);
  if (!internal::ReparentingIsCandidate(probe)) {
    const auto errors = decide(solved, bound_pct, internal::Figures::kQuadratic);
    if (!errors) return Score{std::nextafter(bound_pct, kInfinity), kInfinity, true};
    return Score{errors->max_vertex_error_pct, errors->mean_e, false};
  }
  // The reparented level bounds what is written: the solution counts only within it.
  const LevelErrors base = *decide(reparented, kInfinity, internal::Figures::kAll);
  const auto own =
      decide(solved, std::min(bound_pct, base.max_vertex_error_pct), internal::Figures::kAll);
  const bool solution_written = own && internal::NoWorseThan(*own, base);
  const LevelErrors& written = solution_written ? *own : base;
  if (written.max_vertex_error_pct > bound_pct)
    return Score{written.max_vertex_error_pct, kInfinity, true};
  return Score{written.max_vertex_error_pct, written.mean_e, false};
}

}  // namespace

int GreedyPick(std::span<const int> joints, std::span<const double> max_pct,
               std::span<const double> mean_e) {
  const double lowest_max = *std::min_element(max_pct.begin(), max_pct.end());
  double lowest_mean = kInfinity;
  for (size_t i = 0; i < joints.size(); ++i) {
    if (max_pct[i] <= TieLimit(lowest_max)) lowest_mean = std::min(lowest_mean, mean_e[i]);
  }
  int pick = -1;
  for (size_t i = 0; i < joints.size(); ++i) {
    if (max_pct[i] <= TieLimit(lowest_max) && mean_e[i] <= TieLimit(lowest_mean)) {
      pick = std::max(pick, joints[i]);
    }
  }
  return pick;
}

std::vector<int> ProbeFrames(std::span<const MotionClip> clips, int per_clip) {
  std::vector<int> frames;
  for (const MotionClip& clip : clips) {
    if (per_clip <= 0 || clip.frame_count <= per_clip) {
      for (int t = 0; t < clip.frame_count; ++t) frames.push_back(clip.first_frame + t);
      continue;
    }
    // Evenly spaced from the first frame to the last.
    for (int i = 0; i < per_clip; ++i) {
      frames.push_back(
          clip.first_frame +
          static_cast<int>(static_cast<int64_t>(i) * (clip.frame_count - 1) / (per_clip - 1)));
    }
  }
  return frames;
}

Status GreedyRankingJob::Validate() const {
  if (prepared == nullptr) return InvalidArgument("GreedyRankingJob: no prepared motion");
  if (probe_frames_per_clip < 0) {
    return InvalidArgument(
        "GreedyRankingJob: probe_frames_per_clip must be >= 0 (0 = every frame)");
  }
  std::string unknown;
  for (const std::string& name : locked_joints) {
    if (prepared->character().FindJoint(name) < 0)
      unknown += (unknown.empty() ? "'" : ", '") + name + "'";
  }
  if (!unknown.empty()) return NotFound("locked joints not in the skeleton: " + unknown);
  return Status::Ok();
}

StatusOr<JointRanking> GreedyRankingJob::Run(const PieceRunner& run) const {
  if (Status status = Validate(); !status.ok()) return status;
  const Character& c = prepared->character();
  const int n = c.joint_count();
  auto probe = internal::SelectFrames(prepared->data(),
                                      ProbeFrames(prepared->clips(), probe_frames_per_clip));
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
    // The candidate that scored best last time is scored exactly first; its maximum is
    // the bound every other candidate of the step is decided against, each in a piece of
    // its own writing only its own score.
    const auto score = [&](int j, double bound) -> StatusOr<Score> {
      const auto flags = std::make_unique<bool[]>(n);
      for (int k = 0; k < n; ++k) flags[k] = keep[k] && k != j;
      auto level = ReduceSkeleton(c, std::span<const bool>(flags.get(), n));
      if (!level.ok()) return level.status();
      return ScoreLevel(d, *level, reparented, bound);
    };
    std::vector<StatusOr<Score>> scores(candidates.size(), Score{});
    scores[0] = score(candidates[0], kInfinity);
    if (!scores[0].ok()) return scores[0].status();
    const double bound = TieLimit(scores[0]->max_pct);
    RunPieces(run, static_cast<int>(candidates.size()) - 1,
              [&](int piece) { scores[piece + 1] = score(candidates[piece + 1], bound); });
    std::vector<double> max_pct, mean_e;
    for (size_t i = 0; i < candidates.size(); ++i) {
      if (!scores[i].ok()) return scores[i].status();
      last[candidates[i]] = *scores[i];
      max_pct.push_back(scores[i]->max_pct);
      mean_e.push_back(scores[i]->mean_e);
    }
    const int best_joint = GreedyPick(candidates, max_pct, mean_e);
    keep[best_joint] = 0;
    ranking.priority[best_joint] = last[best_joint].max_pct;
    ranking.removal_order.push_back(best_joint);
  }
  // The locked joints last, the root at the very end.
  for (int j = n - 1; j >= 0; --j) {
    if (locked[j]) ranking.removal_order.push_back(j);
  }
  return ranking;
}

}  // namespace motionlod::core
