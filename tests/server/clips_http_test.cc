// Character-wide bakes over HTTP: several clips baked together, each clip's frames served
// on their own (?clip=), the request's clips, ranking and defaults, and their errors.
#include <gtest/gtest.h>

#include <algorithm>

#include "proto/aligned_bytes.h"
#include "proto/level_format.h"
#include "tests/server/test_util.h"

namespace motionlod::server::testing {
namespace {

const std::vector<std::string> kClips = {"Walking_A", "Running_A", "Jump_Start"};

class ClipBakes : public ::testing::Test {
 protected:
  void SetUp() override {
    daemon_ = std::make_unique<Daemon>(TestDirectory());
    ASSERT_TRUE(daemon_->Start()) << daemon_->error;
    client_ = daemon_->Client();
    auto uploaded =
        UploadFile(*client_, SourcePath("samples/Rig_Medium_MovementBasic.glb"), "rig.glb");
    ASSERT_TRUE(uploaded);
    ASSERT_EQ(uploaded->status, 201);
    const json character = Json(uploaded);
    for (const json& animation : character["animations"]) {
      motion_ids_.push_back(animation["id"]);
      animations_.push_back(animation["animation"]);
    }
  }

  // Submits `request` and returns the bake's GET /v1/bakes/{id}, after its job finished
  // when `wait`.
  json Bake(const json& request, bool wait) {
    auto submitted = SubmitBake(*client_, request);
    EXPECT_TRUE(submitted);
    if (!submitted) return json();
    EXPECT_EQ(submitted->status, 202) << submitted->body;
    const std::string id = Json(submitted)["id"];
    if (wait) {
      EXPECT_EQ(WaitForJob(*client_, id).value("state", ""), "succeeded");
    }
    return Json(client_->Get(("/v1/bakes/" + id).c_str()));
  }

  std::string MotionId(const std::string& animation) const {
    const auto found = std::find(animations_.begin(), animations_.end(), animation);
    return found == animations_.end() ? std::string() : motion_ids_[found - animations_.begin()];
  }

