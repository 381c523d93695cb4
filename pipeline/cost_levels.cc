// The cheapest level within a budget (pipeline/cost_levels.h).
#include "pipeline/cost_levels.h"

#include <algorithm>
#include <numeric>
#include <span>
#include <string>

#include "core/pose_rate.h"
#include "core/reduce_skeleton.h"
#include "core/smallest_level.h"

namespace motionlod::pipeline {
namespace {

// Shares of the budget a simplified mesh may take (its bind-pose error), the rest left to
// the skeleton, the influences and the pose rate; the whole mesh is tried besides. Once
// skinned, the levels chosen are 2.5 to 12 times their mesh's bind-pose error off
// (motionlod_bench_cost_ladder, its mesh% column), hence the small shares.
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

// Every one of `vertices` vertices bound to one influence of weight 1 (`weights` one per
// vertex): the skinner's path without a blend.
bool OneInfluenceEach(std::span<const float> weights, size_t vertices) {
  return weights.size() == vertices &&
         std::all_of(weights.begin(), weights.end(), [](float w) { return w == 1.0f; });
}

// The modelled units of one frame (the header's model).
double CostUnits(const DrawnLevel& level) {
  const double per_vertex = level.one_influence_each ? kSingleInfluenceVertexCost
                                                     : kVertexCost + level.mean_influences;
  const double interpolated_share = 1 - 1.0 / level.frame_stride;
  return kDrawCost + level.vertices * per_vertex +
         level.joints * (kJointCost + kInterpolatedJointCost * interpolated_share);
}

// A frame step of about frames / kProbeFrames, prime to 2 and 3 so that the probe sees
// frames between stored ones at every stride up to 4.
int ProbeStep(int frames) {
  int step = std::max(1, frames / kProbeFrames);
  while (step > 1 && (step % 2 == 0 || step % 3 == 0)) ++step;
  return step;
}

}  // namespace

double LevelCost(const core::Character& character, const DrawnLevel& level) {
  const core::RawSkin& skin = character.skin();
  const bool one_each = OneInfluenceEach(skin.influence_weights, skin.positions.size());
  const double influences = static_cast<double>(skin.influence_joints.size());
  const DrawnLevel full{static_cast<double>(skin.positions.size()),
                        influences / static_cast<double>(skin.positions.size()), one_each,
                        character.joint_count(), 1};
  return CostUnits(level) / CostUnits(full);
}

CostLevel SkeletonLevel(const core::Character& character, const core::LevelResult& solved) {
  CostLevel level;
  level.skeleton = solved.skeleton;
  level.stored_matrices = solved.matrices;
  level.deviation.max_pct = solved.optimized.max_vertex_error_pct;
  level.deviation.mean_pct = solved.optimized.mean_vertex_error_pct;
  level.deviation.max_frame = solved.optimized.max_vertex_frame;
  level.deviation.max_vertex = solved.optimized.max_vertex_index;
  for (const core::LevelErrors& clip : solved.optimized.per_clip) {
    core::LevelDeviation figures;
    figures.max_pct = clip.max_vertex_error_pct;
    figures.mean_pct = clip.mean_vertex_error_pct;
    figures.max_frame = clip.max_vertex_frame;
    figures.max_vertex = clip.max_vertex_index;
    level.deviation.per_clip.push_back(figures);
  }
  const core::ReducedInfluences merged = core::ReduceInfluences(character.skin(), solved.skeleton);
  level.mean_influences = static_cast<double>(merged.slots.size()) / character.vertex_count();
  const bool one_each =
      OneInfluenceEach(merged.weights, static_cast<size_t>(character.vertex_count()));
  level.cost = LevelCost(character, {static_cast<double>(character.vertex_count()),
                                     level.mean_influences, one_each,
                                     solved.skeleton.kept_count(), 1});
  return level;
}

StatusOr<CostLevel> FullDetailLevel(const core::PreparedMotion& prepared) {
  const core::Character& character = prepared.character();
  std::unique_ptr<bool[]> every(new bool[character.joint_count()]);
  std::fill_n(every.get(), character.joint_count(), true);
  auto skeleton =
      core::ReduceSkeleton(character, std::span<const bool>(every.get(), character.joint_count()));
  if (!skeleton.ok()) return skeleton.status();
  auto solved = prepared.SolveLevel(*skeleton);  // the full level is the original matrices
  if (!solved.ok()) return solved.status();
  return SkeletonLevel(character, *solved);
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

  // A candidate's level and the influences it is measured with (its own, or the mesh's
  // merged through the joint map where influences are not cut).
  struct Candidate {
    CostLevel level;
    core::LevelInfluences measured_influences;
  };
  auto deviation_of = [&](const Candidate& candidate, int step) {
    const CostLevel& level = candidate.level;
    const core::LevelDeviationJob job{prepared.get(),
                                      &level.skeleton,
                                      level.mesh ? &*level.mesh : nullptr,
                                      &candidate.measured_influences,
                                      level.stored_matrices,
                                      level.frame_stride,
                                      rigid,
                                      step};
    return job.Run(pool.Runner());
  };

  // A candidate of `level`'s mesh (none: the whole) keeping `kept` joints, solved on
  // `solve_on` (the character, or its subset on that mesh): the smallest cap, then the
  // largest stride, whose probe fits; none where no cap fits.
  std::vector<Candidate> candidates;
  auto try_skeleton = [&](CostLevel level, const core::PreparedMotion& solve_on,
                          int kept) -> Status {
    auto skeleton = core::ReduceSkeletonToCount(solve_on.character(), *ranking, kept);
    if (!skeleton.ok()) return skeleton.status();
    auto chosen = solve_on.SolveLevel(*skeleton);
    if (!chosen.ok()) return chosen.status();
    level.skeleton = chosen->skeleton;
    // Cap 0: the mesh's influences merged through the joint map (none of the level's own).
    const std::vector<int> tried_caps = parts.influences ? caps : std::vector<int>{0};
    for (int cap : tried_caps) {
      auto influences = cap == 0 ? core::TruncateInfluences(solve_on.character(), level.skeleton,
                                                            core::kMaxInfluencesPerVertex)
                                 : core::InfluenceCapJob{&solve_on, &level.skeleton,
                                                         chosen->matrices, cap, normal_weight}
                                       .Run();
      if (!influences.ok()) return influences.status();
      std::vector<core::RowMajorAffine34f> matrices = chosen->matrices;
      if (!rigid && cap > 0) {  // affine levels: a matrix step, then the weights again
        auto stepped =
            core::InfluenceMatrixJob{&solve_on,    &level.skeleton, matrices,
                                     &*influences, normal_weight,   settings.regularization}
                .Run();
        if (!stepped.ok()) return stepped.status();
        matrices = *std::move(stepped);
        influences =
            core::InfluenceCapJob{&solve_on, &level.skeleton, matrices, cap, normal_weight}.Run();
        if (!influences.ok()) return influences.status();
      }
      Candidate candidate{level, *std::move(influences)};
      if (cap > 0) candidate.level.influences = candidate.measured_influences;
      candidate.level.mean_influences = candidate.measured_influences.mean_used();
      bool fits = false;
      Candidate best;
      for (int stride = 1; stride <= (parts.pose_rate ? max_frame_stride : 1); ++stride) {
        auto stored =
            core::StoreAtStride(matrices, level.skeleton.kept_count(), original.clips(), stride);
        if (!stored.ok()) return stored.status();
        candidate.level.frame_stride = stride;
        candidate.level.stored_matrices = *std::move(stored);
        auto probed = deviation_of(candidate, probe_step);
        if (!probed.ok()) return probed.status();
        if (probed->max_pct > kProbeMargin * budget_pct) break;
        fits = true;
        best = candidate;
      }
      if (fits) {
        best.level.cost = LevelCost(
            character, {static_cast<double>(best.level.vertex_count(character)),
                        best.level.mean_influences, cap == 1, best.level.skeleton.kept_count(),
                        best.level.frame_stride});
        candidates.push_back(std::move(best));
        return Status::Ok();  // a larger cap costs more at the same vertices and joints
      }
    }
    return Status::Ok();
  };

  // Every way of simplifying the mesh, then the original mesh (share 0).
  std::vector<std::pair<double, core::SkinSplit>> meshes;
  if (parts.vertices) {
    for (core::SkinSplit split : {core::SkinSplit::kDominantJoint, core::SkinSplit::kWeightBands}) {
      for (double share : kMeshShares) meshes.emplace_back(share, split);
    }
  }
  meshes.emplace_back(0.0, core::SkinSplit::kNone);
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
    // Two skeletons: the fewest joints whose solved error on the level's vertices fits the
    // skeleton's share (bisection on probe frames), and every joint the finer level keeps
    // (joints cost little: the rest of the budget may then go to the mesh and the rate).
    const double skeleton_pct = kSkeletonShare * (1 - share) * budget_pct;
    const int most = std::clamp(max_joints, fewest, n);
    auto count = core::SmallestLevelJob{solve_on.get(), ranking, parts.joints ? fewest : most, most,
                                        skeleton_pct}
                     .Run();
    if (!count.ok()) return count.status();
    std::vector<int> counts = {*count};
    if (most != *count) counts.push_back(most);
    for (int kept : counts) {
      if (Status status = try_skeleton(level, *solve_on, kept); !status.ok()) return status;
    }
  }
  std::sort(candidates.begin(), candidates.end(),
            [](const Candidate& a, const Candidate& b) { return a.level.cost < b.level.cost; });
  for (Candidate& candidate : candidates) {
    auto measured = deviation_of(candidate, 1);
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
  CheapestLevelJob job;
  job.prepared = prepared;
  job.motion = motion;
  job.ranking = ranking;
  return job.Validate();
}

StatusOr<std::vector<CostLevel>> CostLadderJob::Run(TaskPool& pool) const {
  if (Status status = Validate(); !status.ok()) return status;
  std::vector<CostLevel> ladder;
  auto full = FullDetailLevel(*prepared);
  if (!full.ok()) return full.status();
  ladder.push_back(*std::move(full));
  for (double height : heights_px) {
    CheapestLevelJob job;
    job.prepared = prepared;
    job.motion = motion;
    job.ranking = ranking;
    job.simd = simd;
    job.parts = parts;
    job.budget_pct = 100.0 * budget_px / height;
    job.max_joints = ladder.back().skeleton.kept_count();
    auto found = job.Run(pool);
    if (!found.ok()) return found.status();
    // A coarser budget also admits every finer level: a new level only where it is cheaper.
    if (*found && (*found)->cost < ladder.back().cost) ladder.push_back(**std::move(found));
  }
  // A level that a cheaper one after it matches in accuracy serves no height: dropped.
  double coarser_error = std::numeric_limits<double>::infinity();
  for (size_t l = ladder.size(); l-- > 1;) {
    if (ladder[l].deviation.max_pct >= coarser_error) {
      ladder.erase(ladder.begin() + static_cast<std::ptrdiff_t>(l));
    } else {
      coarser_error = ladder[l].deviation.max_pct;
    }
  }
  return ladder;
}

}  // namespace motionlod::pipeline
