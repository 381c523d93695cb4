// Import of every file of the third-party data set (../shared/data/MANIFEST.md), and of
// the hand-made glTF fixture whose answers are known exactly.
#include "io/asset.h"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "core/character.h"
#include "core/motion.h"
#include "gltf_fixture.h"
#include "tests/fixtures/flat_bvh.h"
#include "test_util.h"

namespace motionlod::io {
namespace {

using Eigen::Vector3d;
using testing::DataAsset;

struct ManifestFile {
  const char* path;
  int joints;
  int min_vertices;  // real skins: near MANIFEST's welded count; proxies: a few thousand
  int max_vertices;
  bool proxy;
  int animations;
};

// Joints from MANIFEST's "Joints" column; vertex bounds bracket its welded ("Vertices")
// and raw counts with a few percent of slack for Assimp's welding of generated normals.
const ManifestFile kManifest[] = {
    {"characters/CesiumMan.glb", 19, 2500, 3273, false, 1},
    {"characters/RobotExpressive.glb", 43, 6900, 7214, false, 14},
    {"characters/Orc.gltf", 43, 4300, 4412, false, 14},
    {"characters/Rig_Medium_MovementBasic.glb", 23, 6400, 6675, false, 11},
    {"characters/Rig_Medium_General.glb", 23, 6400, 6675, false, 15},
    {"characters/Knight.glb", 23, 5200, 5328, false, 0},
    {"characters/stormtrooper.dae", 52, 5000, 5700, false, 1},
    {"characters/Fox.glb", 24, 420, 1728, false, 3},
    {"characters/Superhero_Male_FullBody.gltf", 65, 8000, 8483, false, 0},
    {"motions/cmu_131_01.bvh", 31, 500, 20000, true, 1},
    {"motions/cmu_131_02.bvh", 31, 500, 20000, true, 1},
    {"motions/cmu_131_03.bvh", 31, 500, 20000, true, 1},
    {"motions/pirouette.bvh", 43, 500, 20000, true, 1},
    {"motions/acrnn_salsa_10.bvh", 43, 500, 20000, true, 1},
    {"motions/acrnn_martial_04.bvh", 43, 500, 20000, true, 1},
    {"motions/acrnn_indian_13.bvh", 43, 500, 20000, true, 1},
    {"motions/07_01_cmu.fbx", 31, 500, 20000, true, 1},
    {"motions/08_02_cmu.fbx", 31, 500, 20000, true, 1},
    {"motions/09_11_cmu.fbx", 31, 500, 20000, true, 1},
    {"motions/49_08_cmu.fbx", 31, 500, 20000, true, 1},
    {"motions/55_01_cmu.fbx", 31, 500, 20000, true, 1},
};

TEST(LoadAsset, EveryManifestFileHasItsJointCountAndASensibleSkin) {
  MOTIONLOD_REQUIRE_DATA();
  for (const ManifestFile& f : kManifest) {
    SCOPED_TRACE(f.path);
    const auto asset = DataAsset(f.path);
    ASSERT_NE(asset, nullptr);
    const core::RawCharacter& c = asset->character();
    EXPECT_EQ(static_cast<int>(c.skeleton.parents.size()), f.joints);
    EXPECT_GE(static_cast<int>(c.skin.positions.size()), f.min_vertices);
    EXPECT_LE(static_cast<int>(c.skin.positions.size()), f.max_vertices);
    EXPECT_EQ(asset->has_proxy_skin(), f.proxy);
    EXPECT_EQ(static_cast<int>(asset->animations().size()), f.animations);
  }
}

TEST(LoadAsset, EveryManifestFileBuildsAValidCharacterWithUnitWeights) {
  MOTIONLOD_REQUIRE_DATA();
  for (const ManifestFile& f : kManifest) {
    SCOPED_TRACE(f.path);
    const auto asset = DataAsset(f.path);
    ASSERT_NE(asset, nullptr);
    const core::RawSkin& skin = asset->character().skin;
    for (size_t i = 0; i + 1 < skin.influence_offsets.size(); ++i) {
      double sum = 0;
      for (uint32_t e = skin.influence_offsets[i]; e < skin.influence_offsets[i + 1]; ++e) {
        sum += skin.influence_weights[e];
      }
      ASSERT_NEAR(sum, 1.0, 1e-5) << "vertex " << i;
      ASSERT_LE(skin.influence_offsets[i + 1] - skin.influence_offsets[i], 8u);
    }
    const auto built = core::BuildCharacter(asset->character());
    ASSERT_TRUE(built.ok()) << built.status().ToString();
    EXPECT_GT((*built)->height(), 0);
  }
}

TEST(LoadAsset, JointsFollowTheFormatRules) {
  MOTIONLOD_REQUIRE_DATA();
  const auto& bvh = DataAsset("motions/cmu_131_01.bvh")->character().skeleton;
  const auto& fbx = DataAsset("motions/07_01_cmu.fbx")->character().skeleton;
  EXPECT_EQ(bvh.joint_names.front(), "Hips");
  EXPECT_EQ(fbx.joint_names.front(), "Hips");
  for (const std::string& name : bvh.joint_names)
    EXPECT_EQ(name.find("EndSite"), std::string::npos) << name;
  for (const std::string& name : fbx.joint_names) {
    EXPECT_EQ(name.find("_end"), std::string::npos) << name;
    EXPECT_EQ(name.find("$AssimpFbx$"), std::string::npos) << name;
    EXPECT_NE(name, "07_01");  // the FBX Null above the skeleton
  }
  // RobotExpressive has mesh nodes named like their joints; the joints win.
  const auto robot = DataAsset("characters/RobotExpressive.glb");
  EXPECT_EQ(robot->character().skeleton.joint_names.front(), "Bone");
  EXPECT_GE(testing::JointIndex(robot->character().skeleton, "Torso"), 0);
}

struct ClipExpectation {
  const char* path;
  const char* clip;  // "" = the first
  double duration;   // seconds, MANIFEST
  double fps;        // source rate
  int frames;        // at the source rate
};

const ClipExpectation kClips[] = {
    {"motions/cmu_131_01.bvh", "", 8.275, 120, 994},
    {"motions/cmu_131_02.bvh", "", 10.383, 120, 1247},
    {"motions/cmu_131_03.bvh", "", 9.175, 120, 1102},
    {"motions/pirouette.bvh", "", 4.925, 120, 592},
    {"motions/acrnn_salsa_10.bvh", "", 9.975, 120, 1198},
    {"motions/acrnn_martial_04.bvh", "", 10.967, 120, 1317},
    {"motions/acrnn_indian_13.bvh", "", 16.625, 120, 1996},
    {"motions/07_01_cmu.fbx", "", 2.633, 120, 317},
    {"motions/08_02_cmu.fbx", "", 2.575, 120, 310},
    {"motions/09_11_cmu.fbx", "", 1.375, 120, 166},
    {"motions/49_08_cmu.fbx", "", 4.792, 120, 576},
    {"motions/55_01_cmu.fbx", "", 15.050, 120, 1807},
    {"characters/RobotExpressive.glb", "Dance", 3.333, 24, 81},
    {"characters/RobotExpressive.glb", "Wave", 1.833, 24, 45},
    {"characters/CesiumMan.glb", "", 2.0, 24, 49},
    {"characters/Orc.gltf", "Idle", 1.0, 30, 31},
    {"characters/Rig_Medium_MovementBasic.glb", "Walking_A", 1.0667, 30, 33},
    {"characters/Rig_Medium_MovementBasic.glb", "T-Pose", 0.0, 30, 1},
    {"characters/stormtrooper.dae", "", 3.867, 30, 117},
    {"characters/Fox.glb", "Survey", 3.417, 24, 83},
};

TEST(SampleAnimation, FrameCountsFollowManifestDurationsAndRates) {
  MOTIONLOD_REQUIRE_DATA();
  for (const ClipExpectation& e : kClips) {
    SCOPED_TRACE(std::string(e.path) + " " + e.clip);
    const auto asset = DataAsset(e.path);
    ASSERT_NE(asset, nullptr);
    const AnimationInfo* info = &asset->animations().front();
    for (const AnimationInfo& a : asset->animations()) {
      if (a.name == e.clip) info = &a;
    }
    EXPECT_NEAR(info->duration_seconds, e.duration, 1e-3);
    EXPECT_DOUBLE_EQ(info->source_fps, e.fps);
    EXPECT_EQ(info->source_frame_count, e.frames);
    const StatusOr<core::Motion> motion = asset->SampleAnimation(e.clip, 0);
    ASSERT_TRUE(motion.ok()) << motion.status().ToString();
    EXPECT_EQ(motion->frame_count, e.frames);
    EXPECT_EQ(motion->fps, e.fps);
  }
}

TEST(SampleAnimation, ResamplesAtTheRequestedRate) {
  MOTIONLOD_REQUIRE_DATA();
  const auto bvh = DataAsset("motions/cmu_131_01.bvh");
  EXPECT_EQ(bvh->SampleAnimation("", 120)->frame_count, 994);
  EXPECT_EQ(bvh->SampleAnimation("Motion", 30)->frame_count, 249);
  const auto robot = DataAsset("characters/RobotExpressive.glb");
  EXPECT_EQ(robot->SampleAnimation("Dance", 30)->frame_count, 101);
  // At the source rate, frames land on keys: resampling at twice the rate keeps them.
  const core::Motion at24 = *robot->SampleAnimation("Dance", 24);
  const core::Motion at48 = *robot->SampleAnimation("Dance", 48);
  for (int t = 0; t < at24.frame_count; t += 10) {
    for (int j = 0; j < at24.joint_count; ++j) {
      ASSERT_TRUE(at24.world(t, j).isApprox(at48.world(2 * t, j), 1e-9)) << t << " " << j;
    }
  }
}

TEST(SampleAnimation, ThreadsSplitTheFramesWithoutChangingThem) {
  MOTIONLOD_REQUIRE_DATA();
  for (const char* file : {"motions/cmu_131_01.bvh", "characters/RobotExpressive.glb"}) {
    const auto asset = DataAsset(file);
    const core::Motion one = *asset->SampleAnimation("", 0);
    for (int threads : {2, 3, 7}) {
      const core::Motion split = *asset->SampleAnimation("", 0, testing::ThreadRunner(threads));
      ASSERT_EQ(split.frame_count, one.frame_count) << file;
      ASSERT_EQ(split.joint_world.size(), one.joint_world.size()) << file;
      for (size_t q = 0; q < one.joint_world.size(); ++q) {
        ASSERT_EQ(split.joint_world[q], one.joint_world[q])
            << file << " " << threads << " matrix " << q;
      }
    }
  }
}

TEST(SampleAnimation, EveryClipOfEveryFileValidatesAgainstItsCharacter) {
  MOTIONLOD_REQUIRE_DATA();
  for (const ManifestFile& f : kManifest) {
    SCOPED_TRACE(f.path);
    const auto asset = DataAsset(f.path);
    ASSERT_NE(asset, nullptr);
    const auto character = core::BuildCharacter(asset->character());
    ASSERT_TRUE(character.ok());
    for (const AnimationInfo& info : asset->animations()) {
      SCOPED_TRACE(info.name);
      const StatusOr<core::Motion> motion = asset->SampleAnimation(info.name, 0);
      ASSERT_TRUE(motion.ok()) << motion.status().ToString();
      EXPECT_EQ(motion->frame_count, info.source_frame_count);
      const Status valid = core::ValidateMotion(*motion, **character);
      EXPECT_TRUE(valid.ok()) << valid.ToString();
    }
  }
}

TEST(SampleAnimation, FirstFrameSkinsToAFiniteMeshOfTheSameSize) {
  MOTIONLOD_REQUIRE_DATA();
  for (const ManifestFile& f : kManifest) {
    if (f.animations == 0) continue;
    SCOPED_TRACE(f.path);
    const auto asset = DataAsset(f.path);
    const core::RawCharacter& c = asset->character();
    const double rest_extent = testing::Extent(testing::BindPositions(c));
    for (const AnimationInfo& info : asset->animations()) {
      if (info.name.rfind("Spawn", 0) == 0) continue;  // these start scaled to nothing
      SCOPED_TRACE(info.name);
      const core::Motion motion = *asset->SampleAnimation(info.name, 0);
      const std::vector<Vector3d> posed = testing::SkinFrame(c, motion, 0);
      ASSERT_EQ(posed.size(), c.skin.positions.size());
      for (const Vector3d& p : posed) ASSERT_TRUE(p.allFinite());
      const double extent = testing::Extent(posed);
      EXPECT_GT(extent, 0.3 * rest_extent);
      EXPECT_LT(extent, 3.0 * rest_extent);
    }
  }
}

TEST(SampleAnimation, TPoseClipSkinsBackToTheBindPoseMesh) {
  // KayKit's "T-Pose" clip is the bind pose: K_j = M_j M0_j^-1 must then be the identity
  // on every vertex, which checks that bind matrices and vertices share one space.
  MOTIONLOD_REQUIRE_DATA();
  for (const char* path :
       {"characters/Rig_Medium_MovementBasic.glb", "characters/Rig_Medium_General.glb"}) {
    SCOPED_TRACE(path);
    const auto asset = DataAsset(path);
    const core::RawCharacter& c = asset->character();
    const core::Motion motion = *asset->SampleAnimation("T-Pose", 0);
    const std::vector<Vector3d> posed = testing::SkinFrame(c, motion, 0);
    const double height = testing::Extent(testing::BindPositions(c));
    double worst = 0;
    for (size_t i = 0; i < posed.size(); ++i) {
      worst = std::max(worst, (posed[i] - c.skin.positions[i].cast<double>()).norm());
    }
    EXPECT_LT(worst, 1e-3 * height);
  }
}

TEST(SampleAnimation, BindMatricesMatchTheRestPoseWhereTheFileSaysSo) {
  // Where a file's node rest pose is its bind pose (KayKit, Superhero), M0 = rest world.
  MOTIONLOD_REQUIRE_DATA();
  const auto asset = DataAsset("characters/Rig_Medium_MovementBasic.glb");
  const core::RawSkeleton& s = asset->character().skeleton;
  const core::Motion pose = *asset->SampleAnimation("T-Pose", 0);
  for (size_t j = 0; j < s.parents.size(); ++j) {
    EXPECT_TRUE(pose.world(0, static_cast<int>(j)).isApprox(s.bind_world[j], 1e-4))
        << s.joint_names[j];
  }
}

TEST(SampleAnimation, RigidMeshesMoveWithTheirJoints) {
  MOTIONLOD_REQUIRE_DATA();
  const auto robot = DataAsset("characters/RobotExpressive.glb");
  const core::RawCharacter& c = robot->character();
  const int head = testing::JointIndex(c.skeleton, "Head");
  ASSERT_GE(head, 0);
  int head_vertices = 0;
  for (size_t i = 0; i + 1 < c.skin.influence_offsets.size(); ++i) {
    const uint32_t b = c.skin.influence_offsets[i];
    head_vertices += c.skin.influence_offsets[i + 1] - b == 1 && c.skin.influence_joints[b] == head;
  }
  EXPECT_GT(head_vertices, 500);  // the three Head meshes
  // Over the Wave clip, a rigid head vertex keeps its distance to the head joint.
  const core::Motion wave = *robot->SampleAnimation("Wave", 0);
  for (int t = 0; t < wave.frame_count; t += 7) {
    const std::vector<Vector3d> posed = testing::SkinFrame(c, wave, t);
    for (size_t i = 0; i + 1 < c.skin.influence_offsets.size(); i += 97) {
      const uint32_t b = c.skin.influence_offsets[i];
      if (c.skin.influence_offsets[i + 1] - b != 1 || c.skin.influence_joints[b] != head) continue;
      const double rest =
          (c.skin.positions[i].cast<double>() - Vector3d(c.skeleton.bind_world[head].col(3)))
              .norm();
      const double now = (posed[i] - Vector3d(wave.world(t, head).col(3))).norm();
      EXPECT_NEAR(now, rest, 1e-4 * rest + 1e-9);
    }
  }
}

TEST(SampleAnimation, UnknownNamesAndBadRatesAreReported) {
  MOTIONLOD_REQUIRE_DATA();
  const auto robot = DataAsset("characters/RobotExpressive.glb");
  const StatusOr<core::Motion> missing = robot->SampleAnimation("Moonwalk", 0);
  ASSERT_EQ(missing.status().code(), StatusCode::kNotFound);
  EXPECT_NE(missing.status().message().find("Moonwalk"), std::string::npos);
  EXPECT_NE(missing.status().message().find("'Dance'"), std::string::npos);
  EXPECT_EQ(robot->SampleAnimation("Dance", -1).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(robot->SampleAnimation("Dance", std::nan("")).status().code(),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(robot->SampleAnimation("Dance", 1e6).status().code(), StatusCode::kInvalidArgument);
  const auto knight = DataAsset("characters/Knight.glb");
  const StatusOr<core::Motion> none = knight->SampleAnimation("", 0);
  EXPECT_EQ(none.status().code(), StatusCode::kNotFound);
  EXPECT_NE(none.status().message().find("no animation"), std::string::npos);
}

TEST(LoadAsset, GltfWithSeparateBufferLoadsFromTheGivenFilesOnly) {
  MOTIONLOD_REQUIRE_DATA();
  const std::string gltf =
      testing::ReadBytes(testing::DataDir() / "characters/Superhero_Male_FullBody.gltf");
  const std::string bin =
      testing::ReadBytes(testing::DataDir() / "characters/Superhero_Male_FullBody.bin");
  const auto with_bin =
      LoadAsset({{"Superhero_Male_FullBody.gltf", gltf}, {"Superhero_Male_FullBody.bin", bin}});
  ASSERT_TRUE(with_bin.ok()) << with_bin.status().ToString();
  EXPECT_EQ((*with_bin)->character().skeleton.parents.size(), 65u);
  const auto without_bin = LoadAsset({{"Superhero_Male_FullBody.gltf", gltf}});
  ASSERT_FALSE(without_bin.ok());
  EXPECT_NE(without_bin.status().message().find("Superhero_Male_FullBody.bin"), std::string::npos);
}

// --- The hand-made fixture: exact answers -------------------------------------------

TEST(LoadAsset, FixtureSkeletonSkinAndClipAreExact) {
  const testing::GltfFixture fixture = testing::MakeSkinnedGltf();
  const auto asset = LoadAsset({{"fixture.gltf", fixture.json}});
  ASSERT_TRUE(asset.ok()) << asset.status().ToString();
  const core::RawCharacter& c = (*asset)->character();
  EXPECT_EQ(c.skeleton.joint_names, (std::vector<std::string>{"root", "child"}));
  EXPECT_EQ(c.skeleton.parents, (std::vector<int>{-1, 0}));
  EXPECT_TRUE(c.skeleton.bind_world[1].col(3).isApprox(Vector3d(0, 1, 0)));
  ASSERT_EQ(c.skin.positions.size(), 4u);
  ASSERT_EQ(c.skin.triangles.size(), 2u);
  ASSERT_EQ((*asset)->animations().size(), 1u);
  const AnimationInfo& info = (*asset)->animations()[0];
  EXPECT_EQ(info.name, "Bend");
  EXPECT_DOUBLE_EQ(info.duration_seconds, 1.0);
  EXPECT_EQ(info.source_fps, 30.0);  // keys every 0.5 s are poses, not a rate
  EXPECT_EQ(info.source_frame_count, 31);

  // At 4 fps frame 1 is t = 0.25 s: root at (0.5, 0, 0), child turned 22.5 degrees.
  const core::Motion m = *(*asset)->SampleAnimation("Bend", 4);
  ASSERT_EQ(m.frame_count, 5);
  EXPECT_TRUE(m.world(1, 0).col(3).isApprox(Vector3d(0.5, 0, 0), 1e-6));
  const Eigen::Matrix3d turn =
      Eigen::AngleAxisd(std::numbers::pi / 8, Vector3d::UnitZ()).toRotationMatrix();
  EXPECT_TRUE(m.world(1, 1).leftCols<3>().isApprox(turn, 1e-6));
  EXPECT_TRUE(m.world(1, 1).col(3).isApprox(Vector3d(0.5, 1, 0), 1e-6));
  // Skinning: the top vertex (0.5, 2, 0) turns about the child joint (0.5, 1, 0).
  const std::vector<Vector3d> posed = testing::SkinFrame(c, m, 1);
  for (size_t i = 0; i < 4; ++i) {
    const Vector3d v = c.skin.positions[i].cast<double>();
    const Vector3d expected = v.y() > 1
                                  ? Vector3d(Vector3d(0.5, 1, 0) + turn * (v - Vector3d(0, 1, 0)))
                                  : Vector3d(v + Vector3d(0.5, 0, 0));
    EXPECT_TRUE(posed[i].isApprox(expected, 1e-6)) << i;
  }
}

TEST(LoadAsset, FixtureAsGlbAndAsGltfWithBinAgree) {
  testing::GltfFixtureOptions glb_options;
  glb_options.glb_buffer = true;
  const testing::GltfFixture glb_fixture = testing::MakeSkinnedGltf(glb_options);
  const auto glb =
      LoadAsset({{"fixture.glb", testing::MakeGlb(glb_fixture.json, glb_fixture.buffer)}});
  ASSERT_TRUE(glb.ok()) << glb.status().ToString();
  testing::GltfFixtureOptions bin_options;
  bin_options.buffer_uri = "fixture.bin";
  const testing::GltfFixture bin_fixture = testing::MakeSkinnedGltf(bin_options);
  const auto gltf =
      LoadAsset({{"fixture.gltf", bin_fixture.json}, {"fixture.bin", bin_fixture.buffer}});
  ASSERT_TRUE(gltf.ok()) << gltf.status().ToString();
  EXPECT_EQ((*glb)->character().skin.positions, (*gltf)->character().skin.positions);
}

TEST(LoadAsset, ValveSmdWithSkeletonAndAnimationImports) {
  const std::string smd =
      "version 1\nnodes\n0 \"root\" -1\n1 \"child\" 0\nend\nskeleton\ntime 0\n0 0 0 0 0 0 0\n"
      "1 0 1 0 0 0 0\ntime 1\n0 0 0 0 0 0 0\n1 0 1 0 0 0 1.5\nend\ntriangles\nmat\n"
      "0 0 0 0 0 0 1 0 0\n0 1 0 0 0 0 1 1 0\n1 0 2 0 0 0 1 0 1\nend\n";
  const auto asset = LoadAsset({{"two.smd", smd}});
  ASSERT_TRUE(asset.ok()) << asset.status().ToString();
  EXPECT_EQ((*asset)->character().skeleton.joint_names,
            (std::vector<std::string>{"root", "child"}));
  EXPECT_EQ((*asset)->character().skin.positions.size(), 3u);
  EXPECT_TRUE((*asset)->warnings().empty()) << (*asset)->warnings().front();
  ASSERT_EQ((*asset)->animations().size(), 1u);
  const auto built = core::BuildCharacter((*asset)->character());
  ASSERT_TRUE(built.ok());
  EXPECT_TRUE(core::ValidateMotion(*(*asset)->SampleAnimation("", 0), **built).ok());
}

TEST(LoadAsset, DirectXRigidAnimationUsesTheAnimatedFrameAsJoint) {
  const std::string x =
      "xof 0303txt 0032\nFrame Root {\n FrameTransformMatrix { 1.0,0.0,0.0,0.0,0.0,1.0,0.0,0.0,"
      "0.0,0.0,1.0,0.0,0.0,0.0,0.0,1.0;; }\n Frame Child {\n  FrameTransformMatrix { "
      "1.0,0.0,0.0,0.0,"
      "0.0,1.0,0.0,0.0,0.0,0.0,1.0,0.0,0.0,1.0,0.0,1.0;; }\n  Mesh {\n   3;\n   0.0;0.0;0.0;,\n"
      "   1.0;0.0;0.0;,\n   0.0;1.0;0.0;;\n   1;\n   3;0,1,2;;\n  }\n }\n}\n"
      "AnimationSet Lift {\n Animation {\n  {Child}\n  AnimationKey { 2; 2; 0;3;0.0,1.0,0.0;;, "
      "4800;3;0.0,2.0,0.0;;; }\n }\n}\n";
  const auto asset = LoadAsset({{"lift.x", x}});
  ASSERT_TRUE(asset.ok()) << asset.status().ToString();
  EXPECT_EQ((*asset)->character().skeleton.joint_names, (std::vector<std::string>{"Child"}));
  EXPECT_FALSE((*asset)->has_proxy_skin());
  ASSERT_EQ((*asset)->animations().size(), 1u);
  EXPECT_DOUBLE_EQ((*asset)->animations()[0].duration_seconds, 1.0);  // 4800 ticks per second
  const core::Motion m = *(*asset)->SampleAnimation("Lift", 10);
  EXPECT_TRUE(m.world(5, 0).col(3).isApprox(Vector3d(0, 1.5, 0), 1e-9));
}

TEST(LoadAsset, RejectsBadOptions) {
  LoadOptions options;
  options.max_influences = 0;
  EXPECT_EQ(LoadAsset({{"a.gltf", "{}"}}, options).status().code(), StatusCode::kInvalidArgument);
  options = {};
  options.allowed_extensions = {"obj"};
  EXPECT_EQ(LoadAsset({{"a.gltf", "{}"}}, options).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(LoadAsset({}).status().code(), StatusCode::kInvalidArgument);
}

TEST(LoadAsset, LimitsOnJointsVerticesAndFramesRefuseTheAsset) {
  using motionlod::testing::FlatBvh;
  const std::string bvh = FlatBvh(50, 10);
  ASSERT_TRUE(LoadAsset({{"flat.bvh", bvh}}).ok());
  const auto refused = [](const std::string& name, const std::string& bytes,
                          const LoadOptions& options, const std::string& message) {
    const auto asset = LoadAsset({{name, bytes}}, options);
    ASSERT_FALSE(asset.ok()) << message;
    EXPECT_EQ(asset.status().code(), StatusCode::kInvalidArgument);
    EXPECT_NE(asset.status().message().find(message), std::string::npos)
        << asset.status().message();
  };
  // A BVH's declared joints and frames are counted before Assimp parses it: a file of
  // 20,000 joints (3 MB, which Assimp turned into a 3 M-vertex proxy skin) is refused.
  refused("flat.bvh", FlatBvh(20000, 2), {},
          "declares 20000 joints, more than the limit of 1024 "
          "(max_joints)");
  LoadOptions options;
  options.max_joints = 40;
  refused("flat.bvh", bvh, options, "declares 50 joints");
  options = {};
  options.max_frames = 9;
  refused("flat.bvh", bvh, options, "(max_frames)");
  options = {};
  options.max_joint_frames = 499;  // 50 joints x 10 frames
  refused("flat.bvh", bvh, options, "10 frames of 50 joints");
  // Other formats: joints found when the skeleton is built, vertices once the skin is.
  const std::string sample = testing::ReadBytes(std::filesystem::path(MOTIONLOD_SOURCE_DIR) /
                                       "samples/Rig_Medium_MovementBasic.glb");
  options = {};
  options.max_joints = 10;
  refused("rig.glb", sample, options, "has 23 joints, more than the limit of 10");
  options = {};
  options.max_vertices = 1000;
  refused("rig.glb", sample, options, "(max_vertices)");
  options = {};
  options.max_joints = 0;
  refused("rig.glb", sample, options, "must be positive");
}

}  // namespace
}  // namespace motionlod::io
