// The daemon behind nginx with deploy/nginx/motionlod.conf: level files are served from
// nginx's cache once fetched, still only to clients with a read key, and while the daemon
// is down. (The slow-client load through the same proxy: slow_clients_test.cc.)
#include <gtest/gtest.h>
#include <signal.h>

#include "io/sha256.h"
#include "tests/server/nginx.h"
#include "tests/server/test_util.h"

namespace motionlod::server::testing {
namespace {

TEST(Proxy, LevelsAreCachedForKeyHoldersAndServedWhileTheDaemonIsDown) {
  ASSERT_TRUE(Nginx::Installed()) << "nginx is missing: bash scripts/setup.sh installs it";
  const std::string write_key = "write-key-0123456789";
  const std::string read_key = "read-key-0123456789";
  Daemon daemon(TestDirectory());
  ASSERT_TRUE(daemon.Start({"--write-keys", write_key, "--read-keys", read_key})) << daemon.error;
  Nginx proxy(daemon.dir() / "nginx");
  ASSERT_TRUE(proxy.Start(daemon.port())) << proxy.error;
  httplib::Client client("127.0.0.1", proxy.port());
  client.set_read_timeout(60, 0);

  ASSERT_EQ(UploadFile(client, Sample(), "rig.glb", write_key)->status, 201);
  auto submitted = SubmitBake(
      client, {{"character", kSampleId}, {"motion", "Walking_A"}, {"levels", {17, 6}}}, write_key);
  ASSERT_TRUE(submitted);
  ASSERT_EQ(submitted->status, 202) << submitted->body;
  const std::string id = Json(submitted)["id"];
  auto direct = daemon.Client();
  direct->set_bearer_token_auth(read_key.c_str());
  ASSERT_EQ(WaitForJob(*direct, id).value("state", ""), "succeeded");
  auto choice =
      direct->Get(("/v1/bakes/" + id + "/level?px=50").c_str(), {{"Accept", "application/json"}});
  ASSERT_TRUE(choice);
  const std::string url = Json(choice)["url"];
  const std::string hash = Json(choice)["hash"];

  auto first = client.Get(url.c_str(), Auth(read_key));
  ASSERT_TRUE(first);
  EXPECT_EQ(first->status, 200);
  EXPECT_EQ(first->get_header_value("X-Cache-Status"), "MISS");
  EXPECT_EQ(io::Sha256Hex(first->body), hash);
  auto second = client.Get(url.c_str(), Auth(read_key));
  ASSERT_TRUE(second);
  EXPECT_EQ(second->get_header_value("X-Cache-Status"), "HIT");
  EXPECT_TRUE(second->body == first->body);
  // Without a key the daemon is asked, and says no; the cache never answers for it.
  auto anonymous = client.Get(url.c_str());
  ASSERT_TRUE(anonymous);
  EXPECT_EQ(anonymous->status, 401);

  // Every daemon down: cached levels are still served.
  EXPECT_EQ(daemon.Stop(SIGTERM), 0);
  auto while_down = client.Get(url.c_str(), Auth(read_key));
  ASSERT_TRUE(while_down);
  EXPECT_EQ(while_down->status, 200);
  EXPECT_EQ(while_down->get_header_value("X-Cache-Status"), "HIT");
  EXPECT_EQ(io::Sha256Hex(while_down->body), hash);
}

}  // namespace
}  // namespace motionlod::server::testing
