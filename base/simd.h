// Hot loops in two machine versions, picked at run time: the x86-64 baseline (SSE2) that
// every build runs on, and AVX2 with FMA (x86-64-v3: Intel Core since Haswell, AMD since
// Excavator). A dispatched function passes its body, as a lambda, to
// RunWithWidestSimd.
//
// How: RunWithAvx2Fma<Body> is compiled with `target("avx2,fma")` and `flatten`, which
// inlines the body and everything it calls, so the compiler vectorises its loops 256 bits
// wide and fuses multiplies with adds (Eigen keeps 128-bit packets there: it picks their
// width when it is compiled). Nothing else is compiled for AVX2: what cannot be inlined (a
// function of another file, a recursive one) is called in its baseline version. So no
// AVX2 instruction runs on a CPU without it, and no inline function (Eigen's templates) is
// emitted twice under one name for two instruction sets, as a file compiled with `-mavx2`
// would (the linker keeps one copy for every caller). `noinline` keeps each AVX2 version a
// single function: a dispatched kernel called from two dispatched callers computes bit for
// bit the same for both.
//
// A fused multiply-add rounds once where the baseline rounds twice, so the two versions
// differ in the last bits of their results. MOTIONLOD_SIMD=baseline in the environment
// forces the baseline version, for bakes that are bit for bit the same on every x86-64 CPU
// of a farm, and to test that version on an AVX2 machine; it is read once, at the first call.
#pragma once

#include <cstdlib>
#include <string>
#include <string_view>

namespace motionlod {

// What is wrong with the environment's MOTIONLOD_SIMD, or "" when it is unset, "auto" (the
// widest version this CPU runs) or "baseline". Programs report it as a usage error before
// any work: a misspelt "baseline" must not silently bake another version.
inline std::string SimdSettingProblem() {
  const char* value = std::getenv("MOTIONLOD_SIMD");
  if (value == nullptr) return {};
  const std::string_view setting(value);
  if (setting.empty() || setting == "auto" || setting == "baseline") return {};
  return "MOTIONLOD_SIMD is '" + std::string(setting) + "' ('auto' or 'baseline' expected)";
}

#if defined(__GNUC__) && defined(__x86_64__) && !(defined(__AVX2__) && defined(__FMA__))
#define MOTIONLOD_SIMD_DISPATCH 1

inline bool UseAvx2Fma() {
  static const bool use = [] {
    const char* forced = std::getenv("MOTIONLOD_SIMD");
    if (forced != nullptr && std::string_view(forced) == "baseline") return false;
    return __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
  }();
  return use;
}

template <typename Body>
__attribute__((target("avx2,fma"), flatten, noinline)) auto RunWithAvx2Fma(Body& body) {
  return body();
}

template <typename Body>
auto RunWithWidestSimd(Body&& body) {
  if (UseAvx2Fma()) return RunWithAvx2Fma(body);
  return body();
}
#else
template <typename Body>
auto RunWithWidestSimd(Body&& body) {
  return body();
}
#endif

// The version RunWithWidestSimd runs: "avx2-fma" or "baseline" (a build for x86-64-v3 or
// another architecture has only the one it was compiled for: "native").
inline std::string_view SimdVersionName() {
#ifdef MOTIONLOD_SIMD_DISPATCH
  return UseAvx2Fma() ? "avx2-fma" : "baseline";
#else
  return "native";
#endif
}

}  // namespace motionlod
