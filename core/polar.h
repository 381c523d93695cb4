// Polar decomposition A = R S (eq. 8): R the orthonormal factor nearest to A in the
// Frobenius norm, det(R) = +1 (a rotation, never a reflection).
#pragma once

#include <cstddef>
#include <span>

#include <Eigen/Core>

#include "core/simd.h"

namespace motionlod::core {

// For well-conditioned A with det(A) > 0: scaled Newton steps (Higham 1986) while far from
// orthonormal, then inverse-free Newton-Schulz steps; both converge quadratically, and a
// near-rotation needs two or three 3x3 products. The SVD of the reference otherwise
// (core/reference/polar_reference.h: det(A) <= 0 or nearly singular A). Returns the
// identity for A = 0. One matrix through NearestRotations.
Eigen::Matrix3d NearestRotation(const Eigen::Matrix3d& a);

// NearestRotation of many 3x3 blocks where they lie, several at a time: the steps of eight
// matrices interleave in one vectorised loop instead of waiting on each other's latency
// (the rigid variants project m x T matrices per level); a matrix for the SVD goes alone.
// Block i is the top 3x3 of a column-major 4x3 at blocks[i], coefficient (r, c) at
// blocks[i][r + c * column_stride] (column_stride >= 4: a 4x3 block of a larger matrix,
// as a solution's K'^T with its translation row, or a Matrix<double, 4, 3> with 4). Its
// columns are read and written whole: row 3 is put back as it was. A matrix's result does
// not depend on its batch beyond rounding: a batch steps until all of its matrices have
// converged, and a converged matrix's further steps are the identity's.
// `simd`: the machine version of its steps (core/simd.h).
void NearestRotations(std::span<double* const> blocks, std::ptrdiff_t column_stride,
                      SimdChoice simd = SimdChoice::kWidest);

}  // namespace motionlod::core
