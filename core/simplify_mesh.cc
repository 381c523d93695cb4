// The simplified mesh of a far level (core/simplify_mesh.h).
#include "core/simplify_mesh.h"

#include <meshoptimizer.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <string>
#include <tuple>
#include <utility>

namespace motionlod::core {
namespace {

constexpr float kShareStep = 0.25f;
// How much farther than the nearest point a corresponding point may be, in heights.
constexpr double kCorrespondenceSlack = 0.01;

// The closest point to p on triangle (a, b, c), as barycentric weights (Ericson, Real-Time
// Collision Detection, 5.1.5).
std::array<float, 3> ClosestOnTriangle(const Vec3f& p, const Vec3f& a, const Vec3f& b,
                                       const Vec3f& c) {
  const Vec3f ab = b - a, ac = c - a, ap = p - a;
  const float d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return {1, 0, 0};
  const Vec3f bp = p - b;
  const float d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return {0, 1, 0};
  const float vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) {
    const float v = d1 / (d1 - d3);
    return {1 - v, v, 0};
  }
  const Vec3f cp = p - c;
  const float d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return {0, 0, 1};
  const float vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) {
    const float w = d2 / (d2 - d6);
    return {1 - w, 0, w};
  }
  const float va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
    const float w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
    return {0, 1 - w, w};
  }
  const float denominator = va + vb + vc;
  if (!(denominator > 0)) return {1, 0, 0};  // degenerate triangle: its first corner
  const float v = vb / denominator, w = vc / denominator;
  return {1 - v - w, v, w};
}

// The triangles' bounding boxes in a uniform grid, so that a vertex looks at the cells
// around it, ring after ring, rather than at every triangle.
struct TriangleGrid {
  static constexpr int kCellsPerAxis = 32;
  Eigen::AlignedBox3f bounds;
  float cell = 1;
  Eigen::Array3i dims = Eigen::Array3i::Ones();
  std::vector<std::vector<uint32_t>> cells;

  explicit TriangleGrid(const std::vector<Eigen::AlignedBox3f>& boxes) {
    for (const auto& box : boxes) bounds.extend(box);
    cell = std::max(bounds.sizes().maxCoeff() / kCellsPerAxis, 1e-20f);
    dims = ((bounds.sizes().array() / cell).ceil().cast<int>()).max(1).min(kCellsPerAxis);
    cells.resize(static_cast<size_t>(dims.prod()));
    for (uint32_t t = 0; t < boxes.size(); ++t) {
      const Eigen::Array3i low = CellOf(boxes[t].min()), high = CellOf(boxes[t].max());
      for (int z = low.z(); z <= high.z(); ++z) {
        for (int y = low.y(); y <= high.y(); ++y) {
          for (int x = low.x(); x <= high.x(); ++x) cells[Index(x, y, z)].push_back(t);
        }
      }
    }
  }
  Eigen::Array3i CellOf(const Vec3f& point) const {
    return ((point - bounds.min()).array() / cell).floor().cast<int>().max(0).min(dims - 1);
  }
  size_t Index(int x, int y, int z) const {
    return (static_cast<size_t>(z) * dims.y() + y) * dims.x() + x;
  }
  int max_ring() const { return dims.maxCoeff(); }
  // Calls visit(t) for every triangle listed in the cells at Chebyshev distance `ring`
  // from `home` (a triangle may come more than once).
  template <typename Visit>
  void VisitRing(const Eigen::Array3i& home, int ring, Visit&& visit) const {
    const Eigen::Array3i low = (home - ring).max(0), high = (home + ring).min(dims - 1);
    for (int z = low.z(); z <= high.z(); ++z) {
      for (int y = low.y(); y <= high.y(); ++y) {
        for (int x = low.x(); x <= high.x(); ++x) {
          const int distance =
              std::max({std::abs(x - home.x()), std::abs(y - home.y()), std::abs(z - home.z())});
          if (distance != ring) continue;
          for (uint32_t t : cells[Index(x, y, z)]) visit(t);
        }
      }
    }
  }
};

}  // namespace

Status SimplifyMeshJob::Validate() const {
  if (character == nullptr) return InvalidArgument("SimplifyMeshJob: no character");
  if (character->skin().triangles.empty()) {
    return InvalidArgument("SimplifyMeshJob: the character has no triangles to simplify");
  }
  if (target_triangles < 1)
    return InvalidArgument("SimplifyMeshJob: the target must be at least one triangle");
  if (!(target_error >= 0) || !std::isfinite(target_error)) {
    return InvalidArgument("SimplifyMeshJob: the target error must be finite and >= 0");
  }
  return Status::Ok();
}

