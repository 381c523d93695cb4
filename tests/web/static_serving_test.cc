// The web viewer's static files: what LoadWebAssets lists (and never lists), and what
// a real motionlodd answers for them over HTTP: content types, cache and security headers,
// 304, 404 for unknown paths and for every traversal attempt, and "/" without a built
// viewer.
#include <gtest/gtest.h>
#include <httplib.h>

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <tuple>
#include <vector>

#include "server/web_assets.h"
#include "tests/server/daemon.h"

namespace motionlod::server {
namespace {

namespace fs = std::filesystem;
using testing::Daemon;
using testing::TestDirectory;

void Write(const fs::path& path, const std::string& bytes) {
  fs::create_directories(path.parent_path());
  std::ofstream(path, std::ios::binary) << bytes;
}

const std::string kIndex = "<!doctype html><title>viewer</title><script src=./assets/app-1a2b.js>";
const std::string kScript = "console.log('motionlod');\n";
const std::string kSecret = "outside the web root\n";

// root/: what Vite writes, plus what must never be served.
fs::path MakeWebRoot(const fs::path& dir) {
  const fs::path root = dir / "dist";
  Write(root / "index.html", kIndex);
  Write(root / "assets" / "app-1a2b.js", kScript);
  Write(root / "assets" / "app-1a2b.css", "body{}");
  Write(root / "favicon.svg", "<svg xmlns='http://www.w3.org/2000/svg'/>");
  Write(root / "data" / "levels.json", "{}");
  Write(root / ".hidden.js", "hidden");
  Write(root / "bad name.js", "space");
  Write(root / "notes.unknownext", "no type");
  Write(root / "Makefile", "no extension");
  Write(root / "a" / "b" / "c" / "d" / "too-deep.js", "deep");
  Write(dir / "secret.txt", kSecret);
  fs::create_symlink(dir / "secret.txt", root / "link.txt");
  fs::create_directory_symlink(dir, root / "up");
  return root;
}

TEST(WebAssets, ListsOnlyPlainFilesOfKnownTypesUnderTheRoot) {
  const fs::path dir = TestDirectory();
  auto assets = LoadWebAssets(MakeWebRoot(dir).string());
  ASSERT_TRUE(assets.ok()) << assets.status().message();
  std::vector<std::string> paths;
  for (const WebFile& file : assets->files) paths.push_back(file.url_path);
  EXPECT_EQ(paths, (std::vector<std::string>{"/assets/app-1a2b.css", "/assets/app-1a2b.js",
                                             "/data/levels.json", "/favicon.svg", "/index.html"}));
  ASSERT_NE(assets->index(), nullptr);
  EXPECT_EQ(*assets->index()->bytes, kIndex);
  EXPECT_EQ(assets->index()->content_type, "text/html; charset=utf-8");
  EXPECT_EQ(assets->index()->cache_control, "no-cache");
  // The entity tag is the SHA-256 of the bytes, quoted.
  EXPECT_EQ(assets->index()->etag.size(), 66u);
  for (const WebFile& file : assets->files) {
    if (file.url_path == "/assets/app-1a2b.js") {
      EXPECT_EQ(file.content_type, "text/javascript; charset=utf-8");
      EXPECT_EQ(file.cache_control, "public, max-age=31536000, immutable");
      EXPECT_EQ(*file.bytes, kScript);
    }
  }
  fs::remove_all(dir);
}

TEST(WebAssets, RefusesARootWithoutIndexOrMissing) {
  const fs::path dir = TestDirectory();
  auto missing = LoadWebAssets((dir / "nowhere").string());
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.status().code(), StatusCode::kNotFound);
  Write(dir / "dist" / "app.js", kScript);
  auto no_index = LoadWebAssets((dir / "dist").string());
  ASSERT_FALSE(no_index.ok());
  EXPECT_NE(no_index.status().message().find("index.html"), std::string::npos);
  EXPECT_FALSE(LoadWebAssets("").ok());
  fs::remove_all(dir);
}

TEST(WebAssets, ContentTypesByExtension) {
  EXPECT_EQ(WebContentType("index.html"), "text/html; charset=utf-8");
  EXPECT_EQ(WebContentType("INDEX.HTML"), "text/html; charset=utf-8");
  EXPECT_EQ(WebContentType("index-3f9c.js"), "text/javascript; charset=utf-8");
  EXPECT_EQ(WebContentType("index-3f9c.css"), "text/css; charset=utf-8");
  EXPECT_EQ(WebContentType("logo.svg"), "image/svg+xml");
  EXPECT_EQ(WebContentType("shot.png"), "image/png");
  EXPECT_EQ(WebContentType("app.js.map"), "application/json");
  EXPECT_EQ(WebContentType("font.woff2"), "font/woff2");
  EXPECT_EQ(WebContentType("Makefile"), "");
  EXPECT_EQ(WebContentType("archive.tar"), "");
}

class WebServing : public ::testing::Test {
 protected:
  void SetUp() override {
    root_ = MakeWebRoot(TestDirectory() / "site");
    daemon_ = std::make_unique<Daemon>(root_.parent_path().parent_path());
    ASSERT_TRUE(daemon_->Start({"--web-root", root_.string()})) << daemon_->error;
    client_ = daemon_->Client();
  }

