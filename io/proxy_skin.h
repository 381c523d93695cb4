// A stand-in skin for motion-only files (BVH, skeleton-only FBX): one capsule per bone,
// so that skeleton-only clips can go through the same skinning and error metrics as
// skinned characters. Pure geometry on the skeleton: no Assimp, no I/O.
//
// Shape. For each joint j with parent p, the bone is the segment from M0_p's position
// to M0_j's position; it moves with p, so its capsule is weighted to p. Near either end
// the weights blend smoothly into the neighbouring joint (p's parent at the start, j at
// the end; both 0.5/0.5 exactly at the joint) so that bends do not tear. A joint
// without children gets a short capsule continuing its parent bone's direction,
// weighted to itself. Bones shorter than 1e-6 of the skeleton height are skipped.
// Radius r = clamp(radius_ratio * bone length, min_radius_ratio * H, max_radius_ratio * H),
// H = the skeleton height (longest side of the bounding box of the bind joint positions).
#pragma once

#include "base/status.h"
#include "core/character.h"

namespace motionlod::io {

struct ProxySkinOptions {
  int sides = 8;                   // vertices around each ring, >= 3
  int rings = 4;                   // segments along the cylinder part of a capsule, >= 1
  int cap_rings = 2;               // rings of each hemispherical cap (plus a pole), >= 1
  double radius_ratio = 0.15;      // of the bone length
  double min_radius_ratio = 0.02;  // of H
  double max_radius_ratio = 0.04;  // of H
  double leaf_length_ratio = 0.5;  // leaf capsule length, of the parent bone's length
  double blend = 0.25;             // fraction of a bone blended at each end, in (0, 0.5]

  Status Validate() const;
};

// A closed, triangulated capsule mesh with unit normals and weights summing to 1.
// Errors: InvalidArgument for an invalid skeleton (see core::ValidateRawCharacter's
// skeleton rules) or options.
StatusOr<core::RawSkin> MakeProxySkin(const core::RawSkeleton& skeleton,
                                      const ProxySkinOptions& options = {});

}  // namespace motionlod::io
