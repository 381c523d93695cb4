#include "proto/checksum.h"

#include <gtest/gtest.h>

#include <cstdint>
#include <string>

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

}  // namespace
}  // namespace motionlod::proto
