// Levels chosen by cost (#44): for a pixel height, the cheapest level whose honest error
// (core/level_deviation.h) stays within the budget, built from the four things a level can
// cut: joints (the ranking's nested skeletons), vertices (a simplified mesh,
// core/simplify_mesh.h), influences per vertex (re-solved weights, core/influence_cap.h)
// and stored poses (core/pose_rate.h).
//
// The cost model (what one frame of a level costs a CPU or GPU skinner, relative to full
// detail): every vertex pays one blend per influence it uses, every kept joint one matrix
// to play (sample or interpolate) and upload,
//   cost = (vertices x mean influences + kJointCost x joints) / (the same at full detail),
// kJointCost in vertex-influences: an estimate (the crowd bench measures a joint's matrix
// update at about 14 vertex-influences of the client's skinning on an AMD EPYC;
// docs/PERFORMANCE.md, "Crowd"). The pose rate does not enter it: interpolating two stored
// poses costs what playing one does; it saves stream bytes.
#pragma once

#include <limits>
#include <memory>
#include <optional>
#include <vector>

#include "base/status.h"
#include "core/influence_cap.h"
#include "core/level_deviation.h"
#include "core/rank_joints.h"
#include "core/simplify_mesh.h"
#include "core/solve_levels.h"
#include "pipeline/task_pool.h"

namespace motionlod::pipeline {

inline constexpr double kJointCost = 24.0;

// One level with its own mesh, influences and pose rate.
struct CostLevel {
  core::ReducedSkeleton skeleton;
  std::optional<core::LevelMesh> mesh;  // empty: every vertex and triangle of the character
  // Per level vertex; empty (per_vertex 0): the mesh's own, merged through the joint map.
  core::LevelInfluences influences;
  int frame_stride = 1;
  // The stored frames of every clip (core::StoreAtStride) x m.
  std::vector<core::RowMajorAffine34f> stored_matrices;
  double mean_influences = 0;      // used per level vertex, on average
  core::LevelDeviation deviation;  // on every frame and original vertex
  double cost = 1;                 // the model above, full detail = 1

  int vertex_count(const core::Character& character) const {
    return mesh ? static_cast<int>(mesh->vertices.size()) : character.vertex_count();
  }
  int triangle_count(const core::Character& character) const {
    return static_cast<int>(mesh ? mesh->triangles.size() : character.skin().triangles.size());
  }
};

// The modelled cost of drawing `vertices` with `mean_influences` each and `joints`
// matrices, relative to `character` at full detail.
double LevelCost(const core::Character& character, double vertices, double mean_influences,
                 int joints);

// A level of the skeleton's solve alone (`--levels`): the whole mesh, the mesh's
// influences merged through the joint map (no influences of its own: LevelInfluences
// empty), every frame, the solved matrices; its deviation the solve's exact figures.
CostLevel SkeletonLevel(const core::Character& character, const core::LevelResult& solved);

// Full detail as a CostLevel: every joint, vertex and influence, every frame, the original
// matrices; deviation 0, cost 1.
StatusOr<CostLevel> FullDetailLevel(const core::PreparedMotion& prepared);

// What levels may cut; all of it by default, one part switched off to measure its share of
// the saving.
struct CostLevelParts {
  bool joints = true;      // else every joint up to the finer level's
  bool vertices = true;    // else the whole mesh
  bool influences = true;  // else the mesh's own, merged through the joint map
  bool pose_rate = true;   // else every frame
};

struct CheapestLevelJob {
  // The original character and every clip, in the bake's variant.
  std::shared_ptr<const core::PreparedMotion> prepared;
  const core::Motion* motion = nullptr;  // the motion `prepared` was made from
  const core::JointRanking* ranking = nullptr;
  core::SimdChoice simd = core::SimdChoice::kWidest;
  double budget_pct = 1;  // the honest maximum error allowed, percent of the height
  CostLevelParts parts;
  std::vector<int> caps = {1, 2, 4};
  int max_frame_stride = 4;
  // At most this many joints (a coarser level of a ladder keeps a subset of the finer one's).
  int max_joints = std::numeric_limits<int>::max();

  Status Validate() const;
  // The cheapest level found within the budget, none when nothing is cheaper than full
  // detail.
  StatusOr<std::optional<CostLevel>> Run(TaskPool& pool) const;
};

// A character's levels for a spread of on-screen heights: full detail, then for each
// height the cheapest level within budget_px there (a maximum error of 100 budget_px /
// height percent of the character's height), kept where it is cheaper than the level
// before. Costs fall and errors rise along the ladder, and each level's joints are a
// subset of the one before, so the coarsest level within a budget is also the cheapest.
struct CostLadderJob {
  std::shared_ptr<const core::PreparedMotion> prepared;
  const core::Motion* motion = nullptr;
  const core::JointRanking* ranking = nullptr;
  core::SimdChoice simd = core::SimdChoice::kWidest;
  std::vector<double> heights_px = {800, 400, 200, 100, 50, 25, 12};  // decreasing
  double budget_px = 1;
  CostLevelParts parts;

  Status Validate() const;
  StatusOr<std::vector<CostLevel>> Run(TaskPool& pool) const;
};

}  // namespace motionlod::pipeline
