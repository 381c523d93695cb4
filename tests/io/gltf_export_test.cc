// io::ExportLevelGlb: levels solved on real characters, exported, re-imported through the
// project's own importer (Assimp) and posed by three.js' GLTFLoader, and compared with the
// level they came from.
#include "io/gltf_export.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <string_view>
#include <vector>

#include "core/rank_joints.h"
#include "core/reduce_skeleton.h"
#include "core/solve_levels.h"
#include "io/asset.h"
#include "tests/core/fixtures.h"
#include "tests/io/test_util.h"
#include "tests/tools/gltf_validator.h"

namespace motionlod::io {
namespace {

using testing::DataAsset;

// A level solved in-process, with the storage a GltfLevel points into.
struct SolvedLevel {
  std::shared_ptr<const core::Character> character;
  core::ReducedSkeleton skeleton;
  std::vector<std::string_view> joint_names;
  std::vector<uint16_t> kept_joints, joint_map;
  std::vector<float> matrices;  // T x m x 12, row-major 3x4
  double fps = 0;
  int frames = 0;
  bool rigid = false;

  GltfLevel View() const {
    return {.joint_names = joint_names,
            .kept_joints = kept_joints,
            .joint_map = joint_map,
            .matrices = matrices,
            .frame_count = static_cast<uint32_t>(frames),
            .fps = fps,
            .rigid = rigid,
            .animation_name = "test"};
  }
  core::Affine34d K(int t, int s) const {
    core::Affine34d k;
    const float* f = matrices.data() + (static_cast<size_t>(t) * kept_joints.size() + s) * 12;
    for (int row = 0; row < 3; ++row) {
      for (int col = 0; col < 4; ++col) k(row, col) = f[row * 4 + col];
    }
    return k;
  }
};

SolvedLevel Solve(const std::string& file, int kept, core::Variant variant, int max_frames = 40) {
  SolvedLevel level;
  const auto asset = DataAsset(file);
  EXPECT_NE(asset, nullptr);
  level.character = *core::BuildCharacter(asset->character());
  core::Motion motion = *asset->SampleAnimation("", 0);
  if (motion.frame_count > max_frames) {
    motion.frame_count = max_frames;
    motion.joint_world.resize(static_cast<size_t>(max_frames) * motion.joint_count);
  }
  const core::JointRanking ranking = *core::RankJointsJob{level.character.get(), &motion, {}}.Run();
  level.skeleton = *core::ReduceSkeletonToCount(*level.character, ranking, kept);
  core::SolveSettings settings;
  settings.variant = variant;
  const auto prepared = *core::PreparedMotion::Create(level.character, motion, settings);
  const core::LevelResult result = *prepared->SolveLevel(level.skeleton);
  for (const std::string& name : level.character->skeleton().joint_names)
    level.joint_names.push_back(name);
  level.kept_joints.assign(level.skeleton.kept_joints.begin(), level.skeleton.kept_joints.end());
  level.joint_map.assign(level.skeleton.joint_to_slot.begin(), level.skeleton.joint_to_slot.end());
  for (const core::RowMajorAffine34f& k : result.matrices) {
    for (int row = 0; row < 3; ++row) {
      for (int col = 0; col < 4; ++col) level.matrices.push_back(k(row, col));
    }
  }
  level.fps = motion.fps;
  level.frames = motion.frame_count;
  level.rigid = core::IsRigid(variant);
  return level;
}

// The level's own skinned mesh at frame t: reduced influences w' and K'.
std::vector<Eigen::Vector3d> LevelSkin(const SolvedLevel& level, int t) {
  const core::RawSkin& skin = level.character->skin();
  const core::ReducedInfluences w = core::ReduceInfluences(skin, level.skeleton);
  std::vector<Eigen::Vector3d> out(skin.positions.size(), Eigen::Vector3d::Zero());
  for (size_t i = 0; i < out.size(); ++i) {
    for (uint32_t e = w.offsets[i]; e < w.offsets[i + 1]; ++e) {
      out[i] +=
          w.weights[e] * core::TransformPoint(level.K(t, w.slots[e]),
                                              Eigen::Vector3d(skin.positions[i].cast<double>()));
    }
  }
  return out;
}

// Index of the vertex of `skin` at `position` with normal `normal` (within `tolerance`
// and 1e-3), or -1. Linear search: the skins here have a few thousand vertices.
int FindVertex(const core::RawSkin& skin, const Eigen::Vector3f& position,
               const Eigen::Vector3f& normal, double tolerance) {
  for (size_t i = 0; i < skin.positions.size(); ++i) {
    if ((skin.positions[i] - position).norm() <= tolerance &&
        (skin.normals[i].normalized() - normal.normalized()).norm() <= 1e-3) {
      return static_cast<int>(i);
    }
  }
  return -1;
}

struct Case {
  const char* file;
  int kept;
  core::Variant variant;
};

class GltfExportRoundTrip : public ::testing::TestWithParam<Case> {};

// Re-importing the .glb gives the kept joints, the same skin (welded), T frames, and a skinned mesh
// equal to the level's within the deviation the export reports (float noise for rigid
// levels without truncated influences): the TRS channels reproduce K'.
TEST_P(GltfExportRoundTrip, ReimportedAnimationSkinsLikeTheLevel) {
  MOTIONLOD_REQUIRE_DATA();
  const Case c = GetParam();
  const SolvedLevel level = Solve(c.file, c.kept, c.variant);
  auto exported = ExportLevelGlb(*level.character, level.View());
  ASSERT_TRUE(exported.ok()) << exported.status().ToString();
  const GltfExportStats& stats = exported->stats;
  EXPECT_EQ(stats.joints, c.kept);
  EXPECT_EQ(stats.vertices, level.character->vertex_count());
  EXPECT_EQ(stats.frames, level.frames);
  EXPECT_EQ(std::memcmp(exported->glb.data(), "glTF", 4), 0);

  auto reimported = LoadAsset({{"level.glb", exported->glb}});
  ASSERT_TRUE(reimported.ok()) << reimported.status().ToString();
  const core::RawCharacter& raw = (*reimported)->character();
  ASSERT_EQ(raw.skeleton.joint_names.size(), static_cast<size_t>(c.kept));
  for (uint16_t j : level.kept_joints) {
    EXPECT_GE(testing::JointIndex(raw.skeleton, level.character->skeleton().joint_names[j]), 0)
        << "kept joint " << level.character->skeleton().joint_names[j] << " is missing";
  }
  // The importer welds vertices equal in position and normal (the source's copies differ
  // in UVs, which the export leaves out): every vertex of either skin has its match in
  // the other.
  const core::RawSkin& skin = level.character->skin();
  const double height = level.character->height();
  const double tolerance = 1e-6 * height;
  EXPECT_LE(raw.skin.positions.size(), skin.positions.size());
  EXPECT_EQ(raw.skin.triangles.size(), skin.triangles.size());
  std::vector<size_t> original_of(raw.skin.positions.size());
  for (size_t i = 0; i < raw.skin.positions.size(); ++i) {
    const int found = FindVertex(skin, raw.skin.positions[i], raw.skin.normals[i], tolerance);
    ASSERT_GE(found, 0) << "re-imported vertex " << i << " is no vertex of the skin";
    original_of[i] = static_cast<size_t>(found);
  }
  for (size_t i = 0; i < skin.positions.size(); i += 7) {
    EXPECT_GE(FindVertex(raw.skin, skin.positions[i], skin.normals[i], tolerance), 0)
        << "vertex " << i << " is missing from the export";
  }

  const core::Motion motion = *(*reimported)->SampleAnimation("", level.fps);
  ASSERT_EQ(motion.frame_count, level.frames);
  double max_difference = 0;
  for (int t = 0; t < level.frames; ++t) {
    const std::vector<Eigen::Vector3d> expected = LevelSkin(level, t);
    const std::vector<Eigen::Vector3d> actual = testing::SkinFrame(raw, motion, t);
    for (size_t i = 0; i < actual.size(); ++i) {
      max_difference = std::max(max_difference, (actual[i] - expected[original_of[i]]).norm());
    }
  }
  const double max_difference_pct = 100.0 * max_difference / height;
  // The export's own figure and the re-import agree up to float rounding of the keys.
  EXPECT_NEAR(max_difference_pct, stats.max_vertex_deviation_pct, 1e-3)
      << c.file << " " << c.kept << " joints, " << core::VariantName(c.variant);
  if (level.rigid && stats.truncated_vertices == 0) {
    EXPECT_LT(max_difference_pct, 1e-3);
  }

  // three.js (the web viewer's loader) poses the skin the same way at a key frame.
  const int t = level.frames / 2;
  const std::filesystem::path file = std::filesystem::temp_directory_path() /
                                     ("motionlod_gltf_" + std::to_string(::getpid()) + ".glb");
  std::ofstream(file, std::ios::binary) << exported->glb;
  const nlohmann::json pose = motionlod::testing::ThreePose(file, t / level.fps);
  std::filesystem::remove(file);
  ASSERT_TRUE(pose.is_object());
  EXPECT_EQ(pose["bones"], c.kept);
  EXPECT_EQ(pose["unbound"], 0) << "animation tracks three.js could not bind to a node";
  const std::vector<double> three = pose["positions"].get<std::vector<double>>();
  ASSERT_EQ(three.size(), 3 * skin.positions.size());
  const std::vector<Eigen::Vector3d> expected = LevelSkin(level, t);
  double max_three_difference = 0;
  for (size_t i = 0; i < expected.size(); ++i) {
    const Eigen::Vector3d v(three[3 * i], three[3 * i + 1], three[3 * i + 2]);
    max_three_difference = std::max(max_three_difference, (v - expected[i]).norm());
  }
  EXPECT_LE(100.0 * max_three_difference / height, stats.max_vertex_deviation_pct + 1e-3)
      << "three.js poses frame " << t << " away from the level";

  RecordProperty("max_vertex_deviation_pct", std::to_string(stats.max_vertex_deviation_pct));
  std::printf(
      "%s, %d joints, %s: deviation %.3g%% of the height, %d vertices truncated "
      "(dropped weight up to %.3g)\n",
      c.file, c.kept, core::VariantName(c.variant), stats.max_vertex_deviation_pct,
      stats.truncated_vertices, stats.max_dropped_weight);
}

INSTANTIATE_TEST_SUITE_P(
    RealCharacters, GltfExportRoundTrip,
    ::testing::Values(Case{"characters/CesiumMan.glb", 19, core::Variant::kVPNOPD},
                      Case{"characters/CesiumMan.glb", 8, core::Variant::kVPNOPD},
                      Case{"characters/Fox.glb", 10, core::Variant::kVPPD},
                      Case{"characters/Fox.glb", 10, core::Variant::kVP},
                      Case{"characters/Orc.gltf", 20, core::Variant::kVPNO},
                      Case{"characters/Rig_Medium_MovementBasic.glb", 12, core::Variant::kVPNOPD},
                      Case{"characters/RobotExpressive.glb", 43, core::Variant::kVPNOPD},
                      Case{"characters/RobotExpressive.glb", 20, core::Variant::kVP},
                      Case{"characters/stormtrooper.dae", 52, core::Variant::kVPPD},
                      Case{"characters/stormtrooper.dae", 25, core::Variant::kVPNOPD}));

// The hand-made creature of tests/core/fixtures.h keeping root, spine and arm_l, over two
// frames: the bind pose, then everything moved by +x 1 with the spine (and so the arm)
// turned 90 degrees about z around the spine joint (0, 1, 0).
TEST(GltfExport, WritesTheHandComputedPoseOfAReducedCreature) {
  const auto creature = *core::BuildCharacter(core::testing::MakeCreature());
  const std::vector<std::string_view> names(creature->skeleton().joint_names.begin(),
                                            creature->skeleton().joint_names.end());
  const std::vector<uint16_t> kept = {0, 1, 4};  // root, spine, arm_l
  //                                 root spine neck head arm_l hand_l arm_r hand_r
  const std::vector<uint16_t> map = {0, 1, 1, 1, 2, 2, 1, 1};
  const core::Affine34d shift = core::testing::Translation(1, 0, 0);
  const core::Affine34d turn = core::ComposeAffine(
      shift, core::testing::RotationAbout(Eigen::Vector3d::UnitZ(), M_PI / 2, {0, 1, 0}));
  std::vector<float> matrices;
  for (const core::Affine34d& k : {core::IdentityAffine(), core::IdentityAffine(),
                                   core::IdentityAffine(), shift, turn, turn}) {
    for (int row = 0; row < 3; ++row) {
      for (int col = 0; col < 4; ++col) matrices.push_back(static_cast<float>(k(row, col)));
    }
  }
  const GltfLevel level{.joint_names = names,
                        .kept_joints = kept,
                        .joint_map = map,
                        .matrices = matrices,
                        .frame_count = 2,
                        .fps = 10.0,
                        .rigid = true,
                        .animation_name = "turn"};
  auto exported = ExportLevelGlb(*creature, level);
  ASSERT_TRUE(exported.ok()) << exported.status().ToString();
  EXPECT_LT(exported->stats.max_vertex_deviation_pct, 1e-4);
  EXPECT_EQ(exported->stats.truncated_vertices, 0);

  auto reimported = LoadAsset({{"creature.glb", exported->glb}});
  ASSERT_TRUE(reimported.ok()) << reimported.status().ToString();
  const core::RawCharacter& raw = (*reimported)->character();
  ASSERT_EQ(raw.skeleton.joint_names.size(), 3u);
  const int root = testing::JointIndex(raw.skeleton, "root");
  const int spine = testing::JointIndex(raw.skeleton, "spine");
  const int arm = testing::JointIndex(raw.skeleton, "arm_l");
  ASSERT_TRUE(root >= 0 && spine >= 0 && arm >= 0);
  EXPECT_EQ(raw.skeleton.parents[spine], root);
  EXPECT_EQ(raw.skeleton.parents[arm], spine);
  // Rest: the bind positions (the creature's bind matrices are translations).
  EXPECT_TRUE(
      raw.skeleton.bind_world[arm].isApprox(core::testing::Translation(-0.5, 1.6, 0), 1e-6));

  auto motion = (*reimported)->SampleAnimation("turn", 10.0);
  ASSERT_TRUE(motion.ok()) << motion.status().ToString();
  ASSERT_EQ(motion->frame_count, 2);
  const Eigen::Matrix3d rz =
      Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  const auto world = [](const Eigen::Matrix3d& r, double x, double y) {
    core::Affine34d m;
    m.leftCols<3>() = r;
    m.col(3) << x, y, 0;
    return m;
  };
  EXPECT_TRUE(motion->world(0, arm).isApprox(world(Eigen::Matrix3d::Identity(), -0.5, 1.6), 1e-5));
  EXPECT_TRUE(motion->world(1, root).isApprox(world(Eigen::Matrix3d::Identity(), 1, 0), 1e-5));
  EXPECT_TRUE(motion->world(1, spine).isApprox(world(rz, 1, 1), 1e-5)) << motion->world(1, spine);
  // arm_l at (-0.5, 1.6): (-0.5, 0.6) from the pivot, turned to (-0.6, -0.5), plus the pivot
  // (0, 1) and the shift (1, 0).
  EXPECT_TRUE(motion->world(1, arm).isApprox(world(rz, 0.4, 0.5), 1e-5)) << motion->world(1, arm);
  // The head's skin follows the spine, its nearest kept ancestor, with weight 1.
  const core::RawSkin& skin = raw.skin;
  int head_vertices = 0;
  for (size_t i = 0; i < skin.positions.size(); ++i) {
    if (skin.positions[i].y() <= 2.05f) continue;
    ++head_vertices;
    ASSERT_EQ(skin.influence_offsets[i + 1] - skin.influence_offsets[i], 1u);
    EXPECT_EQ(skin.influence_joints[skin.influence_offsets[i]], spine);
  }
  EXPECT_GT(head_vertices, 0);
}

class GltfExportInput : public ::testing::Test {
 protected:
  void SetUp() override {
    if (!testing::HaveData()) GTEST_SKIP() << "no ../shared/data";
    level_ = Solve("characters/Fox.glb", 10, core::Variant::kVPNOPD, 4);
  }
  Status Export(const GltfLevel& view) const {
    return ExportLevelGlb(*level_.character, view).status();
  }
  SolvedLevel level_;
};

TEST_F(GltfExportInput, RejectsALevelOfAnotherSkeleton) {
  std::vector<std::string_view> names = level_.joint_names;
  names[3] = "not_a_joint";
  GltfLevel view = level_.View();
  view.joint_names = names;
  EXPECT_EQ(Export(view).code(), StatusCode::kInvalidArgument);
  view.joint_names = std::span(level_.joint_names).first(5);
  EXPECT_EQ(Export(view).code(), StatusCode::kInvalidArgument);
}

TEST_F(GltfExportInput, RejectsAJointMapThatIsNotTheNearestKeptAncestor) {
  // Point the first removed joint at a slot other than its nearest kept ancestor's.
  std::vector<uint16_t> map = level_.joint_map;
  size_t removed = 1;
  while (std::find(level_.kept_joints.begin(), level_.kept_joints.end(), removed) !=
         level_.kept_joints.end()) {
    ++removed;
  }
  ASSERT_LT(removed, map.size());
  map[removed] = map[removed] == 0 ? 1 : 0;
  GltfLevel view = level_.View();
  view.joint_map = map;
  const Status status = Export(view);
  EXPECT_EQ(status.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(status.message().find("nearest kept ancestor"), std::string::npos) << status.message();
}

TEST_F(GltfExportInput, RejectsBadShapesAndValues) {
  GltfLevel view = level_.View();
  view.matrices = std::span(level_.matrices).first(level_.matrices.size() - 12);
  EXPECT_EQ(Export(view).code(), StatusCode::kInvalidArgument);

  std::vector<float> nan = level_.matrices;
  nan[5] = std::numeric_limits<float>::quiet_NaN();
  view = level_.View();
  view.matrices = nan;
  EXPECT_EQ(Export(view).code(), StatusCode::kInvalidArgument);

  std::vector<float> singular = level_.matrices;
  std::fill(singular.begin(), singular.begin() + 12, 0.0f);
  view.matrices = singular;
  EXPECT_EQ(Export(view).code(), StatusCode::kInvalidArgument);

  view = level_.View();
  view.fps = 0;
  EXPECT_EQ(Export(view).code(), StatusCode::kInvalidArgument);

  std::vector<uint16_t> without_root(level_.kept_joints.begin() + 1, level_.kept_joints.end());
  view = level_.View();
  view.kept_joints = without_root;
  EXPECT_EQ(Export(view).code(), StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace motionlod::io
