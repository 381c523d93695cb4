// `motionlod plot`: the paper's fig. 7 (mean E(t) against kept joints, one curve per
// variant) drawn as a standalone SVG from a report.json.
#pragma once

#include <string>

#include <nlohmann/json.hpp>

#include "base/status.h"

namespace motionlod::tools {

// Uses report["variant_curves"] when present (bake --curves), else the report's own
// levels (one variant plus its unoptimised baseline).
StatusOr<std::string> RenderErrorPlotSvg(const nlohmann::json& report);

}  // namespace motionlod::tools
