// One level choice everywhere, on a rig where a coarser level is as exact as the full one:
// RobotExpressive's skeleton has joints that move no vertex (pole targets and end sites),
// so a level of its default ladder that drops only those has a max vertex error of 0. On
// its bake the level table's pixel ranges partition (0, inf) with no empty range chosen,
// and for a sweep of heights the daemon's `level?px=`, the client's LevelSelector and
// proto::SelectLevel pick the same level, the one whose range holds the height.
#include <cmath>
#include <limits>
#include <vector>

#include "client/level_selector.h"
#include "proto/level_selection.h"
#include "tests/client/fixture.h"

namespace motionlod::client::testing {
namespace {

namespace api = proto::api;

using LevelChoiceOnRealData = DaemonTest;

// The chosen levels' ranges, coarsest first, tile (0, inf); the others have none.
void ExpectRangesPartition(const std::vector<api::LevelEntry>& levels) {
  double covered = 0;
  bool unbounded = false;
  for (auto level = levels.rbegin(); level != levels.rend(); ++level) {
    if (!level->chosen) {
      EXPECT_FALSE(level->px_min.has_value()) << "level " << level->index;
      EXPECT_FALSE(level->px_max.has_value()) << "level " << level->index;
      continue;
    }
    EXPECT_FALSE(unbounded) << "level " << level->index << " overlaps a coarser unbounded range";
    ASSERT_TRUE(level->px_min.has_value()) << "level " << level->index;
    EXPECT_EQ(*level->px_min, covered) << "level " << level->index << ": a gap or an overlap";
    if (level->px_max) {
      EXPECT_LT(*level->px_min, *level->px_max) << "level " << level->index << ": an empty range";
      covered = *level->px_max;
    } else {
      unbounded = true;
    }
  }
  EXPECT_TRUE(unbounded) << "no level serves the tallest characters";
}

// Sweeps heights across the table of `bake`: every bound, the next double either side, and
// between. The daemon, the client and proto pick one level, whose range holds the height.
void ExpectOneChoice(Client& client, const api::BakeInfo& bake) {
  std::vector<double> fractions;
  for (const api::LevelEntry& level : bake.levels) fractions.push_back(level.max_vertex_error_pct / 100);
  auto selector = LevelSelector::FromBake(bake);
  ASSERT_TRUE(selector.ok()) << selector.error().ToString();
  std::vector<double> heights = {0.25, 2, 20, 120, 700, 5000, 1e6};
  for (const api::LevelEntry& level : bake.levels) {
    if (!level.px_max) continue;
    const double bound = *level.px_max;
    heights.insert(heights.end(), {bound, std::nextafter(bound, 0.0),
                                   std::nextafter(bound, std::numeric_limits<double>::infinity()),
                                   bound * 0.8});
  }
  for (double px : heights) {
    const int proto_choice = proto::SelectLevel(fractions, px, 1.0);
    auto daemon_choice = client.ChooseLevel(bake.id, px);
    ASSERT_TRUE(daemon_choice.ok()) << daemon_choice.error().ToString();
    EXPECT_EQ(daemon_choice->index, proto_choice) << px << " px";
    EXPECT_EQ(selector->Choose(px, -1), proto_choice) << px << " px";
    const api::LevelEntry& level = bake.levels[static_cast<size_t>(proto_choice)];
    EXPECT_TRUE(level.chosen) << px << " px";
    EXPECT_GT(px, level.px_min.value_or(std::numeric_limits<double>::infinity())) << px << " px";
    if (level.px_max) {
      EXPECT_LE(px, *level.px_max) << px << " px";
    }
  }
}

TEST_F(LevelChoiceOnRealData, AnExactCoarserLevelGetsOneChoiceEverywhere) {
  const std::string path = server::testing::SharedDataPath("characters/RobotExpressive.glb");
  if (path.empty()) GTEST_SKIP() << "../shared/data/characters/RobotExpressive.glb is missing";
  StartDaemon();
  Client client = MakeClient(Options());
  auto file = ReadUploadFile(path);
  ASSERT_TRUE(file.ok()) << file.error().ToString();
  auto character = client.UploadCharacter({*file});
  ASSERT_TRUE(character.ok()) << character.error().ToString();
  // The default ladder (all joints, 3/4, 1/2, ...), then every level, from all joints down:
  // 43 levels, the 13 finest of them exact and many with equal errors.
  for (const bool all_levels : {false, true}) {
    SCOPED_TRACE(all_levels ? "all levels" : "the default ladder");
    api::BakeRequest request;
    request.character = character->value.id;
    request.motion = "Walking";
    request.all_levels = all_levels;
    auto job = client.SubmitBake(request);
    ASSERT_TRUE(job.ok()) << job.error().ToString();
    auto bake = client.WaitForBake(job->id, {}, 600);
    ASSERT_TRUE(bake.ok()) << bake.error().ToString();
    const std::vector<api::LevelEntry>& levels = bake->levels;
    ASSERT_GE(levels.size(), 3u);
    EXPECT_EQ(levels[0].joints, character->value.joints);
    // What makes this rig the case at hand: a coarser level as exact as the full skeleton,
    // which then serves every large height while the full one is never chosen.
    ASSERT_EQ(levels[0].max_vertex_error_pct, 0.0);
    ASSERT_EQ(levels[1].max_vertex_error_pct, 0.0) << "level 1 keeps " << levels[1].joints;
    EXPECT_FALSE(levels[0].chosen);
    ExpectRangesPartition(levels);
    ExpectOneChoice(client, *bake);
    // The case: a small character gets a coarse level, never the full skeleton.
    auto small = client.ChooseLevel(bake->id, 20);
    ASSERT_TRUE(small.ok());
    EXPECT_LT(small->joints, levels[0].joints);
  }
}

}  // namespace
}  // namespace motionlod::client::testing
