// io keeps Assimp and OpenSSL private: no public io header may include them (or a logger).
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

namespace motionlod::io {
namespace {

TEST(IoHeaders, PublicHeadersIncludeNeitherAssimpNorOpenSslNorALogger) {
  const std::filesystem::path io = std::filesystem::path(MOTIONLOD_SOURCE_DIR) / "io";
  ASSERT_TRUE(std::filesystem::exists(io));
  int headers = 0;
  for (const auto& entry : std::filesystem::directory_iterator(io)) {
    if (entry.path().extension() != ".h") continue;
    ++headers;
    std::ifstream in(entry.path());
    std::string line;
    while (std::getline(in, line)) {
      if (line.rfind("#include", 0) != 0) continue;
      EXPECT_EQ(line.find("assimp"), std::string::npos) << entry.path() << ": " << line;
      EXPECT_EQ(line.find("openssl"), std::string::npos) << entry.path() << ": " << line;
      EXPECT_EQ(line.find("spdlog"), std::string::npos) << entry.path() << ": " << line;
    }
  }
  EXPECT_GE(headers, 4);
}

TEST(IoSources, OnlyTheAssimpDoorIncludesAssimp) {
  const std::filesystem::path io = std::filesystem::path(MOTIONLOD_SOURCE_DIR) / "io";
  for (const auto& entry : std::filesystem::directory_iterator(io)) {
    if (entry.path().extension() != ".cc" || entry.path().filename() == "assimp_scene.cc") continue;
    std::ifstream in(entry.path());
    std::stringstream text;
    text << in.rdbuf();
    EXPECT_EQ(text.str().find("#include <assimp"), std::string::npos) << entry.path();
  }
}

}  // namespace
}  // namespace motionlod::io
