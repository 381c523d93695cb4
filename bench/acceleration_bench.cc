// Does each acceleration of the core pay for itself? For every real character of
// kCharacters subdivided to >= 10k vertices (bench/subdivide.h) with its own first clip,
// every level from all joints down to the root (vpno+pd, the default), each accelerated
// step is timed beside the simpler code it replaces, in one run, in random interleaved
// order, and the medians compared:
//   simd            the solve and errors of every level (SolveOptimized, BaselineSequence),
//                   SimdChoice::kWidest against kBaseline
//   threads         the same on a pool of 2 threads against 1
//   factor          G's block Cholesky factor and the 3T right-hand sides against Eigen's
//                   dense LLT of the same G and B
//   polar           NearestRotations (batched Newton steps) against the SVD reference of
//                   every K'_s(t) of the least-squares solutions
//   errors          BaselineErrors (quadratic forms, bounded maximum, sample) against the
//                   skinned reference (core/reference/level_errors_reference.h)
//   max search      the maximum vertex error alone, bounded search against brute force over
//                   every vertex and frame
//   sequence        BaselineSequence against BaselineErrors level by level
//   ranking         RankJointsJob against RankJointsReference
// Prints a markdown table (docs/PERFORMANCE.md): the gain is reference over accelerated.
//   acceleration_bench [--data=DIR] [--repetitions=N] [--min_vertices=N]
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include <Eigen/Cholesky>

#include "bench/subdivide.h"
#include "core/baseline_sequence.h"
#include "core/internal/block_cholesky.h"
#include "core/internal/level_errors.h"
#include "core/internal/level_solve.h"
#include "core/internal/normal_equations.h"
#include "core/internal/prepared_data.h"
#include "core/polar.h"
#include "core/rank_joints.h"
#include "core/reduce_skeleton.h"
#include "core/reference/level_errors_reference.h"
#include "core/reference/polar_reference.h"
#include "core/reference/rank_joints_reference.h"
#include "core/solve_levels.h"
#include "io/asset.h"
#include "pipeline/allocator.h"
#include "pipeline/task_pool.h"

