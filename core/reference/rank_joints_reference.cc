#include "core/reference/rank_joints_reference.h"

#include <algorithm>
#include <limits>
#include <numeric>
#include <vector>

#include <Eigen/Geometry>

namespace motionlod::core {
namespace {

// The local transform L = M_parent^-1 M as a rotation (columns normalised: local matrices
// may carry scale) and a translation.
void Local(const Affine34d& world, const Affine34d* parent, Eigen::Quaterniond& rotation,
           Vec3d& translation) {
  const Affine34d local = parent ? ComposeAffine(InverseAffine(*parent), world) : world;
  Eigen::Matrix3d r = local.leftCols<3>();
  for (int c = 0; c < 3; ++c) {
    if (r.col(c).norm() > 0) r.col(c).normalize();
  }
  rotation = Eigen::Quaterniond(r).normalized();
  translation = local.col(3);
}

}  // namespace

JointRanking RankJointsReference(const Character& character, const Motion& motion,
                                 std::span<const std::string> locked_joints) {
  const RawSkeleton& s = character.skeleton();
  const int n = character.joint_count(), frames = motion.frame_count;
  JointRanking ranking;
  ranking.hierarchical = character.subtree_lengths();
  ranking.rotational.assign(n, 0.0);
  ranking.priority.assign(n, 0.0);
  for (int j = 0; j < n; ++j) {
    const int parent = s.parents[j];
    Eigen::Quaterniond bind_rotation;
    Vec3d bind_translation;
    Local(s.bind_world[j], parent < 0 ? nullptr : &s.bind_world[parent], bind_rotation,
          bind_translation);
    std::vector<Eigen::Quaterniond> rotations(frames);
    std::vector<Vec3d> translations(frames);
    Eigen::Vector4d sum = Eigen::Vector4d::Zero();
    for (int t = 0; t < frames; ++t) {
      Local(motion.world(t, j), parent < 0 ? nullptr : &motion.world(t, parent), rotations[t],
            translations[t]);
      // q and -q are one rotation: averaged on the bind rotation's side.
      if (rotations[t].dot(bind_rotation) < 0) rotations[t].coeffs() *= -1;
      sum += rotations[t].coeffs();
    }
    const Eigen::Quaterniond mean =
        sum.norm() > 0 ? Eigen::Quaterniond(sum.normalized()) : bind_rotation;
    const double translation_scale = std::max(ranking.hierarchical[j], 0.01 * character.height());
    double variation = 0, offset = 0, translation = 0;
    for (int t = 0; t < frames; ++t) {
      variation += rotations[t].angularDistance(mean);
      offset += rotations[t].angularDistance(bind_rotation);
      translation += (translations[t] - bind_translation).norm() / translation_scale;
    }
    ranking.rotational[j] = (variation + offset + translation) / frames;
    ranking.priority[j] = ranking.hierarchical[j] * ranking.rotational[j];
  }
  // The root and the locked joints are never removed.
  ranking.priority[0] = std::numeric_limits<double>::infinity();
  for (const std::string& name : locked_joints) {
    ranking.priority[character.FindJoint(name)] = std::numeric_limits<double>::infinity();
  }
  ranking.locked_count = static_cast<int>(std::count(
      ranking.priority.begin(), ranking.priority.end(), std::numeric_limits<double>::infinity()));
  // Lowest priority first; ties: the deeper joint, then the higher index; the root last.
  std::vector<int> depth(n, 0);
  for (int j = 1; j < n; ++j) depth[j] = depth[s.parents[j]] + 1;
  ranking.removal_order.resize(n);
  std::iota(ranking.removal_order.begin(), ranking.removal_order.end(), 0);
  std::sort(ranking.removal_order.begin(), ranking.removal_order.end(), [&](int a, int b) {
    if (a == 0 || b == 0) return b == 0 && a != 0;
    if (ranking.priority[a] != ranking.priority[b]) return ranking.priority[a] < ranking.priority[b];
    if (depth[a] != depth[b]) return depth[a] > depth[b];
    return a > b;
  });
  return ranking;
}

}  // namespace motionlod::core
