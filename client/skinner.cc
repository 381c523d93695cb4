#include "client/skinner.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <string>

namespace motionlod::client {
namespace {

Error Invalid(std::string message) {
  return Error{ErrorKind::kInvalidArgument, 0, std::nullopt, std::move(message)};
}

// Unit quaternion (w, x, y, z) of a rotation given as a row-major 3x4 (its 3x3 part), by
// the largest of the four diagonal combinations (Shepperd), which stays accurate at every
// angle.
std::array<float, 4> QuaternionOf(const float* k) {
  const float m00 = k[0], m01 = k[1], m02 = k[2], m10 = k[4], m11 = k[5], m12 = k[6], m20 = k[8],
              m21 = k[9], m22 = k[10];
  const float trace = m00 + m11 + m22;
  std::array<float, 4> q{};
  if (trace > 0) {
    const float r = std::sqrt(1 + trace), h = 0.5f / r;
    q = {0.5f * r, (m21 - m12) * h, (m02 - m20) * h, (m10 - m01) * h};
  } else if (m00 >= m11 && m00 >= m22) {
    const float r = std::sqrt(std::max(1 + m00 - m11 - m22, 0.0f)), h = r > 0 ? 0.5f / r : 0.0f;
    q = {(m21 - m12) * h, 0.5f * r, (m01 + m10) * h, (m02 + m20) * h};
  } else if (m11 >= m22) {
    const float r = std::sqrt(std::max(1 + m11 - m00 - m22, 0.0f)), h = r > 0 ? 0.5f / r : 0.0f;
    q = {(m02 - m20) * h, (m01 + m10) * h, 0.5f * r, (m12 + m21) * h};
  } else {
    const float r = std::sqrt(std::max(1 + m22 - m00 - m11, 0.0f)), h = r > 0 ? 0.5f / r : 0.0f;
    q = {(m10 - m01) * h, (m02 + m20) * h, (m12 + m21) * h, 0.5f * r};
  }
  const float norm = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
  for (float& c : q) c /= norm;
  return q;
}

// a at fraction 0, b at 1, into out (row-major 3x4 each): rigid, the rotations by slerp
// (the shorter arc) and the translations by lerp; otherwise every entry by lerp.
void BlendMatrix(const float* a, const float* b, float fraction, bool rigid, float* out) {
  for (int c = 0; c < 12; ++c) out[c] = (1 - fraction) * a[c] + fraction * b[c];
  if (!rigid) return;
  const std::array<float, 4> qa = QuaternionOf(a);
  std::array<float, 4> qb = QuaternionOf(b);
  float dot = qa[0] * qb[0] + qa[1] * qb[1] + qa[2] * qb[2] + qa[3] * qb[3];
  if (dot < 0) {
    for (float& c : qb) c = -c;
    dot = -dot;
  }
  float wa = 1 - fraction, wb = fraction;
  if (dot < 0.9995f) {  // nearly equal rotations: the lerp, normalised below, is exact enough
    const float angle = std::acos(std::min(dot, 1.0f)), sine = std::sin(angle);
    wa = std::sin((1 - fraction) * angle) / sine;
    wb = std::sin(fraction * angle) / sine;
  }
  float w = wa * qa[0] + wb * qb[0], x = wa * qa[1] + wb * qb[1], y = wa * qa[2] + wb * qb[2],
        z = wa * qa[3] + wb * qb[3];
  const float norm = std::sqrt(w * w + x * x + y * y + z * z);
  w /= norm;
  x /= norm;
  y /= norm;
  z /= norm;
  out[0] = 1 - 2 * (y * y + z * z);
  out[1] = 2 * (x * y - w * z);
  out[2] = 2 * (x * z + w * y);
  out[4] = 2 * (x * y + w * z);
  out[5] = 1 - 2 * (x * x + z * z);
  out[6] = 2 * (y * z - w * x);
  out[8] = 2 * (x * z - w * y);
  out[9] = 2 * (y * z + w * x);
  out[10] = 1 - 2 * (x * x + y * y);
}

}  // namespace

Result<LevelSkin> LevelSkin::Build(const SkinMesh& mesh, std::span<const uint16_t> joint_map,
                                   uint32_t kept_count) {
  return BuildSkin(mesh, {}, {}, joint_map, kept_count, 0, {}, {});
}

Result<LevelSkin> LevelSkin::Build(const SkinMesh& mesh, const proto::LevelView& level) {
  return BuildSkin(mesh, level.vertices(), level.triangles(), level.joint_map(), level.kept_count(),
                   level.influences_per_vertex(), level.influence_slots(),
                   level.influence_weights());
}

Result<LevelSkin> LevelSkin::BuildSkin(const SkinMesh& mesh, std::span<const uint32_t> vertex_ids,
                                       std::span<const uint32_t> triangles,
                                       std::span<const uint16_t> joint_map, uint32_t kept_count,
                                       uint32_t per_vertex, std::span<const uint16_t> slots,
                                       std::span<const float> weights) {
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
  for (uint32_t id : vertex_ids) {
    if (id >= p) {
      return Invalid("LevelSkin: the level draws vertex " + std::to_string(id) + ", the mesh has " +
                     std::to_string(p) + " (the level set of another mesh?)");
    }
  }
  const size_t count = vertex_ids.empty() ? p : vertex_ids.size();
  if (per_vertex > 0 && (slots.size() != count * per_vertex || weights.size() != slots.size()))
    return Invalid("LevelSkin: the level's influences are not " + std::to_string(per_vertex) +
                   " per vertex");
  LevelSkin skin;
  skin.kept_count_ = kept_count;
  skin.vertex_ids_.assign(vertex_ids.begin(), vertex_ids.end());
  skin.triangles_.assign(triangles.begin(), triangles.end());
  skin.positions_.reserve(3 * count);
  if (!mesh.normals.empty()) skin.normals_.reserve(3 * count);
  skin.offsets_.reserve(count + 1);
  skin.offsets_.push_back(0);
  for (size_t v = 0; v < count; ++v) {
    const size_t i = vertex_ids.empty() ? v : vertex_ids[v];
    skin.positions_.insert(skin.positions_.end(), mesh.positions.begin() + 3 * i,
                           mesh.positions.begin() + 3 * i + 3);
    if (!mesh.normals.empty()) {
      skin.normals_.insert(skin.normals_.end(), mesh.normals.begin() + 3 * i,
                           mesh.normals.begin() + 3 * i + 3);
    }
    const size_t first = skin.slots_.size();
    if (per_vertex > 0) {  // the level's own influences, zero weights dropped
      for (uint32_t e = 0; e < per_vertex; ++e) {
        const uint16_t s = slots[v * per_vertex + e];
        const float w = weights[v * per_vertex + e];
        if (s >= kept_count || !(w >= 0) || !std::isfinite(w))
          return Invalid("LevelSkin: influence " + std::to_string(e) + " of level vertex " +
                         std::to_string(v) + " has a slot out of range or a bad weight");
        if (w == 0) continue;
        skin.slots_.push_back(s);
        skin.weights_.push_back(w);
      }
    } else {
      const uint32_t begin = mesh.influence_offsets[i], end = mesh.influence_offsets[i + 1];
      if (end < begin || end > mesh.influence_joints.size()) {
        return Invalid(
            "SkinMesh: influence_offsets decrease or run past the influences at vertex " +
            std::to_string(i));
      }
      for (uint32_t e = begin; e < end; ++e) {
        const int32_t j = mesh.influence_joints[e];
        const float w = mesh.influence_weights[e];
        if (j < 0 || static_cast<size_t>(j) >= joint_map.size()) {
          return Invalid("SkinMesh: vertex " + std::to_string(i) + " names joint " +
                         std::to_string(j) + ", the level's skeleton has " +
                         std::to_string(joint_map.size()));
        }
        if (!(w >= 0) || !std::isfinite(w))
          return Invalid("SkinMesh: vertex " + std::to_string(i) +
                         " has a negative or non-finite weight");
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
    }
    if (skin.slots_.size() == first)
      return Invalid("SkinMesh: vertex " + std::to_string(i) + " has no influence");
    skin.offsets_.push_back(static_cast<uint32_t>(skin.slots_.size()));
  }
  skin.one_slot_each_ =
      skin.slots_.size() == count &&
      std::all_of(skin.weights_.begin(), skin.weights_.end(), [](float w) { return w == 1.0f; });
  return skin;
}

Result<uint32_t> PlayFrame(const proto::LevelSetView& set, const proto::LevelView& level,
                           uint32_t clip, uint32_t t, std::span<float> out) {
  const uint32_t m = level.kept_count();
  if (out.size() != size_t{m} * proto::kMatrixFloats)
    return Invalid("PlayFrame: out must hold 12 floats per kept joint (" + std::to_string(m) + ")");
  if (clip >= set.clip_count() || t >= set.clip(clip).frame_count)
    return Invalid("PlayFrame: no frame " + std::to_string(t) + " of clip " + std::to_string(clip));
  const proto::FrameBlend blend = level.Blend(clip, t, set.clip(clip).frame_count);
  const std::span<const float> from = level.frame(blend.from);
  if (blend.fraction == 0) {
    std::copy(from.begin(), from.end(), out.begin());
    return m;
  }
  const std::span<const float> to = level.frame(blend.to);
  for (uint32_t s = 0; s < m; ++s) {
    BlendMatrix(from.data() + s * 12, to.data() + s * 12, blend.fraction, set.rigid(),
                out.data() + s * 12);
  }
  return m;
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
    return Invalid(
        "SkinFrameJob: out_normals must be empty, or hold 3 floats per vertex of a "
        "mesh with normals");
  return skin->vertex_count();
}

namespace {

// Poses vertex `v` (normal `n`, or null) by B = `b` (12 floats, row-major 3x4) into `o`
// and `on`. Rigid: the normal by B's 3x3, else by cof(B); renormalised unless `unit` says
// B's 3x3 is a rotation (it keeps unit normals unit).
inline void PoseVertex(const float* b, const float* v, const float* n, bool rigid, bool unit,
                       float* o, float* on) {
  o[0] = b[0] * v[0] + b[1] * v[1] + b[2] * v[2] + b[3];
  o[1] = b[4] * v[0] + b[5] * v[1] + b[6] * v[2] + b[7];
  o[2] = b[8] * v[0] + b[9] * v[1] + b[10] * v[2] + b[11];
  if (n == nullptr) return;
  float x, y, z;
  if (rigid) {
    x = b[0] * n[0] + b[1] * n[1] + b[2] * n[2];
    y = b[4] * n[0] + b[5] * n[1] + b[6] * n[2];
    z = b[8] * n[0] + b[9] * n[1] + b[10] * n[2];
  } else {
    // cof(B) n = n0 (c1 x c2) + n1 (c2 x c0) + n2 (c0 x c1), c the columns of B's 3x3.
    const float c0[3] = {b[0], b[4], b[8]}, c1[3] = {b[1], b[5], b[9]},
                c2[3] = {b[2], b[6], b[10]};
    x = n[0] * (c1[1] * c2[2] - c1[2] * c2[1]) + n[1] * (c2[1] * c0[2] - c2[2] * c0[1]) +
        n[2] * (c0[1] * c1[2] - c0[2] * c1[1]);
    y = n[0] * (c1[2] * c2[0] - c1[0] * c2[2]) + n[1] * (c2[2] * c0[0] - c2[0] * c0[2]) +
        n[2] * (c0[2] * c1[0] - c0[0] * c1[2]);
    z = n[0] * (c1[0] * c2[1] - c1[1] * c2[0]) + n[1] * (c2[0] * c0[1] - c2[1] * c0[0]) +
        n[2] * (c0[0] * c1[1] - c0[1] * c1[0]);
  }
  if (unit) {
    on[0] = x;
    on[1] = y;
    on[2] = z;
    return;
  }
  const float length = std::sqrt(x * x + y * y + z * z);
  const float scale = length > 0 ? 1.0f / length : 0.0f;
  on[0] = x * scale;
  on[1] = y * scale;
  on[2] = z * scale;
}

}  // namespace

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
  if (skin->one_slot_each_) {
    // One slot of weight 1 per vertex: B is the slot's matrix, no blend.
    for (uint32_t i = 0; i < p; ++i) {
      PoseVertex(k + size_t{slots[i]} * 12, positions + size_t{i} * 3,
                 out_n == nullptr ? nullptr : normals + size_t{i} * 3, rigid, rigid,
                 out_p + size_t{i} * 3, out_n == nullptr ? nullptr : out_n + size_t{i} * 3);
    }
    return p;
  }
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
    PoseVertex(b, positions + size_t{i} * 3, out_n == nullptr ? nullptr : normals + size_t{i} * 3,
               rigid, false, out_p + size_t{i} * 3,
               out_n == nullptr ? nullptr : out_n + size_t{i} * 3);
  }
  return p;
}

}  // namespace motionlod::client
