// Levels by cost as a client draws them: a bake's default ladder read back from its level
// file and drawn with the client's skinner (PlayFrame, SkinFrameJob over the level's own
// vertices and influences). The full level is the original; every level's reported error
// is the deviation measured here by skinning it and the original on every frame; the
// levels get cheaper as they get coarser; the level chosen for a height is within budget;
// re-solved weights beat truncated ones at every cap.
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstring>
#include <numeric>

#include "client/level_selector.h"
#include "client/skinner.h"
#include "core/greedy_ranking.h"
#include "core/influence_cap.h"
#include "core/simplify_mesh.h"
#include "io/asset.h"
#include "pipeline/bake.h"
#include "proto/level_format.h"
#include "proto/level_selection.h"
#include "tests/client/baked.h"
#include "tests/server/daemon.h"

namespace motionlod::client::testing {
namespace {

using server::testing::SharedDataPath;
using server::testing::SourcePath;

// A bake's default ladder, levels by cost, of one clip.
Baked BakeLadder(const std::string& path, const std::string& animation) {
  return BakeInProcess(path, animation, {}, core::Variant::kVPNOPD);
}

// Level l of `ladder` drawn by the client on every frame of every clip against level 0
// (the original): the largest distance, percent of the height, of an original vertex from
// the point of the level's surface that stands for it.
double MeasuredMaxErrorPct(const Baked& ladder, uint32_t l) {
  const core::Character& character = *ladder.character;
  const SkinMesh mesh = MeshOf(character);
  const proto::LevelView& level = ladder.view.level(l);
  const proto::LevelView& full = ladder.view.level(0);
  auto level_skin = LevelSkin::Build(mesh, level);
  auto full_skin = LevelSkin::Build(mesh, full);
  EXPECT_TRUE(level_skin.ok() && full_skin.ok());
  if (!level_skin.ok() || !full_skin.ok()) return 0;
  std::vector<core::SurfacePoint> points;
  if (level.has_own_mesh()) {
    std::vector<std::array<uint32_t, 3>> triangles(level.triangles().size() / 3);
    std::memcpy(triangles.data(), level.triangles().data(), level.triangles().size_bytes());
    points = core::SurfaceCorrespondence(character, level.vertices(), triangles);
  }
  const size_t p = static_cast<size_t>(character.vertex_count());
  std::vector<float> level_positions(3 * level_skin->vertex_count()), full_positions(3 * p);
  std::vector<float> level_palette(level.kept_count() * proto::kMatrixFloats);
  std::vector<float> full_palette(full.kept_count() * proto::kMatrixFloats);
  double worst = 0;
  for (uint32_t c = 0; c < ladder.view.clip_count(); ++c) {
    for (uint32_t t = 0; t < ladder.view.clip(c).frame_count; ++t) {
      EXPECT_TRUE(PlayFrame(ladder.view, level, c, t, level_palette).ok());
      EXPECT_TRUE(PlayFrame(ladder.view, full, c, t, full_palette).ok());
      EXPECT_TRUE(
          (SkinFrameJob{&*level_skin, level_palette, ladder.view.rigid(), level_positions, {}}
               .Run()
               .ok()));
      EXPECT_TRUE((SkinFrameJob{&*full_skin, full_palette, ladder.view.rigid(), full_positions, {}}
                       .Run()
                       .ok()));
      for (size_t i = 0; i < p; ++i) {
        double drawn[3] = {0, 0, 0};
        for (int a = 0; a < 3; ++a) {
          if (points.empty()) {
            drawn[a] = level_positions[3 * i + a];
          } else {
            for (int corner = 0; corner < 3; ++corner) {
              drawn[a] +=
                  points[i].weights[corner] * level_positions[3 * points[i].vertices[corner] + a];
            }
          }
        }
        const double dx = drawn[0] - full_positions[3 * i],
                     dy = drawn[1] - full_positions[3 * i + 1],
                     dz = drawn[2] - full_positions[3 * i + 2];
        worst = std::max(worst, std::sqrt(dx * dx + dy * dy + dz * dz));
      }
    }
  }
  return 100 * worst / character.height();
}

void ExpectAnHonestLadder(const Baked& ladder, const std::string& what) {
  ASSERT_GE(ladder.view.level_count(), 2u) << what << ": the ladder saves nothing";
  // The full level is the original: every joint, vertex and influence, every frame.
  const proto::LevelView& full = ladder.view.level(0);
  EXPECT_EQ(full.kept_count(), ladder.view.joint_count()) << what;
  EXPECT_FALSE(full.has_own_mesh()) << what;
  EXPECT_EQ(full.influences_per_vertex(), 0u) << what;
  EXPECT_EQ(full.frame_stride(), 1u) << what;
  EXPECT_EQ(full.figures().max_vertex_error_pct, 0.0f) << what;
  EXPECT_FLOAT_EQ(full.cost(), 1.0f) << what;
  float last_cost = 2;
  for (uint32_t l = 0; l < ladder.view.level_count(); ++l) {
    const proto::LevelView& level = ladder.view.level(l);
    const std::string where = what + " level " + std::to_string(l);
    EXPECT_LT(level.cost(), last_cost) << where << ": levels get cheaper as they get coarser";
    last_cost = level.cost();
    // The reported error is what drawing the level measures (float skinning on both sides).
    const double measured = MeasuredMaxErrorPct(ladder, l);
    const double reported = level.figures().max_vertex_error_pct;
    EXPECT_LE(measured, reported * 1.001 + 1e-4) << where << ": the reported error is not a bound";
    EXPECT_GE(measured, reported * 0.99 - 1e-4) << where;
  }
  // The level chosen for a height keeps the error within the 1 px budget there.
  std::vector<double> errors;
  for (const proto::LevelView& level : ladder.view.levels())
    errors.push_back(level.figures().max_vertex_error_pct);
  auto selector = LevelSelector::Create(errors);
  ASSERT_TRUE(selector.ok());
  for (double px : {800.0, 400.0, 200.0, 100.0, 50.0, 25.0, 12.0}) {
    const int chosen = selector->Choose(px, -1);
    EXPECT_LE(errors[chosen] / 100 * px, 1.0 + 1e-6) << what << " at " << px << " px";
  }
}

TEST(CostLevels, TheSamplesLadderIsHonestAndCheaper) {
  const Baked ladder = BakeLadder(SourcePath("samples/Rig_Medium_MovementBasic.glb"), "Walking_A");
  ExpectAnHonestLadder(ladder, "sample");
  // Far levels cut the mesh, the influences or the pose rate, not only joints.
  const proto::LevelView& coarsest = ladder.view.level(ladder.view.level_count() - 1);
  EXPECT_TRUE(coarsest.has_own_mesh() || coarsest.influences_per_vertex() > 0 ||
              coarsest.frame_stride() > 1);
  EXPECT_LT(coarsest.cost(), 0.5f);
}

TEST(CostLevels, RealCharactersLaddersAreHonestAndCheaper) {
  const std::string cesium = SharedDataPath("characters/CesiumMan.glb");
  const std::string robot = SharedDataPath("characters/RobotExpressive.glb");
  if (cesium.empty() || robot.empty()) GTEST_SKIP() << "../shared/data is absent";
  ExpectAnHonestLadder(BakeLadder(cesium, ""), "CesiumMan");
  ExpectAnHonestLadder(BakeLadder(robot, "Walking"), "RobotExpressive Walking");
}

// Re-solved weights against truncated ones on a real character's level: the weight step's
// objective (summed over frames) per vertex is never above truncation's, and the sum well
// below, at every cap.
TEST(CostLevels, ReSolvedWeightsBeatTruncationOnRealData) {
  const std::string path = SharedDataPath("characters/CesiumMan.glb");
  if (path.empty()) GTEST_SKIP() << "../shared/data is absent";
  auto asset = io::LoadAssetFile(path);
  ASSERT_TRUE(asset.ok());
  pipeline::BakeRequest request;
  request.character = *asset;
  auto inputs = pipeline::PrepareInputs(request);
  ASSERT_TRUE(inputs.ok());
  auto prepared = core::PreparedMotion::Create(inputs->character, inputs->motion, request.settings);
  ASSERT_TRUE(prepared.ok());
  auto ranking = core::GreedyRankingJob{prepared->get()}.Run();
  ASSERT_TRUE(ranking.ok());
  const core::Character& character = *inputs->character;
  for (int kept : {character.joint_count(), 12}) {
    const auto level = *core::ReduceSkeletonToCount(character, *ranking, kept);
    const auto solved = *(*prepared)->SolveLevel(level);
    for (int cap : {1, 2, 4}) {
      const auto truncated = *core::TruncateInfluences(character, level, cap);
      const auto resolved =
          *core::InfluenceCapJob{prepared->get(), &level, solved.matrices, cap, 0}.Run();
      const auto before =
          *core::InfluenceObjective(**prepared, level, solved.matrices, truncated, 0);
      const auto after = *core::InfluenceObjective(**prepared, level, solved.matrices, resolved, 0);
      for (size_t i = 0; i < before.size(); ++i) {
        ASSERT_LE(after[i], before[i] * (1 + 1e-4) + 1e-12)
            << kept << " joints, cap " << cap << ", vertex " << i;
      }
      const double sum_before = std::accumulate(before.begin(), before.end(), 0.0);
      const double sum_after = std::accumulate(after.begin(), after.end(), 0.0);
      // At every joint both are rounding, at most 2e-10 of the height squared.
      EXPECT_LE(sum_after, std::max(sum_before, 2e-10 * character.height() * character.height()))
          << kept << " joints, cap " << cap;
      // Measured on CesiumMan: 0.94 and 0.91 of truncation's at one influence (a better
      // joint), 0.31 and 0.77 at two, 0.69 at four (at every joint four are exact).
      const double ratio = cap == 1 ? 0.97 : cap == 2 ? 0.85 : 0.8;
      if (sum_before > 1e-6 * character.height() * character.height()) {
        EXPECT_LT(sum_after, ratio * sum_before) << kept << " joints, cap " << cap;
      }
    }
  }
}

}  // namespace
}  // namespace motionlod::client::testing
