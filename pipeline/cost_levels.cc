// The cheapest level within a budget (pipeline/cost_levels.h).
#include "pipeline/cost_levels.h"

#include <algorithm>
#include <numeric>
#include <string>

#include "core/pose_rate.h"
#include "core/reduce_skeleton.h"

namespace motionlod::pipeline {
namespace {

// Shares of the budget the simplified mesh may take, the rest left to the skeleton, the
// influences and the pose rate; 0 keeps the original mesh.
// A simplified surface deviates two to four times its bind-pose error once skinned (measured
// on CesiumMan, Fox and RobotExpressive), hence the small shares.
constexpr double kMeshShares[] = {0.3, 0.2, 0.12, 0.07};
// The skeleton is searched within this part of what the mesh leaves, the rest for the
// influence cap and the pose rate.
constexpr double kSkeletonShare = 0.6;
// Probes of the search must stay this far within the budget; the level chosen is then
// measured on every frame.
constexpr double kProbeMargin = 0.9;
// About this many frames probed per search step.
constexpr int kProbeFrames = 96;
// A simplification that keeps more of the triangles than this is not worth a mesh.
constexpr double kMostTrianglesKept = 0.8;

double MeanInfluences(const core::RawSkin& skin) {
  return static_cast<double>(skin.influence_joints.size()) /
         static_cast<double>(skin.positions.size());
}

int MostInfluences(const core::RawSkin& skin) {
  uint32_t most = 1;
  for (size_t i = 0; i + 1 < skin.influence_offsets.size(); ++i) {
    most = std::max(most, skin.influence_offsets[i + 1] - skin.influence_offsets[i]);
  }
  return static_cast<int>(std::min<uint32_t>(most, core::kMaxInfluencesPerVertex));
}

// A frame step of about frames / kProbeFrames, prime to 2 and 3 so that the probe sees
// frames between stored ones at every stride up to 4.
int ProbeStep(int frames) {
  int step = std::max(1, frames / kProbeFrames);
  while (step > 1 && (step % 2 == 0 || step % 3 == 0)) ++step;
  return step;
}

struct Candidate {
  CostLevel level;
  double probed_pct = 0;
};

}  // namespace

double LevelCost(const core::Character& character, double vertices, double mean_influences,
                 int joints) {
  const core::RawSkin& skin = character.skin();
  const double full = static_cast<double>(skin.positions.size()) * MeanInfluences(skin) +
                      kJointCost * character.joint_count();
  return (vertices * mean_influences + kJointCost * joints) / full;
}

StatusOr<CostLevel> FullDetailLevel(const core::PreparedMotion& prepared) {
  const core::Character& character = prepared.character();
  CostLevel level;
  std::unique_ptr<bool[]> every(new bool[character.joint_count()]);
  std::fill_n(every.get(), character.joint_count(), true);
  auto skeleton =
      core::ReduceSkeleton(character, std::span<const bool>(every.get(), character.joint_count()));
  if (!skeleton.ok()) return skeleton.status();
  level.skeleton = *std::move(skeleton);
  auto influences =
      core::TruncateInfluences(character, level.skeleton, MostInfluences(character.skin()));
  if (!influences.ok()) return influences.status();
  level.influences = *std::move(influences);
  auto solved = prepared.SolveLevel(level.skeleton);  // the full level is the original matrices
  if (!solved.ok()) return solved.status();
  level.stored_matrices = std::move(solved->matrices);
  level.cost = 1;
  return level;
}

Status CheapestLevelJob::Validate() const {
  if (!prepared || ranking == nullptr || motion == nullptr) {
    return InvalidArgument("CheapestLevelJob: no prepared motion, motion or ranking");
  }
  if (static_cast<int>(ranking->removal_order.size()) != prepared->character().joint_count()) {
    return InvalidArgument("CheapestLevelJob: the ranking is of another skeleton");
  }
  if (!(budget_pct > 0)) return InvalidArgument("CheapestLevelJob: the budget must be positive");
  if (caps.empty() || !std::is_sorted(caps.begin(), caps.end()) || caps.front() < 1 ||
      caps.back() > core::kMaxInfluencesPerVertex) {
    return InvalidArgument("CheapestLevelJob: the caps must ascend within [1, " +
                           std::to_string(core::kMaxInfluencesPerVertex) + "]");
  }
  if (max_frame_stride < 1 || max_frame_stride > core::kMaxFrameStride) {
    return InvalidArgument("CheapestLevelJob: the frame stride must be 1 to " +
                           std::to_string(core::kMaxFrameStride));
  }
  return Status::Ok();
}

StatusOr<std::optional<CostLevel>> CheapestLevelJob::Run(TaskPool& pool) const {
  if (Status status = Validate(); !status.ok()) return status;
  const core::PreparedMotion& original = *prepared;
  const core::Character& character = original.character();
  const core::SolveSettings& settings = original.settings();
  const bool rigid = core::IsRigid(settings.variant);
  // The budget is on positions: the weights fit them alone.
  constexpr double normal_weight = 0;
  const int n = character.joint_count(), fewest = std::max(1, ranking->locked_count);
  const int probe_step = ProbeStep(original.frame_count());
  const double budget_length = budget_pct / 100.0 * character.height();

  auto deviation_of = [&](const CostLevel& level, int step) {
    const core::LevelDeviationJob job{prepared.get(),
                                      &level.skeleton,
                                      level.mesh ? &*level.mesh : nullptr,
                                      &level.influences,
                                      level.stored_matrices,
                                      level.frame_stride,
                                      rigid,
                                      step};
    return job.Run(pool.Runner());
  };

  // Every way of simplifying the mesh, then the original mesh (share 0).
  std::vector<std::pair<double, core::SkinSplit>> meshes;
  for (core::SkinSplit split : {core::SkinSplit::kDominantJoint, core::SkinSplit::kWeightBands}) {
    for (double share : kMeshShares) meshes.emplace_back(share, split);
  }
  meshes.emplace_back(0.0, core::SkinSplit::kNone);
  std::vector<Candidate> candidates;
  for (const auto& [share, split] : meshes) {
    CostLevel level;
    std::shared_ptr<const core::PreparedMotion> solve_on = prepared;
    if (share > 0) {
      auto mesh = core::SimplifyMeshJob{&character, 1, share * budget_length, split}.Run();
      if (!mesh.ok()) return mesh.status();
      if (mesh->triangles.size() > kMostTrianglesKept * character.skin().triangles.size()) continue;
      auto subset = core::SubsetCharacter(character, *mesh);
      if (!subset.ok()) return subset.status();
      auto made = core::PreparedMotion::Create(*subset, *motion, settings, simd, pool.Runner());
      if (!made.ok()) return made.status();
      solve_on = *std::move(made);
      level.mesh = *std::move(mesh);
    }
    // The fewest joints whose solved error on the level's vertices fits the skeleton's share.
    const double skeleton_pct = kSkeletonShare * (1 - share) * budget_pct;
    std::optional<core::LevelResult> chosen;
    const int most = std::clamp(max_joints, fewest, n);
    int lo = fewest, hi = most;
    while (lo <= hi) {
      const int mid = lo + (hi - lo) / 2;
      auto skeleton = core::ReduceSkeletonToCount(solve_on->character(), *ranking, mid);
      if (!skeleton.ok()) return skeleton.status();
      auto solved = solve_on->SolveLevel(*skeleton);
      if (!solved.ok()) return solved.status();
      if (solved->optimized.max_vertex_error_pct <= skeleton_pct || mid == most) {
        chosen = *std::move(solved);
        hi = mid - 1;
      } else {
        lo = mid + 1;
      }
    }
    level.skeleton = chosen->skeleton;
    for (int cap : caps) {
      auto influences = core::InfluenceCapJob{solve_on.get(), &level.skeleton, chosen->matrices,
                                              cap, normal_weight}
                            .Run();
      if (!influences.ok()) return influences.status();
      std::vector<core::RowMajorAffine34f> matrices = chosen->matrices;
      if (!rigid) {  // affine levels: a matrix step, then the weights again
        auto stepped =
            core::InfluenceMatrixJob{solve_on.get(), &level.skeleton, matrices,
                                     &*influences,   normal_weight,   settings.regularization}
                .Run();
        if (!stepped.ok()) return stepped.status();
        matrices = *std::move(stepped);
        influences =
            core::InfluenceCapJob{solve_on.get(), &level.skeleton, matrices, cap, normal_weight}
                .Run();
        if (!influences.ok()) return influences.status();
      }
      level.influences = *std::move(influences);
      bool fits = false;
      Candidate best;
      for (int stride = 1; stride <= max_frame_stride; ++stride) {
        auto stored =
            core::StoreAtStride(matrices, level.skeleton.kept_count(), original.clips(), stride);
        if (!stored.ok()) return stored.status();
        level.frame_stride = stride;
        level.stored_matrices = *std::move(stored);
        auto probed = deviation_of(level, probe_step);
        if (!probed.ok()) return probed.status();
        if (probed->max_pct > kProbeMargin * budget_pct) break;
        fits = true;
        best = {level, probed->max_pct};
      }
      if (fits) {
        best.level.cost =
            LevelCost(character, best.level.vertex_count(character),
                      best.level.influences.mean_used(), best.level.skeleton.kept_count());
        candidates.push_back(std::move(best));
        break;  // a larger cap costs more at the same vertices and joints
      }
    }
  }
  std::sort(candidates.begin(), candidates.end(),
            [](const Candidate& a, const Candidate& b) { return a.level.cost < b.level.cost; });
  for (Candidate& candidate : candidates) {
    auto measured = deviation_of(candidate.level, 1);
    if (!measured.ok()) return measured.status();
    if (measured->max_pct <= budget_pct && candidate.level.cost < 1) {
      candidate.level.deviation = *std::move(measured);
      return std::optional<CostLevel>(std::move(candidate.level));
    }
  }
  return std::optional<CostLevel>();
}

Status CostLadderJob::Validate() const {
  if (heights_px.empty() || !std::is_sorted(heights_px.rbegin(), heights_px.rend()) ||
      !(heights_px.back() > 0)) {
    return InvalidArgument("CostLadderJob: the pixel heights must be positive and decreasing");
  }
  if (!(budget_px > 0)) return InvalidArgument("CostLadderJob: the budget must be positive");
  return CheapestLevelJob{prepared, motion, ranking, simd}.Validate();
}

StatusOr<std::vector<CostLevel>> CostLadderJob::Run(TaskPool& pool) const {
  if (Status status = Validate(); !status.ok()) return status;
  std::vector<CostLevel> ladder;
  auto full = FullDetailLevel(*prepared);
  if (!full.ok()) return full.status();
  ladder.push_back(*std::move(full));
  for (double height : heights_px) {
    CheapestLevelJob job{prepared, motion, ranking, simd};
    job.budget_pct = 100.0 * budget_px / height;
    job.max_joints = ladder.back().skeleton.kept_count();
    auto found = job.Run(pool);
    if (!found.ok()) return found.status();
    // A coarser budget also admits every finer level: a new level only where it is cheaper.
    if (*found && (*found)->cost < ladder.back().cost) ladder.push_back(**std::move(found));
  }
  return ladder;
}

}  // namespace motionlod::pipeline
