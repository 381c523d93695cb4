// The fuzzers' assertion: a broken invariant aborts, which libFuzzer reports as a crash
// with its input (assert() would vanish under NDEBUG).
#pragma once

#include <cstdlib>

namespace motionlod::fuzz {

inline void Check(bool condition) {
  if (!condition) std::abort();
}

}  // namespace motionlod::fuzz
