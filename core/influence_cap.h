// Beyond the paper (#44): a level's influences capped at k per vertex, the weights
// re-solved rather than truncated. Skinning costs vertices x influences, and fewer joints
// barely lower the influences per vertex, so a far level also keeps fewer of them.
//
// Weight step, per vertex i with vbar = [v0_i; 1] and nbar = [n0_i; 0]: the weights W_i
// (at most k non-zero, W >= 0, sum W = 1) that minimise, over every frame t,
//   |sum_s W_is K'_s(t) vbar - v_i(t)|^2 + mu |sum_s W_is K'_s(t) nbar - n_i(t)|^2
// against the original skinning v_i(t) = sum_j w_ij K_j(t) vbar (n_i alike), for the
// level's matrices K'_s(t) held fixed. Its quadratic form needs no loop over frames per
// vertex: with the frame sums P_ss' = sum_t K'_s(t)^T K'_s'(t) and
// Q_sj = sum_t K'_s(t)^T K_j(t) (4x4 each, independent of the vertex),
//   G_ab = vbar^T P_{s_a s_b} vbar + mu nbar^T P nbar,  r_a = sum_j w_ij (vbar^T Q_{s_a j} vbar +
//   ...)
// and the objective is W^T G W - 2 r^T W + const. The candidates are the slots the vertex's
// influences move to (ReduceInfluences) and their kept parents, at most kMaxCandidates;
// every support of at most k of them is solved exactly under sum W = 1 and the best one
// with non-negative weights wins, so the result is never worse (in this objective) than
// truncating the merged weights and renormalising, whose support is one of those tried.
//
// Matrix step (affine variants), the paper's solve with these weights: the K'_s(t) that
// minimise the area-weighted sum over vertices and frames of the same objective, with
// moments G_ss' = sum_i a_i W_is W_is' vbar vbar^T and C_sj = sum_i a_i W_is w_ij vbar vbar^T
// (normals alike): one factorisation of G, every frame a right-hand side. Alternating the
// two steps lowers the objective each round. Rigid levels keep their matrices (their
// rotations and bone lengths are what a rigid level promises); only their weights move.
//
// The naive reference (core/reference/influence_cap_reference.h) forms G and r by skinning
// every frame.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "base/status.h"
#include "core/reduce_skeleton.h"
#include "core/solve_levels.h"
#include "core/types.h"

namespace motionlod::core {

inline constexpr int kMaxInfluencesPerVertex = 8;
// Candidate slots per vertex the weight step chooses its support from.
inline constexpr int kMaxCandidates = 8;

// A level's influences, k per vertex (fixed width, what a GPU skinner reads): entry
// (i, e) at i * k + e, in decreasing weight; unused entries have weight 0 and repeat the
// vertex's first slot.
struct LevelInfluences {
  int per_vertex = 0;           // k in [1, kMaxInfluencesPerVertex]
  std::vector<uint16_t> slots;  // p x k, slots s of the level's kept joints
  std::vector<float> weights;   // p x k, >= 0, each vertex's summing to 1
  int vertex_count() const {
    return per_vertex > 0 ? static_cast<int>(slots.size()) / per_vertex : 0;
  }
  // Non-zero weights over vertices, on average.
  double mean_used() const;
};

// The merged influences of `level` (ReduceInfluences), the k largest of each vertex kept
// and renormalised: what engines do when they cap influences.
StatusOr<LevelInfluences> TruncateInfluences(const Character& character,
                                             const ReducedSkeleton& level, int cap);

// The weight step for the character `prepared` was made from (its vertices, its original
// skinning over its frames).
struct InfluenceCapJob {
  const PreparedMotion* prepared = nullptr;
  const ReducedSkeleton* level = nullptr;       // of prepared->character()
  std::span<const RowMajorAffine34f> matrices;  // T x m, the level's K'_s(t), frame-major
  int cap = 4;                                  // k
  double normal_weight = 0;                     // mu >= 0, the normals' weight (length^2)

  Status Validate() const;
  StatusOr<LevelInfluences> Run() const;
};

// The matrix step: the level's affine K'_s(t) (T x m, frame-major) for fixed influences,
// minimising the area-weighted objective above (normals weighted by normal_weight) plus a
// Tikhonov term of relative weight `regularization` towards the given matrices (a kept
// joint that no vertex follows any more keeps them).
struct InfluenceMatrixJob {
  const PreparedMotion* prepared = nullptr;
  const ReducedSkeleton* level = nullptr;
  std::span<const RowMajorAffine34f> matrices;  // T x m, the level's current K'_s(t)
  const LevelInfluences* influences = nullptr;  // p x k, of prepared->character()
  double normal_weight = 0;
  double regularization = 1e-7;

  Status Validate() const;
  StatusOr<std::vector<RowMajorAffine34f>> Run() const;
};

// Per vertex, the objective of the weight step (sum over frames, length^2) of `influences`
// with `matrices`: what the tests and the bench compare re-solved and truncated weights by.
// Indexing as InfluenceCapJob.
StatusOr<std::vector<double>> InfluenceObjective(const PreparedMotion& prepared,
                                                 const ReducedSkeleton& level,
                                                 std::span<const RowMajorAffine34f> matrices,
                                                 const LevelInfluences& influences,
                                                 double normal_weight);

}  // namespace motionlod::core
