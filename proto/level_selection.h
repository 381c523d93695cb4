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
#include <vector>

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

// The level choice, the one every consumer makes (the server's `level?px=` and level table,
// the client's LevelSelector, the viewer's crowd in web/src/level_choice.js). Levels are
// ordered finest first (index 0 the full or finest skeleton); level l's limit is
// MaxPixelHeightForBudget(max_vertex_error_fraction[l], budget_px). At `pixel_height` the
// choice is
//   * the coarsest level within the budget there (pixel_height <= its limit);
//   * when none is (taller than every limit), the coarsest of the most accurate levels
//     (those with the largest limit): the best a taller character can get.
// That is, the coarsest l whose limit is >= min(pixel_height, the largest limit). The rule
// does not assume that errors grow as levels get coarser: a coarser level can be exact
// (it drops only joints that move no vertex, such as pole targets) or more accurate than
// a finer one, and then the finer one is never chosen. The choice only gets finer as
// pixel_height grows, so each level is chosen on one interval of heights (LevelRanges).
// Errors are finite and >= 0 (the level format's rule), budget_px > 0; a NaN height gets
// the most accurate level. 0 for an empty table.
int SelectLevel(std::span<const double> max_vertex_error_fraction, double pixel_height,
                double budget_px);

// The on-screen heights (pixels) at which SelectLevel picks a level: (px_min, px_max].
struct LevelRange {
  bool chosen = false;  // false: picked at no height (a coarser level is as accurate); 0, 0
  double px_min = 0;    // exclusive
  double px_max = 0;    // inclusive; +inf for the level that serves every larger height
};

// One range per level, finest first. The chosen levels' ranges partition (0, +inf): none
// is empty, none overlaps another, the coarsest level's starts at 0, each next finer
// chosen level's starts where the previous one ends, and the last one is unbounded.
std::vector<LevelRange> LevelRanges(std::span<const double> max_vertex_error_fraction,
                                    double budget_px);

}  // namespace motionlod::proto
