#include "proto/checksum.h"

#include <gtest/gtest.h>

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

namespace motionlod::proto {
namespace {

// Reference digests of the xxHash specification's XXH64, as published with every
// conforming implementation.
TEST(Xxh64, MatchesReferenceDigestsOfShortInputs) {
  EXPECT_EQ(Xxh64(""), 0xEF46DB3751D8E999ull);
  EXPECT_EQ(Xxh64("a"), 0xD24EC4F1A98C6E5Bull);
  EXPECT_EQ(Xxh64("abc"), 0x44BC2CF5AD770999ull);
  EXPECT_EQ(Xxh64("ABC"), 0xE66AE7354FCFEE98ull);
  EXPECT_EQ(Xxh64("xxhash"), 0x32DD38952C4BC720ull);
}

TEST(Xxh64, MatchesReferenceDigestsAroundTheStripeSize) {
  EXPECT_EQ(Xxh64("1234567890123456789012345678901"), 0x8F367CB873A5376Eull);   // 31 bytes
  EXPECT_EQ(Xxh64("12345678901234567890123456789012"), 0x40FD1AA52D98274Cull);  // 32 bytes
  EXPECT_EQ(Xxh64("The quick brown fox jumps over the lazy dog"), 0x0B242D361FDA71BCull);
}

TEST(Xxh64, MatchesReferenceDigestWithSeed) {
  EXPECT_EQ(Xxh64("Nobody inspects the spammish repetition", 123), 0xA8BA45551F24B7AEull);
}

TEST(Xxh64, ChangesWhenAnyBitFlips) {
  std::string text(100, 'x');
  const uint64_t original = Xxh64(text);
  for (size_t i = 0; i < text.size(); ++i) {
    text[i] ^= 1;
    EXPECT_NE(Xxh64(text), original) << "byte " << i;
    text[i] ^= 1;
  }
}

// The stripes in AVX-512 (where this CPU has it) and in scalar code give the same digest:
// every length up to a few stripes past a multiple of 32, at every alignment, with seeds,
// and a level-set-sized input.
TEST(Xxh64, StripesInAvx512AndScalarCodeAgree) {
  std::vector<std::byte> data(300000);
  uint64_t state = 1;
  for (std::byte& b : data) {
    state = state * 6364136223846793005ull + 1442695040888963407ull;
    b = static_cast<std::byte>(state >> 56);
  }
  const std::span<const std::byte> all(data);
  for (size_t offset = 0; offset < 8; ++offset) {
    for (size_t size = 0; size <= 200; ++size) {
      const auto bytes = all.subspan(offset, size);
      for (const uint64_t seed : {uint64_t{0}, uint64_t{123}, ~uint64_t{0}}) {
        EXPECT_EQ(internal::Xxh64(bytes, seed, true), internal::Xxh64(bytes, seed, false))
            << offset << " " << size << " " << seed;
      }
    }
  }
  EXPECT_EQ(internal::Xxh64(all.subspan(3), 0, true), internal::Xxh64(all.subspan(3), 0, false));
  EXPECT_EQ(Xxh64(all), internal::Xxh64(all, 0, false));
}

}  // namespace
}  // namespace motionlod::proto
