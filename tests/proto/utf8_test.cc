#include "proto/utf8.h"

#include <gtest/gtest.h>

#include <string>

namespace motionlod::proto {
namespace {

TEST(IsValidUtf8, AcceptsAsciiAndMultiByteCharacters) {
  EXPECT_TRUE(IsValidUtf8(""));
  EXPECT_TRUE(IsValidUtf8("mixamorig:LeftUpLeg"));
  EXPECT_TRUE(IsValidUtf8("\xC3\xA9paule"));                 // U+00E9
  EXPECT_TRUE(IsValidUtf8("\xE8\x85\x95"));                  // U+8155
  EXPECT_TRUE(IsValidUtf8("\xF0\x9F\xA6\xB4"));              // U+1F9B4
  EXPECT_TRUE(IsValidUtf8("\xEF\xBF\xBF\xF4\x8F\xBF\xBF"));  // U+FFFF, U+10FFFF
}

TEST(IsValidUtf8, RejectsStrayContinuationAndInvalidLeadBytes) {
  EXPECT_FALSE(IsValidUtf8("\x80"));
  EXPECT_FALSE(IsValidUtf8("a\xBF"));
  EXPECT_FALSE(IsValidUtf8("\xFF"));
  EXPECT_FALSE(IsValidUtf8("\xF5\x80\x80\x80"));
}

TEST(IsValidUtf8, RejectsOverlongForms) {
  EXPECT_FALSE(IsValidUtf8("\xC0\xAF"));
  EXPECT_FALSE(IsValidUtf8("\xC1\xBF"));
  EXPECT_FALSE(IsValidUtf8("\xE0\x80\xAF"));
  EXPECT_FALSE(IsValidUtf8("\xF0\x80\x80\xAF"));
}

TEST(IsValidUtf8, RejectsSurrogatesAndCodePointsAboveTheUnicodeRange) {
  EXPECT_FALSE(IsValidUtf8("\xED\xA0\x80"));      // U+D800
  EXPECT_FALSE(IsValidUtf8("\xED\xBF\xBF"));      // U+DFFF
  EXPECT_FALSE(IsValidUtf8("\xF4\x90\x80\x80"));  // U+110000
}

TEST(IsValidUtf8, RejectsTruncatedSequences) {
  EXPECT_FALSE(IsValidUtf8("\xC3"));
  EXPECT_FALSE(IsValidUtf8("\xE8\x85"));
  EXPECT_FALSE(IsValidUtf8("\xF0\x9F\xA6"));
  EXPECT_FALSE(
      IsValidUtf8("\xE8"
                  "a"
                  "\x95"));
}

}  // namespace
}  // namespace motionlod::proto
