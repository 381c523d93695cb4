// What PreparedMotion::Create computes once for one (character, motion, settings) and
// every level then reads (core/solve_levels.h has the letters, shapes and equations).
// Internal to the core: the steps' files read it, nothing above the core does.
#pragma once

#include <memory>
#include <span>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "core/character.h"
#include "core/internal/error_sample.h"
#include "core/internal/lanes.h"
#include "core/simd.h"
#include "core/solve_levels.h"

namespace motionlod::core::internal {

struct PreparedData {
  std::shared_ptr<const Character> character;
  SolveSettings settings;
  SimdChoice simd = SimdChoice::kWidest;
  int n = 0;
  int frames = 0;
  Eigen::MatrixXd kt;  // 4n x 3T: block (4k, 3t) = K_k(t)^T
  // The area-fraction weighted moments per pair of joints k <= l sharing vertices
  // (Character::joint_pair_moments): for the per-frame quadratic forms of the errors,
  // with off-diagonal pairs doubled (they appear twice in the trace sum), and
  // Q_kl = alpha Cp_kl + beta_fit Cn_kl for the normal equations, as they are.
  std::vector<std::pair<int, int>> pairs;
  std::vector<Eigen::Matrix4d> pair_cp;
  std::vector<Eigen::Matrix4d> pair_cn;  // 3x3, padded with a zero row and column
  std::vector<Eigen::Matrix4d> pair_fit;
  // F^T = (Q Kt)^T, 3T x 4n: the right-hand sides are assembled transposed from it
  // (core/normal_equations.cc).
  Eigen::MatrixXd ft;
  // The joint terms' forms, Ep_joint(t) = sum_j tr(Delta_j^T Jp_j Delta_j) and the same
  // for En with Jn_j: Jp_j = omega b_j [p0_j;1][p0_j;1]^T, Jn_j = omega b_j [o0_j;0][o0_j;0]^T
  // (o0_j the bind y axis).
  std::vector<Eigen::Matrix4d> joint_cp, joint_cn;
  std::vector<Eigen::Matrix4d> joint_fit;  // J_j with alpha and beta_fit
  // Whether every K_k(t) is a rotation as a rigid level set's matrices must be
  // (AllRotations to kRigidLevelRotation): then the reparented matrices are a candidate of
  // the rigid variants too (KeepNoWorseThanReparenting).
  bool original_rotations = false;
  double alpha = 1, beta = 1;
  double beta_fit = 1;  // beta where the variant fits normals, else 0
  ErrorSample sample;   // the sampled figures' frames and vertices
  // Motion::Clips(), and with more than one, each clip's frames prepared on their own
  // (SelectFrames): a level's figures per clip are evaluated on its part.
  std::vector<MotionClip> clips;
  std::vector<std::shared_ptr<const PreparedMotion>> clip_parts;
};

// The prepared motion on the given frames (ascending, each in [0, T)) as one clip: alpha
// and beta stay the motion's and the normal matrix does not depend on the frames, so a
// level solved on it has the full motion's solution on those frames, to rounding. Costs a
// copy of those frames' columns and a new sample, not a Create.
StatusOr<std::shared_ptr<const PreparedMotion>> SelectFrames(const PreparedData& d,
                                                             std::span<const int> frames);

// Delta_k(t) = S_k(t) - K_k(t) for every original joint k, read from the matrices S it
// compares with the originals instead of materialised: a long motion's 4n x 3T
// difference does not fit the caches, and every figure would read it again.
struct DeltaView {
  const Eigen::MatrixXd* solution;  // rows of S, 3T columns (the solution, or kt itself)
  std::vector<int> solution_row;    // first row of S_k in *solution
  const Eigen::MatrixXd* original;  // kt

  // Whether Delta_k can be nonzero in some frame.
  bool Moves(int k) const { return solution != original || solution_row[k] != 4 * k; }
  // Frame t's Delta_k^T stacked (4n x 3, block (4k, 0) = Delta_k(t)^T) for the listed
  // joints; the other blocks are left as they are. Column by column as whole vectors:
  // the trace forms read each column back as one.
  void Frame(int t, const std::vector<int>& joints,
             Eigen::Matrix<double, Eigen::Dynamic, 3>& out) const {
    const double* s = solution->data() + 3 * t * solution->rows();
    const double* o = original->data() + 3 * t * original->rows();
    const Eigen::Index s_stride = solution->rows(), o_stride = original->rows();
    const int* s_row = solution_row.data();
    double* d = out.data();
    const Eigen::Index d_stride = out.rows();
    for (int k : joints) {
      const double* sk = s + s_row[k];
      const double* ok = o + 4 * k;
      double* dk = d + 4 * k;
      for (int col = 0; col < 3; ++col) {
        *AsLanes4(dk + col * d_stride) =
            *AsLanes4(sk + col * s_stride) - *AsLanes4(ok + col * o_stride);
      }
    }
  }
};

// The baseline's Delta_k = K_kept(phi(k)) - K_k of a validated level.
DeltaView BaselineDelta(const PreparedData& d, const ReducedSkeleton& level);

// Whether `level` belongs to a character of n joints (the public entry points' check).
Status ValidateLevel(const ReducedSkeleton& level, int n);

}  // namespace motionlod::core::internal
