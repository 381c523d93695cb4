// CPU skinning with a decoded level (docs/level-format.md, "Skinning with a level").
//
// Letters: i vertex (p of them), j joint of the original skeleton (n), s slot of a kept
// joint of the level (m), t frame. Positions and normals are xyz float triples,
// interleaved (3p floats), in the character's bind-pose model space.
//
// The level file carries the skeleton and the per-frame matrices, not the mesh: the
// client draws its own copy of the character, whose influences name the original joints
// in the order of the level set's joint_names (the order of the daemon's
// CharacterInfo::joint_names). LevelSkin merges them once per level through the level's
// joint map (influences on one slot summed, so a vertex has at most as many as before);
// SkinFrameJob then poses one frame from the level's m matrices into caller-owned
// buffers, allocating nothing:
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

// A mesh's influences merged onto the slots of one level. Immutable once built; shared
// by every character that draws this mesh at this level, from any thread.
class LevelSkin {
 public:
  // `joint_map`: the level's (n entries, slots < kept_count). kInvalidArgument naming the
  // vertex or entry when the mesh's shapes disagree, a joint is out of range or a weight
  // is negative or not finite.
  static Result<LevelSkin> Build(const SkinMesh& mesh, std::span<const uint16_t> joint_map,
                                 uint32_t kept_count);

  uint32_t vertex_count() const { return static_cast<uint32_t>(offsets_.size() - 1); }
  uint32_t kept_count() const { return kept_count_; }
  bool has_normals() const { return !normals_.empty(); }
  // Merged influences per vertex, on average (the per-vertex cost of a frame).
  double mean_influences() const {
    return static_cast<double>(slots_.size()) / static_cast<double>(vertex_count());
  }

 private:
  friend struct SkinFrameJob;
  LevelSkin() = default;
  std::span<const float> positions_;
  std::span<const float> normals_;
  uint32_t kept_count_ = 0;
  std::vector<uint32_t> offsets_;  // p + 1
  std::vector<uint16_t> slots_;    // s of each merged influence
  std::vector<float> weights_;     // W_is
};

// One frame of one character.
struct SkinFrameJob {
  const LevelSkin* skin = nullptr;
  std::span<const float> matrices;  // m x 12: the level's frame t (LevelView::frame(t))
  bool rigid = false;               // LevelSetView::rigid(): normals by B instead of cof(B)
  std::span<float> out_positions;   // 3p
  std::span<float> out_normals;     // 3p, or empty to skip normals

  // Shapes only (the level's matrices are finite: DecodeLevelSet checked them).
  Result<uint32_t> Validate() const;
  // Validates, then writes every vertex; returns p. Touches nothing when invalid.
  Result<uint32_t> Run() const;
};

}  // namespace motionlod::client
