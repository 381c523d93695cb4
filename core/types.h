// Shared math types of the core. Index letters used throughout the core:
//   i vertex (p of them), j or k joint of the original skeleton (n),
//   s slot of a kept joint in a reduced skeleton (m), t frame (T).
// All positions are in the character's model space, in the source file's length unit.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <Eigen/LU>

namespace motionlod::core {

// The top three rows of an affine 4x4 matrix [A | t]; the last row is (0 0 0 1).
using Affine34d = Eigen::Matrix<double, 3, 4>;
using Affine34f = Eigen::Matrix<float, 3, 4>;
// The same in row-major order: the layout the level file streams (three rows of four), so
// a level's matrices are written out as they are.
using RowMajorAffine34f = Eigen::Matrix<float, 3, 4, Eigen::RowMajor>;
using Vec3f = Eigen::Vector3f;
using Vec3d = Eigen::Vector3d;

// Applies a 3x4 affine to a point (w = 1) and to a direction (w = 0).
template <typename Scalar>
inline Eigen::Matrix<Scalar, 3, 1> TransformPoint(const Eigen::Matrix<Scalar, 3, 4>& m,
                                                  const Eigen::Matrix<Scalar, 3, 1>& p) {
  return m.template leftCols<3>() * p + m.col(3);
}
template <typename Scalar>
inline Eigen::Matrix<Scalar, 3, 1> TransformDirection(const Eigen::Matrix<Scalar, 3, 4>& m,
                                                      const Eigen::Matrix<Scalar, 3, 1>& d) {
  return m.template leftCols<3>() * d;
}

// a * b for affine matrices stored as 3x4.
inline Affine34d ComposeAffine(const Affine34d& a, const Affine34d& b) {
  Affine34d r;
  r.leftCols<3>() = a.leftCols<3>() * b.leftCols<3>();
  r.col(3) = a.leftCols<3>() * b.col(3) + a.col(3);
  return r;
}

// Inverse of an invertible affine matrix.
inline Affine34d InverseAffine(const Affine34d& a) {
  Affine34d r;
  const Eigen::Matrix3d inv = a.leftCols<3>().inverse();
  r.leftCols<3>() = inv;
  r.col(3) = -inv * a.col(3);
  return r;
}

inline Affine34d IdentityAffine() {
  Affine34d r = Affine34d::Zero();
  r.leftCols<3>().setIdentity();
  return r;
}

}  // namespace motionlod::core
