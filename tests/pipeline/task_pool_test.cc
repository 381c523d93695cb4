#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <thread>
#include <vector>

#include "core/character.h"
#include "core/internal/skin_clusters.h"
#include "core/rank_joints.h"
#include "core/reduce_skeleton.h"
#include "core/solve_levels.h"
#include "io/asset.h"
#include "pipeline/bake.h"
#include "pipeline/task_pool.h"

namespace motionlod::pipeline {
namespace {

// Waits up to 30 s for `condition`; whether it came true.
template <typename Condition>
bool WaitFor(Condition&& condition) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(30);
  while (!condition() && std::chrono::steady_clock::now() < deadline) std::this_thread::yield();
  return condition();
}

TEST(TaskPool, RunsEveryPieceOnceAndReportsEachCountInOrder) {
  for (int threads : {1, 2, 4}) {
    TaskPool pool(threads);
    EXPECT_EQ(pool.threads(), threads);
    for (int count : {0, 1, 2, 3, 100}) {
      std::vector<std::atomic<int>> runs(count);
      std::vector<int> reported;
      const std::thread::id caller = std::this_thread::get_id();
      bool reported_elsewhere = false;
      pool.Run(
          count, [&](int index) { ++runs[index]; },
          [&](int done) {
            reported.push_back(done);
            reported_elsewhere |= std::this_thread::get_id() != caller;
          });
      for (int index = 0; index < count; ++index) {
        EXPECT_EQ(runs[index].load(), 1) << "threads " << threads << " count " << count << " index " << index;
      }
      ASSERT_EQ(static_cast<int>(reported.size()), count) << "threads " << threads;
      for (int r = 0; r < count; ++r) EXPECT_EQ(reported[r], r + 1);
      EXPECT_FALSE(reported_elsewhere);
    }
  }
}

// Two pieces that each wait for the other to start finish only if they run at the same
// time: the pool really uses its worker beside the calling thread.
TEST(TaskPool, PiecesRunAtTheSameTime) {
  TaskPool pool(2);
  std::atomic<int> started{0};
  std::atomic<int> met{0};
  pool.Run(2, [&](int) {
    ++started;
    if (WaitFor([&] { return started.load() == 2; })) ++met;
  });
  EXPECT_EQ(met.load(), 2);
}

// Past their spin, idle threads sleep on the condition variable: a worker idle for far
// longer than the spin still takes the next job's piece, and a caller whose last piece
// runs elsewhere for longer than the spin is still woken when it ends.
TEST(TaskPool, ThreadsPastTheirSpinAreWokenByTheNextChange) {
  TaskPool pool(2);
  for (int round = 0; round < 3; ++round) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));  // the worker now sleeps
    std::atomic<int> started{0};
    std::atomic<int> met{0};
    pool.Run(2, [&](int) {
      ++started;
      if (WaitFor([&] { return started.load() == 2; })) ++met;
    });
    EXPECT_EQ(met.load(), 2) << "round " << round;

    const std::thread::id caller = std::this_thread::get_id();
    std::atomic<int> finished{0};
    pool.Run(2, [&](int) {
      if (std::this_thread::get_id() != caller) {
        std::this_thread::sleep_for(std::chrono::milliseconds(20));  // the caller now sleeps
      }
      ++finished;
    });
    EXPECT_EQ(finished.load(), 2) << "round " << round;
  }
}

// The worker runs an outer piece that opens a job of two pieces which wait for each other;
// the caller, its own pieces handed out, must take the second: a caller that only waited
// for its own job would leave that job to its one busy owner.
TEST(TaskPool, AWaitingCallerHelpsWithAJobOpenedInsideAPiece) {
  TaskPool pool(2);
  std::atomic<bool> outer_started{false};
  std::atomic<int> inner_started{0};
  std::atomic<int> met{0};
  pool.Run(2, [&](int outer) {
    if (outer == 0) {
      WaitFor([&] { return outer_started.load(); });  // the worker holds piece 1
      return;
    }
    outer_started = true;
    pool.Run(2, [&](int) {
      ++inner_started;
      if (WaitFor([&] { return inner_started.load() == 2; })) ++met;
    });
  });
  EXPECT_EQ(met.load(), 2);
}

// Runs from inside pieces, nested deeper than there are threads, and from several
// threads at once, all complete: a caller works on its own pieces while it waits.
TEST(TaskPool, NestedAndConcurrentRunsComplete) {
  TaskPool pool(2);
  std::atomic<int> leaves{0};
  const auto nested = [&](int depth, auto&& self) -> void {
    if (depth == 0) {
      ++leaves;
      return;
    }
    pool.Run(3, [&](int) { self(depth - 1, self); });
  };
  std::vector<std::thread> callers;
  for (int c = 0; c < 3; ++c) callers.emplace_back([&] { nested(4, nested); });
  for (std::thread& caller : callers) caller.join();
  EXPECT_EQ(leaves.load(), 3 * 81);
}

