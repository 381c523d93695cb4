#include "core/character.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <limits>
#include <string>
#include <tuple>
#include <unordered_set>

#include "base/lanes.h"
#include "core/motion.h"

namespace motionlod::core {
namespace {

// Eigen's allFinite() was an out-of-line call per vector here.
bool IsFinite(const Vec3f& v) {
  return std::isfinite(v.x()) && std::isfinite(v.y()) && std::isfinite(v.z());
}

std::string JointLabel(const RawSkeleton& s, int j) {
  return "joint " + std::to_string(j) + " ('" + s.joint_names[j] + "')";
}

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
  std::vector<Character::InfluenceRange> group_influences;
  std::vector<uint32_t> cluster_vertex_ends;
  std::vector<Vec3d> cluster_centers, cluster_half_extents;
  std::vector<uint32_t> cluster_influence_ends;
  std::vector<Character::InfluenceRange> cluster_influences;
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
                      ClusterScratch& scratch, std::vector<Character::InfluenceRange>& list,
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
    if (hi - lo <= static_cast<uint32_t>(Character::kMaxClusterVertices)) {
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

// ValidateRawCharacter checks a large skin in pieces of this many vertices.
constexpr size_t kValidationPieceVertices = 4096;

// ValidateRawCharacter's checks of the vertices [first, end), for a skin whose arrays have
// consistent lengths (ValidateTriangles: of its triangles).
Status ValidateVertices(const RawSkin& k, size_t n, size_t first, size_t end) {
  for (size_t i = first; i < end; ++i) {
    if (!IsFinite(k.positions[i])) {
      return InvalidArgument("vertex " + std::to_string(i) + " has a non-finite position");
    }
    if (!IsFinite(k.normals[i]) || std::abs(k.normals[i].norm() - 1.0f) > 1e-3f) {
      return InvalidArgument("vertex " + std::to_string(i) + " has a normal that is not unit length");
    }
    const uint32_t begin = k.influence_offsets[i], stop = k.influence_offsets[i + 1];
    if (stop < begin) {
      return InvalidArgument("influence_offsets decrease at vertex " + std::to_string(i));
    }
    if (begin == stop) {
      return InvalidArgument("vertex " + std::to_string(i) + " has no influences (zero weights)");
    }
    double sum = 0;
    for (uint32_t e = begin; e < stop; ++e) {
      const int32_t j = k.influence_joints[e];
      const float w = k.influence_weights[e];
      if (j < 0 || static_cast<size_t>(j) >= n) {
        return InvalidArgument("vertex " + std::to_string(i) + " is weighted to joint " +
                               std::to_string(j) + ", which does not exist");
      }
      if (!(w > 0.0f) || !std::isfinite(w)) {
        return InvalidArgument("vertex " + std::to_string(i) + " has a weight that is not positive");
      }
      for (uint32_t f = begin; f < e; ++f) {
        if (k.influence_joints[f] == j) {
          return InvalidArgument("vertex " + std::to_string(i) + " lists joint " +
                                 std::to_string(j) + " twice");
        }
      }
      sum += w;
    }
    if (std::abs(sum - 1.0) > 1e-3) {
      return InvalidArgument("vertex " + std::to_string(i) + " has weights summing to " +
                             std::to_string(sum) + ", not 1");
    }
  }
  return Status::Ok();
}

Status ValidateTriangles(const RawSkin& k) {
  const size_t p = k.positions.size();
  for (size_t f = 0; f < k.triangles.size(); ++f) {
    for (uint32_t v : k.triangles[f]) {
      if (v >= p) {
        return InvalidArgument("triangle " + std::to_string(f) + " refers to vertex " +
                               std::to_string(v) + " of " + std::to_string(p));
      }
    }
  }
  return Status::Ok();
}

// ValidateRawCharacter's checks of the skeleton and of the skin's array lengths, before its
// pieces of vertices.
Status ValidateStructure(const RawCharacter& raw) {
  const RawSkeleton& s = raw.skeleton;
  const RawSkin& k = raw.skin;
  const size_t n = s.parents.size();
  if (n == 0) return InvalidArgument("the skeleton has no joints");
  if (s.joint_names.size() != n || s.bind_world.size() != n) {
    return InvalidArgument("skeleton arrays differ in length: " + std::to_string(n) + " parents, " +
                           std::to_string(s.joint_names.size()) + " names, " +
                           std::to_string(s.bind_world.size()) + " bind matrices");
  }
  if (n > 65535) return InvalidArgument("more than 65535 joints");
  if (s.parents[0] != -1) return InvalidArgument("joint 0 must be the root (parent -1)");
  std::unordered_set<std::string> names;
  for (size_t j = 0; j < n; ++j) {
    const int jj = static_cast<int>(j);
    if (j > 0 && (s.parents[j] < 0 || s.parents[j] >= jj)) {
      return InvalidArgument(JointLabel(s, jj) + " has parent " + std::to_string(s.parents[j]) +
                             "; joints must follow their parent and only joint 0 is a root");
    }
    if (!names.insert(s.joint_names[j]).second) {
      return InvalidArgument("two joints are named '" + s.joint_names[j] + "'");
    }
    const Affine34d& m = s.bind_world[j];
    if (!m.allFinite()) return InvalidArgument(JointLabel(s, jj) + " has a non-finite bind matrix");
    if (!IsInvertibleAffine(m)) {
      return InvalidArgument(JointLabel(s, jj) + " has a singular bind matrix");
    }
  }

  const size_t p = k.positions.size();
  if (p == 0) return InvalidArgument("the skin has no vertices");
  if (p > 0x7fffffff) return InvalidArgument("too many vertices");
  if (k.normals.size() != p) {
    return InvalidArgument("the skin has " + std::to_string(p) + " positions but " +
                           std::to_string(k.normals.size()) + " normals");
  }
  if (k.influence_offsets.size() != p + 1 || k.influence_offsets[0] != 0) {
    return InvalidArgument("influence_offsets must have p + 1 entries starting at 0");
  }
  if (k.influence_joints.size() != k.influence_weights.size() ||
      k.influence_offsets.back() != k.influence_joints.size()) {
    return InvalidArgument("influence arrays disagree with influence_offsets");
  }
  return Status::Ok();
}

// How many pieces ValidatePiece checks a skin of p vertices in.
size_t ValidationPieces(size_t p) {
  return (p + kValidationPieceVertices - 1) / kValidationPieceVertices;
}

// Piece `piece` of ValidationPieces(p) of a skin that passed ValidateStructure: its
// vertices, and in the last piece the triangles.
Status ValidatePiece(const RawCharacter& raw, size_t piece) {
  const RawSkin& k = raw.skin;
  const size_t p = k.positions.size();
  const size_t first = piece * kValidationPieceVertices;
  Status status = ValidateVertices(k, raw.skeleton.parents.size(), first,
                                   std::min(p, first + kValidationPieceVertices));
  if (status.ok() && piece + 1 == ValidationPieces(p)) status = ValidateTriangles(k);
  return status;
}

// The first problem of the pieces' (the first in the skin), or Ok.
Status FirstProblem(std::vector<Status>& found) {
  for (Status& status : found) {
    if (!status.ok()) return std::move(status);
  }
  return Status::Ok();
}

}  // namespace

Status ValidateRawCharacter(const RawCharacter& raw, const PieceRunner& run) {
  if (Status status = ValidateStructure(raw); !status.ok()) return status;
  // The vertices in pieces, the last one also checking the triangles: each piece finds
  // its first problem, and the first piece's that has one is the message (the first in
  // the skin).
  std::vector<Status> found(ValidationPieces(raw.skin.positions.size()));
  RunPieces(run, static_cast<int>(found.size()),
            [&](int piece) { found[piece] = ValidatePiece(raw, piece); });
  return FirstProblem(found);
}

int Character::FindJoint(const std::string& name) const {
  const auto it = std::find(skeleton_.joint_names.begin(), skeleton_.joint_names.end(), name);
  return it == skeleton_.joint_names.end()
             ? -1
             : static_cast<int>(it - skeleton_.joint_names.begin());
}

StatusOr<std::shared_ptr<const Character>> BuildCharacter(const RawCharacter& raw,
                                                          const PieceRunner& run) {
  if (Status status = ValidateStructure(raw); !status.ok()) return status;
  std::shared_ptr<Character> c(new Character());
  c->name_ = raw.name;
  c->skeleton_ = raw.skeleton;
  // The skin's arrays are copied by three pieces of the validation's job, first: a
  // 16k-vertex skin is a megabyte, and its copy ahead of the checks was a tenth of the
  // build on two threads. A skin of one validation piece is copied and checked in one
  // piece (a few kilobytes). (A skin that fails the checks is dropped with the character.)
  constexpr int kCopyParts = 3;
  const auto copy_part = [&](int part) {
    if (part == 0) {
      c->skin_.triangles = raw.skin.triangles;
    } else if (part == 1) {
      c->skin_.positions = raw.skin.positions;
      c->skin_.normals = raw.skin.normals;
    } else {
      c->skin_.influence_offsets = raw.skin.influence_offsets;
      c->skin_.influence_joints = raw.skin.influence_joints;
      c->skin_.influence_weights = raw.skin.influence_weights;
    }
  };
  std::vector<Status> found(ValidationPieces(raw.skin.positions.size()));
  const int copy_pieces = found.size() > 1 ? kCopyParts : 0;
  RunPieces(run, copy_pieces + static_cast<int>(found.size()), [&](int piece) {
    if (piece < copy_pieces) {
      copy_part(piece);
      return;
    }
    if (copy_pieces == 0) {
      for (int part = 0; part < kCopyParts; ++part) copy_part(part);
    }
    found[piece - copy_pieces] = ValidatePiece(raw, piece - copy_pieces);
  });
  if (Status status = FirstProblem(found); !status.ok()) return status;
  const RawSkeleton& s = c->skeleton_;
  const RawSkin& k = c->skin_;
  const int n = c->joint_count();
  const int p = c->vertex_count();

  c->children_.assign(n, {});
  for (int j = 1; j < n; ++j) c->children_[s.parents[j]].push_back(j);

  // Three independent parts, side by side where the caller has threads: the clusters
  // (themselves in pieces); the areas and pair moments; the bounding boxes and the
  // subtree lengths.
  const auto boxes_and_lengths = [&] {
    Eigen::Vector3d lo = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity());
    Eigen::Vector3d hi = -lo;
    for (const Vec3f& v : k.positions) {
      lo = lo.cwiseMin(v.cast<double>());
      hi = hi.cwiseMax(v.cast<double>());
    }
    c->height_ = (hi - lo).maxCoeff();
    if (!(c->height_ > 0)) c->height_ = 1.0;
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
      c->joint_vertex_centers_.resize(n);
      c->joint_vertex_half_extents_.assign(n, Vec3d::Zero());
      for (int j = 0; j < n; ++j) {
        if (lo[j].x() > hi[j].x()) {
          c->joint_vertex_centers_[j] = s.bind_world[j].col(3);
        } else {
          c->joint_vertex_centers_[j] = 0.5 * (lo[j] + hi[j]);
          c->joint_vertex_half_extents_[j] = 0.5 * (hi[j] - lo[j]);
        }
      }
    }
    // h_j = l_j: summed distance from joint j to each leaf of its subtree. A childless
    // joint that dominates some vertices ends at a virtual end site, its farthest such
    // vertex (glTF rigs rarely carry the "...Nub" end joints of fig. 2); a childless
    // joint without skin is itself the leaf.
    std::vector<Vec3d> leaf_point(n);
    std::vector<double> end_site_distance(n, -1.0);
    for (int j = 0; j < n; ++j) leaf_point[j] = s.bind_world[j].col(3);
    for (int i = 0; i < p; ++i) {
      int dominant = -1;
      float dominant_weight = 0.5f;
      for (uint32_t e = k.influence_offsets[i]; e < k.influence_offsets[i + 1]; ++e) {
        if (k.influence_weights[e] > dominant_weight) {
          dominant_weight = k.influence_weights[e];
          dominant = k.influence_joints[e];
        }
      }
      if (dominant < 0 || !c->children_[dominant].empty()) continue;
      const Vec3d v = k.positions[i].cast<double>();
      const double d = (v - s.bind_world[dominant].col(3)).norm();
      if (d > end_site_distance[dominant]) {
        end_site_distance[dominant] = d;
        leaf_point[dominant] = v;
      }
    }
    c->subtree_lengths_.assign(n, 0.0);
    for (int q = 0; q < n; ++q) {
      if (!c->children_[q].empty()) continue;
      for (int j = q; j >= 0; j = s.parents[j]) {
        c->subtree_lengths_[j] += (leaf_point[q] - Vec3d(s.bind_world[j].col(3))).norm();
      }
    }
  };
  const auto clusters = [&] {
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
    c->cluster_vertices_.resize(p);
    {
      std::vector<uint32_t> cursor(group_offsets.begin(), group_offsets.end() - 1);
      for (int i = 0; i < p; ++i) {
        c->cluster_vertices_[cursor[dominant_joint[i]]++] = static_cast<uint32_t>(i);
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
    c->group_centers_.assign(n, Vec3d::Zero());
    c->group_half_extents_.assign(n, Vec3d::Zero());
    RunPieces(run, runs, [&](int r) {
      ClusterScratch scratch(n);
      GroupClusters& out = run_clusters[r];
      for (int j = run_first[r]; j < run_first[r + 1]; ++j) {
        ClusterGroup(k, c->cluster_vertices_.data(), group_offsets[j], group_offsets[j + 1],
                     scratch, c->group_centers_[j], c->group_half_extents_[j], out);
      }
    });
    c->group_cluster_offsets_.assign(1, 0);
    c->cluster_vertex_offsets_.assign(1, 0);
    c->group_influence_offsets_.assign(1, 0);
    c->cluster_influence_offsets_.assign(1, 0);
    const auto append_ends = [](const std::vector<uint32_t>& ends, std::vector<uint32_t>& offsets) {
      const uint32_t start = offsets.back();
      for (uint32_t end : ends) offsets.push_back(start + end);
    };
    for (const GroupClusters& run_out : run_clusters) {
      append_ends(run_out.group_cluster_ends, c->group_cluster_offsets_);
      append_ends(run_out.group_influence_ends, c->group_influence_offsets_);
      append_ends(run_out.cluster_influence_ends, c->cluster_influence_offsets_);
      c->group_influences_.insert(c->group_influences_.end(), run_out.group_influences.begin(),
                                  run_out.group_influences.end());
      c->cluster_influences_.insert(c->cluster_influences_.end(),
                                    run_out.cluster_influences.begin(),
                                    run_out.cluster_influences.end());
      c->cluster_vertex_offsets_.insert(c->cluster_vertex_offsets_.end(),
                                        run_out.cluster_vertex_ends.begin(),
                                        run_out.cluster_vertex_ends.end());
      c->cluster_centers_.insert(c->cluster_centers_.end(), run_out.cluster_centers.begin(),
                                 run_out.cluster_centers.end());
      c->cluster_half_extents_.insert(c->cluster_half_extents_.end(),
                                      run_out.cluster_half_extents.begin(),
                                      run_out.cluster_half_extents.end());
    }
    // The clusters' lane blocks (cluster_lanes), in pieces of clusters.
    const size_t clusters = c->cluster_centers_.size();
    c->cluster_lane_offsets_.resize(clusters + 1);
    c->cluster_lane_offsets_[0] = 0;
    for (size_t q = 0; q < clusters; ++q) {
      const uint32_t count = c->cluster_vertex_offsets_[q + 1] - c->cluster_vertex_offsets_[q];
      const uint32_t rows =
          3 + c->cluster_influence_offsets_[q + 1] - c->cluster_influence_offsets_[q];
      c->cluster_lane_offsets_[q + 1] =
          c->cluster_lane_offsets_[q] + rows * Character::ClusterLaneRow(count);
    }
    c->cluster_lanes_.assign(c->cluster_lane_offsets_.back(), 0.0f);
    constexpr size_t kLanePieceClusters = kClusterPieceVertices / Character::kMaxClusterVertices;
    const size_t lane_pieces = (clusters + kLanePieceClusters - 1) / kLanePieceClusters;
    RunPieces(run, static_cast<int>(lane_pieces), [&](int piece) {
      std::vector<int32_t> row_of_joint(n, -1);
      const size_t first_cluster = piece * kLanePieceClusters;
      const size_t end_cluster = std::min(clusters, first_cluster + kLanePieceClusters);
      for (size_t q = first_cluster; q < end_cluster; ++q) {
        const uint32_t first = c->cluster_vertex_offsets_[q];
        const uint32_t count = c->cluster_vertex_offsets_[q + 1] - first;
        const uint32_t padded = Character::ClusterLaneRow(count);
        const uint32_t influences = c->cluster_influence_offsets_[q];
        for (uint32_t g = influences; g < c->cluster_influence_offsets_[q + 1]; ++g) {
          row_of_joint[c->cluster_influences_[g].joint] = static_cast<int32_t>(3 + g - influences);
        }
        float* block = c->cluster_lanes_.data() + c->cluster_lane_offsets_[q];
        for (uint32_t v = 0; v < count; ++v) {
          const uint32_t i = c->cluster_vertices_[first + v];
          for (int a = 0; a < 3; ++a) block[a * padded + v] = k.positions[i][a];
          for (uint32_t e = k.influence_offsets[i]; e < k.influence_offsets[i + 1]; ++e) {
            block[row_of_joint[k.influence_joints[e]] * padded + v] = k.influence_weights[e];
          }
        }
      }
    });
  };
  const auto areas_and_moments = [&] {
    // A_i: each triangle's area goes to its three corners.
    c->vertex_areas_.assign(p, 0.0);
    for (const auto& tri : k.triangles) {
      const Vec3d a = k.positions[tri[0]].cast<double>();
      const Vec3d b = k.positions[tri[1]].cast<double>();
      const Vec3d d = k.positions[tri[2]].cast<double>();
      const double area = 0.5 * (b - a).cross(d - a).norm();
      for (uint32_t v : tri) c->vertex_areas_[v] += area;
    }
    // Vertices outside every triangle (point clouds, degenerate faces) still count:
    // they get the mean area so the fit never ignores them.
    double total_area = 0;
    int with_area = 0;
    for (double a : c->vertex_areas_) {
      total_area += a;
      with_area += a > 0;
    }
    const double fallback_area = with_area > 0 ? total_area / with_area : 1.0;
    for (double& a : c->vertex_areas_) {
      if (a <= 0) a = fallback_area;
    }

    // Pair moments, accumulated per (k <= l) block of an n x n table, then listed. Both
    // moments are symmetric: their 10 + 6 distinct entries are summed as one contiguous
    // row of 16 (a third fewer additions than the full matrices, in whole vectors).
    {
      double total = 0;
      for (double a : c->vertex_areas_) total += a;
      constexpr int kEntries = 16;
      std::vector<int> slot(static_cast<size_t>(n) * n, -1);
      std::vector<std::pair<int, int>> pairs;
      std::vector<double> sums;
      for (int i = 0; i < p; ++i) {
        const double a = c->vertex_areas_[i] / total;
        const double x = k.positions[i].x(), y = k.positions[i].y(), z = k.positions[i].z();
        const double nx = k.normals[i].x(), ny = k.normals[i].y(), nz = k.normals[i].z();
        // The row of 16, upper triangles row by row (v_r v_q for q >= r with v = [x y z 1],
        // then the normal's), built as pairs in registers: written one double at a time,
        // each 16-byte read of the row waited for two stores to retire.
        const Lanes2 entries[kEntries / 2] = {Lanes2{x, y} * x,
                                              Lanes2{z, 1.0} * x,
                                              Lanes2{y, y} * Lanes2{y, z},
                                              Lanes2{y, z} * Lanes2{1.0, z},
                                              Lanes2{z, 1.0},
                                              Lanes2{nx, nx} * Lanes2{nx, ny},
                                              Lanes2{nx, ny} * Lanes2{nz, ny},
                                              Lanes2{ny, nz} * Lanes2{nz, nz}};
        for (uint32_t f = k.influence_offsets[i]; f < k.influence_offsets[i + 1]; ++f) {
          for (uint32_t g = f; g < k.influence_offsets[i + 1]; ++g) {
            const int lo = std::min(k.influence_joints[f], k.influence_joints[g]);
            const int hi = std::max(k.influence_joints[f], k.influence_joints[g]);
            int& index = slot[static_cast<size_t>(lo) * n + hi];
            if (index < 0) {
              index = static_cast<int>(pairs.size());
              pairs.emplace_back(lo, hi);
              sums.resize(sums.size() + kEntries, 0.0);
            }
            const double w = a * k.influence_weights[f] * k.influence_weights[g];
            UnalignedLanes2* sum = AsLanes2(sums.data() + static_cast<size_t>(index) * kEntries);
            for (int e = 0; e < kEntries / 2; ++e) sum[e] += w * entries[e];
          }
        }
      }
      auto& moments = c->joint_pair_moments_;
      moments.resize(pairs.size());
      for (size_t index = 0; index < pairs.size(); ++index) {
        const double* sum = sums.data() + index * kEntries;
        Character::JointPairMoment& moment = moments[index];
        std::tie(moment.k, moment.l) = pairs[index];
        int e = 0;
        for (int r = 0; r < 4; ++r) {
          for (int q = r; q < 4; ++q)
            moment.position_moment(r, q) = moment.position_moment(q, r) = sum[e++];
        }
        for (int r = 0; r < 3; ++r) {
          for (int q = r; q < 3; ++q)
            moment.normal_moment(r, q) = moment.normal_moment(q, r) = sum[e++];
        }
      }
    }
  };
  RunPieces(run, 3, [&](int piece) {
    if (piece == 0) {
      clusters();
    } else if (piece == 1) {
      areas_and_moments();
    } else {
      boxes_and_lengths();
    }
  });
  return std::shared_ptr<const Character>(std::move(c));
}

}  // namespace motionlod::core
