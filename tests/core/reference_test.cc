// Every accelerated step of the core held to its naive reference (core/reference/) on the
// hand-made creature: the ranking, the errors (quadratic forms, the bounded maximum
// search, the sampled figures), the baselines level by level and in sequence, and the
// smallest-level search's probes.
#include <algorithm>
#include <cmath>
#include <vector>

#include <gtest/gtest.h>

#include "core/baseline_sequence.h"
#include "core/internal/level_search.h"
#include "core/internal/level_solve.h"
#include "core/internal/prepared_data.h"
#include "core/rank_joints.h"
#include "core/reference/level_errors_reference.h"
#include "core/reference/rank_joints_reference.h"
#include "core/smallest_level.h"
#include "core/solve_levels.h"
#include "tests/core/fixtures.h"

namespace motionlod::core {
namespace {

using testing::BuildOrDie;
using testing::MakeCreature;
using testing::MakeWaveMotion;
using testing::TestSimd;

constexpr Variant kVariants[] = {Variant::kVP, Variant::kVPNO, Variant::kVPPD, Variant::kVPNOPD};

struct ReferenceScene {
  std::shared_ptr<const Character> character;
  Motion motion;
  JointRanking ranking;
};

ReferenceScene MakeReferenceScene(int frames) {
  ReferenceScene s;
  s.character = BuildOrDie(MakeCreature(12, 5));
  s.motion = MakeWaveMotion(*s.character, frames, 0.9);
  s.ranking = *RankJointsJob{s.character.get(), &s.motion, {}, TestSimd()}.Run();
  return s;
}

std::shared_ptr<const PreparedMotion> Prepare(const ReferenceScene& s, Variant variant) {
  SolveSettings settings;
  settings.variant = variant;
  return *PreparedMotion::Create(s.character, s.motion, settings, TestSimd());
}

void ExpectNearRelative(double fast, double reference, double tolerance, const std::string& what) {
  EXPECT_LE(std::abs(fast - reference), tolerance * std::abs(reference) + 1e-14) << what << ": " << fast
                                                                                   << " vs " << reference;
}

// The exact figures of `fast` against the reference's; the maximum vertex error to the
// float precision its blends run in.
void ExpectSameFigures(const LevelErrors& fast, const LevelErrors& reference, const std::string& where) {
  ASSERT_EQ(fast.e.size(), reference.e.size()) << where;
  for (size_t t = 0; t < fast.e.size(); ++t) {
    const std::string at = where + " frame " + std::to_string(t);
    ExpectNearRelative(fast.e[t], reference.e[t], 1e-9, at + " E");
    ExpectNearRelative(fast.ep_vertex[t], reference.ep_vertex[t], 1e-9, at + " Ep vertex");
    ExpectNearRelative(fast.en_vertex[t], reference.en_vertex[t], 1e-9, at + " En vertex");
    ExpectNearRelative(fast.ep_joint[t], reference.ep_joint[t], 1e-9, at + " Ep joint");
    ExpectNearRelative(fast.en_joint[t], reference.en_joint[t], 1e-9, at + " En joint");
  }
  ExpectNearRelative(fast.mean_e, reference.mean_e, 1e-9, where + " mean E");
  ExpectNearRelative(fast.max_e, reference.max_e, 1e-9, where + " max E");
  ExpectNearRelative(fast.rms_vertex_error_pct, reference.rms_vertex_error_pct, 1e-9, where + " RMS");
  ExpectNearRelative(fast.max_vertex_error_pct, reference.max_vertex_error_pct, 1e-5, where + " max");
  if (reference.max_vertex_error_pct > 1e-3) {
    EXPECT_EQ(fast.max_vertex_frame, reference.max_vertex_frame) << where;
    EXPECT_EQ(fast.max_vertex_index, reference.max_vertex_index) << where;
  }
  // The sampled means estimate the exact ones (ratio estimates on 64 of the vertices).
  ExpectNearRelative(fast.mean_vertex_error_pct, reference.mean_vertex_error_pct, 0.2, where + " mean");
  ExpectNearRelative(fast.mean_normal_error_deg, reference.mean_normal_error_deg, 0.2,
                     where + " mean angle");
}

TEST(Reference, RankingMatchesItsReference) {
  const ReferenceScene s = MakeReferenceScene(30);
  for (const std::vector<std::string>& locked : {std::vector<std::string>{}, {"neck", "hand_r"}}) {
    const auto fast = *RankJointsJob{s.character.get(), &s.motion, locked, TestSimd()}.Run();
    const JointRanking reference = RankJointsReference(*s.character, s.motion, locked);
    EXPECT_EQ(fast.removal_order, reference.removal_order);
    EXPECT_EQ(fast.locked_count, reference.locked_count);
    for (int j = 0; j < s.character->joint_count(); ++j) {
      ExpectNearRelative(fast.rotational[j], reference.rotational[j], 1e-9, "r_" + std::to_string(j));
      if (std::isfinite(reference.priority[j])) {
        ExpectNearRelative(fast.priority[j], reference.priority[j], 1e-9, "priority " + std::to_string(j));
      } else {
        EXPECT_EQ(fast.priority[j], reference.priority[j]) << j;
      }
    }
  }
}

TEST(Reference, LevelFiguresMatchTheSkinnedMesh) {
  // 13 frames: the maximum search's batches of four end with a lone frame.
  const ReferenceScene s = MakeReferenceScene(13);
  for (Variant variant : kVariants) {
    const auto prepared = Prepare(s, variant);
    for (int kept = 1; kept <= s.character->joint_count(); ++kept) {
      const ReducedSkeleton level = *ReduceSkeletonToCount(*s.character, s.ranking, kept);
      LevelResult result = *prepared->SolveOptimized(level);
      result.baseline = *prepared->BaselineErrors(level);
      const auto solution = internal::SolveVariant(prepared->data(), level);
      ASSERT_TRUE(solution.ok());
      const std::string where = std::string(VariantName(variant)) + " kept " + std::to_string(kept);
      const Eigen::MatrixXd& x = solution->Matrices(prepared->data());
      ExpectSameFigures(result.optimized, LevelErrorsReference(*prepared, level, x), where);
      ExpectSameFigures(result.baseline, BaselineErrorsReference(*prepared, level), where + " baseline");
    }
  }
}

TEST(Reference, BaselineSequenceMatchesTheReferenceAtEveryLevel) {
  const ReferenceScene s = MakeReferenceScene(9);
  const auto prepared = Prepare(s, Variant::kVPNOPD);
  BaselineSequence sequence(prepared);
  for (int kept = s.character->joint_count(); kept >= 1; --kept) {
    const ReducedSkeleton level = *ReduceSkeletonToCount(*s.character, s.ranking, kept);
    const auto errors = sequence.Next(level);
    ASSERT_TRUE(errors.ok()) << errors.status().ToString();
    ExpectSameFigures(*errors, BaselineErrorsReference(*prepared, level), "kept " + std::to_string(kept));
  }
  // A level that keeps a joint the one before removed is not a step of the sequence.
  const ReducedSkeleton full = *ReduceSkeletonToCount(*s.character, s.ranking, s.character->joint_count());
  EXPECT_EQ(sequence.Next(full).status().code(), StatusCode::kInvalidArgument);
}

TEST(Reference, ProbesDecideLikeTheReferenceMaximum) {
  const ReferenceScene s = MakeReferenceScene(20);
  const auto prepared = Prepare(s, Variant::kVPNOPD);
  for (int kept = 1; kept < s.character->joint_count(); ++kept) {
    const ReducedSkeleton level = *ReduceSkeletonToCount(*s.character, s.ranking, kept);
    const auto solution = internal::SolveVariant(prepared->data(), level);
    const double maximum =
        LevelErrorsReference(*prepared, level, solution->Matrices(prepared->data())).max_vertex_error_pct;
    ASSERT_GT(maximum, 0) << kept;
    EXPECT_TRUE(*internal::MaxVertexErrorWithin(*prepared, level, maximum * 1.001)) << kept;
    EXPECT_FALSE(*internal::MaxVertexErrorWithin(*prepared, level, maximum * 0.999)) << kept;
  }
  EXPECT_FALSE(internal::MaxVertexErrorWithin(*prepared, *ReduceSkeletonToCount(*s.character, s.ranking, 2), 0).ok());
  // Every second frame: the same solution on those frames.
  const auto strided = *internal::EveryNthFrame(*prepared, 2);
  EXPECT_EQ(strided->frame_count(), 10);
  EXPECT_EQ(strided->alpha(), prepared->alpha());
  EXPECT_FALSE(internal::EveryNthFrame(*prepared, 0).ok());
}

TEST(SmallestLevel, FindsTheFewestJointsWithinTheBound) {
  const ReferenceScene s = MakeReferenceScene(16);
  const auto prepared = Prepare(s, Variant::kVPNO);
  const int n = s.character->joint_count();
  std::vector<double> maximum(n + 1, 0.0);
  for (int kept = 1; kept <= n; ++kept) {
    maximum[kept] = prepared->SolveOptimized(*ReduceSkeletonToCount(*s.character, s.ranking, kept))
                        ->optimized.max_vertex_error_pct;
  }
  for (double bound : {maximum[2] * 1.01, maximum[4] * 1.01, maximum[1] * 2}) {
    const auto found = SmallestLevelJob{prepared.get(), &s.ranking, 1, n, bound}.Run();
    ASSERT_TRUE(found.ok()) << found.status().ToString();
    EXPECT_LE(maximum[*found], bound);
    if (*found > 1) {
      EXPECT_GT(maximum[*found - 1], bound) << bound;
    }
  }
  EXPECT_FALSE((SmallestLevelJob{prepared.get(), &s.ranking, 3, 2, 5.0}.Validate().ok()));
  EXPECT_FALSE((SmallestLevelJob{prepared.get(), &s.ranking, 1, n, 0.0}.Validate().ok()));
  EXPECT_FALSE((SmallestLevelJob{prepared.get(), nullptr, 1, n, 5.0}.Validate().ok()));
  EXPECT_EQ(*(SmallestLevelJob{prepared.get(), &s.ranking, 4, 4, 5.0}.Run()), 4);
}

TEST(Simd, ParsesTheProgramsSetting) {
  EXPECT_EQ(*ParseSimdChoice(""), SimdChoice::kWidest);
  EXPECT_EQ(*ParseSimdChoice("auto"), SimdChoice::kWidest);
  EXPECT_EQ(*ParseSimdChoice("baseline"), SimdChoice::kBaseline);
  const auto wrong = ParseSimdChoice("baseline2");
  ASSERT_FALSE(wrong.ok());
  EXPECT_NE(wrong.status().message().find("'baseline2'"), std::string::npos);
  EXPECT_EQ(std::string(SimdVersionName(SimdChoice::kBaseline)) == "native",
            std::string(SimdVersionName(SimdChoice::kWidest)) == "native");
}

}  // namespace
}  // namespace motionlod::core