// BuildCharacter's pieces on a pool give the character they give on one thread, to the
// bit, on real skins.
TEST(TaskPool, BuildsTheSameCharacterAsOneThread) {
  const std::filesystem::path data = MOTIONLOD_SHARED_DATA;
  if (!std::filesystem::exists(data / "MANIFEST.md")) GTEST_SKIP() << "../shared/data is absent";
  TaskPool pool(2);
  for (const char* file : {"characters/stormtrooper.dae", "characters/RobotExpressive.glb"}) {
    auto asset = io::LoadAssetFile(data / file);
    ASSERT_TRUE(asset.ok()) << file;
    const auto one = *core::BuildCharacter((*asset)->character());
    const auto split = *core::BuildCharacter((*asset)->character(), pool.Runner());
    // The skin's arrays, copied by pieces of the validation's job.
    const core::RawSkin& raw = (*asset)->character().skin;
    EXPECT_EQ(split->skin().positions, raw.positions) << file;
    EXPECT_EQ(split->skin().normals, raw.normals) << file;
    EXPECT_EQ(split->skin().triangles, raw.triangles) << file;
    EXPECT_EQ(split->skin().influence_offsets, raw.influence_offsets) << file;
    EXPECT_EQ(split->skin().influence_joints, raw.influence_joints) << file;
    EXPECT_EQ(split->skin().influence_weights, raw.influence_weights) << file;
    EXPECT_EQ(split->height(), one->height()) << file;
    EXPECT_EQ(split->vertex_areas(), one->vertex_areas()) << file;
    EXPECT_EQ(split->subtree_lengths(), one->subtree_lengths()) << file;
    EXPECT_EQ(split->clusters().joint_vertex_centers, one->clusters().joint_vertex_centers) << file;
    EXPECT_EQ(split->clusters().joint_vertex_half_extents, one->clusters().joint_vertex_half_extents) << file;
    EXPECT_EQ(split->clusters().cluster_vertices, one->clusters().cluster_vertices) << file;
    EXPECT_EQ(split->clusters().cluster_vertex_offsets, one->clusters().cluster_vertex_offsets) << file;
    EXPECT_EQ(split->clusters().cluster_centers, one->clusters().cluster_centers) << file;
    EXPECT_EQ(split->clusters().group_cluster_offsets, one->clusters().group_cluster_offsets) << file;
    EXPECT_EQ(split->clusters().group_centers, one->clusters().group_centers) << file;
    EXPECT_EQ(split->clusters().group_half_extents, one->clusters().group_half_extents) << file;
    EXPECT_EQ(split->clusters().cluster_half_extents, one->clusters().cluster_half_extents) << file;
    EXPECT_EQ(split->clusters().group_influence_offsets, one->clusters().group_influence_offsets) << file;
    EXPECT_EQ(split->clusters().cluster_influence_offsets, one->clusters().cluster_influence_offsets) << file;
    const auto same_ranges = [](const std::vector<core::internal::InfluenceRange>& a,
                                const std::vector<core::internal::InfluenceRange>& b) {
      return std::equal(a.begin(), a.end(), b.begin(), b.end(), [](const auto& x, const auto& y) {
        return x.joint == y.joint && x.min_weight == y.min_weight && x.max_weight == y.max_weight;
      });
    };
    EXPECT_TRUE(same_ranges(split->clusters().group_influences, one->clusters().group_influences)) << file;
    EXPECT_TRUE(same_ranges(split->clusters().cluster_influences, one->clusters().cluster_influences)) << file;
    EXPECT_EQ(split->clusters().cluster_lane_offsets, one->clusters().cluster_lane_offsets) << file;
    EXPECT_EQ(split->clusters().cluster_lanes, one->clusters().cluster_lanes) << file;
    ASSERT_EQ(split->joint_pair_moments().size(), one->joint_pair_moments().size()) << file;
    for (size_t q = 0; q < one->joint_pair_moments().size(); ++q) {
      const auto& a = split->joint_pair_moments()[q];
      const auto& b = one->joint_pair_moments()[q];
      EXPECT_EQ(a.k, b.k);
      EXPECT_EQ(a.l, b.l);
      EXPECT_EQ(a.position_moment, b.position_moment) << file << " pair " << q;
      EXPECT_EQ(a.normal_moment, b.normal_moment) << file << " pair " << q;
    }
  }
}

