#include "core/internal/max_vertex_error.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <utility>

#include "core/internal/lanes.h"
#include "core/internal/simd_dispatch.h"
#include "core/internal/skin_clusters.h"

namespace motionlod::core::internal {
namespace {

// Delta_g in four frames, lane by lane (the maximum search bounds a batch of frames at
// once): entry 3a + i of m is Delta_g(i, a) (a = 3: the translation), then the column
// norms of its 3x3 part.
struct LaneDelta {
  static constexpr int kLanes = 4;
  double m[12][kLanes];
  double column_norms[3][kLanes];

  // Sets Delta_g of the four frames whose columns start at solution[f] and original[f]
  // (DeltaView: column c of Delta_g^T is row c of Delta_g, four contiguous doubles from
  // solution_offset and original_offset) and its column norms. Each row of the four frames
  // is transposed into lanes as whole vectors: element by element, this copy was a third
  // of the search.
  void Fill(const double* const solution[kLanes], const double* const original[kLanes],
            Eigen::Index solution_stride, Eigen::Index original_stride,
            Eigen::Index solution_offset, Eigen::Index original_offset) {
    for (int c = 0; c < 3; ++c) {
      Lanes4 row[kLanes], by_column[4];
      for (int f = 0; f < kLanes; ++f) {
        row[f] = *AsLanes4(solution[f] + c * solution_stride + solution_offset) -
                 *AsLanes4(original[f] + c * original_stride + original_offset);
      }
      Transpose4(row, by_column);
      for (int a = 0; a < 4; ++a) *AsLanes4(m[3 * a + c]) = by_column[a];
    }
    for (int a = 0; a < 3; ++a) {
      const Lanes4 x = *AsLanes4(m[3 * a]), y = *AsLanes4(m[3 * a + 1]);
      const Lanes4 z = *AsLanes4(m[3 * a + 2]);
      const Lanes4 squared = x * x + y * y + z * z;
      for (int f = 0; f < kLanes; ++f) column_norms[a][f] = std::sqrt(squared[f]);
    }
  }

