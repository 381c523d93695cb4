#include "core/block_cholesky.h"

#include <Eigen/Cholesky>
#include <algorithm>
#include <utility>

#include "base/lanes.h"
#include "base/simd.h"

namespace motionlod::core {

namespace {

template <int B>
void MultiplyPanel(double* panel, const Eigen::Matrix<double, B, B>& m, Eigen::Index rows,
                   Eigen::Index column_stride) {
  PanelProduct<B, false>(panel, panel, m, rows, column_stride);
}

}  // namespace

template <int B>
BlockSymmetric<B>::BlockSymmetric(int block_count)
    : diagonal_(block_count, Block::Zero()), column_blocks_(block_count) {}

template <int B>
typename BlockSymmetric<B>::Block& BlockSymmetric<B>::LowerAt(int row, int col) {
  for (int index : column_blocks_[col]) {
    if (lower_[index].row == row) return lower_[index].value;
  }
  column_blocks_[col].push_back(static_cast<int>(lower_.size()));
  lower_.push_back({row, col, Block::Zero()});
  return lower_.back().value;
}

template <int B>
void BlockSymmetric<B>::AddPair(int s, int u, const Block& v) {
  if (s == u) {
    diagonal_[s] += v + v.transpose();
  } else if (s > u) {
    LowerAt(s, u) += v;
  } else {
    LowerAt(u, s) += v.transpose();
  }
}

template <int B>
void BlockSymmetric<B>::AddDiagonal(int s, const Block& v) {
  diagonal_[s] += v;
}

template <int B>
void BlockSymmetric<B>::AddIdentity(double lambda) {
  for (Block& d : diagonal_) d.diagonal().array() += lambda;
}

template <int B>
double BlockSymmetric<B>::Trace() const {
  double trace = 0;
  for (const Block& d : diagonal_) trace += d.trace();
  return trace;
}

template <int B>
StatusOr<BlockCholesky<B>> BlockCholesky<B>::Factor(const BlockSymmetric<B>& a) {
  return RunWithWidestSimd([&]() -> StatusOr<BlockCholesky<B>> {
    const int count = a.block_count();
    // Columns are indexed by A's blocks and eliminated from the last to the first, so a
    // block (r, s) of the factor has r < s: row r is eliminated after column s.
    BlockCholesky factor;
    factor.columns_.resize(count);
    std::vector<Block> diagonal(count);
    for (int s = 0; s < count; ++s) diagonal[s] = a.diagonal(s);
    for (const auto& block : a.lower()) {
      factor.columns_[block.row].below.emplace_back(block.col, block.value.transpose());
    }
    std::vector<int> where(count, -1);
    for (int s = count - 1; s >= 0; --s) {
      Column& column = factor.columns_[s];
      const Eigen::LLT<Block> llt(diagonal[s]);
      const Block l = llt.matrixL();
      if (llt.info() != Eigen::Success || !l.allFinite()) {
        return Status(StatusCode::kInternal, "a normal matrix is not positive definite");
      }
      column.diagonal_inverse = l.template triangularView<Eigen::Lower>().solve(Block::Identity());
      for (auto& [r, value] : column.below) value = value * column.diagonal_inverse.transpose();
      // The Schur complement: A(r1, r2) -= L(r1, s) L(r2, s)^T for rows r1 <= r2 (r1 is
      // eliminated after r2), the fill created where A has no such block.
      for (const auto& [r2, l2] : column.below) {
        diagonal[r2].noalias() -= l2 * l2.transpose();
        auto& target = factor.columns_[r2].below;
        for (size_t e = 0; e < target.size(); ++e) where[target[e].first] = static_cast<int>(e);
        for (const auto& [r1, l1] : column.below) {
          if (r1 >= r2) continue;
          if (where[r1] < 0) {
            where[r1] = static_cast<int>(target.size());
            target.emplace_back(r1, Block::Zero());
          }
          target[where[r1]].second.noalias() -= l1 * l2.transpose();
        }
        for (const auto& entry : target) where[entry.first] = -1;
      }
    }
    return factor;
  });
}

template <int B>
Eigen::MatrixXd BlockCholesky<B>::SolveTransposed(Eigen::MatrixXd bt) const {
  return RunWithWidestSimd([&]() -> Eigen::MatrixXd {
    const int count = static_cast<int>(columns_.size());
    const Eigen::Index dim = static_cast<Eigen::Index>(B) * count;
    const Eigen::Index cols = bt.rows();
    // About 1 MiB of panels per chunk, a multiple of 8 rows (whole vectors).
    constexpr Eigen::Index kChunkBytes = Eigen::Index{1} << 20;
    const Eigen::Index chunk = std::min(
        cols,
        std::max<Eigen::Index>(8, kChunkBytes / (8 * std::max<Eigen::Index>(dim, 1)) / 8 * 8));
    Eigen::MatrixXd x(dim, cols);
    const Eigen::Index stride = cols;
    for (Eigen::Index first = 0; first < cols; first += chunk) {
      const Eigen::Index rows = std::min(chunk, cols - first);
      auto panel = [&](int s) {
        return bt.data() + static_cast<Eigen::Index>(B) * s * stride + first;
      };
      for (int s = count - 1; s >= 0; --s) {  // L z = y
        MultiplyPanel<B>(panel(s), columns_[s].diagonal_inverse, rows, stride);
        for (const auto& [r, l] : columns_[s].below)
          AddPanelProduct<B>(panel(r), panel(s), -l, rows, stride);
      }
      for (int s = 0; s < count; ++s) {  // L^T w = z
        for (const auto& [r, l] : columns_[s].below) {
          AddPanelProduct<B>(panel(s), panel(r), -l.transpose(), rows, stride);
        }
        MultiplyPanel<B>(panel(s), columns_[s].diagonal_inverse.transpose(), rows, stride);
      }
      TransposeDoubles(bt.data() + first, stride, rows, dim, x.data() + first * dim, dim);
    }
    return x;
  });
}

template class BlockSymmetric<1>;
template class BlockSymmetric<4>;
template class BlockCholesky<1>;
template class BlockCholesky<4>;

}  // namespace motionlod::core
