#include "io/proxy_skin.h"

#include <gtest/gtest.h>

#include "core/character.h"

namespace motionlod::io {
namespace {

using Eigen::Vector3d;

core::RawSkeleton Chain(const std::vector<Vector3d>& positions) {
  core::RawSkeleton s;
  for (size_t j = 0; j < positions.size(); ++j) {
    s.joint_names.push_back(std::string("j").append(std::to_string(j)));
    s.parents.push_back(static_cast<int>(j) - 1);
    core::Affine34d m = core::IdentityAffine();
    m.col(3) = positions[j];
    s.bind_world.push_back(m);
  }
  return s;
}

void ExpectValidSkin(const core::RawSkeleton& skeleton, const core::RawSkin& skin) {
  core::RawCharacter c;
  c.skeleton = skeleton;
  c.skin = skin;
  const Status status = core::ValidateRawCharacter(c);
  EXPECT_TRUE(status.ok()) << status.ToString();
}

TEST(MakeProxySkin, CapsulesAroundAChainAreValidAndOutwardFacing) {
  const core::RawSkeleton s = Chain({Vector3d(0, 0, 0), Vector3d(0, 1, 0), Vector3d(0, 2, 0)});
  const StatusOr<core::RawSkin> skin = MakeProxySkin(s);
  ASSERT_TRUE(skin.ok()) << skin.status().ToString();
  ExpectValidSkin(s, *skin);
  ASSERT_FALSE(skin->triangles.empty());
  for (const auto& t : skin->triangles) {
    const Vector3d a = skin->positions[t[0]].cast<double>(),
                   b = skin->positions[t[1]].cast<double>(),
                   c = skin->positions[t[2]].cast<double>();
    const Vector3d n =
        (skin->normals[t[0]] + skin->normals[t[1]] + skin->normals[t[2]]).cast<double>();
    EXPECT_GE((b - a).cross(c - a).dot(n), 0.0);
  }
  // Every vertex lies within the radius (at most 4% of the height 2) of the bones plus
  // the leaf's continuation up to y = 3.
  for (const auto& p : skin->positions) {
    EXPECT_LE(std::hypot(p.x(), p.z()), 0.08 + 1e-5);
    EXPECT_GE(p.y(), -0.08 - 1e-5);
    EXPECT_LE(p.y(), 2.5 + 0.08 + 1e-5);
  }
}

TEST(MakeProxySkin, WeightsBlendHalfAndHalfAtJoints) {
  const core::RawSkeleton s = Chain({Vector3d(0, 0, 0), Vector3d(0, 1, 0), Vector3d(0, 2, 0)});
  const StatusOr<core::RawSkin> skin = MakeProxySkin(s);
  ASSERT_TRUE(skin.ok());
  // A vertex on the ring at y = 1 (the middle joint) of the first bone: 0.5 j0, 0.5 j1.
  bool found = false;
  for (size_t i = 0; i < skin->positions.size() && !found; ++i) {
    if (std::abs(skin->positions[i].y() - 1.0f) > 1e-6f) continue;
    const uint32_t b = skin->influence_offsets[i], e = skin->influence_offsets[i + 1];
    if (e - b != 2) continue;
    found = true;
    EXPECT_NEAR(skin->influence_weights[b], 0.5f, 1e-6);
    EXPECT_NEAR(skin->influence_weights[b + 1], 0.5f, 1e-6);
  }
  EXPECT_TRUE(found);
  // The mid-bone rings are weighted to the bone's parent joint only.
  for (size_t i = 0; i < skin->positions.size(); ++i) {
    if (std::abs(skin->positions[i].y() - 0.5f) < 1e-6f) {
      ASSERT_EQ(skin->influence_offsets[i + 1] - skin->influence_offsets[i], 1u);
      EXPECT_EQ(skin->influence_joints[skin->influence_offsets[i]], 0);
    }
  }
}

TEST(MakeProxySkin, ZeroLengthBonesAreSkippedButTheSkinStaysValid) {
  // BVH-style: a joint at its parent's position (LHipJoint at Hips).
  core::RawSkeleton s =
      Chain({Vector3d(0, 1, 0), Vector3d(0, 1, 0), Vector3d(0.2, 0.5, 0), Vector3d(0.2, 0, 0)});
  const StatusOr<core::RawSkin> skin = MakeProxySkin(s);
  ASSERT_TRUE(skin.ok());
  ExpectValidSkin(s, *skin);
  bool root_weighted = false;
  for (int32_t j : skin->influence_joints) root_weighted = root_weighted || j == 0;
  EXPECT_TRUE(root_weighted);  // through the blend at the start of j1's bone
}

TEST(MakeProxySkin, LoneJointGetsABall) {
  const core::RawSkeleton s = Chain({Vector3d(1, 2, 3)});
  const StatusOr<core::RawSkin> skin = MakeProxySkin(s);
  ASSERT_TRUE(skin.ok());
  ExpectValidSkin(s, *skin);
  EXPECT_GT(skin->positions.size(), 2u);
}

TEST(MakeProxySkin, RejectsInvalidInput) {
  EXPECT_FALSE(MakeProxySkin(core::RawSkeleton{}).ok());
  core::RawSkeleton s = Chain({Vector3d(0, 0, 0), Vector3d(0, 1, 0)});
  s.parents[1] = 5;
  EXPECT_FALSE(MakeProxySkin(s).ok());
  s = Chain({Vector3d(0, 0, 0), Vector3d(0, std::nan(""), 0)});
  EXPECT_FALSE(MakeProxySkin(s).ok());
  ProxySkinOptions options;
  options.sides = 2;
  EXPECT_FALSE(MakeProxySkin(Chain({Vector3d::Zero()}), options).ok());
  options = {};
  options.blend = 0.7;
  EXPECT_FALSE(MakeProxySkin(Chain({Vector3d::Zero()}), options).ok());
}

}  // namespace
}  // namespace motionlod::io
