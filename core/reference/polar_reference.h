// The naive reference for the polar projection (core/polar.h, eq. 8): the rotation nearest
// to A in the Frobenius norm from A's SVD, R = U diag(1, 1, det(U V^T)) V^T, the
// reflection guard keeping det R = +1. NearestRotations takes this path itself for the
// matrices its Newton steps cannot (det A <= 0, nearly singular A).
#pragma once

#include <Eigen/Core>

namespace motionlod::core {

Eigen::Matrix3d NearestRotationReference(const Eigen::Matrix3d& a);

}  // namespace motionlod::core
