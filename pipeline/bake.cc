#include "pipeline/bake.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <map>
#include <memory>
#include <mutex>
#include <optional>

#include "core/reduce_skeleton.h"
#include "core/skinning.h"
#include "io/retarget.h"
#include "base/parallel.h"
#include "pipeline/report.h"
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

Status CancelledStatus() { return Status(StatusCode::kNotFound, "the bake was cancelled"); }

}  // namespace

Status BakeRequest::Validate() const {
  if (!character) return InvalidArgument("no character to bake");
  if (Status status = settings.Validate(); !status.ok()) return status;
  if (!(fps >= 0) || fps > 1000) return InvalidArgument("fps must be in [0, 1000] (0 = the source's)");
  for (int count : levels) {
    if (count < 1) return InvalidArgument("every level must keep at least one joint");
  }
  if (all_levels && !levels.empty()) {
    return InvalidArgument("ask for explicit levels or for all levels, not both");
  }
  if (!(smallest_useful_error_pct > 0)) {
    return InvalidArgument("smallest_useful_error_pct must be positive");
  }
  // Bake starts its pool's threads up front.
  if (threads < 0 || threads > kMaxThreads) {
    return InvalidArgument("threads must be in [0, " + std::to_string(kMaxThreads) +
                           "] (0 = one per hardware thread)");
  }
  return Status::Ok();
}

