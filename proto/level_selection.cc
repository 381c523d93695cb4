#include "proto/level_selection.h"

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
  int chosen = 0;
  for (int l = 0; l < static_cast<int>(max_vertex_error_fraction.size()); ++l) {
    if (max_vertex_error_fraction[l] * pixel_height <= budget_px) chosen = l;
  }
  return chosen;
}

}  // namespace motionlod::proto