  void ExpectNotFound(const std::string& path) {
    auto result = client_->Get(path.c_str());
    ASSERT_TRUE(result) << path;
    EXPECT_EQ(result->status, 404) << path;
    EXPECT_EQ(result->get_header_value("Content-Type"), "application/problem+json") << path;
    EXPECT_EQ(result->body.find(kSecret), std::string::npos) << path;
    EXPECT_EQ(result->body.find(kScript), std::string::npos) << path;
  }

  fs::path root_;
  std::unique_ptr<Daemon> daemon_;
  std::unique_ptr<httplib::Client> client_;
};

TEST_F(WebServing, ServesTheListedFilesWithTypesAndCacheHeaders) {
  for (const char* path : {"/", "/index.html"}) {
    auto page = client_->Get(path);
    ASSERT_TRUE(page);
    EXPECT_EQ(page->status, 200) << path;
    EXPECT_EQ(page->body, kIndex);
    EXPECT_EQ(page->get_header_value("Content-Type"), "text/html; charset=utf-8");
    EXPECT_EQ(page->get_header_value("Cache-Control"), "no-cache");
    EXPECT_EQ(page->get_header_value("X-Content-Type-Options"), "nosniff");
  }
  auto script = client_->Get("/assets/app-1a2b.js");
  ASSERT_TRUE(script);
  EXPECT_EQ(script->status, 200);
  EXPECT_EQ(script->body, kScript);
  EXPECT_EQ(script->get_header_value("Content-Type"), "text/javascript; charset=utf-8");
  EXPECT_EQ(script->get_header_value("Cache-Control"), "public, max-age=31536000, immutable");
  auto style = client_->Get("/assets/app-1a2b.css");
  ASSERT_TRUE(style);
  EXPECT_EQ(style->get_header_value("Content-Type"), "text/css; charset=utf-8");
  auto icon = client_->Get("/favicon.svg");
  ASSERT_TRUE(icon);
  EXPECT_EQ(icon->get_header_value("Content-Type"), "image/svg+xml");
  auto nested = client_->Get("/data/levels.json");
  ASSERT_TRUE(nested);
  EXPECT_EQ(nested->get_header_value("Content-Type"), "application/json");

  // Revalidation: the entity tag answers 304 without a body.
  const std::string etag = script->get_header_value("ETag");
  auto again = client_->Get("/assets/app-1a2b.js", {{"If-None-Match", etag}});
  ASSERT_TRUE(again);
  EXPECT_EQ(again->status, 304);
  EXPECT_TRUE(again->body.empty());
  auto head = client_->Head("/");
  ASSERT_TRUE(head);
  EXPECT_EQ(head->status, 200);
  EXPECT_TRUE(head->body.empty());
  // Writes are not files.
  auto post = client_->Post("/index.html", "x", "text/plain");
  ASSERT_TRUE(post);
  EXPECT_EQ(post->status, 405);
  // The API is unaffected.
  auto health = client_->Get("/healthz");
  ASSERT_TRUE(health);
  EXPECT_EQ(health->status, 200);
}

// The viewer's page and files carry the policy and framing headers (also on a 304, which
// a browser may take its headers from); the API's answers, errors included, carry
// nosniff but none of the page's policy.
TEST_F(WebServing, SendsSecurityHeaders) {
  const std::string etag = client_->Get("/assets/app-1a2b.js")->get_header_value("ETag");
  ASSERT_FALSE(etag.empty());
  for (const auto& [path, status, request_headers] :
       std::vector<std::tuple<std::string, int, httplib::Headers>>{
           {"/", 200, {}},
           {"/index.html", 200, {}},
           {"/assets/app-1a2b.js", 200, {}},
           {"/assets/app-1a2b.css", 200, {}},
           {"/favicon.svg", 200, {}},
           {"/assets/app-1a2b.js", 304, {{"If-None-Match", etag}}}}) {
    auto result = client_->Get(path.c_str(), request_headers);
    ASSERT_TRUE(result) << path;
    EXPECT_EQ(result->status, status) << path;
    EXPECT_EQ(result->get_header_value("Content-Security-Policy"),
              "default-src 'self'; script-src 'self'; style-src 'self'; img-src 'self' blob:; "
              "connect-src 'self' blob:; worker-src 'none'; object-src 'none'; base-uri 'none'; "
              "frame-ancestors 'none'; form-action 'none'")
        << path;
    EXPECT_EQ(result->get_header_value("X-Content-Type-Options"), "nosniff") << path;
    EXPECT_EQ(result->get_header_value("Referrer-Policy"), "no-referrer") << path;
    EXPECT_EQ(result->get_header_value("X-Frame-Options"), "DENY") << path;
    EXPECT_EQ(result->get_header_value_count("X-Content-Type-Options"), 1u) << path;
  }
  auto post = client_->Post("/index.html", "x", "text/plain");
  auto bakes = client_->Get("/v1/bakes");
  auto health = client_->Get("/healthz");
  auto missing = client_->Get(("/v1/bakes/" + std::string(64, '0')).c_str());
  for (const auto* api : {&post, &bakes, &health, &missing}) {
    ASSERT_TRUE(*api);
    const httplib::Response& answer = **api;
    EXPECT_EQ(answer.get_header_value("X-Content-Type-Options"), "nosniff") << answer.status;
    EXPECT_EQ(answer.get_header_value_count("X-Content-Type-Options"), 1u) << answer.status;
    EXPECT_FALSE(answer.has_header("Content-Security-Policy")) << answer.status;
  }
  EXPECT_EQ(post->status, 405);
  EXPECT_EQ(bakes->status, 200);
  EXPECT_EQ(bakes->get_header_value("Content-Type"), "application/json");
  EXPECT_EQ(health->status, 200);
  EXPECT_EQ(missing->status, 404);
  EXPECT_EQ(missing->get_header_value("Content-Type"), "application/problem+json");
}

TEST_F(WebServing, UnknownPathsAndTraversalAttemptsAre404) {
  for (const char* path : {"/nothing.html",
                           "/assets/",
                           "/assets/missing.js",
                           "/.hidden.js",
                           "/bad%20name.js",
                           "/notes.unknownext",
                           "/Makefile",
                           "/a/b/c/d/too-deep.js",
                           "/link.txt",
                           "/up/secret.txt",
                           "/../secret.txt",
                           "/assets/../../secret.txt",
                           "/%2e%2e/secret.txt",
                           "/assets/%2e%2e/%2e%2e/secret.txt",
                           "/assets/..%2f..%2fsecret.txt",
                           "//index.html",
                           "/index.html/",
                           "/assets/app-1a2b.js/..",
                           "/%2fetc%2fpasswd",
                           "/assets/app-1a2b.js%00.png",
                           "/INDEX.HTML"}) {
    ExpectNotFound(path);
  }
}

TEST(WebServingWithoutViewer, SlashSaysHowToBuildIt) {
  Daemon daemon(TestDirectory());
  ASSERT_TRUE(daemon.Start({"--web-root", (daemon.dir() / "no-dist").string()})) << daemon.error;
  auto client = daemon.Client();
  auto root = client->Get("/");
  ASSERT_TRUE(root);
  EXPECT_EQ(root->status, 404);
  EXPECT_EQ(root->get_header_value("Content-Type"), "application/problem+json");
  const auto problem = nlohmann::json::parse(root->body, nullptr, false);
  EXPECT_NE(problem.value("detail", "").find("scripts/setup.sh"), std::string::npos) << root->body;
  auto health = client->Get("/healthz");
  ASSERT_TRUE(health);
  EXPECT_EQ(health->status, 200);
}

}  // namespace
}  // namespace motionlod::server
