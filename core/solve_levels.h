// Steps 3-5 (sec. 4.2-4.4): per level, the skinning matrices K'_s(t) of the kept joints
// that minimise E(t) of eq. (2), and the errors people read.
//
// Letters: i vertex (p), k or j original joint (n), s kept slot (m), t frame (T),
// c output coordinate (x, y, z). phi(k) = ReducedSkeleton::joint_to_slot[k].
//
// Objective, per frame (eqs. 2-4 with the weights this product uses):
//   E(t)  = alpha * Ep(t) + beta * En(t)
//   Ep(t) = sum_i a_i |v_i - v'_i|^2 + omega * sum_{j kept} b_j |p_j - p'_j|^2   (length^2)
//   En(t) = sum_i a_i |n_i - n'_i|^2 + omega * sum_{j kept} b_j |o_j - o'_j|^2   (unitless)
//   a_i = A_i / sum A   (area fraction: the vertex part is the surface-mean square error)
//   b_j = l_j / sum l   (the joint part is a length-weighted mean over joints)
//   omega = SolveSettings::joint_weight (default 0.1): the mesh, which is what users see,
//           is not swamped by the joint rows (METHOD.md, pitfalls).
//   alpha = 1 / max_t Ep(t), beta = 1 / max_t En(t) of the *root-only* skeleton with
//           unoptimised matrices: the paper's normalisation by the maximum error, taken on
//           a reference that depends on the character and motion only (not on the levels
//           asked for), so E is comparable across levels, variants and runs.
//   n_i are the unnormalised blended normals (linear blending cannot produce unit
//   normals; unit targets would stop the full skeleton from reproducing itself).
//   VP fits with beta = 0 but reports E with both terms.
//
// Structure (METHOD.md): every row of eq. (6) involves one coordinate, so the three
// coordinates share the normal matrix G (4m x 4m), which is frame independent:
//   G = P Q P^T + S J S^T + lambda I      (S J S^T: J_j on the diagonal block of kept j)
//   Q = alpha Cp + beta Cn          (4n x 4n, block-sparse: pairs of joints sharing vertices)
//   Cp_kl = sum_i a_i w_ik w_il [v0_i;1][v0_i;1]^T,   Cn_kl = sum_i a_i w_ik w_il [n0_i;0][n0_i;0]^T
//   J_j = omega b_j (alpha [p0_j;1][p0_j;1]^T + beta [o0_j;0][o0_j;0]^T)
//   P (4m x 4n) sums original joints into their slot, S picks the kept joints.
// The targets v_i = sum_l w_il K_l [v0_i;1] are linear in the original matrices, so the
// right-hand side of every frame is B(t) = (P Q + S J + lambda S) Kt(t), with Kt(t) the
// stack of K_k(t)^T (4n x 3) and J block-diagonal over all joints: the
// per-original-joint accumulations D_k(t) of METHOD.md reduce to
// F = Q Kt, computed once for all frames and shared by every level, and the mesh is never
// skinned while baking. Each level factors G once and solves all 3T columns at once.
// lambda = SolveSettings::regularization * trace(G) / 4m pulls each K'_s towards the
// original K of its own joint, so joints with too few or coplanar vertices stay
// determined without moving well-determined solutions measurably.
// Errors of any candidate (optimised, rotation-projected, unoptimised baseline) come from
// Delta_k(t) = K'_phi(k)(t) - K_k(t): sum_i a_i |v_i - v'_i|^2 = sum_kl tr(Delta_k Cp_kl Delta_l^T),
// again without skinning.
//
// Where each step lives (a newcomer reads the reference first):
//   prepare_motion.cc     Kt, the pairs' moments, alpha and beta, F          (Create)
//   normal_equations.cc   G, B, the block Cholesky factor, X    reference/solve_frame_reference.h
//   rigid_projection.cc   polar projection, translation re-solve under the bone lengths,
//                         rotation re-fit                          reference/polar_reference.h
//   skeleton_drift.cc     bone length and rotation drift     reference/skeleton_drift_reference.h
//   level_errors.cc       E and its parts, RMS, sampled figures   reference/level_errors_reference.h
//   max_vertex_error.cc   the exact maximum by bounded search     reference/level_errors_reference.h
//   baseline_sequence.h   baselines of nested levels            BaselineErrors level by level
//   smallest_level.h      the fewest joints within a bound (bisection on probe frames)
//   greedy_ranking.h      removal by error                  reference/greedy_ranking_reference.h
// and, for levels by cost (pipeline/cost_levels.h), beyond the paper:
//   influence_cap.h       k influences per vertex, re-solved   reference/influence_cap_reference.h
//   simplify_mesh.h       a simplified mesh (meshoptimizer) and the points that stand for
//                         the removed vertices
//   pose_rate.h           stored frames and their interpolation
//   level_deviation.h     the honest error of a level's own surface (skins every frame)
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <string_view>
#include <vector>