  std::unique_ptr<Daemon> daemon_;
  std::unique_ptr<httplib::Client> client_;
  std::vector<std::string> motion_ids_, animations_;  // the character's, in its list's order
};

proto::AlignedBytes Bytes(const httplib::Result& result) {
  return proto::AlignedBytes::CopyOf(result ? result->body : std::string());
}

TEST_F(ClipBakes, EveryClipGetsItsOwnFramesOfTheSameReducedSkeleton) {
  const json bake = Bake({{"character", kSampleId}, {"clips", kClips}, {"levels", {17, 6}}}, true);
  ASSERT_EQ(bake["state"], "succeeded") << bake.dump();
  const std::string id = bake["id"];
  EXPECT_EQ(bake["ranking"], "greedy");
  ASSERT_EQ(bake["clips"].size(), kClips.size());
  int first_frame = 0;
  for (size_t c = 0; c < kClips.size(); ++c) {
    const json& clip = bake["clips"][c];
    EXPECT_EQ(clip["animation"], kClips[c]);
    EXPECT_EQ(bake["request"]["clips"][c], clip["motion"]) << "resolved to motion ids";
    EXPECT_EQ(clip["motion"], MotionId(kClips[c]));
    EXPECT_EQ(clip["first_frame"], first_frame);
    EXPECT_GT(clip["frames"].get<int>(), 1);
    EXPECT_GT(clip["fps"].get<double>(), 0);
    first_frame += clip["frames"].get<int>();
  }
  EXPECT_EQ(bake["frames"], first_frame);
  EXPECT_EQ(bake["motion"], bake["clips"][0]["motion"]) << "the first clip's, as before";
  EXPECT_EQ(bake["animation"], kClips[0]);

  for (const json& level : bake["levels"]) {
    auto whole_reply = client_->Get(level["url"].get<std::string>().c_str());
    ASSERT_TRUE(whole_reply);
    ASSERT_EQ(whole_reply->status, 200);
    const proto::AlignedBytes whole_bytes = Bytes(whole_reply);
    auto whole = proto::DecodeLevelSet(whole_bytes.bytes());
    ASSERT_TRUE(whole.ok()) << whole.status().message();
    ASSERT_EQ(whole->clip_count(), kClips.size());
    EXPECT_EQ(whole->frame_count(), static_cast<uint32_t>(first_frame));
    const uint32_t m = whole->level(0).kept_count();
    for (const json& clip : bake["clips"]) {
      const std::string name = clip["animation"];
      const std::string url = level["url"].get<std::string>() + "?clip=" + name;
      auto reply = client_->Get(url.c_str());
      ASSERT_TRUE(reply);
      ASSERT_EQ(reply->status, 200) << reply->body;
      EXPECT_EQ(reply->get_header_value("Cache-Control"), "public, max-age=31536000, immutable");
      const std::string etag = reply->get_header_value("ETag");
      EXPECT_NE(etag, "\"" + level["hash"].get<std::string>() + "\"");
      auto again = client_->Get(url.c_str(), {{"If-None-Match", etag}});
      ASSERT_TRUE(again);
      EXPECT_EQ(again->status, 304);
      const proto::AlignedBytes bytes = Bytes(reply);
      auto one = proto::DecodeLevelSet(bytes.bytes());
      ASSERT_TRUE(one.ok()) << one.status().message();
      ASSERT_EQ(one->clip_count(), 1u);
      EXPECT_EQ(one->clip(0).name, name);
      EXPECT_EQ(one->frame_count(), clip["frames"].get<uint32_t>());
      EXPECT_DOUBLE_EQ(one->fps(), clip["fps"].get<double>());
      // The same kept joints for every clip, and the clip's frames of the whole level.
      ASSERT_TRUE(std::ranges::equal(one->level(0).kept_joints(), whole->level(0).kept_joints()));
      const auto frames = whole->level(0).matrices().subspan(
          size_t{clip["first_frame"].get<uint32_t>()} * m * proto::kMatrixFloats,
          size_t{one->frame_count()} * m * proto::kMatrixFloats);
      EXPECT_TRUE(std::ranges::equal(one->level(0).matrices(), frames)) << name;
    }
  }

  // The level for a height, narrowed to a clip: chosen by the figures over every clip.
  for (const std::string& name : kClips) {
    const std::string choose = "/v1/bakes/" + id + "/level?px=100&clip=" + name;
    auto choice = client_->Get(choose.c_str(), {{"Accept", "application/json"}});
    auto whole = client_->Get(("/v1/bakes/" + id + "/level?px=100").c_str(),
                              {{"Accept", "application/json"}});
    ASSERT_TRUE(choice && whole);
    ASSERT_EQ(choice->status, 200) << choice->body;
    EXPECT_EQ(Json(choice)["clip"], name);
    EXPECT_TRUE(Json(whole)["clip"].is_null());
    EXPECT_EQ(Json(choice)["hash"], Json(whole)["hash"]);
    EXPECT_EQ(Json(choice)["url"], Json(whole)["url"].get<std::string>() + "?clip=" + name);
    auto redirect = client_->Get(choose.c_str());
    ASSERT_TRUE(redirect);
    ASSERT_EQ(redirect->status, 302);
    EXPECT_EQ(redirect->get_header_value("Location"), Json(choice)["url"]);
  }

  // The glTF export plays the clip asked for; each clip is its own file.
  const std::string glb = "/v1/bakes/" + id + "/levels/17.glb";
  auto first = client_->Get(glb.c_str());
  auto running = client_->Get((glb + "?clip=Running_A").c_str());
  auto walking = client_->Get((glb + "?clip=Walking_A").c_str());
  ASSERT_TRUE(first && running && walking);
  ASSERT_EQ(running->status, 200) << running->body;
  EXPECT_EQ(running->get_header_value("Content-Type"), "model/gltf-binary");
  EXPECT_NE(running->get_header_value("ETag"), walking->get_header_value("ETag"));
  EXPECT_EQ(first->get_header_value("ETag"), walking->get_header_value("ETag"))
      << "no clip: the first";
  EXPECT_NE(running->body.find("Running_A"), std::string::npos);

  // An unknown clip is a 404 naming the bake's clips; an empty one a 400.
  const std::string hash = bake["levels"][0]["hash"];
  for (const std::string& path :
       {"/v1/bakes/" + id + "/level?px=100&clip=Moonwalk", "/v1/levels/" + hash + "?clip=Moonwalk",
        glb + "?clip=Moonwalk"}) {
    ExpectProblem(client_->Get(path.c_str()), 404, "'Walking_A', 'Running_A', 'Jump_Start'");
  }
  ExpectProblem(client_->Get(("/v1/levels/" + hash + "?clip=").c_str()), 400, "clip");

  // A deleted bake's clip files go with its levels (though made and cached before).
  const std::string clip_url = "/v1/levels/" + hash + "?clip=Running_A";
  ASSERT_EQ(client_->Get(clip_url.c_str())->status, 200);
  ASSERT_EQ(client_->Delete(("/v1/bakes/" + id).c_str())->status, 204);
  ExpectProblem(client_->Get(clip_url.c_str()), 404);
}

TEST_F(ClipBakes, TheRequestNamesTheClipsTheRankingAndByDefaultEveryMotion) {
  // Neither motion nor clips: every motion of the character, in its list's order.
  const json every = Bake({{"character", kSampleId}, {"levels", {6}}}, false);
  ASSERT_TRUE(every.is_object());
  EXPECT_EQ(every["request"]["clips"], motion_ids_);
  ASSERT_EQ(every["clips"].size(), animations_.size());
  for (size_t c = 0; c < animations_.size(); ++c)
    EXPECT_EQ(every["clips"][c]["animation"], animations_[c]);
  EXPECT_EQ(client_->Delete(("/v1/bakes/" + every["id"].get<std::string>()).c_str())->status, 204);

  // The bake id covers the clips (in order) and the ranking.
  const json greedy = Bake(
      {{"character", kSampleId}, {"clips", {"Walking_A", "Running_A"}}, {"levels", {6}}}, false);
  const json paper = Bake({{"character", kSampleId},
                           {"clips", {"Walking_A", "Running_A"}},
                           {"levels", {6}},
                           {"ranking", "paper"}},
                          false);
  const json swapped = Bake(
      {{"character", kSampleId}, {"clips", {"Running_A", "Walking_A"}}, {"levels", {6}}}, false);
  const json one =
      Bake({{"character", kSampleId}, {"motion", "Walking_A"}, {"levels", {6}}}, false);
  EXPECT_EQ(paper["ranking"], "paper");
  EXPECT_EQ(paper["request"]["ranking"], "paper");
  EXPECT_EQ(greedy["ranking"], "greedy");
  std::vector<std::string> ids;
  for (const json* bake : {&greedy, &paper, &swapped, &one}) ids.push_back((*bake)["id"]);
  std::sort(ids.begin(), ids.end());
  EXPECT_EQ(std::unique(ids.begin(), ids.end()), ids.end()) << "four requests, four bakes";
  // `motion` is the one clip `clips` names alone: the same bake.
  auto same = SubmitBake(
      *client_, {{"character", kSampleId}, {"clips", {MotionId("Walking_A")}}, {"levels", {6}}});
  ASSERT_TRUE(same);
  EXPECT_EQ(same->status, 200) << same->body;
  EXPECT_EQ(Json(same)["id"], one["id"]);
  for (const std::string& id : ids) client_->Delete(("/v1/bakes/" + id).c_str());
}

TEST_F(ClipBakes, BadClipsAndRankingsAreProblems) {
  const auto post = [&](const json& body) { return SubmitBake(*client_, body); };
  ExpectProblem(post({{"character", kSampleId}, {"ranking", "best"}}), 400,
                "'ranking' must be greedy (the default) or paper");
  ExpectProblem(post({{"character", kSampleId}, {"ranking", 1}}), 400, "ranking");
  ExpectProblem(post({{"character", kSampleId}, {"motion", "Walking_A"}, {"clips", {"Running_A"}}}),
                400, "not both");
  ExpectProblem(post({{"character", kSampleId}, {"clips", json::array()}}), 400,
                "'clips' is empty");
  ExpectProblem(post({{"character", kSampleId}, {"clips", "Walking_A"}}), 400,
                "'clips' must be an array");
  ExpectProblem(post({{"character", kSampleId}, {"clips", {"Walking_A", ""}}}), 400,
                "'clips' entries");
  ExpectProblem(post({{"character", kSampleId}, {"clips", {"Walking_A", "Moonwalk"}}}), 422,
                "'clips'[1]: the character has no animation named 'Moonwalk'");
  ExpectProblem(post({{"character", kSampleId}, {"clips", {"Walking_A", MotionId("Walking_A")}}}),
                422, "named twice");
  ExpectProblem(post({{"character", kSampleId}, {"clips", {std::string(64, 'f')}}}), 404,
                "no motion");
}

}  // namespace
}  // namespace motionlod::server::testing
