// The naive reference for the greedy removal order (core/greedy_ranking.h): at each step
// every candidate's level is solved with every figure (PreparedMotion::SolveLevel on
// the probe frames; BaselineErrors where the job scores reparented levels) and GreedyPick
// chooses among them.
#pragma once

#include <span>
#include <string>

#include "core/greedy_ranking.h"

namespace motionlod::core {

// Expects a valid job (GreedyRankingJob::Validate); the order and the priorities.
StatusOr<JointRanking> GreedyRankingReference(const GreedyRankingJob& job);

}  // namespace motionlod::core
