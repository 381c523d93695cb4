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
  const double norm_squared = a.squaredNorm();
  if (!(norm_squared > 0)) return Eigen::Matrix3d::Identity();
  const double norm = std::sqrt(norm_squared);
  // Newton needs det > 0 (it converges to the orthogonal factor, which is a reflection
  // when det < 0) and a condition number it can recover from in a few steps.
  if (!(a.determinant() > 1e-6 * norm * norm_squared)) return NearestRotationSvd(a);
  // Start from a unit mean squared singular value: the polar factor is scale invariant and
  // both iterations below converge fastest near the orthonormal set. (The geometric mean,
  // det^(1/3), is as good a start and costs a cube root, a fifth of a near-rotation's
  // iterations.)
  Eigen::Matrix3d x = a * (std::sqrt(3.0) / norm);
  for (int iteration = 0; iteration < 30; ++iteration) {
    // X^T X is symmetric: its six distinct entries (a full 3x3 product costs half again).
    const double g00 = x.col(0).squaredNorm(), g11 = x.col(1).squaredNorm();
    const double g22 = x.col(2).squaredNorm(), g01 = x.col(0).dot(x.col(1));
    const double g02 = x.col(0).dot(x.col(2)), g12 = x.col(1).dot(x.col(2));
    // e^2 = |X^T X - I|_F^2, squared to spare a square root per step.
    const double error_squared = (g00 - 1) * (g00 - 1) + (g11 - 1) * (g11 - 1) +
                                 (g22 - 1) * (g22 - 1) + 2 * (g01 * g01 + g02 * g02 + g12 * g12);
    if (error_squared < 1e-26) break;
    if (error_squared < 0.25) {
      // Newton-Schulz, X (3I - X^T X) / 2: no inverse, quadratic convergence near the
      // orthonormal set, where the solved K' of a level almost always is.
      Eigen::Matrix3d step;
      step << 1.5 - 0.5 * g00, -0.5 * g01, -0.5 * g02,  //
          -0.5 * g01, 1.5 - 0.5 * g11, -0.5 * g12,      //
          -0.5 * g02, -0.5 * g12, 1.5 - 0.5 * g22;
      x = x * step;
      // The step maps each eigenvalue 1 + d of X^T X to 1 - d^2 (3 - d) / 4, so for
      // e <= 1/2 the next error is at most e^2: below 1e-13 here, no need to check it.
      if (error_squared < 1e-13) break;
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
