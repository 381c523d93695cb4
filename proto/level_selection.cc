#include "proto/level_selection.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>

namespace motionlod::proto {

double PixelHeight(const CameraView& view) {
  const bool valid = view.fov_y_radians > 0 && view.fov_y_radians < std::numbers::pi &&
                     view.distance > 0 && view.character_size > 0 && view.screen_height_px > 0 &&
                     std::isfinite(view.distance) && std::isfinite(view.character_size) &&
                     std::isfinite(view.screen_height_px);
  if (!valid) return 0.0;
  const double theta = std::atan(view.character_size / view.distance);
  return theta / view.fov_y_radians * view.screen_height_px;
}

double MaxPixelHeightForBudget(double max_vertex_error_fraction, double budget_px) {
  if (!(max_vertex_error_fraction > 0)) return std::numeric_limits<double>::infinity();
  return budget_px / max_vertex_error_fraction;
}

int SelectLevel(std::span<const double> max_vertex_error_fraction, double pixel_height,
                double budget_px) {
  double largest_limit = 0;
  for (double error : max_vertex_error_fraction) {
    largest_limit = std::max(largest_limit, MaxPixelHeightForBudget(error, budget_px));
  }
  // Taller than every limit (or NaN): as if at the largest limit, where the coarsest of the
  // most accurate levels is within the budget.
  const double height = pixel_height < largest_limit ? pixel_height : largest_limit;
  for (int l = static_cast<int>(max_vertex_error_fraction.size()) - 1; l > 0; --l) {
    if (MaxPixelHeightForBudget(max_vertex_error_fraction[l], budget_px) >= height) return l;
  }
  return 0;
}

std::vector<LevelRange> LevelRanges(std::span<const double> max_vertex_error_fraction,
                                    double budget_px) {
  std::vector<LevelRange> ranges(max_vertex_error_fraction.size());
  // From the coarsest level up: a level is chosen above the largest limit of the coarser
  // levels (`covered`, up to which one of them is) and up to its own limit; a level whose
  // limit does not exceed `covered` is never chosen.
  double covered = 0;
  LevelRange* finest_chosen = nullptr;
  for (size_t l = ranges.size(); l-- > 0;) {
    const double limit = MaxPixelHeightForBudget(max_vertex_error_fraction[l], budget_px);
    if (!(limit > covered)) continue;
    ranges[l] = {.chosen = true, .px_min = covered, .px_max = limit};
    covered = limit;
    finest_chosen = &ranges[l];
  }
  // The level with the largest limit also serves every taller character (SelectLevel).
  if (finest_chosen != nullptr) finest_chosen->px_max = std::numeric_limits<double>::infinity();
  return ranges;
}

}  // namespace motionlod::proto
