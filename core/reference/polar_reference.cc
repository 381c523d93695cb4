#include "core/reference/polar_reference.h"

#include <Eigen/LU>
#include <Eigen/SVD>

namespace motionlod::core {

Eigen::Matrix3d NearestRotationReference(const Eigen::Matrix3d& a) {
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(a, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d u = svd.matrixU();
  const Eigen::Matrix3d& v = svd.matrixV();
  if ((u * v.transpose()).determinant() < 0) u.col(2) = -u.col(2);
  return u * v.transpose();
}

}  // namespace motionlod::core
