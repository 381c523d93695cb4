#include "core/internal/block_cholesky.h"

#include <Eigen/Cholesky>
#include <algorithm>
#include <bit>
#include <utility>

#include "core/internal/lanes.h"
#include "core/internal/simd_dispatch.h"

namespace motionlod::core {

namespace {

template <int B>
void MultiplyPanel(double* panel, const Eigen::Matrix<double, B, B>& m, Eigen::Index rows,
                   Eigen::Index column_stride) {
  PanelProduct<B, false>(panel, panel, m, rows, column_stride);
}

}  // namespace

template <int B>
BlockSymmetric<B>::BlockSymmetric(int block_count, size_t lower_capacity)
    : diagonal_(block_count, Block::Zero()), column_first_(block_count, -1) {
  lower_.reserve(lower_capacity);
  next_in_column_.reserve(lower_capacity);
}

template <int B>
typename BlockSymmetric<B>::Block& BlockSymmetric<B>::LowerAt(int row, int col) {
  for (int index = column_first_[col]; index >= 0; index = next_in_column_[index]) {
    if (lower_[index].row == row) return lower_[index].value;
  }
  next_in_column_.push_back(column_first_[col]);
  column_first_[col] = static_cast<int>(lower_.size());
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
StatusOr<BlockCholesky<B>> BlockCholesky<B>::Factor(const BlockSymmetric<B>& a, SimdChoice simd) {
  return RunWithSimd(simd, [&]() -> StatusOr<BlockCholesky<B>> {
    const int count = a.block_count();
    // Columns are indexed by A's blocks and eliminated from the last to the first, so a
    // block (r, s) of the factor has r < s: row r is eliminated after column s.
    BlockCholesky factor;
    factor.simd_ = simd;
    factor.columns_.resize(count);
    // The pattern first: column s holds row r < s where A has block (s, r) or the
    // elimination of a later column s' holding both r and s fills it in. One bit per row,
    // columns eliminated from the last, as below; each column's count of blocks gives
    // its place in below_.
    const size_t words = (static_cast<size_t>(count) + 63) / 64;
    std::vector<uint64_t> rows_of(words * count, 0);
    for (const auto& block : a.lower()) {
      rows_of[block.row * words + block.col / 64] |= uint64_t{1} << (block.col % 64);
    }
    for (int s = count - 1; s >= 0; --s) {
      const uint64_t* rows = &rows_of[s * words];
      for (size_t w = 0; w < words; ++w) {
        for (uint64_t bits = rows[w]; bits != 0; bits &= bits - 1) {
          const size_t r2 = 64 * w + static_cast<size_t>(std::countr_zero(bits));
          uint64_t* target = &rows_of[r2 * words];
          // Rows r1 < r2 of column s.
          for (size_t v = 0; v < r2 / 64; ++v) target[v] |= rows[v];
          if (r2 % 64 != 0) target[r2 / 64] |= rows[r2 / 64] & ((uint64_t{1} << (r2 % 64)) - 1);
        }
      }
    }
    uint32_t blocks = 0;
    for (int s = 0; s < count; ++s) {
      uint32_t column_blocks = 0;
      for (size_t w = 0; w < words; ++w) column_blocks += std::popcount(rows_of[s * words + w]);
      factor.columns_[s].begin = factor.columns_[s].end = blocks;
      blocks += column_blocks;
    }
    std::vector<std::pair<int, Block>>& below = factor.below_;
    below.resize(blocks);
    std::vector<Block> diagonal(count);
    for (int s = 0; s < count; ++s) diagonal[s] = a.diagonal(s);
    for (const auto& block : a.lower()) {
      below[factor.columns_[block.row].end++] = {block.col, block.value.transpose()};
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
      for (uint32_t e = column.begin; e < column.end; ++e) {
        below[e].second = below[e].second * column.diagonal_inverse.transpose();
      }
      // The Schur complement: A(r1, r2) -= L(r1, s) L(r2, s)^T for rows r1 <= r2 (r1 is
      // eliminated after r2), the fill created where A has no such block.
      for (uint32_t e2 = column.begin; e2 < column.end; ++e2) {
        const auto& [r2, l2] = below[e2];
        diagonal[r2].noalias() -= l2 * l2.transpose();
        Column& target = factor.columns_[r2];
        for (uint32_t e = target.begin; e < target.end; ++e)
          where[below[e].first] = static_cast<int>(e);
        for (uint32_t e1 = column.begin; e1 < column.end; ++e1) {
          const auto& [r1, l1] = below[e1];
          if (r1 >= r2) continue;
          if (where[r1] < 0) {
            where[r1] = static_cast<int>(target.end);
            below[target.end++] = {r1, Block::Zero()};
          }
          below[where[r1]].second.noalias() -= l1 * l2.transpose();
        }
        for (uint32_t e = target.begin; e < target.end; ++e) where[below[e].first] = -1;
      }
    }
    return factor;
  });
}

template <int B>
Eigen::MatrixXd BlockCholesky<B>::SolveTransposed(Eigen::MatrixXd bt) const {
  return RunWithSimd(simd_, [&]() -> Eigen::MatrixXd {
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
        for (uint32_t e = columns_[s].begin; e < columns_[s].end; ++e) {
          AddPanelProduct<B>(panel(below_[e].first), panel(s), -below_[e].second, rows, stride);
        }
      }
      for (int s = 0; s < count; ++s) {  // L^T w = z
        for (uint32_t e = columns_[s].begin; e < columns_[s].end; ++e) {
          AddPanelProduct<B>(panel(s), panel(below_[e].first), -below_[e].second.transpose(), rows,
                             stride);
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
