// The bake: from imported assets to an encoded level set and its report. Shared by the
// `motionlod` tool and the daemon. Runs the core's jobs on a pool of threads (the core
// itself has none) and reports progress through a callback; never logs.
#pragma once

#include <array>
#include <atomic>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "base/status.h"
#include "core/character.h"
#include "core/motion.h"
#include "core/rank_joints.h"
#include "core/simd.h"
#include "core/solve_levels.h"
#include "io/asset.h"
#include "pipeline/cost_levels.h"
#include "pipeline/task_pool.h"

namespace motionlod::pipeline {

// One clip to bake: an animation of the character's own file, or of a separate motion file
// retargeted onto the character by joint name.
struct ClipSource {
  std::shared_ptr<const io::Asset> motion;  // null: the character's own file
  std::string animation;                    // "" = the source's first
  std::string label;                        // the motion file's name, for the report
};

// Every animation of `source` (null: `character`'s own file), in the file's order; one
// unnamed clip (the first, which sampling then finds missing) where it has none.
std::vector<ClipSource> EveryClipOf(const io::Asset& character,
                                    std::shared_ptr<const io::Asset> source,
                                    const std::string& label);

// A rigid bake's full detail further off than this (percent of the height) on a clip: the
// clip scales joints, which no rigid level follows (the bake warns and names it).
inline constexpr double kRigidMissPct = 0.1;

struct BakeRequest {
  std::shared_ptr<const io::Asset> character;
  // The clips baked together, in this order: one reduced skeleton per level for all of
  // them, matrices and figures per clip. Empty = every animation of the character's file.
  std::vector<ClipSource> clips;
  double fps = 0;  // 0 = the source's rate
  // Joint matrices of every clip at `fps` together (joints x frames): InvalidArgument
  // beyond, before any is sampled. Bounds a bake's motion memory (96 bytes a matrix).
  int64_t max_joint_frames = 10'000'000;
  // Kept joint counts, any order (levels of the skeleton alone: the whole mesh, its own
  // influences, every frame); empty = the levels by cost (pipeline/cost_levels.h: the
  // cheapest within 1 px at each of a spread of heights). all_levels: every count from n
  // down to the minimum.
  std::vector<int> levels;
  bool all_levels = false;
  std::vector<std::string> locked_joints;  // never removed (sockets, IK targets)
  core::RankingMethod ranking_method = core::RankingMethod::kGreedy;
  // What the default ladder's levels may cut (pipeline/cost_levels.h): everything unless a
  // part is switched off.
  CostLevelParts level_parts;
  // The on-screen heights (px, decreasing) the default ladder picks its levels for; empty =
  // CostLadderJob's spread. Only with the default ladder (no levels, not all_levels).
  std::vector<double> ladder_heights_px;
  static constexpr size_t kMaxLadderHeights = 32;
  core::SolveSettings settings;
  // The machine version of the core's hot loops (core/simd.h): the programs read it from
  // MOTIONLOD_SIMD.
  core::SimdChoice simd = core::SimdChoice::kWidest;
  // Also solve the four variants at every level (errors only) for the fig. 7 plot.
  bool variant_curves = false;
  static constexpr int kMaxThreads = 256;
  int threads = 0;  // 0 = one per hardware thread; at most kMaxThreads
  // Time one plain skinning pass after the bake for the report's
  // timing.skinning_pass_seconds and bake_over_skinning_pass (both 0 when false): it
  // costs a sixth to a third of the bake again, outside bake_seconds.
  bool measure_skinning_pass = true;
  std::array<uint8_t, 32> source_hash{};  // SHA-256 of the inputs, stored in the level set
  std::string character_label;            // for the report (the file's name)

  Status Validate() const;
};

struct BakeProgress {
  double fraction = 0;  // 0..1
  const char* stage = "";
};
// Called from the thread that runs Bake, never concurrently.
using ProgressCallback = std::function<void(const BakeProgress&)>;

struct BakeOutput {
  std::string level_set;  // proto level-set file
  nlohmann::json report;  // report.json
  std::vector<std::string> warnings;
};

// Errors: the importer's and the core's Status, kInvalidArgument for bad requests, and
// kCancelled when *cancel becomes true.
StatusOr<BakeOutput> Bake(const BakeRequest& request, const ProgressCallback& progress = {},
                          const std::atomic<bool>* cancel = nullptr);

// The character and motion a request bakes, built and validated; used by Bake and `rank`.
// The motion holds every clip, one after another (core::Motion::clips names them).
struct BakeInputs {
  std::shared_ptr<const core::Character> character;
  core::Motion motion;
  std::vector<std::string> warnings;
};
StatusOr<BakeInputs> PrepareInputs(const BakeRequest& request);

// Seconds of one plain skinning pass over the whole motion (palette K_j(t) = M_j(t) M0_j^-1
// in float, then positions and normals of every vertex) on `threads` threads: the
// yardstick the bake time is compared with.
double SkinningPassSeconds(const core::Character& character, const core::Motion& motion,
                           int threads);

// Solves the levels that keep `counts` joints (decreasing, each in [locked_count, n]:
// nested levels of the ranking) as Bake solves them, on a pool: each level's optimised
// half is a task, and so is its baseline, except that levels a joint apart (every level)
// take their baselines one from the other in one task (core::BaselineSequence). Each level
// is then made no worse than its baseline (PreparedMotion::KeepNoWorseThanReparenting).
struct SolveLevelsJob {
  std::shared_ptr<const core::PreparedMotion> prepared;
  const core::JointRanking* ranking = nullptr;
  std::vector<int> counts;
  // Runs on the calling thread as levels complete, with the number done so far.
  std::function<void(int)> on_done = {};
  const std::atomic<bool>* cancel = nullptr;  // kCancelled once it becomes true

  Status Validate() const;
  // The levels keyed by count.
  StatusOr<std::map<int, core::LevelResult>> Run(TaskPool& pool) const;
};

// Coarsest first, each level of nested `levels` (keyed by count) made no worse than the
// next coarser one (PreparedMotion::LiftCoarserLevel): adding joints never raises the error.
Status LiftCoarserLevels(const core::PreparedMotion& prepared,
                         std::map<int, core::LevelResult>& levels);

}  // namespace motionlod::pipeline
