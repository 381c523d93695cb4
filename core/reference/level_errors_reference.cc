#include "core/reference/level_errors_reference.h"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <vector>

namespace motionlod::core {

LevelErrors LevelErrorsReference(const PreparedMotion& prepared, const ReducedSkeleton& level,
                                 const Eigen::MatrixXd& x) {
  const Character& c = prepared.character();
  const RawSkin& skin = c.skin();
  const Eigen::MatrixXd& kt = prepared.original_matrices();
  const int p = c.vertex_count(), frames = prepared.frame_count();
  const double height = c.height();
  const std::vector<double>& areas = c.vertex_areas();
  const double total_area = std::accumulate(areas.begin(), areas.end(), 0.0);
  const std::vector<double>& lengths = c.subtree_lengths();
  const double total_length = std::accumulate(lengths.begin(), lengths.end(), 0.0);
  const double omega = prepared.settings().joint_weight;

  LevelErrors out;
  double sum_distance = 0, sum_angle = 0;
  for (int t = 0; t < frames; ++t) {
    // K_k(t) of every original joint and K'_phi(k)(t) of the level.
    const auto original = [&](int k) -> Affine34d { return kt.block<4, 3>(4 * k, 3 * t).transpose(); };
    const auto solved = [&](int k) -> Affine34d {
      return x.block<4, 3>(4 * level.joint_to_slot[k], 3 * t).transpose();
    };
    double ep_vertex = 0, en_vertex = 0;
    for (int i = 0; i < p; ++i) {
      const Vec3d v0 = skin.positions[i].cast<double>(), n0 = skin.normals[i].cast<double>();
      Vec3d v = Vec3d::Zero(), v_level = Vec3d::Zero(), n = Vec3d::Zero(), n_level = Vec3d::Zero();
      for (uint32_t e = skin.influence_offsets[i]; e < skin.influence_offsets[i + 1]; ++e) {
        const int k = skin.influence_joints[e];
        const double w = skin.influence_weights[e];
        v += w * TransformPoint(original(k), v0);
        v_level += w * TransformPoint(solved(k), v0);
        n += w * TransformDirection(original(k), n0);
        n_level += w * TransformDirection(solved(k), n0);
      }
      const double a = areas[i] / total_area;
      const double distance = (v - v_level).norm();
      ep_vertex += a * distance * distance;
      en_vertex += a * (n - n_level).squaredNorm();
      if (100.0 * distance / height > out.max_vertex_error_pct) {
        out.max_vertex_error_pct = 100.0 * distance / height;
        out.max_vertex_frame = t;
        out.max_vertex_index = i;
      }
      sum_distance += a * distance;
      // atan2 of the cross and dot products: exact at small angles, where acos is not.
      if (n.norm() > 0 && n_level.norm() > 0) sum_angle += a * std::atan2(n.cross(n_level).norm(), n.dot(n_level));
    }
    // The kept joints' positions and bind y axes, weighted by omega l_j / sum l.
    double ep_joint = 0, en_joint = 0;
    for (int j : level.kept_joints) {
      const double b = total_length > 0 ? omega * lengths[j] / total_length : 0.0;
      const Affine34d& bind = c.skeleton().bind_world[j];
      const Vec3d point = bind.col(3), axis = bind.col(1).normalized();
      ep_joint += b * (TransformPoint(original(j), point) - TransformPoint(solved(j), point)).squaredNorm();
      en_joint += b * (TransformDirection(original(j), axis) - TransformDirection(solved(j), axis)).squaredNorm();
    }
    out.ep_vertex.push_back(ep_vertex);
    out.en_vertex.push_back(en_vertex);
    out.ep_joint.push_back(ep_joint);
    out.en_joint.push_back(en_joint);
    out.e.push_back(prepared.alpha() * (ep_vertex + ep_joint) + prepared.beta() * (en_vertex + en_joint));
  }
  out.mean_e = std::accumulate(out.e.begin(), out.e.end(), 0.0) / frames;
  const auto max_e = std::max_element(out.e.begin(), out.e.end());
  out.max_e = *max_e;
  out.max_e_frame = static_cast<int>(max_e - out.e.begin());
  const double mean_squared = std::accumulate(out.ep_vertex.begin(), out.ep_vertex.end(), 0.0) / frames;
  out.rms_vertex_error_pct = 100.0 * std::sqrt(mean_squared) / height;
  out.mean_vertex_error_pct = 100.0 * sum_distance / frames / height;
  out.mean_normal_error_deg = sum_angle / frames * 180.0 / M_PI;
  return out;
}

LevelErrors BaselineErrorsReference(const PreparedMotion& prepared, const ReducedSkeleton& level) {
  const Eigen::MatrixXd& kt = prepared.original_matrices();
  Eigen::MatrixXd kept(4 * level.kept_count(), kt.cols());
  for (int s = 0; s < level.kept_count(); ++s) {
    kept.middleRows<4>(4 * s) = kt.middleRows<4>(4 * level.kept_joints[s]);
  }
  return LevelErrorsReference(prepared, level, kept);
}

}  // namespace motionlod::core
