// Beyond the paper (its sec. 7, future work): a far level draws a simplified mesh. Its
// triangles are meshoptimizer's simplification (meshopt_simplify: edge collapses onto
// original vertices under a quadric error, UV seams and borders kept) of the bind-pose
// mesh, so a level's mesh is a list of original vertices and triangles over them; the
// level's matrices and weights are then solved on those vertices, weighted by the
// simplified surface (SubsetCharacter), and every original vertex is measured against the
// point of the level's surface that stands for it (core/level_deviation.h).
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include "base/status.h"
#include "core/character.h"

namespace motionlod::core {

// A point of a level's surface: barycentric coordinates over three of its vertices
// (indices into LevelMesh::vertices; a vertex the level keeps is itself, weight 1).
struct SurfacePoint {
  std::array<uint32_t, 3> vertices{};
  std::array<float, 3> weights{};
};

struct LevelMesh {
  std::vector<uint32_t> vertices;                  // original vertex ids, ascending
  std::vector<std::array<uint32_t, 3>> triangles;  // indices into `vertices`
  // Per original vertex: the nearest point of the simplified bind-pose surface among the
  // triangles around the kept vertices nearest to it along the original mesh.
  std::vector<SurfacePoint> correspondence;
  // meshoptimizer's error of the simplification (length): how far the simplified surface
  // may lie from the original in the bind pose.
  double bind_error = 0;
};

// The parts of the skin a simplification keeps apart (their borders become seams).
enum class SkinSplit {
  kNone,           // one surface
  kDominantJoint,  // a part per joint: triangles by the joint with the most weight
  // A part per band of blending: the two joints with the most weight and the first's share
  // in steps of a quarter, so that collapses also stay within a blend.
  kWeightBands,
};

struct SimplifyMeshJob {
  const Character* character = nullptr;
  // Stop at this many triangles or more (the original's at most) ...
  int target_triangles = 0;
  // ... or where the next collapse would move the surface by more than this (length).
  double target_error = 0;
  SkinSplit split = SkinSplit::kDominantJoint;

  Status Validate() const;
  StatusOr<LevelMesh> Run() const;
};

// LevelMesh::correspondence for a level mesh of `character` given by its vertices (original
// ids, ascending) and triangles (indices into them): from these alone, so that a reader of
// a level file measures a level against the same points as the bake.
std::vector<SurfacePoint> SurfaceCorrespondence(const Character& character,
                                                std::span<const uint32_t> vertices,
                                                std::span<const std::array<uint32_t, 3>> triangles);

// The character on the vertices of `mesh` only, with its triangles (the areas that weight
// the solve are the simplified surface's): what a simplified level is solved on. Vertex s
// of the result is original vertex mesh.vertices[s].
StatusOr<std::shared_ptr<const Character>> SubsetCharacter(const Character& character,
                                                           const LevelMesh& mesh);

}  // namespace motionlod::core
