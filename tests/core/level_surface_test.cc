// A level's own surface: the simplified mesh, the pose rate and the honest deviation that
// measures both against the original.
#include <gtest/gtest.h>

#include <cmath>

#include "core/level_deviation.h"
#include "core/pose_rate.h"
#include "core/simplify_mesh.h"
#include "tests/core/fixtures.h"

namespace motionlod::core {
namespace {

using testing::BuildOrDie;
using testing::MakeCreature;
using testing::MakeWaveMotion;
using testing::TestSimd;

struct SurfaceScene {
  std::shared_ptr<const Character> character;
  Motion motion;
  std::shared_ptr<const PreparedMotion> prepared;
};

SurfaceScene MakeSurfaceScene(int segments = 12, int rings = 8) {
  SurfaceScene s;
  s.character = BuildOrDie(MakeCreature(segments, rings));
  s.motion = MakeWaveMotion(*s.character, 25);
  s.prepared = *PreparedMotion::Create(s.character, s.motion, SolveSettings{}, TestSimd());
  return s;
}

ReducedSkeleton Keep(const Character& character, std::initializer_list<int> kept) {
  std::unique_ptr<bool[]> flags(new bool[character.joint_count()]());
  for (int j : kept) flags[j] = true;
  return *ReduceSkeleton(character, std::span<const bool>(flags.get(), character.joint_count()));
}

TEST(PoseRate, StoresEveryStrideAndTheLastFrame) {
  EXPECT_EQ(StoredFrameCount(1, 3), 1);
  EXPECT_EQ(StoredFrameCount(10, 1), 10);
  EXPECT_EQ(StoredFrameCount(10, 3), 4);                     // 0 3 6 9
  EXPECT_EQ(StoredFrameCount(11, 3), 5);                     // 0 3 6 9 10
  const StoredFrameBlend between = BlendOfFrame(10, 12, 3);  // stored 9 and 11
  EXPECT_EQ(between.index, 3);
  EXPECT_FLOAT_EQ(between.fraction, 0.5f);
  const StoredFrameBlend last = BlendOfFrame(11, 12, 3);
  EXPECT_EQ(last.index, 4);
  EXPECT_EQ(last.fraction, 0.0f);
  const StoredFrameBlend at = BlendOfFrame(6, 12, 3);
  EXPECT_EQ(at.index, 2);
  EXPECT_EQ(at.fraction, 0.0f);
}

TEST(PoseRate, RigidInterpolationStaysRigid) {
  RowMajorAffine34f a = RowMajorAffine34f::Zero(), b = RowMajorAffine34f::Zero();
  a.leftCols<3>() = Eigen::AngleAxisf(0.2f, Vec3f::UnitY()).toRotationMatrix();
  b.leftCols<3>() = Eigen::AngleAxisf(1.4f, Vec3f::UnitY()).toRotationMatrix();
  a.col(3) = Vec3f(1, 0, 0);
  b.col(3) = Vec3f(3, 2, 0);
  const RowMajorAffine34f mid = InterpolateMatrix(a, b, 0.5f, true);
  EXPECT_TRUE(mid.leftCols<3>().isApprox(Eigen::AngleAxisf(0.8f, Vec3f::UnitY()).toRotationMatrix(),
                                         1e-5f));
  EXPECT_TRUE(mid.col(3).isApprox(Vec3f(2, 1, 0)));
  const RowMajorAffine34f affine = InterpolateMatrix(a, b, 0.5f, false);
  EXPECT_LT(std::abs(affine.leftCols<3>().determinant() - 1), 0.9f);
  EXPECT_GT(std::abs(affine.leftCols<3>().determinant() - 1), 1e-2f);  // lerp shrinks
}

TEST(LevelDeviation, EqualsTheSolvesMaximumForTheMergedWeightsAtFullRate) {
  const SurfaceScene s = MakeSurfaceScene();
  const ReducedSkeleton level = Keep(*s.character, {0, 1, 4, 7});
  const LevelResult solved = *s.prepared->SolveLevel(level);
  const LevelInfluences merged = *TruncateInfluences(*s.character, level, 4);
  const auto stored = *StoreAtStride(solved.matrices, level.kept_count(), s.prepared->clips(), 1);
  const LevelDeviationJob job{s.prepared.get(), &level, nullptr, &merged, stored, 1, true};
  const LevelDeviation deviation = *job.Run();
  EXPECT_NEAR(deviation.max_pct, solved.optimized.max_vertex_error_pct,
              1e-3 * solved.optimized.max_vertex_error_pct);
  EXPECT_GT(deviation.max_pct, 0.5);
  ASSERT_EQ(deviation.per_clip.size(), 1u);
  EXPECT_EQ(deviation.per_clip[0].max_pct, deviation.max_pct);
  EXPECT_LE(deviation.mean_pct, deviation.max_pct);
  // Storing every other frame costs error; the full level at full rate costs none.
  const auto halved = *StoreAtStride(solved.matrices, level.kept_count(), s.prepared->clips(), 2);
  const LevelDeviation slower =
      *LevelDeviationJob{s.prepared.get(), &level, nullptr, &merged, halved, 2, true}.Run();
  EXPECT_GT(slower.mean_pct, deviation.mean_pct);
  const ReducedSkeleton full = Keep(*s.character, {0, 1, 2, 3, 4, 5, 6, 7});
  const LevelResult exact = *s.prepared->SolveLevel(full);
  const LevelInfluences original = *TruncateInfluences(*s.character, full, 4);
  const auto all = *StoreAtStride(exact.matrices, full.kept_count(), s.prepared->clips(), 1);
  EXPECT_LT(
      (LevelDeviationJob{s.prepared.get(), &full, nullptr, &original, all, 1, true}.Run())->max_pct,
      1e-4);
}

TEST(SimplifyMesh, KeepsASubsetOfVerticesAndAnHonestBound) {
  const SurfaceScene s = MakeSurfaceScene();
  const int triangles = static_cast<int>(s.character->skin().triangles.size());
  const LevelMesh mesh =
      *SimplifyMeshJob{s.character.get(), triangles / 4, 0.05 * s.character->height()}.Run();
  EXPECT_LT(mesh.triangles.size(), static_cast<size_t>(triangles) / 2);
  EXPECT_LT(mesh.vertices.size(), static_cast<size_t>(s.character->vertex_count()));
  EXPECT_TRUE(std::is_sorted(mesh.vertices.begin(), mesh.vertices.end()));
  EXPECT_LE(mesh.bind_error, 0.05 * s.character->height());
  ASSERT_EQ(mesh.correspondence.size(), static_cast<size_t>(s.character->vertex_count()));
  // Every original vertex's point lies near it in the bind pose.
  const RawSkin& skin = s.character->skin();
  for (int i = 0; i < s.character->vertex_count(); ++i) {
    const SurfacePoint& point = mesh.correspondence[i];
    Vec3f at = Vec3f::Zero();
    for (int c = 0; c < 3; ++c)
      at += point.weights[c] * skin.positions[mesh.vertices[point.vertices[c]]];
    EXPECT_LT((at - skin.positions[i]).norm(), 0.1 * s.character->height()) << "vertex " << i;
  }
  // The level solved on the kept vertices, measured on every original one.
  const auto subset = *SubsetCharacter(*s.character, mesh);
  ASSERT_EQ(subset->vertex_count(), static_cast<int>(mesh.vertices.size()));
  const auto prepared = *PreparedMotion::Create(subset, s.motion, SolveSettings{}, TestSimd());
  const ReducedSkeleton level = Keep(*subset, {0, 1, 4, 7});
  const LevelResult solved = *prepared->SolveLevel(level);
  const LevelInfluences weights =
      *InfluenceCapJob{prepared.get(), &level, solved.matrices, 2, 0}.Run();
  const auto stored = *StoreAtStride(solved.matrices, level.kept_count(), s.prepared->clips(), 1);
  const LevelDeviation on_every_vertex =
      *LevelDeviationJob{s.prepared.get(), &level, &mesh, &weights, stored, 1, true}.Run();
  const LevelDeviation on_kept =
      *LevelDeviationJob{prepared.get(), &level, nullptr, &weights, stored, 1, true}.Run();
  EXPECT_GE(on_every_vertex.max_pct, on_kept.max_pct);
  EXPECT_LT(on_every_vertex.max_pct,
            3 * on_kept.max_pct + 100 * mesh.bind_error / s.character->height());
}

TEST(LevelSurface, RefusesBadInput) {
  const SurfaceScene s = MakeSurfaceScene(8, 4);
  EXPECT_FALSE((SimplifyMeshJob{s.character.get(), 0, 0}.Run().ok()));
  EXPECT_FALSE((SimplifyMeshJob{s.character.get(), 10, -1}.Run().ok()));
  EXPECT_FALSE((SimplifyMeshJob{nullptr, 10, 0}.Run().ok()));
  const ReducedSkeleton level = Keep(*s.character, {0, 1});
  const LevelResult solved = *s.prepared->SolveLevel(level);
  EXPECT_FALSE(StoreAtStride(solved.matrices, level.kept_count(), s.prepared->clips(), 0).ok());
  EXPECT_FALSE(
      StoreAtStride(std::span(solved.matrices).first(5), level.kept_count(), s.prepared->clips(), 1)
          .ok());
  const LevelInfluences merged = *TruncateInfluences(*s.character, level, 2);
  const auto stored = *StoreAtStride(solved.matrices, level.kept_count(), s.prepared->clips(), 2);
  EXPECT_FALSE(
      (LevelDeviationJob{s.prepared.get(), &level, nullptr, &merged, stored, 1, true}.Run().ok()));
  EXPECT_TRUE(
      (LevelDeviationJob{s.prepared.get(), &level, nullptr, &merged, stored, 2, true}.Run().ok()));
}

}  // namespace
}  // namespace motionlod::core
