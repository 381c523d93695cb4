// The bake against its yardstick (issue "engine"): for every file of the data directory,
// side by side in one run,
//   skin/<case>/threads:N                  pipeline::SkinningPassSeconds: one plain skinning
//                                          pass (palette, positions and normals of every
//                                          vertex) over the whole motion on N threads
//   bake/<case>/<variant>/default/threads:N   pipeline::Bake with the default ladder on N
//                                          threads, timed by the report's
//                                          timing.bake_seconds (import excluded, the report's
//                                          own skinning pass excluded); counters: the report's
//                                          paired ratio and the stages between Bake's
//                                          progress reports
//   bake/<case>/<variant>/all/threads:N    pipeline::Bake with every level (all_levels) on
//                                          the characters that are also subdivided
//   replica/<case>/vpno+pd/all/threads:N   BakeEveryLevel (below) on the same original
//                                          character: checks the replica against Bake
//   skin/<case>@<p>v/threads:N,           the same on a copy of a real character
//   bake/<case>@<p>v/<variant>/all/...     subdivided to p >= 10k vertices, every level
//                                          (see BakeEveryLevel: Bake takes an io::Asset, so
//                                          the subdivided character runs Bake's all_levels
//                                          path step by step); counter insitu_ratio: each
//                                          bake over a skinning pass run right after it
//   naive/<case>, level/<case>, ls/<case>  one mid level (round(n/2) joints, vpno+pd settings,
//                                          1 thread): core::SolveFrameReference on a few evenly
//                                          spaced frames, scaled by T / frames to the whole
//                                          motion, beside PreparedMotion::SolveLevel (solve,
//                                          polar projection, errors) and SolveLeastSquares
//                                          (the same unconstrained solution the naive one
//                                          computes) for all T frames.
// Every case uses manual time (state.SetIterationTime), so that what is timed is exactly
// the stage named. bench/summarize.py turns the JSON output into docs/PERFORMANCE.md.
//
// Flags (before Google Benchmark's own):
//   --data=DIR          characters/ and motions/ (default: the CMake cache's ../shared/data)
//   --threads=1,2       thread counts; each registers its own skin/bake cases
//   --variants=vp,...   variants of the bake cases (default: all four)
//   --quick             vp and vpno+pd only, two subdivided characters, naive on 3 files
//   --min_vertices=N    subdivision target (default 10000)
//   --naive_frames=K    frames the naive solve runs per iteration (default 4)
//   --breakdown         no benchmarks: prints where the bake time goes, stage by stage
//   --per_level         with --breakdown: each level's LS / errors / polar time
//   --only=TEXT         with --breakdown: only the cases whose label contains TEXT
#include <benchmark/benchmark.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "pipeline/task_pool.h"
#include "bench/subdivide.h"
#include "core/character.h"
#include "core/motion.h"
#include "core/rank_joints.h"
#include "core/baseline_sequence.h"
#include "core/reduce_skeleton.h"
#include "core/reference/solve_frame_reference.h"
#include "core/simd.h"
#include "core/solve_levels.h"
#include "io/asset.h"
#include "io/retarget.h"
#include "pipeline/allocator.h"
#include "pipeline/bake.h"
#include "pipeline/report.h"
#include "pipeline/task_pool.h"
#include "proto/level_format.h"