namespace motionlod::bench {
namespace {

using Clock = std::chrono::steady_clock;
namespace fs = std::filesystem;

constexpr const char* kCharacters[] = {"Orc.gltf", "Rig_Medium_MovementBasic.glb",
                                       "stormtrooper.dae", "RobotExpressive.glb"};

struct Workload {
  std::string label;
  std::shared_ptr<const core::Character> character;
  core::Motion motion;
  core::JointRanking ranking;
  std::vector<core::ReducedSkeleton> levels;  // every level, all joints first
};

// One comparison: the accelerated code and the code it replaces, timed side by side.
struct Comparison {
  std::string step;
  std::function<void()> accelerated, reference;
  std::vector<double> accelerated_seconds = {}, reference_seconds = {};
};

double Seconds(const std::function<void()>& run) {
  const auto start = Clock::now();
  run();
  return std::chrono::duration<double>(Clock::now() - start).count();
}

double Median(std::vector<double> values) {
  std::sort(values.begin(), values.end());
  return values[values.size() / 2];
}

void Check(const Status& status, const char* what) {
  if (!status.ok()) {
    std::fprintf(stderr, "%s: %s\n", what, status.ToString().c_str());
    std::exit(1);
  }
}

std::shared_ptr<const core::PreparedMotion> Prepare(const Workload& w, core::SimdChoice simd,
                                                    const PieceRunner& run = {}) {
  auto prepared = core::PreparedMotion::Create(w.character, w.motion, core::SolveSettings{}, simd, run);
  Check(prepared.status(), "prepare");
  return *prepared;
}

// Every level solved with its errors, as an every-level bake solves them: SolveOptimized
// per level, the baselines in one sequence.
void SolveEveryLevel(const Workload& w, core::SimdChoice simd, pipeline::TaskPool* pool) {
  const PieceRunner run = pool != nullptr ? pool->Runner() : PieceRunner{};
  const auto prepared = Prepare(w, simd, run);
  const int count = static_cast<int>(w.levels.size());
  const auto solve = [&](int task) {
    if (task == count) {
      core::BaselineSequence sequence(prepared);
      for (const core::ReducedSkeleton& level : w.levels) Check(sequence.Next(level).status(), "sequence");
      return;
    }
    Check(prepared->SolveOptimized(w.levels[task], run).status(), "solve");
  };
  if (pool != nullptr) {
    pool->Run(count + 1, solve);
  } else {
    for (int task = 0; task <= count; ++task) solve(task);
  }
}

std::vector<Comparison> Comparisons(const Workload& w, pipeline::TaskPool& two_threads) {
  std::vector<Comparison> out;
  const auto prepared = Prepare(w, core::SimdChoice::kWidest);
  const core::internal::PreparedData& d = prepared->data();
  out.push_back({"simd (AVX2+FMA against SSE2)",
                 [&w] { SolveEveryLevel(w, core::SimdChoice::kWidest, nullptr); },
                 [&w] { SolveEveryLevel(w, core::SimdChoice::kBaseline, nullptr); }});
  out.push_back({"threads (2 against 1)",
                 [&w, &two_threads] { SolveEveryLevel(w, core::SimdChoice::kWidest, &two_threads); },
                 [&w] { SolveEveryLevel(w, core::SimdChoice::kWidest, nullptr); }});
  // G and B of every level, block and dense (B = G X), made once: only the factors and
  // the solves of the 3T right-hand sides are timed.
  struct System {
    core::BlockSymmetric<4> g;
    Eigen::MatrixXd dense_g, b;
  };
  auto systems = std::make_shared<std::vector<System>>();
  for (const core::ReducedSkeleton& level : w.levels) {
    if (level.kept_count() == w.character->joint_count()) continue;  // no system to solve
    auto system = core::internal::SolveNormalEquations(d, level);
    Check(system.status(), "normal equations");
    const int dim = 4 * level.kept_count();
    System dense{system->g, Eigen::MatrixXd::Zero(dim, dim), Eigen::MatrixXd()};
    for (int s = 0; s < level.kept_count(); ++s) dense.dense_g.block<4, 4>(4 * s, 4 * s) = system->g.diagonal(s);
    for (const auto& block : system->g.lower()) {
      dense.dense_g.block<4, 4>(4 * block.row, 4 * block.col) = block.value;
      dense.dense_g.block<4, 4>(4 * block.col, 4 * block.row) = block.value.transpose();
    }
    dense.b = dense.dense_g * system->x;
    systems->push_back(std::move(dense));
  }
  out.push_back({"factor (block Cholesky against dense LLT)",
                 [systems] {
                   for (const System& system : *systems) {
                     auto factor = core::BlockCholesky<4>::Factor(system.g);
                     Check(factor.status(), "factor");
                     if (!factor->SolveTransposed(system.b.transpose()).allFinite()) std::abort();
                   }
                 },
                 [systems] {
                   for (const System& system : *systems) {
                     if (!system.dense_g.llt().solve(system.b).allFinite()) std::abort();
                   }
                 }});
  out.push_back({"polar (batched Newton against SVD)",
                 [&w, prepared] {
                   for (const core::ReducedSkeleton& level : w.levels) {
                     Eigen::MatrixXd x = *prepared->SolveLeastSquares(level);
                     std::vector<double*> blocks;
                     for (Eigen::Index t = 0; t < x.cols(); t += 3) {
                       for (Eigen::Index s = 0; s < x.rows(); s += 4) blocks.push_back(x.data() + t * x.rows() + s);
                     }
                     core::NearestRotations(blocks, x.rows());
                   }
                 },
                 [&w, prepared] {
                   for (const core::ReducedSkeleton& level : w.levels) {
                     Eigen::MatrixXd x = *prepared->SolveLeastSquares(level);
                     for (Eigen::Index t = 0; t < x.cols(); t += 3) {
                       for (Eigen::Index s = 0; s < x.rows(); s += 4) {
                         x.block<3, 3>(s, t) = core::NearestRotationReference(x.block<3, 3>(s, t));
                       }
                     }
                   }
                 }});
  out.push_back({"errors (quadratic forms and bounded search against skinning)",
                 [&w, prepared] {
                   for (const core::ReducedSkeleton& level : w.levels) {
                     Check(prepared->BaselineErrors(level).status(), "errors");
                   }
                 },
                 [&w, prepared] {
                   for (const core::ReducedSkeleton& level : w.levels) {
                     (void)core::BaselineErrorsReference(*prepared, level);
                   }
                 }});
  out.push_back({"max search (bounded against every vertex)",
                 [&w, &d] {
                   for (const core::ReducedSkeleton& level : w.levels) {
                     core::LevelErrors errors;
                     core::internal::EvaluateErrors(d, core::internal::BaselineDelta(d, level),
                                                    level.kept_joints,
                                                    core::internal::Figures::kMaxVertexError, errors);
                   }
                 },
                 [&w, &d] {
                   // |d_i(t)| of every vertex in every frame, blended in float as the search is.
                   const core::RawSkin& skin = w.character->skin();
                   float largest = 0;
                   for (const core::ReducedSkeleton& level : w.levels) {
                     for (int t = 0; t < d.frames; ++t) {
                       std::vector<Eigen::Matrix<float, 3, 4>> delta(d.n);
                       for (int k = 0; k < d.n; ++k) {
                         const int kept = level.kept_joints[level.joint_to_slot[k]];
                         delta[k] = (d.kt.block<4, 3>(4 * kept, 3 * t) - d.kt.block<4, 3>(4 * k, 3 * t))
                                        .transpose()
                                        .cast<float>();
                       }
                       for (size_t i = 0; i < skin.positions.size(); ++i) {
                         Eigen::Vector3f moved = Eigen::Vector3f::Zero();
                         for (uint32_t e = skin.influence_offsets[i]; e < skin.influence_offsets[i + 1]; ++e) {
                           const auto& m = delta[skin.influence_joints[e]];
                           moved += skin.influence_weights[e] * (m.leftCols<3>() * skin.positions[i] + m.col(3));
                         }
                         largest = std::max(largest, moved.squaredNorm());
                       }
                     }
                   }
                   if (!(largest >= 0)) std::abort();
                 }});
  out.push_back({"sequence (BaselineSequence against level by level)",
                 [&w, prepared] {
                   core::BaselineSequence sequence(prepared);
                   for (const core::ReducedSkeleton& level : w.levels) Check(sequence.Next(level).status(), "sequence");
                 },
                 [&w, prepared] {
                   for (const core::ReducedSkeleton& level : w.levels) {
                     Check(prepared->BaselineErrors(level).status(), "errors");
                   }
                 }});
  out.push_back({"ranking (RankJointsJob against the reference)",
                 [&w] { Check(core::RankJointsJob{w.character.get(), &w.motion, {}}.Run().status(), "rank"); },
                 [&w] { (void)core::RankJointsReference(*w.character, w.motion, {}); }});
  return out;
}

int Main(int argc, char** argv) {
  std::string data = MOTIONLOD_BENCH_DATA;
  int repetitions = 5, min_vertices = 10000;
  for (int a = 1; a < argc; ++a) {
    const std::string arg = argv[a];
    if (arg.rfind("--data=", 0) == 0) {
      data = arg.substr(7);
    } else if (arg.rfind("--repetitions=", 0) == 0) {
      repetitions = std::max(1, std::atoi(arg.c_str() + 14));
    } else if (arg.rfind("--min_vertices=", 0) == 0) {
      min_vertices = std::max(1, std::atoi(arg.c_str() + 15));
    } else {
      std::fprintf(stderr, "usage: %s [--data=DIR] [--repetitions=N] [--min_vertices=N]\n", argv[0]);
      return 2;
    }
  }
  pipeline::TaskPool two_threads(2);
  std::mt19937 random(42);
  std::printf("| workload | step | accelerated ms | replaced ms | gain |\n|---|---|---|---|---|\n");
  for (const char* name : kCharacters) {
    const fs::path path = fs::path(data) / "characters" / name;
    if (!fs::exists(path)) continue;
    auto asset = io::LoadAssetFile(path);
    Check(asset.status(), name);
    Workload w;
    auto built = core::BuildCharacter(SubdivideToVertexCount((*asset)->character(), min_vertices));
    Check(built.status(), "subdivide");
    w.character = *built;
    auto motion = (*asset)->SampleAnimation("", 0);
    Check(motion.status(), "sample");
    w.motion = *std::move(motion);
    w.ranking = *core::RankJointsJob{w.character.get(), &w.motion, {}}.Run();
    for (int kept = w.character->joint_count(); kept >= w.ranking.locked_count; --kept) {
      w.levels.push_back(*core::ReduceSkeletonToCount(*w.character, w.ranking, kept));
    }
    w.label = std::string(name) + "@" + std::to_string(w.character->vertex_count()) + "v, " +
              std::to_string(w.motion.frame_count) + " frames, " + std::to_string(w.levels.size()) +
              " levels";
    std::vector<Comparison> comparisons = Comparisons(w, two_threads);
    // Random interleaved order: a slow moment of the machine falls on both sides alike.
    std::vector<std::pair<size_t, bool>> runs;
    for (size_t c = 0; c < comparisons.size(); ++c) {
      for (int r = 0; r < repetitions; ++r) {
        runs.emplace_back(c, true);
        runs.emplace_back(c, false);
      }
    }
    std::shuffle(runs.begin(), runs.end(), random);
    for (const auto& [c, accelerated] : runs) {
      Comparison& comparison = comparisons[c];
      if (accelerated) {
        comparison.accelerated_seconds.push_back(Seconds(comparison.accelerated));
      } else {
        comparison.reference_seconds.push_back(Seconds(comparison.reference));
      }
    }
    for (const Comparison& comparison : comparisons) {
      const double fast = Median(comparison.accelerated_seconds);
      const double slow = Median(comparison.reference_seconds);
      std::printf("| %s | %s | %.2f | %.2f | %.2fx |\n", w.label.c_str(), comparison.step.c_str(),
                  1e3 * fast, 1e3 * slow, slow / fast);
      std::fflush(stdout);
    }
  }
  return 0;
}

}  // namespace
}  // namespace motionlod::bench

int main(int argc, char** argv) {
  motionlod::pipeline::KeepFreedBlocksForReuse();
  return motionlod::bench::Main(argc, argv);
}
