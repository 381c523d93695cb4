#include "core/rank_joints.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>

#include <Eigen/Geometry>

namespace motionlod::core {
namespace {

Eigen::Quaterniond RotationOf(const Affine34d& local) {
  // Local matrices may carry scale; the rotation is the orthonormal part of each axis.
  Eigen::Matrix3d r = local.leftCols<3>();
  for (int c = 0; c < 3; ++c) {
    const double len = r.col(c).norm();
    if (len > 0) r.col(c) /= len;
  }
  Eigen::Quaterniond q(r);
  return q.normalized();
}

double Angle(const Eigen::Quaterniond& a, const Eigen::Quaterniond& b) {
  return 2.0 * std::acos(std::min(1.0, std::abs(a.dot(b))));
}

}  // namespace

Status RankJointsJob::Validate() const {
  if (character == nullptr || motion == nullptr) {
    return InvalidArgument("RankJointsJob needs a character and a motion");
  }
  if (Status status = ValidateMotion(*motion, *character); !status.ok()) return status;
  std::string unknown;
  for (const std::string& name : locked_joints) {
    if (character->FindJoint(name) < 0) unknown += (unknown.empty() ? "'" : ", '") + name + "'";
  }
  if (!unknown.empty()) return NotFound("locked joints not in the skeleton: " + unknown);
  return Status::Ok();
}

StatusOr<JointRanking> RankJointsJob::Run(const PieceRunner& run) const {
  if (Status status = Validate(); !status.ok()) return status;
  const Character& c = *character;
  const RawSkeleton& s = c.skeleton();
  const int n = c.joint_count();
  const int frames = motion->frame_count;

  JointRanking ranking;
  ranking.hierarchical = c.subtree_lengths();
  ranking.rotational.assign(n, 0.0);
  ranking.priority.assign(n, 0.0);

  constexpr int kJointsPerPiece = 4;
  RunPieces(run, (n + kJointsPerPiece - 1) / kJointsPerPiece, [&](int piece) {
    std::vector<Eigen::Quaterniond> rotations(frames);
    std::vector<Vec3d> translations(frames);
    for (int j = piece * kJointsPerPiece; j < std::min(n, (piece + 1) * kJointsPerPiece); ++j) {
      const int parent = s.parents[j];
      const Affine34d bind_local =
          parent < 0 ? s.bind_world[j] : ComposeAffine(InverseAffine(s.bind_world[parent]), s.bind_world[j]);
      const Eigen::Quaterniond bind_rotation = RotationOf(bind_local);
      Eigen::Vector4d sum = Eigen::Vector4d::Zero();
      for (int t = 0; t < frames; ++t) {
        const Affine34d local = parent < 0 ? motion->world(t, j)
                                           : ComposeAffine(InverseAffine(motion->world(t, parent)),
                                                           motion->world(t, j));
        rotations[t] = RotationOf(local);
        translations[t] = local.col(3);
        // Align signs with the bind rotation so q and -q average together.
        if (rotations[t].dot(bind_rotation) < 0) rotations[t].coeffs() *= -1.0;
        sum += rotations[t].coeffs();
      }
      Eigen::Quaterniond mean(bind_rotation);
      if (sum.norm() > 0) mean.coeffs() = sum.normalized();
      const double translation_scale = std::max(ranking.hierarchical[j], 0.01 * c.height());
      double variation = 0, offset = 0, translation = 0;
      for (int t = 0; t < frames; ++t) {
        variation += Angle(rotations[t], mean);
        offset += Angle(rotations[t], bind_rotation);
        translation += (translations[t] - bind_local.col(3)).norm() / translation_scale;
      }
      ranking.rotational[j] = (variation + offset + translation) / frames;
      ranking.priority[j] = ranking.hierarchical[j] * ranking.rotational[j];
    }
  });

  std::vector<int> depth(n, 0);
  for (int j = 1; j < n; ++j) depth[j] = depth[s.parents[j]] + 1;
  ranking.priority[0] = std::numeric_limits<double>::infinity();
  for (const std::string& name : locked_joints) {
    ranking.priority[c.FindJoint(name)] = std::numeric_limits<double>::infinity();
  }
  ranking.locked_count = static_cast<int>(
      std::count(ranking.priority.begin(), ranking.priority.end(),
                 std::numeric_limits<double>::infinity()));
  ranking.removal_order.resize(n);
  std::iota(ranking.removal_order.begin(), ranking.removal_order.end(), 0);
  std::stable_sort(ranking.removal_order.begin(), ranking.removal_order.end(), [&](int a, int b) {
    if (ranking.priority[a] != ranking.priority[b]) return ranking.priority[a] < ranking.priority[b];
    if (a == 0 || b == 0) return b == 0;
    if (depth[a] != depth[b]) return depth[a] > depth[b];
    return a > b;
  });
  return ranking;
}

}  // namespace motionlod::core
