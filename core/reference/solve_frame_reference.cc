#include "core/reference/solve_frame_reference.h"

#include <cmath>
#include <numeric>

#include <Eigen/QR>

namespace motionlod::core {

std::vector<Affine34d> SolveFrameReference(const PreparedMotion& prepared,
                                       const ReducedSkeleton& level, int frame) {
  const Character& c = prepared.character();
  const RawSkin& skin = c.skin();
  const SolveSettings& settings = prepared.settings();
  const int n = c.joint_count();
  const int p = c.vertex_count();
  const int m = level.kept_count();
  const double alpha = prepared.alpha();
  const double beta = FitsNormals(settings.variant) ? prepared.beta() : 0.0;
  const std::vector<double>& areas = c.vertex_areas();
  const double total_area = std::accumulate(areas.begin(), areas.end(), 0.0);
  const std::vector<double>& lengths = c.subtree_lengths();
  const double total_length = std::accumulate(lengths.begin(), lengths.end(), 0.0);

  std::vector<Affine34d> k(n);
  for (int j = 0; j < n; ++j) {
    k[j] = prepared.original_matrices().block<4, 3>(4 * j, 3 * frame).transpose();
  }

  // Rows: p vertex positions, p normals, m joint positions, m joint axes, 4m regularisers.
  const int rows = 2 * p + 2 * m + 4 * m;
  Eigen::MatrixXd a = Eigen::MatrixXd::Zero(rows, 4 * m);
  Eigen::MatrixXd target = Eigen::MatrixXd::Zero(rows, 3);
  int r = 0;
  // One row per vertex: its position (w = 1) or normal (w = 0) rows, the targets being the
  // original skinned values (unnormalised blended normals).
  auto add_vertex_rows = [&](double scale, const std::vector<Vec3f>& attribute, double w_coord) {
    for (int i = 0; i < p; ++i, ++r) {
      const double weight = std::sqrt(scale * areas[i] / total_area);
      Eigen::Vector4d h;
      h << attribute[i].cast<double>(), w_coord;
      Vec3d original = Vec3d::Zero();
      for (uint32_t e = skin.influence_offsets[i]; e < skin.influence_offsets[i + 1]; ++e) {
        const int j = skin.influence_joints[e];
        const double w = skin.influence_weights[e];
        a.block<1, 4>(r, 4 * level.joint_to_slot[j]) += weight * w * h.transpose();
        original += w * (k[j] * h);
      }
      target.row(r) = weight * original.transpose();
    }
  };
  add_vertex_rows(alpha, skin.positions, 1.0);
  add_vertex_rows(beta, skin.normals, 0.0);
  for (int s = 0; s < m; ++s) {
    const int j = level.kept_joints[s];
    const double b = total_length > 0 ? settings.joint_weight * lengths[j] / total_length : 0.0;
    const Affine34d& bind = c.skeleton().bind_world[j];
    Eigen::Vector4d ph, oh;
    ph << bind.col(3), 1.0;
    oh << bind.col(1).normalized(), 0.0;
    const double wp = std::sqrt(alpha * b), wo = std::sqrt(beta * b);
    a.block<1, 4>(r, 4 * s) = wp * ph.transpose();
    target.row(r++) = wp * (k[j] * ph).transpose();
    a.block<1, 4>(r, 4 * s) = wo * oh.transpose();
    target.row(r++) = wo * (k[j] * oh).transpose();
  }
  // lambda as SolveLevel defines it, from the trace of this system's normal matrix.
  const double trace = a.topRows(r).squaredNorm();
  const double lambda = settings.regularization * (trace > 0 ? trace / (4 * m) : 1.0);
  for (int s = 0; s < m; ++s) {
    const int j = level.kept_joints[s];
    for (int q = 0; q < 4; ++q, ++r) {
      a(r, 4 * s + q) = std::sqrt(lambda);
      target.row(r) = std::sqrt(lambda) * k[j].col(q).transpose();
    }
  }
  const Eigen::MatrixXd x = a.colPivHouseholderQr().solve(target);
  std::vector<Affine34d> out(m);
  for (int s = 0; s < m; ++s) out[s] = x.block<4, 3>(4 * s, 0).transpose();
  return out;
}

}  // namespace motionlod::core
