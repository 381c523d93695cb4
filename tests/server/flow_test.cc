// The whole flow on real data, over real HTTP against a real motionlodd: upload, bake,
// watch progress (long-poll and SSE), choose and fetch levels for several on-screen
// sizes, and check every level byte for byte against the engine run in-process.
#include <gtest/gtest.h>
#include <signal.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <set>

#include "proto/level_selection.h"
#include "io/asset.h"
#include "pipeline/bake.h"
#include "proto/api.h"
#include "proto/level_format.h"
#include "server/service.h"
#include "tests/server/test_util.h"

namespace motionlod::server::testing {
namespace {

// Bakes in-process what the daemon baked for `bake` (its GET /v1/bakes/{id} reply).
pipeline::BakeOutput BakeLikeTheDaemon(const json& bake, const std::string& character_path,
                                       const std::string& motion_path,
                                       const std::string& motion_source_id, int threads) {
  auto request = proto::api::ParseBakeRequest(bake["request"].dump());
  EXPECT_TRUE(request.ok()) << request.status().message();
  const std::string animation = bake["animation"].get<std::string>();
  pipeline::ClipSource clip{nullptr, animation, ""};
  if (!motion_path.empty()) {
    auto motion = io::LoadAssetFile(motion_path);
    EXPECT_TRUE(motion.ok());
    clip = {*motion, animation, std::filesystem::path(motion_path).filename().string()};
  }
  pipeline::BakeRequest p = MakePipelineRequest(*request, {std::move(clip)}, threads);
  auto character = io::LoadAssetFile(character_path);
  EXPECT_TRUE(character.ok());
  p.character = *character;
  const BakeKey key = MakeBakeKey(*request, {{motion_source_id, animation}}, p.settings.Hash());
  EXPECT_EQ(key.id, bake["id"].get<std::string>())
      << "the bake id is the hash of the resolved request";
  p.source_hash = key.source_hash;
  auto output = pipeline::Bake(p);
  EXPECT_TRUE(output.ok()) << output.status().message();
  return output.ok() ? std::move(*output) : pipeline::BakeOutput{};
}

// Every level the daemon serves for `bake` is the one-level file of the in-process
// level set, byte for byte, and decodes to the same joints and matrices.
void ExpectLevelsMatch(httplib::Client& client, const json& bake,
                       const pipeline::BakeOutput& expected) {
  const proto::AlignedBytes aligned = proto::AlignedBytes::CopyOf(expected.level_set);
  auto view = proto::DecodeLevelSet(aligned.bytes());
  ASSERT_TRUE(view.ok()) << view.status().message();
  ASSERT_EQ(bake["levels"].size(), view->level_count());
  for (uint32_t l = 0; l < view->level_count(); ++l) {
    const json& entry = bake["levels"][l];
    auto fetched = client.Get(entry["url"].get<std::string>().c_str());
    ASSERT_TRUE(fetched);
    ASSERT_EQ(fetched->status, 200);
    auto one = proto::ExtractLevel(*view, l);
    ASSERT_TRUE(one.ok());
    EXPECT_TRUE(fetched->body == *one) << "level " << l;
    const proto::AlignedBytes got_bytes = proto::AlignedBytes::CopyOf(fetched->body);
    auto got = proto::DecodeLevelSet(got_bytes.bytes());
    ASSERT_TRUE(got.ok()) << got.status().message();
    ASSERT_EQ(got->level_count(), 1u);
    EXPECT_EQ(got->joint_count(), view->joint_count());
    EXPECT_EQ(got->frame_count(), view->frame_count());
    EXPECT_EQ(got->level(0).kept_count(), view->level(l).kept_count());
    EXPECT_EQ(static_cast<int>(got->level(0).kept_count()), entry["joints"].get<int>());
    EXPECT_TRUE(std::equal(got->level(0).joint_map().begin(), got->level(0).joint_map().end(),
                           view->level(l).joint_map().begin()));
    const auto a = got->level(0).matrices(), b = view->level(l).matrices();
    ASSERT_EQ(a.size(), b.size());
    EXPECT_TRUE(std::equal(a.begin(), a.end(), b.begin())) << "matrices of level " << l;
  }
}

TEST(DaemonFlow, UploadBakeWatchAndFetchLevelsMatchTheEngineInProcess) {
  Daemon daemon(TestDirectory());
  ASSERT_TRUE(daemon.Start({"--threads", "1", "--bake-threads", "1"})) << daemon.error;
  auto client = daemon.Client();

  // Upload: 201 with the content address, the skeleton and the animations.
  auto uploaded = UploadFile(*client, Sample(), "Rig_Medium_MovementBasic.glb");
  ASSERT_TRUE(uploaded);
  ASSERT_EQ(uploaded->status, 201) << uploaded->body;
  const json character = Json(uploaded);
  EXPECT_EQ(character["id"], kSampleId);
  EXPECT_EQ(uploaded->get_header_value("Location"), std::string("/v1/characters/") + kSampleId);
  EXPECT_EQ(character["joints"], 23);
  EXPECT_EQ(character["vertices"], 6551);
  EXPECT_EQ(character["animations"].size(), 11u);

  // The same bytes again: the same character, 200.
  auto again = UploadFile(*client, Sample(), "another-name.glb");
  ASSERT_TRUE(again);
  EXPECT_EQ(again->status, 200);
  EXPECT_EQ(Json(again)["id"], kSampleId);

  // Bake: 202 with the job's location; the same request again is the same bake.
  const json request = {{"character", kSampleId}, {"motion", "Walking_A"}};
  auto submitted = SubmitBake(*client, request);
  ASSERT_TRUE(submitted);
  ASSERT_EQ(submitted->status, 202) << submitted->body;
  const std::string id = Json(submitted)["id"];
  EXPECT_EQ(submitted->get_header_value("Location"), "/v1/jobs/" + id);
  auto resubmitted = SubmitBake(*client, request);
  ASSERT_TRUE(resubmitted);
  EXPECT_EQ(resubmitted->status, 200);
  EXPECT_EQ(Json(resubmitted)["id"], id);

  // Watch it by long-poll until it finishes.
  const json finished = WaitForJob(*client, id);
  ASSERT_EQ(finished.value("state", ""), "succeeded") << finished.dump();
  EXPECT_EQ(finished["progress"], 1.0);
  EXPECT_GE(finished["attempts"].get<int>(), 1);

  // The level table: levels finest first with pixel ranges that tile (0, inf).
  auto bake_reply = client->Get(("/v1/bakes/" + id).c_str());
  ASSERT_TRUE(bake_reply);
  ASSERT_EQ(bake_reply->status, 200);
  const json bake = Json(bake_reply);
  EXPECT_EQ(bake["state"], "succeeded");
  EXPECT_EQ(bake["animation"], "Walking_A");
  ASSERT_GE(bake["levels"].size(), 3u);
  EXPECT_EQ(bake["levels"][0]["joints"], 23);
  EXPECT_TRUE(bake["levels"][0]["px_max"].is_null());
  std::vector<double> fractions;
  for (const json& level : bake["levels"])
    fractions.push_back(level["max_vertex_error_pct"].get<double>() / 100);

  // Levels for several on-screen heights: the redirect names the level proto::SelectLevel
  // picks, inside that level's pixel range; the JSON form says the same.
  for (double px : {5.0, 15.0, 50.0, 120.0, 1000.0, 1e5}) {
    const std::string path = "/v1/bakes/" + id + "/level?px=" + std::to_string(px);
    auto redirect = client->Get(path.c_str());
    ASSERT_TRUE(redirect);
    ASSERT_EQ(redirect->status, 302) << redirect->body;
    const int l = proto::SelectLevel(fractions, px, 1.0);
    const json& level = bake["levels"][l];
    EXPECT_EQ(redirect->get_header_value("Location"), level["url"]) << "px " << px;
    EXPECT_TRUE(level["chosen"].get<bool>());
    EXPECT_GT(px, level["px_min"].get<double>());
    if (!level["px_max"].is_null()) {
      EXPECT_LE(px, level["px_max"].get<double>());
    }
    auto choice = client->Get(path.c_str(), {{"Accept", "application/json"}});
    ASSERT_TRUE(choice);
    ASSERT_EQ(choice->status, 200);
    EXPECT_EQ(Json(choice)["index"], l);
    EXPECT_EQ(Json(choice)["joints"], level["joints"]);
    auto fetched = client->Get(level["url"].get<std::string>().c_str());
    ASSERT_TRUE(fetched);
    ASSERT_EQ(fetched->status, 200);
    const proto::AlignedBytes bytes = proto::AlignedBytes::CopyOf(fetched->body);
    auto view = proto::DecodeLevelSet(bytes.bytes());
    ASSERT_TRUE(view.ok()) << view.status().message();
    EXPECT_EQ(static_cast<int>(view->level(0).kept_count()), level["joints"].get<int>());
  }
  // A tighter budget never picks a coarser level.
  auto strict = client->Get(("/v1/bakes/" + id + "/level?px=120&budget=0.1").c_str(),
                            {{"Accept", "application/json"}});
  auto loose = client->Get(("/v1/bakes/" + id + "/level?px=120&budget=10").c_str(),
                           {{"Accept", "application/json"}});
  ASSERT_TRUE(strict && loose);
  EXPECT_LE(Json(strict)["index"].get<int>(), Json(loose)["index"].get<int>());

  // Byte for byte what the engine bakes in-process (with another thread count).
  ExpectLevelsMatch(*client, bake, BakeLikeTheDaemon(bake, Sample(), "", "character", 2));

  auto report = client->Get(("/v1/bakes/" + id + "/report").c_str());
  ASSERT_TRUE(report);
  EXPECT_EQ(report->status, 200);
  EXPECT_EQ(Json(report)["format"], "motionlod-report");

  // Metrics saw it all.
  auto metrics = client->Get("/metrics");
  ASSERT_TRUE(metrics);
  ASSERT_EQ(metrics->status, 200);
  for (const char* name :
       {"motionlodd_queue_depth", "motionlodd_jobs{state=\"succeeded\"} 1",
        "motionlodd_bake_duration_seconds_count 1", "motionlodd_level_cache_requests_total",
        "motionlodd_http_requests_total{route=\"/v1/levels/{hash}\",method=\"GET\",code=\"200\"}",
        "motionlodd_http_request_duration_seconds_bucket"}) {
    EXPECT_NE(metrics->body.find(name), std::string::npos) << name;
  }

  // Deleting the bake removes it and its levels.
  const std::string level_url = bake["levels"][1]["url"];
  auto deleted = client->Delete(("/v1/bakes/" + id).c_str());
  ASSERT_TRUE(deleted);
  EXPECT_EQ(deleted->status, 204);
  ExpectProblem(client->Get(("/v1/bakes/" + id).c_str()), 404);
  ExpectProblem(client->Get(level_url.c_str()), 404);
  ExpectProblem(client->Get(("/v1/jobs/" + id).c_str()), 404);

  // Deleting the character removes it.
  auto gone = client->Delete((std::string("/v1/characters/") + kSampleId).c_str());
  ASSERT_TRUE(gone);
  EXPECT_EQ(gone->status, 204);
  ExpectProblem(client->Get((std::string("/v1/characters/") + kSampleId).c_str()), 404);
  EXPECT_EQ(daemon.Stop(SIGTERM), 0) << daemon.Log();
}

// The run command's daemon (--seed) prints where each level of the sample is drawn: a
// range that can be read for every level, including one that serves only a sliver of
// heights (the sample's 12- and 9-joint levels differ in the sixth digit of their error).
TEST(DaemonFlow, TheSeedPrintsAReadableHeightRangeForEveryLevel) {
  Daemon daemon(TestDirectory());
  ASSERT_TRUE(daemon.Start({"--seed", Sample(), "--seed-animation", "Walking_A"})) << daemon.error;
  // The seed's default ladder takes a minute or more in the sanitizer build.
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(300);
  std::string line, bake_url;
  std::vector<std::string> levels;
  while (daemon.ReadStdoutLine(line, deadline)) {
    if (line.rfind("bake (level table): ", 0) == 0) bake_url = line.substr(line.find("/v1/"));
    if (line.rfind("  level ", 0) == 0) levels.push_back(line);
    if (line.rfind("level for a character 120 px tall", 0) == 0) break;
  }
  ASSERT_FALSE(bake_url.empty()) << daemon.Log();
  auto client = daemon.Client();
  auto bake = client->Get(bake_url.c_str());
  ASSERT_TRUE(bake);
  ASSERT_EQ(bake->status, 200);
  const json table = Json(bake)["levels"];
  ASSERT_EQ(levels.size(), table.size());
  for (size_t l = 0; l < levels.size(); ++l) {
    const json& entry = table[l];
    const std::string& printed = levels[l];
    if (!entry["chosen"].get<bool>()) {
      EXPECT_NE(printed.find("never"), std::string::npos) << printed;
    } else if (entry.contains("px_max") && !entry["px_max"].is_null() &&
               entry["px_max"].get<double>() - entry["px_min"].get<double>() < 0.05) {
      EXPECT_NE(printed.find("only within 0.05 px of"), std::string::npos) << printed;
    } else {
      // "for heights above A px[ up to B px]" with A below B as printed.
      double above = 0, up_to = 0;
      const size_t at = printed.find("for heights above ");
      ASSERT_NE(at, std::string::npos) << printed;
      const int read = std::sscanf(printed.c_str() + at, "for heights above %lf px up to %lf px",
                                   &above, &up_to);
      ASSERT_GE(read, 1) << printed;
      if (read == 2) {
        EXPECT_LT(above, up_to) << printed;
      }
    }
  }
}

TEST(DaemonFlow, ProgressStreamsAsServerSentEvents) {
  Daemon daemon(TestDirectory());
  ASSERT_TRUE(daemon.Start({"--threads", "1"})) << daemon.error;
  auto client = daemon.Client();
  ASSERT_EQ(UploadFile(*client, Sample(), "rig.glb")->status, 201);
  // Long enough to report progress on the way.
  auto submitted = SubmitBake(
      *client,
      {{"character", kSampleId}, {"motion", "Jump_Full_Long"}, {"all_levels", true}, {"fps", 600}});
  ASSERT_TRUE(submitted);
  ASSERT_EQ(submitted->status, 202) << submitted->body;
  const std::string id = Json(submitted)["id"];

  std::string stream;
  auto result =
      client->Get(("/v1/jobs/" + id + "/events").c_str(), [&](const char* data, size_t n) {
        stream.append(data, n);
        return true;
      });
  ASSERT_TRUE(result);
  EXPECT_EQ(result->status, 200);
  EXPECT_EQ(result->get_header_value("Content-Type"), "text/event-stream");
  // Events: "progress" with a non-decreasing fraction, then one "done" that ends it.
  std::vector<json> events;
  std::vector<std::string> names;
  size_t start = 0;
  while (true) {
    const size_t end = stream.find("\n\n", start);
    if (end == std::string::npos) break;
    const std::string block = stream.substr(start, end - start);
    start = end + 2;
    const size_t event = block.find("event: ");
    const size_t data = block.find("data: ");
    if (event == std::string::npos || data == std::string::npos) continue;
    names.push_back(block.substr(event + 7, block.find('\n', event) - event - 7));
    events.push_back(json::parse(block.substr(data + 6), nullptr, false));
  }
  ASSERT_GE(events.size(), 2u) << stream;
  EXPECT_EQ(names.back(), "done");
  EXPECT_EQ(events.back()["state"], "succeeded");
  for (size_t e = 0; e + 1 < names.size(); ++e) EXPECT_EQ(names[e], "progress");
  for (size_t e = 1; e < events.size(); ++e) {
    EXPECT_GE(events[e]["progress"].get<double>(), events[e - 1]["progress"].get<double>());
  }
  std::set<std::string> states;
  for (const json& e : events) states.insert(e["state"].get<std::string>());
  EXPECT_TRUE(states.count("running") || states.count("queued"));
}

TEST(DaemonFlow, MotionFilesRetargetOntoTheCharacterAndMultipartUploadsResolveAmongTheirParts) {
  const std::string general = SharedDataPath("characters/Rig_Medium_General.glb");
  const std::string gltf = SharedDataPath("characters/Superhero_Male_FullBody.gltf");
  if (general.empty() || gltf.empty()) GTEST_SKIP() << "shared data absent";
  Daemon daemon(TestDirectory());
  ASSERT_TRUE(daemon.Start({"--threads", "1"})) << daemon.error;
  auto client = daemon.Client();
  ASSERT_EQ(UploadFile(*client, Sample(), "rig.glb")->status, 201);

  // Another file of the same rig: its clips become motions of the character.
  auto motions = client->Post(
      (std::string("/v1/motions?character=") + kSampleId + "&filename=Rig_Medium_General.glb")
          .c_str(),
      ReadFile(general), "application/octet-stream");
  ASSERT_TRUE(motions);
  ASSERT_EQ(motions->status, 201) << motions->body;
  const json list = Json(motions)["motions"];
  ASSERT_FALSE(list.empty());
  EXPECT_EQ(list[0]["source"], "file");
  const std::string motion_id = list[0]["id"];
  auto listed = client->Get((std::string("/v1/characters/") + kSampleId + "/motions").c_str());
  ASSERT_TRUE(listed);
  EXPECT_EQ(Json(listed)["motions"].size(), 11u + list.size());

  auto submitted =
      SubmitBake(*client, {{"character", kSampleId}, {"motion", motion_id}, {"levels", {12, 6}}});
  ASSERT_TRUE(submitted);
  ASSERT_EQ(submitted->status, 202) << submitted->body;
  const std::string id = Json(submitted)["id"];
  ASSERT_EQ(WaitForJob(*client, id).value("state", ""), "succeeded");
  const json bake = Json(client->Get(("/v1/bakes/" + id).c_str()));
  ASSERT_EQ(bake["levels"].size(), 2u);
  ExpectLevelsMatch(*client, bake,
                    BakeLikeTheDaemon(bake, Sample(), general, list[0]["files"][0]["sha256"], 1));

  // A glTF with its .bin as two multipart parts: the reference resolves among the parts.
  httplib::MultipartFormDataItems items = {
      {"file", ReadFile(gltf), "Superhero_Male_FullBody.gltf", "model/gltf+json"},
      {"buffer", ReadFile(SharedDataPath("characters/Superhero_Male_FullBody.bin")),
       "Superhero_Male_FullBody.bin", "application/octet-stream"}};
  auto multipart = client->Post("/v1/characters", items);
  ASSERT_TRUE(multipart);
  ASSERT_EQ(multipart->status, 201) << multipart->body;
  EXPECT_EQ(Json(multipart)["joints"], 65);
  EXPECT_EQ(Json(multipart)["files"].size(), 2u);
  // Without its .bin the same glTF is unimportable: 422 with the importer's message.
  httplib::MultipartFormDataItems alone = {
      {"file", ReadFile(gltf), "Superhero_Male_FullBody.gltf", "model/gltf+json"}};
  ExpectProblem(client->Post("/v1/characters", alone), 422);
  // A bake of a character without animation names the fix.
  ExpectProblem(SubmitBake(*client, {{"character", Json(multipart)["id"]}}), 422, "/v1/motions");
}

}  // namespace
}  // namespace motionlod::server::testing
