// Step 1 by error (beyond the paper): the removal order that, at each step, removes the
// joint whose removal raises the level's optimised maximum vertex error least, over every
// clip of the motion. The paper's order (core/rank_joints.h) predicts the error from each
// joint's subtree length and rotation; it removes short, fast end joints early, removes a
// chain's links one after another and protects trunk joints whose removal costs little.
//
// Each step scores every candidate (a kept joint, never the root or a locked one) by
// solving the level without it on the probe frames as PreparedMotion::SolveLevel does (the
// variant's solution, or the reparented level where the solution is worse), up to
// probe_frames_per_clip evenly spaced frames of each clip (0: all), and taking its maximum
// vertex error; the lowest wins, ties by the lower mean E, then the higher joint index
// (GreedyPick: values within kGreedyTieTolerance of each other tie, so that the order
// between symmetric joints does not follow the rounding in which the machine versions of
// core/simd.h differ). Two savings change no choice: the candidate that scored best at the
// last step is scored first, and every other candidate's maximum is only decided against
// its (the search stops at the first vertex past it, core/internal/max_vertex_error.h),
// found exactly only where it is within it.
// The naive reference, every candidate scored by PreparedMotion::SolveLevel, is
// core/reference/greedy_ranking_reference.h.
#pragma once

#include <span>
#include <string>

#include "base/pieces.h"
#include "base/status.h"
#include "core/rank_joints.h"
#include "core/solve_levels.h"

namespace motionlod::core {

struct GreedyRankingJob {
  static constexpr int kDefaultProbeFramesPerClip = 8;

  const PreparedMotion* prepared = nullptr;
  std::span<const std::string> locked_joints = {};  // names; never removed
  int probe_frames_per_clip = kDefaultProbeFramesPerClip;  // >= 0; 0 = every frame
  // Score the reparented level (kept joints keep their original matrices, nothing solved)
  // instead of the variant's solution: plain reparenting's own greedy order, the strongest
  // form of what engines ship, to compare with.
  bool reparented = false;

  Status Validate() const;
  // The order, with JointRanking::priority the probe's maximum vertex error (percent of the
  // character's height) of the level each joint's removal made, +inf for the root and the
  // locked joints (hierarchical and rotational are the paper's and stay empty). `run`: the
  // candidates of a step are scored a few per piece (base/pieces.h); the order is the same
  // for any runner.
  StatusOr<JointRanking> Run(const PieceRunner& run = {}) const;
};

inline constexpr double kGreedyTieTolerance = 1e-9;  // relative

// The candidate a greedy step removes, given each candidate's joint, maximum vertex error
// and mean E (infinite where only decided above another's maximum): the lowest maximum,
// among those within the tolerance of it the lowest mean E, among those within the
// tolerance of that the highest joint index. The same for any order of the candidates.
int GreedyPick(std::span<const int> joints, std::span<const double> max_pct,
               std::span<const double> mean_e);

// The probe frames of GreedyRankingJob: up to `per_clip` evenly spaced frames of each clip
// (its first among them), every frame where per_clip is 0 or the clip is no longer.
std::vector<int> ProbeFrames(std::span<const MotionClip> clips, int per_clip);

}  // namespace motionlod::core
