// Scene: the plain-data image of an imported file (node tree, meshes, bones, animation
// channels), copied out of Assimp so that everything after the import is Assimp-free
// and can be tested on hand-made scenes. Internal to io.
//
// Conventions: matrices are affine 3x4 (core::Affine34d), column vectors, world =
// parent_world * local. Mesh data is in the space of the mesh (Assimp's convention:
// a bone offset O maps mesh space to the bone's space in the bind pose).
#pragma once

#include <Eigen/Geometry>
#include <array>
#include <cstdint>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include "core/types.h"
#include "io/format.h"

namespace motionlod::io {

struct SceneNode {
  std::string name;
  int parent = -1;  // index into Scene::nodes; nodes are in preorder, so parent < own index
  core::Affine34d local = core::IdentityAffine();  // rest local transform
  // local = T * R * S (exact unless the node shears).
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();
  Eigen::Quaterniond rotation = Eigen::Quaterniond::Identity();
  Eigen::Vector3d scale = Eigen::Vector3d::Ones();
  bool is_null = false;     // an FBX "Null" (armature or locator), never a limb
  std::vector<int> meshes;  // indices into Scene::meshes drawn at this node
};

struct SceneBone {
  std::string name;                                 // the name of the joint's node
  core::Affine34d offset = core::IdentityAffine();  // O: mesh space -> bone space (bind pose)
  std::vector<std::pair<uint32_t, float>> weights;  // (vertex, weight)
};

struct SceneMesh {
  std::string name;
  bool synthetic = false;  // a stick figure the importer made for a skeleton-only file
  std::vector<Eigen::Vector3f> positions;  // mesh space
  std::vector<Eigen::Vector3f> normals;    // empty or one per position
  std::vector<std::array<uint32_t, 3>> triangles;
  std::vector<SceneBone> bones;
};

// Keys of one node, times ascending. Any of the three lists may be empty (the node's
// rest value is used then). Rotations are unit quaternions.
struct NodeKeys {
  std::vector<double> position_times;
  std::vector<Eigen::Vector3d> positions;
  std::vector<double> rotation_times;
  std::vector<Eigen::Quaterniond> rotations;
  std::vector<double> scaling_times;
  std::vector<Eigen::Vector3d> scalings;
};

// A node's keys as the file gives them: times in ticks.
struct SceneChannel : NodeKeys {
  std::string node_name;
};

struct SceneAnimation {
  std::string name;
  double duration_ticks = 0;
  double ticks_per_second = 0;  // 0: not given by the file
  std::vector<SceneChannel> channels;
};

struct Scene {
  Format format = Format::kGltf;
  std::vector<SceneNode> nodes;  // preorder; nodes[0] is the root
  std::vector<SceneMesh> meshes;
  std::vector<SceneAnimation> animations;
  std::vector<std::string> warnings;
};

// Fills translation/rotation/scale of `node` from node.local.
void DecomposeLocal(SceneNode& node);

// T * R * S as an affine matrix. Inline: the sampler (io/clips.cc) calls it for every
// animated node of every frame.
inline core::Affine34d ComposeTrs(const Eigen::Vector3d& translation,
                                  const Eigen::Quaterniond& rotation,
                                  const Eigen::Vector3d& scale) {
  core::Affine34d m;
  m.leftCols<3>() = rotation.toRotationMatrix() * scale.asDiagonal();
  m.col(3) = translation;
  return m;
}

}  // namespace motionlod::io

namespace motionlod::io {

// Node lookup by name. Names need not be unique (glTF mesh nodes often share their
// joint's name): among several nodes of one name, Find prefers one whose entry in
// `preferred` is non-zero, then one without meshes, then the first in preorder.
class NodeNames {
 public:
  explicit NodeNames(const std::vector<SceneNode>& nodes);
  // -1 when no node has that name.
  int Find(const std::string& name, const std::vector<char>* preferred = nullptr) const;

 private:
  const std::vector<SceneNode>* nodes_;
  std::unordered_map<std::string, std::vector<int>> by_name_;
};

// Assimp's FBX importer splits a node with pivots into helper nodes named
// "<joint>_$AssimpFbx$_<Part>" above the joint itself.
bool IsFbxHelperName(const std::string& name);
// "<joint>" of a helper name; the name itself otherwise.
std::string FbxHelperOwner(const std::string& name);

}  // namespace motionlod::io
