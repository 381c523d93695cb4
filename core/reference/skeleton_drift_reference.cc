#include "core/reference/skeleton_drift_reference.h"

#include <algorithm>
#include <cmath>

#include "core/reference/polar_reference.h"

namespace motionlod::core {

SkeletonDriftFigures SkeletonDriftReference(const Character& character, const Motion& motion,
                                            const LevelResult& level) {
  const ReducedSkeleton& skeleton = level.skeleton;
  const int m = skeleton.kept_count();
  const auto fitted = [&](int t, int s) -> Affine34d {
    return level.matrices[static_cast<size_t>(t) * m + s].cast<double>();
  };
  SkeletonDriftFigures figures;
  for (int t = 0; t < motion.frame_count; ++t) {
    for (int s = 0; s < m; ++s) {
      const int j = skeleton.kept_joints[s];
      const Affine34d& bind = character.skeleton().bind_world[j];
      const Affine34d original = ComposeAffine(motion.world(t, j), InverseAffine(bind));
      const Eigen::Matrix3d r = NearestRotationReference(original.leftCols<3>());
      // A rigid variant's stored rotations are rotations to float precision: their polar
      // factor is themselves, orthonormal to the last bit.
      const Eigen::Matrix3d r_fitted = NearestRotationReference(fitted(t, s).leftCols<3>());
      const double cosine = std::clamp(((r_fitted.transpose() * r).trace() - 1) / 2, -1.0, 1.0);
      figures.joint_rotation_drift_deg =
          std::max(figures.joint_rotation_drift_deg, std::acos(cosine) * 180.0 / M_PI);
      if (s == 0) continue;
      const int q = skeleton.kept_joints[skeleton.parent_slots[s]];
      const Vec3d p0_j = bind.col(3);
      const Vec3d p0_q = character.skeleton().bind_world[q].col(3);
      const double length = (motion.world(t, j).col(3) - motion.world(t, q).col(3)).norm();
      const double fitted_length =
          (TransformPoint(fitted(t, s), p0_j) -
           TransformPoint(fitted(t, skeleton.parent_slots[s]), p0_q)).norm();
      figures.bone_length_drift_pct = std::max(
          figures.bone_length_drift_pct, 100.0 * std::abs(fitted_length - length) / character.height());
    }
  }
  return figures;
}

}  // namespace motionlod::core
