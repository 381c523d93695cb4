#include "client/level_selector.h"

#include <algorithm>
#include <cmath>

#include "proto/level_selection.h"

namespace motionlod::client {

Result<LevelSelector> LevelSelector::Create(std::vector<double> max_vertex_error_pct,
                                            const SelectorSettings& settings) {
  auto invalid = [](std::string message) {
    return Error{ErrorKind::kInvalidArgument, 0, std::nullopt, std::move(message)};
  };
  if (max_vertex_error_pct.empty()) return invalid("the level table is empty");
  if (!(settings.budget_px > 0) || !std::isfinite(settings.budget_px))
    return invalid("budget_px must be a positive number of pixels");
  if (!(settings.hysteresis >= 0 && settings.hysteresis < 1))
    return invalid("hysteresis must be in [0, 1)");
  LevelSelector selector;
  selector.settings_ = settings;
  for (double pct : max_vertex_error_pct) {
    if (!(pct >= 0) || !std::isfinite(pct))
      return invalid("level errors must be finite percentages >= 0");
    selector.max_error_fraction_.push_back(pct / 100.0);
  }
  return selector;
}

Result<LevelSelector> LevelSelector::FromBake(const proto::api::BakeInfo& bake,
                                              const SelectorSettings& settings) {
  std::vector<double> errors;
  for (const proto::api::LevelEntry& level : bake.levels) errors.push_back(level.max_vertex_error_pct);
  if (errors.empty()) {
    return Error{ErrorKind::kInvalidArgument, 0, std::nullopt,
                 "bake " + bake.id + " has no level table (state " + bake.state + ")"};
  }
  return Create(std::move(errors), settings);
}

int LevelSelector::Choose(double pixel_height, int current) const {
  const int plain = proto::SelectLevel(max_error_fraction_, pixel_height, settings_.budget_px);
  if (current < 0 || current >= level_count() || plain <= current) return plain;
  // Coarser only with the margin: the level must hold the budget at a larger height.
  const int with_margin =
      proto::SelectLevel(max_error_fraction_, pixel_height * (1 + settings_.hysteresis),
                         settings_.budget_px);
  return std::max(current, with_margin);
}

}  // namespace motionlod::client
