// What the weight step (core/influence_cap.h) and its reference share: the candidate
// slots of a vertex and the capped least squares on the simplex that picks its weights
// from them, given the quadratic form of the vertex's objective.
#pragma once

#include <cstdint>
#include <span>

#include "core/character.h"
#include "core/influence_cap.h"
#include "core/reduce_skeleton.h"

namespace motionlod::core::internal {

// Vertex i's candidate slots, at most kMaxCandidates, into `out`; returns how many: the
// slots its influences move to (decreasing merged weight), then the kept parent and
// kept children of each.
int CandidateSlots(const Character& character, const ReducedSkeleton& level,
                   std::span<const std::vector<int>> kept_children, int vertex,
                   std::span<int, kMaxCandidates> out);

// Each slot's kept children (slots whose kept parent it is).
std::vector<std::vector<int>> KeptChildren(const ReducedSkeleton& level);

// argmin over w of w^T G w - 2 r^T w with w >= 0, sum w = 1 and at most `cap` non-zero,
// G symmetric positive semi-definite (c x c, row-major), by solving every support of at
// most `cap` of the c candidates exactly: the optimum lies inside the face of its support.
// Writes c weights; returns the objective.
double SolveCappedSimplex(std::span<const double> g, std::span<const double> r, int c, int cap,
                          std::span<double> w);

// The vertex's influences (`weights` over `slots`, c of them) written into row `vertex` of
// `out` in decreasing weight, zero weights dropped, unused entries padded.
void WriteInfluenceRow(std::span<const int> slots, std::span<const double> weights, int vertex,
                       LevelInfluences& out);

}  // namespace motionlod::core::internal
