#include "io/rig.h"

#include <gtest/gtest.h>

#include "core/character.h"

namespace motionlod::io {
namespace {

using Eigen::Vector3d;
using Eigen::Vector3f;

int AddNode(Scene& scene, const std::string& name, int parent,
            const Vector3d& translation = Vector3d::Zero()) {
  SceneNode node;
  node.name = name;
  node.parent = parent;
  node.local = core::IdentityAffine();
  node.local.col(3) = translation;
  DecomposeLocal(node);
  scene.nodes.push_back(node);
  return static_cast<int>(scene.nodes.size()) - 1;
}

// A one-triangle mesh at node `node`.
SceneMesh& AddMesh(Scene& scene, int node, const std::string& name) {
  SceneMesh mesh;
  mesh.name = name;
  mesh.positions = {Vector3f(0, 0, 0), Vector3f(1, 0, 0), Vector3f(0, 1, 0)};
  mesh.normals = {Vector3f::UnitZ(), Vector3f::UnitZ(), Vector3f::UnitZ()};
  mesh.triangles = {{0, 1, 2}};
  scene.meshes.push_back(mesh);
  scene.nodes[node].meshes.push_back(static_cast<int>(scene.meshes.size()) - 1);
  return scene.meshes.back();
}

// Bone whose offset is the inverse of the node's rest world translation.
SceneBone Bone(const std::string& name, const Vector3d& world_translation,
               std::vector<std::pair<uint32_t, float>> weights) {
  SceneBone bone;
  bone.name = name;
  bone.offset = core::IdentityAffine();
  bone.offset.col(3) = -world_translation;
  bone.weights = std::move(weights);
  return bone;
}

TEST(BuildRig, JoinsBonesThroughTheNodesBetweenThem) {
  Scene scene;
  const int top = AddNode(scene, "Scene", -1);
  const int armature = AddNode(scene, "Armature", top);
  const int hips = AddNode(scene, "Hips", armature, Vector3d(0, 1, 0));
  const int spine = AddNode(scene, "Spine", hips, Vector3d(0, 0.5, 0));  // no bone
  AddNode(scene, "Head", spine, Vector3d(0, 0.5, 0));
  AddNode(scene, "Leg", hips, Vector3d(0, -0.5, 0));
  SceneMesh& mesh = AddMesh(scene, top, "body");
  mesh.bones = {Bone("Hips", Vector3d(0, 1, 0), {{0, 1.0f}}),
                Bone("Head", Vector3d(0, 2, 0), {{1, 1.0f}}),
                Bone("Leg", Vector3d(0, 0.5, 0), {{2, 1.0f}})};
  const StatusOr<Rig> rig = BuildRig(scene, 8, "test");
  ASSERT_TRUE(rig.ok()) << rig.status().ToString();
  const core::RawSkeleton& s = rig->character.skeleton;
  EXPECT_EQ(s.joint_names, (std::vector<std::string>{"Hips", "Spine", "Head", "Leg"}));
  EXPECT_EQ(s.parents, (std::vector<int>{-1, 0, 1, 0}));
  EXPECT_TRUE(s.bind_world[2].col(3).isApprox(Vector3d(0, 2, 0)));
  EXPECT_TRUE(s.bind_world[1].col(3).isApprox(Vector3d(0, 1.5, 0)));  // rest world of the connector
  EXPECT_FALSE(rig->proxy_skin);
  EXPECT_TRUE(core::ValidateRawCharacter(rig->character).ok());
}

TEST(BuildRig, SeveralBoneRootsMeetAtTheirCommonAncestor) {
  Scene scene;
  const int top = AddNode(scene, "Scene", -1);
  const int armature = AddNode(scene, "Armature", top);
  const int x = AddNode(scene, "X", armature);  // nodes in preorder, as Scene requires
  AddNode(scene, "A", x, Vector3d(1, 0, 0));
  const int y = AddNode(scene, "Y", armature);
  AddNode(scene, "B", y, Vector3d(-1, 0, 0));
  SceneMesh& mesh = AddMesh(scene, top, "body");
  mesh.bones = {Bone("A", Vector3d(1, 0, 0), {{0, 1.0f}, {1, 1.0f}}),
                Bone("B", Vector3d(-1, 0, 0), {{2, 1.0f}})};
  const StatusOr<Rig> rig = BuildRig(scene, 8, "test");
  ASSERT_TRUE(rig.ok()) << rig.status().ToString();
  EXPECT_EQ(rig->character.skeleton.joint_names,
            (std::vector<std::string>{"Armature", "X", "A", "Y", "B"}));
  EXPECT_EQ(rig->character.skeleton.parents, (std::vector<int>{-1, 0, 1, 0, 3}));
}

TEST(BuildRig, MotionOnlySceneUsesAnimatedNodesWithoutNullsAndHelpers) {
  Scene scene;
  scene.format = Format::kFbx;
  const int top = AddNode(scene, "RootNode", -1);
  const int armature = AddNode(scene, "Take", top);
  scene.nodes[armature].is_null = true;
  const int helper = AddNode(scene, "Hips_$AssimpFbx$_Translation", armature, Vector3d(0, 1, 0));
  const int hips = AddNode(scene, "Hips", helper);
  const int leg = AddNode(scene, "Leg", hips, Vector3d(0, -0.5, 0));
  AddNode(scene, "Leg_end", leg, Vector3d(0, -0.5, 0));
  SceneAnimation animation;
  animation.name = "walk";
  animation.ticks_per_second = 30;
  for (const char* name : {"Take", "Hips_$AssimpFbx$_Translation", "Leg"}) {
    SceneChannel channel;
    channel.node_name = name;
    channel.position_times = {0};
    channel.positions = {Vector3d::Zero()};
    animation.channels.push_back(channel);
  }
  scene.animations.push_back(animation);
  const StatusOr<Rig> rig = BuildRig(scene, 8, "walk.fbx");
  ASSERT_TRUE(rig.ok()) << rig.status().ToString();
  EXPECT_EQ(rig->character.skeleton.joint_names, (std::vector<std::string>{"Hips", "Leg"}));
  EXPECT_TRUE(rig->proxy_skin);
  EXPECT_TRUE(core::ValidateRawCharacter(rig->character).ok());
}

TEST(BuildRig, RigidMeshFollowsItsJointWithWeightOne) {
  Scene scene;
  const int top = AddNode(scene, "Scene", -1);
  const int hips = AddNode(scene, "Hips", top, Vector3d(0, 1, 0));
  const int head = AddNode(scene, "Head", hips, Vector3d(0, 1, 0));
  const int helmet =
      AddNode(scene, "Helmet", head, Vector3d(0, 0.25, 0));  // mesh node under a joint
  SceneMesh& skinned = AddMesh(scene, top, "body");
  skinned.bones = {Bone("Hips", Vector3d(0, 1, 0), {{0, 1.0f}, {1, 1.0f}, {2, 1.0f}}),
                   Bone("Head", Vector3d(0, 2, 0), {})};
  AddMesh(scene, helmet, "helmet");
  const StatusOr<Rig> rig = BuildRig(scene, 8, "test");
  ASSERT_TRUE(rig.ok()) << rig.status().ToString();
  const core::RawSkin& skin = rig->character.skin;
  ASSERT_EQ(skin.positions.size(), 6u);
  for (size_t i = 3; i < 6; ++i) {
    ASSERT_EQ(skin.influence_offsets[i + 1] - skin.influence_offsets[i], 1u);
    EXPECT_EQ(skin.influence_joints[skin.influence_offsets[i]], 1);  // Head
    EXPECT_EQ(skin.influence_weights[skin.influence_offsets[i]], 1.0f);
  }
  // The helmet's vertices are placed by its node's world transform (0, 2.25, 0).
  EXPECT_TRUE(skin.positions[3].isApprox(Vector3f(0, 2.25f, 0)));
}

TEST(BuildRig, WeightsAreMergedTruncatedAndRenormalised) {
  Scene scene;
  const int top = AddNode(scene, "Scene", -1);
  const int root = AddNode(scene, "J0", top);
  std::vector<SceneBone> bones;
  for (int j = 0; j < 10; ++j) {
    const std::string name = std::string("J").append(std::to_string(j));
    if (j > 0) AddNode(scene, name, root, Vector3d(j, 0, 0));
    // Vertex 0: ten influences, weights 1..10. Vertex 1: half-sum weights.
    std::vector<std::pair<uint32_t, float>> weights = {{0, static_cast<float>(j + 1)}};
    if (j < 2) weights.push_back({1, 0.2f});
    bones.push_back(Bone(name, Vector3d(j, 0, 0), weights));
  }
  bones.push_back(Bone("J1", Vector3d(1, 0, 0), {{1, 0.2f}}));  // a duplicate bone: merged
  SceneMesh& mesh = AddMesh(scene, top, "body");
  mesh.bones = bones;
  const StatusOr<Rig> rig = BuildRig(scene, 8, "test");
  ASSERT_TRUE(rig.ok()) << rig.status().ToString();
  const core::RawSkin& skin = rig->character.skin;
  EXPECT_EQ(skin.influence_offsets[1] - skin.influence_offsets[0], 8u);
  float sum = 0;
  for (uint32_t e = skin.influence_offsets[0]; e < skin.influence_offsets[1]; ++e)
    sum += skin.influence_weights[e];
  EXPECT_NEAR(sum, 1.0f, 1e-6);
  EXPECT_EQ(skin.influence_joints[skin.influence_offsets[0]], 9);  // the largest first
  // Vertex 1: J0 0.2, J1 0.2 + 0.2 -> 1/3, 2/3.
  ASSERT_EQ(skin.influence_offsets[2] - skin.influence_offsets[1], 2u);
  EXPECT_NEAR(skin.influence_weights[skin.influence_offsets[1]], 2.0f / 3, 1e-6);
  // Vertex 2 has no weight: bound to the joint of the mesh's node (none: the root).
  ASSERT_EQ(skin.influence_offsets[3] - skin.influence_offsets[2], 1u);
  EXPECT_EQ(skin.influence_joints[skin.influence_offsets[2]], 0);
  EXPECT_FALSE(rig->warnings.empty());
  EXPECT_TRUE(core::ValidateRawCharacter(rig->character).ok());
}

TEST(BuildRig, ConsensusBindPlacesTheMeshWhereTheRestPoseIs) {
  // The mesh's bind space is rotated 90 degrees about x against the world (as in a Z-up
  // export under a Y-up root): offsets include that rotation, the consensus C undoes it.
  Scene scene;
  const int top = AddNode(scene, "Scene", -1);
  const Eigen::Matrix3d rot = Eigen::AngleAxisd(EIGEN_PI / 2, Vector3d::UnitX()).toRotationMatrix();
  scene.nodes[top].local.leftCols<3>() = rot;
  DecomposeLocal(scene.nodes[top]);
  const int a = AddNode(scene, "A", top, Vector3d(0, 0, 1));
  AddNode(scene, "B", a, Vector3d(0, 0, 1));
  SceneMesh& mesh = AddMesh(scene, top, "body");
  // Offsets map mesh space to bone space: inverse of the bone's world *without* the
  // root rotation (the file's bind pose lives in mesh space).
  mesh.bones = {Bone("A", Vector3d(0, 0, 1), {{0, 1.0f}, {1, 1.0f}}),
                Bone("B", Vector3d(0, 0, 2), {{2, 1.0f}})};
  const StatusOr<Rig> rig = BuildRig(scene, 8, "test");
  ASSERT_TRUE(rig.ok()) << rig.status().ToString();
  const core::RawSkeleton& s = rig->character.skeleton;
  // M0 equals the rest world (with the rotation), and the vertices are rotated alike.
  EXPECT_TRUE(s.bind_world[1].isApprox(
      core::ComposeAffine(core::ComposeAffine(scene.nodes[top].local, scene.nodes[a].local),
                          scene.nodes[2].local),
      1e-12));
  EXPECT_TRUE(
      rig->character.skin.positions[2].cast<double>().isApprox(rot * Vector3d(0, 1, 0), 1e-6));
}

TEST(BuildRig, SceneWithoutBonesOrAnimationHasNoSkeleton) {
  Scene scene;
  const int top = AddNode(scene, "Scene", -1);
  AddMesh(scene, top, "static");
  const StatusOr<Rig> rig = BuildRig(scene, 8, "static.glb");
  ASSERT_FALSE(rig.ok());
  EXPECT_EQ(rig.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(rig.status().message().find("no skeleton"), std::string::npos);
}

TEST(BuildRig, SingularBoneOffsetIsAnError) {
  Scene scene;
  const int top = AddNode(scene, "Scene", -1);
  AddNode(scene, "A", top);
  SceneMesh& mesh = AddMesh(scene, top, "body");
  mesh.bones = {Bone("A", Vector3d::Zero(), {{0, 1.0f}})};
  mesh.bones[0].offset.setZero();
  const StatusOr<Rig> rig = BuildRig(scene, 8, "test");
  EXPECT_EQ(rig.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(rig.status().message().find("singular"), std::string::npos);
}

}  // namespace
}  // namespace motionlod::io