Status SolveLevels(const std::shared_ptr<const core::PreparedMotion>& prepared,
                   const core::JointRanking& ranking, const std::vector<int>& counts,
                   TaskPool& pool, std::map<int, core::LevelResult>& out,
                   const std::function<void(int)>& on_done, const std::atomic<bool>* cancel,
                   const std::function<void()>& first,
                   std::unique_ptr<core::BaselineSequence>* chain) {
  const size_t count = counts.size();
  std::vector<core::ReducedSkeleton> levels;
  levels.reserve(count);
  for (int kept : counts) {
    auto level = core::ReduceSkeletonToCount(prepared->character(), ranking, kept);
    if (!level.ok()) return level.status();
    levels.push_back(*std::move(level));
  }
  std::vector<std::optional<core::LevelResult>> results(count);
  std::vector<std::optional<core::LevelErrors>> baselines(count);
  // Levels a joint apart (every level) take their baselines one from the other, in one
  // task, the first (the longest); task i + 1 solves level i. A ladder's far apart levels
  // change most joints at each step: each baseline is a task of its own, task 2i solving
  // level i and task 2i + 1 its baseline, the order that balances best over threads.
  bool consecutive = count > 1;
  for (size_t index = 1; index < count; ++index) {
    consecutive = consecutive && counts[index] == counts[index - 1] - 1;
  }
  const size_t level_tasks = consecutive ? count + 1 : 2 * count;
  const int first_tasks = first ? 1 : 0;
  std::vector<Status> errors(level_tasks);
  std::vector<std::atomic<int>> halves_done(count);
  // The sequence that baselines taken one from another continue: *chain, or this call's
  // own; made at its first step (one task takes every step of a call).
  std::unique_ptr<core::BaselineSequence> own_sequence;
  std::unique_ptr<core::BaselineSequence>& sequence = chain != nullptr ? *chain : own_sequence;
  const auto next_in_sequence = [&](size_t index) {
    if (!sequence) sequence = std::make_unique<core::BaselineSequence>(prepared);
    return sequence->Next(levels[index]);
  };
  size_t reported = 0;
  pool.Run(
      static_cast<int>(level_tasks) + first_tasks,
      [&](int job_task) {
        if (Cancelled(cancel)) return;
        if (job_task < first_tasks) {
          first();
          return;
        }
        const int task = job_task - first_tasks;
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
          for (size_t index = 0; index < count && !Cancelled(cancel); ++index) {
            if (!set_baseline(index, next_in_sequence(index))) return;
          }
          return;
        }
        if (!consecutive && task % 2 == 1) {
          const size_t index = task / 2;
          if (chain != nullptr && index + 1 == count) {
            set_baseline(index, next_in_sequence(index));
          } else {
            set_baseline(index, prepared->BaselineErrors(levels[index], pool.Runner()));
          }
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
  for (size_t index = 0; index < count; ++index) {
    results[index]->baseline = *std::move(baselines[index]);
    out.emplace(counts[index], *std::move(results[index]));
  }
  return Status::Ok();
}

std::vector<int> DefaultLadder(int joint_count, int minimum) {
  const int n = joint_count;
  std::vector<int> ladder = {n, static_cast<int>(std::lround(0.75 * n)),
                             static_cast<int>(std::lround(0.5 * n)),
                             static_cast<int>(std::lround(0.25 * n))};
  for (int& count : ladder) count = std::clamp(count, std::min(minimum, n), n);
  std::sort(ladder.begin(), ladder.end(), std::greater<>());
  ladder.erase(std::unique(ladder.begin(), ladder.end()), ladder.end());
  return ladder;
}

namespace {

// The prepared motion the probes of Bake's search for the smallest useful level run on:
// on a long motion, at most kProbeFrames evenly strided frames of `prepared`.
StatusOr<std::shared_ptr<const core::PreparedMotion>> ProbeMotion(
    const std::shared_ptr<const core::PreparedMotion>& prepared) {
  constexpr int kProbeFrames = 64;
  const int stride = (prepared->frame_count() + kProbeFrames - 1) / kProbeFrames;
  if (stride == 1) return prepared;
  return prepared->EveryNthFrame(stride);
}

// The bisection of Bake's search for the smallest useful level between lo (fails, or the
// fewest joints a level may keep) and hi (meets the bound): the count it ends on. Probes
// only steer the search: they run on `probe` (ProbeMotion), and they only decide whether
// the maximum error is within the bound (the level's own maximum on those frames:
// EveryNthFrame solves the full motion's problem). With `probes_per_round` above one, the
// probes the bisection may make next run beside the one it makes now, the bisection's
// tree of brackets taken breadth first: for a search with the pool to itself, one per
// thread. It then decides from every probe made, exactly as one probe at a time would (the
// count found depends on neither), a round taking as many steps as the probes made reach.
StatusOr<int> SmallestUsefulCount(const core::PreparedMotion& probe,
                                  const core::JointRanking& ranking, int lo, int hi, double bound,
                                  int probes_per_round, TaskPool& pool,
                                  const std::atomic<bool>* cancel) {
  std::map<int, bool> within_at;  // kept joints -> probe within the bound
  while (lo < hi) {
    if (Cancelled(cancel)) return CancelledStatus();
    std::vector<int> probes;
    std::vector<std::pair<int, int>> brackets = {{lo, hi}};
    for (size_t next = 0;
         next < brackets.size() && probes.size() < static_cast<size_t>(probes_per_round); ++next) {
      const auto [low, high] = brackets[next];
      if (low >= high) continue;
      const int mid = low + (high - low) / 2;
      if (!within_at.count(mid)) probes.push_back(mid);
      brackets.emplace_back(low, mid);       // mid within the bound
      brackets.emplace_back(mid + 1, high);  // mid not within it
    }
    std::vector<StatusOr<bool>> within(probes.size(), StatusOr<bool>(false));
    pool.Run(static_cast<int>(probes.size()), [&](int index) {
      auto level = core::ReduceSkeletonToCount(probe.character(), ranking, probes[index]);
      if (!level.ok()) {
        within[index] = level.status();
        return;
      }
      within[index] = probe.MaxVertexErrorWithin(*level, bound);
    });
    for (size_t index = 0; index < probes.size(); ++index) {
      if (!within[index].ok()) return within[index].status();
      within_at[probes[index]] = *within[index];
    }
    while (lo < hi) {
      const auto made = within_at.find(lo + (hi - lo) / 2);
      if (made == within_at.end()) break;
      if (made->second) {
        hi = made->first;
      } else {
        lo = made->first + 1;
      }
    }
  }
  return hi;
}

// What the first task of Bake's default ladder computes (SolveLadderBottom).
struct LadderBottom {
  Status status;
  // The ladder's smallest level, and the level the search found below it.
  std::map<int, core::LevelResult> levels;
  // The motion the search's probes run on (ProbeMotion), for a search after the ladder too.
  std::optional<StatusOr<std::shared_ptr<const core::PreparedMotion>>> probe_motion;
  // The count the search below the smallest level ended on, if that level is within the
  // bound and a level may keep fewer joints; a failure of the search or of the level it
  // found stays here, for the caller to report if it uses the search.
  std::optional<StatusOr<int>> search;
};

// The ladder's smallest level (`smallest` joints: its solve and its baseline, the first
// step of a core::BaselineSequence), the search's probe motion, and, when that level is
// within `bound`, the search for the smallest useful level below it ([minimum, smallest])
// and that level, solved unless it is the smallest. A level a joint below continues the
// sequence, evaluating only the joints whose nearest kept joint changes (Fox's on 2
// threads: its final level 86 -> 65 us); one further below gets a baseline of its own: the
// more joints change, the more a step costs, and a sequence's evaluation runs as one piece
// where BaselineErrors runs as two. Neither the search nor that level depend on the
// ladder's larger levels, only on whether one of them is over the bound (Bake's check).
// The search probes one count at a time: the other threads have those levels to solve,
// so a probe beside it, in a bracket the bisection may never need, would mostly cost this
// thread (Fox's 4 probes in 2 rounds of 2 became 3).
LadderBottom SolveLadderBottom(const std::shared_ptr<const core::PreparedMotion>& prepared,
                               const core::JointRanking& ranking, int smallest, int minimum,
                               double bound, TaskPool& pool, const std::atomic<bool>* cancel) {
  LadderBottom bottom;
  std::unique_ptr<core::BaselineSequence> chain;
  bottom.status =
      SolveLevels(prepared, ranking, {smallest}, pool, bottom.levels, {}, cancel, {}, &chain);
  if (!bottom.status.ok()) return bottom;
  bottom.probe_motion = ProbeMotion(prepared);
  if (minimum >= smallest ||
      !(bottom.levels.at(smallest).optimized.max_vertex_error_pct <= bound) ||
      !bottom.probe_motion->ok()) {
    return bottom;
  }
  bottom.search = SmallestUsefulCount(***bottom.probe_motion, ranking, minimum, smallest, bound, 1,
                                      pool, cancel);
  if (bottom.search->ok() && **bottom.search != smallest) {
    const int found = **bottom.search;
    if (Status status = SolveLevels(prepared, ranking, {found}, pool, bottom.levels, {}, cancel, {},
                                    found + 1 == smallest ? &chain : nullptr);
        !status.ok()) {
      bottom.search = status;
    }
  }
  return bottom;
}

// PrepareInputs for a validated request, on `pool`, without the motion's check: Bake's
// core entry points (the ranking, PreparedMotion::Create) each make it first.
StatusOr<BakeInputs> PrepareInputsOn(const BakeRequest& request, TaskPool& pool) {
  BakeInputs inputs;
  const io::Asset& character_asset = *request.character;
  inputs.warnings = character_asset.warnings();
  // The character and the motion are built side by side: the motion needs only the asset.
  std::optional<StatusOr<std::shared_ptr<const core::Character>>> character;
  Status motion_status;
  std::vector<std::string> motion_warnings;
  pool.Run(2, [&](int task) {
    if (task == 0) {
      character = core::BuildCharacter(character_asset.character(), pool.Runner());
    } else if (request.motion) {
      auto retargeted = io::RetargetAnimation(*request.motion, request.animation, request.fps,
                                              character_asset.character(), &pool);
      if (!retargeted.ok()) {
        motion_status = retargeted.status();
        return;
      }
      inputs.motion = std::move(retargeted->motion);
      for (const std::string& name : retargeted->unmatched_target_joints) {
        motion_warnings.push_back("joint '" + name + "' has no match in the motion: it keeps its bind pose");
      }
      for (const std::string& name : retargeted->unmatched_source_joints) {
        motion_warnings.push_back("the motion's joint '" + name + "' matches no joint of the character");
      }
    } else {
      auto motion = character_asset.SampleAnimation(request.animation, request.fps, &pool);
      if (!motion.ok()) {
        motion_status = motion.status();
        return;
      }
      inputs.motion = std::move(*motion);
    }
  });
  if (!character->ok()) return character->status();
  inputs.character = **character;
  if (!motion_status.ok()) return motion_status;
  inputs.warnings.insert(inputs.warnings.end(), motion_warnings.begin(), motion_warnings.end());
  return inputs;
}

}  // namespace

StatusOr<BakeInputs> PrepareInputs(const BakeRequest& request) {
  if (Status status = request.Validate(); !status.ok()) return status;
  TaskPool pool(request.threads);
  auto inputs = PrepareInputsOn(request, pool);
  if (!inputs.ok()) return inputs.status();
  if (Status status = core::ValidateMotion(inputs->motion, *inputs->character); !status.ok()) {
    return status;
  }
  return inputs;
}

double SkinningPassSeconds(const core::Character& character, const core::Motion& motion,
                           int threads) {
  const int n = character.joint_count();
  const int p = character.vertex_count();
  std::vector<core::Affine34d> inverse_bind(n);
  for (int j = 0; j < n; ++j) inverse_bind[j] = core::InverseAffine(character.skeleton().bind_world[j]);
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
          ranked = core::RankJointsJob{&character, &motion, request.locked_joints}.Run(pool.Runner());
          ranking_done = true;
        } else {
          created = core::PreparedMotion::Create(inputs->character, motion, request.settings,
                                                 request.all_levels
                                                     ? core::PreparedMotion::Workload::kEveryLevel
                                                     : core::PreparedMotion::Workload::kSomeLevels,
                                                 pool.Runner());
        }
      },
      [&](int) {
        if (ranking_done && !prepare_reported) {
          report_progress(0.05, "prepare");
          prepare_reported = true;
        }
      });
  const StatusOr<core::JointRanking>& ranking = *ranked;
  if (!ranking.ok()) return ranking.status();
  const int minimum = ranking->locked_count;
  const StatusOr<std::shared_ptr<const core::PreparedMotion>>& prepared = *created;
  if (!prepared.ok()) return prepared.status();
  if (Cancelled(cancel)) return CancelledStatus();

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
  } else {
    counts = DefaultLadder(n, minimum);
  }
  std::sort(counts.begin(), counts.end(), std::greater<>());
  counts.erase(std::unique(counts.begin(), counts.end()), counts.end());

  const bool default_ladder = request.levels.empty() && !request.all_levels;
  std::map<int, core::LevelResult> solved;
  const double solve_begin = 0.1, solve_end = request.variant_curves ? 0.6 : 0.95;
  int solved_count = 0;
  const auto on_level_done = [&](int) {
    ++solved_count;
    report_progress(solve_begin + (solve_end - solve_begin) * solved_count /
                                      std::max<size_t>(counts.size() + (default_ladder ? 1 : 0), 1),
                    "solve");
  };
  if (!default_ladder) {
    if (Status status =
            SolveLevels(*prepared, *ranking, counts, pool, solved, on_level_done, cancel);
        !status.ok()) {
      return status;
    }
  } else {
    // The smallest useful skeleton: the fewest joints whose optimised maximum vertex error
    // is within the bound. The ladder's exact errors bracket it; bisection narrows the
    // bracket (the error grows as joints go, though not strictly, so this finds a count
    // that meets the bound with the one below failing; SmallestUsefulCount). The chosen
    // level is then solved in full on every frame.
    //
    // The ladder's smallest level is the first task of the ladder's job, and when it is
    // within the bound the same task goes on to the search below it and the level that
    // search finds (LadderBottom), beside the larger levels: the search and that level no
    // longer wait for the whole ladder with a thread idle at each end (Fox on 2 threads:
    // the ladder, the search and the final level 548 -> 483 us). What the task found is
    // used if no larger level is over the bound, which is when the bracket is the one it
    // searched; otherwise the search below the ladder's lowest level over the bound runs
    // after the ladder, as it must.
    const double bound = request.smallest_useful_error_pct;
    const int smallest = counts.back();
    LadderBottom bottom;
    if (Status status =
            SolveLevels(*prepared, *ranking, std::vector<int>(counts.begin(), counts.end() - 1),
                        pool, solved, on_level_done, cancel,
                        [&] {
                          bottom = SolveLadderBottom(*prepared, *ranking, smallest, minimum, bound,
                                                     pool, cancel);
                        });
        !status.ok()) {
      return status;
    }
    if (!bottom.status.ok()) return bottom.status;
    solved.insert(bottom.levels.extract(smallest));
    on_level_done(static_cast<int>(solved.size()));
    int lo = minimum, hi = n;
    for (const auto& [count, result] : solved) {
      if (result.optimized.max_vertex_error_pct <= bound) {
        hi = std::min(hi, count);
      } else {
        lo = std::max(lo, count + 1);
      }
    }
    lo = std::min(lo, hi);
    if (lo < hi && bottom.search) {
      if (!bottom.search->ok()) return bottom.search->status();
      hi = **bottom.search;
      if (hi != smallest) solved.insert(bottom.levels.extract(hi));
    } else if (lo < hi) {
      if (!bottom.probe_motion->ok()) return bottom.probe_motion->status();
      auto found = SmallestUsefulCount(***bottom.probe_motion, *ranking, lo, hi, bound,
                                       pool.threads(), pool, cancel);
      if (!found.ok()) return found.status();
      hi = *found;
      if (!solved.count(hi)) {
        if (Status status = SolveLevels(*prepared, *ranking, {hi}, pool, solved, {}, cancel);
            !status.ok()) {
          return status;
        }
      }
    }
    if (std::find(counts.begin(), counts.end(), hi) == counts.end()) {
      counts.push_back(hi);
      std::sort(counts.begin(), counts.end(), std::greater<>());
      on_level_done(static_cast<int>(solved.size()));
    }
  }

  // Fig. 7: the four variants at every level, errors only.
  std::vector<VariantCurve> curves;
  if (request.variant_curves) {
    for (core::Variant variant : {core::Variant::kVP, core::Variant::kVPNO, core::Variant::kVPPD,
                                  core::Variant::kVPNOPD}) {
      core::SolveSettings settings = request.settings;
      settings.variant = variant;
      auto variant_prepared =
          core::PreparedMotion::Create(inputs->character, motion, settings,
                                       core::PreparedMotion::Workload::kEveryLevel, pool.Runner());
      if (!variant_prepared.ok()) return variant_prepared.status();
      std::vector<int> every;
      for (int count = n; count >= minimum; --count) every.push_back(count);
      std::map<int, core::LevelResult> results;
      if (Status status = SolveLevels(*variant_prepared, *ranking, every, pool, results, {}, cancel);
          !status.ok()) {
        return status;
      }
      VariantCurve curve{variant, {}};
      for (int count : every) {
        const core::LevelResult& r = results.at(count);
        curve.points.push_back({count, r.optimized.mean_e, r.baseline.mean_e,
                                r.optimized.max_vertex_error_pct});
      }
      curves.push_back(std::move(curve));
      report_progress(solve_end + 0.35 * curves.size() / 4.0, "variant curves");
    }
  }
  if (Cancelled(cancel)) return CancelledStatus();

  report_progress(0.96, "encode");
  auto encoded = EncodeSolvedLevels(character, motion, request.settings, request.source_hash,
                                    counts, solved, pool.Runner());
  if (!encoded.ok()) return encoded.status();
  const double bake_seconds = SecondsSince(start);

  report_progress(0.98, "measure");
  const ReportInputs report_inputs{request,       character, motion, *ranking, **prepared,
                                   counts,        solved,    curves,  bake_seconds,
                                   request.measure_skinning_pass
                                       ? SkinningPassSeconds(character, motion, threads)
                                       : 0.0,
                                   threads,       inputs->warnings};

  BakeOutput output;
  output.level_set = std::move(*encoded);
  output.report = BuildReport(report_inputs);
  output.warnings = std::move(inputs->warnings);
  report_progress(1.0, "done");
  return output;
}

}  // namespace motionlod::pipeline
