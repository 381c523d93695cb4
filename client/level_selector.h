// Level choice on the client, per character and per frame: the on-screen height from the
// camera (proto/level_selection.h, the paper's fig. 5) against the bake's level table,
// with hysteresis so that a character hovering at a threshold does not switch level
// every frame.
//
// Rule (levels finest first, l = 0 the finest): the plain choice is proto::SelectLevel,
// the coarsest level whose max vertex error at `px` pixels is within the budget (the
// coarsest of the most accurate levels when none is), the daemon's and the viewer's
// choice too. A character moves to a finer level as soon as its current one exceeds the
// budget (the budget is never broken for the sake of stability), but to a coarser one
// only when that level would still be within the budget at px x (1 + hysteresis): it
// must shrink by that margin past the threshold before it gets coarser again.
#pragma once

#include <vector>

#include "client/error.h"
#include "proto/api.h"
#include "proto/level_format.h"

namespace motionlod::client {

struct SelectorSettings {
  double budget_px = 1.0;   // the largest visible vertex error allowed, pixels
  double hysteresis = 0.1;  // relative margin in on-screen height, [0, 1)
};

class LevelSelector {
 public:
  // From the max vertex errors of the levels (percent of the character's height, finest
  // first). kInvalidArgument when empty, negative or not finite, or settings out of range.
  static Result<LevelSelector> Create(std::vector<double> max_vertex_error_pct,
                                      const SelectorSettings& settings = {});
  // From a finished bake's level table (GET /v1/bakes/{id}).
  static Result<LevelSelector> FromBake(const proto::api::BakeInfo& bake,
                                        const SelectorSettings& settings = {});

  // The level for a character `pixel_height` pixels tall that is drawn with `current`
  // now (-1: none yet, the plain choice).
  int Choose(double pixel_height, int current) const;
  int level_count() const { return static_cast<int>(max_error_fraction_.size()); }
  const SelectorSettings& settings() const { return settings_; }

 private:
  LevelSelector() = default;
  std::vector<double> max_error_fraction_;  // per level, of the character's height
  SelectorSettings settings_;
};

}  // namespace motionlod::client
