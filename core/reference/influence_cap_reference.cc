#include "core/reference/influence_cap_reference.h"

#include <array>
#include <vector>

#include "core/internal/influence_cap.h"

namespace motionlod::core {

LevelInfluences InfluenceCapReference(const Character& character, const Motion& motion,
                                      const ReducedSkeleton& level,
                                      std::span<const RowMajorAffine34f> matrices, int cap,
                                      double normal_weight) {
  const RawSkin& skin = character.skin();
  const RawSkeleton& skeleton = character.skeleton();
  const int p = character.vertex_count(), n = character.joint_count(), m = level.kept_count();
  std::vector<Affine34d> inverse_bind(static_cast<size_t>(n));
  for (int j = 0; j < n; ++j) inverse_bind[j] = InverseAffine(skeleton.bind_world[j]);
  const std::vector<std::vector<int>> children = internal::KeptChildren(level);
  LevelInfluences out;
  out.per_vertex = cap;
  out.slots.resize(static_cast<size_t>(p) * cap);
  out.weights.resize(out.slots.size());
  std::array<int, kMaxCandidates> candidates{};
  for (int i = 0; i < p; ++i) {
    const int c = internal::CandidateSlots(character, level, children, i, candidates);
    const Vec3d v0 = skin.positions[i].cast<double>(), n0 = skin.normals[i].cast<double>();
    std::vector<double> g(static_cast<size_t>(c) * c, 0.0), r(static_cast<size_t>(c), 0.0),
        w(static_cast<size_t>(c));
    for (int t = 0; t < motion.frame_count; ++t) {
      Vec3d original_v = Vec3d::Zero(), original_n = Vec3d::Zero();
      for (uint32_t e = skin.influence_offsets[i]; e < skin.influence_offsets[i + 1]; ++e) {
        const int j = skin.influence_joints[e];
        const Affine34d k = ComposeAffine(motion.world(t, j), inverse_bind[j]);
        original_v += skin.influence_weights[e] * TransformPoint(k, v0);
        original_n += skin.influence_weights[e] * TransformDirection(k, n0);
      }
      std::vector<Vec3d> slot_v(static_cast<size_t>(c)), slot_n(static_cast<size_t>(c));
      for (int a = 0; a < c; ++a) {
        const Affine34d k = matrices[static_cast<size_t>(t) * m + candidates[a]].cast<double>();
        slot_v[a] = TransformPoint(k, v0);
        slot_n[a] = TransformDirection(k, n0);
      }
      for (int a = 0; a < c; ++a) {
        for (int b = 0; b < c; ++b)
          g[a * c + b] += slot_v[a].dot(slot_v[b]) + normal_weight * slot_n[a].dot(slot_n[b]);
        r[a] += slot_v[a].dot(original_v) + normal_weight * slot_n[a].dot(original_n);
      }
    }
    internal::SolveCappedSimplex(g, r, c, cap, w);
    internal::WriteInfluenceRow(std::span(candidates).first(c), w, i, out);
  }
  return out;
}

}  // namespace motionlod::core
