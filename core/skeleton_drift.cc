#include "core/internal/skeleton_drift.h"

#include <algorithm>
#include <cmath>

#include "core/polar.h"

namespace motionlod::core::internal {

using Eigen::MatrixXd;

MatrixXd JointPositions(const PreparedData& d, const MatrixXd& k, const std::vector<int>& first_rows,
                        const std::vector<int>& joints) {
  const int m = static_cast<int>(joints.size());
  const int cols = 3 * d.frames;
  MatrixXd positions(m, cols);
  for (int s = 0; s < m; ++s) {
    const Eigen::Vector3d p0 = d.character->skeleton().bind_world[joints[s]].col(3);
    const int r = first_rows[s];
    // Column 3t + c of K^T's block is row c of K(t): its rotation row times p0, plus the
    // translation.
    for (int col = 0; col < cols; ++col) {
      positions(s, col) = k(r, col) * p0.x() + k(r + 1, col) * p0.y() + k(r + 2, col) * p0.z() +
                          k(r + 3, col);
    }
  }
  return positions;
}

MatrixXd KeptJointPositions(const PreparedData& d, const MatrixXd& x, const ReducedSkeleton& level) {
  std::vector<int> rows(level.kept_count());
  for (int s = 0; s < level.kept_count(); ++s) rows[s] = 4 * s;
  return JointPositions(d, x, rows, level.kept_joints);
}

MatrixXd OriginalBoneLengths(const PreparedData& d, const ReducedSkeleton& level) {
  const int m = level.kept_count();
  std::vector<int> rows(m);
  for (int s = 0; s < m; ++s) rows[s] = 4 * level.kept_joints[s];
  const MatrixXd positions = JointPositions(d, d.kt, rows, level.kept_joints);
  MatrixXd lengths = MatrixXd::Zero(m, d.frames);
  for (int s = 1; s < m; ++s) {
    const int q = level.parent_slots[s];
    for (int t = 0; t < d.frames; ++t) {
      lengths(s, t) = (positions.block<1, 3>(s, 3 * t) - positions.block<1, 3>(q, 3 * t)).norm();
    }
  }
  return lengths;
}

void EvaluateSkeletonDrift(const PreparedData& d, const ReducedSkeleton& level, const MatrixXd& x,
                           LevelErrors& out) {
  const int m = level.kept_count();
  const int cols = 3 * d.frames;
  const MatrixXd positions = KeptJointPositions(d, x, level);
  const MatrixXd lengths = OriginalBoneLengths(d, level);
  double length_drift = 0;
  for (int s = 1; s < m; ++s) {
    const int q = level.parent_slots[s];
    for (int t = 0; t < d.frames; ++t) {
      const double length =
          (positions.block<1, 3>(s, 3 * t) - positions.block<1, 3>(q, 3 * t)).norm();
      length_drift = std::max(length_drift, std::abs(length - lengths(s, t)));
    }
  }
  out.bone_length_drift_pct = 100.0 * length_drift / d.character->height();

  // The rotations of both: their polar factors (a rigid variant's and the originals are
  // rotations to their float source's precision already, and converge at once).
  MatrixXd fitted = x, original(4 * m, cols);
  for (int s = 0; s < m; ++s) original.middleRows<4>(4 * s) = d.kt.middleRows<4>(4 * level.kept_joints[s]);
  std::vector<double*> fitted_blocks, original_blocks;
  fitted_blocks.reserve(static_cast<size_t>(m) * d.frames);
  original_blocks.reserve(static_cast<size_t>(m) * d.frames);
  for (int t = 0; t < d.frames; ++t) {
    for (int s = 0; s < m; ++s) {
      fitted_blocks.push_back(fitted.data() + 3 * t * fitted.rows() + 4 * s);
      original_blocks.push_back(original.data() + 3 * t * original.rows() + 4 * s);
    }
  }
  NearestRotations(fitted_blocks, fitted.rows(), d.simd);
  NearestRotations(original_blocks, original.rows(), d.simd);
  // The angle between rotations R and R' from their chord: |R - R'|_F = 2 sqrt(2) sin(angle / 2),
  // exact at small angles where acos of the trace keeps half the digits.
  double chord = 0;
  for (int t = 0; t < d.frames; ++t) {
    for (int s = 0; s < m; ++s) {
      chord = std::max(chord, (fitted.block<3, 3>(4 * s, 3 * t) - original.block<3, 3>(4 * s, 3 * t)).norm());
    }
  }
  out.joint_rotation_drift_deg = 2 * std::asin(std::min(1.0, chord / (2 * std::sqrt(2.0)))) * 180.0 / M_PI;
}

}  // namespace motionlod::core::internal
