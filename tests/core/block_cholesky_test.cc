#include "core/internal/block_cholesky.h"

#include <random>

#include <Eigen/Cholesky>
#include <gtest/gtest.h>

namespace motionlod::core {
namespace {

// A symmetric positive definite block matrix with the couplings given, and its dense copy.
template <int B>
struct Fixture {
  BlockSymmetric<B> sparse;
  Eigen::MatrixXd dense;
};

template <int B>
Fixture<B> MakeSystem(int count, const std::vector<std::pair<int, int>>& couplings, unsigned seed) {
  using Block = Eigen::Matrix<double, B, B>;
  std::mt19937 random(seed);
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  const auto random_block = [&] {
    Block v;
    for (int r = 0; r < B; ++r) {
      for (int c = 0; c < B; ++c) v(r, c) = uniform(random);
    }
    return v;
  };
  Fixture<B> f{BlockSymmetric<B>(count), Eigen::MatrixXd::Zero(B * count, B * count)};
  // Diagonal dominance makes it positive definite whatever the couplings.
  for (int s = 0; s < count; ++s) {
    const Block v = random_block();
    const Block d = v * v.transpose() + (4.0 * B * (couplings.size() + 1)) * Block::Identity();
    f.sparse.AddDiagonal(s, d);
    f.dense.template block<B, B>(B * s, B * s) += d;
  }
  for (const auto& [s, u] : couplings) {
    const Block v = random_block();
    f.sparse.AddPair(s, u, v);
    f.dense.template block<B, B>(B * s, B * u) += v;
    f.dense.template block<B, B>(B * u, B * s) += v.transpose();
  }
  return f;
}

template <int B>
void ExpectSolvesLikeDense(const Fixture<B>& f, int right_hand_sides) {
  const Eigen::MatrixXd bt = Eigen::MatrixXd::Random(right_hand_sides, f.dense.rows());
  auto factor = BlockCholesky<B>::Factor(f.sparse);
  ASSERT_TRUE(factor.ok()) << factor.status().ToString();
  const Eigen::MatrixXd x = factor->SolveTransposed(bt);
  const Eigen::MatrixXd expected = f.dense.llt().solve(bt.transpose());
  ASSERT_EQ(x.rows(), expected.rows());
  ASSERT_EQ(x.cols(), expected.cols());
  EXPECT_LE((x - expected).norm(), 1e-12 * expected.norm());
  EXPECT_LE((f.dense * x - bt.transpose()).norm(), 1e-12 * bt.norm());
}

TEST(BlockCholesky, SolvesATreeLikeTheDenseFactor) {
  // A chain with branches, as a skeleton's slots: every block coupled to its parent.
  const std::vector<std::pair<int, int>> tree = {{1, 0}, {2, 1}, {3, 2}, {4, 1}, {5, 4}, {6, 0}, {7, 6}};
  ExpectSolvesLikeDense(MakeSystem<4>(8, tree, 1), 37);
  ExpectSolvesLikeDense(MakeSystem<1>(8, tree, 2), 37);
}

TEST(BlockCholesky, SolvesWithFillAndCouplingsGivenInEitherOrder) {
  // Siblings coupled to each other and blocks coupled to their grandparents: eliminating
  // 4 fills (3, 1), then 3 fills (2, 0); (0, 3) is given upper, (2, 2) as a pair within
  // one block.
  const std::vector<std::pair<int, int>> couplings = {{1, 0}, {2, 1}, {3, 2}, {5, 3}, {5, 2},
                                                      {4, 3}, {4, 1}, {0, 3}, {2, 2}};
  ExpectSolvesLikeDense(MakeSystem<4>(6, couplings, 3), 5);
  ExpectSolvesLikeDense(MakeSystem<1>(6, couplings, 4), 5);
}

TEST(BlockCholesky, ChunksLongRightHandSides) {
  // 40 blocks of 4 (160 rows) and 2000 right-hand sides: several row chunks of the
  // right-hand sides, the last one partial.
  std::vector<std::pair<int, int>> couplings;
  for (int s = 1; s < 40; ++s) couplings.emplace_back(s, (s - 1) / 2);
  ExpectSolvesLikeDense(MakeSystem<4>(40, couplings, 5), 2000);
}

TEST(BlockCholesky, FillsAcrossManyWordsOfItsPattern) {
  // 150 blocks (a pattern of three 64-bit words a column): a binary tree with couplings
  // to grandparents and a few long-range ones, whose fill crosses word boundaries (rows
  // 63, 64, 127 and 128 among them).
  std::vector<std::pair<int, int>> couplings;
  for (int s = 1; s < 150; ++s) {
    couplings.emplace_back(s, (s - 1) / 2);
    if (s > 2) couplings.emplace_back(s, ((s - 1) / 2 - 1) / 2);
  }
  for (const auto& [s, u] : std::vector<std::pair<int, int>>{
           {149, 3}, {130, 64}, {128, 63}, {127, 0}, {100, 65}, {65, 64}}) {
    couplings.emplace_back(s, u);
  }
  ExpectSolvesLikeDense(MakeSystem<4>(150, couplings, 7), 9);
  ExpectSolvesLikeDense(MakeSystem<1>(150, couplings, 8), 9);
}

TEST(BlockCholesky, RejectsAMatrixThatIsNotPositiveDefinite) {
  BlockSymmetric<4> a(2);
  a.AddDiagonal(0, Eigen::Matrix4d::Identity());
  a.AddDiagonal(1, Eigen::Matrix4d::Identity());
  a.AddPair(1, 0, 2.0 * Eigen::Matrix4d::Identity());  // [[I, 2I], [2I, I]] is indefinite
  EXPECT_FALSE(BlockCholesky<4>::Factor(a).ok());
  BlockSymmetric<1> nan(1);
  nan.AddDiagonal(0, Eigen::Matrix<double, 1, 1>(std::nan("")));
  EXPECT_FALSE(BlockCholesky<1>::Factor(nan).ok());
}

TEST(BlockSymmetric, SumsRepeatedBlocksAndReportsTheTrace) {
  BlockSymmetric<1> a(3);
  a.AddDiagonal(0, Eigen::Matrix<double, 1, 1>(2.0));
  a.AddPair(2, 0, Eigen::Matrix<double, 1, 1>(1.5));
  a.AddPair(0, 2, Eigen::Matrix<double, 1, 1>(0.5));
  a.AddPair(1, 1, Eigen::Matrix<double, 1, 1>(3.0));
  a.AddIdentity(1.0);
  ASSERT_EQ(a.lower().size(), 1u);
  EXPECT_EQ(a.lower()[0].row, 2);
  EXPECT_EQ(a.lower()[0].col, 0);
  EXPECT_DOUBLE_EQ(a.lower()[0].value(0, 0), 2.0);
  EXPECT_DOUBLE_EQ(a.diagonal(1)(0, 0), 7.0);  // 3 + 3 (a pair within one block) + 1
  EXPECT_DOUBLE_EQ(a.Trace(), 3.0 + 7.0 + 1.0);
}

}  // namespace
}  // namespace motionlod::core
