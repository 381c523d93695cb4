#include "core/skinning.h"

#include <string>

namespace motionlod::core {

Status SkinningJob::Validate() const {
  if (character == nullptr) return InvalidArgument("SkinningJob: no character");
  const size_t p = static_cast<size_t>(character->vertex_count());
  if (out_positions.size() != p) {
    return InvalidArgument("SkinningJob: out_positions holds " +
                           std::to_string(out_positions.size()) + " vertices, the skin " +
                           std::to_string(p));
  }
  if (!out_normals.empty() && out_normals.size() != p) {
    return InvalidArgument("SkinningJob: out_normals must be empty or hold every vertex");
  }
  if (skinning_matrices.size() != static_cast<size_t>(character->joint_count())) {
    return InvalidArgument("SkinningJob: " + std::to_string(skinning_matrices.size()) +
                           " skinning matrices for " + std::to_string(character->joint_count()) +
                           " joints");
  }
  return Status::Ok();
}

// Not in an AVX2 version (core/internal/simd_dispatch.h): on this loop that version was 3% to 4% slower, and
// the bake benchmark's reference skinning pass must be the faster one.
Status SkinningJob::Run() const {
  if (Status status = Validate(); !status.ok()) return status;
  const RawSkin& k = character->skin();
  const size_t p = k.positions.size();
  const bool with_normals = !out_normals.empty();
  const uint32_t* offsets = k.influence_offsets.data();
  const int32_t* joints = k.influence_joints.data();
  const float* weights = k.influence_weights.data();
  for (size_t i = 0; i < p; ++i) {
    // Blend the matrices first: 12 multiply-adds per influence, then one transform.
    Affine34f blended = weights[offsets[i]] * skinning_matrices[joints[offsets[i]]];
    for (uint32_t e = offsets[i] + 1; e < offsets[i + 1]; ++e) {
      blended.noalias() += weights[e] * skinning_matrices[joints[e]];
    }
    out_positions[i] = blended.leftCols<3>() * k.positions[i] + blended.col(3);
    if (with_normals) out_normals[i] = blended.leftCols<3>() * k.normals[i];
  }
  return Status::Ok();
}

}  // namespace motionlod::core
