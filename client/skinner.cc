#include "client/skinner.h"

#include <cmath>
#include <string>

namespace motionlod::client {
namespace {

Error Invalid(std::string message) {
  return Error{ErrorKind::kInvalidArgument, 0, std::nullopt, std::move(message)};
}

}  // namespace

Result<LevelSkin> LevelSkin::Build(const SkinMesh& mesh, std::span<const uint16_t> joint_map,
                                   uint32_t kept_count) {
  const size_t p = mesh.positions.size() / 3;
  if (mesh.positions.size() % 3 != 0 || p == 0)
    return Invalid("SkinMesh: positions must hold 3 floats per vertex, at least one vertex");
  if (!mesh.normals.empty() && mesh.normals.size() != mesh.positions.size())
    return Invalid("SkinMesh: normals must be empty or hold 3 floats per vertex");
  if (mesh.influence_offsets.size() != p + 1 || mesh.influence_offsets[0] != 0)
    return Invalid("SkinMesh: influence_offsets must hold p + 1 entries starting at 0");
  if (mesh.influence_joints.size() != mesh.influence_weights.size() ||
      mesh.influence_offsets[p] != mesh.influence_joints.size())
    return Invalid("SkinMesh: influence_offsets must end at the number of influences");
  if (kept_count == 0) return Invalid("LevelSkin: a level keeps at least one joint");
  for (size_t j = 0; j < joint_map.size(); ++j) {
    if (joint_map[j] >= kept_count)
      return Invalid("LevelSkin: joint_map[" + std::to_string(j) + "] is not a slot");
  }
  LevelSkin skin;
  skin.positions_ = mesh.positions;
  skin.normals_ = mesh.normals;
  skin.kept_count_ = kept_count;
  skin.offsets_.reserve(p + 1);
  skin.offsets_.push_back(0);
  skin.slots_.reserve(mesh.influence_joints.size());
  skin.weights_.reserve(mesh.influence_joints.size());
  for (size_t i = 0; i < p; ++i) {
    const uint32_t begin = mesh.influence_offsets[i], end = mesh.influence_offsets[i + 1];
    if (end < begin || end > mesh.influence_joints.size()) {
      return Invalid("SkinMesh: influence_offsets decrease or run past the influences at vertex " +
                     std::to_string(i));
    }
    const size_t first = skin.slots_.size();
    for (uint32_t e = begin; e < end; ++e) {
      const int32_t j = mesh.influence_joints[e];
      const float w = mesh.influence_weights[e];
      if (j < 0 || static_cast<size_t>(j) >= joint_map.size()) {
        return Invalid("SkinMesh: vertex " + std::to_string(i) + " names joint " +
                       std::to_string(j) + ", the level's skeleton has " +
                       std::to_string(joint_map.size()));
      }
      if (!(w >= 0) || !std::isfinite(w))
        return Invalid("SkinMesh: vertex " + std::to_string(i) + " has a negative or non-finite weight");
      // Influences that land on one slot add up (a vertex has a handful: a linear scan).
      const uint16_t s = joint_map[static_cast<size_t>(j)];
      size_t k = first;
      while (k < skin.slots_.size() && skin.slots_[k] != s) ++k;
      if (k == skin.slots_.size()) {
        skin.slots_.push_back(s);
        skin.weights_.push_back(w);
      } else {
        skin.weights_[k] += w;
      }
    }
    if (skin.slots_.size() == first)
      return Invalid("SkinMesh: vertex " + std::to_string(i) + " has no influence");
    skin.offsets_.push_back(static_cast<uint32_t>(skin.slots_.size()));
  }
  return skin;
}

Result<uint32_t> SkinFrameJob::Validate() const {
  if (skin == nullptr) return Invalid("SkinFrameJob: no skin");
  const size_t floats = size_t{skin->vertex_count()} * 3;
  if (matrices.size() != size_t{skin->kept_count()} * proto::kMatrixFloats) {
    return Invalid("SkinFrameJob: " + std::to_string(matrices.size()) + " matrix floats for " +
                   std::to_string(skin->kept_count()) + " kept joints (12 each)");
  }
  if (out_positions.size() != floats)
    return Invalid("SkinFrameJob: out_positions must hold 3 floats per vertex");
  if (!out_normals.empty() && (out_normals.size() != floats || !skin->has_normals()))
    return Invalid("SkinFrameJob: out_normals must be empty, or hold 3 floats per vertex of a "
                   "mesh with normals");
  return skin->vertex_count();
}

Result<uint32_t> SkinFrameJob::Run() const {
  Result<uint32_t> valid = Validate();
  if (!valid.ok()) return valid;
  const uint32_t p = *valid;
  const float* k = matrices.data();
  const float* positions = skin->positions_.data();
  const float* normals = skin->normals_.data();
  const uint32_t* offsets = skin->offsets_.data();
  const uint16_t* slots = skin->slots_.data();
  const float* weights = skin->weights_.data();
  float* out_p = out_positions.data();
  float* out_n = out_normals.empty() ? nullptr : out_normals.data();
  for (uint32_t i = 0; i < p; ++i) {
    // B = sum_s W_is K_s: 12 multiply-adds per influence, then one transform.
    float b[12];
    {
      const float w = weights[offsets[i]];
      const float* m = k + size_t{slots[offsets[i]]} * 12;
      for (int c = 0; c < 12; ++c) b[c] = w * m[c];
    }
    for (uint32_t e = offsets[i] + 1; e < offsets[i + 1]; ++e) {
      const float w = weights[e];
      const float* m = k + size_t{slots[e]} * 12;
      for (int c = 0; c < 12; ++c) b[c] += w * m[c];
    }
    const float* v = positions + size_t{i} * 3;
    float* o = out_p + size_t{i} * 3;
    o[0] = b[0] * v[0] + b[1] * v[1] + b[2] * v[2] + b[3];
    o[1] = b[4] * v[0] + b[5] * v[1] + b[6] * v[2] + b[7];
    o[2] = b[8] * v[0] + b[9] * v[1] + b[10] * v[2] + b[11];
    if (out_n == nullptr) continue;
    const float* n = normals + size_t{i} * 3;
    float x, y, z;
    if (rigid) {
      x = b[0] * n[0] + b[1] * n[1] + b[2] * n[2];
      y = b[4] * n[0] + b[5] * n[1] + b[6] * n[2];
      z = b[8] * n[0] + b[9] * n[1] + b[10] * n[2];
    } else {
      // cof(B) n = n0 (c1 x c2) + n1 (c2 x c0) + n2 (c0 x c1), c the columns of B's 3x3.
      const float c0[3] = {b[0], b[4], b[8]}, c1[3] = {b[1], b[5], b[9]}, c2[3] = {b[2], b[6], b[10]};
      x = n[0] * (c1[1] * c2[2] - c1[2] * c2[1]) + n[1] * (c2[1] * c0[2] - c2[2] * c0[1]) +
          n[2] * (c0[1] * c1[2] - c0[2] * c1[1]);
      y = n[0] * (c1[2] * c2[0] - c1[0] * c2[2]) + n[1] * (c2[2] * c0[0] - c2[0] * c0[2]) +
          n[2] * (c0[2] * c1[0] - c0[0] * c1[2]);
      z = n[0] * (c1[0] * c2[1] - c1[1] * c2[0]) + n[1] * (c2[0] * c0[1] - c2[1] * c0[0]) +
          n[2] * (c0[0] * c1[1] - c0[1] * c1[0]);
    }
    const float length = std::sqrt(x * x + y * y + z * z);
    const float scale = length > 0 ? 1.0f / length : 0.0f;
    float* on = out_n + size_t{i} * 3;
    on[0] = x * scale;
    on[1] = y * scale;
    on[2] = z * scale;
  }
  return p;
}

}  // namespace motionlod::client