StatusOr<LevelMesh> SimplifyMeshJob::Run() const {
  if (Status status = Validate(); !status.ok()) return status;
  const RawSkin& skin = character->skin();
  const size_t p = skin.positions.size();
  // Each triangle belongs to a part of the skin (SkinSplit); a vertex of triangles of
  // several parts, and the copies of a vertex at one position (a flat-shaded mesh), become
  // one vertex per part, which meshoptimizer keeps as a seam. Collapses then stay within a
  // part: the bind pose alone cannot tell that a vertex on a straight edge between two
  // joints' parts bends with them.
  std::map<std::tuple<float, float, float, int64_t>, uint32_t> split_of;
  std::vector<uint32_t> original_of;
  std::vector<Vec3f> split_positions;
  std::vector<uint32_t> indices;
  indices.reserve(3 * skin.triangles.size());
  std::map<int, float> weight_of_joint;
  for (const auto& triangle : skin.triangles) {
    weight_of_joint.clear();
    for (uint32_t v : triangle) {
      for (uint32_t e = skin.influence_offsets[v]; e < skin.influence_offsets[v + 1]; ++e) {
        weight_of_joint[skin.influence_joints[e]] += skin.influence_weights[e];
      }
    }
    // The two joints with the most weight and the first's share, in steps of kShareStep.
    std::pair<int, float> first{-1, 0.0f}, second{-1, 0.0f};
    float total = 0;
    for (const auto& [joint, weight] : weight_of_joint) {
      total += weight;
      if (weight > first.second) {
        second = first;
        first = {joint, weight};
      } else if (weight > second.second) {
        second = {joint, weight};
      }
    }
    const int share = static_cast<int>(std::lround(first.second / total / kShareStep));
    const int64_t region =
        (static_cast<int64_t>(first.first) * 65536 + (second.first + 1)) * 64 + share;
    for (uint32_t v : triangle) {
      const Vec3f& at = skin.positions[v];
      const auto [it, inserted] =
          split_of.try_emplace({at.x(), at.y(), at.z(),
                                split == SkinSplit::kNone            ? 0
                                : split == SkinSplit::kDominantJoint ? first.first
                                                                     : region},
                               static_cast<uint32_t>(original_of.size()));
      if (inserted) {
        original_of.push_back(v);
        split_positions.push_back(skin.positions[v]);
      }
      indices.push_back(it->second);
    }
  }
  const float* positions = split_positions.data()->data();
  const float scale = meshopt_simplifyScale(positions, split_positions.size(), sizeof(Vec3f));
  std::vector<uint32_t> simplified(indices.size());
  float relative_error = 0;
  const size_t target_indices = std::min(indices.size(), 3 * static_cast<size_t>(target_triangles));
  simplified.resize(meshopt_simplify(simplified.data(), indices.data(), indices.size(), positions,
                                     split_positions.size(), sizeof(Vec3f), target_indices,
                                     static_cast<float>(target_error / std::max(scale, 1e-30f)), 0,
                                     &relative_error));
  for (uint32_t& v : simplified) v = original_of[v];
  if (simplified.empty()) {
    return InvalidArgument("SimplifyMeshJob: the simplification left no triangle");
  }
  LevelMesh mesh;
  mesh.bind_error = static_cast<double>(relative_error) * scale;
  constexpr uint32_t kRemoved = std::numeric_limits<uint32_t>::max();
  std::vector<uint32_t> level_index(p, kRemoved);
  for (uint32_t v : simplified) level_index[v] = 0;
  for (uint32_t v = 0; v < p; ++v) {
    if (level_index[v] != kRemoved) {
      level_index[v] = static_cast<uint32_t>(mesh.vertices.size());
      mesh.vertices.push_back(v);
    }
  }
  for (size_t e = 0; e < simplified.size(); e += 3) {
    const auto triangle = std::array<uint32_t, 3>{
        level_index[simplified[e]], level_index[simplified[e + 1]], level_index[simplified[e + 2]]};
    mesh.triangles.push_back(triangle);
  }

  mesh.correspondence =
      SurfaceCorrespondence(*character, mesh.vertices, mesh.triangles);
  return mesh;
}

