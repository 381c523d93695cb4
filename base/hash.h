// FNV-1a, 64 bit: a fast, stable hash for settings keys and format checksums (not for
// security; content addresses use SHA-256).
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <string_view>

namespace motionlod {

inline constexpr uint64_t kFnv1a64Offset = 0xcbf29ce484222325ull;

inline uint64_t Fnv1a64(const void* data, size_t size, uint64_t hash = kFnv1a64Offset) {
  const auto* bytes = static_cast<const unsigned char*>(data);
  for (size_t i = 0; i < size; ++i) {
    hash ^= bytes[i];
    hash *= 0x100000001b3ull;
  }
  return hash;
}

inline uint64_t Fnv1a64(std::string_view text, uint64_t hash = kFnv1a64Offset) {
  return Fnv1a64(text.data(), text.size(), hash);
}

// Hashes the object representation of a trivially copyable value (fixed-size fields only).
template <typename T>
uint64_t Fnv1a64Value(const T& value, uint64_t hash) {
  unsigned char bytes[sizeof(T)];
  std::memcpy(bytes, &value, sizeof(T));
  return Fnv1a64(bytes, sizeof(T), hash);
}

}  // namespace motionlod
