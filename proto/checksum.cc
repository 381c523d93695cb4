#include "proto/checksum.h"

#include <bit>
#include <cstring>

#if defined(__GNUC__) && defined(__x86_64__)
#include <immintrin.h>
#endif

namespace motionlod::proto {
namespace {

constexpr uint64_t kPrime1 = 0x9E3779B185EBCA87ull;
constexpr uint64_t kPrime2 = 0xC2B2AE3D27D4EB4Full;
constexpr uint64_t kPrime3 = 0x165667B19E3779F9ull;
constexpr uint64_t kPrime4 = 0x85EBCA77C2B2AE63ull;
constexpr uint64_t kPrime5 = 0x27D4EB2F165667C5ull;

// The wire contract is little-endian and so are the hosts proto builds for (see
// level_format.h); loads at any alignment (memcpy compiles to one mov on x86 and ARM).
static_assert(std::endian::native == std::endian::little, "proto assumes a little-endian host");

uint64_t Load64(const unsigned char* p) {
  uint64_t v;
  std::memcpy(&v, p, sizeof v);
  return v;
}
uint32_t Load32(const unsigned char* p) {
  uint32_t v;
  std::memcpy(&v, p, sizeof v);
  return v;
}

uint64_t Round(uint64_t acc, uint64_t input) {
  acc += input * kPrime2;
  acc = std::rotl(acc, 31);
  return acc * kPrime1;
}

uint64_t MergeRound(uint64_t acc, uint64_t value) {
  acc ^= Round(0, value);
  return acc * kPrime1 + kPrime4;
}

// The stripes, the bulk of a long input's hash: `stripes` 32-byte stripes from p into the
// four lanes' accumulators v. Each lane is a chain of 64-bit multiplies, so one core goes
// as fast as its scalar multiplier takes them (about 4 bytes a cycle).
void Stripes(const unsigned char* p, size_t stripes, uint64_t (&v)[4]) {
  for (size_t s = 0; s < stripes; ++s, p += 32) {
    v[0] = Round(v[0], Load64(p));
    v[1] = Round(v[1], Load64(p + 8));
    v[2] = Round(v[2], Load64(p + 16));
    v[3] = Round(v[3], Load64(p + 24));
  }
}

#if defined(__GNUC__) && defined(__x86_64__)
// The same with the four lanes in one AVX-512 register (VPMULLQ multiplies 64-bit lanes).
// Each lane is a chain of two multiplies per stripe, so the multiply's latency sets the
// speed: VPMULLQ takes 3 cycles on AMD's Zen 4 and 5, where this is twice as fast as the
// scalar chains (Fox's 260 KB level set: 13.6 us), and 15 cycles on Intel's cores, where
// it is twice as slow (38.6 us against 18.2 on a Xeon with AVX-512).
__attribute__((target("avx512f,avx512vl,avx512dq"))) void StripesAvx512(const unsigned char* p,
                                                                        size_t stripes,
                                                                        uint64_t (&v)[4]) {
  __m256i lanes = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(v));
  const __m256i prime1 = _mm256_set1_epi64x(static_cast<long long>(kPrime1));
  const __m256i prime2 = _mm256_set1_epi64x(static_cast<long long>(kPrime2));
  for (size_t s = 0; s < stripes; ++s, p += 32) {
    const __m256i input = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(p));
    lanes = _mm256_add_epi64(lanes, _mm256_mullo_epi64(input, prime2));
    lanes = _mm256_mullo_epi64(_mm256_rol_epi64(lanes, 31), prime1);
  }
  _mm256_storeu_si256(reinterpret_cast<__m256i*>(v), lanes);
}

bool HasAvx512Multiplies() {
  static const bool has = __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512vl") &&
                          __builtin_cpu_supports("avx512dq");
  return has;
}
#endif

// Whether StripesAvx512 is the faster version on this CPU (see there).
bool Avx512StripesAreFaster() {
#if defined(__GNUC__) && defined(__x86_64__)
  static const bool faster = __builtin_cpu_is("amd") && HasAvx512Multiplies();
  return faster;
#else
  return false;
#endif
}

}  // namespace

namespace internal {

uint64_t Xxh64(std::span<const std::byte> bytes, uint64_t seed, bool avx512) {
  const auto* p = reinterpret_cast<const unsigned char*>(bytes.data());
  const size_t size = bytes.size();
  const unsigned char* const end = p + size;
  uint64_t h;
  if (size >= 32) {
    // Four independent lanes over 32-byte stripes: the multiply latency overlaps.
    uint64_t v[4] = {seed + kPrime1 + kPrime2, seed + kPrime2, seed, seed - kPrime1};
    const size_t stripes = size / 32;
#if defined(__GNUC__) && defined(__x86_64__)
    if (avx512 && HasAvx512Multiplies()) {
      StripesAvx512(p, stripes, v);
    } else {
      Stripes(p, stripes, v);
    }
#else
    (void)avx512;
    Stripes(p, stripes, v);
#endif
    p += 32 * stripes;
    h = std::rotl(v[0], 1) + std::rotl(v[1], 7) + std::rotl(v[2], 12) + std::rotl(v[3], 18);
    for (const uint64_t lane : v) h = MergeRound(h, lane);
  } else {
    h = seed + kPrime5;
  }
  h += static_cast<uint64_t>(size);
  while (end - p >= 8) {
    h ^= Round(0, Load64(p));
    h = std::rotl(h, 27) * kPrime1 + kPrime4;
    p += 8;
  }
  if (end - p >= 4) {
    h ^= static_cast<uint64_t>(Load32(p)) * kPrime1;
    h = std::rotl(h, 23) * kPrime2 + kPrime3;
    p += 4;
  }
  while (p < end) {
    h ^= static_cast<uint64_t>(*p) * kPrime5;
    h = std::rotl(h, 11) * kPrime1;
    ++p;
  }
  h ^= h >> 33;
  h *= kPrime2;
  h ^= h >> 29;
  h *= kPrime3;
  h ^= h >> 32;
  return h;
}

}  // namespace internal

uint64_t Xxh64(std::span<const std::byte> bytes, uint64_t seed) {
  return internal::Xxh64(bytes, seed, Avx512StripesAreFaster());
}

uint64_t Xxh64(std::string_view bytes, uint64_t seed) {
  return Xxh64(std::as_bytes(std::span(bytes.data(), bytes.size())), seed);
}

}  // namespace motionlod::proto
