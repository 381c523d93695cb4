// Accepted jobs survive a crash: SIGKILL with one bake running and others queued, start
// again on the same data, and every bake completes with the level files an
// uninterrupted run (the engine in-process) produces, byte for byte.
#include <gtest/gtest.h>
#include <signal.h>

#include "io/asset.h"
#include "pipeline/bake.h"
#include "proto/api.h"
#include "proto/level_format.h"
#include "server/service.h"
#include "tests/server/test_util.h"

namespace motionlod::server::testing {
namespace {

TEST(DaemonRestart, JobsQueuedOrRunningAtASigkillCompleteAfterARestartWithIdenticalLevels) {
  const std::string sample = SourcePath("samples/Rig_Medium_MovementBasic.glb");
  Daemon daemon(TestDirectory());
  ASSERT_TRUE(daemon.Start({"--threads", "1", "--bake-threads", "1"})) << daemon.error;
  auto client = daemon.Client();
  ASSERT_EQ(UploadFile(*client, sample, "rig.glb")->status, 201);
  std::vector<std::string> ids;
  for (const char* motion : {"Jump_Full_Long", "Walking_A", "Running_A", "Walking_C"}) {
    auto submitted = SubmitBake(
        *client,
        {{"character", kSampleId}, {"motion", motion}, {"all_levels", true}, {"fps", 500}});
    ASSERT_TRUE(submitted);
    ASSERT_EQ(submitted->status, 202) << submitted->body;
    ids.push_back(Json(submitted)["id"]);
  }
  // Kill while the first runs and the others wait.
  bool running = false;
  for (int tries = 0; tries < 400 && !running; ++tries) {
    running = Json(client->Get(("/v1/jobs/" + ids[0]).c_str())).value("state", "") == "running";
    if (!running) std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  ASSERT_TRUE(running);
  EXPECT_EQ(Json(client->Get(("/v1/jobs/" + ids[3]).c_str())).value("state", ""), "queued");
  EXPECT_EQ(daemon.Stop(SIGKILL), 128 + SIGKILL);

  ASSERT_TRUE(daemon.Start({"--threads", "1", "--bake-threads", "2"})) << daemon.error;
  client = daemon.Client();
  EXPECT_NE(daemon.Log().find("requeued 4 unfinished jobs"), std::string::npos) << daemon.Log();
  auto character = io::LoadAssetFile(sample);
  ASSERT_TRUE(character.ok());
  for (const std::string& id : ids) {
    const json finished = WaitForJob(*client, id);
    ASSERT_EQ(finished.value("state", ""), "succeeded") << finished.dump();
    const json bake = Json(client->Get(("/v1/bakes/" + id).c_str()));
    if (id == ids[0]) {
      EXPECT_EQ(finished["attempts"], 2) << "the running job ran again";
    }

    // The uninterrupted run.
    auto request = proto::api::ParseBakeRequest(bake["request"].dump());
    ASSERT_TRUE(request.ok());
    pipeline::BakeRequest p = MakePipelineRequest(*request, {{nullptr, bake["animation"], ""}}, 1);
    p.character = *character;
    p.source_hash =
        MakeBakeKey(*request, {{"character", bake["animation"]}}, p.settings.Hash()).source_hash;
    auto expected = pipeline::Bake(p);
    ASSERT_TRUE(expected.ok()) << expected.status().message();
    const proto::AlignedBytes aligned = proto::AlignedBytes::CopyOf(expected->level_set);
    auto view = proto::DecodeLevelSet(aligned.bytes());
    ASSERT_TRUE(view.ok());
    ASSERT_EQ(bake["levels"].size(), view->level_count());
    for (uint32_t l = 0; l < view->level_count(); ++l) {
      auto fetched = client->Get(bake["levels"][l]["url"].get<std::string>().c_str());
      ASSERT_TRUE(fetched);
      auto one = proto::ExtractLevel(*view, l);
      ASSERT_TRUE(one.ok());
      EXPECT_TRUE(fetched->body == *one) << "bake " << id << " level " << l;
    }
  }
  EXPECT_EQ(daemon.Stop(SIGTERM), 0);
}

TEST(DaemonRestart, SigtermLeavesUnfinishedJobsQueuedForTheNextStart) {
  const std::string sample = SourcePath("samples/Rig_Medium_MovementBasic.glb");
  Daemon daemon(TestDirectory());
  ASSERT_TRUE(daemon.Start({"--threads", "1", "--drain-seconds", "0"})) << daemon.error;
  auto client = daemon.Client();
  ASSERT_EQ(UploadFile(*client, sample, "rig.glb")->status, 201);
  std::vector<std::string> ids;
  for (const char* motion : {"Jump_Full_Long", "Walking_B"}) {
    auto submitted = SubmitBake(
        *client,
        {{"character", kSampleId}, {"motion", motion}, {"all_levels", true}, {"fps", 800}});
    ASSERT_TRUE(submitted);
    ids.push_back(Json(submitted)["id"]);
  }
  EXPECT_EQ(daemon.Stop(SIGTERM), 0) << daemon.Log();
  ASSERT_TRUE(daemon.Start({"--threads", "1"})) << daemon.error;
  client = daemon.Client();
  for (const std::string& id : ids)
    EXPECT_EQ(WaitForJob(*client, id).value("state", ""), "succeeded");
}

TEST(DaemonRestart, ABakeRunningAtEachOfMaxJobCrashesDeathsIsFailedAndTheDaemonServes) {
  // The daemon dies (SIGKILL, as the kernel's OOM killer would) while the same bake runs,
  // twice: with max_job_crashes 2 the next start fails it as 'crashed' instead of running
  // it a third time, and serves.
  Daemon daemon(TestDirectory());
  const std::vector<std::string> args = {"--threads", "1", "--max-job-crashes", "2"};
  ASSERT_TRUE(daemon.Start(args)) << daemon.error;
  auto client = daemon.Client();
  ASSERT_EQ(UploadFile(*client, Sample(), "rig.glb")->status, 201);
  auto submitted = SubmitBake(
      *client,
      {{"character", kSampleId}, {"motion", "Jump_Full_Long"}, {"all_levels", true}, {"fps", 800}});
  ASSERT_TRUE(submitted);
  ASSERT_EQ(submitted->status, 202) << submitted->body;
  const std::string id = Json(submitted)["id"];
  for (int death = 1; death <= 2; ++death) {
    json status;
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
    while (std::chrono::steady_clock::now() < deadline) {
      status = Json(client->Get(("/v1/jobs/" + id).c_str()));
      if (status.value("state", "") == "running") break;
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    ASSERT_EQ(status.value("state", ""), "running") << status.dump();
    ASSERT_EQ(status.value("attempts", 0), death);
    EXPECT_EQ(daemon.Stop(SIGKILL), 128 + SIGKILL);
    ASSERT_TRUE(daemon.Start(args)) << daemon.error;
    client = daemon.Client();
  }
  const json failed = Json(client->Get(("/v1/jobs/" + id).c_str()));
  EXPECT_EQ(failed.value("state", ""), "failed") << failed.dump();
  EXPECT_EQ(failed["error"].value("code", ""), "crashed") << failed.dump();
  EXPECT_NE(failed["error"].value("detail", "").find("2"), std::string::npos) << failed.dump();
  EXPECT_EQ(client->Get("/readyz")->status, 200);
  auto health = client->Get("/healthz");
  ASSERT_TRUE(health);
  EXPECT_EQ(health->status, 200);
}

}  // namespace
}  // namespace motionlod::server::testing
