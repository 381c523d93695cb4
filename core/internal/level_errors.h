// Step 5's figures (LevelErrors, core/solve_levels.h) of any candidate matrices, from
// Delta_k(t) = K'_phi(k)(t) - K_k(t) without skinning the mesh:
//   sum_i a_i |v_i - v'_i|^2 = sum_kl tr(Delta_k Cp_kl Delta_l^T)   (the same with Cn)
// summed over the joint pairs that share vertices; the maximum vertex error by the
// bounded search of core/max_vertex_error.cc; the mean error and angle on the sample.
// The naive reference, which skins every vertex of every frame, is
// core/reference/level_errors_reference.h.
#pragma once

#include <cstddef>
#include <limits>
#include <span>
#include <vector>

#include "base/pieces.h"
#include "core/internal/error_sample.h"
#include "core/internal/prepared_data.h"

namespace motionlod::core::internal {

enum class Figures {
  kQuadratic,       // E and its parts per frame, their means and maxima, the RMS error
  kMaxVertexError,  // the exact maximum vertex error and where it is
  kAll,             // both and the sampled figures: every field of LevelErrors
};

// The figures of `delta` for a level keeping `kept` (original indices). The quadratic
// figures (with the sampled ones) and the maximum read the same Delta and nothing of each
// other: with both asked for, they are two pieces on `run`, and the figures do not depend
// on the runner. A finite `decide_within` (length) makes the maximum search a decision: it
// stops at the first vertex past it, so the maximum it reports is only on the right side
// of it.
void EvaluateErrors(const PreparedData& d, const DeltaView& delta, const std::vector<int>& kept,
                    Figures figures, LevelErrors& out,
                    double decide_within = std::numeric_limits<double>::infinity(),
                    const PieceRunner& run = {});

// The joint pairs whose both joints' Delta can be nonzero: the others add nothing.
std::vector<size_t> ActivePairs(const PreparedData& d, const DeltaView& delta);

// The figures of a motion's clips (LevelErrors::per_clip, each of its own frames, in the
// order of `clips`): the worst clip's figures, every frame's per-frame parts, and the
// clips themselves as per_clip.
LevelErrors WorstOverClips(std::vector<LevelErrors> per_clip, std::span<const MotionClip> clips);

// The figures that follow from the per-frame parts of E (e, mean_e, max_e, the RMS error)
// and, where given, from the sample's sums.
void FinishErrors(const PreparedData& d, const SampleSums* sums, LevelErrors& out);

}  // namespace motionlod::core::internal
