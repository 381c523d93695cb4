// Content hashing for cache keys: SHA-256 (FIPS 180-4) of a byte string.
#pragma once

#include <string>
#include <string_view>

namespace motionlod::io {

// Lower-case hexadecimal SHA-256 digest of `bytes` (64 characters).
std::string Sha256Hex(std::string_view bytes);

}  // namespace motionlod::io
