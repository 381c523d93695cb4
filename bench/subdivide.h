// Benchmark support: denser copies of real characters, so the "every level of a 10k+
// vertex mesh" target can be measured on real skeletons, weights and motions.
//
// One step of 1-to-4 midpoint subdivision: every edge (a, b) used by a triangle gets one
// new vertex at its midpoint, shared by the triangles on both sides (edges are keyed by
// their vertex indices, so a UV seam that duplicates vertices stays a seam):
//   v0 = (v0_a + v0_b) / 2,   n0 = normalise(n0_a + n0_b)   (n0_a when the sum vanishes)
//   w  = (w_a + w_b) / 2      influences on the same joint merged, the largest
//                             `max_influences` kept and renormalised to sum 1
// and every triangle (a, b, c) becomes (a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca).
// The skeleton is unchanged, so any motion of the original plays on the copy.
#pragma once

#include "core/character.h"

namespace motionlod::bench {

// One subdivision step. Vertices in no triangle are kept as they are.
core::RawCharacter SubdivideOnce(const core::RawCharacter& raw, int max_influences = 8);

// Subdivides until the skin has at least `min_vertices` vertices (or `max_steps` steps,
// for a skin without triangles); `steps` receives the number of steps taken.
core::RawCharacter SubdivideToVertexCount(const core::RawCharacter& raw, int min_vertices,
                                          int* steps = nullptr, int max_influences = 8,
                                          int max_steps = 4);

}  // namespace motionlod::bench
