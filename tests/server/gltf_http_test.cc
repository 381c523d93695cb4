// GET /v1/bakes/{id}/levels/{joints|hash}.glb on the real daemon: bakes of real characters at
// several levels and variants, exported over HTTP, checked by the Khronos glTF validator
// and served again from the cache (ETag, 304); wrong counts and names answer 404.
#include <gtest/gtest.h>

#include <fstream>

#include "io/sha256.h"
#include "tests/server/test_util.h"
#include "tests/tools/gltf_validator.h"

namespace motionlod::server::testing {
namespace {

namespace fs = std::filesystem;

class GltfExportHttp : public ::testing::Test {
 protected:
  void SetUp() override {
    daemon_ = std::make_unique<Daemon>(TestDirectory());
    ASSERT_TRUE(daemon_->Start()) << daemon_->error;
    client_ = daemon_->Client();
  }

  // Uploads `path` and bakes `request` (character filled in); returns the bake id.
  std::string Bake(const std::string& path, json request) {
    auto uploaded = UploadFile(*client_, path, fs::path(path).filename().string());
    EXPECT_TRUE(uploaded && (uploaded->status == 201 || uploaded->status == 200));
    request["character"] = Json(uploaded)["id"];
    auto submitted = SubmitBake(*client_, request);
    EXPECT_TRUE(submitted);
    const std::string id = Json(submitted).value("id", "");
    EXPECT_EQ(WaitForJob(*client_, id, 300).value("state", ""), "succeeded") << path;
    return id;
  }

  // GETs the level's .glb, checks the response and the file's skeleton, saves it.
  fs::path Fetch(const std::string& bake, int joints, bool rigid) {
    const std::string url = "/v1/bakes/" + bake + "/levels/" + std::to_string(joints) + ".glb";
    auto result = client_->Get(url.c_str());
    EXPECT_TRUE(result);
    if (!result) return {};
    EXPECT_EQ(result->status, 200) << url << ": " << result->body;
    EXPECT_EQ(result->get_header_value("Content-Type"), "model/gltf-binary");
    EXPECT_EQ(result->get_header_value("Cache-Control"), "public, max-age=86400");
    const nlohmann::json gltf = motionlod::testing::GlbJson(result->body);
    EXPECT_TRUE(gltf.is_object()) << url << " is no GLB";
    if (gltf.is_object()) {
      EXPECT_EQ(gltf["skins"][0]["joints"].size(), static_cast<size_t>(joints)) << url;
      EXPECT_EQ(gltf["animations"][0]["channels"].size(),
                static_cast<size_t>(joints) * (rigid ? 2 : 3))
          << url;
    }
    const fs::path file =
        daemon_->dir() / (bake.substr(0, 8) + "-" + std::to_string(joints) + ".glb");
    std::ofstream(file, std::ios::binary) << result->body;
    return file;
  }

