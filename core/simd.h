// Which machine version of the core's hot loops runs: a setting the programs pass down
// (they read MOTIONLOD_SIMD; the core reads no environment). The versions are the x86-64
// baseline (SSE2) and AVX2 with FMA (core/internal/simd_dispatch.h); a fused multiply-add
// rounds once where the baseline rounds twice, so they differ in the last bits of results.
// kBaseline makes bakes bit for bit the same on every x86-64 CPU of a farm.
#pragma once

#include <string_view>

#include "base/status.h"

namespace motionlod::core {

enum class SimdChoice {
  kWidest,    // the widest version this CPU runs ("auto")
  kBaseline,  // the baseline version everywhere ("baseline")
};

// "auto" (or "") and "baseline"; anything else is an error that names the value.
StatusOr<SimdChoice> ParseSimdChoice(std::string_view text);

// The version a choice runs on this CPU: "avx2-fma" or "baseline" ("native" for a build
// that has one version only: compiled for x86-64-v3 or for another architecture).
const char* SimdVersionName(SimdChoice choice);

}  // namespace motionlod::core
