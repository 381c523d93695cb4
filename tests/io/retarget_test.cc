#include "io/retarget.h"

#include <gtest/gtest.h>

#include <Eigen/SVD>
#include <algorithm>
#include <numbers>

#include "core/character.h"
#include "core/motion.h"
#include "test_util.h"

namespace motionlod::io {
namespace {

using Eigen::Matrix3d;
using Eigen::Vector3d;

TEST(NormalizeJointName, StripsCommonPrefixesNamespacesAndSeparators) {
  EXPECT_EQ(NormalizeJointName("mixamorig:LeftUpLeg"), "leftupleg");
  EXPECT_EQ(NormalizeJointName("mixamorig_LeftUpLeg"), "leftupleg");
  EXPECT_EQ(NormalizeJointName("Armature|Left_Up_Leg"), "leftupleg");
  EXPECT_EQ(NormalizeJointName("Bip01 L Thigh"), "lthigh");
  EXPECT_EQ(NormalizeJointName("DEF-spine.001"), "spine001");
  EXPECT_EQ(NormalizeJointName("Hips"), "hips");
}

core::Affine34d At(const Vector3d& p, const Matrix3d& r = Matrix3d::Identity()) {
  core::Affine34d m;
  m.leftCols<3>() = r;
  m.col(3) = p;
  return m;
}

// A chain along +y: names[j] at height j * bone.
core::RawSkeleton Chain(const std::vector<std::string>& names, double bone,
                        const std::vector<Matrix3d>& frames = {}) {
  core::RawSkeleton s;
  for (size_t j = 0; j < names.size(); ++j) {
    s.joint_names.push_back(names[j]);
    s.parents.push_back(static_cast<int>(j) - 1);
    s.bind_world.push_back(
        At(Vector3d(0, bone * j, 0), frames.empty() ? Matrix3d::Identity() : frames[j]));
  }
  return s;
}

// One frame: joint 1 turned 90 degrees about z, the root moved by (1, 0, 0).
core::Motion BendMotion(const core::RawSkeleton& s) {
  core::Motion m;
  m.fps = 30;
  m.frame_count = 1;
  m.joint_count = static_cast<int>(s.parents.size());
  const Matrix3d turn =
      Eigen::AngleAxisd(std::numbers::pi / 2, Vector3d::UnitZ()).toRotationMatrix();
  const double bone = s.bind_world[1].col(3).y();
  m.joint_world = {At(Vector3d(1, 0, 0)), At(Vector3d(1, bone, 0), turn),
                   At(Vector3d(1 - bone, bone, 0), turn)};
  return m;
}

TEST(RetargetMotion, IdenticalSkeletonsCopyTheMotion) {
  const core::RawSkeleton s = Chain({"a", "b", "c"}, 1.0);
  const core::Motion m = BendMotion(s);
  const StatusOr<RetargetedMotion> r = RetargetMotion(s, m, s);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  for (int j = 0; j < 3; ++j)
    EXPECT_TRUE(r->motion.world(0, j).isApprox(m.world(0, j), 1e-12)) << j;
  EXPECT_TRUE(r->unmatched_target_joints.empty());
  EXPECT_TRUE(r->unmatched_source_joints.empty());
}

TEST(RetargetMotion, KeepsTargetBoneLengthsAndScalesRootMotionByHeight) {
  const core::RawSkeleton source = Chain({"a", "b", "c"}, 1.0);
  const core::RawSkeleton target = Chain({"A", "B", "C"}, 2.0);  // matched case-insensitively
  const StatusOr<RetargetedMotion> r = RetargetMotion(source, BendMotion(source), target);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_TRUE(r->motion.world(0, 0).col(3).isApprox(Vector3d(2, 0, 0), 1e-12));  // (1,0,0) * 4/2
  EXPECT_TRUE(r->motion.world(0, 1).col(3).isApprox(Vector3d(2, 2, 0), 1e-12));
  EXPECT_TRUE(r->motion.world(0, 2).col(3).isApprox(Vector3d(0, 2, 0), 1e-12));  // bent, length 2
}

TEST(RetargetMotion, WorksAcrossLocalAxisConventions) {
  // The target's joints carry arbitrary bind rotations (another exporter's axis
  // convention): world rotation changes still transfer, positions match the source.
  const core::RawSkeleton source = Chain({"a", "b", "c"}, 1.0);
  const std::vector<Matrix3d> frames = {
      Eigen::AngleAxisd(0.3, Vector3d(1, 2, 3).normalized()).toRotationMatrix(),
      Eigen::AngleAxisd(-1.1, Vector3d(0, 1, 0)).toRotationMatrix(),
      Eigen::AngleAxisd(2.0, Vector3d(1, 0, 1).normalized()).toRotationMatrix()};
  const core::RawSkeleton target = Chain({"a", "b", "c"}, 1.0, frames);
  const core::Motion m = BendMotion(source);
  const StatusOr<RetargetedMotion> r = RetargetMotion(source, m, target);
  ASSERT_TRUE(r.ok());
  const Matrix3d turn =
      Eigen::AngleAxisd(std::numbers::pi / 2, Vector3d::UnitZ()).toRotationMatrix();
  for (int j = 0; j < 3; ++j) {
    EXPECT_TRUE(r->motion.world(0, j).col(3).isApprox(m.world(0, j).col(3), 1e-12)) << j;
    const Matrix3d expected_change = j == 0 ? Matrix3d::Identity() : turn;
    EXPECT_TRUE(r->motion.world(0, j).leftCols<3>().isApprox(expected_change * frames[j], 1e-12))
        << j;
  }
}

TEST(RetargetMotion, UnmatchedTargetJointsKeepTheirBindPoseRelativeToTheParent) {
  const core::RawSkeleton source = Chain({"a", "b", "c"}, 1.0);
  core::RawSkeleton target = Chain({"a", "b", "c"}, 1.0);
  target.joint_names.push_back("tail");
  target.parents.push_back(1);
  target.bind_world.push_back(At(Vector3d(0.5, 1, 0)));
  const StatusOr<RetargetedMotion> r = RetargetMotion(source, BendMotion(source), target);
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->unmatched_target_joints, (std::vector<std::string>{"tail"}));
  const core::Affine34d expected = core::ComposeAffine(
      core::ComposeAffine(r->motion.world(0, 1), core::InverseAffine(target.bind_world[1])),
      target.bind_world[3]);
  EXPECT_TRUE(r->motion.world(0, 3).isApprox(expected, 1e-12));
}

TEST(RetargetMotion, FailsNamingTheUnmatchedJointsWhenFewerThanHalfMatch) {
  const core::RawSkeleton source = Chain({"a", "b", "c"}, 1.0);
  const core::RawSkeleton target = Chain({"a", "x", "y", "z"}, 1.0);
  const StatusOr<RetargetedMotion> r = RetargetMotion(source, BendMotion(source), target);
  ASSERT_EQ(r.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(r.status().message().find("'x', 'y', 'z'"), std::string::npos);
}

TEST(RetargetAnimation, KayKitClipOnKnightEqualsCopyingLocalTransforms) {
  // Knight.glb and Rig_Medium_*.glb share one rig (same names and bind poses) but list
  // the joints in different orders.
  MOTIONLOD_REQUIRE_DATA();
  const auto rig = testing::DataAsset("characters/Rig_Medium_MovementBasic.glb");
  const auto knight = testing::DataAsset("characters/Knight.glb");
  const core::RawCharacter& target = knight->character();
  const StatusOr<RetargetedMotion> r = RetargetAnimation(*rig, "Walking_A", 0, target);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_TRUE(r->unmatched_target_joints.empty());
  EXPECT_TRUE(r->unmatched_source_joints.empty());
  const core::Motion source = *rig->SampleAnimation("Walking_A", 0);
  ASSERT_EQ(r->motion.frame_count, source.frame_count);
  const core::RawSkeleton& s = rig->character().skeleton;
  const core::RawSkeleton& t = target.skeleton;
  double worst = 0;
  for (int f = 0; f < source.frame_count; ++f) {
    for (size_t j = 0; j < t.parents.size(); ++j) {
      const int sj = testing::JointIndex(s, t.joint_names[j]);
      ASSERT_GE(sj, 0);
      // Local transforms: parent^-1 * world on both sides.
      auto local = [](const core::Motion& m, const core::RawSkeleton& sk, int frame, int joint) {
        const int p = sk.parents[joint];
        return p < 0 ? m.world(frame, joint)
                     : core::ComposeAffine(core::InverseAffine(m.world(frame, p)),
                                           m.world(frame, joint));
      };
      worst =
          std::max(worst, (local(r->motion, t, f, static_cast<int>(j)) - local(source, s, f, sj))
                              .cwiseAbs()
                              .maxCoeff());
      worst = std::max(
          worst,
          (r->motion.world(f, static_cast<int>(j)) - source.world(f, sj)).cwiseAbs().maxCoeff());
    }
  }
  EXPECT_LT(worst, 1e-5);
  const auto built = core::BuildCharacter(target);
  ASSERT_TRUE(built.ok());
  EXPECT_TRUE(core::ValidateMotion(r->motion, **built).ok());
}

TEST(RetargetAnimation, FailsListingUnmatchedJointsWhenNamingConventionsDiffer) {
  // The CMU FBX and the CMU BVH clips name their joints differently (LeftUpLeg vs
  // LeftHip): fewer than half match, and the error lists what did not.
  MOTIONLOD_REQUIRE_DATA();
  const auto bvh = testing::DataAsset("motions/cmu_131_01.bvh");
  const auto fbx = testing::DataAsset("motions/07_01_cmu.fbx");
  const StatusOr<RetargetedMotion> r = RetargetAnimation(*bvh, "", 30, fbx->character());
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("LeftUpLeg"), std::string::npos);
}

TEST(RetargetAnimation, FbxClipOntoAnotherFbxSkeletonValidates) {
  MOTIONLOD_REQUIRE_DATA();
  const auto walk = testing::DataAsset("motions/07_01_cmu.fbx");
  const auto run = testing::DataAsset("motions/09_11_cmu.fbx");
  const StatusOr<RetargetedMotion> r = RetargetAnimation(*walk, "", 30, run->character());
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_TRUE(r->unmatched_target_joints.empty());
  const auto built = core::BuildCharacter(run->character());
  ASSERT_TRUE(built.ok());
  EXPECT_TRUE(core::ValidateMotion(r->motion, **built).ok());
  // Bone lengths are the target's: hips-to-left-up-leg distance stays at its bind value.
  const core::RawSkeleton& t = run->character().skeleton;
  const int hips = testing::JointIndex(t, "LHipJoint"), leg = testing::JointIndex(t, "LeftUpLeg");
  const double bind = (t.bind_world[leg].col(3) - t.bind_world[hips].col(3)).norm();
  for (int f = 0; f < r->motion.frame_count; f += 11) {
    EXPECT_NEAR((r->motion.world(f, leg).col(3) - r->motion.world(f, hips).col(3)).norm(), bind,
                1e-6 * bind);
  }
}

TEST(RetargetAnimation, QuaterniusRobotClipDrivesTheOrc) {
  // Two rigs from one author: the body joints share names, the fingers do not.
  MOTIONLOD_REQUIRE_DATA();
  const auto robot = testing::DataAsset("characters/RobotExpressive.glb");
  const auto orc = testing::DataAsset("characters/Orc.gltf");
  const StatusOr<RetargetedMotion> r = RetargetAnimation(*robot, "Wave", 0, orc->character());
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->motion.frame_count, 45);
  EXPECT_NE(std::find(r->unmatched_target_joints.begin(), r->unmatched_target_joints.end(), "Root"),
            r->unmatched_target_joints.end());
  EXPECT_LE(2 * r->unmatched_target_joints.size(), orc->character().skeleton.parents.size());
  const auto built = core::BuildCharacter(orc->character());
  ASSERT_TRUE(built.ok());
  EXPECT_TRUE(core::ValidateMotion(r->motion, **built).ok());
  // The waving arm of the orc turns like the robot's: compare world-rotation changes.
  const core::Motion source = *robot->SampleAnimation("Wave", 0);
  const int s = testing::JointIndex(robot->character().skeleton, "UpperArm.R");
  const int t = testing::JointIndex(orc->character().skeleton, "UpperArm.R");
  ASSERT_GE(s, 0);
  ASSERT_GE(t, 0);
  auto rotation = [](const core::Affine34d& m) {
    Eigen::JacobiSVD<Matrix3d> svd(m.leftCols<3>(), Eigen::ComputeFullU | Eigen::ComputeFullV);
    return Matrix3d(svd.matrixU() * svd.matrixV().transpose());
  };
  const Matrix3d source_change = rotation(source.world(20, s)) *
                                 rotation(robot->character().skeleton.bind_world[s]).transpose();
  const Matrix3d target_change = rotation(r->motion.world(20, t)) *
                                 rotation(orc->character().skeleton.bind_world[t]).transpose();
  EXPECT_TRUE(target_change.isApprox(source_change, 1e-9));
}

}  // namespace
}  // namespace motionlod::io
