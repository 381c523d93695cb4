#include "io/scene.h"

#include <Eigen/SVD>
#include <cmath>

namespace motionlod::io {

void DecomposeLocal(SceneNode& node) {
  const Eigen::Matrix3d a = node.local.leftCols<3>();
  node.translation = node.local.col(3);
  Eigen::Vector3d scale(a.col(0).norm(), a.col(1).norm(), a.col(2).norm());
  if (a.determinant() < 0) scale.x() = -scale.x();
  Eigen::Matrix3d r = a;
  for (int c = 0; c < 3; ++c) {
    if (scale[c] != 0) r.col(c) /= scale[c];
  }
  // Project onto the nearest rotation: columns are orthonormal only without shear.
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(r, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d rotation = svd.matrixU() * svd.matrixV().transpose();
  if (rotation.determinant() < 0) {
    Eigen::Matrix3d u = svd.matrixU();
    u.col(2) = -u.col(2);
    rotation = u * svd.matrixV().transpose();
  }
  node.rotation = Eigen::Quaterniond(rotation).normalized();
  node.scale = scale;
}

}  // namespace motionlod::io

namespace motionlod::io {

namespace {
constexpr const char kFbxHelperTag[] = "_$AssimpFbx$_";
}  // namespace

NodeNames::NodeNames(const std::vector<SceneNode>& nodes) : nodes_(&nodes) {
  for (size_t i = 0; i < nodes.size(); ++i) by_name_[nodes[i].name].push_back(static_cast<int>(i));
}

int NodeNames::Find(const std::string& name, const std::vector<char>* preferred) const {
  const auto it = by_name_.find(name);
  if (it == by_name_.end()) return -1;
  const std::vector<int>& candidates = it->second;
  if (candidates.size() == 1) return candidates.front();
  if (preferred != nullptr) {
    for (int c : candidates) {
      if ((*preferred)[c]) return c;
    }
  }
  for (int c : candidates) {
    if ((*nodes_)[c].meshes.empty()) return c;
  }
  return candidates.front();
}

bool IsFbxHelperName(const std::string& name) {
  return name.find(kFbxHelperTag) != std::string::npos;
}

std::string FbxHelperOwner(const std::string& name) {
  const size_t at = name.find(kFbxHelperTag);
  return at == std::string::npos ? name : name.substr(0, at);
}

}  // namespace motionlod::io
