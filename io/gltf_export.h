// glTF 2.0 export of one level: the character's skin bound to the reduced skeleton, with
// the reassigned influences and the level's animation, as one self-contained binary
// (.glb) that three.js, Blender, Godot and Unity load as is. docs/EXPORT.md says what each
// variant exports and what is lost.
//
// Letters as in core/types.h: i vertex (p), j original joint (n), s kept slot (m),
// t frame (T). K'_s(t) maps bind-pose model space to posed model space.
//
// What the file holds (model space and length unit of the source, no conversion):
//  * one node per kept joint, named as the joint, each the child of the node of its nearest
//    kept ancestor; the root joint's node and the mesh node are the scene's roots;
//  * joint node s rests at B_s, the rigid part of its bind matrix M0 (translation of M0,
//    rotation nearest M0's 3x3): its inverse bind matrix is B_s^-1, so that the joint
//    matrix glTF skins with, world_s(t) * B_s^-1, is K'_s(t) when world_s(t) = K'_s(t) B_s;
//  * one mesh with POSITION, NORMAL, JOINTS_0 / WEIGHTS_0 and triangles: the level's own
//    vertices, triangles and influences where it has them, else the character's with the
//    reduced influences w' (core::ReduceInfluences); at most 4 per vertex as every loader
//    reads: the 4 largest, renormalised to sum 1 (kGltfMaxInfluences);
//  * one animation, LINEAR, one key per frame at t / fps seconds: translation and rotation
//    of every joint node, local to its parent node; scale only when the level is not rigid.
//    Local transforms are taken top-down relative to the parent's *realised* world matrix,
//    so a non-rigid level's decomposition error never accumulates down the hierarchy.
// A non-rigid K' (variants vp, vpno) is affine; TRS cannot hold its shear: the local
// matrix A is exported as translation, the rotation R of its polar decomposition A = R P
// and the scale diag(P). GltfExportStats reports the resulting vertex deviation.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <string_view>

#include "base/status.h"
#include "core/character.h"

namespace motionlod::io {

// One level as the level-set format carries it (proto::LevelView's spans fit as they are;
// io does not depend on proto).
struct GltfLevel {
  // n joint names of the skeleton the level was solved for: must equal the character's.
  std::span<const std::string_view> joint_names;
  std::span<const uint16_t> kept_joints;  // m original indices, ascending, starting with 0
  std::span<const uint16_t> joint_map;    // n: slot of each joint's nearest kept ancestor
  // T x m x 12 floats, frame-major: K'_s(t) as the top three rows of [A | b], row-major.
  std::span<const float> matrices;
  uint32_t frame_count = 0;    // T >= 1
  double fps = 30.0;           // > 0
  bool rigid = false;          // every K' is a rotation plus a translation (exports no scale)
  std::string animation_name;  // glTF animation name; may be empty
  // The level's own mesh (level format 3.0): the character's vertices it draws (ids,
  // ascending) and its triangles, 3 indices into those; both empty: the whole mesh.
  std::span<const uint32_t> vertices = {};
  std::span<const uint32_t> triangles = {};
  // The level's own influences, influences_per_vertex (k) slots and weights per level
  // vertex (zero weights unused); k = 0: the character's, merged through the joint map.
  uint32_t influences_per_vertex = 0;
  std::span<const uint16_t> influence_slots = {};
  std::span<const float> influence_weights = {};
};

// Influences per vertex in JOINTS_0 / WEIGHTS_0: the one set every glTF loader reads.
inline constexpr int kGltfMaxInfluences = 4;

// What the export changed, for callers to report. Lengths in percent of the character's
// height (core::Character::height()).
struct GltfExportStats {
  int joints = 0;    // m
  int vertices = 0;  // the level's (p when it draws the whole mesh)
  int frames = 0;    // T
  // Vertices that had more than kGltfMaxInfluences reduced influences, and the largest weight
  // sum dropped from one vertex (before renormalising).
  int truncated_vertices = 0;
  double max_dropped_weight = 0;
  // Largest |v_exported(t) - v_level(t)| over every vertex and frame: linear blend skinning
  // with the exported weights and the animation's realised joint matrices against the
  // reduced influences and the level's K'. Floating-point noise for a rigid level whose
  // vertices have at most kGltfMaxInfluences influences.
  double max_vertex_deviation_pct = 0;
};

struct GltfExport {
  std::string glb;  // the whole .glb file
  GltfExportStats stats;
};

// Errors: kInvalidArgument when the level does not belong to the character (joint count or
// names differ, kept joints or joint map inconsistent with the skeleton, a vertex the
// character does not have), when a shape is wrong (matrices not T x m x 12, frame_count or
// fps out of range, triangles or influences not matching the level's vertices), when an
// index, slot or weight is out of range, or when a matrix is not finite or singular.
StatusOr<GltfExport> ExportLevelGlb(const core::Character& character, const GltfLevel& level);

}  // namespace motionlod::io
