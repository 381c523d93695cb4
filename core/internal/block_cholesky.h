// Sparse symmetric positive definite systems made of B x B blocks, as the normal matrices
// of the levels are (B = 4: one block per pair of kept joints sharing vertices; B = 1:
// the translations of the rigid re-solve), and their Cholesky factors.
//
// Why not Eigen's SimplicialLLT: the systems are small (4m rows, m kept joints) and solved
// for thousands of right-hand sides (3T, every frame's coordinates). A scalar sparse
// factor spends its time on the fill-reducing ordering, the symbolic analysis and
// triplet assembly, then updates one right-hand-side column per nonzero; a block factor
// needs no ordering search (see BlockCholesky) and updates B columns per block at once,
// reading each panel of right-hand sides a quarter as often.
#pragma once

#include <Eigen/Core>
#include <cstddef>
#include <cstdint>
#include <utility>
#include <vector>

#include "base/status.h"
#include "core/simd.h"

namespace motionlod::core {

using ::motionlod::Status;
using ::motionlod::StatusOr;

// Panels of B columns of `rows` doubles each, column c at column_stride * c from the
// first: row i of panel_r becomes M times row i of panel_q, added to what it holds with
// kAccumulate. Iteration i reads and writes row i only, so the panels may be the same one
// (the diagonal steps of the solves) and the loop vectorises over the rows. Inline, so
// that a caller's AVX2 version (core/internal/simd_dispatch.h) runs it 256 bits wide.
template <int B, bool kAccumulate>
inline void PanelProduct(double* panel_r, const double* panel_q,
                         const Eigen::Matrix<double, B, B>& m, Eigen::Index rows,
                         Eigen::Index column_stride) {
  double coefficient[B][B];
  for (int c = 0; c < B; ++c) {
    for (int a = 0; a < B; ++a) coefficient[c][a] = m(c, a);
  }
#pragma GCC ivdep
  for (Eigen::Index i = 0; i < rows; ++i) {
    double q[B];
    for (int a = 0; a < B; ++a) q[a] = panel_q[a * column_stride + i];
    for (int c = 0; c < B; ++c) {
      double sum = kAccumulate ? panel_r[c * column_stride + i] : 0.0;
      for (int a = 0; a < B; ++a) sum += coefficient[c][a] * q[a];
      panel_r[c * column_stride + i] = sum;
    }
  }
}

// Row i of panel_r gains M times row i of panel_q (the panels must not overlap).
template <int B>
inline void AddPanelProduct(double* panel_r, const double* panel_q,
                            const Eigen::Matrix<double, B, B>& m, Eigen::Index rows,
                            Eigen::Index column_stride) {
  PanelProduct<B, true>(panel_r, panel_q, m, rows, column_stride);
}

template <int B>
class BlockSymmetric {
 public:
  using Block = Eigen::Matrix<double, B, B>;
  // A block (row, col), row > col; block (col, row) is its transpose.
  struct LowerBlock {
    int row = 0, col = 0;
    Block value;
  };

  // `lower_capacity`: how many off-diagonal blocks to make room for (a bound saves the
  // list's regrowth, the normal matrices being built once per level).
  explicit BlockSymmetric(int block_count = 0, size_t lower_capacity = 0);
  int block_count() const { return static_cast<int>(diagonal_.size()); }

  // Adds v to block (s, u) and v^T to block (u, s): v + v^T where s == u.
  void AddPair(int s, int u, const Block& v);
  // Adds a symmetric v to the diagonal block s.
  void AddDiagonal(int s, const Block& v);
  // Adds lambda to every diagonal coefficient.
  void AddIdentity(double lambda);
  double Trace() const;

  const Block& diagonal(int s) const { return diagonal_[s]; }
  const std::vector<LowerBlock>& lower() const { return lower_; }

 private:
  Block& LowerAt(int row, int col);

  std::vector<Block> diagonal_;
  std::vector<LowerBlock> lower_;
  // Each column's blocks as a list through lower_: its first block's index, and each
  // block's next in its column (-1 ends a list). Two lists in all, where a list per
  // column was a block of its own, grown block by block.
  std::vector<int> column_first_, next_in_column_;
};

// A = L L^T with A's blocks eliminated from the last to the first. For a skeleton's slots,
// which are in topological order (parents first), that is leaves first: the normal
// matrix of a tree (joints coupled to their parent only) then factors without fill, and
// the couplings a vertex weighted to three or more joints adds fill only among their
// ancestors, so no ordering search pays for itself.
template <int B>
class BlockCholesky {
 public:
  using Block = Eigen::Matrix<double, B, B>;

  // Fails (kInternal) when A is not numerically positive definite. `simd`: the machine
  // version of the factor and of its solves (core/simd.h).
  static StatusOr<BlockCholesky> Factor(const BlockSymmetric<B>& a,
                                        SimdChoice simd = SimdChoice::kWidest);

  // X = A^-1 Y for the right-hand sides given transposed, bt = Y^T (cols x B blocks);
  // returns X (B blocks x cols). The right-hand sides go through in row chunks whose
  // panels stay in the L2 cache for the whole forward and backward pass, solved where
  // they are (bt is taken by value: move it in where the caller is done with it; a copy
  // was a pass over all of it, and a write to lines the other thread may have held).
  Eigen::MatrixXd SolveTransposed(Eigen::MatrixXd bt) const;

 private:
  struct Column {
    Block diagonal_inverse;  // L_qq^-1, lower triangular
    uint32_t begin = 0, end = 0;  // its blocks in below_
  };
  SimdChoice simd_ = SimdChoice::kWidest;
  std::vector<Column> columns_;  // column q is block count - 1 - q of A
  // Every column's (r, L_rq), r > q in elimination order: column s's in [begin, end) of
  // its Column, in the order of A's blocks, then of the fill. Sized by a pass over the
  // pattern alone before the numbers (one block for all, where a list per column grew
  // with its fill).
  std::vector<std::pair<int, Block>> below_;
};

}  // namespace motionlod::core
