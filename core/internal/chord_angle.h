// Angles between unit vectors from their chords (internal to the core). The angle between
// unit vectors u and w is 2 asin(|u - w| / 2): exact to rounding at every angle, where acos
// of their dot product keeps only half the digits of a small angle (acos(1 - e) ~ sqrt(2e)).
#pragma once

#include <algorithm>
#include <cmath>

namespace motionlod::core {

// 2 asin(x) for a half chord x = |u - w| / 2 up to 0.25 (angles up to 29 degrees, where
// most are), by the series of asin (its first omitted term is below 3e-12 of the result);
// past it -x, for FinishChordAngle. Without a branch or a call, so that a loop over many
// angles vectorises; a NaN x stays NaN.
inline double ChordAngleOrMarker(double x) {
  const double x2 = x * x, x4 = x2 * x2, x8 = x4 * x4;
  // asin x = sum_k (2k)! / (4^k (k!)^2 (2k+1)) x^(2k+1), k = 0..7, in Estrin's order:
  // three dependent multiply-adds instead of Horner's eight, which made the loops wait on
  // their own latency.
  const double series =
      2 * x *
      ((1 + x2 * (1.0 / 6)) + x4 * (3.0 / 40 + x2 * (5.0 / 112)) +
       x8 * ((35.0 / 1152 + x2 * (63.0 / 2816)) + x4 * (231.0 / 13312 + x2 * (143.0 / 10240))));
  return x <= 0.25 ? series : -x;
}

// The angle from ChordAngleOrMarker's result (not NaN).
inline double FinishChordAngle(double angle_or_marker) {
  return angle_or_marker >= 0 ? angle_or_marker : 2 * std::asin(std::min(-angle_or_marker, 1.0));
}

}  // namespace motionlod::core
