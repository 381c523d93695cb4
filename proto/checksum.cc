#include "proto/checksum.h"

#include <xxhash.h>

namespace motionlod::proto {

uint64_t Xxh64(std::span<const std::byte> bytes, uint64_t seed) {
  return XXH64(bytes.data(), bytes.size(), seed);
}

uint64_t Xxh64(std::string_view bytes, uint64_t seed) {
  return XXH64(bytes.data(), bytes.size(), seed);
}

}  // namespace motionlod::proto
