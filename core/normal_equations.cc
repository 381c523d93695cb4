#include "core/internal/normal_equations.h"

#include <algorithm>

#include "core/internal/lanes.h"
#include "core/internal/simd_dispatch.h"

namespace motionlod::core::internal {
namespace {

using Eigen::MatrixXd;

// Row i of a panel of B^T (4 columns of kt.cols() rows each, one after the other) gains
// M times rows 4j to 4j + 3 of kt's column i, M symmetric: K_j^T M in the right-hand sides'
// transposed layout, read from Kt itself. Four columns at a time, each column's four rows
// (four contiguous doubles) transposed as whole vectors; the sums are PanelProduct's, in
// its order. Inline, so that a caller's AVX2 version (core/internal/simd_dispatch.h) runs it 256 bits wide.
inline void AddKtProduct(double* panel, const MatrixXd& kt, int j, const Eigen::Matrix4d& m) {
  const Eigen::Index rows = kt.cols(), stride = kt.rows();
  const double* source = kt.data() + 4 * j;
  double coefficient[4][4];
  for (int c = 0; c < 4; ++c) {
    for (int a = 0; a < 4; ++a) coefficient[c][a] = m(c, a);
  }
  Eigen::Index i = 0;
  for (; i + 4 <= rows; i += 4) {
    Lanes4 columns[4], q[4];  // q[a]: row 4j + a of the columns i to i + 3
    for (int f = 0; f < 4; ++f) columns[f] = *AsLanes4(source + (i + f) * stride);
    Transpose4(columns, q);
    for (int c = 0; c < 4; ++c) {
      Lanes4 sum = *AsLanes4(panel + c * rows + i);
      for (int a = 0; a < 4; ++a) sum += coefficient[c][a] * q[a];
      *AsLanes4(panel + c * rows + i) = sum;
    }
  }
  for (; i < rows; ++i) {
    const double* q = source + i * stride;
    for (int c = 0; c < 4; ++c) {
      double sum = panel[c * rows + i];
      for (int a = 0; a < 4; ++a) sum += coefficient[c][a] * q[a];
      panel[c * rows + i] = sum;
    }
  }
}

}  // namespace

StatusOr<LevelSystem> SolveNormalEquations(const PreparedData& d, const ReducedSkeleton& level) {
  if (Status status = ValidateLevel(level, d.n); !status.ok()) return status;
  return RunWithSimd(d.simd, [&]() -> StatusOr<LevelSystem> {
    const int n = d.n;
    const int m = level.kept_count();
    const int dim = 4 * m;
    const int cols = 3 * d.frames;
    const std::vector<int>& phi = level.joint_to_slot;
    LevelSystem system;

    // G = P Q P^T + S J S^T + lambda I.
    BlockSymmetric<4>& g = system.g;
    g = BlockSymmetric<4>(m, d.pairs.size());  // at most a block per joint pair
    for (size_t q = 0; q < d.pairs.size(); ++q) {
      const auto [k, l] = d.pairs[q];
      if (k == l) {
        g.AddDiagonal(phi[k], d.pair_fit[q]);
      } else {
        g.AddPair(phi[k], phi[l], d.pair_fit[q]);
      }
    }
    for (int s = 0; s < m; ++s) g.AddDiagonal(s, d.joint_fit[level.kept_joints[s]]);
    const double trace = g.Trace();
    const double lambda = d.settings.regularization * (trace > 0 ? trace / dim : 1.0);
    g.AddIdentity(lambda);

    // B^T = (P F + S (J + lambda I) Kt)^T, slot by slot: its 4 columns of all frames (one
    // contiguous panel) start as F of its kept joint, gain F of each joint merged into it
    // (ancestors come first: the same sums in the same order as from zero), then
    // (J + lambda I) Kt of its kept joint. Plain loops over whole panels, which the AVX2
    // version runs 256 bits wide; Eigen's column blocks kept 128-bit packets.
    MatrixXd& bt = system.bt;
    bt.resize(cols, dim);
    const Eigen::Index panel = 4 * static_cast<Eigen::Index>(cols);
    for (int s = 0; s < m; ++s) {
      std::copy_n(d.ft.col(4 * level.kept_joints[s]).data(), panel, bt.col(4 * s).data());
    }
    for (int k = 0; k < n; ++k) {
      if (level.kept_joints[phi[k]] == k) continue;
      double* __restrict target = bt.col(4 * phi[k]).data();
      const double* source = d.ft.col(4 * k).data();
      for (Eigen::Index i = 0; i < panel; ++i) target[i] += source[i];
    }
    for (int s = 0; s < m; ++s) {
      const int j = level.kept_joints[s];
      AddKtProduct(bt.col(4 * s).data(), d.kt, j,
                   d.joint_fit[j] + lambda * Eigen::Matrix4d::Identity());
    }

    if (IsRigid(d.settings.variant) && d.settings.resolve_rigid_translation) {
      system.translation_bt.resize(cols, m);
      for (int s = 0; s < m; ++s) system.translation_bt.col(s) = bt.col(4 * s + 3);
    }
    if (m == n) {
      // Nothing removed: the original matrices leave no residual and are what the
      // regulariser pulls towards, so they are the exact minimiser (SolveVariant skips the
      // system altogether where the level needs nothing else).
      system.x = d.kt;
      return system;
    }
    // G is block-sparse (kept joints that share vertices) and nearly a tree: its block
    // Cholesky factor solves the 3T right-hand sides in time nearly linear in m instead of
    // quadratic.
    auto factor = BlockCholesky<4>::Factor(g, d.simd);
    if (!factor.ok()) return factor.status();
    system.x = factor->SolveTransposed(std::move(bt));
    return system;
  });
}

}  // namespace motionlod::core::internal
