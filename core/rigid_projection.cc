#include "core/internal/rigid_projection.h"

#include <algorithm>
#include <vector>

#include <Eigen/Eigenvalues>

#include "core/internal/lanes.h"
#include "core/internal/simd_dispatch.h"
#include "core/internal/skeleton_drift.h"
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
inline bool AllRotationsKernel(const MatrixXd& x, double tolerance) {
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
      const auto rotation = (error_squared <= tolerance * tolerance) & (determinant > 0);
      for (int j = 0; j < 4; ++j) {
        if (rotation[j] == 0) return false;
      }
    }
  }
  return true;
}

// The right-hand sides of the translations' re-solve with the rotations of x fixed,
// b_T - G_TN x_N, transposed (3T x m), from b_T^T (bt) in place.
// G_TT and G_TN keep G's block sparsity: each coefficient of G_TN subtracts one contiguous
// column of all frames.
class TranslationSystem {
 public:
  explicit TranslationSystem(const BlockSymmetric<4>& g) : m_(g.block_count()), g_tt_(m_, g.lower().size()) {
    // Row s of G_TN as its couplings to the slots u of its blocks (G_su(3, 0..2): the
    // diagonal block first, then the others in G's order), so that each slot's
    // right-hand sides are summed in registers, eight frames' columns at a time, and
    // stored once (a pass over the blocks read and wrote every right-hand side once per
    // block).
    offsets_.assign(m_ + 1, 0);
    for (const auto& block : g.lower()) {
      ++offsets_[block.row + 1];
      ++offsets_[block.col + 1];
    }
    for (int s = 0; s < m_; ++s) offsets_[s + 1] += offsets_[s] + 1;
    couplings_.resize(offsets_[m_]);
    std::vector<int> filled(offsets_.begin(), offsets_.end() - 1);
    for (int s = 0; s < m_; ++s) {
      const Eigen::Matrix4d& g_ss = g.diagonal(s);
      couplings_[filled[s]++] = {s, {g_ss(3, 0), g_ss(3, 1), g_ss(3, 2)}};
      g_tt_.AddDiagonal(s, g_ss.bottomRightCorner<1, 1>());
    }
    for (const auto& block : g.lower()) {  // G(row, col) and its transpose G(col, row)
      const Eigen::Matrix4d& v = block.value;
      g_tt_.AddPair(block.row, block.col, v.bottomRightCorner<1, 1>());
      couplings_[filled[block.row]++] = {block.col, {v(3, 0), v(3, 1), v(3, 2)}};
      couplings_[filled[block.col]++] = {block.row, {v(0, 3), v(1, 3), v(2, 3)}};
    }
  }

  const BlockSymmetric<1>& g_tt() const { return g_tt_; }

