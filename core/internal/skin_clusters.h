// The skin indexed for bounding how far per-joint matrix errors can move it without
// visiting it (the maximum vertex error search, core/internal/max_vertex_error.h). Built
// once per character by BuildCharacter.
//
// Every vertex is in exactly one cluster. Vertices are grouped by their dominant joint
// (largest weight, the first listed on ties); each group is split into spatially compact
// clusters of at most kMaxClusterVertices by median splits along the longest axis. Group
// j's clusters are [group_cluster_offsets[j], group_cluster_offsets[j+1]); cluster c's
// vertices are cluster_vertices[cluster_vertex_offsets[c] .. cluster_vertex_offsets[c+1]).
// Boxes are axis-aligned in the bind pose, as center and half extents.
#pragma once

#include <cstdint>
#include <vector>

#include "base/pieces.h"
#include "core/character.h"
#include "core/types.h"

namespace motionlod::core::internal {

inline constexpr int kMaxClusterVertices = 32;

// A joint that weights the vertices of a group or cluster, with the range of the weights
// it gives them: the smallest (0 where some vertex has no weight from it) and the largest.
// A vertex moves by at most sum_g w_g |Delta_g [v;1]|, so these ranges (with the weights'
// sum of 1) bound a whole cluster's error from per-joint bounds.
struct InfluenceRange {
  int32_t joint = 0;
  float min_weight = 0;
  float max_weight = 0;
};

// Each cluster's skin is laid out again to blend kClusterLanes vertices at once: cluster
// c's block starts at cluster_lane_offsets[c] in cluster_lanes and has rows of P floats, P
// its vertex count rounded up to a multiple of kClusterLanes: the bind positions' x, y and
// z, then the weight its cluster_influences' joints give each vertex, in that order (0
// where one gives none). Vertices in cluster_vertices order; the padding sits at the
// origin with no weight.
inline constexpr int kClusterLanes = 8;
// P for a cluster of `count` vertices.
constexpr uint32_t ClusterLaneRow(uint32_t count) {
  return (count + kClusterLanes - 1) / kClusterLanes * kClusterLanes;
}

struct SkinClusters {
  // Box of the vertices weighted to joint j; the joint's bind position and zero extents
  // when none are.
  std::vector<Vec3d> joint_vertex_centers, joint_vertex_half_extents;
  std::vector<uint32_t> group_cluster_offsets;                // n + 1
  std::vector<Vec3d> group_centers, group_half_extents;       // n (zero for an empty group)
  std::vector<uint32_t> cluster_vertex_offsets;               // clusters + 1
  std::vector<uint32_t> cluster_vertices;                     // p
  std::vector<Vec3d> cluster_centers, cluster_half_extents;   // clusters
  // The joints that weight any vertex of a group or cluster (CSR).
  std::vector<uint32_t> group_influence_offsets;
  std::vector<InfluenceRange> group_influences;
  std::vector<uint32_t> cluster_influence_offsets;
  std::vector<InfluenceRange> cluster_influences;
  std::vector<uint32_t> cluster_lane_offsets;  // clusters + 1
  std::vector<float> cluster_lanes;
};

// The clusters of a validated skeleton and skin; `run`: where its pieces run (the result
// is the same).
SkinClusters BuildSkinClusters(const RawSkeleton& skeleton, const RawSkin& skin,
                               const PieceRunner& run = {});

}  // namespace motionlod::core::internal