#include "base/pieces.h"
#include "base/status.h"
#include "core/character.h"
#include "core/motion.h"
#include "core/reduce_skeleton.h"
#include "core/simd.h"
#include "core/types.h"

namespace motionlod::core {

namespace internal {
struct PreparedData;  // core/internal/prepared_data.h
}  // namespace internal

// The paper's variants: fitted rows (positions, or positions and normals) and whether
// each K' is projected on its rotation by polar decomposition (eq. 8).
enum class Variant { kVP, kVPNO, kVPPD, kVPNOPD };
const char* VariantName(Variant variant);  // "vp", "vpno", "vp+pd", "vpno+pd"
StatusOr<Variant> ParseVariant(std::string_view name);
inline bool IsRigid(Variant v) { return v == Variant::kVPPD || v == Variant::kVPNOPD; }
inline bool FitsNormals(Variant v) { return v == Variant::kVPNO || v == Variant::kVPNOPD; }

// Bumped whenever results for the same inputs and settings may change.
inline constexpr uint32_t kAlgorithmVersion = 9;

struct SolveSettings {
  Variant variant = Variant::kVPNOPD;
  // Rigid variants: after the projection, re-solve each translation with its rotation
  // fixed (the exact minimiser of E over them) under the bone lengths, and re-fit the
  // rotations (core/internal/rigid_projection.h); false keeps the solved translation, and
  // with it the bones' stretch.
  bool resolve_rigid_translation = true;
  double joint_weight = 0.1;     // omega, >= 0
  double regularization = 1e-7;  // relative Tikhonov weight, > 0
  // The sampled figures (mean vertex error, mean normal angle) use up to this many evenly
  // spaced frames and vertices per frame, and no more vertices per frame than keep the
  // sample within 1% of the motion's vertex-frames (64 at least), so a short clip of a
  // small mesh is not sampled more densely than a long one. The maximum vertex error is
  // exact over every frame.
  int sample_frames = 8;
  int sample_vertices = 512;

  Status Validate() const;
  uint64_t Hash() const;  // feeds cache keys together with kAlgorithmVersion
};

struct LevelErrors {
  // Per frame (T each): E and its four parts, alpha and beta not applied.
  std::vector<double> e, ep_vertex, ep_joint, en_vertex, en_joint;
  double mean_e = 0, max_e = 0;
  int max_e_frame = 0;
  // Largest |v_i(t) - v'_i(t)| over every vertex and frame, percent of the height.
  double max_vertex_error_pct = 0;
  int max_vertex_frame = 0, max_vertex_index = 0;
  // Surface-area-weighted RMS of |v - v'| over every vertex and frame, percent of height.
  double rms_vertex_error_pct = 0;
  // Area-weighted mean of |v - v'| (percent of height) and of the angle between the
  // blended normals (degrees) over the sample of SolveSettings.
  double mean_vertex_error_pct = 0;
  double mean_normal_error_deg = 0;
  // How far the kept joints stray from the original skeleton over every frame
  // (core/internal/skeleton_drift.h): the largest change of a kept joint's distance to its
  // kept parent, percent of the height, and the largest angle between a kept joint's
  // rotation (polar factor) and its original's, degrees. Zero for the baseline, whose
  // kept joints keep their original matrices.
  double bone_length_drift_pct = 0;
  double joint_rotation_drift_deg = 0;
  // Each clip's figures (Motion::clips, in order) on its own frames: frame and vertex
  // indices within the clip, per_clip empty. The figures above are the worst clip's (each
  // on its own: mean_e the largest clip mean, max_e_frame and max_vertex_frame frames of
  // the whole motion) and the per-frame vectors cover every frame; with one clip, its one
  // entry equals them.
  std::vector<LevelErrors> per_clip;
};

// Where a clip's matrices of a level come from.
enum class LevelSource {
  kSolved,        // the variant's solution
  kReparented,    // the kept joints' original matrices: the solution was worse (KeepNoWorse...)
  kCoarserLevel,  // a coarser level's matrices: this level's were worse (LiftCoarserLevel)
};
const char* LevelSourceName(LevelSource source);  // "solved", "reparented", "coarser level"

struct LevelResult {
  ReducedSkeleton skeleton;
  // T x m, row-major by frame: K'_s(t) maps bind-pose model space to posed model space.
  std::vector<RowMajorAffine34f> matrices;
  LevelErrors optimized;  // of `matrices`
  LevelErrors baseline;   // kept joints keep their original matrices
  std::vector<LevelSource> sources;  // per clip
};

// Everything shared by the levels of one (character, motion, settings): built once,
// immutable, thread-safe to solve levels from concurrently.
class PreparedMotion {
 public:
  // `simd`: which machine version of the hot loops runs (core/simd.h). Create's per-frame
  // work runs in pieces on `run` (base/pieces.h); the result does not depend on the runner.
  static StatusOr<std::shared_ptr<const PreparedMotion>> Create(
      std::shared_ptr<const Character> character, const Motion& motion,
      const SolveSettings& settings, SimdChoice simd = SimdChoice::kWidest,
      const PieceRunner& run = {});
  // Made by Create (and the core's own steps) only: the data is the core's.
  explicit PreparedMotion(std::unique_ptr<const internal::PreparedData> data);
  ~PreparedMotion();

