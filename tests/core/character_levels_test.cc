// Character-wide levels: clips baked as one motion, levels lifted from coarser ones, and
// the greedy removal order against its exhaustive reference.
#include <gtest/gtest.h>

#include <algorithm>

#include "core/greedy_ranking.h"
#include "core/rank_joints.h"
#include "core/reference/greedy_ranking_reference.h"
#include "core/solve_levels.h"
#include "tests/core/fixtures.h"

namespace motionlod::core {
namespace {

using testing::BuildOrDie;
using testing::MakeCreature;
using testing::MakeWaveMotion;
using testing::TestSimd;

std::shared_ptr<const PreparedMotion> Prepare(std::shared_ptr<const Character> character,
                                              const Motion& motion, Variant variant) {
  SolveSettings settings;
  settings.variant = variant;
  auto prepared = PreparedMotion::Create(std::move(character), motion, settings, TestSimd());
  EXPECT_TRUE(prepared.ok()) << prepared.status().ToString();
  return *prepared;
}

// Two clips of another amplitude and length, the second with still joints.
std::vector<Motion> TwoClips(const Character& c) {
  Motion walk = MakeWaveMotion(c, 11, 0.6);
  walk.name = "walk";
  Motion idle = MakeWaveMotion(c, 7, 0.25, {2, 5});
  idle.name = "idle";
  idle.fps = 24;
  return {walk, idle};
}

TEST(Clips, ConcatenatedClipsKeepTheirFramesAndNames) {
  const auto character = BuildOrDie(MakeCreature());
  const std::vector<Motion> clips = TwoClips(*character);
  const Motion motion = *ConcatenateClips(clips);
  ASSERT_EQ(motion.frame_count, 18);
  ASSERT_EQ(motion.clips.size(), 2u);
  EXPECT_EQ(motion.clips[1].name, "idle");
  EXPECT_EQ(motion.clips[1].first_frame, 11);
  EXPECT_EQ(motion.clips[1].fps, 24);
  EXPECT_EQ(motion.world(11, 3), clips[1].world(0, 3));
  EXPECT_TRUE(ValidateMotion(motion, *character).ok());
  Motion gap = motion;
  gap.clips[1].first_frame = 12;
  EXPECT_FALSE(ValidateMotion(gap, *character).ok());
  Motion short_cover = motion;
  short_cover.clips[1].frame_count = 6;
  EXPECT_FALSE(ValidateMotion(short_cover, *character).ok());
  EXPECT_FALSE(ConcatenateClips({}).ok());
}

TEST(Clips, EachClipsFiguresAreThoseOfTheClipSolvedAlone) {
  // vp fits positions only: alpha scales the whole system, so every frame's solution does
  // not depend on the other clip, and each clip's figures are the clip's own.
  const auto character = BuildOrDie(MakeCreature());
  const std::vector<Motion> clips = TwoClips(*character);
  const auto both = Prepare(character, *ConcatenateClips(clips), Variant::kVP);
  ASSERT_EQ(both->clips().size(), 2u);
  const JointRanking ranking = *RankJointsJob{character.get(), &clips[0], {}, TestSimd()}.Run();
  for (int kept : {2, 4, 7}) {
    const ReducedSkeleton level = *ReduceSkeletonToCount(*character, ranking, kept);
    LevelResult joint = *both->SolveOptimized(level);
    joint.baseline = *both->BaselineErrors(level);
    ASSERT_EQ(joint.optimized.per_clip.size(), 2u);
    double worst = 0;
    for (int c = 0; c < 2; ++c) {
      const auto alone = Prepare(character, clips[c], Variant::kVP);
      const LevelResult own = *alone->SolveOptimized(level);
      const LevelErrors& part = joint.optimized.per_clip[c];
      EXPECT_NEAR(part.max_vertex_error_pct, own.optimized.max_vertex_error_pct,
                  1e-9 * own.optimized.max_vertex_error_pct) << kept << " clip " << c;
      EXPECT_NEAR(part.rms_vertex_error_pct, own.optimized.rms_vertex_error_pct,
                  1e-9 * own.optimized.rms_vertex_error_pct);
      EXPECT_NEAR(joint.baseline.per_clip[c].max_vertex_error_pct,
                  alone->BaselineErrors(level)->max_vertex_error_pct, 1e-12);
      worst = std::max(worst, part.max_vertex_error_pct);
    }
    EXPECT_EQ(joint.optimized.max_vertex_error_pct, worst);
    EXPECT_EQ(joint.optimized.e.size(), 18u);
    EXPECT_EQ(joint.matrices.size(), 18u * kept);
  }
}

TEST(Clips, LiftedLevelsAreNeverWorseThanTheCoarserOne) {
  const auto character = BuildOrDie(MakeCreature());
  const Motion motion = *ConcatenateClips(TwoClips(*character));
  const int n = character->joint_count();
  for (Variant variant : {Variant::kVP, Variant::kVPNOPD}) {
    const auto prepared = Prepare(character, motion, variant);
    const JointRanking ranking = *GreedyRankingJob{prepared.get(), {}, 0}.Run();
    std::vector<LevelResult> levels;  // coarsest first
    for (int kept = 1; kept <= n; ++kept) {
      levels.push_back(*prepared->SolveLevel(*ReduceSkeletonToCount(*character, ranking, kept)));
      if (kept > 1) {
        ASSERT_TRUE(prepared->LiftCoarserLevel(levels[kept - 2], levels[kept - 1]).ok());
      }
      const LevelResult& level = levels.back();
      for (size_t c = 0; c < 2; ++c) {
        EXPECT_LE(level.optimized.per_clip[c].max_vertex_error_pct,
                  level.baseline.per_clip[c].max_vertex_error_pct);
        EXPECT_LE(level.optimized.per_clip[c].mean_vertex_error_pct,
                  level.baseline.per_clip[c].mean_vertex_error_pct);
        if (kept > 1 && level.sources[c] == LevelSource::kCoarserLevel) {
          // The coarser level's mesh, measured again from its float matrices.
          EXPECT_NEAR(level.optimized.per_clip[c].max_vertex_error_pct,
                      levels[kept - 2].optimized.per_clip[c].max_vertex_error_pct, 1e-4);
        }
      }
    }
  }
  // A finer level must keep every joint of the coarser one.
  const auto prepared = Prepare(character, motion, Variant::kVP);
  const JointRanking ranking = *RankJointsJob{character.get(), &motion, {}, TestSimd()}.Run();
  LevelResult four = *prepared->SolveLevel(*ReduceSkeletonToCount(*character, ranking, 4));
  LevelResult three = *prepared->SolveLevel(*ReduceSkeletonToCount(*character, ranking, 3));
  EXPECT_TRUE(prepared->LiftCoarserLevel(three, four).ok());
  EXPECT_EQ(prepared->LiftCoarserLevel(four, three).code(), StatusCode::kInvalidArgument);
}

TEST(GreedyRanking, EqualsTheExhaustiveSearchInEveryVariant) {
  const auto character = BuildOrDie(MakeCreature());
  const Motion motion = *ConcatenateClips(TwoClips(*character));
  const std::vector<std::string> locked = {"arm_l"};
  for (Variant variant : {Variant::kVP, Variant::kVPNO, Variant::kVPPD, Variant::kVPNOPD}) {
    const auto prepared = Prepare(character, motion, variant);
    for (int probe : {0, 4}) {
      const GreedyRankingJob job{prepared.get(), locked, probe, false};
      const JointRanking fast = *job.Run();
      const JointRanking reference = *GreedyRankingReference(job);
      EXPECT_EQ(fast.removal_order, reference.removal_order) << VariantName(variant) << " probe " << probe;
      EXPECT_EQ(fast.priority, reference.priority) << VariantName(variant);
      EXPECT_EQ(fast.locked_count, 2);
      EXPECT_EQ(fast.removal_order.back(), 0);
      EXPECT_EQ(fast.priority[character->FindJoint("arm_l")], std::numeric_limits<double>::infinity());
    }
  }
  // Plain reparenting's own order, scored without a solve.
  const auto prepared_vp = Prepare(character, motion, Variant::kVP);
  const GreedyRankingJob reparented{prepared_vp.get(), {}, 0, true};
  const JointRanking fast = *reparented.Run();
  EXPECT_EQ(fast.removal_order, GreedyRankingReference(reparented)->removal_order);
  EXPECT_EQ(fast.priority, GreedyRankingReference(reparented)->priority);
  EXPECT_EQ(GreedyRankingJob{}.Validate().code(), StatusCode::kInvalidArgument);
  const auto prepared = Prepare(character, motion, Variant::kVP);
  const std::vector<std::string> unknown = {"no_such_joint"};
  EXPECT_EQ((GreedyRankingJob{prepared.get(), unknown, 0}.Validate().code()), StatusCode::kNotFound);
  EXPECT_FALSE((GreedyRankingJob{prepared.get(), {}, -1}.Validate().ok()));
}

TEST(GreedyRanking, ProbeFramesSpanEachClip) {
  const std::vector<MotionClip> clips = {{"a", 30, 0, 10}, {"b", 30, 10, 3}};
  EXPECT_EQ(ProbeFrames(clips, 4), (std::vector<int>{0, 3, 6, 9, 10, 11, 12}));
  EXPECT_EQ(ProbeFrames(clips, 0).size(), 13u);
}

}  // namespace
}  // namespace motionlod::core
