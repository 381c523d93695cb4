#include "core/reduce_skeleton.h"

#include <algorithm>
#include <memory>
#include <string>

namespace motionlod::core {

StatusOr<ReducedSkeleton> ReduceSkeleton(const Character& character, std::span<const bool> keep) {
  const int n = character.joint_count();
  if (static_cast<int>(keep.size()) != n) {
    return InvalidArgument("ReduceSkeleton: " + std::to_string(keep.size()) + " flags for " +
                           std::to_string(n) + " joints");
  }
  if (!keep[0]) return InvalidArgument("ReduceSkeleton: the root joint cannot be removed");
  const std::vector<int>& parents = character.skeleton().parents;
  ReducedSkeleton reduced;
  // Sized up front: an every-level bake reduces n skeletons serially before its solves
  // start, with the other thread idle.
  const auto kept = static_cast<size_t>(std::count(keep.begin(), keep.end(), true));
  reduced.kept_joints.reserve(kept);
  reduced.parent_slots.reserve(kept);
  reduced.joint_to_slot.assign(n, -1);
  // Topological order makes the parent's slot known before its children's.
  for (int j = 0; j < n; ++j) {
    if (keep[j]) {
      const int slot = reduced.kept_count();
      reduced.kept_joints.push_back(j);
      reduced.parent_slots.push_back(j == 0 ? -1 : reduced.joint_to_slot[parents[j]]);
      reduced.joint_to_slot[j] = slot;
    } else {
      reduced.joint_to_slot[j] = reduced.joint_to_slot[parents[j]];
    }
  }
  return reduced;
}

StatusOr<ReducedSkeleton> ReduceSkeletonToCount(const Character& character,
                                                const JointRanking& ranking, int kept_count) {
  const int n = character.joint_count();
  if (kept_count < ranking.locked_count || kept_count > n) {
    return InvalidArgument("a level must keep between " + std::to_string(ranking.locked_count) +
                           " (the root and locked joints) and " + std::to_string(n) +
                           " joints, got " + std::to_string(kept_count));
  }
  // std::vector<bool> has no contiguous storage to span over.
  std::unique_ptr<bool[]> keep(new bool[n]);
  std::fill(keep.get(), keep.get() + n, true);
  for (int r = 0; r < n - kept_count; ++r) keep[ranking.removal_order[r]] = false;
  return ReduceSkeleton(character, std::span<const bool>(keep.get(), n));
}

ReducedInfluences ReduceInfluences(const RawSkin& skin, const ReducedSkeleton& reduced) {
  ReducedInfluences out;
  const size_t p = skin.positions.size();
  out.offsets.reserve(p + 1);
  out.offsets.push_back(0);
  out.slots.reserve(skin.influence_joints.size());
  out.weights.reserve(skin.influence_joints.size());
  for (size_t i = 0; i < p; ++i) {
    const uint32_t first = static_cast<uint32_t>(out.slots.size());
    for (uint32_t e = skin.influence_offsets[i]; e < skin.influence_offsets[i + 1]; ++e) {
      const int32_t slot = reduced.joint_to_slot[skin.influence_joints[e]];
      bool merged = false;
      for (uint32_t f = first; f < out.slots.size(); ++f) {
        if (out.slots[f] == slot) {
          out.weights[f] += skin.influence_weights[e];
          merged = true;
          break;
        }
      }
      if (!merged) {
        out.slots.push_back(slot);
        out.weights.push_back(skin.influence_weights[e]);
      }
    }
    out.offsets.push_back(static_cast<uint32_t>(out.slots.size()));
  }
  return out;
}

}  // namespace motionlod::core