std::vector<SurfacePoint> SurfaceCorrespondence(const Character& character,
                                                std::span<const uint32_t> vertices,
                                                std::span<const std::array<uint32_t, 3>> triangles) {
  const RawSkin& skin = character.skin();
  const size_t p = skin.positions.size();
  constexpr uint32_t kRemoved = std::numeric_limits<uint32_t>::max();
  std::vector<uint32_t> level_index(p, kRemoved);
  for (uint32_t s = 0; s < vertices.size(); ++s) level_index[vertices[s]] = s;
  std::vector<SurfacePoint> correspondence(p);
  // Each removed vertex: a point of the simplified bind-pose surface near it that moves as
  // it does. Pieces of a mesh need not share edges and often pass close to other pieces
  // (a robot's torso through its head), so the nearest point may follow other joints: of
  // the points within kCorrespondenceSlack of the nearest, the one whose interpolated
  // weights differ least from the vertex's (L1) wins. Triangles whose bounding box is
  // farther than that skipped.
  std::vector<Eigen::AlignedBox3f> boxes;
  boxes.reserve(triangles.size());
  for (const auto& corners : triangles) {
    Eigen::AlignedBox3f box;
    for (uint32_t corner : corners) box.extend(skin.positions[vertices[corner]]);
    boxes.push_back(box);
  }
  const TriangleGrid grid(boxes);
  std::vector<uint32_t> visited(triangles.size(), 0);
  uint32_t stamp = 0;
  const float slack =
      static_cast<float>(kCorrespondenceSlack * character.height());
  auto weight_difference = [&](uint32_t v, const std::array<uint32_t, 3>& corners,
                               const std::array<float, 3>& w) {
    // sum_j |w_vj - sum_c w_c w_{corner c, j}|: every joint of the vertex or a corner.
    float difference = 0;
    auto weight_in = [&](uint32_t u, int joint) {
      for (uint32_t e = skin.influence_offsets[u]; e < skin.influence_offsets[u + 1]; ++e) {
        if (skin.influence_joints[e] == joint) return skin.influence_weights[e];
      }
      return 0.0f;
    };
    auto add_joint = [&](int joint, bool seen_before) {
      if (seen_before) return;
      float blended = 0;
      for (int c = 0; c < 3; ++c) blended += w[c] * weight_in(vertices[corners[c]], joint);
      difference += std::abs(weight_in(v, joint) - blended);
    };
    std::array<int, 64> seen{};
    int seen_count = 0;
    auto visit = [&](uint32_t u) {
      for (uint32_t e = skin.influence_offsets[u]; e < skin.influence_offsets[u + 1]; ++e) {
        const int joint = skin.influence_joints[e];
        const bool before =
            std::find(seen.begin(), seen.begin() + seen_count, joint) != seen.begin() + seen_count;
        add_joint(joint, before);
        if (!before && seen_count < static_cast<int>(seen.size())) seen[seen_count++] = joint;
      }
    };
    visit(v);
    for (int c = 0; c < 3; ++c) visit(vertices[corners[c]]);
    return difference;
  };
  for (uint32_t v = 0; v < p; ++v) {
    if (level_index[v] != kRemoved) {
      correspondence[v] = {{level_index[v], level_index[v], level_index[v]}, {1, 0, 0}};
      continue;
    }
    const Vec3f& at = skin.positions[v];
    auto closest = [&](size_t t) {
      const auto& corners = triangles[t];
      const Vec3f& a = skin.positions[vertices[corners[0]]];
      const Vec3f& b = skin.positions[vertices[corners[1]]];
      const Vec3f& c = skin.positions[vertices[corners[2]]];
      const std::array<float, 3> w = ClosestOnTriangle(at, a, b, c);
      return std::pair(w, (w[0] * a + w[1] * b + w[2] * c - at).norm());
    };
    const Eigen::Array3i home = grid.CellOf(at);
    float nearest = std::numeric_limits<float>::infinity();
    for (int ring = 0; ring <= grid.max_ring() && !(nearest <= ring * grid.cell); ++ring) {
      grid.VisitRing(home, ring, [&](uint32_t t) {
        if (boxes[t].exteriorDistance(at) < nearest) nearest = std::min(nearest, closest(t).second);
      });
    }
    float best = std::numeric_limits<float>::infinity(), best_distance = 0;
    const int reach = static_cast<int>(std::ceil((nearest + slack) / grid.cell));
    ++stamp;
    for (int ring = 0; ring <= std::min(reach, grid.max_ring()); ++ring) {
      grid.VisitRing(home, ring, [&](uint32_t t) {
        if (visited[t] == stamp) return;
        visited[t] = stamp;
        if (boxes[t].exteriorDistance(at) > nearest + slack) return;
        const auto [w, distance] = closest(t);
        if (distance > nearest + slack) return;
        const float difference = weight_difference(v, triangles[t], w);
        if (difference < best || (difference == best && distance < best_distance)) {
          best = difference;
          best_distance = distance;
          correspondence[v] = {triangles[t], w};
        }
      });
    }
  }
  return correspondence;
}

StatusOr<std::shared_ptr<const Character>> SubsetCharacter(const Character& character,
                                                           const LevelMesh& mesh) {
  const RawSkin& skin = character.skin();
  RawCharacter raw;
  raw.name = character.name();
  raw.skeleton = character.skeleton();
  raw.skin.influence_offsets.push_back(0);
  for (uint32_t v : mesh.vertices) {
    if (v >= skin.positions.size()) {
      return InvalidArgument("SubsetCharacter: vertex " + std::to_string(v) +
                             " is not the character's");
    }
    raw.skin.positions.push_back(skin.positions[v]);
    raw.skin.normals.push_back(skin.normals[v]);
    for (uint32_t e = skin.influence_offsets[v]; e < skin.influence_offsets[v + 1]; ++e) {
      raw.skin.influence_joints.push_back(skin.influence_joints[e]);
      raw.skin.influence_weights.push_back(skin.influence_weights[e]);
    }
    raw.skin.influence_offsets.push_back(static_cast<uint32_t>(raw.skin.influence_joints.size()));
  }
  raw.skin.triangles = mesh.triangles;
  return BuildCharacter(raw);
}

}  // namespace motionlod::core
