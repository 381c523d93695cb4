// The simplified mesh of a far level (core/simplify_mesh.h).
#include "core/simplify_mesh.h"

#include <meshoptimizer.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

namespace motionlod::core {
namespace {

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
  std::vector<uint32_t> indices;
  indices.reserve(3 * skin.triangles.size());
  for (const auto& triangle : skin.triangles)
    indices.insert(indices.end(), triangle.begin(), triangle.end());
  const float* positions = skin.positions.data()->data();
  const float scale = meshopt_simplifyScale(positions, p, sizeof(Vec3f));
  std::vector<uint32_t> simplified(indices.size());
  float relative_error = 0;
  const size_t target_indices = std::min(indices.size(), 3 * static_cast<size_t>(target_triangles));
  simplified.resize(meshopt_simplify(simplified.data(), indices.data(), indices.size(), positions,
                                     p, sizeof(Vec3f), target_indices,
                                     static_cast<float>(target_error / std::max(scale, 1e-30f)), 0,
                                     &relative_error));
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
  std::vector<std::vector<uint32_t>> triangles_of(
      mesh.vertices.size());  // level vertex -> level triangles
  for (size_t e = 0; e < simplified.size(); e += 3) {
    const auto triangle = std::array<uint32_t, 3>{
        level_index[simplified[e]], level_index[simplified[e + 1]], level_index[simplified[e + 2]]};
    for (uint32_t corner : triangle)
      triangles_of[corner].push_back(static_cast<uint32_t>(mesh.triangles.size()));
    mesh.triangles.push_back(triangle);
  }

  // Each removed vertex: breadth first along the original edges until kept vertices are
  // found, then the nearest point on the simplified triangles around them.
  std::vector<std::vector<uint32_t>> neighbours(p);
  for (const auto& t : skin.triangles) {
    for (int a = 0; a < 3; ++a) {
      neighbours[t[a]].push_back(t[(a + 1) % 3]);
      neighbours[t[a]].push_back(t[(a + 2) % 3]);
    }
  }
  mesh.correspondence.resize(p);
  std::vector<uint32_t> visited_at(p, kRemoved), frontier, next, found;
  for (uint32_t v = 0; v < p; ++v) {
    if (level_index[v] != kRemoved) {
      mesh.correspondence[v] = {{level_index[v], level_index[v], level_index[v]}, {1, 0, 0}};
      continue;
    }
    found.clear();
    frontier.assign(1, v);
    visited_at[v] = v;
    // The ring where kept vertices first appear and the one after it.
    for (int extra_rings = -1; !frontier.empty() && extra_rings < 1;) {
      next.clear();
      for (uint32_t u : frontier) {
        for (uint32_t w : neighbours[u]) {
          if (visited_at[w] == v) continue;
          visited_at[w] = v;
          next.push_back(w);
          if (level_index[w] != kRemoved) found.push_back(level_index[w]);
        }
      }
      frontier.swap(next);
      if (!found.empty()) ++extra_rings;
    }
    if (found.empty()) {  // a piece of the mesh with no kept vertex: the nearest kept one
      float nearest = std::numeric_limits<float>::infinity();
      for (uint32_t s = 0; s < mesh.vertices.size(); ++s) {
        const float d = (skin.positions[mesh.vertices[s]] - skin.positions[v]).squaredNorm();
        if (d < nearest) {
          nearest = d;
          found.assign(1, s);
        }
      }
    }
    float best = std::numeric_limits<float>::infinity();
    for (uint32_t s : found) {
      for (uint32_t t : triangles_of[s]) {
        const auto& corners = mesh.triangles[t];
        const Vec3f& a = skin.positions[mesh.vertices[corners[0]]];
        const Vec3f& b = skin.positions[mesh.vertices[corners[1]]];
        const Vec3f& c = skin.positions[mesh.vertices[corners[2]]];
        const std::array<float, 3> w = ClosestOnTriangle(skin.positions[v], a, b, c);
        const float d = (w[0] * a + w[1] * b + w[2] * c - skin.positions[v]).squaredNorm();
        if (d < best) {
          best = d;
          mesh.correspondence[v] = {corners, w};
        }
      }
    }
  }
  return mesh;
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
