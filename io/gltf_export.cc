#include "io/gltf_export.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <memory>
#include <nlohmann/json.hpp>
#include <numeric>
#include <vector>

#include "core/polar.h"
#include "core/reduce_skeleton.h"
#include "core/types.h"

namespace motionlod::io {
namespace {

using nlohmann::json;

// glTF enums (glTF 2.0 specification, 5.1 accessor.componentType and bufferView.target).
constexpr int kUnsignedShort = 5123;
constexpr int kUnsignedInt = 5125;
constexpr int kFloat = 5126;
constexpr int kArrayBuffer = 34962;
constexpr int kElementArrayBuffer = 34963;
// GLB container (glTF 2.0 specification, 4.4 Binary glTF Layout).
constexpr uint32_t kGlbMagic = 0x46546C67;  // "glTF"
constexpr uint32_t kGlbVersion = 2;
constexpr uint32_t kChunkJson = 0x4E4F534A;    // "JSON"
constexpr uint32_t kChunkBinary = 0x004E4942;  // "BIN\0"

// Per-frame transforms of one joint node, local to its parent node.
struct NodeTrack {
  std::vector<float> translations;  // T x 3
  std::vector<float> rotations;     // T x 4, quaternion x y z w
  std::vector<float> scales;        // T x 3; empty when rigid
};

// The binary chunk and the JSON arrays that describe it.
class GlbBuilder {
 public:
  // Appends `bytes` as a buffer view (4-byte aligned); returns its index.
  int AddView(const void* bytes, size_t size, int target) {
    bin_.resize((bin_.size() + 3) & ~size_t{3}, '\0');
    json view = {{"buffer", 0}, {"byteOffset", bin_.size()}, {"byteLength", size}};
    if (target != 0) view["target"] = target;
    bin_.append(static_cast<const char*>(bytes), size);
    views_.push_back(std::move(view));
    return static_cast<int>(views_.size()) - 1;
  }

  // A float accessor over `values` (count x components, `type` "SCALAR", "VEC3", ...);
  // with_bounds adds the per-component min and max the specification requires for
  // POSITION and animation inputs.
  int AddFloats(const std::vector<float>& values, int components, const char* type, int target,
                bool with_bounds = false) {
    const size_t count = values.size() / components;
    json accessor = {{"bufferView", AddView(values.data(), values.size() * sizeof(float), target)},
                     {"componentType", kFloat},
                     {"count", count},
                     {"type", type}};
    if (with_bounds) {
      std::vector<float> lo(components, std::numeric_limits<float>::infinity());
      std::vector<float> hi(components, -std::numeric_limits<float>::infinity());
      for (size_t e = 0; e < values.size(); ++e) {
        lo[e % components] = std::min(lo[e % components], values[e]);
        hi[e % components] = std::max(hi[e % components], values[e]);
      }
      accessor["min"] = lo;
      accessor["max"] = hi;
    }
    accessors_.push_back(std::move(accessor));
    return static_cast<int>(accessors_.size()) - 1;
  }

  template <typename Integer>
  int AddIntegers(const std::vector<Integer>& values, int component_type, const char* type,
                  size_t count, int target) {
    accessors_.push_back(
        {{"bufferView", AddView(values.data(), values.size() * sizeof(Integer), target)},
         {"componentType", component_type},
         {"count", count},
         {"type", type}});
    return static_cast<int>(accessors_.size()) - 1;
  }

  // Completes `document` with the buffer, views and accessors and writes the GLB file.
  std::string Finish(json document) {
    bin_.resize((bin_.size() + 3) & ~size_t{3}, '\0');
    document["buffers"] = json::array({{{"byteLength", bin_.size()}}});
    document["bufferViews"] = std::move(views_);
    document["accessors"] = std::move(accessors_);
    std::string text = document.dump();
    text.resize((text.size() + 3) & ~size_t{3}, ' ');  // JSON chunks pad with spaces
    const uint32_t total = static_cast<uint32_t>(12 + 8 + text.size() + 8 + bin_.size());
    std::string glb;
    glb.reserve(total);
    const auto put = [&glb](uint32_t word) {
      char bytes[4];
      std::memcpy(bytes, &word, 4);  // GLB is little-endian, as every supported host
      glb.append(bytes, 4);
    };
    put(kGlbMagic);
    put(kGlbVersion);
    put(total);
    put(static_cast<uint32_t>(text.size()));
    put(kChunkJson);
    glb += text;
    put(static_cast<uint32_t>(bin_.size()));
    put(kChunkBinary);
    glb += bin_;
    return glb;
  }

