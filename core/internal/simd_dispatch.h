// Hot loops in two machine versions, picked at run time from a SimdChoice (core/simd.h):
// the x86-64 baseline (SSE2) that every build runs on, and AVX2 with FMA (x86-64-v3). A
// dispatched function passes its body, as a lambda, to RunWithSimd.
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
#pragma once

#include "core/simd.h"

namespace motionlod::core {

#if defined(__GNUC__) && defined(__x86_64__) && !(defined(__AVX2__) && defined(__FMA__))
#define MOTIONLOD_SIMD_DISPATCH 1

inline bool CpuHasAvx2Fma() {
  return __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
}

template <typename Body>
__attribute__((target("avx2,fma"), flatten, noinline)) auto RunWithAvx2Fma(Body& body) {
  return body();
}

template <typename Body>
auto RunWithSimd(SimdChoice choice, Body&& body) {
  if (choice == SimdChoice::kWidest && CpuHasAvx2Fma()) return RunWithAvx2Fma(body);
  return body();
}
#else
template <typename Body>
auto RunWithSimd(SimdChoice, Body&& body) {
  return body();
}
#endif

}  // namespace motionlod::core
