#include "core/internal/skin_clusters.h"

#include <algorithm>
#include <bit>
#include <limits>
#include <utility>

#include "core/internal/lanes.h"

namespace motionlod::core::internal {
namespace {

// A vertex's bind position and index, copied contiguously for the cluster splits.
struct ClusterPoint {
  float position[3];
  uint32_t vertex;
};

// Moves [begin, end) so that the points whose `axis` coordinate is below `pivot` (at most
// `pivot`, with or_equal) come first; returns where the rest begin. Branch-free (Lomuto's scheme
// with an unconditional swap): mesh coordinates make a compare's outcome a coin flip, and
// std::nth_element's branching partition spent most of its time on mispredictions.
ClusterPoint* PartitionBelow(ClusterPoint* begin, ClusterPoint* end, int axis, float pivot,
                             bool or_equal) {
  ClusterPoint* store = begin;
  for (ClusterPoint* q = begin; q != end; ++q) {
    const ClusterPoint point = *q;
    const float key = point.position[axis];
    *q = *store;
    *store = point;
    store += or_equal ? key <= pivot : key < pivot;
  }
  return store;
}

// std::nth_element(begin, nth, end) by `axis` coordinate, with the branch-free partition:
// quickselect around the median of three, equal keys set apart so that every round
// shrinks the range. Past a logarithmic number of rounds (an input built against the
// pivot choice) it hands the rest to std::nth_element, whose worst case is bounded.
void SelectByAxis(ClusterPoint* begin, ClusterPoint* nth, ClusterPoint* end, int axis) {
  int rounds_left = 2 * std::bit_width(static_cast<size_t>(end - begin)) + 8;
  while (end - begin > 16) {
    if (--rounds_left < 0) break;
    const float a = begin->position[axis], b = nth->position[axis], c = (end - 1)->position[axis];
    const float pivot = std::max(std::min(a, b), std::min(std::max(a, b), c));
    ClusterPoint* const below = PartitionBelow(begin, end, axis, pivot, false);
    if (nth < below) {
      end = below;
      continue;
    }
    ClusterPoint* const equal_end = PartitionBelow(below, end, axis, pivot, true);
    if (nth < equal_end) return;
    begin = equal_end;
  }
  std::nth_element(begin, nth, end, [axis](const ClusterPoint& x, const ClusterPoint& y) {
    return x.position[axis] < y.position[axis];
  });
}

// BuildCharacter clusters the groups in runs of at least this many vertices, one piece each.
constexpr uint32_t kClusterPieceVertices = 2048;

// The clusters of a run of groups (ClusterGroup), as the character lists them: the
// offsets' ends counted from the run's start, except the vertices' (positions in
// cluster_vertices).
struct GroupClusters {
  std::vector<uint32_t> group_cluster_ends;
  std::vector<uint32_t> group_influence_ends;
  std::vector<InfluenceRange> group_influences;
  std::vector<uint32_t> cluster_vertex_ends;
  std::vector<Vec3d> cluster_centers, cluster_half_extents;
  std::vector<uint32_t> cluster_influence_ends;
  std::vector<InfluenceRange> cluster_influences;
};

// ClusterGroup's scratch, for a skeleton of n joints.
struct ClusterScratch {
  explicit ClusterScratch(int n) : min_weight(n, 0.0f), max_weight(n, 0.0f), weighted_count(n, 0) {}
  std::vector<float> min_weight, max_weight;
  std::vector<uint32_t> weighted_count;
  std::vector<int32_t> touched;
  // The splitting works on a contiguous copy of each group's positions: comparing through
  // the vertex indices cost a cache miss per comparison on a large mesh.
  std::vector<ClusterPoint> points;
  std::vector<std::pair<uint32_t, uint32_t>> stack;
};

// Appends the joints that weight the vertices [begin, end) to `list`, each with the range
// of the weights it gives them (min_weight stays 0 unless every vertex has a weight from
// the joint), and the list's new size to `ends`.
void AppendInfluences(const RawSkin& k, const uint32_t* begin, const uint32_t* end,
                      ClusterScratch& scratch, std::vector<InfluenceRange>& list,
                      std::vector<uint32_t>& ends) {
  for (const uint32_t* v = begin; v != end; ++v) {
    for (uint32_t e = k.influence_offsets[*v]; e < k.influence_offsets[*v + 1]; ++e) {
      const int32_t j = k.influence_joints[e];
      const float w = k.influence_weights[e];
      if (scratch.weighted_count[j]++ == 0) {
        scratch.touched.push_back(j);
        scratch.min_weight[j] = scratch.max_weight[j] = w;
      }
      scratch.min_weight[j] = std::min(scratch.min_weight[j], w);
      scratch.max_weight[j] = std::max(scratch.max_weight[j], w);
    }
  }
  const auto size = static_cast<uint32_t>(end - begin);
  for (int32_t j : scratch.touched) {
    list.push_back({j, scratch.weighted_count[j] == size ? scratch.min_weight[j] : 0.0f,
                    scratch.max_weight[j]});
    scratch.weighted_count[j] = 0;
  }
  scratch.touched.clear();
  ends.push_back(static_cast<uint32_t>(list.size()));
}

// The bounds as whole 16-byte points (the vertex index rides along in the last lane,
// unused), in four independent chains: one min and max per point instead of three
// dependent ones.
void PointBox(const ClusterPoint* begin, const ClusterPoint* end, Vec3d& center, Vec3d& half) {
  const auto point = [](const ClusterPoint* q) { return *AsLanes4f(q->position); };
  Lanes4f lo[4], hi[4];
  for (int chain = 0; chain < 4; ++chain) lo[chain] = hi[chain] = point(begin);
  const ClusterPoint* q = begin + 1;
  for (; end - q >= 4; q += 4) {
    for (int chain = 0; chain < 4; ++chain) {
      const Lanes4f x = point(q + chain);
      lo[chain] = x < lo[chain] ? x : lo[chain];
      hi[chain] = hi[chain] < x ? x : hi[chain];
    }
  }
  for (; q != end; ++q) {
    const Lanes4f x = point(q);
    lo[0] = x < lo[0] ? x : lo[0];
    hi[0] = hi[0] < x ? x : hi[0];
  }
  for (int chain = 1; chain < 4; ++chain) {
    lo[0] = lo[chain] < lo[0] ? lo[chain] : lo[0];
    hi[0] = hi[0] < hi[chain] ? hi[chain] : hi[0];
  }
  for (int a = 0; a < 3; ++a) {
    center[a] = 0.5 * (static_cast<double>(lo[0][a]) + static_cast<double>(hi[0][a]));
    half[a] = 0.5 * (static_cast<double>(hi[0][a]) - static_cast<double>(lo[0][a]));
  }
}

// Splits the group of vertices base[begin, end) of cluster_vertices into clusters of at most
// kMaxClusterVertices by median splits along the longest axis, depth first (each
// cluster's vertices stay contiguous: the range is reordered in place), appending them and
// the group to `out`; the group's box goes to center and half (left as they are for an
// empty group).
void ClusterGroup(const RawSkin& k, uint32_t* base, uint32_t begin, uint32_t end,
                  ClusterScratch& scratch, Vec3d& center, Vec3d& half, GroupClusters& out) {
  AppendInfluences(k, base + begin, base + end, scratch, out.group_influences,
                   out.group_influence_ends);
  std::vector<ClusterPoint>& points = scratch.points;
  std::vector<std::pair<uint32_t, uint32_t>>& stack = scratch.stack;
  if (begin != end) {
    points.resize(end - begin);
    for (uint32_t e = begin; e < end; ++e) {
      const Vec3f& position = k.positions[base[e]];
      points[e - begin] = {{position.x(), position.y(), position.z()}, base[e]};
    }
    PointBox(points.data(), points.data() + points.size(), center, half);
    stack.push_back({0, end - begin});
  }
  while (!stack.empty()) {
    const auto [lo, hi] = stack.back();
    stack.pop_back();
    Vec3d cluster_center, cluster_half;
    PointBox(points.data() + lo, points.data() + hi, cluster_center, cluster_half);
    if (hi - lo <= static_cast<uint32_t>(kMaxClusterVertices)) {
      for (uint32_t e = lo; e < hi; ++e) base[begin + e] = points[e].vertex;
      out.cluster_vertex_ends.push_back(begin + hi);
      out.cluster_centers.push_back(cluster_center);
      out.cluster_half_extents.push_back(cluster_half);
      AppendInfluences(k, base + begin + lo, base + begin + hi, scratch, out.cluster_influences,
                       out.cluster_influence_ends);
      continue;
    }
    int axis = 0;
    cluster_half.maxCoeff(&axis);
    const uint32_t mid = lo + (hi - lo) / 2;
    SelectByAxis(points.data() + lo, points.data() + mid, points.data() + hi, axis);
    stack.push_back({mid, hi});
    stack.push_back({lo, mid});
  }
  out.group_cluster_ends.push_back(static_cast<uint32_t>(out.cluster_centers.size()));
}
}  // namespace

SkinClusters BuildSkinClusters(const RawSkeleton& s, const RawSkin& k, const PieceRunner& run) {
  SkinClusters out;
  const int n = static_cast<int>(s.parents.size());
  const int p = static_cast<int>(k.positions.size());
  // Bounding box of each joint's weighted vertices.
  {
    std::vector<Vec3d> lo(n, Vec3d::Constant(std::numeric_limits<double>::infinity()));
    std::vector<Vec3d> hi(n, Vec3d::Constant(-std::numeric_limits<double>::infinity()));
    for (int i = 0; i < p; ++i) {
      for (uint32_t e = k.influence_offsets[i]; e < k.influence_offsets[i + 1]; ++e) {
        const int j = k.influence_joints[e];
        lo[j] = lo[j].cwiseMin(k.positions[i].cast<double>());
        hi[j] = hi[j].cwiseMax(k.positions[i].cast<double>());
      }
    }
    out.joint_vertex_centers.resize(n);
    out.joint_vertex_half_extents.assign(n, Vec3d::Zero());
    for (int j = 0; j < n; ++j) {
      if (lo[j].x() > hi[j].x()) {
        out.joint_vertex_centers[j] = s.bind_world[j].col(3);
      } else {
        out.joint_vertex_centers[j] = 0.5 * (lo[j] + hi[j]);
        out.joint_vertex_half_extents[j] = 0.5 * (hi[j] - lo[j]);
      }
    }
  }
  // Vertices grouped by dominant joint (a counting sort), then clustered per group.
  std::vector<int> dominant_joint(p, 0);
  for (int i = 0; i < p; ++i) {
    float largest = -1;
    for (uint32_t e = k.influence_offsets[i]; e < k.influence_offsets[i + 1]; ++e) {
      if (k.influence_weights[e] > largest) {
        largest = k.influence_weights[e];
        dominant_joint[i] = k.influence_joints[e];
      }
    }
  }
  std::vector<uint32_t> group_offsets(n + 1, 0);
  for (int i = 0; i < p; ++i) ++group_offsets[dominant_joint[i] + 1];
  for (int j = 0; j < n; ++j) group_offsets[j + 1] += group_offsets[j];
  out.cluster_vertices.resize(p);
  {
    std::vector<uint32_t> cursor(group_offsets.begin(), group_offsets.end() - 1);
    for (int i = 0; i < p; ++i) {
      out.cluster_vertices[cursor[dominant_joint[i]]++] = static_cast<uint32_t>(i);
    }
  }
  // The groups in runs of consecutive joints of at least kClusterPieceVertices vertices,
  // each run a piece with lists of its own, appended to the character's in group order.
  std::vector<int> run_first = {0};
  for (int j = 0; j + 1 < n; ++j) {
    if (group_offsets[j + 1] - group_offsets[run_first.back()] >= kClusterPieceVertices) {
      run_first.push_back(j + 1);
    }
  }
  run_first.push_back(n);
  const int runs = static_cast<int>(run_first.size()) - 1;
  std::vector<GroupClusters> run_clusters(runs);
  out.group_centers.assign(n, Vec3d::Zero());
  out.group_half_extents.assign(n, Vec3d::Zero());
  RunPieces(run, runs, [&](int r) {
    ClusterScratch scratch(n);
    for (int j = run_first[r]; j < run_first[r + 1]; ++j) {
      ClusterGroup(k, out.cluster_vertices.data(), group_offsets[j], group_offsets[j + 1],
                   scratch, out.group_centers[j], out.group_half_extents[j], run_clusters[r]);
    }
  });
  out.group_cluster_offsets.assign(1, 0);
  out.cluster_vertex_offsets.assign(1, 0);
  out.group_influence_offsets.assign(1, 0);
  out.cluster_influence_offsets.assign(1, 0);
  const auto append_ends = [](const std::vector<uint32_t>& ends, std::vector<uint32_t>& offsets) {
    const uint32_t start = offsets.back();
    for (uint32_t end : ends) offsets.push_back(start + end);
  };
  for (const GroupClusters& run_out : run_clusters) {
    append_ends(run_out.group_cluster_ends, out.group_cluster_offsets);
    append_ends(run_out.group_influence_ends, out.group_influence_offsets);
    append_ends(run_out.cluster_influence_ends, out.cluster_influence_offsets);
    out.group_influences.insert(out.group_influences.end(), run_out.group_influences.begin(),
                                run_out.group_influences.end());
    out.cluster_influences.insert(out.cluster_influences.end(),
                                  run_out.cluster_influences.begin(),
                                  run_out.cluster_influences.end());
    out.cluster_vertex_offsets.insert(out.cluster_vertex_offsets.end(),
                                      run_out.cluster_vertex_ends.begin(),
                                      run_out.cluster_vertex_ends.end());
    out.cluster_centers.insert(out.cluster_centers.end(), run_out.cluster_centers.begin(),
                               run_out.cluster_centers.end());
    out.cluster_half_extents.insert(out.cluster_half_extents.end(),
                                    run_out.cluster_half_extents.begin(),
                                    run_out.cluster_half_extents.end());
  }
  // The clusters' lane blocks (cluster_lanes), in pieces of clusters.
  const size_t clusters = out.cluster_centers.size();
  out.cluster_lane_offsets.resize(clusters + 1);
  out.cluster_lane_offsets[0] = 0;
  for (size_t q = 0; q < clusters; ++q) {
    const uint32_t count = out.cluster_vertex_offsets[q + 1] - out.cluster_vertex_offsets[q];
    const uint32_t rows =
        3 + out.cluster_influence_offsets[q + 1] - out.cluster_influence_offsets[q];
    out.cluster_lane_offsets[q + 1] =
        out.cluster_lane_offsets[q] + rows * ClusterLaneRow(count);
  }
  out.cluster_lanes.assign(out.cluster_lane_offsets.back(), 0.0f);
  constexpr size_t kLanePieceClusters = kClusterPieceVertices / kMaxClusterVertices;
  const size_t lane_pieces = (clusters + kLanePieceClusters - 1) / kLanePieceClusters;
  RunPieces(run, static_cast<int>(lane_pieces), [&](int piece) {
    std::vector<int32_t> row_of_joint(n, -1);
    const size_t first_cluster = piece * kLanePieceClusters;
    const size_t end_cluster = std::min(clusters, first_cluster + kLanePieceClusters);
    for (size_t q = first_cluster; q < end_cluster; ++q) {
      const uint32_t first = out.cluster_vertex_offsets[q];
      const uint32_t count = out.cluster_vertex_offsets[q + 1] - first;
      const uint32_t padded = ClusterLaneRow(count);
      const uint32_t influences = out.cluster_influence_offsets[q];
      for (uint32_t g = influences; g < out.cluster_influence_offsets[q + 1]; ++g) {
        row_of_joint[out.cluster_influences[g].joint] = static_cast<int32_t>(3 + g - influences);
      }
      float* block = out.cluster_lanes.data() + out.cluster_lane_offsets[q];
      for (uint32_t v = 0; v < count; ++v) {
        const uint32_t i = out.cluster_vertices[first + v];
        for (int a = 0; a < 3; ++a) block[a * padded + v] = k.positions[i][a];
        for (uint32_t e = k.influence_offsets[i]; e < k.influence_offsets[i + 1]; ++e) {
          block[row_of_joint[k.influence_joints[e]] * padded + v] = k.influence_weights[e];
        }
      }
    }
  });
  return out;
}

}  // namespace motionlod::core::internal