 private:
  std::string bin_;
  json views_ = json::array();
  json accessors_ = json::array();
};

json Floats(const Eigen::Vector3d& v) { return {v.x(), v.y(), v.z()}; }
json Floats(const Eigen::Quaterniond& q) { return {q.x(), q.y(), q.z(), q.w()}; }

core::Affine34d RigidAffine(const Eigen::Matrix3d& rotation, const Eigen::Vector3d& translation) {
  core::Affine34d m;
  m.leftCols<3>() = rotation;
  m.col(3) = translation;
  return m;
}

Status CheckLevel(const core::Character& character, const GltfLevel& level) {
  const auto& names = character.skeleton().joint_names;
  const size_t n = names.size();
  if (level.joint_names.size() != n || level.joint_map.size() != n) {
    return InvalidArgument("the level is for a skeleton of " +
                           std::to_string(level.joint_names.size()) +
                           " joints, the character has " + std::to_string(n) +
                           ": the level was baked for another character");
  }
  for (size_t j = 0; j < n; ++j) {
    if (level.joint_names[j] != names[j]) {
      return InvalidArgument("the level's joint " + std::to_string(j) + " is '" +
                             std::string(level.joint_names[j]) + "', the character's is '" +
                             names[j] + "': the level was baked for another character");
    }
  }
  if (level.kept_joints.empty() || level.kept_joints[0] != 0) {
    return InvalidArgument("a level keeps the root joint first");
  }
  for (size_t s = 0; s < level.kept_joints.size(); ++s) {
    if (level.kept_joints[s] >= n || (s > 0 && level.kept_joints[s] <= level.kept_joints[s - 1])) {
      return InvalidArgument("the kept joints must be ascending joint indices below " +
                             std::to_string(n));
    }
  }
  if (level.frame_count < 1 || level.frame_count > 1000000) {
    return InvalidArgument("a level has 1 to 1e6 frames, got " + std::to_string(level.frame_count));
  }
  if (!(level.fps > 0) || !std::isfinite(level.fps)) {
    return InvalidArgument("the level's fps must be positive and finite");
  }
  const size_t m = level.kept_joints.size();
  if (level.matrices.size() != size_t{level.frame_count} * m * 12) {
    return InvalidArgument("the level has " + std::to_string(level.matrices.size()) +
                           " matrix floats, expected frames x kept joints x 12 = " +
                           std::to_string(size_t{level.frame_count} * m * 12));
  }
  for (float value : level.matrices) {
    if (!std::isfinite(value)) return InvalidArgument("the level has a non-finite matrix");
  }
  const size_t p = character.skin().positions.size();
  if (level.vertices.empty() != level.triangles.empty()) {
    return InvalidArgument("a level's own mesh has both vertices and triangles");
  }
  for (size_t v = 0; v < level.vertices.size(); ++v) {
    if (level.vertices[v] >= p || (v > 0 && level.vertices[v] <= level.vertices[v - 1])) {
      return InvalidArgument("the level's vertices must be ascending vertex ids below " +
                             std::to_string(p));
    }
  }
  const size_t count = level.vertices.empty() ? p : level.vertices.size();
  if (level.triangles.size() % 3 != 0 ||
      std::any_of(level.triangles.begin(), level.triangles.end(),
                  [&](uint32_t index) { return index >= count; })) {
    return InvalidArgument("the level's triangles must be triples of indices below its " +
                           std::to_string(count) + " vertices");
  }
  const size_t k = level.influences_per_vertex;
  if (level.influence_slots.size() != count * k || level.influence_weights.size() != count * k) {
    return InvalidArgument("the level's influences must be " + std::to_string(k) +
                           " slots and weights per vertex");
  }
  for (size_t e = 0; e < level.influence_slots.size(); ++e) {
    if (level.influence_slots[e] >= m || !(level.influence_weights[e] >= 0) ||
        !std::isfinite(level.influence_weights[e])) {
      return InvalidArgument("the level's influence " + std::to_string(e) +
                             " has a slot out of range or a bad weight");
    }
  }
  return Status::Ok();
}

// The level's vertices' influences on its slots, in compressed rows: its own, or the
// character's merged through the reduced skeleton. kInvalidArgument for a vertex left
// with no weight.
StatusOr<core::ReducedInfluences> LevelInfluences(const core::RawSkin& skin,
                                                  const core::ReducedSkeleton& reduced,
                                                  const GltfLevel& level,
                                                  std::span<const uint32_t> vertex_ids) {
  core::ReducedInfluences out;
  out.offsets.push_back(0);
  const core::ReducedInfluences merged =
      level.influences_per_vertex == 0 ? core::ReduceInfluences(skin, reduced)
                                       : core::ReducedInfluences{};
  for (size_t v = 0; v < vertex_ids.size(); ++v) {
    if (level.influences_per_vertex > 0) {
      for (size_t e = v * level.influences_per_vertex; e < (v + 1) * level.influences_per_vertex;
           ++e) {
        if (level.influence_weights[e] == 0) continue;
        out.slots.push_back(level.influence_slots[e]);
        out.weights.push_back(level.influence_weights[e]);
      }
    } else {
      const uint32_t i = vertex_ids[v];
      out.slots.insert(out.slots.end(), merged.slots.begin() + merged.offsets[i],
                       merged.slots.begin() + merged.offsets[i + 1]);
      out.weights.insert(out.weights.end(), merged.weights.begin() + merged.offsets[i],
                         merged.weights.begin() + merged.offsets[i + 1]);
    }
    if (out.slots.size() == out.offsets.back()) {
      return InvalidArgument("the level's vertex " + std::to_string(v) + " has no weight");
    }
    out.offsets.push_back(static_cast<uint32_t>(out.slots.size()));
  }
  return out;
}

// K'_s(t) of the level as a double 3x4 matrix.
core::Affine34d LevelMatrix(const GltfLevel& level, size_t m, uint32_t t, size_t s) {
  const float* f = level.matrices.data() + (size_t{t} * m + s) * 12;
  core::Affine34d k;
  for (int row = 0; row < 3; ++row) {
    for (int col = 0; col < 4; ++col) k(row, col) = f[row * 4 + col];
  }
  return k;
}

// The largest kGltfMaxInfluences reduced influences of each vertex, renormalised:
// p x 4 slots and weights (unused entries: slot 0, weight 0).
struct VertexInfluences {
  std::vector<uint16_t> slots;
  std::vector<float> weights;
};

VertexInfluences TopInfluences(const core::ReducedInfluences& reduced, GltfExportStats& stats) {
  constexpr int kK = kGltfMaxInfluences;
  const size_t p = reduced.offsets.size() - 1;
  VertexInfluences out;
  out.slots.assign(p * kK, 0);
  out.weights.assign(p * kK, 0.0f);
  std::vector<uint32_t> order;
  for (size_t i = 0; i < p; ++i) {
    order.clear();
    for (uint32_t e = reduced.offsets[i]; e < reduced.offsets[i + 1]; ++e) order.push_back(e);
    std::sort(order.begin(), order.end(),
              [&](uint32_t a, uint32_t b) { return reduced.weights[a] > reduced.weights[b]; });
    const size_t kept = std::min<size_t>(order.size(), kK);
    double total = 0, kept_total = 0;
    for (size_t q = 0; q < order.size(); ++q) {
      total += reduced.weights[order[q]];
      if (q < kept) kept_total += reduced.weights[order[q]];
    }
    if (order.size() > kept) {
      ++stats.truncated_vertices;
      stats.max_dropped_weight = std::max(stats.max_dropped_weight, 1.0 - kept_total / total);
    }
    for (size_t q = 0; q < kept; ++q) {
      out.slots[i * kK + q] = static_cast<uint16_t>(reduced.slots[order[q]]);
      out.weights[i * kK + q] = static_cast<float>(reduced.weights[order[q]] / kept_total);
    }
  }
  return out;
}

}  // namespace

StatusOr<GltfExport> ExportLevelGlb(const core::Character& character, const GltfLevel& level) {
  if (Status status = CheckLevel(character, level); !status.ok()) return status;
  const core::RawSkeleton& skeleton = character.skeleton();
  const core::RawSkin& skin = character.skin();
  const size_t n = skeleton.parents.size();
  const size_t m = level.kept_joints.size();
  const uint32_t frames = level.frame_count;
  // The character's vertex of each of the level's.
  std::vector<uint32_t> vertex_ids(level.vertices.begin(), level.vertices.end());
  if (vertex_ids.empty()) {
    vertex_ids.resize(skin.positions.size());
    std::iota(vertex_ids.begin(), vertex_ids.end(), 0u);
  }
  const size_t p = vertex_ids.size();

  std::unique_ptr<bool[]> keep(new bool[n]());
  for (uint16_t j : level.kept_joints) keep[j] = true;
  auto reduced = core::ReduceSkeleton(character, std::span<const bool>(keep.get(), n));
  if (!reduced.ok()) return reduced.status();
  for (size_t j = 0; j < n; ++j) {
    if (reduced->joint_to_slot[j] != level.joint_map[j]) {
      return InvalidArgument("the level's joint map sends joint '" + skeleton.joint_names[j] +
                             "' to slot " + std::to_string(level.joint_map[j]) +
                             ", its nearest kept ancestor is slot " +
                             std::to_string(reduced->joint_to_slot[j]));
    }
  }

  GltfExport result;
  GltfExportStats& stats = result.stats;
  stats.joints = static_cast<int>(m);
  stats.vertices = static_cast<int>(p);
  stats.frames = static_cast<int>(frames);

  // B_s: the rigid rest pose of each joint node; the bind pose of the skin is then
  // K'_s = world_s B_s^-1 = identity.
  std::vector<core::Affine34d> rest_world(m), inverse_rest(m);
  for (size_t s = 0; s < m; ++s) {
    const core::Affine34d& bind = skeleton.bind_world[level.kept_joints[s]];
    rest_world[s] = RigidAffine(core::NearestRotation(bind.leftCols<3>()), bind.col(3));
    inverse_rest[s] = core::InverseAffine(rest_world[s]);
  }

  // Animation tracks, top-down (a parent's slot is below its children's) so each local
  // transform is taken against the parent's realised world matrix. joint_matrices holds
  // what a loader skins with, world_s(t) B_s^-1, for the deviation figure.
  std::vector<NodeTrack> tracks(m);
  for (NodeTrack& track : tracks) {
    track.translations.reserve(size_t{frames} * 3);
    track.rotations.reserve(size_t{frames} * 4);
    if (!level.rigid) track.scales.reserve(size_t{frames} * 3);
  }
  std::vector<core::Affine34d> joint_matrices(size_t{frames} * m),
      level_matrices(size_t{frames} * m);
  std::vector<core::Affine34d> realised_world(m);
  std::vector<Eigen::Quaterniond> previous(m);
  for (uint32_t t = 0; t < frames; ++t) {
    for (size_t s = 0; s < m; ++s) {
      const core::Affine34d k = LevelMatrix(level, m, t, s);
      if (std::abs(k.leftCols<3>().determinant()) < 1e-12) {
        return InvalidArgument("the level's matrix of joint '" +
                               skeleton.joint_names[level.kept_joints[s]] + "' at frame " +
                               std::to_string(t) + " is singular");
      }
      level_matrices[size_t{t} * m + s] = k;
      const int parent = reduced->parent_slots[s];
      const core::Affine34d wanted_world = core::ComposeAffine(k, rest_world[s]);
      const core::Affine34d local =
          parent < 0
              ? wanted_world
              : core::ComposeAffine(core::InverseAffine(realised_world[parent]), wanted_world);
      const Eigen::Matrix3d rotation = core::NearestRotation(local.leftCols<3>());
      Eigen::Vector3d scale = Eigen::Vector3d::Ones();
      if (!level.rigid) scale = (rotation.transpose() * local.leftCols<3>()).diagonal();
      Eigen::Quaterniond q(rotation);
      q.normalize();
      // Keep consecutive keys in one hemisphere so that interpolation takes the short way.
      if (t > 0 && q.dot(previous[s]) < 0) q.coeffs() = -q.coeffs();
      previous[s] = q;
      const Eigen::Vector3d translation = local.col(3);
      NodeTrack& track = tracks[s];
      track.translations.insert(
          track.translations.end(),
          {float(translation.x()), float(translation.y()), float(translation.z())});
      track.rotations.insert(track.rotations.end(),
                             {float(q.x()), float(q.y()), float(q.z()), float(q.w())});
      if (!level.rigid) {
        track.scales.insert(track.scales.end(),
                            {float(scale.x()), float(scale.y()), float(scale.z())});
      }
      const core::Affine34d realised_local =
          RigidAffine(rotation * scale.asDiagonal(), translation);
      realised_world[s] =
          parent < 0 ? realised_local : core::ComposeAffine(realised_world[parent], realised_local);
      joint_matrices[size_t{t} * m + s] = core::ComposeAffine(realised_world[s], inverse_rest[s]);
    }
  }

  auto level_influences = LevelInfluences(skin, *reduced, level, vertex_ids);
  if (!level_influences.ok()) return level_influences.status();
  const core::ReducedInfluences& influences = *level_influences;
  const VertexInfluences top = TopInfluences(influences, stats);

  double max_deviation = 0;
  for (uint32_t t = 0; t < frames; ++t) {
    const core::Affine34d* exported = joint_matrices.data() + size_t{t} * m;
    const core::Affine34d* solved = level_matrices.data() + size_t{t} * m;
    for (size_t i = 0; i < p; ++i) {
      const Eigen::Vector3d v0 = skin.positions[vertex_ids[i]].cast<double>();
      Eigen::Vector3d v_exported = Eigen::Vector3d::Zero(), v_level = Eigen::Vector3d::Zero();
      for (int q = 0; q < kGltfMaxInfluences; ++q) {
        const float w = top.weights[i * kGltfMaxInfluences + q];
        if (w > 0)
          v_exported +=
              w * core::TransformPoint(exported[top.slots[i * kGltfMaxInfluences + q]], v0);
      }
      for (uint32_t e = influences.offsets[i]; e < influences.offsets[i + 1]; ++e) {
        v_level += influences.weights[e] * core::TransformPoint(solved[influences.slots[e]], v0);
      }
      max_deviation = std::max(max_deviation, (v_exported - v_level).norm());
    }
  }
  stats.max_vertex_deviation_pct = 100.0 * max_deviation / character.height();

  GlbBuilder glb;
  json document;
  document["asset"] = {{"version", "2.0"}, {"generator", "motionlod"}};

  // Mesh.
  std::vector<float> positions(p * 3), normals(p * 3);
  for (size_t i = 0; i < p; ++i) {
    Eigen::Vector3f normal = skin.normals[vertex_ids[i]];
    // The specification wants unit normals; a degenerate one gets an arbitrary unit axis.
    normal = normal.norm() > 1e-12f ? normal.normalized() : Eigen::Vector3f::UnitZ();
    for (int c = 0; c < 3; ++c) {
      positions[i * 3 + c] = skin.positions[vertex_ids[i]][c];
      normals[i * 3 + c] = normal[c];
    }
  }
  std::vector<uint32_t> indices(level.triangles.begin(), level.triangles.end());
  if (level.vertices.empty()) {
    indices.reserve(skin.triangles.size() * 3);
    for (const auto& triangle : skin.triangles)
      indices.insert(indices.end(), triangle.begin(), triangle.end());
  }
  json attributes = {
      {"POSITION", glb.AddFloats(positions, 3, "VEC3", kArrayBuffer, true)},
      {"NORMAL", glb.AddFloats(normals, 3, "VEC3", kArrayBuffer)},
      {"JOINTS_0", glb.AddIntegers(top.slots, kUnsignedShort, "VEC4", p, kArrayBuffer)},
      {"WEIGHTS_0", glb.AddFloats(top.weights, 4, "VEC4", kArrayBuffer)},
  };
  json primitive = {{"attributes", std::move(attributes)}, {"material", 0}, {"mode", 4}};
  if (!indices.empty()) {
    primitive["indices"] =
        glb.AddIntegers(indices, kUnsignedInt, "SCALAR", indices.size(), kElementArrayBuffer);
  }
  document["materials"] = json::array({{{"name", "default"},
                                        {"pbrMetallicRoughness",
                                         {{"baseColorFactor", {0.8, 0.8, 0.8, 1.0}},
                                          {"metallicFactor", 0.0},
                                          {"roughnessFactor", 0.8}}},
                                        {"doubleSided", true}}});
  document["meshes"] = json::array({{{"name", character.name().empty() ? "skin" : character.name()},
                                     {"primitives", json::array({std::move(primitive)})}}});

  // Joint nodes 0..m-1 (slot order) and the mesh node m.
  json nodes = json::array();
  std::vector<json> children(m, json::array());
  for (size_t s = 1; s < m; ++s) children[reduced->parent_slots[s]].push_back(s);
  for (size_t s = 0; s < m; ++s) {
    const int parent = reduced->parent_slots[s];
    const core::Affine34d local =
        parent < 0 ? rest_world[s] : core::ComposeAffine(inverse_rest[parent], rest_world[s]);
    Eigen::Quaterniond rotation(Eigen::Matrix3d(local.leftCols<3>()));
    rotation.normalize();
    json node = {{"name", skeleton.joint_names[level.kept_joints[s]]},
                 {"translation", Floats(Eigen::Vector3d(local.col(3)))},
                 {"rotation", Floats(rotation)}};
    if (!children[s].empty()) node["children"] = std::move(children[s]);
    nodes.push_back(std::move(node));
  }
  nodes.push_back({{"name", "skin"}, {"mesh", 0}, {"skin", 0}});
  document["nodes"] = std::move(nodes);
  document["scene"] = 0;
  document["scenes"] = json::array({{{"nodes", {0, m}}}});

  std::vector<float> inverse_binds;
  inverse_binds.reserve(m * 16);
  for (size_t s = 0; s < m; ++s) {
    // MAT4, column-major, last row (0 0 0 1).
    for (int col = 0; col < 4; ++col) {
      for (int row = 0; row < 3; ++row) inverse_binds.push_back(float(inverse_rest[s](row, col)));
      inverse_binds.push_back(col == 3 ? 1.0f : 0.0f);
    }
  }
  json joints = json::array();
  for (size_t s = 0; s < m; ++s) joints.push_back(s);
  document["skins"] =
      json::array({{{"inverseBindMatrices", glb.AddFloats(inverse_binds, 16, "MAT4", 0)},
                    {"skeleton", 0},
                    {"joints", std::move(joints)}}});

  // Animation: one shared time accessor, one sampler per animated property.
  std::vector<float> times(frames);
  for (uint32_t t = 0; t < frames; ++t) times[t] = static_cast<float>(t / level.fps);
  const int input = glb.AddFloats(times, 1, "SCALAR", 0, true);
  json samplers = json::array(), channels = json::array();
  const auto add_channel = [&](size_t node, const char* path, int output) {
    samplers.push_back({{"input", input}, {"output", output}, {"interpolation", "LINEAR"}});
    channels.push_back(
        {{"sampler", samplers.size() - 1}, {"target", {{"node", node}, {"path", path}}}});
  };
  for (size_t s = 0; s < m; ++s) {
    add_channel(s, "translation", glb.AddFloats(tracks[s].translations, 3, "VEC3", 0));
    add_channel(s, "rotation", glb.AddFloats(tracks[s].rotations, 4, "VEC4", 0));
    if (!level.rigid) add_channel(s, "scale", glb.AddFloats(tracks[s].scales, 3, "VEC3", 0));
  }
  json animation = {{"samplers", std::move(samplers)}, {"channels", std::move(channels)}};
  if (!level.animation_name.empty()) animation["name"] = level.animation_name;
  document["animations"] = json::array({std::move(animation)});

  result.glb = glb.Finish(std::move(document));
  return result;
}

}  // namespace motionlod::io
