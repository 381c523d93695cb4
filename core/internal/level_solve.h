// A level's matrices in its variant (steps 4 and 4b): the least-squares solution of the
// normal equations (core/internal/normal_equations.h), projected on rotations with
// re-solved translations for the rigid variants (core/internal/rigid_projection.h).
#pragma once

#include <Eigen/Core>

#include "core/internal/prepared_data.h"
#include "core/reduce_skeleton.h"

namespace motionlod::core::internal {

// The matrices (4m x 3T, block (4s, 3t) = K'_s(t)^T) and the view of their
// Delta_k = K'_phi(k) - K_k for the errors.
struct VariantSolution {
  Eigen::MatrixXd x;  // empty where unchanged
  // The solution is the original matrices: nothing removed, nothing projected.
  bool unchanged = false;

  const Eigen::MatrixXd& Matrices(const PreparedData& d) const { return unchanged ? d.kt : x; }
  // Reads x, so it lives as long as this.
  DeltaView Delta(const PreparedData& d, const ReducedSkeleton& level) const;
};

StatusOr<VariantSolution> SolveVariant(const PreparedData& d, const ReducedSkeleton& level);

// The guarantee of PreparedMotion::KeepNoWorseThanReparenting: whether the reparented
// level is a candidate for d's variant (always, but in a rigid variant only where the
// original matrices are rotations), and whether a candidate's figures are no worse than
// the reparented level's in what it covers, the maximum and the mean vertex error.
bool ReparentingIsCandidate(const PreparedData& d);
bool NoWorseThan(const LevelErrors& candidate, const LevelErrors& reparented);

}  // namespace motionlod::core::internal
