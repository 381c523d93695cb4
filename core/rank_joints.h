// Step 1 (sec. 4.1, fig. 2): the order in which joints are removed.
//   priority_j = h_j * r_j, lowest removed first; the root and locked joints never.
//   h_j: Character::subtree_lengths(), summed distance to the leaves below j (length).
//   r_j: rotational factor (radians, plus a dimensionless translation term), how much
//        the joint's *local* transform L_j(t) = M_parent(t)^-1 M_j(t) moves:
//          r_j = mean_t angle(R_j(t), mean_t R_j)       the paper's variation
//              + mean_t angle(R_j(t), R0_j)             offset from the bind pose
//              + mean_t |T_j(t) - T0_j| / max(h_j, 1% of the character's height)
//        where R, T are the rotation and translation of L_j, R0/T0 those of the bind
//        pose, angle() the geodesic angle and the mean rotation the normalised,
//        sign-aligned quaternion average. The second and third terms catch joints that
//        hold a constant offset from the bind pose or only translate, which a variation
//        measure alone ranks as free to remove (METHOD.md, pitfalls).
#pragma once

#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "base/pieces.h"
#include "base/status.h"
#include "core/character.h"
#include "core/motion.h"
#include "core/simd.h"

namespace motionlod::core {

// Which order removes the joints: greedy by error (core/greedy_ranking.h, the default) or
// the paper's priorities (RankJointsJob).
enum class RankingMethod { kGreedy, kPaper };
const char* RankingMethodName(RankingMethod method);  // "greedy", "paper"
StatusOr<RankingMethod> ParseRankingMethod(std::string_view name);

struct JointRanking {
  std::vector<double> hierarchical;  // h_j, length
  std::vector<double> rotational;    // r_j, radians
  std::vector<double> priority;      // h_j * r_j; +inf for the root and locked joints
  // All joints, lowest priority first (ties: deeper joint first, then higher index);
  // the root is last. Removing the first k of them gives the level with n - k joints.
  std::vector<int> removal_order;
  int locked_count = 0;  // joints that no level removes, the root included
};

struct RankJointsJob {
  const Character* character = nullptr;
  const Motion* motion = nullptr;
  std::span<const std::string> locked_joints;  // names; never removed
  SimdChoice simd = SimdChoice::kWidest;       // the hot loops' machine version (core/simd.h)

  Status Validate() const;  // unknown locked names are an error naming them
  // `run`: where the joints' rotational factors are measured, a few joints per piece
  // (base/pieces.h); the ranking is the same for any runner.
  StatusOr<JointRanking> Run(const PieceRunner& run = {}) const;
};

}  // namespace motionlod::core