// A skin of more vertices than one validation piece holds is checked in pieces, and the
// message is still that of its first problem, as one thread finds it.
TEST(TaskPool, ValidatesACharacterInPiecesWithTheFirstProblem) {
  const std::filesystem::path data = MOTIONLOD_SHARED_DATA;
  if (!std::filesystem::exists(data / "MANIFEST.md")) GTEST_SKIP() << "../shared/data is absent";
  auto asset = io::LoadAssetFile(data / "characters/RobotExpressive.glb");
  ASSERT_TRUE(asset.ok());
  const core::RawCharacter& valid = (*asset)->character();
  ASSERT_GT(valid.skin.positions.size(), 6000u);
  TaskPool pool(2);
  ASSERT_TRUE(core::ValidateRawCharacter(valid, pool.Runner()).ok());
  const auto expect_message = [&](const core::RawCharacter& c, const std::string& message) {
    const Status one = core::ValidateRawCharacter(c);
    const Status split = core::ValidateRawCharacter(c, pool.Runner());
    EXPECT_EQ(one.message(), message);
    EXPECT_EQ(split.message(), message);
    EXPECT_EQ(core::BuildCharacter(c, pool.Runner()).status().message(), message);
    EXPECT_EQ(core::BuildCharacter(c).status().message(), message);
  };
  core::RawCharacter late = valid;
  late.skin.positions[6000].x() = NAN;
  expect_message(late, "vertex 6000 has a non-finite position");
  core::RawCharacter both = late;
  both.skin.normals[100] *= 2;
  expect_message(both, "vertex 100 has a normal that is not unit length");
  core::RawCharacter triangle = valid;
  triangle.skin.triangles[0][1] = 1 << 30;
  expect_message(triangle, "triangle 0 refers to vertex 1073741824 of " +
                               std::to_string(valid.skin.positions.size()));
}

// What a one-thread bake of `file` (in ../shared/data) works on.
StatusOr<pipeline::BakeInputs> InputsOf(const char* file) {
  auto asset = io::LoadAssetFile(std::filesystem::path(MOTIONLOD_SHARED_DATA) / file);
  if (!asset.ok()) return asset.status();
  pipeline::BakeRequest request;
  request.character = *asset;
  request.threads = 1;
  return pipeline::PrepareInputs(request);
}

// The ranking's pieces on a pool give the ranking of one thread, to the bit.
TEST(TaskPool, RanksTheSameAsOneThread) {
  const std::filesystem::path data = MOTIONLOD_SHARED_DATA;
  if (!std::filesystem::exists(data / "MANIFEST.md")) GTEST_SKIP() << "../shared/data is absent";
  TaskPool pool(2);
  for (const char* file : {"motions/55_01_cmu.fbx", "characters/RobotExpressive.glb"}) {
    const auto inputs = InputsOf(file);
    ASSERT_TRUE(inputs.ok()) << file;
    const core::RankJointsJob job{inputs->character.get(), &inputs->motion, {}};
    const auto one = *job.Run();
    const auto split = *job.Run(pool.Runner());
    EXPECT_EQ(split.rotational, one.rotational) << file;
    EXPECT_EQ(split.priority, one.priority) << file;
    EXPECT_EQ(split.removal_order, one.removal_order) << file;
  }
}

// A prepared motion made in pieces on a pool solves the levels it solves made on one
// thread, to the bit.
TEST(TaskPool, PreparesTheSameMotionAsOneThread) {
  const std::filesystem::path data = MOTIONLOD_SHARED_DATA;
  if (!std::filesystem::exists(data / "MANIFEST.md")) GTEST_SKIP() << "../shared/data is absent";
  TaskPool pool(2);
  for (const char* file : {"characters/stormtrooper.dae", "motions/09_11_cmu.fbx"}) {
    const auto inputs = InputsOf(file);
    ASSERT_TRUE(inputs.ok()) << file;
    const auto ranking = *core::RankJointsJob{inputs->character.get(), &inputs->motion, {}}.Run();
    const auto one = *core::PreparedMotion::Create(inputs->character, inputs->motion, {});
    const auto split = *core::PreparedMotion::Create(inputs->character, inputs->motion, {},
                                                     core::SimdChoice::kWidest, pool.Runner());
    const int n = inputs->character->joint_count();
    for (int kept : {n - 1, n / 2, 3}) {
      const auto level = *core::ReduceSkeletonToCount(*inputs->character, ranking, kept);
      const auto a = *split->SolveLevel(level);
      const auto b = *one->SolveLevel(level);
      EXPECT_GT(b.optimized.mean_e, 0) << file << " at " << kept;
      EXPECT_EQ(a.optimized.e, b.optimized.e) << file << " at " << kept;
      EXPECT_EQ(a.optimized.ep_vertex, b.optimized.ep_vertex) << file << " at " << kept;
      EXPECT_EQ(a.optimized.en_vertex, b.optimized.en_vertex) << file << " at " << kept;
      EXPECT_EQ(a.optimized.max_vertex_error_pct, b.optimized.max_vertex_error_pct) << file;
      EXPECT_EQ(a.baseline.e, b.baseline.e) << file << " at " << kept;
    }
  }
}

}  // namespace
}  // namespace motionlod::pipeline
