// Step 6 (sec. 5, fig. 5): which level to draw a character with. Pure arithmetic on the
// level table's figures, in proto so that the server, the bake's report and the thin client
// (which must not depend on the core or Eigen) use the same formulas.
//   x = theta / fov * H,  theta = atan(s / d)
// s: character size (length), d: camera distance (same length unit), fov: vertical
// field of view (radians), H: screen height (pixels), x: character height (pixels).
// Beyond the paper's fixed thresholds, the choice is error-driven: the coarsest level
// whose maximum vertex deviation, projected at x pixels, stays within a pixel budget.
#pragma once

#include <span>

namespace motionlod::proto {

struct CameraView {
  double fov_y_radians = 0.0;      // vertical field of view, (0, pi)
  double distance = 0.0;           // camera to character, > 0
  double character_size = 0.0;     // s, > 0, same unit as distance
  double screen_height_px = 0.0;   // H, > 0
};

// x in pixels; 0 for an invalid view (non-positive or non-finite parameters).
double PixelHeight(const CameraView& view);

// Tallest on-screen height (pixels) at which a level with this maximum vertex deviation
// (a fraction of the character's height) stays within `budget_px`; +inf when exact.
double MaxPixelHeightForBudget(double max_vertex_error_fraction, double budget_px);

// Levels ordered finest first (index 0 the full or finest skeleton). Returns the index of
// the coarsest level whose max deviation at `pixel_height` is within `budget_px`, and 0
// when none is (the finest level is the best available).
int SelectLevel(std::span<const double> max_vertex_error_fraction, double pixel_height,
                double budget_px);

}  // namespace motionlod::proto
