#include "core/simd.h"

#include <string>
#include <utility>

#include "core/internal/simd_dispatch.h"

namespace motionlod::core {

StatusOr<SimdChoice> ParseSimdChoice(std::string_view text) {
  if (text.empty() || text == "auto") return SimdChoice::kWidest;
  if (text == "baseline") return SimdChoice::kBaseline;
  std::string message = "'";
  message.append(text).append("' ('auto' or 'baseline' expected)");
  return InvalidArgument(std::move(message));
}

const char* SimdVersionName(SimdChoice choice) {
#ifdef MOTIONLOD_SIMD_DISPATCH
  return choice == SimdChoice::kWidest && CpuHasAvx2Fma() ? "avx2-fma" : "baseline";
#else
  (void)choice;
  return "native";
#endif
}

}  // namespace motionlod::core
