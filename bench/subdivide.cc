#include "bench/subdivide.h"

#include <algorithm>
#include <cstdint>
#include <unordered_map>
#include <utility>
#include <vector>

namespace motionlod::bench {
namespace {

using core::RawSkin;
using core::Vec3f;

struct Influence {
  int32_t joint;
  float weight;
};

// Appends the influences of a vertex to the skin's compressed rows (weights renormalised).
void AppendInfluences(std::vector<Influence>& influences, int max_influences, RawSkin& out) {
  std::sort(influences.begin(), influences.end(),
            [](const Influence& a, const Influence& b) {
              return a.weight != b.weight ? a.weight > b.weight : a.joint < b.joint;
            });
  if (static_cast<int>(influences.size()) > max_influences) influences.resize(max_influences);
  float sum = 0;
  for (const Influence& f : influences) sum += f.weight;
  for (const Influence& f : influences) {
    out.influence_joints.push_back(f.joint);
    out.influence_weights.push_back(f.weight / sum);
  }
  out.influence_offsets.push_back(static_cast<uint32_t>(out.influence_joints.size()));
}

}  // namespace

core::RawCharacter SubdivideOnce(const core::RawCharacter& raw, int max_influences) {
  const RawSkin& in = raw.skin;
  core::RawCharacter result;
  result.name = raw.name;
  result.skeleton = raw.skeleton;
  RawSkin& out = result.skin;

  out.positions = in.positions;
  out.normals = in.normals;
  out.influence_offsets.assign(in.influence_offsets.begin(), in.influence_offsets.end());
  out.influence_joints = in.influence_joints;
  out.influence_weights = in.influence_weights;

  std::unordered_map<uint64_t, uint32_t> midpoints;
  midpoints.reserve(in.triangles.size() * 2);
  std::vector<Influence> merged;
  auto midpoint = [&](uint32_t a, uint32_t b) -> uint32_t {
    const uint64_t key = (uint64_t{std::min(a, b)} << 32) | std::max(a, b);
    const auto [it, inserted] = midpoints.emplace(key, static_cast<uint32_t>(out.positions.size()));
    if (!inserted) return it->second;
    out.positions.push_back(0.5f * (in.positions[a] + in.positions[b]));
    Vec3f normal = in.normals[a] + in.normals[b];
    const float length = normal.norm();
    out.normals.push_back(length > 1e-6f ? Vec3f(normal / length) : in.normals[a]);
    merged.clear();
    for (uint32_t v : {a, b}) {
      for (uint32_t e = in.influence_offsets[v]; e < in.influence_offsets[v + 1]; ++e) {
        const int32_t joint = in.influence_joints[e];
        const float weight = 0.5f * in.influence_weights[e];
        auto same = std::find_if(merged.begin(), merged.end(),
                                 [&](const Influence& f) { return f.joint == joint; });
        if (same != merged.end()) {
          same->weight += weight;
        } else {
          merged.push_back({joint, weight});
        }
      }
    }
    AppendInfluences(merged, max_influences, out);
    return it->second;
  };

  out.triangles.reserve(in.triangles.size() * 4);
  for (const auto& tri : in.triangles) {
    const uint32_t a = tri[0], b = tri[1], c = tri[2];
    const uint32_t ab = midpoint(a, b), bc = midpoint(b, c), ca = midpoint(c, a);
    out.triangles.push_back({a, ab, ca});
    out.triangles.push_back({ab, b, bc});
    out.triangles.push_back({ca, bc, c});
    out.triangles.push_back({ab, bc, ca});
  }
  return result;
}

core::RawCharacter SubdivideToVertexCount(const core::RawCharacter& raw, int min_vertices,
                                          int* steps, int max_influences, int max_steps) {
  core::RawCharacter current = raw;
  int taken = 0;
  while (static_cast<int>(current.skin.positions.size()) < min_vertices && taken < max_steps &&
         !current.skin.triangles.empty()) {
    current = SubdivideOnce(current, max_influences);
    ++taken;
  }
  if (steps != nullptr) *steps = taken;
  return current;
}

}  // namespace motionlod::bench
