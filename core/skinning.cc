#include "core/skinning.h"

#include <string>

namespace motionlod::core {

Status SkinningJob::Validate() const {
  if (skin == nullptr) return InvalidArgument("SkinningJob: no skin");
  const size_t p = skin->positions.size();
  if (out_positions.size() != p) {
    return InvalidArgument("SkinningJob: out_positions holds " +
                           std::to_string(out_positions.size()) + " vertices, the skin " +
                           std::to_string(p));
  }
  if (!out_normals.empty() && out_normals.size() != p) {
    return InvalidArgument("SkinningJob: out_normals must be empty or hold every vertex");
  }
  for (int32_t j : skin->influence_joints) {
    if (j < 0 || static_cast<size_t>(j) >= skinning_matrices.size()) {
      return InvalidArgument("SkinningJob: the skin references joint " + std::to_string(j) +
                             " but only " + std::to_string(skinning_matrices.size()) +
                             " skinning matrices were given");
    }
  }
  return Status::Ok();
}

Status SkinningJob::Run() const {
  if (Status status = Validate(); !status.ok()) return status;
  const RawSkin& k = *skin;
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
