// Checksums of the wire contract. XXH64 is the standard 64-bit xxHash (seed 0 in the
// level format), written here from its public specification so that proto needs no
// dependency; any xxHash library in another language computes the same value.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <string_view>

namespace motionlod::proto {

// XXH64 of `bytes` with `seed`. Reads the input as little-endian words at any
// alignment; about 14 GB/s on one core in scalar code and twice that with AVX-512 on AMD's
// Zen 4 and later, so checking a whole level set costs less than reading it from disk.
uint64_t Xxh64(std::span<const std::byte> bytes, uint64_t seed = 0);
uint64_t Xxh64(std::string_view bytes, uint64_t seed = 0);

namespace internal {
// Xxh64 with its 32-byte stripes in AVX-512 where `avx512` and this CPU has it, in scalar
// code otherwise: the same value either way, which tests compare. Xxh64 asks for AVX-512
// where it is the faster (AMD's cores; Intel's multiply 64-bit lanes too slowly).
uint64_t Xxh64(std::span<const std::byte> bytes, uint64_t seed, bool avx512);
}  // namespace internal

}  // namespace motionlod::proto
