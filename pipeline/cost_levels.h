// Levels chosen by cost (#44): for a pixel height, the cheapest level whose honest error
// (core/level_deviation.h) stays within the budget, built from the four things a level can
// cut: joints (the ranking's nested skeletons), vertices (a simplified mesh,
// core/simplify_mesh.h), influences per vertex (re-solved weights, core/influence_cap.h)
// and stored poses (core/pose_rate.h).
//
// The cost model: what one frame of a level costs the client's CPU skinner
// (client/skinner.h), relative to full detail, in units of one influence's blend:
//   a draw          kDrawCost
//   each vertex     kVertexCost + its influences (transform, normal, output and the blend),
//                   or kSingleInfluenceVertexCost when every vertex is bound to one joint
//                   with weight 1 (no blend, and a rigid normal needs no renormalising)
//   each joint      kJointCost per stored pose (a copy into the palette), plus
//                   kInterpolatedJointCost on the frames played between stored poses
// The constants are `motionlod_bench_crowd`'s "Cost model" on an AMD EPYC (docs/
// PERFORMANCE.md, "Crowd"): 1.8 ns an influence there. A GPU renderer pays little per
// vertex and more per joint (the upload); the level table's stream bytes say that part.
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

inline constexpr double kDrawCost = 20;
inline constexpr double kVertexCost = 2.1;
inline constexpr double kSingleInfluenceVertexCost = 2.25;
inline constexpr double kJointCost = 0.5;
inline constexpr double kInterpolatedJointCost = 18;

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

// What a level draws each frame, as the cost model counts it.
struct DrawnLevel {
  double vertices = 0;
  double mean_influences = 0;
  bool one_influence_each = false;  // every vertex on one joint with weight 1
  int joints = 0;
  int frame_stride = 1;
};

// The modelled cost of `level`, relative to `character` at full detail.
double LevelCost(const core::Character& character, const DrawnLevel& level);

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
// before and less accurate than every level after. Costs fall and errors rise along the
// ladder, and each level's joints are a
// subset of the one before, so the coarsest level within a budget is also the cheapest.
struct CostLadderJob {
  std::shared_ptr<const core::PreparedMotion> prepared;
  const core::Motion* motion = nullptr;
  const core::JointRanking* ranking = nullptr;
  core::SimdChoice simd = core::SimdChoice::kWidest;
  // Decreasing; dense where crowds are (three characters in four under 35 px in the
  // crowd bench's wedge), where each step down saves most.
  std::vector<double> heights_px = {800, 400, 200, 100, 70, 50, 35, 25, 20, 16, 12};
  double budget_px = 1;
  CostLevelParts parts;

  Status Validate() const;
  StatusOr<std::vector<CostLevel>> Run(TaskPool& pool) const;
};

}  // namespace motionlod::pipeline
