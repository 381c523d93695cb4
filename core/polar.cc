#include "core/polar.h"

#include <algorithm>
#include <cmath>

#include <Eigen/LU>

#include "core/internal/lanes.h"
#include "core/internal/simd_dispatch.h"
#include "core/reference/polar_reference.h"

namespace motionlod::core {

namespace {

constexpr int kLanes = 8;

// X^T X's six distinct entries (00, 11, 22, 01, 02, 12) for NearestRotations' lanes
// (x[3 c + r][lane]: coefficient (r, c)).
inline void Gram(const double (&x)[9][kLanes], double (&g)[6][kLanes]) {
  for (int l = 0; l < kLanes; ++l) {
    g[0][l] = x[0][l] * x[0][l] + x[1][l] * x[1][l] + x[2][l] * x[2][l];
    g[1][l] = x[3][l] * x[3][l] + x[4][l] * x[4][l] + x[5][l] * x[5][l];
    g[2][l] = x[6][l] * x[6][l] + x[7][l] * x[7][l] + x[8][l] * x[8][l];
    g[3][l] = x[0][l] * x[3][l] + x[1][l] * x[4][l] + x[2][l] * x[5][l];
    g[4][l] = x[0][l] * x[6][l] + x[1][l] * x[7][l] + x[2][l] * x[8][l];
    g[5][l] = x[3][l] * x[6][l] + x[4][l] * x[7][l] + x[5][l] * x[8][l];
  }
}

// e^2 = |X^T X - I|_F^2 of each lane from its Gram entries, and the largest.
inline double ErrorsSquared(const double (&g)[6][kLanes], double (&error_squared)[kLanes]) {
  for (int l = 0; l < kLanes; ++l) {
    error_squared[l] = (g[0][l] - 1) * (g[0][l] - 1) + (g[1][l] - 1) * (g[1][l] - 1) +
                       (g[2][l] - 1) * (g[2][l] - 1) +
                       2 * (g[3][l] * g[3][l] + g[4][l] * g[4][l] + g[5][l] * g[5][l]);
  }
  double largest = error_squared[0];
  for (int l = 1; l < kLanes; ++l) largest = std::max(largest, error_squared[l]);
  return largest;
}

// The Newton-Schulz steps that take a batch whose largest error is sqrt(error_squared) <=
// 1/2 below 1e-13: a step maps each eigenvalue 1 + d of X^T X to 1 - d^2 (3 - d) / 4, so
// the next error is at most e^2 (3 + e) / 4. Counted from that bound, the batch steps
// without measuring its errors again.
inline int NewtonSchulzSteps(double error_squared) {
  double error = std::sqrt(error_squared);
  int steps = 1;
  for (; error * error >= 1e-13; ++steps) error = error * error * (3 + error) / 4;
  return steps;
}

}  // namespace

void NearestRotations(std::span<double* const> blocks, std::ptrdiff_t column_stride,
                      SimdChoice simd) {
  RunWithSimd(simd, [&] {
    const Eigen::Matrix3d identity = Eigen::Matrix3d::Identity();
    for (size_t first = 0; first < blocks.size(); first += kLanes) {
      const int lanes = static_cast<int>(std::min<size_t>(kLanes, blocks.size() - first));
      // x[3 c + r][lane]: coefficient (r, c) of each lane's iterate; fourth[c][lane]: row 3
      // of column c, put back as it was. Each column of four blocks is read as four vectors
      // and transposed into lanes, and written back the same way (element by element, every
      // vector read of x waited for the scalar stores it spans to retire). Lanes past the
      // last block repeat the first block of the batch, whose steps they then match.
      alignas(32) double x[9][kLanes];
      alignas(32) double fourth[3][kLanes];
      for (int half = 0; half < kLanes; half += 4) {
        const double* source[4];
        for (int j = 0; j < 4; ++j) source[j] = blocks[first + (half + j < lanes ? half + j : 0)];
        for (int c = 0; c < 3; ++c) {
          Lanes4 column[4], rows[4];
          for (int j = 0; j < 4; ++j) column[j] = *AsLanes4(source[j] + c * column_stride);
          Transpose4(column, rows);
          for (int r = 0; r < 3; ++r) *AsLanes4(&x[3 * c + r][half]) = rows[r];
          *AsLanes4(&fourth[c][half]) = rows[3];
        }
      }
      // Each lane starts from a unit mean squared singular value: the polar factor is scale
      // invariant and both iterations below converge fastest near the orthonormal set. (The
      // geometric mean, det^(1/3), is as good a start and costs a cube root, a fifth of a
      // near-rotation's iterations.)
      double norm_squared[kLanes], determinant[kLanes], scale[kLanes];
      for (int l = 0; l < kLanes; ++l) {
        norm_squared[l] = 0;
        for (int q = 0; q < 9; ++q) norm_squared[l] += x[q][l] * x[q][l];
        determinant[l] = x[0][l] * (x[4][l] * x[8][l] - x[7][l] * x[5][l]) -
                         x[3][l] * (x[1][l] * x[8][l] - x[7][l] * x[2][l]) +
                         x[6][l] * (x[1][l] * x[5][l] - x[4][l] * x[2][l]);
        scale[l] = std::sqrt(3.0) / std::sqrt(norm_squared[l]);
        for (int q = 0; q < 9; ++q) x[q][l] *= scale[l];
      }
      // Newton needs det > 0 (it converges to the orthogonal factor, which is a reflection
      // when det < 0) and a condition number it can recover from in a few steps: a lane
      // without them goes alone, to the SVD.
      bool alone[kLanes];
      bool any_alone = false;
      for (int l = 0; l < kLanes; ++l) {
        const double norm = std::sqrt(norm_squared[l]);
        alone[l] = !(norm_squared[l] > 0) || !(determinant[l] > 1e-6 * norm * norm_squared[l]);
        any_alone = any_alone || alone[l];
      }
      for (int l = 0; any_alone && l < kLanes; ++l) {
        if (alone[l]) {
          for (int q = 0; q < 9; ++q) x[q][l] = identity(q);
        }
      }
      double g[6][kLanes];  // X^T X: 00, 11, 22, 01, 02, 12
      double error_squared[kLanes];
      double largest_error_squared = 0;
      int steps_left = 0;  // once every lane is near: the Newton-Schulz steps still to take
      for (int iteration = 0; iteration < 30; ++iteration) {
        Gram(x, g);
        if (steps_left == 0) {
          largest_error_squared = ErrorsSquared(g, error_squared);
          if (largest_error_squared < 1e-26) break;
          if (largest_error_squared < 0.25) steps_left = NewtonSchulzSteps(largest_error_squared);
        }
        // A lane still far from orthonormal (a tenth of a rigid every-level bake's matrices
        // start there) takes a scaled Newton step (Higham) instead of Newton-Schulz:
        // X <- (zeta X + X^-T / zeta) / 2, zeta = sqrt(|X^-1| / |X|) speeding the first
        // steps, X^-T the cofactors over the determinant.
        const bool any_far = steps_left == 0;
        double newton[9][kLanes];
        if (any_far) {
          for (int l = 0; l < kLanes; ++l) {
            double cofactor[9];
            for (int c = 0; c < 3; ++c) {
              for (int r = 0; r < 3; ++r) {
                const int r1 = (r + 1) % 3, r2 = (r + 2) % 3, c1 = (c + 1) % 3, c2 = (c + 2) % 3;
                cofactor[3 * c + r] =
                    x[3 * c1 + r1][l] * x[3 * c2 + r2][l] - x[3 * c2 + r1][l] * x[3 * c1 + r2][l];
              }
            }
            const double det =
                x[0][l] * cofactor[0] + x[1][l] * cofactor[1] + x[2][l] * cofactor[2];
            double inverse_squared = 0, x_squared = 0;
            for (int q = 0; q < 9; ++q) {
              cofactor[q] /= det;
              inverse_squared += cofactor[q] * cofactor[q];
              x_squared += x[q][l] * x[q][l];
            }
            const double zeta = std::sqrt(std::sqrt(inverse_squared) / std::sqrt(x_squared));
            for (int q = 0; q < 9; ++q) newton[q][l] = 0.5 * (zeta * x[q][l] + cofactor[q] / zeta);
          }
        }
        // Newton-Schulz, X (3I - X^T X) / 2: no inverse, quadratic convergence near the
        // orthonormal set, where the solved K' of a level almost always is; the step is the
        // identity's to rounding for a lane that has converged.
        for (int l = 0; l < kLanes; ++l) {
          const double s00 = 1.5 - 0.5 * g[0][l], s11 = 1.5 - 0.5 * g[1][l],
                       s22 = 1.5 - 0.5 * g[2][l];
          const double s01 = -0.5 * g[3][l], s02 = -0.5 * g[4][l], s12 = -0.5 * g[5][l];
          for (int r = 0; r < 3; ++r) {
            const double x0 = x[r][l], x1 = x[3 + r][l], x2 = x[6 + r][l];
            x[r][l] = x0 * s00 + x1 * s01 + x2 * s02;
            x[3 + r][l] = x0 * s01 + x1 * s11 + x2 * s12;
            x[6 + r][l] = x0 * s02 + x1 * s12 + x2 * s22;
          }
        }
        if (any_far) {
          for (int l = 0; l < kLanes; ++l) {
            const bool far = error_squared[l] >= 0.25;
            for (int q = 0; q < 9; ++q) x[q][l] = far ? newton[q][l] : x[q][l];
          }
        }
        if (steps_left > 0 && --steps_left == 0) break;
      }
      for (int l = 0; any_alone && l < lanes; ++l) {
        if (!alone[l]) continue;
        const double* block = blocks[first + l];
        Eigen::Matrix3d m;
        for (int c = 0; c < 3; ++c) {
          for (int r = 0; r < 3; ++r) m(r, c) = block[r + c * column_stride];
        }
        m = norm_squared[l] > 0 ? NearestRotationReference(m) : identity;
        for (int q = 0; q < 9; ++q) x[q][l] = m(q);
      }
      for (int half = 0; half < lanes; half += 4) {
        for (int c = 0; c < 3; ++c) {
          Lanes4 rows[4], column[4];
          for (int r = 0; r < 3; ++r) rows[r] = *AsLanes4(&x[3 * c + r][half]);
          rows[3] = *AsLanes4(&fourth[c][half]);
          Transpose4(rows, column);
          for (int j = 0; j < 4 && half + j < lanes; ++j)
            *AsLanes4(blocks[first + half + j] + c * column_stride) = column[j];
        }
      }
    }
  });
}

Eigen::Matrix3d NearestRotation(const Eigen::Matrix3d& a) {
  Eigen::Matrix<double, 4, 3> block = Eigen::Matrix<double, 4, 3>::Zero();
  block.topRows<3>() = a;
  double* const data = block.data();
  NearestRotations(std::span<double* const>(&data, 1), 4);
  return block.topRows<3>();
}

}  // namespace motionlod::core
