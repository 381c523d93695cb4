// Checksums of the wire contract. XXH64 is the standard 64-bit xxHash (seed 0 in the
// level format), computed by the xxHash library, so that any xxHash implementation in
// another language computes the same value.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <string_view>

namespace motionlod::proto {

// XXH64 of `bytes` with `seed`, at any alignment.
uint64_t Xxh64(std::span<const std::byte> bytes, uint64_t seed = 0);
uint64_t Xxh64(std::string_view bytes, uint64_t seed = 0);

}  // namespace motionlod::proto
