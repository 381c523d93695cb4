// Step 2 (sec. 4.1): keep m joints, move every influence on a removed joint to its
// nearest kept ancestor and sum influences that land on the same joint.
#pragma once

#include <span>
#include <vector>

#include "base/status.h"
#include "core/character.h"
#include "core/rank_joints.h"

namespace motionlod::core {

struct ReducedSkeleton {
  std::vector<int> kept_joints;    // m original indices, ascending; kept_joints[0] == 0
  std::vector<int> joint_to_slot;  // n: slot s of the kept joint that drives joint j
  std::vector<int> parent_slots;   // m: slot of each kept joint's nearest kept ancestor, -1 root
  int kept_count() const { return static_cast<int>(kept_joints.size()); }
};

// The reduced skeleton keeping the joints flagged in `keep` (n flags; the root must be
// kept).
StatusOr<ReducedSkeleton> ReduceSkeleton(const Character& character, std::span<const bool> keep);

// The level with `kept_count` joints: removes the first n - kept_count joints of the
// ranking's removal order. Fails when kept_count is below the locked joints or above n.
StatusOr<ReducedSkeleton> ReduceSkeletonToCount(const Character& character,
                                                const JointRanking& ranking, int kept_count);

// Influences w' of the reduced skeleton in the layout of RawSkin (joint indices are
// slots in [0, m)), duplicates merged so each vertex lists a slot at most once.
struct ReducedInfluences {
  std::vector<uint32_t> offsets;  // p + 1
  std::vector<int32_t> slots;
  std::vector<float> weights;
};
ReducedInfluences ReduceInfluences(const RawSkin& skin, const ReducedSkeleton& reduced);

}  // namespace motionlod::core
