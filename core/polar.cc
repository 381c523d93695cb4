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
  Eigen::Matrix3d x = a;
  for (int iteration = 0; iteration < 20; ++iteration) {
    const Eigen::Matrix3d inverse = x.inverse();
    // Frobenius scaling (Higham): zeta = sqrt(|X^-1| / |X|) speeds the first steps.
    const double zeta = std::sqrt(inverse.norm() / x.norm());
    const Eigen::Matrix3d next = 0.5 * (zeta * x + inverse.transpose() / zeta);
    const double change = (next - x).squaredNorm();
    x = next;
    if (change < 1e-28) break;
  }
  return x;
}

}  // namespace motionlod::core
