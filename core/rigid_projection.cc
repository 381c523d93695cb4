#include "core/internal/rigid_projection.h"

#include <algorithm>
#include <vector>

#include "core/internal/lanes.h"
#include "core/internal/simd_dispatch.h"
#include "core/polar.h"

namespace motionlod::core::internal {
namespace {

using Eigen::MatrixXd;

// The rotations' rows of a solution transposed: `from` is 4m x cols in 4x3 blocks (three
// rotation rows, then the translation's), and row 4b + a (a < 3) becomes column 3b + a of
// `to`, which has from.cols() rows. Four columns at a time, each block's four rows of them
// (four contiguous doubles) are transposed as whole vectors (Transpose4) and the
// translations' lane dropped: element by element, every element was a load and a store of
// its own, and reading a row of `from` touches one cache line per column. (Whole matrices
// go through TransposeDoubles.) Inline, so that a caller's AVX2 version (core/internal/simd_dispatch.h)
// runs it 256 bits wide.
inline void TransposeRotationRows(const MatrixXd& from, MatrixXd& to) {
  const Eigen::Index blocks = from.rows() / 4, cols = from.cols();
  const Eigen::Index from_stride = from.rows(), to_stride = to.rows();
  Eigen::Index col = 0;
  for (; col + 4 <= cols; col += 4) {
    for (Eigen::Index b = 0; b < blocks; ++b) {
      Lanes4 columns[4], rows[4];
      for (int f = 0; f < 4; ++f) {
        columns[f] = *AsLanes4(from.data() + (col + f) * from_stride + 4 * b);
      }
      Transpose4(columns, rows);
      for (int a = 0; a < 3; ++a) *AsLanes4(to.data() + (3 * b + a) * to_stride + col) = rows[a];
    }
  }
  for (; col < cols; ++col) {
    for (Eigen::Index b = 0; b < blocks; ++b) {
      for (int a = 0; a < 3; ++a) to(col, 3 * b + a) = from(4 * b + a, col);
    }
  }
}

// Four joints of a frame at a time, one per lane: each column of their blocks (four
// contiguous doubles, the translation's last) is transposed into lanes, and the column
// products of R^T R and the determinant (the columns' triple product) are whole vectors;
// the last group repeats its last joint.
inline bool AllRotationsKernel(const MatrixXd& x) {
  const Eigen::Index joints = x.rows() / 4, stride = x.rows();
  for (Eigen::Index t = 0; t < x.cols(); t += 3) {
    const double* frame = x.data() + t * stride;
    for (Eigen::Index first = 0; first < joints; first += 4) {
      Lanes4 column[3][4];  // column[c][i]: R(i, c) of the four joints
      for (int c = 0; c < 3; ++c) {
        Lanes4 blocks[4];
        for (Eigen::Index j = 0; j < 4; ++j) {
          blocks[j] = *AsLanes4(frame + c * stride + 4 * std::min(first + j, joints - 1));
        }
        Transpose4(blocks, column[c]);
      }
      Lanes4 gram[3][3];  // R^T R - I, its upper triangle
      for (int a = 0; a < 3; ++a) {
        for (int b = a; b < 3; ++b) {
          gram[a][b] = column[a][0] * column[b][0] + column[a][1] * column[b][1] +
                       column[a][2] * column[b][2] - (a == b ? 1.0 : 0.0);
        }
      }
      const Lanes4 error_squared =
          gram[0][0] * gram[0][0] + gram[1][1] * gram[1][1] + gram[2][2] * gram[2][2] +
          2 * (gram[0][1] * gram[0][1] + gram[0][2] * gram[0][2] + gram[1][2] * gram[1][2]);
      const Lanes4* c0 = column[0];
      const Lanes4* c1 = column[1];
      const Lanes4* c2 = column[2];
      const Lanes4 determinant = c0[0] * (c1[1] * c2[2] - c1[2] * c2[1]) -
                                 c0[1] * (c1[0] * c2[2] - c1[2] * c2[0]) +
                                 c0[2] * (c1[0] * c2[1] - c1[1] * c2[0]);
      const auto rotation = (error_squared <= 1e-10) & (determinant > 0);
      for (int j = 0; j < 4; ++j) {
        if (rotation[j] == 0) return false;
      }
    }
  }
  return true;
}

}  // namespace

bool AllRotations(const MatrixXd& x, SimdChoice simd) {
  return RunWithSimd(simd, [&] { return AllRotationsKernel(x); });
}

Status ProjectOnRotations(const PreparedData& d, LevelSystem& system) {
  return RunWithSimd(d.simd, [&]() -> Status {
    const int m = system.g.block_count();
    const int cols = 3 * d.frames;
    const BlockSymmetric<4>& g = system.g;
    MatrixXd& x = system.x;
    // x holds each K'^T: the polar factor of a transpose is the transpose of the factor.
    // Projected where they are, joint by joint: a batch of NearestRotations steps until
    // its slowest matrix converges, and a joint's matrices in consecutive frames converge
    // alike, where the joints of one frame did not (a fifth fewer steps on real rigs'
    // ladders, and a third to a seventh of the batches that need Newton's inverses).
    std::vector<double*> rotations(static_cast<size_t>(d.frames) * m);
    for (int s = 0; s < m; ++s) {
      for (int t = 0; t < d.frames; ++t)
        rotations[static_cast<size_t>(s) * d.frames + t] = x.data() + 3 * t * x.rows() + 4 * s;
    }
    NearestRotations(rotations, x.rows(), d.simd);
    if (d.settings.resolve_rigid_translation) {
      // x_T = G_TT^-1 (b_T - G_TN x_N): translations are rows 4s+3, the rest is fixed.
      // The right-hand sides transposed, as SolveTransposed takes them: b_T^T - x_N^T G_TN^T.
      // G_TT and G_TN keep G's block sparsity: G_TT is a block matrix of 1x1 blocks, and
      // each coefficient of G_TN subtracts one contiguous column of all frames.
      // x_N^T: the rotations' rows of x, transposed.
      MatrixXd x_nt(cols, 3 * m);
      TransposeRotationRows(x, x_nt);
      const Eigen::Index nt_stride = x_nt.rows();
      const double* nt_data = x_nt.data();
      BlockSymmetric<1> g_tt(m, g.lower().size());
      // Row s of G_TN as its couplings to the slots u of its blocks (G_su(3, 0..2): the
      // diagonal block first, then the others in G's order), so that each slot's
      // right-hand sides are summed in registers, eight frames' columns at a time, and
      // stored once (a pass over the blocks read and wrote every right-hand side once per
      // block).
      struct Coupling {
        int u;
        double g[3];
      };
      std::vector<int> coupling_offsets(m + 1, 0);
      for (const auto& block : g.lower()) {
        ++coupling_offsets[block.row + 1];
        ++coupling_offsets[block.col + 1];
      }
      for (int s = 0; s < m; ++s) coupling_offsets[s + 1] += coupling_offsets[s] + 1;
      std::vector<Coupling> couplings(coupling_offsets[m]);
      std::vector<int> filled(coupling_offsets.begin(), coupling_offsets.end() - 1);
      for (int s = 0; s < m; ++s) {
        const Eigen::Matrix4d& g_ss = g.diagonal(s);
        couplings[filled[s]++] = {s, {g_ss(3, 0), g_ss(3, 1), g_ss(3, 2)}};
        g_tt.AddDiagonal(s, g_ss.bottomRightCorner<1, 1>());
      }
      for (const auto& block : g.lower()) {  // G(row, col) and its transpose G(col, row)
        const Eigen::Matrix4d& v = block.value;
        g_tt.AddPair(block.row, block.col, v.bottomRightCorner<1, 1>());
        couplings[filled[block.row]++] = {block.col, {v(3, 0), v(3, 1), v(3, 2)}};
        couplings[filled[block.col]++] = {block.row, {v(0, 3), v(1, 3), v(2, 3)}};
      }
      // In place: each right-hand side is read before its own value is written.
      MatrixXd x_tt = std::move(system.translation_bt);
      for (int s = 0; s < m; ++s) {
        const Coupling* begin = couplings.data() + coupling_offsets[s];
        const Coupling* end = couplings.data() + coupling_offsets[s + 1];
        double* rhs = x_tt.col(s).data();
        int col = 0;
        for (; col + 8 <= cols; col += 8) {
          Lanes4 sum0 = *AsLanes4(rhs + col), sum1 = *AsLanes4(rhs + col + 4);
          for (const Coupling* c = begin; c != end; ++c) {
            const double* x0 = nt_data + 3 * c->u * nt_stride + col;
            const double* x1 = x0 + nt_stride;
            const double* x2 = x1 + nt_stride;
            sum0 -= c->g[0] * *AsLanes4(x0) + c->g[1] * *AsLanes4(x1) + c->g[2] * *AsLanes4(x2);
            sum1 -= c->g[0] * *AsLanes4(x0 + 4) + c->g[1] * *AsLanes4(x1 + 4) +
                    c->g[2] * *AsLanes4(x2 + 4);
          }
          *AsLanes4(rhs + col) = sum0;
          *AsLanes4(rhs + col + 4) = sum1;
        }
        for (; col < cols; ++col) {
          double sum = rhs[col];
          for (const Coupling* c = begin; c != end; ++c) {
            const double* x0 = nt_data + 3 * c->u * nt_stride + col;
            sum -= c->g[0] * x0[0] + c->g[1] * x0[nt_stride] + c->g[2] * x0[2 * nt_stride];
          }
          rhs[col] = sum;
        }
      }
      auto factor = BlockCholesky<1>::Factor(g_tt, d.simd);
      if (!factor.ok()) return factor.status();
      const MatrixXd translations = factor->SolveTransposed(std::move(x_tt));
      for (int col = 0; col < cols; ++col) {
        for (int s = 0; s < m; ++s) x(4 * s + 3, col) = translations(s, col);
      }
    }
    return Status::Ok();
  });
}

}  // namespace motionlod::core::internal
