// The bake request's clips and ranking as the daemon parses them, and the query encoding
// of a clip's name.
#include "proto/api.h"

#include <gtest/gtest.h>

#include <string>

namespace motionlod::proto::api {
namespace {

const std::string kCharacter = std::string(64, 'a');

std::string WithCharacter(const std::string& fields) {
  return "{\"character\":\"" + kCharacter + "\"" + (fields.empty() ? "" : "," + fields) + "}";
}

TEST(ParseBakeRequest, TakesClipsInOrderAndTheRanking) {
  auto request = ParseBakeRequest(WithCharacter(R"("clips":["Run","Walk"],"ranking":"paper")"));
  ASSERT_TRUE(request.ok()) << request.status().message();
  EXPECT_EQ(request->clips, (std::vector<std::string>{"Run", "Walk"}));
  EXPECT_EQ(request->ranking, "paper");
  EXPECT_TRUE(request->motion.empty());
  auto defaults = ParseBakeRequest(WithCharacter(""));
  ASSERT_TRUE(defaults.ok());
  EXPECT_TRUE(defaults->clips.empty()) << "neither motion nor clips: every motion";
  EXPECT_EQ(defaults->ranking, "greedy");
}

TEST(ParseBakeRequest, RefusesBadClipsAndRankingsNamingTheField) {
  for (const char* fields :
       {R"("motion":"Walk","clips":["Run"])", R"("clips":[])", R"("clips":"Walk")",
        R"("clips":[""])", R"("clips":[1])", R"("ranking":"best")", R"("ranking":null,"clips":{})",
        R"("ranking":2)"}) {
    auto request = ParseBakeRequest(WithCharacter(fields));
    ASSERT_FALSE(request.ok()) << fields;
    EXPECT_EQ(request.status().code(), StatusCode::kInvalidArgument);
    const std::string message = request.status().message();
    EXPECT_TRUE(message.find("'clips'") != std::string::npos ||
                message.find("'ranking'") != std::string::npos)
        << fields << ": " << message;
  }
}

TEST(ParseBakeRequest, ARequestSerialisesToJsonThatParsesToItself) {
  for (const char* fields :
       {"", R"("motion":"Walk")", R"("clips":["Run","Walk"],"ranking":"paper")"}) {
    auto request = ParseBakeRequest(WithCharacter(fields));
    ASSERT_TRUE(request.ok()) << fields;
    const std::string text = nlohmann::json(*request).dump();
    auto again = ParseBakeRequest(text);
    ASSERT_TRUE(again.ok()) << text << ": " << again.status().message();
    EXPECT_EQ(nlohmann::json(*again).dump(), text);
  }
}

TEST(EncodeQueryValue, KeepsUnreservedCharactersAndEscapesEveryOtherByte) {
  EXPECT_EQ(EncodeQueryValue("Walking_A-1.5~"), "Walking_A-1.5~");
  EXPECT_EQ(EncodeQueryValue("a b&c=d/e?f#g+h%"), "a%20b%26c%3Dd%2Fe%3Ff%23g%2Bh%25");
  EXPECT_EQ(EncodeQueryValue("\xc3\xa9"), "%C3%A9");
  EXPECT_EQ(EncodeQueryValue(""), "");
}

}  // namespace
}  // namespace motionlod::proto::api