  // b_T^T - x_N^T G_TN^T in place of bt (3T x m).
  void SubtractRotationTerms(const MatrixXd& x, MatrixXd& bt) const {
    const int cols = static_cast<int>(bt.rows());
    // x_N^T: the rotations' rows of x, transposed.
    MatrixXd x_nt(cols, 3 * m_);
    TransposeRotationRows(x, x_nt);
    const Eigen::Index nt_stride = x_nt.rows();
    const double* nt_data = x_nt.data();
    for (int s = 0; s < m_; ++s) {
      const Coupling* begin = couplings_.data() + offsets_[s];
      const Coupling* end = couplings_.data() + offsets_[s + 1];
      double* rhs = bt.col(s).data();
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
  }

 private:
  struct Coupling {
    int u = 0;
    double g[3] = {0, 0, 0};
  };
  int m_;
  BlockSymmetric<1> g_tt_;
  std::vector<int> offsets_;
  std::vector<Coupling> couplings_;
};

// a y for a symmetric m x m matrix a and y m x 3T.
MatrixXd Times(const BlockSymmetric<1>& a, const MatrixXd& y) {
  MatrixXd out(y.rows(), y.cols());
  for (int s = 0; s < a.block_count(); ++s) out.row(s) = a.diagonal(s)(0, 0) * y.row(s);
  for (const auto& b : a.lower()) {
    out.row(b.row) += b.value(0, 0) * y.row(b.col);
    out.row(b.col) += b.value(0, 0) * y.row(b.row);
  }
  return out;
}

// The kept joints' positions P (m x 3T, row s, column 3t + c) nearest to `target` in
// the metric of the translations, tr((P - P*)^T G_TT (P - P*)), with every bone length
// | |P_s - P_q| - L_s(t) | within `tolerance` of the original's (q = parent_slots[s],
// L = OriginalBoneLengths). A penalty mu |P_s - P_q - e_s|^2 on each bone, e_s its current
// vector moved into the allowed shell, alternated with the linear solve for P
// (G_TT + mu A^T A, A the bones' incidence: a tree Laplacian, so the factor keeps G_TT's
// sparsity) while mu grows from trace(G_TT)/m by kPenaltyGrowth; then each bone, from the
// root down, moved into its shell exactly (a short move: the penalty left it near).
StatusOr<MatrixXd> ConstrainPositions(const PreparedData& d, const ReducedSkeleton& level,
                                      const BlockSymmetric<1>& g_tt, const MatrixXd& target,
                                      const MatrixXd& lengths, double tolerance) {
  constexpr int kPenaltySteps = 4, kIterationsPerStep = 2;
  constexpr double kPenaltyGrowth = 10;
  const int m = level.kept_count();
  const int frames = d.frames;
  const MatrixXd g_target = Times(g_tt, target);
  // Bone s's vector in frame t with its length clamped into [L - tolerance, L + tolerance].
  const auto allowed_bone = [&](const MatrixXd& positions, int s, int t) -> Eigen::RowVector3d {
    const Eigen::RowVector3d bone =
        positions.block<1, 3>(s, 3 * t) - positions.block<1, 3>(level.parent_slots[s], 3 * t);
    const double length = bone.norm();
    const double allowed =
        std::clamp(length, lengths(s, t) - tolerance, lengths(s, t) + tolerance);
    // A bone of zero length has no direction to keep: any one is as near.
    return length > 0 ? Eigen::RowVector3d(bone * (allowed / length))
                      : Eigen::RowVector3d(allowed, 0, 0);
  };
  MatrixXd positions = target;
  double mu = g_tt.Trace() / m;
  for (int step = 0; step < kPenaltySteps; ++step, mu *= kPenaltyGrowth) {
    BlockSymmetric<1> a = g_tt;
    const Eigen::Matrix<double, 1, 1> weight = Eigen::Matrix<double, 1, 1>::Constant(mu);
    for (int s = 1; s < m; ++s) {
      a.AddDiagonal(s, weight);
      a.AddDiagonal(level.parent_slots[s], weight);
      a.AddPair(s, level.parent_slots[s], -weight);
    }
    auto factor = BlockCholesky<1>::Factor(a, d.simd);
    if (!factor.ok()) return factor.status();
    for (int iteration = 0; iteration < kIterationsPerStep; ++iteration) {
      MatrixXd rhs = g_target;
      for (int s = 1; s < m; ++s) {
        for (int t = 0; t < frames; ++t) {
          const Eigen::RowVector3d pull = mu * allowed_bone(positions, s, t);
          rhs.block<1, 3>(s, 3 * t) += pull;
          rhs.block<1, 3>(level.parent_slots[s], 3 * t) -= pull;
        }
      }
      positions = factor->SolveTransposed(rhs.transpose());
    }
  }
  // Slots are in topological order: each parent is final before its children move.
  for (int s = 1; s < m; ++s) {
    for (int t = 0; t < frames; ++t) {
      positions.block<1, 3>(s, 3 * t) =
          positions.block<1, 3>(level.parent_slots[s], 3 * t) + allowed_bone(positions, s, t);
    }
  }
  return positions;
}

// G's blocks by slot: for slot s, each (u, G_su) with a block, G_ss first.
using BlockRows = std::vector<std::vector<std::pair<int, Eigen::Matrix4d>>>;
BlockRows BlocksBySlot(const BlockSymmetric<4>& g) {
  BlockRows rows(g.block_count());
  for (int s = 0; s < g.block_count(); ++s) rows[s].push_back({s, g.diagonal(s)});
  for (const auto& block : g.lower()) {
    rows[block.row].push_back({block.col, block.value});
    rows[block.col].push_back({block.row, block.value.transpose()});
  }
  return rows;
}

// The rotations' step with the positions fixed. In the coordinates y_s = [N_s; P_s^T]
// (N_s = R_s^T, P_s = R_s p0_s + T_s the joint's position), x_s = W_s y_s with
// W_s = [I 0; -p0_s^T 1], and E is tr((Y - Y_ls)^T H (Y - Y_ls)) + const with
// H = W^T G W, Y_ls the least-squares solution's. Slot by slot, the others fixed, E in N_s
// is tr(N^T A_s N) - 2 tr(N^T C) (A_s = H_ss's rotation block, 3x3); on rotations,
// |N|_F^2 = 3, so the majoriser with A_s <= lambda_s I is minimised by
// N_s = polar(lambda_s N_s - Z_s), Z_s = (H (Y - Y_ls))_Ns = (W_s^T (G (X - X_ls))_s)_rows 0..2,
// a step that never raises E (majorise-minimise). Every frame of a slot at once.
void RotationSweeps(const PreparedData& d, const BlockRows& g_rows,
                    const std::vector<double>& lambda, const std::vector<Eigen::Vector3d>& p0,
                    const MatrixXd& x_ls, const MatrixXd& positions, int sweeps, MatrixXd& x) {
  const int m = static_cast<int>(g_rows.size());
  const Eigen::Index cols = x.cols();
  MatrixXd difference = x - x_ls;
  Eigen::Matrix<double, 4, Eigen::Dynamic> gradient(4, cols), step(4, cols);
  step.row(3).setZero();
  std::vector<double*> blocks(d.frames);
  for (int t = 0; t < d.frames; ++t) blocks[t] = step.data() + 12 * t;
  for (int sweep = 0; sweep < sweeps; ++sweep) {
    for (int s = 0; s < m; ++s) {
      gradient.setZero();
      for (const auto& [u, g_su] : g_rows[s]) gradient.noalias() += g_su * difference.middleRows<4>(4 * u);
      step.topRows<3>() = lambda[s] * x.middleRows<3>(4 * s) - gradient.topRows<3>() +
                          p0[s] * gradient.row(3);
      NearestRotations(blocks, 4, d.simd);
      x.middleRows<3>(4 * s) = step.topRows<3>();
      // T_s = P_s - R_s p0_s: the position stays.
      x.row(4 * s + 3) = positions.row(s) - p0[s].transpose() * x.middleRows<3>(4 * s);
      difference.middleRows<4>(4 * s) = x.middleRows<4>(4 * s) - x_ls.middleRows<4>(4 * s);
    }
  }
}

}  // namespace

