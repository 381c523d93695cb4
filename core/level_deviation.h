// Beyond the paper (#44): the honest error of a level that draws its own mesh, weights and
// pose rate. For every original vertex i and every frame t of the motion, the distance
// between its original skinned position and the point of the level's skinned surface that
// stands for it (LevelMesh::correspondence: itself where the level keeps it, else a point
// of a simplified triangle, whose corners the level skins and the triangle interpolates),
// with the level's matrices played from its stored frames (core/pose_rate.h). That point
// lies on the surface the level draws, so the figure bounds the distance from each
// original vertex to that surface from above. Skins every vertex at every frame: the
// reference is itself.
#pragma once

#include <span>
#include <vector>

#include "base/pieces.h"
#include "base/status.h"
#include "core/influence_cap.h"
#include "core/simplify_mesh.h"
#include "core/solve_levels.h"

namespace motionlod::core {

struct LevelDeviation {
  double max_pct = 0;   // max over vertices and frames, percent of the character's height
  double mean_pct = 0;  // area-weighted mean over vertices and frames, percent of the height
  int max_frame = 0, max_vertex = 0;  // where the maximum is (frame of the motion, original vertex)
  std::vector<LevelDeviation> per_clip;  // each clip's, frames within the clip; empty inside
};

struct LevelDeviationJob {
  // Of the original character and the motion: the original skinning and the clips.
  const PreparedMotion* prepared = nullptr;
  const ReducedSkeleton* level = nullptr;
  const LevelMesh* mesh = nullptr;  // null: every vertex of the character
  // Per level vertex (mesh->vertices, or every vertex), slots of `level`.
  const LevelInfluences* influences = nullptr;
  // Stored frames of every clip at frame_stride (StoreAtStride) x m.
  std::span<const RowMajorAffine34f> stored_matrices;
  int frame_stride = 1;
  bool rigid = false;  // interpolation: slerp and lerp, else lerp
  // Every frame_step-th frame of the motion only (1: every frame, the honest figure); a
  // search's probe. Take it prime to the strides tried, so the probe sees played frames.
  int frame_step = 1;

  Status Validate() const;
  // Pieces of frames run on `run` (base/pieces.h); the result does not depend on it.
  StatusOr<LevelDeviation> Run(const PieceRunner& run = {}) const;
};

}  // namespace motionlod::core
