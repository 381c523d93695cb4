#include "pipeline/bake.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>

#include "core/baseline_sequence.h"
#include "core/greedy_ranking.h"
#include "core/reduce_skeleton.h"
#include "core/skinning.h"
#include "io/retarget.h"
#include "pipeline/report.h"
#include "pipeline/task_pool.h"
#include "proto/level_format.h"

namespace motionlod::pipeline {
namespace {

using Clock = std::chrono::steady_clock;

double SecondsSince(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

bool Cancelled(const std::atomic<bool>* cancel) {
  return cancel != nullptr && cancel->load(std::memory_order_relaxed);
}

Status CancelledStatus() { return Status(StatusCode::kCancelled, "the bake was cancelled"); }

}  // namespace

Status BakeRequest::Validate() const {
  if (!character) return InvalidArgument("no character to bake");
  if (Status status = settings.Validate(); !status.ok()) return status;
  if (!(fps >= 0) || fps > 1000)
    return InvalidArgument("fps must be in [0, 1000] (0 = the source's)");
  if (max_joint_frames < 1) return InvalidArgument("max_joint_frames must be positive");
  for (int count : levels) {
    if (count < 1) return InvalidArgument("every level must keep at least one joint");
  }
  if (all_levels && !levels.empty()) {
    return InvalidArgument("ask for explicit levels or for all levels, not both");
  }
  if (!ladder_heights_px.empty()) {
    if (!levels.empty() || all_levels) {
      return InvalidArgument("ladder heights choose levels by cost: not with explicit levels");
    }
    if (ladder_heights_px.size() > kMaxLadderHeights ||
        !std::all_of(ladder_heights_px.begin(), ladder_heights_px.end(),
                     [](double px) { return px >= 1 && px <= 100000; }) ||
        std::adjacent_find(ladder_heights_px.begin(), ladder_heights_px.end(),
                           std::less_equal<>()) != ladder_heights_px.end()) {
      return InvalidArgument("ladder heights must decrease, each in [1, 100000] px, at most " +
                             std::to_string(kMaxLadderHeights));
    }
  }
  // Bake starts its pool's threads up front.
  if (threads < 0 || threads > kMaxThreads) {
    return InvalidArgument("threads must be in [0, " + std::to_string(kMaxThreads) +
                           "] (0 = one per hardware thread)");
  }
  return Status::Ok();
}

Status SolveLevelsJob::Validate() const {
  if (!prepared || ranking == nullptr)
    return InvalidArgument("SolveLevelsJob: no prepared motion or ranking");
  const int n = prepared->character().joint_count();
  for (size_t index = 0; index < counts.size(); ++index) {
    if (counts[index] < ranking->locked_count || counts[index] > n ||
        (index > 0 && counts[index] >= counts[index - 1])) {
      return InvalidArgument("SolveLevelsJob: the counts must decrease within [" +
                             std::to_string(ranking->locked_count) + ", " + std::to_string(n) +
                             "]");
    }
  }
  return Status::Ok();
}

StatusOr<std::map<int, core::LevelResult>> SolveLevelsJob::Run(TaskPool& pool) const {
  if (Status status = Validate(); !status.ok()) return status;
  const size_t count = counts.size();
  std::vector<core::ReducedSkeleton> levels;
  levels.reserve(count);
  for (int kept : counts) {
    auto level = core::ReduceSkeletonToCount(prepared->character(), *ranking, kept);
    if (!level.ok()) return level.status();
    levels.push_back(*std::move(level));
  }
  std::vector<std::optional<core::LevelResult>> results(count);
  std::vector<std::optional<core::LevelErrors>> baselines(count);
  // Levels a joint apart (every level) take their baselines one from the other, in one
  // task, the first (the longest); task i + 1 solves level i. Far apart levels change most
  // joints at each step: each baseline is a task of its own, task 2i solving level i and
  // task 2i + 1 its baseline.
  bool consecutive = count > 1;
  for (size_t index = 1; index < count; ++index) {
    consecutive = consecutive && counts[index] == counts[index - 1] - 1;
  }
  const size_t tasks = consecutive ? count + 1 : 2 * count;
  std::vector<Status> errors(tasks);
  std::vector<std::atomic<int>> halves_done(count);
  size_t reported = 0;
  pool.Run(
      static_cast<int>(tasks),
      [&](int task) {
        if (Cancelled(cancel)) return;
        const auto set_baseline = [&](size_t index, StatusOr<core::LevelErrors> baseline) {
          if (!baseline.ok()) {
            errors[task] = baseline.status();
            return false;
          }
          baselines[index] = *std::move(baseline);
          ++halves_done[index];
          return true;
        };
        if (consecutive && task == 0) {
          core::BaselineSequence sequence(prepared);
          for (size_t index = 0; index < count && !Cancelled(cancel); ++index) {
            if (!set_baseline(index, sequence.Next(levels[index]))) return;
          }
          return;
        }
        if (!consecutive && task % 2 == 1) {
          const size_t index = task / 2;
          set_baseline(index, prepared->BaselineErrors(levels[index], pool.Runner()));
          return;
        }
        const size_t index = consecutive ? task - 1 : task / 2;
        auto result = prepared->SolveOptimized(levels[index], pool.Runner());
        if (result.ok()) {
          results[index] = *std::move(result);
        } else {
          errors[task] = result.status();
        }
        ++halves_done[index];
      },
      [&](int) {
        size_t levels_done = 0;
        for (const std::atomic<int>& halves : halves_done) levels_done += halves.load() == 2;
        for (; reported < levels_done; ++reported) {
          if (on_done) on_done(static_cast<int>(reported + 1));
        }
      });
  if (Cancelled(cancel)) return CancelledStatus();
  for (const Status& error : errors) {
    if (!error.ok()) return error;
  }
  std::map<int, core::LevelResult> out;
  for (size_t index = 0; index < count; ++index) {
    results[index]->baseline = *std::move(baselines[index]);
    prepared->KeepNoWorseThanReparenting(*results[index]);
    out.emplace(counts[index], *std::move(results[index]));
  }
  return out;
}

Status LiftCoarserLevels(const core::PreparedMotion& prepared,
                         std::map<int, core::LevelResult>& levels) {
  for (auto coarser = levels.begin(); coarser != levels.end() && std::next(coarser) != levels.end();
       ++coarser) {
    if (Status status = prepared.LiftCoarserLevel(coarser->second, std::next(coarser)->second);
        !status.ok()) {
      return status;
    }
  }
  return Status::Ok();
}

namespace {

// The joint matrices sampling `sources` at `fps` gives a character of `joints` joints:
// InvalidArgument beyond `limit`. Clips not found are left to sampling to name.
Status CheckClipMatrices(const io::Asset& character, const std::vector<ClipSource>& sources,
                         double fps, int64_t limit) {
  const double joints = static_cast<double>(character.character().skeleton.parents.size());
  double matrices = 0;
  for (const ClipSource& source : sources) {
    const io::Asset& asset = source.motion ? *source.motion : character;
    for (const io::AnimationInfo& info : asset.animations()) {
      if (!source.animation.empty() && info.name != source.animation) continue;
      const double rate = fps > 0 ? fps : info.source_fps;
      matrices += (std::floor(info.duration_seconds * rate + 1e-6) + 1) * joints;
      break;
    }
  }
  if (matrices > static_cast<double>(limit)) {
    return InvalidArgument("the clips at this frame rate hold " +
                           std::to_string(static_cast<int64_t>(matrices)) +
                           " joint matrices together, more than the limit of " +
                           std::to_string(limit) +
                           " (max_joint_frames): bake fewer clips or at a lower fps");
  }
  return Status::Ok();
}

// PrepareInputs for a validated request, on `pool`, without the motion's check: Bake's
// core entry points (the ranking, PreparedMotion::Create) each make it first.
StatusOr<BakeInputs> PrepareInputsOn(const BakeRequest& request, TaskPool& pool) {
  BakeInputs inputs;
  const io::Asset& character_asset = *request.character;
  inputs.warnings = character_asset.warnings();
  // The character and the motion are built side by side: the motion needs only the assets.
  const std::vector<ClipSource> sources =
      request.clips.empty() ? EveryClipOf(character_asset, nullptr, "") : request.clips;
  if (Status s = CheckClipMatrices(character_asset, sources, request.fps,
                                   request.max_joint_frames);
      !s.ok()) {
    return s;
  }
  std::optional<StatusOr<std::shared_ptr<const core::Character>>> character;
  Status motion_status;
  std::vector<std::string> motion_warnings;
  std::vector<core::Motion> clips(sources.size());
  pool.Run(2, [&](int task) {
    if (task == 0) {
      character = core::BuildCharacter(character_asset.character(), pool.Runner());
      return;
    }
    std::vector<const io::Asset*> warned;  // a motion file's unmatched joints, once
    for (size_t c = 0; c < sources.size() && motion_status.ok(); ++c) {
      const ClipSource& source = sources[c];
      if (source.motion) {
        auto retargeted = io::RetargetAnimation(*source.motion, source.animation, request.fps,
                                                character_asset.character(), pool.Runner());
        if (!retargeted.ok()) {
          motion_status = retargeted.status();
          return;
        }
        clips[c] = std::move(retargeted->motion);
        if (std::find(warned.begin(), warned.end(), source.motion.get()) != warned.end()) continue;
        warned.push_back(source.motion.get());
        const std::string from = source.label.empty() ? "the motion" : "'" + source.label + "'";
        for (const std::string& name : retargeted->unmatched_target_joints) {
          motion_warnings.push_back("joint '" + name + "' has no match in " + from +
                                    ": it keeps its bind pose");
        }
        for (const std::string& name : retargeted->unmatched_source_joints) {
          motion_warnings.push_back(from + "'s joint '" + name +
                                    "' matches no joint of the character");
        }
      } else {
        auto motion = character_asset.SampleAnimation(source.animation, request.fps, pool.Runner());
        if (!motion.ok()) {
          motion_status = motion.status();
          return;
        }
        clips[c] = *std::move(motion);
      }
    }
    if (clips.size() == 1) {
      inputs.motion = std::move(clips.front());
      return;
    }
    auto joined = core::ConcatenateClips(clips);
    if (!joined.ok()) {
      motion_status = joined.status();
      return;
    }
    inputs.motion = *std::move(joined);
  });
  if (!character->ok()) return character->status();
  inputs.character = **character;
  if (!motion_status.ok()) return motion_status;
  inputs.warnings.insert(inputs.warnings.end(), motion_warnings.begin(), motion_warnings.end());
  return inputs;
}

}  // namespace

std::vector<ClipSource> EveryClipOf(const io::Asset& character,
                                    std::shared_ptr<const io::Asset> source,
                                    const std::string& label) {
  const io::Asset& file = source ? *source : character;
  std::vector<ClipSource> clips;
  for (const io::AnimationInfo& animation : file.animations()) {
    clips.push_back({source, animation.name, label});
  }
  if (clips.empty()) clips.push_back({source, "", label});
  return clips;
}

StatusOr<BakeInputs> PrepareInputs(const BakeRequest& request) {
  if (Status status = request.Validate(); !status.ok()) return status;
  TaskPool pool(request.threads);
  auto inputs = PrepareInputsOn(request, pool);
  if (!inputs.ok()) return inputs.status();
  if (Status status = core::ValidateMotion(inputs->motion, *inputs->character, request.simd);
      !status.ok()) {
    return status;
  }
  return inputs;
}

double SkinningPassSeconds(const core::Character& character, const core::Motion& motion,
                           int threads) {
  const int n = character.joint_count();
  const int p = character.vertex_count();
  std::vector<core::Affine34d> inverse_bind(n);
  for (int j = 0; j < n; ++j)
    inverse_bind[j] = core::InverseAffine(character.skeleton().bind_world[j]);
  const int workers = std::max(1, std::min(ResolveThreads(threads), motion.frame_count));
  struct Scratch {
    std::vector<core::Affine34f> palette;
    std::vector<core::Vec3f> positions, normals;
  };
  std::vector<Scratch> scratch(workers);
  for (Scratch& s : scratch) {
    s.palette.resize(n);
    s.positions.resize(p);
    s.normals.resize(p);
  }
  // The pool's start is timed, as Bake's is.
  const auto start = Clock::now();
  TaskPool pool(workers);
  pool.Run(workers, [&](int w) {
    Scratch& s = scratch[w];
    for (int t = w; t < motion.frame_count; t += workers) {
      for (int j = 0; j < n; ++j) {
        s.palette[j] = core::ComposeAffine(motion.world(t, j), inverse_bind[j]).cast<float>();
      }
      const core::SkinningJob job{&character, s.palette, s.positions, s.normals};
      (void)job.Run();
    }
  });
  return SecondsSince(start);
}

StatusOr<BakeOutput> Bake(const BakeRequest& request, const ProgressCallback& progress,
                          const std::atomic<bool>* cancel) {
  const auto start = Clock::now();
  auto report_progress = [&](double fraction, const char* stage) {
    if (progress) progress({std::clamp(fraction, 0.0, 1.0), stage});
  };
  report_progress(0.0, "import");
  if (Status status = request.Validate(); !status.ok()) return status;
  TaskPool pool(request.threads);
  auto inputs = PrepareInputsOn(request, pool);
  if (!inputs.ok()) return inputs.status();
  const core::Character& character = *inputs->character;
  const core::Motion& motion = inputs->motion;
  const int n = character.joint_count();
  const int threads = ResolveThreads(request.threads);

  // The ranking and the prepared motion do not depend on each other: side by side, the
  // ranking first (in that order on one thread). "prepare" is reported once the ranking is
  // done.
  report_progress(0.02, "rank");
  std::optional<StatusOr<core::JointRanking>> ranked;
  std::optional<StatusOr<std::shared_ptr<const core::PreparedMotion>>> created;
  std::atomic<bool> ranking_done{false};
  bool prepare_reported = false;
  pool.Run(
      2,
      [&](int task) {
        if (task == 0) {
          ranked =
              core::RankJointsJob{&character, &motion, request.locked_joints, request.simd}.Run(
                  pool.Runner());
          ranking_done = true;
        } else {
          created = core::PreparedMotion::Create(inputs->character, motion, request.settings,
                                                 request.simd, pool.Runner());
        }
      },
      [&](int) {
        if (ranking_done && !prepare_reported) {
          report_progress(0.05, "prepare");
          prepare_reported = true;
        }
      });
  const StatusOr<core::JointRanking>& paper_ranking = *ranked;
  if (!paper_ranking.ok()) return paper_ranking.status();
  const StatusOr<std::shared_ptr<const core::PreparedMotion>>& prepared = *created;
  if (!prepared.ok()) return prepared.status();
  if (Cancelled(cancel)) return CancelledStatus();
  core::JointRanking greedy_ranking;
  if (request.ranking_method == core::RankingMethod::kGreedy) {
    report_progress(0.06, "rank by error");
    auto greedy = core::GreedyRankingJob{prepared->get(), request.locked_joints}.Run(pool.Runner());
    if (!greedy.ok()) return greedy.status();
    greedy_ranking = *std::move(greedy);
    if (Cancelled(cancel)) return CancelledStatus();
  }
  const core::JointRanking* ranking =
      request.ranking_method == core::RankingMethod::kGreedy ? &greedy_ranking : &*paper_ranking;
  const int minimum = ranking->locked_count;

  std::vector<int> counts;
  if (request.all_levels) {
    for (int count = n; count >= minimum; --count) counts.push_back(count);
  } else if (!request.levels.empty()) {
    for (int count : request.levels) {
      if (count < minimum || count > n) {
        return InvalidArgument("level " + std::to_string(count) + " is outside [" +
                               std::to_string(minimum) + ", " + std::to_string(n) +
                               "]: the skeleton has " + std::to_string(n) + " joints and " +
                               std::to_string(minimum) + " that no level removes");
      }
      counts.push_back(count);
    }
  }
  std::sort(counts.begin(), counts.end(), std::greater<>());
  counts.erase(std::unique(counts.begin(), counts.end()), counts.end());

  const bool default_ladder = request.levels.empty() && !request.all_levels;
  std::map<int, core::LevelResult> solved;
  const double solve_begin = 0.1, solve_end = request.variant_curves ? 0.6 : 0.95;
  int solved_count = 0;
  const auto on_level_done = [&](int) {
    ++solved_count;
    report_progress(
        solve_begin + (solve_end - solve_begin) * solved_count / std::max<size_t>(counts.size(), 1),
        "solve");
  };
  const auto solve = [&](std::vector<int> levels,
                         const std::function<void(int)>& on_done) -> Status {
    auto levels_solved =
        SolveLevelsJob{*prepared, &*ranking, std::move(levels), on_done, cancel}.Run(pool);
    if (!levels_solved.ok()) return levels_solved.status();
    solved.merge(*levels_solved);
    return Status::Ok();
  };
  std::vector<CostLevel> ladder;
  if (default_ladder) {
    // Levels by cost: the cheapest within 1 px at each height of the ladder (its own mesh,
    // influences and pose rate), then each level's skeleton solved on the whole mesh for
    // the report's E and baseline figures.
    report_progress(0.1, "levels by cost");
    CostLadderJob job;
    job.prepared = *prepared;
    job.motion = &motion;
    job.ranking = ranking;
    job.simd = request.simd;
    job.parts = request.level_parts;
    if (!request.ladder_heights_px.empty()) job.heights_px = request.ladder_heights_px;
    auto built = job.Run(pool);
    if (!built.ok()) return built.status();
    ladder = *std::move(built);
    if (Cancelled(cancel)) return CancelledStatus();
    counts.clear();
    for (const CostLevel& level : ladder) counts.push_back(level.skeleton.kept_count());
    std::sort(counts.begin(), counts.end(), std::greater<>());
    counts.erase(std::unique(counts.begin(), counts.end()), counts.end());
  }
  if (Status status = solve(counts, on_level_done); !status.ok()) return status;
  if (!default_ladder) {
    if (Status status = LiftCoarserLevels(**prepared, solved); !status.ok()) return status;
    for (int count : counts) ladder.push_back(SkeletonLevel(character, solved.at(count)));
  }
  std::vector<BakedLevel> baked;
  for (CostLevel& level : ladder) {
    const core::LevelResult* skeleton = &solved.at(level.skeleton.kept_count());
    baked.push_back({std::move(level), skeleton});
  }
  // A rigid variant cannot follow a clip that scales joints: there even full detail is off,
  // and no level is within a pixel budget. Say which clips, and what would follow them.
  if (core::IsRigid(request.settings.variant) && baked.front().level.skeleton.kept_count() == n) {
    const core::LevelDeviation& full = baked.front().level.deviation;
    std::string clips_off;
    double worst = 0;
    for (size_t c = 0; c < full.per_clip.size(); ++c) {
      if (full.per_clip[c].max_pct <= kRigidMissPct) continue;
      clips_off += (clips_off.empty() ? "'" : ", '") + motion.Clips()[c].name + "'";
      worst = std::max(worst, full.per_clip[c].max_pct);
    }
    if (!clips_off.empty()) {
      char figure[32];
      std::snprintf(figure, sizeof figure, "%.3g", worst);
      inputs->warnings.push_back("the rigid variant " + std::string(core::VariantName(request.settings.variant)) +
                                 " cannot follow the joint scaling of clip(s) " + clips_off +
                                 ": full detail is up to " + figure +
                                 "% of the height off there, so no level is within budget; bake them "
                                 "apart or in vp or vpno");
    }
  }

  // Fig. 7: the four variants at every level, errors only.
  std::vector<VariantCurve> curves;
  if (request.variant_curves) {
    for (core::Variant variant :
         {core::Variant::kVP, core::Variant::kVPNO, core::Variant::kVPPD, core::Variant::kVPNOPD}) {
      core::SolveSettings settings = request.settings;
      settings.variant = variant;
      auto variant_prepared = core::PreparedMotion::Create(inputs->character, motion, settings,
                                                           request.simd, pool.Runner());
      if (!variant_prepared.ok()) return variant_prepared.status();
      std::vector<int> every;
      for (int count = n; count >= minimum; --count) every.push_back(count);
      auto curve_levels = SolveLevelsJob{*variant_prepared, &*ranking, every, {}, cancel}.Run(pool);
      if (!curve_levels.ok()) return curve_levels.status();
      if (Status status = LiftCoarserLevels(**variant_prepared, *curve_levels); !status.ok()) {
        return status;
      }
      const std::map<int, core::LevelResult>& results = *curve_levels;
      VariantCurve curve{variant, {}};
      for (int count : every) {
        const core::LevelResult& r = results.at(count);
        curve.points.push_back(
            {count, r.optimized.mean_e, r.baseline.mean_e, r.optimized.max_vertex_error_pct});
      }
      curves.push_back(std::move(curve));
      report_progress(solve_end + 0.35 * curves.size() / 4.0, "variant curves");
    }
  }
  if (Cancelled(cancel)) return CancelledStatus();

  report_progress(0.96, "encode");
  auto encoded = EncodeBakedLevels(character, motion, request.settings, request.source_hash, baked,
                                   pool.Runner());
  if (!encoded.ok()) return encoded.status();
  const double bake_seconds = SecondsSince(start);

  report_progress(0.98, "measure");
  const ReportInputs report_inputs{
      request,
      character,
      motion,
      *ranking,
      *paper_ranking,
      **prepared,
      baked,
      curves,
      bake_seconds,
      request.measure_skinning_pass ? SkinningPassSeconds(character, motion, threads) : 0.0,
      threads,
      inputs->warnings};

  BakeOutput output;
  output.level_set = std::move(*encoded);
  output.report = BuildReport(report_inputs);
  output.warnings = std::move(inputs->warnings);
  report_progress(1.0, "done");
  return output;
}

}  // namespace motionlod::pipeline
