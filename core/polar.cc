#include "core/polar.h"

#include <cmath>

#include <Eigen/LU>
#include <Eigen/SVD>

namespace motionlod::core {

Eigen::Matrix3d NearestRotationSvd(const Eigen::Matrix3d& a) {
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(a, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d u = svd.matrixU();
  const Eigen::Matrix3d& v = svd.matrixV();
  if ((u * v.transpose()).determinant() < 0) u.col(2) = -u.col(2);
  return u * v.transpose();
}

Eigen::Matrix3d NearestRotation(const Eigen::Matrix3d& a) {
  const double norm = a.norm();
  if (!(norm > 0)) return Eigen::Matrix3d::Identity();
  const double det = a.determinant();
  // Newton needs det > 0 (it converges to the orthogonal factor, which is a reflection
  // when det < 0) and a condition number it can recover from in a few steps.
  if (!(det > 1e-6 * norm * norm * norm)) return NearestRotationSvd(a);
  // Start from unit determinant: the polar factor is scale invariant and both iterations
  // below converge fastest near the orthonormal set.
  Eigen::Matrix3d x = a / std::cbrt(det);
  for (int iteration = 0; iteration < 30; ++iteration) {
    const Eigen::Matrix3d gram = x.transpose() * x;
    const double error = (gram - Eigen::Matrix3d::Identity()).norm();
    if (error < 1e-13) break;
    if (error < 0.5) {
      // Newton-Schulz, X (3I - X^T X) / 2: no inverse, quadratic convergence near the
      // orthonormal set, where the solved K' of a level almost always is.
      x = x * (1.5 * Eigen::Matrix3d::Identity() - 0.5 * gram);
    } else {
      // Scaled Newton (Higham): zeta = sqrt(|X^-1| / |X|) speeds the first steps.
      const Eigen::Matrix3d inverse = x.inverse();
      const double zeta = std::sqrt(inverse.norm() / x.norm());
      x = 0.5 * (zeta * x + inverse.transpose() / zeta);
    }
  }
  return x;
}

}  // namespace motionlod::core
