// The client's CPU skinner against the core's skinning (core::SkinningJob) on real baked
// levels: the same positions and normals to float precision, for rigid and non-rigid
// variants, on the sample and on ../shared/data characters; and its validity checks.
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <cmath>

#include "client/skinner.h"
#include "core/skinning.h"
#include "io/asset.h"
#include "pipeline/bake.h"
#include "proto/level_format.h"
#include "tests/client/baked.h"
#include "tests/server/daemon.h"

namespace motionlod::client::testing {
namespace {

using server::testing::SharedDataPath;
using server::testing::SourcePath;

// For every level and a spread of frames: the client's skinner on the level's m matrices
// against core::SkinningJob on the n matrices they stand for (K_j = K'_{map[j]}).
void ExpectSkinnerMatchesCore(const Baked& baked) {
  ASSERT_NE(baked.character, nullptr);
  const core::Character& character = *baked.character;
  const size_t p = static_cast<size_t>(character.vertex_count());
  const size_t n = static_cast<size_t>(character.joint_count());
  ASSERT_EQ(baked.view.joint_count(), n);
  const SkinMesh mesh = MeshOf(character);
  const double height = character.height();
  std::vector<float> positions(3 * p), normals(3 * p);
  std::vector<core::Vec3f> core_positions(p), core_normals(p);
  std::vector<core::Affine34f> expanded(n);
  double worst_position = 0, worst_normal = 0;
  for (const proto::LevelView& level : baked.view.levels()) {
    auto skin = LevelSkin::Build(mesh, level.joint_map(), level.kept_count());
    ASSERT_TRUE(skin.ok()) << skin.error().ToString();
    EXPECT_LE(skin->mean_influences(),
              static_cast<double>(mesh.influence_joints.size()) / static_cast<double>(p));
    const uint32_t frames = level.frame_count();
    for (uint32_t t : {0u, frames / 3, frames / 2, frames - 1}) {
      for (size_t j = 0; j < n; ++j) {
        const float* k = level.matrix(t, level.joint_map()[j]);
        expanded[j] = Eigen::Map<const Eigen::Matrix<float, 3, 4, Eigen::RowMajor>>(k);
      }
      const core::SkinningJob reference{&character, expanded, core_positions, core_normals};
      ASSERT_TRUE(reference.Run().ok());
      const SkinFrameJob job{&*skin, level.frame(t), baked.view.rigid(), positions, normals};
      auto written = job.Run();
      ASSERT_TRUE(written.ok()) << written.error().ToString();
      ASSERT_EQ(*written, p);
      for (size_t i = 0; i < p; ++i) {
        const Eigen::Vector3f ours(positions[3 * i], positions[3 * i + 1], positions[3 * i + 2]);
        worst_position = std::max(worst_position, double((ours - core_positions[i]).norm()));
        // The core's normal is the unnormalised B n (what eq. 3 fits); for a non-rigid
        // level the right transform is cof(B) = det(B) B^-T, computed here in double.
        Eigen::Vector3d expected = core_normals[i].cast<double>();
        if (!baked.view.rigid()) {
          Eigen::Matrix3d blended = Eigen::Matrix3d::Zero();
          const core::RawSkin& raw = character.skin();
          for (uint32_t e = raw.influence_offsets[i]; e < raw.influence_offsets[i + 1]; ++e) {
            blended += double(raw.influence_weights[e]) *
                       expanded[static_cast<size_t>(raw.influence_joints[e])].leftCols<3>().cast<double>();
          }
          expected = blended.determinant() * blended.inverse().transpose() *
                     raw.normals[i].cast<double>();
        }
        const Eigen::Vector3d our_normal(normals[3 * i], normals[3 * i + 1], normals[3 * i + 2]);
        worst_normal = std::max(worst_normal, (our_normal - expected.normalized()).norm());
      }
    }
  }
  // Float precision: a few ulps of the coordinates (the sums run in another order).
  EXPECT_LT(worst_position / height, 2e-6) << "worst " << worst_position << ", height " << height;
  EXPECT_LT(worst_normal, 2e-5);
}

TEST(ClientSkinner, RigidLevelsOfTheSampleMatchCoreSkinning) {
  ExpectSkinnerMatchesCore(BakeInProcess(SourcePath("samples/Rig_Medium_MovementBasic.glb"),
                                         "Walking_A", {23, 12, 6}, core::Variant::kVPNOPD));
}

TEST(ClientSkinner, NonRigidLevelsUseTheCofactorForNormals) {
  const Baked baked = BakeInProcess(SourcePath("samples/Rig_Medium_MovementBasic.glb"),
                                    "Walking_A", {12, 6}, core::Variant::kVPNO);
  ASSERT_FALSE(baked.view.rigid());
  ExpectSkinnerMatchesCore(baked);
}

TEST(ClientSkinner, SharedDataCharactersMatchCoreSkinning) {
  const std::string cesium = SharedDataPath("characters/CesiumMan.glb");
  const std::string orc = SharedDataPath("characters/Orc.gltf");
  if (cesium.empty() || orc.empty()) GTEST_SKIP() << "../shared/data is absent";
  ExpectSkinnerMatchesCore(BakeInProcess(cesium, "", {19, 10, 4}, core::Variant::kVPNOPD));
  ExpectSkinnerMatchesCore(BakeInProcess(orc, "", {43, 20, 8}, core::Variant::kVPNOPD));
}

// A mesh bound one joint per vertex with weight 1 (what a level capped at one influence
// draws) takes the skinner's path without a blend; it poses every vertex as the blending
// path does, which the same mesh takes once one vertex carries a second, zero-weight entry.
TEST(ClientSkinner, OneInfluencePerVertexPosesAsTheBlendDoes) {
  for (core::Variant variant : {core::Variant::kVPNOPD, core::Variant::kVPNO}) {
    const Baked baked = BakeInProcess(SourcePath("samples/Rig_Medium_MovementBasic.glb"),
                                      "Walking_A", {23, 8}, variant);
    ASSERT_NE(baked.character, nullptr);
    const core::RawSkin& raw = baked.character->skin();
    const size_t p = raw.positions.size();
    std::vector<uint32_t> offsets{0};
    std::vector<int32_t> joints;
    for (size_t i = 0; i < p; ++i) {  // each vertex's heaviest joint
      uint32_t heaviest = raw.influence_offsets[i];
      for (uint32_t e = heaviest; e < raw.influence_offsets[i + 1]; ++e) {
        if (raw.influence_weights[e] > raw.influence_weights[heaviest]) heaviest = e;
      }
      joints.push_back(raw.influence_joints[heaviest]);
      offsets.push_back(static_cast<uint32_t>(joints.size()));
    }
    std::vector<float> ones(p, 1.0f);
    const SkinMesh mesh = MeshOf(*baked.character);
    const SkinMesh bound{mesh.positions, mesh.normals, offsets, joints, ones};
    std::vector<uint32_t> blend_offsets = offsets;
    for (size_t i = 1; i <= p; ++i) ++blend_offsets[i];
    std::vector<float> blend_weights = ones;
    blend_weights.insert(blend_weights.begin() + 1, 0.0f);
    for (const proto::LevelView& level : baked.view.levels()) {
      // Vertex 0's second entry: a joint on another slot of this level.
      const std::span<const uint16_t> map = level.joint_map();
      int32_t other = 0;
      while (map[static_cast<size_t>(other)] == map[static_cast<size_t>(joints[0])]) ++other;
      std::vector<int32_t> blend_joints = joints;
      blend_joints.insert(blend_joints.begin() + 1, other);
      const SkinMesh blended{mesh.positions, mesh.normals, blend_offsets, blend_joints,
                             blend_weights};
      auto one = LevelSkin::Build(bound, level.joint_map(), level.kept_count());
      auto two = LevelSkin::Build(blended, level.joint_map(), level.kept_count());
      ASSERT_TRUE(one.ok() && two.ok());
      EXPECT_DOUBLE_EQ(one->mean_influences(), 1.0);
      EXPECT_GT(two->mean_influences(), 1.0);
      std::vector<float> one_positions(3 * p), one_normals(3 * p), two_positions(3 * p),
          two_normals(3 * p);
      const uint32_t t = level.frame_count() / 2;
      ASSERT_TRUE((SkinFrameJob{&*one, level.frame(t), baked.view.rigid(), one_positions, one_normals}.Run().ok()));
      ASSERT_TRUE((SkinFrameJob{&*two, level.frame(t), baked.view.rigid(), two_positions, two_normals}.Run().ok()));
      double worst_position = 0, worst_normal = 0;
      for (size_t c = 3; c < 3 * p; ++c) {  // vertex 0 blends a second slot at weight 0
        worst_position = std::max(worst_position, double(std::abs(one_positions[c] - two_positions[c])));
        worst_normal = std::max(worst_normal, double(std::abs(one_normals[c] - two_normals[c])));
      }
      EXPECT_EQ(worst_position, 0.0) << core::VariantName(variant);
      EXPECT_LT(worst_normal, 1e-5) << core::VariantName(variant);  // rotations in float
    }
  }
}

TEST(ClientSkinner, RejectsMismatchedShapesAndTouchesNothing) {
  const float positions[] = {0, 0, 0, 1, 0, 0};
  const float normals[] = {0, 0, 1, 0, 0, 1};
  const uint32_t offsets[] = {0, 1, 3};
  const int32_t joints[] = {0, 1, 2};
  const float weights[] = {1.0f, 0.25f, 0.75f};
  const SkinMesh mesh{positions, normals, offsets, joints, weights};
  // Joints 1 and 2 both map to slot 1: vertex 1's two influences merge into one.
  const uint16_t joint_map[] = {0, 1, 1};
  auto skin = LevelSkin::Build(mesh, joint_map, 2);
  ASSERT_TRUE(skin.ok()) << skin.error().ToString();
  EXPECT_DOUBLE_EQ(skin->mean_influences(), 1.0);

  // Slot 0 identity, slot 1 a translation by (0, 2, 0).
  const float matrices[] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0,
                            1, 0, 0, 0, 0, 1, 0, 2, 0, 0, 1, 0};
  float out_positions[6] = {}, out_normals[6] = {};
  auto written = SkinFrameJob{&*skin, matrices, true, out_positions, out_normals}.Run();
  ASSERT_TRUE(written.ok());
  EXPECT_EQ(*written, 2u);
  EXPECT_FLOAT_EQ(out_positions[3], 1.0f);
  EXPECT_FLOAT_EQ(out_positions[4], 2.0f);  // 0.25 * 2 + 0.75 * 2
  EXPECT_FLOAT_EQ(out_normals[5], 1.0f);

