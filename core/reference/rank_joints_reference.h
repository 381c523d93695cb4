// The naive reference for the joint ranking (core/rank_joints.h, step 1): each joint's
// local transforms through Eigen's inverse and quaternion conversion, angles by Eigen's
// angularDistance, the priorities and the removal order as the header defines them.
#pragma once

#include <span>
#include <string>

#include "core/rank_joints.h"

namespace motionlod::core {

// Expects a valid character, motion and locked joints (RankJointsJob::Validate).
JointRanking RankJointsReference(const Character& character, const Motion& motion,
                                 std::span<const std::string> locked_joints);

}  // namespace motionlod::core
