// CPU skinning with a decoded level (docs/level-format.md, "Skinning with a level").
//
// Letters: i vertex (p of them), j joint of the original skeleton (n), s slot of a kept
// joint of the level (m), t frame. Positions and normals are xyz float triples,
// interleaved (3p floats), in the character's bind-pose model space.
//
// The level file carries the skeleton and the per-frame matrices, and since format 3.0 a
// level's own mesh (a subset of the character's vertices with its own triangles), its own
// influences (k per vertex) and its pose rate; not the vertex data: the client draws its
// own copy of the character, whose vertices are in the order the bake read them and whose
// influences name the original joints in the order of the level set's joint_names (the
// order of the daemon's CharacterInfo::joint_names). LevelSkin takes a level's vertices
// from that mesh once per level, with the level's own influences, or else the mesh's
// merged through the level's joint map (influences on one slot summed); PlayFrame writes
// the frame's m matrices, interpolated between stored poses where the level stores fewer;
// SkinFrameJob then poses the level's vertices into caller-owned buffers, allocating
// nothing:
//   p'_i = sum_s W_is (A_s p_i + b_s)
//   n'_i = normalize(B_i n_i),  B_i = sum_s W_is A_s (rigid levels), cof(B_i) otherwise
// (cof(B) = det(B) B^-T transforms normals correctly under scale and shear).
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "client/error.h"
#include "proto/level_format.h"

namespace motionlod::client {

// The caller's mesh: views, which must outlive the LevelSkin built from them.
struct SkinMesh {
  std::span<const float> positions;  // 3p, bind pose
  std::span<const float> normals;    // 3p, unit length; empty when normals are not skinned
  // Influences in compressed rows: vertex i's are entries
  // [influence_offsets[i], influence_offsets[i+1]) of the two arrays below.
  std::span<const uint32_t> influence_offsets;  // p + 1, first 0
  std::span<const int32_t> influence_joints;    // original joint index j in [0, n)
  std::span<const float> influence_weights;     // >= 0, summing to 1 per vertex
};

// What one level draws of a mesh: its vertices (copied, packed) and their influences on
// the level's slots. Immutable once built; shared by every character that draws this mesh
// at this level, from any thread.
class LevelSkin {
 public:
  // Every vertex of `mesh`, its influences merged through `joint_map` (the level's: n
  // entries, slots < kept_count). kInvalidArgument naming the vertex or entry when the
  // mesh's shapes disagree, a joint is out of range or a weight is negative or not finite.
  static Result<LevelSkin> Build(const SkinMesh& mesh, std::span<const uint16_t> joint_map,
                                 uint32_t kept_count);
  // What `level` draws of `mesh`: its own vertices and triangles or the whole mesh, its own
  // influences or the mesh's merged through its joint map. kInvalidArgument also when the
  // level names vertices the mesh does not have (another character's level set).
  static Result<LevelSkin> Build(const SkinMesh& mesh, const proto::LevelView& level);

  uint32_t vertex_count() const { return static_cast<uint32_t>(offsets_.size() - 1); }
  uint32_t kept_count() const { return kept_count_; }
  bool has_normals() const { return !normals_.empty(); }
  // The mesh's vertex id of each of the level's vertices (empty: every vertex, in order).
  std::span<const uint32_t> vertex_ids() const { return vertex_ids_; }
  // The level's own triangles, 3 indices into its vertices each (empty: the mesh's own).
  std::span<const uint32_t> triangles() const { return triangles_; }
  // Merged influences per vertex, on average (the per-vertex cost of a frame).
  double mean_influences() const {
    return static_cast<double>(slots_.size()) / static_cast<double>(vertex_count());
  }

 private:
  friend struct SkinFrameJob;
  LevelSkin() = default;
  static Result<LevelSkin> BuildSkin(const SkinMesh& mesh, std::span<const uint32_t> vertex_ids,
                                     std::span<const uint32_t> triangles,
                                     std::span<const uint16_t> joint_map, uint32_t kept_count,
                                     uint32_t per_vertex, std::span<const uint16_t> slots,
                                     std::span<const float> weights);
  std::vector<float> positions_;  // 3 per level vertex
  std::vector<float> normals_;    // 3 per level vertex, or empty
  std::vector<uint32_t> vertex_ids_;
  std::vector<uint32_t> triangles_;
  uint32_t kept_count_ = 0;
  // Every vertex on one slot with weight 1 (one influence per vertex): SkinFrameJob skips
  // the blend, and rigid levels the normals' renormalisation.
  bool one_slot_each_ = false;
  std::vector<uint32_t> offsets_;  // p + 1
  std::vector<uint16_t> slots_;    // s of each merged influence
  std::vector<float> weights_;     // W_is
};

// The m x 12 matrices of frame t of clip c of `level` (a level set's, `rigid` as the set's
// flag) into `out`: the stored frame itself, or the blend of the two stored frames around
// it (rigid: slerp of the rotation and lerp of the translation; otherwise lerp).
// kInvalidArgument when `out` does not hold m x 12 floats or c, t are out of range.
Result<uint32_t> PlayFrame(const proto::LevelSetView& set, const proto::LevelView& level,
                           uint32_t clip, uint32_t t, std::span<float> out);

// One frame of one character.
struct SkinFrameJob {
  const LevelSkin* skin = nullptr;
  std::span<const float> matrices;  // m x 12: the level's frame (PlayFrame)
  bool rigid = false;               // LevelSetView::rigid(): normals by B instead of cof(B)
  std::span<float> out_positions;   // 3p
  std::span<float> out_normals;     // 3p, or empty to skip normals

  // Shapes only (the level's matrices are finite: DecodeLevelSet checked them).
  Result<uint32_t> Validate() const;
  // Validates, then writes every vertex; returns p. Touches nothing when invalid.
  Result<uint32_t> Run() const;
};

}  // namespace motionlod::client
