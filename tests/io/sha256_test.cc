#include "io/sha256.h"

#include <gtest/gtest.h>

#include <string>

namespace motionlod::io {
namespace {

// Test vectors of FIPS 180-4 (NIST "SHA256.pdf" examples and the CAVP short messages).
TEST(Sha256Hex, EmptyMessage) {
  EXPECT_EQ(Sha256Hex(""), "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855");
}

TEST(Sha256Hex, Abc) {
  EXPECT_EQ(Sha256Hex("abc"), "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
}

TEST(Sha256Hex, TwoBlockMessage) {
  EXPECT_EQ(Sha256Hex("abcdbcdecdefdefgefghfghighijhijkijkljklmklmnlmnomnopnopq"),
            "248d6a61d20638b8e5c026930c3e6039a33ce45964ff2167f6ecedd419db06c1");
}

TEST(Sha256Hex, LongMessage896Bits) {
  EXPECT_EQ(
      Sha256Hex(
          "abcdefghbcdefghicdefghijdefghijkefghijklfghijklmghijklmnhijklmnoijklmnopjklmnopqklmnopqr"
          "lmnopqrsmnopqrstnopqrstu"),
      "cf5b16a778af8380036ce59e7b0492370b249b11e8f07a51afac45037afee9d1");
}

TEST(Sha256Hex, MillionAs) {
  EXPECT_EQ(Sha256Hex(std::string(1000000, 'a')),
            "cdc76e5c9914fb9281a1c7e284d73e67f1809a48a497200e046d39ccc7112cd0");
}

TEST(Sha256Hex, BinaryBytesWithNul) {
  const std::string bytes("\x00\xff\x00", 3);
  const std::string hex = Sha256Hex(bytes);
  EXPECT_EQ(hex.size(), 64u);
  EXPECT_NE(hex, Sha256Hex(std::string("\x00\xff", 2)));
}

}  // namespace
}  // namespace motionlod::io