  const Character& character() const;
  const SolveSettings& settings() const;
  int frame_count() const;
  double alpha() const;
  double beta() const;
  // K_j(t)^T stacked: 4n x 3T, block (4j, 3t) = K_j(t)^T.
  const Eigen::MatrixXd& original_matrices() const;
  // Motion::Clips() of the motion it was made from.
  std::span<const MotionClip> clips() const;

  // Solves one level with every figure, optimised and baseline, no worse than the baseline
  // (KeepNoWorseThanReparenting). Allocates per level, never per frame.
  StatusOr<LevelResult> SolveLevel(const ReducedSkeleton& level) const;
  // SolveLevel in two independent halves, to run concurrently: the matrices with the
  // optimised figures (LevelResult::baseline left empty), and the baseline's figures, which
  // do not depend on the solution. Each evaluates its figures in two pieces on `run`
  // (base/pieces.h); the results do not depend on the runner.
  StatusOr<LevelResult> SolveOptimized(const ReducedSkeleton& level, const PieceRunner& run = {}) const;
  StatusOr<LevelErrors> BaselineErrors(const ReducedSkeleton& level, const PieceRunner& run = {}) const;

  // The unconstrained least-squares solution in double precision, before any polar
  // projection: 4m x 3T, block (4s, 3t) = K'_s(t)^T. What SolveLevel starts from.
  StatusOr<Eigen::MatrixXd> SolveLeastSquares(const ReducedSkeleton& level) const;

  // Step 5b, beyond the paper: a level is never worse than reparenting. Where a clip's
  // solution has a larger maximum or mean vertex error than the baseline's (possible:
  // least squares minimises the weighted square sum, not the maximum; the rigid projection
  // and the regulariser move off the minimiser), that clip takes the baseline's matrices
  // and figures; in the rigid variants only where the original matrices are rotations.
  // Needs result.baseline.
  void KeepNoWorseThanReparenting(LevelResult& result) const;
  // `finer` keeps every joint `coarser` keeps: each clip whose maximum vertex error is
  // above the coarser level's takes the coarser level's matrices (each kept joint its
  // coarser ancestor's: the same mesh, so the same vertex figures) where that stays no
  // worse than the finer level's baseline (and, rigid, within the bone lengths' 2%), so
  // that adding joints never raises the error.
  Status LiftCoarserLevel(const LevelResult& coarser, LevelResult& finer) const;

  // The core's steps read the prepared data (core/internal/prepared_data.h).
  const internal::PreparedData& data() const { return *data_; }

 private:
  std::unique_ptr<const internal::PreparedData> data_;
};

}  // namespace motionlod::core
