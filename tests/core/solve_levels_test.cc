#include "core/solve_levels.h"

#include <gtest/gtest.h>

#include "core/rank_joints.h"
#include "core/reference/solve_frame_reference.h"
#include "tests/core/fixtures.h"

namespace motionlod::core {
namespace {

using testing::BuildOrDie;
using testing::MakeCreature;
using testing::MakeWaveMotion;
using testing::TestSimd;

struct Scene {
  std::shared_ptr<const Character> character;
  Motion motion;
  JointRanking ranking;
};

Scene MakeScene(int frames = 24) {
  Scene s;
  s.character = BuildOrDie(MakeCreature());
  s.motion = MakeWaveMotion(*s.character, frames);
  s.ranking = *RankJointsJob{s.character.get(), &s.motion, {}, TestSimd()}.Run();
  return s;
}

std::shared_ptr<const PreparedMotion> Prepare(const Scene& s, Variant variant) {
  SolveSettings settings;
  settings.variant = variant;
  auto prepared = PreparedMotion::Create(s.character, s.motion, settings, TestSimd());
  EXPECT_TRUE(prepared.ok()) << prepared.status().ToString();
  return *prepared;
}

// The variant's own solution with its baseline's figures, before SolveLevel's guard.
LevelResult Solve(const PreparedMotion& prepared, const Scene& s, int kept) {
  auto level = ReduceSkeletonToCount(*s.character, s.ranking, kept);
  EXPECT_TRUE(level.ok());
  auto result = prepared.SolveOptimized(*level);
  EXPECT_TRUE(result.ok()) << result.status().ToString();
  result->baseline = *prepared.BaselineErrors(*level);
  return *result;
}

TEST(SolveLevel, LeastSquaresEqualsTheNaivePerFrameSolve) {
  const Scene s = MakeScene(6);
  for (Variant variant : {Variant::kVP, Variant::kVPNO}) {
    const auto prepared = Prepare(s, variant);
    for (int kept : {1, 3, 5, 8}) {
      const auto level = *ReduceSkeletonToCount(*s.character, s.ranking, kept);
      const auto fast = prepared->SolveLeastSquares(level);
      ASSERT_TRUE(fast.ok());
      for (int t = 0; t < s.motion.frame_count; ++t) {
        const std::vector<Affine34d> naive = SolveFrameReference(*prepared, level, t);
        for (int slot = 0; slot < kept; ++slot) {
          const Affine34d k = fast->block<4, 3>(4 * slot, 3 * t).transpose();
          EXPECT_LE((k - naive[slot]).norm(), 1e-9 * naive[slot].norm())
              << VariantName(variant) << " kept " << kept << " frame " << t;
        }
      }
    }
  }
}

TEST(SolveLevel, StoredMatricesAreTheLeastSquaresSolutionInFloat) {
  const Scene s = MakeScene(6);
  for (Variant variant : {Variant::kVP, Variant::kVPNO}) {
    const auto prepared = Prepare(s, variant);
    for (int kept : {1, 3, 5, 8}) {
      const LevelResult result = Solve(*prepared, s, kept);
      for (int t = 0; t < s.motion.frame_count; ++t) {
        const std::vector<Affine34d> naive = SolveFrameReference(*prepared, result.skeleton, t);
        for (int slot = 0; slot < kept; ++slot) {
          const Affine34d fast = result.matrices[t * kept + slot].cast<double>();
          EXPECT_LE((fast - naive[slot]).norm(), 1e-5 * naive[slot].norm())
              << VariantName(variant) << " kept " << kept << " frame " << t;
        }
      }
    }
  }
}

TEST(SolveLevel, ReproducesTheOriginalWhenNoJointIsRemoved) {
  const Scene s = MakeScene();
  for (Variant variant : {Variant::kVP, Variant::kVPNO, Variant::kVPPD, Variant::kVPNOPD}) {
    const auto prepared = Prepare(s, variant);
    const LevelResult result = Solve(*prepared, s, s.character->joint_count());
    EXPECT_LT(result.optimized.mean_e, 1e-12) << VariantName(variant);
    EXPECT_LT(result.optimized.max_vertex_error_pct, 1e-4) << VariantName(variant);
    EXPECT_LT(result.baseline.max_e, 1e-20);
    const Eigen::MatrixXd& kt = prepared->original_matrices();
    for (int t = 0; t < s.motion.frame_count; ++t) {
      for (int j = 0; j < s.character->joint_count(); ++j) {
        const Affine34d original = kt.block<4, 3>(4 * j, 3 * t).transpose();
        EXPECT_TRUE(result.matrices[t * s.character->joint_count() + j].cast<double>().isApprox(
            original, 1e-5));
      }
    }
  }
}

TEST(SolveLevel, RigidFullLevelKeepsRotationsExactlyAndProjectsScaledJoints) {
  Scene s = MakeScene();
  const int n = s.character->joint_count();
  for (Variant variant : {Variant::kVPPD, Variant::kVPNOPD}) {
    // Every K_j(t) of the wave motion is a rotation: the full level is the original, bit
    // for bit, with no error at all (not an error at the level of rounding).
    const auto prepared = Prepare(s, variant);
    const LevelResult result = Solve(*prepared, s, n);
    EXPECT_EQ(result.optimized.mean_e, 0.0) << VariantName(variant);
    EXPECT_EQ(result.optimized.max_vertex_error_pct, 0.0) << VariantName(variant);
    const Eigen::MatrixXd& kt = prepared->original_matrices();
    for (int t = 0; t < s.motion.frame_count; ++t) {
      for (int j = 0; j < n; ++j) {
        const Affine34f original = kt.block<4, 3>(4 * j, 3 * t).transpose().cast<float>();
        EXPECT_EQ(result.matrices[t * n + j], original) << t << " " << j;
      }
    }
  }
  // A joint scaled by 1.2 in every frame is no rotation: the rigid full level projects it
  // and pays for it, so the shortcut above must not apply.
  const int scaled = n - 1;
  for (int t = 0; t < s.motion.frame_count; ++t) {
    s.motion.joint_world[static_cast<size_t>(t) * n + scaled].leftCols<3>() *= 1.2;
  }
  const LevelResult result = Solve(*Prepare(s, Variant::kVPNOPD), s, n);
  EXPECT_GT(result.optimized.mean_e, 0.0);
  for (int t = 0; t < s.motion.frame_count; ++t) {
    const Eigen::Matrix3d r = result.matrices[t * n + scaled].leftCols<3>().cast<double>();
    EXPECT_NEAR((r.transpose() * r - Eigen::Matrix3d::Identity()).norm(), 0, 1e-6) << t;
  }
}

TEST(SolveLevel, LeastSquaresVariantsNeverLoseToTheBaseline) {
  const Scene s = MakeScene();
  const auto vpno = Prepare(s, Variant::kVPNO);
  const auto vp = Prepare(s, Variant::kVP);
  for (int kept = 1; kept <= s.character->joint_count(); ++kept) {
    const LevelResult a = Solve(*vpno, s, kept);
    for (int t = 0; t < s.motion.frame_count; ++t) {
      EXPECT_LE(a.optimized.e[t], a.baseline.e[t] * (1 + 1e-9) + 1e-15) << kept << " " << t;
    }
    const LevelResult b = Solve(*vp, s, kept);
    for (int t = 0; t < s.motion.frame_count; ++t) {
      const double ep = b.optimized.ep_vertex[t] + b.optimized.ep_joint[t];
      const double ep_base = b.baseline.ep_vertex[t] + b.baseline.ep_joint[t];
      EXPECT_LE(ep, ep_base * (1 + 1e-9) + 1e-15) << kept << " " << t;
    }
  }
}

TEST(SolveLevel, NeverWorseThanReparentingAndTakesItsMatricesWhereTheSolutionIs) {
  const Scene s = MakeScene();
  const int n = s.character->joint_count();
  int reparented = 0;
  for (Variant variant : {Variant::kVP, Variant::kVPNO, Variant::kVPPD, Variant::kVPNOPD}) {
    const auto prepared = Prepare(s, variant);
    for (int kept = 1; kept <= n; ++kept) {
      const LevelResult own = Solve(*prepared, s, kept);
      const LevelResult level = *prepared->SolveLevel(own.skeleton);
      ASSERT_EQ(level.sources.size(), 1u);
      EXPECT_LE(level.optimized.max_vertex_error_pct, level.baseline.max_vertex_error_pct);
      EXPECT_LE(level.optimized.mean_vertex_error_pct, level.baseline.mean_vertex_error_pct);
      const bool worse = own.optimized.max_vertex_error_pct > own.baseline.max_vertex_error_pct ||
                         own.optimized.mean_vertex_error_pct > own.baseline.mean_vertex_error_pct;
      EXPECT_EQ(level.sources[0], worse ? LevelSource::kReparented : LevelSource::kSolved)
          << VariantName(variant) << " kept " << kept;
      if (!worse) {
        EXPECT_EQ(level.matrices, own.matrices);
        continue;
      }
      ++reparented;
      EXPECT_EQ(level.optimized.max_vertex_error_pct, level.baseline.max_vertex_error_pct);
      const Eigen::MatrixXd& kt = prepared->original_matrices();
      for (int t = 0; t < s.motion.frame_count; ++t) {
        for (int slot = 0; slot < kept; ++slot) {
          const int j = level.skeleton.kept_joints[slot];
          EXPECT_EQ(level.matrices[t * kept + slot], RowMajorAffine34f(kt.block<4, 3>(4 * j, 3 * t).transpose().cast<float>()));
        }
      }
    }
  }
  // The creature's waving levels lose to reparenting somewhere (the maximum, which least
  // squares does not minimise): the guard is exercised.
  EXPECT_GT(reparented, 0);
}

TEST(SolveLevel, RigidVariantsStoreRotations) {
  const Scene s = MakeScene();
  const auto prepared = Prepare(s, Variant::kVPNOPD);
  const LevelResult result = Solve(*prepared, s, 4);
  for (const RowMajorAffine34f& k : result.matrices) {
    const Eigen::Matrix3d r = k.leftCols<3>().cast<double>();
    EXPECT_NEAR((r.transpose() * r - Eigen::Matrix3d::Identity()).norm(), 0, 1e-6);
    EXPECT_NEAR(r.determinant(), 1.0, 1e-6);
  }
}

TEST(SolveLevel, ResolvedTranslationBeatsTheSolvedOne) {
  const Scene s = MakeScene();
  SolveSettings keep;
  keep.variant = Variant::kVPNOPD;
  keep.resolve_rigid_translation = false;
  const auto kept_t = *PreparedMotion::Create(s.character, s.motion, keep, TestSimd());
  const auto resolved = Prepare(s, Variant::kVPNOPD);
  for (int kept = 2; kept < s.character->joint_count(); ++kept) {
    const LevelResult a = Solve(*resolved, s, kept);
    const LevelResult b = Solve(*kept_t, s, kept);
    EXPECT_LE(a.optimized.mean_e, b.optimized.mean_e * (1 + 1e-9)) << kept;
  }
}

TEST(SolveLevel, ErrorsAreInvariantToARigidTransformOfTheMotion) {
  Scene s = MakeScene();
  Scene moved = s;
  const Affine34d rigid = ComposeAffine(testing::Translation(3, -2, 7),
                                        testing::RotationAbout(Vec3d(1, 2, 3), 1.1, Vec3d::Zero()));
  for (Affine34d& w : moved.motion.joint_world) w = ComposeAffine(rigid, w);
  for (Variant variant : {Variant::kVP, Variant::kVPNO, Variant::kVPPD, Variant::kVPNOPD}) {
    const auto a = Prepare(s, variant);
    const auto b = Prepare(moved, variant);
    EXPECT_NEAR(a->alpha(), b->alpha(), 1e-9 * a->alpha());
    for (int kept : {2, 5}) {
      const LevelResult ra = Solve(*a, s, kept);
      const LevelResult rb = Solve(*b, moved, kept);
      EXPECT_NEAR(ra.optimized.mean_e, rb.optimized.mean_e, 1e-7 * ra.optimized.mean_e + 1e-12);
      EXPECT_NEAR(ra.optimized.max_vertex_error_pct, rb.optimized.max_vertex_error_pct, 1e-5);
      EXPECT_NEAR(ra.optimized.mean_normal_error_deg, rb.optimized.mean_normal_error_deg, 1e-5);
      EXPECT_NEAR(ra.baseline.mean_e, rb.baseline.mean_e, 1e-9 * ra.baseline.mean_e);
    }
  }
}

TEST(SolveLevel, MaxVertexErrorIsTheExactMaximum) {
  // 12 frames, and 13 whose last, alone in the maximum search's last batch of frames, moves
  // three times as far as the wave does: the largest errors are there.
  for (int frames : {12, 13}) {
    Scene s = MakeScene(frames);
    if (frames % 4 != 0) {
      const Motion wider = MakeWaveMotion(*s.character, frames, 1.8);
      const size_t last = static_cast<size_t>(frames - 1) * s.motion.joint_count;
      std::copy_n(wider.joint_world.begin() + last, s.motion.joint_count,
                  s.motion.joint_world.begin() + last);
    }
    const auto prepared = Prepare(s, Variant::kVPNO);
    const Character& c = *s.character;
    for (int kept : {1, 3, 6}) {
      const LevelResult result = Solve(*prepared, s, kept);
      // Brute force over every vertex and frame with the stored (float) matrices, and for the
      // baseline with the kept joints' original ones (its search reads only the removed
      // joints, whose Delta is not zero).
      double brute = 0, brute_baseline = 0;
      int brute_frame = -1;
      const auto reduced = ReduceInfluences(c.skin(), result.skeleton);
      const Eigen::MatrixXd& kt = prepared->original_matrices();
      const auto original_matrix = [&](int joint, int t) -> Affine34d {
        return kt.block<4, 3>(4 * joint, 3 * t).transpose();
      };
      for (int t = 0; t < s.motion.frame_count; ++t) {
        for (int i = 0; i < c.vertex_count(); ++i) {
          const Vec3d v0 = c.skin().positions[i].cast<double>();
          Vec3d original = Vec3d::Zero(), lod = Vec3d::Zero(), baseline = Vec3d::Zero();
          for (uint32_t e = c.skin().influence_offsets[i]; e < c.skin().influence_offsets[i + 1];
               ++e) {
            original += c.skin().influence_weights[e] *
                        TransformPoint(original_matrix(c.skin().influence_joints[e], t), v0);
          }
          for (uint32_t e = reduced.offsets[i]; e < reduced.offsets[i + 1]; ++e) {
            const Affine34d k = result.matrices[t * kept + reduced.slots[e]].cast<double>();
            lod += reduced.weights[e] * TransformPoint(k, v0);
            const int kept_joint = result.skeleton.kept_joints[reduced.slots[e]];
            baseline += reduced.weights[e] * TransformPoint(original_matrix(kept_joint, t), v0);
          }
          if ((original - lod).norm() > brute) {
            brute = (original - lod).norm();
            brute_frame = t;
          }
          brute_baseline = std::max(brute_baseline, (original - baseline).norm());
        }
      }
      if (frames % 4 != 0) {
        ASSERT_EQ(brute_frame, frames - 1) << kept;
      }
      EXPECT_NEAR(result.optimized.max_vertex_error_pct, 100 * brute / c.height(), 1e-4) << kept;
      EXPECT_EQ(result.optimized.max_vertex_frame, brute_frame) << kept;
      EXPECT_GT(brute_baseline, 0) << kept;
      EXPECT_NEAR(result.baseline.max_vertex_error_pct, 100 * brute_baseline / c.height(), 1e-4)
          << kept;
    }
  }
}

TEST(SolveSettings, ValidateAndHash) {
  SolveSettings a;
  EXPECT_TRUE(a.Validate().ok());
  SolveSettings b = a;
  b.variant = Variant::kVP;
  EXPECT_NE(a.Hash(), b.Hash());
  EXPECT_EQ(a.Hash(), SolveSettings{}.Hash());
  b = a;
  b.regularization = 0;
  EXPECT_FALSE(b.Validate().ok());
  b = a;
  b.joint_weight = -1;
  EXPECT_FALSE(b.Validate().ok());
  EXPECT_EQ(*ParseVariant("vpno+pd"), Variant::kVPNOPD);
  EXPECT_FALSE(ParseVariant("vpn").ok());
}

}  // namespace
}  // namespace motionlod::core
