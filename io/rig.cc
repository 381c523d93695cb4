#include "io/rig.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <set>
#include <utility>

#include "core/motion.h"
#include "io/proxy_skin.h"
#include "io/text.h"

namespace motionlod::io {
namespace {

using core::Affine34d;
using core::ComposeAffine;
using core::InverseAffine;

struct MeshInstance {
  int node;
  int mesh;
};

// Whether two affine maps move the points within `radius` of the origin alike, to 0.1%
// of the size they map that region to.
bool Agree(const Affine34d& a, const Affine34d& b, double radius) {
  const double distance =
      (a.leftCols<3>() - b.leftCols<3>()).norm() * radius + (a.col(3) - b.col(3)).norm();
  const double size = a.leftCols<3>().norm() / std::sqrt(3.0) * radius;
  return distance <= 1e-3 * std::max(size, 1e-12);
}

double MeshRadius(const SceneMesh& mesh) {
  double radius = 0;
  for (const Eigen::Vector3f& v : mesh.positions)
    radius = std::max(radius, static_cast<double>(v.norm()));
  return radius > 0 ? radius : 1.0;
}

int FindInSubtree(const std::vector<SceneNode>& nodes, int top, const std::string& name) {
  // Preorder: the subtree of `top` is the run of nodes after it that descend from it.
  std::vector<char> inside(nodes.size(), 0);
  inside[top] = 1;
  for (size_t k = top + 1; k < nodes.size(); ++k) {
    if (nodes[k].parent < 0 || !inside[nodes[k].parent]) break;
    inside[k] = 1;
    if (nodes[k].name == name) return static_cast<int>(k);
  }
  return -1;
}

}  // namespace

StatusOr<Rig> BuildRig(const Scene& scene, int max_influences, const std::string& name,
                       int max_joints) {
  const std::vector<SceneNode>& nodes = scene.nodes;
  const int node_count = static_cast<int>(nodes.size());
  if (node_count == 0) return InvalidArgument(Quote(name) + " has no nodes");
  Rig rig;
  rig.character.name = name;

  std::vector<MeshInstance> instances;
  bool skinned = false;
  for (int k = 0; k < node_count; ++k) {
    for (int m : nodes[k].meshes) {
      if (scene.meshes[m].synthetic) continue;
      instances.push_back({k, m});
      skinned = skinned || !scene.meshes[m].bones.empty();
    }
  }

  // --- Joint selection -----------------------------------------------------------------
  const NodeNames names(nodes);
  std::vector<char> selected(node_count, 0);
  std::map<std::pair<int, int>, int> bone_node;  // (instance, bone) -> node
  if (skinned) {
    for (size_t i = 0; i < instances.size(); ++i) {
      const SceneMesh& mesh = scene.meshes[instances[i].mesh];
      for (size_t b = 0; b < mesh.bones.size(); ++b) {
        const int node = names.Find(mesh.bones[b].name);
        if (node < 0) {
          return DataLoss("bone '" + mesh.bones[b].name + "' of mesh '" + mesh.name +
                          "' names no node of the file");
        }
        selected[node] = 1;
        bone_node[{static_cast<int>(i), static_cast<int>(b)}] = node;
      }
    }
  } else {
    for (const SceneAnimation& animation : scene.animations) {
      for (const SceneChannel& channel : animation.channels) {
        int node = names.Find(channel.node_name);
        if (node < 0) continue;
        if (IsFbxHelperName(channel.node_name)) {
          node = FindInSubtree(nodes, node, FbxHelperOwner(channel.node_name));
          if (node < 0) continue;
        }
        if (!nodes[node].is_null) selected[node] = 1;
      }
    }
  }
  std::vector<int> depth(node_count, 0);
  for (int k = 1; k < node_count; ++k)
    depth[k] = nodes[k].parent >= 0 ? depth[nodes[k].parent] + 1 : 0;
  int root = -1;
  for (int k = 0; k < node_count; ++k) {
    if (!selected[k]) continue;
    if (root < 0) {
      root = k;
      continue;
    }
    int a = root, b = k;
    while (depth[a] > depth[b]) a = nodes[a].parent;
    while (depth[b] > depth[a]) b = nodes[b].parent;
    while (a != b) {
      a = nodes[a].parent;
      b = nodes[b].parent;
    }
    root = a;
  }
  if (root < 0) {
    return InvalidArgument(Quote(name) +
                           " has no skeleton: no mesh is skinned and no node is animated");
  }
  while (IsFbxHelperName(nodes[root].name) && nodes[root].parent >= 0) root = nodes[root].parent;
  std::vector<char> is_joint(node_count, 0);
  is_joint[root] = 1;
  for (int k = 0; k < node_count; ++k) {
    if (!selected[k]) continue;
    for (int q = k; q >= 0 && q != root; q = nodes[q].parent) {
      if (!IsFbxHelperName(nodes[q].name)) is_joint[q] = 1;
    }
  }
  const auto joint_count = std::count(is_joint.begin(), is_joint.end(), 1);
  if (joint_count > max_joints) {
    return InvalidArgument(Quote(name) + " has " + std::to_string(joint_count) +
                           " joints, more than the limit of " + std::to_string(max_joints) +
                           " (max_joints)");
  }
  std::vector<int> joint_of_node(node_count, -1);
  core::RawSkeleton& skeleton = rig.character.skeleton;
  std::set<std::string> used_names;
  for (int k = 0; k < node_count; ++k) {
    if (!is_joint[k]) continue;
    joint_of_node[k] = static_cast<int>(rig.joint_nodes.size());
    rig.joint_nodes.push_back(k);
    int parent = -1;
    for (int q = nodes[k].parent; q >= 0 && k != root; q = nodes[q].parent) {
      if (joint_of_node[q] >= 0) {
        parent = joint_of_node[q];
        break;
      }
    }
    skeleton.parents.push_back(parent);
    std::string joint_name = nodes[k].name.empty() ? "joint_" + std::to_string(k) : nodes[k].name;
    if (used_names.count(joint_name) != 0) {
      std::string unique = joint_name;
      for (int c = 2; used_names.count(unique) != 0; ++c)
        unique = joint_name + "." + std::to_string(c);
      rig.warnings.push_back("two joints are named '" + joint_name + "'; the later one is '" +
                             unique + "'");
      joint_name = unique;
    }
    used_names.insert(joint_name);
    skeleton.joint_names.push_back(joint_name);
  }
  const int n = static_cast<int>(rig.joint_nodes.size());

  // --- Rest world matrices and bind pose -------------------------------------------------
  std::vector<Affine34d> rest_world(node_count);
  for (int k = 0; k < node_count; ++k) {
    rest_world[k] = nodes[k].parent >= 0
                        ? ComposeAffine(rest_world[nodes[k].parent], nodes[k].local)
                        : nodes[k].local;
  }
  skeleton.bind_world.assign(n, Affine34d::Zero());
  std::vector<char> has_bind(n, 0);
  std::vector<Affine34d> mesh_to_model(instances.size(), core::IdentityAffine());
  for (size_t i = 0; i < instances.size(); ++i) {
    const SceneMesh& mesh = scene.meshes[instances[i].mesh];
    if (mesh.bones.empty()) continue;
    const double radius = MeshRadius(mesh);
    const size_t bone_count = mesh.bones.size();
    std::vector<int> joint(bone_count);
    std::vector<int> weight(bone_count);
    for (size_t b = 0; b < bone_count; ++b) {
      const SceneBone& bone = mesh.bones[b];
      if (!core::IsInvertibleAffine(bone.offset)) {
        return InvalidArgument("bone '" + bone.name + "' of mesh '" + mesh.name +
                               "' has a singular offset matrix");
      }
      joint[b] = joint_of_node[bone_node.at({static_cast<int>(i), static_cast<int>(b)})];
      weight[b] = 1;
      for (const auto& vw : bone.weights) weight[b] += vw.second > 0;
    }
    int known = -1;
    for (size_t b = 0; b < bone_count; ++b) {
      if (has_bind[joint[b]] && (known < 0 || weight[b] > weight[known]))
        known = static_cast<int>(b);
    }
    Affine34d d;
    if (known >= 0) {
      d = ComposeAffine(skeleton.bind_world[joint[known]], mesh.bones[known].offset);
    } else {
      // C_b = W_b(rest) O_b is the rest-to-bind change of bone b. Bones below a limb that
      // rests in another pose than its bind pose share one C_b, so a majority vote can pick
      // a posed arm; the shallowest bone's C_b places the whole bind pose instead.
      size_t top = 0;
      for (size_t b = 1; b < bone_count; ++b) {
        if (depth[rig.joint_nodes[joint[b]]] < depth[rig.joint_nodes[joint[top]]]) top = b;
      }
      d = ComposeAffine(rest_world[rig.joint_nodes[joint[top]]], mesh.bones[top].offset);
    }
    if (!core::IsInvertibleAffine(d)) {
      return InvalidArgument("mesh '" + mesh.name + "' has a singular bind transform");
    }
    int disagree = 0;
    for (size_t b = 0; b < bone_count; ++b) {
      if (has_bind[joint[b]]) {
        disagree +=
            !Agree(ComposeAffine(skeleton.bind_world[joint[b]], mesh.bones[b].offset), d, radius);
      } else {
        skeleton.bind_world[joint[b]] = ComposeAffine(d, InverseAffine(mesh.bones[b].offset));
        has_bind[joint[b]] = 1;
      }
    }
    if (disagree > 0) {
      rig.warnings.push_back(
          "mesh '" + mesh.name + "' binds " + std::to_string(disagree) +
          " bones differently from an earlier mesh; the earlier bind pose is kept");
    }
    mesh_to_model[i] = d;
  }
  for (int j = 0; j < n; ++j) {
    if (!has_bind[j]) skeleton.bind_world[j] = rest_world[rig.joint_nodes[j]];
    if (!core::IsInvertibleAffine(skeleton.bind_world[j])) {
      return InvalidArgument("joint '" + skeleton.joint_names[j] + "' has a singular bind matrix");
    }
  }

  // --- Skin --------------------------------------------------------------------------------
  core::RawSkin& skin = rig.character.skin;
  skin.influence_offsets.assign(1, 0);
  auto nearest_joint = [&](int node) {
    for (int q = node; q >= 0; q = nodes[q].parent) {
      if (joint_of_node[q] >= 0) return joint_of_node[q];
    }
    return 0;
  };
  int unweighted = 0, bad_normals = 0, negative_weights = 0;
  for (size_t i = 0; i < instances.size(); ++i) {
    const SceneMesh& mesh = scene.meshes[instances[i].mesh];
    if (mesh.triangles.empty()) {
      rig.warnings.push_back("mesh '" + mesh.name + "' has no triangles; skipped");
      continue;
    }
    const int node_joint = nearest_joint(instances[i].node);
    Affine34d to_model = mesh_to_model[i];
    if (mesh.bones.empty()) {
      to_model =
          ComposeAffine(ComposeAffine(skeleton.bind_world[node_joint],
                                      InverseAffine(rest_world[rig.joint_nodes[node_joint]])),
                        rest_world[instances[i].node]);
    }
    if (!core::IsInvertibleAffine(to_model)) {
      return InvalidArgument("mesh '" + mesh.name + "' is placed by a singular transform");
    }
    const Eigen::Matrix3d normal_matrix = to_model.leftCols<3>().inverse().transpose();
    const size_t base = skin.positions.size();
    if (base + mesh.positions.size() > 0x7fffffff) return InvalidArgument("too many vertices");
    Eigen::Vector3d centre = Eigen::Vector3d::Zero();
    for (const Eigen::Vector3f& v : mesh.positions) {
      const Eigen::Vector3d p = core::TransformPoint(to_model, Eigen::Vector3d(v.cast<double>()));
      if (!p.allFinite())
        return InvalidArgument("mesh '" + mesh.name + "' has a vertex out of range");
      skin.positions.push_back(p.cast<float>());
      centre += p;
    }
    centre /= std::max<size_t>(1, mesh.positions.size());
    for (size_t v = 0; v < mesh.positions.size(); ++v) {
      Eigen::Vector3d normal = Eigen::Vector3d::Zero();
      if (!mesh.normals.empty()) normal = normal_matrix * mesh.normals[v].cast<double>();
      if (!(normal.norm() > 1e-12) || !normal.allFinite()) {
        ++bad_normals;
        normal = skin.positions[base + v].cast<double>() - centre;
        if (!(normal.norm() > 1e-12)) normal = Eigen::Vector3d::UnitY();
      }
      skin.normals.push_back(normal.normalized().cast<float>());
    }
    for (const auto& t : mesh.triangles) {
      skin.triangles.push_back({static_cast<uint32_t>(base + t[0]),
                                static_cast<uint32_t>(base + t[1]),
                                static_cast<uint32_t>(base + t[2])});
    }
    std::vector<std::vector<std::pair<int, float>>> influences(mesh.positions.size());
    if (mesh.bones.empty()) {
      for (auto& list : influences) list.emplace_back(node_joint, 1.0f);
    } else {
      for (size_t b = 0; b < mesh.bones.size(); ++b) {
        const int j = joint_of_node[bone_node.at({static_cast<int>(i), static_cast<int>(b)})];
        for (const auto& [vertex, w] : mesh.bones[b].weights) {
          if (w > 0) {
            influences[vertex].emplace_back(j, w);
          } else if (w < 0) {
            ++negative_weights;
          }
        }
      }
    }
    for (auto& list : influences) {
      std::sort(list.begin(), list.end());
      std::vector<std::pair<int, float>> merged;
      for (const auto& [j, w] : list) {
        if (!merged.empty() && merged.back().first == j) {
          merged.back().second += w;
        } else {
          merged.emplace_back(j, w);
        }
      }
      std::stable_sort(merged.begin(), merged.end(),
                       [](const auto& a, const auto& b) { return a.second > b.second; });
      if (merged.size() > static_cast<size_t>(max_influences)) merged.resize(max_influences);
      double sum = 0;
      for (const auto& e : merged) sum += e.second;
      if (!(sum > 0)) {
        ++unweighted;
        merged.assign(1, {node_joint, 1.0f});
        sum = 1;
      }
      for (const auto& [j, w] : merged) {
        skin.influence_joints.push_back(j);
        skin.influence_weights.push_back(static_cast<float>(w / sum));
      }
      skin.influence_offsets.push_back(static_cast<uint32_t>(skin.influence_joints.size()));
    }
  }
  if (unweighted > 0) {
    rig.warnings.push_back(std::to_string(unweighted) +
                           " vertices of skinned meshes had no weight; each was bound to the joint "
                           "of its mesh's node");
  }
  if (negative_weights > 0) {
    rig.warnings.push_back(std::to_string(negative_weights) + " negative weights were dropped");
  }
  if (bad_normals > 0) {
    rig.warnings.push_back(
        std::to_string(bad_normals) +
        " vertices had no usable normal; they point away from their mesh's centre");
  }
  if (skin.positions.empty()) {
    StatusOr<core::RawSkin> proxy = MakeProxySkin(skeleton);
    if (!proxy.ok()) return proxy.status();
    skin = std::move(proxy).value();
    rig.proxy_skin = true;
  }
  return rig;
}

}  // namespace motionlod::io
