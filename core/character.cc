#include "core/character.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <tuple>
#include <unordered_set>

#include "core/internal/lanes.h"
#include "core/internal/skin_clusters.h"
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
  // (themselves in pieces); the areas and pair moments; the height and the subtree lengths.
  const auto height_and_lengths = [&] {
    Eigen::Vector3d lo = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity());
    Eigen::Vector3d hi = -lo;
    for (const Vec3f& v : k.positions) {
      lo = lo.cwiseMin(v.cast<double>());
      hi = hi.cwiseMax(v.cast<double>());
    }
    c->height_ = (hi - lo).maxCoeff();
    if (!(c->height_ > 0)) c->height_ = 1.0;
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
      c->clusters_ = std::make_shared<const internal::SkinClusters>(
          internal::BuildSkinClusters(c->skeleton_, c->skin_, run));
    } else if (piece == 1) {
      areas_and_moments();
    } else {
      height_and_lengths();
    }
  });
  return std::shared_ptr<const Character>(std::move(c));
}

}  // namespace motionlod::core