bool AllRotations(const MatrixXd& x, SimdChoice simd, double tolerance) {
  return RunWithSimd(simd, [&] { return AllRotationsKernel(x, tolerance); });
}

Status ProjectOnRotations(const PreparedData& d, const ReducedSkeleton& level, LevelSystem& system) {
  return RunWithSimd(d.simd, [&]() -> Status {
    // Rounds of the rotations' and the positions' steps, and sweeps of the slots in each
    // rotations' step: on the levels of five real characters a third round and a third sweep
    // still lowered the vertex error, more did not measurably.
    constexpr int kRounds = 3, kSweeps = 3;
    // Bone lengths are held within this fraction of the height of the original's: what the
    // rigid variants promise, less a margin. Each bone held closer costs vertex error
    // (exact lengths cost up to 7% of the height more in the maximum on CesiumMan).
    constexpr double kBoneLengthTolerance = 0.95 * kRigidBoneLengthDriftPct / 100;
    const int m = system.g.block_count();
    MatrixXd& x = system.x;
    const MatrixXd x_ls = d.settings.resolve_rigid_translation ? x : MatrixXd();
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
    if (!d.settings.resolve_rigid_translation) return Status::Ok();

    const TranslationSystem translations(system.g);
    auto factor = BlockCholesky<1>::Factor(translations.g_tt(), d.simd);
    if (!factor.ok()) return factor.status();
    const MatrixXd translation_bt = std::move(system.translation_bt);
    const MatrixXd lengths = OriginalBoneLengths(d, level);
    const double tolerance = kBoneLengthTolerance * d.character->height();
    std::vector<Eigen::Vector3d> p0(m);
    std::vector<double> lambda(m);
    for (int s = 0; s < m; ++s) {
      p0[s] = d.character->skeleton().bind_world[level.kept_joints[s]].col(3);
      Eigen::Matrix4d w = Eigen::Matrix4d::Identity();
      w.block<1, 3>(3, 0) = -p0[s].transpose();
      const Eigen::Matrix3d a = (w.transpose() * system.g.diagonal(s) * w).topLeftCorner<3, 3>();
      lambda[s] = Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(a, Eigen::EigenvaluesOnly)
                      .eigenvalues()
                      .maxCoeff();
    }
    const BlockRows g_rows = BlocksBySlot(system.g);
    MatrixXd positions;
    for (int round = 0; round < kRounds; ++round) {
      if (round > 0) RotationSweeps(d, g_rows, lambda, p0, x_ls, positions, kSweeps, x);
      // The positions' step: the translations re-solved with the rotations fixed, the
      // exact minimiser of E over them, x_T = G_TT^-1 (b_T - G_TN x_N); then the positions
      // they give moved into the bone lengths' shells, T = P - R p0.
      MatrixXd bt = translation_bt;
      translations.SubtractRotationTerms(x, bt);
      const MatrixXd resolved = factor->SolveTransposed(std::move(bt));
      for (int s = 0; s < m; ++s) x.row(4 * s + 3) = resolved.row(s);
      const MatrixXd unconstrained = KeptJointPositions(d, x, level);
      auto constrained =
          ConstrainPositions(d, level, translations.g_tt(), unconstrained, lengths, tolerance);
      if (!constrained.ok()) return constrained.status();
      positions = *std::move(constrained);
      x(Eigen::seqN(3, m, 4), Eigen::all) += positions - unconstrained;
    }
    return Status::Ok();
  });
}

}  // namespace motionlod::core::internal
