// The method's guarantees on real characters and motions from ../shared/data.
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <limits>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include "core/rank_joints.h"
#include "core/reduce_skeleton.h"
#include "core/baseline_sequence.h"
#include "core/internal/level_search.h"
#include "core/internal/level_solve.h"
#include "core/internal/prepared_data.h"
#include "core/reference/level_errors_reference.h"
#include "core/reference/skeleton_drift_reference.h"
#include "core/reference/solve_frame_reference.h"
#include "core/solve_levels.h"
#include "io/asset.h"
#include "pipeline/bake.h"
#include "proto/level_format.h"
#include "proto/level_selection.h"

namespace motionlod::pipeline {
namespace {

namespace fs = std::filesystem;

fs::path DataPath(const std::string& relative) { return fs::path(MOTIONLOD_SHARED_DATA) / relative; }

struct RealScene {
  BakeInputs inputs;
  core::JointRanking ranking;
};

// Loads a file (and an optional separate motion), samples `fps` (0 = source), ranks.
RealScene Load(const std::string& file, double fps = 0, int max_frames = 0) {
  RealScene scene;
  auto asset = io::LoadAssetFile(DataPath(file));
  EXPECT_TRUE(asset.ok()) << file << ": " << asset.status().ToString();
  BakeRequest request;
  request.character = *asset;
  request.clips = {{nullptr, "", ""}};  // the first clip
  request.fps = fps;
  auto inputs = PrepareInputs(request);
  EXPECT_TRUE(inputs.ok()) << file << ": " << inputs.status().ToString();
  scene.inputs = std::move(*inputs);
  core::Motion& m = scene.inputs.motion;
  if (max_frames > 0 && m.frame_count > max_frames) {
    m.frame_count = max_frames;
    m.joint_world.resize(static_cast<size_t>(max_frames) * m.joint_count);
  }
  scene.ranking = *core::RankJointsJob{scene.inputs.character.get(), &m, {}}.Run();
  return scene;
}

std::shared_ptr<const core::PreparedMotion> Prepare(const RealScene& s, core::Variant variant) {
  core::SolveSettings settings;
  settings.variant = variant;
  auto prepared = core::PreparedMotion::Create(s.inputs.character, s.inputs.motion, settings);
  EXPECT_TRUE(prepared.ok()) << prepared.status().ToString();
  return *prepared;
}

// A bake of `asset`'s first clip's default ladder in `variant`, without the report's
// skinning pass.
BakeRequest DefaultLadderRequest(std::shared_ptr<const io::Asset> asset, core::Variant variant) {
  BakeRequest request;
  request.character = std::move(asset);
  request.clips = {{nullptr, "", ""}};  // the first clip
  request.settings.variant = variant;
  request.measure_skinning_pass = false;
  return request;
}

core::ReducedSkeleton Level(const RealScene& s, int kept) {
  return *core::ReduceSkeletonToCount(*s.inputs.character, s.ranking, kept);
}

// The variant's own solution with its baseline's figures, before SolveLevel's guard
// against reparenting: what the solver's figures are checked on.
StatusOr<core::LevelResult> SolveUnguarded(const core::PreparedMotion& prepared,
                                           const core::ReducedSkeleton& level) {
  auto result = prepared.SolveOptimized(level);
  if (!result.ok()) return result;
  auto baseline = prepared.BaselineErrors(level);
  if (!baseline.ok()) return baseline.status();
  result->baseline = *std::move(baseline);
  return result;
}

class RealData : public ::testing::Test {
 protected:
  void SetUp() override {
    if (!fs::exists(DataPath("MANIFEST.md"))) GTEST_SKIP() << "../shared/data is absent";
  }
};

TEST_F(RealData, FastSolverEqualsTheNaiveDenseSolvePerFrame) {
  for (const char* file : {"characters/Fox.glb", "characters/CesiumMan.glb"}) {
    const RealScene s = Load(file, 0, 12);
    const int n = s.inputs.character->joint_count();
    for (core::Variant variant : {core::Variant::kVP, core::Variant::kVPNO}) {
      const auto prepared = Prepare(s, variant);
      for (int kept : {n, n / 2, 3}) {
        const core::ReducedSkeleton level = Level(s, kept);
        const auto fast = prepared->SolveLeastSquares(level);
        ASSERT_TRUE(fast.ok());
        for (int t : {0, 5, 11}) {
          const auto naive = core::SolveFrameReference(*prepared, level, t);
          for (int slot = 0; slot < kept; ++slot) {
            const core::Affine34d k = fast->block<4, 3>(4 * slot, 3 * t).transpose();
            EXPECT_LE((k - naive[slot]).norm(), 1e-9 * naive[slot].norm())
                << file << " " << core::VariantName(variant) << " kept " << kept << " t " << t;
          }
        }
      }
    }
  }
}

TEST_F(RealData, NoJointRemovedReproducesTheOriginal) {
  for (const char* file : {"characters/CesiumMan.glb", "characters/Fox.glb", "characters/Orc.gltf",
                           "characters/RobotExpressive.glb", "characters/stormtrooper.dae",
                           "characters/Rig_Medium_General.glb", "motions/cmu_131_01.bvh"}) {
    const RealScene s = Load(file, 0, 60);
    for (core::Variant variant : {core::Variant::kVPNO, core::Variant::kVPNOPD}) {
      const auto prepared = Prepare(s, variant);
      auto result = prepared->SolveLevel(Level(s, s.inputs.character->joint_count()));
      ASSERT_TRUE(result.ok()) << file;
      EXPECT_LT(result->optimized.mean_e, 1e-9) << file << " " << core::VariantName(variant);
      EXPECT_LT(result->optimized.max_vertex_error_pct, 1e-3) << file;
    }
  }
}

TEST_F(RealData, RigidFullLevelKeepsRotationsAndChecksEveryJointOfEveryFrame) {
  // CesiumMan's 19 joints leave the last of the check's groups of four joints padded.
  const RealScene base = Load("characters/CesiumMan.glb", 0, 12);
  const int n = base.inputs.character->joint_count();
  ASSERT_NE(n % 4, 0);
  const auto full_level = [&](const RealScene& s) {
    const auto prepared = Prepare(s, core::Variant::kVPPD);
    auto result = prepared->SolveLevel(Level(s, n));
    EXPECT_TRUE(result.ok()) << result.status().ToString();
    return std::make_pair(prepared, *std::move(result));
  };
  const auto original_of = [&](const core::PreparedMotion& prepared, int t, int joint) {
    const core::Affine34f k =
        prepared.original_matrices().block<4, 3>(4 * joint, 3 * t).transpose().cast<float>();
    return k;
  };
  // The glTF's matrices are rotations to float precision: the level is the original.
  {
    const auto [prepared, result] = full_level(base);
    EXPECT_EQ(result.optimized.mean_e, 0.0);
    for (int t = 0; t < base.inputs.motion.frame_count; ++t) {
      for (int j = 0; j < n; ++j) {
        EXPECT_EQ(result.matrices[static_cast<size_t>(t) * n + j], original_of(*prepared, t, j))
            << t << " " << j;
      }
    }
  }
  // Any one joint that is no rotation in one frame (scaled by 1.01, or mirrored), whatever
  // its lane in its group: the level goes through the solve and the projection, which
  // leaves a rotation where it was (and the original matrices, which a rigid level set
  // could not hold, are no candidate for the level).
  for (int bad = 0; bad < n; ++bad) {
    for (bool mirror : {false, true}) {
      RealScene s = base;
      const int t = mirror ? 0 : s.inputs.motion.frame_count - 1;
      core::Affine34d& world = s.inputs.motion.joint_world[static_cast<size_t>(t) * n + bad];
      if (mirror) {
        world.col(0) *= -1;
      } else {
        world.leftCols<3>() *= 1.01;
      }
      const auto [prepared, result] = full_level(s);
      const core::RowMajorAffine34f& solved = result.matrices[static_cast<size_t>(t) * n + bad];
      EXPECT_NE(solved, original_of(*prepared, t, bad)) << bad << " " << mirror;
      EXPECT_GT(solved.leftCols<3>().cast<double>().determinant(), 0) << bad << " " << mirror;
      EXPECT_GT(result.optimized.mean_e, 0.0) << bad << " " << mirror;
    }
  }
}

TEST_F(RealData, LeastSquaresVariantsAreAtOrBelowTheBaselineAtEveryLevel) {
  for (const char* file : {"characters/Fox.glb", "characters/CesiumMan.glb", "motions/pirouette.bvh"}) {
    const RealScene s = Load(file, 30, 90);
    const auto vpno = Prepare(s, core::Variant::kVPNO);
    const auto vp = Prepare(s, core::Variant::kVP);
    for (int kept = s.ranking.locked_count; kept <= s.inputs.character->joint_count(); ++kept) {
      const core::ReducedSkeleton level = Level(s, kept);
      const auto a = vpno->SolveLevel(level);
      const auto b = vp->SolveLevel(level);
      ASSERT_TRUE(a.ok() && b.ok());
      for (size_t t = 0; t < a->optimized.e.size(); ++t) {
        EXPECT_LE(a->optimized.e[t], a->baseline.e[t] * (1 + 1e-9) + 1e-12) << file << " " << kept;
        const double ep = b->optimized.ep_vertex[t] + b->optimized.ep_joint[t];
        const double ep_base = b->baseline.ep_vertex[t] + b->baseline.ep_joint[t];
        EXPECT_LE(ep, ep_base * (1 + 1e-9) + 1e-15) << file << " " << kept;
      }
    }
  }
}

TEST_F(RealData, ErrorsAreInvariantToARigidTransformOfTheWholeMotion) {
  RealScene s = Load("characters/CesiumMan.glb", 0, 30);
  RealScene moved = s;
  core::Affine34d rigid;
  rigid.leftCols<3>() = Eigen::AngleAxisd(0.9, core::Vec3d(0.3, -1, 0.5).normalized()).toRotationMatrix();
  rigid.col(3) << 12.0, -3.0, 40.0;
  for (core::Affine34d& w : moved.inputs.motion.joint_world) w = core::ComposeAffine(rigid, w);
  for (core::Variant variant : {core::Variant::kVP, core::Variant::kVPNO, core::Variant::kVPPD,
                                core::Variant::kVPNOPD}) {
    const auto a = Prepare(s, variant);
    const auto b = Prepare(moved, variant);
    for (int kept : {10, 4}) {
      const auto ra = a->SolveLevel(Level(s, kept));
      const auto rb = b->SolveLevel(Level(moved, kept));
      ASSERT_TRUE(ra.ok() && rb.ok());
      EXPECT_NEAR(ra->optimized.mean_e, rb->optimized.mean_e, 1e-6 * ra->optimized.mean_e + 1e-12);
      EXPECT_NEAR(ra->optimized.max_vertex_error_pct, rb->optimized.max_vertex_error_pct,
                  1e-4 * ra->optimized.max_vertex_error_pct + 1e-6);
      EXPECT_NEAR(ra->baseline.mean_e, rb->baseline.mean_e, 1e-9 * ra->baseline.mean_e + 1e-12);
    }
  }
}

TEST_F(RealData, RigidVariantsStoreRotationsAndReSolvedTranslationHelps) {
  const RealScene s = Load("characters/RobotExpressive.glb", 0, 40);
  const auto prepared = Prepare(s, core::Variant::kVPNOPD);
  core::SolveSettings keep;
  keep.variant = core::Variant::kVPNOPD;
  keep.resolve_rigid_translation = false;
  const auto kept_t = *core::PreparedMotion::Create(s.inputs.character, s.inputs.motion, keep);
  for (int kept : {30, 15, 6}) {
    const auto r = prepared->SolveLevel(Level(s, kept));
    ASSERT_TRUE(r.ok());
    // Rotations to the rigid level set's 1e-3: a clip that reparenting serves better keeps
    // the source's matrices, whose float rotations RobotExpressive composes to 1e-4.
    for (const core::RowMajorAffine34f& k : r->matrices) {
      const Eigen::Matrix3d rot = k.leftCols<3>().cast<double>();
      ASSERT_NEAR((rot.transpose() * rot - Eigen::Matrix3d::Identity()).norm(), 0,
                  r->sources[0] == core::LevelSource::kSolved ? 1e-5 : 1e-3);
      ASSERT_NEAR(rot.determinant(), 1.0, 1e-3);
    }
    const auto r_keep = kept_t->SolveLevel(Level(s, kept));
    EXPECT_LE(r->optimized.mean_e, r_keep->optimized.mean_e * (1 + 1e-9)) << kept;
  }
}

// Rigid levels keep their skeleton: at every level, each kept joint's distance to its kept
// parent stays within 2% of the character's height of the original's at that frame, and
// the vertex error stays near that of the rigid levels before they kept it (algorithm
// version 6, which stretched bones by up to 16.6% of the height): the sum over levels of the
// mean vertex error within 5% of its sum then, the largest maximum within 1% of the height
// of the largest then (figures of `motionlod bake --all-levels`, % of height).
TEST_F(RealData, RigidLevelsKeepTheirBoneLengthsAtEveryLevel) {
  struct Before {
    const char* file;
    core::Variant variant;
    double mean_sum_pct, max_pct;
  };
  const Before before[] = {
      {"characters/CesiumMan.glb", core::Variant::kVPPD, 30.569, 40.330},
      {"characters/CesiumMan.glb", core::Variant::kVPNOPD, 28.103, 45.268},
      {"characters/Fox.glb", core::Variant::kVPPD, 9.000, 16.512},
      {"characters/Fox.glb", core::Variant::kVPNOPD, 8.973, 16.830},
      {"characters/RobotExpressive.glb", core::Variant::kVPPD, 31.345, 73.824},
      {"characters/RobotExpressive.glb", core::Variant::kVPNOPD, 31.656, 73.813},
      {"characters/Orc.gltf", core::Variant::kVPPD, 33.881, 62.678},
      {"characters/Orc.gltf", core::Variant::kVPNOPD, 35.228, 52.147},
  };
  for (const Before& b : before) {
    const RealScene s = Load(b.file);
    const auto prepared = Prepare(s, b.variant);
    const std::string where = std::string(b.file) + " " + core::VariantName(b.variant);
    double mean_sum = 0, max_max = 0;
    for (int kept = 1; kept <= s.inputs.character->joint_count(); ++kept) {
      const auto r = prepared->SolveOptimized(Level(s, kept));
      ASSERT_TRUE(r.ok()) << where;
      EXPECT_LE(r->optimized.bone_length_drift_pct, 2.0) << where << " kept " << kept;
      mean_sum += r->optimized.mean_vertex_error_pct;
      max_max = std::max(max_max, r->optimized.max_vertex_error_pct);
    }
    EXPECT_LE(mean_sum, 1.05 * b.mean_sum_pct) << where;
    EXPECT_LE(max_max, b.max_pct + 1.0) << where;
  }
}

// The drift figures are those of the naive reference (the motion's world matrices, SVDs),
// to the float precision of the stored matrices, in every variant.
TEST_F(RealData, SkeletonDriftFiguresEqualTheNaiveReference) {
  for (const char* file : {"characters/CesiumMan.glb", "characters/Fox.glb"}) {
    const RealScene s = Load(file, 0, 40);
    const int n = s.inputs.character->joint_count();
    for (core::Variant variant : {core::Variant::kVP, core::Variant::kVPNO, core::Variant::kVPPD,
                                  core::Variant::kVPNOPD}) {
      const auto prepared = Prepare(s, variant);
      for (int kept : {n, n / 2, 4, 1}) {
        const auto r = prepared->SolveOptimized(Level(s, kept));
        ASSERT_TRUE(r.ok());
        const core::SkeletonDriftFigures reference =
            core::SkeletonDriftReference(*s.inputs.character, s.inputs.motion, *r);
        const std::string where =
            std::string(file) + " " + core::VariantName(variant) + " kept " + std::to_string(kept);
        EXPECT_NEAR(r->optimized.bone_length_drift_pct, reference.bone_length_drift_pct, 1e-3)
            << where;
        // acos of the trace resolves small angles to about 1e-6 degrees; the stored matrices
        // are floats.
        EXPECT_NEAR(r->optimized.joint_rotation_drift_deg, reference.joint_rotation_drift_deg, 1e-3)
            << where;
      }
    }
  }
}

// The maximum vertex error search prunes with per-cluster bounds; on real weights
// (many influences per vertex, some tiny) it must still find the exact maximum of the
// optimised and the baseline skin over every vertex and frame.
// The maximum is exact; the means come from a sample of frames and vertices and must
// estimate the surface-weighted means over every vertex and frame.
TEST_F(RealData, VertexFiguresMatchBruteForce) {
  for (const char* file : {"characters/stormtrooper.dae", "characters/Orc.gltf",
                           "characters/CesiumMan.glb", "motions/cmu_131_01.bvh"}) {
    const RealScene s = Load(file, 0, 40);
    const core::Character& c = *s.inputs.character;
    const int n = c.joint_count();
    const core::RawSkin& skin = c.skin();
    const std::vector<double>& areas = c.vertex_areas();
    for (core::Variant variant : {core::Variant::kVP, core::Variant::kVPNOPD}) {
      const auto prepared = Prepare(s, variant);
      const Eigen::MatrixXd& kt = prepared->original_matrices();
      auto original = [&](int joint, int t) -> core::Affine34d {
        return kt.block<4, 3>(4 * joint, 3 * t).transpose();
      };
      for (int kept : {n - 1, n / 2, n / 4, 2}) {
        const auto result = SolveUnguarded(*prepared, Level(s, kept));
        ASSERT_TRUE(result.ok());
        const core::ReducedSkeleton& level = result->skeleton;
        const auto reduced = core::ReduceInfluences(skin, level);
        double optimized = 0, baseline = 0, weight = 0, distance = 0, angle = 0;
        for (int t = 0; t < s.inputs.motion.frame_count; ++t) {
          for (int i = 0; i < c.vertex_count(); ++i) {
            const core::Vec3d v0 = skin.positions[i].cast<double>();
            const core::Vec3d n0 = skin.normals[i].cast<double>();
            core::Vec3d reference = core::Vec3d::Zero(), unoptimized = core::Vec3d::Zero();
            core::Vec3d reference_normal = core::Vec3d::Zero();
            for (uint32_t e = skin.influence_offsets[i]; e < skin.influence_offsets[i + 1]; ++e) {
              const int joint = skin.influence_joints[e];
              reference += skin.influence_weights[e] * core::TransformPoint(original(joint, t), v0);
              reference_normal += skin.influence_weights[e] * core::TransformDirection(original(joint, t), n0);
              const int ancestor = level.kept_joints[level.joint_to_slot[joint]];
              unoptimized += skin.influence_weights[e] * core::TransformPoint(original(ancestor, t), v0);
            }
            core::Vec3d lod = core::Vec3d::Zero(), lod_normal = core::Vec3d::Zero();
            for (uint32_t e = reduced.offsets[i]; e < reduced.offsets[i + 1]; ++e) {
              const core::Affine34d k = result->matrices[t * kept + reduced.slots[e]].cast<double>();
              lod += reduced.weights[e] * core::TransformPoint(k, v0);
              lod_normal += reduced.weights[e] * core::TransformDirection(k, n0);
            }
            optimized = std::max(optimized, (reference - lod).norm());
            baseline = std::max(baseline, (reference - unoptimized).norm());
            weight += areas[i];
            distance += areas[i] * (reference - lod).norm();
            const double cosine = reference_normal.normalized().dot(lod_normal.normalized());
            angle += areas[i] * std::atan2(reference_normal.normalized().cross(lod_normal.normalized()).norm(),
                                           cosine);
          }
        }
        const std::string where = std::string(file) + " " + core::VariantName(variant) + " kept " +
                                  std::to_string(kept);
        EXPECT_NEAR(result->optimized.max_vertex_error_pct, 100 * optimized / c.height(),
                    1e-4 + 1e-5 * result->optimized.max_vertex_error_pct) << where;
        EXPECT_NEAR(result->baseline.max_vertex_error_pct, 100 * baseline / c.height(),
                    1e-4 + 1e-5 * result->baseline.max_vertex_error_pct) << where;
        const double mean_distance_pct = 100 * distance / weight / c.height();
        const double mean_angle_deg = angle / weight * 180 / M_PI;
        // Within 20% (plain sample means were off by up to 2x here); the absolute part is
        // the stored floats' rounding, which the brute force sees at near-exact levels.
        EXPECT_NEAR(result->optimized.mean_vertex_error_pct, mean_distance_pct,
                    0.2 * mean_distance_pct + 1e-4) << where;
        EXPECT_NEAR(result->optimized.mean_normal_error_deg, mean_angle_deg, 0.2 * mean_angle_deg + 1e-4)
            << where;
      }
    }
  }
}

// The figures of real characters' levels, optimised and baseline, are those of their
// skinned meshes (core/reference/level_errors_reference.h), also 1000 heights from the
// origin, where a careless expansion of the quadratic forms would lose every digit.
TEST_F(RealData, LevelFiguresAreThoseOfTheSkinnedMesh) {
  for (const char* file : {"characters/stormtrooper.dae", "characters/Orc.gltf", "motions/cmu_131_01.bvh"}) {
    for (const double distance : {0.0, 1000.0}) {
      RealScene s = Load(file, 0, 24);
      const double height = s.inputs.character->height();
      for (core::Affine34d& w : s.inputs.motion.joint_world) w(0, 3) += distance * height;
      const int n = s.inputs.character->joint_count();
      for (core::Variant variant : {core::Variant::kVP, core::Variant::kVPNOPD}) {
        core::SolveSettings settings;
        settings.variant = variant;
        const auto prepared = *core::PreparedMotion::Create(s.inputs.character, s.inputs.motion, settings);
        for (int kept : {n - 1, n / 2, std::max(s.ranking.locked_count, 3)}) {
          const core::ReducedSkeleton level = Level(s, kept);
          const auto result = SolveUnguarded(*prepared, level);
          ASSERT_TRUE(result.ok());
          const auto solution = core::internal::SolveVariant(prepared->data(), level);
          const core::LevelErrors optimized =
              core::LevelErrorsReference(*prepared, level, solution->Matrices(prepared->data()));
          const core::LevelErrors baseline = core::BaselineErrorsReference(*prepared, level);
          const std::string where = std::string(file) + " " + core::VariantName(variant) + " at " +
                                    std::to_string(distance) + " kept " + std::to_string(kept);
          for (size_t t = 0; t < optimized.e.size(); ++t) {
            EXPECT_NEAR(result->optimized.ep_vertex[t], optimized.ep_vertex[t],
                        1e-9 * optimized.ep_vertex[t] + 1e-12 * height * height)
                << where << " frame " << t;
            EXPECT_NEAR(result->optimized.e[t], optimized.e[t], 1e-9 * optimized.e[t] + 1e-13) << where;
            EXPECT_NEAR(result->baseline.e[t], baseline.e[t], 1e-9 * baseline.e[t] + 1e-13) << where;
          }
          // The search does not refine below 1e-4 % of the height (max_vertex_error.cc).
          EXPECT_NEAR(result->optimized.max_vertex_error_pct, optimized.max_vertex_error_pct,
                      1e-5 * optimized.max_vertex_error_pct + 1e-4) << where;
          EXPECT_NEAR(result->baseline.max_vertex_error_pct, baseline.max_vertex_error_pct,
                      1e-5 * baseline.max_vertex_error_pct + 1e-4) << where;
        }
      }
    }
  }
}

// Baselines evaluated level from level agree with each level's own: every level of a
// ranking, and a ladder's larger steps, each from a character with its own hierarchy.
TEST_F(RealData, BaselineSequenceGivesEachLevelsBaselineErrors) {
  for (const char* file : {"characters/stormtrooper.dae", "characters/RobotExpressive.glb",
                           "characters/Fox.glb", "motions/cmu_131_01.bvh"}) {
    const RealScene s = Load(file, 0, 60);
    const int n = s.inputs.character->joint_count();
    const double height = s.inputs.character->height();
    const auto prepared = Prepare(s, core::Variant::kVPNO);
    std::vector<int> every_level, ladder;
    for (int kept : {n, (3 * n + 2) / 4, (n + 1) / 2, (n + 2) / 4}) {
      if (kept >= s.ranking.locked_count && (ladder.empty() || kept < ladder.back())) ladder.push_back(kept);
    }
    for (int kept = n; kept >= s.ranking.locked_count; --kept) every_level.push_back(kept);
    int restarts = 0;
    for (const std::vector<int>* counts : {&every_level, &ladder}) {
      core::BaselineSequence sequence(prepared);
      core::LevelErrors last;
      for (int kept : *counts) {
        const core::ReducedSkeleton level = Level(s, kept);
        const auto a = prepared->BaselineErrors(level);
        const auto b = sequence.Next(level);
        ASSERT_TRUE(a.ok() && b.ok()) << b.status().ToString();
        const std::string where = std::string(file) + " kept " + std::to_string(kept);
        ASSERT_EQ(b->e.size(), a->e.size());
        for (size_t t = 0; t < a->e.size(); ++t) {
          EXPECT_NEAR(b->ep_vertex[t], a->ep_vertex[t], 1e-9 * a->ep_vertex[t] + 1e-12 * height * height)
              << where << " frame " << t;
          EXPECT_NEAR(b->en_vertex[t], a->en_vertex[t], 1e-9 * a->en_vertex[t] + 1e-12) << where << " frame " << t;
          EXPECT_NEAR(b->e[t], a->e[t], 1e-9 * a->e[t] + 1e-13) << where << " frame " << t;
          EXPECT_EQ(b->ep_joint[t], 0.0) << where;
          EXPECT_EQ(a->ep_joint[t], 0.0) << where;
        }
        EXPECT_NEAR(b->mean_e, a->mean_e, 1e-9 * a->mean_e + 1e-13) << where;
        EXPECT_NEAR(b->rms_vertex_error_pct, a->rms_vertex_error_pct, 1e-9 * a->rms_vertex_error_pct + 1e-12)
            << where;
        // The same maximum: both blend the same vertices in the same float arithmetic.
        EXPECT_EQ(b->max_vertex_error_pct, a->max_vertex_error_pct) << where;
        // The sample's sums add the same values in the same order; only the ratio
        // estimates' exact mean squares are summed another way. The normals of vertices
        // that no change reaches are at exactly 0 degrees in the sequence, where
        // BaselineErrors measures a normal against itself to a few 1e-17 rad (1e-14 deg
        // in the mean at most).
        EXPECT_NEAR(b->mean_vertex_error_pct, a->mean_vertex_error_pct, 1e-9 * a->mean_vertex_error_pct) << where;
        EXPECT_NEAR(b->mean_normal_error_deg, a->mean_normal_error_deg,
                    1e-9 * a->mean_normal_error_deg + 1e-12)
            << where;
        restarts += b->max_vertex_error_pct < last.max_vertex_error_pct;
        last = *b;
      }
      // The same level again changes nothing.
      const auto again = sequence.Next(Level(s, counts->back()));
      ASSERT_TRUE(again.ok());
      EXPECT_EQ(again->max_vertex_error_pct, last.max_vertex_error_pct);
      EXPECT_EQ(again->e, last.e);
      // A level that keeps a joint the last one removed is refused.
      const auto wider = sequence.Next(Level(s, n));
      EXPECT_FALSE(wider.ok()) << file;
      EXPECT_EQ(wider.status().code(), StatusCode::kInvalidArgument);
    }
    // Some level's maximum fell below the one before, which only a search that restarts
    // can find: that path is checked too.
    if (std::string(file) != "characters/Fox.glb") {
      EXPECT_GT(restarts, 0) << file;
    }
  }
}

// An every-level bake takes its baselines one level from the other, on its own thread:
// the report still shows each level's own baseline.
TEST_F(RealData, EveryLevelBakeReportsEachLevelsBaseline) {
  const std::string file = "characters/stormtrooper.dae";
  const RealScene s = Load(file);
  BakeRequest request;
  request.character = *io::LoadAssetFile(DataPath(file));
  request.all_levels = true;
  request.ranking_method = core::RankingMethod::kPaper;  // the levels of s.ranking
  request.threads = 2;
  request.measure_skinning_pass = false;
  const auto baked = Bake(request);
  ASSERT_TRUE(baked.ok()) << baked.status().ToString();
  const auto prepared = Prepare(s, request.settings.variant);
  const nlohmann::json& levels = baked->report.at("levels");
  ASSERT_EQ(static_cast<int>(levels.size()), s.inputs.character->joint_count() - s.ranking.locked_count + 1);
  for (const nlohmann::json& reported : levels) {
    const int kept = reported.at("joints").get<int>();
    const auto own = prepared->BaselineErrors(Level(s, kept));
    ASSERT_TRUE(own.ok());
    EXPECT_NEAR(reported.at("baseline_mean_E").get<double>(), own->mean_e, 1e-9 * own->mean_e) << kept;
    EXPECT_EQ(reported.at("baseline_max_vertex_error_pct").get<double>(), own->max_vertex_error_pct) << kept;
  }
}

// The decision agrees with the exact maximum on either side of it.
TEST_F(RealData, MaxVertexErrorWithinDecidesLikeTheExactMaximum) {
  for (const char* file : {"characters/stormtrooper.dae", "characters/Orc.gltf", "motions/09_11_cmu.fbx"}) {
    const RealScene s = Load(file, 0, 80);
    const int n = s.inputs.character->joint_count();
    for (core::Variant variant : {core::Variant::kVP, core::Variant::kVPNOPD}) {
      const auto prepared = Prepare(s, variant);
      for (int kept : {n / 2, n / 3, n / 4, 2}) {
        const core::ReducedSkeleton level = Level(s, kept);
        const auto exact = SolveUnguarded(*prepared, level);
        ASSERT_TRUE(exact.ok());
        const double maximum = exact->optimized.max_vertex_error_pct;
        const std::string where = std::string(file) + " " + core::VariantName(variant) + " kept " +
                                  std::to_string(kept) + " max " + std::to_string(maximum);
        ASSERT_GT(maximum, 1e-3) << where;
        EXPECT_TRUE(*core::internal::MaxVertexErrorWithin(*prepared, level, maximum * 1.001)) << where;
        EXPECT_FALSE(*core::internal::MaxVertexErrorWithin(*prepared, level, maximum * 0.999)) << where;
        EXPECT_FALSE(*core::internal::MaxVertexErrorWithin(*prepared, level, maximum * 0.2)) << where;
      }
      EXPECT_FALSE(core::internal::MaxVertexErrorWithin(*prepared, Level(s, 2), 0).ok());
    }
  }
}

// The probes' strided frames solve the full motion's problem: a level's matrices and errors
// on every third frame are the full motion's on those frames, in both workloads (the
// kept-space forms' columns are strided too).
TEST_F(RealData, EveryNthFrameSolvesTheFullMotionsProblemOnItsFrames) {
  constexpr int kStride = 3;
  for (const char* file : {"characters/Fox.glb", "motions/09_11_cmu.fbx"}) {
    const RealScene s = Load(file, 0, 100);
    const int n = s.inputs.character->joint_count();
    const int frames = s.inputs.motion.frame_count;
    for (core::Variant variant : {core::Variant::kVP, core::Variant::kVPNOPD}) {
      core::SolveSettings settings;
      settings.variant = variant;
      const auto full = *core::PreparedMotion::Create(s.inputs.character, s.inputs.motion, settings);
      const auto strided = core::internal::EveryNthFrame(*full, kStride);
      ASSERT_TRUE(strided.ok()) << strided.status().ToString();
      const core::PreparedMotion& every_third = **strided;
      ASSERT_EQ(every_third.frame_count(), (frames + kStride - 1) / kStride) << file;
      EXPECT_EQ(every_third.alpha(), full->alpha());
      EXPECT_EQ(every_third.beta(), full->beta());
      for (int kept : {n, n / 2, 2}) {
        const core::ReducedSkeleton level = Level(s, kept);
        const auto a = SolveUnguarded(*full, level);
        const auto b = SolveUnguarded(every_third, level);
        ASSERT_TRUE(a.ok() && b.ok()) << file;
        const std::string where = std::string(file) + " " + core::VariantName(variant) +
                                  " kept " + std::to_string(kept);
        for (int t = 0; t < every_third.frame_count(); ++t) {
          const int source = t * kStride;
          for (int slot = 0; slot < kept; ++slot) {
            const core::RowMajorAffine34f& ka =
                a->matrices[static_cast<size_t>(source) * kept + slot];
            const core::RowMajorAffine34f& kb = b->matrices[static_cast<size_t>(t) * kept + slot];
            EXPECT_LE((ka - kb).norm(), 1e-5f * (1 + ka.norm())) << where << " frame " << source;
          }
          EXPECT_NEAR(b->optimized.e[t], a->optimized.e[source],
                      1e-9 * a->optimized.e[source] + 1e-13)
              << where << " frame " << source;
          EXPECT_NEAR(b->baseline.e[t], a->baseline.e[source],
                      1e-9 * a->baseline.e[source] + 1e-13)
              << where << " frame " << source;
        }
        // Its maximum vertex error is the full one's over fewer frames.
        EXPECT_LE(b->optimized.max_vertex_error_pct,
                  a->optimized.max_vertex_error_pct * (1 + 1e-6))
            << where;
        if (kept < n) {
          EXPECT_GT(b->optimized.max_vertex_error_pct, 0) << where;
        }
      }
    }
    const auto prepared = Prepare(s, core::Variant::kVP);
    EXPECT_FALSE(core::internal::EveryNthFrame(*prepared, 0).ok());
    // A stride past the last frame keeps the first frame alone.
    const auto first = core::internal::EveryNthFrame(*prepared, std::numeric_limits<int>::max());
    ASSERT_TRUE(first.ok());
    EXPECT_EQ((*first)->frame_count(), 1);
    EXPECT_TRUE((*first)->SolveLevel(Level(s, 2)).ok()) << file;
  }
}

TEST_F(RealData, TheReportTimesASkinningPassOnlyWhenAsked) {
  auto asset = io::LoadAssetFile(DataPath("characters/Fox.glb"));
  ASSERT_TRUE(asset.ok());
  BakeRequest request;
  request.character = *asset;
  request.levels = {12};
  request.threads = 1;
  for (bool measure : {true, false}) {
    request.measure_skinning_pass = measure;
    auto output = Bake(request);
    ASSERT_TRUE(output.ok()) << output.status().ToString();
    const nlohmann::json& timing = output->report["timing"];
    EXPECT_GT(timing["bake_seconds"].get<double>(), 0);
    EXPECT_EQ(timing["skinning_pass_seconds"].get<double>() > 0, measure);
    EXPECT_EQ(timing["bake_over_skinning_pass"].get<double>() > 0, measure);
  }
}

// The default ladder, levels by cost: full detail first, then levels each cheaper than the
// one before, each keeping a subset of the finer level's joints, each within the 1 px
// budget at 12 px tall (8.3% of the height), the coarsest at a fraction of the cost.
TEST_F(RealData, TheDefaultLadderGetsCheaperWithinTheBudget) {
  for (const auto& [file, variant] : {std::pair{"characters/CesiumMan.glb", core::Variant::kVPNOPD},
                                      std::pair{"characters/Fox.glb", core::Variant::kVPNOPD},
                                      std::pair{"characters/Fox.glb", core::Variant::kVP}}) {
    {
      auto asset = io::LoadAssetFile(DataPath(file));
      ASSERT_TRUE(asset.ok()) << file;
      BakeRequest request = DefaultLadderRequest(*asset, variant);
      auto output = Bake(request);
      ASSERT_TRUE(output.ok()) << file << ": " << output.status().ToString();
      const std::string what = std::string(file) + " " + core::VariantName(variant);
      const nlohmann::json& levels = output->report["levels"];
      ASSERT_GE(levels.size(), 2u) << what;
      EXPECT_EQ(levels[0]["cost"].get<double>(), 1.0) << what;
      EXPECT_EQ(levels[0]["max_vertex_error_pct"].get<double>(), 0.0) << what;
      for (size_t l = 1; l < levels.size(); ++l) {
        EXPECT_LT(levels[l]["cost"].get<double>(), levels[l - 1]["cost"].get<double>()) << what << " " << l;
        // Each level serves heights no finer level can: it is less accurate, and cheaper
        // (the first may be exact too: full detail stays the original).
        if (l >= 2) {
          EXPECT_GT(levels[l]["max_vertex_error_pct"].get<double>(),
                    levels[l - 1]["max_vertex_error_pct"].get<double>())
              << what << " " << l;
        }
        EXPECT_LE(levels[l]["max_vertex_error_pct"].get<double>(), 100.0 / 12) << what << " " << l;
        EXPECT_LE(levels[l]["joints"].get<int>(), levels[l - 1]["joints"].get<int>()) << what << " " << l;
        for (const auto& name : levels[l - 1]["removed"]) {
          const auto& removed = levels[l]["removed"];
          EXPECT_NE(std::find(removed.begin(), removed.end(), name), removed.end())
              << what << " " << l << ": a coarser level keeps a joint the finer one removed";
        }
      }
      EXPECT_LT(levels.back()["cost"].get<double>(), 0.75) << what;
    }
  }
}

// A clip that scales joints to nothing (Rig_Medium_General's Spawn_Air) is out of a rigid
// variant's reach even at full detail: the bake says which clip.
TEST_F(RealData, ARigidBakeNamesTheClipsItCannotFollow) {
  auto asset = io::LoadAssetFile(DataPath("characters/Rig_Medium_General.glb"));
  ASSERT_TRUE(asset.ok());
  BakeRequest request = DefaultLadderRequest(*asset, core::Variant::kVPNOPD);
  request.clips = {{nullptr, "Hit_A", ""}, {nullptr, "Spawn_Air", ""}};
  request.ladder_heights_px = {50};  // the warning is full detail's: one height will do
  auto output = Bake(request);
  ASSERT_TRUE(output.ok()) << output.status().ToString();
  std::string named;
  for (const std::string& warning : output->warnings) {
    if (warning.find("cannot follow the joint scaling") != std::string::npos) named = warning;
  }
  EXPECT_NE(named.find("'Spawn_Air'"), std::string::npos) << named;
  EXPECT_EQ(named.find("Hit_A"), std::string::npos) << named;
  const nlohmann::json& full = output->report["levels"][0];
  EXPECT_GT(full["per_clip"][1]["max_vertex_error_pct"].get<double>(), 1.0);
  EXPECT_LT(full["per_clip"][0]["max_vertex_error_pct"].get<double>(), 0.1);
}

// The levels by cost are the same on any number of threads: the ladder, and the level set
// to the byte.
TEST_F(RealData, TheDefaultLadderDoesNotDependOnTheThreads) {
  for (const char* file : {"characters/Fox.glb"}) {
    for (core::Variant variant : {core::Variant::kVP, core::Variant::kVPNOPD}) {
      auto asset = io::LoadAssetFile(DataPath(file));
      ASSERT_TRUE(asset.ok()) << file;
      BakeRequest request = DefaultLadderRequest(*asset, variant);
      std::string one_thread_bytes;
      std::vector<int> one_thread_ladder;
      for (int threads : {1, 3}) {
        request.threads = threads;
        auto output = Bake(request);
        ASSERT_TRUE(output.ok()) << file << ": " << output.status().ToString();
        std::vector<int> ladder;
        for (const nlohmann::json& level : output->report["levels"]) {
          ladder.push_back(level["joints"].get<int>());
        }
        if (threads == 1) {
          ASSERT_GE(ladder.size(), 2u) << file << ": the ladder saves nothing";
          one_thread_bytes = output->level_set;
          one_thread_ladder = ladder;
          continue;
        }
        EXPECT_EQ(ladder, one_thread_ladder) << file << " " << core::VariantName(variant) << " " << threads;
        EXPECT_TRUE(output->level_set == one_thread_bytes)
            << file << " " << core::VariantName(variant) << " " << threads;
      }
    }
  }
}

// A bake of several clips: one reduced skeleton per level for all of them, nested levels,
// every clip's level no worse than reparenting it, rigid levels within 2% of their bone
// lengths, the chosen levels' errors falling as joints are added, and a level set whose
// clips each hold their own frames.
TEST_F(RealData, CharacterWideLevelsServeEveryClip) {
  struct Case {
    const char* file;
    std::vector<std::string> clips;  // empty: every animation
    size_t clip_count;
    std::vector<core::Variant> variants;
  };
  const std::vector<core::Variant> all = {core::Variant::kVP, core::Variant::kVPNO,
                                          core::Variant::kVPPD, core::Variant::kVPNOPD};
  const Case cases[] = {{"characters/Fox.glb", {}, 3, all},
                        {"characters/CesiumMan.glb", {}, 1, all},
                        {"characters/RobotExpressive.glb", {"Idle", "Punch", "Jump"}, 3,
                         {core::Variant::kVP, core::Variant::kVPNOPD}}};
  for (const Case& c : cases) {
    for (core::Variant variant : c.variants) {
      BakeRequest request;
      request.character = *io::LoadAssetFile(DataPath(c.file));
      for (const std::string& clip : c.clips) request.clips.push_back({nullptr, clip, ""});
      request.all_levels = true;
      request.settings.variant = variant;
      request.threads = 2;
      request.measure_skinning_pass = false;
      const auto baked = Bake(request);
      ASSERT_TRUE(baked.ok()) << baked.status().ToString();
      const std::string where = std::string(c.file) + " " + core::VariantName(variant);
      const nlohmann::json& report = baked->report;
      EXPECT_EQ(report["ranking_method"], "greedy");
      ASSERT_EQ(report["clips"].size(), c.clip_count) << where;
      const proto::AlignedBytes bytes = proto::AlignedBytes::CopyOf(baked->level_set);
      const auto view = proto::DecodeLevelSet(bytes.bytes());
      ASSERT_TRUE(view.ok()) << view.status().ToString();
      ASSERT_EQ(view->clips().size(), c.clip_count);
      for (size_t k = 0; k < c.clip_count; ++k) {
        EXPECT_EQ(view->clips()[k].name, report["clips"][k]["name"].get<std::string>());
        EXPECT_EQ(view->clips()[k].frame_count, report["clips"][k]["frames"].get<uint32_t>());
      }
      std::vector<double> max_error_fraction;
      for (uint32_t l = 0; l < view->level_count(); ++l) {
        const nlohmann::json& level = report["levels"][l];
        const std::string at = where + " at " + std::to_string(level["joints"].get<int>()) + " joints";
        ASSERT_EQ(level["per_clip"].size(), c.clip_count);
        double worst = 0;
        for (const nlohmann::json& clip : level["per_clip"]) {
          EXPECT_LE(clip["max_vertex_error_pct"].get<double>(), clip["baseline_max_vertex_error_pct"].get<double>()) << at;
          EXPECT_LE(clip["mean_vertex_error_pct"].get<double>(), clip["baseline_mean_vertex_error_pct"].get<double>()) << at;
          worst = std::max(worst, clip["max_vertex_error_pct"].get<double>());
        }
        EXPECT_EQ(level["max_vertex_error_pct"].get<double>(), worst) << at;
        if (core::IsRigid(variant)) {
          EXPECT_LE(level["bone_length_drift_pct"].get<double>(), 2.0) << at;
        }
        max_error_fraction.push_back(level["max_vertex_error_pct"].get<double>() / 100);
        // Nested: each level keeps every joint of the next coarser one.
        if (l + 1 < view->level_count()) {
          const auto finer = view->level(l).kept_joints(), coarser = view->level(l + 1).kept_joints();
          EXPECT_TRUE(std::includes(finer.begin(), finer.end(), coarser.begin(), coarser.end())) << at;
        }
        // Each clip's one-level file holds that clip's frames of the level.
        const uint32_t k = static_cast<uint32_t>(l % c.clip_count);
        const auto one = proto::ExtractLevelClip(*view, l, k);
        ASSERT_TRUE(one.ok()) << one.status().ToString();
        const proto::AlignedBytes one_bytes = proto::AlignedBytes::CopyOf(*one);
        const auto clip_view = proto::DecodeLevelSet(one_bytes.bytes());
        ASSERT_TRUE(clip_view.ok());
        ASSERT_EQ(clip_view->frame_count(), view->clips()[k].frame_count);
        EXPECT_EQ(clip_view->level(0).frame(0)[5], view->level(l).frame(view->clips()[k].first_frame)[5]) << at;
      }
      // The levels the table chooses: fewer joints, never less error.
      const std::vector<proto::LevelRange> ranges = proto::LevelRanges(max_error_fraction, 1.0);
      double finer_error = 0;
      for (size_t l = 0; l < ranges.size(); ++l) {
        if (!ranges[l].chosen) continue;
        EXPECT_GE(max_error_fraction[l], finer_error) << where << " level " << l;
        finer_error = max_error_fraction[l];
      }
    }
  }
}

TEST_F(RealData, BakeWritesALevelSetThatDecodesToTheSolvedMatrices) {
  auto asset = io::LoadAssetFile(DataPath("characters/Fox.glb"));
  ASSERT_TRUE(asset.ok());
  BakeRequest request;
  request.character = *asset;
  request.clips = {{nullptr, "Walk", ""}};
  request.levels = {24, 12, 5};
  request.ranking_method = core::RankingMethod::kPaper;
  request.threads = 2;
  auto output = Bake(request);
  ASSERT_TRUE(output.ok()) << output.status().ToString();
  const proto::AlignedBytes bytes = proto::AlignedBytes::CopyOf(output->level_set);
  auto view = proto::DecodeLevelSet(bytes.bytes());
  ASSERT_TRUE(view.ok()) << view.status().ToString();
  ASSERT_EQ(view->level_count(), 3u);
  EXPECT_EQ(view->joint_count(), 24u);
  EXPECT_TRUE(view->rigid());
  const nlohmann::json& report = output->report;
  EXPECT_EQ(report["character"]["joints"], 24);
  EXPECT_EQ(report["levels"].size(), 3u);
  EXPECT_EQ(report["motion"]["frames"].get<uint32_t>(), view->frame_count());

  // The same levels solved in-process, each no worse than the coarser, give the same
  // matrices.
  auto inputs = PrepareInputs(request);
  ASSERT_TRUE(inputs.ok());
  const auto ranking = *core::RankJointsJob{inputs->character.get(), &inputs->motion, {}}.Run();
  const auto prepared = *core::PreparedMotion::Create(inputs->character, inputs->motion, request.settings);
  std::map<int, core::LevelResult> solved;
  for (int kept : request.levels) {
    solved[kept] = *prepared->SolveLevel(*core::ReduceSkeletonToCount(*inputs->character, ranking, kept));
  }
  ASSERT_TRUE(LiftCoarserLevels(*prepared, solved).ok());
  const core::LevelResult* level = &solved.at(12);
  const proto::LevelView& stored = view->level(1);
  ASSERT_EQ(stored.kept_count(), 12u);
  for (uint32_t t = 0; t < stored.frame_count(); ++t) {
    for (uint32_t s = 0; s < 12; ++s) {
      const float* k = stored.matrix(t, s);
      for (int q = 0; q < 12; ++q) {
        ASSERT_EQ(k[q], level->matrices[t * 12 + s](q / 4, q % 4)) << t << " " << s;
      }
    }
  }
  EXPECT_FLOAT_EQ(stored.figures().max_vertex_error_pct,
                  static_cast<float>(level->optimized.max_vertex_error_pct));
  // The bake solves a level's optimised half and its baseline as separate tasks on its
  // threads: both land on that level.
  const nlohmann::json& reported = report["levels"][1];
  ASSERT_EQ(reported["joints"], 12);
  EXPECT_EQ(reported["mean_E"].get<double>(), level->optimized.mean_e);
  EXPECT_EQ(reported["baseline_mean_E"].get<double>(), level->baseline.mean_e);
  EXPECT_EQ(reported["baseline_max_vertex_error_pct"].get<double>(), level->baseline.max_vertex_error_pct);
}

}  // namespace
}  // namespace motionlod::pipeline
