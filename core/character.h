// A skinned character: skeleton (joint hierarchy and bind pose) and skin (mesh and
// influences). RawCharacter is editable plain data (what importers fill in);
// BuildCharacter validates it and derives what the method needs into an immutable
// Character, shared as std::shared_ptr<const Character>.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "base/pieces.h"
#include "base/status.h"
#include "core/types.h"

namespace motionlod::core {

namespace internal {
struct SkinClusters;  // core/internal/skin_clusters.h
}  // namespace internal

using ::motionlod::Status;
using ::motionlod::StatusOr;

struct RawSkeleton {
  std::vector<std::string> joint_names;  // n, unique
  // n; parents[0] == -1 (the single root) and 0 <= parents[j] < j for j > 0,
  // so joints are in topological order.
  std::vector<int> parents;
  // n; M0_j: joint j's world matrix in the bind pose (the inverse of its inverse bind
  // matrix), model space. Must be invertible.
  std::vector<Affine34d> bind_world;
};

struct RawSkin {
  std::vector<Vec3f> positions;  // p; v0_i, bind pose, model space
  std::vector<Vec3f> normals;    // p; n0_i, unit length, bind pose, model space
  std::vector<std::array<uint32_t, 3>> triangles;  // indices into positions
  // Influences in compressed rows: vertex i's influences are the entries
  // [influence_offsets[i], influence_offsets[i+1]) of influence_joints / _weights.
  std::vector<uint32_t> influence_offsets;  // p + 1, influence_offsets[0] == 0
  std::vector<int32_t> influence_joints;    // joint index in [0, n), unique per vertex
  std::vector<float> influence_weights;     // > 0, each vertex's weights sum to 1 (1e-3)
};

struct RawCharacter {
  std::string name;
  RawSkeleton skeleton;
  RawSkin skin;
};

// Checks every field combination of RawCharacter; the message names the first
// offending joint, vertex or triangle. `run`: where its pieces of vertices run
// (base/pieces.h); the result is the same.
Status ValidateRawCharacter(const RawCharacter& raw, const PieceRunner& run = {});

class Character {
 public:
  const std::string& name() const { return name_; }
  const RawSkeleton& skeleton() const { return skeleton_; }
  const RawSkin& skin() const { return skin_; }
  int joint_count() const { return static_cast<int>(skeleton_.parents.size()); }
  int vertex_count() const { return static_cast<int>(skin_.positions.size()); }

  // A_i: summed area of the triangles incident to vertex i (length^2), eq. (3).
  const std::vector<double>& vertex_areas() const { return vertex_areas_; }
  // l_j = h_j: summed distance from joint j to each leaf of its subtree (length).
  // A childless joint that carries skin gets a virtual end site at its farthest
  // dominantly-weighted vertex, the role the "...Nub" joints play in fig. 2.
  const std::vector<double>& subtree_lengths() const { return subtree_lengths_; }
  // Longest side of the bind-pose bounding box of the mesh (length): the "height"
  // that percentages of vertex error refer to.
  double height() const { return height_; }
  // The skin indexed for the maximum vertex error search (core/internal/skin_clusters.h).
  const internal::SkinClusters& clusters() const { return *clusters_; }
  // Direct children of each joint.
  const std::vector<std::vector<int>>& children() const { return children_; }
  int FindJoint(const std::string& name) const;  // -1 when absent

  // Second moments of the skin per pair of joints k <= l that share a vertex, weighted by
  // the area fractions a_i = A_i / sum A (what eq. 3 sums over vertices, factored so
  // that no solve or error evaluation ever loops over the mesh again):
  //   position_moment = sum_i a_i w_ik w_il [v0_i;1][v0_i;1]^T   (4x4, length^2)
  //   normal_moment   = sum_i a_i w_ik w_il n0_i n0_i^T           (3x3)
  struct JointPairMoment {
    int k = 0, l = 0;
    Eigen::Matrix4d position_moment;
    Eigen::Matrix3d normal_moment;
  };
  const std::vector<JointPairMoment>& joint_pair_moments() const { return joint_pair_moments_; }

 private:
  friend StatusOr<std::shared_ptr<const Character>> BuildCharacter(const RawCharacter& raw,
                                                                   const PieceRunner& run);
  Character() = default;

  std::string name_;
  RawSkeleton skeleton_;
  RawSkin skin_;
  std::vector<double> vertex_areas_;
  std::vector<double> subtree_lengths_;
  double height_ = 0;
  std::shared_ptr<const internal::SkinClusters> clusters_;
  std::vector<std::vector<int>> children_;
  std::vector<JointPairMoment> joint_pair_moments_;
};

// Checks `raw` (ValidateRawCharacter's errors) and builds its Character, a copy of its
// arrays with what the solver derives from them. `run`: where its pieces run
// (base/pieces.h); the result is the same.
StatusOr<std::shared_ptr<const Character>> BuildCharacter(const RawCharacter& raw,
                                                          const PieceRunner& run = {});

}  // namespace motionlod::core
