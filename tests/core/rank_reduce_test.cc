#include <cmath>
#include <limits>

#include <gtest/gtest.h>

#include "core/rank_joints.h"
#include "core/reduce_skeleton.h"
#include "tests/core/fixtures.h"

namespace motionlod::core {
namespace {

using testing::BuildOrDie;
using testing::MakeCreature;
using testing::MakeWaveMotion;

constexpr int kNeck = 2, kHead = 3, kArmL = 4, kHandL = 5;

TEST(RankJoints, StillJointsRankZeroAndTheRootIsNeverRemoved) {
  const auto c = BuildOrDie(MakeCreature());
  const Motion m = MakeWaveMotion(*c, 40, 0.6, {kNeck});
  auto ranking = RankJointsJob{c.get(), &m, {}}.Run();
  ASSERT_TRUE(ranking.ok()) << ranking.status().ToString();
  EXPECT_NEAR(ranking->rotational[kNeck], 0.0, 1e-12);
  EXPECT_NEAR(ranking->priority[kNeck], 0.0, 1e-12);
  EXPECT_EQ(ranking->removal_order.front(), kNeck);
  EXPECT_EQ(ranking->removal_order.back(), 0);
  EXPECT_TRUE(std::isinf(ranking->priority[0]));
  EXPECT_EQ(ranking->locked_count, 1);
  // Priority is the product of the two factors.
  for (int j = 1; j < c->joint_count(); ++j) {
    EXPECT_DOUBLE_EQ(ranking->priority[j], ranking->hierarchical[j] * ranking->rotational[j]);
  }
  // Lowest priority first.
  for (size_t r = 1; r + 1 < ranking->removal_order.size(); ++r) {
    EXPECT_LE(ranking->priority[ranking->removal_order[r - 1]],
              ranking->priority[ranking->removal_order[r]]);
  }
}

TEST(RankJoints, AConstantOffsetFromTheBindPoseIsNotFreeToRemove) {
  // The neck holds a fixed bend for the whole clip: its variation about the clip's mean is
  // zero, but removing it would straighten the head. The offset is measured to rounding at
  // any angle: a tenth of a microradian (where the acos of a quaternion dot product keeps
  // half its digits: 1.2e-9 off), 40 degrees (the chord's series) and 115 degrees (past it).
  const auto c = BuildOrDie(MakeCreature());
  for (double angle : {1e-7, 0.7, 2.0}) {
    SCOPED_TRACE(angle);
    Motion m = MakeWaveMotion(*c, 40, 0.6, {kNeck, kHead});
    const Affine34d bend = testing::RotationAbout(Vec3d::UnitZ(), angle, Vec3d(0, 2, 0));
    for (int t = 0; t < m.frame_count; ++t) {
      for (int j : {kNeck, kHead}) {
        Affine34d& w = m.joint_world[static_cast<size_t>(t) * m.joint_count + j];
        // Bend the subtree about the neck in the neck's own frame.
        w = ComposeAffine(m.world(t, 1),
                          ComposeAffine(InverseAffine(c->skeleton().bind_world[1]),
                                        ComposeAffine(bend, c->skeleton().bind_world[j])));
      }
    }
    auto ranking = RankJointsJob{c.get(), &m, {}}.Run();
    ASSERT_TRUE(ranking.ok());
    EXPECT_NEAR(ranking->rotational[kNeck], angle, 1e-14 + 1e-12 * angle);
    EXPECT_GT(ranking->priority[kNeck], 0.0);
  }
}

TEST(RankJoints, LockedJointsAreKeptAndUnknownNamesFail) {
  const auto c = BuildOrDie(MakeCreature());
  const Motion m = MakeWaveMotion(*c, 10);
  const std::string locked[] = {"hand_l"};
  auto ranking = RankJointsJob{c.get(), &m, locked}.Run();
  ASSERT_TRUE(ranking.ok());
  EXPECT_EQ(ranking->locked_count, 2);
  EXPECT_TRUE(std::isinf(ranking->priority[kHandL]));
  auto level = ReduceSkeletonToCount(*c, *ranking, 2);
  ASSERT_TRUE(level.ok());
  EXPECT_EQ(level->kept_joints, (std::vector<int>{0, kHandL}));
  EXPECT_FALSE(ReduceSkeletonToCount(*c, *ranking, 1).ok());
  const std::string unknown[] = {"tail"};
  const auto failed = RankJointsJob{c.get(), &m, unknown}.Run();
  ASSERT_FALSE(failed.ok());
  EXPECT_NE(failed.status().message().find("'tail'"), std::string::npos);
}

TEST(ReduceSkeleton, MergesWeightsIntoNearestKeptAncestor) {
  const auto c = BuildOrDie(MakeCreature());
  // Keep root, spine, hand_l: neck and head fall to spine, arm_l to spine, hand_l stays
  // (its parent arm_l is gone, so its parent slot is spine), arm_r/hand_r to spine.
  const bool keep[] = {true, true, false, false, false, true, false, false};
  auto reduced = ReduceSkeleton(*c, keep);
  ASSERT_TRUE(reduced.ok());
  EXPECT_EQ(reduced->kept_joints, (std::vector<int>{0, 1, kHandL}));
  EXPECT_EQ(reduced->joint_to_slot, (std::vector<int>{0, 1, 1, 1, 1, 2, 1, 1}));
  EXPECT_EQ(reduced->parent_slots, (std::vector<int>{-1, 0, 1}));
  const ReducedInfluences w = ReduceInfluences(c->skin(), *reduced);
  ASSERT_EQ(w.offsets.size(), c->skin().positions.size() + 1);
  for (size_t i = 0; i + 1 < w.offsets.size(); ++i) {
    float sum = 0;
    for (uint32_t e = w.offsets[i]; e < w.offsets[i + 1]; ++e) {
      sum += w.weights[e];
      for (uint32_t f = w.offsets[i]; f < e; ++f) EXPECT_NE(w.slots[e], w.slots[f]);
    }
    EXPECT_NEAR(sum, 1.0f, 1e-6f);
  }
  // A vertex of the neck->head tube (weights neck/head) now sits on spine alone.
  const int neck_tube_vertex = 2 * 5 * 8 + 8 * 2;  // third bone, middle ring
  EXPECT_EQ(w.offsets[neck_tube_vertex + 1] - w.offsets[neck_tube_vertex], 1u);
  EXPECT_EQ(w.slots[w.offsets[neck_tube_vertex]], 1);
  // An arm_l->hand_l vertex blends spine (from arm_l) and hand_l.
  const int hand_tube_vertex = 4 * 5 * 8 + 8 * 2;
  EXPECT_EQ(w.offsets[hand_tube_vertex + 1] - w.offsets[hand_tube_vertex], 2u);
}

TEST(ReduceSkeleton, RejectsRemovingTheRootOrWrongSizes) {
  const auto c = BuildOrDie(MakeCreature());
  const bool no_root[] = {false, true, true, true, true, true, true, true};
  EXPECT_FALSE(ReduceSkeleton(*c, no_root).ok());
  const bool short_flags[] = {true, true};
  EXPECT_FALSE(ReduceSkeleton(*c, short_flags).ok());
}

}  // namespace
}  // namespace motionlod::core
