// Short vectors of doubles and floats for the hot loops (GCC's and clang's vector
// extensions): Lanes4 and Lanes8f are one 256-bit register each in the AVX2 version
// (core/internal/simd_dispatch.h), two 128-bit ones in the baseline; Lanes2 and Lanes4f one 128-bit register.
// The Unaligned types read or write that many contiguous elements at any address, one
// unaligned load or store each, through AsLanes*. (A memcpy of several into an array of
// vectors went through the stack in 16-byte halves, and each 32-byte read of them then
// waited for the two stores to retire.) Transpose4 turns four Lanes4 into lanes of each
// other in registers.
#pragma once

namespace motionlod::core {

typedef double Lanes2 __attribute__((vector_size(2 * sizeof(double))));
typedef double Lanes4 __attribute__((vector_size(4 * sizeof(double))));
typedef float Lanes4f __attribute__((vector_size(4 * sizeof(float))));
typedef float Lanes8f __attribute__((vector_size(8 * sizeof(float))));

typedef double UnalignedLanes2
    __attribute__((vector_size(2 * sizeof(double)), aligned(alignof(double)), may_alias));
typedef double UnalignedLanes4
    __attribute__((vector_size(4 * sizeof(double)), aligned(alignof(double)), may_alias));
typedef float UnalignedLanes4f
    __attribute__((vector_size(4 * sizeof(float)), aligned(alignof(float)), may_alias));
typedef float UnalignedLanes8f
    __attribute__((vector_size(8 * sizeof(float)), aligned(alignof(float)), may_alias));

inline UnalignedLanes2* AsLanes2(double* x) { return reinterpret_cast<UnalignedLanes2*>(x); }
inline const UnalignedLanes4* AsLanes4(const double* x) {
  return reinterpret_cast<const UnalignedLanes4*>(x);
}
inline UnalignedLanes4* AsLanes4(double* x) { return reinterpret_cast<UnalignedLanes4*>(x); }
inline const UnalignedLanes4f* AsLanes4f(const float* x) {
  return reinterpret_cast<const UnalignedLanes4f*>(x);
}
inline UnalignedLanes4f* AsLanes4f(float* x) { return reinterpret_cast<UnalignedLanes4f*>(x); }
inline const UnalignedLanes8f* AsLanes8f(const float* x) {
  return reinterpret_cast<const UnalignedLanes8f*>(x);
}

// The rows of a 4x4 whose columns are x[0..3]: row a holds lane a of each, in order.
// Unpacks within 128-bit halves, then a swap of halves: no lane-crossing shuffle per
// element.
inline void Transpose4(const Lanes4 x[4], Lanes4 rows[4]) {
  const Lanes4 even01 = __builtin_shufflevector(x[0], x[1], 0, 4, 2, 6);
  const Lanes4 odd01 = __builtin_shufflevector(x[0], x[1], 1, 5, 3, 7);
  const Lanes4 even23 = __builtin_shufflevector(x[2], x[3], 0, 4, 2, 6);
  const Lanes4 odd23 = __builtin_shufflevector(x[2], x[3], 1, 5, 3, 7);
  rows[0] = __builtin_shufflevector(even01, even23, 0, 1, 4, 5);
  rows[1] = __builtin_shufflevector(odd01, odd23, 0, 1, 4, 5);
  rows[2] = __builtin_shufflevector(even01, even23, 2, 3, 6, 7);
  rows[3] = __builtin_shufflevector(odd01, odd23, 2, 3, 6, 7);
}

// to[c + r * to_stride] = from[r + c * from_stride] for r < rows, c < cols (column-major
// blocks, strides in doubles): four by four in registers (Transpose4), the edges element
// by element. Element by element throughout (Eigen's transposed copy), every element was
// a load and a store of its own. Inline, so that a caller's AVX2 version (core/internal/simd_dispatch.h)
// runs it 256 bits wide.
inline void TransposeDoubles(const double* from, long from_stride, long rows, long cols, double* to,
                             long to_stride) {
  long r = 0;
  for (; r + 4 <= rows; r += 4) {
    long c = 0;
    for (; c + 4 <= cols; c += 4) {
      Lanes4 columns[4], transposed[4];
      for (int f = 0; f < 4; ++f) columns[f] = *AsLanes4(from + r + (c + f) * from_stride);
      Transpose4(columns, transposed);
      for (int a = 0; a < 4; ++a) *AsLanes4(to + c + (r + a) * to_stride) = transposed[a];
    }
    for (; c < cols; ++c) {
      for (int a = 0; a < 4; ++a) to[c + (r + a) * to_stride] = from[r + a + c * from_stride];
    }
  }
  for (; r < rows; ++r) {
    for (long c = 0; c < cols; ++c) to[c + r * to_stride] = from[r + c * from_stride];
  }
}

}  // namespace motionlod::core
