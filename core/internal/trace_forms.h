// The kernel of every quadratic error figure: tr(A^T C B) for 4x3 blocks A, B of Delta^T
// and the 4x4 moments C of a joint pair (core/internal/level_errors.h). Inline, so that a
// caller's AVX2 version (core/internal/simd_dispatch.h) runs it 256 bits wide.
#pragma once

#include <cstddef>
#include <utility>

#include <Eigen/Core>

#include "core/internal/lanes.h"
#include "core/internal/prepared_data.h"

namespace motionlod::core::internal {

// Adds tr(A^T Cp B) and tr(A^T Cn B), lane by lane, to p and n (each sums to its trace): A
// and B are 4x3 blocks of column-major matrices with `stride` rows (4 contiguous rows per
// column), Cp and Cn 4x4 (Cn a 3x3 padded with zeros, which leaves the translation rows
// out). As tr(A^T C B) = <C, A B^T>, the columns of A B^T are formed once for both forms.
// Written with vector types: GCC vectorised plain loops over the rows with every load
// lane-reversed and every element of B broadcast by a shuffle.
inline void AddTraceForms(const double* a, const double* b, Eigen::Index stride,
                          const Eigen::Matrix4d& cp, const Eigen::Matrix4d& cn, Lanes4& p,
                          Lanes4& n) {
  const Lanes4 a0 = *AsLanes4(a), a1 = *AsLanes4(a + stride), a2 = *AsLanes4(a + 2 * stride);
  const double* b1 = b + stride;
  const double* b2 = b + 2 * stride;
  // Column r of A B^T.
  const Lanes4 outer0 = a0 * b[0] + a1 * b1[0] + a2 * b2[0];
  const Lanes4 outer1 = a0 * b[1] + a1 * b1[1] + a2 * b2[1];
  const Lanes4 outer2 = a0 * b[2] + a1 * b1[2] + a2 * b2[2];
  const Lanes4 outer3 = a0 * b[3] + a1 * b1[3] + a2 * b2[3];
  const UnalignedLanes4* cp_columns = AsLanes4(cp.data());
  const UnalignedLanes4* cn_columns = AsLanes4(cn.data());  // the last one is zero
  p += (cp_columns[0] * outer0 + cp_columns[1] * outer1) +
       (cp_columns[2] * outer2 + cp_columns[3] * outer3);
  n += (cn_columns[0] * outer0 + cn_columns[1] * outer1) + cn_columns[2] * outer2;
}

// The sum of AddTraceForms' four lanes.
inline double LaneSum(const Lanes4& lanes) { return (lanes[0] + lanes[1]) + (lanes[2] + lanes[3]); }

// Joint pair q's terms of the vertex parts of Ep and En in a frame (4n x 3, Delta_k^T
// stacked), added lane by lane to p and n: tr(Delta_k^T Cp_kl Delta_l) and
// tr(Delta_k^T Cn_kl Delta_l), doubled for k != l.
inline void AddPairTerms(const PreparedData& d, const Eigen::Matrix<double, Eigen::Dynamic, 3>& frame,
                         size_t q, Lanes4& p, Lanes4& n) {
  const auto [k, l] = d.pairs[q];
  AddTraceForms(frame.data() + 4 * k, frame.data() + 4 * l, frame.rows(), d.pair_cp[q],
                d.pair_cn[q], p, n);
}

// The same summed: (Ep part, En part).
inline std::pair<double, double> PairTerms(const PreparedData& d,
                                           const Eigen::Matrix<double, Eigen::Dynamic, 3>& frame,
                                           size_t q) {
  Lanes4 p = {}, n = {};
  AddPairTerms(d, frame, q, p, n);
  return {LaneSum(p), LaneSum(n)};
}

}  // namespace motionlod::core::internal