namespace motionlod::bench {
namespace {

// Joint counts n, ~3n/4, ~n/2, ~n/4 clamped to [minimum, n], finest first: the ladder of
// the skeleton's solve alone that the solve's timings are measured on.
std::vector<int> QuarterLadder(int joint_count, int minimum) {
  const int n = joint_count;
  std::vector<int> ladder = {n, static_cast<int>(std::lround(0.75 * n)), static_cast<int>(std::lround(0.5 * n)),
                             static_cast<int>(std::lround(0.25 * n))};
  for (int& count : ladder) count = std::clamp(count, std::min(minimum, n), n);
  std::sort(ladder.begin(), ladder.end(), std::greater<>());
  ladder.erase(std::unique(ladder.begin(), ladder.end()), ladder.end());
  return ladder;
}

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

// The machine version the bench runs (core/simd.h), from MOTIONLOD_SIMD as the programs
// read it ("auto" when unset or unknown: Main reports an unknown value).
core::SimdChoice Simd() {
  const char* setting = std::getenv("MOTIONLOD_SIMD");
  const auto choice = core::ParseSimdChoice(setting != nullptr ? setting : "");
  return choice.ok() ? *choice : core::SimdChoice::kWidest;
}

double SecondsSince(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

struct Options {
  std::string data_dir = MOTIONLOD_BENCH_DATA;
  std::vector<int> threads = {1};
  std::vector<core::Variant> variants = {core::Variant::kVP, core::Variant::kVPNO,
                                         core::Variant::kVPPD, core::Variant::kVPNOPD};
  bool quick = false;
  bool breakdown = false;
  bool per_level = false;  // --breakdown: also each level's times
  std::string only;         // --breakdown: cases whose label contains this
  int min_vertices = 10000;
  int naive_frames = 4;
};

// Characters whose file has no animation play a clip of another file. Knight shares the
// KayKit Rig_Medium skeleton (same joint names); other files are matched by retargeting.
struct MotionChoice {
  const char* character;
  const char* motion;
  const char* animation;
};
constexpr MotionChoice kPreferredMotions[] = {
    {"Knight.glb", "Rig_Medium_MovementBasic.glb", "Walking_A"},
};

// Real characters the every-level target is measured on, subdivided to >= 10k vertices.
constexpr const char* kSubdivided[] = {"Orc.gltf", "Rig_Medium_MovementBasic.glb",
                                       "stormtrooper.dae", "RobotExpressive.glb"};

// One bakeable (character, motion) pair, imported once.
struct Case {
  std::string label;  // file name, or "character+clip" for a borrowed clip
  std::string file;
  std::shared_ptr<const io::Asset> character;
  std::shared_ptr<const io::Asset> motion;  // null: the character's own first animation
  std::string animation;
  // Built once for the yardstick and the naive solve.
  std::shared_ptr<const core::Character> built;
  core::Motion sampled;
};

pipeline::BakeRequest RequestOf(const Case& c, core::Variant variant, int threads) {
  pipeline::BakeRequest request;
  request.simd = Simd();
  request.character = c.character;
  request.clips = {{c.motion, c.animation, ""}};
  request.settings.variant = variant;
  request.threads = threads;
  request.character_label = c.file;
  return request;
}

void Fail(benchmark::State& state, const Status& status) {
  state.SkipWithError(status.ToString().c_str());
}

// Shared counters: the shape of the work.
void ShapeCounters(benchmark::State& state, const core::Character& character,
                   const core::Motion& motion) {
  state.counters["vertices"] = character.vertex_count();
  state.counters["joints"] = character.joint_count();
  state.counters["frames"] = motion.frame_count;
}

void BM_Skin(benchmark::State& state, const core::Character* character, const core::Motion* motion,
             int threads) {
  for (auto _ : state) {
    state.SetIterationTime(pipeline::SkinningPassSeconds(*character, *motion, threads));
  }
  ShapeCounters(state, *character, *motion);
}

// pipeline::Bake with the default ladder, or every level when `all_levels`.
void BM_Bake(benchmark::State& state, const Case* c, core::Variant variant, int threads,
             bool all_levels) {
  pipeline::BakeRequest request = RequestOf(*c, variant, threads);
  request.all_levels = all_levels;
  double insitu_ratio_sum = 0;
  int levels = 0;
  // Stages of the bake from the times of its progress reports (the pipeline's own stage
  // names): import -> rank -> prepare -> one "solve" per final level -> encode -> measure.
  // "prepare" to the first finished level holds PreparedMotion::Create and the first
  // level(s); the first to the last finished level, the other levels and, for the default
  // ladder, the bisection probes of the smallest useful level and that level.
  struct Mark {
    std::string stage;
    Clock::time_point at;
  };
  std::vector<Mark> marks;
  const pipeline::ProgressCallback progress = [&](const pipeline::BakeProgress& p) {
    marks.push_back({p.stage, Clock::now()});
  };
  double inputs = 0, rank = 0, to_first_level = 0, later_levels = 0, encode = 0;
  int later_count = 0;
  for (auto _ : state) {
    marks.clear();
    auto output = pipeline::Bake(request, progress);
    if (!output.ok()) {
      Fail(state, output.status());
      return;
    }
    const auto& timing = output->report.at("timing");
    state.SetIterationTime(timing.at("bake_seconds").get<double>());
    insitu_ratio_sum += timing.at("bake_over_skinning_pass").get<double>();
    levels = static_cast<int>(output->report.at("levels").size());
    auto at = [&](std::string_view stage, bool last) -> std::optional<Clock::time_point> {
      std::optional<Clock::time_point> found;
      for (const Mark& m : marks) {
        if (m.stage == stage) {
          found = m.at;
          if (!last) break;
        }
      }
      return found;
    };
    const auto imp = at("import", false), rnk = at("rank", false), prep = at("prepare", false),
               first = at("solve", false), last = at("solve", true), enc = at("encode", false),
               meas = at("measure", false);
    auto span = [](const auto& a, const auto& b) {
      return a && b ? std::chrono::duration<double>(*b - *a).count() : 0.0;
    };
    inputs += span(imp, rnk);
    rank += span(rnk, prep);
    to_first_level += span(prep, first);
    later_levels += span(first, last);
    encode += span(enc, meas);
    later_count += static_cast<int>(std::count_if(marks.begin(), marks.end(),
                                                  [](const Mark& m) { return m.stage == std::string_view("solve"); })) - 1;
  }
  ShapeCounters(state, *c->built, c->sampled);
  state.counters["levels"] = levels;
  // The report's own ratio: its skinning pass runs right after the bake (paired sample).
  const double iterations = std::max<double>(1, static_cast<double>(state.iterations()));
  state.counters["insitu_ratio"] = insitu_ratio_sum / iterations;
  state.counters["inputs_s"] = inputs / iterations;
  state.counters["rank_s"] = rank / iterations;
  state.counters["to_first_level_s"] = to_first_level / iterations;
  state.counters["later_levels_s"] = later_levels / iterations;
  state.counters["later_level_count"] = later_count / iterations;
  state.counters["encode_s"] = encode / iterations;
}

// Stage times of one every-level bake (seconds).
struct Stages {
  double inputs = 0, rank = 0, prepare = 0, solve = 0, encode = 0;
  double total() const { return inputs + rank + prepare + solve + encode; }
};

// pipeline::Bake's all_levels path on a core::RawCharacter, step by step and with Bake's
// tasks side by side: build the character and sample the motion (PrepareInputs), rank and
// prepare, solve every count from n down to the locked minimum on `threads` threads,
// encode. It exists because
// BakeRequest takes an io::Asset, which cannot be made from a subdivided RawCharacter.
// Like Bake's timing.bake_seconds, it leaves out the report (built after the timed part).
StatusOr<Stages> BakeEveryLevel(const core::RawCharacter& raw, const io::Asset& motion_source,
                                const std::string& animation, core::Variant variant,
                                int threads) {
  Stages stages;
  auto begin = Clock::now();
  pipeline::TaskPool pool(threads);
  // The character and the motion side by side, as pipeline::Bake builds them.
  std::optional<StatusOr<std::shared_ptr<const core::Character>>> built;
  std::optional<StatusOr<core::Motion>> sampled;
  pool.Run(2, [&](int task) {
    if (task == 0) {
      built = core::BuildCharacter(raw, pool.Runner());
    } else {
      sampled = motion_source.SampleAnimation(animation, 0, pool.Runner());
    }
  });
  auto character = *std::move(built);
  if (!character.ok()) return character.status();
  auto motion = *std::move(sampled);
  if (!motion.ok()) return motion.status();
  if (Status status = core::ValidateMotion(*motion, **character); !status.ok()) return status;
  stages.inputs = SecondsSince(begin);

  // The ranking and the prepared motion side by side, the ranking first, as in Bake; "prepare"
  // is the time after the ranking is done (Bake's "prepare" report).
  begin = Clock::now();
  core::SolveSettings settings;
  settings.variant = variant;
  std::optional<StatusOr<core::JointRanking>> ranked;
  std::optional<StatusOr<std::shared_ptr<const core::PreparedMotion>>> created;
  pool.Run(2, [&](int task) {
    if (task == 0) {
      ranked = core::RankJointsJob{character->get(), &*motion, {}, Simd()}.Run(pool.Runner());
      stages.rank = SecondsSince(begin);
    } else {
      created = core::PreparedMotion::Create(*character, *motion, settings, Simd(), pool.Runner());
    }
  });
  auto ranking = *std::move(ranked);
  if (!ranking.ok()) return ranking.status();
  auto prepared = *std::move(created);
  if (!prepared.ok()) return prepared.status();
  stages.prepare = SecondsSince(begin) - stages.rank;

  begin = Clock::now();
  const int n = (*character)->joint_count();
  std::vector<int> counts;
  for (int count = n; count >= ranking->locked_count; --count) counts.push_back(count);
  auto results = pipeline::SolveLevelsJob{*prepared, &*ranking, counts}.Run(pool);
  if (!results.ok()) return results.status();
  stages.solve = SecondsSince(begin);

  begin = Clock::now();
  std::vector<pipeline::BakedLevel> baked;
  for (int count : counts) baked.push_back({pipeline::SkeletonLevel(**character, results->at(count)), &results->at(count)});
  auto encoded = pipeline::EncodeBakedLevels(**character, *motion, settings, {}, baked, pool.Runner());
  if (!encoded.ok()) return encoded.status();
  benchmark::DoNotOptimize(encoded->data());
  stages.encode = SecondsSince(begin);
  return stages;
}

void BM_BakeEveryLevel(benchmark::State& state, const core::RawCharacter* raw, const Case* c,
                       const core::Character* built, core::Variant variant, int threads) {
  Stages sum;
  double insitu_ratio_sum = 0;
  for (auto _ : state) {
    auto stages = BakeEveryLevel(*raw, c->motion ? *c->motion : *c->character, c->animation,
                                 variant, threads);
    if (!stages.ok()) {
      Fail(state, stages.status());
      return;
    }
    state.SetIterationTime(stages->total());
    // Paired, as Bake's report pairs them: a skinning pass right after the bake, untimed.
    insitu_ratio_sum +=
        stages->total() / pipeline::SkinningPassSeconds(*built, c->sampled, threads);
    sum.inputs += stages->inputs;
    sum.rank += stages->rank;
    sum.prepare += stages->prepare;
    sum.solve += stages->solve;
    sum.encode += stages->encode;
  }
  ShapeCounters(state, *built, c->sampled);
  const double iterations = std::max<double>(1, static_cast<double>(state.iterations()));
  state.counters["levels"] = built->joint_count();  // every count down to the root
  state.counters["insitu_ratio"] = insitu_ratio_sum / iterations;
  state.counters["inputs_s"] = sum.inputs / iterations;
  state.counters["rank_s"] = sum.rank / iterations;
  state.counters["prepare_s"] = sum.prepare / iterations;
  state.counters["solve_s"] = sum.solve / iterations;
  state.counters["encode_s"] = sum.encode / iterations;
}

// The mid level (round(n/2) joints) of a case, with its prepared motion.
struct MidLevel {
  std::shared_ptr<const core::PreparedMotion> prepared;
  core::ReducedSkeleton level;
};

StatusOr<MidLevel> MakeMidLevel(const Case& c) {
  auto ranking = core::RankJointsJob{c.built.get(), &c.sampled, {}}.Run();
  if (!ranking.ok()) return ranking.status();
  core::SolveSettings settings;  // vpno+pd: the naive solve fits positions and normals
  auto prepared = core::PreparedMotion::Create(c.built, c.sampled, settings);
  if (!prepared.ok()) return prepared.status();
  const int n = c.built->joint_count();
  const int count = std::max(ranking->locked_count, static_cast<int>(std::lround(0.5 * n)));
  auto level = core::ReduceSkeletonToCount(*c.built, *ranking, count);
  if (!level.ok()) return level.status();
  return MidLevel{*prepared, *level};
}

void BM_Naive(benchmark::State& state, const Case* c, int naive_frames) {
  auto mid = MakeMidLevel(*c);
  if (!mid.ok()) {
    Fail(state, mid.status());
    return;
  }
  const int frames = c->sampled.frame_count;
  const int used = std::min(naive_frames, frames);
  for (auto _ : state) {
    const auto begin = Clock::now();
    for (int q = 0; q < used; ++q) {
      const int t = used == 1 ? 0 : static_cast<int>(std::lround(double(q) * (frames - 1) / (used - 1)));
      auto solution = core::SolveFrameReference(*mid->prepared, mid->level, t);
      benchmark::DoNotOptimize(solution.data());
    }
    // Scaled to the whole motion: every frame costs the same (same system size).
    state.SetIterationTime(SecondsSince(begin) * frames / used);
  }
  ShapeCounters(state, *c->built, c->sampled);
  state.counters["kept"] = mid->level.kept_count();
  state.counters["naive_frames"] = used;
}

void BM_Level(benchmark::State& state, const Case* c, bool least_squares_only) {
  auto mid = MakeMidLevel(*c);
  if (!mid.ok()) {
    Fail(state, mid.status());
    return;
  }
  for (auto _ : state) {
    const auto begin = Clock::now();
    if (least_squares_only) {
      auto x = mid->prepared->SolveLeastSquares(mid->level);
      if (!x.ok()) {
        Fail(state, x.status());
        return;
      }
      benchmark::DoNotOptimize(x->data());
    } else {
      auto result = mid->prepared->SolveLevel(mid->level);
      if (!result.ok()) {
        Fail(state, result.status());
        return;
      }
      benchmark::DoNotOptimize(result->matrices.data());
    }
    state.SetIterationTime(SecondsSince(begin));
  }
  ShapeCounters(state, *c->built, c->sampled);
  state.counters["kept"] = mid->level.kept_count();
}

bool IsAssetFile(const fs::path& path) {
  static const char* kExtensions[] = {".glb", ".gltf", ".fbx", ".dae", ".bvh", ".x", ".smd"};
  const std::string ext = path.extension().string();
  return std::any_of(std::begin(kExtensions), std::end(kExtensions),
                     [&](const char* e) { return ext == e; });
}

std::vector<fs::path> ListAssets(const fs::path& dir) {
  std::vector<fs::path> files;
  std::error_code error;
  for (const auto& entry : fs::directory_iterator(dir, error)) {
    if (entry.is_regular_file() && IsAssetFile(entry.path())) files.push_back(entry.path());
  }
  std::sort(files.begin(), files.end());
  return files;
}

// Imports every file and pairs each with a motion; prints what it skips and why.
std::vector<std::unique_ptr<Case>> LoadCases(const Options& options) {
  std::vector<fs::path> files = ListAssets(fs::path(options.data_dir) / "characters");
  for (const fs::path& f : ListAssets(fs::path(options.data_dir) / "motions")) files.push_back(f);
  std::map<std::string, std::shared_ptr<const io::Asset>> assets;
  std::vector<std::string> order;
  for (const fs::path& f : files) {
    auto asset = io::LoadAssetFile(f);
    const std::string name = f.filename().string();
    if (!asset.ok()) {
      std::fprintf(stderr, "note: skipping %s: %s\n", name.c_str(), asset.status().ToString().c_str());
      continue;
    }
    assets[name] = *asset;
    order.push_back(name);
  }

  std::vector<std::unique_ptr<Case>> cases;
  for (const std::string& name : order) {
    auto c = std::make_unique<Case>();
    c->file = name;
    c->label = name;
    c->character = assets[name];
    if (c->character->animations().empty()) {
      // A clip of another file: the preferred pairing, else the retarget that matches the
      // most joints.
      for (const MotionChoice& choice : kPreferredMotions) {
        if (name == choice.character && assets.count(choice.motion)) {
          c->motion = assets[choice.motion];
          c->animation = choice.animation;
          c->label = name + "+" + choice.animation;
        }
      }
      if (!c->motion) {
        size_t best_unmatched = SIZE_MAX;
        for (const std::string& other : order) {
          if (assets[other]->animations().empty()) continue;
          auto retargeted = io::RetargetAnimation(*assets[other], "", 0, c->character->character());
          if (!retargeted.ok()) continue;
          if (retargeted->unmatched_target_joints.size() < best_unmatched) {
            best_unmatched = retargeted->unmatched_target_joints.size();
            c->motion = assets[other];
            c->animation = "";
            c->label = name + "+" + other;
          }
        }
      }
      if (!c->motion) {
        std::fprintf(stderr,
                     "note: skipping %s: no animation, and no file's clip retargets onto it "
                     "(fewer than half of its joint names match)\n",
                     name.c_str());
        continue;
      }
    }
    pipeline::BakeRequest request = RequestOf(*c, core::Variant::kVPNOPD, 1);
    auto inputs = pipeline::PrepareInputs(request);
    if (!inputs.ok()) {
      std::fprintf(stderr, "note: skipping %s: %s\n", c->label.c_str(), inputs.status().ToString().c_str());
      continue;
    }
    c->built = inputs->character;
    c->sampled = std::move(inputs->motion);
    cases.push_back(std::move(c));
  }
  return cases;
}

// The subdivided copies (owned for the life of the run).
struct Dense {
  const Case* source = nullptr;
  std::string label;
  core::RawCharacter raw;
  std::shared_ptr<const core::Character> built;
};

std::string ThreadsSuffix(int threads) { return "/threads:" + std::to_string(threads); }

void RegisterAll(const Options& options, const std::vector<std::unique_ptr<Case>>& cases,
                 const std::vector<std::unique_ptr<Dense>>& dense) {
  for (int threads : options.threads) {
    for (const auto& c : cases) {
      benchmark::RegisterBenchmark(("skin/" + c->label + ThreadsSuffix(threads)).c_str(), BM_Skin,
                                   c->built.get(), &c->sampled, threads)
          ->UseManualTime()
          ->Unit(benchmark::kMillisecond);
      for (core::Variant variant : options.variants) {
        benchmark::RegisterBenchmark(("bake/" + c->label + "/" + core::VariantName(variant) +
                                      "/default" + ThreadsSuffix(threads))
                                         .c_str(),
                                     BM_Bake, c.get(), variant, threads, false)
            ->UseManualTime()
            ->Unit(benchmark::kMillisecond);
      }
    }
    for (const auto& d : dense) {
      // The original character, every level through pipeline::Bake, and the bench's
      // step-by-step replica of that path (which the subdivided copies need) beside it.
      const Case* c = d->source;
      for (core::Variant variant : options.variants) {
        benchmark::RegisterBenchmark(("bake/" + c->label + "/" + core::VariantName(variant) +
                                      "/all" + ThreadsSuffix(threads))
                                         .c_str(),
                                     BM_Bake, c, variant, threads, true)
            ->UseManualTime()
            ->Unit(benchmark::kMillisecond);
      }
      benchmark::RegisterBenchmark(("replica/" + c->label + "/vpno+pd/all" + ThreadsSuffix(threads)).c_str(),
                                   BM_BakeEveryLevel, &c->character->character(), c, c->built.get(),
                                   core::Variant::kVPNOPD, threads)
          ->UseManualTime()
          ->Unit(benchmark::kMillisecond);
      benchmark::RegisterBenchmark(("skin/" + d->label + ThreadsSuffix(threads)).c_str(), BM_Skin,
                                   d->built.get(), &d->source->sampled, threads)
          ->UseManualTime()
          ->Unit(benchmark::kMillisecond);
      for (core::Variant variant : options.variants) {
        benchmark::RegisterBenchmark(("bake/" + d->label + "/" + core::VariantName(variant) +
                                      "/all" + ThreadsSuffix(threads))
                                         .c_str(),
                                     BM_BakeEveryLevel, &d->raw, d->source, d->built.get(),
                                     variant, threads)
            ->UseManualTime()
            ->Unit(benchmark::kMillisecond);
      }
    }
  }
  // The naive solve and its fast counterparts run on one thread (a single level).
  int naive_count = 0;
  for (const auto& c : cases) {
    if (options.quick && naive_count >= 3) break;
    ++naive_count;
    benchmark::RegisterBenchmark(("naive/" + c->label).c_str(), BM_Naive, c.get(), options.naive_frames)
        ->UseManualTime()
        ->Iterations(1)
        ->Unit(benchmark::kMillisecond);
    benchmark::RegisterBenchmark(("level/" + c->label).c_str(), BM_Level, c.get(), false)
        ->UseManualTime()
        ->Unit(benchmark::kMillisecond);
    benchmark::RegisterBenchmark(("ls/" + c->label).c_str(), BM_Level, c.get(), true)
        ->UseManualTime()
        ->Unit(benchmark::kMillisecond);
  }
}

// --breakdown: where the time of the levels goes, stage by stage, on one thread, median of
// 5 runs per figure, as markdown rows. SolveLevel is split from outside the core:
//   LS      SolveLeastSquares (G and B, Cholesky, the 3T right-hand sides)
//   errors     SolveOptimized(vp or vpno) - LS: the optimised errors (quadratic forms,
//              exact maximum vertex error, sampled figures) and the float copy
//   baselines  every level's baseline errors, one from the other (BaselineSequence)
//   PD         SolveOptimized(+pd) - SolveOptimized(without): polar projection, translation
//              re-solve
// Default ladder: n, ~3n/4, ~n/2, ~n/4 (the smallest useful level and the bisection probes
// that find it are left out; the benchmark's bake/ cases include them).
template <typename F>
double MedianSeconds(int runs, F&& fn) {
  std::vector<double> times;
  for (int r = 0; r < runs; ++r) {
    const auto begin = Clock::now();
    fn();
    times.push_back(SecondsSince(begin));
  }
  std::sort(times.begin(), times.end());
  return times[times.size() / 2];
}

void PrintBreakdownHeader() {
  std::printf(
      "| case | fit | p | n | T | levels | skin ms | inputs | rank | prepare | LS | errors | baselines "
      "| PD | sum without PD (x skin) | sum with PD (x skin) |\n"
      "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
}

void PrintBreakdown(const std::string& label, const Case& c,
                    const std::shared_ptr<const core::Character>& built,
                    const core::RawCharacter* raw, const Options& options, bool every_level) {
  const core::Character& character = *built;
  const int runs = 5;
  const core::Motion& motion = c.sampled;
  const double skin = MedianSeconds(runs, [&] { pipeline::SkinningPassSeconds(character, motion, 1); });
  double inputs = 0;
  if (raw != nullptr) {
    inputs = MedianSeconds(runs, [&] {
      auto character_again = core::BuildCharacter(*raw);
      auto sampled = (c.motion ? *c.motion : *c.character).SampleAnimation(c.animation, 0);
      benchmark::DoNotOptimize(character_again.ok() && sampled.ok());
    });
  } else {
    inputs = MedianSeconds(runs, [&] {
      auto prepared = pipeline::PrepareInputs(RequestOf(c, core::Variant::kVPNOPD, 1));
      benchmark::DoNotOptimize(prepared.ok());
    });
  }
  const double rank = MedianSeconds(runs, [&] {
    auto r = core::RankJointsJob{&character, &motion, {}}.Run();
    benchmark::DoNotOptimize(r.ok());
  });
  auto ranking = core::RankJointsJob{&character, &motion, {}}.Run();
  const int n = character.joint_count();
  std::vector<int> counts;
  if (every_level) {
    for (int count = n; count >= ranking->locked_count; --count) counts.push_back(count);
  } else {
    counts = QuarterLadder(n, ranking->locked_count);
  }
  const bool want_vp = std::count(options.variants.begin(), options.variants.end(), core::Variant::kVP) ||
                       std::count(options.variants.begin(), options.variants.end(), core::Variant::kVPPD);
  const bool want_vpno = std::count(options.variants.begin(), options.variants.end(), core::Variant::kVPNO) ||
                         std::count(options.variants.begin(), options.variants.end(), core::Variant::kVPNOPD);
  for (const auto& [fit, rigid] : {std::pair{core::Variant::kVP, core::Variant::kVPPD},
                                   std::pair{core::Variant::kVPNO, core::Variant::kVPNOPD}}) {
    if ((fit == core::Variant::kVP && !want_vp) || (fit == core::Variant::kVPNO && !want_vpno)) continue;
    core::SolveSettings settings;
    settings.variant = fit;
    std::shared_ptr<const core::PreparedMotion> prepared_fit, prepared_rigid;
    const double prepare = MedianSeconds(runs, [&] {
      prepared_fit = *core::PreparedMotion::Create(built, motion, settings, Simd());
    });
    settings.variant = rigid;
    prepared_rigid = *core::PreparedMotion::Create(built, motion, settings, Simd());
    double ls = 0, level_fit = 0, level_rigid = 0;
    std::string per_level;
    std::vector<core::ReducedSkeleton> levels;
    for (int count : counts) levels.push_back(*core::ReduceSkeletonToCount(character, *ranking, count));
    const double baselines = MedianSeconds(runs, [&] {
      core::BaselineSequence sequence(prepared_fit);
      for (const core::ReducedSkeleton& level : levels) benchmark::DoNotOptimize(sequence.Next(level).ok());
    });
    for (size_t index = 0; index < counts.size(); ++index) {
      const int count = counts[index];
      const core::ReducedSkeleton& reduced = levels[index];
      const double ls_one = MedianSeconds(runs, [&] { benchmark::DoNotOptimize(prepared_fit->SolveLeastSquares(reduced).ok()); });
      const double fit_one = MedianSeconds(runs, [&] { benchmark::DoNotOptimize(prepared_fit->SolveOptimized(reduced).ok()); });
      const double rigid_one = MedianSeconds(runs, [&] { benchmark::DoNotOptimize(prepared_rigid->SolveOptimized(reduced).ok()); });
      ls += ls_one;
      level_fit += fit_one;
      level_rigid += rigid_one;
      char buffer[80];
      std::snprintf(buffer, sizeof buffer, " %d:%.2f/%.2f/%.2f", count, 1e3 * ls_one,
                    1e3 * (fit_one - ls_one), 1e3 * (rigid_one - fit_one));
      per_level += buffer;
    }
    const double without = inputs + rank + prepare + level_fit + baselines;
    const double with = inputs + rank + prepare + level_rigid + baselines;
    std::printf(
        "| `%s` | %s | %d | %d | %d | %zu | %.2f | %.2f | %.2f | %.2f | %.2f | %.2f | %.2f | %.2f "
        "| %.1f (%.1fx) | %.1f (%.1fx) |\n",
        label.c_str(), core::VariantName(fit), character.vertex_count(), n, motion.frame_count,
        counts.size(), 1e3 * skin, 1e3 * inputs, 1e3 * rank, 1e3 * prepare, 1e3 * ls,
        1e3 * (level_fit - ls), 1e3 * baselines, 1e3 * (level_rigid - level_fit), 1e3 * without,
        without / skin, 1e3 * with, with / skin);
    if (options.per_level) std::printf("    per level (kept: LS / errors / PD ms):%s\n", per_level.c_str());
    std::fflush(stdout);
  }
}

int Main(int argc, char** argv) {
  if (const char* setting = std::getenv("MOTIONLOD_SIMD"); setting != nullptr) {
    if (auto choice = core::ParseSimdChoice(setting); !choice.ok()) {
      std::fprintf(stderr, "MOTIONLOD_SIMD is %s\n", choice.status().message().c_str());
      return 2;
    }
  }
  Options options;
  std::vector<char*> rest = {argv[0]};
  for (int a = 1; a < argc; ++a) {
    const std::string_view arg = argv[a];
    auto value = [&](std::string_view flag) -> std::optional<std::string> {
      if (arg.rfind(flag, 0) == 0 && arg.size() > flag.size() && arg[flag.size()] == '=') {
        return std::string(arg.substr(flag.size() + 1));
      }
      return std::nullopt;
    };
    if (auto v = value("--data")) {
      options.data_dir = *v;
    } else if (auto v = value("--threads")) {
      options.threads.clear();
      for (size_t at = 0; at <= v->size();) {
        const size_t comma = std::min(v->find(',', at), v->size());
        options.threads.push_back(std::max(1, std::atoi(v->substr(at, comma - at).c_str())));
        at = comma + 1;
      }
    } else if (auto v = value("--variants")) {
      options.variants.clear();
      for (size_t at = 0; at <= v->size();) {
        const size_t comma = std::min(v->find(',', at), v->size());
        auto variant = core::ParseVariant(v->substr(at, comma - at));
        if (!variant.ok()) {
          std::fprintf(stderr, "%s\n", variant.status().ToString().c_str());
          return 2;
        }
        options.variants.push_back(*variant);
        at = comma + 1;
      }
    } else if (arg == "--quick") {
      options.quick = true;
    } else if (arg == "--breakdown") {
      options.breakdown = true;
    } else if (arg == "--per_level") {
      options.per_level = true;
    } else if (auto v = value("--only")) {
      options.only = *v;
    } else if (auto v = value("--min_vertices")) {
      options.min_vertices = std::atoi(v->c_str());
    } else if (auto v = value("--naive_frames")) {
      options.naive_frames = std::max(1, std::atoi(v->c_str()));
    } else {
      rest.push_back(argv[a]);
    }
  }
  if (options.quick && options.variants.size() == 4) {
    options.variants = {core::Variant::kVP, core::Variant::kVPNOPD};
  }

  const auto cases = LoadCases(options);
  if (cases.empty()) {
    std::fprintf(stderr, "no bakeable file under %s\n", options.data_dir.c_str());
    return 2;
  }
  std::vector<std::unique_ptr<Dense>> dense;
  for (const char* name : kSubdivided) {
    if (options.quick && dense.size() >= 2) break;
    for (const auto& c : cases) {
      if (c->file != name || c->motion) continue;  // own animation only (BakeEveryLevel samples it)
      auto d = std::make_unique<Dense>();
      d->source = c.get();
      int steps = 0;
      d->raw = SubdivideToVertexCount(c->character->character(), options.min_vertices, &steps);
      auto built = core::BuildCharacter(d->raw);
      if (!built.ok()) {
        std::fprintf(stderr, "note: subdivided %s is invalid: %s\n", name, built.status().ToString().c_str());
        break;
      }
      d->built = *built;
      d->label = c->label + "@" + std::to_string(d->built->vertex_count()) + "v";
      std::fprintf(stderr, "note: %s: %d subdivision step(s), %d -> %d vertices\n", name, steps,
                   c->built->vertex_count(), d->built->vertex_count());
      dense.push_back(std::move(d));
      break;
    }
  }

  if (options.breakdown) {
    PrintBreakdownHeader();
    for (const auto& c : cases) {
      if (c->label.find(options.only) != std::string::npos) {
        PrintBreakdown(c->label + " (ladder)", *c, c->built, nullptr, options, false);
      }
    }
    for (const auto& d : dense) {
      if (d->label.find(options.only) != std::string::npos) {
        PrintBreakdown(d->label + " (all)", *d->source, d->built, &d->raw, options, true);
      }
    }
    return 0;
  }

  RegisterAll(options, cases, dense);
  int rest_argc = static_cast<int>(rest.size());
  benchmark::Initialize(&rest_argc, rest.data());
  if (benchmark::ReportUnrecognizedArguments(rest_argc, rest.data())) return 2;
  benchmark::AddCustomContext("data_dir", options.data_dir);
  benchmark::AddCustomContext("simd", core::SimdVersionName(Simd()));
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}

}  // namespace
}  // namespace motionlod::bench

// Bakes run with the allocator settings of the programs that bake (pipeline/allocator.h).
int main(int argc, char** argv) {
  motionlod::pipeline::KeepFreedBlocksForReuse();
  return motionlod::bench::Main(argc, argv);
}
