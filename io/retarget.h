// Retargeting: plays one asset's animation on another character by joint name.
//
// Matching: a target joint takes the source joint of exactly its name; failing that, the
// source joint with the same normalised name (NormalizeJointName), when exactly one
// source joint has it. Each source joint serves at most one target joint.
//
// Rule (R the orthogonal polar factor of a 3x3 part A, p a position; s = s(j) the source
// joint of target joint j; 0 the bind pose, (t) frame t; D(t) = R(t) R0^-1 a joint's
// rotation change):
//  * matched j:  A_j(t) = D_s(t) A0_j, the source joint's world-rotation change from its
//    bind pose applied to the target's bind matrix (right for any local-axis convention
//    when both bind poses are alike, e.g. T-poses), and
//    p_j(t) = p_q(t) + D_q(t) (p0_j - p0_q) + h Δ_j(t), q the target parent (none for the
//    root: p_j(t) = p0_j + h Δ_j(t)), so bone lengths are the target's own. Δ_j is what
//    the source adds by translation: p_s(t) - p0_s (root motion) when no target ancestor
//    of j is matched; (p_s - p_ps)(t) - D_ps(t) (p0_s - p0_ps) when the source parent ps of
//    s is the source joint of j's nearest matched ancestor (animated bone translations);
//    0 otherwise. h = target height / source height, each the longest side of the
//    bounding box of the bind joint positions.
//  * unmatched j keeps its bind pose relative to its parent: M_j(t) = M_q(t) M0_q^-1 M0_j
//    (the root: M0_j).
// With identical skeletons (same names, same bind poses) the result equals the source
// motion, i.e. copying the local transforms.
#pragma once

#include <string>
#include <string_view>
#include <vector>

#include "base/pieces.h"
#include "base/status.h"
#include "core/character.h"
#include "core/motion.h"
#include "io/asset.h"

namespace motionlod::io {

struct RetargetedMotion {
  core::Motion motion;  // over the target's joints
  std::vector<std::string> unmatched_target_joints;
  std::vector<std::string> unmatched_source_joints;
};

// Lower case, namespaces and common rig prefixes removed ("mixamorig:", "mixamorig_",
// "Armature|", "Bip01 ", "Bip001 ", "DEF-", "ORG-", ...), separators (space _ - . :)
// dropped: "mixamorig:LeftUpLeg" and "Left_Up_Leg" both become "leftupleg".
std::string NormalizeJointName(std::string_view name);

// Samples `animation` of `source` ("" = the first) at `fps` (0 = its source rate) and
// retargets it onto `target`'s skeleton (only the skeleton is used). Errors: those of
// Asset::SampleAnimation; InvalidArgument for an invalid target skeleton, or when fewer
// than half of the target's joints match (the message names the unmatched ones).
// `run`: as for Asset::SampleAnimation.
StatusOr<RetargetedMotion> RetargetAnimation(const Asset& source, std::string_view animation,
                                             double fps, const core::RawCharacter& target,
                                             const PieceRunner& run = {});

// The same on an already sampled motion of `source_skeleton`.
StatusOr<RetargetedMotion> RetargetMotion(const core::RawSkeleton& source_skeleton,
                                          const core::Motion& source_motion,
                                          const core::RawSkeleton& target_skeleton);

}  // namespace motionlod::io
