// A transient storage fault stays transient: while the data directory cannot be written,
// /readyz answers 503, an upload 503 and a bake fails with the code 'storage', each
// saying why without a server path; once the directory is back, /readyz is ready again
// and the same bake submitted again runs again and succeeds. The fault is real: the
// blob directory is replaced by a plain file (which fails even for root, unlike a
// permission change).
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "tests/fixtures/flat_bvh.h"
#include "tests/server/test_util.h"

namespace motionlod::server::testing {
namespace {

namespace fs = std::filesystem;

json Bake(httplib::Client& client, const std::vector<int>& levels) {
  auto submitted =
      SubmitBake(client, {{"character", kSampleId}, {"motion", "Walking_A"}, {"levels", levels}});
  EXPECT_TRUE(submitted);
  if (!submitted) return json();
  EXPECT_EQ(submitted->status, 202) << submitted->body;
  return WaitForJob(client, Json(submitted)["id"]);
}

TEST(StorageFaults, AFailedStoreIsRetriedWhenAskedAgainAndReadyzSaysSo) {
  Daemon daemon(TestDirectory());
  ASSERT_TRUE(daemon.Start()) << daemon.error;
  auto client = daemon.Client();
  ASSERT_EQ(UploadFile(*client, Sample(), "rig.glb")->status, 201);
  // A first bake leaves the character imported in the daemon's asset cache, so that the
  // next one needs no blob read, only writes.
  ASSERT_EQ(Bake(*client, {17, 6}).value("state", ""), "succeeded");
  EXPECT_EQ(client->Get("/readyz")->status, 200);

  const fs::path blobs = daemon.dir() / "data" / "blobs" / "sha256";
  const fs::path away = daemon.dir() / "data" / "blobs" / "sha256.away";
  fs::rename(blobs, away);
  std::ofstream(blobs) << "not a directory";
  const std::string data_dir = (daemon.dir() / "data").string();

  auto ready = client->Get("/readyz");
  ExpectProblem(ready, 503, "the data directory is not writable");
  EXPECT_EQ(ready->body.find(data_dir), std::string::npos) << ready->body;
  auto upload = UploadBytes(*client, "small.bvh", motionlod::testing::FlatBvh(30, 10));
  ExpectProblem(upload, 503, "cannot be written now");
  EXPECT_EQ(upload->body.find(data_dir), std::string::npos) << upload->body;

  const json failed = Bake(*client, {12, 4});
  EXPECT_EQ(failed.value("state", ""), "failed");
  EXPECT_EQ(failed["error"].value("code", ""), "storage") << failed.dump();
  const std::string detail = failed["error"].value("detail", "");
  EXPECT_NE(detail.find("submit the same bake again"), std::string::npos) << detail;
  EXPECT_EQ(detail.find('/'), std::string::npos) << detail;

  fs::remove(blobs);
  fs::rename(away, blobs);
  EXPECT_EQ(client->Get("/readyz")->status, 200);
  const json retried = Bake(*client, {12, 4});
  EXPECT_EQ(retried.value("state", ""), "succeeded") << retried.dump();
  EXPECT_EQ(retried.value("attempts", 0), 2);
  auto choice = client->Get(("/v1/bakes/" + retried.value("id", "") + "/level?px=50").c_str(),
                            {{"Accept", "application/json"}});
  ASSERT_TRUE(choice);
  auto level = client->Get(Json(choice).value("url", "").c_str());
  ASSERT_TRUE(level);
  EXPECT_EQ(level->status, 200);
}

}  // namespace
}  // namespace motionlod::server::testing
