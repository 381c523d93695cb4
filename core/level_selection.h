// Step 6 (sec. 5, fig. 5): which level to draw a character with. The formulas are pure
// arithmetic and live in base/level_selection.h, so that the thin client (which must not
// depend on the core) uses the same ones; the core names them here.
#pragma once

#include "base/level_selection.h"

namespace motionlod::core {

using ::motionlod::CameraView;
using ::motionlod::MaxPixelHeightForBudget;
using ::motionlod::PixelHeight;
using ::motionlod::SelectLevel;

}  // namespace motionlod::core
