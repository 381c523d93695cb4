#include <random>

#include <gtest/gtest.h>

#include "core/polar.h"
#include "core/reference/polar_reference.h"
#include "core/skinning.h"
#include "tests/core/fixtures.h"

namespace motionlod::core {
namespace {

TEST(SkinningJob, IdentityMatricesReproduceTheBindPose) {
  const auto c = testing::BuildOrDie(testing::MakeCreature());
  std::vector<Affine34f> k(c->joint_count(), IdentityAffine().cast<float>());
  std::vector<Vec3f> positions(c->vertex_count()), normals(c->vertex_count());
  SkinningJob job{c.get(), k, positions, normals};
  ASSERT_TRUE(job.Run().ok());
  for (int i = 0; i < c->vertex_count(); ++i) {
    EXPECT_TRUE(positions[i].isApprox(c->skin().positions[i], 1e-6f));
    EXPECT_TRUE(normals[i].isApprox(c->skin().normals[i], 1e-6f));
  }
}

TEST(SkinningJob, BlendsMatricesByWeight) {
  const auto c = testing::BuildOrDie(testing::MakeCreature());
  std::vector<Affine34f> k(c->joint_count(), IdentityAffine().cast<float>());
  k[1].col(3) << 1, 0, 0;  // spine moves +x by 1
  std::vector<Vec3f> positions(c->vertex_count());
  ASSERT_TRUE((SkinningJob{c.get(), k, positions, {}}).Run().ok());
  const RawSkin& skin = c->skin();
  for (int i = 0; i < c->vertex_count(); ++i) {
    float w_spine = 0;
    for (uint32_t e = skin.influence_offsets[i]; e < skin.influence_offsets[i + 1]; ++e) {
      if (skin.influence_joints[e] == 1) w_spine = skin.influence_weights[e];
    }
    EXPECT_NEAR(positions[i].x() - skin.positions[i].x(), w_spine, 1e-6f);
  }
}

TEST(SkinningJob, ValidateRejectsWrongShapesAndTouchesNothing) {
  const auto c = testing::BuildOrDie(testing::MakeCreature());
  std::vector<Affine34f> k(3, IdentityAffine().cast<float>());  // too few matrices
  std::vector<Vec3f> positions(c->vertex_count(), Vec3f::Constant(7));
  EXPECT_FALSE((SkinningJob{c.get(), k, positions, {}}).Run().ok());
  EXPECT_EQ(positions[0], Vec3f::Constant(7));
  std::vector<Affine34f> all(c->joint_count(), IdentityAffine().cast<float>());
  std::vector<Vec3f> short_positions(5);
  EXPECT_FALSE((SkinningJob{c.get(), all, short_positions, {}}).Validate().ok());
  EXPECT_FALSE((SkinningJob{nullptr, all, positions, {}}).Validate().ok());
}

TEST(NearestRotation, NewtonMatchesSvdAndIsARotation) {
  std::mt19937 rng(7);
  std::normal_distribution<double> noise(0, 1);
  for (int trial = 0; trial < 500; ++trial) {
    Eigen::Matrix3d a;
    for (int q = 0; q < 9; ++q) a(q / 3, q % 3) = noise(rng);
    const Eigen::Matrix3d r = NearestRotation(a);
    EXPECT_NEAR((r.transpose() * r - Eigen::Matrix3d::Identity()).norm(), 0, 1e-12);
    EXPECT_NEAR(r.determinant(), 1.0, 1e-12);
    EXPECT_TRUE(r.isApprox(NearestRotationReference(a), 1e-9)) << a;
  }
}

TEST(NearestRotation, BatchesAgreeWithOneAtATime) {
  // Near-rotations (the common case), general and ill-conditioned matrices (scaled Newton
  // first), reflections, zero and singular ones in one list whose length is not a multiple
  // of the batch.
  std::mt19937 rng(11);
  std::normal_distribution<double> noise(0, 1);
  std::vector<Eigen::Matrix3d> matrices;
  for (int q = 0; q < 45; ++q) {
    Eigen::Matrix3d a;
    for (int c = 0; c < 9; ++c) a(c / 3, c % 3) = noise(rng);
    const Eigen::Matrix3d rotation = Eigen::AngleAxisd(noise(rng), Vec3d(noise(rng), 1, noise(rng)).normalized())
                                         .toRotationMatrix();
    matrices.push_back(q % 3 == 0 ? a : 2.5 * rotation + 0.05 * a);
  }
  matrices[7] = Eigen::Vector3d(1, 1, -1).asDiagonal();
  matrices[20] = Eigen::Matrix3d::Zero();
  matrices[33] = Eigen::Vector3d(1, 1, 0).asDiagonal();
  // Ill-conditioned, yet not for the SVD: scaled Newton steps in one lane (Newton-Schulz
  // alone would not converge within its steps) beside its batch's near-rotations.
  matrices[12] = matrices[13] * Eigen::Vector3d(1, 1, 2e-5).asDiagonal();
  // Each in a 4x3 block whose fourth row the projection leaves as it was.
  std::vector<Eigen::Matrix<double, 4, 3>> batched(matrices.size());
  std::vector<double*> blocks;
  for (size_t q = 0; q < matrices.size(); ++q) {
    batched[q].topRows<3>() = matrices[q];
    batched[q].row(3) = Eigen::RowVector3d(0.5, -1.0, static_cast<double>(q));
    blocks.push_back(batched[q].data());
  }
  NearestRotations(blocks, 4);
  for (size_t q = 0; q < matrices.size(); ++q) {
    const Eigen::Matrix3d expected = NearestRotation(matrices[q]);
    const Eigen::Matrix3d r = batched[q].topRows<3>();
    EXPECT_LE((r - expected).norm(), 1e-12) << q << "\n" << matrices[q];
    EXPECT_NEAR((r.transpose() * r - Eigen::Matrix3d::Identity()).norm(), 0, 1e-12) << q;
    EXPECT_NEAR(r.determinant(), 1.0, 1e-12) << q;
    EXPECT_EQ(batched[q].row(3), Eigen::RowVector3d(0.5, -1.0, static_cast<double>(q))) << q;
  }
}

TEST(NearestRotations, ProjectsBlocksWhereTheyLie) {
  // Four 3x3 blocks of an 8x6 column-major matrix (rows 0 and 4, columns 0 and 3): each
  // projected in place as NearestRotation projects it alone, every other entry untouched.
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> value(-1.0, 1.0);
  Eigen::MatrixXd grid(8, 6);
  for (Eigen::Index q = 0; q < grid.size(); ++q) grid(q) = value(rng);
  for (int s = 0; s < 2; ++s) {
    for (int t = 0; t < 2; ++t) grid.block<3, 3>(4 * s, 3 * t) += 2 * Eigen::Matrix3d::Identity();
  }
  const Eigen::MatrixXd before = grid;
  std::vector<double*> blocks;
  for (int t = 0; t < 2; ++t) {
    for (int s = 0; s < 2; ++s) blocks.push_back(grid.data() + 3 * t * grid.rows() + 4 * s);
  }
  NearestRotations(blocks, grid.rows());
  Eigen::MatrixXd expected = before;
  for (int s = 0; s < 2; ++s) {
    for (int t = 0; t < 2; ++t) {
      expected.block<3, 3>(4 * s, 3 * t) = NearestRotation(before.block<3, 3>(4 * s, 3 * t));
    }
  }
  EXPECT_LE((grid - expected).norm(), 1e-12);
  for (int t = 0; t < 6; ++t) EXPECT_EQ(grid(3, t), before(3, t)) << t;
  for (int t = 0; t < 6; ++t) EXPECT_EQ(grid(7, t), before(7, t)) << t;
  EXPECT_NE(grid(0, 0), before(0, 0));
}

TEST(NearestRotation, HandlesReflectionsScaleAndZero) {
  const Eigen::Matrix3d mirror = Eigen::Vector3d(1, 1, -1).asDiagonal();
  EXPECT_NEAR(NearestRotation(mirror).determinant(), 1.0, 1e-12);
  const Eigen::Matrix3d scaled = 3.0 * Eigen::AngleAxisd(0.4, Vec3d::UnitY()).toRotationMatrix();
  EXPECT_TRUE(NearestRotation(scaled).isApprox(scaled / 3.0, 1e-12));
  EXPECT_TRUE(NearestRotation(Eigen::Matrix3d::Zero()).isIdentity());
}

}  // namespace
}  // namespace motionlod::core
