// The exact maximum vertex error of a level, max over i and t of |d_i(t)|, with
// d_i(t) = sum_g w_ig Delta_g(t) [v0_i; 1], found without evaluating most vertices: every
// vertex of a box with center c and half extents h (bind pose) has
//   |Delta_g [v;1]| <= U_g(t) = |Delta_g [c;1]| + sum_a |Delta_g(3x3) e_a| h_a,
// so a set of vertices whose joints g weight them within [a_g, b_g] has |d_i| at most the
// largest sum_g w_g U_g over weights in those ranges that sum to 1. Bounds nest: per frame
// and vertex group (dominant joint, from the joints' boxes), then the group's own box, then
// per cluster (core/internal/skin_clusters.h); frames and groups are visited by decreasing
// bound and only clusters whose bound beats the best exact value so far are evaluated.
// The naive reference, every vertex of every frame, is in
// core/reference/level_errors_reference.h.
#pragma once

#include <cstdint>
#include <vector>

#include "core/internal/prepared_data.h"

namespace motionlod::core::internal {

// The per-frame bounds of the search over a set of vertex groups: the others' bounds stay
// 0, so the search never visits them.
struct MaxSearchBounds {
  std::vector<int> groups;          // the groups bounded (nonempty ones)
  std::vector<int> joints;          // the joints that weight them (their Delta is read)
  std::vector<double> group_bound;  // n x T: bound of group j's vertices in frame t at jT + t
  std::vector<double> frame_bound;  // T
  // Scratch: the joints' box bounds U_k in the frames of the batch of kGroupBoundFrames
  // that FrameBounds is filling, joint k's at kGroupBoundFrames k.
  std::vector<double> joint_bound;
};
inline constexpr int kGroupBoundFrames = 4;

// Where a search starts: the largest |d_i(t)|^2 known (in float, as the search compares
// them) and where it is.
struct MaxSearchStart {
  float best_squared = 0;
  int frame = 0, vertex = 0;
};

// Bounds of every nonempty group, or (group_mask) of the groups it flags, and of those only
// where a joint that `moving` flags weights them, from those joints alone: the others'
// Delta is zero (a baseline's kept joints).
MaxSearchBounds MakeMaxSearchBounds(const PreparedData& d, const std::vector<uint8_t>* group_mask,
                                    const std::vector<uint8_t>& moving);

// Called for every frame, 0 to T - 1: the bounds are computed a batch of kGroupBoundFrames
// frames at a time, when the batch's last frame (or frame T - 1) comes.
void FrameBounds(const PreparedData& d, const DeltaView& delta, int t, MaxSearchBounds& bounds);

// Sets out.max_vertex_error_pct, max_vertex_frame and max_vertex_index. The search starts
// from `start` (a value some vertex attains) and evaluates only the clusters that
// cluster_mask flags (nullptr: every cluster). A finite `decide_within` (length) stops it
// at the first vertex past that value. Returns where it ended, the start of a later search.
MaxSearchStart MaxVertexError(const PreparedData& d, const DeltaView& delta,
                              const MaxSearchBounds& bounds, double decide_within,
                              const MaxSearchStart& start, const std::vector<uint8_t>* cluster_mask,
                              LevelErrors& out);

}  // namespace motionlod::core::internal