  // The bounds of the maximum search (see MaxVertexError) for a box with center c and half
  // extents h: U_g = |Delta_g [c;1]| + sum_a |Delta_g(3x3) e_a| h_a in each lane.
  // (Vectors go out through references: returned by value, they would change the
  // baseline version's calling convention, which GCC warns of.)
  void BoxBounds(const Vec3d& center, const Vec3d& half, Lanes4& u) const {
    Lanes4 moved[3];
    for (int i = 0; i < 3; ++i) {
      moved[i] = *AsLanes4(m[i]) * center[0] + *AsLanes4(m[3 + i]) * center[1] +
                 *AsLanes4(m[6 + i]) * center[2] + *AsLanes4(m[9 + i]);
    }
    const Lanes4 squared = moved[0] * moved[0] + moved[1] * moved[1] + moved[2] * moved[2];
    Lanes4 length;
    for (int f = 0; f < kLanes; ++f) length[f] = std::sqrt(squared[f]);
    u = length + *AsLanes4(column_norms[0]) * half[0] + *AsLanes4(column_norms[1]) * half[1] +
        *AsLanes4(column_norms[2]) * half[2];
  }
};

// The largest sum_g w_g U_g, U_g = bound_of(g) >= 0, over weights w_g in their ranges
// [a_g, b_g] that sum to at most 1: a linear programme whose value, for every lambda >= 0,
// is at most
//   f(lambda) = sum_g a_g U_g + lambda (1 - sum_g a_g) + sum_g (b_g - a_g) max(0, U_g - lambda)
// (weak duality) and equals the smallest f at a breakpoint lambda in {0, U_g}. lambda = 0
// gives sum_g b_g U_g and lambda = max_g U_g, with every a_g 0, gives max_g U_g: this is
// never looser than the better of those two, and much tighter on blended clusters, where
// the largest weights of a cluster in a blend region sum to well over 1.
// The breakpoints past lambda = 0 and max_g U_g cost a pass over the joints each: with
// kRefine they are tried where one of those two is above `threshold` (nothing to gain
// below it); without, the two alone (the per-frame group bounds, computed for every group).
// For four frames at once, one per lane (the maximum search's batches): bound_of(g, u)
// sets U_g of each, and `out` gets each frame's bound. Written with vector types: GCC left
// the plain loops over the four lanes scalar, and a bound stored one lane at a time and
// read back as a vector waited for the stores to retire.
template <bool kRefine, typename BoundOf>
void WeightedBound(const InfluenceRange* begin, const InfluenceRange* end,
                   double threshold, BoundOf&& bound_of, Lanes4& out) {
  // Weights sum to 1 within the validation's tolerance.
  constexpr double kWeightSum = 1.0 + 1e-3;
  constexpr int kMaxJoints = 8;
  const auto count = static_cast<int>(std::min<std::ptrdiff_t>(end - begin, kMaxJoints));
  Lanes4 u[kMaxJoints];  // the first `count` entries
  double span[kMaxJoints];
  Lanes4 floor = {}, largest = {}, widest = {};
  double budget = kWeightSum;
  for (const InfluenceRange* q = begin; q != end; ++q) {
    Lanes4 bound;
    bound_of(q->joint, bound);
    floor += static_cast<double>(q->min_weight) * bound;
    largest = largest < bound ? bound : largest;
    widest += static_cast<double>(q->max_weight) * bound;
    budget -= q->min_weight;
    if (const auto index = q - begin; kRefine && index < kMaxJoints) {
      u[index] = bound;
      span[index] = q->max_weight - q->min_weight;
    }
  }
  budget = std::max(budget, 0.0);
  // lambda = 0 and lambda = max_g U_g hold for any number of joints; the other breakpoints
  // are tried for lists of up to kMaxJoints (a cluster's few joints).
  const Lanes4 at_largest = floor + largest * budget;
  out = at_largest < widest ? at_largest : widest;
  if (!kRefine || end - begin > kMaxJoints) return;
  const auto above = out > threshold;
  if (!(above[0] || above[1] || above[2] || above[3])) return;
  // f at the breakpoints lambda = U_b (lambda = 0 is `widest`), each over the lanes at once.
  for (int b = 0; b < count; ++b) {
    Lanes4 value = floor + u[b] * budget;
    for (int g = 0; g < count; ++g) {
      const Lanes4 past = u[g] - u[b];
      value += span[g] * (0.0 < past ? past : Lanes4{});
    }
    out = value < out ? value : out;
  }
}

constexpr int kVertexLanes = kClusterLanes;

// |d_i|^2, d_i = sum_g w_ig Delta_g [v0_i; 1], of kVertexLanes vertices of a cluster in one
// frame, from its lane block (Character::cluster_lanes: rows of `padded` floats, read from
// the chunk's column on) and Delta_g of its influences' joints g (entry 3a + i, Delta_g(i,
// a), at delta[(12 g + 3a + i) * kDeltaLanes]: the maximum search's float lanes).
// Each blended entry of the 8 vertices is one vector (a 256-bit register in the AVX2
// version): a vertex at a time, the blends ran 128 bits wide through each vertex's own
// influence list, with a horizontal sum at the end. Written with vector types: from plain
// loops over the lanes GCC read the second and third coordinate rows one float at a time
// (it could not prove `padded + v` contiguous) and kept the blend in memory.
template <int kDeltaLanes>
inline float ChunkSquaredErrors(const float* rows, uint32_t padded,
                                const InfluenceRange* influences,
                                uint32_t influence_count, const float* delta, float* squared) {
  static_assert(kVertexLanes == 8, "a chunk is one Lanes8f per row");
  const size_t row = padded;
  Lanes8f blended[12];  // entry 3a + i: the blended Delta(i, a)
  {
    const Lanes8f weight = *AsLanes8f(rows + 3 * row);
    const float* entries = delta + static_cast<size_t>(influences[0].joint) * 12 * kDeltaLanes;
#pragma GCC unroll 12
    for (int e = 0; e < 12; ++e) blended[e] = weight * entries[e * kDeltaLanes];
  }
  for (uint32_t g = 1; g < influence_count; ++g) {
    const Lanes8f weight = *AsLanes8f(rows + (3 + g) * row);
    const float* entries = delta + static_cast<size_t>(influences[g].joint) * 12 * kDeltaLanes;
#pragma GCC unroll 12
    for (int e = 0; e < 12; ++e) blended[e] += weight * entries[e * kDeltaLanes];
  }
  const Lanes8f x = *AsLanes8f(rows), y = *AsLanes8f(rows + row), z = *AsLanes8f(rows + 2 * row);
  Lanes8f length_squared = {};
#pragma GCC unroll 3
  for (int i = 0; i < 3; ++i) {
    const Lanes8f moved = blended[i] * x + blended[3 + i] * y + blended[6 + i] * z + blended[9 + i];
    length_squared += moved * moved;
  }
  float largest[kVertexLanes];
  for (int v = 0; v < kVertexLanes; ++v) {
    squared[v] = length_squared[v];
    largest[v] = length_squared[v];
  }
  for (int width = kVertexLanes / 2; width > 0; width /= 2) {
    for (int v = 0; v < width; ++v) largest[v] = std::max(largest[v], largest[v + width]);
  }
  return largest[0];
}

}  // namespace

MaxSearchBounds MakeMaxSearchBounds(const PreparedData& d, const std::vector<uint8_t>* group_mask,
                                    const std::vector<uint8_t>& moving) {
  const int n = d.n, frames = d.frames;
  const SkinClusters& c = d.character->clusters();
  const auto& group_clusters = c.group_cluster_offsets;
  const auto& group_influence_offsets = c.group_influence_offsets;
  const auto& group_influences = c.group_influences;
  MaxSearchBounds bounds;
  bounds.groups.reserve(n);
  bounds.joints.reserve(n);
  std::vector<uint8_t> weights_a_group(n, 0);
  for (int j = 0; j < n; ++j) {
    if (group_clusters[j] == group_clusters[j + 1] || (group_mask != nullptr && !(*group_mask)[j])) continue;
    bool moved = false;
    for (uint32_t q = group_influence_offsets[j]; q < group_influence_offsets[j + 1]; ++q) {
      moved = moved || moving[group_influences[q].joint];
    }
    if (!moved) continue;
    bounds.groups.push_back(j);
    for (uint32_t q = group_influence_offsets[j]; q < group_influence_offsets[j + 1]; ++q) {
      weights_a_group[group_influences[q].joint] = 1;
    }
  }
  for (int k = 0; k < n; ++k) {
    if (weights_a_group[k] && moving[k]) bounds.joints.push_back(k);
  }
  bounds.group_bound.assign(static_cast<size_t>(frames) * n, 0.0);
  bounds.frame_bound.assign(frames, 0.0);
  bounds.joint_bound.assign(static_cast<size_t>(n) * kGroupBoundFrames, 0.0);
  return bounds;
}

void FrameBounds(const PreparedData& d, const DeltaView& delta, int t, MaxSearchBounds& bounds) {
  const int frames = d.frames;
  if (t % kGroupBoundFrames != kGroupBoundFrames - 1 && t != frames - 1) return;
  RunWithSimd(d.simd, [&] {
    // Coarse bounds for every group from the joints' own boxes (one box bound per joint); a
    // visited group is refined with its own box.
    const SkinClusters& c = d.character->clusters();
    const auto& group_influence_offsets = c.group_influence_offsets;
    const auto& group_influences = c.group_influences;
    static_assert(kGroupBoundFrames == 4, "a batch's bounds are one Lanes4");
    const int batch_first = t - t % kGroupBoundFrames, batch_frames = t - batch_first + 1;
    // Delta_k's rows read as DeltaView::Frame forms them, without a copy of the frames; a
    // batch past the last frame repeats its last frame in the lanes it lacks, unused.
    const Eigen::Index s_stride = delta.solution->rows(), o_stride = delta.original->rows();
    const double* s_frame[kGroupBoundFrames];
    const double* o_frame[kGroupBoundFrames];
    for (int f = 0; f < kGroupBoundFrames; ++f) {
      const int frame = batch_first + std::min(f, batch_frames - 1);
      s_frame[f] = delta.solution->data() + 3 * frame * s_stride;
      o_frame[f] = delta.original->data() + 3 * frame * o_stride;
    }
    const int* s_row = delta.solution_row.data();
    // U_k for each joint's own box in the batch's frames (LaneDelta::BoxBounds), one frame
    // per lane, stored as one vector. (Frame by frame with four joints in the lanes, each
    // frame's U_k and the column norms the search read were stored one double at a time.)
    static_assert(LaneDelta::kLanes == kGroupBoundFrames);
    LaneDelta lanes;
    for (int k : bounds.joints) {
      lanes.Fill(s_frame, o_frame, s_stride, o_stride, s_row[k], 4 * k);
      Lanes4 u;
      lanes.BoxBounds(c.joint_vertex_centers[k], c.joint_vertex_half_extents[k], u);
      *AsLanes4(bounds.joint_bound.data() + static_cast<size_t>(k) * kGroupBoundFrames) = u;
    }
    // The groups' bounds of the batch, one frame per lane: a frame at a time, the weighted
    // bound of each group was scalar, most of FrameBounds' time.
    Lanes4 batch_bound = {};  // each frame's largest group bound
    for (int j : bounds.groups) {
      Lanes4 group;
      WeightedBound<false>(
          group_influences.data() + group_influence_offsets[j],
          group_influences.data() + group_influence_offsets[j + 1],
          std::numeric_limits<double>::infinity(),
          [&](int g, Lanes4& u) {
            u = *AsLanes4(bounds.joint_bound.data() + static_cast<size_t>(g) * kGroupBoundFrames);
          },
          group);
      // A whole batch as one vector: a copy of batch_frames doubles was a call to memcpy.
      double* group_bound = bounds.group_bound.data() + static_cast<size_t>(j) * frames + batch_first;
      if (batch_frames == kGroupBoundFrames) {
        *AsLanes4(group_bound) = group;
      } else {
        for (int f = 0; f < batch_frames; ++f) group_bound[f] = group[f];
      }
      batch_bound = batch_bound < group ? group : batch_bound;
    }
    for (int f = 0; f < batch_frames; ++f) bounds.frame_bound[batch_first + f] = batch_bound[f];
  });
}

MaxSearchStart MaxVertexError(const PreparedData& d, const DeltaView& delta,
                              const MaxSearchBounds& bounds, double decide_within,
                              const MaxSearchStart& start, const std::vector<uint8_t>* cluster_mask,
                              LevelErrors& out) {
  const int n = d.n, frames = d.frames;
  const double height = d.character->height();
  return RunWithSimd(d.simd, [&]() -> MaxSearchStart {
    // Exact maximum of |d_i(t)|, d_i(t) = sum_g w_ig Delta_g(t) [v0_i; 1], over all vertices
    // and frames without evaluating most of them. For a box with center c and half extents
    // h in the bind pose, every vertex v in it has
    //   |Delta_g [v;1]| <= U_g(t) = |Delta_g [c;1]| + sum_a |Delta_g(3x3) e_a| h_a,
    // so a set of vertices whose joints g give them weights in [a_g, b_g] has, by the
    // triangle inequality, |d_i| <= max sum_g w_g U_g over weights in those ranges that
    // sum to 1 (WeightedBound: at most min(max_g U_g, sum_g b_g U_g), often much less).
    // Bounds nest: per frame and vertex group (dominant joint) from the joints' boxes
    // (FrameBounds), then from the group's box, then per cluster; frames and groups are
    // visited by decreasing bound and only clusters whose bound beats the best exact value
    // so far are evaluated.
    // Bounds below kNegligible of the height are not refined: a level that close to exact
    // reports its maximum to within 1e-4 % of the height (0.01 px on a 10000 px tall
    // character). That is the resolution of the streamed float matrices themselves (their
    // rounding moves a vertex by about 1e-7 of its distance from the origin), and it keeps
    // the rigid full level of a rig whose matrices are rotations only to float precision
    // (most glTF and FBX files) from visiting every vertex of every frame.
    constexpr double kNegligible = 1e-6;
    const SkinClusters& c = d.character->clusters();
    const auto& group_clusters = c.group_cluster_offsets;
    const auto& group_influence_offsets = c.group_influence_offsets;
    const auto& group_influences = c.group_influences;
    const auto& cluster_vertex_offsets = c.cluster_vertex_offsets;
    const auto& cluster_vertices = c.cluster_vertices;
    const auto& cluster_influence_offsets = c.cluster_influence_offsets;
    const auto& cluster_influences = c.cluster_influences;

    std::vector<int> frame_order(frames);
    std::iota(frame_order.begin(), frame_order.end(), 0);
    std::sort(frame_order.begin(), frame_order.end(),
              [&](int a, int b) { return bounds.frame_bound[a] > bounds.frame_bound[b]; });

    float best_squared = start.best_squared;  // the float |d_i|^2 whose root is `best`
    double best = std::sqrt(static_cast<double>(best_squared));
    int best_frame = start.frame, best_vertex = start.vertex;
    // Nothing at or below `floor` is refined: negligible, or within the decision's bound.
    const double floor =
        std::max(kNegligible * height, std::isfinite(decide_within) ? decide_within : 0.0);
    // Frames are searched in batches of kLanes, taken in that order: every bound is computed
    // for the whole batch at once, one frame per lane of a vector (the frames of a batch
    // have similar bounds, and most of them need the same groups and clusters bounded).
    constexpr int kLanes = LaneDelta::kLanes;
    static_assert(kLanes == 4, "a batch's Delta_k is transposed as Lanes4");
    std::vector<LaneDelta> lane_delta(n);
    // The exact evaluations blend in float (the skin's own precision): twice the throughput,
    // and the figure is a display quantity. Entry (12 k + 3a + i) kLanes + f: Delta_k(i, a)
    // of lane f's frame.
    std::vector<float> lane_delta_f(static_cast<size_t>(n) * 12 * kLanes);
    const double* solution = delta.solution->data();
    const double* original = delta.original->data();
    const Eigen::Index s_stride = delta.solution->rows(), o_stride = delta.original->rows();
    const int* s_row = delta.solution_row.data();
    std::vector<std::pair<double, int>> group_order;  // (largest lane bound, group)
    group_order.reserve(n);
    // The batch whose lanes joint k holds, -1 for the joints outside bounds.joints.
    std::vector<int> filled_in_batch(n, -1);
    for (int k : bounds.joints) filled_in_batch[k] = 0;
    int batch = 0;
    // The bounds of a group's or a cluster's vertices (entry `index` of a CSR list of
    // influences) from their box, per lane.
    const auto weighted_box_bounds = [&](const std::vector<InfluenceRange>& influences,
                                         const std::vector<uint32_t>& offsets, size_t index,
                                         const Vec3d& center, const Vec3d& half, double* bound) {
      Lanes4 lanes;
      WeightedBound<true>(
          influences.data() + offsets[index], influences.data() + offsets[index + 1],
          std::max(best, floor), [&](int g, Lanes4& u) { lane_delta[g].BoxBounds(center, half, u); },
          lanes);
      *AsLanes4(bound) = lanes;
    };
    // A lambda, so that a decided search returns from every loop at once.
    const auto search = [&] {
      for (size_t first = 0; first < frame_order.size(); first += kLanes) {
        if (bounds.frame_bound[frame_order[first]] <= std::max(best, floor)) break;
        // A batch past the last frame repeats its first frame in the lanes it lacks, unused.
        int lane_frame[kLanes];
        bool lane_used[kLanes];
        for (int f = 0; f < kLanes; ++f) {
          lane_used[f] = first + f < frame_order.size();
          lane_frame[f] = frame_order[lane_used[f] ? first + f : first];
        }
        // Delta_k of the batch's frames in lanes (LaneDelta::Fill), for the joints that
        // weight the groups the batch refines (and so their clusters), each the first time
        // one needs it: all of them up front transposed joints that most batches never read.
        // A joint outside bounds.joints keeps the zero lanes it started with (its Delta is
        // zero).
        const double* s_frame[kLanes];
        const double* o_frame[kLanes];
        for (int f = 0; f < kLanes; ++f) {
          s_frame[f] = solution + 3 * lane_frame[f] * s_stride;
          o_frame[f] = original + 3 * lane_frame[f] * o_stride;
        }
        ++batch;
        const auto fill_lanes = [&](int j) {
          for (uint32_t q = group_influence_offsets[j]; q < group_influence_offsets[j + 1]; ++q) {
            const int k = group_influences[q].joint;
            if (filled_in_batch[k] == batch || filled_in_batch[k] < 0) continue;
            filled_in_batch[k] = batch;
            LaneDelta& lanes = lane_delta[k];
            lanes.Fill(s_frame, o_frame, s_stride, o_stride, s_row[k], 4 * k);
            float* lanes_f = lane_delta_f.data() + static_cast<size_t>(k) * 12 * kLanes;
            for (int e = 0; e < 12; ++e) {
              *AsLanes4f(lanes_f + e * kLanes) =
                  __builtin_convertvector(*AsLanes4(lanes.m[e]), Lanes4f);
            }
          }
        };
        const auto group_bound = [&](int f, int j) {
          return lane_used[f] ? bounds.group_bound[static_cast<size_t>(j) * frames + lane_frame[f]]
                              : 0.0;
        };
        // Only the groups that can beat the best so far in some lane, by decreasing bound.
        group_order.clear();
        for (int j : bounds.groups) {
          double largest = 0;
          for (int f = 0; f < kLanes; ++f) largest = std::max(largest, group_bound(f, j));
          if (largest > std::max(best, floor)) group_order.emplace_back(largest, j);
        }
        std::sort(group_order.begin(), group_order.end(),
                  [](const auto& a, const auto& b) { return a.first > b.first; });
        for (const auto& [largest, j] : group_order) {
          if (largest <= std::max(best, floor)) break;
          fill_lanes(j);
          bool open[kLanes];  // the lanes whose bound beats the best so far
          double refined[kLanes];
          weighted_box_bounds(group_influences, group_influence_offsets, j, c.group_centers[j],
                              c.group_half_extents[j], refined);
          bool any_open = false;
          for (int f = 0; f < kLanes; ++f) {
            open[f] =
                group_bound(f, j) > std::max(best, floor) && refined[f] > std::max(best, floor);
            any_open = any_open || open[f];
          }
          if (!any_open) continue;
          for (uint32_t cluster = group_clusters[j]; cluster < group_clusters[j + 1]; ++cluster) {
            if (cluster_mask != nullptr && !(*cluster_mask)[cluster]) continue;
            double cluster_bound[kLanes];
            weighted_box_bounds(cluster_influences, cluster_influence_offsets, cluster,
                                c.cluster_centers[cluster], c.cluster_half_extents[cluster],
                                cluster_bound);
            const uint32_t first_vertex = cluster_vertex_offsets[cluster];
            const uint32_t padded =
                ClusterLaneRow(cluster_vertex_offsets[cluster + 1] - first_vertex);
            const float* block = c.cluster_lanes.data() + c.cluster_lane_offsets[cluster];
            for (int f = 0; f < kLanes; ++f) {
              if (!open[f] || cluster_bound[f] <= std::max(best, floor)) continue;
              for (uint32_t chunk = 0; chunk < padded; chunk += kVertexLanes) {
                float squared[kVertexLanes];
                const float largest = ChunkSquaredErrors<kLanes>(
                    block + chunk, padded,
                    cluster_influences.data() + cluster_influence_offsets[cluster],
                    cluster_influence_offsets[cluster + 1] - cluster_influence_offsets[cluster],
                    lane_delta_f.data() + f, squared);
                if (!(largest > best_squared)) continue;
                // Compared squared (sqrt is monotonic): the square root, its conversion and a
                // compare with `best` in memory were a fifth of the search's time per vertex.
                for (int v = 0; v < kVertexLanes; ++v) {
                  if (squared[v] > best_squared) {
                    best_squared = squared[v];
                    best = std::sqrt(static_cast<double>(squared[v]));
                    best_frame = lane_frame[f];
                    best_vertex = static_cast<int>(cluster_vertices[first_vertex + chunk + v]);
                    if (best > decide_within) return;
                  }
                }
              }
            }
          }
        }
      }
    };
    search();
    out.max_vertex_error_pct = 100.0 * best / height;
    out.max_vertex_frame = best_frame;
    out.max_vertex_index = best_vertex;
    return MaxSearchStart{best_squared, best_frame, best_vertex};
  });
}

}  // namespace motionlod::core::internal
