// Scene -> skeleton and skin (core::RawCharacter). Internal to io.
//
// Joint selection.
//  * A file with skinned meshes: the joints are the nodes that are bones of a mesh, plus
//    the nodes on the paths joining them to their lowest common ancestor, which becomes
//    the root (so the joints always form one tree; FBX pivot helper nodes are never
//    joints). A bone name shared by several nodes binds to one without meshes.
//  * Otherwise (BVH, skeleton-only FBX, rigidly animated files): the nodes animated by
//    some clip, except FBX Null nodes (armatures), with FBX pivot helpers replaced by the
//    joint they belong to; then joined up the same way. BVH End Sites and FBX "_end"
//    leaves carry no keys and are not joints.
//  Joints are in node preorder, so parents come first and joint 0 is the root.
//
// Bind pose. For the first skinned mesh, C = W_b(rest) O_b of its shallowest bone b (W
// the node's rest world matrix, O the bone offset) maps mesh space to model space, and
// the mesh's vertices become C v; then M0_b = C O_b^-1 for all its bones, which equals
// W_b(rest) wherever the rest pose is the bind pose (a Z-up export under a Y-up root, or a
// COLLADA bind-shape matrix, so stays upright and consistent). A later mesh sharing
// bones uses D = M0_k O_k of its best-weighted known bone k, so that all meshes agree on
// M0 (disagreements are reported). Joints that are no bone get M0_j = W_j(rest).
// A rigid mesh at node N under joint k (its nearest joint ancestor, or the root) gets
// vertices M0_k W_k(rest)^-1 W_N(rest) v, all weighted 1 to k.
//
// Weights: per vertex, zero weights dropped, duplicates merged, the largest
// `max_influences` kept and renormalised. A vertex of a skinned mesh without any weight
// is bound rigidly to the joint of its mesh's node (nearest joint ancestor, else the
// root), and the count is reported in warnings. Normals: the file's (Assimp
// generates smooth normals when absent), transformed by the inverse transpose and
// normalised; a degenerate normal is replaced by the direction from the mesh centre.
#pragma once

#include <limits>
#include <string>
#include <vector>

#include "base/status.h"
#include "core/character.h"
#include "io/scene.h"

namespace motionlod::io {

struct Rig {
  core::RawCharacter character;
  bool proxy_skin = false;
  std::vector<int> joint_nodes;  // n: the scene node of each joint
  std::vector<std::string> warnings;
};

// Errors: InvalidArgument when the scene has no skeleton (no bone and no animated node)
// or a bone offset is singular.
// More than `max_joints` joints is InvalidArgument, found before any proxy skin is made.
StatusOr<Rig> BuildRig(const Scene& scene, int max_influences, const std::string& name,
                       int max_joints = std::numeric_limits<int>::max());

}  // namespace motionlod::io