  std::unique_ptr<Daemon> daemon_;
  std::unique_ptr<httplib::Client> client_;
};

TEST_F(GltfExportHttp, ExportsLevelsThatTheGltfValidatorAccepts) {
  std::vector<fs::path> files;
  const std::string sample = Bake(SourcePath("samples/Rig_Medium_MovementBasic.glb"),
                                  {{"motion", "Walking_A"}, {"levels", {23, 6}}});
  files.push_back(Fetch(sample, 23, true));  // full detail, what the viewer shows beside a level
  files.push_back(Fetch(sample, 6, true));
  if (const std::string cesium = SharedDataPath("characters/CesiumMan.glb"); !cesium.empty()) {
    const std::string bake = Bake(cesium, {{"levels", {19, 8}}, {"variant", "vp+pd"}});
    files.push_back(Fetch(bake, 19, true));
    files.push_back(Fetch(bake, 8, true));
    const std::string fox = Bake(SharedDataPath("characters/Fox.glb"),
                                 {{"motion", "Run"}, {"levels", {12}}, {"variant", "vpno"}});
    files.push_back(Fetch(fox, 12, false));
    const std::string orc = Bake(SharedDataPath("characters/Orc.gltf"),
                                 {{"motion", "Walk"}, {"levels", {30, 10}}, {"variant", "vp"}});
    files.push_back(Fetch(orc, 10, false));
  }
  motionlod::testing::ExpectValidGltf(files);
}

// Levels by cost: several may keep the same joints, and each draws its own mesh. Each is
// exported by its hash from the level table, with its own vertices and triangles.
TEST_F(GltfExportHttp, ExportsEachLevelByCostByItsHash) {
  const std::string bake =
      Bake(SourcePath("samples/Rig_Medium_MovementBasic.glb"), {{"motion", "Walking_A"}});
  auto info = client_->Get(("/v1/bakes/" + bake).c_str());
  ASSERT_TRUE(info);
  const json levels = Json(info)["levels"];
  ASSERT_GE(levels.size(), 3u);
  std::vector<fs::path> files;
  for (const json& level : levels) {
    const std::string url = "/v1/bakes/" + bake + "/levels/" + level["hash"].get<std::string>() + ".glb";
    auto result = client_->Get(url.c_str());
    ASSERT_TRUE(result);
    ASSERT_EQ(result->status, 200) << url << ": " << result->body;
    const nlohmann::json gltf = motionlod::testing::GlbJson(result->body);
    ASSERT_TRUE(gltf.is_object()) << url;
    const nlohmann::json& primitive = gltf["meshes"][0]["primitives"][0];
    EXPECT_EQ(gltf["accessors"][primitive["attributes"]["POSITION"].get<int>()]["count"],
              level["vertices"]);
    EXPECT_EQ(gltf["accessors"][primitive["indices"].get<int>()]["count"].get<int>(),
              3 * level["triangles"].get<int>());
    EXPECT_EQ(gltf["skins"][0]["joints"].size(), level["joints"].get<size_t>());
    files.push_back(daemon_->dir() / ("level-" + std::to_string(files.size()) + ".glb"));
    std::ofstream(files.back(), std::ios::binary) << result->body;
  }
  EXPECT_LT(levels.back()["vertices"].get<int>(), levels.front()["vertices"].get<int>());
  motionlod::testing::ExpectValidGltf(files);
  ExpectProblem(client_->Get(("/v1/bakes/" + bake + "/levels/" + std::string(64, 'b') + ".glb").c_str()),
                404, "has no level");
}

TEST_F(GltfExportHttp, IsCachedAndConditional) {
  const std::string bake = Bake(SourcePath("samples/Rig_Medium_MovementBasic.glb"),
                                {{"motion", "Walking_A"}, {"levels", {23, 9}}});
  const std::string url = "/v1/bakes/" + bake + "/levels/9.glb";
  auto first = client_->Get(url.c_str());
  ASSERT_TRUE(first);
  ASSERT_EQ(first->status, 200);
  const std::string etag = first->get_header_value("ETag");
  ASSERT_EQ(etag.size(), 66u) << "a quoted SHA-256";
  auto again = client_->Get(url.c_str());
  ASSERT_TRUE(again);
  EXPECT_EQ(again->status, 200);
  EXPECT_TRUE(again->body == first->body);
  EXPECT_EQ(again->get_header_value("ETag"), etag);
  auto conditional = client_->Get(url.c_str(), {{"If-None-Match", etag}});
  ASSERT_TRUE(conditional);
  EXPECT_EQ(conditional->status, 304);
  EXPECT_TRUE(conditional->body.empty());
  // Another level of the same bake is another file.
  auto other = client_->Get(("/v1/bakes/" + bake + "/levels/23.glb").c_str());
  ASSERT_TRUE(other);
  EXPECT_EQ(other->status, 200);
  EXPECT_NE(other->get_header_value("ETag"), etag);
  EXPECT_GT(other->body.size(), first->body.size());
}

TEST_F(GltfExportHttp, AnswersNotFoundForWhatIsNoLevel) {
  const std::string bake = Bake(SourcePath("samples/Rig_Medium_MovementBasic.glb"),
                                {{"motion", "Walking_A"}, {"levels", {23, 9}}});
  const std::string base = "/v1/bakes/" + bake + "/levels/";
  ExpectProblem(client_->Get((base + "5.glb").c_str()), 404, "its levels keep 23, 9");
  for (const char* name : {"9.gltf", "9", "nine.glb", ".glb", "0.glb", "-9.glb", "99999999.glb"}) {
    ExpectProblem(client_->Get((base + name).c_str()), 404, "{joints}.glb");
  }
  ExpectProblem(client_->Get(("/v1/bakes/" + std::string(64, 'a') + "/levels/9.glb").c_str()), 404,
                "no bake");
  ExpectProblem(client_->Get("/v1/bakes/nothex/levels/9.glb"), 404, "64 hex digits");
}

}  // namespace
}  // namespace motionlod::server::testing