  float untouched[6] = {9, 9, 9, 9, 9, 9};
  const float short_matrices[12] = {};
  EXPECT_EQ(SkinFrameJob({&*skin, short_matrices, true, untouched, {}}).Run().error().kind,
            ErrorKind::kInvalidArgument);
  EXPECT_FALSE(SkinFrameJob({&*skin, matrices, true, std::span<float>(untouched, 3), {}}).Run().ok());
  EXPECT_FALSE(SkinFrameJob({nullptr, matrices, true, untouched, {}}).Run().ok());
  EXPECT_EQ(untouched[0], 9.0f);

  const int32_t out_of_range[] = {0, 1, 7};
  EXPECT_FALSE(LevelSkin::Build({positions, normals, offsets, out_of_range, weights}, joint_map, 2).ok());
  const uint16_t bad_map[] = {0, 1, 5};
  EXPECT_FALSE(LevelSkin::Build(mesh, bad_map, 2).ok());
  const float negative[] = {1.0f, -0.25f, 1.25f};
  EXPECT_FALSE(LevelSkin::Build({positions, normals, offsets, joints, negative}, joint_map, 2).ok());
  const uint32_t past_the_end[] = {0, 9, 3};
  EXPECT_FALSE(LevelSkin::Build({positions, normals, past_the_end, joints, weights}, joint_map, 2).ok());
  const uint32_t short_offsets[] = {0, 1};
  EXPECT_FALSE(LevelSkin::Build({positions, normals, short_offsets, joints, weights}, joint_map, 2).ok());
}

}  // namespace
}  // namespace motionlod::client::testing
